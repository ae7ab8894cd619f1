#version 330
#ifdef AA
// Image atomics (OpenGL 4.2; the volume renderer already needs 4.3).
#extension GL_ARB_shader_image_load_store : require
// Image units set in the shader (layout binding).
#extension GL_ARB_shading_language_420pack : require
#endif
// Splat renderer (c), fragment stage: the exact ray-splat intersection.
// In: SplatData (flat, from splat.vert or splat.geom; see splat.vert for the
// homography rows hu, hv, hw, hc, over pixel offsets from SplatData.org),
// gl_FragCoord. The intersection reads no uniform (splat.vert passes what it
// needs per splat: on llvmpipe a uniform costs a gather per load). Without
// AA, PASS 2 and FORWARD also read u_ray (columns f, R, U: the eye ray of
// NDC (x, y) is f + x R + y U), u_viewport, u_visible (PASS 2) and
// lighting.glsl's. With AA the sprites read only the images u_mask and
// u_surfaces; the geometry path's per-pixel shading reads u_ray,
// u_viewport, u_shade_box and lighting.glsl's.
// Defines: ROUND (0: square |u|, |v| <= 1; 1: disc/ellipse u^2 + v^2 <= 1,
// the ellipse being a disc in stretched axes); PASS:
//   0 (geometry)   out: the point's id (f_id, unsigned), exact gl_FragDepth;
//                  splat_deferred.frag shades the visible point of each pixel;
//   1 (visibility) out: gl_FragDepth pushed back by SplatData.push only;
//   2 (accumulate) out: (RGB * w, w), w a Gaussian of the splat radius, for
//                  additive blending, from fragments no farther than the
//                  visibility depth in u_visible (tested here, so hidden
//                  fragments are never shaded); no depth attachment.
// A pixel is drawn when its ray meets the splat's plane in front of the eye,
// between near and far, inside the shape; and the pixel holding the projected
// centre is always drawn (at the centre's depth), so no splat vanishes. There
// is no division by the ray-plane cosine: a grazing ray fails w' > 0 cleanly.
//
// AA (quality "high", coverage-aware): a fragment carries the fraction c of
// its pixel the splat covers, the splat's shape convolved with the pixel
// filter (splat_filter.glsl) and sampled at the pixel centre:
//   sub-pixel regime: the splat as an axis-aligned box of its true projected
//     area (SplatData.box, from splat.vert): c = amplitude x the filtered
//     box along x times along y. The filter's copies at the pixel centres sum
//     to 1, so the splat's c summed over the pixels is its true projected
//     area wherever it lies: no splat gets a whole pixel, none vanishes;
//   resolved regime: the exact (perspective) shape with the size factor, each
//     pair of edges filtered across its distance in pixels, (1 - u) / |grad u|
//     (a disc's or ellipse's across (1 - r) / |grad r|);
//   in between (SplatData.regime) a blend. No centre pixel is forced; only
//   the box splat.vert computed (SplatData.clip) is drawn, sprite or quad.
// Fragments with c < MIN_COVERAGE are dropped in both passes. A fragment's
// depth z is linear, (t - near) / (far - near) (a surface may be far thinner
// than a step of window depth far away), the plane's where the pixel's ray
// meets it, else the centre's, clamped to zrange (the bounding sphere grown
// by a few pixels: see splat.vert). The pixel's fragments are grouped into
// surfaces by depth (aniso3d/rendering/splat/reference.py, the NumPy twin,
// states the rule):
//   PASS 1 writes the pushed depth z + push (the visible depth, kept for
//     compositing with other draws; the least by a MIN blend), z +
//     surface_reach() (the least by a MIN blend: how far beyond its span the
//     pixel's nearest surface reaches), 0 for a one-sided splat whose back
//     is culled and 1 otherwise (a MIN blend: whether the pixel holds a
//     closed surface seen from outside), and c (summed by an additive
//     blend: the pixel's coverage sum), and sets the bit of
//     z's slice in the pixel's occupancy mask u_mask (SLICES slices over the
//     cloud's depths, u_slices) by atomic OR; splat_surfaces.frag then finds
//     where the pixel's surfaces start (u_surfaces);
//   PASS 2 adds (RGB c, c) to the layer of the fragment's surface: layer k
//     holds the k-th surface from the front, the last (LAYERS - 1) every
//     surface from there on, where a fragment of the layer's j-th surface
//     adds (RGB c w, c w), w = (1 - a_s)^j, a_s = min(1, the pixel's
//     coverage sum (u_cover) / its number of surfaces): what the j surfaces
//     in front leave of it had they the mean coverage each (j from the
//     fragment's depth, the layer's surfaces taken to spread evenly from its
//     first slice to the first slice of the pixel's last surface). A splat whose box is wider than u_shade_box
//     pixels is shaded per fragment in layer 0 (in the geometry path, which
//     aniso3d/rendering/splat sends those splats through); any other
//     fragment takes its splat's colour shaded once at the centre
//     (SplatData.rgb). splat_aa_resolve.frag composites the layers.
#include "lighting.glsl"
#ifdef AA
#include "splat_filter.glsl"
#ifndef LAYERS
#define LAYERS 4
#endif
#ifndef SLICES
#define SLICES 512
#endif
#if LAYERS > 7 || LAYERS < 1
#error 1 to 7 layers (one draw buffer each; splat_surfaces.frag packs their starts)
#endif
#define MIN_COVERAGE 1e-4
#ifndef LAST_WEIGHTS  // aniso3d/rendering/splat/params.py (AA_LAST_WEIGHTS)
#define LAST_WEIGHTS 1
#endif
#endif

