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

#include "splat_data.glsl"

in SplatData SPLAT_DATA gs_in[];

flat in vec4 vs_box[];

out SplatData SPLAT_DATA gs_out;

void main() {
    vec4 box = vs_box[0];
    if (box.x > box.z) return;
    vec4 ndc = box / u_viewport.xyxy * 2.0 - 1.0;
    vec2 corner[4] = vec2[4](ndc.xy, ndc.zy, ndc.xw, ndc.zw);
    for (int i = 0; i < 4; ++i) {
        SPLAT_DATA_COPY(gs_out, gs_in[0])
        gl_Position = vec4(corner[i], 0.0, 1.0);
        EmitVertex();
    }
    EndPrimitive();
}
