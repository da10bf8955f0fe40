// The eye's rays and depths, shared by the fragment programs that cast the eye's rays
// themselves (raycast.glsl, rt.glsl): each pixel's ray through its centre (as
// plantgen.geometry.Camera.rays), and the window depth of a hit, so that cast surfaces
// and rasterised meshes meet in one depth test.

#ifndef EYE_GLSL
#define EYE_GLSL

uniform vec2 viewport;          // width, height in pixels
uniform vec3 cam_forward;       // unit
uniform vec3 cam_right_scaled;  // unit right * tan(fov_x / 2)
uniform vec3 cam_up_scaled;     // unit up * tan(fov_y / 2)
uniform vec2 depth_coeffs;      // projection m[2][2], m[2][3]: clip z = A*z_view + B

// Window depth of a hit `distance` along the eye's ray direction d: the depth test against
// other frusta and ordinary meshes (the projection's z of the view-space depth).
float eye_depth(float distance, vec3 d) {
    float z_view = -distance * dot(d, cam_forward);
    float ndc_z = (depth_coeffs.x * z_view + depth_coeffs.y) / (-z_view);
    return clamp(0.5 * ndc_z + 0.5, 0.0, 1.0);
}

// The unit direction of this fragment's pixel's ray (eye-relative world).
vec3 pixel_ray() {
    vec2 ndc = 2.0 * gl_FragCoord.xy / viewport - 1.0;   // pixel centres; +y is up
    return normalize(cam_forward + ndc.x * cam_right_scaled + ndc.y * cam_up_scaled);
}

#if !defined SHADOW_PASS
layout(location = 0) out vec4 out_color;
layout(location = 1) out float out_distance;   // distance along the ray from the eye

#if !defined LABELS
#if defined SKY_LIGHT
vec2 sky_light_traced(vec3 p, vec3 n, vec3 side, float distance, int samples);   // sky_light.glsl
#endif
// Shade and write the hit at p (eye-relative), `distance` along the eye's ray direction d:
// its albedo, material, shading normal and (with SHADOWS, shadow.glsl included before) the
// receiver normal of its shadow test; colour, distance and depth.
// A surface turned away from the light (shading.glsl's facing normal) gets no direct light
// whatever its visibility: its shadow test is skipped (a shadow ray saved, the same colour).
void write_hit(vec3 albedo, int material, vec3 normal, vec3 receiver_normal, vec3 p, vec3 d, float distance) {
    float visibility = 1.0;
#if defined SHADOWS
    vec3 facing = dot(normal, d) > 0.0 ? -normal : normal;
    if (dot(facing, light_dir) > 0.0) visibility = shadow_visibility(p, receiver_normal);
#endif
#if defined SKY_LIGHT
    // the sky's light traced (sky_light.glsl), about the normal facing the eye
    vec3 n_eye = dot(normal, d) > 0.0 ? -normal : normal;
    vec3 side = dot(receiver_normal, d) > 0.0 ? -receiver_normal : receiver_normal;
    vec2 sky = sky_light_traced(p, n_eye, side, distance, sky_samples);
    vec3 color = shade_surface_sky(albedo, material, n_eye, -d, sky, visibility);
#else
    vec3 color = shade_surface_visible(albedo, material, normal, -d, 1.0, visibility, p);
#endif
    out_color = vec4(to_display(color), 1.0);
    out_distance = distance;
    gl_FragDepth = eye_depth(distance, d);
}
#endif
#endif

#endif
