// Analytic ray casting of (relief-mapped) conical frusta (Bhagvat et al. 2009, §2.5-§3).
//
// One instance per segment: the vertex shader builds the segment's bounding pyramid
// (§2.6, 8 corners, 12 triangles) from the segment's record; back faces are rasterised so
// an eye inside a pyramid still gets fragments. The fragment shader casts the pixel's ray
// (through the pixel centre, as plantgen.geometry.Camera.rays does), writes colour,
// the distance along the ray, and gl_FragDepth.
//
// Variants (defines): RELIEF (march the relief shell, §3), V_EXACT (v of (7) per sample
// instead of interpolated between entry and exit), SCREEN_PROXY (each instance covers the
// whole screen instead of its pyramid: slow, a coverage oracle for tests), SHADOWS (sample
// the light's shadow map, shaders/shadow.glsl), SHADOW_PASS (cast orthographic rays along
// the light instead of the eye's rays and write only the hit's depth in the light's
// window: the shadow map pass of plantgen.render.passes; with RELIEF the relief surface
// is what casts the shadow, found by light_march.glsl, or with LIGHT_BISECT by the eye's
// march), LABELS (write the row's material slot as a label, unshaded: part masks,
// plantgen.render.raycast.label_image).

#include "cone.glsl"

#if defined VERTEX_SHADER

in vec3 corner;            // template: (sx, sz, end) with sx, sz = -1 or +1, end = 0 or 1
in vec4 rec0;              // base (relative to the render origin), h
in vec4 rec1;              // axis, r1
in vec4 rec2;              // ref_dir, r2
in vec4 rec3;              // plane_lo (n, d - n.base)
in vec4 rec4;              // plane_hi (n, d - n.base)
in vec4 rec5;              // u_offset, twist, shell, tag (material + 256 open_lo + 512 open_hi
                           // + 1024 v_slot + 131072 (v_slots - 1))

uniform mat4 view_projection;   // render-origin-relative world -> clip
uniform float hull_padding;     // relative growth of the pyramid (covers rasterisation edges)
// The copy's placement (plantgen.geometry.instances): a record in its plant's frame is
// turned, scaled and moved to copy_offset (the copy's origin minus the render origin,
// formed in float64 on the CPU). Merged records draw with the identity (exact in float32).
uniform mat3 copy_turn;
uniform float copy_scale;
uniform vec3 copy_offset;

flat out vec4 f_rec0, f_rec1, f_rec2, f_rec3, f_rec4, f_rec5;

// Axial height where the edge line base + y*axis + (r1 + k*y)*q of the pyramid meets
// `plane`; `rise` is the line's approach rate to the plane (small: grazing).
float edge_cut(vec4 plane, vec3 base, vec3 axis, vec3 q, float r1, float k, out float rise) {
    return plane_height(plane.w - dot(plane.xyz, base), dot(plane.xyz, axis), dot(plane.xyz, q),
                        r1, k, 0.0, rise);
}

// Lowest (highest) axial height of the section of the cone r1 + k*y by `plane` over all
// generators: the extremes sit where n.e_r = -+|n_perp| (the GLSL twin of
// plantgen.geometry.frusta._axial_extent).
vec2 plane_axial_range(vec4 plane, vec3 base, vec3 axis, float r1, float k) {
    float na = dot(plane.xyz, axis);
    float n_perp = sqrt(max(1.0 - na * na, 0.0));
    float gap = plane.w - dot(plane.xyz, base);
    float rise;
    float y_minus = plane_height(gap, na, -n_perp, r1, k, TOL_GENERATOR_RISE, rise);
    float y_plus = plane_height(gap, na, n_perp, r1, k, TOL_GENERATOR_RISE, rise);
    return vec2(min(y_minus, y_plus), max(y_minus, y_plus));
}

