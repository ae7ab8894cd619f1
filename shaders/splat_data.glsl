// The SplatData interface block: what splat.vert computes per splat and the
// later stages read, all flat. See splat.vert for what each member means.
// Each stage declares the block with its own qualifier and instance name:
//   splat.vert:        out SplatData SPLAT_DATA vs_out;
//   splat.geom:        in SplatData SPLAT_DATA gs_in[];  out SplatData SPLAT_DATA gs_out;
//   splat.frag, splat_floor.frag: in SplatData SPLAT_DATA fs_in;
// and splat.geom passes a splat on with SPLAT_DATA_COPY(gs_out, gs_in[0]).
// Macros (on one line each: GLSL 3.30 has no line continuation) rather than
// a struct member, because fragment inputs may not be structs in GLSL 3.30.

// The homography from the screen to the splat's plane (rows hu, hv, hw, hc),
// the eye's distance from that plane (num) and K / num (kn).
#define SPLAT_PLANE flat vec3 hu; flat vec3 hv; flat vec3 hw; flat vec3 hc; flat float num; flat float kn;
// Centre of the pixel holding the projected centre (-1e9 if none), the
// centre's window depth and the same pushed back by push, and the
// visibility pass's push-back along the view axis.
#define SPLAT_CENTRE flat vec2 centre_px; flat float centre_z; flat float centre_zp; flat float push;
// Index of the point in the uploaded buffer; normal (world orientation,
// its length the point's coherence), diffuse colour and (ks, shininess).
#define SPLAT_SHADING flat int id; flat vec3 n; flat vec3 kd; flat vec2 spec;
#ifdef AA
// Coverage-aware splats: projected centre in pixels (continuous); sub-pixel
// footprint (half-sides in pixels, amplitude); regime (0: sub-pixel box
// formula, 1: exact shape); linear depths of the bounding sphere's front and
// back; shade() at the centre (PASS 2); the pixel box drawn (x0, y0, x1, y1);
// and what the fragment stage would otherwise read from uniforms (see
// splat.vert): the pixel the plane rows are taken about (org), the range of
// t - t0 (srange), the linear depth and slice maps (lmap: lin = x + y (t - t0),
// slice = (lin - z) w), the push-back as a linear depth (pushz), and how many
// times the splat's coverage counts in its pixel's coverage sum (sided: 2 for
// a one-sided splat whose back is culled, else 1), the most a fragment's
// depth change across its pixel may extend its surface (reachz, linear
// depth: 0 but for a one-sided splat whose back is culled and a surface
// sheet's; splat.frag,
// surface_reach), the least of that a two-sided sheet's fragment must reach
// to count (graze, linear depth: 0 for any other splat), and its clip planes' lines in the image (cut0, cut1: rows
// over the pixel offsets from org, positive on the kept side; (1, 0, 0):
// none).
#define SPLAT_COVERAGE flat vec2 cpx; flat vec3 box; flat float regime; flat vec2 zrange; flat vec3 rgb; flat vec4 clip; flat vec2 org; flat vec2 srange; flat vec4 lmap; flat float pushz; flat float sided; flat float reachz; flat float graze; flat vec3 cut0; flat vec3 cut1;
#define SPLAT_COPY_COVERAGE(d, s) d.cpx = s.cpx; d.box = s.box; d.regime = s.regime; d.zrange = s.zrange; d.rgb = s.rgb; d.clip = s.clip; d.org = s.org; d.srange = s.srange; d.lmap = s.lmap; d.pushz = s.pushz; d.sided = s.sided; d.reachz = s.reachz; d.graze = s.graze; d.cut0 = s.cut0; d.cut1 = s.cut1;
#else
// Opaque splats (fast, blend): what the fragment stage would otherwise read
// from uniforms (see splat.vert): the pixel the plane rows are taken about
// (org) and (near - t0, far - t0, t0 - near, K) (frame: the range of t - t0,
// and the window depth K (t - near) / t's offset and K).
#define SPLAT_COVERAGE flat vec2 org; flat vec4 frame;
#define SPLAT_COPY_COVERAGE(d, s) d.org = s.org; d.frame = s.frame;
#endif

#define SPLAT_DATA { SPLAT_PLANE SPLAT_CENTRE SPLAT_SHADING SPLAT_COVERAGE }

#define SPLAT_DATA_COPY(d, s) d.hu = s.hu; d.hv = s.hv; d.hw = s.hw; d.hc = s.hc; d.num = s.num; d.kn = s.kn; d.centre_px = s.centre_px; d.centre_z = s.centre_z; d.centre_zp = s.centre_zp; d.push = s.push; d.id = s.id; d.n = s.n; d.kd = s.kd; d.spec = s.spec; SPLAT_COPY_COVERAGE(d, s)
