// The light's relief caster (plantgen.settings.ShadowSettings.march = "secant"): where a
// ray of the shadow map's pass meets the relief surface of one frustum. Included by
// raycast.glsl for SHADOW_PASS with RELIEF (not LIGHT_BISECT, the eye's march instead).
//
// The light only needs the hit's depth to a fraction of a map texel (the receivers' bias
// is half a texel), and its rays are many and short, so each sample is made cheap:
//
// - Only the band of the shell the material's relief occupies is marched (between its
//   map's lowest and highest heights: aloe fills 0.30 to 0.70 of its shell): a ray enters
//   it at the cone of the highest height and has met the relief by the cone of the lowest.
// - (u, v) are interpolated along the ray between the band's entry and its end (the
//   bottom cone's entry, or the band's exit): u quadratically through the angles at the
//   ends and the middle (three angles instead of one per sample), v linearly, as the
//   paper interpolates it (the remark after (12)). The ray's height w of (12) is exact at
//   every sample (one length).
// - The linear samples are sized as the eye's adaptive march sizes them, in the map's
//   texels: march_density per relief texel the path crosses in u and v, a texel counting
//   at least one map texel, clamped to [march_min_steps, linear_steps]. A ray that enters
//   through the outer cone is at w = 1 there: its entry is sampled only if the first
//   bracket needs it.
// - The crossing is refined by regula falsi (the Illinois variant) between the last
//   sample above the relief and the first under it, until the bracket is shorter than
//   march_precision map texels (at most binary_steps): the relief is bilinear between
//   texel centres and w nearly linear, so one or two steps usually land within a small
//   part of a texel where bisection needs five.
// - A bilinear cell's four heights come from one texel fetch of height_corners (the
//   cells' corners, built by plantgen.gl.material_uniforms.corner_maps), weighted in
//   float32 as heights.glsl weights its gather: the same heights as the eye's.

#ifndef LIGHT_MARCH_GLSL
#define LIGHT_MARCH_GLSL

uniform sampler2DArray height_corners;   // RGBA8: texel (i, j) = the cell whose lower-left
                                         // texel is (i, j - 1), in textureGather's order
uniform vec2 height_range[MAX_MATERIALS];  // lowest and highest height of each material's map

// The part of the shell a material's relief can occupy: its map's lowest height times the
// relief's shallowest depth along the row (relief_scale at the thinner end), its highest
// times the shell. Above it the light's rays cannot meet the relief, and by the lowest
// level every ray has met it: only this band is marched.
vec2 relief_band(Frustum f) {
    vec2 range = height_range[clamp(f.material, 0, MAX_MATERIALS - 1)];
    float shallow = max(f.r1, f.r2) > 0.0 ? clamp(min(f.r1, f.r2) / max(f.r1, f.r2), 0.0, 1.0) : 1.0;
    return f.shell * vec2(range.x * shallow, range.y);
}

// Bilinear height of map m at u_rep = u * repeat.x (turns) and y = v * repeat.y * height
// - 0.5 (texel rows): height_in of heights.glsl (u repeats, v clamps), one texel fetch.
float cell_height(HeightMap m, float u_rep, float y) {
    vec2 xy = vec2(fract(u_rep) * m.size.x - 0.5, clamp(y, -0.5, m.size.y - 0.5));
    vec2 cell = floor(xy);
    vec2 w = xy - cell;
    ivec2 c = ivec2(cell);
    vec4 g = texelFetch(height_corners, ivec3(c.x < 0 ? c.x + int(m.size.x) : c.x, c.y + 1, int(m.layer)), 0);
    return mix(mix(g.w, g.z, w.x), mix(g.x, g.y, w.x), w.y);
}

// atan(y, x) within 1e-5 radians (Abramowitz & Stegun 4.4.49 after range reduction): a
// ten-thousandth of a relief texel, for the path's two ends.
float atan_light(float y, float x) {
    float ax = abs(x), ay = abs(y);
    float a = min(ax, ay) / max(max(ax, ay), 1e-30);
    float s = a * a;
    float r = a * (0.9998660 + s * (-0.3302995 + s * (0.1801410 + s * (-0.0851330 + s * 0.0208351))));
    r = ay > ax ? 1.5707963 - r : r;
    r = x < 0.0 ? 3.1415927 - r : r;
    return y < 0.0 ? -r : r;
}

// The first t >= t0 where the ray o + t*d enters the cone grown by dr (no plane clipping:
// the march ends there or at the shell's exit, whichever comes first); NO_HIT if it does not.
float grown_cone_entry(Frustum f, float dr, vec3 o, vec3 d, float t0) {
    float a, b, c, e_y, d_y;
    cone_quadratic(f, dr, o - f.base, d, a, b, c, e_y, d_y);
    float disc = b * b - a * c;
    if (disc < 0.0) return NO_HIT;
    float q = -(b + (b >= 0.0 ? sqrt(disc) : -sqrt(disc)));
    float t1 = a != 0.0 ? q / a : NO_HIT, t2 = q != 0.0 ? c / q : t1;
    float lo = min(t1, t2), hi = max(t1, t2);
    return lo >= t0 ? lo : (hi >= t0 && a < 0.0 ? hi : NO_HIT);
}

// A path through the relief's band, s in [0, 1] from its entry: t = mix(t_in, t_end, s);
// everything a sample needs is a polynomial in s: the point across the axis q_in + s dq,
// the cone's radius there r_in + s dr, the map's column u_in + s du + s (1 - s) bend (u
// quadratic through the angles at both ends and the middle, in turns times the repeat) and
// its row y_in + s dy (v linear, in texels).
struct LightPath {
    float t_in, t_end;
    vec2 q_in, dq;
    float r_in, dr;
    float u_in, du, bend;
    float y_in, dy;
};

