// Raster renderer for tessellated frusta (GS, GS+R): the polygonal baseline of Table 1.
//
// One indexed draw of the whole mesh, back faces culled. The shading is the ray caster's:
// the same shading.glsl (material albedo from the height map texel, one light,
// Blinn-Phong), the same height maps and texture repeats, the same normals (8) (per vertex,
// interpolated), the same colour and distance outputs. Only the geometry differs.
//
// GS+R meshes come displaced onto the relief shell, with vertex normals tilted by the
// height map's gradient as RC+R tilts its normals (plantgen.geometry.mesh.tessellate).
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
// pose buffer that shaders/pose.glsl writes; plantgen.geometry.skinned_mesh); NORMAL_MAP (GS+N:
// the relief as a baked tangent-space normal map, plantgen.geometry.textures, read as glTF
// readers read one: T the vertex tangent, B = cross(N, T)·w, n = T·x + B·y + N·z; caps,
// which the ray caster leaves unrelieved, keep their normal).

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

in vec3 v_position;
in vec3 v_normal;
in vec2 v_texcoord;
#if defined NORMAL_MAP
in vec4 v_tangent;
uniform sampler2DArray normal_maps;    // RGB8 baked normal maps, layer = material (repeat, trilinear)

// The normal map's normal at the mesh's (u, v + chain) in the frame (T, cross(N, T)·w, N).
vec3 normal_mapped(vec3 n, int material) {
    vec3 t = normalize(v_tangent.xyz);
    vec3 b = cross(n, t) * v_tangent.w;
    vec3 m = texture(normal_maps, vec3(v_texcoord, float(material))).xyz * 2.0 - 1.0;
    return normalize(m.x * t + m.y * b + m.z * n);
}
#endif

layout(std430, binding = 0) readonly buffer RowData { vec2 row_data[]; };  // chain position, material
layout(std430, binding = 1) readonly buffer CapRows { int cap_row[]; };   // caps' rows (FACE_ROWS: every face's)

uniform int n_rows;
#include "heights.glsl"

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
    vec3 normal = normalize(v_normal);
#if defined NORMAL_MAP
#if defined FACE_ROWS
    normal = normal_mapped(normal, material);
#else
    if (primitive < n_rows * TRIANGLES_PER_ROW) normal = normal_mapped(normal, material);
#endif
#endif
    float texel = height_at(material, uv);
    vec3 to_eye = normalize(-v_position);
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
    vec3 color = shade_surface_visible(albedo, material, normal, to_eye, 1.0, visibility);
    out_color = vec4(to_display(color), 1.0);
    out_distance = length(v_position);
}
#endif

#endif
