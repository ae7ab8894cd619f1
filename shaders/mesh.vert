#version 330
// Polygon renderer (a), vertex stage.
// In: per-vertex position relative to the object's local origin, the face's
// normal and Phong material (faces are unshared, so material is per face).
// Out: local-frame position and normal for per-fragment two-sided Phong.
uniform mat4 u_mvp;          // clip <- local (float64 on the CPU, cast once)
in vec3 in_position;
in vec3 in_normal;
in vec3 in_kd;
in vec2 in_spec;             // (ks, shininess)
out vec3 v_position;
out vec3 v_normal;
out vec3 v_kd;
out vec2 v_spec;
void main() {
    v_position = in_position;
    v_normal = in_normal;
    v_kd = in_kd;
    v_spec = in_spec;
    gl_Position = u_mvp * vec4(in_position, 1.0);
}
