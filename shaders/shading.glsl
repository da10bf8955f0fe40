// Shading shared by the ray caster and the raster renderer: material colours, one
// directional light with Blinn-Phong, and a sky background. Include after declaring
// nothing; it declares its own uniforms (their values: plantgen.render.materials's
// shading_uniforms and palette_uniforms; MAX_MATERIALS is a define from Python).

#ifndef SHADING_GLSL
#define SHADING_GLSL


uniform vec3 light_dir;                         // unit, from the surface towards the light
uniform vec3 light_color;
uniform vec3 ambient_color;
uniform vec3 sky_zenith;
uniform vec3 sky_horizon;
uniform vec3 ground_tint;                       // sky colour below the horizon
uniform vec3 material_dark[MAX_MATERIALS];      // albedo where the texture is low
uniform vec3 material_light[MAX_MATERIALS];     // albedo where the texture is high
uniform vec2 material_gloss[MAX_MATERIALS];     // (specular strength, Blinn-Phong exponent)

// Sky seen along unit direction `dir` (y up): horizon haze to zenith blue, darker below.
vec3 sky_color(vec3 dir) {
    float up = dir.y;
    if (up >= 0.0) return mix(sky_horizon, sky_zenith, pow(up, 0.6));
    return mix(sky_horizon, ground_tint, pow(-up, 0.5));
}

// Albedo of material `material` where its texture (a height map) reads `texel` in [0, 1].
vec3 material_albedo(int material, float texel) {
    int m = clamp(material, 0, MAX_MATERIALS - 1);
    return mix(material_dark[m], material_light[m], texel);
}

// The shading normal that never turns its back on the eye (the numpy twin:
// plantgen.geometry.skeletons.frusta.facing_normals). n: the interpolated normal (8); n_true: the
// surface's own; to_eye: unit. Seen from behind (inside a tube) both are negated first;
// then where n's cosine with the eye is below TOL_FACING_MIN it is bent towards n_true by
// the least amount that brings it back: continuous, never negated.
vec3 facing_normal(vec3 n, vec3 n_true, vec3 to_eye) {
    if (dot(n_true, to_eye) < 0.0) { n = -n; n_true = -n_true; }
    float c = dot(n, to_eye);
    if (c >= TOL_FACING_MIN) return n;
    float lambda = (TOL_FACING_MIN - c) / max(dot(n_true, to_eye), 1e-30);
    vec3 bent = n + lambda * n_true;
    float len = length(bent);
    return len > 0.0 ? bent / len : n_true;
}

// The unit normal of the facet the rasteriser draws at eye-relative `position` (from the
// screen-space derivatives), turned to agree with `fallback`, which it is where the
// derivatives vanish. Fragment shaders only.
#if defined FRAGMENT_SHADER
vec3 facet_normal(vec3 position, vec3 fallback) {
    vec3 facet = cross(dFdx(position), dFdy(position));
    vec3 n = dot(facet, facet) > 0.0 ? normalize(facet) : fallback;
    return dot(n, fallback) < 0.0 ? -n : n;
}
#endif

// One directional light, Blinn-Phong, plus a hemispherical ambient term.
// normal and to_eye are unit vectors; the normal is flipped to face the eye.
// `light_visibility` in [0, 1] scales the direct light (1: lit, 0: in shadow; see shadow.glsl).
vec3 shade_surface_visible(vec3 albedo, int material, vec3 normal, vec3 to_eye, float occlusion,
                           float light_visibility) {
    int m = clamp(material, 0, MAX_MATERIALS - 1);
    vec3 n = dot(normal, to_eye) < 0.0 ? -normal : normal;
    float diffuse = max(dot(n, light_dir), 0.0) * light_visibility;
    vec3 halfway = normalize(light_dir + to_eye);
    float specular = diffuse > 0.0
        ? material_gloss[m].x * pow(max(dot(n, halfway), 0.0), material_gloss[m].y) : 0.0;
    float sky_light = 0.5 + 0.5 * n.y;
    vec3 lit = albedo * (ambient_color * sky_light * occlusion + light_color * diffuse)
             + light_color * specular * light_visibility;
    return lit;
}

vec3 shade_surface(vec3 albedo, int material, vec3 normal, vec3 to_eye, float occlusion) {
    return shade_surface_visible(albedo, material, normal, to_eye, occlusion, 1.0);
}

// Linear colour to display (sRGB-like gamma).
vec3 to_display(vec3 linear) { return pow(clamp(linear, 0.0, 1.0), vec3(1.0 / 2.2)); }

#endif
