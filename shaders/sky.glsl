// Sky background: one full-screen triangle, coloured by the pixel's ray direction.
// Writes distance = +inf (a miss) to the distance target and leaves depth at the far plane.
// With FLAT_BACKGROUND it writes the colour `background` instead (display-encoded RGBA;
// alpha 0 for a transparent image), so every renderer's background is one pass.

#if defined VERTEX_SHADER

void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);   // (0,0) (2,0) (0,2)
    gl_Position = vec4(2.0 * p - 1.0, 1.0, 1.0);
}

#elif defined FRAGMENT_SHADER

#include "shading.glsl"

#if defined FLAT_BACKGROUND
uniform vec4 background;
#else
uniform vec2 viewport;
uniform vec3 cam_forward;
uniform vec3 cam_right_scaled;
uniform vec3 cam_up_scaled;
#endif

layout(location = 0) out vec4 out_color;
layout(location = 1) out float out_distance;

void main() {
#if defined FLAT_BACKGROUND
    out_color = background;
#else
    vec2 ndc = 2.0 * gl_FragCoord.xy / viewport - 1.0;
    vec3 d = normalize(cam_forward + ndc.x * cam_right_scaled + ndc.y * cam_up_scaled);
    out_color = vec4(to_display(sky_color(d)), 1.0);
#endif
    out_distance = uintBitsToFloat(0x7f800000u);
}

#endif
