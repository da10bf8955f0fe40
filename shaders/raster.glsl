// Raster renderer for tessellated frusta (GS, GS+R): the polygonal baseline of Table 1.
//
// One indexed draw of the whole mesh, back faces culled. The shading is the ray caster's:
// the same shading.glsl (material albedo from the height map texel, one light,
// Blinn-Phong), the same height maps and texture repeats, the same normals (8) (per vertex,
// interpolated), the same colour and distance outputs. Only the geometry differs.
//
// GS+R meshes come displaced onto the relief shell, with vertex normals tilted by the
// height map's gradient as RC+R tilts its normals (plantgen.geometry.meshes.mesh.tessellate).
//
// Per-row data (chain position, material) sits in a storage buffer indexed by the
// primitive: lateral triangles come row by row, TRIANGLES_PER_ROW each, caps after them.
//
// Variants (defines): TRIANGLES_PER_ROW (16·4^m); FACE_ROWS (a mesh with knuckles, whose
// slices carry other counts: every face's row from the CapRows buffer); SHADOWS (sample the light's shadow map,
// shaders/shadow.glsl, with the facet's own plane as the receiver plane, as the ray caster
// uses the cone's tangent plane); SHADOW_PASS (depth only, into the light's map: the
// mesh's front faces as the light sees them, as the ray caster writes its nearest hit);
// SKINNED (a swaying scene's mesh, built once at rest, posed here: each vertex turns about
// its pivot segment's posed start by the mean turn of its two segments, read from the
// pose buffer that shaders/pose.glsl writes; plantgen.geometry.meshes.skinned_mesh); NORMAL_MAP (GS+N:
// the relief as a baked tangent-space normal map, plantgen.geometry.meshes.textures, read as glTF
// readers read one: T the vertex tangent, B = cross(N, T)·w, n = T·x + B·y + N·z; caps,
// which the ray caster leaves unrelieved, keep their normal); PARALLAX (GS+POM, with NORMAL_MAP:
// parallax occlusion mapping, the maps' alpha the baked relief height w; see below).
//
// GS+POM. The mesh sits on the relief's outer shell (r + shell: w = 1 everywhere,
// plantgen.geometry.meshes.mesh.tessellate with relief and a height of 1), the top of the
// relief, so that what the mesh covers holds the whole relief. Each fragment walks its
// view ray down into the shell in tangent space: depth d in [0, 1] below the mesh (a
// fraction of the relief's depth there, model units, RowShell) meets the relief where
// d = 1 - w(u, v). The walk goes in layers (pom_min_layers face-on up to pom_max_layers at
// grazing angles, mixed by the view's cosine as engines do), then pom_refine_steps secant
// steps between the last layer above the relief and the first below it (1: the classic
// POM interpolation, no extra sample; 0: steep parallax mapping, the first layer below).
// The march's frame is GS+N's vertex tangent frame (T along +u, B = cross(N, T)·w along -v,
// N), interpolated, with each vertex's model units per unit of u and of v (uv_scale:
// plantgen.geometry.meshes.textures.mesh_uv_scales), which a unit frame cannot carry (a segment's
// own aspect): per unit of depth the ray moves (-V·T/|∂P/∂u|, V·B/|∂P/∂v|)/(N·V) in (u, v).
// (A per-facet frame from screen derivatives jumps at every triangle edge: the march's
// offset with it, drawing the mesh's edges into the relief.) The fragment is then shaded
// at the displaced (u, v) with the normal map (in the vertex tangent frame, as GS+N) and
// the albedo of the height there (the height read bilinearly at the base level, the
// normal map trilinear); out_distance is the distance to the displaced point (what the
// pixel shows, the bench's geometry); the depth buffer keeps the mesh's depth
// (gl_FragDepth not written: early depth tests stay on, as engines keep them), and shadows
// are looked up at the mesh's point (the light's map holds the mesh, whose plane is the
// receiver's).

#if defined VERTEX_SHADER

in vec3 position;          // relative to the mesh origin (float64 subtraction on the CPU);
                           // SKINNED and moving: relative to the pivot segment's rest start
in vec3 normal;            // interpolated normal (8)
in vec2 texcoord;          // (u, v + chain position)

uniform mat4 view_projection;   // eye-relative world -> clip
uniform vec3 origin_from_eye;   // mesh origin - eye (a placed copy's: its placed origin - eye)
// A placed copy (plantgen.gl.instanced): positions and normals turned and scaled into
// place; the identity for a merged mesh (exact in float32).
uniform mat3 copy_turn;
uniform float copy_scale;

out vec3 v_position;            // eye-relative
out vec3 v_normal;
out vec2 v_texcoord;
#if defined NORMAL_MAP
in vec4 tangent;                // unit tangent along +u, w: the bitangent's sign (glTF's TANGENT)
out vec4 v_tangent;
#endif
#if defined PARALLAX
in vec2 uv_scale;               // model units per unit of u and of v here (0: no relief, caps)
out vec2 v_uv_scale;
#endif

