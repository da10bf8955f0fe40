// Traversal of the bounding volume hierarchy (plantgen.geometry.rays.bvh): the one ray search
// of every GPU query (render --method rt, scan, plantgen.trace). Included by programs that
// trace rays; they get closest hits (bvh_closest) and any hits (bvh_any, shadow rays).
//
// Data (plantgen/gl/trace.py uploads it, std430 SSBOs):
//   bvh_nodes    the binary BVH collapsed 4-wide (below, bvh_node): per node its four
//                children's boxes on an 8-bit grid of the node's own and where their
//                references start; a leaf reference gives count primitives at positions
//                offset... of its plant's GPU order (plantgen.gl.trace.leaf_order: a node's
//                leaves one after another). Decoded boxes hold the float32 boxes rounded
//                outward from the float64 build, relative to their frame's origin.
//   bvh_prims    for a plant of rows and triangles, its primitive ids in that order (rows
//                0..rows-1, then leaf triangles); a plant of one kind has none, its rows'
//                or triangles' data going up in that order (bvh_leaf_prim).
//   bvh_rows     one row record per row (6 vec4, plantgen.gl.records.pack_records).
//   bvh_tris     3 vec4 per leaf triangle: (v0, |e1|*|e2|), (e1, 0), (e2, 0).
//   bvh_bounds   with BVH_ROW_BOUND, one float per row (its plant's row offset, as
//                bvh_rows, in the same order): the reach of the cheap reject before the
//                row test (bvh_row_near, plantgen.gl.trace.row_bounds), binding 9.
//   bvh_plants   2 ivec4 per distinct plant (a BLAS): (node, prim (-1: no id table), row,
//                triangle offsets),
//                (rows, the top level's node offset (plant 0's), 0, 0): a plant's nodes'
//                `first` and its primitive ids are its
//                own; the offsets place them in the shared arrays. The caller skips
//                an empty hierarchy (no nodes).
//   With TWO_LEVEL (an instanced scene): a top level over the copies, its nodes after the
//   plants' in bvh_nodes (one array, one load a word), and bvh_copies, the copies in the
//   top level's leaf order (a top-level leaf's `first` is the slot of its first copy), the
//   world -> plant-frame map x -> rotation^T (x - offset) / scale of each (the offset formed
//   in float64 on the CPU relative to the frame origin) and its plant:
//     2 vec4 a copy: (u.xyzw), (offset.xyz, plant index as int bits), u = conj(q) /
//     sqrt(scale) for the rotation's unit quaternion q: u v conj(u) = rotation^T v / scale.
//     With BVH_AFFINE_COPIES (a copy that mirrors, scales unevenly or shears), 4 vec4 a
//     copy: three rows of the 3x4 map (the linear part's inverse, -inverse offset), then
//     (plant index as int bits, 0, 0, 0).
//   Without TWO_LEVEL the model is plant 0 in the frame itself.
//
// A ray is o + t*d in the frame (origin relative); t is in units of |d| and keeps its
// value in a copy's frame (the map is affine). Hits: the rows through row.glsl's row_hit
// after re-centring (the ray caster's test, with RELIEF its march; bvh_row_hit), the triangles by
// Möller-Trumbore with the scan's grazing guard (bvh_triangle_hit). Stack-based, near
// child first (by slab entry), nodes entered at or beyond the best t skipped.
// BVH_COUNT: bvh_visits and bvh_tests count the nodes a trace walks and the primitives it
// tests (the bench's work per ray); bvh_row_tests, bvh_bound_pass and bvh_row_hits the rows
// among those, the rows that passed the cheap reject and the rows whose test hit. The
// bench's variants: BVH_NO_PRIMS (no primitive tested: the node steps alone) and
// BVH_PRIMS_TWICE (each tested twice: what the tests cost).

#ifndef BVH_GLSL
#define BVH_GLSL

#include "row.glsl"

// Bindings 3..8 (plantgen.gl.trace.BVH_BINDING; literals: GLSL 4.30 takes no expression).
#ifndef BVH_STACK
#define BVH_STACK 96
#endif

