"""PLACEHOLDER until the geometry branch merges (it owns this file)."""
from __future__ import annotations


class Tolerances:
    def glsl_defines(self) -> dict[str, float]:
        return {}


tol = Tolerances()
