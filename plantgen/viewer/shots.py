"""Saving from the viewer: P the frame as drawn, Shift+P the window as shown, C the
camera as JSON with the ``plantgen render`` command that draws the same frame (functions
over a :class:`~plantgen.viewer.state.ViewerState`)."""

from __future__ import annotations

import shlex
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import PlantgenError
from ..files import write_atomically
from ..images import write_png
from ..knobs import knob_args
from ..settings import ViewSettings
from .frame import current
from .options import one_line
from .state import ViewerState

__all__ = ["screenshot", "window_shot", "save_camera", "render_command"]


def screenshot(state: ViewerState) -> Path | None:
    """Write the current frame as drawn (no heads-up line) as a PNG."""
    current(state)
    try:
        path = write_png(_next_name(state, ".png"), state.last.color)
    except PlantgenError as exc:
        return _failed(state, exc)
    state.say(f"saved screenshot {path} ({state.last.camera.width}x{state.last.camera.height})")
    state.status = f"saved {path.name}"
    return path


def window_shot(state: ViewerState, pixels: np.ndarray | None = None) -> Path | None:
    """Write ``pixels`` (the window as shown; the window passes them) as a PNG."""
    if pixels is None:
        state.want_window_shot = True
        return None
    state.want_window_shot = False
    try:
        path = write_png(_next_name(state, ".png"), pixels)
    except PlantgenError as exc:
        return _failed(state, exc)
    state.say(f"saved window {path}")
    state.status = f"saved {path.name}"
    return path


def save_camera(state: ViewerState) -> Path | None:
    """Write the camera of the last frame as JSON and print the ``plantgen render``
    command that draws the same frame."""
    camera = current(state).camera
    try:
        path = write_atomically(_next_name(state, ".json"), camera.save)
    except PlantgenError as exc:
        return _failed(state, exc)
    state.say(f"saved camera {path}; the same frame: {render_command(state, path)}")
    state.status = f"saved {path.name}"
    return path


def render_command(state: ViewerState, camera_path: Path) -> str:
    """The ``plantgen render`` command line that draws the current frame from
    ``camera_path`` (pixel for pixel for RC and RC+R): the options of the settings
    that differ from their defaults (:func:`plantgen.knobs.knob_args`)."""
    o = state.options
    out = Path(camera_path).with_suffix(".render.png")
    request = replace(state.request(), view=ViewSettings(camera=str(camera_path)),
                      image=replace(state.request().image, size=None))
    args = ["plantgen", "render", str(o.input), "-o", str(out), *knob_args(request)]
    iterations = o.iterations if state.step_target is None else state.step
    for flag, value in (("--seed", o.seed), ("--iterations", iterations), ("--smooth-bends", o.smooth_bends)):
        if value is not None:
            args += [flag, str(value)]
    text = shlex.join(args)
    if state.method.startswith("GS"):
        text += f"   (ray cast; the viewer drew {state.method} m = {state.level} with the raster renderer)"
    return text


def _next_name(state: ViewerState, suffix: str) -> Path:
    folder = Path(state.options.shots)
    stem = state.model.grown.name or Path(state.model.source).stem
    for i in range(1, 100000):
        path = folder / f"{stem}-{i:03d}{suffix}"
        if not path.exists() and not path.with_suffix(".png").exists() and not path.with_suffix(".json").exists():
            return path
    raise PlantgenError(f"{folder}: no free name for {stem}-NNN{suffix}")


def _failed(state: ViewerState, exc) -> None:
    state.error = one_line(exc)
    state.warn(f"plantgen view: error: {state.error}")
