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
// plantgen.render.raycast.label_image), SKY_LIGHT (the sky's light traced through the BVH,
// sky_light.glsl), THIN_COVERAGE (coverage anti-aliasing, plantgen.gl.raycast: a row
// thinner than the floor radius at its distance from the eye is cast as if it had that
// radius, so it stays a continuous line instead of breaking into dots, and its alpha is its
// true radius over the floor's, its share of the pixel; such rows are drawn by a pass of
// their own after everything opaque (plantgen.gl.coverage: coverage_pass 1, blended, no
// depth or distance written), the rest by pass 0); THIN_RIBBON (with THIN_COVERAGE, pass 1's
// program: each thin row's proxy is one screen quad around its axis's projection, as wide
// as its cast radius's, instead of its pyramid's back faces: the same pixels' rays from two
// triangles instead of up to six, each of which llvmpipe shades in 4 x 4 blocks of its
// own; thick rows are dropped).

#include "cone.glsl"

#if defined THIN_COVERAGE
uniform float coverage_floor;   // the floor radius per unit of distance from the eye
uniform int coverage_pass;      // 0: the rows at or above the floor; 1: the thinner rows, cast at
                                // the floor (blended)
#endif

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
// The copy's placement (plantgen.geometry.rays.instances): a record in its plant's frame is
// turned, scaled and moved to copy_offset (the copy's origin minus the render origin,
// formed in float64 on the CPU). Merged records draw with the identity (exact in float32).
uniform mat3 copy_turn;
uniform float copy_scale;
uniform vec3 copy_offset;

flat out vec4 f_rec0, f_rec1, f_rec2, f_rec3, f_rec4, f_rec5;
#if defined THIN_COVERAGE
flat out vec2 f_true_radii;   // the row's own radii (r1, r2) before the floor
#endif
#if defined THIN_RIBBON
uniform vec2 viewport;          // width, height in pixels (as eye.glsl's)
uniform vec3 cam_forward;       // unit
uniform vec3 cam_up_scaled;     // unit up * tan(fov_y / 2)
uniform float ribbon_near;      // the eye distance along cam_forward the axis is cut at (the near plane)
#endif

// Axial height where the edge line base + y*axis + (r1 + k*y)*q of the pyramid meets
// `plane`; `rise` is the line's approach rate to the plane (small: grazing).
float edge_cut(vec4 plane, vec3 base, vec3 axis, vec3 q, float r1, float k, out float rise) {
    return plane_height(plane.w - dot(plane.xyz, base), dot(plane.xyz, axis), dot(plane.xyz, q),
                        r1, k, 0.0, rise);
}

// Lowest (highest) axial height of the section of the cone r1 + k*y by `plane` over all
// generators: the extremes sit where n.e_r = -+|n_perp| (the GLSL twin of
// plantgen.geometry.skeletons.frusta._axial_extent).
vec2 plane_axial_range(vec4 plane, vec3 base, vec3 axis, float r1, float k) {
    float na = dot(plane.xyz, axis);
    float n_perp = sqrt(max(1.0 - na * na, 0.0));
    float gap = plane.w - dot(plane.xyz, base);
    float rise;
    float y_minus = plane_height(gap, na, -n_perp, r1, k, TOL_GENERATOR_RISE, rise);
    float y_plus = plane_height(gap, na, n_perp, r1, k, TOL_GENERATOR_RISE, rise);
    return vec2(min(y_minus, y_plus), max(y_minus, y_plus));
}

// The bounding pyramid of §2.6, as plantgen.geometry.skeletons.frusta.bounding_pyramids builds it:
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

#if defined THIN_RIBBON
// The screen quad (corner: sx = -1 or +1 across, end 0 or 1 along; clip coordinates) that
// holds the projection of the cone r1 + k*y cut by the two planes (both relative to the
// render origin, grown by the padding): the axis between the planes' lowest and highest
// cuts (as the grazing pyramid takes them) is projected, and the quad reaches `width`
// pixels beyond it on every side, a bound on the projected radius anywhere along it (a
// sphere of radius r at distance rho, eye depth w, spans at most f*r*rho/w^2 pixels).
vec4 ribbon_corner(vec3 base, vec3 axis, float r1, float k, vec4 plane_lo, vec4 plane_hi, vec3 corner) {
    vec2 range_lo = plane_axial_range(plane_lo, base, axis, r1, k);
    vec2 range_hi = plane_axial_range(plane_hi, base, axis, r1, k);
    float y_lo = min(range_lo.x, range_hi.x), y_hi = max(range_lo.y, range_hi.y);
    float r_max = max(max(r1 + k * y_lo, r1 + k * y_hi), 0.0);
    vec3 p0 = base + y_lo * axis, p1 = base + y_hi * axis;
    float w0 = dot(p0, cam_forward), w1 = dot(p1, cam_forward);
    if (max(w0, w1) < ribbon_near) return vec4(0.0, 0.0, 2.0, 1.0);    // behind the near plane
    if (w0 < ribbon_near) { p0 = mix(p0, p1, (ribbon_near - w0) / (w1 - w0)); w0 = ribbon_near; }
    if (w1 < ribbon_near) { p1 = mix(p1, p0, (ribbon_near - w1) / (w0 - w1)); w1 = ribbon_near; }
    vec2 half_view = 0.5 * viewport;
    vec4 c0 = view_projection * vec4(p0, 1.0), c1 = view_projection * vec4(p1, 1.0);
    vec2 s0 = c0.xy / c0.w * half_view, s1 = c1.xy / c1.w * half_view;   // pixels from the centre
    float focal = half_view.y / length(cam_up_scaled);
    float w_min = min(w0, w1);
    float width = r_max * focal * max(length(p0), length(p1)) / (w_min * w_min) * (1.0 + TOL_RIBBON_MARGIN)
                + TOL_RIBBON_MARGIN;
    vec2 e = s1 - s0;
    float len = length(e);
    vec2 along = len > 1e-6 ? e / len : vec2(1.0, 0.0);
    vec2 across = vec2(-along.y, along.x);
    vec2 s = (corner.z < 0.5 ? s0 - width * along : s1 + width * along) + corner.x * width * across;
    return vec4(s / half_view, 0.0, 1.0);
}
#endif

