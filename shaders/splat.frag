#version 330
// Splat renderer (c), fragment stage: the exact ray-splat intersection.
// In: SplatData (flat, from splat.vert or splat.geom; see splat.vert for the
// homography rows hu, hv, hw, hc), gl_FragCoord. Uniforms: u_viewport,
// u_srange and u_depth (below); for PASS 2 also u_ray (columns f, R, U: the
// eye ray of NDC (x, y) is f + x R + y U), u_visible and lighting.glsl's.
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
#include "lighting.glsl"

#ifndef PASS
#define PASS 0
#endif
#ifndef ROUND
#define ROUND 0
#endif

uniform vec2 u_viewport;
uniform vec2 u_srange;  // (near - t0, far - t0): the range of t - t0
uniform vec2 u_depth;   // (K, t0 - near): window depth = K (t - near) / t
#if PASS == 2
uniform mat3 u_ray;
uniform sampler2D u_visible;
#endif

in SplatData {
    flat vec3 hu;
    flat vec3 hv;
    flat vec3 hw;
    flat vec3 hc;
    flat float num;
    flat float kn;
    flat vec2 centre_px;
    flat float centre_z;
    flat float centre_zp;
    flat float push;
    flat int id;
    flat vec3 n;
    flat vec3 kd;
    flat vec2 spec;
} fs_in;

#if PASS == 0
out uint f_id;
#elif PASS == 2
out vec4 f_color;
#endif

void main() {
    vec3 xy1 = vec3(1.0, gl_FragCoord.xy / u_viewport * 2.0 - 1.0);
    vec3 h = vec3(dot(fs_in.hu, xy1), dot(fs_in.hv, xy1), dot(fs_in.hw, xy1));
    float sw = -dot(fs_in.hc, xy1);  // (t - t0) w'
#if ROUND
    bool inside = dot(h.xy, h.xy) <= h.z * h.z;
#else
    bool inside = max(abs(h.x), abs(h.y)) <= h.z;
#endif
    // In front of the eye (w' > 0) and near <= t <= far.
    inside = inside && h.z > 0.0 && sw >= u_srange.x * h.z && sw <= u_srange.y * h.z;
    // (t - near) w', for the window depth K (t - near) / t = kn (t - near) w'.
    float tw = u_depth.y * h.z + sw;
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
    f_id = uint(fs_in.id);
#elif PASS == 1
    float pw = fs_in.push * h.z;
    gl_FragDepth = inside ? u_depth.x * (tw + pw) / (fs_in.num + pw) : fs_in.centre_zp;
#else
    float depth = inside ? fs_in.kn * tw : fs_in.centre_z;
    // 3e-7: a few steps of a 24-bit depth buffer, so the front splat always
    // passes its own (pushed, then quantised) visibility depth.
    if (depth > texelFetch(u_visible, ivec2(gl_FragCoord.xy), 0).r + 3e-7) discard;
    vec3 d = u_ray * xy1;
    vec3 rgb = clamp(shade(fs_in.n, -normalize(d), fs_in.kd, fs_in.spec.x, fs_in.spec.y), 0.0, 1.0);
    float k = exp(-2.0 * dot(uv, uv));
    f_color = vec4(rgb * k, k);
#endif
}
