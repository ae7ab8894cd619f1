"""The world box of anything aniso3d draws, for framing a camera and clipping.

One definition for every front end: the command line and the viewer frame
the same object the same way.
"""

from __future__ import annotations

import numpy as np

from aniso3d.build.mesh import Mesh
from aniso3d.build.points import PointCloud
from aniso3d.build.scene import Scene
from aniso3d.build.texture import AnisoTexture
from aniso3d.errors import InputError


def bounds_of(thing: Mesh | AnisoTexture | PointCloud | Scene) -> np.ndarray:
    """(2, 3) float64 min and max corner, world units, of what is drawn of
    ``thing``: a mesh's used vertices, a point cloud's splats (grown by each
    splat's radius), a texture's occupied voxels (not its whole grid).
    a scene's instances (their transformed asset boxes). Refuses an empty
    texture, point cloud or scene, and anything else."""
    if isinstance(thing, Scene):
        return thing.bounds
    if isinstance(thing, AnisoTexture):
        if thing.n_voxels == 0:
            raise InputError("the texture is empty (no occupied voxels): nothing to draw")
        c, h = np.asarray(thing.coords), float(thing.voxel_size)
        origin = np.asarray(thing.origin, dtype=np.float64)
        return np.stack([origin + c.min(0) * h, origin + (c.max(0) + 1) * h])
    if isinstance(thing, PointCloud):
        if len(thing) == 0:
            raise InputError("the point cloud is empty: nothing to draw")
        return np.asarray(thing.bounds, dtype=np.float64)
    if isinstance(thing, Mesh):
        return np.asarray(thing.bounds, dtype=np.float64)
    raise InputError(
        f"cannot draw a {type(thing).__name__}; give a mesh, a scene, a .a3d texture or a PLY point cloud"
    )


def surface_sample(thing: Mesh | AnisoTexture | PointCloud | Scene, limit: int = 50_000) -> np.ndarray | None:
    """Up to ``limit`` points of the thing's surface (every k-th), for a
    framing tighter than its bounding box (a scene: its instances' box corners)."""
    if isinstance(thing, Scene):
        return thing.corners(limit)
    if isinstance(thing, Mesh):
        pts = thing.vertices
    elif isinstance(thing, PointCloud):
        pts = thing.positions
    elif isinstance(thing, AnisoTexture):
        pts = thing.entry_centroid
    else:
        return None
    return pts[:: max(1, len(pts) // limit)]
