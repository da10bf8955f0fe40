"""The turtle's symbols, each declared once: its character, its parameters, what it does.

As L-Py declares a module with its name, arity, documentation and interpretation, each
:class:`Symbol` of :data:`SYMBOLS` says

* ``char``: the one character written in a grammar;
* ``params`` and ``required``: the names of its parameters and how many must be given,
  hence its ``arity``, the parameter counts the parser accepts (:data:`ARITY`);
* ``doc``: one line (Markdown) with ABOP's meaning and the defaults of its parameters;
* ``action``: the :class:`Action` the turtle (:mod:`plantgen.lsystem.turtle`) runs for
  it, or :attr:`Action.CUT`, which the derivation runs (:mod:`plantgen.lsystem.derive`),
  or :attr:`Action.NONE` for an unsupported symbol;
* ``unsupported``: for a symbol with a turtle meaning in ABOP (or its program cpfg) that
  plantgen does not draw yet, what that meaning is; the turtle skips it with the warning
  :func:`unsupported_warning`. Such a symbol is parsed as any other: any parameter count,
  the same one wherever the grammar writes it.

The parser (:mod:`plantgen.lsystem.grammar`), the derivation's cut, the turtle, its warnings
and the grammar reference's table of turtle symbols (:func:`markdown_table`, which the
documentation's build inserts) all read this table.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from ..geometry.meshes.surfaces import SURFACES

__all__ = ["ARITY", "DERIVATION_ACTIONS", "QUERY_PREFIX", "SYMBOLS", "UNSUPPORTED", "Action", "Symbol", "by_action",
           "markdown_table", "unsupported_warning"]


class Action(IntEnum):
    """What a symbol does. The values are the codes of the turtle's program (0: nothing)."""

    NONE = 0            # no turtle meaning: skipped (and warned of, for an unsupported symbol)
    DRAW = 1            # F
    MOVE = 2            # f: move; a vertex of a polygon without dots
    MOVE_NO_VERTEX = 3  # G: move, never a vertex
    TURN_LEFT = 4       # +, about U
    TURN_RIGHT = 5      # -
    PITCH_DOWN = 6      # &, about L
    PITCH_UP = 7        # ^
    ROLL_LEFT = 8       # \, about H
    ROLL_RIGHT = 9      # /
    TURN_AROUND = 10    # |
    PUSH = 11           # [
    POP = 12            # ]
    WIDTH = 13          # !
    LEVEL = 14          # $
    MATERIAL = 15       # ;
    NEXT_MATERIAL = 16  # '
    POLYGON_OPEN = 17   # {
    POLYGON_CLOSE = 18  # }
    VERTEX = 19         # .
    SURFACE = 20        # ~
    CUT = 21            # %: run by the derivation, never reaches the turtle
    QUERY_POSITION = 22  # ?P: written by the derivation's query pass (as are the four below)
    QUERY_HEADING = 23   # ?H
    QUERY_UP = 24        # ?U
    QUERY_LEFT = 25      # ?L
    COMMUNICATE = 26     # ?E: answered by the environment


#: The actions the derivation runs (the cut, the query and communication modules): the
#: turtle draws nothing for them.
DERIVATION_ACTIONS = frozenset({Action.CUT, Action.QUERY_POSITION, Action.QUERY_HEADING, Action.QUERY_UP,
                                Action.QUERY_LEFT, Action.COMMUNICATE})
#: What a query module's symbol starts with (``?P``): its symbol is this and one letter.
QUERY_PREFIX = "?"


@dataclass(frozen=True)
class Symbol:
    """One turtle symbol (see the module's notes)."""

    char: str
    params: tuple[str, ...]
    action: Action
    doc: str
    required: int = 0
    unsupported: str = ""
    any_count: bool = False     # any parameter count, the same one wherever the grammar writes it

    def __post_init__(self):
        if len(self.char) != 1 and not (len(self.char) == 2 and self.char[0] == QUERY_PREFIX
                                        and self.char[1].isalpha()):
            raise ValueError(f"a turtle symbol is one character (or {QUERY_PREFIX!r} and a letter), "
                             f"not {self.char!r}")
        if not 0 <= self.required <= len(self.params):
            raise ValueError(f"{self.char!r}: {self.required} required of {len(self.params)} parameters")
        if bool(self.unsupported) != (self.action is Action.NONE):
            raise ValueError(f"{self.char!r}: a symbol without an action is one plantgen does not draw yet")
        if self.unsupported and not self.doc:
            object.__setattr__(self, "doc", f"not drawn yet ({self.unsupported}): the string is drawn without "
                                            "it, with a warning")

    @property
    def arity(self) -> tuple[int, ...] | None:
        """The parameter counts the parser accepts; None (any, as for any other symbol)
        for an unsupported one."""
        if self.unsupported or self.any_count:
            return None
        return tuple(range(self.required, len(self.params) + 1))

    def forms(self) -> tuple[str, ...]:
        """How the symbol is written, one form per accepted parameter count: ``F``,
        ``F(l)``, ``F(l, w)``."""
        if self.any_count:
            return (f"{self.char}({', '.join(self.params)}, ...)",)
        if self.arity is None:
            return (self.char,)
        return tuple(self.char + (f"({', '.join(self.params[:n])})" if n else "") for n in self.arity)


_SURFACE_NAMES = ", ".join(f"`{name}`" for name in SURFACES)

