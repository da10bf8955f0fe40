"""``light``: the light reaching each ``?E`` from the sky and the sun, traced against the
plant grown so far (its branches and leaves) and the environment's obstacles.

The sky is ``directions`` directions over the upper hemisphere, one per equal solid angle
(a Fibonacci lattice: cos θ evenly spaced, the azimuth turned by the golden angle), each
weighted by the sky's radiance there: ``uniform`` (the same everywhere) or ``overcast``
(the CIE standard overcast sky, L(θ) ∝ (1 + 2 cos θ) / 3 for the zenith angle θ). The
weights sum to 1, so an open sky gives 1, and a bud under a disc of half-angle α
(uniform sky) receives cos α, the sky fraction outside the disc's solid angle
2π(1 - cos α). The quadrature's error falls as the directions grow: about 1/√N or less
(the tests state it). A ``sun`` adds its ``share`` of the light from one direction (the
direction the light travels, as a scene's light): the answer is
``(1 - share)·sky + share·sun``. The ground (below the horizon) receives no sky ray.

Each ray starts ``offset`` plus one and a half times the radius of the segment the module
hangs from away from the module, so a bud does not shade itself with its own branch
(its leaves do shade it). The plant's branches (skinned into frusta) and leaf triangles go
into one BVH (:mod:`plantgen.geometry.rays.bvh`), and every ray is traced by its float64
traversal, any hit (compiled, :mod:`plantgen.geometry.rays.native_trace`, where numba
runs); the obstacles' shapes by their own ray distance. Among plants grown together the
target holds the others' branches and only those of their leaves that a ray of the step
may reach (:class:`~plantgen.environment.together.StandLeaves`): the same answers, each
ray's any hit the same, for a fraction of the leaves.

The answer, 4 numbers (5 with ``allocation``): the light q, and the unit mean of the open
directions weighted by their light, in the module's frame (H, L, U; the direction a shoot
would turn to, zero when nothing is open). With ``allocation: {alpha, lambda}`` the fifth
is the bud's vigour v by the Borchert–Honda model (Palubicki et al. 2009): the light of
every bud is summed from the tips down to the base, the base receives ``alpha`` times the
total, and at every node the resource is shared among the main axis (weight
``lambda``·q) and each lateral branch (``1 - lambda``·q), up to each bud.

The rays a step traces count against ``max_light_rays``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import fields
from ..geometry.meshes.polygons import Polygons
from ..geometry.rays.scan import scan_target
from ..geometry.skeletons.skeleton import Skeleton
from ..limits import Limits
from ..lsystem.queries import QueryState
from ..tolerances import tol
from .shapes import EnvError, batch_size, parse_shape

__all__ = ["SKIES", "Light", "allocate", "sky_directions"]

SKIES = ("uniform", "overcast")
GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))


def sky_directions(n: int, sky: str = "uniform") -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) unit directions towards the upper hemisphere (y up), one per equal solid
    angle, and (n,) their weights (the sky's radiance there), summing to 1."""
    i = np.arange(n)
    cos_t = 1.0 - (i + 0.5) / n
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    phi = i * GOLDEN_ANGLE
    dirs = np.stack([sin_t * np.cos(phi), cos_t, sin_t * np.sin(phi)], axis=1)
    w = np.ones(n) if sky == "uniform" else (1.0 + 2.0 * cos_t) / 3.0
    return dirs, w / w.sum()


