#version 330
// Splat renderer (c), vertex stage: one oriented point -> the pixel box its
// splat may cover, and the constants that let splat.frag intersect it exactly.
//
// In (one vertex per point, positions relative to the cloud's local origin):
//   in_position (local frame), in_normal (world orientation; its length is
//   the point's coherence, see lighting.glsl),
//   in_size = sqrt(area) (world units), negated for a one-sided point (a
//   piece of a closed surface, its normal pointing out: culled where it faces
//   away from the eye), in_kd (RGB), in_spec = (ks, shininess), the sign bit
//   of ks set for a point of a surface sheet (aniso3d.build.points.PointCloud.sheet:
//   with AA and SHEET_REACH its surface reaches as a one-sided point's does).
//   A point with clip planes has in_spec.y negated (its sign bit set):
//   quality "high" skips it here and draws it from the cloud's cut upload,
//   with CLIPS: its two clip planes from u_clip_table (see clip_inputs()).
// Out: SplatData (splat_data.glsl; all flat), and
//   SPRITE path (default): gl_Position at the box centre and a gl_PointSize
//   covering the box; splats whose box is wider than u_max_sprite, or with
//   nothing to draw, are moved outside the clip volume (culled);
//   GEOMETRY_PATH: vs_box = the box (x0, y0, x1, y1) in pixels for splat.geom,
//   which draws only the splats the sprite path culls for size (x0 > x1: none).
//
// The splat: centre p, unit normal n, tangent axes t, b divided by the
// shape's half-axes (tu, tv). A pixel's eye ray is e + t d, d = f + x R + y U
// (x, y in NDC, f the unit view direction), so d . f = 1 and t is the view
// depth. To keep float32 precision with the eye far away (a telephoto view),
// nothing eye-relative is formed here: with t0 the view depth of the cloud's
// local origin and q0 = e + t0 f (the foot of the origin on the view axis;
// both from float64 on the CPU), g = q0 - p is of the cloud's size and the
// ray point is q0 + x t0 R + y t0 U + s d, with s = t - t0. The ray meets the
// plane at s = -(C . (1, x, y)) / w', w' = n . d, and the plane point's shape
// coordinates are u = u' / w', v = v' / w', where u', v', w', C are linear
// in (1, x, y) (products of two linear functions whose quadratic terms cancel):
// rows hu, hv, hw, hc of the homography from the screen to the splat's plane.
// Rows are negated when n faces away from the eye, so w' > 0 <=> t > 0.
// No division by n.d anywhere: a ray grazing the plane just has w' -> 0.
// Window depth: K (t - near) / t = kn (delta w' - C), kn = K / num,
// num = n . (p - e) = t w', delta = t0 - near; no large terms cancel.
//
// The box is the screen bounding box of the projected disc/ellipse (ROUND, when
// it lies wholly beyond the near plane) or else of the shape's bounding
// rectangle clipped to the near plane (exact for a square), grown to hold
// the centre of the pixel containing the projected splat centre (that pixel
// is always drawn: a splat never vanishes, however small or oblique) and
// clamped to the viewport (with AA, see below: grown by the pixel filter's
// reach instead, no centre pixel forced). Tangent frame, shared with
// aniso3d.grid.tangent_frame (used by splats and by to_points): t = normalize(n x h),
// b = n x t, h = x if |n.x| < 0.9 else y.
//
// AA (quality "high", coverage-aware; see splat.frag): also the splat's
// projected centre in pixels (continuous), its footprint for the sub-pixel
// formula (an axis-aligned box of the true area's second moments, half-sides
// box.xy in pixels, amplitude box.z = true projected area / box area), the
// regime weight (0: sub-pixel box formula with the true area, 1: the exact
// shape with the size factor; by sqrt(true projected area) between
// u_regime.x and .y pixels), linear depths (t - near) / (far - near) of the
// centre (centre_z, centre_zp) and of its bounding sphere (zrange), the box
// drawn (clip) and, in PASS 2, its colour shaded once at the centre (for
// sub-pixel splats and the layers behind the first). The rows hu, hv, hw, hc
// leave this stage over (1, p - org), p the pixel coordinates (gl_FragCoord)
// and org a pixel of the box, instead of (1, x, y) in NDC, and the uniforms
// the fragment stage needs come per splat (with AA srange, lmap, pushz;
// without, frame): see the end of main().

