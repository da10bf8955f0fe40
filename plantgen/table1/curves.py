"""The accuracy curves' families: which points share a reference, and their Pareto fronts."""

from __future__ import annotations

import numpy as np

from .configs import METHODS
from .quality import pareto_front

__all__ = ["FAMILIES", "family_points", "family_front"]

#: The two families of the accuracy curves: each is measured against its own reference
#: (analytic cones, or the relief surface), so each has its own Pareto front
#: (:attr:`~plantgen.table1.configs.Method.family`).
FAMILIES = {family: tuple(m.name for m in METHODS if m.family == family) for family in ("plain", "relief")}


def family_points(model: dict, family: str) -> list[dict]:
    """The measured curve points of one family (:data:`FAMILIES`) of a model's results."""
    return [c for c in model["curve"] if "error" in c and c["method"] in FAMILIES[family]]


def family_front(points: list[dict]) -> np.ndarray:
    """(k,) indices into ``points`` of their Pareto front in (ms, error), fastest first."""
    return pareto_front([c["ms"] for c in points], [c["error"] for c in points])
