#version 330
// Splat renderer (c): the benchmark floor's fragment stage.
// In: SplatData from splat.vert (sprite path), drawn as plain GL_POINTS
// covering the splats' own on-screen boxes. Out: the flat diffuse colour,
// alpha 1; no intersection, discard, lighting or gl_FragDepth (so early depth
// testing on the centre's depth stays on): what any point renderer pays.
#include "splat_data.glsl"

in SplatData SPLAT_DATA fs_in;

out vec4 f_color;

void main() {
    f_color = vec4(fs_in.kd, 1.0);
}
