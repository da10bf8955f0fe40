"""Turtle interpretation: a derived module string to a :class:`Skeleton`.

Coordinates are y-up (as in Bhagvat et al. 2009). The turtle starts at the origin with
heading H = +y, left L = -x and up U = H × L = +z. The symbols it acts on, their
parameters and their meanings (ABOP's) are declared once, in :data:`plantgen.lsystem.symbols.SYMBOLS`;
each names the :class:`~plantgen.lsystem.symbols.Action` the turtle runs, and the turtle has one
handler per kind of action (:class:`Turtle`).

Polygons follow ABOP. A polygon's vertices are its ``.`` positions (chapter 5, "developmental
surface models"); a polygon with no ``.`` uses chapter 1's convention instead (figure 1.27,
the bush of figure 1.25): its vertices are the position at ``{`` and the position after each
``f``. So ``f`` records a vertex only in a polygon without dots, ``G`` never does, and ``F``
draws a segment as anywhere else. Polygons nest: ``{`` inside a polygon starts a new one, and
the outer one resumes at its ``}``. The polygon stack is not part of the turtle state:
vertices recorded inside a branch ``[...]`` belong to the polygon open around the branch.
A surface's polygons follow the ``{ }`` polygons in :class:`Polygons`, in string order.
Symbols with a turtle meaning in ABOP (or cpfg) that plantgen does not draw yet
(:data:`UNSUPPORTED`) are skipped with a warning naming them.

A segment's end radius is the turtle's radius when it is drawn. A segment that continues
its parent starts with the parent's end radius, so the skin tapers without steps; a root
or a side branch starts with the current radius. After each ``F`` the heading bends
towards the tropism vector T by ``strength·|H × T|`` radians (ABOP, section 2.3).

The segments drawn are counted before the walk (``max_segments`` of the limits in force),
and the walk's result is checked: a coordinate or radius that is not finite or lies
beyond ``tol.max_coordinate`` stops with one line naming the segment and its module.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import chain
from math import cos, radians, sin, sqrt

import numpy as np

from ..errors import PlantgenError
from ..geometry.meshes import surfaces
from ..geometry.meshes.polygons import PolygonBuilder, Polygons
from ..geometry.skeletons.skeleton import Skeleton
from ..limits import Limits
from ..limits import limits as default_limits
from ..tolerances import tol
from .grammar import TurtleSettings
from .strings import ModuleString
from .symbols import SYMBOLS, UNSUPPORTED, Action, by_action, unsupported_warning

__all__ = ["HANDLERS", "Drawing", "MAX_POLYGON_VERTICES", "UNSUPPORTED", "Turtle", "interpret", "interpret_plant"]

#: Modules turned into Python values at a time by :func:`_turtle_program`.
PROGRAM_CHUNK = 65_536
#: The most vertices one polygon may have (ear clipping is quadratic in them).
MAX_POLYGON_VERTICES = 4096


@dataclass(frozen=True, eq=False)
class Drawing:
    """What the turtle drew: the skeleton's segments, the filled polygons, and one line per
    thing it skipped (to be shown to the user)."""

    skeleton: Skeleton
    polygons: Polygons
    warnings: tuple[str, ...] = ()
    #: (k, 4, 3): the turtle's position, H, L and U at each query and communication module
    #: (``?P`` ... ``?E``), in string order; None unless asked for (``queries=True``)
    queries: np.ndarray | None = None
    #: (k, 2) int64: per query module the segment it hangs from (the last drawn on its
    #: path, -1: none) and 1 if it starts a side branch (after a ``[``, before any ``F``)
    query_links: np.ndarray | None = None


def _rot(a, b, c, s):
    """Rotate the pair (a, b) of 3-tuples by an angle with cosine c and sine s: a towards b."""
    return ((a[0] * c + b[0] * s, a[1] * c + b[1] * s, a[2] * c + b[2] * s),
            (b[0] * c - a[0] * s, b[1] * c - a[1] * s, b[2] * c - a[2] * s))


def interpret(ms: ModuleString, settings: TurtleSettings, materials: tuple[str, ...] = ("bark",),
              source: str = "<grammar>", limits: Limits | None = None) -> Skeleton:
    """The skeleton :func:`interpret_plant` draws (its polygons and warnings dropped)."""
    return interpret_plant(ms, settings, materials, source, limits).skeleton


def interpret_plant(ms: ModuleString, settings: TurtleSettings, materials: tuple[str, ...] = ("bark",),
                    source: str = "<grammar>", limits: Limits | None = None, *, queries: bool = False) -> Drawing:
    """Walk the turtle over ``ms``: the drawn segments as a Skeleton, the filled polygons,
    and the warnings (one line each, naming ``source``).

    Three phases: :func:`_turtle_program` keeps the modules the turtle acts on, as action
    codes with their arguments; :func:`_walk` moves the turtle and collects the segments'
    columns and the polygons; the columns become the skeleton's arrays, checked finite and
    within ``tol.max_coordinate``. More segments than ``limits.max_segments``, or more
    polygon vertices (``.`` and placed surfaces) than ``limits.max_polygon_vertices``, are
    refused before the walk. With ``queries``, the drawing also holds the turtle's state at
    each query and communication module (:attr:`Drawing.queries`: what the derivation's
    query pass writes into them).
    """
    limits = limits or default_limits
    drawn = _drawing_modules(ms, settings)
    limits.check("segments", len(drawn), f"{source}: segments drawn")
    limits.check("polygon_vertices", _polygon_vertices(ms, source), f"{source}: polygon vertices")
    builder = PolygonBuilder()
    placed: list = []
    recorded: list | None = [] if queries else None
    codes = _QUERY_CODES if queries else _CODES
    columns, stray_dots = _walk(_turtle_program(ms, codes), settings, materials, source, builder, placed,
                                recorded)
    starts, ends, r0s, r1s, parents, conts, mats = columns
    n = len(ends)
    skel = Skeleton(
        start=np.array(starts, dtype=np.float64).reshape(n, 3),
        end=np.array(ends, dtype=np.float64).reshape(n, 3),
        r_start=np.array(r0s, dtype=np.float64),
        r_end=np.array(r1s, dtype=np.float64),
        parent=np.array(parents, dtype=np.int64),
        continues=np.array(conts, dtype=bool),
        material=np.array(mats, dtype=np.int32),
        material_names=materials,
    )
    _check_extent(skel, ms, drawn, source)
    _place_surfaces(placed, builder)
    polygons = builder.build()
    if len(polygons) and not np.all(np.abs(polygons.vertices) <= tol.max_coordinate):
        raise PlantgenError(f"{source}: a polygon vertex is not finite or beyond {tol.max_coordinate:g}: "
                            "an f or G length or the turtle step too large")
    states = links = None
    if recorded is not None:
        states = np.array([r[:4] for r in recorded], dtype=np.float64).reshape(-1, 4, 3)
        links = np.array([r[4:] for r in recorded], dtype=np.int64).reshape(-1, 2)
    return Drawing(skel, polygons, tuple(_warnings(ms, source, stray_dots, builder.degenerate)), states, links)


def _warnings(ms: ModuleString, source: str, stray_dots: int, degenerate: int) -> list[str]:
    """One line per symbol of :data:`UNSUPPORTED` in ``ms``, then the stray ``.`` and the
    polygons dropped."""
    out = []
    counts = np.bincount(ms.sym, minlength=len(ms.symbols)) if len(ms) else np.zeros(len(ms.symbols), int)
    for code, name in enumerate(ms.symbols):
        if name in UNSUPPORTED and counts[code]:
            out.append(unsupported_warning(source, name, int(counts[code])))
    if stray_dots:
        out.append(f"{source}: warning: {stray_dots:,} '.' outside any polygon '{{ }}' recorded nothing")
    if degenerate:
        out.append(f"{source}: warning: {degenerate:,} polygon(s) with fewer than 3 distinct vertices or "
                   "no area were not drawn")
    return out


def _polygon_vertices(ms: ModuleString, source: str) -> int:
    """The polygon vertices ``ms`` records with ``.`` and places with ``~``; a ``~`` whose
    surface index is not one of :data:`surfaces.SURFACES` stops with one line."""
    total = int(np.count_nonzero(_runs(ms, Action.VERTEX)))
    rows = np.flatnonzero(_runs(ms, Action.SURFACE))
    if not len(rows):
        return total
    index = ms.params[rows, 0] if ms.params.shape[1] else np.full(len(rows), -1.0)
    known = np.arange(len(surfaces.SURFACES))
    bad = ~np.isin(index, known) | (ms.nparam[rows] < 1)
    if bad.any():
        raise PlantgenError(f"{source}: {by_action(Action.SURFACE)!r} in module {int(rows[np.argmax(bad)]) + 1} "
                            f"of the derived string names no surface (known: {', '.join(surfaces.SURFACES)})")
    counts = np.array([surfaces.surface(int(k)).vertex_count for k in known])
    return total + int(counts[index.astype(np.int64)].sum())


def _place_surfaces(placed: list, builder: PolygonBuilder) -> None:
    """Hand the surfaces ``~`` placed (tuples of surface index, position, H, L, U, scale,
    material, segment hung from, in string order) to ``builder``, transformed in one batch
    per run of the same surface."""
    start = 0
    while start < len(placed):
        index = placed[start][0]
        stop = start
        while stop < len(placed) and placed[stop][0] == index:
            stop += 1
        rows = placed[start:stop]
        placed_copies = surfaces.place(index, [r[1] for r in rows], [(r[2], r[3], r[4]) for r in rows],
                                       [r[5] for r in rows], [r[6] for r in rows])
        per_copy = len(surfaces.surface(index).polygons.material)
        builder.extend(placed_copies.hung_from(np.repeat([r[7] for r in rows], per_copy)))
        start = stop


def _drawing_modules(ms: ModuleString, settings: TurtleSettings) -> np.ndarray:
    """(k,) int: the modules that draw a segment (``F`` of non-zero length), in order."""
    draws = _runs(ms, Action.DRAW)
    if not draws.any():
        return np.zeros(0, dtype=np.int64)
    length = np.where(ms.nparam > 0, ms.params[:, 0], settings.step)
    return np.flatnonzero(draws & (length != 0.0))


def _runs(ms: ModuleString, action: Action) -> np.ndarray:
    """(n,) bool: the modules of ``ms`` whose symbol runs ``action``."""
    char = by_action(action)
    return ms.sym == ms.symbols.index(char) if char in ms.symbols else np.zeros(len(ms), dtype=bool)


def _check_extent(skel: Skeleton, ms: ModuleString, drawn: np.ndarray, source: str) -> None:
    """One line naming the first segment (and the module that drew it) whose end points or
    radii are not finite or lie beyond ``tol.max_coordinate``."""
    limit = tol.max_coordinate
    with np.errstate(invalid="ignore"):
        bad = ~(np.all(np.abs(skel.start) <= limit, axis=1) & np.all(np.abs(skel.end) <= limit, axis=1)
                & (skel.r_start <= limit) & (skel.r_end <= limit))
    if not bad.any():
        return
    i = int(np.argmax(bad))
    what = ("a radius" if np.all(np.abs(skel.end[i]) <= limit) and np.all(np.abs(skel.start[i]) <= limit)
            else "an end point")
    module = int(drawn[i])
    k = int(ms.nparam[module])
    text = by_action(Action.DRAW) + ("(" + ", ".join(f"{x:g}" for x in ms.params[module, :k]) + ")" if k else "")
    raise PlantgenError(f"{source}: segment {i} (module {module + 1} of the derived string, {text}) has "
                        f"{what} that is not finite or beyond {limit:g}: an F length, a radius or "
                        "the turtle step too large")


def _turtle_program(ms: ModuleString, codes: dict | None = None):
    """The modules the turtle acts on, as an iterator of (action code, parameter count,
    first parameter, second parameter (0.0 where absent)). Other symbols are dropped. The
    tuples are made PROGRAM_CHUNK modules at a time: a string of millions of modules is
    never held as Python objects all at once. ``codes`` (symbol -> action code; default
    the drawing's) says which symbols the turtle acts on."""
    codes = _CODES if codes is None else codes
    table = np.array([codes.get(s, Action.NONE) for s in ms.symbols] or [Action.NONE], dtype=np.int8)
    action = table[ms.sym]
    keep = np.flatnonzero(action != Action.NONE)

    def chunks():
        for lo in range(0, len(keep), PROGRAM_CHUNK):
            rows = keep[lo:lo + PROGRAM_CHUNK]
            args2 = ms.params[rows, 1].tolist() if ms.params.shape[1] > 1 else [0.0] * len(rows)
            yield zip(action[rows].tolist(), ms.nparam[rows].tolist(), ms.params[rows, 0].tolist(), args2,
                      strict=True)

    return chain.from_iterable(chunks())


class Turtle:
    """The turtle's state during one walk, and one handler per kind of action.

    A handler takes the action code, the parameter count and the first two parameters
    (0.0 where absent) of one module; :data:`HANDLERS` says which handler runs each
    :class:`Action`. The state is the position, the frame H, L, U, the radius, the
    material, the last segment drawn from this state (``last``, -1: none, the chain
    broken), the last segment drawn on this path, moves or not (``hang``: what a leaf hangs
    from), and whether the next segment starts a side branch; ``[`` pushes it, ``]`` pops
    it. The open polygons (innermost last: dot vertices, move vertices, segment hung from)
    are not part of it. ``segments`` collects seven values per segment drawn, one flat
    list (cheaper on the hot path than a list per column or a tuple per row): start and end
    (x, y, z), start and end radius, parent (-1 for a root), continues flag, material.
    """

    __slots__ = ("step", "width_factor", "default_turn", "tropism", "tropism_strength", "materials", "source",
                 "builder", "placed", "pos", "frame", "width", "material", "last", "hang", "side", "stack",
                 "polygons", "stray_dots", "segments", "queries")

    def __init__(self, settings: TurtleSettings, materials: tuple[str, ...], source: str,
                 builder: PolygonBuilder, placed: list):
        self.step, self.width_factor = settings.step, settings.width_factor
        self.default_turn = (cos(radians(settings.angle)), sin(radians(settings.angle)))
        self.tropism, self.tropism_strength = settings.tropism_direction, settings.tropism_strength
        self.materials, self.source, self.builder, self.placed = materials, source, builder, placed
        self.pos = (0.0, 0.0, 0.0)
        self.frame = ((0.0, 1.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 0.0, 1.0))    # H, L, U
        self.width = settings.radius
        self.material = 0
        self.last = self.hang = -1
        self.side = False
        self.stack, self.polygons, self.segments = [], [], []
        self.stray_dots = 0
        self.queries = None

    def draw(self, act, n, length, end_radius):
        """``F``: a segment along H (of ``step`` without parameters; none of length 0),
        tapering to ``end_radius`` where given; then tropism bends H."""
        if not n:
            length = self.step
        if length == 0.0:
            return
        r_start = self.width
        if n == 2:
            if end_radius < 0:
                raise PlantgenError(f"{self.source}: negative radius {end_radius:g} given to "
                                    f"{by_action(Action.DRAW)}")
            self.width = end_radius
        start = px, py, pz = self.pos
        H, L, U = self.frame
        self.pos = end = (px + H[0] * length, py + H[1] * length, pz + H[2] * length)
        last, segments = self.last, self.segments
        cont = last >= 0 and not self.side
        segments.extend((start, end, segments[7 * last + 3] if cont else r_start, self.width, last, cont,
                         self.material))
        self.last = self.hang = len(segments) // 7 - 1
        self.side = False
        if self.tropism_strength != 0.0:
            self.frame = _bend_towards(H, L, U, self.tropism, self.tropism_strength)

    def move(self, act, n, length, _):
        """``f`` and ``G``: move along H without drawing, breaking the chain of segments;
        ``f`` records a vertex of the innermost open polygon (used if it has no dots)."""
        if not n:
            length = self.step
        px, py, pz = self.pos
        H = self.frame[0]
        self.pos = (px + H[0] * length, py + H[1] * length, pz + H[2] * length)
        self.last = -1
        self.side = False
        if act == _MOVE and self.polygons:
            _record(self.polygons[-1][1], self.pos, self.source)

    def turn(self, act, n, angle, _):
        """``+`` and ``-``: turn left or right about U."""
        c, s = (cos(radians(angle)), sin(radians(angle))) if n else self.default_turn
        if act == _TURN_RIGHT:
            s = -s
        H, L, U = self.frame
        H, L = _rot(H, L, c, s)
        self.frame = (H, L, U)

    def pitch(self, act, n, angle, _):
        """``&`` and ``^``: pitch down or up about L."""
        c, s = (cos(radians(angle)), sin(radians(angle))) if n else self.default_turn
        if act == _PITCH_UP:
            s = -s
        H, L, U = self.frame
        H, U = _rot(H, (-U[0], -U[1], -U[2]), c, s)
        self.frame = (H, L, (-U[0], -U[1], -U[2]))

    def roll(self, act, n, angle, _):
        """``\\`` and ``/``: roll left or right about H."""
        c, s = (cos(radians(angle)), sin(radians(angle))) if n else self.default_turn
        if act == _ROLL_RIGHT:
            s = -s
        H, L, U = self.frame
        L, U = _rot(L, U, c, s)
        self.frame = (H, L, U)

    def turn_around(self, act, n, arg, arg2):
        """``|``: 180° about U."""
        H, L, U = self.frame
        self.frame = ((-H[0], -H[1], -H[2]), (-L[0], -L[1], -L[2]), U)

    def level(self, act, n, arg, arg2):
        """``$``: roll about H so that L is horizontal."""
        H, L, U = self.frame
        self.frame = (H, *_level_left(H, L, U))

    def push(self, act, n, arg, arg2):
        """``[``: save the state; the next segment starts a side branch."""
        self.stack.append((self.pos, self.frame, self.width, self.material, self.last, self.side, self.hang))
        self.side = True

    def pop(self, act, n, arg, arg2):
        """``]``: restore the state saved by the matching ``[``."""
        if not self.stack:
            raise PlantgenError(f"{self.source}: unbalanced brackets in the derived string")
        self.pos, self.frame, self.width, self.material, self.last, self.side, self.hang = self.stack.pop()

    def set_width(self, act, n, width, _):
        """``!``: set the radius, or multiply it by ``width_factor``."""
        self.width = width = width if n else self.width * self.width_factor
        if width < 0:
            raise PlantgenError(f"{self.source}: negative radius {width:g} set by {by_action(Action.WIDTH)!r}")

    def select_material(self, act, n, index, _):
        """``;`` selects material ``index``; ``;`` without it and ``'`` select the next one."""
        count = len(self.materials)
        self.material = material = int(index) if act == _MATERIAL and n else (self.material + 1) % count
        if not 0 <= material < count:
            raise PlantgenError(f"{self.source}: material index {material} outside the grammar's "
                                f"{count} materials {list(self.materials)}")

    def open_polygon(self, act, n, arg, arg2):
        """``{``: a new innermost polygon, its first move vertex the position."""
        self.polygons.append(([], [self.pos], self.hang))

    def close_polygon(self, act, n, arg, arg2):
        """``}``: hand the innermost polygon (its dots, or else its moves) to the builder."""
        if not self.polygons:
            raise PlantgenError(f"{self.source}: '}}' without an open polygon '{{' in the derived string")
        dots, moves, from_segment = self.polygons.pop()
        self.builder.add(dots or moves, self.material, from_segment)

    def vertex(self, act, n, arg, arg2):
        """``.``: the position, a vertex of the innermost polygon (counted as stray outside any)."""
        if self.polygons:
            _record(self.polygons[-1][0], self.pos, self.source)
        else:
            self.stray_dots += 1

    def place_surface(self, act, n, index, scale):
        """``~``: place surface ``index`` at the turtle, scaled (1 without a scale; nothing at 0)."""
        if n != 2:
            scale = 1.0
        if scale < 0:
            raise PlantgenError(f"{self.source}: negative scale {scale:g} given to {by_action(Action.SURFACE)!r} "
                                f"({surfaces.SURFACES[int(index)]})")
        if scale > 0:
            self.placed.append((int(index), self.pos, *self.frame, scale, self.material, self.hang))


    def query(self, act, n, arg, arg2):
        """A query or communication module (``?P`` ... ``?E``), in the query pass only:
        record the position, the frame H, L, U, the segment it hangs from and whether it
        starts a side branch."""
        H, L, U = self.frame
        self.queries.append((self.pos, H, L, U, self.hang, int(self.side)))


#: The handler the turtle runs for each :class:`Action` it draws (the cut runs in the derivation).
HANDLERS = {
    Action.DRAW: Turtle.draw, Action.MOVE: Turtle.move, Action.MOVE_NO_VERTEX: Turtle.move,
    Action.TURN_LEFT: Turtle.turn, Action.TURN_RIGHT: Turtle.turn,
    Action.PITCH_DOWN: Turtle.pitch, Action.PITCH_UP: Turtle.pitch,
    Action.ROLL_LEFT: Turtle.roll, Action.ROLL_RIGHT: Turtle.roll,
    Action.TURN_AROUND: Turtle.turn_around, Action.LEVEL: Turtle.level,
    Action.PUSH: Turtle.push, Action.POP: Turtle.pop, Action.WIDTH: Turtle.set_width,
    Action.MATERIAL: Turtle.select_material, Action.NEXT_MATERIAL: Turtle.select_material,
    Action.POLYGON_OPEN: Turtle.open_polygon, Action.POLYGON_CLOSE: Turtle.close_polygon,
    Action.VERTEX: Turtle.vertex, Action.SURFACE: Turtle.place_surface,
}
# plain ints for the handlers' comparisons (an IntEnum member compares more slowly)
_MOVE, _TURN_RIGHT, _PITCH_UP, _ROLL_RIGHT, _MATERIAL = (
    int(a) for a in (Action.MOVE, Action.TURN_RIGHT, Action.PITCH_UP, Action.ROLL_RIGHT, Action.MATERIAL))
#: Each symbol the turtle draws: its action code.
_CODES = {s.char: int(s.action) for s in SYMBOLS if s.action in HANDLERS}
#: The actions of the query and communication modules, which the query pass records.
_QUERY_ACTIONS = (Action.QUERY_POSITION, Action.QUERY_HEADING, Action.QUERY_UP, Action.QUERY_LEFT,
                  Action.COMMUNICATE)
_QUERY_CODES = {**_CODES, **{s.char: int(s.action) for s in SYMBOLS if s.action in _QUERY_ACTIONS}}


def _walk(program, settings: TurtleSettings, materials: tuple[str, ...], source: str,
          builder: PolygonBuilder, placed: list, recorded: list | None = None):
    """Run a :class:`Turtle` over ``program`` (see :func:`_turtle_program`), handing each
    closed polygon to ``builder`` and appending each surface ``~`` places to ``placed``
    (surface index, position, H, L, U, scale, material, segment hung from).

    Returns the segment columns as lists (start and end (x, y, z) tuples, start and end
    radius, parent index (-1 for a root), continues flag, material index) and the number of
    ``.`` met outside any polygon. With ``recorded`` (a list), the turtle's state at each
    query and communication module is appended to it.
    """
    turtle = Turtle(settings, materials, source, builder, placed)
    turtle.queries = recorded
    handlers = [None] * (max(Action) + 1)
    for action, handler in HANDLERS.items():
        handlers[action] = handler
    for action in _QUERY_ACTIONS:
        handlers[action] = Turtle.query
    for act, n, arg, arg2 in program:
        handlers[act](turtle, act, n, arg, arg2)
    if turtle.polygons:
        raise PlantgenError(f"{source}: {len(turtle.polygons)} polygon(s) '{{' not closed by '}}' in the derived "
                            "string")
    return tuple(turtle.segments[k::7] for k in range(7)), turtle.stray_dots


def _record(vertices: list, position, source: str) -> None:
    """Append a vertex to an open polygon, within :data:`MAX_POLYGON_VERTICES`."""
    if len(vertices) >= MAX_POLYGON_VERTICES:
        raise PlantgenError(f"{source}: a polygon with more than {MAX_POLYGON_VERTICES:,} vertices; "
                            "close it with '}' sooner")
    vertices.append(position)


def _bend_towards(H, L, U, tropism, e):
    """Tropism after a segment: H, L, U turned together about the axis H × T by
    ``e·|H × T|`` radians, bending H towards T (ABOP, section 2.3)."""
    tx, ty, tz = tropism
    ax, ay, az = H[1] * tz - H[2] * ty, H[2] * tx - H[0] * tz, H[0] * ty - H[1] * tx
    s = sqrt(ax * ax + ay * ay + az * az)
    if not s > tol.parallel:
        return H, L, U
    ax, ay, az = ax / s, ay / s, az / s
    alpha = e * s
    ca, sa = cos(alpha), sin(alpha)
    return (_rodrigues(H, ax, ay, az, ca, sa), _rodrigues(L, ax, ay, az, ca, sa),
            _rodrigues(U, ax, ay, az, ca, sa))


def _level_left(H, L, U):
    """``$``: roll about H so that L is horizontal: L = (V × H)/|V × H| with V = +y and
    U = H × L. (L, U) unchanged when H is vertical."""
    lx, lz = H[2], -H[0]
    s = sqrt(lx * lx + lz * lz)
    if not s > tol.parallel:
        return L, U
    L = (lx / s, 0.0, lz / s)
    U = (H[1] * L[2] - H[2] * L[1], H[2] * L[0] - H[0] * L[2], H[0] * L[1] - H[1] * L[0])
    return L, U


def _rodrigues(v, ax, ay, az, c, s):
    """Rotate v about the unit axis (ax, ay, az) by the angle with cosine c, sine s.

    The scalar twin of :func:`plantgen.geometry.vec.rotate` (same formula, same order of
    operations): the turtle turns one module at a time, where numpy's per-call cost would
    dominate."""
    vx, vy, vz = v
    d = (ax * vx + ay * vy + az * vz) * (1 - c)
    cx, cy, cz = ay * vz - az * vy, az * vx - ax * vz, ax * vy - ay * vx
    return (vx * c + cx * s + ax * d, vy * c + cy * s + ay * d, vz * c + cz * s + az * d)
