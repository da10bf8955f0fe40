"""The models the bench measures: grown, skinned, framed and lit as their scene asks."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..errors import PlantgenError
from ..geometry.camera import Camera
from ..geometry.frusta import Frusta, skin_skeleton
from ..geometry.stage import MODEL_LIGHT
from ..pipeline import grow_file, resolve_input
from ..render.animate import AnimatedScene
from ..render.raycast import auto_camera
from .paper import TABLE1_MODELS

__all__ = ["Stage", "scene_stage", "BenchModel", "load_model", "check_models"]


class Stage(NamedTuple):
    """What a render needs around the frusta: the view, the light and the ground."""

    camera: Camera
    light_dir: tuple   # (3,) direction towards the light (not normalised)
    ground: dict | None


def scene_stage(scene, frusta: Frusta, width: int, height: int, source: str = "camera") -> Stage:
    """The camera, light and ground a grown model is rendered with.

    Parameters
    ----------
    scene : the grown input's Scene, or None for a grammar or skeleton file
    frusta : the skinned model, framed when the scene gives no camera
    width, height : the image size in pixels (replaces the scene camera's)
    source : names the camera in error messages

    The camera is the scene's, else :func:`plantgen.render.raycast.auto_camera` (the model
    spans most of the viewport); the light is the opposite of the scene light's travel
    direction, else :data:`plantgen.geometry.stage.MODEL_LIGHT`'s; the ground is the
    scene's, else None.
    """
    if scene is not None and isinstance(scene.camera, dict):
        camera = Camera.from_dict({**scene.camera, "width": width, "height": height}, source)
    else:
        camera = auto_camera(frusta, width, height)
    travel = MODEL_LIGHT.travel if scene is None else scene.light["direction"]
    light_dir = tuple(-np.asarray(travel, dtype=np.float64))
    return Stage(camera, light_dir, scene.ground if scene is not None else None)


@dataclass
class BenchModel:
    """One model as the bench renders it."""

    name: str                    # file stem: the row of the tables
    frusta: Frusta               # at t = 0
    names: tuple                 # material names
    camera: Camera               # the Table 1 (timing) camera
    light_dir: tuple             # (3,) towards the light
    ground: dict | None
    shadows: bool                # the scene lists shadows
    animation: AnimatedScene | None   # None unless the scene moves
    relief: bool                 # any row with a relief shell


def _skinned(grown) -> tuple[Frusta, AnimatedScene | None]:
    """The frusta at t = 0 and the animation of a scene that lists one and moves."""
    scene = grown.scene
    if scene is None or "animation" not in scene.effects:
        return skin_skeleton(grown.skeleton), None
    animation = AnimatedScene.from_scene(scene)
    return animation.frusta_at(0.0), (animation if animation.animated else None)


def load_model(name: str, size) -> BenchModel:
    """Grow, skin, frame and light ``name`` (a shipped name or a path) for ``size``
    (width, height) timing frames."""
    grown = grow_file(name)
    scene = grown.scene
    frusta, animation = _skinned(grown)
    if len(frusta) == 0:
        raise PlantgenError(f"{name}: nothing to bench (no segments)")
    stage = scene_stage(scene, frusta, *size, source=f"{name}: camera")
    effects = tuple(scene.effects) if scene is not None else ()
    return BenchModel(Path(str(name)).stem, frusta, tuple(frusta.material_names), stage.camera,
                      stage.light_dir, stage.ground, "shadows" in effects, animation,
                      bool(np.any(np.asarray(frusta.shell) > 0)))


def check_models(models) -> None:
    """Raise PlantgenError naming every model that is neither a shipped name nor a file."""
    missing = [str(m) for m in models if not resolve_input(m).is_file()]
    if missing:
        raise PlantgenError(f"no such model: {', '.join(missing)} (a shipped grammar/scene name "
                            f"such as {', '.join(TABLE1_MODELS[:3])}, or a path)")
