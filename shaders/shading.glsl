// Shading shared by the ray caster and the raster renderer: material colours, one
// directional light with Blinn-Phong, and a sky background. Include after declaring
// nothing; it declares its own uniforms (their values: plantgen.render.materials's
// shading_uniforms and palette_uniforms; MAX_MATERIALS is a define from Python).
//
// The looks (plantgen.settings.LookSettings, each a define): TONE_MAP (to_display is a
// filmic tone curve in linear light, then the sRGB transfer curve; without it: clip, then
// c^(1/2.2)); TRANSLUCENT (shade_leaf: light falling on a leaf's far side comes through it,
// tinted by its albedo); SKY_LIGHT (shade_surface_sky: the sky's light as traced by
// sky_light.glsl, occluded, instead of the open hemisphere); GROUND_BOUNCE (the light the
// sunlit ground sends up, `ground_light`, reaches the surface from below, as much of it as
// the ground covers of the surface's hemisphere: ground_share; 0 where no ground is drawn).

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
// The looks' knobs (plantgen.settings.LookSettings.uniforms; unused without their define)
uniform float leaf_transmission;                // TRANSLUCENT: fraction through a leaf
uniform float exposure;                         // TONE_MAP: linear light scale before the curve
uniform float tone_knee;                        // TONE_MAP: the filmic curve's knee
uniform int sky_samples;                        // SKY_LIGHT: rays a pixel (sky_light.glsl)
uniform vec3 ground_light;                      // GROUND_BOUNCE: the ground's albedo times its light
uniform float ground_eye_height;                // GROUND_BOUNCE: the eye's height above the ground
uniform float ground_reach;                     // GROUND_BOUNCE: the ground's radius (to its fade's middle)

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

#if defined FRAGMENT_SHADER
// Deterministic per-pixel numbers for the looks' samples (sky_light.glsl, shadow.glsl's
// soft sun): an integer hash (the 32-bit finaliser of MurmurHash3 over a mix of the
// words) of the pixel and a salt; no time seed, so a frame drawn twice is the same.
uint look_hash(uvec3 v) {
    uint h = v.x * 0x9E3779B1u ^ (v.y + 0x7F4A7C15u) * 0x85EBCA77u ^ (v.z + 0x165667B1u) * 0xC2B2AE3Du;
    h ^= h >> 16; h *= 0x85EBCA6Bu;
    h ^= h >> 13; h *= 0xC2B2AE35u;
    h ^= h >> 16;
    return h;
}

// Two numbers in [0, 1) from this fragment's pixel and `salt`.
vec2 pixel_random(uint salt) {
    uvec2 px = uvec2(gl_FragCoord.xy);
    uint a = look_hash(uvec3(px, salt));
    uint b = look_hash(uvec3(px, salt ^ 0xA5A5A5A5u));
    return vec2(a >> 8, b >> 8) * (1.0 / 16777216.0);
}

// Sample i of n of a pixel's sequence in [0, 1)^2: n strata in u1, the golden ratio in u2,
// both shifted by `shift` (a Cranley-Patterson rotation, pixel_random).
vec2 look_sample(int i, int n, vec2 shift) {
    return fract(vec2((float(i) + 0.5) / float(n), 0.6180339887 * float(i)) + shift);
}

// A unit basis (t, b) perpendicular to unit n.
void look_basis(vec3 n, out vec3 t, out vec3 b) {
    vec3 a = abs(n.y) < 0.9 ? vec3(0.0, 1.0, 0.0) : vec3(1.0, 0.0, 0.0);
    t = normalize(cross(a, n));
    b = cross(n, t);
}

// A point of the unit disc, uniform in area, from u in [0, 1)^2.
vec2 look_disc(vec2 u) {
    float r = sqrt(u.x), phi = 6.283185307 * u.y;
    return r * vec2(cos(phi), sin(phi));
}
#endif

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

#if defined GROUND_BOUNCE
// The share of the ground's light that reaches a surface of unit normal n at eye-relative
// p: seen from p, h above it, the ground is a disc of radius ground_reach straight below
// (the plant stands at its middle), a cap of directions about -y of half-angle s with
// sin^2 s = R^2 / (R^2 + h^2). Its cosine-weighted share of n's hemisphere is the
// irradiance of a uniform cap over pi (J. Snyder, "Area light sources for real-time
// graphics", 1996; the cap cut by n's horizon where it straddles it): (1 - n.y) / 2 on the
// ground itself, less higher up, where the ground spans less of the view below.
float ground_share(vec3 n, vec3 p) {
    float reach = max(ground_reach, 1e-30);
    float h = max(p.y + ground_eye_height, 1e-6 * reach);
    float x = h / reach;                                   // cot s
    float sin2 = 1.0 / (1.0 + x * x);
    float c = -n.y;                                        // cos of n's angle to the cap's axis
    if (c * c > sin2) return max(c, 0.0) * sin2;           // the cap wholly above n's horizon, or below
    float s = sqrt(max(1.0 - c * c, 0.0));
    float y = clamp(-x * c / max(s, 1e-30), -1.0, 1.0);
    float sy = s * sqrt(max(1.0 - y * y, 0.0));
    return max(((c * acos(y) - x * sy) * sin2 + atan(sy, x)) * 0.3183098862, 0.0);
}
#endif

