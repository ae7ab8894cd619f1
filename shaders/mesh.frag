#version 330
// Polygon renderer (a), fragment stage: flat face normal, two-sided Phong.
// In: local-frame position/normal/material from mesh.vert; u_eye is the eye
// position in the same local frame. Out: RGBA colour.
#include "lighting.glsl"
uniform vec3 u_eye;
in vec3 v_position;
in vec3 v_normal;
in vec3 v_kd;
in vec2 v_spec;
out vec4 f_color;
void main() {
    vec3 v = normalize(u_eye - v_position);
    f_color = vec4(clamp(shade(v_normal, v, v_kd, v_spec.x, v_spec.y), 0.0, 1.0), 1.0);
}
