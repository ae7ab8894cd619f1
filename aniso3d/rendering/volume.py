"""Renderer (b): ray marching of the sparse anisotropic 3D texture (paper section 4 (b)).

One ray per pixel (``shaders/volume.frag``), from the near plane, clipped to
the grid's box. Rays start from a base point near the grid computed in
float64 (:func:`ray_base`), never from the eye's float32 position, so a
camera 1e7 radii away loses nothing. A two-level 3D DDA (Amanatides-Woo over
8^3 bricks, then over the voxels of occupied bricks) gives each voxel's exact
chord, so nothing depends on a step size and an empty brick costs one lookup.
The arrays live in 2D textures (texelFetch; llvmpipe reads a storage buffer
lane by lane), and each ray first finds its next occupied voxel, then
composites it, so that a SIMD batch of pixels composites together
(``march="skip"``); ``march="plain"`` keeps the first version for comparison
(docs/volume_speed.md). A scene's instances of one grid are marched in one
instanced draw call (:meth:`VolumeRenderer.draw_instanced`, ``INSTANCED`` in
volume.vert/.frag): each instance's screen box, with the camera moved into
its frame (:func:`instance_rays`).

A voxel seen along the unit ray direction w (METHOD.md "Reference
conventions"), with ``P(w) = |wx| + |wy| + |wz|`` and h the voxel edge:

- coverage over the mean chord ``h / P(w)`` is ``alpha = min(1, D_v(w) / P(w))``;
- over a chord c, ``opacity="exponential"`` (Beer-Lambert with
  ``sigma = -ln(1 - alpha) P / h``, alpha capped at :data:`ALPHA_MAX` so it
  stays finite) multiplies the transmittance T by ``exp(-sigma c)``:
  facets at independent random places. ``opacity="linear"`` subtracts
  ``min(D, P) c / h`` from T (never below 0): coverage adds up along the ray.
  Both give ``alpha`` over the mean chord. They differ across voxels, and
  neither is right for both kinds of object (docs/coverage.md): a plane's
  facets are perfectly correlated along a ray, so "exponential" lets
  ``(x / (1 + x))^(1 + x)`` of the background through an opaque plane, with
  ``x = (|wx| + |wy|) / |wz|`` in the plane's frame (0.29 at 60 degrees off
  its normal); "linear" adds up one crossing of a plane on average over the
  rays (Crofton), exactly only for a plane along the grid axes, and leaves
  stripes along the voxel edges of a tilted one; and it over-covers a cloud
  of leaves (+0.16 to +0.25 of alpha);
- ``opacity="planar"`` (default, :data:`DEFAULT_OPACITY`) reads each shading
  entry as a *sheet*, the plane through its facets' centroid normal to their
  mean normal (:func:`entry_sheets`, derived from what every texture
  stores), covering a fraction ``fill`` of the plane's section of the voxel.
  A ray counts a sheet where it crosses its plane inside the voxel (the
  signed distance changes sign between the ray's entry and exit): a plane
  cut into many voxels is crossed in exactly one of them, so it is opaque
  from every angle, and a leaf cut into several is counted once. What a
  sheet does not take (:func:`sheet_share`) is a cloud, Beer-Lambert on
  what the sheets leave of D; in a voxel the two coverages add (they are
  the same facets). An entry filling its section (a surface continuing into
  the neighbours) is a sheet at every scale; a partial one (a leaf, an
  edge) is crossed all or nothing, which one ray per pixel samples well only
  on voxels spanning a few pixels, so on smaller ones it fades into its cloud,
  the filtered average (:data:`SHEET_PIXELS`). A surface sheet's edge,
  crossed all or nothing by the centre ray, would alias like one polygon
  sample per pixel (its silhouette is the volume's whole error on a smooth
  closed object); so with ``edges="filtered"`` (default, :data:`EDGE_MODES`)
  the surface sheets a ray meets within :data:`RUN_GAP` of each other form a
  *run*, composited as one layer when the ray leaves it: covered whole where
  the centre ray crosses them on one side only (a surface cut by voxel faces,
  a corner), else (a near miss, or through both sides of a silhouette) by
  the share of the pixel's footprint whose rays cross them inside their
  voxels (:func:`crossing_fraction`), on the side that most do
  (:func:`run_coverage`; docs/coverage.md). Where a surface sheet ends on a
  voxel face (a wall's top on a grid plane) or creases into another (a
  box's edge), the share of the footprint across the edge is cut from it and
  carried by a halo in the voxel past the edge
  (:mod:`~aniso3d.rendering.sheet_edges`; the GPU grid has a margin of
  :data:`~aniso3d.rendering.sheet_edges.GRID_PAD` voxels for them), and a
  run's colour is its near side's where that covers the footprint
  (:func:`run_color`), and a closed surface's back keeps its coverage there
  but not its colour (:data:`RUN_BACK_MIN`). ``opacity="split"`` is the
  candidate that keeps the chord: sheets add up linearly along the ray (T =
  ``max(0, 1 - tau_s) exp(-tau_f)``); measured, it keeps the stripes of
  "linear" on tilted planes;
- colour: the shaded colours of its shading entries (``shade()`` of
  ``lighting.glsl``; the view vector is -w, exact for every point of the
  ray) weighted by ``A_e |n_e . w|``, ``n_e`` the entry's mean facet normal
  (``normal="mean"``) or its sample direction (``normal="sample"``, the
  paper's reading); each shaded colour is clamped to [0, 1] first, as the
  polygon renderer clamps each fragment. With ``shading="smooth"``
  (default, :data:`SHADING_MODES`) a run's surface sheets are shaded where
  the ray crosses them, by their linear models of normal and reflectance
  across their planes (:mod:`~aniso3d.rendering.sheet_slopes`), so that a
  smooth surface does not shade in steps a voxel wide.

Front to back, stopping when T falls below :data:`T_MIN` (the rest then
takes the colour seen so far: ``C / (1 - T)``, T = 0). The pixel is
``C + T * background`` (C premultiplied), alpha ``1 - T``, and the depth is
where ``1 - T`` first reaches 0.5 (1.0, the clear value, if it never does).

Reading the density sphere along w (``density=``); D is even, so a sample
N_p also stands at -N_p:

- ``"nearest"``: the sample nearest the line of w (what
  :meth:`AnisoTexture.coverage` reads);
- ``"kernel"``: the 4 samples nearest the line of w, weighted
  ``((R - a) / (R a))^2`` (Franke-Little; a the angle to w, R the angle of
  the 5th nearest): continuous in w and exact at the samples, but like any
  average of samples it cannot reach the peak ``|N . w| = 1`` of a plane
  seen head-on between samples (0.984 at K = 64);
- ``"facet"`` (default): the shading entries' own projected area
  ``F(w) = sum_e A_e |n_e . w|`` plus the kernel interpolation of the
  residual ``D_v(N_p) - F(N_p)``. Exact at the samples like "kernel", and
  exact in every direction when each entry's facets are flat (a plane
  head-on gives exactly 1). Relative L1 error against the exact
  ``sum S |N . w|`` at K = 64: sphere 0.125 / 0.093 / 0.0011, tree
  0.080 / 0.059 / 0.0002 (nearest / kernel / facet).

The 4 samples and weights depend only on w, so they are found once per ray.

:func:`march_ray_np` is the slow, obvious twin of one GPU pixel (a plain
voxel DDA over the whole grid, float64); the tests hold the two together.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import ClassVar

import moderngl
import numpy as np

from aniso3d.build.pyramid import Pyramid
from aniso3d.build.texture import QUANTISED, AnisoTexture
from aniso3d.errors import InputError, ResourceError
from aniso3d.grid import cell_coords, cell_keys
from aniso3d.rendering import sheet_line_halos as line_halo_module
from aniso3d.rendering.base import DrawOptions, number, option_parser
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.frame import DrawStats, FrameView
from aniso3d.rendering.lighting import Lighting, shade_np
from aniso3d.rendering.select import volume_level
from aniso3d.rendering.sheet_creases import (
    CREASE_GAP,
    CREASE_TILT,
    crease_factors,
    crease_partners,
    partner_codes,
)
from aniso3d.rendering.sheet_edges import (
    GRID_PAD,
    MAX_EDGES,
    NO_FACE,
    SheetEdges,
    edge_factors,
    edge_ramp,
    edge_words,
    sheet_edges,
)
from aniso3d.rendering.sheet_halfplanes import C_RANGE as HALF_C_RANGE
from aniso3d.rendering.sheet_halfplanes import (
    HALF_PIXELS,
    SheetHalfplanes,
    halfplane_ramp,
    halfplane_words,
    offset_code,
    sheet_halfplanes,
)
from aniso3d.rendering.sheet_line_halos import FACE_CUT_BIT, LineHalos, line_halos
from aniso3d.rendering.sheet_slopes import SheetSlopes, sheet_slopes, smoothed
from aniso3d.rendering.sheet_strips import STRIP_FOOT, STRIP_PIXELS, SheetStrips, sheet_strips, strip_cover, strip_words

#: Brick edge in voxels of the two-level index.
BRICK = 8
assert GRID_PAD % BRICK == 0, "the GPU grid's margin must keep the bricks aligned"
#: Rays cross this much (voxels) of the GPU grid's margin: its first layer,
#: where the halos lie (:mod:`~aniso3d.rendering.sheet_edges`); beyond, the
#: margin is empty, and a ray clipped to the texture's box widened by one
#: voxel does not march through it (crossing the whole margin cost up to 20%
#: of a frame where the object is small on screen).
CLIP_MARGIN = 1
assert 0 < CLIP_MARGIN <= GRID_PAD
#: Coverage cap: a voxel at full coverage lets 1e-6 through along its mean chord.
ALPHA_MAX = 1.0 - 1e-6
#: Early ray termination: stop when the transmittance falls below this, and
#: give what is left the colour seen so far (C / (1 - T), alpha 1): a pixel
#: changes by at most this much (0.005 = 1.3 / 255), an opaque surface not at all.
T_MIN = 5e-3
#: ... as first written, in the "plain" marching (:data:`MARCH_MODES`).
T_MIN_PLAIN = 1e-3
#: Density samples interpolated per ray direction.
NEIGHBOURS = 4

STEPS = ("dda",)
#: How the rays find the occupied voxels: "skip" (default) finds each ray's
#: next occupied voxel before compositing it, so that a batch of pixels
#: composites together; "plain" composites inside the DDA, as first written
#: (kept for comparison, demos/bench_volume_speed.py). The same image.
MARCH_MODES = ("skip", "plain")
#: Where the "skip" marching starts a ray (``start=``): "bricks" (default) at
#: the first occupied brick it enters, found by a pass that rasterises the
#: occupied bricks' boxes (widened by :data:`START_MARGIN`; volume_start.vert),
#: a pixel whose ray enters none being left as cleared; "box" at the grid's
#: box. The same image but for float rounding. "bricks" draws the pass only
#: where it pays, a voxel at the grid's front spanning :data:`START_PIXELS`
#: or more (docs/volume_speed.md), and never where a box reaches the eye's
#: plane, with instances or with :attr:`VolumeRenderer.blend_over`. Both
#: march only the pixels of the occupied bricks' screen box
#: (:func:`screen_box`); "frame" marches every pixel from the grid's box, as
#: first written (kept for comparison). The same image.
START_MODES = ("bricks", "box", "frame")
#: The start pass is drawn when a voxel at the grid's front spans at least
#: this many pixels: measured (CPU time, docs/volume_speed.md) it saves 1 to
#: 9% of the frame on the corpus at 8 px, 7% on the tree at 4 px; drawn only
#: in the screen box, it saves a median 2% at 2 px (-11% to +4% per scene),
#: breaks even at 1 px and costs up to 11% at 0.5 px
#: (demos/sweep_start_pixels.py).
START_PIXELS = 2.0
#: Voxels by which the start pass widens each brick's box: the pass keeps a
#: ray's entry into the widened box, at least half a voxel before its entry
#: into the brick, far more than float32 rounding of the rasterised depth.
START_MARGIN = 0.5
DENSITY_MODES = ("facet", "kernel", "nearest")
NORMAL_MODES = ("mean", "sample")
#: How the "planar" law shades a run's surface sheets: "smooth" (default) where
#: the ray crosses each, by its linear model of normal and reflectance across
#: its plane fitted to its neighbours (:mod:`~aniso3d.rendering.sheet_slopes`);
#: "flat" with its voxel's values (the first version; no moiré-free
#: shading, 12-20% faster on llvmpipe, docs/coverage.md).
SHADING_MODES = ("smooth", "flat")
OPACITY_MODES = ("exponential", "linear", "split", "planar")
#: The opacity law drawn when none is asked for (chosen by demos/bench_coverage.py).
DEFAULT_OPACITY = "planar"
#: Sheet crossing tolerance, voxel units along the sheet's normal: a ray that
#: crosses a sheet within it of a voxel face counts in both voxels, never in
#: neither (float32 puts the same point a few 1e-5 apart in the two voxels).
SHEET_EPS = 1e-3
#: Extra crossing tolerance of a sheet (times its share) in a texture whose
#: centroids and normals went through the compact encoding: without it, rays
#: slip between neighbouring voxels' rounded planes (up to -4.5 dB on a
#: sphere); chosen on the corpus with demos/bench_encoding.py (docs/encoding.md).
SHEET_QUANTISED = 0.02
#: The same for a texture of format version 3 or later (``meta["quantised"]``
#: 3): its centroids' depth along the normal is exact to h/1180 and its normal
#: lengths are stored finely near 1 (where :data:`SHEET_BEND` is steep). Runs
#: of surface sheets (:data:`RUN_SHARE`) close the gaps between neighbouring
#: planes by the footprint's shares, and widening them by 0.005 (chosen before
#: runs) lost the blob and the sphere more than it kept from the file's
#: rounding: none.
SHEET_QUANTISED_V3 = 0.0
#: Extra crossing tolerance per unit spread of an entry's normals (see
#: :class:`EntrySheets`).
SHEET_BEND = 1.0
#: ... fading out at this spread ``1 - |n|`` (normals some 0.3-0.5 rad apart):
#: beyond it the entry is facets of unrelated directions, not a bent surface,
#: and its plane is a fiction that no neighbour continues.
SHEET_BEND_MAX = 0.01
#: An entry is a sheet at every scale in proportion to how much of its
#: plane's section of the voxel it fills: ramp from 0 at the first value to 1
#: at the second (see :class:`EntrySheets`).
SHEET_FILL = (0.7, 0.95)
#: An entry facing against its voxel's largest entry counts with it as one
#: surface wound either way (:func:`entry_sheets`) when its centroid lies
#: within this (voxel units) of that entry's plane.
SHEET_FLIP_GAP = 0.05
#: Every entry is a sheet in proportion to its voxel's size in pixels: ramp
#: from 0 at the first value to 1 at the second (see :func:`sheet_share`).
SHEET_PIXELS = (1.0, 3.0)
#: How the "planar" law counts the crossings of surface sheets (entries whose
#: static share is whole, :data:`RUN_SHARE`): "filtered" (default) counts
#: them run by run over the pixel's footprint (:func:`run_coverage`), so
#: silhouettes are anti-aliased as a box-filtered pixel sees them; "sampled"
#: counts the centre ray's crossing alone, all or nothing, in its voxel (the
#: first version).
EDGE_MODES = ("filtered", "sampled")
#: A sheet is a surface sheet, counted in runs, when its static share
#: (:attr:`EntrySheets.share`) is at least this: it fills its plane's section
#: of the voxel (or its voxel's facets together do) and continues into the
#: neighbours. Partial sheets (leaves, edges) keep the per-voxel count.
RUN_SHARE = 0.999
#: A surface sheet only with its voxel's other facets (their net area fills
#: the section, :attr:`EntrySheets.share`, its own does not) is a **crease**
#: sheet where one of the voxel's entries turns from the largest by more than
#: this (|n . n'| below it, about 60 degrees): a box's or a CAD part's edge
#: crossing the voxel, where each face covers only its side of the edge.
#: Where it is a half-plane (sheet_halfplanes: its facets fill one side of a
#: line, here the edge) and the voxel spans :data:`HALF_PIXELS` or more, it
#: is drawn as that half-plane, not in a run: a run counts each face's sheet
#: over the whole section, past the edge, and outlines a box's silhouette a
#: voxel too wide (docs/coverage.md, "Creases inside voxels"). Smaller, it
#: stays in the runs, its line cutting it as an edge on a voxel face cuts a
#: sheet (render/sheet_creases.py).
SHEET_CREASE = 0.5
#: A crease sheet of a closed surface whose facets fit no half-plane but a
#: strip between two parallel lines (a narrow face between two creases: a
#: CAD part's bevel or fillet facet, a side of a beam about a voxel thick)
#: is drawn as that strip (render/sheet_strips.py), not counted over its
#: whole section in the runs (:func:`layout_sheets`; docs/coverage.md,
#: "Narrow faces between creases"). False: a surface sheet, as before.
CREASE_STRIPS = True
#: Strips carry their footprint into the voxels beside them through line
#: halos (render/sheet_line_halos.py), so that they can be drawn where a
#: voxel spans about a pixel (STRIP_PIXELS). False: none (as before them).
LINE_HALOS = True
#: ... but a closed surface's half-plane (a strip of one line: a face
#: ending at a crease, whose partner face covers the footprint past it)
#: has a halo only where its line lies within this (voxel units, in the
#: plane) of the halo's voxel's q0: farther ones added 0.003-0.004 to a
#: turned cube's outline alpha error at 1.5 pixels a voxel and cost the
#: duck, the monkey and quadknot 0.04-0.08 dB minified, for nothing on
#: the lattice (docs/coverage.md, "Halos of lines inside voxels").
ONE_LINE_REACH = 0.875
#: Entry word 11's bit marking a halo of a crease sheet's half-plane
#: (volume.frag: not drawn where the half-plane is).
CREASE_BIT = 27
#: A closed surface's back in a run keeps its coverage (a silhouette's far
#: side is part of its filter) but shows as little of its colour as the
#: planar law's ``vis`` leaves of it, and at least this share: where a run's
#: side mixes a solid's front and back (a crease turning away from the
#: eye), the front's colour shows, and a far side of hidden backs takes the
#: near side's (:func:`run_color`); a run whose near side holds thick
#: backs alone, after something was drawn, shows the colour seen so far
#: (:func:`hidden_run`). 1 draws the backs' colours as before
#: (the unlit underside of a box drew a dark line along its outline;
#: docs/coverage.md, "A solid's back in its outline").
RUN_BACK_MIN = 1e-3
#: A run sums its closed backs' bands and fills apart from its other
#: sheets', per side, and counts the larger (:func:`run_sides`): a solid's
#: back lies behind its own front, so where a CAD part's beveled edge is on
#: the outline, the face seen and the face turned away, each filling part of
#: the bevel's voxel, covered the sum of their fills and drew the outline
#: too wide. False: summed with the rest, as before (docs/coverage.md, "A
#: solid's back counted once").
RUN_BACK_APART = True
#: What a voxel adds outside the open run (its partial sheets and cloud)
#: where the run's centre ray has crossed whole sheets on its entering side
#: only, before that voxel's crossings, lies behind the run's surface: it is
#: composited as a layer behind the run when the run closes. It was
#: composited at once, in front of the run: where two solids touch (a
#: building's storeys and parts, an assembly), the face between them, a
#: partial sheet in the wall's or roof's voxels, drew a line across the
#: surface (bright or dark by its shading). False: at once, as before.
RUN_DEFER = True
#: Within a voxel, a run's sheet that the centre ray crosses more than this
#: (grid units) after it crosses a whole surface sheet of the voxel (fill at
#: least :data:`RUN_FRONT_FILL`, not grazing, no edge or half-plane of its
#: own) is hidden by that sheet: it keeps its coverage but adds nothing to
#: the run's colour. A run weighs its sheets by what it left uncovered
#: before their voxel, so two surfaces in one voxel (a wall and the face
#: between two touching solids behind it, a concave corner's wall and floor)
#: mixed their colours. None: as before.
RUN_FRONT_GAP: float | None = 1e-3
RUN_FRONT_FILL = 0.99
#: A run closes when the ray has gone this far (grid units) past its last
#: voxel: a surface cut by voxel faces, or a silhouette's near and far sides,
#: lie in voxels a cell's diagonal apart at most along the ray.
RUN_GAP = 1.0
#: The side of a surface sheet in a run: whether the ray meets it as it
#: meets the run's first sheet or turned back. For a sheet whose normal is
#: within 60 degrees of the first's, or of its opposite (|cos| at least
#: this), the side is ``sign((n . w)(n . n_0)(n_0 . w))``, the same for a
#: sheet and its flipped twin (a mesh's winding does not matter), opposite
#: for the near and far sides of a silhouette; one across it (the two faces
#: of a corner or of a box's edge) is on the first side.
RUN_PARALLEL = 0.5
#: A run whose centre ray crosses whole fills on its entering side only, one
#: of them at ``|n . w|`` at least this, closes at once: its far side could only
#: follow within :data:`RUN_GAP` through an object under a voxel thick
#: (a surface of curvature radius R voxels is crossed twice within a voxel
#: or two only at ``|n . w|`` below about 1 / R), so the ray stops there.
RUN_STEEP = 0.5
#: A centre ray crossing a surface sheet at ``|n . w|`` below this grazes
#: it, as at a closed surface's tangent, and the crossing counts on both
#: sides of the run (so the footprint's shares decide, see
#: :func:`run_coverage`). There ``n . w`` is near 0 and its sign, the side,
#: falls either way as a file rounds the normal; a sheet seen at 88 degrees
#: off its normal is still crossed whole. Chosen on the corpus, the cube and
#: the sphere (0.06 took in the cube's faces seen at 86 degrees).
RUN_GRAZE = 0.03
#: The "planar" law's share of a closed surface's back that is hidden:
#: entries on closed surfaces (:meth:`~aniso3d.build.mesh.Mesh.closed_sides`)
#: whose outward normal faces away from the eye lie behind the same solid's
#: front along every ray, which covers the footprint already. Their sheets'
#: fills and colour weights keep ``1 - BACK_HIDE`` of themselves, and the
#: density ``max(0, V . w)`` of what the voxel's closed vector area V adds
#: along the ray (the texture's own law, aniso3d.build.closure, can hide a
#: back only where the front lies in the same voxel: a beam 0.8 voxel wide
#: puts them in two voxels most of the way). Not all of it: the front of a
#: thin solid is drawn spread over its voxels' sections and chords, thinner
#: than it is, and its back covers where the front leaves a gap (hiding
#: all of it cost the corpus lattice minified 0.5 dB against none, 0.75 gained 0.5;
#: ``demos/bench_thin_solids.py --backs``, docs/coverage.md). Surface sheets
#: (:data:`RUN_SHARE`) keep both sides: a silhouette's far side is part of
#: its filter, and a tangent's planes may be crossed on the far side only.
BACK_HIDE = 0.75
#: ... but where a closed entry's solid is thick, its back is hidden whole
#: (the share scaled by 1 / BACK_HIDE, at most 1): no closed surface facing
#: the other way in its voxel or the cells half a voxel to THICK_STEPS voxels
#: into the solid along its inward normal, in half-voxel steps (a closed
#: vector area of at least THICK_OPPOSITE voxel^2 against it). A beam a voxel or two wide keeps
#: BACK_HIDE; a CAD part's or a building's back, many voxels behind its
#: front, let a quarter of itself through at the outline, which drew
#: outlines too wide (a turned cube's outline alpha 0.11 over the
#: polygons', docs/coverage.md "Thick backs"; :func:`thick_backs`).
THICK_STEPS = 3
THICK_OPPOSITE = 0.03
#: A thick entry's sigma is stored moved out by this (float16 word 15: its
#: magnitude is at most 2 otherwise), volume.frag moves it back.
THICK_CODE = 4.0
#: uint32 words per shading entry on the GPU (four uvec4; see volume.frag).
ENTRY_WORDS = 16
#: Width in texels of the 2D textures the arrays of :func:`pack_volume` are
#: uploaded as (a power of two: the shader splits an index with a mask and a shift).
TEX_WIDTH = 4096
#: Each array's texture: its sampler in volume.frag, the dtype and components
#: of a texel, and what pads an empty array (-1: "no brick", "no voxel").
_TEXTURES = {
    "top": ("t_top", "i4", 1, -1),
    "pool": ("t_pool", "i4", 1, -1),
    "offsets": ("t_offs", "u4", 1, 0),
    "density": ("t_dens", "f2", 1, 0),
    "entries": ("t_ent", "u4", 4, 0),
    "directions": ("t_dirs", "f4", 4, 0),
}
#: OpenGL version the shaders need (shader storage buffers).
REQUIRE_GL = 430
_BIG = 1e30


# ------------------------------------------------------------------ the reading


def direction_weights(
    directions: np.ndarray, w: np.ndarray, mode: str = "facet"
) -> tuple[np.ndarray, np.ndarray]:
    """Sample indices (4,) and weights (4,) that interpolate an even function on
    the sphere along the unit vector ``w`` from its values at ``directions``
    (K, 3). Mirrors ``neighbours()`` in volume.frag; "nearest" puts all the
    weight on the first index."""
    dirs = np.asarray(directions, dtype=np.float64)
    K = len(dirs)
    c = np.abs(dirs @ np.asarray(w, dtype=np.float64))
    order = np.argsort(-c, kind="stable")
    idx = np.zeros(NEIGHBOURS, dtype=np.int64)
    k = min(NEIGHBOURS, K)
    idx[:k] = order[:k]
    ang = np.arccos(np.clip(c[order[: k + 1]], 0.0, 1.0))
    radius = ang[NEIGHBOURS] if K > NEIGHBOURS else 2.0
    wt = np.zeros(NEIGHBOURS)
    a = np.maximum(ang[:k], 1e-6)
    wt[:k] = np.where(a < radius, ((radius - a) / (radius * a)) ** 2, 0.0)
    s = wt.sum()
    if mode == "nearest" or ang[0] <= 1e-6 or not (0.0 < s < np.inf):
        wt = np.array([1.0, 0.0, 0.0, 0.0])
    else:
        wt /= s
    return idx, wt


def _entry_rows(texture: AnisoTexture, voxels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Entry indices of ``voxels`` and, for each, its position in ``voxels``."""
    off = np.asarray(texture.entry_offsets)
    start, stop = off[voxels], off[voxels + 1]
    counts = stop - start
    owner = np.repeat(np.arange(len(voxels)), counts)
    first = np.repeat(start - np.concatenate([[0], np.cumsum(counts)[:-1]]), counts)
    return first + np.arange(int(counts.sum())), owner