// The bounding pyramid of §2.6, as plantgen.geometry.frusta.bounding_pyramids builds it:
// the square pyramid around the cone r1 + k*y (here grown by the shell and a padding),
// its four edge lines cut by the two planes, each edge keeping the lower and the higher
// of its two cuts (so rows whose planes cross inside stay covered). If any edge meets a
// plane at a grazing angle, the whole row uses planes perpendicular to the axis at the
// frustum's axial extent instead.
vec3 pyramid_corner(vec3 base, vec3 axis, vec3 ref_dir, vec3 side, float r1, float k,
                    vec4 plane_lo, vec4 plane_hi, vec3 corner) {
    float n_dot_a = min(dot(plane_lo.xyz, axis), dot(plane_hi.xyz, axis));
    float limit = TOL_PYRAMID_GRAZING * max(n_dot_a, TOL_PLANE_TILT_COS);
    bool grazing = false;
    for (int i = 0; i < 4; ++i) {
        vec3 q = float((i & 1) * 2 - 1) * ref_dir + float((i >> 1) * 2 - 1) * side;
        float rise_lo, rise_hi;
        float y_a = edge_cut(plane_lo, base, axis, q, r1, k, rise_lo);
        float y_b = edge_cut(plane_hi, base, axis, q, r1, k, rise_hi);
        grazing = grazing || min(rise_lo, rise_hi) < limit || isinf(y_a) || isinf(y_b)
                  || isnan(y_a) || isnan(y_b);
    }
    vec3 q = corner.x * ref_dir + corner.y * side;
    float y;
    if (grazing) {
        vec2 range_lo = plane_axial_range(plane_lo, base, axis, r1, k);
        vec2 range_hi = plane_axial_range(plane_hi, base, axis, r1, k);
        float lowest = min(range_lo.x, range_hi.x), highest = max(range_hi.y, range_lo.y);
        y = corner.z < 0.5 ? lowest : highest;
    } else {
        float rise;
        float y_a = edge_cut(plane_lo, base, axis, q, r1, k, rise);
        float y_b = edge_cut(plane_hi, base, axis, q, r1, k, rise);
        y = corner.z < 0.5 ? min(y_a, y_b) : max(y_a, y_b);
    }
    float radius = max(r1 + k * y, 0.0);   // past an apex the square shrinks to the axis
    return base + y * axis + radius * q;
}

void main() {
    // the record placed (directions turned; lengths, radii, plane offsets, shell scaled)
    f_rec0 = vec4(copy_turn * (copy_scale * rec0.xyz) + copy_offset, copy_scale * rec0.w);
    f_rec1 = vec4(copy_turn * rec1.xyz, copy_scale * rec1.w);
    f_rec2 = vec4(copy_turn * rec2.xyz, copy_scale * rec2.w);
    f_rec3 = vec4(copy_turn * rec3.xyz, copy_scale * rec3.w);
    f_rec4 = vec4(copy_turn * rec4.xyz, copy_scale * rec4.w);
    f_rec5 = vec4(rec5.xy, copy_scale * rec5.z, rec5.w);
    vec3 base = f_rec0.xyz; float h = f_rec0.w;
    vec3 axis = f_rec1.xyz; vec3 ref_dir = f_rec2.xyz;
    float shell = f_rec5.z;
    float r1 = f_rec1.w + shell, r2 = f_rec2.w + shell;
    float r_max = max(r1, r2);
    float pad = hull_padding * r_max + TOL_PYRAMID_PAD * (h + r_max);
    float k = cone_slope(r1, r2, h);
    vec3 side = cross(ref_dir, axis);
    // planes relative to the render origin, grown by `pad` all round (moved outwards)
    vec4 plane_lo = vec4(f_rec3.xyz, f_rec3.w + dot(f_rec3.xyz, base) - pad);
    vec4 plane_hi = vec4(f_rec4.xyz, f_rec4.w + dot(f_rec4.xyz, base) + pad);
    vec3 p = pyramid_corner(base, axis, ref_dir, side, r1 + pad, k, plane_lo, plane_hi, corner);
    gl_Position = view_projection * vec4(p, 1.0);
#if defined SCREEN_PROXY
    vec2 screen = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);   // one full-screen triangle
    gl_Position = vec4(2.0 * screen - 1.0, 1e-9 * corner.z, 1.0);   // (keeps `corner` live)
#endif
}

#elif defined FRAGMENT_SHADER

