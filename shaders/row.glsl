// One row's hit and surface, shared by the programs that cast rays at frusta: the ray
// caster's fragments (raycast.glsl, one row per fragment) and the BVH traversal
// (bvh.glsl: render --method rt, its shadow rays, the scan, plantgen.trace).
// Variants: RELIEF (the relief shell is marched, §3), V_EXACT, MARCH_FIXED (see
// plantgen.settings.RaycastSettings). Needs cone.glsl; declares the march's uniforms.

#ifndef ROW_GLSL
#define ROW_GLSL

#include "cone.glsl"
#include "heights.glsl"
uniform int linear_steps;        // fixed march: the samples; adaptive: their most
uniform int binary_steps;
uniform int march_min_steps;     // adaptive march: the fewest samples
uniform float march_density;     // adaptive march: samples per relief texel crossed
uniform float march_precision;   // adaptive march: bisect to this many pixel footprints
uniform vec2 pixel_footprint;    // world size of a pixel at distance s: x*s + y

// Whether a cutting plane closes the frustum with a visible cap (an open chain end) rather
// than being a joint shared with a continuing neighbour (inside the plant).
bool face_is_open_cap(Frustum f, int face) {
    return (face == FACE_LO && f.open_lo) || (face == FACE_HI && f.open_hi);
}

#if defined RELIEF
// The ray o + t*d in the frame of frustum f, for the relief march: per sample everything
// is linear in t but one length and one atan (the paper's remark after (12): the inner and
// outer radii are linear along the ray, u is the angle in the plane across the axis).
struct ShellRay {
    vec2 q0, dq;    // the point's part across the axis, in the (ref_dir, axis x ref_dir)
                    // frame: q0 + t*dq (its length is the radial distance, its angle u)
    float y0, dy;   // the axial coordinate y0 + t*dy
};

ShellRay shell_ray(Frustum f, vec3 o, vec3 d) {
    vec3 e = o - f.base;
    vec3 bitangent = cross(f.axis, f.ref_dir);
    ShellRay r;
    r.q0 = vec2(dot(e, f.ref_dir), dot(e, bitangent));
    r.dq = vec2(dot(d, f.ref_dir), dot(d, bitangent));
    r.y0 = dot(e, f.axis);
    r.dy = dot(d, f.axis);
    return r;
}

// Relief height w of (12) at t: 0 on the inner cone, 1 at the relief's full depth there
// (shell * relief_scale: the relief follows the radius).
float shell_height_at(Frustum f, ShellRay r, float t) {
    float radial = length(r.q0 + t * r.dq);
    float y = r.y0 + t * r.dy;
    return (radial - (f.r1 + frustum_slope(f) * y)) / max(f.shell * relief_scale(f, y), 1e-30);
}

// (u, v) at t: u from the point's angle (6), v interpolated between entry and exit (the
// paper's approximation, exact for parallel planes) or, with V_EXACT, v of (7).
vec2 shell_uv_at(Frustum f, ShellRay r, vec3 o, vec3 d, float t, float v_interp) {
    vec2 q = r.q0 + t * r.dq;
#if defined V_EXACT
    float v = frustum_v(f, o + t * d);
#else
    float v = v_interp;
#endif
    return vec2(fract(atan(q.y, q.x) / TWO_PI + f.u_offset + v * f.twist), texture_v(f, v));
}

