#version 330
// Splat renderer (c), full-screen passes, vertex stage.
// In: nothing (gl_VertexID 0..2). Out: one triangle covering the viewport, at
// window depth 0.5, or at the far plane (1) with FAR (a pass run, by an early
// depth test GREATER, only where something was drawn).
void main() {
    vec2 p = vec2(float((gl_VertexID & 1) << 2), float((gl_VertexID & 2) << 1)) - 1.0;
#ifdef FAR
    gl_Position = vec4(p, 1.0, 1.0);
#else
    gl_Position = vec4(p, 0.0, 1.0);
#endif
}
