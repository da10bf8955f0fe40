// Shadow map look-up for one directional light (plantgen.render.passes): included by the
// programs that receive shadows (the ray caster and the ground) when SHADOWS is defined;
// with SHADOW_RAYS instead shadow rays through the BVH (no map).
//
// The map is an orthographic depth image along the light: texel (i, j) holds the depth,
// as (z - near) / (far - near), of the first surface met by the light ray through the
// texel's centre (the ray-cast frusta write their analytic hit, the ground its plane).
//
// Filtering: percentage-closer filtering over a 3x3 tent of texels (16 texel fetches),
// each texel compared on its own. Bias: the receiver-plane depth, i.e. the receiver's
// depth is extrapolated to each texel centre along the plane of its (known) normal before
// the comparison, so a flat lit surface never shadows itself however grazing the light;
// only a small constant `shadow_bias` (world units) remains, so shadows stay attached.
// Positions are relative to the render origin (the camera eye), like every other input.

#ifndef SHADOW_GLSL
#define SHADOW_GLSL

#if defined SHADOW_RAYS
// Shadow rays (render --method rt): the light reaches p unless the ray from p towards it
// (shading.glsl's light_dir) hits something of the BVH (bvh.glsl, any hit): exact, no
// map. The ray starts `shadow_ray_offset` pixel footprints (pixel_footprint at p's
// distance from the eye) off the surface, along the receiver's normal on the light's side,
// so that the receiver's own rounding (and a relief hit's bisection bracket, a fraction of
// a footprint) does not shadow it. The program includes bvh.glsl before this file (the
// loader's includes ignore #if, and bvh.glsl's own includes are each taken once).
uniform float shadow_ray_offset;

#if defined SOFT_SUN
// The soft sun: `sun_samples` shadow rays a pixel towards points of the sun's disc (radius
// `sun_radius`, the tangent of its half angle, about light_dir), the pixel's own sequence
// (shading.glsl's look_sample); the fraction that gets through.
uniform float sun_radius;
uniform int sun_samples;

float shadow_visibility(vec3 p, vec3 n) {
    float distance = length(p);
    float lift = shadow_ray_offset * (pixel_footprint.x * distance + pixel_footprint.y);
    vec3 o = p + lift * (dot(n, light_dir) >= 0.0 ? n : -n);
    vec3 t, b;
    look_basis(light_dir, t, b);
    vec2 shift = pixel_random(2u);
    float lit = 0.0;
    for (int i = 0; i < sun_samples; ++i) {
        vec2 disc = sun_radius * look_disc(look_sample(i, sun_samples, shift));
        vec3 d = normalize(light_dir + disc.x * t + disc.y * b);
        lit += bvh_trace(o, d, 0.0, RAY_T_MAX, true, distance, true).prim >= 0 ? 0.0 : 1.0;
    }
    return lit / float(sun_samples);
}
#else
float shadow_visibility(vec3 p, vec3 n) {
    float distance = length(p);
    float lift = shadow_ray_offset * (pixel_footprint.x * distance + pixel_footprint.y);
    vec3 o = p + lift * (dot(n, light_dir) >= 0.0 ? n : -n);
    return bvh_trace(o, light_dir, 0.0, RAY_T_MAX, true, distance, true).prim >= 0 ? 0.0 : 1.0;
}
#endif
#else
uniform sampler2D shadow_map;      // depth texture, compare mode off
uniform vec3 light_origin;         // centre of the light's window, render-origin relative
uniform vec3 light_right;          // unit, the map's +x
uniform vec3 light_up;             // unit, the map's +y
uniform vec3 light_forward;        // unit, the direction the light travels
uniform vec2 light_half;           // half width, half height of the window (world units)
uniform vec2 light_depth;          // near, far along light_forward from light_origin
uniform float shadow_bias;         // world units subtracted from the receiver's depth
uniform float shadow_max_slope;    // clamp of the receiver plane's depth gradient

#if defined SOFT_SUN
// The soft sun (percentage-closer soft shadows): the centre and `sun_samples` taps over the
// disc the sun (radius `sun_radius`, the tangent of its half angle) subtends between the
// receiver and the window's near plane find the occluders' mean depth; the penumbra's radius is then
// sun_radius * (receiver - occluder depth), at least 1.5 texels, and as many taps over
// that disc are compared, each with the receiver-plane depth at its offset. The taps are
// the pixel's own sequence (shading.glsl's look_sample): noise, not banding.
uniform float sun_radius;
uniform int sun_samples;

