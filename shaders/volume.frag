#version 430
// Volume renderer (b), fragment stage: one ray per pixel through the sparse
// (PLAIN_MARCH: the first version, compositing inside the DDA; else each ray
// finds its next occupied voxel, then composites it)
// anisotropic texture, exact voxel chords by a two-level 3D DDA
// (Amanatides-Woo over 8^3 bricks, then over the voxels of occupied bricks).
//
// In (uniforms): camera basis u_forward/u_right/u_up (world, unit) with
// u_tan = (tan(fov/2) * aspect, tan(fov/2)); u_size framebuffer pixels;
// u_base_c the ray base point: the eye moved u_base_s (voxel units) along
// u_forward, in grid coordinates relative to the grid centre (the CPU puts
// it at the near side of the grid's bounding sphere, or at the eye when the
// eye is that close, so it is of the order of the grid size however far the
// eye is); u_near_b/u_far_b the near/far planes' distances along u_forward
// from the base (voxel units, may be negative); u_depth_k = far / (far -
// near); u_shape grid cells, u_bricks brick cells; u_center_g grid centre
// (grid coords, minimum corner at 0); u_num_dirs K; u_density_mode 0 facet /
// 1 kernel / 2 nearest; u_normal_mode 0 mean / 1 sample; u_shading_mode 0
// smooth (a run's sheets shaded by their linear models) / 1 flat; u_opacity_mode 0
// exponential / 1 linear / 2 split / 3 planar; u_pixel_angle the angle a
// pixel spans (radians, 2 tan(fov/2) / height) and u_sheet_pixels the voxel
// sizes in pixels over which every sheet fades in (render/volume.py:
// sheet_share); u_edge_filter 1 to count the share of the pixel's footprint
// that crosses each sheet, 0 to count the centre ray's crossing alone
// (render/volume.py:crossing_fraction); u_back_hide the share of a closed
// surface's back the planar law hides (render/volume.py:BACK_HIDE); u_background RGB; the lighting
// uniforms of lighting.glsl.
// In (laid out by aniso3d/rendering/volume.py:pack_volume; 2D textures t_top ...
// t_dirs, TEX_WIDTH texels a row, or with PLAIN_MARCH the same arrays as SSBOs):
// The grid is the texture's with a margin of GRID_PAD cells each side
// (render/sheet_edges.py: halos of edges on its outer planes).
//   0 top[]      int, brick id of each brick cell or -1 (x fastest)
//   1 pool[]     int, voxel index of each cell of each brick or -1
//   2 offs[]     uint, CSR offsets of each voxel's shading entries (M + 1)
//   3 dens[]     uint, density sphere D_v(N_p) (M x K) as float16 pairs
//   4 ent[]      uvec4 x 4 per entry: (mean normal xyz, area) as float bits;
//                (half2(kd.rg), half2(kd.b, ks), half shininess | sample
//                index << 16, half2(S11, S12) of its linear model);
//                the entry's sheet (render/volume.py:entry_sheets): plane
//                offset d as float bits (the plane n/|n| . x = d in
//                voxel-local coordinates, the voxel being the unit cube),
//                half2(fill, static share), half2(sheet area, crossing
//                slack), its edges (render/sheet_edges.py:edge_words: a
//                halo, area 0, has its edge's face in bits 8-10; bit 31 set:
//                a half-plane, render/sheet_halfplanes.py:halfplane_words; bits 31
//                and 3: a strip, render/sheet_strips.py:strip_words); the rest
//                of its linear model across its plane as half2 pairs (S22,
//                dkd/du, dkd/dv: render/sheet_slopes.py, smooth_sheet(); a
//                strip has none: word 12 is its far line's offset, float bits) and
//                sigma, the entry's closed (outward) vector area over its
//                area times normal (render/volume.py:closed_sign)
//   5 dirs[]     vec4, the K sample directions N_p (xyz)
// Out: f_color = (C + T * background, 1 - T), C the premultiplied colour and
// T the transmittance left; gl_FragDepth where 1 - T first reaches 0.5 (1.0
// if it never does). Rays that miss the grid are discarded.
// INSTANCED (volume.vert): the camera basis and the ray base come per
// instance as flat inputs v_forward, v_right, v_up, v_base_c and v_planes =
// (u_base_s, u_near_b, u_far_b), in the instance's grid frame; the uniforms
// u_forward/u_right/u_up stay the world camera basis, and the lights
// (u_light_dir, world) are turned into the instance's frame per fragment
// (the rotation taking the world basis to the instance's: L W^T). The
// depth is not meant to be kept (the scene draws without depth writes).
#ifdef INSTANCED
vec3 g_light_dir[4];
#define LIGHT_DIR g_light_dir
#endif
#include "lighting.glsl"

// Injected by render/volume.py: BRICK (brick edge in voxels), GRID_PAD and
// CLIP_MARGIN (the grid's margin, and the part of it rays cross), ALPHA_MAX
// (coverage cap below 1 so the optical depth stays finite), T_MIN (early
// termination; T_MIN_PLAIN in the plain marching), BIG (stands for an
// infinite ray parameter), RUN_SHARE, RUN_GAP, RUN_PARALLEL, RUN_STEEP and RUN_GRAZE
// (the runs of surface sheets: render/volume.py:sheet_terms), RUN_BACK_MIN and
// RUN_BACK_APART (a closed back's colour, and its coverage counted apart:
// render/volume.py), RUN_DEFER (what lies behind an open run's crossed
// surface goes behind it) and RUN_FRONT_GAP, RUN_FRONT_FILL (a run's
// sheets behind its voxel's first whole one add no colour: render/volume.py),
// HALF_C_RANGE
// and HALF_PIXELS (half-planes: render/sheet_halfplanes.py), STRIP_PIXELS
// (strips: render/sheet_strips.py), CREASE_BIT and FACE_CUT_BIT (entry word
// 11's flags of a crease sheet's halo and of a line halo cut by its face:
// render/sheet_line_halos.py).

uniform vec2 u_size;
uniform vec3 u_forward;
uniform vec3 u_right;
uniform vec3 u_up;
uniform vec2 u_tan;
uniform vec3 u_base_c;
uniform float u_base_s;
uniform float u_near_b;
uniform float u_far_b;
uniform float u_depth_k;
uniform ivec3 u_shape;
uniform ivec3 u_bricks;
uniform vec3 u_center_g;
uniform int u_num_dirs;
// The four modes are compiled in (render/volume.py: VolumeRenderer,
// DENSITY_MODE, NORMAL_MODE, SHADING_MODE, OPACITY_MODE: llvmpipe then drops
// the other modes' code, 5% of a frame; smooth shading's code costs 12-20%
// where it never runs) or read as uniforms.
#ifdef DENSITY_MODE
#define u_density_mode DENSITY_MODE
#else
uniform int u_density_mode;
#endif
#ifdef NORMAL_MODE
#define u_normal_mode NORMAL_MODE
#else
uniform int u_normal_mode;
#endif
#ifdef SHADING_MODE
#define u_shading_mode SHADING_MODE
#else
uniform int u_shading_mode;
#endif
#ifdef OPACITY_MODE
#define u_opacity_mode OPACITY_MODE
#else
uniform int u_opacity_mode;
#endif
uniform float u_pixel_angle;
uniform vec2 u_sheet_pixels;
uniform float u_edge_filter;
uniform float u_back_hide;
uniform vec3 u_background;
#ifdef INSTANCED
flat in vec3 v_forward;
flat in vec3 v_right;
flat in vec3 v_up;
flat in vec3 v_base_c;
flat in vec3 v_planes;
#define RAY_FORWARD v_forward
#define RAY_RIGHT v_right
#define RAY_UP v_up
#define RAY_BASE_C v_base_c
#define RAY_BASE_S v_planes.x
#define RAY_NEAR_B v_planes.y
#define RAY_FAR_B v_planes.z
#else
#define RAY_FORWARD u_forward
#define RAY_RIGHT u_right
#define RAY_UP u_up
#define RAY_BASE_C u_base_c
#define RAY_BASE_S u_base_s
#define RAY_NEAR_B u_near_b
#define RAY_FAR_B u_far_b
#endif