#ifndef PASS
#define PASS 0
#endif
#ifndef ROUND
#define ROUND 0
#endif

uniform vec2 u_viewport;
#ifdef AA
uniform float u_range;  // far - near
uniform vec2 u_slices;  // (lo, scale): slice coordinate (z - lo) scale of a linear depth z
#if PASS == 1
layout(r32ui) uniform uimage2DArray u_mask;  // SLICES / 32 words per pixel
#endif
#endif
#if PASS == 0 && defined(FORWARD)
// FORWARD (a scene's instances, quality "fast"): the geometry pass shades
// each fragment itself (the instance's normal and tint exist only here),
// writing colour, alpha 1, and the exact depth, instead of the point's id.
#include "lighting.glsl"
uniform mat3 u_ray;
#endif
#if PASS == 2
uniform mat3 u_ray;
#ifdef AA
// splat_surfaces.frag's output, where the pixel's surfaces start, read as an
// image: llvmpipe's image load costs about half its texel fetch, which ran
// for every fragment of the pass (0.2 s of a 1M-point frame at 1024^2).
layout(binding = 0, rgba32ui) readonly uniform uimage2D u_surfaces;
#if LAYERS > 1
// The pixel's coverage sum and its last surface's first slice (splat_surfaces.frag).
layout(binding = 1, rg32f) readonly uniform image2D u_cover;
#endif
#ifdef GEOMETRY_PATH
uniform float u_shade_box;    // splats of wider boxes are shaded per pixel
#endif
#else
uniform sampler2D u_visible;
#endif
#endif

#include "splat_data.glsl"
in SplatData SPLAT_DATA fs_in;

#if PASS == 0 && defined(FORWARD)
out vec4 f_color;
#elif PASS == 0
out uint f_id;
#elif PASS == 1 && defined(AA)
out vec4 f_visible;  // (pushed depth, surface reach, 0 if one-sided else 1, c): blended MIN in RGB, added in alpha
#elif PASS == 2 && defined(AA)
layout(location = 0) out vec4 f_layer[LAYERS];  // (RGB c, c) of each layer
#elif PASS == 2
out vec4 f_color;
#endif

