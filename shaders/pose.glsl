// The sway's pose and skin on the GPU (compute): paper §4's "could be moved to the vertex
// shader", the twin of plantgen.geometry.skeletons.sway_skin.SwaySkin (pose, then skin) for the
// moving rows of an animation, written straight into the ray caster's record buffer.
//
// Every joint of a tree turns about the tree's axis k, so segment i points along its rest
// direction turned by its total turn T_i(t) = sin X·CA_i - cos X·SA_i (X the tree's wave
// phase, CA and SA sums along the root path, uploaded once). Its end is its root start
// plus the sum, along the root path, of the turned directions (or: the tree's fixed part
// plus the turned parts ⟂ k). The joint planes (3)-(5) are built in each joint's medial
// frame; the texture frames' reference angle ψ and the u offsets are products and sums
// along the continuing chains.
//
// Positions stay relative to the eye so float32 keeps its digits: a tree's root start is
// uploaded relative to the eye (formed in float64, rounded once), ends are summed relative
// to their root start from plant-sized terms; plane offsets are
// formed relative to each row's base from lengths and angles alone (the records'
// convention, plantgen.gl.records.pack_records).
//
// Two schedules:
// * GROUPS (one dispatch a frame): trees never depend on each other, so each work group
//   takes whole trees (plantgen.gl.pose balances their rows) and runs the frame on them,
//   with barriers between the steps: the turns and axes of its rows; their ends level by
//   level down the trees (each row's end is its parent's plus its turned direction: one
//   read a row) and their shapes (side branches moved back into their hosts); the joint
//   below each continuing row; the texture frames' turns and u offsets level by level
//   down the continuing chains; the records.
// * PHASE (1..4, one dispatch each, every row an invocation): turns and axes; ends (each
//   invocation walks its root path), shapes and joints; the texture frames' turns (chain
//   walks) and each joint's local u offset; the u offsets (chain walks) and the records.
// With RECORDS undefined (the vertex-skinned mesh, GS) only the ends are made, and each
// segment's posed start and turn go into the pose buffer instead of records.
//
// Variants (defines): GROUP_SIZE; GROUPS or PHASE; DOUBLING (GROUPS: the ends by pointer
// doubling, this many rounds of every row, instead of level by level); RECORDS; MAX_DEPTH,
// MAX_CHAIN (the levels of the trees and of the chains: loop bounds); MIN_BEND_COS,
// ELLIPSE_MARGIN, PARALLEL (plantgen.tolerances and the bend limit, as SwaySkin uses them).

#if defined COMPUTE_SHADER

layout(local_size_x = GROUP_SIZE) in;

const float TWO_PI = 6.283185307179586;
const float HUGE = 3.0e38;

struct Rest {
    ivec4 links;    // parent, chain parent (the row whose upper plane is this row's lower one,
                    // linked joints only; -1), continuing child row (-1), tree * 16 + flags
    vec4 along;     // the rest direction's part along k (xyz), 1/|d| (0: a zero length)
    vec4 wave;      // the part ⟂ k in the tree's frame (u1, u2) as (re, im); CA, SA
    vec4 still;     // the end's part that does not turn, relative to the root start; skinned length
    vec4 radii;     // r_start, r_end (seams fitted), slope, room (a side branch: r_end(host) - r_start)
    vec4 tail;      // record column 5 but u: (0, twist, shell, tag)
};
const int SIDE = 1;        // flags: a side branch (its base moves back into its host)
const int JOINT = 2;       // its lower plane is a continuing joint's (shared with its parent)
const int LINKED = 4;      // that joint continues the texture chain (no radius step)

struct Tree {
    vec4 root;      // root start - eye (xyz), phase / 2π
    vec4 u1;        // the frame ⟂ k (xyz), the frequency's slot in `cycles`
    vec4 u2;
    vec4 k;         // the axis every joint of the tree turns about
};

