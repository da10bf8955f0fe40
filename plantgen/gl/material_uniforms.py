"""What every program shades with: the light, ambient and sky constants, the material
palette as uniforms, and the relief height maps as one texture array per material list.

The palette and the height maps themselves are data of :mod:`plantgen.geometry.materials`
(shared with the mesh exporter); this module turns them into GL uniforms and textures.
"""

from __future__ import annotations

import numpy as np

from ..geometry.materials import material_height_maps, material_palette

__all__ = ["LIGHT_COLOR", "AMBIENT_COLOR", "SKY", "shading_uniforms", "palette_uniforms",
           "HeightTextures"]

LIGHT_COLOR = (1.0, 0.96, 0.9)
AMBIENT_COLOR = (0.35, 0.4, 0.5)
SKY = {"sky_zenith": (0.18, 0.36, 0.75), "sky_horizon": (0.72, 0.8, 0.9),
       "ground_tint": (0.35, 0.33, 0.3)}


def shading_uniforms(light_dir) -> dict:
    """Uniform values of shaders/shading.glsl other than the palette: the light
    (``light_dir`` (3,) towards the light, normalised here), its colour, the ambient term and
    the sky. Every renderer sets these so RC, GS and the sky agree."""
    light = np.asarray(light_dir, dtype=np.float64)
    light = light / np.linalg.norm(light)
    return {"light_dir": tuple(light), "light_color": LIGHT_COLOR,
            "ambient_color": AMBIENT_COLOR, **SKY}


def palette_uniforms(material_names) -> dict[str, np.ndarray]:
    """The ``material_dark``, ``material_light`` and ``material_gloss`` uniform arrays of
    shaders/shading.glsl for the material slots ``material_names``."""
    palette = material_palette(material_names)
    return {f"material_{key}": palette[key] for key in ("dark", "light", "gloss")}


class HeightTextures:
    """The relief height maps of each material list, uploaded once as an R8 texture array
    (one layer per material slot; shaders/heights.glsl gathers 2x2 texels and filters
    them in float32)."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._textures: dict[tuple, tuple] = {}

    def get(self, material_names):
        """(texture array, (MAX_MATERIALS, 2) float32 texture repeats) of the material list."""
        key = tuple(material_names)
        if key not in self._textures:
            maps, repeats = material_height_maps(material_names)
            layers, h, w = maps.shape
            tex = self.ctx.texture_array((w, h, layers), 1, maps.tobytes(), dtype="f1")
            tex.filter = (self.ctx.NEAREST, self.ctx.NEAREST)   # gathered: filtered in GLSL
            tex.repeat_x, tex.repeat_y = True, False               # u repeats, v clamps
            self._textures[key] = (tex, repeats)
        return self._textures[key]

    def release(self) -> None:
        for tex, _ in self._textures.values():
            tex.release()
        self._textures = {}