uniform vec3 u_q0;           // e + t0 f, local frame (see above)
uniform float u_t0;          // view depth of the local origin
uniform mat3 u_view_rot;     // eye <- world rotation (rows: right, up, -forward)
uniform mat3 u_ray;          // columns f, R = right tan(fov/2) aspect, U = up tan(fov/2)
uniform vec2 u_proj_scale;   // (1 / (tan(fov/2) aspect), 1 / tan(fov/2))
uniform vec2 u_viewport;     // framebuffer size, pixels
uniform float u_near;        // clip distances, world units along the view axis
uniform float u_far;
uniform vec2 u_depth;        // (K, delta): window depth = K (t - near) / t, delta = t0 - near
uniform vec2 u_srange;       // (near - t0, far - t0): the range of t - t0
uniform vec2 u_extent;       // shape half-axes per unit of in_size
uniform float u_max_sprite;  // widest point sprite the sprite path may draw, pixels
uniform float u_push;        // visibility push-back, in units of the larger half-axis
uniform bool u_one_sided;    // cull one-sided points seen from behind (the eye is outside the cloud)
#ifdef AA
#include "splat_filter.glsl"
#ifndef SHEET_REACH  // aniso3d/rendering/splat/params.py (AA_SHEET_REACH, AA_SHEET_GRAZE)
#define SHEET_REACH 1
#define SHEET_GRAZE 3.0
#endif
uniform float u_size_factor; // the shape's linear scale over its true area's
uniform vec2 u_regime;       // sqrt(true projected area) in pixels: box formula below x, exact shape above y
uniform float u_range;       // far - near
uniform vec2 u_slices;       // (lo, scale): slice coordinate (z - lo) scale of a linear depth z
uniform float u_span;        // the depth one surface spans, slices
#if PASS == 2
#include "lighting.glsl"
#endif
#endif

#include "splat_data.glsl"

#ifdef INSTANCED
// A scene's instances: the asset's points (inst_*) and, per instance
// (divisor 1), the frame-local <- asset-local affine matrix and an RGB tint.
// instance_inputs() sets the usual in_* from them: position moved, normal by
// the cofactor matrix (det(A) A^-T) keeping its length (the coherence), size by
// the square root of the area's stretch |cof(A) n| / |n|, kd tinted; everything below is unchanged.
in vec3 inst_position;
in vec3 inst_normal;
in float inst_size;
in vec3 inst_kd;
in mat4 in_instance;
in vec4 in_tint;
vec3 in_position;
vec3 in_normal;
float in_size;
vec3 in_kd;
void instance_inputs() {
    mat3 a = mat3(in_instance);
    vec3 cn = mat3(cross(a[1], a[2]), cross(a[2], a[0]), cross(a[0], a[1])) * inst_normal;
    float coherence = length(inst_normal);  // kept as the moved normal's length
    float stretch = coherence > 0.0 ? length(cn) / coherence : 0.0;
    in_position = (in_instance * vec4(inst_position, 1.0)).xyz;
    in_normal = stretch > 0.0 ? cn / stretch : inst_normal;
    in_size = inst_size * sqrt(stretch);
    in_kd = inst_kd * in_tint.rgb;
}
#else
in vec3 in_position;
in vec3 in_normal;
in float in_size;
in vec3 in_kd;
#endif
in vec2 in_spec;
#if defined(CLIPS) && !defined(INSTANCED)
// A cut upload (aniso3d.rendering.splat.buffers.GPUPoints.cut): its points'
// two clip planes, each (code, o, phi): the half-space s x_a <= o, code
// s (a + 1) (0: none), phi the angle of the surface meeting the splat's there
// (0: none; aniso3d.build.points.PointCloud.clips); point i's in row i of the
// table, two texels.
uniform sampler2D u_clip_table;
vec3 in_clip0 = vec3(0.0);
vec3 in_clip1 = vec3(0.0);

