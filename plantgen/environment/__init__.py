"""The environment a grammar grows in: what answers its communication modules ``?E``.

Měch and Prusinkiewicz (1996) let a plant talk to an environment program: after each
derivation step the environment receives the communication modules with the turtle's
state at each, and writes its answers into their parameters. A grammar declares its
environment as a list of parts; each ``?E`` receives the answers of every part, in the
list's order, so ``?E`` has as many parameters as the parts answer together::

    environment:
      - envelope: {shape: ellipsoid, center: [0, 3, 0], radii: [2, 2.5, 2]}     # 1: signed distance
      - obstacle: {shapes: [{shape: box, center: [1, 4, 0], size: [0.2, 8, 8]}], reach: 20}
                                                    # 2: distance along H, inside (1) or not (0)
      - markers: {shape: {shape: ellipsoid, center: [0, 6, 0], radii: [4, 3, 4]},
                  density: 30, influence: 2, kill: 0.4}   # 3: mean direction to its markers (H, L, U)

* ``envelope``: the signed distance from the module to the shape (negative inside).
* ``obstacle``: the distance along the turtle's heading H to the nearest of the shapes
  (a wall, the slats of a trellis, a mesh), ``reach`` when none lies within it, and 1 if
  the module is inside one (then the distance is 0), else 0.
* ``markers``: space colonisation (Runions, Lane and Prusinkiewicz 2007). ``density``
  attraction points per unit volume are scattered in the shape (from the grammar's seed);
  after each step those within ``kill`` of the plant (a module ``?E`` or the end of a
  segment) are consumed, and each one left is assigned to the nearest ``?E`` within
  ``influence``. The answer is the unit mean of the directions to its markers, in the
  module's frame (components along H, L and U, so that ``+(deg(atan2(l, h)))`` turns
  towards it), zero when it has none.

Every value is typed and ranged; a mesh file is read only inside the grammar's folder.
The markers count against ``max_markers``. Each part answers the modules ``batch`` at a
time (a knob of memory, never of the answer).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import fields
from ..limits import Limits
from ..limits import limits as default_limits
from ..lsystem.grammar import Grammar
from ..lsystem.queries import QueryState
from ..tolerances import tol
from .light import Light
from .nearest import nearest_within
from .shapes import EnvError, Shape, batch_size, parse_shape

__all__ = ["Envelope", "Environment", "EnvError", "Light", "Markers", "Obstacles", "environment_for"]

class Envelope:
    """``envelope``: the signed distance to a shape."""

    width = 1
    keys = {"shape", "center", "size", "radii", "radius", "height", "file", "batch"}

    def __init__(self, d: dict, where: str, base: Path, limits: Limits, seed: int):
        self.batch = batch_size(d, where)
        self.shape = parse_shape({k: v for k, v in d.items() if k != "batch"}, where, base, limits)

    def answer(self, state: QueryState) -> np.ndarray:
        return np.concatenate([self.shape.distance(state.position[lo:lo + self.batch])
                               for lo in range(0, len(state), self.batch)] or [np.zeros(0)])[:, None]


class Obstacles:
    """``obstacle``: the distance along H to the nearest shape, and whether inside one."""

    width = 2
    keys = {"shapes", "reach", "batch"}

    def __init__(self, d: dict, where: str, base: Path, limits: Limits, seed: int):
        self.batch = batch_size(d, where)
        shapes = d.get("shapes")
        if not isinstance(shapes, list) or not shapes:
            raise EnvError(f"{where}: shapes must be a non-empty list of shapes")
        if len(shapes) > 1000:
            raise EnvError(f"{where}: {len(shapes):,} shapes, more than 1,000")
        self.shapes = [parse_shape(s, f"{where}: shape {i + 1}", base, limits) for i, s in enumerate(shapes)]
        self.reach = fields.number(d.get("reach", 100.0), "reach", where, EnvError, positive=True,
                                   max_abs=tol.max_coordinate)

    def answer(self, state: QueryState) -> np.ndarray:
        out = np.zeros((len(state), 2))
        for lo in range(0, len(state), self.batch):
            p, h = state.position[lo:lo + self.batch], state.heading[lo:lo + self.batch]
            inside = np.zeros(len(p), dtype=bool)
            t = np.full(len(p), np.inf)
            for shape in self.shapes:
                inside |= shape.distance(p) < 0
                t = np.minimum(t, shape.ray(p, h, self.reach))
            out[lo:lo + len(p), 0] = np.where(inside, 0.0, np.minimum(t, self.reach))
            out[lo:lo + len(p), 1] = inside
        return out


class Markers:
    """``markers``: space colonisation's attraction points, consumed as the plant reaches them."""

    width = 3
    keys = {"shape", "density", "influence", "kill", "batch"}

    def __init__(self, d: dict, where: str, base: Path, limits: Limits, seed: int):
        self.batch = batch_size(d, where)
        self.shape = parse_shape(d.get("shape"), f"{where}: shape", base, limits)
        density = fields.number(d.get("density", 10.0), "density (markers per unit volume)", where, EnvError,
                                positive=True)
        self.influence = fields.number(d.get("influence", 1.0), "influence", where, EnvError, positive=True,
                                       max_abs=tol.max_coordinate)
        self.kill = fields.number(d.get("kill", 0.2), "kill", where, EnvError, positive=True,
                                  hi=self.influence)
        count = density * self.shape.volume
        limits.check("markers", int(min(count, 2.0 ** 62)), f"{where}: markers (density x volume)")
        self.points = _scatter(self.shape, int(round(count)), np.random.default_rng([seed, 0x6D61726B]))

    def answer(self, state: QueryState) -> np.ndarray:
        skel = state.drawing.skeleton
        nodes = np.concatenate([state.position, skel.end, skel.start[:1]])
        _, reach = nearest_within(self.points, nodes, self.kill, self.batch)
        self.points = self.points[~np.isfinite(reach)]          # the markers the plant reached are consumed
        owner, _ = nearest_within(self.points, state.position, self.influence, self.batch)
        mine = owner >= 0
        v = self.points[mine] - state.position[owner[mine]]
        v /= np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-300)
        total = np.zeros((len(state), 3))
        np.add.at(total, owner[mine], v)
        norm = np.linalg.norm(total, axis=1, keepdims=True)
        world = np.where(norm > tol.parallel, total / np.maximum(norm, 1e-300), 0.0)
        return state.local(world)


