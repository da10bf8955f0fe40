// The ground: an ordinary rasterised mesh (a square) drawn into the same depth buffer as
// the ray-cast frusta, so frusta that reach below it are cut by it and vice versa.
// Positions are relative to the render origin (the camera eye), like the frusta records.
// Variants: SHADOWS (sample the shadow map; with SHADOW_RAYS shadow rays through the BVH instead,
// plantgen.gl.rt), SHADOW_PASS (depth only, into the light's map).

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
#if defined SHADOW_RAYS
#include "bvh.glsl"
#endif
#if defined SHADOWS
#include "shadow.glsl"
#endif

in vec3 v_position;
uniform int ground_material;
uniform vec3 origin_offset;   // world position of the render origin, for the texture pattern

layout(location = 0) out vec4 out_color;
layout(location = 1) out float out_distance;

void main() {
    vec3 world = v_position + origin_offset;
    // A soft procedural mottle so the ground reads as a surface, not a flat fill.
    float mottle = 0.5 + 0.25 * sin(world.x * 1.7 + sin(world.z * 0.9)) * sin(world.z * 1.3 + sin(world.x * 0.7));
    vec3 albedo = material_albedo(ground_material, mottle);
    vec3 to_eye = normalize(-v_position);
#if defined SHADOWS
    float visibility = shadow_visibility(v_position, vec3(0.0, 1.0, 0.0));
#else
    float visibility = 1.0;
#endif
    out_color = vec4(to_display(shade_surface_visible(albedo, ground_material, vec3(0.0, 1.0, 0.0),
                                                      to_eye, 1.0, visibility)), 1.0);
    out_distance = length(v_position);
}
#endif

#endif