def density_along(
    texture: AnisoTexture, w: np.ndarray, mode: str = "facet", voxels: np.ndarray | None = None,
    stored: bool = False,
) -> np.ndarray:  # fmt: skip
    """(V,) projected facet area ``D_v(w)`` (units of h^2) of ``voxels`` (default:
    all) seen along the unit vector ``w``, read from the density sphere as
    ``mode`` says (see the module docstring). Never negative. ``stored``
    reads the samples as the GPU stores them (float16), as the NumPy ray does:
    what the sheets leave of D is a small difference where they take most."""
    _check_choice(mode, DENSITY_MODES, "density reading")
    w = np.asarray(w, dtype=np.float64)
    w = w / np.linalg.norm(w)
    voxels = np.arange(texture.n_voxels) if voxels is None else np.asarray(voxels, dtype=np.int64)
    idx, wt = direction_weights(texture.directions, w, mode)
    dens = np.asarray(texture.density)[voxels][:, idx]
    if stored:
        dens = np.minimum(dens, 6e4).astype(np.float16).astype(np.float64)
    if mode != "facet":
        return np.maximum(dens @ wt, 0.0)
    rows, owner = _entry_rows(texture, voxels)
    n = np.asarray(texture.entry_normal, dtype=np.float64)[rows]
    area = covered_area(texture, rows)
    base_w = np.bincount(owner, area * np.abs(n @ w), minlength=len(voxels))
    nb = np.abs(n @ texture.directions[idx].T) * area[:, None]
    base_nb = np.stack(
        [np.bincount(owner, nb[:, j], minlength=len(voxels)) for j in range(NEIGHBOURS)], 1
    )
    return np.maximum(base_w + (dens - base_nb) @ wt, 0.0)


def voxel_colors(
    texture: AnisoTexture, w: np.ndarray, lighting: Lighting, normal: str = "mean",
    voxels: np.ndarray | None = None,
) -> np.ndarray:  # fmt: skip
    """(V, 3) colour of ``voxels`` seen along the unit ray direction ``w``: the
    shaded entries (each clamped to [0, 1]) weighted by ``A |n . w|``."""
    _check_choice(normal, NORMAL_MODES, "normal")
    w = np.asarray(w, dtype=np.float64)
    w = w / np.linalg.norm(w)
    voxels = np.arange(texture.n_voxels) if voxels is None else np.asarray(voxels, dtype=np.int64)
    rows, owner = _entry_rows(texture, voxels)
    c, n = _entry_colors(texture, w, lighting, normal, rows)
    area = covered_area(texture, rows)
    return _weighted_colors(owner, len(voxels), c, area * np.abs(n @ w), area)


