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

import statistics

from . import frame, growth, handlers, reload, shots
from .options import (
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

    # ------------------------------------------------------------------ the controls (handlers.py)
    key = handlers.key
    orbit = handlers.orbit
    drag = handlers.drag
    pan = handlers.pan_by
    pan_view = handlers.pan_view
    zoom = handlers.zoom
    scroll = handlers.scroll
    reset_view = handlers.reset_view
    set_method = handlers.set_method
    change_level = handlers.change_level
    scale_linear_steps = handlers.scale_linear_steps
    change_binary_steps = handlers.change_binary_steps
    toggle_march = handlers.toggle_march
    toggle_shadows = handlers.toggle_shadows
    cycle_ssaa = handlers.cycle_ssaa
    toggle_play = handlers.toggle_play
    scrub = handlers.scrub
    toggle_help = handlers.toggle_help
    quit = handlers.quit

    # ------------------------------------------------------------------ growth step by step (growth.py)
    grow_step = growth.grow_step
    toggle_growth = growth.toggle_growth

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

