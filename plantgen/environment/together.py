"""Plants that grow together: one derivation step for all, in one shared space.

A scene with ``grow: together`` derives all its plants in lockstep: every plant applies
its rules once (:meth:`~plantgen.lsystem.derive.Derivation.rewrite`), every plant's string
is drawn and placed in the world, and only then is every plant's environment asked
(:meth:`~plantgen.lsystem.derive.Derivation.answer`), so each sees the others as they
stand after the same step, whatever their order. A ``light`` part traces its sky against
the other plants too (placed, in its own plant's frame), and takes the sky and the sun as
the world's, whatever the plant's rotation. Plants without query modules are drawn each
step all the same, for the others to see. The others' branches are all traced; of their
leaves, only the clusters some ray of the step may reach (:class:`StandLeaves`), which
changes no ray's answer.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..geometry.meshes.polygons import Polygons
from ..geometry.rays.morton import morton_codes
from ..geometry.skeletons.skeleton import Skeleton
from ..limits import QUERY_WORK, LimitError, Limits, Meter, hint
from ..lsystem.derive import Derivation, steps_floor
from ..lsystem.grammar import Grammar
from ..lsystem.strings import ModuleString
from ..lsystem.turtle import interpret_plant
from . import environment_for
from .light import Light

__all__ = ["BLOCK", "CLUSTER", "Neighbours", "StandLeaves", "TogetherPlant", "grow_together"]


@dataclass(frozen=True, eq=False)
class TogetherPlant:
    """One plant of a stand: its grammar, seed, steps, and where it stands (4 x 4 similarity)."""

    grammar: Grammar
    seed: int
    iterations: int | None
    matrix: np.ndarray


#: Leaf triangles a cluster of a plant's leaves holds, and clusters a block: the light
#: culls the other plants' leaves a cluster at a time, a block's box first
#: (:meth:`StandLeaves.met`).
CLUSTER, BLOCK = 2, 16


class _Placed(NamedTuple):
    """A plant's drawing placed in the world: its skeleton, its leaves' vertices and
    triangles (as :meth:`Polygons.transformed` moves them), their polygons and segments,
    and its triangles in clusters (Morton order of their centres, :data:`CLUSTER` a
    cluster): ``order``, each cluster's first in it and its box (lo, hi), and each block's
    first cluster (:data:`BLOCK` a block)."""

    skeleton: Skeleton
    vertices: np.ndarray
    triangles: np.ndarray
    polygon: np.ndarray
    segment: np.ndarray
    order: np.ndarray
    first: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    block: np.ndarray


def _affine(points: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Points (n, 3) under the 4 x 4 ``m``: :meth:`Polygons.transformed`'s vertices, the
    same operations (numpy's matrix product, a row's result whatever rows come with it)."""
    m = np.asarray(m, dtype=np.float64)
    return points @ m[:3, :3].T + m[:3, 3]


def _facing(triangles: np.ndarray, m: np.ndarray) -> np.ndarray:
    """The triangles as :meth:`Polygons.transformed` keeps them under ``m`` (reversed where
    it mirrors)."""
    return triangles if np.linalg.det(np.asarray(m, dtype=np.float64)[:3, :3]) > 0 else triangles[:, ::-1].copy()


def _placed(skeleton: Skeleton, polygons: Polygons, m: np.ndarray) -> _Placed:
    vertices = _affine(polygons.vertices, m)
    triangles = _facing(np.asarray(polygons.triangles, np.int64).reshape(-1, 3), m)
    t = len(triangles)
    corners = vertices[triangles]
    order = np.argsort(morton_codes(corners.sum(axis=1)), kind="stable") if t else np.zeros(0, np.int64)
    first = np.r_[np.arange(0, t, CLUSTER), t].astype(np.int64)
    lo, hi = np.zeros((0, 3)), np.zeros((0, 3))
    if t:
        c = corners[order]
        lo = np.minimum.reduceat(np.minimum(np.minimum(c[:, 0], c[:, 1]), c[:, 2]), first[:-1], axis=0)
        hi = np.maximum.reduceat(np.maximum(np.maximum(c[:, 0], c[:, 1]), c[:, 2]), first[:-1], axis=0)
    c = len(first) - 1
    return _Placed(skeleton.transformed(m), vertices, triangles, np.asarray(polygons.polygon, np.int64),
                   np.asarray(polygons.segment, np.int64), order.astype(np.int64), first, lo, hi,
                   np.r_[np.arange(0, c, BLOCK), c].astype(np.int64))