layout(std430, binding = 3) readonly buffer BvhNodes { vec4 bvh_nodes[]; };
layout(std430, binding = 4) readonly buffer BvhPrims { int bvh_prims[]; };
layout(std430, binding = 5) readonly buffer BvhRows { vec4 bvh_rows[]; };
layout(std430, binding = 6) readonly buffer BvhTris { vec4 bvh_tris[]; };
layout(std430, binding = 7) readonly buffer BvhPlants { ivec4 bvh_plants[]; };
#if defined TWO_LEVEL
layout(std430, binding = 8) readonly buffer BvhCopies { vec4 bvh_copies[]; };
#endif
#if defined BVH_ROW_BOUND
layout(std430, binding = 9) readonly buffer BvhBounds { float bvh_bounds[]; };
#endif

#if defined BVH_COUNT
int bvh_visits = 0;         // wide nodes walked by the last bvh_trace (trace.glsl's BVH_COUNT)
int bvh_tests = 0;          // primitives it tested
int bvh_row_tests = 0;      // rows of those (the rest are leaf triangles)
int bvh_bound_pass = 0;     // rows that passed the cheap reject (BVH_ROW_BOUND; else every row)
int bvh_row_hits = 0;       // rows of those whose full test hit (at any t in the ray's interval)
#endif

// A hit: t along the ray, the primitive (its data's slot in its plant: row, or rows +
// triangle; plantgen.gl.trace.trace_rays maps it to the plant's own id), the
// copy (0 without TWO_LEVEL; -1 with the primitive on a miss), the face: FACE_LO or
// FACE_HI for a hit on a row's open end (a cap), else FACE_CONE (a triangle too).
struct BvhHit { float t; int prim; int copy; int face; };

BvhHit bvh_no_hit(float t_max) { return BvhHit(t_max, -1, -1, FACE_CONE); }

// Row `row` of plant `plant` as a Frustum (its record's six vec4).
Frustum bvh_frustum(int plant, int row) {
    int i = 6 * (bvh_plants[2 * plant].z + row);
    return frustum_from_record(bvh_rows[i], bvh_rows[i + 1], bvh_rows[i + 2], bvh_rows[i + 3],
                               bvh_rows[i + 4], bvh_rows[i + 5]);
}

// The ray caster's row test (row.glsl's row_hit: the analytic skin, with RELIEF the relief
// march) after re-centring the ray at its point nearest the axis segment, as raycast.glsl
// does. t > t_min (and with RELIEF the march stops at t_max); NO_HIT on a miss; `face` FACE_LO or FACE_HI for a hit on an open end's
// disc (a cap), else FACE_CONE. `distance`, `footprint_scale`: row_hit's.
float bvh_row_hit_at(Frustum f, float t_shift, vec3 o, vec3 d, float t_min, float t_max, float distance,
                     float footprint_scale, out int face) {
    float t_hit;
    bool cap;
    int samples;
    if (!row_hit(f, o + t_shift * d, d, t_min - t_shift, t_max - t_shift, distance + t_shift, footprint_scale,
                 t_hit, face, cap, samples)) return NO_HIT;
    face = cap ? face : FACE_CONE;
    return t_shift + t_hit;
}

float bvh_row_hit(Frustum f, vec3 o, vec3 d, float t_min, float t_max, float distance, float footprint_scale,
                  out int face) {
    return bvh_row_hit_at(f, recenter_shift(f, o, d), o, d, t_min, t_max, distance, footprint_scale, face);
}

