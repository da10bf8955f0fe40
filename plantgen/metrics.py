"""Tree-level figures of a skeleton: height, bounds, DBH, wood volume, crown.

The model measured is the skeleton's own solid: every segment a conical frustum from
``start`` to ``end`` with radii ``r_start`` and ``r_end`` and end discs perpendicular to
the segment (the skin's oblique joint planes and knuckles move material between
neighbouring segments, not the figures below, up to the bevel of a bend). Coordinates are
plantgen's: y up, model units.

- **bounds**: the exact axis-aligned box of the frusta (a disc of radius r about the unit
  axis a reaches r·sqrt(1 - a_i²) along axis i): what ``plantgen grow`` prints.
  (``Skeleton.bounds`` pads every end point by its radius in every direction: a safe box
  for framing, not the model's.)
- **height**: from the trunk's base point (the start of segment 0, where the stem meets
  the ground) up to the highest point of any frustum's surface: the box's top less the
  base's y. Geometry below the base (a leaning stem's base disc dipping under it, a
  drooping branch, a grammar's parts drawn below the start) does not count, as a
  forester's tree height is measured from the ground at the stem. (Until this was
  written down it was the box's extent along y, which counted it.)
- **volume**: the sum of the frusta, πh/3·(r1² + r1·r2 + r2²); trunk and branch volumes
  split it by branch (:mod:`plantgen.geometry.skeletons.topology`: the trunk is branch 0, the
  chain of segment 0). Lengths likewise.
- **DBH**: the trunk's diameter at breast height, 1.3 m along the trunk's axis from its
  base (forestry's rule for a leaning stem, and TreeQSM's: the trunk cylinders' lengths
  summed; for an upright stem, 1.3 m above the base), the frustum's radius interpolated
  there. ``unit`` says how long a model unit is in metres (default 1: model units are
  metres); a trunk shorter than breast height has no DBH (None; TreeQSM would take its
  top cylinder's).
- **crown**: the convex hull of the whole model's vertical projection (onto the ground
  plane, ⟂ y): its area (TreeQSM's ``CrownAreaConv``), its largest width
  (``CrownDiamMax``, the largest distance across it) and its mean width over all
  directions (the hull's perimeter / π, Cauchy's formula: the mean caliper width;
  TreeQSM's ``CrownDiamAve`` is instead the mean of 18 diameters through the hull's
  centroid, each the farthest branch tips in opposite 10° sectors, which is at most the
  width in that direction). Wood only, as TreeQSM's: leaves do not count. The hull is
  found from the support function of every end
  disc in ``crown_directions`` directions, plus the exact tangent points where the hull
  bridges from one disc to another: every vertex lies on the true hull, and the chords
  along a round disc's arc lose a relative 2π²/(3·directions²) of its area (1.3e-5 at 720).

A skeleton with several roots (a scene, a grammar's ``f`` moves) is measured as one model:
its plants together, the trunk the first root's chain. For figures per plant, measure each
plant of ``Scene.plants()`` (in its own frame) or each instance.

Pure numpy, no GL, no click: for the exporters (QSM files) and for batch statistics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry.skeletons.skeleton import Skeleton
from .geometry.skeletons.topology import Branches, branches
from .geometry.vec import unit

__all__ = ["BREAST_HEIGHT_M", "CrownProjection", "TreeMetrics", "crown_projection", "end_discs", "may_reach_hull",
           "geometry_bounds", "segment_lengths", "segment_volumes", "trunk_diameter_at", "tree_metrics"]

#: Breast height in metres, where DBH is measured.
BREAST_HEIGHT_M = 1.3
#: Directions the crown's support function is sampled in.
CROWN_DIRECTIONS = 720
#: Disc-direction pairs evaluated at a time (bounds the crown's scratch memory, 8 B each).
CHUNK = 1 << 22


def segment_lengths(skeleton: Skeleton) -> np.ndarray:
    """(n,) length of every segment."""
    return np.linalg.norm(skeleton.end - skeleton.start, axis=1)


def segment_volumes(skeleton: Skeleton) -> np.ndarray:
    """(n,) volume of every segment's frustum, πh/3·(r1² + r1·r2 + r2²)."""
    r1, r2 = skeleton.r_start, skeleton.r_end
    return np.pi * segment_lengths(skeleton) / 3.0 * (r1 * r1 + r1 * r2 + r2 * r2)


