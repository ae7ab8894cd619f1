#version 330
// Viewer: one screen rectangle, fragment stage.
// In: v_uv; u_tex, the image; u_opaque, 1 for the scene (alpha forced to 1).
// Out: the texture's colour (blended over the scene for text panels).
uniform sampler2D u_tex;
uniform int u_opaque;
in vec2 v_uv;
out vec4 f_color;
void main() {
    vec4 c = texture(u_tex, v_uv);
    f_color = u_opaque == 1 ? vec4(c.rgb, 1.0) : c;
}