// Möller-Trumbore, both faces, as plantgen.geometry.rays.scan._triangle_hits (the grazing
// guard |det| > TOL_TRIANGLE_GRAZING * |e1||e2||d|), with the ray first moved to the
// point nearest v0 (float32 keeps the digits of a far eye). t > t_min; NO_HIT on a miss.
float bvh_triangle_hit(vec3 v0, vec3 e1, vec3 e2, float size, vec3 o, vec3 d, float t_min) {
    float t_shift = dot(v0 - o, d) / dot(d, d);
    vec3 s = o + t_shift * d - v0;
    vec3 p = cross(d, e2);
    float det = dot(e1, p);
    if (!(abs(det) > TOL_TRIANGLE_GRAZING * size * length(d))) return NO_HIT;
    float inv = 1.0 / det;
    float u = dot(s, p) * inv;
    vec3 q = cross(s, e1);
    float v = dot(d, q) * inv;
    float t = t_shift + dot(e2, q) * inv;
    return u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > t_min ? t : NO_HIT;
}

#if defined BVH_ROW_BOUND
// The cheap reject before a row's test (BVH_ROW_BOUND): whether the ray's line passes
// within bvh_bounds[row] of the row's axis segment {base + s*axis, 0 <= s <= h}, from the
// record's first two vec4 alone. The bound (plantgen.gl.trace.row_bounds) is the largest
// distance from that segment of any point of the solid row (its relief shell and oblique
// ends included, their joint slack too), widened for float32 rounding; the line's nearest
// point to the segment is the one the row test re-centres the ray at (recenter_shift, whose
// shift is returned), so a ray the test could hit is never rejected. Where the ray runs
// parallel to the axis (recenter_shift's fallback, the segment's middle) the bound grows by
// how far that middle may be from the nearest point. Off by default
// (plantgen.gl.trace.ROW_BOUND): llvmpipe runs the row test behind it on all lanes anyway.
bool bvh_row_near(vec4 r0, vec4 r1, float bound, vec3 o, vec3 d, out float t_shift) {
    vec3 base = r0.xyz, axis = r1.xyz;
    float h = r0.w;
    vec3 E = o - base;
    float b = dot(d, axis), de = dot(d, E), e = dot(axis, E), dd = dot(d, d);
    float den = dd - b * b;
    bool parallel = !(den > TOL_RECENTER_PARALLEL * dd);
    float s = parallel ? 0.5 * h : clamp(e + b * (b * e - de) / den, 0.0, h);
    t_shift = (s * b - de) / dd;
    vec3 w = (o + t_shift * d) - base - s * axis;
    float reach = bound + h * (parallel ? 0.5 * sqrt(TOL_RECENTER_PARALLEL) + 1.0e-5 : 1.0e-5);
    return dot(w, w) <= reach * reach;
}
#endif

#if defined BVH_PRIMS_TWICE
uniform float bvh_bench_zero;    // 0: the bench's second test of each primitive is the first's
#define bvh_prim_hit bvh_prim_hit_once
#endif

// Primitive `prim` of plant `plant` against the ray: t (NO_HIT for a miss) and the face.
float bvh_prim_hit(int plant, int prim, vec3 o, vec3 d, float t_min, float t_max, float distance,
                   float footprint_scale, bool triangles, out int face) {
    face = FACE_CONE;
#if defined BVH_NO_PRIMS
    return NO_HIT;       // the bench's node steps alone (nothing is hit, so more nodes are walked)
#endif
    int rows = bvh_plants[2 * plant + 1].x;
    if (prim < rows) {
#if defined BVH_COUNT
        ++bvh_row_tests;
#endif
#if defined BVH_ROW_BOUND
        int row = bvh_plants[2 * plant].z + prim;
        vec4 r0 = bvh_rows[6 * row], r1 = bvh_rows[6 * row + 1];
        float t_shift;
        bool near = bvh_row_near(r0, r1, bvh_bounds[row], o, d, t_shift);
        float t = NO_HIT;
        if (near) {
#if defined BVH_COUNT
            ++bvh_bound_pass;
#endif
            Frustum f = frustum_from_record(r0, r1, bvh_rows[6 * row + 2], bvh_rows[6 * row + 3],
                                            bvh_rows[6 * row + 4], bvh_rows[6 * row + 5]);
            t = bvh_row_hit_at(f, t_shift, o, d, t_min, t_max, distance, footprint_scale, face);
        }
#else
#if defined BVH_COUNT
        ++bvh_bound_pass;
#endif
        float t = bvh_row_hit(bvh_frustum(plant, prim), o, d, t_min, t_max, distance, footprint_scale, face);
#endif
#if defined BVH_COUNT
        if (t < NO_HIT) ++bvh_row_hits;
#endif
        return t;
    }
    if (!triangles) return NO_HIT;
    int i = 3 * (bvh_plants[2 * plant].w + prim - rows);
    vec4 v0 = bvh_tris[i];
    return bvh_triangle_hit(v0.xyz, bvh_tris[i + 1].xyz, bvh_tris[i + 2].xyz, v0.w, o, d, t_min);
}

