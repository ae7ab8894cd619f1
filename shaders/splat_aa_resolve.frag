#version 330
// Splat renderer (c), compositing pass of quality "high" (coverage-aware),
// fragment stage (vertex stage: splat_resolve.vert, one triangle).
// In: u_layer[i], LAYERS layers front to back, each (sum of RGB c, sum of c)
// over its fragments (c: the fraction of the pixel a splat covers; see
// splat.frag, PASS 2 with AA): layer k < LAYERS - 1 holds the k-th surface
// from the front, the last every surface from there on; u_surfaces
// (splat_surfaces.frag), the number of surfaces in its w >> 16 and surface
// 0's first slice in its w & 0xFFFF; u_span, a surface's span in slices; u_visible,
// the visibility pass's linear depth (t - near) / (far - near), pushed.
// The rule (aniso3d/rendering/splat/reference.py is its NumPy twin):
//   within a surface, splats tile: its coverage is a = min(1, sum c);
//   the nearest surface is whole (a = 1) where the mean of min(1, sum) over
//     the pixel and its four neighbours reaches CLOSE_MEAN (CLOSE_MEAN_SIDED
//     where the pixel holds a one-sided splat, u_visible's blue 0), a neighbour
//     counting (0 otherwise, and off the image) when its nearest surface
//     starts less than CLOSE_REACH u_span slices from this one's, plus,
//     where the pixel holds a one-sided splat (CLOSE_SLOPE), the slices its
//     surface's depth changes across a pixel (u_visible's least reach past
//     its start: a closed surface at a grazing angle), and the
//     pixel's own sum reaches CLOSE_OWN (a speck is not its surface): sub-pixel
//     footprints (boxes at the splats' centres) do not tile a sheet exactly,
//     so its sums scatter about 1 where it is whole, and what lies behind
//     would show through every pixel below 1;
//   the last layer holds n = surfaces - (LAYERS - 1) surfaces, taken to share
//     its sum equally: a = 1 - (1 - min(1, sum c / n))^n (exact for equal
//     ones, less than independent unequal ones would cover); its colour
//     sums were weighted (splat.frag, PASS 2), so where n > 1 its sum of c
//     is the pixel's (u_cover) less the other layers';
//   surfaces in front hide those behind at random: front to back, with T the
//     transmittance left (starts at 1), each layer adds T a of its
//     coverage-weighted mean colour and T *= 1 - a (an opaque layer ends it).
// Out, by u_mode (aniso3d.rendering.splat.coverage.HighPass.composite), C the colour so
// composited (premultiplied):
//   0 (over what the target holds):  (C, 1 - T), blended src + (1 - src.a) dst;
//   1, 2 (under it):  the positive, then the negative part of
//                     C - (1 - T) u_background, alpha 1 - T;
// and the visible layer's window depth. Pixels no splat reached are
// discarded, so whatever the target holds there stays.
#ifndef LAYERS
#define LAYERS 4
#endif
#ifndef CLOSE_SLOPE  // injected from aniso3d/rendering/splat/params.py (AA_CLOSE_SLOPE)
#define CLOSE_SLOPE 1
#endif
#ifndef CLOSE_MEAN  // injected from aniso3d/rendering/splat/params.py (AA_CLOSE, AA_CLOSE_SIDED)
#define CLOSE_MEAN 0.9
#define CLOSE_REACH 3.0
#define CLOSE_MEAN_SIDED 0.9
#endif
#ifndef CLOSE_OWN  // injected from aniso3d/rendering/splat/params.py (AA_CLOSE_OWN)
#define CLOSE_OWN 0.1
#endif

uniform sampler2D u_layer[LAYERS];
uniform usampler2D u_surfaces;
uniform sampler2D u_cover;     // the pixel's coverage sum in r (splat_surfaces.frag)
uniform sampler2D u_visible;  // linear depth (t - near) / (far - near), pushed
uniform vec2 u_depth;          // (K, t0 - near): window depth = K (t - near) / t
uniform float u_near;
uniform float u_range;         // far - near
uniform vec3 u_background;
uniform float u_span;          // slices one surface spans (splat_surfaces.frag)
uniform vec2 u_slices;         // (lo, scale): slice coordinate (z - lo) scale of a linear depth z
uniform int u_mode;

out vec4 f_color;