def _entry_colors(
    texture: AnisoTexture, w: np.ndarray, lighting: Lighting, normal: str, rows: np.ndarray,
    at: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """(E', 3) shaded colours, clamped to [0, 1], of entries ``rows`` seen along
    the unit vector ``w``, and (E', 3) the normals they were shaded with.
    ``at``: their (mean) normals and reflectances where a sheet's linear
    model puts them (:func:`~aniso3d.rendering.sheet_slopes.smoothed`)
    instead of the stored ones. The Phong exponent as the GPU stores it
    (float16)."""
    mean = np.asarray(texture.entry_normal, dtype=np.float64)[rows]
    kd = texture.entry_kd[rows]
    if at is not None:
        mean, kd = at
    n = mean if normal == "mean" else texture.directions[texture.entry_direction[rows]]
    shininess = np.minimum(np.asarray(texture.entry_shininess, np.float64)[rows], 6e4).astype(np.float16)
    c = shade_np(
        n,
        -w,
        kd,
        texture.entry_ks[rows],
        shininess.astype(np.float64),
        lighting,
        np.linalg.norm(mean, axis=1),  # the facets' coherence
    )
    return np.clip(c, 0.0, 1.0), n


def _weighted_colors(
    owner: np.ndarray, V: int, c: np.ndarray, wgt: np.ndarray, area: np.ndarray
) -> np.ndarray:
    """(V, 3) per-voxel mean of entry colours ``c`` weighted by ``wgt``, or by
    ``area`` where the weights vanish (a voxel seen edge-on); 0 if both do."""
    sum_w = np.bincount(owner, wgt, minlength=V)
    sum_a = np.bincount(owner, area, minlength=V)
    col_w = np.stack([np.bincount(owner, wgt * c[:, i], minlength=V) for i in range(3)], 1)
    col_a = np.stack([np.bincount(owner, area * c[:, i], minlength=V) for i in range(3)], 1)
    use_w = sum_w > 1e-7 * sum_a
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(use_w[:, None], col_w / sum_w[:, None], col_a / sum_a[:, None])
    return np.where(np.isfinite(out), out, 0.0)


# ------------------------------------------------------------- the sheets

def plane_section_area(normal: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """(N,) area of the unit cube's section ``{x in [0, 1]^3 : n . x = d}`` by
    the planes of unit normals ``normal`` (N, 3) and offsets ``offset`` (N,),
    in cube faces (h^2); 0 where a plane misses the cube.

    For U uniform in the cube, ``n . U`` has density ``area / |n|`` at d: the
    sum of three uniforms on ``[0, |n_i|]`` (shifted by the negative
    components). The two narrower ones sum to a trapezoid (CDF F, closed
    form); the widest, c >= 1/sqrt(3), spreads it: ``(F(y) - F(y - c)) / c``,
    never a division by a small width. A plane on a face counts it whole."""
    n = np.asarray(normal, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(offset, dtype=np.float64).reshape(-1)
    a, b, c = np.sort(np.abs(n), axis=1).T
    y = d - np.minimum(n, 0.0).sum(axis=1)

    def trapezoid_cdf(x: np.ndarray) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            rise = x * x / (2.0 * a * b)
            flat = (x - 0.5 * a) / b
            fall = 1.0 - (a + b - x) ** 2 / (2.0 * a * b)
        return np.where(x <= 0, 0.0, np.where(x < a, rise, np.where(x < b, flat, np.where(x < a + b, fall, 1.0))))

    with np.errstate(divide="ignore", invalid="ignore"):
        area = (trapezoid_cdf(y) - trapezoid_cdf(y - c)) / c
    # Along an axis the two narrow widths are 0: a point mass, the face whole.
    on_axis = a + b == 0
    return np.where(on_axis, ((y >= 0) & (y <= c)).astype(np.float64), area)


def _ramp(x: np.ndarray, ends: tuple[float, float]) -> np.ndarray:
    """0 below ``ends[0]``, 1 above ``ends[1]``, linear between."""
    lo, hi = ends
    return np.clip((np.asarray(x, dtype=np.float64) - lo) / max(hi - lo, 1e-9), 0.0, 1.0)


def sheet_share(static: np.ndarray, voxel_pixels: np.ndarray) -> np.ndarray:
    """Share in [0, 1] of an entry's sheet area drawn as a sheet, from its
    static share (:attr:`EntrySheets.share`) and the size of its voxel in
    pixels where the ray crosses it (inf: a point sample). Mirrors volume.frag.

    A sheet that fills its voxel's section continues into its neighbours
    and is crossed exactly once by any ray: a sheet at every scale. A partial
    one (a leaf, a surface's edge) is crossed or missed, all or nothing,
    which a single ray per pixel samples well only where the voxel spans
    several pixels (:data:`SHEET_PIXELS`); smaller, its cloud (coverage
    spread through the voxel) is the filtered average."""
    zoom = _ramp(voxel_pixels, SHEET_PIXELS)
    return 1.0 - (1.0 - np.asarray(static, dtype=np.float64)) * (1.0 - zoom)


@dataclass(frozen=True)
class EntrySheets:
    """Each shading entry of a texture read as a sheet: the plane through its
    facets' centroid normal to their mean normal, in voxel-local grid
    coordinates (the voxel is the unit cube). All (E,) but ``normal`` (E, 3).

    Attributes:
        normal: unit normal (0 where the facets have no mean direction).
        offset: the plane ``normal . x = offset``.
        section: area of the plane's section of the voxel, h^2.
        area: facet area that can be drawn as a sheet, ``min(A, section)``
            (h^2); the rest of the entry's area A is always cloud.
        fill: ``area / section``, the coverage of the section, in [0, 1]
            (to float16, as the GPU stores it).
        crease: bool, a crease sheet (:data:`SHEET_CREASE`): a surface
            sheet by its voxel's facets together, not by its own, in a voxel
            whose entries meet at a crease.
        share: static share of ``area`` drawn as a sheet at every scale:
            :data:`SHEET_FILL` ramp of how well the entry, or its voxel's
            facets together (a bent surface whose facets fall on several
            sample directions), fill their plane's section (to float16).
        slack: crossing tolerance, voxel units along the normal:
            :data:`SHEET_EPS` plus :data:`SHEET_BEND` times the normals'
            spread ``sqrt(1 - |n|)`` (fading out by :data:`SHEET_BEND_MAX`):
            a bent surface's planes step where they meet at a voxel face, by
            about its bend over the voxel, and a ray must not slip through.
    """

    normal: np.ndarray
    offset: np.ndarray
    section: np.ndarray
    area: np.ndarray
    fill: np.ndarray
    share: np.ndarray
    slack: np.ndarray
    crease: np.ndarray

    @property
    def surface(self) -> np.ndarray:
        """(E,) bool: the surface sheets (:data:`RUN_SHARE`), crease sheets
        included."""
        return self.share >= RUN_SHARE

    @property
    def plain_surface(self) -> np.ndarray:
        """(E,) bool: the surface sheets that are no crease sheet (a crease
        sheet may also be a half-plane)."""
        return (self.share >= RUN_SHARE) & ~self.crease


def _sections(normal: np.ndarray, local: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit normals, offsets and section areas of the planes through the
    voxel-local points ``local`` (N, 3) normal to ``normal`` (N, 3, any
    length; 0: no plane, section 0)."""
    # Sums over the 3 columns written out, in the order sum(axis=1) adds
    # them (the same values, without a reduction's overhead per row).
    normal = np.asarray(normal, dtype=np.float64)
    sq = normal * normal
    length = np.sqrt(sq[:, 0] + sq[:, 1] + sq[:, 2])
    ok = length > 1e-6
    nh = np.where(ok[:, None], normal / np.where(ok, length, 1.0)[:, None], 0.0)
    # The outer cells are unbounded (clip.py): keep the plane on the cube.
    neg, pos, mag = np.minimum(nh, 0), np.maximum(nh, 0), np.abs(nh)
    lo, hi = neg[:, 0] + neg[:, 1] + neg[:, 2], pos[:, 0] + pos[:, 1] + pos[:, 2]
    dots = nh * local
    d = np.clip(dots[:, 0] + dots[:, 1] + dots[:, 2], lo, hi)
    # A plane on a voxel face (a box's side on a grid plane) keeps the whole
    # face as its section however its normal and centroid were rounded: the
    # section of a plane that tilts by at most SHEET_EPS across the voxel is
    # taken SHEET_EPS inside, where rays count its crossings too. Without it
    # a tilt of 1e-6 halves it (the side tilted out is lost).
    flat = mag[:, 0] + mag[:, 1] + mag[:, 2] - np.maximum(np.maximum(mag[:, 0], mag[:, 1]), mag[:, 2]) <= SHEET_EPS
    inner = np.where(flat, np.clip(d, lo + SHEET_EPS, hi - SHEET_EPS), d)
    return nh, d, np.where(ok, plane_section_area(nh, inner), 0.0)


def closed_sign(texture: AnisoTexture, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
    """(E,) float64 ``sigma`` of the entries ``rows``, as the GPU stores it
    (float16): the entry's closed vector area, turned outwards
    (``entry_closed_normal``), is about ``sigma`` times its covered area
    (:func:`covered_area`) times its mean normal n (exactly, for an entry
    wholly on closed surfaces: ``sigma = +-1 / cover``, the sign of the
    winding): ``(V_e . n) / (A_cov |n|^2)``, in [-2, 2]. 0 for open entries. A
    texture loaded from a file keeps no closed sums, but (format version 6)
    each entry's side: ``side / cover`` for the entries wholly on closed
    surfaces (0 for those partly on one, and in older files). Read by the
    "planar" law (:data:`BACK_HIDE`)."""
    n = np.asarray(texture.entry_normal, np.float64)[rows]
    if texture.entry_closed_normal is None:
        side = np.zeros(len(n)) if texture.entry_side is None else np.asarray(texture.entry_side, np.float64)[rows]
        cover = np.asarray(texture.entry_cover, np.float64)[rows]
        with np.errstate(divide="ignore", invalid="ignore"):
            sig = np.where(cover > 0, side / cover, 0.0)
        return np.clip(sig, -2.0, 2.0).astype(np.float16).astype(np.float64)
    den = covered_area(texture, rows) * np.einsum("ij,ij->i", n, n)
    num = np.einsum("ij,ij->i", np.asarray(texture.entry_closed_normal, np.float64)[rows], n)
    with np.errstate(divide="ignore", invalid="ignore"):
        sig = np.where(den > 1e-12, num / den, 0.0)
    return np.clip(sig, -2.0, 2.0).astype(np.float16).astype(np.float64)


def thick_backs(texture: AnisoTexture) -> np.ndarray:
    """(E,) bool: the closed entries whose solid is thick behind them (see
    :data:`THICK_STEPS`): no closed vector area of :data:`THICK_OPPOSITE`
    or more facing against their outward normal in their voxel (their own
    left out) nor in the cells half a voxel to ``THICK_STEPS`` voxels along
    their inward normal, in half-voxel steps. Vectorised (one look-up per
    step)."""
    E = texture.n_entries
    sigma = closed_sign(texture)
    rows = np.flatnonzero(sigma != 0.0)
    out = np.zeros(E, dtype=bool)
    if len(rows) == 0:
        return out
    owner = np.asarray(texture.entry_voxel, dtype=np.int64)
    n = np.asarray(texture.entry_normal, np.float64)
    vec = (covered_area(texture) * sigma)[:, None] * n  # each entry's closed outward vector area
    V = np.stack([np.bincount(owner, vec[:, i], minlength=texture.n_voxels) for i in range(3)], axis=1)
    out_n = np.sign(sigma[rows])[:, None] * n[rows]
    out_n /= np.maximum(np.linalg.norm(out_n, axis=1, keepdims=True), 1e-12)
    coords = np.asarray(texture.coords, dtype=np.int64)
    shape = np.asarray(texture.shape, dtype=np.int64)
    keys = cell_keys(coords, shape)
    order = np.argsort(keys, kind="stable")
    thin = np.einsum("ek,ek->e", V[owner[rows]] - vec[rows], out_n) <= -THICK_OPPOSITE
    for k in np.arange(1, 2 * THICK_STEPS + 1) / 2:
        cell = coords[owner[rows]] + np.rint(-k * out_n).astype(np.int64)
        inside = np.all((cell >= 0) & (cell < shape), axis=1)
        key = np.where(inside, cell_keys(np.where(inside[:, None], cell, 0), shape), -1)
        pos = np.minimum(np.searchsorted(keys[order], key), len(keys) - 1)
        found = inside & (keys[order][pos] == key)
        at = order[pos[found]]
        thin[found] |= np.einsum("ek,ek->e", V[at], out_n[found]) <= -THICK_OPPOSITE
    out[rows] = ~thin
    return out


def stored_sign(sigma: np.ndarray, thick: np.ndarray) -> np.ndarray:
    """(E,) ``sigma`` as entry word 15 stores it (float16): a thick entry's
    moved out by :data:`THICK_CODE`."""
    moved = np.where(thick, np.sign(sigma) * (np.abs(sigma) + THICK_CODE), sigma)
    return moved.astype(np.float16).astype(np.float64)


def back_terms(
    texture: AnisoTexture, rows: np.ndarray, owner: np.ndarray, n_voxels: int, w: np.ndarray, hide: float,
    thick: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """What the "planar" law keeps of the entries ``rows`` (of voxels
    ``owner``, in ``0..n_voxels``) seen along the unit ``w`` (:data:`BACK_HIDE`):
    (E,) ``vis``, 1 less the entry's share hidden (``hide``; a thick
    entry's, ``thick`` (E,) of the whole texture (:func:`thick_backs`),
    ``min(1, hide / BACK_HIDE)``) times the closed share ``min(|sigma|, 1)``
    where the closed part faces away from the eye (``sigma n . w > 0``),
    else 1; and (V,) what to take from each voxel's density, ``max(0,
    sum share A_cov sigma n . w)``. Mirrors composite() in volume.frag."""
    sigma, nwo = _closed_facing(texture, rows, w, thick)
    if thick is not None:
        share = np.where(thick[rows], min(1.0, hide / BACK_HIDE), hide)
    else:
        share = np.full(len(sigma), float(hide))
    vis = np.where(nwo > 0.0, 1.0 - share * np.minimum(np.abs(sigma), 1.0), 1.0)
    v_dot_w = np.bincount(owner, share * covered_area(texture, rows) * nwo, minlength=n_voxels)
    return vis, np.maximum(v_dot_w, 0.0)


def back_share(texture: AnisoTexture, rows: np.ndarray, w: np.ndarray, thick: np.ndarray | None = None) -> np.ndarray:
    """(E,) the share of each entry ``rows`` that is a closed surface's
    back seen along the unit ``w``: its closed share ``min(|sigma|, 1)``
    where the closed part faces away from the eye, else 0. A run sums its
    sheets' backs apart from the rest and counts the larger (:func:`run_sides`).
    Mirrors composite() in volume.frag."""
    sigma, nwo = _closed_facing(texture, rows, w, thick)
    return np.where(RUN_BACK_APART & (nwo > 0.0), np.minimum(np.abs(sigma), 1.0), 0.0)


def _closed_facing(
    texture: AnisoTexture, rows: np.ndarray, w: np.ndarray, thick: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """(E,) the entries' closed signs ``sigma`` as the GPU reads them back
    (a thick entry's stored moved out by THICK_CODE, :func:`stored_sign`)
    and ``sigma n . w``, positive where the closed part faces away from
    the eye: what :func:`back_terms` and :func:`back_share` read."""
    sigma = closed_sign(texture, rows)
    if thick is not None:
        t = thick[rows]
        sigma = np.where(t, np.sign(sigma) * (np.abs(stored_sign(sigma, t)) - THICK_CODE), sigma)
    n = np.asarray(texture.entry_normal, np.float32)[rows].astype(np.float64)
    return sigma, sigma * (n @ w)


def covered_area(texture: AnisoTexture, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
    """Entry areas (h^2) as the volume draws them: each times its
    ``entry_cover``, so that the back of a thin solid, which its front
    hides inside the voxel, is not counted twice (aniso3d.build.closure)."""
    return np.asarray(texture.entry_area, dtype=np.float64)[rows] * np.asarray(texture.entry_cover, np.float64)[rows]


def _largest_per_group(value: np.ndarray, group: np.ndarray) -> np.ndarray:
    """Index of the largest ``value`` of each group in ``group`` (both (N,)),
    the last such index on a tie, groups in ascending order: the last of
    each group in ``np.lexsort((value, group))``, without the sort where
    ``group`` is already ascending (a texture's entries are grouped by voxel)."""
    group = np.asarray(group)
    if len(group) == 0:
        return np.zeros(0, dtype=np.int64)
    if np.any(group[1:] < group[:-1]):
        order = np.lexsort((value, group))
        return order[np.r_[group[order][1:] != group[order][:-1], True]]
    start = np.flatnonzero(np.r_[True, group[1:] != group[:-1]])
    top = np.maximum.reduceat(value, start)
    size = np.diff(np.r_[start, len(group)])
    cand = np.flatnonzero(value == np.repeat(top, size))
    return cand[np.r_[group[cand][1:] != group[cand][:-1], True]]


def entry_sheets(texture: AnisoTexture, voxels: np.ndarray | None = None) -> EntrySheets:
    """The sheets of ``texture``'s entries (see :class:`EntrySheets`), derived
    from what every texture stores (entry area, mean normal, centroid), so
    old files and every pyramid level have them. With ``voxels``, only their
    entries, voxel by voxel in the given order."""
    if voxels is None:
        rows, owner = np.arange(texture.n_entries), texture.entry_voxel
        V = texture.n_voxels
    else:
        voxels = np.asarray(voxels, dtype=np.int64)
        rows, owner = _entry_rows(texture, voxels)
        V = len(voxels)
    n = np.asarray(texture.entry_normal, dtype=np.float64)[rows]
    # The facets' own area, not what they cover (covered_area): the cover is
    # a mean over directions, which would thin a box's edges seen from where
    # both faces show (the cube's FLIP rose close up); a thin
    # solid's back is taken out of its density instead (aniso3d.build.closure).
    area = np.asarray(texture.entry_area, dtype=np.float64)[rows]
    local = texture.local_centroids(rows)
    nh, d, section = _sections(n, local)
    # The voxel's facets together: net area along their mean normal over the
    # section of the plane through their centroid. A surface whose facets are
    # wound either way (a scan, a careless export) is filed under opposite
    # sample directions, and its halves must not cancel: an entry facing
    # against the voxel's largest entry and lying in its plane (within
    # SHEET_FLIP_GAP) is turned to its side first; the two faces of a thin
    # slab, a voxel's width apart, and leaves at random are left as they are.
    big = _largest_per_group(area, owner)
    ref_n, ref_c = np.zeros((V, 3)), np.zeros((V, 3))
    ref_n[owner[big]], ref_c[owner[big]] = nh[big], local[big]
    facing = np.einsum("ek,ek->e", nh, ref_n[owner])
    apart = np.abs(np.einsum("ek,ek->e", local - ref_c[owner], ref_n[owner]))
    turned = np.where((facing < -0.5) & (apart <= SHEET_FLIP_GAP), -1.0, 1.0)[:, None] * n
    net = np.stack([np.bincount(owner, area * turned[:, i], minlength=V) for i in range(3)], axis=1)
    total = np.maximum(np.bincount(owner, area, minlength=V), 1e-300)
    centre = np.stack([np.bincount(owner, area * local[:, i], minlength=V) for i in range(3)], 1) / total[:, None]
    _, _, voxel_section = _sections(net, centre)
    with np.errstate(divide="ignore", invalid="ignore"):
        own = np.where(section > 1e-9, area / section, 0.0)
        together = np.where(voxel_section > 1e-9, np.linalg.norm(net, axis=1) / voxel_section, 0.0)
        sheet_area = np.where(section > 1e-9, np.minimum(area, section), 0.0)
        fill = np.where(section > 1e-9, sheet_area / section, 0.0)
    share = _ramp(np.maximum(own, together[owner]), SHEET_FILL)
    # Crease sheets: a surface sheet only together, in a voxel where an
    # entry turns from the largest by more than SHEET_CREASE.
    turned_away = np.zeros(V, dtype=bool)
    np.logical_or.at(turned_away, owner, np.abs(facing) < SHEET_CREASE)
    crease = turned_away[owner] & (share >= RUN_SHARE) & (_ramp(own, SHEET_FILL) < RUN_SHARE)
    spread = np.clip(1.0 - np.linalg.norm(n, axis=1), 0.0, 1.0)
    slack = SHEET_EPS + SHEET_BEND * np.sqrt(spread) * np.clip(1.0 - spread / SHEET_BEND_MAX, 0.0, 1.0)
    # Rounded centroids and normals move neighbouring voxels' planes apart
    # by up to a few 1e-2 voxel where they meet (version 2; a few 1e-3 in
    # version 3, whose files say 3): sheets widen by that.
    slack = slack + _quantised_slack(texture) * share
    # Fill, share, area and slack as the GPU stores them (float16): where the
    # sheets bring a ray's transmittance to about 0.5, its depth hangs on the
    # last digit.
    fill = np.clip(fill, 0.0, 1.0).astype(np.float16).astype(np.float64)
    share = share.astype(np.float16).astype(np.float64)
    sheet_area = np.minimum(sheet_area, 6e4).astype(np.float16).astype(np.float64)
    slack = np.minimum(slack, 6e4).astype(np.float16).astype(np.float64)
    return EntrySheets(nh, d, section, sheet_area, fill, share, slack, crease)


def _quantised_slack(texture: AnisoTexture) -> float:
    """The crossing slack a quantised texture's sheets add per unit of
    static share (:attr:`EntrySheets.slack`): :data:`SHEET_QUANTISED` for
    version 2 files, :data:`SHEET_QUANTISED_V3` from version 3, 0 built."""
    quantised = texture.meta.get(QUANTISED)
    if not quantised:
        return 0.0
    fine = not isinstance(quantised, bool) and isinstance(quantised, int) and quantised >= 3
    return SHEET_QUANTISED_V3 if fine else SHEET_QUANTISED


@dataclass
class SheetTerms:
    """What the sheet laws ("split", "planar") need of each voxel a ray
    crosses, all (V,) or (V, 3):

    - ``projected``: the sheets' projected area ``sum A_s |n . w|`` (h^2);
    - ``crossed``: "planar": the sum of the fills of the sheets the ray
      crosses inside the voxel; "split": ``projected`` (their linear rate);
    - ``t_cross``: "planar": the fill-weighted mean ray parameter of those
      crossings, from the voxel's entry (grid units);
    - ``sheet_color`` and ``cloud_color``: the entries' shaded colours weighted
      by what each adds to the sheet part and by its cloud area ``(A - A_s)
      |n . w|``;
    - ``run``: "planar" with ``edges="filtered"``: the surface sheets
      (:data:`RUN_SHARE`) that count for the ray's runs, one row each, in
      voxel order (these are not in ``crossed``): ``voxel`` (its index in
      ``voxels``), ``normal`` (3), ``nw`` (its normal . w), ``band`` (its fill
      times the share of the pixel's footprint whose rays cross it inside the
      voxel), ``hit`` (its fill where the centre ray crosses it, else 0),
      ``counted`` (``hit`` if crossed, else ``band``), ``color`` (3) and ``t``
      (crossing parameter from the voxel's entry, grid units);
    - ``back``: "planar": what the backs of closed surfaces add to the
      density along the ray, to be taken out (:func:`back_terms`);
    - ``spread``: "planar": the voxel counts a half-plane or strip whose
      covered side the centre ray's crossing misses (its share is the
      footprint's, beside the ray: a concave corner's wall) or a line halo:
      not behind an open run (:data:`RUN_DEFER`).
    """

    projected: np.ndarray
    crossed: np.ndarray
    t_cross: np.ndarray
    sheet_color: np.ndarray
    cloud_color: np.ndarray
    run: dict[str, np.ndarray]
    back: np.ndarray
    spread: np.ndarray | None = None


def crossing_fraction(lo: np.ndarray, hi: np.ndarray, half_width: np.ndarray) -> np.ndarray:
    """Share in [0, 1] of a pixel's footprint whose rays cross a sheet's
    plane inside a voxel. The footprint's rays are offset from the centre ray
    along the plane's normal by up to ``half_width`` (grid units: half a
    pixel's width there times the normal's part across the ray, a box seen
    along it), and those offset by ``[lo, hi]`` cross inside the ray's
    stretch of the voxel. ``half_width`` 0 is the centre ray: 1 or 0.
    Mirrors volume.frag."""
    lo, hi, hw = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (lo, hi, half_width)))
    point = ((lo <= 0.0) & (hi >= 0.0)).astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        box = np.clip((np.minimum(hi, hw) - np.maximum(lo, -hw)) / (2.0 * hw), 0.0, 1.0)
    return np.where(hw <= 1e-7, point, box)


def run_sides(run: dict) -> tuple[np.ndarray, np.ndarray]:
    """Per side (2,) the band and hit of a run (the NumPy ray's ``run``):
    its sheets' sums (``band``, ``hit``) and their closed backs' apart
    (``band_back``, ``hit_back``), the larger, as a solid's back lies behind
    its own front (at a box's silhouette crease the face turned away covers
    what the face seen covers: summed, they drew its outline too wide), plus
    the sheets an edge cuts (``edge``). Mirrors run_sides() in volume.frag."""
    band = np.maximum(run["band"], run.get("band_back", 0.0)) + run["edge"][:2]
    hit = np.maximum(run["hit"], run.get("hit_back", 0.0)) + run["edge"][2:]
    return band, hit


def run_coverage(band: np.ndarray, hit: np.ndarray, halo: float = 0.0) -> float:
    """Coverage of a run of surface sheets from its sums on each side (2,):
    the side where the ray met the run's first sheet (entering a surface)
    and the side turned back (leaving it, as at a silhouette's far side;
    :data:`RUN_PARALLEL`). ``band``: the fills times the footprint's shares
    crossing them; ``hit``: the fills of those the centre ray crosses. Where
    it crosses sheets on the entering side only (a surface cut by voxel
    faces, a corner), their fills, whole; elsewhere (a near miss, through
    both sides of a silhouette, or on the far side only, which a ray that
    never entered meets only where a tangent's planes were rounded) the
    share of the footprint that crosses the side it crosses most. A grazing
    crossing (:data:`RUN_GRAZE`) is on both sides. ``halo``: the largest
    share its halos carry past sheets' edges (:mod:`~aniso3d.rendering.sheet_edges`),
    if larger. Mirrors run_sheets() and run_coverage() in volume.frag."""
    cov = float(np.max(band))
    if hit[0] > 0.0 and not hit[1] > 0.0:
        cov = max(cov, float(hit[0]))
    return max(min(max(cov, 0.0), 1.0), float(halo))


def run_color(run: dict) -> np.ndarray:
    """(3,) the colour of a run (the NumPy ray's ``run``: per side the sums
    ``band``, ``hit``, the sheets an edge cuts ``edge`` (band 0-1, hit 2-3),
    the largest halo ``halo``, and the weighted colours ``col``/``w`` of all
    its sheets, ``far_col``/``far_w`` of the far side's, ``far_wr`` its
    weights before the share of its colour each shows): each
    side's mean colour (halos with the near side), the near side's weighted
    by its coverage b0, the far side's by what it covers beyond, ``max(0,
    b1 - b0)``. Near a silhouette the far side lies behind the near side,
    whose colour shows where both cover the footprint; a solid's back that
    the planar law hides takes the near side's colour, the solid's front
    that hides it (a crease turning away from the eye: the cube's far
    edges drew a dark outline). Mirrors run_color() in volume.frag."""
    all_c = run["col"] / run["w"]
    w0 = run["w"] - run["far_w"]
    if not run["far_w"] > 0.0 or not w0 > 1e-6 * run["w"]:
        return all_c
    band, hit = run_sides(run)
    b0 = max(band[0], 0.0 if hit[1] > 0.0 else hit[0], run["halo"])
    b1 = max(band[1] - b0, 0.0)
    if not b0 + b1 > 0.0:
        return all_c
    c0 = (run["col"] - run["far_col"]) / w0
    c1 = run["far_col"] / run["far_w"]
    far_wr = run.get("far_wr", 0.0)
    s = run["far_w"] / far_wr if far_wr > 0.0 else 1.0
    c1 = s * c1 + (1.0 - s) * c0
    return (b0 * c0 + b1 * c1) / (b0 + b1)


def hidden_run(run: dict, trans: float) -> bool:
    """Whether a run closing at transmittance ``trans`` shows the colour
    the ray has so far instead of its own (:func:`run_color`): its near side
    holds nothing but thick solids' backs, which the planar law hides
    (their colour shown at ``RUN_BACK_MIN`` of their weight), behind
    something already drawn: that solid's front, drawn in part (a ray along
    a CAD part's edge met the front's voxels at their corners and the
    underside's run filled the rest in its own colour). Mirrors close_run()
    in volume.frag."""
    near_w, near_raw = run["w"] - run["far_w"], run["wr"] - run["far_wr"]
    return trans < 1.0 and near_raw > 0.0 and near_w < near_raw and near_w <= 1.5 * RUN_BACK_MIN * near_raw


def sheet_terms(
    texture: AnisoTexture,
    w: np.ndarray,
    lighting: Lighting,
    voxels: np.ndarray,
    x_in: np.ndarray,
    chords: np.ndarray,
    opacity: str = DEFAULT_OPACITY,
    normal: str = "mean",
    voxel_pixels: np.ndarray | float = np.inf,
    sheets: EntrySheets | None = None,
    edges: str = "filtered",
    layout: SheetLayout | None = None,
    halos: np.ndarray | None = None,
    shading: str = "smooth",
    back_hide: float = BACK_HIDE,
    line_halos: list | None = None,
) -> SheetTerms:
    """:class:`SheetTerms` of ``voxels`` (V,; -1: a cell holding halos only)
    crossed along the unit vector ``w`` from the voxel-local points ``x_in``
    (V, 3; the voxel is the unit cube) over ``chords`` (V,) grid units, each
    voxel spanning ``voxel_pixels`` (V,) pixels there (see
    :func:`sheet_share`). Mirrors composite() in volume.frag.

    A ray crosses a sheet's plane inside the voxel when the plane's signed
    distance changes sign (within the sheet's slack) between where the ray
    enters and leaves: a plane cut into many voxels is crossed in exactly one
    of them, whatever the angle. With ``edges="filtered"``, surface sheets
    (:data:`RUN_SHARE`) also count the share of the pixel's footprint (a
    voxel spans ``voxel_pixels``) crossing them, for the ray's runs
    (:func:`run_coverage`): along a plane cut by voxel faces the shares add
    up to 1, and a silhouette or a near miss gets its partial coverage. Their
    edges on voxel faces (``layout``'s, :func:`sheet_layout`) cut the share
    across them (:func:`~aniso3d.rendering.sheet_edges.edge_factors`), and
    ``halos`` (V,) lists, per voxel, the halos in it (indices into the
    layout's), counted after its own entries. ``shading="smooth"`` shades the
    runs' sheets by their linear models (:data:`SHADING_MODES`).
    ``back_hide``: "planar" only, :data:`BACK_HIDE` (:func:`back_terms`).
    ``line_halos`` (V,) lists, per voxel, the line halos in it (indices into
    the layout's :attr:`SheetLayout.line_halos`), counted as its own
    half-planes and strips are (:func:`_line_halo_terms`)."""
    w = np.asarray(w, dtype=np.float64)
    w = w / np.linalg.norm(w)
    voxels = np.asarray(voxels, dtype=np.int64)
    V = len(voxels)
    real = np.flatnonzero(voxels >= 0)
    rows, owner = _entry_rows(texture, voxels[real])
    owner = real[owner]
    if layout is not None:
        sh, at = layout.sheets, rows
    elif sheets is None:
        sh, at = entry_sheets(texture, voxels[real]), np.arange(len(rows))
    else:
        sh, at = sheets, rows
    c, n = _entry_colors(texture, w, lighting, normal, rows)
    area = covered_area(texture, rows)
    thick = layout.thick if layout is not None else thick_backs(texture)
    vis, back = back_terms(texture, rows, owner, V, w, back_hide if opacity == "planar" else 0.0, thick)
    pixels_v = np.broadcast_to(np.asarray(voxel_pixels, dtype=np.float64), (V,))
    x_in = np.asarray(x_in, np.float64).reshape(V, 3)
    chords = np.asarray(chords, np.float64).reshape(V)
    pixels = pixels_v[owner]
    share = sheet_share(sh.share[at], pixels)
    # Half-planes (sheet_halfplanes): surface sheets with an edge inside
    # the voxel, where the footprint is filtered.
    with np.errstate(divide="ignore"):
        filtered = (opacity == "planar") & (edges == "filtered") & (1.0 / pixels > 0.0) & (pixels >= HALF_PIXELS)
    # Strips (sheet_strips): a closed surface's partial sheet between two
    # lines (or one: its half-planes), the half-plane's terms with both
    # lines, drawn from STRIP_PIXELS on.
    with np.errstate(divide="ignore"):
        closer = (opacity == "planar") & (edges == "filtered") & (1.0 / pixels > 0.0) & (pixels >= STRIP_PIXELS)
    if layout is not None:
        strip = layout.strips.mask[rows] & closer
        halfp = (layout.halfplanes.mask[rows] & ~layout.strips.mask[rows] & filtered) | strip
    else:
        strip = halfp = np.zeros(len(rows), bool)
    share = np.where(halfp, 1.0, share)
    # Surface sheets (counted in runs) keep a closed surface's back (vis); a
    # crease sheet drawn as its half-plane is none.
    in_runs = (sh.share[at] >= RUN_SHARE) & ~halfp
    sv = np.where(in_runs, 1.0, vis)
    nh, a_s, fill = sh.normal[at], sv * share * sh.area[at], sv * np.where(halfp, 1.0, share * sh.fill[at])
    nw = nh @ w
    projected = np.bincount(owner, a_s * np.abs(nw), minlength=V)
    counted, band, t_hit = np.zeros(len(rows)), np.zeros(len(rows)), np.zeros(len(rows))
    hit = surface = np.zeros(len(rows), dtype=bool)
    run = None
    if opacity == "split":
        ws = a_s * np.abs(nw)
    else:
        x, ch = x_in[owner], chords[owner]
        s_in = np.einsum("ek,ek->e", nh, x) - sh.offset[at]
        hit, band_all, t_hit, foot, lo, hi = _crossings(s_in, nw, ch, sh.slack[at], a_s, pixels, edges)
        surface = (foot > 0.0) & in_runs & (a_s > 0)
        ramp = np.ones((len(rows), 2))
        # Crease sheets' half-planes: in a run, shaded flat and cut by their lines.
        crease_line = layout.halfplanes.mask[rows] & sh.crease[at] if layout is not None else np.zeros(len(rows), bool)
        if layout is not None and surface.any():
            e = np.flatnonzero(surface & (layout.edges.face[rows] >= 0).any(axis=1))
            if len(e):
                ramp[e] = _edge_ramps(layout.edges, rows[e], None, x[e], nh[e], s_in[e], nw[e], w, foot[e])
            # A crease sheet in a run: its half-plane's line cuts it as an edge (sheet_creases).
            e = np.flatnonzero(surface & crease_line)
            if len(e):
                with np.errstate(divide="ignore", invalid="ignore"):
                    p = x[e] + w[None, :] * np.where(nw[e] != 0.0, -s_in[e] / nw[e], 0.0)[:, None]
                re = rows[e]
                cov, col = crease_factors(layout.halfplanes.angle[re], layout.halfplanes.offset[re],
                                          layout.crease_phi[re], sh.offset[at][e], p, nh[e], w, foot[e])  # fmt: skip
                ramp[e, 0] *= cov
                ramp[e, 1] *= col
        band = np.where(surface, fill * band_all * ramp[:, 0], 0.0)
        counted = np.where(surface, np.where(hit, fill * ramp[:, 0], band), 0.0)
        weight = np.where(surface, np.where(hit, fill, fill * band_all) * ramp[:, 1], 0.0)
        run_c = c
        if layout is not None and normal == "mean" and shading == "smooth" and surface.any():
            # The run's sheets shaded where the ray crosses their planes, by
            # their linear models across them (sheet_slopes); a crease
            # sheet's half-plane flat (its line takes the model's word).
            e = np.flatnonzero(surface & ~crease_line)
            with np.errstate(divide="ignore", invalid="ignore"):
                p = x[e] + w[None, :] * np.where(nw[e] != 0.0, -s_in[e] / nw[e], 0.0)[:, None]
            there = smoothed(np.asarray(texture.entry_normal, np.float64)[rows[e]],
                             np.asarray(texture.entry_kd, np.float64)[rows[e]], layout.slopes.shape[rows[e]],
                             layout.slopes.kd[rows[e]], nh[e], sh.offset[at][e], p)  # fmt: skip
            run_c = c.copy()
            run_c[e] = _entry_colors(texture, w, lighting, normal, rows[e], at=there)[0]
        ws = np.where(hit & ~surface, fill, 0.0)
        # A half-plane crossed: the share of the footprint on its covered
        # side (per voxel, not in a run: leaves in a voxel are independent).
        e = np.flatnonzero(hit & ~surface & halfp)
        spread_at = np.zeros(0, np.int64)
        if len(e):
            with np.errstate(divide="ignore", invalid="ignore"):
                p = x[e] + w[None, :] * np.where(nw[e] != 0.0, -s_in[e] / nw[e], 0.0)[:, None]
            hpl, stp, re = layout.halfplanes, layout.strips, rows[e]
            share_on = np.where(
                strip[e],
                strip_cover(stp.angle[re], stp.lo[re], stp.hi[re], sh.offset[at][e], p, nh[e], w, STRIP_FOOT * foot[e]),
                halfplane_ramp(hpl.angle[re], hpl.offset[re], sh.offset[at][e], p, nh[e], w, foot[e]),
            )
            ws[e] *= share_on
            spread_at = owner[e[(share_on < 0.5) & (ws[e] > 0.0)]]
        # A whole sheet the centre ray crosses, with no edge or half-plane of
        # its own: it hides the voxel's run sheets crossed after it (RUN_FRONT_GAP).
        faced = (layout.edges.face[rows] >= 0).any(axis=1) if layout is not None else np.zeros(len(rows), bool)
        plain = ~layout.halfplanes.mask[rows] & ~layout.strips.mask[rows] if layout is not None else True
        front = surface & hit & plain & ~faced & (fill >= RUN_FRONT_FILL) & (np.abs(nw) >= RUN_GRAZE)
        keep = (counted > 0.0) | (weight > 0.0)
        run = {"voxel": owner[keep], "normal": nh[keep], "nw": nw[keep], "band": band[keep], "front": front[keep],
               "hit": np.where(hit, fill * ramp[:, 0], 0.0)[keep], "counted": counted[keep],
               "weight": weight[keep], "color": run_c[keep], "t": t_hit[keep],
               "edge": (ramp[:, 0] < 1.0)[keep], "halo": np.zeros(int(keep.sum()), dtype=bool),
               "vis": vis[keep], "back": back_share(texture, rows[keep], w, thick)}  # fmt: skip
        if layout is not None and halos is not None and edges == "filtered":
            run = _with_halos(run, layout, halos, texture, w, lighting, normal, x_in, chords, pixels_v,
                              back_hide if opacity == "planar" else 0.0)  # fmt: skip
    ws_owner, ws_c, ws_t = owner, c, t_hit
    spread = np.zeros(V, dtype=bool)
    if opacity == "planar" and edges == "filtered" and layout is not None:
        spread[spread_at] = True
    if line_halos is not None and layout is not None and opacity == "planar" and edges == "filtered":
        lo_, lws, lc, lt = _line_halo_terms(layout, line_halos, texture, w, lighting, normal, x_in, chords,
                                           pixels_v, back_hide)  # fmt: skip
        spread[lo_[lws > 0.0]] = True
        ws_owner, ws, ws_c, ws_t = (np.concatenate(x) for x in ((owner, lo_), (ws, lws), (c, lc), (t_hit, lt)))
    crossed = np.bincount(ws_owner, ws, minlength=V)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_cross = np.where(crossed > 0, np.bincount(ws_owner, ws * ws_t, minlength=V) / crossed, 0.0)
    zero = np.zeros(len(rows))
    sheet_color = _weighted_colors(ws_owner, V, ws_c, ws, np.zeros(len(ws)))
    cloud_w = vis * np.maximum(area - a_s, 0.0) * np.abs(n @ w)
    all_w = vis * area * np.abs(n @ w)
    cloud_color = np.where(
        (np.bincount(owner, cloud_w, minlength=V) > 1e-7 * np.bincount(owner, vis * area, minlength=V))[:, None],
        _weighted_colors(owner, V, c, cloud_w, zero),
        _weighted_colors(owner, V, c, all_w, vis * area),
    )
    if run is None:
        run = {k: np.zeros(0) for k in ("voxel", "nw", "band", "hit", "counted", "weight", "t", "vis", "back")}
        run.update(normal=np.zeros((0, 3)), color=np.zeros((0, 3)), edge=np.zeros(0, bool), halo=np.zeros(0, bool),
                   front=np.zeros(0, bool))
        run["voxel"] = run["voxel"].astype(np.int64)
    return SheetTerms(projected, crossed, t_cross, sheet_color, cloud_color, run, back, spread)


def _crossings(s_in, nw, chords, slack, a_s, pixels, edges):
    """Per sheet: whether the centre ray crosses its plane inside the voxel
    (within ``slack``), the share of the footprint crossing it there, the
    crossing's ray parameter from the voxel's entry (clamped to the chord),
    the footprint's width (grid units; 0 with ``edges="sampled"``) and the
    offsets ``lo``, ``hi`` crossing inside."""
    s_out = s_in + nw * chords
    lo, hi = -np.maximum(s_in, s_out), -np.minimum(s_in, s_out)
    hit = (lo - slack <= 0.0) & (hi + slack >= 0.0) & (a_s > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_hit = np.where(nw != 0, -s_in / nw, 0.0)
    t_hit = np.clip(t_hit, 0.0, chords)
    with np.errstate(divide="ignore"):
        foot = np.zeros(len(s_in)) if edges == "sampled" else 1.0 / pixels
    # The band without the slack: that only keeps a centre ray from slipping
    # between neighbouring planes.
    half_w = 0.5 * foot * np.sqrt(np.maximum(1.0 - nw * nw, 0.0))
    return hit, crossing_fraction(lo, hi, half_w), t_hit, foot, lo, hi


def _edge_ramps(edges_: SheetEdges, rows, halo_ids, x, nh, s_in, nw, w, foot) -> np.ndarray:
    """(N, 2) what the edges of entries ``rows`` (or the halos ``halo_ids``)
    leave of their coverage and colour weight where the ray crosses their
    planes (:func:`~aniso3d.rendering.sheet_edges.edge_factors`)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        p = x + w[None, :] * np.where(nw != 0.0, -s_in / nw, 0.0)[:, None]
    out = np.ones((len(x), 2))
    if halo_ids is not None:
        cov, col = edge_factors(edges_.halo_face[halo_ids], edges_.halo_kind[halo_ids],
                                edges_.halo_angle[halo_ids], p, nh, w, foot, halo=True)  # fmt: skip
        return np.stack([cov, col], axis=1)
    for j in range(MAX_EDGES):
        f = edges_.face[rows, j].astype(np.int64)
        has = f >= 0
        cov, col = edge_factors(np.maximum(f, 0), edges_.kind[rows, j], edges_.angle[rows, j], p, nh, w, foot, False)
        out[:, 0] *= np.where(has, cov, 1.0)
        out[:, 1] *= np.where(has, col, 1.0)
    return out


def _with_halos(run, layout, halos, texture, w, lighting, normal, x_in, chords, pixels, hide: float) -> dict:
    """``run`` (the rows of :class:`SheetTerms`) with the halos ``halos``
    (per voxel, halo indices) joined after each voxel's own sheets.
    ``hide``: the planar law's share of closed backs hidden (a halo's
    ``vis`` is its sheet's, :func:`back_terms`)."""
    counts = np.array([len(h) for h in halos], dtype=np.int64)
    if counts.sum() == 0:
        return run
    ids = np.concatenate([np.asarray(h, dtype=np.int64) for h in halos])
    owner = np.repeat(np.arange(len(halos)), counts)
    ed, sh = layout.edges, layout.sheets
    src = ed.halo_row[ids]
    c, _ = _entry_colors(texture, w, lighting, normal, src)
    share = sheet_share(sh.share[src], pixels[owner])
    nh, fill, a_s = sh.normal[src], share * sh.fill[src], share * sh.area[src]
    nw = nh @ w
    x, ch = x_in[owner], chords[owner]
    s_in = np.einsum("ek,ek->e", nh, x) - ed.halo_offset[ids]
    hit, band_all, t_hit, foot, _, _ = _crossings(s_in, nw, ch, sh.slack[src], a_s, pixels[owner], "filtered")
    ramp = _edge_ramps(ed, None, ids, x, nh, s_in, nw, w, foot)
    vis, _ = back_terms(texture, src, owner, len(halos), w, hide, layout.thick)
    counted = np.where(hit, fill, fill * band_all) * ramp[:, 0]
    weight = np.where(hit, fill, fill * band_all) * ramp[:, 1]
    ok = (sh.share[src] >= RUN_SHARE) & (a_s > 0) & ((counted > 0.0) | (weight > 0.0))
    # A crease sheet drawn as its half-plane carries no halo.
    ok &= ~(layout.halfplanes.mask[src] & sh.crease[src] & (pixels[owner] >= HALF_PIXELS))
    halo_run = {"voxel": owner[ok], "normal": nh[ok], "nw": nw[ok], "band": (fill * band_all * ramp[:, 0])[ok],
                "hit": np.where(hit, fill * ramp[:, 0], 0.0)[ok], "counted": counted[ok], "weight": weight[ok],
                "color": c[ok], "t": t_hit[ok], "edge": np.zeros(int(ok.sum()), bool),
                "halo": np.ones(int(ok.sum()), bool), "vis": vis[ok], "front": np.zeros(int(ok.sum()), bool),
                "back": back_share(texture, src[ok], w, layout.thick)}  # fmt: skip
    # Each voxel's own sheets, then its halos (as the GPU lists them).
    order = np.argsort(np.concatenate([run["voxel"], halo_run["voxel"]]), kind="stable")
    return {k: np.concatenate([run[k], halo_run[k]])[order] for k in run}


def _line_halo_terms(layout, line_halos, texture, w, lighting, normal, x_in, chords, pixels, hide: float):
    """The line halos ``line_halos`` (per voxel, indices into the layout's:
    the strips', :func:`sheet_line_halos`) as partial sheets of their
    voxels: (N,) each one's voxel, the share of the footprint it covers
    where the ray crosses its plane (its strip's lines, moved into the
    voxel, and where its line crosses its face, cut by the face:
    :mod:`~aniso3d.rendering.sheet_line_halos`), its colour and crossing
    parameter. Mirrors volume.frag (a line halo: drawn where its strip is)."""
    counts = np.array([len(h) for h in line_halos], dtype=np.int64)
    if counts.sum() == 0:
        z = np.zeros(0)
        return np.zeros(0, np.int64), z, np.zeros((0, 3)), z
    ids = np.concatenate([np.asarray(h, dtype=np.int64) for h in line_halos])
    owner = np.repeat(np.arange(len(line_halos)), counts)
    lh, sh, st = layout.line_halos, layout.sheets, layout.strips
    src = lh.row[ids]
    pix = np.asarray(pixels, dtype=np.float64)[owner]
    with np.errstate(divide="ignore"):
        drawn = (1.0 / pix > 0.0) & (pix >= STRIP_PIXELS)
    nh = sh.normal[src]
    nw = nh @ w
    x = np.asarray(x_in, np.float64)[owner]
    s_in = np.einsum("ek,ek->e", nh, x) - lh.offset[ids]
    vis, _ = back_terms(texture, src, owner, len(line_halos), w, hide, layout.thick)
    a_s = vis * sh.area[src]
    hit, _, t_hit, foot, _, _ = _crossings(s_in, nw, np.asarray(chords, np.float64)[owner], sh.slack[src], a_s,
                                           pix, "filtered")  # fmt: skip
    with np.errstate(divide="ignore", invalid="ignore"):
        p = x + w[None, :] * np.where(nw != 0.0, -s_in / nw, 0.0)[:, None]
    cover = strip_cover(st.angle[src], lh.lo[ids], lh.hi[ids], lh.offset[ids], p, nh, w, STRIP_FOOT * foot)
    cut = lh.cut[ids]
    if cut.any():
        cover[cut] *= edge_ramp(lh.face[ids][cut], p[cut], nh[cut], w, foot[cut], inside=False)
    ws = np.where(drawn & hit, vis * cover, 0.0)
    c, _ = _entry_colors(texture, w, lighting, normal, src)
    return owner, ws, c, t_hit


@dataclass(frozen=True)
class SheetLayout:
    """What the NumPy ray needs of a whole texture's sheets (the GPU's
    upload derives the same, :func:`pack_volume`): every entry's
    :class:`EntrySheets`, the surface sheets' :class:`~aniso3d.rendering.sheet_edges.SheetEdges`
    and :class:`~aniso3d.rendering.sheet_slopes.SheetSlopes` (as the GPU
    stores them, float16), the halos' cells as keys of the grid with its
    margin (sorted, with the halo indices in that order), and the partial
    sheets' :class:`~aniso3d.rendering.sheet_halfplanes.SheetHalfplanes` and
    :class:`~aniso3d.rendering.sheet_strips.SheetStrips`."""

    sheets: EntrySheets
    edges: SheetEdges
    halo_keys: np.ndarray
    halo_order: np.ndarray
    slopes: SheetSlopes
    halfplanes: SheetHalfplanes
    strips: SheetStrips
    #: (E,) a crease half-plane's partner angle (sheet_creases.crease_partners), else 0.
    crease_phi: np.ndarray
    #: (E,) bool, the closed entries whose solid is thick behind them (:func:`thick_backs`).
    thick: np.ndarray
    #: The lines' halos (:func:`sheet_line_halos`), their cells' keys
    #: (sorted) and their indices in that order.
    line_halos: LineHalos = field(default_factory=LineHalos.empty)
    line_keys: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    line_order: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))


def _no_creases(halfplanes: SheetHalfplanes, sheets: EntrySheets) -> SheetHalfplanes:
    """``halfplanes`` less the crease sheets': those stay surface sheets
    where drawn small, whose linear model a strip's far line would overwrite."""
    return replace(halfplanes, mask=halfplanes.mask & ~sheets.crease)


def _sheet_halfplanes(texture: AnisoTexture, sheets: EntrySheets) -> tuple[SheetHalfplanes, np.ndarray]:
    """The half-planes of ``texture``'s partial and crease sheets, a crease
    sheet's kept only where its line lies on its partner's plane (an edge:
    :func:`~aniso3d.rendering.sheet_creases.crease_partners`), and (E,) each
    kept crease half-plane's partner angle, 0 elsewhere."""
    hp = sheet_halfplanes(texture, sheets, sheets.plain_surface)
    rows = np.flatnonzero(hp.mask & sheets.crease)
    phi, tilt, gap = crease_partners(texture, sheets, hp, rows)
    edge = (tilt <= CREASE_TILT) & (gap <= CREASE_GAP)
    mask = hp.mask.copy()
    mask[rows[~edge]] = False
    angles = np.zeros(texture.n_entries)
    angles[rows[edge]] = phi[edge]
    return replace(hp, mask=mask), angles


def sheet_line_halos(sheets: EntrySheets, strips: SheetStrips, texture) -> LineHalos:
    """The :class:`~aniso3d.rendering.sheet_line_halos.LineHalos` of the
    strips (a closed surface's half-plane among them, its far line at
    infinity; :data:`LINE_HALOS`; none when off). An open surface's
    half-planes have none: with them the shell's border over-covered (its
    volume lost 0.1 dB close up and 0.3 dB with half-planes from 0.5 pixel;
    docs/coverage.md, "Halos of lines inside voxels")."""
    if not LINE_HALOS:
        return LineHalos.empty()
    rows = np.flatnonzero(strips.mask)
    return line_halos(texture, sheets, rows, strips.angle[rows], strips.lo[rows], strips.hi[rows],
                      ONE_LINE_REACH, strips, line_halo_module.SPLIT_REST)  # fmt: skip


def line_halo_entries(entries: np.ndarray, lh: LineHalos) -> np.ndarray:
    """(H, ENTRY_WORDS) uint32: the strips' line halos ``lh`` as
    volume.frag reads them: their strips' words with no area, their planes
    and lines in their voxels' frames (the far line in word 12), the halo's
    face in word 11 (bits 8-10) and whether the face cuts it (bit
    FACE_CUT_BIT)."""
    halo = entries[lh.row].copy()
    halo[:, 3] = np.float32(0.0).view(np.uint32)
    halo[:, 8] = lh.offset.astype(np.float32).view(np.uint32)
    no_face = np.uint32(NO_FACE | (NO_FACE << 4))
    halo[:, 11] = (
        (halo[:, 11] & np.uint32(0x7F808))  # the angle and the strip bit kept
        | (offset_code(lh.lo).astype(np.uint32) << 19) | np.uint32(1 << 31) | no_face
        | (lh.face.astype(np.uint32) << 8) | (lh.cut.astype(np.uint32) << FACE_CUT_BIT)
    )  # fmt: skip
    halo[:, 12] = lh.hi.astype(np.float32).view(np.uint32)
    return halo


def layout_sheets(texture: AnisoTexture) -> tuple[EntrySheets, SheetHalfplanes, np.ndarray]:
    """``texture``'s :func:`entry_sheets` as the renderer lays them out, and
    their half-planes and crease partners' angles (:func:`_sheet_halfplanes`):
    a crease sheet of a closed surface that is no half-plane but fits a
    strip (:data:`CREASE_STRIPS`) is no surface sheet (its static share its
    own fill's, :data:`SHEET_FILL`), so that it is drawn as that strip."""
    sheets = entry_sheets(texture)
    hp, phi = _sheet_halfplanes(texture, sheets)
    if not CREASE_STRIPS or not sheets.crease.any():
        return sheets, hp, phi
    sigma = closed_sign(texture)
    narrow = sheets.crease & ~hp.mask & (sigma != 0.0)
    if not narrow.any():
        return sheets, hp, phi
    # (Only those fitted here: every other entry passed as a surface sheet.)
    st = sheet_strips(texture, sheets, ~narrow, _no_creases(hp, sheets), sigma)
    narrow &= st.mask
    with np.errstate(divide="ignore", invalid="ignore"):
        own = np.where(sheets.section > 1e-9, sheets.area / sheets.section, 0.0)
    share = np.where(narrow, _ramp(own, SHEET_FILL).astype(np.float16).astype(np.float64), sheets.share)
    # A quantised texture's slack follows the share (entry_sheets).
    slack = sheets.slack + _quantised_slack(texture) * (share - sheets.share)
    slack = np.minimum(np.maximum(slack, 0.0), 6e4).astype(np.float16).astype(np.float64)
    return replace(sheets, share=share, slack=slack, crease=sheets.crease & ~narrow), hp, phi


def sheet_layout(texture: AnisoTexture) -> SheetLayout:
    """The :class:`SheetLayout` of ``texture``."""
    sheets, hp, phi = layout_sheets(texture)
    ed = sheet_edges(texture, sheets, sheets.surface)
    sl = sheet_slopes(texture, sheets, sheets.surface)
    half = lambda x: x.astype(np.float16).astype(np.float64)  # noqa: E731
    pshape = np.asarray(texture.shape, dtype=np.int64) + 2 * GRID_PAD
    keys = cell_keys(ed.halo_cell + GRID_PAD, pshape)
    order = np.argsort(keys, kind="stable")
    st = sheet_strips(texture, sheets, sheets.surface, _no_creases(hp, sheets), closed_sign(texture))
    lh = sheet_line_halos(sheets, st, texture)
    lkeys = cell_keys(lh.cell + GRID_PAD, pshape)
    lorder = np.argsort(lkeys, kind="stable")
    return SheetLayout(sheets, ed, keys[order], order, SheetSlopes(half(sl.shape), half(sl.kd)), hp, st, phi,
                       thick_backs(texture), lh, lkeys[lorder], lorder)  # fmt: skip


# ------------------------------------------------------------ the NumPy ray


@dataclass
class RayTrace:
    """What one NumPy ray met: per crossed occupied voxel its index, entry
    parameter and chord (world units), and the result."""

    voxels: list[int] = field(default_factory=list)
    t_enter: list[float] = field(default_factory=list)
    chords: list[float] = field(default_factory=list)
    rgb: np.ndarray = field(default_factory=lambda: np.zeros(3))
    alpha: float = 0.0
    t50: float | None = None


def march_ray_np(
    texture: AnisoTexture,
    origin,
    direction,
    lighting: Lighting,
    t_range: tuple[float, float] = (0.0, np.inf),
    density: str = "facet",
    normal: str = "mean",
    opacity: str = DEFAULT_OPACITY,
    pixel_angle: float = 0.0,
    edges: str = "filtered",
    layout: SheetLayout | None = None,
    shading: str = "smooth",
    back_hide: float = BACK_HIDE,
) -> tuple[np.ndarray, float]:
    """One ray through ``texture``, the slow twin of a GPU pixel.

    ``origin`` (3,), the eye, and ``direction`` (3,) are world; ``t_range``
    limits the ray parameter (world distance along the unit direction; the
    renderer passes the near and far planes). ``pixel_angle`` is the angle a
    pixel spans, radians (the renderer's ``2 tan(fov / 2) / height``): a
    voxel at distance r from the eye spans ``h / (r pixel_angle)`` pixels,
    which the sheet law "planar" reads (:func:`sheet_share`); 0 stands for a
    point sample. ``edges``, ``shading`` and ``back_hide`` are
    :attr:`VolumeOptions.edges`, :attr:`VolumeOptions.shading` and
    :attr:`VolumeOptions.back_hide`; ``layout`` the
    texture's :func:`sheet_layout` (made when not given). Returns the
    pixel's (3,) RGB in [0, 1], ``C + T * background``, and its alpha ``1 - T``.
    """
    tr = trace_ray_np(
        texture, origin, direction, lighting, t_range, density, normal, opacity, pixel_angle, edges, layout, shading,
        back_hide,
    )
    return tr.rgb, tr.alpha


def trace_ray_np(
    texture: AnisoTexture,
    origin,
    direction,
    lighting: Lighting,
    t_range: tuple[float, float] = (0.0, np.inf),
    density: str = "facet",
    normal: str = "mean",
    opacity: str = DEFAULT_OPACITY,
    pixel_angle: float = 0.0,
    edges: str = "filtered",
    layout: SheetLayout | None = None,
    shading: str = "smooth",
    back_hide: float = BACK_HIDE,
) -> RayTrace:
    """:func:`march_ray_np` with what the ray met (see :class:`RayTrace`).
    ``layout``: the texture's :func:`sheet_layout`, made here when not given
    (pass it when tracing many rays of one texture)."""
    _check_choice(edges, EDGE_MODES, "volume edges")
    _check_choice(density, DENSITY_MODES, "density reading")
    _check_choice(normal, NORMAL_MODES, "normal")
    _check_choice(shading, SHADING_MODES, "volume shading")
    _check_choice(opacity, OPACITY_MODES, "opacity law")
    d = np.asarray(direction, dtype=np.float64)
    if d.shape != (3,) or not np.isfinite(d).all() or not np.linalg.norm(d) > 0:
        raise InputError(f"ray direction must be a finite non-zero 3-vector, got {direction!r}")
    d = d / np.linalg.norm(d)
    d = np.where(np.abs(d) < 1e-12, 0.0, d)
    h = float(texture.voxel_size)
    # The grid with its margin (the GPU's, pack_volume): cells from -GRID_PAD;
    # rays clipped to the texture's box widened by CLIP_MARGIN.
    o = (np.asarray(origin, dtype=np.float64) - np.asarray(texture.origin, np.float64)) / h + GRID_PAD
    shape = np.asarray(texture.shape, dtype=np.int64) + 2 * GRID_PAD
    lo = float(GRID_PAD - CLIP_MARGIN)
    t0, t1 = float(t_range[0]) / h, float(t_range[1]) / h
    out = RayTrace()
    for a in range(3):
        if d[a] == 0.0:
            if o[a] < lo or o[a] > shape[a] - lo:
                t1 = -np.inf
        else:
            ta, tb = (lo - o[a]) / d[a], (shape[a] - lo - o[a]) / d[a]
            t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
    bg = np.asarray(lighting.background, dtype=np.float64)
    if not t0 < t1 or texture.n_voxels == 0:
        out.rgb = bg.copy()
        return out

    sheeted = opacity in ("split", "planar")
    if sheeted and layout is None:
        layout = sheet_layout(texture)
    # Occupied cells by key; coords are sorted, so their keys are too. Halos
    # (planar law only) by their cells' keys.
    keys = cell_keys(np.asarray(texture.coords, np.int64) + GRID_PAD, shape)
    hkeys = layout.halo_keys if opacity == "planar" else np.zeros(0, np.int64)
    lkeys = layout.line_keys if opacity == "planar" and edges == "filtered" else np.zeros(0, np.int64)

    cell = np.clip(np.floor(o + d * t0).astype(np.int64), 0, shape - 1)
    step = np.sign(d).astype(np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):
        tmax = np.where(d > 0, (cell + 1 - o) / d, np.where(d < 0, (cell - o) / d, _BIG))
        tdelta = np.where(d != 0, 1.0 / np.abs(d), _BIG)
    t = t0
    # Per cell met: texture voxel (-1: none), entry, chord, cell, its halos.
    hits: list[tuple[int, float, float, np.ndarray, np.ndarray, np.ndarray]] = []
    while t < t1:
        tx = float(tmax.min())
        te = min(tx, t1)
        if te > t:
            key = int(cell_keys(cell, shape)[0])
            i = int(np.searchsorted(keys, key))
            v = i if i < len(keys) and keys[i] == key else -1
            lo, hi = np.searchsorted(hkeys, key), np.searchsorted(hkeys, key, side="right")
            halo_ids = layout.halo_order[lo:hi] if hi > lo else np.zeros(0, np.int64)
            lo, hi = np.searchsorted(lkeys, key), np.searchsorted(lkeys, key, side="right")
            line_ids = layout.line_order[lo:hi] if hi > lo else np.zeros(0, np.int64)
            if v >= 0 or len(halo_ids) or len(line_ids):
                hits.append((v, t, te - t, cell.copy(), halo_ids, line_ids))
            t = te
        if tx >= t1:
            break
        a = int(np.argmin(tmax))  # first minimum: x, then y, then z, as on the GPU
        cell[a] += step[a]
        tmax[a] += tdelta[a]
        if not 0 <= cell[a] < shape[a]:
            break

    P = float(np.abs(d).sum())
    vox = np.array([hv[0] for hv in hits], dtype=np.int64)
    real = vox >= 0
    dens, cols = np.zeros(len(vox)), np.zeros((len(vox), 3))
    if real.any():
        dens[real] = density_along(texture, d, density, vox[real], stored=True)
        cols[real] = voxel_colors(texture, d, lighting, normal, vox[real])
    st = None
    if sheeted and len(vox):
        t_in = np.array([hv[1] for hv in hits])
        chords = np.array([hv[2] for hv in hits])
        x_in = o + d * t_in[:, None] - np.array([hv[3] for hv in hits], dtype=np.float64)
        # A voxel's size in pixels where the ray crosses its middle (t is in
        # voxels from the eye).
        with np.errstate(divide="ignore"):
            pixels = 1.0 / ((t_in + 0.5 * chords) * float(pixel_angle))
        st = sheet_terms(texture, d, lighting, vox, x_in, chords, opacity, normal, pixels, edges=edges,
                         layout=layout, halos=[hv[4] for hv in hits], shading=shading,
                         back_hide=back_hide, line_halos=[hv[5] for hv in hits])  # fmt: skip
    C, T = np.zeros(3), 1.0
    tau_s, T_f = 0.0, 1.0  # "split": the sheets' linear depth, the cloud's transmittance
    # "planar": the open run of surface sheets (volume.frag: g_run...): per
    # side the sums of band and hit of sheets whole, the largest of those an
    # edge cuts, the largest halo; colour, weight, weighted t (from the eye),
    # and the far side's colour and weight (run_color).
    run: dict | None = None
    # RUN_DEFER: what lies behind the open run's crossed surface, a layer
    # (premultiplied colour, transmittance, the ray parameter where it began).
    behind = {"col": np.zeros(3), "trans": 1.0, "t": 0.0}

    def run_sheets() -> float:
        return run_coverage(*run_sides(run))

    def close_run() -> None:
        nonlocal C, T, run
        if run is not None:
            cov = max(run_sheets(), run["halo"])
            if cov > 0.0 and run["w"] > 0.0:
                seg = T * cov
                if out.t50 is None and T > 0.5 and T - seg <= 0.5:
                    out.t50 = run["tw"] / run["w"] * h
                C = C + seg * (C / (1.0 - T) if hidden_run(run, T) else run_color(run))
                T -= seg
            if behind["trans"] < 1.0:
                if out.t50 is None and T > 0.5 and T * behind["trans"] <= 0.5:
                    out.t50 = behind["t"] * h
                C = C + T * behind["col"]
                T *= behind["trans"]
                behind.update(col=np.zeros(3), trans=1.0)
        run = None

    for k, ((v, ti, chord, _, _, _), D, col) in enumerate(zip(hits, dens, cols, strict=True)):
        if T <= T_MIN:
            break
        steep = False  # the centre ray crosses one of this voxel's surface sheets steeply
        if run is not None and ti > run["end"] + RUN_GAP:
            close_run()  # the GPU closes it on its way to this voxel
            if T <= T_MIN:
                break
        if opacity == "exponential":
            alpha = min(max(D / P, 0.0), ALPHA_MAX)
            sigma = -np.log1p(-alpha) * P
            seg = -T * np.expm1(-sigma * chord)
        elif opacity == "linear":
            sigma = min(max(D, 0.0), P)
            seg = min(T, sigma * chord)
        else:
            if opacity == "planar":
                D = max(D - st.back[k], 0.0)  # the backs of closed surfaces (back_terms)
            alpha_f = min(max(D - st.projected[k], 0.0) / P, ALPHA_MAX)
            sigma = -np.log1p(-alpha_f) * P
            keep_f = np.exp(-sigma * chord)
            if opacity == "split":
                a_s = min(st.projected[k], P) * chord
                tau_s += a_s
                T_f *= keep_f
                t_after = max(0.0, 1.0 - tau_s) * T_f
            else:
                mine = st.run["voxel"] == k
                if mine.any():
                    # Surface sheets join the run, weighted by what the run
                    # had left uncovered before this voxel; the side is
                    # whether the ray meets each as it met the run's first.
                    e = {key: val[mine] for key, val in st.run.items()}
                    whole = ~e["edge"] & ~e["halo"]
                    steep = bool(((e["hit"] > 0.0) & whole & (np.abs(e["nw"]) >= RUN_STEEP)).any())
                    if run is None:
                        run = {"ref": e["normal"][0], "band": np.zeros(2), "hit": np.zeros(2), "hit_t": np.inf,
                               "band_back": np.zeros(2), "hit_back": np.zeros(2),
                               "edge": np.zeros(4), "halo": 0.0, "col": np.zeros(3), "w": 0.0,
                               "far_col": np.zeros(3), "far_w": 0.0, "far_wr": 0.0, "wr": 0.0,
                               "tw": 0.0}  # fmt: skip
                        open_ = 1.0
                    else:
                        open_ = 1.0 - run_sheets()
                    along = e["normal"] @ run["ref"]
                    same = np.where(np.abs(along) >= RUN_PARALLEL, e["nw"] * (run["ref"] @ d) * along, 1.0)
                    other = (same < 0.0).astype(np.int64)
                    graze = np.abs(e["nw"]) < RUN_GRAZE
                    # Closed backs apart (run_sides).
                    for key, part in (("", 1.0 - e["back"]), ("_back", e["back"])):
                        band_p, hit_p = (e["band"] * part)[whole], (e["hit"] * part)[whole]
                        run["band" + key] = run["band" + key] + np.bincount(other[whole], band_p, minlength=2)
                        run["hit" + key] = run["hit" + key] + np.bincount(other[whole], hit_p * ~graze[whole],
                                                                          minlength=2)  # fmt: skip
                        run["hit" + key] = run["hit" + key] + float((hit_p * graze[whole]).sum())
                    # Where the centre ray first crossed a whole sheet on the entering side (RUN_DEFER).
                    first = whole & (e["hit"] > 0.0) & ~graze & (other == 0)
                    if first.any():
                        run["hit_t"] = min(run["hit_t"], float((e["t"][first] + ti).min()))
                    # Sheets an edge cuts: the largest per side (a silhouette's
                    # crease: its two faces overlap); halos: the largest.
                    # (No grazing rule for them: volume.frag.)
                    cut = e["edge"]
                    for side in (0, 1):
                        on = cut & (other == side)
                        if on.any():
                            run["edge"][side] = max(run["edge"][side], float(e["band"][on].max()))
                            run["edge"][2 + side] = max(run["edge"][2 + side], float(e["hit"][on].max()))
                    if e["halo"].any():
                        run["halo"] = max(run["halo"], float(e["counted"][e["halo"]].max()))
                    # A closed surface's back keeps its coverage but hardly
                    # colours its side (RUN_BACK_MIN).
                    wr = np.where(e["halo"], 1.0, open_) * e["weight"]
                    if RUN_FRONT_GAP is not None and e["front"].any():
                        # Hidden behind the voxel's first whole sheet (RUN_FRONT_GAP).
                        first_t = float(e["t"][e["front"]].min())
                        wr = np.where(~e["halo"] & (e["t"] > first_t + RUN_FRONT_GAP), 0.0, wr)
                    wc = wr * np.maximum(e["vis"], RUN_BACK_MIN)
                    run["col"] = run["col"] + wc @ e["color"]
                    run["w"] += float(wc.sum())
                    run["wr"] += float(wr.sum())
                    run["tw"] += float(wc @ (e["t"] + ti))
                    far = (other == 1) & ~e["halo"]
                    run["far_col"] = run["far_col"] + wc[far] @ e["color"][far]
                    run["far_w"] += float(wc[far].sum())
                    run["far_wr"] += float(wr[far].sum())
                    run["end"] = ti + chord
                # Sheet and cloud share the facets: their coverages add.
                a_s = min(st.crossed[k], 1.0)
                t_after = T * max(0.0, keep_f - a_s)
            seg = T - t_after
            a_s, a_f = min(a_s, 1.0), 1.0 - keep_f
            if a_s + a_f > 0.0:
                col = (a_s * st.sheet_color[k] + a_f * st.cloud_color[k]) / (a_s + a_f)
        # A run crossed whole on its entering side, steeply, is settled (volume.frag).
        # The run's centre ray crossed whole sheets on its entering side only.
        hit_sides = run_sides(run)[1] if run is not None else None
        crossed_whole = hit_sides is not None and hit_sides[0] >= 1.0 and hit_sides[1] == 0.0
        settled = steep and crossed_whole
        if RUN_DEFER and opacity == "planar" and crossed_whole and seg > 0.0 and T > 0.0 and not st.spread[k]:
            here = ti + (st.t_cross[k] if st.crossed[k] > 0.0 else 0.5 * chord)
            if run["hit_t"] <= here:
                # Behind the run's surface: a layer behind it (RUN_DEFER).
                a = seg / T
                if behind["trans"] == 1.0:
                    behind["t"] = here
                behind["col"] = behind["col"] + behind["trans"] * a * np.asarray(col, np.float64)
                behind["trans"] *= 1.0 - a
                out.voxels.append(v)
                out.t_enter.append(ti * h)
                out.chords.append(chord * h)
                if settled:
                    close_run()
                continue
        if not seg > 0.0:
            if settled:
                close_run()
            continue
        out.voxels.append(v)
        out.t_enter.append(ti * h)
        out.chords.append(chord * h)
        if out.t50 is None and T - seg <= 0.5:
            out.t50 = (ti + _t50_offset(opacity, T, seg, sigma, chord, st, k)) * h
        C += seg * col
        T -= seg
        if settled:
            close_run()
    close_run()
    if T <= T_MIN:  # stopped early: the rest takes the colour seen so far, as on the GPU
        C, T = C / (1.0 - T), 0.0
    out.rgb = np.clip(C + T * bg, 0.0, 1.0)
    out.alpha = float(np.clip(1.0 - T, 0.0, 1.0))
    return out


def _t50_offset(
    opacity: str, T: float, seg: float, sigma: float, chord: float, st: SheetTerms | None, k: int
) -> float:
    """Where in a voxel (ray parameter from its entry, grid units) 1 - T
    reaches 0.5, given T before it and ``seg`` taken in it. Mirrors volume.frag."""
    if T <= 0.5:
        return 0.0
    if opacity == "exponential":
        return float(np.log(T / 0.5) / sigma)
    if opacity == "linear":
        return (T - 0.5) / sigma
    if opacity == "split":
        return chord * (T - 0.5) / seg
    a_s = min(st.crossed[k], 1.0)
    if T * (1.0 - a_s) <= 0.5:  # the sheets alone take it there
        return float(st.t_cross[k])
    return float(-np.log(0.5 / T + a_s) / sigma)


# --------------------------------------------------------------- GPU layout


def pack_volume(texture: AnisoTexture) -> dict[str, np.ndarray]:
    """The arrays volume.frag reads, in upload order (see its header): the
    two-level index (``top``, ``pool``), ``offsets``, ``density`` (float16
    pairs in uint32), ``entries`` (:data:`ENTRY_WORDS` uint32 per entry: the
    shading entry and its sheet, :func:`entry_sheets`, with its edges and
    after its voxel's entries the halos there, :func:`sheet_edges`; or its
    half-plane, :func:`~aniso3d.rendering.sheet_halfplanes.sheet_halfplanes`,
    or strip, :func:`~aniso3d.rendering.sheet_strips.sheet_strips`) and
    ``directions``, over the GPU grid (:func:`pack_volume_grid`). CPU only;
    checks the texture holds finite numbers."""
    return pack_volume_grid(texture).arrays


@dataclass(frozen=True)
class PackedVolume:
    """:func:`pack_volume`'s arrays and the GPU grid they index.

    Attributes:
        arrays: the arrays, by name, in upload order.
        shape: (3,) int64 cells of the GPU grid: the texture's with
            :data:`~aniso3d.rendering.sheet_edges.GRID_PAD` more on each side.
        cells: (M', 3) int64 cell of each GPU voxel in that grid: the
            texture's voxels (``coords + GRID_PAD``, in order), then the
            cells that hold only halos.
    """

    arrays: dict[str, np.ndarray]
    shape: np.ndarray
    cells: np.ndarray


def pack_volume_grid(texture: AnisoTexture) -> PackedVolume:
    """:func:`pack_volume` with the GPU grid (:class:`PackedVolume`)."""
    if not isinstance(texture, AnisoTexture):
        raise InputError(f"the volume renderer draws an AnisoTexture, got {type(texture).__name__}")
    for name in (
        "density",
        "entry_area",
        "entry_normal",
        "entry_kd",
        "entry_ks",
        "entry_shininess",
    ):
        if not np.isfinite(np.asarray(getattr(texture, name))).all():
            raise InputError(
                f"texture field '{name}' holds NaN or infinite values; rebuild the texture"
            )
    if np.any(np.asarray(texture.density) < 0) or np.any(np.asarray(texture.entry_area) < 0):
        raise InputError("texture has negative density or area; rebuild the texture")
    if texture.n_directions > 1 << 16:
        raise InputError(f"the volume renderer draws at most {1 << 16} directions, got {texture.n_directions}")
    shape = np.asarray(texture.shape, dtype=np.int64)
    M, K = texture.n_voxels, texture.n_directions
    coords = np.asarray(texture.coords, dtype=np.int64)
    if M and (np.any(coords < 0) or np.any(coords >= shape)):
        raise InputError("texture coords lie outside its grid shape; the texture is damaged")

    E = texture.n_entries
    sheets, halfplanes, phi = layout_sheets(texture)
    entries = np.zeros((E, ENTRY_WORDS), dtype=np.uint32)
    entries[:, 0:3] = np.asarray(texture.entry_normal, dtype=np.float32).view(np.uint32)
    entries[:, 3] = covered_area(texture).astype(np.float32).view(np.uint32)
    half = np.zeros((E, 4), dtype=np.float16)
    half[:, 0:3] = np.clip(texture.entry_kd, 0.0, 6e4)
    half[:, 3] = np.clip(texture.entry_ks, 0.0, 6e4)
    entries[:, 4:6] = half.view(np.uint32)
    shininess = np.minimum(np.asarray(texture.entry_shininess, dtype=np.float64), 6e4).astype(np.float16)
    entries[:, 6] = shininess.view(np.uint16).astype(np.uint32) | (np.asarray(texture.entry_direction, np.uint32) << 16)
    entries[:, 8] = sheets.offset.astype(np.float32).view(np.uint32)
    fill_share = np.stack([sheets.fill, sheets.share], axis=1).astype(np.float16)
    entries[:, 9] = fill_share.view(np.uint32).ravel()
    area_slack = np.stack([sheets.area, sheets.slack], axis=1).astype(np.float16)
    entries[:, 10] = area_slack.view(np.uint32).ravel()
    edges = sheet_edges(texture, sheets, sheets.surface)
    entries[:, 11] = edge_words(edges.face, edges.kind, edges.angle)
    # A half-plane has no edges on faces: its words take the edges' angles' bits.
    lines = halfplane_words(halfplanes)
    plain_hp, crease_hp = halfplanes.mask & ~sheets.crease, halfplanes.mask & sheets.crease
    entries[:, 11] = np.where(plain_hp, (entries[:, 11] & 0x7F7) | lines, entries[:, 11])
    # A crease sheet's half-plane keeps its edges on faces (it is a surface
    # sheet where drawn small): its flag (bit 31; a surface sheet's static
    # share tells it from the others') in word 11, its line in word 12, which
    # its linear model leaves (it is shaded flat where drawn in a run).
    entries[:, 11] = np.where(crease_hp, entries[:, 11] | np.uint32(1 << 31), entries[:, 11])
    slopes = sheet_slopes(texture, sheets, sheets.surface)
    # (S11, S12), (S22, dkd_r/du), (dkd_r/dv, dkd_g/du), (dkd_g/dv, dkd_b/du), (dkd_b/dv, sigma).
    sigma = closed_sign(texture)
    stored = stored_sign(sigma, thick_backs(texture))
    model = np.concatenate([slopes.shape, slopes.kd.transpose(0, 2, 1).reshape(E, 6), stored[:, None]], axis=1)
    model = model.astype(np.float16).view(np.uint32)
    entries[:, 7] = model[:, 0]
    entries[:, 12:16] = model[:, 1:5]
    entries[:, 12] = np.where(crease_hp, lines | partner_codes(phi), entries[:, 12])
    # A strip is a half-plane with a far line: no surface sheet, so no
    # linear model in word 12, which takes the far line's offset.
    strips = sheet_strips(texture, sheets, sheets.surface, _no_creases(halfplanes, sheets), sigma)
    near, far = strip_words(strips)
    entries[:, 11] = np.where(strips.mask, (entries[:, 11] & 0x7F7) | near, entries[:, 11])
    entries[:, 12] = np.where(strips.mask, far, entries[:, 12])

    lh = sheet_line_halos(sheets, strips, texture)

    # The GPU grid: GRID_PAD voxels of margin (halos of edges on the outer
    # planes), the texture's voxels first, then the halos' voxels it lacks.
    pshape = shape + 2 * GRID_PAD
    cells = coords + GRID_PAD
    tkeys = cell_keys(cells, pshape)
    hkeys = cell_keys(np.concatenate([edges.halo_cell, lh.cell]) + GRID_PAD, pshape)
    pos = np.minimum(np.searchsorted(tkeys, hkeys), max(M - 1, 0))
    found = (tkeys[pos] == hkeys) if M else np.zeros(len(hkeys), dtype=bool)
    new_keys = np.unique(hkeys[~found])
    halo_vox = np.where(found, pos, M + np.searchsorted(new_keys, hkeys))
    cells = np.concatenate([cells, cell_coords(new_keys, pshape)]) if len(new_keys) else cells
    # Each halo: its sheet's entry with no area (it adds nothing to the
    # voxel's density or colour), its plane in the halo's voxel, its edge.
    halo = entries[edges.halo_row].copy()
    halo[:, 3] = np.float32(0.0).view(np.uint32)
    halo[:, 8] = edges.halo_offset.astype(np.float32).view(np.uint32)
    none = np.zeros((len(halo), MAX_EDGES))
    halo[:, 11] = edge_words(
        np.full((len(halo), MAX_EDGES), -1), np.stack([edges.halo_kind, none[:, 1]], 1),
        np.stack([edges.halo_angle, none[:, 1]], 1), edges.halo_face,
    ) | np.where(crease_hp[edges.halo_row], np.uint32(1 << CREASE_BIT), np.uint32(0))
    halo = np.concatenate([halo, line_halo_entries(entries, lh)])
    voxel_of = np.concatenate([texture.entry_voxel, halo_vox])
    order = np.lexsort((np.arange(len(voxel_of)), np.arange(len(voxel_of)) >= E, voxel_of))
    entries = np.concatenate([entries, halo])[order]
    n_vox = len(cells)
    offsets = np.concatenate([[0], np.cumsum(np.bincount(voxel_of, minlength=n_vox))]).astype(np.uint32)
    dens16 = np.concatenate([np.asarray(texture.density), np.zeros((n_vox - M, K))])
    # float16 ends at 65504; a voxel saturates long before (D > P <= sqrt 3),
    # and an infinity times a zero weight would be NaN on the GPU.
    dens16 = np.minimum(dens16, 6e4).astype(np.float16).ravel()
    if len(dens16) % 2:
        dens16 = np.append(dens16, np.float16(0))
    density = dens16.view(np.uint32)

    bricks = -(-pshape // BRICK)
    bc = cells // BRICK
    bkey = (bc[:, 2] * bricks[1] + bc[:, 1]) * bricks[0] + bc[:, 0]
    ukeys, brick_of = np.unique(bkey, return_inverse=True)
    top = np.full(int(np.prod(bricks)), -1, dtype=np.int32)
    top[ukeys] = np.arange(len(ukeys), dtype=np.int32)
    lc = cells - bc * BRICK
    pool = np.full(len(ukeys) * BRICK**3, -1, dtype=np.int32)
    pool[brick_of * BRICK**3 + (lc[:, 2] * BRICK + lc[:, 1]) * BRICK + lc[:, 0]] = np.arange(
        n_vox, dtype=np.int32
    )

    directions = np.zeros((K, 4), dtype=np.float32)
    directions[:, :3] = texture.directions
    arrays = {"top": top, "pool": pool, "offsets": offsets, "density": density,
              "entries": entries, "directions": directions}  # fmt: skip
    return PackedVolume(arrays, pshape, cells)


@dataclass(eq=False)
class GPUVolume:
    """A texture uploaded once: the arrays of :func:`pack_volume` as 2D
    textures (``textures``, :data:`TEX_WIDTH` texels wide, texture units 0-5
    in that order) and the grid's geometry; ``buffers`` the same arrays as
    shader storage buffers (bindings 0-5), made only when the "plain"
    marching first draws it. ``origin`` is the grid centre."""

    textures: dict[str, moderngl.Texture]
    origin: np.ndarray
    bounds: np.ndarray
    grid_origin: np.ndarray
    voxel_size: float
    shape: np.ndarray
    bricks: np.ndarray
    n_directions: int
    n_voxels: int
    sizes: dict[str, int]
    buffers: dict[str, moderngl.Buffer] = field(default_factory=dict)
    #: The occupied brick cells (x, y, z) as float32 triples (the start pass's instances).
    brick_cells: moderngl.Buffer | None = None
    n_bricks: int = 0
    #: ... and on the CPU, (n_bricks, 3) int64.
    brick_grid: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))

    @property
    def nbytes(self) -> int:
        """Bytes of the arrays uploaded to the GPU (textures; the plain
        marching's storage buffers come on top)."""
        return int(sum(self.sizes.values()))

    @cached_property
    def occupied_corners(self) -> np.ndarray:
        """(8, 3) float64, world: the corners of the occupied bricks'
        bounding box (what :func:`screen_box` projects each frame), found
        once. Empty (0, 3) when no brick is occupied."""
        if self.n_bricks == 0:
            return np.zeros((0, 3))
        lo = self.brick_grid.min(axis=0) * float(BRICK)
        hi = np.minimum((self.brick_grid.max(axis=0) + 1) * float(BRICK), np.asarray(self.shape, np.float64))
        pick = np.array([[i & 1, i >> 1 & 1, i >> 2 & 1] for i in range(8)]) > 0
        return np.asarray(self.grid_origin, np.float64) + self.voxel_size * np.where(pick, hi, lo)