struct Posed {
    vec4 w;         // turned part ⟂ k (re, im), T, 0
    vec4 axis;      // unit axis, 0
    vec4 end;       // end - the tree's root start (phase 1: the turned direction), 0
    vec4 shape;     // skinned length, r1, slope, δ (a side branch's base moved back by δ)
    vec4 plane;     // the joint below this row: unit normal, offset from the joint point
    vec4 medial;    // that joint's alpha, gamma (normal along M1, n1), cos and sin of the bend
    vec4 step;      // the texture frame's step across it (re, im), conj(at_p) (re, im)
    vec4 turn;      // e^(iψ) (re, im), u offset (PHASE: the joint's local share), 0
    vec4 frame;     // e1 = any_perpendicular(axis), the texture frame's first axis; 0
    vec4 hop;       // DOUBLING: the partial sum of the other round (xyz)
    ivec4 jump;     // DOUBLING: the row 2^r above (x: the sum in end, y: in hop)
};

layout(std430, binding = 0) readonly buffer Rests { Rest rests[]; };
layout(std430, binding = 1) readonly buffer Trees { Tree trees[]; };
layout(std430, binding = 2) readonly buffer Cycles { float cycles[]; };  // fract(f·t), each frequency
layout(std430, binding = 3) coherent buffer Scratch { Posed posed[]; };
#if defined RECORDS
struct Record { vec4 r[6]; };
layout(std430, binding = 4) writeonly buffer Records { Record records[]; };
#else
layout(std430, binding = 4) writeonly buffer Poses { vec4 poses[]; };   // (start - eye, T), (k, 0)
#endif
layout(std430, binding = 5) buffer Report { uint sharp_joints; };
// GROUPS: where each work group's block starts, then the blocks: the first entry of each
// tree level (MAX_DEPTH + 1, the last one past the end), of each chain level (MAX_CHAIN +
// 1), then the group's rows by tree level and by chain level (entries of `schedule`)
layout(std430, binding = 6) readonly buffer Schedule { int schedule[]; };
const int CHAIN_LEVELS = MAX_DEPTH + 1;

uniform int n_rows;
uniform int row_offset;         // the record of the first moving row

int parent_of(int i) { return rests[i].links.x; }
int tree_of(int i) { return rests[i].links.w >> 4; }
bool flag(int i, int f) { return (rests[i].links.w & f) != 0; }
vec2 cmul(vec2 a, vec2 b) { return vec2(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x); }

// any_perpendicular(a): x (z where a is near x) with its part along a removed, made unit.
vec3 first_perpendicular(vec3 a) {
    bool near_x = abs(a.x) >= 0.9;
    vec3 e = a * -(near_x ? a.z : a.x) + (near_x ? vec3(0.0, 0.0, 1.0) : vec3(1.0, 0.0, 0.0));
    return normalize(e);
}

// ------------------------------------------------------------------ phase 1: turns, axes
void phase_turns(int i) {
    Rest r = rests[i];
    Tree tree = trees[r.links.w >> 4];
    float x = TWO_PI * fract(cycles[int(tree.u1.w)] + tree.root.w);
    float turn = sin(x) * r.wave.z - cos(x) * r.wave.w;
    vec2 w = cmul(r.wave.xy, vec2(cos(turn), sin(turn)));
    vec3 d = r.along.xyz + tree.u1.xyz * w.x + tree.u2.xyz * w.y;
    posed[i].w = vec4(w, turn, 0.0);
    vec3 axis = r.along.w > 0.0 ? normalize(d) : vec3(0.0, 1.0, 0.0);
    posed[i].axis = vec4(axis, 0.0);
    posed[i].end = vec4(d, 0.0);
#if defined DOUBLING
    posed[i].jump.x = r.links.x;
#endif
#if defined RECORDS
    posed[i].frame = vec4(first_perpendicular(axis), 0.0);
#endif
}

// ------------------------------------------------------------------ ends, shapes, joints
vec4 shape_of(int j);

// GROUPS, one tree level: a row's end is its parent's plus its turned direction (and its
// shape, which needs its host's axis).
void tree_step(int i) {
    int p = parent_of(i);
    posed[i].end.xyz = (p >= 0 ? posed[p].end.xyz : vec3(0.0)) + posed[i].end.xyz;
#if defined RECORDS
    posed[i].shape = shape_of(i);
#endif
}

// PHASE 2: row i's end, its fixed part plus the turned parts of its root path.
vec3 walked_end(int i) {
    vec2 sum = vec2(0.0);
    int j = i;
    for (int k = 0; k < MAX_DEPTH && j >= 0; k++) {
        sum += posed[j].w.xy;
        j = parent_of(j);
    }
    Tree tree = trees[tree_of(i)];
    return rests[i].still.xyz + tree.u1.xyz * sum.x + tree.u2.xyz * sum.y;
}

