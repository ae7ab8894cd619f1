#version 430
// Splat renderer (c), surfaces pass of quality "high" (coverage-aware),
// fragment stage (vertex stage: splat_resolve.vert, one triangle).
// In: u_mask, each pixel's occupancy mask of SLICES depth slices (WORDS 32-bit
// words, layer k of the array holding slices 32 k .. 32 k + 31), a bit set
// for each slice holding a fragment's depth (splat.frag, PASS 1 with AA);
// u_span, the depth a surface may span, in slices (>= 1); u_visible's green,
// the least depth plus reach of the pixel's fragments (splat.frag,
// surface_reach), and u_slices, the slices' (lo, scale).
// The pixel's surfaces, front to back: the nearest occupied slice starts one,
// which takes every occupied slice less than u_span beyond its start (the
// nearest surface: beyond the reach's slice if that lies farther, where the
// pixel holds no closed surface seen from outside, u_visible's blue 1, only
// as far as its occupied slices are chained, each less than CHAIN u_span
// beyond the one before); the next occupied slice starts the next
// (aniso3d/rendering/splat/reference.py is the NumPy twin).
// Out: f_surfaces, the first slices of surfaces 1 .. LAYERS - 1, 16 bits
// each in x, y and z (0xFFFF where there is no such surface; LAYERS <= 7),
// the first slice of surface 0 (the nearest) in the low half of w, and the
// number of surfaces in its high half; f_cover, the pixel's coverage sum
// (u_visible's alpha) and the first slice of its last surface. The mask is
// cleared on the way (for the next draw).
#ifndef LAYERS
#define LAYERS 4
#endif
#ifndef WORDS
#define WORDS 16
#endif
#ifndef CHAIN  // aniso3d/rendering/splat/params.py (AA_SHEET_CHAIN)
#define CHAIN 1.5
#endif
#if LAYERS > 7
#error at most 7 layers (their starts and surface 0's share 128 bits)
#endif

layout(r32ui) uniform uimage2DArray u_mask;
uniform sampler2D u_visible;  // (pushed depth, least reach, 0 if one-sided else 1, coverage sum) of the visibility pass
uniform float u_span;
uniform vec2 u_slices;  // (lo, scale): slice coordinate (z - lo) scale of a linear depth z

layout(location = 0) out uvec4 f_surfaces;
layout(location = 1) out vec2 f_cover;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec4 visible = texelFetch(u_visible, px, 0);
    if (!(visible.r < 1.0)) discard;  // only pixels something was drawn in
    uint starts[8] = uint[8](0xFFFFu, 0xFFFFu, 0xFFFFu, 0xFFFFu, 0xFFFFu, 0xFFFFu, 0xFFFFu, 0xFFFFu);
    uint count = 0u;
    float limit = -1.0;  // the current surface takes the slices below this
    int last = 0;        // the last surface's first slice
    // Chained (the nearest surface, where the pixel holds no closed surface
    // seen from outside, blue 1): each slice it takes extends it to CHAIN
    // spans beyond, up to end.
    bool chain = false;
    float end = 0.0;
    for (int k = 0; k < WORDS; ++k) {
        uint w = imageLoad(u_mask, ivec3(px, k)).r;
        if (w == 0u) continue;
        imageStore(u_mask, ivec3(px, k), uvec4(0u));
        while (w != 0u) {
            if (chain) {
                int s = 32 * k + findLSB(w);
                if (float(s) < limit) {
                    limit = max(limit, min(float(s) + CHAIN * u_span, end));
                    w &= w - 1u;
                    continue;
                }
                chain = false;
            }
            // Drop the slices the current surface still takes.
            float skip = limit - float(32 * k);
            if (skip > 31.0) break;
            if (skip > 0.0) w &= ~((1u << uint(ceil(skip))) - 1u);
            if (w == 0u) break;
            int s = 32 * k + findLSB(w);
            if (count == 0u) starts[6] = uint(s);
            if (count >= 1u && count < uint(LAYERS)) starts[count - 1u] = uint(s);
            last = s;
            count += 1u;
            limit = float(s) + u_span;
            if (count == 1u) {
                end = max(float(s), floor((visible.g - u_slices.x) * u_slices.y)) + u_span;
                chain = visible.b > 0.5 && end > limit;
                limit = chain ? max(limit, min(float(s) + CHAIN * u_span, end)) : end;
            }
            w &= w - 1u;
        }
    }
    f_cover = vec2(visible.a, float(last));
    f_surfaces = uvec4(starts[0] | (starts[1] << 16), starts[2] | (starts[3] << 16),
                   starts[4] | (starts[5] << 16), starts[6] | (min(count, 0xFFFFu) << 16));
}
