"""What every program shades with: the light, ambient and sky constants, the material
palette as uniforms, and the relief height maps as one texture array per material list.

The palette and the height maps themselves are data of :mod:`plantgen.geometry.skeletons.materials`
(shared with the mesh exporter); this module turns them into GL uniforms and textures.
"""

from __future__ import annotations

import numpy as np

from ..geometry.skeletons.materials import MAX_MATERIALS, material_height_maps, material_palette

__all__ = ["LIGHT_COLOR", "AMBIENT_COLOR", "SKY", "shading_uniforms", "palette_uniforms", "ground_light",
           "ground_uniforms",
           "HeightTextures", "corner_maps"]

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


def ground_light(light_dir, material: str | None) -> tuple[float, float, float]:
    """The ``bounce`` look's ``ground_light`` (shaders/shading.glsl): what an open, flat
    ground of ``material`` sends up, its albedo (the mottle's mean, halfway between the
    material's dark and light colours) times the light it gets, the sun at its elevation
    (``light_dir`` (3,) towards the light, y up) and the whole sky's ambient; a surface of
    normal n gets (1 - n_y) / 2 of it. None (no ground): black."""
    if material is None:
        return (0.0, 0.0, 0.0)
    light = np.asarray(light_dir, dtype=np.float64)
    light = light / np.linalg.norm(light)
    palette = material_palette([material])
    albedo = 0.5 * (palette["dark"][0].astype(np.float64) + palette["light"][0].astype(np.float64))
    falling = np.asarray(LIGHT_COLOR) * max(float(light[1]), 0.0) + np.asarray(AMBIENT_COLOR)
    return tuple(float(v) for v in albedo * falling)


def ground_uniforms(ground, light_dir, eye) -> dict:
    """The ``bounce`` look's uniforms of shaders/shading.glsl for ``ground`` (a
    :class:`~plantgen.geometry.stage.Ground`, None: none, no light from below) lit from
    ``light_dir``, seen from ``eye`` (3,) world, the render origin: ``ground_light``
    (:func:`ground_light`), the eye's height above the ground and the ground's reach, its
    half size to the middle of its fade (``ground_share`` takes it for a disc's radius)."""
    if ground is None:
        return {"ground_light": (0.0, 0.0, 0.0), "ground_eye_height": 0.0, "ground_reach": 1.0}
    return {"ground_light": ground_light(light_dir, ground.material),
            "ground_eye_height": float(eye[1]) - float(ground.height),
            "ground_reach": ground.half * (1.0 - 0.5 * float(np.clip(ground.fade, 0.0, 1.0)))}


def palette_uniforms(material_names) -> dict[str, np.ndarray]:
    """The ``material_dark``, ``material_light`` and ``material_gloss`` uniform arrays of
    shaders/shading.glsl for the material slots ``material_names``."""
    palette = material_palette(material_names)
    return {f"material_{key}": palette[key] for key in ("dark", "light", "gloss")}


def corner_maps(maps: np.ndarray) -> np.ndarray:
    """(n, H + 1, W, 4) uint8: the four texels of every bilinear cell of the (n, H, W)
    height maps, in textureGather's order, so one texel fetch gives what one gather gives
    (shaders/light_march.glsl). Texel (i, j) holds the cell whose lower-left texel is
    (i, j - 1): (i, j), (i + 1, j), (i + 1, j - 1), (i, j - 1), with i + 1 wrapping (u
    repeats) and rows clamped to 0..H - 1 (v clamps)."""
    n, h, w = maps.shape
    rows = np.arange(h + 1)
    lower, upper = np.clip(rows - 1, 0, h - 1), np.clip(rows, 0, h - 1)
    left, right = np.arange(w), (np.arange(w) + 1) % w
    out = np.empty((n, h + 1, w, 4), np.uint8)
    for k, (r, c) in enumerate(((upper, left), (upper, right), (lower, right), (lower, left))):
        out[..., k] = maps[:, r][:, :, c]
    return out


class HeightTextures:
    """The relief height maps of each material list, uploaded once as an R8 texture array
    (one layer per material slot; shaders/heights.glsl gathers 2x2 texels and filters
    them in float32)."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._textures: dict[tuple, tuple] = {}
        self._corners: dict[tuple, object] = {}

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

    def corners(self, material_names):
        """The RGBA8 texture array of :func:`corner_maps` of the material list (the light's
        relief march fetches a bilinear cell's four heights in one texel fetch)."""
        key = tuple(material_names)
        if key not in self._corners:
            maps, _ = material_height_maps(material_names)
            cells = corner_maps(maps)
            layers, rows, cols, _ = cells.shape
            tex = self.ctx.texture_array((cols, rows, layers), 4, cells.tobytes(), dtype="f1")
            tex.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
            self._corners[key] = tex
        return self._corners[key]

    def ranges(self, material_names) -> np.ndarray:
        """(MAX_MATERIALS, 2) float32: the lowest and highest height of each material's
        map, in [0, 1]: the band of the shell its relief occupies (a slot past the list
        has the last map's, as the texture array clamps its layer)."""
        maps, _ = material_height_maps(material_names)
        layer = np.minimum(np.arange(MAX_MATERIALS), len(maps) - 1)
        low, high = maps.min(axis=(1, 2)) / 255.0, maps.max(axis=(1, 2)) / 255.0
        return np.stack([low[layer], high[layer]], axis=1).astype(np.float32)

    def release(self) -> None:
        for tex, _ in self._textures.values():
            tex.release()
        for tex in self._corners.values():
            tex.release()
        self._textures, self._corners = {}, {}