@dataclass(eq=False)
class GPULodVolume:
    """Every level of a texture pyramid uploaded once (``levels[l]``, a
    :class:`GPUVolume` each); a frame ray-marches the one level
    :func:`~aniso3d.rendering.select.volume_level` picks. ``bounds`` covers every level's
    grid, so the clip range does not depend on the level drawn.
    ``last_stats`` is the last frame's choice."""

    pyramid: Pyramid
    levels: list[GPUVolume]
    origin: np.ndarray
    bounds: np.ndarray
    last_stats: dict = field(default_factory=dict)

    @property
    def nbytes(self) -> int:
        return int(sum(v.nbytes for v in self.levels))


@dataclass(frozen=True)
class VolumeOptions(DrawOptions):
    """How the volume is drawn (see the module docstring).

    Attributes:
        step: "dda" (exact voxel chords; the only stepping).
        density: how the density sphere is read, one of :data:`DENSITY_MODES`.
        normal: the shading normal of an entry, one of :data:`NORMAL_MODES`.
        shading: how a run's surface sheets are shaded, one of :data:`SHADING_MODES`.
        opacity: how coverage adds up along the ray, one of :data:`OPACITY_MODES`.
        pixel_error: pyramid uploads only: the largest a voxel of the level
            drawn may be on screen, framebuffer pixels (None: 1).
        march: how the rays find the occupied voxels, one of :data:`MARCH_MODES`
            (the same image; "plain" is the slower first version).
        edges: how the "planar" law counts a sheet's crossing, one of
            :data:`EDGE_MODES`.
        start: where the "skip" marching starts a ray, one of
            :data:`START_MODES` (the same image to float rounding).
        back_hide: the share of a closed surface's back the "planar" law
            hides, in [0, 1] (:data:`BACK_HIDE`; 0: as before it).
    """

    what: ClassVar[str] = "volume"

    step: str = "dda"
    density: str = "facet"
    normal: str = "mean"
    shading: str = "smooth"
    opacity: str = DEFAULT_OPACITY
    pixel_error: float | None = None
    march: str = "skip"
    edges: str = "filtered"
    start: str = "bricks"
    back_hide: float = BACK_HIDE

    def __post_init__(self) -> None:
        _check_choice(self.step, STEPS, "volume step")
        _check_choice(self.edges, EDGE_MODES, "volume edges")
        _check_choice(self.march, MARCH_MODES, "volume marching")
        _check_choice(self.start, START_MODES, "volume ray start")
        _check_choice(self.density, DENSITY_MODES, "density reading")
        _check_choice(self.normal, NORMAL_MODES, "normal")
        _check_choice(self.shading, SHADING_MODES, "volume shading")
        _check_choice(self.opacity, OPACITY_MODES, "opacity law")
        hide = number(self.back_hide, "volume option back_hide (a share)", 0, False)
        if hide > 1.0:
            raise InputError(f"volume option back_hide is a share in [0, 1], got {self.back_hide!r}")
        object.__setattr__(self, "back_hide", hide)
        if self.pixel_error is not None:
            pe = number(self.pixel_error, "volume option pixel_error (pixels)", 0, True)
            object.__setattr__(self, "pixel_error", pe)