#: Every turtle symbol, in the order the grammar reference lists them.
SYMBOLS: tuple[Symbol, ...] = (
    Symbol("F", ("l", "w"), Action.DRAW,
           "draw a segment of length l (default `step`) along the heading H; with w it tapers to end radius w, "
           "which becomes the radius"),
    Symbol("f", ("l",), Action.MOVE,
           "move by l (default `step`) without drawing; the next segment starts a new root; in a polygon "
           "without `.` the position reached is a vertex"),
    Symbol("G", ("l",), Action.MOVE_NO_VERTEX,
           "move by l (default `step`) without drawing and without recording a polygon vertex; the next "
           "segment starts a new root"),
    Symbol("+", ("a",), Action.TURN_LEFT, "turn left by a degrees (default `angle`) about the up axis U"),
    Symbol("-", ("a",), Action.TURN_RIGHT, "turn right by a degrees (default `angle`) about U"),
    Symbol("&", ("a",), Action.PITCH_DOWN, "pitch down by a degrees (default `angle`) about the left axis L"),
    Symbol("^", ("a",), Action.PITCH_UP, "pitch up by a degrees (default `angle`) about L"),
    Symbol("\\", ("a",), Action.ROLL_LEFT, "roll left by a degrees (default `angle`) about the heading H"),
    Symbol("/", ("a",), Action.ROLL_RIGHT, "roll right by a degrees (default `angle`) about H"),
    Symbol("|", (), Action.TURN_AROUND, "turn around (180° about U)"),
    Symbol("[", (), Action.PUSH,
           "push the turtle state; the first segment after it starts a side branch"),
    Symbol("]", (), Action.POP,
           "pop the turtle state; the first segment after it carries on the axis the branch grew from"),
    Symbol("!", ("w",), Action.WIDTH, "set the radius to w; without w multiply it by `width_factor`"),
    Symbol("$", (), Action.LEVEL, "roll about H so that the turtle's left L is horizontal"),
    Symbol(";", ("i",), Action.MATERIAL,
           "select material i (an index into `materials`); without i the next material, cycling"),
    Symbol("'", (), Action.NEXT_MATERIAL, "the next material, cycling (ABOP's colour index step)"),
    Symbol("{", (), Action.POLYGON_OPEN,
           "start a polygon; inside another, a new one (the outer one resumes at its `}`)"),
    Symbol("}", (), Action.POLYGON_CLOSE,
           "close the innermost open polygon, filled with the current material (triangulated, concave "
           "outlines too)"),
    Symbol(".", (), Action.VERTEX, "record the turtle's position as a vertex of the innermost open polygon"),
    Symbol("~", ("name", "s"), Action.SURFACE,
           f"place the predefined surface `name` ({_SURFACE_NAMES}) at the turtle, oriented by H, L, U and "
           "scaled by s (default 1), in the current material; the turtle does not move",
           required=1),
    Symbol("%", (), Action.CUT,
           "cut (in the derivation): remove this module and the rest of its branch, up to its `]`"),
    Symbol("?P", ("x", "y", "z"), Action.QUERY_POSITION,
           "query (in the derivation): after each step the turtle's position at this module is written "
           "into x, y, z, for the next step's rules to test", required=3),
    Symbol("?H", ("x", "y", "z"), Action.QUERY_HEADING, "query: the turtle's heading H, written as `?P` "
           "writes the position", required=3),
    Symbol("?U", ("x", "y", "z"), Action.QUERY_UP, "query: the turtle's up axis U, written as `?P` writes "
           "the position", required=3),
    Symbol("?L", ("x", "y", "z"), Action.QUERY_LEFT, "query: the turtle's left axis L, written as `?P` "
           "writes the position", required=3),
    Symbol("?E", ("a",), Action.COMMUNICATE,
           "communication (in the derivation): after each step the grammar's `environment` writes its "
           "answers at this module into the parameters (see \"Environment\")", any_count=True),
    Symbol("@", (), Action.NONE, "", unsupported="cpfg's spheres and circles"),
    Symbol("#", (), Action.NONE, "", unsupported="cpfg's width increment"),
)

#: The parameter counts each turtle symbol accepts (the parser's check); symbols not listed,
#: the unsupported ones included, take one count per grammar.
ARITY: dict[str, tuple[int, ...]] = {s.char: s.arity for s in SYMBOLS if s.arity is not None}
#: The symbols plantgen does not draw yet, with what they mean in ABOP or cpfg.
UNSUPPORTED: dict[str, str] = {s.char: s.unsupported for s in SYMBOLS if s.unsupported}


def by_action(action: Action) -> str:
    """The character of the symbol that runs ``action`` (each action has one)."""
    if action is Action.NONE:
        raise ValueError("several symbols have no action: name one by its character")
    return next(s.char for s in SYMBOLS if s.action is action)


def unsupported_warning(source: str, char: str, count: int) -> str:
    """The line warning that ``count`` modules ``char`` (one of :data:`UNSUPPORTED`) were
    not drawn."""
    return (f"{source}: warning: {char!r} ({UNSUPPORTED[char]}) has a turtle meaning in ABOP "
            f"but none in plantgen yet; {count:,} module(s) not drawn")


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def markdown_table() -> str:
    """The grammar reference's table of turtle symbols (Markdown, one row per symbol, no final
    newline)."""
    rows = ["| module | meaning |", "| --- | --- |"]
    for s in SYMBOLS:
        forms = " ".join(f"`{form}`" for form in s.forms()) + (", any parameters" if s.arity is None
                                                              and not s.any_count else "")
        rows.append(f"| {_cell(forms)} | {_cell(s.doc)} |")
    return "\n".join(rows)
