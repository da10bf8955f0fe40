// Conical frusta (Bhagvat et al. 2009, §2): the one place the cone math lives.
// Included by every program that ray casts or bounds frusta.
//
// Coordinates are world coordinates relative to the render origin (the camera eye),
// converted to float32 on the CPU after subtracting the origin in float64, so nothing
// here carries the digits of a model that sits far from the world origin.
//
// The cone is in slope form, r(y) = r1 + k*y with k = (r2 - r1)/h and y measured along
// the axis from the base (the paper's (1) without h'): cylinders, flaring cones and cones
// closing to a point need no branch. Points with r(y) < 0 (the mirror nappe) are outside.
// Every ray/cone intersection goes through cone_quadratic and solve_quadratic (pbrt-v4's
// Quadratic: the discriminant as a difference of products, the stable q form); their numpy
// twins in plantgen/geometry/rays/reference.py read line for line the same.

#ifndef CONE_GLSL
#define CONE_GLSL

const float TWO_PI = 6.283185307179586;
const float RAY_T_MAX = 1e30;   // beyond every hit: the open end of a ray's interval
const float NO_HIT = 3.0e38;    // "no root", "no hit": the numpy reference's inf

// One segment, unpacked from its record (see plantgen/render/records.py, pack_records).
struct Frustum {
    vec3 base;      // C1, relative to the render origin
    float h;        // axis length
    vec3 axis;      // unit axis, base towards top
    float r1;       // radius at the base
    vec3 ref_dir;   // unit, perpendicular to axis: the u = 0 direction
    float r2;       // radius at the top
    vec4 plane_lo;  // (n, d): inside iff dot(n, x - base) - d >= 0 (d relative to base)
    vec4 plane_hi;  // (n, d): inside iff dot(n, x - base) - d <= 0
    bool open_lo;   // the lower end is capped (no continuing row shares its plane)
    bool open_hi;   // the upper end is capped
    float u_offset; // added to u so u is continuous across joints
    float twist;    // turns; u gains v*twist
    float shell;    // relief shell thickness (0: no relief): the relief's bound, its
                    // depth at height y shell * relief_scale(f, y)
    int material;   // material index
    float v_slot;   // the row's slot of the texture's v, of v_slots (Frusta.v_part):
    float v_slots;  // the texture is looked up at (v_slot + v) / v_slots
};

// A row's record (plantgen.gl.records.pack_records: six vec4) as a Frustum.
Frustum frustum_from_record(vec4 r0, vec4 r1, vec4 r2, vec4 r3, vec4 r4, vec4 r5) {
    Frustum f;
    f.base = r0.xyz; f.h = r0.w;
    f.axis = r1.xyz; f.r1 = r1.w;
    f.ref_dir = r2.xyz; f.r2 = r2.w;
    f.plane_lo = r3; f.plane_hi = r4;
    f.u_offset = r5.x; f.twist = r5.y; f.shell = r5.z;
    int tag = int(r5.w + 0.5);
    f.material = tag & 255;
    f.open_lo = (tag & 256) != 0;
    f.open_hi = (tag & 512) != 0;
    f.v_slot = float((tag >> 10) & 127);
    f.v_slots = float(((tag >> 17) & 127) + 1);
    return f;
}

// The texture's v of the row's own v (the paper's v where v_slots is 1).
float texture_v(Frustum f, float v) { return (f.v_slot + v) / f.v_slots; }

// k = (r2 - r1)/h, the slope of a cone with radii r1, r2 an axis length h apart
// (plantgen.geometry.skeletons.frusta.cone_slope).
float cone_slope(float r1, float r2, float h) { return (r2 - r1) / h; }

float frustum_slope(Frustum f) { return cone_slope(f.r1, f.r2, f.h); }

// How far beyond a cutting plane shared with a continuing neighbour a lateral hit still
// counts (plantgen.tolerances.Tolerances.joint_slack): the float32 rounding of the plane
// test, done relative to the base, which lies |base| from the render origin. 0 at an open
// end (a cap). Twin: reference._joint_slack.
float joint_slack(Frustum f, bool open_end) {
    return open_end ? 0.0 : TOL_JOINT_SLACK * 5.9604645e-8 * (length(f.base) + f.h);
}