void main() {
    // the record placed (directions turned; lengths, radii, plane offsets, shell scaled)
    f_rec0 = vec4(copy_turn * (copy_scale * rec0.xyz) + copy_offset, copy_scale * rec0.w);
    f_rec1 = vec4(copy_turn * rec1.xyz, copy_scale * rec1.w);
    f_rec2 = vec4(copy_turn * rec2.xyz, copy_scale * rec2.w);
    f_rec3 = vec4(copy_turn * rec3.xyz, copy_scale * rec3.w);
    f_rec4 = vec4(copy_turn * rec4.xyz, copy_scale * rec4.w);
    f_rec5 = vec4(rec5.xy, copy_scale * rec5.z, rec5.w);
#if defined THIN_COVERAGE
    // the floor at each end (records are eye-relative): a row thinner than it at both ends is
    // cast at the floor, without its relief (under a pixel it shows none). A row wider at
    // either end stays opaque at its own radii: a cone closing to a point (a roof, a branch
    // tip) keeps its relief and its depth, and only its last pixel or two go unsmoothed.
    f_true_radii = vec2(f_rec1.w, f_rec2.w);
    vec2 floor_radii = coverage_floor * vec2(length(f_rec0.xyz), length(f_rec0.xyz + f_rec0.w * f_rec1.xyz));
    bool thin = f_rec1.w < floor_radii.x && f_rec2.w < floor_radii.y;
    if (thin) {
        f_rec1.w = max(f_rec1.w, floor_radii.x);
        f_rec2.w = max(f_rec2.w, floor_radii.y);
        f_rec5.z = 0.0;
    }
#endif
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
#if defined THIN_RIBBON
    gl_Position = thin ? ribbon_corner(base, axis, r1 + pad, k, plane_lo, plane_hi, corner)
                       : vec4(0.0, 0.0, 2.0, 1.0);     // a thick row: pass 0's
    return;
#endif
    vec3 p = pyramid_corner(base, axis, ref_dir, side, r1 + pad, k, plane_lo, plane_hi, corner);
    gl_Position = view_projection * vec4(p, 1.0);
#if defined SCREEN_PROXY
    vec2 screen = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);   // one full-screen triangle
    gl_Position = vec4(2.0 * screen - 1.0, 1e-9 * corner.z, 1.0);   // (keeps `corner` live)
#endif
#if defined THIN_COVERAGE
    if (thin != (coverage_pass == 1)) gl_Position = vec4(0.0, 0.0, 2.0, 1.0);   // not this pass's: no area
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
#if defined THIN_COVERAGE
flat in vec2 f_true_radii;
uniform float coverage_exponent;   // the alpha is the coverage to this power (plantgen.settings.AA_ALPHA_EXPONENT)

// The share of its pixel a hit at p on row f (cast at the floor) covers: the row's true
// radius over the cast one there (1 for a row at or above the floor).
float thin_coverage(Frustum f, vec3 p) {
    float y, radial; vec3 e_r;
    frustum_local(f, p, y, radial, e_r);
    float s = clamp(y / max(f.h, 1e-30), 0.0, 1.0);
    float cast_radius = mix(f.r1, f.r2, s);
    return cast_radius > 0.0 ? clamp(mix(f_true_radii.x, f_true_radii.y, s) / cast_radius, 0.0, 1.0) : 1.0;
}
#endif

#include "eye.glsl"
#include "row.glsl"
#include "sky_light.glsl"

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


Frustum unpack_frustum() {
    return frustum_from_record(f_rec0, f_rec1, f_rec2, f_rec3, f_rec4, f_rec5);
}



#if defined RELIEF && defined SHADOW_PASS && !defined LIGHT_BISECT
#include "light_march.glsl"
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
    int face, samples;
    float t_hit;
    bool cap;
#if defined RELIEF && defined SHADOW_PASS && !defined LIGHT_BISECT
    if (f.shell > 0.0) {
        // the light's map: the relief's secant march along the light (light_march.glsl)
        float t_enter, t_exit;
        if (!frustum_interval(f, relief_band(f).y, o, d, t_min, RAY_T_MAX, t_enter, t_exit, face)) discard;
        bool hit = march_light(f, o, d, t_enter, t_exit, face == FACE_CONE, t_hit, samples);
        count_samples(samples);
        if (!hit) discard;
        cap = t_hit == t_enter && face_is_open_cap(f, face);
    } else
#endif
    {
        bool hit = row_hit(f, o, d, t_min, RAY_T_MAX, t_shift, 1.0, t_hit, face, cap, samples);
        count_samples(samples);
        if (!hit) discard;
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

    vec3 normal, receiver_normal, albedo;
    row_surface(f, p, d, face, cap, normal, receiver_normal, albedo);
    write_hit(albedo, f.material, normal, receiver_normal, p, d, distance);
#if defined THIN_COVERAGE
    out_color.a = pow(thin_coverage(f, p), coverage_exponent);
#endif
#endif
}

#endif