// One layer of n surfaces, whose coverages sum to total (acc.a, but for a
// last layer of weighted sums) (the loop over layers is unrolled below, the
// sampler array taking constant indices); is_whole: coverage 1.
void layer(vec4 acc, float n, float total, bool is_whole, inout vec3 colour, inout float trans) {
    if (acc.a > 0.0) {
        float a = is_whole ? 1.0 : n > 1.0 ? 1.0 - pow(1.0 - min(total / n, 1.0), n) : min(total, 1.0);
        colour += trans * a * (acc.rgb / acc.a);
        trans *= 1.0 - a;
    }
}

#define LAYER(i) \
    acc = texelFetch(u_layer[i], px, 0); \
    if (i < LAYERS - 1) front += acc.a; \
    layer(acc, i == LAYERS - 1 ? last : 1.0, i == LAYERS - 1 && last > 1.0 ? max(cover - front, 0.0) : acc.a, \
          false, colour, trans)

// What a neighbour q adds to the whole-surface test: min(1, its first
// layer's sum) where its nearest surface starts within `within` slices of
// start, else 0 (and off the image).
float neighbour(ivec2 q, ivec2 size, float start, float within) {
    if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) return 0.0;
    float c = texelFetch(u_layer[0], q, 0).a;
    float s = float(texelFetch(u_surfaces, q, 0).w & 0xFFFFu);
    return c > 0.0 && abs(s - start) < within ? min(c, 1.0) : 0.0;
}

// Whether the nearest surface, summing to own here and starting at slice
// start, is whole (see the top); slope: the slices its depth changes across
// a pixel, where it counts. Four calls, not a loop over an array of
// offsets: llvmpipe puts an indexed local array in memory.
bool whole(ivec2 px, float own, float start, float mean, float slope) {
    // Above 1 it is whole anyway; below 5 mean - 4 the neighbours cannot
    // make it; below CLOSE_OWN it is a speck, not this pixel's surface.
    if (!(own >= max(5.0 * mean - 4.0, CLOSE_OWN) && own < 1.0)) return false;
    ivec2 size = textureSize(u_layer[0], 0);
    float within = CLOSE_REACH * u_span + slope;
    float sum = own + neighbour(px + ivec2(1, 0), size, start, within) + neighbour(px - ivec2(1, 0), size, start, within)
              + neighbour(px + ivec2(0, 1), size, start, within) + neighbour(px - ivec2(0, 1), size, start, within);
    return sum >= 5.0 * mean;
}

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec4 seen = texelFetch(u_visible, px, 0);
    float visible = seen.r;  // 1 where no splat was drawn
    if (!(visible < 1.0)) discard;
    // A closed surface seen from outside (a one-sided splat: blue 0) has no holes.
    float mean = seen.b < 0.5 ? CLOSE_MEAN_SIDED : CLOSE_MEAN;
    vec3 colour = vec3(0.0);
    float trans = 1.0;
    uint sw = texelFetch(u_surfaces, px, 0).w;
    float last = max(float(sw >> 16) - float(LAYERS - 1), 1.0);
    float cover = texelFetch(u_cover, px, 0).r;
    vec4 first = texelFetch(u_layer[0], px, 0);
    vec4 acc;
    float front = first.a;
    float start = float(sw & 0xFFFFu);
    float slope = CLOSE_SLOPE != 0 && seen.b < 0.5 ? max(floor((seen.g - u_slices.x) * u_slices.y) - start, 0.0) : 0.0;
    layer(first, LAYERS == 1 ? last : 1.0, first.a, LAYERS > 1 && whole(px, first.a, start, mean, slope), colour, trans);
#if LAYERS > 1
    LAYER(1);
#endif
#if LAYERS > 2
    LAYER(2);
#endif
#if LAYERS > 3
    LAYER(3);
#endif
#if LAYERS > 4
    LAYER(4);
#endif
#if LAYERS > 5
    LAYER(5);
#endif
#if LAYERS > 6
    LAYER(6);
#endif
    if (!(trans < 1.0)) discard;
    if (u_mode == 0) {
        f_color = vec4(colour, 1.0 - trans);
    } else {
        vec3 x = colour - (1.0 - trans) * u_background;
        f_color = vec4(max(u_mode == 1 ? x : -x, 0.0), 1.0 - trans);
    }
    float lin = visible * u_range;  // t - near
    gl_FragDepth = u_depth.x * lin / (u_near + lin);
}