#if defined BVH_PRIMS_TWICE
#undef bvh_prim_hit
// The bench's measure of what the primitive tests cost: each primitive tested twice.
float bvh_prim_hit(int plant, int prim, vec3 o, vec3 d, float t_min, float t_max, float distance,
                   float footprint_scale, bool triangles, out int face) {
    int face2;
    float a = bvh_prim_hit_once(plant, prim, o, d, t_min, t_max, distance, footprint_scale, triangles, face);
    float b = bvh_prim_hit_once(plant, prim, o + bvh_bench_zero * d, d, t_min, t_max, distance, footprint_scale,
                                triangles, face2);
    return min(a, b);
}
#endif

vec3 bvh_inverse_dir(vec3 d) {
    vec3 safe = mix(d, sign(d) * 1e-30 + vec3(equal(d, vec3(0.0))) * 1e-30, lessThan(abs(d), vec3(1e-30)));
    return 1.0 / safe;
}

#if defined TWO_LEVEL && defined BVH_AFFINE_COPIES
// Copy `copy`'s world -> plant-frame map applied to a point (w = 1) or a direction (w = 0).
vec3 bvh_to_copy(int copy, vec4 x) {
    int i = 4 * copy;
    return vec3(dot(bvh_copies[i], x), dot(bvh_copies[i + 1], x), dot(bvh_copies[i + 2], x));
}

// A normal n in copy `copy`'s frame as a unit world normal (the map's transpose).
vec3 bvh_normal_from_copy(int copy, vec3 n) {
    int i = 4 * copy;
    return normalize(bvh_copies[i].xyz * n.x + bvh_copies[i + 1].xyz * n.y + bvh_copies[i + 2].xyz * n.z);
}

int bvh_copy_plant(int copy) { return floatBitsToInt(bvh_copies[4 * copy + 3].x); }

#elif defined TWO_LEVEL
// v turned and scaled by the quaternion u (not unit): u v conj(u) = |u|^2 R(u / |u|) v.
vec3 bvh_quat_turn(vec4 u, vec3 v) {
    return (u.w * u.w - dot(u.xyz, u.xyz)) * v + 2.0 * dot(u.xyz, v) * u.xyz + 2.0 * u.w * cross(u.xyz, v);
}

// Copy `copy`'s world -> plant-frame map applied to a point (w = 1) or a direction (w = 0).
vec3 bvh_to_copy(int copy, vec4 x) {
    return bvh_quat_turn(bvh_copies[2 * copy], x.xyz - x.w * bvh_copies[2 * copy + 1].xyz);
}

// A normal n in copy `copy`'s frame as a unit world normal (turned by the rotation itself).
vec3 bvh_normal_from_copy(int copy, vec3 n) {
    vec4 u = bvh_copies[2 * copy];
    return normalize(bvh_quat_turn(vec4(-u.xyz, u.w), n));
}

int bvh_copy_plant(int copy) { return floatBitsToInt(bvh_copies[2 * copy + 1].w); }

#endif

