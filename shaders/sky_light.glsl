// Sky light with occlusion (the effect `sky`, define SKY_LIGHT; plantgen.settings.LookSettings):
// the ambient light a surface gets is the sky's seen along `sky_samples` cosine-weighted
// rays about its normal, traced through the model's BVH (bvh.glsl, any hit, up to
// `sky_reach` world units). A ray that escapes upwards sees the sky (shading.glsl's
// ambient colour); one that is blocked, or goes below the horizon (the ground's side),
// sees none. The mean is the fraction of the ambient colour that reaches the surface: on
// an open surface its expectation is 0.5 + 0.5 n.y, the unoccluded hemisphere's term.
//
// The rays are deterministic per pixel: shading.glsl's look_sample, a stratified sequence
// shifted by a hash of the pixel, no time seed. Rays start `sky_ray_offset` pixel
// footprints off the surface (as shadow.glsl's shadow rays). Include after row.glsl (or bvh.glsl): without SKY_LIGHT nothing of it, nor
// of the bvh.glsl it includes, is compiled (the loader pastes an include once, whatever
// the #if around it, so a program that needs row.glsl includes it before this file).

#if defined SKY_LIGHT && !defined SKY_LIGHT_GLSL
#define SKY_LIGHT_GLSL
#include "bvh.glsl"

// sky_samples (rays a pixel) is shading.glsl's
uniform float sky_reach;        // world units a ray looks for an occluder
uniform float sky_ray_offset;   // pixel footprints off the surface

// The fraction of the sky's light reaching p (`distance` from the eye) about unit normal
// n, traced with `samples` rays, in [0, 1] (x); with GROUND_BOUNCE (y) that of the
// ground's light: the rays below the horizon that no part of the model stops and that
// meet the ground within ground_reach of the point under p (shading.glsl's ground_share,
// which the untraced light takes, is its expectation on an open surface). The rays start
// off the surface along `side` (unit: the geometric normal on n's side).
vec2 sky_light_traced(vec3 p, vec3 n, vec3 side, float distance, int samples) {
    float lift = sky_ray_offset * (pixel_footprint.x * distance + pixel_footprint.y);
    vec3 o = p + lift * side;
    vec3 t, b;
    look_basis(n, t, b);
    vec2 shift = pixel_random(1u);
    vec2 open = vec2(0.0);
#if defined GROUND_BOUNCE
    float h = max(p.y + ground_eye_height, 0.0);
#endif
    for (int i = 0; i < samples; ++i) {
        vec2 u = look_sample(i, samples, shift);
        vec2 disc = look_disc(u);                     // cosine-weighted: the disc lifted
        vec3 d = normalize(disc.x * t + disc.y * b + sqrt(max(1.0 - u.x, 0.0)) * n);
        if (d.y > 0.0) {
            if (bvh_trace(o, d, 0.0, sky_reach, true, distance, true).prim < 0) open.x += 1.0;
            continue;
        }
#if defined GROUND_BOUNCE
        // below the horizon: the ground, where the ray meets it within its reach
        if (h * length(d.xz) > ground_reach * max(-d.y, 1e-30)) continue;
        float to_ground = h / max(-d.y, 1e-30);
        if (bvh_trace(o, d, 0.0, min(to_ground, sky_reach), true, distance, true).prim < 0) open.y += 1.0;
#endif
    }
    return open / float(samples);
}

#endif
