"""The viewer's controls: the key handlers (the bindings of ``keys.py`` name them, :data:`ACTIONS`
maps the names to the functions) and the mouse's drag and wheel, as functions over a
:class:`~plantgen.viewer.state.ViewerState`: the camera, the method and its knobs, the time
of an animated scene, the help, quitting. The growth's keys are in ``growth.py``, the
saving keys in ``shots.py``."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..geometry.rays.camera import MAX_ELEVATION, Orbit, orbit_angles, orbit_view
from ..knobs import knob_of
from ..pipeline import stage_model
from ..settings import MAX_SSAA, MAX_SUBDIV, RaycastSettings
from .growth import grow_step, toggle_growth
from .keys import binding_for
from .options import DRAG_TURN, VIEW_MAX_TRIANGLES, stored_triangles
from .shots import save_camera, screenshot, window_shot
from .state import ViewerState

__all__ = ["ACTIONS", "key", "orbit", "drag", "pan_by", "pan_view", "zoom", "scroll", "reset_view", "set_method",
           "change_level", "scale_linear_steps", "change_binary_steps", "toggle_march", "toggle_shadows",
           "cycle_ssaa", "toggle_play", "scrub", "toggle_help", "quit"]


def key(state: ViewerState, name: str, shift: bool = False) -> bool:
    """Handle key ``name`` (a pyglet key name) by the handler its binding names (:data:`ACTIONS`);
    returns False for a key with no binding."""
    binding = binding_for(name, shift)
    if binding is None:
        return False
    ACTIONS[binding.action](state, *binding.args)
    return True


def orbit(state: ViewerState, d_azimuth: float, d_elevation: float) -> None:
    """Turn the view around its target by degrees."""
    az, el, _ = orbit_angles(state.camera)
    el = float(np.clip(el + d_elevation, -MAX_ELEVATION, MAX_ELEVATION))
    state.camera = orbit_view(state.camera, Orbit(azimuth=(az + d_azimuth + 180.0) % 360.0 - 180.0, elevation=el))
    state.dirty = True


def drag(state: ViewerState, dx: float, dy: float, pan: bool = False) -> None:
    """A mouse drag of (dx, dy) window pixels (y down): turn, or with ``pan`` move."""
    if pan:
        pan_by(state, dx, dy)
    else:
        orbit(state, -DRAG_TURN * dx, DRAG_TURN * dy)


def pan_by(state: ViewerState, dx: float, dy: float) -> None:
    """Move eye and target across the view by (dx, dy) pixels (the target follows the
    cursor)."""
    right, up, _ = state.camera.basis()
    dist = float(np.linalg.norm(np.subtract(state.camera.eye, state.camera.target)))
    per_pixel = 2.0 * dist * math.tan(math.radians(state.camera.fov_y) / 2) / state.camera.height
    shift = (-dx * right + dy * up) * per_pixel
    state.camera = replace(state.camera, eye=tuple((np.asarray(state.camera.eye) + shift).tolist()),
                           target=tuple((np.asarray(state.camera.target) + shift).tolist()))
    state.dirty = True


def pan_view(state: ViewerState, fx: float, fy: float) -> None:
    """Move the view right and up by fractions of its height (keys; a drag moves the
    model with the cursor instead)."""
    pan_by(state, -fx * state.camera.height, fy * state.camera.height)


def zoom(state: ViewerState, factor: float) -> None:
    """Move the eye ``factor`` times closer to the target."""
    state.camera = orbit_view(state.camera, Orbit(zoom=factor))
    state.dirty = True


def scroll(state: ViewerState, notches: float) -> None:
    zoom(state, 1.1 ** notches)


def reset_view(state: ViewerState) -> None:
    state.camera = stage_model(state.model.grown, state.frusta(), state.camera.width, state.camera.height).camera
    state.dirty = True


def set_method(state: ViewerState, method: str) -> None:
    state.method = method
    if method.startswith("GS"):
        change_level(state, 0)
    state.dirty = True


def change_level(state: ViewerState, delta: int) -> None:
    level = int(np.clip(state.level + delta, 0, MAX_SUBDIV))
    frusta = state.frusta()
    n = stored_triangles(frusta, level)
    while n > VIEW_MAX_TRIANGLES and level > 0:
        state.status = f"m = {level} would make {n:,} triangles, over the viewer's {VIEW_MAX_TRIANGLES:,}"
        level -= 1
        n = stored_triangles(frusta, level)
    state.level = level
    state.dirty = True


def scale_linear_steps(state: ViewerState, factor: float) -> None:
    steps = knob_of(RaycastSettings, "linear_steps").clamp(int(round(state.march.linear_steps * factor)))
    state.march = replace(state.march, linear_steps=steps)
    state.dirty = True


def change_binary_steps(state: ViewerState, delta: int) -> None:
    steps = knob_of(RaycastSettings, "binary_steps").clamp(state.march.binary_steps + delta)
    state.march = replace(state.march, binary_steps=steps)
    state.dirty = True


def toggle_march(state: ViewerState) -> None:
    state.march = replace(state.march, march="fixed" if state.march.march == "adaptive" else "adaptive")
    state.dirty = True


def toggle_shadows(state: ViewerState) -> None:
    state.shadows = not state.shadows
    state.dirty = True


def cycle_ssaa(state: ViewerState) -> None:
    state.ssaa = state.ssaa % min(4, MAX_SSAA) + 1
    state.dirty = True


def toggle_play(state: ViewerState) -> None:
    if not state.model.animated:
        state.status = "nothing moves in this model (a scene with motion plays)"
        return
    state.playing = not state.playing
    state.dirty = True


def scrub(state: ViewerState, dt: float) -> None:
    if not state.model.animated:
        state.status = "nothing moves in this model (a scene with motion plays)"
        return
    state.t = max(0.0, state.t + dt)
    state.dirty = True


def toggle_help(state: ViewerState) -> None:
    state.show_help = not state.show_help


def quit(state: ViewerState) -> None:
    state.closing = True


#: The handlers the key bindings name (:attr:`plantgen.viewer.keys.Binding.action`), by name.
ACTIONS = {f.__name__: f for f in (orbit, pan_view, zoom, reset_view, set_method, change_level, scale_linear_steps,
                                   change_binary_steps, toggle_march, toggle_shadows, cycle_ssaa, toggle_play, scrub,
                                   grow_step, toggle_growth, screenshot, window_shot, save_camera, toggle_help, quit)}
