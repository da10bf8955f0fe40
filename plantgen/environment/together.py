"""Plants that grow together: one derivation step for all, in one shared space.

A scene with ``grow: together`` derives all its plants in lockstep: every plant applies
its rules once (:meth:`~plantgen.lsystem.derive.Derivation.rewrite`), every plant's string
is drawn and placed in the world, and only then is every plant's environment asked
(:meth:`~plantgen.lsystem.derive.Derivation.answer`), so each sees the others as they
stand after the same step, whatever their order. A ``light`` part traces its sky against
the other plants too (placed, in its own plant's frame), and takes the sky and the sun as
the world's, whatever the plant's rotation. Plants without query modules are drawn each
step all the same, for the others to see.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.meshes.polygons import Polygons
from ..geometry.skeletons.skeleton import Skeleton
from ..limits import QUERY_WORK, LimitError, Limits, Meter, hint
from ..lsystem.derive import Derivation, steps_floor
from ..lsystem.grammar import Grammar
from ..lsystem.strings import ModuleString
from ..lsystem.turtle import interpret_plant
from . import environment_for
from .light import Light

__all__ = ["TogetherPlant", "grow_together"]


@dataclass(frozen=True, eq=False)
class TogetherPlant:
    """One plant of a stand: its grammar, seed, steps, and where it stands (4 x 4 similarity)."""

    grammar: Grammar
    seed: int
    iterations: int | None
    matrix: np.ndarray


class _World:
    """Every plant's latest drawing, placed in the world, and its segments in all (a running
    total). Gathering the others for a plant's light is charged to ``work``, ``QUERY_WORK``
    a segment gathered, before it is done: a stand of P plants gathers P - 1 plants for
    each of them at every step, so its cost grows as P squared, and a large stand ends at
    the budget instead of running for hours."""

    def __init__(self, plants: list[TogetherPlant], work: Meter | None = None):
        self.plants, self.work = plants, work
        self.placed: list[tuple[Skeleton, Polygons] | None] = [None] * len(plants)
        self.segments = 0

    def put(self, i: int, skeleton: Skeleton, polygons: Polygons) -> None:
        m = self.plants[i].matrix
        if self.placed[i] is not None:
            self.segments -= len(self.placed[i][0])
        self.placed[i] = (skeleton.transformed(m), polygons.transformed(m))
        self.segments += len(skeleton)

    def others(self, i: int):
        """The other plants' (Skeleton, Polygons) in plant ``i``'s frame, None for none."""
        if self.work is not None:
            own = len(self.placed[i][0]) if self.placed[i] is not None else 0
            self.work.spend((self.segments - own) * QUERY_WORK, f"{self.plants[i].grammar.path}: the light of "
                                                                  f"plant {i + 1} of the stand, among the others")
        parts = [p for j, p in enumerate(self.placed) if j != i and p is not None]
        if not parts:
            return None
        back = np.linalg.inv(self.plants[i].matrix)
        skeletons = [s for s, _ in parts]
        offsets = np.cumsum([0] + [len(s) for s in skeletons])[:-1]
        return (Skeleton.concatenate(skeletons).transformed(back),
                Polygons.concatenate([p for _, p in parts], offsets).transformed(back))


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