#ifdef AA
// The fraction of this pixel the splat covers (see the top); h as in main(),
// hit: the pixel's ray meets the splat's plane in front, within near..far.
float coverage(vec3 h, bool hit) {
#ifdef CLIPS
    bool cut = fs_in.cut0.yz != vec2(0.0) || fs_in.cut1.yz != vec2(0.0);
#else
    // No point of this draw is cut (a cloud's cut points are drawn apart):
    // compiled out, as llvmpipe runs a branch's code for every fragment.
    const bool cut = false;
#endif
    float small = 0.0;
    if (fs_in.regime < 1.0) {
        vec2 d = gl_FragCoord.xy - fs_in.cpx;
        small = fs_in.box.z * filtered_interval(d.x, fs_in.box.x) * filtered_interval(d.y, fs_in.box.y);
        if (cut && small > 0.0) {
#if FILTER == 0
            // The box times the pixel is a rectangle: its area on the kept
            // side of each line, exactly (of both, the product of the shares).
            vec2 p = gl_FragCoord.xy - fs_in.org;
            vec2 c = fs_in.cpx - fs_in.org;
            vec2 lo = max(c - fs_in.box.xy, p - 0.5);
            vec2 hi = min(c + fs_in.box.xy, p + 0.5);
            float rect = max(hi.x - lo.x, 0.0) * max(hi.y - lo.y, 0.0);
            small *= rect > 0.0 ? rect_kept(lo, hi, fs_in.cut0) / rect * (rect_kept(lo, hi, fs_in.cut1) / rect) : 0.0;
#else
            vec3 p1 = vec3(1.0, gl_FragCoord.xy - fs_in.org);
            small *= filter_cdf(dot(fs_in.cut0, p1) / max(length(fs_in.cut0.yz), 1e-30))
                   * filter_cdf(dot(fs_in.cut1, p1) / max(length(fs_in.cut1.yz), 1e-30));
#endif
        }
    }
    float large = 0.0;
    if (fs_in.regime > 0.0 && hit) {
        vec2 uv = h.xy / h.z;
        float k = 1.0 / h.z;
        // Gradients of u and v per pixel (the homography's derivatives; its
        // rows are over pixels here, see main()).
        vec2 gu = (fs_in.hu.yz - uv.x * fs_in.hw.yz) * k;
        vec2 gv = (fs_in.hv.yz - uv.y * fs_in.hw.yz) * k;
#if ROUND
        float r = length(uv);
        float g = r > 1e-6 ? length(uv.x * gu + uv.y * gv) / r : max(length(gu), length(gv));
        g = max(g, 1e-30);
        large = filter_cdf((1.0 - r) / g) - filter_cdf((-1.0 - r) / g);
#else
        float a = max(length(gu), 1e-30);
        float b = max(length(gv), 1e-30);
        large = (filter_cdf((1.0 - uv.x) / a) - filter_cdf((-1.0 - uv.x) / a))
              * (filter_cdf((1.0 - uv.y) / b) - filter_cdf((-1.0 - uv.y) / b));
#endif
        if (cut) {
            // Each clip line filtered across its distance in pixels.
            vec3 p1 = vec3(1.0, gl_FragCoord.xy - fs_in.org);
            large *= filter_cdf(dot(fs_in.cut0, p1) / max(length(fs_in.cut0.yz), 1e-30))
                   * filter_cdf(dot(fs_in.cut1, p1) / max(length(fs_in.cut1.yz), 1e-30));
        }
    }
    return mix(small, large, fs_in.regime);
}

// The slice coordinate of a linear depth.
float slice_of(float z) {
    return (z - fs_in.lmap.z) * fs_in.lmap.w;
}
#endif
#if defined(AA) && PASS == 1
#ifndef SURFACE_REACH  // aniso3d/rendering/splat/params.py (AA_SURFACE_REACH)
#define SURFACE_REACH 1.0
#endif
// How far (linear depth) behind this fragment its surface may reach in this
// pixel beyond the span: 0, but for a one-sided splat whose back is culled (a
// closed surface seen from outside, whose splats facing the eye are one
// surface within a pixel or lie a solid's thickness apart) the change of the
// fragment's depth across SURFACE_REACH pixels where the ray meets the
// splat's plane, at most the depth of its bounding sphere (reachz); the
// same for a two-sided surface sheet's where that change is graze at least
// (a sheet grazing the ray; splat_surfaces.frag chains its slices). h, sw,
// hit as in main().
float surface_reach(vec3 h, float sw, bool hit) {
    if (!hit || fs_in.reachz <= 0.0) return 0.0;
    // d (t - t0) / d pixel, t - t0 = sw / h.z (rows over pixels: splat.vert).
    vec2 g = -(fs_in.hc.yz + (sw / h.z) * fs_in.hw.yz) / h.z;
    float r = min(length(g) * fs_in.lmap.y * SURFACE_REACH, fs_in.reachz);
    return r < fs_in.graze ? 0.0 : r;  // a two-sided sheet reaches where it grazes the ray
}

// Mark the slice holding slice coordinate u in this pixel's mask (a plain
// load first: most fragments find their bit set, and an atomic costs more).
void mark(float u) {
    int k = clamp(int(floor(u)), 0, SLICES - 1);
    ivec3 at = ivec3(ivec2(gl_FragCoord.xy), k >> 5);
    uint bit = 1u << uint(k & 31);
    if ((imageLoad(u_mask, at).r & bit) == 0u) imageAtomicOr(u_mask, at, bit);
}