// (skinned length, r1, slope, δ) of row j: a side branch's base moves back into its host
// along its own axis (skinning's _extend_side_branches, as SwaySkin's _FrameSegments).
vec4 shape_of(int j) {
    Rest r = rests[j];
    if (!flag(j, SIDE))
        return vec4(r.still.w, r.radii.x, r.radii.z, 0.0);
    float cos_b = clamp(dot(posed[j].axis.xyz, posed[parent_of(j)].axis.xyz), -1.0, 1.0);
    float sin_b = sqrt(1.0 - cos_b * cos_b);
    float room = r.radii.w / max(sin_b, PARALLEL);
    float need = cos_b > PARALLEL ? r.radii.x * sin_b / max(cos_b, PARALLEL) : HUGE;
    float delta = min(need, room);
    float r1 = max(r.radii.x - r.radii.z * delta, 0.0);
    float length = r.still.w + delta;
    return vec4(length, r1, (r.radii.y - r1) / length, delta);
}

// The joint plane in the medial frame (M1, n1) of a joint bent by (c, s): skinning's
// _sphere_planes in 2-d, as SwaySkin's _medial_planes. Returns the unit normal (alpha,
// gamma) and the plane point (xi, eta) relative to the joint point.
vec4 medial_plane(float c, float s, float kp, float rp, float kc, float rc) {
    float inv_sp = 1.0 / sqrt(1.0 + kp * kp);
    float sc = sqrt(1.0 + kc * kc);
    float rho = 0.5 * (rp * inv_sp + rc / sc);
    float ep_x = -kp * inv_sp, ec_m = -kc / sc;
    vec2 pt[2];
    bool far = false;
    for (int side = 0; side < 2; side++) {
        float sigma = side == 0 ? 1.0 : -1.0;
        float ep_y = sigma * inv_sp;
        float ec_x = sigma / sc * s + ec_m * c;
        float ec_y = sigma / sc * c - ec_m * s;
        float den = ep_x * ec_x + ep_y * ec_y + 1.0;
        bool parallel = den <= PARALLEL;                 // parallel on opposite sides
        far = far || parallel;
        pt[side] = vec2(ep_x + ec_x, ep_y + ec_y) * (rho / (parallel ? 1.0 : den));
    }
    vec2 a = pt[0] - pt[1];
    vec2 n = vec2(-a.y, a.x);                            // (A - B) × N_m
    float len = length(n);
    vec2 bisector = vec2(1.0 + c, -s) / sqrt((1.0 + c) * (1.0 + c) + s * s);
    n = len > 1e-30 ? n / len : bisector;                // A = B: the bisector's direction
    if (n.x * (1.0 + c) - n.y * s < 0.0)
        n = -n;
    vec2 point = 0.5 * (pt[0] + pt[1]);
    if (far) {                                           // the bisector plane through J
        n = bisector;
        point = vec2(0.0);
    }
    return vec4(n, point);
}

#if defined RECORDS
// The joint below row i (a continuing child of its parent p): plane, medial frame, and
// the texture frame's step across it (SwaySkin's _frame_joints and _texture_frames).
void joint_below(int i) {
    int p = parent_of(i);
    vec3 m1 = posed[p].axis.xyz, m2 = posed[i].axis.xyz;
    float c = dot(m1, m2);
    vec3 x = cross(m1, m2);
    float s = length(x);
    vec3 nm = s > 1e-30 ? x / s : cross(m1, first_perpendicular(m1));
    nm = normalize(nm - m1 * dot(nm, m1));               // ⟂ M1 to round-off
#if defined GROUPS
    float kp = posed[p].shape.z;                         // made level by level
#else
    float kp = shape_of(p).z;                            // made in this phase: again
#endif
    Rest r = rests[i];
    vec4 mp = medial_plane(c, s, kp, rests[p].radii.y, r.radii.z, r.radii.x);
    float sin_p = abs(kp) / sqrt(1.0 + kp * kp);
    float sin_c = abs(r.radii.z) / sqrt(1.0 + r.radii.z * r.radii.z);
    float n_child = mp.x * c - mp.y * s;
    if (c < MIN_BEND_COS || mp.x <= sin_p + ELLIPSE_MARGIN || n_child <= sin_c + ELLIPSE_MARGIN)
        atomicAdd(sharp_joints, 1u);                     // the CPU path draws such frames
    vec3 n1 = cross(m1, nm);
    posed[i].plane = vec4(mp.x * m1 + mp.y * n1, mp.x * mp.z + mp.y * mp.w);
    posed[i].medial = vec4(mp.xy, c, s);
    vec3 e1p = posed[p].frame.xyz, e1c = posed[i].frame.xyz;
    vec2 at_p = vec2(dot(nm, e1p), -dot(nm, cross(m1, e1p)));        // conjugated
    vec2 at_c = vec2(dot(nm, e1c), dot(nm, cross(m2, e1c)));
    posed[i].step = vec4(flag(i, LINKED) ? cmul(at_c, at_p) : vec2(1.0, 0.0), at_p);
}
#endif

