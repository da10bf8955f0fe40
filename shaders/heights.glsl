// Relief height maps shared by every program that samples them (ray caster, raster).
// Needs MAX_MATERIALS. Bilinear height in [0, 1] as plantgen.geometry.skeletons.relief.sample_height
// computes it: u repeats, v clamps, texel centres at (i + 0.5) / size.
//
// One texture instruction per sample: textureGather returns the 2x2 texels around the
// sample (the texture's wrap modes repeat u and clamp v, plantgen.render.materials), and
// the weights are computed here in float32, so the result is the exact bilinear
// interpolation of the reference, not the texture unit's (8-bit weights on most GPUs).
// The gather is taken at the shared corner of the four texels, so the texels the unit
// picks and the cell the weights belong to can never disagree.
uniform sampler2DArray height_maps;          // R8 height maps, layer = material, row j = v texel j
uniform vec2 texture_repeat[MAX_MATERIALS];  // (u repeats around, v repeats per segment)

// One material's map: its layer, its size in texels and its repeats.
struct HeightMap {
    float layer;
    vec2 size;       // (width, height) in texels
    vec2 repeat;     // (u repeats around, v repeats per segment)
};

HeightMap height_map(int material) {
    ivec3 size = textureSize(height_maps, 0);
    vec2 rep = texture_repeat[clamp(material, 0, MAX_MATERIALS - 1)];
    HeightMap m;
    m.layer = float(clamp(material, 0, size.z - 1));
    m.size = vec2(size.xy);
    m.repeat = rep;
    return m;
}

// The bilinear mix, by the weights w, of a gather's four texels (textureGather's order:
// (i, j+1), (i+1, j+1), (i+1, j), (i, j)); the raster's PARALLAX reads its maps' height so too.
float gather_mix(vec4 g, vec2 w) {
    return mix(mix(g.w, g.z, w.x), mix(g.x, g.y, w.x), w.y);
}

// Bilinear height at texture coordinates (u, v) of map m.
float height_in(HeightMap m, vec2 uv) {
    vec2 xy = vec2(fract(uv.x * m.repeat.x), clamp(uv.y * m.repeat.y, 0.0, 1.0)) * m.size - 0.5;
    vec2 cell = floor(xy);
    vec2 w = xy - cell;
#if defined HEIGHT_FETCH4
    // the same four texels by four fetches with the wrap done here (the ablation's "off")
    ivec2 size = ivec2(m.size), c = ivec2(cell);
    int i0 = ((c.x % size.x) + size.x) % size.x, i1 = (i0 + 1) % size.x;
    int j0 = clamp(c.y, 0, size.y - 1), j1 = clamp(c.y + 1, 0, size.y - 1);
    int layer = int(m.layer);
    vec4 g = vec4(texelFetch(height_maps, ivec3(i0, j1, layer), 0).r,
                  texelFetch(height_maps, ivec3(i1, j1, layer), 0).r,
                  texelFetch(height_maps, ivec3(i1, j0, layer), 0).r,
                  texelFetch(height_maps, ivec3(i0, j0, layer), 0).r);
#else
    vec4 g = textureGather(height_maps, vec3((cell + 1.0) / m.size, m.layer));
#endif
    return gather_mix(g, w);
}

float height_at(int material, vec2 uv) {
    return height_in(height_map(material), uv);
}
