"""What each renderer draws for the viewer's current settings, and getting it
made: data keys, the conversion jobs run on the :class:`Builder` thread, and
the finished conversions kept for switching back, in a
:class:`~aniso3d.rendering.cache.Cache` (the window shares the
:class:`~aniso3d.rendering.renderer.Renderer`'s conversion cache).

A data key is a tuple naming one value:

- ``("mesh",)``, ``("texture",)``, ``("points",)``: the input itself;
- ``("texture", resolution, K)``: a mesh converted to a texture;
- ``("points", texture key, placement)``: a texture's points;
- ``("pyramid", texture key)``: a texture's level-of-detail pyramid;
- ``("lod points", texture key, placement)``: the points of every level;
- for a :class:`~aniso3d.build.scene.Scene`: ``("scene",)`` the scene itself
  (the polygons draw it as it is), ``("scene pyramids", resolution, K)``
  every asset's texture and pyramid (the volume), ``("scene points",
  resolution, K, placement)`` those and every level's points (the splats). They
  are made in the background and kept in the renderer's conversion cache
  where :func:`~aniso3d.rendering.scene_draw.upload_scene`, the renderer's
  own scene path, finds them, so that it only uploads; their value is a
  :class:`ScenePrep`.

No GL here: uploads are the scene's (:mod:`aniso3d.app.viewer.scene`).
"""

from __future__ import annotations

import sys
import traceback
from dataclasses import dataclass, field

from aniso3d.app.viewer.state import ViewState
from aniso3d.app.viewer.worker import Builder, Cancelled, Job
from aniso3d.build.mesh import Mesh
from aniso3d.build.points import PointCloud
from aniso3d.build.pyramid import LodPoints, Pyramid, pyramid
from aniso3d.build.scene import Scene
from aniso3d.build.texture import AnisoTexture, build_texture
from aniso3d.errors import InputError
from aniso3d.rendering.cache import Cache

#: Bounds of the viewer's caches (conversions kept for switching back, and
#: uploads): entries, and bytes in all; least recently used out first.
CACHE_ENTRIES, CACHE_BYTES = 16, 1 << 30
#: Cache entries a scene adds per asset: its texture and pyramid (conversions),
#: and its upload for each of the three methods (uploads), with room for a rebuild.
ENTRIES_PER_ASSET = 6


def cache_entries(thing) -> int:
    """Entries of each of the viewer's caches for ``thing``: :data:`CACHE_ENTRIES`,
    and for a scene :data:`ENTRIES_PER_ASSET` more per asset, so that a frame's
    every asset stays cached (a scene frame touches them all)."""
    return CACHE_ENTRIES + (ENTRIES_PER_ASSET * len(thing.assets) if isinstance(thing, Scene) else 0)


@dataclass(eq=False)
class ScenePrep:
    """A scene's assets made ready to draw as volume (``placement`` None) or
    splats: per asset its texture and pyramid (finest level first), and for
    splats every level's points for ``placement`` (kept in the pyramid)."""

    scene: Scene
    textures: list = field(default_factory=list)
    pyramids: list = field(default_factory=list)
    placement: str | None = None

    @property
    def n_voxels(self) -> int:
        """Occupied voxels of the assets' finest levels."""
        return int(sum(t.n_voxels for t in self.textures))


def describe_data(data) -> str:
    """How much there is to draw, for the log and the overlay ("12 triangles")."""
    if isinstance(data, Scene):
        return f"{data.n_instances:,} instances of {len(data.assets)} assets, {data.n_faces:,} triangles in all"
    if isinstance(data, ScenePrep):
        sc = data.scene
        return f"{sc.n_instances:,} instances of {len(sc.assets)} assets, {data.n_voxels:,} voxels at the finest"
    if isinstance(data, Mesh):
        return f"{data.n_faces:,} triangles"
    if isinstance(data, AnisoTexture):
        return f"{data.n_voxels:,} voxels of {'x'.join(str(int(x)) for x in data.shape)}"
    if isinstance(data, PointCloud):
        return f"{len(data):,} points"
    if isinstance(data, Pyramid):
        return f"a pyramid of {len(data)} levels, {describe_data(data[0])} at the finest"
    if isinstance(data, LodPoints):
        n = sum(len(data.level_cloud(lvl)[0]) for lvl in range(len(data.pyramid)))
        return f"{n:,} points in {len(data.pyramid)} levels"
    return type(data).__name__


def describe_key(key: tuple) -> str:
    """A data key in words ("texture 64³ (K=16)")."""
    if key[0] == "pyramid":
        return f"pyramid of the {describe_key(key[1])}"
    if key[0] == "lod points":
        return f"level-of-detail points ({key[2]}) of the {describe_key(key[1])}"
    if key[0] == "scene pyramids":
        return f"scene's asset pyramids {key[1]}³ (K={key[2]})"
    if key[0] == "scene points":
        return f"scene's asset points ({key[3]}) {key[1]}³ (K={key[2]})"
    if key[0] == "texture" and len(key) == 3:
        return f"texture {key[1]}³ (K={key[2]})"
    if key[0] == "points" and len(key) == 3:
        return f"points ({key[2]}) from the {describe_key(key[1])}"
    return key[0]


