#version 330
// Viewer: one screen rectangle (the scene image or a text panel), vertex stage.
// In: gl_VertexID 0..3 (a triangle strip, no buffers).
// u_rect: (x0, y0, x1, y1) in normalised device coordinates.
// u_flip: 1 for images stored top row first (Pillow), 0 for GL textures.
// Out: v_uv, texture coordinates of the corner.
uniform vec4 u_rect;
uniform int u_flip;
out vec2 v_uv;
void main() {
    vec2 c = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1));
    v_uv = vec2(c.x, u_flip == 1 ? 1.0 - c.y : c.y);
    gl_Position = vec4(mix(u_rect.xy, u_rect.zw, c), 0.0, 1.0);
}
