"""What the viewer shows and how it changes, apart from any window: the model, the camera,
the method and its knobs, the time of an animated scene, a grammar's growth step by step,
live reload, and the frames, drawn by the same renderers as ``plantgen render`` with the
same arguments, so a saved camera reproduces a frame pixel for pixel.

A :class:`ViewerSession` needs only a moderngl context: the window (``window.py``) feeds it
events and presents its frames; the tests drive it headless too. It is the state
(:class:`~plantgen.viewer.state.ViewerState`) with the functions over it bound as its
methods: the frames (``frame.py``), time passing and live reload (``reload.py``), the keys
and the mouse (``handlers.py``), the growth (``growth.py``), saving (``shots.py``) and the
heads-up lines (``hud.py``). What ``plantgen view`` starts from (:class:`ViewOptions`, the
methods, the limits) is in ``options.py``, and importable from here as before.
"""

from __future__ import annotations

from . import frame, growth, handlers, hud, reload, shots
from .options import (
    DRAG_TURN,
    HUD_FRAMES,
    METHODS,
    VIEW_MAX_TRIANGLES,
    FrameStats,
    ViewOptions,
    one_line,
    stored_triangles,
)
from .state import ViewerState

__all__ = ["METHODS", "VIEW_MAX_TRIANGLES", "DRAG_TURN", "HUD_FRAMES", "ViewOptions", "ViewerSession",
           "ViewerState", "FrameStats", "one_line", "stored_triangles"]


class ViewerSession(ViewerState):
    """The viewer's state and its frames (see the module's docstring): a
    :class:`~plantgen.viewer.state.ViewerState`, built with the same parameters, whose
    methods below are the functions of the modules named beside them (``session.orbit(...)``
    is ``handlers.orbit(session, ...)``).

    Parameters
    ----------
    ctx : the moderngl context to draw with (the window's)
    options : :class:`ViewOptions`
    model : the first model, grown by the caller (:func:`~plantgen.pipeline.prepare_model`)
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

    # ------------------------------------------------------------------ the heads-up line (hud.py)
    hud_lines = hud.hud_lines