class StandLeaves:
    """The other plants' leaves as plant ``i`` sees them (:meth:`_World.others`): ``segment``
    (p,), each of their polygons' segment among the other skeletons joined in order (-1:
    none), and :meth:`met`, the triangles some rays may meet, moved into the frame."""

    def __init__(self, world: _World, i: int, back: np.ndarray):
        self.world, self.i, self.back = world, i, back
        s = world.stand()
        own_polygons = s.polygon_first[i + 1] - s.polygon_first[i]
        own_segments = s.segment_first[i + 1] - s.segment_first[i]
        others = np.r_[0:s.polygon_first[i], s.polygon_first[i + 1]:s.polygon_first[-1]]
        after = others >= s.polygon_first[i + 1]
        seg = s.segment[others]
        self.segment = np.where(seg >= 0, seg - after * own_segments, -1).astype(np.int64)
        self.own_polygons = int(own_polygons)
        self.triangles_in_all = len(s.triangles) - int(s.triangle_first[i + 1] - s.triangle_first[i])

    def __len__(self) -> int:
        return self.triangles_in_all

    def met(self, origins: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Vertices (v, 3) in the frame, triangles (k, 3) into them and each one's polygon
        (k,) among the others': the triangles of every cluster that some ray (``origins``,
        ``dirs``) may meet (:func:`~plantgen.geometry.rays.native_cull.boxes_met`), in the
        order the others' leaves join. A triangle left out is one whose padded box no
        ray's box test passes, so no ray's any hit changes without it. Its vertices are
        moved into the frame as :meth:`Polygons.transformed` moves them all."""
        from ..geometry.rays.native_cull import boxes_met

        s = self.world.stand()
        met = boxes_met(s.lo, s.hi, s.block, s.group, origins, dirs, matrix=self.back, skip=self.i, box=s.box)
        keep = np.flatnonzero(met[s.cluster])
        kept = s.triangles[keep]
        used = np.zeros(len(s.vertices), bool)         # np.unique's sorted corners and inverse, without its sort
        used[kept] = True
        corners = np.flatnonzero(used)
        number = np.empty(len(s.vertices), np.int64)
        number[corners] = np.arange(len(corners))
        at = number[kept]
        vertices = _affine(s.vertices[corners], self.back)
        polygon = s.polygon[keep]
        polygon = polygon - (polygon >= s.polygon_first[self.i + 1]) * self.own_polygons
        return vertices, _facing(at.reshape(-1, 3).astype(np.int64), self.back), polygon.astype(np.int64)


class _Stand(NamedTuple):
    """Every plant's placed leaves joined (plant by plant), their clusters numbered across
    all: vertices, triangles (into them), each triangle's polygon, each polygon's segment
    (among the skeletons joined), the clusters' boxes (lo, hi), each triangle's cluster,
    each block's first cluster (``block``), each plant's first block (``group``), and
    each plant's first polygon, segment and triangle; and ``box``, (lo, hi) side by side
    (:func:`~plantgen.geometry.rays.native_cull.boxes_met`'s)."""

    vertices: np.ndarray
    triangles: np.ndarray
    polygon: np.ndarray
    segment: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    cluster: np.ndarray
    block: np.ndarray
    group: np.ndarray
    polygon_first: np.ndarray
    segment_first: np.ndarray
    triangle_first: np.ndarray
    box: np.ndarray


def _stand(placed: list[_Placed]) -> _Stand:
    first = lambda sizes: np.cumsum([0] + list(sizes)).astype(np.int64)  # noqa: E731
    vertex_first = first(len(p.vertices) for p in placed)
    triangle_first = first(len(p.triangles) for p in placed)
    polygon_first = first(len(p.segment) for p in placed)
    segment_first = first(len(p.skeleton) for p in placed)
    clusters = first(len(p.first) - 1 for p in placed)
    block = np.r_[np.concatenate([p.block[:-1] + k for p, k in zip(placed, clusters, strict=False)]),
                  clusters[-1]].astype(np.int64)
    group = first(len(p.block) - 1 for p in placed)
    cluster = np.empty(int(triangle_first[-1]), np.int64)
    for j, p in enumerate(placed):
        where = np.repeat(np.arange(len(p.first) - 1), np.diff(p.first)) + clusters[j]
        cluster[triangle_first[j] + p.order] = where
    cat = lambda arrays, shape: np.concatenate(list(arrays)).reshape(shape)  # noqa: E731
    lo, hi = cat((p.lo for p in placed), (-1, 3)), cat((p.hi for p in placed), (-1, 3))
    return _Stand(cat((p.vertices for p in placed), (-1, 3)),
                  cat((p.triangles + v for p, v in zip(placed, vertex_first, strict=False)), (-1, 3)),
                  cat((p.polygon + k for p, k in zip(placed, polygon_first, strict=False)), (-1,)),
                  cat((np.where(p.segment >= 0, p.segment + o, -1) for p, o in zip(placed, segment_first,
                                                                                   strict=False)), (-1,)),
                  lo, hi, cluster, block, group, polygon_first, segment_first, triangle_first,
                  np.ascontiguousarray(np.concatenate([lo, hi], axis=1), np.float64))


class Neighbours(NamedTuple):
    """The other plants in one plant's frame: their skeleton, joined in order, and their
    leaves (:class:`StandLeaves`)."""

    skeleton: Skeleton
    leaves: StandLeaves


class _World:
    """Every plant's latest drawing, placed in the world, and its segments in all (a running
    total). Gathering the others for a plant's light is charged to ``work``, ``QUERY_WORK``
    a segment gathered, before it is done: a stand of P plants gathers P - 1 plants for
    each of them at every step, so its cost grows as P squared, and a large stand ends at
    the budget instead of running for hours."""

    def __init__(self, plants: list[TogetherPlant], work: Meter | None = None):
        self.plants, self.work = plants, work
        self.placed: list[_Placed | None] = [None] * len(plants)
        self.segments = 0
        self._stand: _Stand | None = None
        self._joined: tuple[Skeleton, np.ndarray, bool] | None = None

    def put(self, i: int, skeleton: Skeleton, polygons: Polygons) -> None:
        m = self.plants[i].matrix
        if self.placed[i] is not None:
            self.segments -= len(self.placed[i][0])
        self.placed[i] = _placed(skeleton, polygons, m)
        self.segments += len(skeleton)
        self._stand = None
        self._joined = None

    def stand(self) -> _Stand:
        """Every plant's leaves joined (built once after the plants last moved; a plant not
        drawn yet counts as none)."""
        if self._stand is None:
            empty = _placed(Skeleton.empty(), Polygons.empty(), np.eye(4))
            self._stand = _stand([p if p is not None else empty for p in self.placed])
        return self._stand

    def others(self, i: int) -> Neighbours | None:
        """The other plants in plant ``i``'s frame (:class:`Neighbours`), None for none: their
        skeletons joined in the world and moved back into the frame together, as
        :meth:`Skeleton.transformed` moves them, and their leaves (:class:`StandLeaves`)."""
        if self.work is not None:
            own = len(self.placed[i][0]) if self.placed[i] is not None else 0
            self.work.spend((self.segments - own) * QUERY_WORK, f"{self.plants[i].grammar.path}: the light of "
                                                                  f"plant {i + 1} of the stand, among the others")
        parts = [p for j, p in enumerate(self.placed) if j != i and p is not None]
        if not parts:
            return None
        back = np.linalg.inv(self.plants[i].matrix)
        return Neighbours(self._others_joined(i, parts).transformed(back), StandLeaves(self, i, back))

    def _others_joined(self, i: int, parts: list[_Placed]) -> Skeleton:
        """The placed skeletons but plant ``i``'s, joined in order: what
        :meth:`Skeleton.concatenate` makes of them. Where every plant's material names are
        the same (no index remapped), the rows of all the plants joined once after they
        last moved, plant ``i``'s left out and the parents after them moved down."""
        if self._joined is None:
            placed = [p.skeleton if p is not None else Skeleton.empty() for p in self.placed]
            every = [p.skeleton for p in self.placed if p is not None]
            joined = Skeleton.concatenate(every)
            self._joined = (joined, np.cumsum([0] + [len(p) for p in placed]).astype(np.int64),
                            all(p.material_names == joined.material_names for p in every))
        joined, first, same = self._joined
        if not same:
            return Skeleton.concatenate([p.skeleton for p in parts])
        a, b = int(first[i]), int(first[i + 1])
        rows = np.r_[0:a, b:len(joined)]
        parent = joined.parent[rows]
        return Skeleton(joined.start[rows], joined.end[rows], joined.r_start[rows], joined.r_end[rows],
                        np.where(parent >= b, parent - (b - a), parent), joined.continues[rows], joined.material[rows],
                        joined.material_names)


def _check_steps(plants: list[TogetherPlant], limits: Limits, work: Meter | None) -> None:
    """Refuse a stand whose plants' steps alone would spend past ``work``: plants grown
    together take every step they are given (none settles early), each spending at least
    its floor (``STEP_WORK`` a rule group, plus one), so the sum is known before the first
    step, from each grammar's rule groups and step count (O(1) a plant)."""
    if work is None:
        return
    floors: dict = {}
    total = work.spent
    for plant in plants:
        key = (id(plant.grammar), plant.iterations)
        if key not in floors:
            floors[key] = steps_floor(plant.grammar, plant.iterations)
        total += floors[key]
    if total > work.limit:
        raise LimitError(f"{plants[0].grammar.path}: {len(plants):,} plants grown together take steps that spend at "
                         f"least {total:,} of derive_work, over the limit of {work.limit:,} ({hint(work.name)})")


def grow_together(plants: list[TogetherPlant], *, limits: Limits, work: Meter | None = None,
                  progress=None) -> list[ModuleString]:
    """Derive ``plants`` in lockstep in one shared space (see the module's notes): their
    derived strings, in order. ``progress(step, modules)`` after each step, all plants'
    modules together. A stand whose steps alone would spend past ``work`` is refused before
    any plant derives (:func:`_check_steps`); each plant's drawing for the others, a turtle
    walk over its string after every step, is charged to ``work`` (``QUERY_WORK`` a module)
    before it is taken, as the query pass is."""
    _check_steps(plants, limits, work)
    world = _World(plants, work)
    runs = []
    for i, plant in enumerate(plants):
        env = environment_for(plant.grammar, seed=plant.seed, limits=limits)
        for part in env.parts if env is not None else ():
            if isinstance(part, Light):
                lin = plant.matrix[:3, :3]
                part.neighbours = lambda i=i: world.others(i)
                part.rotation = lin / np.cbrt(abs(np.linalg.det(lin)))
        runs.append(Derivation(plant.grammar, plant.iterations, plant.seed, limits=limits, work=work,
                               environment=env, together=True))
    moved = list(range(len(runs)))
    step = 0
    while moved:
        for i in moved:
            run = runs[i]
            run.interpret()
            drawing = run.queries.pending[3] if run.queries is not None else None
            if drawing is None:
                if work is not None:
                    work.spend(len(run.string[0]) * QUERY_WORK, f"{run.grammar.path}: drawn for the stand after "
                                                                f"step {step}")
                drawing = interpret_plant(run.result(), run.grammar.turtle, run.grammar.materials, run.grammar.path,
                                          limits)
            world.put(i, drawing.skeleton, drawing.polygons)
        for i in moved:
            runs[i].answer()
        if step and progress is not None:
            progress(step, sum(len(r.string[0]) for r in runs))
        moved = [i for i, run in enumerate(runs) if run.rewrite()]
        step += 1
    return [run.result() for run in runs]