// Node layout (plantgen.gl.trace.node_words): the binary tree collapsed 4-wide, BVH_NODE_VEC4
// vec4 (48 bytes) a node, its four children on an 8-bit grid of the node's own:
//   [0] the grid's origin xyz (float32), w: the first internal child's node (24 bits; the
//       node's internal children are consecutive nodes) | the x step's exponent bits << 24
//   [1] the children's bounds in steps, a byte a child (child j in bits 8j): lo.x, lo.y,
//       lo.z, hi.x; [2].xy: hi.y, hi.z
//   [2].z the leaf children's first primitive position (24 bits; their primitives follow one
//       another in slot order) | the y step's exponent bits << 24
//   [2].w each child's 6-bit code (bits 6j: 0 unused, BVH_INTERNAL a node, else a leaf of
//       that many primitives) | the z step's exponent bits << 24
// A step is a power of two (its float32 bits are the exponent's << 23) and the origin a
// whole number of steps under 2^23 of them, so origin + steps * step is exact in float32:
// the decoded box holds the child's float32 box (lo rounded down, hi up, on the CPU).
// A node's own box is its parent's business: a walk tests four boxes a node, in vec4 lanes.
const int BVH_NODE_VEC4 = 3;
const int BVH_LEAF_BITS = 6;
const uint BVH_INTERNAL = 63u;
const int BVH_EMPTY = -1;
const float BVH_MISS = 3.0e38;   // the entry t of a child the ray misses

// The four bytes of w as a vec4 (byte j in component j).
vec4 bvh_bytes(uint w) { return vec4((uvec4(w) >> uvec4(0u, 8u, 16u, 24u)) & 0xFFu); }

// Wide node w (its index in bvh_nodes) decoded: its four children's boxes by coordinate
// (lo.x of the four, lo.y, ...) and their references as the walk holds them: a node
// (>= 0, in its level's part of bvh_nodes), a leaf -1 - (offset << BVH_LEAF_BITS | count),
// or BVH_EMPTY (an unused slot). The one place that reads the node layout.
void bvh_node(int w, out vec4 lo_x, out vec4 lo_y, out vec4 lo_z, out vec4 hi_x, out vec4 hi_y, out vec4 hi_z,
              out ivec4 ref) {
    int i = BVH_NODE_VEC4 * w;
    vec4 n0 = bvh_nodes[i], n1 = bvh_nodes[i + 1], n2 = bvh_nodes[i + 2];
    uvec4 b1 = floatBitsToUint(n1), b2 = floatBitsToUint(n2);
    uvec3 head = uvec3(floatBitsToUint(n0.w), b2.zw);
    vec3 step = uintBitsToFloat((head >> 24u) << 23u);
    lo_x = n0.x + bvh_bytes(b1.x) * step.x;
    lo_y = n0.y + bvh_bytes(b1.y) * step.y;
    lo_z = n0.z + bvh_bytes(b1.z) * step.z;
    hi_x = n0.x + bvh_bytes(b1.w) * step.x;
    hi_y = n0.y + bvh_bytes(b2.x) * step.y;
    hi_z = n0.z + bvh_bytes(b2.y) * step.z;
    ivec4 code = ivec4((uvec4(head.z) >> uvec4(0u, 6u, 12u, 18u)) & 63u);
    ivec4 inner = ivec4(equal(code, ivec4(BVH_INTERNAL)));
    ivec4 count = code * (1 - inner);
    ivec3 base = ivec3(head & 0xFFFFFFu);
    ivec4 node = base.x + ivec4(0, inner.x, inner.x + inner.y, inner.x + inner.y + inner.z);
    ivec4 offset = base.y + ivec4(0, count.x, count.x + count.y, count.x + count.y + count.z);
    ivec4 leaf = ivec4(greaterThan(code, ivec4(0))) - inner;       // 1 for a leaf
    ref = inner * node + leaf * (-1 - ((offset << BVH_LEAF_BITS) | count)) + (1 - inner - leaf) * BVH_EMPTY;
}