// The march's samples for the shell interval [t_in, t_end] (plantgen.render.raycast.
// RaycastSettings): x linear samples, y bisection steps. MARCH_FIXED: linear_steps and
// binary_steps. Otherwise sized to what the pixel sees: march_density linear samples per
// relief texel the ray crosses (in u and v), where a texel counts at least one pixel
// footprint (a far branch's pixel covers many texels and needs few samples, a grazing ray
// near the eye crosses many), clamped to [march_min_steps, linear_steps]; then bisection
// until the bracket is shorter than march_precision pixel footprints, at most binary_steps.
ivec2 march_steps(Frustum f, ShellRay r, HeightMap m, float t_in, float t_end, float v_in,
                  float v_end, float distance) {
#if defined MARCH_FIXED
    return ivec2(max(linear_steps, 1), binary_steps);
#else
    vec2 q_in = r.q0 + t_in * r.dq, q_end = r.q0 + t_end * r.dq;
    float turns = abs(atan(q_in.x * q_end.y - q_in.y * q_end.x, dot(q_in, q_end))) / TWO_PI;
    float dv = abs(v_end - v_in);                 // the row's own v
    vec2 texels_per_unit = m.size * m.repeat;    // texels per turn of u, per unit of texture v
    float texels = (turns + dv * abs(f.twist)) * texels_per_unit.x + dv / f.v_slots * texels_per_unit.y;
    float radius = max(max(f.r1, f.r2), 1e-30);
    float texel_world = min(TWO_PI * radius / texels_per_unit.x, f.h * f.v_slots / texels_per_unit.y);
    float pixel_world = max(pixel_footprint.x * distance + pixel_footprint.y, 1e-30);
    float footprint = max(pixel_world / max(texel_world, 1e-30), 1.0);
    float linear = clamp(ceil(march_density * texels / footprint),
                         float(max(march_min_steps, 1)), float(max(linear_steps, 1)));
    float bracket = (t_end - t_in) / linear;     // length of the interval bisected
    float halvings = ceil(log2(max(bracket / (march_precision * pixel_world), 1.0)));
    return ivec2(int(linear), int(min(halvings, float(binary_steps))));
#endif
}

// March the shell from t_in to t_end: linear steps, then a bisection. True on a hit.
// `distance` is the eye's (or the light's window's) distance to the entry, for the pixel
// footprint; `samples` counts the height samples taken.
bool march_relief(Frustum f, vec3 o, vec3 d, float t_in, float t_end, bool end_on_inner,
                  float distance, out float t_hit, out int samples) {
    HeightMap m = height_map(f.material);
    ShellRay r = shell_ray(f, o, d);
    float v_in = frustum_v(f, o + t_in * d), v_end = frustum_v(f, o + t_end * d);
    ivec2 plan = march_steps(f, r, m, t_in, t_end, v_in, v_end, distance);
    int steps = plan.x;
    // Linear search for the first sample on or under the relief; then, outside the loop (so
    // that neighbouring rays that stop at different samples share one bisection), bisect
    // between the last sample above and that one.
    float t_out = t_in, t_inside = t_in;
    bool found = false;
    samples = 0;
    for (int i = 0; i <= steps; ++i) {
        float s = float(i) / float(steps);
        float t = mix(t_in, t_end, s);
        float ground = height_in(m, shell_uv_at(f, r, o, d, t, mix(v_in, v_end, s)));
        ++samples;
        if (shell_height_at(f, r, t) <= ground || (i == steps && end_on_inner)) {
            t_inside = t;
            found = true;
            break;
        }
        t_out = t;
    }
    if (!found) return false;
    int halvings = t_inside > t_in ? plan.y : 0;    // a hit at the entry needs no bisection
    for (int b = 0; b < halvings; ++b) {
        float t_mid = 0.5 * (t_out + t_inside);
        float sm = (t_mid - t_in) / max(t_end - t_in, 1e-30);
        float gm = height_in(m, shell_uv_at(f, r, o, d, t_mid, mix(v_in, v_end, sm)));
        ++samples;
        if (shell_height_at(f, r, t_mid) <= gm) t_inside = t_mid; else t_out = t_mid;
    }
    t_hit = t_inside;
    return true;
}

#endif

// The hit of the ray o + t*d (t > t_min) with row f: cone.glsl's analytic skin, or with
// RELIEF where the row has a shell the relief surface marched in it. `o` should lie near
// the row (the caller re-centres it, recenter_shift). With RELIEF a shell entered at or
// beyond t_max is not marched (a hit found nearer; the analytic skin ignores t_max). The march sizes its samples to the
// eye's pixel footprint (pixel_footprint, whose constant term is 0 for the eye) at the
// world distance `distance` + t, in the row's units times `footprint_scale` (1; in a
// scaled copy's frame the row's units per world unit). Returns false for a miss; else
// t_hit, `face` (FACE_*), `cap` (the hit is on an open end's disc), `samples` (relief).
bool row_hit(Frustum f, vec3 o, vec3 d, float t_min, float t_max, float distance, float footprint_scale,
             out float t_hit, out int face, out bool cap, out int samples) {
    samples = 0;
    cap = false;
#if defined RELIEF
    if (f.shell > 0.0) {
        float t_enter, t_exit;
        if (!frustum_interval(f, f.shell, o, d, t_min, RAY_T_MAX, t_enter, t_exit, face) || t_enter >= t_max)
            return false;
        float t_end = t_exit;
        float ti_enter, ti_exit; int inner_face;
        bool inner = frustum_interval(f, 0.0, o, d, t_min, RAY_T_MAX, ti_enter, ti_exit, inner_face);
        bool end_on_inner = inner && inner_face != FACE_NONE && ti_enter <= t_end;
        if (end_on_inner) t_end = ti_enter;
        if (!march_relief(f, o, d, t_enter, t_end, end_on_inner, (distance + t_enter) * footprint_scale,
                          t_hit, samples)) return false;
        cap = t_hit == t_enter && face_is_open_cap(f, face);
        return true;
    }
#endif
    if (!frustum_hit(f, o, d, t_min, t_hit, face)) return false;
    cap = face != FACE_CONE;
    return true;
}

