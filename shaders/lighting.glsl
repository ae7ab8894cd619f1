// Shared lighting model of all three renderers (METHOD.md "Reference conventions").
// Inputs (uniforms): u_ambient (RGB ambient light), u_num_lights, u_light_dir[i]
// (unit vector from the surface TOWARDS light i, world frame), u_light_color[i],
// u_normal_spread (1: shade an aggregate's normal spread, see below; 0: ignore it).
// shade(): ambient + Lambert diffuse + Phong specular, two-sided: the normal is
// flipped to face the viewer. Kept in step with aniso3d/rendering/lighting.py:shade_np.
//
// Normal spread (docs/shading.md). A voxel entry or a point stands for many
// facets; ``coherence`` is the length c = |N| of the area-weighted mean N of
// their unit normals (1: one plane). Shading the mean normal alone overstates
// the diffuse term (the mean of n.l is c (n.l), not n.l) and keeps the
// specular lobe as narrow as one facet's, so a minified rough surface looks
// smoother and brighter than its facets. With spread on:
// - diffuse: the mean of max(0, n_i . l) over the facets, taking n_i . l as
//   spread uniformly about c (n.l) with the variance the normals' tangential
//   spread gives it, (1 - c)(1 - (n.l)^2) (half-width a = sqrt(3) sigma):
//   c (n.l) where the whole spread is lit, 0 where none is, (mu + a)^2 / 4a
//   between;
// - specular: Toksvig's lobe for Phong's reflection vector, which turns by
//   twice the normal's angle: exponent s' = c s / (c + 4 s (1 - c)), and the
//   lobe's energy kept, (1 + s') / (1 + s) (the integral of cos^s is 2 pi / (s + 1)).
// At c = 1 both reduce exactly to the plain closed form.

#define MAX_LIGHTS 4
// The light directions shade() reads (a shader may name its own array, e.g.
// the lights turned into an instance's frame: volume.frag INSTANCED).
#ifndef LIGHT_DIR
#define LIGHT_DIR u_light_dir
#endif

uniform vec3 u_ambient;
uniform int u_num_lights;
uniform vec3 u_light_dir[MAX_LIGHTS];
uniform vec3 u_light_color[MAX_LIGHTS];
uniform int u_normal_spread;

// n: surface normal (any sign, need not be unit); v: unit vector from the
// surface to the eye; kd: diffuse RGB; ks: specular coefficient; shininess:
// Phong n; coherence: |mean unit normal| of the facets shaded together, in [0, 1].
vec3 shade(vec3 n, vec3 v, vec3 kd, float ks, float shininess, float coherence) {
    float len_n = length(n);
    n = len_n > 0.0 ? n / len_n : v;
    if (dot(n, v) < 0.0) n = -n;
    float c = u_normal_spread != 0 ? clamp(coherence, 0.0, 1.0) : 1.0;
    float spread = 1.0 - c;
    float s = shininess;
    float energy = 1.0;
    if (spread > 0.0) {
        s = c * shininess / max(c + 4.0 * shininess * spread, 1e-30);
        energy = (1.0 + s) / (1.0 + shininess);
    }
    vec3 color = u_ambient * kd;
    for (int i = 0; i < MAX_LIGHTS; ++i) {
        if (i >= u_num_lights) break;
        vec3 l = LIGHT_DIR[i];
        float ndl = dot(n, l);
        float diffuse = max(ndl, 0.0);
        if (spread > 0.0) {
            float mu = c * ndl;
            float a = sqrt(3.0 * spread * max(1.0 - ndl * ndl, 0.0));
            diffuse = mu >= a ? mu : (mu <= -a ? 0.0 : (mu + a) * (mu + a) / (4.0 * a));
        }
        float spec = 0.0;
        if (ndl > 0.0) {
            vec3 r = 2.0 * ndl * n - l;
            float rv = max(dot(r, v), 0.0);
            // pow(0, 0) is undefined in GLSL; a zero exponent means a constant lobe.
            spec = energy * (s > 0.0 ? pow(rv, s) : 1.0);
        }
        color += u_light_color[i] * (kd * diffuse + ks * spec);
    }
    return color;
}

// One plane (coherence 1): the plain closed form.
vec3 shade(vec3 n, vec3 v, vec3 kd, float ks, float shininess) {
    return shade(n, v, kd, ks, shininess, 1.0);
}
