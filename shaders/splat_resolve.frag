#version 330
// Splat renderer (c), normalisation pass of quality "high", fragment stage.
// In: u_accum, the accumulation texture (sum of RGB * w, sum of w) and
// u_visible, the visibility pass's depth texture, both the framebuffer's size.
// Out: RGB = weighted mean colour, alpha 1 (coverage) and the visible depth
// (pushed back) where any splat landed; elsewhere nothing is written, so the
// background the caller cleared to (alpha 0) stays.
uniform sampler2D u_accum;
uniform sampler2D u_visible;

out vec4 f_color;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec4 acc = texelFetch(u_accum, px, 0);
    if (!(acc.a > 0.0)) discard;
    f_color = vec4(clamp(acc.rgb / acc.a, 0.0, 1.0), 1.0);
    gl_FragDepth = texelFetch(u_visible, px, 0).r;
}
