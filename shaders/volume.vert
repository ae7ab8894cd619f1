#version 430
// Volume renderer (b), vertex stage: one triangle that covers the viewport.
// In: nothing but gl_VertexID (draw 3 vertices, no vertex buffer).
// Out: clip positions only; volume.frag rebuilds each pixel's ray from
// gl_FragCoord and the camera uniforms.
void main() {
    vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