// Axial height y where the generator C1 + y*axis + (r1 + k*y)*e of a cone meets the plane
// n.x = d, with gap = d - n.C1, n_axis = n.axis, n_radial = n.e: the GLSL twin of
// plantgen.geometry.skeletons.frusta.plane_height, y = (gap - r1*n_radial) / (n_axis + k*n_radial).
// `rise` is the denominator, the generator's approach to the plane (0: parallel to it).
// With min_rise > 0 the divisor keeps rise's sign but at least min_rise in size (a finite
// height for a generator parallel to the plane).
float plane_height(float gap, float n_axis, float n_radial, float r1, float k, float min_rise,
                   out float rise) {
    rise = n_axis + k * n_radial;
    float above = gap - r1 * n_radial;
    return min_rise > 0.0 ? above / max(abs(rise), min_rise) * sign(rise) : above / rise;
}

// Radius of the cone grown by `dr` at axial coordinate y (negative on the mirror nappe).
float frustum_radius(Frustum f, float dr, float y) { return f.r1 + dr + frustum_slope(f) * y; }

// The relief's depth at axial height y as a fraction of the shell: r(y)/max(r1, r2) in
// [0, 1] (1 where both radii are 0). The relief follows the radius, so a shell that is a
// fraction of the radius is as deep on both sides of a joint.
// Twin: plantgen.geometry.skeletons.frusta.relief_scale.
float relief_scale(Frustum f, float y) {
    float big = max(f.r1, f.r2);
    return big > 0.0 ? clamp(frustum_radius(f, 0.0, y) / big, 0.0, 1.0) : 1.0;
}

// Signed distances to the two cutting planes: lo >= 0 and hi <= 0 inside.
float plane_lo_side(Frustum f, vec3 p) { return dot(f.plane_lo.xyz, p - f.base) - f.plane_lo.w; }
float plane_hi_side(Frustum f, vec3 p) { return dot(f.plane_hi.xyz, p - f.base) - f.plane_hi.w; }

// Clip the parameter interval [t0, t1] of the ray o + t*d to one half-space
// dot(n, x) - w <= 0 (pass n, w negated for a >= 0 half-space). `face` becomes `this_face`
// when the half-space's boundary moves t0. Returns false if the interval becomes empty.
bool clip_half_space(vec3 n, float w, int this_face, vec3 o, vec3 d,
                     inout float t0, inout float t1, inout int face) {
    float side0 = dot(n, o) - w;
    float slope = dot(n, d);
    if (slope == 0.0) return side0 <= 0.0 && t0 <= t1;
    float t_cross = -side0 / slope;
    if (slope > 0.0) t1 = min(t1, t_cross);
    else if (t_cross > t0) { t0 = t_cross; face = this_face; }
    return t0 <= t1;
}

