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
#: Depth layers of ``quality="high"``: the visible one and AA_SLABS - 1 behind
#: it (at most 7; at most 4 from AA_DEEP on). Measured as above (mean PSNR over
#: the five cameras): 4 layers growing by 4, 32.5 dB; 6 growing by 2, 32.6 dB
#: for about 10 % more time; 3 growing by 8, 32.4 dB; 2 (first deep layer 1)
#: 32.5 dB, but see AA_DEEP.
AA_SLABS = 4
#: Each layer behind the visible one is this many times as thick as the one
#: before; the first is ``push`` times a typical (median) splat's larger
#: half-axis.
AA_GROWTH = 4.0
#: First layer whose splats are taken to hide each other at random (coverage
#: 1 - exp(-sum), resolved splats excepted) rather than to tile one surface;
#: the layers before fill the pixel additively. Measured: with 1, a surface
#: seen at a grazing angle (a sphere's rim) spans the boundary and its
#: coverage flickers with the view (0.7 % of pixels of a telephoto sphere change
#: by more than 2 levels between 1e4 and 1e7 units away; 0.1 % with 2); with 3
#: the tree's mean PSNR drops by 0.9 dB (its crown is no surface). So 2.
AA_DEEP = 2
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
#: Texture type of the layers: AA_SLABS + 1 targets, 80 bytes per pixel
#: (80 MiB at 1024 x 1024). Half floats drop small coverages added to large
#: sums; that happens to help where the crown's fringe is over-covered (0.5
#: and 1.6 dB higher PSNR at the two farthest cameras), which is no reason to
#: rely on it.
AA_DTYPE = "f4"


def filter_radius() -> float:
    """Reach of the coverage-aware pixel filter, pixels (splat_filter.glsl)."""
    return {0: 0.5, 1: 1.0, 2: 1.5}[AA_FILTER]
