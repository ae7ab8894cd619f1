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
#ifdef INSTANCED
// Per instance (divisor 1): frame-local <- asset-local affine matrix, and an
// RGB tint multiplying kd. Normals go through the cofactor matrix
// (det(A) A^-T: right for any invertible A; its sign does not matter, the
// shading is two-sided).
in mat4 in_instance;
in vec4 in_tint;
#endif
void main() {
#ifdef INSTANCED
    mat3 a = mat3(in_instance);
    vec4 p = in_instance * vec4(in_position, 1.0);
    v_position = p.xyz;
    v_normal = normalize(mat3(cross(a[1], a[2]), cross(a[2], a[0]), cross(a[0], a[1])) * in_normal);
    v_kd = in_kd * in_tint.rgb;
    v_spec = in_spec;
    gl_Position = u_mvp * p;
#else
    v_position = in_position;
    v_normal = in_normal;
    v_kd = in_kd;
    v_spec = in_spec;
    gl_Position = u_mvp * vec4(in_position, 1.0);
#endif
}
