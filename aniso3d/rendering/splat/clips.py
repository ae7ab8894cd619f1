"""Where a splat's surface ends: the faces of its voxel it is cut at.

A splat is its entry's facets' area as a disc about their centroid (with the
size factor, a disc of radius ``1.25 sqrt(A / pi)``), or, below a pixel, a
box of their projected second moments. Where the surface goes on, the next
voxel's splats overlap it; where it *ends* on a voxel face, as a wall's top or
a box's edge does on a grid plane, the disc or the box reaches past the end
and draws the surface where the background, or another face, should be (the
corpus room: most of the high splats' error lay within 2 px of its outlines).

The volume renderer already classifies each surface sheet's section edges on
its voxel's faces as continued, creased or open from the neighbouring voxels
(:func:`~aniso3d.rendering.sheet_edges.sheet_edges`, docs/coverage.md "Edges
on voxel faces"). :func:`entry_clips` turns the open and creased ones (at most
two an entry, open ones first) into half-spaces ``m . x <= o`` in world
units, the voxel's face planes; :func:`clipped` gives a texture's points them
(:attr:`~aniso3d.build.points.PointCloud.clips`), and quality "high" cuts each
splat at its planes (splat.vert, splat.frag; the NumPy twin in
:mod:`~aniso3d.rendering.splat.reference`): a resolved splat's coverage times
the filtered coverage of the half-plane, a sub-pixel box clipped to it in the
image and scaled back to its true area (all of which lies in the voxel).
"""

from __future__ import annotations

import weakref

import numpy as np

from aniso3d.build.points import PointCloud
from aniso3d.build.texture import AnisoTexture
from aniso3d.errors import InputError
from aniso3d.grid import ranges
from aniso3d.rendering.sheet_edges import CREASE, MAX_EDGES, OPEN, sheet_edges
from aniso3d.rendering.volume import RUN_SHARE, EntrySheets, entry_sheets

#: Edge kinds a splat is cut at: open (the surface ends) and creases (another
#: surface meets it there, a box's edge, a room's corner).
CLIP_KINDS = (OPEN, CREASE)

#: Per texture (held weakly) and kinds, the entries with clip planes and
#: their planes: the points of one texture are made again for every
#: placement, count and normal (the bench's sweeps, a renderer's options),
#: and the planes, a few per cent of the entries, cost a sheet
#: classification each time.
_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def entry_clips(
    texture: AnisoTexture, kinds: tuple[int, ...] = CLIP_KINDS, sheets: EntrySheets | None = None
) -> np.ndarray:
    """(E, 2, 5) float64: per entry of ``texture`` the half-spaces ``m . x <=
    o`` (rows ``(m, o, phi)``, world units; ``m = 0``: none) of the faces of
    its voxel where its surface sheet's edges are of a kind in ``kinds``
    (:func:`~aniso3d.rendering.sheet_edges.sheet_edges`), and a crease's
    partner's angle ``phi`` about the edge from the sheet (0 for an open
    edge; the sheet's normal is its entry's mean normal). Computed once per
    texture and ``kinds`` (a texture is not changed in place); ``sheets``:
    the texture's :func:`~aniso3d.rendering.volume.entry_sheets`, if at hand."""
    rows, planes = _clip_data(texture, tuple(int(k) for k in kinds), sheets)
    out = np.zeros((texture.n_entries, MAX_EDGES, 5))
    out[rows] = planes
    return out


def entry_sheet_flags(texture: AnisoTexture, sheets: EntrySheets | None = None) -> np.ndarray:
    """(E,) bool: the entries of ``texture`` that are surface sheets (fill
    their plane's section of the voxel, :data:`~aniso3d.rendering.volume.RUN_SHARE`),
    computed once per texture."""
    per_texture = _CACHE.setdefault(texture, {})
    if "sheet" not in per_texture:
        sheets = entry_sheets(texture) if sheets is None else sheets
        per_texture["sheet"] = sheets.share >= RUN_SHARE
    return per_texture["sheet"]


