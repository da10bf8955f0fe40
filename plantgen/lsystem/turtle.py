"""Turtle interpretation: a derived module string to a :class:`Skeleton`.

Coordinates are y-up (as in Bhagvat et al. 2009). The turtle starts at the origin with
heading H = +y, left L = -x and up U = H × L = +z. Symbols, with ABOP's meanings:

=========  ===================================================================
``F(l)``   draw a segment of length l (default ``step``) along H;
           ``F(l, w)`` also tapers it to end radius w (and sets the radius to w)
``f(l)``   move by l without drawing; the next segment starts a new root
``+(a)``   turn left by a degrees (default ``angle``) about U;  ``-`` turns right
``&(a)``   pitch down about L;  ``^`` pitches up
``\\(a)``  roll left about H;  ``/`` rolls right
``|``      turn around (180° about U)
``[`` ``]``  push and pop the turtle state; the first segment after ``[`` starts a
           side branch (``continues`` False), the first after ``]`` carries on the
           axis the branch grew from (``continues`` True)
``!(w)``   set the radius to w; ``!`` multiplies it by ``width_factor``
``$``      roll about H so that L is horizontal
``;(i)``   select material i (index into the grammar's ``materials``); ``;`` the next one,
           cycling
``'``      the next material, cycling (ABOP's colour index step)
``G(l)``   move by l without drawing and without recording a polygon vertex; like ``f``,
           the next segment starts a new root
``{``      start a polygon; ``}`` closes the innermost open polygon, fills it with the
           current material and triangulates it (concave outlines too)
``.``      record the turtle's position as a vertex of the innermost open polygon
``~(n, s)``  place the built-in surface named n (``leaf``, ``needles``: see
           :mod:`plantgen.geometry.surfaces`) at the turtle, oriented by H, L, U and
           scaled by s (default 1), in the current material; the turtle does not move
=========  ===================================================================

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
from ..geometry import surfaces
from ..geometry.polygons import PolygonBuilder, Polygons
from ..geometry.skeleton import Skeleton
from ..limits import Limits
from ..limits import limits as default_limits
from ..tolerances import tol
from .derive import ModuleString
from .grammar import TurtleSettings

__all__ = ["Drawing", "MAX_POLYGON_VERTICES", "UNSUPPORTED", "interpret", "interpret_plant"]

# action codes
(_NONE, _F, _f, _PLUS, _MINUS, _AND, _HAT, _BSL, _SL, _BAR, _PUSH, _POP, _WIDTH, _ROLLH, _MAT,
 _G, _OPEN, _CLOSE, _DOT, _TICK, _SURF) = range(21)
#: Modules turned into Python values at a time by :func:`_turtle_program`.
PROGRAM_CHUNK = 65_536

_ACTIONS = {"F": _F, "f": _f, "+": _PLUS, "-": _MINUS, "&": _AND, "^": _HAT, "\\": _BSL,
            "/": _SL, "|": _BAR, "[": _PUSH, "]": _POP, "!": _WIDTH, "$": _ROLLH, ";": _MAT,
            "G": _G, "{": _OPEN, "}": _CLOSE, ".": _DOT, "'": _TICK, "~": _SURF}

#: Symbols with a turtle meaning in ABOP (or its program cpfg) that plantgen does not draw
#: (yet): each present in a string being drawn gets one warning naming it.
UNSUPPORTED = {
    "@": "cpfg's spheres and circles",
    "#": "cpfg's width increment",
}
#: The most vertices one polygon may have (ear clipping is quadratic in them).
MAX_POLYGON_VERTICES = 4096


@dataclass(frozen=True, eq=False)
class Drawing:
    """What the turtle drew: the skeleton's segments, the filled polygons, and one line per
    thing it skipped (to be shown to the user)."""

    skeleton: Skeleton
    polygons: Polygons
    warnings: tuple[str, ...] = ()


def _rot(a, b, c, s):
    """Rotate the pair (a, b) of 3-tuples by an angle with cosine c and sine s: a towards b."""
    return ((a[0] * c + b[0] * s, a[1] * c + b[1] * s, a[2] * c + b[2] * s),
            (b[0] * c - a[0] * s, b[1] * c - a[1] * s, b[2] * c - a[2] * s))


def interpret(ms: ModuleString, settings: TurtleSettings, materials: tuple[str, ...] = ("bark",),
              source: str = "<grammar>", limits: Limits | None = None) -> Skeleton:
    """The skeleton :func:`interpret_plant` draws (its polygons and warnings dropped)."""
    return interpret_plant(ms, settings, materials, source, limits).skeleton


def interpret_plant(ms: ModuleString, settings: TurtleSettings, materials: tuple[str, ...] = ("bark",),
                    source: str = "<grammar>", limits: Limits | None = None) -> Drawing:
    """Walk the turtle over ``ms``: the drawn segments as a Skeleton, the filled polygons,
    and the warnings (one line each, naming ``source``).

    Three phases: :func:`_turtle_program` keeps the modules the turtle acts on, as action
    codes with their arguments; :func:`_walk` moves the turtle and collects the segments'
    columns and the polygons; the columns become the skeleton's arrays, checked finite and
    within ``tol.max_coordinate``. More segments than ``limits.max_segments``, or more
    polygon vertices (``.`` and placed surfaces) than ``limits.max_polygon_vertices``, are
    refused before the walk.
    """
    limits = limits or default_limits
    drawn = _drawing_modules(ms, settings)
    limits.check("segments", len(drawn), f"{source}: segments drawn")
    limits.check("polygon_vertices", _polygon_vertices(ms, source), f"{source}: polygon vertices")
    builder = PolygonBuilder()
    placed: list = []
    columns, stray_dots = _walk(_turtle_program(ms), settings, materials, source, builder, placed)
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
    return Drawing(skel, polygons, tuple(_warnings(ms, source, stray_dots, builder.degenerate)))


def _warnings(ms: ModuleString, source: str, stray_dots: int, degenerate: int) -> list[str]:
    """One line per symbol of :data:`UNSUPPORTED` in ``ms``, then the stray ``.`` and the
    polygons dropped."""
    out = []
    counts = np.bincount(ms.sym, minlength=len(ms.symbols)) if len(ms) else np.zeros(len(ms.symbols), int)
    for code, name in enumerate(ms.symbols):
        if name in UNSUPPORTED and counts[code]:
            out.append(f"{source}: warning: {name!r} ({UNSUPPORTED[name]}) has a turtle meaning in ABOP "
                       f"but none in plantgen yet; {int(counts[code]):,} module(s) not drawn")
    if stray_dots:
        out.append(f"{source}: warning: {stray_dots:,} '.' outside any polygon '{{ }}' recorded nothing")
    if degenerate:
        out.append(f"{source}: warning: {degenerate:,} polygon(s) with fewer than 3 distinct vertices or "
                   "no area were not drawn")
    return out


def _polygon_vertices(ms: ModuleString, source: str) -> int:
    """The polygon vertices ``ms`` records with ``.`` and places with ``~``; a ``~`` whose
    surface index is not one of :data:`surfaces.SURFACES` stops with one line."""
    total = 0
    if "." in ms.symbols:
        total += int(np.count_nonzero(ms.sym == ms.symbols.index(".")))
    if "~" not in ms.symbols:
        return total
    rows = np.flatnonzero(ms.sym == ms.symbols.index("~"))
    index = ms.params[rows, 0] if ms.params.shape[1] else np.full(len(rows), -1.0)
    known = np.arange(len(surfaces.SURFACES))
    bad = ~np.isin(index, known) | (ms.nparam[rows] < 1)
    if bad.any():
        raise PlantgenError(f"{source}: '~' in module {int(rows[np.argmax(bad)]) + 1} of the derived string "
                            f"names no surface (known: {', '.join(surfaces.SURFACES)})")
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
    if "F" not in ms.symbols:
        return np.zeros(0, dtype=np.int64)
    is_f = ms.sym == ms.symbols.index("F")
    length = np.where(ms.nparam > 0, ms.params[:, 0], settings.step)
    return np.flatnonzero(is_f & (length != 0.0))


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
    text = "F" + ("(" + ", ".join(f"{x:g}" for x in ms.params[module, :k]) + ")" if k else "")
    raise PlantgenError(f"{source}: segment {i} (module {module + 1} of the derived string, {text}) has "
                        f"{what} that is not finite or beyond {limit:g}: an F length, a radius or "
                        "the turtle step too large")


def _turtle_program(ms: ModuleString):
    """The modules the turtle acts on, as an iterator of (action code, parameter count,
    first parameter, second parameter (0.0 where absent)). Other symbols are dropped. The
    tuples are made PROGRAM_CHUNK modules at a time: a string of millions of modules is
    never held as Python objects all at once."""
    table = np.array([_ACTIONS.get(s, _NONE) for s in ms.symbols] or [_NONE], dtype=np.int8)
    action = table[ms.sym]
    keep = np.flatnonzero(action != _NONE)

    def chunks():
        for lo in range(0, len(keep), PROGRAM_CHUNK):
            rows = keep[lo:lo + PROGRAM_CHUNK]
            args2 = ms.params[rows, 1].tolist() if ms.params.shape[1] > 1 else [0.0] * len(rows)
            yield zip(action[rows].tolist(), ms.nparam[rows].tolist(), ms.params[rows, 0].tolist(), args2,
                      strict=True)

    return chain.from_iterable(chunks())


def _walk(program, settings: TurtleSettings, materials: tuple[str, ...], source: str,
          builder: PolygonBuilder, placed: list):
    """Run the turtle over ``program`` (see :func:`_turtle_program`), handing each closed
    polygon to ``builder`` and appending each surface ``~`` places to ``placed``
    (surface index, position, H, L, U, scale, material).

    Returns the segment columns as lists (start and end (x, y, z) tuples, start and end
    radius, parent index (-1 for a root), continues flag, material index) and the number of
    ``.`` met outside any polygon.
    """
    step, width_factor = settings.step, settings.width_factor
    dc, ds = cos(radians(settings.angle)), sin(radians(settings.angle))
    tropism = settings.tropism_direction
    e = settings.tropism_strength
    n_mat = len(materials)

    px = py = pz = 0.0
    H, L, U = (0.0, 1.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 0.0, 1.0)
    width = settings.radius
    material = 0
    last = -1            # last segment drawn from this state (-1: none, chain broken)
    hang = -1            # last segment drawn on this path, moves or not: what a leaf hangs from
    side = False         # next segment starts a side branch
    stack = []
    polygons = []        # open polygons, innermost last: (dot vertices, move vertices)
    stray_dots = 0

    starts, ends, r0s, r1s, parents, conts, mats = [], [], [], [], [], [], []

    for act, ha, arg, arg2 in program:
        if act == _F:
            length = arg if ha else step
            if length == 0.0:
                continue
            r_start = width
            if ha == 2:
                if arg2 < 0:
                    raise PlantgenError(f"{source}: negative radius {arg2:g} given to F")
                width = arg2
            ex, ey, ez = px + H[0] * length, py + H[1] * length, pz + H[2] * length
            cont = last >= 0 and not side
            starts.append((px, py, pz))
            ends.append((ex, ey, ez))
            r0s.append(r1s[last] if cont else r_start)
            r1s.append(width)
            parents.append(last)
            conts.append(cont)
            mats.append(material)
            last = hang = len(ends) - 1
            side = False
            px, py, pz = ex, ey, ez
            if e != 0.0:
                H, L, U = _bend_towards(H, L, U, tropism, e)
        elif act == _PLUS or act == _MINUS:  # noqa: SIM109 (a tuple of globals is built per module)
            c, s = (cos(radians(arg)), sin(radians(arg))) if ha else (dc, ds)
            if act == _MINUS:
                s = -s
            H, L = _rot(H, L, c, s)
        elif act == _AND or act == _HAT:  # noqa: SIM109
            c, s = (cos(radians(arg)), sin(radians(arg))) if ha else (dc, ds)
            if act == _HAT:
                s = -s
            H, U = _rot(H, (-U[0], -U[1], -U[2]), c, s)
            U = (-U[0], -U[1], -U[2])
        elif act == _BSL or act == _SL:  # noqa: SIM109
            c, s = (cos(radians(arg)), sin(radians(arg))) if ha else (dc, ds)
            if act == _SL:
                s = -s
            L, U = _rot(L, U, c, s)
        elif act == _BAR:
            H = (-H[0], -H[1], -H[2])
            L = (-L[0], -L[1], -L[2])
        elif act == _PUSH:
            stack.append((px, py, pz, H, L, U, width, material, last, side, hang))
            side = True
        elif act == _POP:
            if not stack:
                raise PlantgenError(f"{source}: unbalanced brackets in the derived string")
            px, py, pz, H, L, U, width, material, last, side, hang = stack.pop()
        elif act == _WIDTH:
            width = arg if ha else width * width_factor
            if width < 0:
                raise PlantgenError(f"{source}: negative radius {width:g} set by '!'")
        elif act == _f:
            length = arg if ha else step
            px, py, pz = px + H[0] * length, py + H[1] * length, pz + H[2] * length
            last = -1
            side = False
            if polygons:
                _record(polygons[-1][1], (px, py, pz), source)
        elif act == _G:
            length = arg if ha else step
            px, py, pz = px + H[0] * length, py + H[1] * length, pz + H[2] * length
            last = -1
            side = False
        elif act == _DOT:
            if polygons:
                _record(polygons[-1][0], (px, py, pz), source)
            else:
                stray_dots += 1
        elif act == _OPEN:
            polygons.append(([], [(px, py, pz)], hang))
        elif act == _CLOSE:
            if not polygons:
                raise PlantgenError(f"{source}: '}}' without an open polygon '{{' in the derived string")
            dots, moves, from_segment = polygons.pop()
            builder.add(dots or moves, material, from_segment)
        elif act == _TICK:
            material = (material + 1) % n_mat
        elif act == _SURF:
            scale = arg2 if ha == 2 else 1.0
            if scale < 0:
                raise PlantgenError(f"{source}: negative scale {scale:g} given to '~' "
                                    f"({surfaces.SURFACES[int(arg)]})")
            if scale > 0:
                placed.append((int(arg), (px, py, pz), H, L, U, scale, material, hang))
        elif act == _ROLLH:
            L, U = _level_left(H, L, U)
        elif act == _MAT:
            material = int(arg) if ha else (material + 1) % n_mat
            if not 0 <= material < n_mat:
                raise PlantgenError(f"{source}: material index {material} outside the grammar's "
                                    f"{n_mat} materials {list(materials)}")

    if polygons:
        raise PlantgenError(f"{source}: {len(polygons)} polygon(s) '{{' not closed by '}}' in the derived string")
    return (starts, ends, r0s, r1s, parents, conts, mats), stray_dots


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