#ifdef PLAIN_MARCH
layout(std430, binding = 0) readonly buffer TopIndex { int top[]; };
layout(std430, binding = 1) readonly buffer BrickPool { int pool[]; };
layout(std430, binding = 2) readonly buffer Offsets { uint offs[]; };
layout(std430, binding = 3) readonly buffer Density { uint dens[]; };
layout(std430, binding = 4) readonly buffer Entries { uvec4 ent[]; };
layout(std430, binding = 5) readonly buffer Directions { vec4 dirs[]; };
#define TOP(i) top[i]
#define POOL(i) pool[i]
#define OFFS(i) offs[i]
#define ENT(i) ent[i]
#define DIR(i) dirs[i]

float density_at(int v, int p) {
    int i = v * u_num_dirs + p;
    vec2 pair = unpackHalf2x16(dens[i >> 1]);
    return (i & 1) == 0 ? pair.x : pair.y;
}
#else
// The same arrays as 2D textures TEX_WIDTH texels wide, element i at texel
// (i mod TEX_WIDTH, i div TEX_WIDTH); the density as float16 texels.
uniform isampler2D t_top;
uniform isampler2D t_pool;
uniform usampler2D t_offs;
uniform sampler2D t_dens;
uniform usampler2D t_ent;
uniform sampler2D t_dirs;
ivec2 texel(int i) { return ivec2(i & (TEX_WIDTH - 1), i >> TEX_SHIFT); }
ivec2 texel(uint i) { return ivec2(int(i & uint(TEX_WIDTH - 1)), int(i >> uint(TEX_SHIFT))); }
#define TOP(i) texelFetch(t_top, texel(i), 0).x
#define POOL(i) texelFetch(t_pool, texel(i), 0).x
#define OFFS(i) texelFetch(t_offs, texel(i), 0).x
#define ENT(i) texelFetch(t_ent, texel(i), 0)
#define DIR(i) texelFetch(t_dirs, texel(i), 0)

float density_at(int v, int p) {
    return texelFetch(t_dens, texel(v * u_num_dirs + p), 0).x;
}
#endif

#ifdef START_PASS
uniform sampler2D t_start;
#endif
out vec4 f_color;

// Per-ray state shared by the helpers below.
vec3 g_d;          // unit ray direction (world = grid axes)
float g_p;         // P(w) = |wx| + |wy| + |wz|
ivec4 g_nb;        // the 4 density samples nearest +-w
vec4 g_nbw;        // their interpolation weights (sum 1)
mat4x3 g_nbdir;    // their directions, as columns
vec3 g_color;      // premultiplied colour so far
float g_trans;     // transmittance so far
float g_tau_s;     // split: the sheets' optical depth so far (adds up linearly)
float g_trans_f;   // split: the clouds' transmittance so far
float g_dist0;     // distance (grid units) from the eye to the ray's origin o
float g_t50;       // ray parameter (grid units, from o) where 1 - T reached 0.5
bool g_has50;      // whether it did (t can be negative: o may lie past near)
// planar, edges filtered: a run of voxels holding surface sheets (entries
// whose static share is whole: sheets at every scale) near the ray, a few
// voxels long: one surface cut by voxel faces, or a silhouette's near and far
// sides. Its sheets are composited together when it closes (close_run()).
bool g_run;        // a run is open
vec3 g_run_ref;    // the unit normal of its first sheet
float g_run_end;   // ray parameter where its last voxel ends
vec4 g_run_band;   // share of the footprint crossing its sheets, on each side (xy), of
                   // their closed backs apart (zw: back_share, run_sides())
vec4 g_run_hit;    // fills of the sheets the centre ray crosses, the same way
float g_run_halo;  // the largest share of the footprint its halos carry past an edge
vec4 g_run_edge;   // band (xy) and hit (zw) on each side of the sheets an open edge
                   // or silhouette crease cuts: the largest (one edge's faces overlap)
vec3 g_run_col;    // its sheets' shaded colours, weighted by what they count
float g_run_w;     // ... the weights' sum
float g_run_tw;    // ... and the weighted crossing parameter (from o)
vec4 g_run_far;    // the far side's part of g_run_col (rgb) and g_run_w (w)
float g_run_wr;    // g_run_w's weights before the share of its colour each
                   // sheet shows (a closed back: vis, at least RUN_BACK_MIN)
float g_run_far_raw;  // ... the far side's (g_run_far.w: after it)
float g_run_hit_t; // where its centre ray first crossed a whole sheet on its entering side
// RUN_DEFER (render/volume.py): what lies behind the open run's crossed
// surface, composited as a layer behind the run when it closes.
vec3 g_behind_col;    // premultiplied colour
float g_behind_trans; // transmittance
float g_behind_t;     // ray parameter (from o) where it began

// Share in [0, 1] of a pixel's footprint, offsets o in [-half_w, half_w]
// along the sheet's normal from the centre ray, whose rays cross the sheet's
// plane inside the ray's stretch of the voxel: o in [lo, hi]. A point sample
// (half_w 0) is 1 or 0. Mirrors render/volume.py:crossing_fraction.
float crossing_fraction(float lo, float hi, float half_w) {
    if (half_w <= 1e-7) return (lo <= 0.0 && hi >= 0.0) ? 1.0 : 0.0;
    return clamp((min(hi, half_w) - max(lo, -half_w)) / (2.0 * half_w), 0.0, 1.0);
}

// The open run's coverage. Its sheets lie on the side where the ray met
// the first one (entering a surface) or on the side turned back (leaving
// it, as at a silhouette's far side). Where the centre ray crosses sheets on
// the entering side only (a surface cut by voxel faces, a corner), their
// fills, whole; elsewhere (a near miss, through both sides of a silhouette,
// or on the far side only: a tangent's rounded planes) the share of the
// footprint's rays that cross the side they cross most. A
// crossing at |n.w| < RUN_GRAZE (a closed surface's tangent, where the side
// falls either way as rounding goes) is on both sides.
// Mirrors render/volume.py:run_coverage. close_run() composites the open
// run as one layer, its depth that of its sheets each weighted by what it
// counts times what the run had left uncovered before its voxel (the
// front-most surface's), its colour the same on each side, the near side's
// where it covers the footprint and the far side's only where that covers
// more (run_color()), and closes it.
// Each side's band (xy) and hit (zw): the sheets' and their closed backs'
// sums, the larger, as a solid's back lies behind its own front (a box's
// silhouette crease: the face turned away covers what the face seen covers),
// and the sheets an edge cuts. Mirrors render/volume.py:run_sides.
vec4 run_sides() {
    return vec4(max(g_run_band.xy, g_run_band.zw) + g_run_edge.xy, max(g_run_hit.xy, g_run_hit.zw) + g_run_edge.zw);
}

float run_sheets() {
    vec4 sides = run_sides();
    vec2 band = sides.xy;
    vec2 hit = sides.zw;
    float cov = max(band.x, band.y);
    if (hit.x > 0.0 && !(hit.y > 0.0)) cov = max(cov, hit.x);
    return clamp(cov, 0.0, 1.0);
}

