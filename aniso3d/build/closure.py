"""Facets hidden behind their own voxel's closed surface.

A thin solid (a beam, a branch, a wall under a voxel thick, an insect's
leg) puts its front and its back into one voxel. The density sphere sums
both, ``D(w) = sum S |n . w|``, but seen along w the back lies behind the
front: the voxel covers that area once. Facets on a closed, consistently
wound surface (:meth:`aniso3d.build.mesh.Mesh.closed_faces`) bring their
vector area ``V = sum S n`` besides. Taking the solid's cut by the voxel's
faces as one flat piece (vector area ``-V``), its front and its back
project ``(D_c(w) + |V . w|) / 2`` each along w, and the voxel keeps one:

    H(w) = (D_c(w) - |V . w|) / 2,   D'(w) = D(w) - H(w),

with ``D_c(w) = sum_e |V_e . w|`` over the voxel's entries (the closed part
of each; a lower bound of the closed facets' own sum, exact for flat ones).
A slab, a beam or a tube under a voxel wide (V = 0) and a solid wholly
inside the voxel keep half; a flat piece of a solid's skin keeps all. At a
box's edge or corner the solid behind fills the voxel through cuts on
several faces, which the flat cut does not see: H takes out what the faces
hide of each other there. Counting those cuts as axis-aligned instead
(``sum_i |V_i| |w_i|`` for ``|V . w|``, which keeps a corner whole) measured
worse on every scene it changed (the lattice minified: volume -0.8 dB,
splats -1.7 dB; the cube's splats -1.4 to -2.0 dB; docs/coverage.md, "Thin
solids"). Open facets (leaves, blades, an open sheet's border) are not
touched: two leaves in a voxel each cover.

The entries' own areas, which splats and the volume's density reading draw,
are scaled by ``entry_cover``: 1 less half the share of the entry's area
that is closed times ``1 - |V| / A_c`` for its voxel, how much of the
voxel's closed area faces both ways (1 for a slab, 0 for a flat skin). That
is the mean of H over all directions (the mean of ``|n . w|`` is 1/2, of
``|V . w|`` is ``|V| / 2``): splats are drawn alike from every side.
"""

from __future__ import annotations

import numpy as np

#: Entries per batch of the (E, K) products of :func:`facet_density`.
DENSITY_BATCH = 1 << 18


def hidden_sides(
    density: np.ndarray,
    offsets: np.ndarray,
    directions: np.ndarray,
    area: np.ndarray,
    closed_area: np.ndarray,
    closed_normal: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``(density', entry_cover)`` of a texture from its density as
    registered (M, K), CSR ``offsets`` (M + 1,), sample ``directions`` (K, 3),
    entry areas (E,) and the closed part of each entry: its area (E,) and
    vector area (E, 3) (``sum S n`` over its pieces on closed surfaces). See
    the module."""
    out = np.maximum(density - hidden_density(offsets, directions, closed_normal), 0.0)
    return out, entry_cover(offsets, area, closed_area, closed_normal)


def hidden_density(offsets: np.ndarray, directions: np.ndarray, closed_normal: np.ndarray) -> np.ndarray:
    """(M, K) what each voxel's closed facets hide of themselves seen along
    each sample direction, ``(D_c - |V . N_p|) / 2`` (see the module)."""
    m = len(offsets) - 1
    closed_normal = np.asarray(closed_normal, dtype=np.float64)
    dirs = np.asarray(directions, dtype=np.float64)
    if not np.any(closed_normal):
        return np.zeros((m, len(dirs)))
    _, net = voxel_net(offsets, closed_normal)
    both = facet_density(np.ones(len(closed_normal)), closed_normal, offsets, dirs)  # D_c: sum_e |V_e . N_p|
    return np.maximum(both - np.abs(net @ dirs.T), 0.0) / 2.0


def entry_cover(
    offsets: np.ndarray, area: np.ndarray, closed_area: np.ndarray, closed_normal: np.ndarray
) -> np.ndarray:
    """(E,) float32 ``entry_cover``: 1 less half the entry's closed share
    times ``1 - |V| / A_c`` of its voxel (see the module)."""
    m = len(offsets) - 1
    area = np.asarray(area, dtype=np.float64)
    closed_area = np.asarray(closed_area, dtype=np.float64)
    if not np.any(closed_area > 0):
        return np.ones(len(area), dtype=np.float32)
    voxel, net = voxel_net(offsets, closed_normal)
    total = np.bincount(voxel, closed_area, minlength=m)
    with np.errstate(divide="ignore", invalid="ignore"):
        facing = np.where(total > 0, 1.0 - np.linalg.norm(net, axis=1) / total, 0.0)
        share = np.where(area > 0, np.clip(closed_area / area, 0.0, 1.0), 0.0)
    return (1.0 - 0.5 * np.clip(facing, 0.0, 1.0)[voxel] * share).astype(np.float32)


def voxel_net(offsets: np.ndarray, closed_normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each entry's voxel (E,) and each voxel's closed vector area ``V``
    (M, 3), the sum of its entries' ``closed_normal`` (E, 3)."""
    m = len(offsets) - 1
    voxel = np.repeat(np.arange(m), np.diff(offsets))
    closed_normal = np.asarray(closed_normal, dtype=np.float64)
    net = np.stack([np.bincount(voxel, closed_normal[:, i], minlength=m) for i in range(3)], axis=1)
    return voxel, net


def facet_density(area: np.ndarray, normal: np.ndarray, offsets: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """(M, K) float64 ``F_v(p) = sum_e A_e |n_e . N_p|`` over each voxel's
    entries: the density sphere as far as the entries' areas (E,) and mean
    normals (E, 3) know it (exact for flat entries, never above the true
    density). Summed in batches of :data:`DENSITY_BATCH` entries."""
    m, k = len(offsets) - 1, len(directions)
    out = np.zeros((m, k))
    voxel = np.repeat(np.arange(m), np.diff(offsets))
    dirs = np.asarray(directions, dtype=np.float64)
    for start in range(0, len(area), DENSITY_BATCH):
        stop = min(len(area), start + DENSITY_BATCH)
        part = np.abs(np.asarray(normal[start:stop], dtype=np.float64) @ dirs.T) * np.asarray(
            area[start:stop], dtype=np.float64
        )[:, None]
        _add_rows(out, voxel[start:stop], part)
    return out


def _add_rows(out: np.ndarray, rows: np.ndarray, values: np.ndarray) -> None:
    """``out[rows] += values`` for sorted ``rows`` with repeats (reduceat, not add.at)."""
    starts = np.flatnonzero(np.diff(rows, prepend=-1))
    out[rows[starts]] += np.add.reduceat(values, starts, axis=0)