class Light:
    """``light`` (see the module's notes)."""

    keys = {"sky", "directions", "sun", "obstacles", "offset", "batch", "allocation"}

    def __init__(self, d: dict, where: str, base: Path, limits: Limits, seed: int):
        self.batch = batch_size(d, where)
        sky = d.get("sky", "uniform")
        if sky not in SKIES:
            raise EnvError(f"{where}: sky must be one of {', '.join(SKIES)}, got {fields.show(sky)}")
        n = fields.integer(d.get("directions", 64), "directions", where, EnvError, lo=1, hi=1 << 20)
        self.dirs, self.weights = sky_directions(n, sky)
        self.share, self.sun = 0.0, None
        if d.get("sun") is not None:
            sun = fields.keys(d["sun"], {"direction", "share"}, f"{where}: sun", EnvError)
            travel = fields.unit_vector(sun.get("direction", [0, -1, 0]), "direction", f"{where}: sun", EnvError)
            self.sun = -np.array(travel)      # towards the sun; below the horizon the ground hides it
            self.share = fields.number(sun.get("share", 0.5), "share", f"{where}: sun", EnvError, lo=0.0, hi=1.0)
        obstacles = d.get("obstacles") or []
        if not isinstance(obstacles, list) or len(obstacles) > 1000:
            raise EnvError(f"{where}: obstacles must be a list of at most 1,000 shapes")
        self.obstacles = [parse_shape(s, f"{where}: obstacle {i + 1}", base, limits) for i, s in enumerate(obstacles)]
        self.offset = fields.number(d.get("offset", 0.01), "offset", where, EnvError, lo=0.0,
                                    max_abs=tol.max_coordinate)
        self.allocation = None
        if d.get("allocation") is not None:
            a = fields.keys(d["allocation"], {"alpha", "lambda"}, f"{where}: allocation", EnvError)
            self.allocation = (fields.number(a.get("alpha", 2.0), "alpha", where, EnvError, positive=True),
                               fields.number(a.get("lambda", 0.5), "lambda", where, EnvError, lo=0.0, hi=1.0))
        self.width = 4 + (self.allocation is not None)
        self.limits = limits
        #: plants grown together (:mod:`plantgen.environment.together`): a callable giving the
        #: others' (Skeleton, Polygons) in this plant's frame, and the frame's rotation (3, 3)
        #: to the world, whose sky and sun these are
        self.neighbours, self.rotation = None, None

    @property
    def rays_per_query(self) -> int:
        return len(self.dirs) + (self.sun is not None)

    def answer(self, state: QueryState) -> np.ndarray:
        k = len(state)
        self.limits.check("light_rays", k * self.rays_per_query, f"step {state.step}: light rays")
        drawing = state.drawing
        dirs = self.dirs if self.sun is None else np.concatenate([self.dirs, self.sun[None]])
        if self.rotation is not None:
            dirs = dirs @ self.rotation                  # the world's sky in the plant's frame
        weights = np.concatenate([(1.0 - self.share) * self.weights, [self.share]]) if self.sun is not None \
            else self.weights
        radius = np.zeros(k)
        if state.segment is not None and len(drawing.skeleton):
            hung = state.segment >= 0
            radius[hung] = drawing.skeleton.r_end[state.segment[hung]]
        target = self._target(state, dirs, radius)
        traced = target is not None and len(target) > 0
        out = np.zeros((k, self.width))
        for lo in range(0, k, self.batch):
            p, r = state.position[lo:lo + self.batch], radius[lo:lo + self.batch]
            m = len(p)
            origin = self._origins(p, r, dirs)
            direction = np.broadcast_to(dirs[None], (m, len(dirs), 3)).reshape(-1, 3)
            open_ = np.ones(len(origin), dtype=bool)
            if traced:        # one frame origin for every batch: the hit test rounds the same, however batched
                t, _ = target.first_hits(origin, direction, origin=target.base, any_hit=True)
                open_ &= ~np.isfinite(t)
            for shape in self.obstacles:
                rest = np.flatnonzero(open_)
                open_[rest] = ~np.isfinite(shape.ray(origin[rest], direction[rest], tol.max_coordinate))
            if self.sun is not None and self.sun[1] <= 0:
                open_.reshape(m, -1)[:, -1] = False
            light = open_.reshape(m, -1) * weights[None]
            out[lo:lo + m, 0] = light.sum(axis=1)
            toward = (light[:, :, None] * dirs[None]).sum(axis=1)   # row by row: the same for any batch
            norm = np.linalg.norm(toward, axis=1, keepdims=True)
            out[lo:lo + m, 1:4] = np.where(norm > tol.parallel, toward / np.maximum(norm, 1e-300), 0.0)
        out[:, 1:4] = state.local(out[:, 1:4])
        if self.allocation is not None:
            out[:, 4] = allocate(state, out[:, 0], *self.allocation)
        return out

    def _origins(self, p: np.ndarray, r: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """(len(p) * len(dirs), 3) the rays' origins from the modules at ``p`` hanging from
        segments of end radius ``r`` (row by row: the same numbers for any batch)."""
        return (p[:, None] + (self.offset + 1.5 * r)[:, None, None] * dirs[None]).reshape(-1, 3)

    def _target(self, state: QueryState, dirs: np.ndarray, radius: np.ndarray):
        """The scan target the rays are traced against: the plant's drawing, and with
        :attr:`neighbours` the other plants after its own segments (its indices stay as
        they are): all their branches, and those clusters of their leaves that some ray
        of this step may meet (:meth:`~plantgen.environment.together.StandLeaves.met`:
        a leaf no ray's box test passes changes no any hit). None for nothing drawn."""
        drawing = state.drawing
        skeleton, polygons = drawing.skeleton, drawing.polygons
        others = self.neighbours() if self.neighbours is not None else None
        if others is not None:
            skeleton = Skeleton.concatenate([skeleton, others.skeleton])
            polygons = _with_leaves_met(polygons, len(drawing.skeleton), others.leaves,
                                        self._origins(state.position, radius, dirs),
                                        np.broadcast_to(dirs[None], (len(state), len(dirs), 3)).reshape(-1, 3))
        if not (len(skeleton) or len(polygons)):
            return None
        from ..geometry.rays.native_trace import available  # numba's import is paid by the first trace
        from ..geometry.skeletons.skin import skin_skeleton

        # a plant's light is traced by few rays a build: the LBVH's quicker build pays (the
        # grove with SAH trees: 5.26 s against 4.68 s, medians of 5 alternated runs)
        return scan_target(skeleton, polygons, frusta=skin_skeleton(skeleton, texture=False), compiled=available(),
                           split="lbvh")


def _with_leaves_met(own: Polygons, own_segments: int, leaves, origins: np.ndarray, dirs: np.ndarray) -> Polygons:
    """``own`` polygons and, after them, the other plants' ``leaves``
    (:class:`~plantgen.environment.together.StandLeaves`): all their polygons, numbered
    as :meth:`Polygons.concatenate` numbers the joined sets, with the triangles some ray
    (``origins``, ``dirs``) may meet (:meth:`~plantgen.environment.together.StandLeaves.met`;
    materials and normals zero: the scan reads neither)."""
    vertices, triangles, polygon = leaves.met(origins, dirs) if len(leaves) else \
        (np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.int64))
    p = len(own) + len(leaves.segment)
    return Polygons(np.concatenate([own.vertices, vertices]).reshape(-1, 3),
                    np.concatenate([own.triangles, triangles + len(own.vertices)]).reshape(-1, 3).astype(np.int64),
                    np.concatenate([own.polygon, polygon + len(own)]).astype(np.int64),
                    np.zeros(p, np.int32), np.zeros((p, 3)),
                    np.concatenate([own.segment, np.where(leaves.segment >= 0, leaves.segment + own_segments, -1)])
                    .astype(np.int64))