PARTS = {"envelope": Envelope, "obstacle": Obstacles, "markers": Markers, "light": Light}


class Environment:
    """A grammar's environment: its parts, each answering its columns of ``?E``."""

    def __init__(self, parts: list):
        self.parts = parts
        self.width = sum(p.width for p in parts)

    def answer(self, state: QueryState) -> np.ndarray:
        if not self.parts:
            return np.zeros((len(state), 0))
        return np.concatenate([p.answer(state) for p in self.parts], axis=1)


def environment_for(grammar: Grammar, *, seed: int | None = None, limits: Limits | None = None) -> Environment | None:
    """The environment ``grammar`` declares (a fresh one: the markers' state is one
    derivation's), or None without one. ``seed`` (default the grammar's) seeds the markers."""
    raw = grammar.environment
    if raw is None:
        return None
    limits = limits or default_limits
    where = f"{grammar.path}: environment"
    if not isinstance(raw, list) or not raw:
        raise EnvError(f"{where}: must be a list of parts like '- envelope: {{shape: box, ...}}' "
                               f"(parts: {', '.join(PARTS)})")
    if len(raw) > 16:
        raise EnvError(f"{where}: {len(raw)} parts, more than 16")
    base = Path(grammar.path).parent
    seed = grammar.seed if seed is None else int(seed)
    parts = []
    for i, entry in enumerate(raw):
        at = f"{where}: part {i + 1}"
        if not isinstance(entry, dict) or len(entry) != 1 or next(iter(entry)) not in PARTS:
            raise EnvError(f"{at}: must be one of {', '.join(PARTS)} with its settings, got "
                                   f"{fields.show(entry)}")
        name, settings = next(iter(entry.items()))
        cls = PARTS[name]
        settings = fields.keys(settings if settings is not None else {}, cls.keys, f"{at} ({name})", EnvError)
        parts.append(cls(settings, f"{at} ({name})", base, limits, seed))
    return Environment(parts)


def _scatter(shape: Shape, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` points uniformly in ``shape`` (rejection from its bounding box)."""
    lo, hi = shape.bounds
    out, have = [], 0
    for _ in range(1000):
        if have >= count:
            break
        p = lo + (hi - lo) * rng.random((max(2 * (count - have), 64), 3))
        p = p[shape.distance(p) < 0]
        out.append(p)
        have += len(p)
    points = np.concatenate(out) if out else np.zeros((0, 3))
    return points[:count]