// Whether the map's texel under `offset` (world, in the window's plane) from the receiver at
// light-space lp occludes it (its depth in `z_occluder`).
bool sun_tap(vec3 lp, vec2 offset, vec2 grad, out float z_occluder) {
    ivec2 size = textureSize(shadow_map, 0);
    vec2 uv = 0.5 + 0.5 * (lp.xy + offset) / light_half;
    ivec2 texel = clamp(ivec2(floor(uv * vec2(size))), ivec2(0), size - 1);
    float stored = texelFetch(shadow_map, texel, 0).r;
    z_occluder = light_depth.x + stored * (light_depth.y - light_depth.x);
    return stored < 1.0 && z_occluder < lp.z + dot(grad, offset) - shadow_bias;
}

float shadow_visibility(vec3 p, vec3 n) {
    vec3 rel = p - light_origin;
    vec3 lp = vec3(dot(rel, light_right), dot(rel, light_up), dot(rel, light_forward));
    vec2 uv = 0.5 + 0.5 * lp.xy / light_half;
    if (any(lessThan(uv, vec2(0.0))) || any(greaterThan(uv, vec2(1.0)))) return 1.0;
    vec3 nl = vec3(dot(n, light_right), dot(n, light_up), dot(n, light_forward));
    float nz = abs(nl.z) < TOL_SHADOW_NORMAL ? TOL_SHADOW_NORMAL : nl.z;
    vec2 grad = clamp(-nl.xy / nz, -shadow_max_slope, shadow_max_slope);
    float texel = 2.0 * max(light_half.x, light_half.y) / float(textureSize(shadow_map, 0).x);
    vec2 shift = pixel_random(3u);
    float search = max(sun_radius * (lp.z - light_depth.x), 1.5 * texel), blockers = 0.0, found = 0.0, z;
    if (sun_tap(lp, vec2(0.0), grad, z)) {      // the centre too: a thin occluder is not missed
        blockers += z;
        found += 1.0;
    }
    for (int i = 0; i < sun_samples; ++i) {
        if (sun_tap(lp, search * look_disc(look_sample(i, sun_samples, shift)), grad, z)) {
            blockers += z;
            found += 1.0;
        }
    }
    if (found == 0.0) return 1.0;
    float radius = max(sun_radius * (lp.z - blockers / found), 1.5 * texel), lit = 0.0;
    for (int i = 0; i < sun_samples; ++i) {
        lit += sun_tap(lp, radius * look_disc(look_sample(i, sun_samples, shift.yx)), grad, z) ? 0.0 : 1.0;
    }
    return lit / float(sun_samples);
}
#else
// Fraction of the light reaching point p (render-origin relative) with unit normal n.
float shadow_visibility(vec3 p, vec3 n) {
    vec3 rel = p - light_origin;
    vec3 lp = vec3(dot(rel, light_right), dot(rel, light_up), dot(rel, light_forward));
    vec2 uv = 0.5 + 0.5 * lp.xy / light_half;
    if (any(lessThan(uv, vec2(0.0))) || any(greaterThan(uv, vec2(1.0)))) return 1.0;
    ivec2 size = textureSize(shadow_map, 0);
    vec2 st = uv * vec2(size) - 0.5;
    vec2 cell = floor(st);
    vec2 fr = st - cell;
    // depth gradient of the receiver's tangent plane in light space (world units per unit)
    vec3 nl = vec3(dot(n, light_right), dot(n, light_up), dot(n, light_forward));
    float nz = abs(nl.z) < TOL_SHADOW_NORMAL ? TOL_SHADOW_NORMAL : nl.z;
    vec2 grad = clamp(-nl.xy / nz, -shadow_max_slope, shadow_max_slope);
    vec2 texel_world = 2.0 * light_half / vec2(size);
    float depth_span = light_depth.y - light_depth.x;
    float lit = 0.0;
    for (int j = -1; j <= 2; ++j) {
        float wy = j == -1 ? 1.0 - fr.y : (j == 2 ? fr.y : 1.0);
        for (int i = -1; i <= 2; ++i) {
            float wx = i == -1 ? 1.0 - fr.x : (i == 2 ? fr.x : 1.0);
            ivec2 texel = ivec2(cell) + ivec2(i, j);
            ivec2 fetch = clamp(texel, ivec2(0), size - 1);
            vec2 offset = (vec2(texel) - st) * texel_world;        // texel centre - receiver
            float z_receiver = lp.z + dot(grad, offset) - shadow_bias;
            float stored = texelFetch(shadow_map, fetch, 0).r;     // 1: nothing drawn there
            float z_occluder = light_depth.x + stored * depth_span;
            lit += wx * wy * (stored >= 1.0 || z_occluder >= z_receiver ? 1.0 : 0.0);
        }
    }
    return lit / 9.0;
}
#endif

#endif

#endif