def _clip_data(texture: AnisoTexture, key: tuple[int, ...], sheets: EntrySheets | None):
    """The entries with clip planes of ``key``'s kinds and their planes, cached."""
    per_texture = _CACHE.setdefault(texture, {})
    if key not in per_texture:
        sheets = entry_sheets(texture) if sheets is None else sheets
        entry_sheet_flags(texture, sheets)
        planes = _entry_clips(texture, key, sheets)
        rows = np.flatnonzero(np.any(planes[..., :3] != 0, axis=(1, 2)))
        per_texture[key] = (rows, planes[rows])
    return per_texture[key]


def _entry_clips(texture: AnisoTexture, kinds: tuple[int, ...], sheets: EntrySheets) -> np.ndarray:
    """:func:`entry_clips`, computed."""
    E = texture.n_entries
    out = np.zeros((E, MAX_EDGES, 5))
    if E == 0:
        return out
    edges = sheet_edges(texture, sheets, sheets.share >= RUN_SHARE, plane_angle=True)
    cut = (edges.face >= 0) & np.isin(edges.kind, kinds)
    row, k = np.nonzero(cut)
    face = edges.face[row, k].astype(np.int64)
    axis, side = face // 2, face % 2
    cell = np.asarray(texture.coords, dtype=np.int64)[np.asarray(texture.entry_voxel, dtype=np.int64)[row]]
    h = float(texture.voxel_size)
    plane = np.asarray(texture.origin, dtype=np.float64)[axis] + (cell[np.arange(len(row)), axis] + side) * h
    sign = np.where(side == 1, 1.0, -1.0)  # side 1: x_a <= plane; side 0: x_a >= plane
    out[row, k, axis] = sign
    out[row, k, 3] = sign * plane
    out[row, k, 4] = np.where(edges.kind[row, k] == CREASE, edges.angle[row, k], 0.0)
    return out


def clipped(
    cloud: PointCloud,
    texture: AnisoTexture,
    voxels: np.ndarray | None = None,
    per_entry: int | np.ndarray = 1,
    kinds: tuple[int, ...] = CLIP_KINDS,
) -> PointCloud:
    """``cloud``, the points :func:`~aniso3d.build.texture.entry_points` made
    of ``texture`` with the same ``voxels`` and ``per_entry`` (in that
    order), with each point's :func:`entry_clips` planes."""
    planes = entry_clips(texture, kinds)
    normal = np.asarray(texture.entry_normal, dtype=np.float64)
    sheet = entry_sheet_flags(texture).copy()
    if voxels is not None:
        off = np.asarray(texture.entry_offsets, dtype=np.int64)
        v = np.asarray(voxels, dtype=np.int64)
        rows = ranges(off[v], off[v + 1])
        planes, normal, sheet = planes[rows], normal[rows], sheet[rows]
    if np.ndim(per_entry) == 0:
        counts = None if int(per_entry) == 1 else np.full(len(planes), int(per_entry))
    else:
        pe = np.asarray(per_entry, dtype=np.int64)
        counts = pe if voxels is None else pe[ranges(off[v], off[v + 1])]
    if counts is not None:
        planes, normal, sheet = (np.repeat(a, counts, axis=0) for a in (planes, normal, sheet))
    if len(planes) != len(cloud):
        raise InputError(f"{len(cloud)} points, but the texture's entries make {len(planes)}: not its points")
    # A point whose normal was turned against its entry's (a closed
    # surface's outside) sees the partner's angle mirrored.
    turned = np.einsum("ij,ij->i", normal, cloud.normals.astype(np.float64)) < 0
    planes[turned, :, 4] *= -1.0
    return PointCloud(cloud.positions, cloud.normals, cloud.areas, cloud.kd, cloud.ks, cloud.shininess,
                      name=cloud.name, coherence=cloud.coherence, one_sided=cloud.one_sided,
                      clips=planes, sheet=sheet)  # fmt: skip


def texture_points(
    texture: AnisoTexture, placement: str = "centroid", per_entry: int | np.ndarray = 1, normal: str = "mean"
) -> PointCloud:
    """``texture.to_points(placement, per_entry, normal)`` with each point's
    clip planes (:func:`clipped`): the points quality "high" draws best."""
    return clipped(texture.to_points(placement, per_entry, normal), texture, None, per_entry)