@dataclass(frozen=True)
class Collected:
    """A finished build, in words; ``error`` when it failed."""

    text: str
    error: bool = False


class Conversions:
    """The data behind the viewer's input ``thing``: the input itself, and what
    was converted from it, made on demand by one background :class:`Builder`.

    Finished conversions go to ``cache`` (default: a new
    :class:`~aniso3d.rendering.cache.Cache` of :data:`CACHE_ENTRIES` and
    :data:`CACHE_BYTES`) under (``thing``, data key); the window passes the
    renderer's, so the two share one budget."""

    def __init__(self, thing, kind: str, cache: Cache | None = None):
        self.thing, self.kind = thing, kind
        self.builder = Builder()
        self._sources = {(kind,): thing}  # the input, under ("mesh",), ("texture",), ("points",) or ("scene",)
        self.cache = cache if cache is not None else Cache(cache_entries(thing), CACHE_BYTES, "viewer conversions")
        #: Why a build failed, by data key; not retried: the settings must change first.
        self.failed: dict[tuple, str] = {}

    # ----------------------------------------------------------------- keys

    def texture_key(self, state: ViewState) -> tuple:
        s = state.settings
        return ("texture",) if self.kind == "texture" else ("texture", s.resolution, s.directions)

    def points_key(self, state: ViewState) -> tuple:
        if self.kind == "points":
            return ("points",)
        return ("points", self.texture_key(state), state.settings.placement)

    def requirement(self, state: ViewState, method: str) -> tuple[tuple | None, str | None]:
        """(data key ``method`` draws, None), or (None, why it cannot draw this input)."""
        if self.kind == "scene":
            s = state.settings
            if method == "mesh":
                return ("scene",), None
            if method == "volume":
                return ("scene pyramids", s.resolution, s.directions), None
            return ("scene points", s.resolution, s.directions, s.placement), None
        if method == "mesh":
            if self.kind != "mesh":
                what = "saved texture" if self.kind == "texture" else "point cloud"
                return None, f"the polygon renderer needs the mesh: a {what} keeps no polygons"
            return ("mesh",), None
        if method == "volume":
            if self.kind == "points":
                return None, "the volume renderer needs an anisotropic texture: a point cloud has none"
            return (("pyramid", self.texture_key(state)) if state.lod else self.texture_key(state)), None
        if state.lod:
            return ("lod points", self.texture_key(state), state.settings.placement), None
        return self.points_key(state), None

    def wanted(self, state: ViewState) -> list[tuple]:
        """Data the current settings need, most urgent first: what the
        selected renderer draws, then (for a mesh) the texture and points, so
        a switch of renderer finds them ready."""
        method_key, _ = self.requirement(state, state.settings.method)
        wanted = [method_key]
        if self.kind == "scene":  # the pyramids first: the splats' points are made from them
            wanted += [self.requirement(state, m)[0] for m in ("volume", "splat")]
            return list(dict.fromkeys(wanted))
        if state.lod and method_key is not None and method_key[0] != "mesh":
            wanted += [self.requirement(state, m)[0] for m in ("volume", "splat")]
        if self.kind == "mesh":
            wanted += [self.texture_key(state), self.points_key(state)]
        elif self.kind == "texture":
            wanted += [self.points_key(state)]
        return list(dict.fromkeys(k for k in wanted if k is not None))

    def lookup(self, key: tuple):
        """The value of ``key`` if it is at hand (the input, or built and cached), else None."""
        if key in self._sources:
            return self._sources[key]
        if key[0] in ("scene pyramids", "scene points"):
            return self._scene_prep(key)
        return self.cache.get(self.thing, key)

    def _scene_prep(self, key: tuple) -> ScenePrep | None:
        """The :class:`ScenePrep` of a scene key if every part of it is in the
        cache, where the renderer's scene path looks (an asset's texture
        under (asset, ("texture", resolution, K)), its pyramid under
        (texture, ("pyramid",)), the renderer's keys), else None."""
        res, k = key[1], key[2]
        prep = ScenePrep(self.thing)
        for asset in self.thing.assets:
            tex = self.cache.get(asset, ("texture", res, k))
            pyr = None if tex is None else self.cache.get(tex, ("pyramid",))
            if pyr is None:
                return None
            prep.textures.append(tex)
            prep.pyramids.append(pyr)
        if key[0] == "scene points":  # made for these very pyramids (a pyramid rebuilt has no points)
            made = self.cache.get(self.thing, key)
            if made is None or any(a is not b for a, b in zip(made.pyramids, prep.pyramids, strict=True)):
                return None
            prep.placement = key[3]
        return prep

    # --------------------------------------------------------------- builds

    def job(self, key: tuple) -> Job:
        """The conversion that makes ``key`` (and what it passes through, for the cache)."""
        if key[0] in ("scene pyramids", "scene points"):
            return self._scene_job(key)
        mesh = self.thing
        if key[0] in ("pyramid", "lod points"):
            tkey = key[1]
            tex = self.lookup(tkey)
            pyr = self.lookup(("pyramid", tkey))

            def levels(progress):
                t = tex
                if t is None:
                    t = build_texture(mesh, tkey[1], tkey[2], progress=progress)
                progress(1.0, "pyramid")
                p = pyr if pyr is not None else pyramid(t)
                out = {tkey: t, ("pyramid", tkey): p}
                if key[0] == "lod points":
                    lp = out[key] = LodPoints(p, key[2])
                    for lvl in range(len(p)):  # the level point sets, off the main thread
                        lp.level_cloud(lvl)
                return out

            return levels
        if key[0] == "texture":
            _, res, k = key
            return lambda progress: {key: build_texture(mesh, res, k, progress=progress)}
        _, tkey, placement = key
        tex = self.lookup(tkey)

        def points(progress):
            t = tex
            if t is None:
                t = build_texture(mesh, tkey[1], tkey[2], progress=progress)
            progress(1.0, "points")
            return {tkey: t, key: t.to_points(placement)}

        return points

    def _scene_job(self, key: tuple) -> Job:
        """Every asset's texture and pyramid (those in the cache reused, as
        found here on the main thread), and for ``("scene points", ...)`` every
        level's points; the progress is the share of the assets done."""
        res, k = key[1], key[2]
        placement = key[3] if key[0] == "scene points" else None
        assets = list(self.thing.assets)
        found = []
        for asset in assets:
            tex = self.cache.get(asset, ("texture", res, k))
            found.append((tex, None if tex is None else self.cache.get(tex, ("pyramid",))))
        scene = self.thing

        def prepare(progress):
            prep = ScenePrep(scene, placement=placement)
            n = len(assets)
            for i, (asset, (tex, pyr)) in enumerate(zip(assets, found, strict=True)):
                def part(fraction, stage="", i=i):
                    progress((i + fraction) / n, stage)

                if tex is None:
                    tex = build_texture(asset, res, k, progress=part)
                part(1.0, "pyramid")
                if pyr is None:
                    pyr = pyramid(tex)
                if placement is not None:
                    for lvl in range(len(pyr)):  # the level point sets, off the main thread
                        pyr.level_cloud(lvl, placement)
                        part(1.0, "points")
                prep.textures.append(tex)
                prep.pyramids.append(pyr)
            return {key: prep}

        return prepare

    def _put_scene(self, key: tuple, prep: ScenePrep) -> None:
        """Keep a finished :class:`ScenePrep` where the renderer's scene path
        finds it: each asset's texture and pyramid under the renderer's keys;
        for splats, a record (of no bytes of its own) that the points were made."""
        res, k = key[1], key[2]
        for asset, tex, pyr in zip(self.thing.assets, prep.textures, prep.pyramids, strict=True):
            self.cache.put(asset, ("texture", res, k), tex)
            self.cache.put(tex, ("pyramid",), pyr)
        if key[0] == "scene points":
            self.cache.put(self.thing, key, prep, nbytes=0)

    def schedule(self, state: ViewState) -> str | None:
        """Start the next conversion the settings need (returning its label);
        stop one they no longer need (a resolution stepped past, say)."""
        wanted = self.wanted(state)
        if self.builder.busy:
            key = self.builder.key
            scene_points = key[0] == "scene points" and ("scene pyramids", *key[1:3]) in wanted
            if not (key in wanted or (key[0] == "points" and key[1] in wanted) or scene_points):
                if not self.builder.cancelling:
                    self.builder.cancel()
            return None
        for key in wanted:
            if self.lookup(key) is not None or key in self.failed:
                continue
            label = describe_key(key)
            self.builder.start(key, label, self.job(key))
            return label
        return None

    def collect(self) -> Collected | None:
        """Take a finished build's results into the cache; None while none has finished."""
        done = self.builder.poll()
        if done is None:
            return None
        results, exc, seconds = done
        label = self.builder.label
        if isinstance(exc, Cancelled):
            return Collected(f"stopped building {label} after {seconds:.2f} s: no longer needed")
        if exc is not None:
            if isinstance(exc, MemoryError):
                msg = "out of memory; step the resolution down"
            elif isinstance(exc, InputError):
                msg = str(exc)
            else:  # a bug: its traceback goes to stderr, the window stays
                traceback.print_exception(exc, file=sys.stderr)
                msg = f"{type(exc).__name__}: {exc}"
            self.failed[self.builder.key] = msg
            return Collected(f"building {label} failed: {msg}", error=True)
        # The wanted value last: the most recently used, the last to be evicted.
        key = self.builder.key
        for k in sorted(results, key=lambda k: k == key):
            if k[0] in ("scene pyramids", "scene points"):
                self._put_scene(k, results[k])
            else:
                self.cache.put(self.thing, k, results[k])
        return Collected(f"built {label} in {seconds:.2f} s: {describe_data(results[self.builder.key])}")