// ... and with its halos (render/sheet_edges.py): the larger.
float run_coverage() {
    return max(run_sheets(), g_run_halo);
}

// The open run's colour: each side's sheets' colours (its halos with the
// near side), the near side's weighted by its coverage b0, the far side's
// by what it covers beyond, b1 - b0: near a silhouette the far side lies
// behind the near side, whose colour shows where both cover the footprint.
// Mirrors render/volume.py:run_color.
vec3 run_color() {
    vec3 all_c = g_run_col / g_run_w;
    float w0 = g_run_w - g_run_far.w;
    if (!(g_run_far.w > 0.0) || !(w0 > 1e-6 * g_run_w)) return all_c;
    vec4 sides = run_sides();
    vec2 band = sides.xy;
    vec2 hit = sides.zw;
    float b0 = max(max(band.x, hit.y > 0.0 ? 0.0 : hit.x), g_run_halo);
    float b1 = max(band.y - b0, 0.0);
    if (!(b0 + b1 > 0.0)) return all_c;
    vec3 c0 = (g_run_col - g_run_far.rgb) / w0;
    vec3 c1 = g_run_far.rgb / g_run_far.w;
    // A solid's back the planar law hides shows the near side's colour: the
    // solid's front, which hides it (a crease turning away from the eye).
    c1 = mix(c0, c1, g_run_far_raw > 0.0 ? g_run_far.w / g_run_far_raw : 1.0);
    return (b0 * c0 + b1 * c1) / (b0 + b1);
}

void close_run() {
    if (!g_run) return;
    g_run = false;
    float cov = run_coverage();
    if (cov > 0.0 && g_run_w > 0.0) {
        float seg = g_trans * cov;
        if (!g_has50 && g_trans > 0.5 && g_trans - seg <= 0.5) {
            g_t50 = g_run_tw / g_run_w;
            g_has50 = true;
        }
        // A run whose near side is a thick solid's hidden back alone follows
        // that solid's front, drawn in part: it shows the colour seen so far.
        float near_w = g_run_w - g_run_far.w;
        float near_raw = g_run_wr - g_run_far_raw;
        bool hidden = g_trans < 1.0 && near_raw > 0.0 && near_w < near_raw && near_w <= 1.5 * RUN_BACK_MIN * near_raw;
        g_color += seg * (hidden ? g_color / (1.0 - g_trans) : run_color());
        g_trans -= seg;
    }
    // What lay behind its surface (RUN_DEFER), behind it.
    if (g_behind_trans < 1.0) {
        if (!g_has50 && g_trans > 0.5 && g_trans * g_behind_trans <= 0.5) {
            g_t50 = g_behind_t;
            g_has50 = true;
        }
        g_color += g_trans * g_behind_col;
        g_trans *= g_behind_trans;
        g_behind_col = vec3(0.0);
        g_behind_trans = 1.0;
    }
}

// Share of the pixel's footprint (width foot, grid units across the ray) on
// a sheet's side of its edge on voxel face `face` (2 axis + side) where the
// ray crosses the sheet's plane at the voxel-local p: sgn +1 for the
// sheet's own edge (the sheet on the voxel's side of the face), -1 for a
// halo (the sheet past it). The crossing lies delta from the face along its
// axis, delta |n.w| / sqrt(1 - n_a^2 - (w x n)_a^2) from the edge seen along
// the ray: a ramp over the footprint, 1/2 on the edge. Mirrors
// render/sheet_edges.py:edge_ramp.
float edge_ramp(uint face, vec3 p, vec3 nh, float nw, float foot, float sgn) {
    int ax = int(face >> 1u);
    float delta = (face & 1u) == 1u ? 1.0 - p[ax] : p[ax];
    float ca = cross(g_d, nh)[ax];
    float den = sqrt(max(1.0 - nh[ax] * nh[ax] - ca * ca, 1e-12));
    return clamp(0.5 + sgn * delta * abs(nw) / (den * max(foot, 1e-12)), 0.0, 1.0);
}

// What a sheet's edge on voxel face `face` leaves of its coverage (x) and
// its colour's weight (y) where the ray crosses its plane at p: an open
// edge, or a crease seen as a silhouette (its two half-planes, the sheet's
// and the partner's at angle phi about the edge, on one side of it on
// screen), the ramp, save that the halo of the face turned away carries
// nothing; any other crease (both faces seen, a concave corner) its
// coverage whole and its colour by the ramp; a halo the ramp (sgn -1).
// Mirrors render/sheet_edges.py:edge_factors.
vec2 edge_factors(uint face, bool crease, float phi, vec3 p, vec3 nh, float nw, float foot, float sgn) {
    float ramp = edge_ramp(face, p, nh, nw, foot, sgn);
    if (!crease) return vec2(ramp);
    int ax = int(face >> 1u);
    vec3 s = vec3(0.0);
    s[ax] = (face & 1u) == 1u ? -sgn : sgn;
    vec3 u = normalize(s - dot(s, nh) * nh);
    vec3 nu = cross(g_d, cross(nh, u));
    float al = dot(nu, u);
    float be = dot(nu, nh);
    bool silhouette = al * (al * cos(phi) + be * sin(phi)) > 0.0;
    if (sgn < 0.0) return (silhouette && sin(phi) * nw <= 0.0) ? vec2(0.0) : vec2(ramp);
    return silhouette ? vec2(ramp) : vec2(1.0, ramp);
}

float edge_angle(uint code) {
    return float(code) * (6.283185307179586 / 256.0) - 3.141592653589793;
}

// The first tangent of a sheet's unit normal nh (the second: cross(nh, t1)).
// Mirrors aniso3d/grid.py:tangent_frame.
vec3 tangent_t1(vec3 nh) {
    return normalize(cross(nh, abs(nh.x) < 0.9 ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0)));
}

// The inward unit direction u of a line at angle theta in that tangent
// frame. Mirrors render/sheet_halfplanes.py:line_inward.
vec3 line_inward(float theta, vec3 nh) {
    vec3 t1 = tangent_t1(nh);
    return cos(theta) * t1 + sin(theta) * cross(nh, t1);
}

// q0: the point of the plane nh.x = d nearest the voxel's centre, where the
// sheets' lines are measured from. Mirrors render/sheet_halfplanes.py:plane_origin.
vec3 plane_origin(vec3 nh, float d) {
    return vec3(0.5) - (dot(nh, vec3(0.5)) - d) * nh;
}

// Share of the pixel's footprint on the covered side of a line (its inward
// normal u at angle theta in the tangent frame of nh, offset c) where the
// ray crosses the sheet's plane nh.x = d at p: (p - q0).u - c from the line
// in the plane (q0 the plane's point nearest the voxel's centre), times
// |n.w| / sqrt(1 - (t.w)^2) seen along the ray (t = n x u): a ramp over the
// footprint, 1/2 on the line. Mirrors render/sheet_halfplanes.py:halfplane_ramp.
float line_ramp(float theta, float c, vec3 p, vec3 nh, float nw, float d, float foot) {
    vec3 u = line_inward(theta, nh);
    float e = dot(p - plane_origin(nh, d), u) - c;
    float tw = dot(cross(nh, u), g_d);
    float dist = e * abs(nw) / sqrt(max(1.0 - tw * tw, 1e-12));
    return clamp(0.5 + dist / max(foot, 1e-12), 0.0, 1.0);
}

