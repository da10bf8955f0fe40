"""Ray queries: the BVH, the float64 reference caster, the scanner, the camera, instanced
plants, the hard-case suite."""