def end_discs(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Both end discs of every segment: centres (2n, 3), unit normals (2n, 3) and radii
    (2n,). A segment of zero length gets a zero normal (its discs count as balls)."""
    axis = unit(skeleton.end - skeleton.start, np.zeros(3))
    centres = np.concatenate([skeleton.start, skeleton.end])
    return centres, np.concatenate([axis, axis]), np.concatenate([skeleton.r_start, skeleton.r_end])


def geometry_bounds(skeleton: Skeleton) -> np.ndarray:
    """(2, 3) the exact axis-aligned box of the segments' frusta (zeros for no segment)."""
    if len(skeleton) == 0:
        return np.zeros((2, 3))
    centres, normals, radii = end_discs(skeleton)
    # sqrt(1 - a_i²) as the norm of the other two components (no cancellation near ±1);
    # a zero normal (a segment of zero length) reaches r every way.
    others = np.sqrt(np.stack([normals[:, 1] ** 2 + normals[:, 2] ** 2, normals[:, 0] ** 2 + normals[:, 2] ** 2,
                               normals[:, 0] ** 2 + normals[:, 1] ** 2], axis=1))
    ball = ~np.any(normals != 0, axis=1)
    reach = radii[:, None] * np.where(ball[:, None], 1.0, others)
    return np.stack([(centres - reach).min(axis=0), (centres + reach).max(axis=0)])


def trunk_diameter_at(skeleton: Skeleton, distance: float, topology: Branches | None = None) -> float | None:
    """The trunk's diameter ``distance`` along it from its base (model units), or None
    where the trunk (branch 0) is shorter."""
    if len(skeleton) == 0 or distance < 0:
        return None
    topology = topology or branches(skeleton)
    trunk = topology.chains()[0]
    length = segment_lengths(skeleton)[trunk]
    ends = np.cumsum(length)
    if ends[-1] < distance:
        return None
    k = int(np.searchsorted(ends, distance))
    seg = trunk[k]
    t = 0.0 if length[k] == 0 else (distance - (ends[k] - length[k])) / length[k]
    return float(2.0 * (skeleton.r_start[seg] + t * (skeleton.r_end[seg] - skeleton.r_start[seg])))


@dataclass(frozen=True)
class CrownProjection:
    """The convex hull of a model's vertical projection (model units, the ground plane's
    x and z): ``polygon`` (k, 2) points on the hull, in order of the direction they
    support (from +x towards +z)."""

    polygon: np.ndarray
    area: float
    max_width: float
    mean_width: float


def _support_values(centres, normals, radii, theta) -> np.ndarray:
    """(k, K) support values of discs (k) in the horizontal directions θ (K,)."""
    d = np.stack([np.cos(theta), np.sin(theta)], axis=-1)                                # (K, 2): x, z
    # |a × d| = sqrt(1 - (a·d)²) for horizontal d, without cancellation; a ball (a = 0) reaches r.
    across = normals[:, 2:3] * d[None, :, 0] - normals[:, 0:1] * d[None, :, 1]
    lateral = np.sqrt(normals[:, 1:2] ** 2 + across ** 2)
    ball = ~np.any(normals != 0, axis=1)[:, None]
    return centres[:, [0, 2]] @ d.T + radii[:, None] * np.where(ball, 1.0, lateral)


def _support_points(centres, normals, radii, theta) -> tuple[np.ndarray, np.ndarray]:
    """Support value (k,) and point (k, 2) in (x, z) of disc i in direction θ_i."""
    d = np.stack([np.cos(theta), np.zeros_like(theta), np.sin(theta)], axis=-1)       # (k, 3)
    toward = d - np.sum(normals * d, axis=1, keepdims=True) * normals                  # d less its a part
    toward = unit(toward, np.zeros(3))                                                    # 0 where d ∥ a
    point = centres + radii[:, None] * toward
    return np.sum(point * d, axis=1), point[:, [0, 2]]


def _farthest(centres, normals, radii, theta) -> tuple[np.ndarray, np.ndarray]:
    """(k,) the largest support value of all discs in each direction θ_i, and (k,) the disc
    that reaches it (the first on ties), over chunks of at most ``CHUNK`` values."""
    best = np.full(len(theta), -np.inf)
    where = np.zeros(len(theta), dtype=np.int64)
    step = max(1, CHUNK // max(len(theta), 1))
    for lo in range(0, len(radii), step):
        value = _support_values(centres[lo:lo + step], normals[lo:lo + step], radii[lo:lo + step], theta)
        arg = np.argmax(value, axis=0)
        top = value[arg, np.arange(len(theta))]
        better = top > best
        best[better], where[better] = top[better], arg[better] + lo
    return best, where


def _bridges(centres, normals, radii, lo, hi, a, b, rounds: int = 24) -> list[np.ndarray]:
    """Tangent points where the hull passes from disc ``a[i]`` (the widest at ``lo[i]``)
    to disc ``b[i]`` (the widest at ``hi[i]``). The direction where the two reach as far is
    found by bisection; if a third disc reaches farther there, the interval splits at it
    (a hull vertex whose directions fall between two samples) and both halves are refined."""
    out: list[np.ndarray] = []
    for _ in range(rounds):
        if len(lo) == 0:
            break
        left, right = lo.copy(), hi.copy()
        for _ in range(40):
            mid = (left + right) / 2
            ahead = (_support_points(centres[a], normals[a], radii[a], mid)[0]
                     >= _support_points(centres[b], normals[b], radii[b], mid)[0])
            left, right = np.where(ahead, mid, left), np.where(ahead, right, mid)
        value_a, point_a = _support_points(centres[a], normals[a], radii[a], left)
        top, winner = _farthest(centres, normals, radii, left)
        third = (top > value_a + 1e-12 * (1 + np.abs(value_a))) & (winner != a) & (winner != b)
        done = ~third
        out += [point_a[done], _support_points(centres[b[done]], normals[b[done]], radii[b[done]], left[done])[1]]
        w = winner[third]
        out.append(_support_points(centres[w], normals[w], radii[w], left[third])[1])
        lo, hi = np.concatenate([lo[third], left[third]]), np.concatenate([left[third], hi[third]])
        a, b = np.concatenate([a[third], w]), np.concatenate([w, b[third]])
    return out


def _hull(points: np.ndarray) -> np.ndarray:
    """The convex hull of points (m, 2), counter-clockwise in (x, z) (Andrew's monotone chain)."""
    pts = np.unique(points, axis=0)
    if len(pts) < 3:
        return pts

    def half(seq):
        out: list = []
        for p in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (p[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(p)
        return out
    rows = pts.tolist()
    return np.array(half(rows)[:-1] + half(rows[::-1])[:-1])


def may_reach_hull(xz: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(k,) bool: the discs (centres ``xz`` (k, 2), ``radii`` (k,)) whose projection may
    reach the hull of them all. A disc's projection lies within its radius of its centre,
    and in every direction the hull reaches at least as far as the centres' hull; so a disc
    whose centre lies deeper inside the centres' hull than its radius is never extreme and
    is left out (exactly: the crown is the same, in a fraction of the time)."""
    hull = _hull(xz)
    if len(hull) < 3:
        return np.ones(len(xz), dtype=bool)
    edge = np.roll(hull, -1, axis=0) - hull
    outward = np.stack([edge[:, 1], -edge[:, 0]], axis=1) / np.linalg.norm(edge, axis=1)[:, None]
    offset = np.einsum("ej,ej->e", hull, outward)                  # each edge's line: outward·p = offset
    depth = np.empty(len(xz))                                         # inside the hull: >= 0
    step = max(1, CHUNK // len(hull))
    for lo in range(0, len(xz), step):
        depth[lo:lo + step] = np.min(offset[None, :] - xz[lo:lo + step] @ outward.T, axis=1)
    scale = float(np.abs(xz).max()) + float(radii.max())
    return depth <= radii + 1e-9 * scale


def crown_projection(skeleton: Skeleton, directions: int = CROWN_DIRECTIONS) -> CrownProjection:
    """The model's projected crown (see the module docstring)."""
    if len(skeleton) == 0:
        return CrownProjection(np.zeros((0, 2)), 0.0, 0.0, 0.0)
    if int(directions) < 8:
        raise ValueError(f"directions must be at least 8, got {directions!r}")
    centres, normals, radii = end_discs(skeleton)
    origin = centres.mean(axis=0)
    centres = centres - origin
    keep = may_reach_hull(centres[:, [0, 2]], radii)
    centres, normals, radii = centres[keep], normals[keep], radii[keep]
    theta = 2 * np.pi * np.arange(int(directions)) / int(directions)
    best, where = _farthest(centres, normals, radii, theta)
    points = [_support_points(centres[where], normals[where], radii[where], theta)[1]]
    switch = np.flatnonzero(where != np.roll(where, -1))
    points += _bridges(centres, normals, radii, theta[switch], theta[switch] + 2 * np.pi / len(theta),
                       where[switch], where[(switch + 1) % len(theta)])
    polygon = _hull(np.concatenate(points))
    x, z = polygon[:, 0], polygon[:, 1]
    area = 0.5 * abs(float(np.dot(x, np.roll(z, -1)) - np.dot(z, np.roll(x, -1))))
    perimeter = float(np.linalg.norm(polygon - np.roll(polygon, -1, axis=0), axis=1).sum())
    width = max(float(np.linalg.norm(polygon[:, None] - polygon[None], axis=-1).max()), 0.0)
    return CrownProjection(polygon + origin[[0, 2]], area, width, perimeter / np.pi)


@dataclass(frozen=True)
class TreeMetrics:
    """Tree-level figures (see the module docstring); lengths in model units, volumes in
    model units³, areas in model units². ``unit``: metres per model unit
    (:meth:`as_dict` with ``metres=True`` converts)."""

    segments: int
    bounds: np.ndarray              # (2, 3)
    height: float
    base: np.ndarray                # (3,) the trunk's base point
    volume: float
    trunk_volume: float
    branch_volume: float
    length: float
    trunk_length: float
    branch_length: float
    surface_area: float             # lateral area of the frusta
    branches: int                   # branches besides the trunk
    max_branch_order: int
    unit: float
    breast_height: float            # model units
    dbh: float | None
    crown: CrownProjection

    def as_dict(self, metres: bool = False) -> dict:
        """The scalar figures by name (for tables and JSON), in model units; with
        ``metres``, lengths in m, areas in m² and volumes in m³ (times ``unit`` to the
        power each needs). ``units`` says which; ``unit`` is the factor either way."""
        m = self.unit if metres else 1.0
        dbh = None if self.dbh is None else self.dbh * m
        return {"segments": self.segments, "height": self.height * m, "volume": self.volume * m ** 3,
                "trunk_volume": self.trunk_volume * m ** 3, "branch_volume": self.branch_volume * m ** 3,
                "length": self.length * m, "trunk_length": self.trunk_length * m,
                "branch_length": self.branch_length * m, "surface_area": self.surface_area * m ** 2,
                "branches": self.branches, "max_branch_order": self.max_branch_order, "dbh": dbh,
                "breast_height": self.breast_height * m, "crown_area": self.crown.area * m ** 2,
                "crown_width_max": self.crown.max_width * m, "crown_width_mean": self.crown.mean_width * m,
                "unit": self.unit, "units": "m" if metres else "model"}


def tree_metrics(skeleton: Skeleton, *, unit: float = 1.0, topology: Branches | None = None,
                 crown_directions: int = CROWN_DIRECTIONS) -> TreeMetrics:
    """The :class:`TreeMetrics` of ``skeleton``; ``unit`` is the length of a model unit
    in metres (it places breast height, 1.3 m)."""
    if not unit > 0:
        raise ValueError(f"unit must be a positive number of metres, got {unit!r}")
    topology = topology or branches(skeleton)
    lengths = segment_lengths(skeleton)
    volumes = segment_volumes(skeleton)
    trunk = topology.branch == 0
    slant = np.hypot(lengths, skeleton.r_end - skeleton.r_start)
    bounds = geometry_bounds(skeleton)
    breast = BREAST_HEIGHT_M / unit
    base = skeleton.start[0].copy() if len(skeleton) else np.zeros(3)
    return TreeMetrics(
        segments=len(skeleton), bounds=bounds, height=float(bounds[1, 1] - base[1]) if len(skeleton) else 0.0,
        base=base,
        volume=float(volumes.sum()), trunk_volume=float(volumes[trunk].sum()),
        branch_volume=float(volumes[~trunk].sum()), length=float(lengths.sum()),
        trunk_length=float(lengths[trunk].sum()), branch_length=float(lengths[~trunk].sum()),
        surface_area=float((np.pi * (skeleton.r_start + skeleton.r_end) * slant).sum()),
        branches=max(len(topology) - 1, 0), max_branch_order=int(topology.order.max()) if len(topology) else 0,
        unit=float(unit), breast_height=breast, dbh=trunk_diameter_at(skeleton, breast, topology),
        crown=crown_projection(skeleton, crown_directions))