// The entry t of the ray into each of wide node w's four children (BVH_MISS where it
// misses the box, enters at or beyond best_t, leaves before t_min, or the slot is unused),
// and their references.
vec4 bvh_children(int w, vec3 o, vec3 inv_d, float t_min, float best_t, out ivec4 ref) {
    vec4 lo_x, lo_y, lo_z, hi_x, hi_y, hi_z;
    bvh_node(w, lo_x, lo_y, lo_z, hi_x, hi_y, hi_z, ref);
    vec4 ax = (lo_x - o.x) * inv_d.x, bx = (hi_x - o.x) * inv_d.x;
    vec4 ay = (lo_y - o.y) * inv_d.y, by = (hi_y - o.y) * inv_d.y;
    vec4 az = (lo_z - o.z) * inv_d.z, bz = (hi_z - o.z) * inv_d.z;
    vec4 near = max(max(min(ax, bx), min(ay, by)), min(az, bz));
    vec4 far = min(min(max(ax, bx), max(ay, by)), max(az, bz));
    far += 4.0e-7 * abs(far);        // pbrt's 1 + 2*gamma(3): rounding loses no ray the box holds
    vec4 miss = vec4(greaterThan(near, far)) + vec4(lessThanEqual(far, vec4(t_min)))
              + vec4(greaterThanEqual(near, vec4(best_t))) + vec4(equal(ref, ivec4(BVH_EMPTY)));
    return mix(near, vec4(BVH_MISS), greaterThan(miss, vec4(0.0)));
}

// The primitive at position i of a plant's GPU order (a leaf's offset + k), as its data's
// slot: through the plant's id table where it has one (offsets.y >= 0: rows and
// triangles together), else the position itself (its data went up in that order).
int bvh_leaf_prim(ivec4 offsets, int i) {
    return offsets.y >= 0 ? bvh_prims[offsets.y + i] : i;
}

// Orders two children by entry t (nearest first).
void bvh_order(inout float ta, inout float tb, inout int ra, inout int rb) {
    bool swap = tb < ta;
    float t = ta; int r = ra;
    ta = swap ? tb : ta; tb = swap ? t : tb;
    ra = swap ? rb : ra; rb = swap ? r : rb;
}

// Stack entries: reference * 4 + kind.
const int BVH_TOP = 0;      // a node of the top level (world ray)
const int BVH_PLANT = 1;    // a node of the current copy's plant (the copy's ray)
const int BVH_COPY = 2;     // a copy not entered yet (its plant's root)
const int BVH_NONE = BVH_EMPTY;   // no node being walked: take the next entry