#if !defined SHADOW_PASS
#include "shading.glsl"
#if defined SHADOWS
#include "shadow.glsl"
#endif
#else
uniform vec3 light_origin;     // centre of the light's window, render-origin relative
uniform vec3 light_right;      // unit, the window's +x
uniform vec3 light_up;         // unit, the window's +y
uniform vec3 light_forward;    // unit, the direction the light travels
uniform vec2 light_half;       // half extents of the window (world units)
uniform vec2 light_depth;      // near, far along light_forward from light_origin
#endif

flat in vec4 f_rec0, f_rec1, f_rec2, f_rec3, f_rec4, f_rec5;

uniform vec2 viewport;          // width, height in pixels
uniform vec3 cam_forward;       // unit
uniform vec3 cam_right_scaled;  // unit right * tan(fov_x / 2)
uniform vec3 cam_up_scaled;     // unit up * tan(fov_y / 2)
uniform vec2 depth_coeffs;      // projection m[2][2], m[2][3]: clip z = A*z_view + B
#include "heights.glsl"
uniform int linear_steps;        // fixed march: the samples; adaptive: their most
uniform int binary_steps;
uniform int march_min_steps;     // adaptive march: the fewest samples
uniform float march_density;     // adaptive march: samples per relief texel crossed
uniform float march_precision;   // adaptive march: bisect to this many pixel footprints
uniform vec2 pixel_footprint;    // world size of a pixel at distance s: x*s + y

#if defined STATS
// Work counters of a diagnostic render (plantgen.render.raycast.Raycaster.work): the
// fragments the shader ran for, the height samples the relief march took. Atomics are
// side effects, so a counting render tests depth late: its fragment count is the work
// without early depth rejection.
layout(std430, binding = 2) buffer WorkCounts { uint counted_fragments; uint counted_samples; };
void count_fragment() { atomicAdd(counted_fragments, 1u); }
void count_samples(int n) { atomicAdd(counted_samples, uint(n)); }
#else
void count_fragment() {}
void count_samples(int n) {}
#endif

#if !defined SHADOW_PASS
layout(location = 0) out vec4 out_color;
layout(location = 1) out float out_distance;   // distance along the ray from the eye
#endif

Frustum unpack_frustum() {
    return frustum_from_record(f_rec0, f_rec1, f_rec2, f_rec3, f_rec4, f_rec5);
}

// Whether a cutting plane closes the frustum with a visible cap (an open chain end) rather
// than being a joint shared with a continuing neighbour (inside the plant).
bool face_is_open_cap(Frustum f, int face) {
    return (face == FACE_LO && f.open_lo) || (face == FACE_HI && f.open_hi);
}


// Window depth of a hit `distance` along the eye's ray direction d: the depth test against
// other frusta and ordinary meshes (the projection's z of the view-space depth).
float eye_depth(float distance, vec3 d) {
    float z_view = -distance * dot(d, cam_forward);
    float ndc_z = (depth_coeffs.x * z_view + depth_coeffs.y) / (-z_view);
    return clamp(0.5 * ndc_z + 0.5, 0.0, 1.0);
}