#endif
#if defined(AA) && PASS == 2
// This fragment's layer: how many of the surfaces after the first start at or
// before its slice (splat_surfaces.frag packs the starts in 16 bits each).
int layer_of(float u, uvec4 r) {
    uint s = uint(clamp(int(floor(u)), 0, SLICES - 1));
    // Plain comparisons, no local array: llvmpipe puts an indexed local
    // array in memory, which cost more than the texel fetch.
    int k = 0;
#if LAYERS > 1
    k += int((r.x & 0xFFFFu) <= s);
#endif
#if LAYERS > 2
    k += int((r.x >> 16) <= s);
#endif
#if LAYERS > 3
    k += int((r.y & 0xFFFFu) <= s);
#endif
#if LAYERS > 4
    k += int((r.y >> 16) <= s);
#endif
#if LAYERS > 5
    k += int((r.z & 0xFFFFu) <= s);
#endif
#if LAYERS > 6
    k += int((r.z >> 16) <= s);
#endif
    return k;
}

#if LAYERS > 1 && LAST_WEIGHTS
// The weight of a fragment at slice coordinate u in the last layer: (1 -
// a_s)^j, j its surface's place in the layer (0 the layer's first), taken
// from the depths: the layer's n surfaces spread evenly from its first
// slice to its last surface's first slice (u_cover.g).
float last_layer_weight(float u, uvec4 r) {
    uint n = r.w >> 16;
    if (n <= uint(LAYERS)) return 1.0;  // the layer holds one surface
#if LAYERS == 2
    uint first = r.x & 0xFFFFu;
#elif LAYERS == 3
    uint first = r.x >> 16;
#elif LAYERS == 4
    uint first = r.y & 0xFFFFu;
#elif LAYERS == 5
    uint first = r.y >> 16;
#elif LAYERS == 6
    uint first = r.z & 0xFFFFu;
#else
    uint first = r.z >> 16;
#endif
    vec2 cover = imageLoad(u_cover, ivec2(gl_FragCoord.xy)).rg;
    float s = float(clamp(int(floor(u)), 0, SLICES - 1));
    float j = max(s - float(first), 0.0) / max(cover.y - float(first), 1.0) * float(n - uint(LAYERS));
    float a = min(cover.x / float(n), 1.0);
    return a >= 1.0 ? (j > 0.0 ? 0.0 : 1.0) : exp2(j * log2(1.0 - a));
}
#endif
#endif