class VolumeRenderer:
    """Ray-marches an :class:`~aniso3d.build.texture.AnisoTexture` (one ray per pixel),
    or per frame one level of a :class:`~aniso3d.build.pyramid.Pyramid`."""

    method = "volume"
    Options = VolumeOptions
    options = option_parser(VolumeOptions)

    def __init__(self, gl: GLContext):
        self.gl = gl
        ctx = gl._check()
        if ctx.version_code < REQUIRE_GL:
            raise ResourceError(
                f"the volume renderer needs OpenGL {REQUIRE_GL // 100}.{REQUIRE_GL % 100 // 10} "
                f"(shader storage buffers); this context is {gl.version}"
            )
        self.max_block = int(ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE", 1 << 27))
        defines = {
            "BRICK": BRICK,
            "BACK_HIDE": BACK_HIDE,
            "THICK_CODE": THICK_CODE,
            "ALPHA_MAX": float(np.float32(ALPHA_MAX)),
            "T_MIN": T_MIN,
            "T_MIN_PLAIN": T_MIN_PLAIN,
            "BIG": _BIG,
            "TEX_WIDTH": TEX_WIDTH,
            "TEX_SHIFT": TEX_WIDTH.bit_length() - 1,
            "RUN_SHARE": RUN_SHARE,
            "RUN_PARALLEL": RUN_PARALLEL,
            "RUN_STEEP": RUN_STEEP,
            "RUN_GRAZE": RUN_GRAZE,
            "RUN_GAP": RUN_GAP,
            "RUN_BACK_MIN": RUN_BACK_MIN,
            "RUN_BACK_APART": int(RUN_BACK_APART),
            "RUN_DEFER": int(RUN_DEFER),
            "RUN_FRONT_GAP": -1.0 if RUN_FRONT_GAP is None else float(RUN_FRONT_GAP),
            "RUN_FRONT_FILL": RUN_FRONT_FILL,
            "GRID_PAD": GRID_PAD,
            "CLIP_MARGIN": CLIP_MARGIN,
            "HALF_C_RANGE": HALF_C_RANGE,
            "HALF_PIXELS": HALF_PIXELS,
            "CREASE_BIT": f"{CREASE_BIT}u",
            "FACE_CUT_BIT": f"{FACE_CUT_BIT}u",
            "STRIP_PIXELS": STRIP_PIXELS,
            "STRIP_FOOT": STRIP_FOOT,
        }
        self._defines = defines
        #: Compile the density, normal and opacity modes into the program (one
        #: program per combination drawn, made when first drawn; llvmpipe then
        #: drops the other modes' code: docs/volume_speed.md), else read them
        #: as uniforms (one program for all: the bench's "uniform" case).
        self.compile_modes = True
        #: Program and vertex array of each marching mode (and modes, when
        #: compiled in), made when first drawn.
        self._variants: dict[tuple, tuple[moderngl.Program, moderngl.VertexArray | None]] = {}
        #: Whether the last :meth:`draw` drew the start pass (:data:`START_MODES`).
        self.last_start_pass = False
        #: The start pass's framebuffer and R32F texture (made for a view size).
        self._start: tuple[moderngl.Framebuffer, moderngl.Texture] | None = None
        self.prog, self.vao = self._program(MARCH_MODES[0], VolumeOptions(), start=True)
        #: The last pyramid frame's level choice (see :func:`~aniso3d.rendering.select.volume_level`).
        self.last_lod_stats: dict | None = None
        #: Blend each frame "over" what the framebuffer holds, without depth
        #: test or depth writes (a scene's instances, drawn back to front, with
        #: a black background in the lighting: aniso3d.rendering.scene_draw).
        self.blend_over = False

    def upload(self, texture: AnisoTexture | Pyramid) -> GPUVolume | GPULodVolume:
        """Upload a texture, or every level of a pyramid (:class:`GPULodVolume`)."""
        if isinstance(texture, Pyramid):
            levels: list[GPUVolume] = []
            try:
                for tex in texture:
                    levels.append(self.upload(tex))
            except BaseException:
                for handle in levels:
                    self.release(handle)
                raise
            boxes = np.stack([tex.bounds for tex in texture])
            bounds = np.stack([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)])
            return GPULodVolume(texture, levels, 0.5 * (bounds[0] + bounds[1]), bounds)
        packed = pack_volume_grid(texture)
        arrays = packed.arrays
        for name, arr in arrays.items():
            if arr.nbytes > self.max_block:
                raise ResourceError(
                    f"the volume's '{name}' buffer needs {arr.nbytes / 2**20:.0f} MiB, above this "
                    f"OpenGL's {self.max_block / 2**20:.0f} MiB per shader storage buffer "
                    f"(texture: {texture.n_voxels} voxels, {texture.n_directions} directions, "
                    f"grid {tuple(int(s) for s in texture.shape)}); "
                    "lower --resolution or --directions"
                )
        textures: dict[str, moderngl.Texture] = {}
        try:
            for name, arr in arrays.items():
                textures[name] = self.gl.track(_array_texture(self.gl.ctx, arr, *_TEXTURES[name][1:]))
        except moderngl.Error as exc:
            self.gl.free(*textures.values())
            raise ResourceError(
                f"uploading the volume failed (out of GPU memory?): {exc}"
            ) from None
        bounds = texture.bounds
        shape = packed.shape
        bricks = -(-shape // BRICK)
        occupied = np.flatnonzero(arrays["top"] >= 0)
        cells = np.stack(
            [occupied % bricks[0], occupied // bricks[0] % bricks[1], occupied // (bricks[0] * bricks[1])], axis=1
        )
        try:
            brick_cells = self.gl.track(self.gl.ctx.buffer(cells.astype(np.float32).tobytes())) if len(cells) else None
        except moderngl.Error as exc:
            self.gl.free(*textures.values())
            raise ResourceError(f"uploading the volume failed (out of GPU memory?): {exc}") from None
        return GPUVolume(
            textures=textures,
            origin=0.5 * (bounds[0] + bounds[1]),
            bounds=bounds,
            grid_origin=np.asarray(texture.origin, dtype=np.float64) - GRID_PAD * float(texture.voxel_size),
            voxel_size=float(texture.voxel_size),
            shape=shape,
            bricks=bricks,
            n_directions=texture.n_directions,
            n_voxels=texture.n_voxels,
            sizes={name: int(arr.nbytes) for name, arr in arrays.items()},
            brick_cells=brick_cells,
            n_bricks=len(cells),
            brick_grid=cells,
        )

    def draw(
        self, handle: GPUVolume | GPULodVolume, view: FrameView, fbo=None,
        options: VolumeOptions | None = None, **values,
    ) -> DrawStats:  # fmt: skip
        """Draw into the bound framebuffer (cleared to the background, alpha 0).

        Options: ``options`` (:class:`VolumeOptions`) or the same as keywords;
        ``opacity`` "planar" (default) | "exponential" | "linear" | "split" says
        how coverage adds up along the ray (see the module docstring).
        A pyramid upload (:class:`GPULodVolume`) draws the level
        :func:`~aniso3d.rendering.select.volume_level` picks for ``pixel_error``
        (framebuffer pixels, default 1).
        """
        opts = VolumeOptions.resolve(options, values)
        stats: dict | None = None
        if isinstance(handle, GPULodVolume):
            stats = {}
            level = volume_level(
                handle.pyramid, view.camera, view.size,
                1.0 if opts.pixel_error is None else opts.pixel_error,
                near=view.near, far=view.far, stats=stats,
            )  # fmt: skip
            stats["selection_ms"] = 1000.0 * stats.pop("seconds")
            handle.last_stats = self.last_lod_stats = stats
            handle = handle.levels[level]
        elif opts.pixel_error is not None:
            raise InputError("pixel_error applies to a pyramid upload only (upload a Pyramid)")
        cam = view.camera
        right, up, forward = cam.basis()
        t = float(np.tan(np.radians(cam.fov) / 2))
        rays = ray_base(handle, cam.position, forward, view.near, view.far)
        start = (
            opts.march == "skip" and opts.start == "bricks" and not self.blend_over
            and start_pass_pays(handle, cam.position, forward, view.near, 2.0 * t / float(view.size[1]))
        )  # fmt: skip
        self.last_start_pass = bool(start)
        prog, vao = self._program(opts.march, opts, start=start)
        # Only the pixels the grid can cover run the march (not with
        # blend_over: a scene's instances set their own scissor).
        box = (
            None if self.blend_over or opts.start == "frame"
            else screen_box(handle, cam.position, (right, up, forward), t, view.size)
        )  # fmt: skip
        if start:
            self._start_pass(handle, view, rays, (right, up, forward), t, box)
        GLContext.set_uniforms(
            prog,
            {
                "u_size": (float(view.size[0]), float(view.size[1])),
                "u_forward": tuple(map(float, forward)),
                "u_right": tuple(map(float, right)),
                "u_up": tuple(map(float, up)),
                "u_tan": (t * view.aspect, t),
                **rays,
                "u_shape": tuple(int(s) for s in handle.shape),
                "u_bricks": tuple(int(s) for s in handle.bricks),
                "u_center_g": tuple(float(s) / 2 for s in handle.shape),
                "u_num_dirs": int(handle.n_directions),
                **self._mode_uniforms(opts),
                "u_background": tuple(float(c) for c in view.lighting.background),
            },
        )
        # The sheets' uniforms: compiled out with a law without sheets.
        GLContext.set_uniforms(prog, self._sheet_uniforms(opts, view, t), strict=not self.compile_modes)
        GLContext.set_uniforms(prog, view.lighting.uniforms(), strict=False)
        if opts.march == "plain":
            for binding, buf in enumerate(self._storage_buffers(handle).values()):
                buf.bind_to_storage_buffer(binding)
        else:
            samplers = {_TEXTURES[name][0]: unit for unit, name in enumerate(handle.textures)}
            GLContext.set_uniforms(prog, samplers, strict=False)
            for unit, tex in enumerate(handle.textures.values()):
                tex.use(location=unit)
            if start:
                unit = len(handle.textures)
                GLContext.set_uniforms(prog, {"t_start": unit})
                self._start[1].use(location=unit)
        ctx = self.gl.ctx
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        # A pixel that never reaches alpha 0.5 writes depth 1.0, the clear value.
        ctx.depth_func = "<="
        if self.blend_over:
            ctx.enable(moderngl.BLEND)
            ctx.blend_func = moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA
            ctx.depth_func = "1"  # always
        target = ctx.fbo
        try:
            if box is not None:
                target.scissor = box
            vao.render(moderngl.TRIANGLES, vertices=3)
        finally:
            ctx.depth_func = "<"
            if box is not None:
                target.scissor = None
        if stats is None:
            return DrawStats(drawn=int(handle.n_voxels), unit="voxels")
        return DrawStats(drawn=int(handle.n_voxels), unit="voxels", levels=(int(stats["level"]),), lod=stats)

    def _mode_defines(self, opts: VolumeOptions) -> dict[str, int]:
        """The modes as volume.frag's defines when :attr:`compile_modes`, else none."""
        if not self.compile_modes:
            return {}
        return {
            "DENSITY_MODE": DENSITY_MODES.index(opts.density),
            "NORMAL_MODE": NORMAL_MODES.index(opts.normal),
            "SHADING_MODE": SHADING_MODES.index(opts.shading),
            "OPACITY_MODE": OPACITY_MODES.index(opts.opacity),
        }

    def _mode_uniforms(self, opts: VolumeOptions) -> dict[str, int]:
        """The modes as volume.frag's uniforms, unless compiled in."""
        if self.compile_modes:
            return {}
        return {
            "u_density_mode": DENSITY_MODES.index(opts.density),
            "u_normal_mode": NORMAL_MODES.index(opts.normal),
            "u_shading_mode": SHADING_MODES.index(opts.shading),
            "u_opacity_mode": OPACITY_MODES.index(opts.opacity),
        }

    @staticmethod
    def _sheet_uniforms(opts: VolumeOptions, view: FrameView, tan_half: float) -> dict[str, object]:
        """volume.frag's uniforms of the sheets ("split" and "planar" laws)."""
        return {
            "u_pixel_angle": 2.0 * tan_half / float(view.size[1]),
            "u_sheet_pixels": tuple(float(x) for x in SHEET_PIXELS),
            "u_edge_filter": 1.0 if opts.edges == "filtered" else 0.0,
            "u_back_hide": float(opts.back_hide),
        }

    def _program(
        self, march: str, opts: VolumeOptions, instanced: bool = False, start: bool = False
    ) -> tuple[moderngl.Program, moderngl.VertexArray | None]:
        """The program of a marching mode (:data:`MARCH_MODES`) and of the
        modes of ``opts`` (when compiled in), with the start pass or without
        (:data:`START_MODES`), with its vertex array (None with
        ``INSTANCED``, whose draws make their own)."""
        modes = self._mode_defines(opts)
        key = (march, instanced, start, *sorted(modes.items()))
        if key not in self._variants:
            defines = {**self._defines, **modes}
            if march == "plain":
                defines["PLAIN_MARCH"] = 1
            if instanced:
                defines["INSTANCED"] = 1
            if start:
                defines["START_PASS"] = 1
            prog = self.gl.program("volume.vert", "volume.frag", defines=defines)
            vao = None if instanced else self.gl.track(self.gl.ctx.vertex_array(prog, []))
            self._variants[key] = (prog, vao)
        return self._variants[key]

    def draw_instanced(
        self, handle: GPUVolume, view: FrameView, instances: np.ndarray, options: VolumeOptions | None = None,
    ) -> DrawStats:  # fmt: skip
        """Ray-march several instances of one grid in one instanced draw call,
        in the order of ``instances``, each blended "over" what the
        framebuffer holds (the caller sets the blending, as for
        :attr:`blend_over`). GL draws instances in order, so back to front
        gives the right "over" composition between instances whose boxes do
        not interpenetrate (overlapping boxes compose as wholes, approximately).

        ``instances``: (N, 19) float32 rows of :data:`INSTANCE_FIELDS`: the
        screen box in NDC and the camera moved into each instance's frame
        (:func:`instance_rays`). ``view`` gives the world camera basis (the
        lights are turned by the rotation between the two bases), the
        lighting (world), the size and the field of view.
        """
        opts = VolumeOptions.resolve(options, {})
        prog = self._program(opts.march, opts, instanced=True)[0]
        cam = view.camera
        right, up, forward = cam.basis()
        t = float(np.tan(np.radians(cam.fov) / 2))
        GLContext.set_uniforms(
            prog,
            {
                "u_size": (float(view.size[0]), float(view.size[1])),
                "u_forward": tuple(map(float, forward)),
                "u_right": tuple(map(float, right)),
                "u_up": tuple(map(float, up)),
                "u_tan": (t * view.aspect, t),
                "u_depth_k": float(view.far) / (float(view.far) - float(view.near)),
                "u_shape": tuple(int(s) for s in handle.shape),
                "u_bricks": tuple(int(s) for s in handle.bricks),
                "u_center_g": tuple(float(s) / 2 for s in handle.shape),
                "u_num_dirs": int(handle.n_directions),
                **self._mode_uniforms(opts),
                **self._sheet_uniforms(opts, view, t),
                "u_background": tuple(float(c) for c in view.lighting.background),
            },
            strict=False,
        )
        GLContext.set_uniforms(prog, view.lighting.uniforms(), strict=False)
        if opts.march == "plain":
            for binding, buf in enumerate(self._storage_buffers(handle).values()):
                buf.bind_to_storage_buffer(binding)
        else:
            samplers = {_TEXTURES[name][0]: unit for unit, name in enumerate(handle.textures)}
            GLContext.set_uniforms(prog, samplers, strict=False)
            for unit, tex in enumerate(handle.textures.values()):
                tex.use(location=unit)
        rows = np.ascontiguousarray(instances, dtype=np.float32)
        ctx = self.gl.ctx
        buf = ctx.buffer(rows.tobytes())
        fmt = " ".join(f"{k}f" if f"in_{name}" in prog else f"{4 * k}x" for name, k in INSTANCE_FIELDS) + "/i"
        names = [f"in_{name}" for name, _ in INSTANCE_FIELDS if f"in_{name}" in prog]
        try:
            vao = ctx.vertex_array(prog, [(buf, fmt, *names)])
            try:
                vao.render(moderngl.TRIANGLES, vertices=6, instances=len(rows))
            finally:
                vao.release()
        finally:
            buf.release()
        return DrawStats(drawn=int(handle.n_voxels) * len(rows), unit="voxels")

    def _storage_buffers(self, handle: GPUVolume) -> dict[str, moderngl.Buffer]:
        """The plain marching's storage buffers of ``handle``, read back from
        its textures the first time (the same bytes)."""
        if not handle.buffers:
            try:
                for name, tex in handle.textures.items():
                    n = handle.sizes[name]
                    # An empty buffer cannot be made; 16 bytes of -1/0 read as "nothing".
                    data = tex.read()[:n] if n else np.full(4, -1, np.int32).tobytes()
                    handle.buffers[name] = self.gl.track(self.gl.ctx.buffer(data))
            except moderngl.Error as exc:
                self.gl.free(*handle.buffers.values())
                handle.buffers.clear()
                raise ResourceError(f"uploading the volume failed (out of GPU memory?): {exc}") from None
        return handle.buffers

    def _start_pass(
        self, handle: GPUVolume, view: FrameView, rays: dict, basis: tuple, tan_half: float,
        box: tuple[int, int, int, int] | None,
    ) -> None:  # fmt: skip
        """Draw the start pass (volume_start.vert/.frag) of ``handle`` into the
        renderer's R32F target of the view's size (``self._start``), only in
        the pixels ``box`` (:func:`screen_box`; None: all); the bound
        framebuffer stays bound."""
        ctx = self.gl.ctx
        size = (int(view.size[0]), int(view.size[1]))
        if self._start is None or self._start[1].size != size:
            if self._start is not None:
                self.gl.free(*self._start)
            try:
                tex = self.gl.track(ctx.texture(size, 1, dtype="f4"))
                self._start = (self.gl.track(ctx.framebuffer(color_attachments=[tex])), tex)
            except moderngl.Error as exc:
                raise ResourceError(f"the volume's start pass failed (out of GPU memory?): {exc}") from None
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        fbo = self._start[0]
        prog = self.gl.program("volume_start.vert", "volume_start.frag", defines=self._defines)
        right, up, forward = basis
        GLContext.set_uniforms(
            prog,
            {
                "u_forward": tuple(map(float, forward)),
                "u_right": tuple(map(float, right)),
                "u_up": tuple(map(float, up)),
                "u_tan": (tan_half * view.aspect, tan_half),
                "u_base_c": rays["u_base_c"],
                "u_base_s": rays["u_base_s"],
                "u_center_g": tuple(float(s) / 2 for s in handle.shape),
                "u_shape": tuple(int(s) for s in handle.shape),
                "u_margin": START_MARGIN,
            },
        )
        bound = ctx.fbo
        vao = ctx.vertex_array(prog, [(handle.brick_cells, "3f/i", "in_brick")])
        try:
            fbo.use()
            fbo.scissor = box
            fbo.clear(_BIG, 0.0, 0.0, 0.0)
            ctx.disable(moderngl.DEPTH_TEST)
            ctx.enable(moderngl.CULL_FACE | moderngl.BLEND)
            ctx.front_face = "ccw"
            ctx.cull_face = "back"
            ctx.blend_equation = moderngl.MIN
            vao.render(moderngl.TRIANGLES, vertices=36, instances=handle.n_bricks)
        finally:
            ctx.blend_equation = moderngl.FUNC_ADD
            ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
            vao.release()
            fbo.scissor = None
            bound.use()

    def release(self, handle: GPUVolume | GPULodVolume) -> None:
        if isinstance(handle, GPULodVolume):
            for level in handle.levels:
                self.release(level)
            return
        self.gl.free(*handle.textures.values(), *handle.buffers.values(), handle.brick_cells)
        handle.brick_cells, handle.n_bricks = None, 0
        handle.textures.clear()
        handle.buffers.clear()

    def release_all(self) -> None:
        """Free the renderer's own GPU objects (the programs stay cached in the context)."""
        self.gl.free(*(vao for _, vao in self._variants.values() if vao is not None), *(self._start or ()))
        self._start = None
        self.vao = None
        self._variants.clear()


def _array_texture(ctx: moderngl.Context, arr: np.ndarray, dtype: str, comps: int, empty: int) -> moderngl.Texture:
    """``arr`` (its bytes read as texels of ``comps`` components of ``dtype``)
    as a 2D texture :data:`TEX_WIDTH` texels wide (narrower if it has fewer
    texels), element i at texel (i mod width, i div width); an empty array is
    one texel of ``empty``."""
    flat = np.frombuffer(arr.tobytes(), dtype=np.dtype(dtype))
    flat = flat.reshape(-1, comps) if len(flat) else np.full((1, comps), empty, dtype=flat.dtype)
    n = len(flat)
    width = min(n, TEX_WIDTH)
    rows = -(-n // width)
    limit = int(ctx.info.get("GL_MAX_TEXTURE_SIZE", 16384))
    if rows > limit:
        raise ResourceError(
            f"a volume array of {n} texels does not fit a {TEX_WIDTH} x {limit} texture; "
            "lower --resolution or --directions"
        )
    data = np.zeros((rows * width, comps), dtype=flat.dtype)
    data[:n] = flat
    tex = ctx.texture((width, rows), comps, data.tobytes(), dtype=dtype)
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    tex.repeat_x = tex.repeat_y = False
    return tex


def start_pass_pays(handle: GPUVolume, eye, forward, near: float, pixel_angle: float) -> bool:
    """Whether :meth:`VolumeRenderer.draw` draws the start pass (float64,
    vectorised over the occupied bricks): every occupied brick's box, widened
    by :data:`START_MARGIN` voxels and a voxel more, lies half a voxel or
    more in front of the eye (so a ray enters the first it meets through a
    front face, the only faces the pass draws, and the pass, which clips only
    at the eye's plane, draws the whole face; a box across the near plane
    then gives an entry before it, and the ray starts at the near plane as
    before), and a voxel at the front-most box's depth spans at least
    :data:`START_PIXELS` pixels (``pixel_angle``: radians a pixel spans).
    ``near`` is the near plane's distance (world units), only for the check
    that it lies in front of the eye."""
    if handle.n_bricks == 0:
        return False
    h = handle.voxel_size
    pad = (START_MARGIN + 1.0) * h
    shape = np.asarray(handle.shape, dtype=np.float64)
    lo = handle.brick_grid * float(BRICK)
    hi = np.minimum(lo + BRICK, shape)
    f = np.asarray(forward, dtype=np.float64)
    # Each box's nearest corner along forward: per axis the end facing the eye.
    corner = np.asarray(handle.grid_origin, dtype=np.float64) + np.where(f > 0, lo, hi) * h - np.sign(f) * pad
    front = float(np.min((corner - np.asarray(eye, dtype=np.float64)) @ f))
    return float(near) > 0.0 and front > 0.5 * h and h >= START_PIXELS * front * pixel_angle


def screen_box(
    handle: GPUVolume, eye, basis, tan_half: float, size: tuple[int, int]
) -> tuple[int, int, int, int] | None:
    """The pixels (x, y, width, height; y up, as OpenGL's scissor) that the
    occupied bricks' bounding box projects to, a pixel wider each side, or
    None (every pixel) when a corner of that box lies within half a voxel of
    the eye's plane or behind it. volume.frag discards the rays that miss the
    grid, but on llvmpipe each discarded pixel still costs its ray's set-up,
    about 190 ms of CPU time a 1024^2 frame (docs/volume_speed.md, the screen
    box's findings). ``basis``:
    the camera's right, up, forward (unit); ``tan_half``: tan(fov / 2)."""
    if handle.n_bricks == 0:
        return (0, 0, 0, 0)
    right, up, forward = (np.asarray(a, np.float64) for a in basis)
    rel = handle.occupied_corners - np.asarray(eye, np.float64)
    z = rel @ forward
    if float(z.min()) <= 0.5 * handle.voxel_size:
        return None
    w, ht = int(size[0]), int(size[1])
    ty = float(tan_half)
    tx = ty * w / ht
    x, y = (rel @ right) / (z * tx), (rel @ up) / (z * ty)
    px0 = max(0, math.floor((float(x.min()) * 0.5 + 0.5) * w) - 1)
    px1 = min(w, math.ceil((float(x.max()) * 0.5 + 0.5) * w) + 1)
    py0 = max(0, math.floor((float(y.min()) * 0.5 + 0.5) * ht) - 1)
    py1 = min(ht, math.ceil((float(y.max()) * 0.5 + 0.5) * ht) + 1)
    return (px0, py0, max(0, px1 - px0), max(0, py1 - py0))


def ray_base(
    handle: GPUVolume, eye, forward, near: float, far: float
) -> dict[str, float | tuple[float, float, float]]:
    """The float64 part of volume.frag's rays, as its uniforms.

    A pixel's ray is ``eye + s (forward + lat)``, s the distance along the
    view axis and ``lat`` the pixel's offset on the plane ``s = 1`` (normal
    to the axis). Rebuilding it in float32 from the eye's grid coordinates
    loses ``|eye| * 6e-8`` voxels, 8 voxels at 1e8 voxels away. Instead the
    eye is moved here, in float64, by ``s_b`` along the axis to the depth of
    the near side of the grid's bounding sphere (``s_b = 0``, the eye itself,
    when the eye is that near or the grid behind it): the base ``b``,
    ``u_base_c`` in grid coordinates relative to the grid centre. Each pixel
    starts its ray where it crosses the base's plane, ``b + s_b lat``, and
    measures its parameter from there; the near and far planes are passed as
    distances from that plane (``u_near_b``, ``u_far_b``, voxel units) and the
    depth is rebuilt from them (``u_depth_k = far / (far - near)``).

    Every float32 quantity of a ray that meets the grid is then of the order
    of the grid size plus its offset from the view axis at its depth (which
    float32 holds to ~1e-7 of the half-view width there, far below a pixel),
    whatever the eye's distance. Clipping to the near plane stays exact: the
    ray starts at ``u_near_b / cos`` from its origin, before it (negative)
    when the base lies past the near plane.
    """
    h = handle.voxel_size
    center_g = np.asarray(handle.shape, dtype=np.float64) / 2
    f = np.asarray(forward, dtype=np.float64)
    eye_c = (np.asarray(eye, dtype=np.float64) - handle.grid_origin) / h - center_g
    radius = float(np.linalg.norm(center_g))
    s_b = max(0.0, float(-eye_c @ f) - radius)
    near_b, far_b = float(near) / h - s_b, float(far) / h - s_b
    return {
        "u_base_c": tuple(float(x) for x in eye_c + s_b * f),
        "u_base_s": s_b,
        "u_near_b": near_b,
        "u_far_b": far_b,
        "u_depth_k": float(far) / (float(far) - float(near)),
    }


#: Per-instance attributes of :meth:`VolumeRenderer.draw_instanced` (name in
#: volume.vert without ``in_``, float32 components), in row order.
INSTANCE_FIELDS = (("box", 4), ("forward", 3), ("right", 3), ("up", 3), ("base_c", 3), ("planes", 3))


def instance_rays(
    grid_origin: np.ndarray, voxel_size: np.ndarray, shape: np.ndarray, eye: np.ndarray, axes: np.ndarray,
    near: np.ndarray, far: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """:func:`ray_base` for many instances at once (float64, vectorised):
    (N, 15) rows ``forward, right, up, base_c, (base_s, near_b, far_b)`` of
    :data:`INSTANCE_FIELDS` after the box. Per instance: ``grid_origin``
    (N, 3), ``voxel_size`` (N,), ``shape`` (N, 3) of the grid drawn, and the
    camera in the instance's frame: ``eye`` (N, 3), ``axes`` (N, 3, 3) right,
    up, forward (unit), ``near``/``far`` (N,) (frame units, divided by the
    instance's scale)."""
    h = np.asarray(voxel_size, dtype=np.float64)
    center_g = np.asarray(shape, dtype=np.float64) / 2
    f = axes[:, 2]
    eye_c = (np.asarray(eye, dtype=np.float64) - grid_origin) / h[:, None] - center_g
    radius = np.linalg.norm(center_g, axis=1)
    s_b = np.maximum(0.0, -np.einsum("ni,ni->n", eye_c, f) - radius)
    planes = np.stack([s_b, near / h - s_b, far / h - s_b], axis=1)
    return np.concatenate([f, axes[:, 0], axes[:, 1], eye_c + s_b[:, None] * f, planes], axis=1)


def _check_choice(value, choices: tuple[str, ...], what: str) -> None:
    if value not in choices:
        raise InputError(f"unknown {what} {value!r}; choose one of {', '.join(choices)}")
