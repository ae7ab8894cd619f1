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
- ``("lod points", texture key, placement)``: the points of every level.

No GL here: uploads are the scene's (:mod:`aniso3d.app.viewer.scene`).
"""

from __future__ import annotations

import sys
import traceback
from dataclasses import dataclass

from aniso3d.app.viewer.state import ViewState
from aniso3d.app.viewer.worker import Builder, Cancelled, Job
from aniso3d.build.mesh import Mesh
from aniso3d.build.points import PointCloud
from aniso3d.build.pyramid import LodPoints, Pyramid, pyramid
from aniso3d.build.texture import AnisoTexture, build_texture
from aniso3d.errors import InputError
from aniso3d.rendering.cache import Cache

#: Bounds of the viewer's caches (conversions kept for switching back, and
#: uploads): entries, and bytes in all; least recently used out first.
CACHE_ENTRIES, CACHE_BYTES = 16, 1 << 30


def describe_data(data) -> str:
    """How much there is to draw, for the log and the overlay ("12 triangles")."""
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
        self._sources = {(kind,): thing}  # the input, under ("mesh",), ("texture",) or ("points",)
        self.cache = cache if cache is not None else Cache(CACHE_ENTRIES, CACHE_BYTES, "viewer conversions")
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
        return self.cache.get(self.thing, key)

    # --------------------------------------------------------------- builds

    def job(self, key: tuple) -> Job:
        """The conversion that makes ``key`` (and what it passes through, for the cache)."""
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

    def schedule(self, state: ViewState) -> str | None:
        """Start the next conversion the settings need (returning its label);
        stop one they no longer need (a resolution stepped past, say)."""
        wanted = self.wanted(state)
        if self.builder.busy:
            key = self.builder.key
            if not (key in wanted or (key[0] == "points" and key[1] in wanted)):
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
            self.cache.put(self.thing, k, results[k])
        return Collected(f"built {label} in {seconds:.2f} s: {describe_data(results[self.builder.key])}")
