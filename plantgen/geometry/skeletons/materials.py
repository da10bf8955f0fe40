"""Materials by name: the colours every renderer and exporter gives them, and how many
material slots a model may use. Pure data and numpy (no GL), so the renderers
(``plantgen.render``) and the mesh exporter (``plantgen.export``) share one palette.

The relief height maps of each material are in :mod:`plantgen.geometry.skeletons.relief`.
"""

from __future__ import annotations

import numpy as np

from . import relief

__all__ = ["MAX_MATERIALS", "PALETTE", "DEFAULT_SHADE", "leaf_colours", "leaf_tones", "material_palette",
           "material_colour", "material_height_maps"]

#: Material slots of one draw (the GLSL arrays' size, passed to every shader as a define).
MAX_MATERIALS = 16

#: name fragment -> (dark albedo, light albedo, (specular, exponent)), linear RGB
PALETTE = {
    "bark": ((0.10, 0.065, 0.04), (0.36, 0.25, 0.16), (0.04, 12.0)),
    "saguaro": ((0.06, 0.16, 0.05), (0.22, 0.42, 0.16), (0.18, 30.0)),
    "cactus": ((0.06, 0.16, 0.05), (0.22, 0.42, 0.16), (0.18, 30.0)),
    "aloe": ((0.10, 0.25, 0.12), (0.30, 0.52, 0.30), (0.25, 40.0)),
    "leaf": ((0.05, 0.20, 0.03), (0.18, 0.45, 0.08), (0.15, 24.0)),
    "stem": ((0.08, 0.10, 0.03), (0.26, 0.30, 0.11), (0.06, 14.0)),     # a green, half-woody stem
    "needle": ((0.03, 0.13, 0.04), (0.10, 0.30, 0.10), (0.10, 20.0)),
    "frond": ((0.06, 0.22, 0.04), (0.22, 0.48, 0.10), (0.15, 24.0)),
    "stone": ((0.22, 0.20, 0.18), (0.55, 0.52, 0.47), (0.05, 10.0)),
    "wood": ((0.18, 0.10, 0.05), (0.45, 0.30, 0.16), (0.06, 14.0)),
    "sand": ((0.45, 0.36, 0.22), (0.70, 0.58, 0.38), (0.02, 8.0)),
    "grass": ((0.10, 0.22, 0.05), (0.25, 0.40, 0.10), (0.02, 8.0)),
    "soil": ((0.20, 0.14, 0.09), (0.38, 0.28, 0.18), (0.02, 8.0)),
}
#: The shade of a material whose name matches no entry of :data:`PALETTE`.
DEFAULT_SHADE = ((0.25, 0.25, 0.25), (0.6, 0.6, 0.6), (0.1, 16.0))


def material_palette(material_names) -> dict[str, np.ndarray]:
    """Shading constants per material slot, looked up by name (substring, case-insensitive).

    Returns arrays ``dark``, ``light`` of shape (MAX_MATERIALS, 3) float32 (linear RGB albedo
    where the texture is low / high) and ``gloss`` (MAX_MATERIALS, 2) (specular, exponent).
    """
    dark = np.tile(np.float32(DEFAULT_SHADE[0]), (MAX_MATERIALS, 1))
    light = np.tile(np.float32(DEFAULT_SHADE[1]), (MAX_MATERIALS, 1))
    gloss = np.tile(np.float32(DEFAULT_SHADE[2]), (MAX_MATERIALS, 1))
    for i, name in enumerate(list(material_names)[:MAX_MATERIALS]):
        for key, (lo, hi, gl) in PALETTE.items():
            if key in name.lower():
                dark[i], light[i], gloss[i] = lo, hi, gl
                break
    return {"dark": dark, "light": light, "gloss": gloss}


def material_colour(name: str) -> tuple[float, float, float]:
    """Linear RGB in [0, 1] of a material for files that hold one colour per material: the
    mean of its dark and light albedo, so an exported mesh has the renderers' colour."""
    palette = material_palette([name])
    return tuple(float(x) for x in (palette["dark"][0] + palette["light"][0]) / 2)


def material_height_maps(material_names) -> tuple[np.ndarray, np.ndarray]:
    """Relief height maps of a draw's material slots.

    Returns
    -------
    maps : (n_layers, H, W) uint8, one layer per material slot (``bark`` if none)
    repeats : (MAX_MATERIALS, 2) float32 texture repeats (u around, v per segment)
    """
    names = list(material_names) or ["bark"]
    repeats = np.ones((MAX_MATERIALS, 2), dtype=np.float32)
    maps, rep = relief.height_maps(names)
    repeats[:len(rep)] = np.asarray(rep, dtype=np.float32)[:MAX_MATERIALS]
    return np.ascontiguousarray(maps, dtype=np.uint8), repeats


def leaf_tones(count: int) -> np.ndarray:
    """(count,) tones in [0.25, 0.85]: where each leaf's albedo lies between its material's
    dark and light colour, a fixed function of the polygon's index (deterministic), so
    neighbouring leaves read apart."""
    k = np.arange(count, dtype=np.uint64)
    h = (k * np.uint64(2654435761) + np.uint64(40503)) % np.uint64(1 << 16)
    return 0.25 + 0.6 * h.astype(np.float64) / float(1 << 16)


def leaf_colours(names, material: np.ndarray, tones: np.ndarray) -> np.ndarray:
    """(k, 3) float64 linear RGB of leaves of ``material`` (k,) (indices into ``names``) at
    ``tones`` (k,) (:func:`leaf_tones`): mix(dark, light, tone), the leaf renderer's albedo."""
    palette = material_palette(names)
    slot = np.clip(np.asarray(material), 0, MAX_MATERIALS - 1)
    dark, light = palette["dark"][slot].astype(np.float64), palette["light"][slot].astype(np.float64)
    return dark + (light - dark) * np.asarray(tones, dtype=np.float64)[:, None]