void phase_joints(int i) {
#if defined RECORDS
#if !defined GROUPS
    posed[i].shape = shape_of(i);
#endif
    if (flag(i, JOINT))
        joint_below(i);
    else
        posed[i].step = vec4(1.0, 0.0, 1.0, 0.0);
#endif
}

// Row i's start (its parent's end, or the root start) relative to its root start.
vec3 start_of(int i) {
    int p = parent_of(i);
    return p >= 0 ? posed[p].end.xyz : vec3(0.0);
}

#if defined RECORDS
// ------------------------------------------------------------------ texture frames
// The share of u offset a linked joint below row i adds (skinning's _u_offsets): where
// the reference direction, turned by ``turn_p`` (its parent's e^(iψ)), meets the plane.
float local_u(int i, int p, vec2 turn_p) {
    vec2 chi = cmul(turn_p, posed[i].step.zw);
    float cos_x = chi.x, sin_x = chi.y;
    vec4 m = posed[i].medial;                      // alpha, gamma, c, s
    vec4 sp = posed[p].shape;                      // length, r1, slope
    float n_r = m.y * sin_x;
    float y = (posed[i].plane.w + sp.x * m.x - sp.y * n_r) / (m.x + sp.z * n_r);
    float rho = sp.y + sp.z * y;
    float back = y - sp.x;
    float along_ref = back * m.w * sin_x + rho * (cos_x * cos_x + m.z * sin_x * sin_x);
    float along_side = back * m.w * cos_x + rho * sin_x * cos_x * (m.z - 1.0);
    return atan(along_side, along_ref) * (-1.0 / TWO_PI);
}

// GROUPS, one chain level: e^(iψ) and the u offset follow from the chain parent's.
void chain_step(int i) {
    int p = rests[i].links.y;
    if (p < 0) {
        posed[i].turn = vec4(1.0, 0.0, 0.0, 0.0);
        return;
    }
    vec4 above = posed[p].turn;
    vec2 turn = cmul(above.xy, posed[i].step.xy);
    posed[i].turn = vec4(turn / length(turn), above.z + local_u(i, p, above.xy), 0.0);
}

// PHASE 3: e^(iψ) of row j, the product of the steps along its chain, made unit.
vec2 chain_turn(int j) {
    vec2 turn = vec2(1.0, 0.0);
    for (int k = 0; k < MAX_CHAIN && j >= 0; k++) {
        turn = cmul(turn, posed[j].step.xy);
        j = rests[j].links.y;
    }
    return turn / length(turn);
}

void phase_frames(int i) {
    int p = rests[i].links.y;
    posed[i].turn = vec4(chain_turn(i), p >= 0 ? local_u(i, p, chain_turn(p)) : 0.0, 0.0);
}