// The distance from the axis minus the relief's radius at fraction s of the path, in world
// units: > 0 above the relief, <= 0 on or under it (w - h of (12), times the relief's
// depth there: the shell times relief_scale, the cone's radius over the larger end's).
float light_gap(Frustum f, HeightMap m, LightPath p, float s) {
    float h = cell_height(m, p.u_in + s * p.du + s * (1.0 - s) * p.bend, p.y_in + s * p.dy);
    float radius = p.r_in + s * p.dr;
    float big = max(f.r1, f.r2);
    float depth = f.shell * (big > 0.0 ? clamp(radius / big, 0.0, 1.0) : 1.0);
    return length(p.q_in + s * p.dq) - radius - depth * h;
}

// The signed angle from a to b, in turns.
float turns_between(vec2 a, vec2 b) {
    return atan_light(a.x * b.y - a.y * b.x, dot(a, b)) / TWO_PI;
}

// Linear samples of the path: march_density per relief texel crossed, a texel counting at
// least one map texel (pixel_footprint.y: the map texel's world size).
int light_steps(Frustum f, HeightMap m, LightPath p) {
    float texels = abs(p.du) * m.size.x + abs(p.dy);
    vec2 texels_per_unit = m.size * m.repeat;
    float radius = max(max(f.r1, f.r2), 1e-30);
    float texel_world = min(TWO_PI * radius / texels_per_unit.x, f.h * f.v_slots / texels_per_unit.y);
    float footprint = max(pixel_footprint.y / max(texel_world, 1e-30), 1.0);
    return int(clamp(ceil(march_density * texels / footprint), float(max(march_min_steps, 1)),
                     float(max(linear_steps, 1))));
}

// Regula falsi (Illinois) on the bracket [s_lo, s_hi] of the path, gaps g_lo > 0 >= g_hi,
// until it is shorter than march_precision map texels (at most binary_steps evaluations);
// returns the crossing's s, the secant's estimate in the last bracket.
float refine_crossing(Frustum f, HeightMap m, LightPath p, float s_lo, float g_lo, float s_hi, float g_hi,
                      inout int samples) {
    float want = march_precision * pixel_footprint.y / max(p.t_end - p.t_in, 1e-30);
    float s = s_lo + (s_hi - s_lo) * g_lo / (g_lo - g_hi);
    int side = 0;
    for (int k = 0; k < binary_steps && s_hi - s_lo > want; ++k) {
        float g = light_gap(f, m, p, s);
        ++samples;
        if (g <= 0.0) { s_hi = s; g_hi = g; if (side < 0) g_lo *= 0.5; side = -1; }
        else { s_lo = s; g_lo = g; if (side > 0) g_hi *= 0.5; side = 1; }
        s = s_lo + (s_hi - s_lo) * g_lo / (g_lo - g_hi);
    }
    return s;
}

// The relief hit of the ray o + t*d that enters the relief's band (relief_band) at t_in
// (through its top cone if cone_entry) and leaves it at t_exit. True on a hit (t_hit);
// `samples` counts heights.
bool march_light(Frustum f, vec3 o, vec3 d, float t_in, float t_exit, bool cone_entry,
                 out float t_hit, out int samples) {
    HeightMap m = height_map(f.material);
    ShellRay r = shell_ray(f, o, d);
    float t_inner = grown_cone_entry(f, relief_band(f).x, o, d, t_in);     // the band's bottom
    bool end_on_inner = t_inner <= t_exit;
    LightPath p;
    p.t_in = t_in;
    p.t_end = end_on_inner ? t_inner : t_exit;
    vec2 q_end = r.q0 + p.t_end * r.dq;
    p.q_in = r.q0 + t_in * r.dq;
    p.dq = q_end - p.q_in;
    float k = frustum_slope(f);
    p.r_in = f.r1 + k * (r.y0 + t_in * r.dy);
    p.dr = k * r.dy * (p.t_end - t_in);
    float v_in = frustum_v(f, o + t_in * d), v_end = frustum_v(f, o + p.t_end * d);
    vec2 q_mid = p.q_in + 0.5 * p.dq;
    float to_mid = turns_between(p.q_in, q_mid), to_end = to_mid + turns_between(q_mid, q_end);
    p.u_in = (atan_light(p.q_in.y, p.q_in.x) / TWO_PI + f.u_offset + v_in * f.twist) * m.repeat.x;
    p.du = (to_end + (v_end - v_in) * f.twist) * m.repeat.x;
    p.bend = (4.0 * to_mid - 2.0 * to_end) * m.repeat.x;    // u(1/2) - (u(0) + u(1)) / 2, times 4
    p.y_in = texture_v(f, v_in) * m.repeat.y * m.size.y - 0.5;
    p.dy = (v_end - v_in) / f.v_slots * m.repeat.y * m.size.y;
    int steps = light_steps(f, m, p);
    float s_prev = 0.0, g_prev = 0.0;
    samples = 0;
    t_hit = p.t_end;
    for (int i = cone_entry ? 1 : 0; i <= steps; ++i) {
        float s = float(i) / float(steps);
        float g = light_gap(f, m, p, s);
        ++samples;
        if (g <= 0.0) {
            if (i == 0) { t_hit = t_in; return true; }
            if (cone_entry && i == 1) { g_prev = light_gap(f, m, p, 0.0); ++samples; }
            if (g_prev <= 0.0) { t_hit = t_in; return true; }      // a relief at the very top
            t_hit = mix(t_in, p.t_end, refine_crossing(f, m, p, s_prev, g_prev, s, g, samples));
            return true;
        }
        s_prev = s;
        g_prev = g;
    }
    return end_on_inner;      // rounding left w a hair above the lowest height at the band's bottom
}

#endif