#if defined SKINNED
in ivec2 bind;                  // pivot segment (-1: still), the other segment of a shared vertex
// per segment: (posed start - eye, total turn), (its tree's unit axis, 0)
layout(std430, binding = 3) readonly buffer Poses { vec4 poses[]; };

vec3 turned(vec3 v, vec3 k, float c, float s) {
    return v * c + cross(k, v) * s + k * (dot(k, v) * (1.0 - c));
}
#endif

void main() {
#if defined SKINNED
    if (bind.x >= 0) {
        vec4 at = poses[2 * bind.x];
        vec3 k = poses[2 * bind.x + 1].xyz;
        float angle = 0.5 * (at.w + poses[2 * bind.y].w);
        float c = cos(angle), s = sin(angle);
        v_position = at.xyz + turned(position, k, c, s);
        v_normal = turned(normal, k, c, s);
    } else {
        v_position = copy_turn * (copy_scale * position) + origin_from_eye;
        v_normal = copy_turn * normal;
    }
#else
    v_position = copy_turn * (copy_scale * position) + origin_from_eye;
    v_normal = copy_turn * normal;
#endif
    v_texcoord = texcoord;
#if defined NORMAL_MAP
    v_tangent = tangent;        // (not turned by SKINNED: the normal-mapped path draws still meshes)
#endif
#if defined PARALLAX
    v_uv_scale = uv_scale;
#endif
    gl_Position = view_projection * vec4(v_position, 1.0);
}

#elif defined FRAGMENT_SHADER

#if defined SHADOW_PASS
// the light's depth pass: the rasteriser's depth is the depth in the light's window
void main() {}
#else
#include "shading.glsl"
#if defined SHADOWS
#include "shadow.glsl"
#endif

#include "heights.glsl"

in vec3 v_position;
in vec3 v_normal;
in vec2 v_texcoord;
#if defined NORMAL_MAP
in vec4 v_tangent;
uniform sampler2DArray normal_maps;    // RGB8 baked normal maps (PARALLAX: RGBA8, alpha the height),
                                       // layer = material (repeat, trilinear)

// The screen derivatives of (u, v + chain), taken once in main's uniform control flow (a
// march's loop is not): every map read has the mesh's level of detail, an offset (u, v)
// keeping the footprint of the fragment's own.
vec2 uv_dx, uv_dy;

// The map's texel at (u, v + chain) ``uv``.
vec4 map_texel(vec2 uv, int material) {
    return textureGrad(normal_maps, vec3(uv, float(material)), uv_dx, uv_dy);
}

// The normal map's normal at ``uv`` in the frame (T, cross(N, T)·w, N).
vec3 normal_mapped(vec3 n, int material, vec2 uv) {
    vec3 t = normalize(v_tangent.xyz);
    vec3 b = cross(n, t) * v_tangent.w;
    vec3 m = map_texel(uv, material).xyz * 2.0 - 1.0;
    return normalize(m.x * t + m.y * b + m.z * n);
}
#endif

#if defined PARALLAX
in vec2 v_uv_scale;
// per row: the relief's depth (model units) at its lower and upper ends, its v slots and
// slot (plantgen.gl.raster.row_depths; the relief follows the radius, so its depth does)
layout(std430, binding = 4) readonly buffer RowShell { vec4 row_shell[]; };
uniform int pom_min_layers;
uniform int pom_max_layers;
uniform int pom_refine_steps;

// Where the view ray meets the relief below the mesh: ``uv`` the (u, v + chain) there,
// ``height`` w there, ``along`` the distance from the mesh's point along the ray.
struct ParallaxHit {
    vec2 uv;
    float height;
    float along;
};

// The ray's (u, v) per unit of depth below the mesh (xy), and the cosine N·V (z), in the
// interpolated tangent frame around the normal ``n`` (GS+N's: T along +u, B along -v).
vec3 parallax_direction(vec3 n, vec3 to_eye) {
    vec3 t = normalize(v_tangent.xyz - n * dot(n, v_tangent.xyz));
    vec3 b = cross(n, t) * v_tangent.w;
    float cos_view = max(dot(n, to_eye), TOL_PARALLAX_GRAZING_COS);
    if (v_uv_scale.x <= 0.0 || v_uv_scale.y <= 0.0) return vec3(0.0, 0.0, cos_view);
    return vec3(vec2(-dot(to_eye, t) / v_uv_scale.x, dot(to_eye, b) / v_uv_scale.y) / cos_view, cos_view);
}

// The height w (the maps' alpha) at (u, v + chain) ``uv``: bilinear in float32 from the base
// level's four texels around it, one textureGather, as heights.glsl reads the ray caster's
// maps (a mipmapped read blurs the depth the march finds: the saguaro's 1 - SSIM 0.12
// against 0.03 at m = 2; llvmpipe also takes a read at an explicit level 3 to 20 times as
// long as a gather).
float parallax_height(vec2 uv, int material) {
    vec2 size = vec2(textureSize(normal_maps, 0).xy);
    vec2 xy = uv * size - 0.5;
    vec2 cell = floor(xy);
    return gather_mix(textureGather(normal_maps, vec3((cell + 1.0) / size, float(material)), 3), xy - cell);
}