#if defined FRAGMENT_SHADER && !defined SHADOW_PASS
#include "shading.glsl"
#if defined RELIEF
// The relief's tilt at p, whose texture coordinates are uv: the height map's gradient in
// the (u, v) frame (central differences a texel apart) times the relief's depth there, a
// vector along the surface; a normal minus it leans as the relief does.
vec3 relief_tilt(Frustum f, vec3 p, HeightMap heights, vec2 uv) {
    vec2 du = vec2(1.0 / (heights.size.x * heights.repeat.x), 0.0);
    vec2 dv = vec2(0.0, 1.0 / (heights.size.y * heights.repeat.y));
    float dh_du = (height_in(heights, uv + du) - height_in(heights, uv - du)) / (2.0 * du.x);
    float dh_dv = (height_in(heights, uv + dv) - height_in(heights, uv - dv)) / (2.0 * dv.y);
    float y, radial; vec3 e_r, g; float s_lo, s_hi;
    frustum_local(f, p, y, radial, e_r);
    generator_params(f, p, e_r, g, s_lo, s_hi);
    vec3 tangent_u = cross(f.axis, e_r);
    float len_u = TWO_PI * max(radial, TOL_TANGENT_FLOOR_F32);            // |dP/du|
    float len_v = max((s_hi - s_lo) * length(g) * f.v_slots, TOL_TANGENT_FLOOR_F32);  // |dP/dv_tex|
    float depth = f.shell * relief_scale(f, y);
    return depth * (dh_du / len_u * tangent_u + dh_dv / len_v * normalize(g));
}
#endif

// The surface of row f at its hit p (the ray's direction d, unit; all in f's frame): the
// shading normal (interpolated (8), tilted by the relief, a cap's plane; turned to face
// the eye), the receiver plane's normal for shadows (the surface's own tangent plane: the
// cone's, or the relief's), and the albedo of its texture.
void row_surface(Frustum f, vec3 p, vec3 d, int face, bool cap, out vec3 normal, out vec3 receiver_normal,
                 out vec3 albedo) {
    // Shading: u, v and the interpolated normal (6)-(8), texture colour, one light.
    float v;
    normal = frustum_normal(f, p, v);
    if (cap) normal = face == FACE_LO ? -f.plane_lo.xyz : f.plane_hi.xyz;
    vec2 uv = frustum_uv_at(f, p, v);
    HeightMap heights = height_map(f.material);
    float texel = height_in(heights, uv);
    albedo = material_albedo(f.material, texel);
    // the cone's own normal e_r - k*axis: what (8) is bent towards where it turns away from
    // the eye, and the receiver plane of the shadow test
    vec3 true_normal = normal;
    float y, radial; vec3 e_r;
    if (!cap) {
        frustum_local(f, p, y, radial, e_r);
        true_normal = normalize(e_r - frustum_slope(f) * f.axis);
    }
    receiver_normal = true_normal;
#if defined RELIEF
    if (f.shell > 0.0 && !cap) {
        vec3 tilt = relief_tilt(f, p, heights, uv);
        normal = normalize(normal - tilt);
        // The receiver plane is the relief surface's own: the tilt applied to the cone the
        // relief grows at this height (its slope grows with the relief, which follows the
        // radius), not to (8), which on a steep cone is nearly radial, tens of degrees off
        // the surface: a plane that far off shadows the relief with itself.
        float big = max(f.r1, f.r2);
        float slope = frustum_slope(f) * (1.0 + (big > 0.0 ? f.shell * texel / big : 0.0));
        receiver_normal = normalize(normalize(e_r - slope * f.axis) - tilt);
    }
#endif
    if (!cap) normal = facing_normal(normal, true_normal, -d);
}
#endif

#endif
