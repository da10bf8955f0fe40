"""Meshes and leaves: tessellated and skinned meshes, leaf polygons and cards, impostors,
baked textures, parametric surfaces."""