// The search: the closest hit (any_hit false) or any hit (the first found) of the ray
// o + t*d with t_min < t < t_max; t = t_max and prim = -1 where there is none. `distance`:
// the eye's distance from the ray's point at t = 0 (world units, |d| = 1: the relief
// march's pixel footprint; 0 for the eye's own rays). `triangles`: false skips the leaf
// triangles (the eye's rays of render --method rt, whose leaves are rasterised as RC's). One loop
// walks both levels: a top-level leaf pushes its copies; popping a copy moves the ray into
// the copy's frame and descends its plant's BLAS (whose nodes are popped before anything
// pushed earlier, so the copy's ray stays the right one until they are done). A node's
// hit children are ordered by entry t; the nearest is walked, the others pushed with their
// entry t, so that an entry popped at or beyond the best t is dropped without a load.
BvhHit bvh_trace(vec3 o, vec3 d, float t_min, float t_max, bool any_hit, float distance, bool triangles) {
    BvhHit best = bvh_no_hit(t_max);
    int stack[BVH_STACK];
    float stack_t[BVH_STACK];
    int sp = 0;
    vec3 inv_w = bvh_inverse_dir(d);
    vec3 oc = o, dc = d, inv_c = inv_w;   // the ray in the current copy's frame
    float scale_c = 1.0;                  // the copy's units per world unit (|dc| / |d|)
    int copy = 0, plant = 0;
    ivec4 offsets = bvh_plants[0];
#if defined TWO_LEVEL
    int kind = BVH_TOP, base = bvh_plants[1].y;   // the walk starts at the top level's root
#else
    int kind = BVH_PLANT, base = offsets.x;
#endif
    int node = 0;                         // the reference being walked (BVH_NONE: pop)
    float t_node = t_min;                 // its entry t
    vec3 ro = o, inv = inv_w;             // its level's ray
#if defined BVH_COUNT
    bvh_visits = 0;
    bvh_tests = 0;
    bvh_row_tests = 0;
    bvh_bound_pass = 0;
    bvh_row_hits = 0;
#endif
    while (true) {
        // Walk the nodes (cheap) until a leaf of primitives is reached or nothing is left;
        // then test that leaf's primitives (dear) outside this loop: on SIMD hardware (a
        // GPU's warp, llvmpipe's lanes) the primitive test then runs once per leaf for the
        // lanes together, not masked at every node step (Aila and Laine's while-while).
        int leaf_first = 0, leaf_count = 0;
        while (true) {
            if (node == BVH_NONE) {
                if (sp == 0) break;
                --sp;
                if (stack_t[sp] >= best.t) continue;
                int entry = stack[sp];
                t_node = stack_t[sp];
                kind = entry & 3;
                node = entry >> 2;
                if (kind == BVH_COPY) {
                    copy = node;
#if defined TWO_LEVEL
                    plant = bvh_copy_plant(copy);
                    oc = bvh_to_copy(copy, vec4(o, 1.0));
                    dc = bvh_to_copy(copy, vec4(d, 0.0));
                    inv_c = bvh_inverse_dir(dc);
                    scale_c = length(dc) / length(d);
#endif
                    offsets = bvh_plants[2 * plant];
                    node = 0;
                    kind = BVH_PLANT;
                }
                bool top = kind == BVH_TOP;
                ro = top ? o : oc;
                inv = top ? inv_w : inv_c;
                base = top ? bvh_plants[1].y : offsets.x;
            }
            if (node < 0) {              // a leaf
                int code = -1 - node;
                int first = code >> BVH_LEAF_BITS, count = code & ((1 << BVH_LEAF_BITS) - 1);
                node = BVH_NONE;
#if defined TWO_LEVEL
                if (kind == BVH_TOP) {
                    for (int k = count - 1; k >= 0; --k) {
                        if (sp < BVH_STACK) {
                            stack[sp] = 4 * (first + k) + BVH_COPY;
                            stack_t[sp++] = t_node;
                        }
                    }
                    continue;
                }
#endif
                leaf_first = first;
                leaf_count = count;
                break;
            }
#if defined BVH_COUNT
            ++bvh_visits;
#endif
            ivec4 ref;
            vec4 t = bvh_children(base + node, ro, inv, t_min, best.t, ref);
            // a sorting network: nearest first
            bvh_order(t.x, t.y, ref.x, ref.y);
            bvh_order(t.z, t.w, ref.z, ref.w);
            bvh_order(t.x, t.z, ref.x, ref.z);
            bvh_order(t.y, t.w, ref.y, ref.w);
            bvh_order(t.y, t.z, ref.y, ref.z);
            if (t.w < BVH_MISS && sp < BVH_STACK) { stack[sp] = 4 * ref.w + kind; stack_t[sp++] = t.w; }
            if (t.z < BVH_MISS && sp < BVH_STACK) { stack[sp] = 4 * ref.z + kind; stack_t[sp++] = t.z; }
            if (t.y < BVH_MISS && sp < BVH_STACK) { stack[sp] = 4 * ref.y + kind; stack_t[sp++] = t.y; }
            node = t.x < BVH_MISS ? ref.x : BVH_NONE;
            t_node = t.x;
        }
        if (leaf_count == 0) break;
        vec3 rd = kind == BVH_TOP ? d : dc;
#if defined BVH_COUNT
        bvh_tests += leaf_count;
#endif
        for (int k = 0; k < leaf_count; ++k) {
            int prim = bvh_leaf_prim(offsets, leaf_first + k);
            int face;
            float t = bvh_prim_hit(plant, prim, ro, rd, t_min, best.t, distance, scale_c, triangles, face);
            if (t < best.t) {
                best = BvhHit(t, prim, copy, face);
                if (any_hit) return best;
            }
        }
    }
    return best;
}

#endif