// The shares of the ambient light an open surface of unit normal n at eye-relative p
// gets: the sky's, 0.5 + 0.5 n.y, and with GROUND_BOUNCE the ground's (ground_share; 0
// without). sky_light.glsl traces both instead.
vec2 open_light(vec3 n, vec3 p) {
#if defined GROUND_BOUNCE
    return vec2(0.5 + 0.5 * n.y, ground_share(n, p));
#else
    return vec2(0.5 + 0.5 * n.y, 0.0);
#endif
}

// The ambient light of `share` (open_light's or sky_light.glsl's): the sky's colour times
// its share, plus with GROUND_BOUNCE the light the ground reflects times its share.
vec3 ambient_light(vec2 share) {
#if defined GROUND_BOUNCE
    return ambient_color * share.x + ground_light * share.y;
#else
    return ambient_color * share.x;
#endif
}

// One directional light, Blinn-Phong, plus a hemispherical ambient term (and with
// GROUND_BOUNCE the ground's light from below).
// normal and to_eye are unit vectors; the normal is flipped to face the eye.
// `light_visibility` in [0, 1] scales the direct light (1: lit, 0: in shadow; see shadow.glsl).
// p: the eye-relative position (the ground's light depends on the height above it).
vec3 shade_surface_visible(vec3 albedo, int material, vec3 normal, vec3 to_eye, float occlusion,
                           float light_visibility, vec3 p) {
    int m = clamp(material, 0, MAX_MATERIALS - 1);
    vec3 n = dot(normal, to_eye) < 0.0 ? -normal : normal;
    float diffuse = max(dot(n, light_dir), 0.0) * light_visibility;
    vec3 halfway = normalize(light_dir + to_eye);
    float specular = diffuse > 0.0
        ? material_gloss[m].x * pow(max(dot(n, halfway), 0.0), material_gloss[m].y) : 0.0;
    vec3 lit = albedo * (ambient_light(open_light(n, p)) * occlusion + light_color * diffuse)
             + light_color * specular * light_visibility;
    return lit;
}

vec3 shade_surface(vec3 albedo, int material, vec3 normal, vec3 to_eye, float occlusion, vec3 p) {
    return shade_surface_visible(albedo, material, normal, to_eye, occlusion, 1.0, p);
}

// As shade_surface_visible, the ambient light's shares given whole: `share` (x: of the
// sky's colour, y: of the ground's light) reaching the surface, open_light's on an open
// surface (sky_light.glsl traces them); `n` faces the eye.
vec3 shade_surface_sky(vec3 albedo, int material, vec3 n, vec3 to_eye, vec2 share, float light_visibility) {
    int m = clamp(material, 0, MAX_MATERIALS - 1);
    float diffuse = max(dot(n, light_dir), 0.0) * light_visibility;
    vec3 halfway = normalize(light_dir + to_eye);
    float specular = diffuse > 0.0
        ? material_gloss[m].x * pow(max(dot(n, halfway), 0.0), material_gloss[m].y) : 0.0;
    return albedo * (ambient_light(share) + light_color * diffuse) + light_color * specular * light_visibility;
}

// A leaf, a thin sheet: the side the eye sees (`n`, facing the eye) shaded as a surface,
// lit by the ambient shares `front` (shade_surface_sky); with TRANSLUCENT the light
// falling on the far side comes through, `leaf_transmission` of it, tinted by the albedo:
// the sun (diffuse on the far side, times its visibility) and the ambient shares `back`.
// Open: front = open_light(n, p), back = open_light(-n, p).
vec3 shade_leaf(vec3 albedo, int material, vec3 n, vec3 to_eye, vec2 front, vec2 back, float light_visibility) {
    vec3 lit = shade_surface_sky(albedo, material, n, to_eye, front, light_visibility);
#if defined TRANSLUCENT
    float behind = max(-dot(n, light_dir), 0.0) * light_visibility;
    lit += leaf_transmission * albedo * (light_color * behind + ambient_light(back));
#endif
    return lit;
}

#if defined TONE_MAP
// The tone curve, per channel in linear light, after `exposure`; 0 -> 0, increasing, below
// 1. The numpy twin: plantgen.gl.supersample.tone_curve.
#if defined TONE_ACES
// The rational fit of ACES's reference rendering and output transforms published by
// K. Narkowicz ("ACES Filmic Tone Mapping Curve", 2016): x (2.51 x + 0.03) / (x (2.43 x +
// 0.59) + 0.14); increasing for x >= 0 (its slope's numerator, 1.408 x^2 + 0.703 x +
// 0.0042, is positive); 1 -> 0.80.
vec3 tone_curve(vec3 x) {
    x = max(x * exposure, 0.0);
    return clamp(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
}
#else
// Filmic: the identity up to the knee k, then k + (1 - k)(1 - exp(-(x - k) / (1 - k))),
// whose slope is 1 at the knee and which tends to 1: highlights roll off, never clip.
vec3 tone_curve(vec3 x) {
    x = max(x * exposure, 0.0);
    vec3 shoulder = tone_knee + (1.0 - tone_knee) * (1.0 - exp(-(x - tone_knee) / (1.0 - tone_knee)));
    return mix(x, shoulder, step(tone_knee, x));
}
#endif

// The sRGB transfer curve (IEC 61966-2-1) of linear values in [0, 1].
vec3 srgb_encode(vec3 c) {
    return mix(12.92 * c, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c));
}

// Linear colour to display: the tone curve, then sRGB.
vec3 to_display(vec3 linear) { return srgb_encode(tone_curve(linear)); }
#else
// Linear colour to display (sRGB-like gamma).
vec3 to_display(vec3 linear) { return pow(clamp(linear, 0.0, 1.0), vec3(1.0 / 2.2)); }
#endif

#endif