void main() {
    // Rows over pixel offsets from fs_in.org (splat.vert), so that no uniform
    // is read here (on llvmpipe a uniform costs a gather per load).
    vec3 xy1 = vec3(1.0, gl_FragCoord.xy - fs_in.org);
    vec3 h = vec3(dot(fs_in.hu, xy1), dot(fs_in.hv, xy1), dot(fs_in.hw, xy1));
    float sw = -dot(fs_in.hc, xy1);  // (t - t0) w'
#ifdef AA
    // Only the box the filtered splat reaches (a point sprite is a square
    // around it; the geometry path's quad is the box itself).
    if (any(lessThan(gl_FragCoord.xy, fs_in.clip.xy)) || any(greaterThan(gl_FragCoord.xy, fs_in.clip.zw))) discard;
    bool hit = h.z > 0.0 && sw >= fs_in.srange.x * h.z && sw <= fs_in.srange.y * h.z;
    // Linear depth (t - near) / (far - near), uniformly precise over the clip
    // range, where a layer may be far thinner than a step of window depth:
    // t - near = delta + (t - t0), the plane's where the ray meets it.
    float lin = hit ? fs_in.lmap.x + fs_in.lmap.y * (sw / h.z) : fs_in.centre_z;
    float c = coverage(h, hit);
    if (!(c >= MIN_COVERAGE)) discard;
    float z = clamp(lin, fs_in.zrange.x, fs_in.zrange.y);
    float u = slice_of(z);
#if PASS == 1
    mark(u);
    // The pushed depth (below 1, so the later passes see every marked pixel),
    // kept the least by a MIN blend, and c, summed by an additive one (twice
    // for a one-sided splat whose back is culled: the back's share).
    f_visible = vec4(clamp(z + fs_in.pushz, 0.0, 0.99999), z + surface_reach(h, sw, hit), fs_in.sided > 1.5 ? 0.0 : 1.0, c * fs_in.sided);
#elif PASS == 2
    uvec4 surfaces = imageLoad(u_surfaces, ivec2(gl_FragCoord.xy));
    int layer = layer_of(u, surfaces);
    vec3 rgb = fs_in.rgb;
#ifdef GEOMETRY_PATH
    vec2 extent = fs_in.clip.zw - fs_in.clip.xy;
    if (layer == 0 && max(extent.x, extent.y) + 0.02 > u_shade_box && hit) {
        vec3 d = u_ray * vec3(1.0, gl_FragCoord.xy / u_viewport * 2.0 - 1.0);
        rgb = clamp(shade(fs_in.n, -normalize(d), fs_in.kd, fs_in.spec.x, fs_in.spec.y, length(fs_in.n)), 0.0, 1.0);
    }
#endif
#if LAYERS > 1 && LAST_WEIGHTS
    float w = layer == LAYERS - 1 ? last_layer_weight(u, surfaces) : 1.0;
    vec4 v = vec4(rgb * (c * w), c * w);
#else
    vec4 v = vec4(rgb * c, c);
#endif
    // One assignment per output, not a loop over the output array: llvmpipe
    // lowered that to indexed stores, which cost 0.6 s of a 1M-point frame.
    f_layer[0] = layer == 0 ? v : vec4(0.0);
#if LAYERS > 1
    f_layer[1] = layer == 1 ? v : vec4(0.0);
#endif
#if LAYERS > 2
    f_layer[2] = layer == 2 ? v : vec4(0.0);
#endif
#if LAYERS > 3
    f_layer[3] = layer == 3 ? v : vec4(0.0);
#endif
#if LAYERS > 4
    f_layer[4] = layer == 4 ? v : vec4(0.0);
#endif
#if LAYERS > 5
    f_layer[5] = layer == 5 ? v : vec4(0.0);
#endif
#if LAYERS > 6
    f_layer[6] = layer == 6 ? v : vec4(0.0);
#endif
#endif
#else
#if ROUND
    bool inside = dot(h.xy, h.xy) <= h.z * h.z;
#else
    bool inside = max(abs(h.x), abs(h.y)) <= h.z;
#endif
    // In front of the eye (w' > 0) and near <= t <= far.
    inside = inside && h.z > 0.0 && sw >= fs_in.frame.x * h.z && sw <= fs_in.frame.y * h.z;
    // (t - near) w', for the window depth K (t - near) / t = kn (t - near) w'.
    float tw = fs_in.frame.z * h.z + sw;
    vec2 uv = vec2(0.0);
    if (inside) {
#if PASS == 2
        uv = h.xy / h.z;
#endif
    } else if (gl_FragCoord.xy != fs_in.centre_px) {
        discard;
    }
#if PASS == 0
    gl_FragDepth = inside ? fs_in.kn * tw : fs_in.centre_z;
#ifdef FORWARD
    vec3 ray = u_ray * vec3(1.0, gl_FragCoord.xy / u_viewport * 2.0 - 1.0);
    f_color = vec4(clamp(shade(fs_in.n, -normalize(ray), fs_in.kd, fs_in.spec.x, fs_in.spec.y, length(fs_in.n)),
                         0.0, 1.0), 1.0);
#else
    f_id = uint(fs_in.id);
#endif
#elif PASS == 1
    float pw = fs_in.push * h.z;
    gl_FragDepth = inside ? fs_in.frame.w * (tw + pw) / (fs_in.num + pw) : fs_in.centre_zp;
#else
    float depth = inside ? fs_in.kn * tw : fs_in.centre_z;
    // 3e-7: a few steps of a 24-bit depth buffer, so the front splat always
    // passes its own (pushed, then quantised) visibility depth.
    if (depth > texelFetch(u_visible, ivec2(gl_FragCoord.xy), 0).r + 3e-7) discard;
    vec3 d = u_ray * vec3(1.0, gl_FragCoord.xy / u_viewport * 2.0 - 1.0);
    vec3 rgb = clamp(shade(fs_in.n, -normalize(d), fs_in.kd, fs_in.spec.x, fs_in.spec.y, length(fs_in.n)), 0.0, 1.0);
    float k = exp(-2.0 * dot(uv, uv));
    f_color = vec4(rgb * k, k);
#endif
#endif
}