// The same for a half-plane's line (entry word 11 `w`: bits 11-18 theta,
// bits 19-30 c).
float halfplane_ramp(uint w, vec3 p, vec3 nh, float nw, float d, float foot) {
    float c = (float((w >> 19u) & 4095u) / 4095.0 * 2.0 - 1.0) * HALF_C_RANGE;
    return line_ramp(edge_angle((w >> 11u) & 255u), c, p, nh, nw, d, foot);
}

// Share of the pixel's footprint between a strip's lines (the half-plane's
// of word 11 and the far one at offset `far`, word 12; infinite: none): the
// near line's ramp less the far one's. Mirrors
// render/sheet_strips.py:strip_cover.
float strip_cover(uint w, float far, vec3 p, vec3 nh, float nw, float d, float foot) {
    float near = halfplane_ramp(w, p, nh, nw, d, foot);
    if (isinf(far)) return near;
    return clamp(near - line_ramp(edge_angle((w >> 11u) & 255u), far, p, nh, nw, d, foot), 0.0, 1.0);
}

// What a crease half-plane's line (entry word 12: bits 11-30 the line, bits
// 0-7 its partner's angle phi about it) leaves of a run sheet's coverage (x)
// and colour weight (y) where the ray crosses its plane at p: the share of
// the footprint on its side for both where the crease is a silhouette, else
// the coverage whole and the colour by that share. Mirrors
// render/sheet_creases.py:crease_factors.
vec2 crease_factors(uint w, vec3 p, vec3 nh, float nw, float d, float foot) {
    float ramp = halfplane_ramp(w, p, nh, nw, d, foot);
    vec3 u = line_inward(edge_angle((w >> 11u) & 255u), nh);
    vec3 nu = cross(g_d, cross(nh, u));
    float al = dot(nu, u);
    float be = dot(nu, nh);
    float phi = edge_angle(w & 255u);
    bool silhouette = al * (al * cos(phi) + be * sin(phi)) > 0.0;
    return silhouette ? vec2(ramp) : vec2(1.0, ramp);
}

// The shaded colour of sheet e (unit normal nh, of length len_n stored:
// its coherence; plane nh.x = d; reflectance kd) at the point p of its
// plane, by its linear model across the plane (render/sheet_slopes.py: the
// shape operator (S11, S12, S22) and dkd/du, dkd/dv in the tangent frame of
// nh, relative to the plane's point nearest the voxel's centre; u and v
// clamped to a voxel). `slope` is entry word 7 (S11, S12); words 12-15 the
// rest. Mirrors render/sheet_slopes.py:smoothed.
vec3 smooth_sheet(uint e, uint slope, vec3 p, vec3 nh, float len_n, float d, vec3 kd, float ks, float shininess) {
    uvec4 m = ENT(4u * e + 3u);
    vec2 s12 = unpackHalf2x16(slope);
    vec2 m0 = unpackHalf2x16(m.x);  // S22, dkd_r/du
    vec2 m1 = unpackHalf2x16(m.y);  // dkd_r/dv, dkd_g/du
    vec2 m2 = unpackHalf2x16(m.z);  // dkd_g/dv, dkd_b/du
    vec2 m3 = unpackHalf2x16(m.w);  // dkd_b/dv
    vec3 t1 = tangent_t1(nh);
    vec3 t2 = cross(nh, t1);
    vec3 rel = p - plane_origin(nh, d);
    float u = clamp(dot(rel, t1), -1.0, 1.0);
    float v = clamp(dot(rel, t2), -1.0, 1.0);
    vec3 n = nh + (s12.x * u + s12.y * v) * t1 + (s12.y * u + m0.x * v) * t2;
    n *= len_n / length(n);
    vec3 k = max(kd + u * vec3(m0.y, m1.y, m2.y) + v * vec3(m1.x, m2.x, m3.x), 0.0);
    return clamp(shade(n, -g_d, k, ks, shininess, len_n), 0.0, 1.0);
}

// The 4 samples nearest the line of w (density is even: D(w) = D(-w), so a
// sample N_p also stands at -N_p) and Franke-Little weights
// ((R - a) / (R a))^2 with R the angle of the 5th nearest: continuous in w,
// and exact (weight 1) at a sample direction. Mirrors direction_weights().
void neighbours(vec3 w) {
    float bd[5] = float[5](-1.0, -1.0, -1.0, -1.0, -1.0);
    int bi[5] = int[5](0, 0, 0, 0, 0);
    for (int p = 0; p < u_num_dirs; ++p) {
        float c = abs(dot(DIR(p).xyz, w));
        if (c > bd[4]) {
            int j = 4;
            while (j > 0 && c > bd[j - 1]) {
                bd[j] = bd[j - 1];
                bi[j] = bi[j - 1];
                --j;
            }
            bd[j] = c;
            bi[j] = p;
        }
    }
    int k = min(4, u_num_dirs);
    float radius = u_num_dirs > 4 ? acos(clamp(bd[4], 0.0, 1.0)) : 2.0;
    vec4 wt = vec4(0.0);
    float a0 = acos(clamp(bd[0], 0.0, 1.0));
    for (int j = 0; j < 4; ++j) {
        g_nb[j] = bi[j];
        g_nbdir[j] = DIR(bi[j]).xyz;
        if (j < k) {
            float a = max(acos(clamp(bd[j], 0.0, 1.0)), 1e-6);
            wt[j] = a < radius ? pow((radius - a) / (radius * a), 2.0) : 0.0;
        }
    }
    float s = wt.x + wt.y + wt.z + wt.w;
    // At a sample direction, or when the 5 nearest tie, the nearest alone.
    g_nbw = (a0 <= 1e-6 || !(s > 0.0) || isinf(s)) ? vec4(1.0, 0.0, 0.0, 0.0) : wt / s;
    if (u_density_mode == 2) g_nbw = vec4(1.0, 0.0, 0.0, 0.0);
}

