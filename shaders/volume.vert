#version 430
// Volume renderer (b), vertex stage: one triangle that covers the viewport.
// In: nothing but gl_VertexID (draw 3 vertices, no vertex buffer).
// Out: clip positions only; volume.frag rebuilds each pixel's ray from
// gl_FragCoord and the camera uniforms.
// INSTANCED (a scene's instances of one grid, aniso3d/rendering/scene_draw.py):
// draw 6 vertices per instance, a quad over the instance's screen box; per
// instance (divisor 1) in_box = the box (x0, y0, x1, y1) in NDC, and the
// camera moved into the instance's frame (float64 on the CPU, as the
// per-instance passes compute it): in_forward, in_right, in_up (unit, the
// instance's grid frame), in_base_c and in_planes = (base_s, near_b, far_b)
// (see volume.frag's u_base_c ... u_far_b). Out: the same, flat, to volume.frag.
#ifdef INSTANCED
in vec4 in_box;
in vec3 in_forward;
in vec3 in_right;
in vec3 in_up;
in vec3 in_base_c;
in vec3 in_planes;
flat out vec3 v_forward;
flat out vec3 v_right;
flat out vec3 v_up;
flat out vec3 v_base_c;
flat out vec3 v_planes;

void main() {
    int k = gl_VertexID % 6;
    // Two triangles: corners (0,0) (1,0) (1,1), (0,0) (1,1) (0,1).
    float fx = (k == 1 || k == 2 || k == 4) ? 1.0 : 0.0;
    float fy = (k == 2 || k == 4 || k == 5) ? 1.0 : 0.0;
    gl_Position = vec4(mix(in_box.x, in_box.z, fx), mix(in_box.y, in_box.w, fy), 0.0, 1.0);
    v_forward = in_forward;
    v_right = in_right;
    v_up = in_up;
    v_base_c = in_base_c;
    v_planes = in_planes;
}
#else
void main() {
    vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
#endif