void clip_inputs() {
    ivec2 at = ivec2(2 * (gl_VertexID % CLIP_TABLE_PER_ROW), gl_VertexID / CLIP_TABLE_PER_ROW);
    in_clip0 = texelFetch(u_clip_table, at, 0).xyz;
    in_clip1 = texelFetch(u_clip_table, at + ivec2(1, 0), 0).xyz;
}
#else
const vec3 in_clip0 = vec3(0.0);  // no point is cut (an instance's never are)
const vec3 in_clip1 = vec3(0.0);
#endif
// A point with clip planes has its shininess negated in the cloud's buffer
// (the sign bit, -0.0 for 0): quality "high" draws it from the cut upload.
#if defined(AA) && !defined(CLIPS) && !defined(INSTANCED)
#define SKIP_CUT 1
#endif

out SplatData SPLAT_DATA vs_out;

#ifdef GEOMETRY_PATH
flat out vec4 vs_box;
#endif

void grow(vec3 e, inout vec2 lo, inout vec2 hi) {
    // e: an eye-frame point at view depth >= u_near > 0 (so no division by 0).
    vec2 ndc = e.xy * u_proj_scale / (-e.z);
    lo = min(lo, ndc);
    hi = max(hi, ndc);
}

void cull() {
#ifdef GEOMETRY_PATH
    vs_box = vec4(1.0, 1.0, 0.0, 0.0);
#else
    gl_Position = vec4(0.0, 0.0, 2.0, 1.0);  // outside the clip volume
    gl_PointSize = 1.0;
#endif
}

// cull() for splats dropped here and there among drawn ones (hidden at a
// crease, drawn from the cut upload): one vertex outside the clip volume
// sends llvmpipe's whole batch of vertices down its clipping path (the
// default tree's high frame cost a fifth more for 0.3 % of its points), so
// with AA such a splat is a point inside the volume, spread over the image
// by its index (no one tile gets them all), whose one fragment splat.frag
// discards at once (the box it may draw, clip, is empty). Splats dropped in
// runs (a closed surface's back, off screen) keep cull(): a batch of them
// all outside costs little, and each of their points inside would cost a
// fragment.
void cull_scattered() {
#if defined(AA) && !defined(GEOMETRY_PATH)
    ivec2 size = ivec2(u_viewport);
    ivec2 px = ivec2(gl_VertexID % size.x, (gl_VertexID / size.x) % size.y);
    gl_Position = vec4((vec2(px) + 0.5) / u_viewport * 2.0 - 1.0, 0.0, 1.0);
    gl_PointSize = 1.0;
    vs_out.clip = vec4(1.0, 1.0, 0.0, 0.0);
#else
    cull();
#endif
}

// (a . (1, x, y)) (b . (1, x, y)) - (c . (1, x, y)) (d . (1, x, y)) when its
// quadratic terms cancel: the coefficients of the linear rest.
vec3 bilinear(vec3 a, vec3 b, vec3 c, vec3 d) {
    vec3 r = a.x * b + b.x * a - c.x * d - d.x * c;
    r.x -= a.x * b.x - c.x * d.x;
    return r;
}

