// Ray queries on the GPU (plantgen.gl.trace): one invocation per ray, the closest or any
// hit through the BVH (shaders/bvh.glsl). TWO_LEVEL: an instanced scene.
//
// In (binding 0): per ray two vec4, (origin relative to the frame origin, t_min),
// (direction, t_max). Out (binding 1): per ray (t, primitive, copy, face), the last three
// as int bits; t_max and primitive -1 where nothing is hit. BVH_COUNT: the nodes walked
// + 65536 * the primitives tested instead of the face, the rows whose test hit + 65536 * the
// rows that passed the cheap reject instead of the copy, the rows tested instead of the
// primitive (bvh.glsl's counters).

#if defined COMPUTE_SHADER
layout(local_size_x = 64) in;

#include "bvh.glsl"

layout(std430, binding = 0) readonly buffer Rays { vec4 rays[]; };
layout(std430, binding = 1) writeonly buffer Hits { vec4 hits[]; };

uniform int ray_count;
uniform int any_hit;        // 1: stop at the first hit (visibility), 0: the closest

void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (i >= ray_count) return;
    vec4 a = rays[2 * i], b = rays[2 * i + 1];
    BvhHit hit = bvh_trace(a.xyz, b.xyz, a.w, b.w, any_hit != 0, 0.0, true);
#if defined BVH_COUNT
    hit.face = bvh_visits + (bvh_tests << 16);   // the bench's counts instead of the face,
    hit.copy = bvh_row_hits + (bvh_bound_pass << 16);   // the copy
    hit.prim = bvh_row_tests;                    // and the primitive
#endif
    hits[i] = vec4(hit.t, intBitsToFloat(hit.prim), intBitsToFloat(hit.copy), intBitsToFloat(hit.face));
}
#endif
