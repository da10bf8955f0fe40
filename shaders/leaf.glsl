// Leaves: the grammar's filled polygons (plantgen.geometry.meshes.polygons), rasterised into the
// same frame and depth buffer as the frusta. The ray-cast frusta write gl_FragDepth from
// the same projection, so a leaf in front of a frustum hides it and one behind is hidden,
// as the ground is (shaders/ground.glsl). Used by both renderers (RC and GS).
//
// Positions are relative to the leaves' own origin (float64 subtraction on the CPU) and
// moved to the eye by `origin_from_eye`, as the raster renderer's mesh is.
// A leaf is a thin sheet seen from either side: no face is culled, and the shading normal
// is the leaf's normal turned towards the eye (lit on both sides). Leaves carry no relief.
//
// Looks (shading.glsl): TRANSLUCENT (light on the far side comes through: a leaf lit from
// behind glows), SKY_LIGHT (the sky traced on both sides, sky_light.glsl), TONE_MAP.
// Variants: SHADOWS (receive: sample the light's map, shaders/shadow.glsl, with the
// facet's own plane as the receiver plane; with SHADOW_RAYS a shadow ray through the BVH
// instead, plantgen.gl.rt); SHADOW_PASS (cast: depth only into the
// light's map, both faces; with EYE_DEPTH the same into the eye's frame, ahead of a costly
// shading, plantgen.gl.leaf_layer); LABELS (a part mask: the leaf's label in red, unshaded);
// THIN_LEAVES (coverage anti-aliasing, plantgen.gl.leaf_layer.thin_leaf_data: a leaf
// narrower than the floor width at its distance, a needle, is drawn widened to the floor
// across its long axis, its alpha its true width over the floor's; such leaves are drawn
// by a pass of their own after everything opaque, plantgen.gl.coverage's 1, the rest by
// pass 0; they write no distance).

#if defined VERTEX_SHADER

in vec3 position;          // relative to the leaves' origin
in vec3 normal;            // the leaf surface's normal (right-hand rule of its outline)
in vec2 shade;             // (material slot or label, tone in [0, 1] of the leaf's albedo)

uniform mat4 view_projection;   // eye-relative world -> clip (the light's window in SHADOW_PASS)
uniform vec3 origin_from_eye;   // leaves' origin - eye

out vec3 v_position;            // eye-relative
out vec3 v_normal;
flat out vec2 v_shade;

#if defined THIN_LEAVES
in vec3 thin_centre;            // the leaf's centroid, relative to the leaves' origin
in vec3 thin_offset;            // the vertex's offset from the leaf's long axis, across it
in float thin_width;            // the leaf's width across its long axis
uniform float coverage_floor;   // the floor radius per unit of distance from the eye
uniform int coverage_pass;      // 0: the leaves at or above the floor; 1: the narrower, widened
                                // (blended)
flat out float v_coverage;      // the leaf's share of the floor's width (1: not widened)
#endif

void main() {
    v_position = position + origin_from_eye;
    v_normal = normal;
    v_shade = shade;
#if defined THIN_LEAVES
    float floor_width = 2.0 * coverage_floor * length(thin_centre + origin_from_eye);
    bool thin = thin_width < floor_width;
    if (thin) v_position += thin_offset * (floor_width / max(thin_width, 1e-30) - 1.0);
    v_coverage = thin ? thin_width / floor_width : 1.0;
#endif
    gl_Position = view_projection * vec4(v_position, 1.0);
#if defined THIN_LEAVES
    if (thin != (coverage_pass == 1)) gl_Position = vec4(0.0, 0.0, 2.0, 1.0);   // not this pass's: no area
#endif
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
in vec3 v_normal;
flat in vec2 v_shade;
#if defined THIN_LEAVES
flat in float v_coverage;
uniform float coverage_exponent;   // the alpha is the coverage to this power (plantgen.settings.AA_ALPHA_EXPONENT)
#endif

layout(location = 0) out vec4 out_color;
layout(location = 1) out float out_distance;

void main() {
    int material = int(v_shade.x + 0.5);
#if defined LABELS
    out_color = vec4(float(material) / 255.0, 0.0, 0.0, 1.0);
#else
    vec3 to_eye = normalize(-v_position);
    vec3 n = normalize(v_normal);
    // the facet the rasteriser draws: the receiver plane for the shadow map, and the side
    // of the sheet the eye sees
    vec3 flat_normal = facet_normal(v_position, to_eye);      // the side the eye sees
    if (dot(n, flat_normal) < 0.0) n = -n;          // the side facing the eye
    n = facing_normal(n, flat_normal, to_eye);
#if defined SHADOWS
    float visibility = shadow_visibility(v_position, flat_normal);
#else
    float visibility = 1.0;
#endif
    vec3 albedo = material_albedo(material, v_shade.y);
#if defined TRANSLUCENT || defined SKY_LIGHT
#if defined SKY_LIGHT
    float distance = length(v_position);
    // the far side's sky, dimmed by the transmission, with half the rays
    vec2 sky_front = sky_light_traced(v_position, n, flat_normal, distance, sky_samples);
#if defined TRANSLUCENT
    vec2 sky_back = sky_light_traced(v_position, -n, -flat_normal, distance, max(sky_samples / 2, 1));
#else
    vec2 sky_back = vec2(0.0);
#endif
#else
    vec2 sky_front = open_light(n, v_position), sky_back = open_light(-n, v_position);
#endif
    // the far side's sun: visible where the sheet itself is (its shadow test is the same)
    out_color = vec4(to_display(shade_leaf(albedo, material, n, to_eye, sky_front, sky_back, visibility)), 1.0);
#else
    out_color = vec4(to_display(shade_surface_visible(albedo, material, n, to_eye, 1.0, visibility, v_position)), 1.0);
#endif
#endif
#if defined THIN_LEAVES
    out_color.a = pow(v_coverage, coverage_exponent);
#endif
    out_distance = length(v_position);
}
#endif

#endif