// Add voxel v, crossed over ray parameters [t0, t0 + chord] (grid units)
// from the voxel-local point x_in (the voxel is the unit cube).
void composite(int v, vec3 x_in, float t0, float chord) {
    if (g_run && t0 > g_run_end + RUN_GAP) {
        close_run();
#ifdef PLAIN_MARCH
        if (g_trans <= T_MIN_PLAIN) return;
#else
        if (g_trans <= T_MIN) return;
#endif
    }
    uint e0 = OFFS(v);
    uint e1 = OFFS(v + 1);
    float base_w = 0.0;        // sum A |n . w|: the facets' own projected area
    vec4 base_nb = vec4(0.0);  // the same at the 4 neighbour samples
    vec3 col_w = vec3(0.0);
    float sum_w = 0.0;
    vec3 col_a = vec3(0.0);
    float sum_a = 0.0;
    // Sheet laws (split, planar): each entry's sheet part and cloud part.
    bool sheets = u_opacity_mode >= 2;
    // Share of the sheets drawn as sheets at this scale (sheet_share()): all
    // of them where the voxel spans enough pixels.
    float pixels = 1.0 / ((g_dist0 + t0 + 0.5 * chord) * u_pixel_angle);
    float zoom = clamp((pixels - u_sheet_pixels.x) / max(u_sheet_pixels.y - u_sheet_pixels.x, 1e-9), 0.0, 1.0);
    float foot = u_edge_filter / pixels;  // the pixel's footprint, voxel units
    bool in_run = false;       // planar: the voxel holds surface sheets near the ray
    float run_open = 1.0;      // ... and what the run left uncovered before it
    bool steep = false;        // ... and the centre ray crosses one of them steeply
    float sheet_proj = 0.0;    // sum A_s |n . w|: the sheets' projected area
    float crossed = 0.0;       // planar: fills of the sheets crossed; split: sheet_proj
    float t_cross = 0.0;       // planar: fill-weighted crossing parameter from t0
    vec3 col_s = vec3(0.0);
    vec3 col_f = vec3(0.0);
    float sum_f = 0.0;
    vec3 view = -g_d;
    // planar: the backs of closed surfaces (render/volume.py:back_terms).
    float hide = u_opacity_mode == 3 ? u_back_hide : 0.0;
    float v_dot_w = 0.0;       // V . w: the hidden share of the closed facets' outward vector area along the ray
    // planar: where the centre ray first crosses a whole surface sheet of
    // the voxel with no edge or half-plane of its own; the run's sheets
    // crossed after it add nothing to its colour (render/volume.py:RUN_FRONT_GAP).
    float front_t = BIG;
    bool spread = false;       // planar: a partial sheet's share lies beside the centre ray (RUN_DEFER)
    if (RUN_FRONT_GAP >= 0.0 && sheets && u_opacity_mode == 3 && foot > 0.0 && e1 - e0 >= 2u) {
        for (uint e = e0; e < e1; ++e) {
            uvec4 sh = ENT(4u * e + 2u);
            vec2 fill_share = unpackHalf2x16(sh.y);
            // Not a halo, a surface sheet, no half-plane word, no edges on faces.
            if (((sh.w >> 8u) & 7u) != 7u || fill_share.y < RUN_SHARE || (sh.w >> 31u) != 0u || (sh.w & 0x77u) != 0x77u)
                continue;
            float share = 1.0 - (1.0 - fill_share.y) * (1.0 - zoom);
            vec2 area_slack = unpackHalf2x16(sh.z);
            if (share * fill_share.x < RUN_FRONT_FILL || !(share * area_slack.x > 0.0)) continue;
            vec3 n = uintBitsToFloat(ENT(4u * e).xyz);
            float len_n = length(n);
            vec3 nh = len_n > 0.0 ? n / len_n : vec3(0.0);
            float nw = dot(nh, g_d);
            if (abs(nw) < RUN_GRAZE) continue;
            float s_in = dot(nh, x_in) - uintBitsToFloat(sh.x);
            float s_out = s_in + nw * chord;
            if (-max(s_in, s_out) - area_slack.y <= 0.0 && -min(s_in, s_out) + area_slack.y >= 0.0)
                front_t = min(front_t, clamp(-s_in / nw, 0.0, chord));
        }
    }
    for (uint e = e0; e < e1; ++e) {
        uvec4 a = ENT(4u * e);
        uvec4 b = ENT(4u * e + 1u);
        vec3 n = uintBitsToFloat(a.xyz);
        float area = uintBitsToFloat(a.w);
        vec2 kd_rg = unpackHalf2x16(b.x);
        vec2 kd_b_ks = unpackHalf2x16(b.y);
        float shininess = unpackHalf2x16(b.z).x;
        base_w += area * abs(dot(n, g_d));
        base_nb += area * abs(n * g_nbdir);
        // Its closed part faces away from the eye (a solid's back): hidden
        // but for a share 1 - u_back_hide (the front is drawn spread).
        float closed = unpackHalf2x16(ENT(4u * e + 3u).w).y;
        // A thick solid's back (render/volume.py:thick_backs, stored moved
        // out by THICK_CODE) is hidden whole at the default share.
        bool thick = abs(closed) >= 0.75 * THICK_CODE;
        closed = thick ? sign(closed) * (abs(closed) - THICK_CODE) : closed;
        float hidden = thick ? min(1.0, hide * (1.0 / BACK_HIDE)) : hide;
        float nwo = closed * dot(n, g_d);
        v_dot_w += hidden * area * nwo;
        float vis = nwo > 0.0 ? 1.0 - hidden * min(abs(closed), 1.0) : 1.0;
        vec3 ns = u_normal_mode == 0 ? n : DIR(b.z >> 16u).xyz;
        float wgt = vis * area * abs(dot(ns, g_d));
        // The mean normal's length is its facets' coherence (lighting.glsl).
        vec3 c = clamp(shade(ns, view, vec3(kd_rg, kd_b_ks.x), kd_b_ks.y, shininess, length(n)), 0.0, 1.0);
        col_w += wgt * c;
        sum_w += wgt;
        col_a += vis * area * c;
        sum_a += vis * area;
        if (sheets) {
            uvec4 sh = ENT(4u * e + 2u);
            // A halo (render/sheet_edges.py) counts in runs only.
            uint halo_face = (sh.w >> 8u) & 7u;
            bool halo = halo_face != 7u;
            if (halo && !(u_opacity_mode == 3 && foot > 0.0)) continue;
            // A crease sheet drawn as its half-plane carries no halo (its
            // halos' bit CREASE_BIT).
            // (A line halo's word 11 holds its line's offset there, bit 31 set.)
            if (halo && (sh.w >> 31u) == 0u && ((sh.w >> CREASE_BIT) & 1u) == 1u && pixels >= HALF_PIXELS) continue;
            vec2 fill_share = unpackHalf2x16(sh.y);
            // A half-plane (render/sheet_halfplanes.py): a surface sheet
            // with an edge inside the voxel, where the footprint is filtered
            // and the voxel spans HALF_PIXELS or more.
            // A strip (render/sheet_strips.py): a closed surface's partial
            // sheet between two lines (or one), drawn from STRIP_PIXELS on.
            // A crease sheet's half-plane (render/volume.py:SHEET_CREASE):
            // a half-plane that is a surface sheet, its line in word 12.
            bool crease_line = (sh.w >> 31u) == 1u && fill_share.y >= RUN_SHARE;
            bool strip = (sh.w >> 31u) == 1u && (sh.w & 8u) != 0u && !crease_line;
            bool hp = (sh.w >> 31u) == 1u && u_opacity_mode == 3 && foot > 0.0
                      && pixels >= (strip ? STRIP_PIXELS : HALF_PIXELS);
            // A line halo (render/sheet_line_halos.py): a strip's lines
            // carried into the voxel beside it, drawn with them.
            bool line_halo = halo && (sh.w >> 31u) == 1u;
            if (line_halo && !hp) continue;
            float share = hp ? 1.0 : 1.0 - (1.0 - fill_share.y) * (1.0 - zoom);
            // A surface sheet counts in runs, but a crease sheet drawn as its
            // half-plane (render/volume.py:SHEET_CREASE). (A surface sheet
            // keeps its runs' near and far sides.)
            bool in_runs = fill_share.y >= RUN_SHARE && !hp;
            float sv = in_runs ? 1.0 : vis;
            float fill = sv * (hp ? 1.0 : share * fill_share.x);
            vec2 area_slack = unpackHalf2x16(sh.z);
            float a_s = sv * share * area_slack.x;
            float len_n = length(n);
            vec3 nh = len_n > 0.0 ? n / len_n : vec3(0.0);
            float nw = dot(nh, g_d);
            float ws = 0.0;
            if (u_opacity_mode == 2) {
                ws = a_s * abs(nw);
            } else if (a_s > 0.0) {
                // The plane is crossed inside the voxel where its signed
                // distance changes sign: in one voxel only, for a plane cut
                // into many, whatever the angle.
                float s_in = dot(nh, x_in) - uintBitsToFloat(sh.x);
                float s_out = s_in + nw * chord;
                float slack = area_slack.y;
                float lo = -max(s_in, s_out) - slack;
                float hi = -min(s_in, s_out) + slack;
                bool hit = lo <= 0.0 && hi >= 0.0;
                float th = clamp(nw != 0.0 ? -s_in / nw : 0.0, 0.0, chord);
                if (foot > 0.0 && in_runs) {
                    // A surface sheet: to the run. The footprint's rays,
                    // offset along the normal by up to half its width there,
                    // cross inside the voxel where the offset is in [lo, hi].
                    float half_w = 0.5 * foot * sqrt(max(1.0 - nw * nw, 0.0));
                    // (Without the slack: it only keeps a centre ray from
                    // slipping between neighbouring planes.)
                    // The share of the footprint on the sheet's side of its
                    // open edges (a halo: past its edge), where the ray
                    // crosses its plane.
                    vec2 ramp = vec2(1.0);  // (coverage, colour weight)
                    bool faced = halo || (sh.w & 0x77u) != 0x77u;
                    if (faced || crease_line) {
                        vec3 p = x_in + g_d * (nw != 0.0 ? -s_in / nw : 0.0);
                        if (faced) {
                            uint f0 = halo ? halo_face : sh.w & 7u;
                            uint f1 = (sh.w >> 4u) & 7u;
                            float sgn = halo ? -1.0 : 1.0;
                            if (f0 != 7u) ramp *= edge_factors(f0, ((sh.w >> 3u) & 1u) == 1u, edge_angle((sh.w >> 11u) & 255u), p, nh, nw, foot, sgn);
                            if (f1 != 7u) ramp *= edge_factors(f1, ((sh.w >> 7u) & 1u) == 1u, edge_angle((sh.w >> 19u) & 255u), p, nh, nw, foot, sgn);
                        }
                        // A crease sheet in a run: its half-plane's line cuts
                        // it as an edge (render/sheet_creases.py).
                        if (crease_line) ramp *= crease_factors(ENT(4u * e + 3u).x, p, nh, nw, uintBitsToFloat(sh.x), foot);
                    }
                    float band_all = fill * crossing_fraction(lo + slack, hi - slack, half_w);
                    float band = band_all * ramp.x;
                    float counted = hit ? fill * ramp.x : band;
                    float weight = hit ? fill * ramp.y : band_all * ramp.y;
                    if (counted > 0.0 || weight > 0.0) {
                        if (!in_run) {
                            run_open = g_run ? 1.0 - run_sheets() : 1.0;
                            if (!g_run) {
                                g_run = true;
                                g_run_ref = nh;
                                g_run_band = vec4(0.0);
                                g_run_hit = vec4(0.0);
                                g_run_halo = 0.0;
                                g_run_edge = vec4(0.0);
                                g_run_col = vec3(0.0);
                                g_run_far = vec4(0.0);
                                g_run_far_raw = 0.0;
                                g_run_wr = 0.0;
                                g_run_w = 0.0;
                                g_run_tw = 0.0;
                                g_run_hit_t = BIG;
                            }
                            g_run_end = t0 + chord;
                            in_run = true;
                        }
                        // The side: for a sheet near parallel to the run's
                        // first, whether the ray meets it as it met that one
                        // or turned back (whatever the facets' winding); one
                        // across it (a corner, a box's edge) stays on the
                        // first side.
                        float along = dot(nh, g_run_ref);
                        float same = abs(along) >= RUN_PARALLEL ? nw * dot(g_run_ref, g_d) * along : 1.0;
                        int side = same >= 0.0 ? 0 : 1;
                        if (halo) {
                            // Halos of one edge's sheets overlap (a box's
                            // silhouette: its two faces'): the largest.
                            g_run_halo = max(g_run_halo, counted);
                        } else if (ramp.x < 1.0) {
                            // Cut by an edge: the faces of a silhouette's
                            // crease overlap there, the largest. (No
                            // grazing rule: that is a smooth surface's
                            // tangent; a face seen edge-on beside a crease
                            // must not undo the surface behind it.)
                            g_run_edge[side] = max(g_run_edge[side], band);
                            g_run_edge[2 + side] = max(g_run_edge[2 + side], hit ? fill * ramp.x : 0.0);
                        } else {
                            // Its closed back's share apart (run_sides()).
                            float bk = RUN_BACK_APART != 0 && nwo > 0.0 ? min(abs(closed), 1.0) : 0.0;
                            g_run_band[side] += band * (1.0 - bk);
                            g_run_band[2 + side] += band * bk;
                            float fh = hit ? fill : 0.0;
                            if (hit && abs(nw) < RUN_GRAZE) {
                                g_run_hit += fh * vec4(1.0 - bk, 1.0 - bk, bk, bk);
                            } else {
                                g_run_hit[side] += fh * (1.0 - bk);
                                g_run_hit[2 + side] += fh * bk;
                                if (hit && side == 0) g_run_hit_t = min(g_run_hit_t, t0 + th);
                            }
                            steep = steep || (hit && abs(nw) >= RUN_STEEP);
                        }
                        // A halo is not hidden by the sheets before it (it
                        // lies beside them on screen, past an edge).
                        float wr = halo ? weight : run_open * weight;
                        // Hidden behind the voxel's first whole sheet (RUN_FRONT_GAP).
                        if (!halo && th > front_t + RUN_FRONT_GAP) wr = 0.0;
                        // A closed surface's back (vis < 1) keeps its
                        // coverage but hardly colours its side.
                        float shown = max(vis, RUN_BACK_MIN);
                        float wc = wr * shown;
                        // Shaded where the ray crosses the plane, by the
                        // sheet's linear model across it (sheet_slopes).
                        vec3 cr = c;
                        if (!halo && !crease_line && u_normal_mode == 0 && u_shading_mode == 0) {
                            vec3 p = x_in + g_d * (nw != 0.0 ? -s_in / nw : 0.0);
                            cr = smooth_sheet(e, b.w, p, nh, len_n, uintBitsToFloat(sh.x), vec3(kd_rg, kd_b_ks.x),
                                              kd_b_ks.y, shininess);
                        }
                        g_run_col += wc * cr;
                        g_run_w += wc;
                        g_run_wr += wr;
                        g_run_tw += wc * (t0 + th);
                        if (side == 1 && !halo) {
                            g_run_far += vec4(wc * cr, wc);
                            g_run_far_raw += wr;
                        }
                    }
                } else if (hit) {
                    // A partial sheet crossed: its fill, or a half-plane's
                    // share of the footprint on its covered side (not in a
                    // run: leaves in a voxel are independent).
                    ws = fill;
                    if (hp) {
                        vec3 p = x_in + g_d * (nw != 0.0 ? -s_in / nw : 0.0);
                        float share_on = strip ? strip_cover(sh.w, uintBitsToFloat(ENT(4u * e + 3u).x), p, nh, nw,
                                                             uintBitsToFloat(sh.x), foot * STRIP_FOOT)
                                               : halfplane_ramp(crease_line ? ENT(4u * e + 3u).x : sh.w, p, nh, nw,
                                                                uintBitsToFloat(sh.x), foot);
                        ws *= share_on;
                        // ... a line halo whose line crosses its face also
                        // cut by the face, as a sheet's halo past an edge.
                        if (line_halo && ((sh.w >> FACE_CUT_BIT) & 1u) == 1u)
                            ws *= edge_ramp(halo_face, p, nh, nw, foot, -1.0);
                        // Its share the footprint's beside the centre ray, not
                        // behind it (RUN_DEFER).
                        if (ws > 0.0 && (line_halo || share_on < 0.5)) spread = true;
                    }
                    t_cross += ws * th;
                }
            }
            if (!halo) sheet_proj += a_s * abs(nw);
            crossed += ws;
            col_s += ws * c;
            float wf = vis * max(area - a_s, 0.0) * abs(dot(ns, g_d));
            col_f += wf * c;
            sum_f += wf;
        }
    }
    vec4 dn = vec4(density_at(v, g_nb.x), density_at(v, g_nb.y), density_at(v, g_nb.z),
                   density_at(v, g_nb.w));
    float density;
    if (u_density_mode == 0) {
        // The facets' projected area, corrected by the density sphere's
        // residual interpolated from the neighbour samples.
        density = base_w + dot(g_nbw, dn - base_nb);
    } else {
        density = dot(g_nbw, dn);
    }
    // What the backs add to the density along the ray: max(0, V . w).
    density = max(density - max(v_dot_w, 0.0), 0.0);
    vec3 color = sum_w > 1e-7 * sum_a ? col_w / sum_w : (sum_a > 0.0 ? col_a / sum_a : vec3(0.0));
    // Per unit length (grid units) both laws have optical depth sigma, and
    // the mean chord 1/P gives coverage min(1, D/P).
    float sigma, seg;
    float t_after;
    if (u_opacity_mode == 0) {
        // exponential (Beer-Lambert): facets at independent random places.
        float alpha = clamp(density / g_p, 0.0, ALPHA_MAX);
        sigma = -log(1.0 - alpha) * g_p;
        seg = g_trans * (1.0 - exp(-sigma * chord));
    } else if (u_opacity_mode == 1) {
        // linear: coverage adds up along the ray and saturates at 1.
        sigma = min(max(density, 0.0), g_p);
        seg = min(g_trans, sigma * chord);
    } else {
        // The cloud part (what the sheets leave of D) as Beer-Lambert; the
        // sheets added linearly along the chord (split) or as crossed (planar).
        float alpha_f = clamp(max(density - sheet_proj, 0.0) / g_p, 0.0, ALPHA_MAX);
        sigma = -log(1.0 - alpha_f) * g_p;
        float keep_f = exp(-sigma * chord);
        float a_s;
        if (u_opacity_mode == 2) {
            a_s = min(sheet_proj, g_p) * chord;
            g_tau_s += a_s;
            g_trans_f *= keep_f;
            t_after = max(0.0, 1.0 - g_tau_s) * g_trans_f;
        } else {
            // Sheet and cloud share the facets: their coverages add.
            a_s = min(crossed, 1.0);
            t_after = g_trans * max(0.0, keep_f - a_s);
        }
        seg = g_trans - t_after;
        a_s = min(a_s, 1.0);
        float a_f = 1.0 - keep_f;
        if (a_s + a_f > 0.0) {
            vec3 cs = crossed > 0.0 ? col_s / crossed : vec3(0.0);
            vec3 cf = sum_f > 1e-7 * sum_a ? col_f / sum_f : color;
            color = (a_s * cs + a_f * cf) / (a_s + a_f);
        }
    }
    // A run crossed whole on its entering side, steeply, is settled: its far side
    // could only follow within RUN_GAP through an object under a voxel thick.
    vec2 run_hit = run_sides().zw;
    bool settled = steep && run_hit.x >= 1.0 && run_hit.y == 0.0;
    if (RUN_DEFER != 0 && u_opacity_mode == 3 && g_run && seg > 0.0 && g_trans > 0.0 && !spread) {
        float here = t0 + (crossed > 0.0 ? t_cross / crossed : 0.5 * chord);
        if (run_hit.x >= 1.0 && run_hit.y == 0.0 && g_run_hit_t <= here) {
            // Behind the run's surface: a layer behind it (RUN_DEFER).
            float a = seg / g_trans;
            if (g_behind_trans == 1.0) g_behind_t = here;
            g_behind_col += g_behind_trans * a * color;
            g_behind_trans *= 1.0 - a;
            if (settled) close_run();
            return;
        }
    }
    if (!(seg > 0.0)) {
        if (settled) close_run();
        return;
    }
    t_after = g_trans - seg;
    if (!g_has50 && t_after <= 0.5) {
        float dt = 0.0;
        if (g_trans > 0.5) {
            if (u_opacity_mode == 0) {
                dt = log(g_trans / 0.5) / sigma;
            } else if (u_opacity_mode == 1) {
                dt = (g_trans - 0.5) / sigma;
            } else if (u_opacity_mode == 2) {
                dt = chord * (g_trans - 0.5) / seg;
            } else {
                // The sheets alone take it there, or the cloud with them.
                float a_s = min(crossed, 1.0);
                dt = g_trans * (1.0 - a_s) <= 0.5 ? t_cross / crossed : -log(0.5 / g_trans + a_s) / sigma;
            }
        }
        g_t50 = t0 + dt;
        g_has50 = true;
    }
    g_color += seg * color;
    g_trans = t_after;
    if (settled) close_run();
}

