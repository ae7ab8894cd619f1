#version 330
// Splat renderer (c), geometry stage of the large-splat path.
// In: one point from splat.vert (compiled with GEOMETRY_PATH): its SplatData
// and vs_box, the pixel box of its splat, or an empty box (x0 > x1) for a
// splat the point-sprite path draws or nobody draws.
// Out: a screen-aligned quad (triangle strip) covering the box at clip z = 0,
// carrying SplatData unchanged (with AA, its members too); splat.frag decides
// every pixel exactly.
layout(points) in;
layout(triangle_strip, max_vertices = 4) out;

uniform vec2 u_viewport;

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
#ifdef AA
    flat vec2 cpx;
    flat vec3 box;
    flat float regime;
    flat vec2 zrange;
    flat vec3 rgb;
    flat vec4 clip;
#endif
} gs_in[];

flat in vec4 vs_box[];

out SplatData {
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
#ifdef AA
    flat vec2 cpx;
    flat vec3 box;
    flat float regime;
    flat vec2 zrange;
    flat vec3 rgb;
    flat vec4 clip;
#endif
} gs_out;

void main() {
    vec4 box = vs_box[0];
    if (box.x > box.z) return;
    vec4 ndc = box / u_viewport.xyxy * 2.0 - 1.0;
    vec2 corner[4] = vec2[4](ndc.xy, ndc.zy, ndc.xw, ndc.zw);
    for (int i = 0; i < 4; ++i) {
        gs_out.hu = gs_in[0].hu;
        gs_out.hv = gs_in[0].hv;
        gs_out.hw = gs_in[0].hw;
        gs_out.hc = gs_in[0].hc;
        gs_out.num = gs_in[0].num;
        gs_out.kn = gs_in[0].kn;
        gs_out.centre_px = gs_in[0].centre_px;
        gs_out.centre_z = gs_in[0].centre_z;
        gs_out.centre_zp = gs_in[0].centre_zp;
        gs_out.push = gs_in[0].push;
        gs_out.id = gs_in[0].id;
        gs_out.n = gs_in[0].n;
        gs_out.kd = gs_in[0].kd;
        gs_out.spec = gs_in[0].spec;
#ifdef AA
        gs_out.cpx = gs_in[0].cpx;
        gs_out.box = gs_in[0].box;
        gs_out.regime = gs_in[0].regime;
        gs_out.zrange = gs_in[0].zrange;
        gs_out.rgb = gs_in[0].rgb;
        gs_out.clip = gs_in[0].clip;
#endif
        gl_Position = vec4(corner[i], 0.0, 1.0);
        EmitVertex();
    }
    EndPrimitive();
}
