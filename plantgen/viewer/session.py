"""What the viewer shows and how it changes, apart from any window: the model, the camera,
the method and its knobs, the time of an animated scene, a grammar's growth step by step,
live reload, and the frames,
drawn by the same :class:`~plantgen.gl.raycast.Raycaster` (RC, RC+R) and
:class:`~plantgen.gl.raster.RasterRenderer` (GS, GS+R) as ``plantgen render``, with the
same arguments (:func:`plantgen.pipeline.frame_arguments`), so a saved camera reproduces a
frame pixel for pixel.

A :class:`ViewerSession` needs only a moderngl context: the window (``window.py``) feeds it
events and presents its frames; the tests drive it headless too.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import replace

import numpy as np

from ..geometry.camera import MAX_ELEVATION, Orbit, orbit_angles, orbit_view
from ..knobs import knob_of
from ..pipeline import stage_model
from ..settings import (
    MAX_SSAA,
    MAX_SUBDIV,
    RaycastSettings,
)
from . import frame, growth, reload, shots
from .keys import binding_for
from .options import (
    DRAG_TURN,
    METHODS,
    VIEW_MAX_TRIANGLES,
    FrameStats,
    ViewOptions,
    one_line,
    stored_triangles,
)
from .state import ViewerState

__all__ = ["METHODS", "VIEW_MAX_TRIANGLES", "ViewOptions", "ViewerSession", "FrameStats", "one_line",
           "stored_triangles"]


class ViewerSession(ViewerState):
    """The viewer's state and its frames (see the module's docstring).

    Parameters
    ----------
    ctx : the moderngl context to draw with (the window's)
    options : :class:`ViewOptions`
    model : the first model, grown by the caller (:func:`prepare_model`)
    say, warn : callables printing one line on stdout / stderr
    """

    # ------------------------------------------------------------------ the frame (frame.py)
    draw = frame.draw
    caster = frame.caster
    skinned_mesh = frame.skinned_mesh
    current = frame.current
    release = frame.release

    # ------------------------------------------------------------------ time passes (reload.py)
    tick = reload.tick
    presented = reload.presented

    # ------------------------------------------------------------------ the controls
    def key(self, name: str, shift: bool = False) -> bool:
        """Handle key ``name`` (a pyglet key name); returns False for a key with no binding."""
        binding = binding_for(name, shift)
        if binding is None:
            return False
        getattr(self, binding.action)(*binding.args)
        return True

    def orbit(self, d_azimuth: float, d_elevation: float) -> None:
        """Turn the view around its target by degrees."""
        az, el, _ = orbit_angles(self.camera)
        el = float(np.clip(el + d_elevation, -MAX_ELEVATION, MAX_ELEVATION))
        self.camera = orbit_view(self.camera, Orbit(azimuth=(az + d_azimuth + 180.0) % 360.0 - 180.0, elevation=el))
        self.dirty = True

    def drag(self, dx: float, dy: float, pan: bool = False) -> None:
        """A mouse drag of (dx, dy) window pixels (y down): turn, or with ``pan`` move."""
        if pan:
            self.pan(dx, dy)
        else:
            self.orbit(-DRAG_TURN * dx, DRAG_TURN * dy)

    def pan(self, dx: float, dy: float) -> None:
        """Move eye and target across the view by (dx, dy) pixels (the target follows the
        cursor)."""
        right, up, _ = self.camera.basis()
        dist = float(np.linalg.norm(np.subtract(self.camera.eye, self.camera.target)))
        per_pixel = 2.0 * dist * math.tan(math.radians(self.camera.fov_y) / 2) / self.camera.height
        shift = (-dx * right + dy * up) * per_pixel
        self.camera = replace(self.camera, eye=tuple((np.asarray(self.camera.eye) + shift).tolist()),
                              target=tuple((np.asarray(self.camera.target) + shift).tolist()))
        self.dirty = True

    def pan_view(self, fx: float, fy: float) -> None:
        """Move the view right and up by fractions of its height (keys; a drag moves the
        model with the cursor instead)."""
        self.pan(-fx * self.camera.height, fy * self.camera.height)

    def zoom(self, factor: float) -> None:
        """Move the eye ``factor`` times closer to the target."""
        self.camera = orbit_view(self.camera, Orbit(zoom=factor))
        self.dirty = True

    def scroll(self, notches: float) -> None:
        self.zoom(1.1 ** notches)

    def reset_view(self) -> None:
        self.camera = stage_model(self.model.grown, self.frusta(), self.camera.width, self.camera.height).camera
        self.dirty = True

    def set_method(self, method: str) -> None:
        self.method = method
        if method.startswith("GS"):
            self.change_level(0)
        self.dirty = True

    def change_level(self, delta: int) -> None:
        level = int(np.clip(self.level + delta, 0, MAX_SUBDIV))
        frusta = self.frusta()
        n = stored_triangles(frusta, level)
        while n > VIEW_MAX_TRIANGLES and level > 0:
            self.status = f"m = {level} would make {n:,} triangles, over the viewer's {VIEW_MAX_TRIANGLES:,}"
            level -= 1
            n = stored_triangles(frusta, level)
        self.level = level
        self.dirty = True

    def scale_linear_steps(self, factor: float) -> None:
        steps = knob_of(RaycastSettings, "linear_steps").clamp(int(round(self.march.linear_steps * factor)))
        self.march = replace(self.march, linear_steps=steps)
        self.dirty = True

    def change_binary_steps(self, delta: int) -> None:
        steps = knob_of(RaycastSettings, "binary_steps").clamp(self.march.binary_steps + delta)
        self.march = replace(self.march, binary_steps=steps)
        self.dirty = True

    def toggle_march(self) -> None:
        self.march = replace(self.march, march="fixed" if self.march.march == "adaptive" else "adaptive")
        self.dirty = True

    def toggle_shadows(self) -> None:
        self.shadows = not self.shadows
        self.dirty = True

    def cycle_ssaa(self) -> None:
        self.ssaa = self.ssaa % min(4, MAX_SSAA) + 1
        self.dirty = True

    def toggle_play(self) -> None:
        if not self.model.animated:
            self.status = "nothing moves in this model (a scene with motion plays)"
            return
        self.playing = not self.playing
        self.dirty = True

    def scrub(self, dt: float) -> None:
        if not self.model.animated:
            self.status = "nothing moves in this model (a scene with motion plays)"
            return
        self.t = max(0.0, self.t + dt)
        self.dirty = True

    # ------------------------------------------------------------------ growth step by step (growth.py)
    grow_step = growth.grow_step
    toggle_growth = growth.toggle_growth

    def toggle_help(self) -> None:
        self.show_help = not self.show_help

    def quit(self) -> None:
        self.closing = True

    # ------------------------------------------------------------------ saving (shots.py)
    screenshot = shots.screenshot
    window_shot = shots.window_shot
    save_camera = shots.save_camera
    render_command = shots.render_command

    # ------------------------------------------------------------------ the heads-up line
    def hud_lines(self) -> list[tuple[str, str]]:
        """(text, kind) lines of the heads-up display; kind is "info", "status" or "error"."""
        s = self.settings()
        if self.method in ("RC", "RT"):
            method = self.method
        elif self.method in ("RC+R", "RT+R"):
            method = (f"{self.method} adaptive <= {s.linear_steps} + {s.binary_steps} steps" if s.march == "adaptive"
                      else f"{self.method} fixed {s.linear_steps} + {s.binary_steps} steps")
        else:
            method = f"{self.method} m = {self.level}"
            if self.posing_on_gpu() and self.skinned is not None and self.skinned[0][1] == self.level:
                method += f", {len(self.skinned[1].mesh.faces):,} triangles, skinned on the GPU"
            elif self.mesh_cache is not None and self.mesh_key is not None and self.mesh_key[1] == self.level:
                method += f", {len(self.mesh_cache.faces):,} triangles"
        frames = list(self.frames)
        timing = "-"
        if frames:
            frame_ms = statistics.median(f.frame_ms for f in frames)
            wall_ms = statistics.median(f.wall_ms for f in frames)
            timing = f"{frame_ms:.1f} ms frame, {1000.0 / max(wall_ms, 1e-3):.1f} fps (median of {len(frames)})"
        cam = self.camera
        leaves = self.model.grown.polygons
        count = 0 if leaves is None else len(leaves)
        leafy = f", {count:,} {'leaf' if count == 1 else 'leaves'}" if count else ""
        lines = [(f"{self.model.grown.name}: {self.model.grown.segments:,} segments{leafy} | {method} | shadows "
                  f"{self._shadow_text()} | ssaa {self.ssaa}", "info"),
                 (f"{timing} | {cam.width}x{cam.height} | {self.renderer} | H: keys", "info")]
        if self.model.animated:
            lines.append((f"t = {self.t:.2f} s {'playing' if self.playing else 'paused'} (Space, , .)", "info"))
        if self.step_target is not None:
            lines.append((f"growth: step {self.step} of {self.steps_end}, {'playing' if self.growing else 'paused'}"
                          " (N, Shift+N, G)", "info"))
        if self.error:
            lines.append((self.error, "error"))
        elif self.status:
            lines.append((self.status, "status"))
        return lines

    def _shadow_text(self) -> str:
        """``off``, or ``on`` and how the last frame had its map: drawn (in how many ms) or
        reused (a camera move does not draw it again)."""
        if not self.shadows:
            return "off"
        stats = self.last.stats if self.last is not None else None
        if stats is None or "shadow" not in stats.passes:
            return "on"
        return "on (map reused)" if stats.shadow_cached else f"on (map drawn, {stats.shadow_ms:.0f} ms)"

