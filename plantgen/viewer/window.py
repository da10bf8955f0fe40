"""The viewer's window: moderngl-window on its pyglet backend, the event loop, and the
presentation of the session's frames with the heads-up line over them.

Why moderngl-window, and why pyglet: moderngl-window creates a moderngl context on a real
window and hands us its events, so the frames come from plantgen's own renderers drawing
into that context; its pyglet backend needs no package beyond moderngl-window's own
dependencies (pyglet is one of them, pure Python, loading the system's libGL and X11 through
ctypes), where glfw would add a native wheel. Our loop (not moderngl-window's
``run_window_config``) drives the window, so it can poll the watched files, take a
reload in, and draw only when something changed.
"""

from __future__ import annotations

import importlib.util
import os
import sys
import time

import numpy as np

from ..errors import PlantgenError, missing_extra
from ..gl.shaders import build_program, set_uniforms
from ..images import write_png
from .hud import help_panel, text_panel
from .session import ViewerSession

__all__ = ["ViewerError", "INSTALL_HINT", "check_viewer_available", "open_window", "run_window"]

#: The command that installs what the viewer needs.
INSTALL_HINT = missing_extra("plantgen view", "view")

#: OpenGL version the viewer's window asks for (the renderers' shaders are GLSL 4.30).
WINDOW_GL = (4, 3)

#: Seconds between redraws of an idle window (it redraws at once on any event).
IDLE_REDRAW_S = 0.5

#: Frames drawn before ``--snapshot`` saves the window (the heads-up medians settle).
SNAPSHOT_FRAMES = 5


class ViewerError(PlantgenError):
    """The viewer cannot start here: its extra is not installed, or no display or no
    OpenGL 4.3 window can be had. One line, exit status 2."""


def check_viewer_available() -> None:
    """One line naming the install command when moderngl-window or pyglet is missing,
    and one line when there is no display to open a window on (Linux and BSD: no
    ``DISPLAY``)."""
    missing = [m for m in ("moderngl_window", "pyglet") if importlib.util.find_spec(m) is None]
    if missing:
        raise ViewerError(f"{INSTALL_HINT} ({' and '.join(m.replace('_', '-') for m in missing)} missing)")
    if sys.platform.startswith(("linux", "freebsd", "openbsd", "netbsd")) and not os.environ.get("DISPLAY"):
        raise ViewerError("no display to open a window on (DISPLAY is not set); plantgen render writes "
                          "images without one")


def open_window(title: str, size: tuple):
    """A resizable moderngl-window (pyglet) with an OpenGL 4.3 core context, or one line."""
    try:
        from moderngl_window.context.pyglet.window import Window
    except ImportError as exc:
        raise ViewerError(f"{INSTALL_HINT} (its window library failed to import: {exc})") from None
    except Exception as exc:   # pyglet opens the display when its window module loads
        raise ViewerError(f"cannot open the display {os.environ.get('DISPLAY', '')!r}: {_short(exc)}") from None
    try:
        return Window(title=title, size=tuple(size), gl_version=WINDOW_GL, resizable=True, vsync=False,
                      cursor=True)
    except Exception as exc:
        if "display" in type(exc).__name__.lower():
            raise ViewerError(f"cannot open the display {os.environ.get('DISPLAY', '')!r}: {_short(exc)}") from None
        version = f"{WINDOW_GL[0]}.{WINDOW_GL[1]}"
        raise ViewerError(f"cannot open a window with OpenGL {version} core: {_short(exc)}") from None


def _short(exc: BaseException) -> str:
    return (" ".join(str(exc).split()) or type(exc).__name__)[:200]


