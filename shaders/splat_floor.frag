#version 330
// Splat renderer (c): the benchmark floor's fragment stage.
// In: SplatData from splat.vert (sprite path), drawn as plain GL_POINTS
// covering the splats' own on-screen boxes. Out: the flat diffuse colour,
// alpha 1; no intersection, discard, lighting or gl_FragDepth (so early depth
// testing on the centre's depth stays on): what any point renderer pays.
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

out vec4 f_color;

void main() {
    f_color = vec4(fs_in.kd, 1.0);
}
