"""What a scene puts around its plants, as typed values: the ground, the light, the sway.

These sit in ``geometry`` (no GL, no files) so that the scene parser (``plantgen.scene``),
the animation (``plantgen.animation``) and the renderers (``plantgen.render``) share one
definition without the renderers knowing anything of scene files.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["GROUND_SHAPES", "GROUND_FADE", "Ground", "model_ground", "Light", "Sway", "MODEL_LIGHT", "SCENE_LIGHT"]


#: Ground shapes: ``square`` (a scene's, of side ``size``), ``disc`` (of diameter ``size``:
#: a single plant's, :func:`model_ground`).
GROUND_SHAPES = ("square", "disc")
#: The fraction of a ground's half size (the square's half side, the disc's radius) over
#: which it fades into the sky behind it, ending at its edge: no edge shows.
GROUND_FADE = 0.3
#: A single plant's ground disc: its radius in units of the plant's largest size (the
#: plant's shadow under the model light is shorter than its height), and never less than
#: :data:`MODEL_GROUND_MIN_RADIUS` world units.
MODEL_GROUND_REACH = 2.5
MODEL_GROUND_MIN_RADIUS = 1.0


@dataclass(frozen=True)
class Ground:
    """A ground at y = ``height``, facing up, shaded with the material named ``material``:
    a square of side ``size`` (world units) or a disc of diameter ``size`` (``shape``),
    centred at ``centre`` (x, z). Its outer ``fade`` (a fraction of its half size) fades
    into the sky behind it, so its edge does not show against the sky."""

    size: float = 10.0
    height: float = 0.0
    material: str = "sand"
    shape: str = "square"
    centre: tuple = (0.0, 0.0)
    fade: float = GROUND_FADE

    def __post_init__(self):
        if self.shape not in GROUND_SHAPES:
            raise ValueError(f"ground shape must be one of {GROUND_SHAPES}, got {self.shape!r}")
        object.__setattr__(self, "centre", (float(self.centre[0]), float(self.centre[1])))

    @property
    def half(self) -> float:
        """The half size: the square's half side, the disc's radius."""
        return float(self.size) / 2

    def quad(self) -> np.ndarray:
        """(4, 3) float64 corners in triangle-strip order, facing up: the square, or the
        square around the disc (the shader cuts the disc out of it)."""
        half = self.half
        y = float(self.height)
        cx, cz = self.centre
        return np.array([[cx - half, y, cz + half], [cx + half, y, cz + half],
                         [cx - half, y, cz - half], [cx + half, y, cz - half]])

    def mottle(self, x, z) -> np.ndarray:
        """The ground's soft procedural mottle at world (``x``, ``z``), in [0.25, 0.75]: where
        its albedo lies between the material's dark and light colour (the numpy twin of
        ``shaders/ground.glsl``'s)."""
        x, z = np.asarray(x, dtype=np.float64), np.asarray(z, dtype=np.float64)
        return 0.5 + 0.25 * np.sin(x * 1.7 + np.sin(z * 0.9)) * np.sin(z * 1.3 + np.sin(x * 0.7))

    def opacity(self, x, z) -> np.ndarray:
        """1 inside the ground, falling smoothly to 0 at its edge over its outer ``fade``, 0
        beyond (the numpy twin of ``shaders/ground.glsl``'s ``1 - ground_edge_fade``): how
        much of the ground covers the sky behind it at world (``x``, ``z``)."""
        dx = np.abs(np.asarray(x, dtype=np.float64) - self.centre[0])
        dz = np.abs(np.asarray(z, dtype=np.float64) - self.centre[1])
        r = np.hypot(dx, dz) if self.shape == "disc" else np.maximum(dx, dz)
        inner = self.half * (1.0 - float(np.clip(self.fade, 1e-6, 1.0)))
        t = np.clip((r - inner) / max(self.half - inner, 1e-12), 0.0, 1.0)
        return np.where(r > self.half, 0.0, 1.0 - t * t * (3.0 - 2.0 * t))

    def uniforms(self) -> dict:
        """The ground shader's uniforms of its shape and fade (``shaders/ground.glsl``)."""
        return {"ground_centre": self.centre, "ground_half": self.half,
                "ground_fade": float(np.clip(self.fade, 1e-6, 1.0)), "ground_disc": self.shape == "disc"}


def model_ground(box, material: str = "sand") -> Ground:
    """A single plant's ground: a disc under the plant's world box ``box`` (2, 3), at its
    lowest point, centred under it, of radius :data:`MODEL_GROUND_REACH` times the box's
    largest side (the plant's shadow falls on it), fading into the sky at its rim."""
    box = np.asarray(box, dtype=np.float64)
    extent = float(np.max(box[1] - box[0]))
    radius = max(MODEL_GROUND_REACH * extent, MODEL_GROUND_MIN_RADIUS)
    centre = 0.5 * (box[0] + box[1])
    return Ground(size=2 * radius, height=float(box[0, 1]), shape="disc", centre=(centre[0], centre[2]))


@dataclass(frozen=True)
class Light:
    """A directional light. ``travel`` (3,) is the direction the light travels (scene
    files give this); :meth:`towards` is the unit direction from a surface to the light."""

    travel: tuple[float, float, float]
    intensity: float = 1.0

    def towards(self) -> np.ndarray:
        """(3,) float64 direction from a surface towards the light: ``-travel``, exactly
        (not normalised again; the renderers normalise it once)."""
        return -np.asarray(self.travel, dtype=np.float64)


#: The light of a render without a scene (a grammar or a skeleton file).
MODEL_LIGHT = Light((-0.45, -0.8, -0.35))
#: The light of a scene that names none.
SCENE_LIGHT = Light((-0.4, -1.0, -0.3))


@dataclass(frozen=True)
class Sway:
    """Sway of one plant instance (see :mod:`plantgen.geometry.skeletons.motion`): the bend at the
    tip in ``amplitude`` degrees, ``frequency`` in Hz, ``phase`` in radians."""

    amplitude: float = 0.0
    frequency: float = 0.0
    phase: float = 0.0

    @property
    def moves(self) -> bool:
        return bool(self.amplitude)
