"""``plantgen view``: a window to turn a plant around in, switch methods and knobs, play an
animated scene, and watch the plant regrow when its grammar is saved.

- :mod:`.session`: :class:`ViewerSession`, what is shown and how it changes (camera,
  method, knobs, time, live reload) and the frames, drawn by plantgen's own Raycaster and
  RasterRenderer; needs only a moderngl context. It is the state (:mod:`.state`) with the
  functions over it bound as methods: :mod:`.frame` (the frames), :mod:`.reload` (time
  passing, live reload), :mod:`.handlers` (the keys and the mouse), :mod:`.growth` (a
  grammar's growth step by step), :mod:`.shots` (P, Shift+P, C); :mod:`.options`: the
  options, the methods, the limits.
- :mod:`.window`: the window (moderngl-window, pyglet backend), the event loop, the
  heads-up line; the only module that imports the ``[view]`` extra.
- :mod:`.keys`: the key bindings, one table; :mod:`.watch`: file polling and the reload
  thread; :mod:`.hud`: the heads-up text.
"""

from __future__ import annotations

import time

from .session import ViewerSession, ViewOptions
from .window import ViewerError, check_viewer_available, open_window, run_window

__all__ = ["ViewOptions", "ViewerError", "ViewerSession", "run_viewer"]


def run_viewer(options: ViewOptions, *, say=print, warn=print) -> str:
    """Open the viewer on ``options.input`` and run it until the window closes; returns
    "closed" or "interrupted" (Ctrl-C). Fails in one line (:class:`ViewerError`, or the
    input's own error) before any window opens when the extra, the display or the input
    is missing or bad."""
    check_viewer_available()
    say(f"growing {options.input} ...")
    t0 = time.perf_counter()
    model = options.prepare()
    say(f"{model.grown.name}: {model.grown.segments:,} segments in {time.perf_counter() - t0:.2f} s"
        + (f"; watching {len(model.grown.sources)} file(s) for changes" if options.watch else ""))
    window = open_window(f"plantgen view: {model.grown.name}", options.size)
    try:
        session = ViewerSession(window.ctx, options, model, say=say, warn=warn)
    except BaseException:
        window.close()
        window.destroy()
        raise
    w, h = window.buffer_size

    def ready():
        say(f"ready: {session.renderer}, {w}x{h}, {session.method} (H shows the keys)")

    return run_window(window, session, ready)
