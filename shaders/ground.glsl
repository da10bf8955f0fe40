// The ground: an ordinary rasterised mesh (a square) drawn into the same depth buffer as
// the ray-cast frusta, so frusta that reach below it are cut by it and vice versa.
// Positions are relative to the render origin (the camera eye), like the frusta records.
// A disc ground (a single plant's) is cut out of its square; either shape fades, over the
// outer `ground_fade` of its half size, into what the background pass draws behind it (the
// sky along the pixel's ray, or the flat background), reaching it exactly at the edge: no
// edge shows. Variants: SHADOWS (sample the shadow map; with SHADOW_RAYS shadow rays through
// the BVH instead, plantgen.gl.rt), SHADOW_PASS (depth only, into the light's map),
// FLAT_BACKGROUND (fade into the flat colour `background`, alpha included), and the looks
// (shading.glsl; SKY_LIGHT: the sky traced through the model's BVH, sky_light.glsl, so the
// ground darkens under and beside the plant).

#if defined VERTEX_SHADER

in vec3 position;
uniform mat4 view_projection;
out vec3 v_position;

void main() {
    v_position = position;
    gl_Position = view_projection * vec4(position, 1.0);
}

#elif defined FRAGMENT_SHADER

#if defined SHADOW_PASS
// the light's depth pass: the rasteriser's depth is the depth in the light's window
void main() {}
#else
#include "shading.glsl"
#if defined SHADOW_RAYS || defined SKY_LIGHT
#include "bvh.glsl"
#endif
#include "sky_light.glsl"
#if defined SHADOWS
#include "shadow.glsl"
#endif

in vec3 v_position;
uniform int ground_material;
uniform vec3 origin_offset;   // world position of the render origin, for the texture pattern
uniform vec2 ground_centre;   // world (x, z) of the ground's centre
uniform float ground_half;    // the square's half side, the disc's radius
uniform float ground_fade;    // the fraction of ground_half over which it fades out
uniform bool ground_disc;
#if defined FLAT_BACKGROUND
uniform vec4 background;      // display-encoded, as the background pass writes it
#endif

// 0 inside the ground, rising smoothly to 1 at its edge (the square's or the disc's).
float ground_edge_fade(vec3 world) {
    vec2 d = abs(world.xz - ground_centre);
    float r = ground_disc ? length(d) : max(d.x, d.y);
    if (r > ground_half) discard;
    return smoothstep(ground_half * (1.0 - ground_fade), ground_half, r);
}

layout(location = 0) out vec4 out_color;
layout(location = 1) out float out_distance;

void main() {
    vec3 world = v_position + origin_offset;
    float fade = ground_edge_fade(world);
    // A soft procedural mottle so the ground reads as a surface, not a flat fill.
    float mottle = 0.5 + 0.25 * sin(world.x * 1.7 + sin(world.z * 0.9)) * sin(world.z * 1.3 + sin(world.x * 0.7));
    vec3 albedo = material_albedo(ground_material, mottle);
    vec3 to_eye = normalize(-v_position);
#if defined SHADOWS
    float visibility = shadow_visibility(v_position, vec3(0.0, 1.0, 0.0));
#else
    float visibility = 1.0;
#endif
    vec3 up = vec3(0.0, 1.0, 0.0);
#if defined SKY_LIGHT
    vec2 sky = sky_light_traced(v_position, up, up, length(v_position), sky_samples);
    vec3 lit = shade_surface_sky(albedo, ground_material, up, to_eye, sky, visibility);
#else
    vec3 lit = shade_surface_visible(albedo, ground_material, up, to_eye, 1.0, visibility, v_position);
#endif
#if defined FLAT_BACKGROUND
    out_color = mix(vec4(to_display(lit), 1.0), background, fade);
#else
    out_color = vec4(to_display(mix(lit, sky_color(-to_eye), fade)), 1.0);
#endif
    out_distance = length(v_position);
}
#endif

#endif