#ifdef AA
// Whether the surface meeting the splat's at clip plane c (in_clip0, 1) hides
// the splat from the eye: in the plane across their edge (the splat's
// direction u from the edge into its voxel, its normal n), the eye's ray to
// the splat near the edge crosses the other half-plane, at phi from u, when
// phi lies between 0 and the eye's angle (a box's face seen behind its
// neighbour at a silhouette, the floor behind the room's front wall). Never
// for a point culled from behind (`sided`): the other surface is its closed
// surface's too, wound alike (outward normal sin(phi) u - cos(phi) n), so
// where it lies in front (0 < phi < th) it faces away, sin(phi - th) < 0,
// and is culled; where phi < th < 0 the point itself faces away. Dropped
// there, a floor's splats along a lip seen from beyond it left a line of
// background (params.py AA_PARTNER_HIDES_SIDED, injected as SIDED_HIDDEN).
#ifndef SIDED_HIDDEN
#define SIDED_HIDDEN 0
#endif
bool hidden_at(vec3 c, vec3 n, vec3 eye, bool sided) {
    if (sided && SIDED_HIDDEN == 0) return false;
    if (c.x == 0.0 || c.z == 0.0) return false;
    int a = int(abs(c.x) + 0.5) - 1;
    float s = c.x > 0.0 ? 1.0 : -1.0;
    vec3 m = vec3(0.0);
    m[a] = s;
    vec3 mp = m - dot(m, n) * n;
    float l = length(mp);
    if (l < 1e-6) return false;
    vec3 u = -mp / l;
    vec3 q = in_position - ((c.y - s * in_position[a]) / l) * u;  // the edge's point nearest the centre
    vec3 e = eye - q;
    float th = atan(dot(e, n), dot(e, u));
    return c.z * th > 0.0 && abs(c.z) < abs(th);
}

// A clip plane (code, o) (in_clip0, 1) as a line in the image: the row over
// (1, p - org) of (o - s x_a) w' at the point x where the pixel's ray meets the
// splat's plane, x = centre + u h.x t + v h.y b: positive on the kept side
// (w' > 0 in front); (1, 0, 0) for none. The rows hu, hv, hw must already be
// over pixel offsets.
vec3 cut_line(vec2 c, vec3 t, vec3 b, vec2 h) {
    if (c.x == 0.0) return vec3(1.0, 0.0, 0.0);
    int a = int(abs(c.x) + 0.5) - 1;
    float s = c.x > 0.0 ? 1.0 : -1.0;
    float k0 = c.y - s * in_position[a];
    return k0 * vs_out.hw - (h.x * s * t[a]) * vs_out.hu - (h.y * s * b[a]) * vs_out.hv;
}
#endif

void main() {
#ifdef INSTANCED
    instance_inputs();
#elif defined(CLIPS)
    clip_inputs();
#endif
#ifdef SKIP_CUT
    if (floatBitsToUint(in_spec.y) >= 0x80000000u) {  // drawn from the cut upload
        cull_scattered();
        return;
    }
#endif
    vec3 n = normalize(in_normal);  // its length is the point's coherence
    // ks's sign bit marks a point of a surface sheet (also on ks = -0.0).
    bool sheet = (floatBitsToUint(in_spec.x) & 0x80000000u) != 0u;
    vec2 spec = vec2(abs(in_spec.x), abs(in_spec.y));
    vec3 helper = abs(n.x) < 0.9 ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0);
    vec3 t = normalize(cross(n, helper));
    vec3 b = cross(n, t);
    vec2 h = u_extent * abs(in_size);
    vec3 tu = t / max(h.x, 1e-30);
    vec3 tv = b / max(h.y, 1e-30);

#ifdef AA
    // A splat hidden behind the surface meeting it at a clip plane is not drawn.
    bool sided = u_one_sided && in_size < 0.0;
    if (hidden_at(in_clip0, n, u_q0 - u_t0 * u_ray[0], sided) || hidden_at(in_clip1, n, u_q0 - u_t0 * u_ray[0], sided)) {
        cull_scattered();
        return;
    }
