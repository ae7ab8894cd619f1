"""Measured parameters of the blended draw passes: the accumulation texture of
``quality="blend"`` and the layers, pixel filter and regimes of
``quality="high"`` (see :mod:`aniso3d.rendering.splat.coverage`)."""

from __future__ import annotations

#: Accumulation texture type of ``quality="blend"``: half floats change at most
#: one pixel in a hundred by one grey level against float32 (tree, sphere),
#: for half the memory (RGBA16F; 32 MB at 2048 x 2048).
ACCUM_DTYPE = "f2"
#: Pixel filter of ``quality="high"`` (shaders/splat_filter.glsl): 0 the box
#: of one pixel, the ground truth's (supersampling averages each pixel's
#: samples); 1 the tent of radius 1 px (bilinear weights); 2 the quadratic
#: B-spline of radius 1.5 px. All three are B-splines, so a splat keeps its
#: projected area wherever it lies on the pixel grid. Measured on the default
#: tree at 512 x 512 against 8 x 8 supersampled polygons at the cameras of
#: demos/bench_splat_aa.py (distance scales 1 to 18), PSNR in the tree's box:
#: the box 30.2 to 34.1 dB; the tent 1.1-2.9 dB and the B-spline 2.1-4.1 dB
#: lower (blurrier than the truth, and more coverage spread past silhouettes).
AA_FILTER = 0
#: Layers of ``quality="high"``: the first AA_LAYERS - 1 surfaces of a pixel
#: from the front, one layer each, and every surface from there on in the
#: last (at most 7, one draw buffer each; their starts share 128 bits). A surface is a run of marked depth
#: slices (see AA_SLICES and aniso3d.rendering.splat.reference).
AA_LAYERS = 4
#: Whether the last layer of ``quality="high"`` weighs each surface's colour
#: by what the surfaces in front of it leave (aniso3d.rendering.splat.reference,
#: rule step 5); False: an equal-weight mean of its surfaces (the earlier
#: rule, kept for the bench's comparison).
AA_LAST_WEIGHTS = True
#: Depth slices of the per-pixel occupancy mask of ``quality="high"`` over the
#: cloud's depth range in the view (a multiple of 32, at most 4096; one bit
#: each, AA_SLICES / 8 bytes per pixel). A fragment marks the slices within
#: its tolerance (``push`` times its larger half-axis) of its depth; a run of
#: marked slices is one surface, so two surfaces are told apart when a slice
#: or more lies between their tolerance intervals.
AA_SLICES = 512
#: Depth one surface of ``quality="high"`` spans, in units of ``push`` times a
#: typical (median) splat's larger half-axis: a pixel's nearest occupied
#: slice starts a surface, which takes every fragment within this depth; the
#: next occupied slice beyond starts the next surface.
AA_SPAN = 2.0
#: The least span, in slices: a surface always takes the slice after its
#: first, so a sheet whose fragments' depths straddle a slice boundary stays
#: one surface. At a span of 1 a sheet crossing a boundary split in two
#: surfaces that composed as independent layers: holes in a lawn seen at
#: 15 degrees (the mixed scene minified: FLIP 0.0293 at 1, 0.0265 at 2; at 3
#: the lattice lost 2 dB, its beams' surfaces merging).
AA_SPAN_MIN = 2.0
#: When quality "high" takes a pixel's nearest surface as whole (coverage 1):
#: (mean, reach): the mean of min(1, sum of its coverages) over the pixel and
#: its four neighbours is at least ``mean``, a neighbour counting where its
#: nearest surface starts less than ``reach`` spans (the ``span`` of AA_SPAN,
#: in slices) from this one's (so the pixel's own sum is at least
#: 5 mean - 4). Sub-pixel footprints (boxes of the true area at the splats'
#: centres) do not tile a sheet exactly: inside a minified smooth blob the
#: sums scatter from 0.83 to 1.16 (1st to 99th percentile), and its back
#: showed through every pixel below 1 as a speckle. Measured on the corpus's
#: close and minified cameras (docs/splat_aa.md): reach 1 / 2 / 3 / 4 spans
#: (at 1 the blob's rim, whose depth changes fast, kept its speckle), mean
#: 0.85 / 0.9 / 0.95, and a further floor on the pixel's own sum of 0.7 or
#: 0.8 (slightly worse on the blob and shell, none better); unclamped
#: neighbour sums closed the edges of resolved splats (sums up to the size
#: factor squared), 0.12 dB off the lattice close up.
AA_CLOSE = (0.9, 3.0)
#: The ``mean`` of AA_CLOSE where the pixel holds a one-sided splat whose
#: back is culled (a closed surface seen from outside, which has no holes):
#: close up, resolved discs of a curved closed surface left pinholes that
#: showed the background (the blob at 128^3, voxels of 3.4 pixels). Measured
#: on the corpus's one-sided scenes (docs/splat_aa.md, bench_splat_rim
#: --closure): 0.8 gives the blob +1.7 dB close up and every other scene
#: within 0.1 dB; 0.7 gives the blob +2.6 dB but the cube -3.6 dB minified
#: (its edges closed where they are not whole), 0.6 more so.
AA_CLOSE_SIDED = 0.8
#: Where the pixel holds a one-sided splat, a neighbour counts in that test
#: when its nearest surface starts within CLOSE_REACH spans plus the slices
#: this pixel's nearest surface's depth changes across a pixel (its least
#: reach, :data:`AA_SURFACE_REACH`, past its start): a closed surface seen
#: at a grazing angle (a low-poly head's brow, a truck's roof at 84 degrees
#: from their normals) changes depth by several slices a pixel, its
#: neighbours' surfaces did not count, and a band of it drew as a sieve of
#: background (demos/bench_pinholes.py --rule slope, docs/splat_aa.md).
AA_CLOSE_SLOPE = True
#: ... and in either case the pixel's own sum must reach this: with the
#: sided mean, 5 x 0.8 - 4 = 0 set no floor, so a speck of a sheet lying
#: just in front of a closed surface (a scan's stray faces, covering 1 % of
#: the pixel, its fragments pulled up to two pixels towards the eye) was
#: taken for the pixel's whole surface, among neighbours that are whole,
#: and painted it its own dark colour (a 1M-triangle bunny's tail). On the
#: corpus and eleven meshes of other tools at both bench cameras, 0.1
#: changes at most 20 pixels a view and no PSNR by more than -0.17 dB (the
#: building close up, 9 pixels), the chair +0.37 and the monkey +0.31
#: minified; 0.25 reopened the blob's pinholes close up (-0.11 dB)
#: (demos/sweep_close_own.py, docs/splat_aa.md).
AA_CLOSE_OWN = 0.1
#: Whether, in quality "high", a one-sided point (culled from behind) is
#: dropped where the surface meeting it at a clip plane lies in front of it
#: (the crease partner's angle, :mod:`~aniso3d.rendering.splat.clips`). No:
#: that surface is the point's closed surface too, wound alike, and there it
#: faces away from the eye and is culled (or the point itself faces away),
#: so it hides nothing; dropped, a floor's splats along a lip seen from
#: beyond it left a line of background (a truck's roof, a CAD part's
#: inner corners; demos/bench_pinholes.py --rule sided, docs/splat_aa.md).
AA_PARTNER_HIDES_SIDED = False
#: A fragment's depth in quality "high" is where its pixel's ray meets the
#: splat's plane, kept within the splat's bounding sphere grown by this many
#: pixels (at the splat's depth): the fragments of a tilted surface tiled by
#: splats far smaller than a pixel meet that ray at the surface's one depth,
#: so they stay one surface (the bounding sphere alone split a plane tilted
#: 60 degrees into several, letting a quarter of the background through).
AA_PLANE_REACH = 2.0
#: How far the nearest surface of a pixel in quality "high" reaches beyond its
#: span where the pixel holds a closed surface seen from outside (one-sided
#: splats, their backs culled): each such fragment's depth changes across
#: this many pixels (where the pixel's ray meets its splat's plane; at most
#: its bounding sphere's depth), and the nearest surface spans from the
#: least of its pixel's fragments' depths plus those changes, if that lies
#: beyond its first slice. A closed surface nearly along the view ray (its
#: rim) changes depth fast across a pixel, and its splats' planes, each
#: extended to the ray, meet it at scattered depths: with the span alone its
#: fragments split into several surfaces that composed as independent
#: layers, and the background showed through the rim of a minified blob as
#: a speckle. Closed surfaces facing the eye can only lie a solid's thickness
#: apart; two-sided splats (leaves, open sheets) keep the span alone, but
#: surface sheets' where they graze the ray (AA_SHEET_REACH). 0: the span
#: alone everywhere.
AA_SURFACE_REACH = 1.0
#: Whether two-sided splats of surface sheets (:attr:`~aniso3d.build.points.PointCloud.sheet`:
#: their entry fills its plane's section of the voxel, a surface that goes on,
#: not a leaf inside it) reach as closed surfaces' do (AA_SURFACE_REACH),
#: where they graze the ray (AA_SHEET_GRAZE) and chained (AA_SHEET_CHAIN). An
#: open sheet seen at a grazing angle along a fold (the corpus shell) changes
#: depth as fast as a closed surface's rim, its fragments split into surfaces
#: that composed as independent layers, and the background showed through
#: the folds as light lines. Leaves and blades in a voxel are not sheets:
#: letting every two-sided splat of coherent normals reach cost the tree and
#: the grass minified.
AA_SHEET_REACH = True
#: A two-sided sheet's fragment reaches only where its depth changes across
#: AA_SURFACE_REACH pixels by at least this many spans (a grazing sheet):
#: a sheet nearer to facing the eye lies within its span, and reaching by
#: less only took in what lies just behind (the wall behind the room's
#: headboard, the floor behind its front wall's bottom edge; ungated, the
#: room lost 3 dB minified). Measured on the corpus (docs/splat_aa.md,
#: bench_splat_sheets): at 2 the shell gains 0.6 dB more minified and the
#: tree loses 0.08 dB there (at 3, 0.04).
AA_SHEET_GRAZE = 3.0
#: Where a pixel holds no closed surface seen from outside, its nearest
#: surface reaches only as far as its slices are chained: each slice it
#: takes extends it to this many spans beyond, up to the reach. Unchained,
#: a bed top's reach at a grazing angle took in the headboard behind its
#: edge; a closed surface's rim keeps the reach whole (chained, the blob's
#: rim split again). Measured as AA_SHEET_GRAZE: at 2 the shell +0.17 dB
#: minified and the tree -0.06; at 1 the shell -0.92.
AA_SHEET_CHAIN = 1.5
#: A splat whose true projected area is below AA_REGIME[0]^2 pixels is drawn as
#: a filtered box of its true area; above AA_REGIME[1]^2, as its exact shape
#: with the size factor (which closes the gaps between resolved splats); a
#: smooth blend between. Measured: (0.5, 2) and (2, 5) are 0.75 and 0.1 dB
#: below (1, 3) at the nearest camera, equal from the third on.
AA_REGIME = (1.0, 3.0)
#: In quality "high" a splat whose pixel box (with the filter's reach) is wider
#: than this many pixels is shaded per pixel in the visible layer (through the
#: geometry path); smaller ones take the colour shaded once at their centre,
#: whose view vector differs from their pixels' by under 0.7 degrees (40
#: degree field of view, 1024 pixels). Shading code in the sprites' shader
#: cost 70 ms per 1024 x 1024 frame of the tree on llvmpipe even where no
#: pixel ran it; at 8 px, every block of that frame took the (slower)
#: geometry path.
AA_SHADE_BOX = 32.0
#: Texture type of the layers: AA_LAYERS targets, 80 bytes per pixel
#: (80 MiB at 1024 x 1024). Half floats drop small coverages added to large
#: sums; that happens to help where the crown's fringe is over-covered (0.5
#: and 1.6 dB higher PSNR at the two farthest cameras), which is no reason to
#: rely on it.
AA_DTYPE = "f4"


def filter_radius() -> float:
    """Reach of the coverage-aware pixel filter, pixels (splat_filter.glsl)."""
    return {0: 0.5, 1: 1.0, 2: 1.5}[AA_FILTER]