// Amanatides-Woo set-up for cells of edge `size` inside [lo, hi) at ray
// parameter t. Zero direction components never step (no division by zero).
void dda_init(vec3 o, float t, float size, ivec3 lo, ivec3 hi,
              out ivec3 cell, out ivec3 stp, out vec3 tmax, out vec3 tdelta) {
    vec3 p = (o + g_d * t) / size;
    cell = clamp(ivec3(floor(p)), lo, hi - 1);
    for (int a = 0; a < 3; ++a) {
        float da = g_d[a];
        if (da > 0.0) {
            stp[a] = 1;
            tmax[a] = (float(cell[a] + 1) * size - o[a]) / da;
            tdelta[a] = size / da;
        } else if (da < 0.0) {
            stp[a] = -1;
            tmax[a] = (float(cell[a]) * size - o[a]) / da;
            tdelta[a] = -size / da;
        } else {
            stp[a] = 0;
            tmax[a] = BIG;
            tdelta[a] = BIG;
        }
    }
}

int min_axis(vec3 tm) {
    return (tm.x <= tm.y && tm.x <= tm.z) ? 0 : (tm.y <= tm.z ? 1 : 2);
}

void main() {
#ifdef INSTANCED
    {
        // World to the instance's frame: its camera basis L times the world's W^T.
        mat3 to_local = mat3(v_right, v_up, v_forward) * transpose(mat3(u_right, u_up, u_forward));
        for (int i = 0; i < 4; ++i) g_light_dir[i] = to_local * u_light_dir[i];
    }
#endif
    vec2 ndc = gl_FragCoord.xy / u_size * 2.0 - 1.0;
    // The pixel's ray is eye + s * (forward + lat), s the distance along
    // forward. Its origin o is where it crosses the base's plane (s =
    // u_base_s): the base plus the lateral offset u_base_s * lat, which is
    // of the order of the grid size for every ray that can meet the grid.
    // Nothing here holds the eye's own (possibly huge) position, so float32
    // keeps a fraction of a voxel however far the eye is; the direction's
    // float32 error only acts over the ray's length inside the grid.
    vec3 lat = ndc.x * u_tan.x * RAY_RIGHT + ndc.y * u_tan.y * RAY_UP;
    g_d = normalize(RAY_FORWARD + lat);
    // Axis components this small cross no cell boundary inside any grid.
    g_d = mix(g_d, vec3(0.0), lessThan(abs(g_d), vec3(1e-12)));
    g_p = abs(g_d.x) + abs(g_d.y) + abs(g_d.z);
    vec3 o = u_center_g + RAY_BASE_C + RAY_BASE_S * lat;
    g_dist0 = RAY_BASE_S * length(RAY_FORWARD + lat);

    // Ray parameter t (grid units from o) range: the grid's box, then
    // near/far. A point at t lies u_base_s + t * cos_f along forward.
    float cos_f = dot(g_d, RAY_FORWARD);
    float t0 = RAY_NEAR_B / cos_f;
    float t1 = RAY_FAR_B / cos_f;
    // The texture's box widened by CLIP_MARGIN voxels, where the halos lie,
    // inside the grid's margin of GRID_PAD (the rest of it is empty).
    float box_lo = float(GRID_PAD - CLIP_MARGIN);
    vec3 hi = vec3(u_shape) - box_lo;
    for (int a = 0; a < 3; ++a) {
        if (g_d[a] == 0.0) {
            if (o[a] < box_lo || o[a] > hi[a]) discard;
        } else {
            float ta = (box_lo - o[a]) / g_d[a];
            float tb = (hi[a] - o[a]) / g_d[a];
            t0 = max(t0, min(ta, tb));
            t1 = min(t1, max(ta, tb));
        }
    }
    if (!(t0 < t1)) discard;
#ifdef START_PASS
    // The start pass (volume_start.vert): where the ray first enters a
    // widened occupied brick, if it enters one; before that it meets no
    // occupied voxel.
    float s_start = texelFetch(t_start, ivec2(gl_FragCoord.xy), 0).r;
    if (!(s_start < 0.5 * BIG)) discard;
    t0 = max(t0, s_start / cos_f);
    if (!(t0 < t1)) discard;
#endif

    neighbours(g_d);
    g_color = vec3(0.0);
    g_trans = 1.0;
    g_tau_s = 0.0;
    g_trans_f = 1.0;
    g_t50 = 0.0;
    g_has50 = false;
    g_run = false;
    g_run_end = 0.0;
    g_behind_col = vec3(0.0);
    g_behind_trans = 1.0;
    g_behind_t = 0.0;

#ifdef PLAIN_MARCH
    ivec3 bcell, bstep, cell, stp;
    vec3 btmax, btdelta, tmax, tdelta;
    dda_init(o, t0, float(BRICK), ivec3(0), u_bricks, bcell, bstep, btmax, btdelta);
    float t = t0;
    int outer_max = u_bricks.x + u_bricks.y + u_bricks.z + 3;
    for (int it = 0; it < outer_max && g_trans > T_MIN_PLAIN; ++it) {
        float tb_exit = min(min(btmax.x, btmax.y), btmax.z);
        float tb_end = min(tb_exit, t1);
        int bid = TOP((bcell.z * u_bricks.y + bcell.y) * u_bricks.x + bcell.x);
        if (bid >= 0 && tb_end > t) {
            ivec3 lo = bcell * BRICK;
            ivec3 vhi = min(lo + BRICK, u_shape);
            dda_init(o, t, 1.0, lo, vhi, cell, stp, tmax, tdelta);
            float ti = t;
            for (int jt = 0; jt < 3 * BRICK + 3 && g_trans > T_MIN_PLAIN; ++jt) {
                float tx = min(min(tmax.x, tmax.y), tmax.z);
                float te = min(tx, tb_end);
                if (te > ti) {
                    ivec3 lc = cell - lo;
                    int v = POOL(bid * BRICK * BRICK * BRICK + (lc.z * BRICK + lc.y) * BRICK + lc.x);
                    if (v >= 0) composite(v, o + g_d * ti - vec3(cell), ti, te - ti);
                    ti = te;
                }
                if (tx >= tb_end) break;
                int a = min_axis(tmax);
                cell[a] += stp[a];
                tmax[a] += tdelta[a];
                if (cell[a] < lo[a] || cell[a] >= vhi[a]) break;
            }
        }
        t = max(t, tb_end);
        if (tb_exit >= t1) break;
        int a = min_axis(btmax);
        bcell[a] += bstep[a];
        btmax[a] += btdelta[a];
        if (bcell[a] < 0 || bcell[a] >= u_bricks[a]) break;
    }
    close_run();

#else
    ivec3 bcell, bstep, cell, stp, lo, vhi;
    vec3 btmax, btdelta, tmax, tdelta;
    dda_init(o, t0, float(BRICK), ivec3(0), u_bricks, bcell, bstep, btmax, btdelta);
    float t = t0;         // brick level: where the ray stands (as in the plain loop)
    float ti = t0;        // voxel level, inside the current brick
    float tb_exit = 0.0;  // where the ray leaves the current brick
    float tb_end = 0.0;   // ... or t1, if sooner
    int bid = -1;
    bool in_brick = false;
    bool alive = true;
    int budget = (u_bricks.x + u_bricks.y + u_bricks.z + 3) * (3 * BRICK + 4);
    while (alive && g_trans > T_MIN) {
        // Find the ray's next occupied voxel, then composite it: every pixel
        // of a SIMD batch composites at once (a composite per loop turn, not
        // one per DDA step that some lane happens to need).
        int v = -1;
        float tv = 0.0;
        float chord = 0.0;
        ivec3 vcell = ivec3(0);
        while (v < 0 && alive) {
            if (--budget < 0) {
                alive = false;
                break;
            }
            if (g_run && (in_brick ? ti : t) > g_run_end + RUN_GAP) {
                // Past the run: its surface is composited, and may end the ray.
                close_run();
                if (g_trans <= T_MIN) {
                    alive = false;
                    break;
                }
            }
            if (!in_brick) {
                tb_exit = min(min(btmax.x, btmax.y), btmax.z);
                tb_end = min(tb_exit, t1);
                bid = TOP((bcell.z * u_bricks.y + bcell.y) * u_bricks.x + bcell.x);
                if (bid >= 0 && tb_end > t) {
                    lo = bcell * BRICK;
                    vhi = min(lo + BRICK, u_shape);
                    dda_init(o, t, 1.0, lo, vhi, cell, stp, tmax, tdelta);
                    ti = t;
                    in_brick = true;
                    continue;
                }
            } else {
                float tx = min(min(tmax.x, tmax.y), tmax.z);
                float te = min(tx, tb_end);
                if (te > ti) {
                    ivec3 lc = cell - lo;
                    v = POOL(bid * BRICK * BRICK * BRICK + (lc.z * BRICK + lc.y) * BRICK + lc.x);
                    tv = ti;
                    chord = te - ti;
                    vcell = cell;
                    ti = te;
                }
                if (tx < tb_end) {
                    int a = min_axis(tmax);
                    cell[a] += stp[a];
                    tmax[a] += tdelta[a];
                    if (cell[a] >= lo[a] && cell[a] < vhi[a]) continue;
                }
                in_brick = false;
            }
            // Leave the brick.
            t = max(t, tb_end);
            if (tb_exit >= t1) {
                alive = false;
                break;
            }
            int a = min_axis(btmax);
            bcell[a] += bstep[a];
            btmax[a] += btdelta[a];
            if (bcell[a] < 0 || bcell[a] >= u_bricks[a]) alive = false;
        }
        if (v >= 0) composite(v, o + g_d * tv - vec3(vcell), tv, chord);
    }
    close_run();
    // Stopped early: what is left behind takes the colour seen so far
    // (an opaque surface keeps its own colour, not a trace of the background).
    if (g_trans <= T_MIN) {
        g_color /= 1.0 - g_trans;
        g_trans = 0.0;
    }
#endif

    vec3 rgb = clamp(g_color + g_trans * u_background, 0.0, 1.0);
    f_color = vec4(rgb, clamp(1.0 - g_trans, 0.0, 1.0));
    // The perspective projection's window depth of a point at distance s
    // along forward, far (s - near) / (s (far - near)), with s - near taken
    // from the base (both terms small), not as a difference of large numbers.
    float depth = 1.0;
    if (g_has50) {
        float sb = g_t50 * cos_f;  // distance along forward beyond the base
        depth = clamp(u_depth_k * (sb - RAY_NEAR_B) / (RAY_BASE_S + sb), 0.0, 1.0);
    }
    gl_FragDepth = depth;
}