#endif
    vec3 g = u_q0 - in_position;
    vec3 rt = u_t0 * u_ray[1];
    vec3 ut = u_t0 * u_ray[2];
    vec3 nd = n * u_ray;  // (n.f, n.R, n.U): w'
    vec3 nc = vec3(dot(n, g), dot(n, rt), dot(n, ut));
    float num = u_t0 * nd.x - nc.x;  // n . (p - e)
    if (u_one_sided && in_size < 0.0 && num > 0.0) {  // a one-sided point seen from behind
        cull();
        return;
    }
    float s = num < 0.0 ? -1.0 : 1.0;
    vs_out.hu = s * bilinear(vec3(dot(tu, g), dot(tu, rt), dot(tu, ut)), nd, nc, tu * u_ray);
    vs_out.hv = s * bilinear(vec3(dot(tv, g), dot(tv, rt), dot(tv, ut)), nd, nc, tv * u_ray);
    vs_out.hw = s * nd;
    vs_out.hc = s * nc;
    vs_out.num = abs(num);
    vs_out.kn = num != 0.0 ? u_depth.x / abs(num) : 0.0;
    vs_out.id = gl_VertexID;
    vs_out.n = in_normal;
    vs_out.kd = in_kd;
    vs_out.spec = spec;
    float push = u_push * max(h.x, h.y);
    vs_out.push = push;
    vs_out.centre_px = vec2(-1e9);
    float gf = dot(g, u_ray[0]);
    float depth = u_t0 - gf;  // view depth of the centre
    vs_out.centre_z = depth > 0.0 ? u_depth.x * (u_depth.y - gf) / depth : 0.0;
    vs_out.centre_zp = depth + push > 0.0 ? u_depth.x * (u_depth.y - gf + push) / (depth + push) : 0.0;

    if (!(h.x > 0.0 && h.y > 0.0)) {  // zero area: nothing to draw
        cull();
        return;
    }

    // NDC box of the shape, clipped to view depth >= near.
    vec3 ce = u_view_rot * -g - vec3(0.0, 0.0, u_t0);  // eye frame: z = -view depth
    vec3 te = u_view_rot * (t * h.x);
    vec3 be = u_view_rot * (b * h.y);
    vec2 lo = vec2(1e30);
    vec2 hi = vec2(-1e30);
    float nearest = 1e30;  // smallest view depth of the shape
    bool boxed = false;
#if ROUND
    // An ellipse wholly in front of the near plane projects to an ellipse;
    // its box from the dual conic M diag(1, 1, -1) M^T, M mapping (u, v, 1)
    // on the unit disc to homogeneous NDC, written relative to the projected
    // centre (no cancellation for splats far smaller than their distance).
    nearest = -ce.z - length(vec2(te.z, be.z));
    if (nearest >= u_near) {
        vec3 r2 = -vec3(te.z, be.z, ce.z);
        vec2 mid = ce.xy * u_proj_scale / r2.z;
        vec3 r0 = u_proj_scale.x * vec3(te.x, be.x, ce.x) - mid.x * r2;
        vec3 r1 = u_proj_scale.y * vec3(te.y, be.y, ce.y) - mid.y * r2;
        r0.z = 0.0;  // zero by construction; drop the rounding residue
        r1.z = 0.0;
        vec3 dr2 = r2 * vec3(1.0, 1.0, -1.0);
        float c22 = dot(dr2, r2);  // < 0: the ellipse is in front of the eye
        vec2 c02 = vec2(dot(dr2, r0), dot(dr2, r1));
        vec2 c00 = vec2(dot(r0.xy, r0.xy), dot(r1.xy, r1.xy));
        vec2 half_ = sqrt(max(c02 * c02 - c00 * c22, 0.0)) / -c22;
        vec2 centre = mid + c02 / c22;
        half_ = half_ * 1.001 + 1e-3 / u_viewport;  // float slack, < 0.01 px
        lo = centre - half_;
        hi = centre + half_;
        boxed = true;
    }
#endif
    if (!boxed) {
        // The bounding rectangle's corners, its edges clipped to depth >= near.
        vec3 q[4] = vec3[4](ce - te - be, ce + te - be, ce + te + be, ce - te + be);
        for (int i = 0; i < 4; ++i) {
            vec3 p0 = q[i];
            vec3 p1 = q[(i + 1) % 4];
            float d0 = -p0.z;
            float d1 = -p1.z;
            nearest = min(nearest, d0);
            if (d0 >= u_near) grow(p0, lo, hi);
            if ((d0 >= u_near) != (d1 >= u_near)) grow(mix(p0, p1, (u_near - d0) / (d1 - d0)), lo, hi);
        }
    }
    if (lo.x > hi.x || nearest > u_far) {  // all behind the near plane, or beyond far
        cull();
        return;
    }
    lo = (lo * 0.5 + 0.5) * u_viewport;
    hi = (hi * 0.5 + 0.5) * u_viewport;

