#version 330
// Splat renderer (c), shading pass of quality "fast", fragment stage
// (vertex stage: splat_resolve.vert, one triangle over the viewport).
// In: u_geodepth, the geometry pass's depth (1 where no splat landed: the
// geometry pass never writes 1, the far plane, since its test is "less");
// u_ids, its point id per pixel (meaningful only where depth < 1, so it needs
// no clearing); u_attrib, two RGBA32F texels per point, (normal, ks) and
// (kd, shininess), u_per_row points per texture row; u_ray and u_viewport
// give the pixel's eye ray; lighting.glsl's uniforms.
// Out: the visible splat's Phong colour, shade() with the view vector from
// its intersection point (along the pixel's ray), alpha 1 (coverage), and its
// depth. Other pixels are discarded, so the caller's background stays.
// Shading once per pixel rather than once per fragment spares the software
// rasteriser the hidden layers of a dense cloud.
#include "lighting.glsl"

uniform sampler2D u_geodepth;
uniform usampler2D u_ids;
uniform sampler2D u_attrib;
uniform int u_per_row;
uniform mat3 u_ray;
uniform vec2 u_viewport;

out vec4 f_color;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    float depth = texelFetch(u_geodepth, px, 0).r;
    if (!(depth < 1.0)) discard;
    int id = int(texelFetch(u_ids, px, 0).r);
    ivec2 at = ivec2((id % u_per_row) * 2, id / u_per_row);
    vec4 a0 = texelFetch(u_attrib, at, 0);
    vec4 a1 = texelFetch(u_attrib, at + ivec2(1, 0), 0);
    vec3 d = u_ray * vec3(1.0, gl_FragCoord.xy / u_viewport * 2.0 - 1.0);
    f_color = vec4(clamp(shade(a0.xyz, -normalize(d), a1.rgb, a0.w, a1.w, length(a0.xyz)), 0.0, 1.0), 1.0);
    gl_FragDepth = depth;
}
