"""The conversion/upload cache: weak keys (a new object at a dead one's
``id()`` gets nothing of it), the bounds and the releases; then the
Renderer's use of it on the GPU."""

from __future__ import annotations

import gc
import weakref

import numpy as np
import pytest

import aniso3d
from aniso3d import InputError, PointCloud
from aniso3d.rendering.cache import Cache
from aniso3d.rendering.camera import Camera


class Thing:
    """A source object: weakly referenceable, hashable by identity."""


class Blob:
    def __init__(self, nbytes: int):
        self.nbytes = nbytes


def at_same_id(old_id: int, make, tries: int = 10_000):
    """A new object from ``make()`` whose ``id()`` is ``old_id`` (CPython hands
    a freed object's memory to the next object of its size), or None."""
    held = []
    for _ in range(tries):
        obj = make()
        if id(obj) == old_id:
            return obj
        held.append(obj)  # keep it, so the next try gets other memory
    return None


# -------------------------------------------------------------- no GPU


def test_a_new_object_at_a_dead_objects_id_gets_nothing_and_the_old_value_is_released():
    cache = Cache(max_entries=8)
    released = []
    a = Thing()
    old = id(a)
    cache.put(a, "points", "made from a", release=released.append)
    assert cache.get(a, "points") == "made from a" and len(cache) == 1
    del a
    b = at_same_id(old, Thing)
    if b is None:
        pytest.skip("this Python did not reuse the freed object's id")
    assert cache.get(b, "points") is None  # an id-keyed dict would hand out "made from a"
    assert len(cache) == 0 and released == ["made from a"]
    cache.put(b, "points", "made from b")
    assert cache.get(b, "points") == "made from b"


def test_the_entry_bound_evicts_the_least_recently_used_and_releases_it():
    cache = Cache(max_entries=2)
    released = []
    things = [Thing() for _ in range(4)]
    for i, t in enumerate(things[:3]):
        cache.put(t, "k", i, release=released.append)
    assert released == [0] and len(cache) == 2 and cache.get(things[0], "k") is None
    assert cache.get(things[1], "k") == 1  # now the most recent
    cache.put(things[3], "k", 3, release=released.append)
    assert released == [0, 2] and [v for _, v in cache.items()] == [1, 3]


def test_the_byte_bound_evicts_and_keeps_the_newest_even_when_too_large():
    cache = Cache(max_entries=100, max_bytes=100)
    released = []
    things = [Thing() for _ in range(4)]
    for t in things[:3]:
        cache.put(t, "k", Blob(40), release=released.append)
    assert len(released) == 1 and len(cache) == 2 and cache.nbytes == 80
    big = cache.put(things[3], "k", Blob(500), release=released.append)
    assert len(cache) == 1 and cache.get(things[3], "k") is big and len(released) == 3


def test_replacing_discarding_and_clearing_release():
    cache = Cache()
    released = []
    a, b = Thing(), Thing()
    cache.put(a, "k", "a1", release=released.append)
    cache.put(a, "k", "a2", release=released.append)  # same key: the old one goes
    cache.put(a, "j", "a3", release=released.append)
    cache.put(b, "k", "b1", release=released.append)
    assert released == ["a1"]
    assert sorted(cache.discard(a)) == ["a2", "a3"] and sorted(released) == ["a1", "a2", "a3"]
    assert cache.discard(a) == [] and len(cache) == 1
    cache.clear()
    assert released[-1] == "b1" and len(cache) == 0


def test_sources_without_weak_references_are_held_until_evicted():
    cache = Cache(max_entries=1)
    key_source = (1, 2)  # tuples cannot be weakly referenced
    cache.put(key_source, "k", "v")
    assert cache.get(key_source, "k") == "v" and cache.get((1, 2) + (), "k") in ("v", None)
    cache.put(Thing(), "k", "w")  # evicts it
    assert cache.get(key_source, "k") is None


def test_bad_bounds_are_refused():
    for kwargs in ({"max_entries": 0}, {"max_entries": 2.5}, {"max_bytes": -1}, {"max_entries": True}):
        with pytest.raises(InputError, match="max_"):
            Cache(**kwargs)


# ----------------------------------------------------------------- GPU