#ifdef AA
    // The footprint of the sub-pixel formula: the projected half-axes pu, pv
    // (pixels, affine at the centre) of the true-area shape (the drawn one
    // over the size factor); a box with the same second moments along x and y
    // (a square's are (pu pu^T + pv pv^T) / 3, a disc's / 4; a box of
    // half-side b has b^2 / 3) whose amplitude keeps the true projected area.
    vs_out.cpx = vec2(-1e9);
    vs_out.box = vec3(0.0);
    vs_out.regime = 1.0;
    if (depth >= u_near) {
        vec2 pix = 0.5 * u_viewport * u_proj_scale / depth;
        vs_out.cpx = (ce.xy * u_proj_scale / depth * 0.5 + 0.5) * u_viewport;
        vec2 pu = pix * (te.xy + ce.xy * (te.z / depth)) / u_size_factor;
        vec2 pv = pix * (be.xy + ce.xy * (be.z / depth)) / u_size_factor;
#if ROUND
        const float AREA = 3.14159265;  // of the unit disc
        const float MOMENT = 0.75;      // 3 x its second moment per axis
#else
        const float AREA = 4.0;         // of the square [-1, 1]^2
        const float MOMENT = 1.0;
#endif
        float area = AREA * abs(pu.x * pv.y - pu.y * pv.x);  // true projected area, pixels
        vec2 half_ = sqrt(MOMENT * (pu * pu + pv * pv));
        float box_area = 4.0 * half_.x * half_.y;
        if (area > box_area) {  // a disc's moment box is smaller than the disc
            half_ *= sqrt(area / box_area);
            box_area = area;
        }
        vs_out.box = vec3(half_, box_area > 0.0 ? area / box_area : 0.0);
        vs_out.regime = smoothstep(u_regime.x, u_regime.y, sqrt(area));
    }
    // Linear depths (t - near) / (far - near) of the bounding sphere's front
    // and back, the sphere grown by PLANE_REACH pixels at the centre's depth:
    // a fragment's depth is where its pixel's ray meets the splat's plane,
    // kept within these, so that the fragments of one tilted surface, however
    // small its splats, lie at the surface's one depth on that ray.
    float rad = length(h);
    if (depth >= u_near) rad += PLANE_REACH * depth / (0.5 * min(u_viewport.x * u_proj_scale.x, u_viewport.y * u_proj_scale.y));
    vs_out.zrange = clamp((u_depth.y - gf + vec2(-rad, rad)) / u_range, 0.0, 1.0);
    // The centre's linear depth, plain and pushed.
    vs_out.centre_z = (u_depth.y - gf) / u_range;
    vs_out.centre_zp = (u_depth.y - gf + push) / u_range;
    vs_out.rgb = vec3(0.0);
#if PASS == 2
    vs_out.rgb = clamp(shade(n, normalize(g - u_t0 * u_ray[0]), in_kd, spec.x, spec.y, length(in_normal)), 0.0, 1.0);
#endif
    // Every pixel the filter reaches (the exact shape's edges are filtered
    // across their own normals, so its corners reach sqrt(2) times as far);
    // no centre pixel is forced (a splat gives its projected area, however
    // small).
    float reach = FILTER_RADIUS * (vs_out.regime > 0.0 ? 1.415 : 1.0) + 0.01;
    lo -= reach;
    hi += reach;
#else
    if (depth >= u_near && depth <= u_far) {
        vec2 p = (ce.xy * u_proj_scale / depth * 0.5 + 0.5) * u_viewport;
        if (all(greaterThanEqual(p, vec2(0.0))) && all(lessThan(p, u_viewport))) {
            vec2 px = floor(p);
            vs_out.centre_px = px + 0.5;  // gl_FragCoord of that pixel, exactly
            lo = min(lo, px + 0.25);
            hi = max(hi, px + 0.75);
        }
    }