class Presenter:
    """Draws the session's last frame texel for pixel, and the heads-up panel over it."""

    def __init__(self, window):
        self.window, self.ctx = window, window.ctx
        self.program = build_program(self.ctx, "overlay.glsl")
        self.vao = self.ctx.vertex_array(self.program, [])
        self.frame_tex = self.hud_tex = None
        self._hud_key = None

    def _texture(self, old, array: np.ndarray):
        h, w, k = array.shape
        data = np.ascontiguousarray(array).tobytes()
        if old is not None and old.size == (w, h) and old.components == k:
            old.write(data)
            return old
        if old is not None:
            old.release()
        tex = self.ctx.texture((w, h), k, data, alignment=1)
        tex.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
        return tex

    def set_frame(self, color: np.ndarray) -> None:
        self.frame_tex = self._texture(self.frame_tex, color)

    def set_hud(self, lines, show_help: bool, width: int, height: int) -> None:
        key = (tuple(lines), show_help, width, height)
        if key == self._hud_key:
            return
        self._hud_key = key
        panel = text_panel(lines, width)
        if show_help:
            keys = help_panel(width, height - panel.shape[0])
            both = np.zeros((panel.shape[0] + keys.shape[0], max(panel.shape[1], keys.shape[1]), 4), np.uint8)
            both[:panel.shape[0], :panel.shape[1]] = panel
            both[panel.shape[0]:, :keys.shape[1]] = keys
            panel = both
        self.hud_tex = self._texture(self.hud_tex, panel)

    def draw(self) -> None:
        ctx, window = self.ctx, self.window
        w, h = window.buffer_size
        window.use()
        ctx.viewport = (0, 0, w, h)
        ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE)
        ctx.clear(0.1, 0.1, 0.1, 1.0)
        if self.frame_tex is not None:
            fw, fh = self.frame_tex.size    # texel for pixel, anchored at the top left
            self._quad(self.frame_tex, fw, fh, w, h)
        if self.hud_tex is not None:
            ctx.enable(ctx.BLEND)
            ctx.blend_func = ctx.SRC_ALPHA, ctx.ONE_MINUS_SRC_ALPHA
            self._quad(self.hud_tex, *self.hud_tex.size, w, h)
            ctx.disable(ctx.BLEND)

    def _quad(self, tex, tw, th, w, h) -> None:
        set_uniforms(self.program, rect=(-1.0, 1.0 - 2.0 * th / h, -1.0 + 2.0 * tw / w, 1.0), image=0)
        tex.use(0)
        self.vao.render(mode=self.ctx.TRIANGLE_STRIP, vertices=4)

    def window_pixels(self) -> np.ndarray:
        """(h, w, 3) uint8 of the window as drawn (before the swap), row 0 the top row."""
        w, h = self.window.buffer_size
        raw = self.window.fbo.read(viewport=(0, 0, w, h), components=3, alignment=1)
        return np.frombuffer(raw, np.uint8).reshape(h, w, 3)[::-1].copy()

    def release(self) -> None:
        for obj in (self.frame_tex, self.hud_tex, self.vao):
            if obj is not None:
                obj.release()


def _wire_events(window, session: ViewerSession, touched: list) -> None:
    """Route the window's key, mouse, resize and close events to the session."""
    from pyglet.window import key as pyglet_key

    def on_key(symbol, action, modifiers):
        touched[0] = True
        if action == window.keys.ACTION_PRESS:
            session.key(pyglet_key.symbol_string(symbol), bool(modifiers.shift))

    def on_drag(x, y, dx, dy):
        touched[0] = True
        states, ratio = window.mouse_states, window.pixel_ratio
        pan = states.right or states.middle or (states.left and window.modifiers.shift)
        session.drag(dx * ratio, dy * ratio, pan=pan)

    def on_scroll(x_offset, y_offset):
        touched[0] = True
        session.scroll(y_offset)

    def on_resize(width, height):
        touched[0] = True
        session.dirty = True

    def on_close():
        session.closing = True

    window.key_event_func = on_key
    window.mouse_drag_event_func = on_drag
    window.mouse_scroll_event_func = on_scroll
    window.resize_func = on_resize
    window.close_func = on_close
    window.exit_key = None          # Esc and Q are the session's "quit" (keys.py)


def _snapshot(session: ViewerSession, presenter: Presenter) -> bool:
    """``--snapshot FILE``: after :data:`SNAPSHOT_FRAMES` frames, save the window as shown
    and say the loop may end (True); before, ask for another frame."""
    if len(session.frames) < SNAPSHOT_FRAMES:
        session.dirty = True
        return False
    path = write_png(session.options.snapshot, presenter.window_pixels())
    session.say(f"saved window {path}")
    return True


def run_window(window, session: ViewerSession, ready=None) -> str:
    """The event loop until the window closes, Q or Esc, or Ctrl-C. Draws a frame when the
    session needs one, the window otherwise only on events (and every
    :data:`IDLE_REDRAW_S`). ``ready()`` is called once the first frame is on screen.
    Returns how it ended: "closed" or "interrupted"."""
    presenter, touched = Presenter(window), [True]
    _wire_events(window, session, touched)
    last_tick = last_draw = time.monotonic()
    how, shown = "closed", None
    try:
        while not (window.is_closing or session.closing):
            now = time.monotonic()
            drew = session.tick(now - last_tick, now)
            last_tick = now
            w, h = window.buffer_size
            if drew or session.last is None or (w, h) != session.last.color.shape[1::-1]:
                session.draw(w, h)
            drew = session.last is not shown          # drawn here, or by a key (P, C) in between
            if drew:
                shown = session.last
                presenter.set_frame(shown.color)
            presenter.set_hud(session.hud_lines(), session.show_help, w, h)
            if drew or touched[0] or session.want_window_shot or now - last_draw > IDLE_REDRAW_S:
                presenter.draw()
                if session.want_window_shot:
                    session.window_shot(presenter.window_pixels())
                if drew and session.options.snapshot is not None and _snapshot(session, presenter):
                    break
                window.swap_buffers()       # also dispatches the window's events
                last_draw, touched[0] = now, False
                if drew:
                    session.presented()
                    if ready is not None:
                        ready()
                        ready = None
            else:
                # events without a redraw: moderngl-window's pyglet window has no public call
                # for this, so its pyglet window (``_window``) dispatches them
                window._window.dispatch_events()
                time.sleep(0.01)
    except KeyboardInterrupt:
        how = "interrupted"
    finally:
        presenter.release()
        session.release()
        window.close()
        window.destroy()
    return how
