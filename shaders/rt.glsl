// Ray tracing (render --method rt; with RELIEF, RT+R): one full-screen triangle, each
// fragment traces its pixel's ray through the BVH (bvh.glsl, closest hit, rows only: the
// leaves are rasterised after it as the ray caster's frames do) and shades the row it hits
// as raycast.glsl does (row.glsl's row_surface, shading.glsl), in the hit copy's frame, the
// normals then turned into the world. With SHADOWS the light's visibility comes from a
// shadow ray (shadow.glsl with SHADOW_RAYS: any hit through the same BVH; no map).
// The BVH is uploaded relative to the eye (the render origin), like the ray caster's
// records. Variants: RELIEF, V_EXACT, MARCH_FIXED (row.glsl), SHADOWS, TWO_LEVEL, and the looks
// (shading.glsl; SKY_LIGHT: sky_light.glsl).

#if defined VERTEX_SHADER

void main() {
    vec2 screen = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(2.0 * screen - 1.0, 0.0, 1.0);
}

#elif defined FRAGMENT_SHADER

#include "shading.glsl"
#include "bvh.glsl"
#include "sky_light.glsl"
#if defined SHADOWS
#include "shadow.glsl"
#endif
#include "eye.glsl"

void main() {
    vec3 d = pixel_ray();
    BvhHit hit = bvh_trace(vec3(0.0), d, 0.0, RAY_T_MAX, false, 0.0, false);
    if (hit.prim < 0) discard;
    // the hit in its copy's frame (the ray moved as bvh_trace moved it)
    int plant = 0;
    vec3 o = vec3(0.0), dc = d;
#if defined TWO_LEVEL
    plant = bvh_copy_plant(hit.copy);
    o = bvh_to_copy(hit.copy, vec4(o, 1.0));
    dc = bvh_to_copy(hit.copy, vec4(d, 0.0));
#endif
    Frustum f = bvh_frustum(plant, hit.prim);
    float t_shift = recenter_shift(f, o, dc);             // the row test's re-centring
    vec3 p = (o + t_shift * dc) + (hit.t - t_shift) * dc;
    vec3 normal, receiver_normal, albedo;
    row_surface(f, p, normalize(dc), hit.face, hit.face != FACE_CONE, normal, receiver_normal, albedo);
#if defined TWO_LEVEL
    normal = bvh_normal_from_copy(hit.copy, normal);
    receiver_normal = bvh_normal_from_copy(hit.copy, receiver_normal);
#endif
    write_hit(albedo, f.material, normal, receiver_normal, hit.t * d, d, hit.t);
}

#endif
