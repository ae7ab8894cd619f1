#version 430
// Volume renderer (b), the shading table: per shading entry, what shade()
// (lighting.glsl) computes without the view direction, for one lighting and
// normal mode. volume.frag (SHADE_TABLE) reads it and adds the specular lobe
// per pixel. Drawn with volume.vert's full-screen triangle into an RGBA32UI
// texture min(entries, TEX_WIDTH) texels wide, texel (x, y) holding entry
// y * TEX_WIDTH + x.
//
// In: t_ent, t_dirs (volume.frag's arrays, same layout), u_num_entries,
// u_normal_mode (0 mean / 1 sample), the lighting uniforms of lighting.glsl.
// Out: f_shade = (half2(D+.rg), half2(D+.b, D-.r), half2(D-.gb),
// half2(s', ks * energy)): D+ = shade_diffuse() of the entry's unit shading
// normal, D- that of the normal turned over (seen from behind), s' and
// energy from shade_lobe() (a positive s' kept at least 1e-7, so that it
// stays positive in float16 and pow(0, s') stays 0). An entry whose shading
// normal has no length, which shade() turns to the viewer (its diffuse term
// then depends on the view only through per-ray terms), holds kd in place of
// D+ and has the sign bit of s' set.
#include "lighting.glsl"

uniform usampler2D t_ent;
uniform sampler2D t_dirs;
uniform int u_num_entries;
uniform int u_normal_mode;

out uvec4 f_shade;

ivec2 texel(int i) { return ivec2(i & (TEX_WIDTH - 1), i >> TEX_SHIFT); }

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    int e = px.y * TEX_WIDTH + px.x;
    if (e >= u_num_entries) {
        f_shade = uvec4(0u);
        return;
    }
    uvec4 a = texelFetch(t_ent, texel(3 * e), 0);
    uvec4 b = texelFetch(t_ent, texel(3 * e + 1), 0);
    vec3 n = uintBitsToFloat(a.xyz);
    vec2 kd_rg = unpackHalf2x16(b.x);
    vec2 kd_b_ks = unpackHalf2x16(b.y);
    vec3 kd = vec3(kd_rg, kd_b_ks.x);
    float shininess = uintBitsToFloat(b.z);
    vec3 ns = u_normal_mode == 0 ? n : texelFetch(t_dirs, texel(int(b.w)), 0).xyz;
    // As shade() does: the coherence is the mean normal's length.
    float c = u_normal_spread != 0 ? clamp(length(n), 0.0, 1.0) : 1.0;
    vec2 lobe = shade_lobe(shininess, c);
    vec2 spec = vec2(lobe.x > 0.0 ? max(lobe.x, 1e-7) : 0.0, kd_b_ks.y * lobe.y);
    float len_s = length(ns);
    if (len_s > 0.0) {
        vec3 nu = ns / len_s;
        vec3 front = shade_diffuse(nu, kd, c);
        vec3 back = shade_diffuse(-nu, kd, c);
        f_shade = uvec4(packHalf2x16(front.rg), packHalf2x16(vec2(front.b, back.r)), packHalf2x16(back.gb),
                        packHalf2x16(spec));
    } else {
        f_shade = uvec4(packHalf2x16(kd.rg), packHalf2x16(vec2(kd.b, 0.0)), 0u,
                        packHalf2x16(spec) | 0x8000u);
    }
}