#endif
    lo = max(lo, vec2(0.0));
    hi = min(hi, u_viewport);
    if (any(greaterThanEqual(lo, hi))) {  // off screen
        cull();
        return;
    }
    // The fragment stage reads no uniforms: llvmpipe loads a uniform there as
    // a bounds-checked gather, lane by lane, which cost about 15 % of both
    // passes of quality "high" and 17 % of fast's geometry pass. So the plane
    // rows become rows over pixel offsets (1, p - org) from a pixel of the
    // box (NDC x = (2 / W) p - 1), and the uniforms it needs are passed per
    // splat.
    vec2 org = floor(0.5 * (lo + hi)) + 0.5;
    vec3 at = vec3(1.0, org * (2.0 / u_viewport) - 1.0);
    vec3 per = vec3(1.0, 2.0 / u_viewport);
    vs_out.hu = vec3(dot(vs_out.hu, at), vs_out.hu.yz * per.yz);
    vs_out.hv = vec3(dot(vs_out.hv, at), vs_out.hv.yz * per.yz);
    vs_out.hw = vec3(dot(vs_out.hw, at), vs_out.hw.yz * per.yz);
    vs_out.hc = vec3(dot(vs_out.hc, at), vs_out.hc.yz * per.yz);
    vs_out.org = org;
#ifndef AA
    vs_out.frame = vec4(u_srange, u_depth.y, u_depth.x);
#else
    vs_out.clip = vec4(lo, hi);
    vs_out.srange = u_srange;
    vs_out.lmap = vec4(u_depth.y / u_range, 1.0 / u_range, u_slices);
    vs_out.pushz = push / u_range;
    vs_out.sided = u_one_sided && in_size < 0.0 ? 2.0 : 1.0;
    // A closed surface's splat, or a surface sheet's (SHEET_REACH), may
    // extend its pixel's nearest surface (splat.frag, surface_reach); a
    // two-sided sheet's only where it grazes the ray, its depth changing
    // across the reach by SHEET_GRAZE spans at least.
    bool sheet_reach = SHEET_REACH != 0 && sheet && vs_out.sided < 1.5;
    vs_out.reachz = vs_out.sided > 1.5 || sheet_reach ? vs_out.zrange.y - vs_out.zrange.x : 0.0;
    vs_out.graze = sheet_reach ? SHEET_GRAZE * u_span / u_slices.y : 0.0;
    // The clip planes' lines; a sub-pixel box cut by them keeps its true
    // area (all of it lies on their kept side): its amplitude grows by the
    // share cut off (at most 4: the kept sides hold its centre).
    vs_out.cut0 = cut_line(in_clip0.xy, t, b, h);
    vs_out.cut1 = cut_line(in_clip1.xy, t, b, h);
    if ((in_clip0.x != 0.0 || in_clip1.x != 0.0) && vs_out.box.z > 0.0) {
        vec2 c = vs_out.cpx - org;
        vec2 blo = c - vs_out.box.xy;
        vec2 bhi = c + vs_out.box.xy;
        float full = 4.0 * vs_out.box.x * vs_out.box.y;
        float kept = rect_kept(blo, bhi, vs_out.cut0) / full * (rect_kept(blo, bhi, vs_out.cut1) / full);
        vs_out.box.z /= max(kept, 0.25);
    }
#endif
    float size = max(hi.x - lo.x, hi.y - lo.y) + 0.02;
#ifdef GEOMETRY_PATH
    vs_box = size > u_max_sprite ? vec4(lo - 0.01, hi + 0.01) : vec4(1.0, 1.0, 0.0, 0.0);
#else
    if (size > u_max_sprite) {
        cull();
        return;
    }
    // Clip-space z: the centre's depth (used only for early depth by the
    // floor benchmark; the splat passes write gl_FragDepth).
    float zc = clamp(2.0 * vs_out.centre_z - 1.0, -1.0, 1.0);
    gl_Position = vec4((lo + hi) / u_viewport - 1.0, zc, 1.0);
    gl_PointSize = size;
#endif
}
