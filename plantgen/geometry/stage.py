"""What a scene puts around its plants, as typed values: the ground, the light, the sway.

These sit in ``geometry`` (no GL, no files) so that the scene parser (``plantgen.scene``),
the animation (``plantgen.animation``) and the renderers (``plantgen.render``) share one
definition without the renderers knowing anything of scene files.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Ground", "Light", "Sway", "MODEL_LIGHT", "SCENE_LIGHT"]


@dataclass(frozen=True)
class Ground:
    """A square of side ``size`` (world units) at y = ``height``, centred under the origin,
    facing up, shaded with the material named ``material``."""

    size: float = 10.0
    height: float = 0.0
    material: str = "sand"

    def quad(self) -> np.ndarray:
        """(4, 3) float64 corners in triangle-strip order, facing up."""
        half = float(self.size) / 2
        y = float(self.height)
        return np.array([[-half, y, half], [half, y, half], [-half, y, -half], [half, y, -half]])


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
