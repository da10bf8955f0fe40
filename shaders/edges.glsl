// Coverage anti-aliasing's edge pass (plantgen.gl.supersample.GpuResolve.smooth_edges): one
// full-screen triangle over the final image, reading the frame drawn at one ray a pixel.
// Where the luma of a pixel and its eight neighbours spans a contrast above a threshold (an
// edge: a silhouette, a leaf's border), the pixel is replaced by the mean of taps taken
// along the edge (perpendicular to the luma gradient, bilinear, half a pixel and a pixel
// and a half either side), so a staircase reads as a slope. Flat regions are copied
// unchanged. The distance is copied as it is (the ray through the
// centre). An edge-directed blur in the spirit of FXAA (T. Lottes, 2009), written here.

#if defined VERTEX_SHADER

void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);   // (0,0) (2,0) (0,2)
    gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform sampler2D frame_color;      // the frame, display-encoded RGBA8, linear filtering
uniform sampler2D frame_distance;   // its distances
uniform float edge_threshold;       // the least luma contrast smoothed (absolute)
uniform float edge_relative;        // ... and relative to the brightest of the nine

layout(location = 0) out vec4 out_color;
layout(location = 1) out float out_distance;

#ifndef RIDGE
#define RIDGE 2.0
#endif

float luma(vec3 c) { return dot(c, vec3(0.299, 0.587, 0.114)); }

// The luma of the pixel at `q`, clamped to the image.
float luma_at(ivec2 q) {
    return luma(texelFetch(frame_color, clamp(q, ivec2(0), textureSize(frame_color, 0) - 1), 0).rgb);
}

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec2 texel = 1.0 / vec2(textureSize(frame_color, 0));
    vec2 uv = gl_FragCoord.xy * texel;
    out_distance = texelFetch(frame_distance, px, 0).r;
    vec4 centre = texelFetch(frame_color, px, 0);
    float l = luma(centre.rgb);
    float n = luma_at(px + ivec2(0, 1));
    float s = luma_at(px + ivec2(0, -1));
    float e = luma_at(px + ivec2(1, 0));
    float w = luma_at(px + ivec2(-1, 0));
    float ne = luma_at(px + ivec2(1, 1));
    float nw = luma_at(px + ivec2(-1, 1));
    float se = luma_at(px + ivec2(1, -1));
    float sw = luma_at(px + ivec2(-1, -1));
    float lo = min(l, min(min(min(n, s), min(e, w)), min(min(ne, nw), min(se, sw))));
    float hi = max(l, max(max(max(n, s), max(e, w)), max(max(ne, nw), max(se, sw))));
    float contrast = hi - lo;
    if (contrast < max(edge_threshold, edge_relative * hi)) {
        out_color = centre;
        return;
    }
    // the luma gradient from the neighbours; the edge runs across it
    vec2 gradient = vec2(2.0 * (e - w) + (ne + se) - (nw + sw), 2.0 * (n - s) + (nw + ne) - (sw + se));
    // a ridge or a dot (a line a pixel wide, a speck: no step to smooth, their gradient
    // small against their contrast; a step edge's is 4 times it) is left as drawn
    if (length(gradient) < RIDGE * contrast) {
        out_color = centre;
        return;
    }
    vec2 along = normalize(vec2(-gradient.y, gradient.x));
    // taps along the edge: half a pixel and a pixel and a half either side (bilinear)
    vec3 inner = 0.5 * (texture(frame_color, uv + 0.5 * along * texel).rgb
                        + texture(frame_color, uv - 0.5 * along * texel).rgb);
    vec3 outer = 0.5 * (texture(frame_color, uv + 1.5 * along * texel).rgb
                        + texture(frame_color, uv - 1.5 * along * texel).rgb);
    vec3 blended = (2.0 * centre.rgb + 4.0 * inner + 2.0 * outer) / 8.0;
    float lb = luma(blended);
    if (lb < lo || lb > hi) blended = 0.5 * (centre.rgb + inner);    // the outer taps crossed another edge
    out_color = vec4(blended, centre.a);
}

#endif
