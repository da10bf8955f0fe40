"""The models the bench measures: grown, skinned, framed and lit as their scene asks."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._resources import closest, shipped_names
from ..animation import AnimatedScene
from ..errors import PlantgenError
from ..geometry.meshes.polygons import Polygons
from ..geometry.rays.camera import Camera
from ..geometry.skeletons.frusta import Frusta
from ..geometry.stage import Ground
from ..pipeline import animate_model, grow_file, resolve_input, stage_model
from .paper import PAPER_TABLE1, TABLE1_MODELS

__all__ = ["BenchModel", "PAPER_VARIANTS", "load_model", "check_models"]

#: The defines that make a shipped model of Table 1 the paper's: a model that gained
#: foliage or detail keeps the paper's variant behind a define (``plantgen grow pine
#: --define foliage=0``), in a scene too (the desert's and the oasis's aloes). Table 1's
#: rows are also skinned one frustum per segment, as the paper drew them, whatever
#: ``turtle: smooth_bends`` a grammar sets (the saguaro's).
PAPER_VARIANTS = {"pine": {"foliage": 0}, "aloe": {"blades": 0}}


@dataclass
class BenchModel:
    """One model as the bench renders it."""

    name: str                    # file stem: the row of the tables
    frusta: Frusta               # at t = 0
    names: tuple                 # material names
    camera: Camera               # the Table 1 (timing) camera
    light_dir: tuple             # (3,) towards the light
    ground: Ground | None
    shadows: bool                # the scene lists shadows
    animation: AnimatedScene | None   # None unless the scene moves
    relief: bool                 # any row with a relief shell
    leaves: Polygons | None = None   # a grammar's leaves, drawn the same way by RC and GS


def load_model(name: str, size) -> BenchModel:
    """Grow, skin, frame and light ``name`` (a shipped name or a path) for ``size``
    (width, height) timing frames."""
    grown = grow_file(name, variants=PAPER_VARIANTS)
    if str(name) in PAPER_TABLE1:
        grown.smooth_bends = None      # the paper's frusta: one per segment
    effects = tuple(grown.scene.effects) if grown.scene is not None else ()
    animation = animate_model(grown, effects)
    frusta = animation.frusta_at(0.0)
    if not animation.animated:
        animation = None
    if len(frusta) == 0:
        raise PlantgenError(f"{name}: nothing to bench (no segments)")
    stage = stage_model(grown, frusta, *size)
    return BenchModel(Path(str(name)).stem, frusta, tuple(frusta.material_names), stage.camera,
                      stage.light_dir, stage.ground, "shadows" in effects, animation,
                      bool(np.any(np.asarray(frusta.shell) > 0)), stage.leaves)


def check_models(models) -> None:
    """Raise PlantgenError naming every model that is neither a shipped name nor a file."""
    missing = [str(m) for m in models if not resolve_input(m).is_file()]
    missing = [m + (f" (did you mean '{near}'?)" if (near := closest(m, shipped_names())) else "") for m in missing]
    if missing:
        raise PlantgenError(f"no such model: {', '.join(missing)} (a shipped grammar/scene name "
                            f"such as {', '.join(TABLE1_MODELS[:3])}, or a path)")