// How far below the relief surface depth d (a fraction of the shell under the mesh) lies:
// > 0 above the relief (the ray still in the air), <= 0 at or below it.
float parallax_gap(vec2 uv, vec2 span, float d, int material) {
    return 1.0 - parallax_height(uv + d * span, material) - d;
}

ParallaxHit parallax_march(vec3 n, vec3 to_eye, float shell, int material) {
    vec3 dir = parallax_direction(n, to_eye);
    float cos_view = dir.z;
    vec2 span = dir.xy * shell;             // (u, v) the ray crosses from w = 1 down to w = 0
    int layers = int(round(mix(float(pom_max_layers), float(pom_min_layers), cos_view)));
    float layer_depth = 1.0 / float(max(layers, 1));
    float d = 0.0, gap = parallax_gap(v_texcoord, span, 0.0, material);
    float d_above = 0.0, gap_above = gap;
    // steep parallax: layer by layer until a depth lies under the relief (d = 1 always does)
    for (int i = 0; i < layers && gap > 0.0; ++i) {
        d_above = d;
        gap_above = gap;
        d = min(d + layer_depth, 1.0);
        gap = parallax_gap(v_texcoord, span, d, material);
    }
    // secant steps in the bracket [d_above, d]: the first is the classic POM interpolation
    float hit = d;
    for (int k = 0; k < pom_refine_steps && gap_above > gap; ++k) {
        hit = d_above + (d - d_above) * gap_above / (gap_above - gap);
        if (k + 1 == pom_refine_steps) break;
        float g = parallax_gap(v_texcoord, span, hit, material);
        if (g > 0.0) { d_above = hit; gap_above = g; } else { d = hit; gap = g; }
    }
    ParallaxHit out_hit;
    out_hit.uv = v_texcoord + hit * span;
    out_hit.height = parallax_height(out_hit.uv, material);
    out_hit.along = hit * shell / cos_view;
    return out_hit;
}
#endif

layout(std430, binding = 0) readonly buffer RowData { vec2 row_data[]; };  // chain position, material
layout(std430, binding = 1) readonly buffer CapRows { int cap_row[]; };   // caps' rows (FACE_ROWS: every face's)

uniform int n_rows;

layout(location = 0) out vec4 out_color;
layout(location = 1) out float out_distance;


#if defined STATS
// Work counter of a diagnostic render (plantgen.render.result.WorkCounter): fragments shaded.
layout(std430, binding = 2) buffer WorkCounts { uint counted_fragments; uint counted_samples; };
#endif

void main() {
#if defined STATS
    atomicAdd(counted_fragments, 1u);
#endif
    int primitive = gl_PrimitiveID;
#if defined FACE_ROWS
    int row = cap_row[primitive];                        // knuckles: every face's row
#else
    int row = primitive < n_rows * TRIANGLES_PER_ROW ? primitive / TRIANGLES_PER_ROW
                                                      : cap_row[primitive - n_rows * TRIANGLES_PER_ROW];
#endif
    vec2 info = row_data[row];
    int material = int(info.y + 0.5);
    vec2 uv = vec2(v_texcoord.x, v_texcoord.y - info.x);   // per-row v of (7)
#if defined NORMAL_MAP
    uv_dx = dFdx(v_texcoord);
    uv_dy = dFdy(v_texcoord);
#endif
    vec3 normal = normalize(v_normal);
    vec3 to_eye = normalize(-v_position);
    float texel;
    float along = 0.0;                                      // PARALLAX: the ray's way under the mesh
#if defined FACE_ROWS
    bool lateral = true;
#else
    bool lateral = primitive < n_rows * TRIANGLES_PER_ROW;  // caps: no relief, as the ray caster's
#endif
#if defined PARALLAX
    if (lateral) {
        vec4 depths = row_shell[row];
        float depth = mix(depths.x, depths.y, clamp(uv.y * depths.z - depths.w, 0.0, 1.0));  // at the row's own v
        ParallaxHit hit = parallax_march(normal, to_eye, depth, material);
        normal = normal_mapped(normal, material, hit.uv);
        texel = hit.height;
        along = hit.along;
    } else {
        texel = height_at(material, uv);
    }
#else
#if defined NORMAL_MAP
    if (lateral) normal = normal_mapped(normal, material, v_texcoord);
#endif
    texel = height_at(material, uv);
#endif
    vec3 albedo = material_albedo(material, texel);
    // the facet the rasteriser draws: the true normal here, which (8) is bent towards where
    // it turns away from the eye, and the receiver plane (the light's map holds facets too)
    vec3 true_normal = facet_normal(v_position, normal);
    normal = facing_normal(normal, true_normal, to_eye);
#if defined SHADOWS
    float visibility = shadow_visibility(v_position, true_normal);
#else
    float visibility = 1.0;
#endif
    vec3 color = shade_surface_visible(albedo, material, normal, to_eye, 1.0, visibility, v_position);
    out_color = vec4(to_display(color), 1.0);
    out_distance = length(v_position) + along;
}
#endif

#endif