vec3 pixel_ray() {
    vec2 ndc = 2.0 * gl_FragCoord.xy / viewport - 1.0;   // pixel centres; +y is up
    return normalize(cam_forward + ndc.x * cam_right_scaled + ndc.y * cam_up_scaled);
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

// Relief height w of (12) at t: 0 on the inner cone, 1 on the outer one.
float shell_height_at(Frustum f, ShellRay r, float t) {
    float radial = length(r.q0 + t * r.dq);
    return (radial - (f.r1 + frustum_slope(f) * (r.y0 + t * r.dy))) / f.shell;
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
#if defined SHADOW_PASS && !defined LIGHT_BISECT
#include "light_march.glsl"
#endif
#endif

void main() {
    count_fragment();
    Frustum f = unpack_frustum();
#if defined SHADOW_PASS
    // an orthographic ray of the light, starting on the window's near plane
    vec2 ndc = 2.0 * gl_FragCoord.xy / viewport - 1.0;
    vec3 ray_origin = light_origin + ndc.x * light_half.x * light_right
                    + ndc.y * light_half.y * light_up + light_depth.x * light_forward;
    vec3 d = light_forward;
    // Re-centre the ray origin at the point of the ray nearest the axis segment.
    float t_shift = recenter_shift(f, ray_origin, d);
    vec3 o = ray_origin + t_shift * d;
#else
    vec3 d = pixel_ray();
    // Re-centre the ray origin at the point of the ray nearest the axis segment.
    float t_shift = recenter_shift(f, vec3(0.0), d);
    vec3 o = t_shift * d;
#endif
    float t_min = -t_shift;        // the ray's start (the eye, or the light's near plane)
    float t_enter, t_exit; int face;
    float t_hit;
    bool cap = false;
#if defined RELIEF
    if (f.shell > 0.0) {
        int samples;
#if defined SHADOW_PASS && !defined LIGHT_BISECT
        if (!frustum_interval(f, relief_band(f).y, o, d, t_min, RAY_T_MAX, t_enter, t_exit, face)) discard;
        bool hit = march_light(f, o, d, t_enter, t_exit, face == FACE_CONE, t_hit, samples);
#else
        if (!frustum_interval(f, f.shell, o, d, t_min, RAY_T_MAX, t_enter, t_exit, face)) discard;
        float t_end = t_exit;
        float ti_enter, ti_exit; int inner_face;
        bool inner = frustum_interval(f, 0.0, o, d, t_min, RAY_T_MAX, ti_enter, ti_exit, inner_face);
        bool end_on_inner = inner && inner_face != FACE_NONE && ti_enter <= t_end;
        if (end_on_inner) t_end = ti_enter;
        bool hit = march_relief(f, o, d, t_enter, t_end, end_on_inner, t_shift + t_enter, t_hit, samples);
#endif
        count_samples(samples);
        if (!hit) discard;
        cap = t_hit == t_enter && face_is_open_cap(f, face);
    } else
#endif
    {
        if (!frustum_hit(f, o, d, t_min, t_hit, face)) discard;
        cap = face != FACE_CONE;
    }
    vec3 p = o + t_hit * d;
    float distance = t_shift + t_hit;
#if defined SHADOW_PASS
    float z_light = dot(p - light_origin, light_forward);
    gl_FragDepth = clamp((z_light - light_depth.x) / (light_depth.y - light_depth.x), 0.0, 1.0);
#elif defined LABELS
    // a part mask: the row's label (its material slot) in red, unshaded
    out_color = vec4(float(f.material) / 255.0, 0.0, 0.0, 1.0);
    out_distance = distance;
    gl_FragDepth = eye_depth(distance, d);
#else

    // Shading: u, v and the interpolated normal (6)-(8), texture colour, one light.
    float v;
    vec3 normal = frustum_normal(f, p, v);
    if (cap) normal = face == FACE_LO ? -f.plane_lo.xyz : f.plane_hi.xyz;
    vec2 uv = frustum_uv_at(f, p, v);
    HeightMap heights = height_map(f.material);
    float texel = height_in(heights, uv);
#if defined RELIEF
    if (f.shell > 0.0 && !cap) {
        // Tilt the normal by the height map's gradient in the (u, v) frame.
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
        normal = normalize(normal - f.shell * (dh_du / len_u * tangent_u
                                               + dh_dv / len_v * normalize(g)));
    }
#endif
    vec3 albedo = material_albedo(f.material, texel);
    // the cone's own normal e_r - k*axis: what (8) is bent towards where it turns away from
    // the eye, and (below) the receiver plane of the shadow test
    vec3 true_normal = normal;
    if (!cap) {
        float y_t, radial_t; vec3 e_r_t;
        frustum_local(f, p, y_t, radial_t, e_r_t);
        true_normal = normalize(e_r_t - frustum_slope(f) * f.axis);
        normal = facing_normal(normal, true_normal, -d);
    }
#if defined SHADOWS
    // the receiver plane of the shadow test is the true tangent plane, not the
    // interpolated shading normal (8), which leans radially
    vec3 receiver_normal = true_normal;
#if defined RELIEF
    if (f.shell > 0.0 && !cap) receiver_normal = normal;
#endif
    float visibility = shadow_visibility(p, receiver_normal);
#else
    float visibility = 1.0;
#endif
    vec3 color = shade_surface_visible(albedo, f.material, normal, -d, 1.0, visibility);
    out_color = vec4(to_display(color), 1.0);
    out_distance = distance;

    gl_FragDepth = eye_depth(distance, d);
#endif
}

#endif
