// Relief height maps shared by every program that samples them (ray caster, raster).
// Needs MAX_MATERIALS. Bilinear height in [0, 1] as plantgen.geometry.relief.sample_height
// computes it: u repeats, v clamps, texel centres at (i + 0.5) / size.
uniform sampler2DArray height_maps;          // R8 height maps, layer = material, row j = v texel j
uniform vec2 texture_repeat[MAX_MATERIALS];  // (u repeats around, v repeats per segment)

float texel_height(ivec2 size, int layer, int i, int j) {
    i = ((i % size.x) + size.x) % size.x;
    j = clamp(j, 0, size.y - 1);
    return texelFetch(height_maps, ivec3(i, j, layer), 0).r;
}

float height_at(int material, vec2 uv) {
    ivec2 size = textureSize(height_maps, 0).xy;
    int layer = clamp(material, 0, textureSize(height_maps, 0).z - 1);
    vec2 rep = texture_repeat[clamp(material, 0, MAX_MATERIALS - 1)];
    vec2 xy = vec2(fract(uv.x * rep.x), clamp(uv.y * rep.y, 0.0, 1.0)) * vec2(size) - 0.5;
    vec2 cell = floor(xy);
    vec2 w = xy - cell;
    int i = int(cell.x), j = int(cell.y);
    float h00 = texel_height(size, layer, i, j), h10 = texel_height(size, layer, i + 1, j);
    float h01 = texel_height(size, layer, i, j + 1), h11 = texel_height(size, layer, i + 1, j + 1);
    return mix(mix(h00, h10, w.x), mix(h01, h11, w.x), w.y);
}