// ------------------------------------------------------------------ phase 4: records
void phase_records(int i) {
#if defined GROUPS
    float total = posed[i].turn.z;
#else
    float total = 0.0;                               // PHASE 4: the chain's shares
    for (int j = i, k = 0; k < MAX_CHAIN && j >= 0; k++) {
        total += posed[j].turn.z;
        j = rests[j].links.y;
    }
#endif
    float u = total - floor(total);
    Rest r = rests[i];
    vec4 shape = posed[i].shape;
    vec3 axis = posed[i].axis.xyz;
    vec3 e1 = posed[i].frame.xyz;
    vec2 turn = posed[i].turn.xy;
    int below = r.links.z;
    Record rec;
    rec.r[0] = vec4(trees[tree_of(i)].root.xyz + (start_of(i) - shape.w * axis), shape.x);
    rec.r[1] = vec4(axis, shape.y);
    rec.r[2] = vec4(e1 * turn.x + cross(axis, e1) * turn.y, r.radii.y);
    rec.r[3] = flag(i, JOINT) ? posed[i].plane : vec4(axis, 0.0);
    rec.r[4] = below >= 0 ? vec4(posed[below].plane.xyz, posed[below].plane.w + shape.x * posed[below].medial.x)
                          : vec4(axis, shape.x);
    rec.r[5] = vec4(u < 1.0 ? u : 0.0, r.tail.yzw);
    records[row_offset + i] = rec;
}
#else
// ------------------------------------------------------------------ phase 3: the pose buffer
void phase_poses(int i) {
    poses[2 * i] = vec4(trees[tree_of(i)].root.xyz + start_of(i), posed[i].w.z);
    poses[2 * i + 1] = trees[tree_of(i)].k;
}
#endif

#if defined DOUBLING
// One round of pointer doubling down the trees: each row adds the sum held by the row
// 2^r above it and takes over that row's jump (the sums alternate between end and hop).
void doubling_step(int i, bool even) {
    vec3 sum = even ? posed[i].end.xyz : posed[i].hop.xyz;
    int j = even ? posed[i].jump.x : posed[i].jump.y;
    int next = -1;
    if (j >= 0) {
        sum += even ? posed[j].end.xyz : posed[j].hop.xyz;
        next = even ? posed[j].jump.x : posed[j].jump.y;
    }
    if (even) {
        posed[i].hop.xyz = sum;
        posed[i].jump.y = next;
    } else {
        posed[i].end.xyz = sum;
        posed[i].jump.x = next;
    }
}

// After the last round: the ends in `end`, and the rows' shapes.
void doubled(int i) {
    if (DOUBLING % 2 == 1)
        posed[i].end.xyz = posed[i].hop.xyz;
#if defined RECORDS
    posed[i].shape = shape_of(i);
#endif
}
#endif

#if defined GROUPS
// every row of this group (its rows by tree level), then a barrier
void each_row(int block, int step) {
    int stop = schedule[block + MAX_DEPTH];
    for (int k = schedule[block] + int(gl_LocalInvocationID.x); k < stop; k += GROUP_SIZE) {
        int i = schedule[k];
        if (step == 0) phase_turns(i);
#if defined DOUBLING
        else if (step >= 3) {
            if (step == 3 + DOUBLING) doubled(i); else doubling_step(i, (step - 3) % 2 == 0);
        }
#endif
#if defined RECORDS
        else if (step == 1) phase_joints(i);
        else phase_records(i);
#else
        else phase_poses(i);
#endif
    }
    memoryBarrierBuffer();
    barrier();
}

// each level in turn (the first entries of levels [first, first + count] in the block), a
// barrier after each
void each_level(int block, int first, int count) {
    for (int level = 0; level < count; level++) {
        int stop = schedule[block + first + level + 1];
        for (int k = schedule[block + first + level] + int(gl_LocalInvocationID.x); k < stop; k += GROUP_SIZE) {
#if defined RECORDS
            if (first > 0) chain_step(schedule[k]); else
#endif
            tree_step(schedule[k]);
        }
        memoryBarrierBuffer();
        barrier();
    }
}
#endif

void main() {
#if defined GROUPS
    int block = schedule[gl_WorkGroupID.x];
    each_row(block, 0);
#if defined DOUBLING
    for (int round = 0; round <= DOUBLING; round++)
        each_row(block, 3 + round);
#else
    each_level(block, 0, MAX_DEPTH);
#endif
#if defined RECORDS
    each_row(block, 1);
    each_level(block, CHAIN_LEVELS, MAX_CHAIN);
#endif
    each_row(block, 2);
#else
    int i = int(gl_GlobalInvocationID.x);
    if (i >= n_rows)
        return;
#if PHASE == 1
    phase_turns(i);
#elif PHASE == 2
    posed[i].end = vec4(walked_end(i), 0.0);
    phase_joints(i);
#elif PHASE == 3 && defined RECORDS
    phase_frames(i);
#elif PHASE == 3
    phase_poses(i);
#else
    phase_records(i);
#endif
#endif
}

#endif