// The float32 product a*b as p + e exactly (Dekker's product, Veltkamp's split into 12-bit
// halves): p = a*b rounded, e its rounding error. Needs no fma (which some drivers, llvmpipe
// among them, evaluate with two roundings); `precise` keeps the compiler from fusing or
// reordering the steps, whose rounding is the point. Twin: reference._two_product.
void two_product(float a, float b, out float p, out float e) {
    const float SPLIT = 4097.0;                 // 2^12 + 1
    precise float a_big = SPLIT * a;
    precise float a_hi = a_big - (a_big - a);
    precise float a_lo = a - a_hi;
    precise float b_big = SPLIT * b;
    precise float b_hi = b_big - (b_big - b);
    precise float b_lo = b - b_hi;
    precise float product = a * b;
    precise float error = ((a_hi * b_hi - product) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo;
    p = product;
    e = error;
}

// a*b - c*d within about an ulp even where the two products nearly cancel (as pbrt-v4's
// DifferenceOfProducts, with exact products instead of fma): the products' difference is
// exact there, and their rounding errors are added back.
// Twin: plantgen.geometry.rays.reference.difference_of_products.
float difference_of_products(float a, float b, float c, float d) {
    float ab, ab_error, cd, cd_error;
    two_product(a, b, ab, ab_error);
    two_product(c, d, cd, cd_error);
    precise float result = (ab - cd) + (ab_error - cd_error);
    return result;
}

// The roots of a*t^2 + 2*b*t + c = 0 (half-b form), as pbrt-v4's Quadratic: the
// discriminant b^2 - a*c as a difference of products, q = -(b + copysign(sqrt(disc), b)),
// t_q = q/a and t_c = c/q (neither cancels; where a = 0, a line, c/q = -c/(2b) is its one
// root). t_q is NO_HIT where a = 0; t_c is t_q where q = 0 (b = 0 and a*c = 0). Returns the
// discriminant: no real root where it is negative.
// Twin: plantgen.geometry.rays.reference.solve_quadratic.
float solve_quadratic(float a, float b, float c, out float t_q, out float t_c) {
    float disc = difference_of_products(b, b, a, c);
    float root = sqrt(max(disc, 0.0));
    float q = -(b + (b >= 0.0 ? root : -root));     // copysign(root, b)
    t_q = a != 0.0 ? q / a : NO_HIT;
    t_c = q != 0.0 ? c / q : t_q;
    return disc;
}

// The cone r(y) = r1 + dr + k*y (the frustum's cone grown by dr) along the ray e + t*d,
// e relative to the base: g(t) = a*t^2 + 2*b*t + c <= 0 inside the double cone. With
// e_y = e.axis, d_y = d.axis, the parts E, D perpendicular to the axis and the radius at
// e's height r0 = r1 + dr + k*e_y: a = D.D - (k*d_y)^2, b = E.D - k*d_y*r0, c = E.E - r0^2.
// Returns e_y and d_y. Twin: plantgen.geometry.rays.reference.cone_quadratic.
void cone_quadratic(Frustum f, float dr, vec3 e, vec3 d, out float a, out float b, out float c,
                    out float e_y, out float d_y) {
    float k = frustum_slope(f);
    e_y = dot(e, f.axis);
    d_y = dot(d, f.axis);
    vec3 e_perp = e - e_y * f.axis, d_perp = d - d_y * f.axis;
    float r0 = f.r1 + dr + k * e_y;
    a = dot(d_perp, d_perp) - k * k * d_y * d_y;
    b = dot(e_perp, d_perp) - k * d_y * r0;
    c = dot(e_perp, e_perp) - r0 * r0;
}

const int FACE_CONE = 0;      // entered through the conical surface
const int FACE_LO = 1;        // entered through the lower cutting plane (a cap)
const int FACE_HI = 2;        // entered through the upper cutting plane (a cap)
const int FACE_NONE = 3;      // the interval starts at t_min (the origin is inside)

// The part of the ray o + t*d, t in [t_min, t_max], inside the solid frustum grown by `dr`
// (cone of radius r(y) + dr, r(y) + dr >= 0, between the two cutting planes). The solid is
// convex, so the part is one interval [t_enter, t_exit]; `enter_face` says which surface
// t_enter lies on. `o` should lie near the segment (the caller re-centres it) so that
// float32 keeps its digits. Returns false if the ray misses the solid in [t_min, t_max].
bool frustum_interval(Frustum f, float dr, vec3 o, vec3 d, float t_min, float t_max,
                      out float t_enter, out float t_exit, out int enter_face) {
    vec3 e = o - f.base;
    float a, b, c, e_y, d_y;
    cone_quadratic(f, dr, e, d, a, b, c, e_y, d_y);
    float t_q, t_c;
    float disc = solve_quadratic(a, b, c, t_q, t_c);

    // Up to two connected pieces of {g <= 0} along the ray; each lies in one nappe.
    float lo0 = -RAY_T_MAX, hi0 = RAY_T_MAX, lo1 = RAY_T_MAX, hi1 = -RAY_T_MAX;   // piece 1 empty
    if (a == 0.0) {                                         // parallel to a generator: g is linear
        if (b == 0.0) { if (c > 0.0) return false; }
        else if (b > 0.0) hi0 = t_c; else lo0 = t_c;
    } else if (disc < 0.0) {
        if (a > 0.0) return false;                          // never inside
        // a < 0: inside for every t, within one nappe: keep the whole line
    } else {
        float t_lo = min(t_q, t_c), t_hi = max(t_q, t_c);
        if (a > 0.0) { lo0 = t_lo; hi0 = t_hi; }
        else { hi0 = t_lo; lo1 = t_hi; hi1 = RAY_T_MAX; }
    }
    for (int piece = 0; piece < 2; ++piece) {
        float t0 = piece == 0 ? lo0 : lo1;
        float t1 = min(piece == 0 ? hi0 : hi1, t_max);
        int face = FACE_CONE;
        if (t0 <= t_min) { t0 = t_min; face = FACE_NONE; }
        if (t0 > t1) continue;
        float w_lo = f.plane_lo.w - joint_slack(f, f.open_lo), w_hi = f.plane_hi.w + joint_slack(f, f.open_hi);
        if (!clip_half_space(-f.plane_lo.xyz, -w_lo, FACE_LO, e, d, t0, t1, face)) continue;
        if (!clip_half_space(f.plane_hi.xyz, w_hi, FACE_HI, e, d, t0, t1, face)) continue;
        float y_mid = e_y + 0.5 * (t0 + t1) * d_y;
        if (frustum_radius(f, dr, y_mid) < 0.0) continue;  // the mirror nappe
        t_enter = t0; t_exit = t1; enter_face = face;
        return true;
    }
    return false;
}

// The ray parameter of the point of o + t*d nearest the axis segment {C1 + s*axis,
// 0 <= s <= h} (step 2 of plantgen.geometry.rays.reference): re-centring the ray there gives
// the quadratic numbers of the size of the ray's distance from the axis, not of the eye's.
float recenter_shift(Frustum f, vec3 o, vec3 d) {
    vec3 E = o - f.base;
    float b = dot(d, f.axis), de = dot(d, E), e = dot(f.axis, E), dd = dot(d, d);
    float den = dd - b * b;
    float s = den > TOL_RECENTER_PARALLEL * dd ? clamp(e + b * (b * e - de) / den, 0.0, f.h) : 0.5 * f.h;
    return (s * b - de) / dd;
}

vec3 safe_normalize(vec3 x, vec3 fallback) {
    float len = length(x);
    return len > 0.0 ? x / len : fallback;
}

// The nearest hit of the ray o + t*d (t > t_min) with the frustum's skin: the cone between
// its planes, and a flat cap on each open end. A line-by-line port of
// plantgen.geometry.rays.reference._pair_hits (there: E = O - C1, already re-centred by the
// caller here). `kind` is FACE_CONE, FACE_LO or FACE_HI. Returns false for a miss.
bool frustum_hit(Frustum f, vec3 o, vec3 d, float t_min, out float t_hit, out int kind) {
    float k = frustum_slope(f);
    vec3 E = o - f.base;
    float A, B, C, ey, dy;
    cone_quadratic(f, 0.0, E, d, A, B, C, ey, dy);
    float t1, t2;
    float disc = solve_quadratic(A, B, C, t1, t2);
    t_hit = NO_HIT;
    kind = FACE_CONE;
    float slack_lo = joint_slack(f, f.open_lo), slack_hi = joint_slack(f, f.open_hi);
    if (disc >= 0.0) {
        for (int i = 0; i < 2; ++i) {
            float t = i == 0 ? t1 : t2;
            vec3 X = E + t * d;
            float y = dot(X, f.axis);
            bool ok = abs(t) < NO_HIT && f.r1 + k * y >= 0.0;   // finite (NaN fails too)
            ok = ok && dot(f.plane_lo.xyz, X) - f.plane_lo.w >= -slack_lo
                    && dot(f.plane_hi.xyz, X) - f.plane_hi.w <= slack_hi;
            ok = ok && t > t_min;
            if (ok && t < t_hit) t_hit = t;
        }
    }
    for (int c = 0; c < 2; ++c) {
        bool is_lo = c == 0;
        if (!(is_lo ? f.open_lo : f.open_hi)) continue;
        vec4 cap = is_lo ? f.plane_lo : f.plane_hi;
        vec4 other = is_lo ? f.plane_hi : f.plane_lo;
        float den = dot(cap.xyz, d);
        if (den == 0.0) continue;
        float t = (cap.w - dot(cap.xyz, E)) / den;
        vec3 X = E + t * d;
        float y = dot(X, f.axis);
        float rr = f.r1 + k * y;
        vec3 perp = X - y * f.axis;
        bool ok = abs(t) < NO_HIT && rr >= 0.0 && dot(perp, perp) <= rr * rr;
        float other_side = dot(other.xyz, X) - other.w;
        ok = ok && (is_lo ? other_side <= slack_hi : other_side >= -slack_lo);
        ok = ok && t > t_min;
        if (ok && t < t_hit) { t_hit = t; kind = is_lo ? FACE_LO : FACE_HI; }
    }
    return t_hit < NO_HIT;
}

// Axial coordinate y, radial distance and unit radial direction of a point p.
void frustum_local(Frustum f, vec3 p, out float y, out float radial, out vec3 e_r) {
    vec3 e = p - f.base;
    y = dot(e, f.axis);
    vec3 perp = e - y * f.axis;
    radial = length(perp);
    e_r = radial > 0.0 ? perp / radial : f.ref_dir;
}

// Where the generator through p of the concentric cone through p meets the two planes:
// p + s_lo*g and p + s_hi*g, with g = axis + k*e_r (the paper's apex line, defined for k = 0).
void generator_params(Frustum f, vec3 p, vec3 e_r, out vec3 g, out float s_lo, out float s_hi) {
    g = f.axis + frustum_slope(f) * e_r;
    s_lo = -plane_lo_side(f, p) / dot(f.plane_lo.xyz, g);
    s_hi = -plane_hi_side(f, p) / dot(f.plane_hi.xyz, g);
}

// v of (7): |P - P_l| / |P_u - P_l| along the generator through p.
float frustum_v(Frustum f, vec3 p) {
    float y, radial; vec3 e_r, g; float s_lo, s_hi;
    frustum_local(f, p, y, radial, e_r);
    generator_params(f, p, e_r, g, s_lo, s_hi);
    return clamp(-s_lo / (s_hi - s_lo), 0.0, 1.0);
}

// u of (6) without the twist term, in turns: the angle around the axis from ref_dir.
float frustum_angle_u(Frustum f, vec3 p) {
    vec3 e = p - f.base;
    vec3 bitangent = cross(f.axis, f.ref_dir);
    return atan(dot(e, bitangent), dot(e, f.ref_dir)) / TWO_PI;
}

// Texture (u, v) at p with the row's own v: u in [0, 1) with the joint offset and twist,
// v the texture's (texture_v).
vec2 frustum_uv_at(Frustum f, vec3 p, float v) {
    return vec2(fract(frustum_angle_u(f, p) + f.u_offset + v * f.twist), texture_v(f, v));
}

// The interpolated normal of (8) at p (on the cone or a concentric one), with its v.
vec3 frustum_normal(Frustum f, vec3 p, out float v) {
    float y, radial; vec3 e_r, g; float s_lo, s_hi;
    frustum_local(f, p, y, radial, e_r);
    generator_params(f, p, e_r, g, s_lo, s_hi);
    v = clamp(-s_lo / (s_hi - s_lo), 0.0, 1.0);
    vec3 top = f.base + f.h * f.axis;
    vec3 n_lo = safe_normalize(p + s_lo * g - f.base, e_r);
    vec3 n_hi = safe_normalize(p + s_hi * g - top, e_r);   // zero at a closed apex
    return safe_normalize(mix(n_lo, n_hi, v), e_r);
}

#endif
