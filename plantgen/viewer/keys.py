"""The viewer's key and mouse bindings, in one table: the key handler dispatches from it,
and the ``H`` overlay and ``plantgen view --help`` print it.

Keys are named as pyglet names them (``A``, ``_1``, ``LEFT``, ``BRACKETLEFT``, ``COMMA``);
``shift`` is True for a binding that needs Shift, False for one that must not have it,
None for either.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Binding", "BINDINGS", "GROW_STEP_S", "MOUSE_HELP", "binding_for", "help_lines"]


@dataclass(frozen=True)
class Binding:
    """``keys`` (names) with ``shift`` call the handler named ``action`` with the state and
    ``args`` (:data:`plantgen.viewer.handlers.ACTIONS`); ``label`` is how the help writes
    the keys, ``text`` what they do."""

    keys: tuple
    shift: bool | None
    action: str
    args: tuple
    label: str
    text: str


def _b(keys, action, label, text, *args, shift=None) -> Binding:
    return Binding(tuple(keys.split()), shift, action, args, label, text)


#: Degrees a key turns the view; the fraction of the view a key pans; the zoom factor of
#: a key or a wheel notch; the seconds a scrub key steps.
KEY_TURN, KEY_PAN, KEY_ZOOM, KEY_SCRUB, KEY_SCRUB_LONG = 5.0, 0.05, 1.1, 0.1, 1.0

#: Seconds between the steps of a playing growth (at least: a step waits for the last one
#: to be grown and drawn).
GROW_STEP_S = 0.5

BINDINGS = (
    _b("LEFT", "orbit", "Left/Right", "turn around the model", -KEY_TURN, 0.0, shift=False),
    _b("RIGHT", "orbit", "", "", KEY_TURN, 0.0, shift=False),
    _b("UP", "orbit", "Up/Down", "look from higher / lower", 0.0, KEY_TURN, shift=False),
    _b("DOWN", "orbit", "", "", 0.0, -KEY_TURN, shift=False),
    _b("LEFT", "pan_view", "Shift+arrows", "move the view", -KEY_PAN, 0.0, shift=True),
    _b("RIGHT", "pan_view", "", "", KEY_PAN, 0.0, shift=True),
    _b("UP", "pan_view", "", "", 0.0, KEY_PAN, shift=True),
    _b("DOWN", "pan_view", "", "", 0.0, -KEY_PAN, shift=True),
    _b("EQUAL PLUS NUM_ADD PAGEUP", "zoom", "+ / -", "zoom in / out", KEY_ZOOM),
    _b("MINUS NUM_SUBTRACT PAGEDOWN", "zoom", "", "", 1.0 / KEY_ZOOM),
    _b("R HOME", "reset_view", "R", "frame the model again"),
    _b("_1", "set_method", "1 2 3 4 5 6", "RC, RC+R, GS, GS+R, RT, RT+R", "RC"),
    _b("_2", "set_method", "", "", "RC+R"),
    _b("_3", "set_method", "", "", "GS"),
    _b("_4", "set_method", "", "", "GS+R"),
    _b("_5", "set_method", "", "", "RT"),
    _b("_6", "set_method", "", "", "RT+R"),
    _b("BRACKETRIGHT", "change_level", "[ / ]", "GS subdivision level m down / up", 1),
    _b("BRACKETLEFT", "change_level", "", "", -1),
    _b("L", "scale_linear_steps", "L / Shift+L", "relief linear steps x2 / /2", 2.0, shift=False),
    _b("L", "scale_linear_steps", "", "", 0.5, shift=True),
    _b("B", "change_binary_steps", "B / Shift+B", "relief binary steps +1 / -1", 1, shift=False),
    _b("B", "change_binary_steps", "", "", -1, shift=True),
    _b("M", "toggle_march", "M", "relief march adaptive / fixed"),
    _b("S", "toggle_shadows", "S", "shadows on / off"),
    _b("A", "cycle_ssaa", "A", "anti-aliasing: 1, 2, 3, 4 samples a side"),
    _b("SPACE", "toggle_play", "Space", "play / pause an animated scene"),
    _b("PERIOD", "scrub", ", / .", "time -0.1 / +0.1 s (Shift: 1 s)", KEY_SCRUB, shift=False),
    _b("COMMA", "scrub", "", "", -KEY_SCRUB, shift=False),
    _b("PERIOD", "scrub", "", "", KEY_SCRUB_LONG, shift=True),
    _b("COMMA", "scrub", "", "", -KEY_SCRUB_LONG, shift=True),
    _b("N", "grow_step", "N / Shift+N", "a grammar's growth: one derivation step forward / back", 1, shift=False),
    _b("N", "grow_step", "", "", -1, shift=True),
    _b("G", "toggle_growth", "G", f"play / stop a grammar's growth, a step each {GROW_STEP_S:g} s (from the axiom "
       "when grown)"),
    _b("P", "screenshot", "P", "save the frame as PNG (as plantgen render draws it)", shift=False),
    _b("P", "window_shot", "Shift+P", "save the window as shown, heads-up line included", shift=True),
    _b("C", "save_camera", "C", "save the camera as JSON for plantgen render --camera"),
    _b("H F1", "toggle_help", "H", "show / hide these keys"),
    _b("Q ESCAPE", "quit", "Q, Esc", "close the viewer"),
)

MOUSE_HELP = (("left drag", "turn around the model"), ("right or Shift+left drag", "move the model with the cursor"),
              ("wheel", "zoom"))


def binding_for(key: str, shift: bool) -> Binding | None:
    """The binding of key ``key`` (a pyglet name) with or without Shift, or None."""
    for b in BINDINGS:
        if key in b.keys and (b.shift is None or b.shift == shift):
            return b
    return None


def help_lines() -> list[tuple[str, str]]:
    """(keys, what they do) for the help: the mouse, then every labelled binding."""
    return [*MOUSE_HELP, *((b.label, b.text) for b in BINDINGS if b.label)]
