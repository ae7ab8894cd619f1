#version 330
// Splat renderer (c), compositing pass of quality "high" (coverage-aware),
// fragment stage (vertex stage: splat_resolve.vert, one triangle).
// In: u_slab[i], SLABS layers front to back, each (sum of RGB c, sum of c)
// over its fragments (c: the fraction of the pixel a splat covers; see
// splat.frag, PASS 2 with AA); u_resolved, per layer from DEEP on (channel
// layer - DEEP), the part of that sum from resolved splats; u_visible, the
// visibility pass's linear depth (t - near) / (far - near), pushed.
// Compositing, front to back, T the transmittance left (starts at 1):
//   layers before DEEP hold the visible surface: their splats tile it, so
//     they fill what is left of the pixel additively, a = min(sum, T);
//   a deeper layer spans many surfaces: its sub-pixel splats hide parts of
//     each other at random, its resolved ones tile, so it covers
//     a = T (1 - (1 - min(1, resolved)) exp(-(sum - resolved)));
//   each adds a (its coverage-weighted mean colour) and T -= a.
// Out, by u_mode (aniso3d.rendering.splat.coverage.HighPass.composite), C the colour so
// composited (premultiplied):
//   0 (over what the target holds):  (C, 1 - T), blended src + (1 - src.a) dst;
//   1, 2 (under it):  the positive, then the negative part of
//                     C - (1 - T) u_background, alpha 1 - T;
// and the visible layer's window depth. Pixels no splat reached are
// discarded, so whatever the target holds there stays.
#ifndef SLABS
#define SLABS 4
#endif
#ifndef DEEP
#define DEEP 2
#endif

uniform sampler2D u_slab[SLABS];
uniform sampler2D u_resolved;
uniform sampler2D u_visible;  // linear depth (t - near) / (far - near), pushed
uniform vec2 u_depth;          // (K, t0 - near): window depth = K (t - near) / t
uniform float u_near;
uniform float u_range;         // far - near
uniform vec3 u_background;
uniform int u_mode;

out vec4 f_color;

// One layer (sampler arrays take constant indices only in GLSL 3.30, so the
// loop over layers is unrolled below); resolved: the part of acc.a from
// resolved splats, or -1 for a layer before DEEP.
void layer(vec4 acc, float resolved, inout vec3 colour, inout float trans) {
    if (acc.a > 0.0) {
        float r = clamp(resolved, 0.0, acc.a);
        float a = resolved < 0.0 ? min(acc.a, trans) : trans * (1.0 - (1.0 - min(r, 1.0)) * exp(r - acc.a));
        colour += a * (acc.rgb / acc.a);
        trans -= a;
    }
}

#define LAYER(i) layer(texelFetch(u_slab[i], px, 0), i >= DEEP ? res[max(i - DEEP, 0)] : -1.0, colour, trans)

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec3 colour = vec3(0.0);
    float trans = 1.0;
    vec4 res = texelFetch(u_resolved, px, 0);
    LAYER(0);
#if SLABS > 1
    LAYER(1);
#endif
#if SLABS > 2
    LAYER(2);
#endif
#if SLABS > 3
    LAYER(3);
#endif
#if SLABS > 4
    LAYER(4);
#endif
#if SLABS > 5
    LAYER(5);
#endif
#if SLABS > 6
    LAYER(6);
#endif
    if (!(trans < 1.0)) discard;
    if (u_mode == 0) {
        f_color = vec4(colour, 1.0 - trans);
    } else {
        vec3 x = colour - (1.0 - trans) * u_background;
        f_color = vec4(max(u_mode == 1 ? x : -x, 0.0), 1.0 - trans);
    }
    float lin = texelFetch(u_visible, px, 0).r * u_range;  // t - near
    gl_FragDepth = u_depth.x * lin / (u_near + lin);
}