def allocate(state: QueryState, q: np.ndarray, alpha: float, lam: float) -> np.ndarray:
    """(k,) the Borchert–Honda vigour of each bud of ``state`` given its light ``q``.

    The tree is the drawing's skeleton with the buds as its tips: a bud hangs from its
    segment (``state.segment``, -1: none yet), a main bud continues it and a side bud
    (``state.side``) is lateral, as a segment that ``continues`` its parent is main and
    any other child lateral. Light is summed from the tips to the base (segments come
    after their parents); each root segment (a plant of its own: a string may hold many)
    receives ``alpha`` times the light above it, a bud on no segment ``alpha`` times its
    own; each node shares what reaches it among its children in proportion to ``lam``·Q
    (main) and ``(1 - lam)``·Q (lateral)."""
    skel = state.drawing.skeleton
    n = len(skel)
    seg = state.segment if state.segment is not None else np.full(len(q), -1)
    side = state.side if state.side is not None else np.zeros(len(q), bool)
    hung = seg >= 0
    vigour_bud = np.where(hung, 0.0, alpha * q)
    if not n:
        return vigour_bud
    below = np.zeros(n)                                   # light gathered above each segment's end
    np.add.at(below, seg[hung], q[hung])
    parent = skel.parent
    for s in range(n - 1, -1, -1):                        # children come after their parents
        if parent[s] >= 0:
            below[parent[s]] += below[s]
    # each child's weight at its node: lam * Q for the main one, (1 - lam) * Q for a lateral one
    seg_w = np.where(skel.continues, lam, 1.0 - lam) * below
    bud_w = np.where(side, 1.0 - lam, lam) * q
    total = np.zeros(n)
    np.add.at(total, parent[parent >= 0], seg_w[parent >= 0])
    np.add.at(total, seg[hung], bud_w[hung])
    vigour = np.zeros(n)
    for s in range(n):                                    # parents first
        p = parent[s]
        if p < 0:
            vigour[s] = alpha * below[s]
        elif total[p] > 0:
            vigour[s] = vigour[p] * seg_w[s] / total[p]
    at = seg[hung]
    with np.errstate(invalid="ignore", divide="ignore"):
        vigour_bud[hung] = np.where(total[at] > 0, vigour[at] * bud_w[hung] / total[at], 0.0)
    return vigour_bud
