#version 430
// Volume renderer (b), the start pass, vertex stage: the box of each
// occupied brick, widened by u_margin voxels, as 12 triangles (36 vertices
// from gl_VertexID, wound counter-clockwise seen from outside), projected
// as volume.frag builds its rays (no matrices: the grid frame relative to
// the ray base, so a far eye loses nothing).
// In: per instance in_brick, the brick cell (x, y, z); u_forward, u_right,
// u_up, u_tan, u_base_c, u_base_s, u_center_g, u_shape as in volume.frag.
// Out: v_s, the distance along u_forward beyond the ray base (voxel units);
// clip z = 0, so only the eye's plane clips (the host draws the pass only
// when every box lies in front of it: render/volume.py start_pass_pays).
in vec3 in_brick;
uniform vec3 u_forward;
uniform vec3 u_right;
uniform vec3 u_up;
uniform vec2 u_tan;
uniform vec3 u_base_c;
uniform float u_base_s;
uniform vec3 u_center_g;
uniform ivec3 u_shape;
uniform float u_margin;
out float v_s;

// Corners (bit 0 x, bit 1 y, bit 2 z) of the 12 triangles.
const int CORNERS[36] = int[36](
    0, 2, 3, 0, 3, 1,  // z = 0, normal -z
    4, 5, 7, 4, 7, 6,  // z = 1, normal +z
    0, 4, 6, 0, 6, 2,  // x = 0, normal -x
    1, 3, 7, 1, 7, 5,  // x = 1, normal +x
    0, 1, 5, 0, 5, 4,  // y = 0, normal -y
    2, 6, 7, 2, 7, 3   // y = 1, normal +y
);

void main() {
    int k = CORNERS[gl_VertexID % 36];
    vec3 lo = in_brick * float(BRICK) - u_margin;
    vec3 hi = min(in_brick * float(BRICK) + float(BRICK), vec3(u_shape)) + u_margin;
    vec3 corner = mix(lo, hi, vec3(float(k & 1), float((k >> 1) & 1), float((k >> 2) & 1)));
    vec3 rel = corner - u_center_g - u_base_c;
    float s = dot(rel, u_forward);
    v_s = s;
    gl_Position = vec4(dot(rel, u_right) / u_tan.x, dot(rel, u_up) / u_tan.y, 0.0, u_base_s + s);
}
