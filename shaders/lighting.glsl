// Shared lighting model of all three renderers (METHOD.md "Reference conventions").
// Inputs (uniforms): u_ambient (RGB ambient light), u_num_lights, u_light_dir[i]
// (unit vector from the surface TOWARDS light i, world frame), u_light_color[i].
// shade(): ambient + Lambert diffuse + Phong specular, two-sided: the normal is
// flipped to face the viewer. Kept in step with aniso3d/lighting.py:shade_np.

#define MAX_LIGHTS 4

uniform vec3 u_ambient;
uniform int u_num_lights;
uniform vec3 u_light_dir[MAX_LIGHTS];
uniform vec3 u_light_color[MAX_LIGHTS];

// n: surface normal (any sign, need not be unit); v: unit vector from the
// surface to the eye; kd: diffuse RGB; ks: specular coefficient; shininess: Phong n.
vec3 shade(vec3 n, vec3 v, vec3 kd, float ks, float shininess) {
    float len_n = length(n);
    n = len_n > 0.0 ? n / len_n : v;
    if (dot(n, v) < 0.0) n = -n;
    vec3 color = u_ambient * kd;
    for (int i = 0; i < MAX_LIGHTS; ++i) {
        if (i >= u_num_lights) break;
        vec3 l = u_light_dir[i];
        float ndl = dot(n, l);
        if (ndl <= 0.0) continue;
        vec3 r = 2.0 * ndl * n - l;
        float rv = max(dot(r, v), 0.0);
        // pow(0, 0) is undefined in GLSL; a zero exponent means a constant lobe.
        float spec = shininess > 0.0 ? pow(rv, shininess) : 1.0;
        color += u_light_color[i] * (kd * ndl + ks * spec);
    }
    return color;
}
