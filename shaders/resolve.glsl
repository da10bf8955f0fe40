// Supersampling's resolve on the GPU: one full-screen triangle over the final image; each
// pixel averages its `factor` x `factor` block of the large frame in linear light (the
// display encoding `to_display` undone first, applied again after) and takes the distance
// of the block's sub-sample nearest its centre. With COVERAGE (a transparent background)
// colours are weighted by their alpha and the alpha is the block's mean coverage. With SRGB
// (a frame drawn with the tone effect) the encoding is sRGB's: `to_linear` holds its decoding
// and the mean is sRGB-encoded again, else c^(1/2.2).
// plantgen.gl.supersample.resolve_supersamples is the same on the CPU (the reference).

#if defined VERTEX_SHADER

void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);   // (0,0) (2,0) (0,2)
    gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform sampler2D frame_color;      // the large frame, display-encoded RGBA8
uniform float to_linear[256];       // the display encoding undone, per 8-bit level
uniform sampler2D frame_distance;   // its distances along each sub-sample's ray
const int factor = FACTOR;           // samples per side, a define: the loops unroll

layout(location = 0) out vec4 out_color;
layout(location = 1) out float out_distance;

const float DISPLAY_GAMMA = 2.2;

vec3 encode(vec3 linear) {
    vec3 c = clamp(linear, 0.0, 1.0);
#if defined SRGB
    // shading.glsl's srgb_encode (IEC 61966-2-1)
    return mix(12.92 * c, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), c));
#else
    return pow(c, vec3(1.0 / DISPLAY_GAMMA));
#endif
}

void main() {
    ivec2 base = ivec2(gl_FragCoord.xy) * factor;
    vec3 sum = vec3(0.0);
    float weight = 0.0;
    for (int j = 0; j < factor; ++j) {
        for (int i = 0; i < factor; ++i) {
            vec4 c = texelFetch(frame_color, base + ivec2(i, j), 0);
            ivec3 level = ivec3(c.rgb * 255.0 + 0.5);
#if defined COVERAGE
            float a = c.a;
#else
            float a = 1.0;
#endif
            sum += a * vec3(to_linear[level.r], to_linear[level.g], to_linear[level.b]);
            weight += a;
        }
    }
    vec3 mean = sum / max(weight, 1e-12);
    float coverage = weight / float(factor * factor);
    out_color = vec4(encode(mean), coverage);
    // the sub-sample nearest the centre: the top-down image's row factor / 2 of the block
    out_distance = texelFetch(frame_distance, base + ivec2(factor / 2, factor - 1 - factor / 2), 0).r;
}

#endif