def coloured_quad(kd, normal_axis=2) -> PointCloud:
    """A 1 x 1 quad's points, all of diffuse colour ``kd``."""
    pts = aniso3d.build_texture(aniso3d.scenes.quad(1.0, normal_axis=normal_axis), 8, 8).to_points()
    n = len(pts)
    return PointCloud(pts.positions, pts.normals, pts.areas, np.tile(kd, (n, 1)), pts.ks, pts.shininess)


@pytest.mark.gpu
def test_a_new_cloud_at_a_dead_clouds_id_is_drawn_from_its_own_upload(r):
    cam = Camera((0.0, 0.0, 2.0), (0.0, 0.0, 0.0))
    parts = {}
    for name, kd in (("red", (1.0, 0.0, 0.0)), ("blue", (0.0, 0.0, 1.0))):
        c = coloured_quad(kd)
        parts[name] = (c.positions, c.normals, c.areas, c.kd, c.ks, c.shininess)
    img = r.render(PointCloud(*parts["red"]), cam, "splat")
    assert img[..., 0].mean() > img[..., 2].mean() + 20  # red shows as red
    gc.collect()
    r.uploads.collect()
    uploads, objects = len(r.uploads), r.gl.n_objects
    blue = None
    for _ in range(20):  # other allocations may take the freed memory first: try again
        red = PointCloud(*parts["red"])
        r.render(red, cam, "splat")
        old, alive = id(red), weakref.ref(red)
        del red
        assert alive() is None  # the renderer keeps no strong reference to what it drew
        # Only the new cloud object is made here, so it can take the freed memory.
        blue = at_same_id(old, lambda: PointCloud(*parts["blue"]), tries=50)
        if blue is not None:
            break
    if blue is None:
        pytest.skip("no new point cloud took a freed one's id")
    img = r.render(blue, cam, "splat")
    drawn = img.min(axis=2) < 250
    assert drawn.sum() > 100 and img[drawn][:, 2].mean() > img[drawn][:, 0].mean() + 50
    # Every cloud's upload is released once the cloud is gone.
    assert len(r.uploads) == uploads + 1
    del blue
    assert r.uploads.collect() >= 1
    assert len(r.uploads) == uploads and r.gl.n_objects == objects


@pytest.mark.gpu
def test_the_upload_bound_evicts_and_frees_gpu_objects(r):
    from aniso3d.rendering.renderer import Renderer

    clouds = [coloured_quad((0.5, 0.5, 0.5), axis) for axis in range(3)]
    base = r.gl.n_objects
    with Renderer((32, 32), gl=r.gl, cache_entries=2) as small:
        h0 = small.upload(clouds[0], "splat")
        per = r.gl.n_objects - base  # buffer and attribute texture
        assert per >= 2
        h1 = small.upload(clouds[1], "splat")
        small.upload(clouds[2], "splat")
        assert len(small.uploads) == 2 and r.gl.n_objects == base + 2 * per
        assert small.upload(clouds[1], "splat") is h1  # kept
        assert small.upload(clouds[0], "splat") is not h0  # evicted, made again
        assert r.gl.n_objects == base + 2 * per
        with pytest.raises(InputError, match="max_entries"):
            Renderer((8, 8), gl=r.gl, cache_entries=0)
    assert r.gl.n_objects == base


@pytest.mark.gpu
def test_forget_drops_conversions_and_uploads_made_from_a_mesh(r):
    from aniso3d.rendering.renderer import Renderer

    mesh = aniso3d.scenes.sphere(1.0, subdivisions=2)
    cam = Camera.fit(mesh.bounds)
    base = r.gl.n_objects
    with Renderer((32, 32), gl=r.gl) as own:
        own.render(mesh, cam, "splat", resolution=16)
        own.render(mesh, cam, "splat", resolution=16, lod=True)
        own.render(mesh, cam, "volume", resolution=16)
        assert len(own.conversions) == 3 and len(own.uploads) == 3  # texture, points, pyramid
        with_uploads = r.gl.n_objects
        own.forget(mesh)
        assert len(own.conversions) == 0 and len(own.uploads) == 0
        assert r.gl.n_objects < with_uploads
    assert r.gl.n_objects == base
