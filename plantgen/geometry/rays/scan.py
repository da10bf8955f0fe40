"""Simulated laser scans: terrestrial scanners around a plant, or airborne passes over it,
cast against the exact frusta and the leaf triangles (first return).

**Beams.** A scanner fires beams on a regular grid of two integers (a, b):

- *terrestrial* (``mode="terrestrial"``): scanners at ``positions``, or ``scanners`` of
  them evenly on a circle of radius ``distance`` around the plant's centre, at
  ``scanner_height`` above its base, the first at ``azimuth`` (degrees, 0 towards +x,
  90 towards +z). Beam (a, b) leaves the scanner at azimuth φ = φ_c + a·Δ and elevation
  θ = b·Δ (Δ = ``angular_step``, φ_c the azimuth of the plant's centre from the
  scanner), direction (cos θ cos φ, sin θ, cos θ sin φ), y up. A scanner fires only the
  beams whose direction can meet the plant's bounding box: it looks at the plant (from
  inside the box, at the whole sphere). Point spacing is Δ times the range.
- *airborne* (``mode="airborne"``): parallel flight lines heading ``azimuth`` at
  ``flight_height`` above the plant's base, ``line_spacing`` apart, over the plant; along
  each, a scan line every ``pulse_spacing``: beam (a, b) leaves the point a·``pulse_spacing``
  along the line, at b·Δ from the nadir across the track, |b·Δ| <= ``scan_angle`` (a
  rotating mirror's sweep, the aircraft taken as still during one sweep). ``scan_angle``
  0 gives one nadir beam per pulse: parallel lines of downward rays. A point's
  ``scanner`` is its flight line.

**Returns.** A beam's first return is the nearest hit of the frusta (the exact ray-cone
intersection of :class:`~plantgen.geometry.rays.reference.PairTester`, float64, clipped by
the cutting planes, open ends capped) and of the leaf triangles (Möller-Trumbore, both
faces; a ray in a leaf's plane misses it). A beam that hits nothing gives no point.

**Beam divergence** γ (``divergence``, full angle, milliradians): the beam is a cone of
half-angle γ/2 around its direction, sampled by ``beam_samples`` sub-rays spread
uniformly over its cross-section (a Vogel spiral, turned by a random angle per beam). The
beam's range is the nearest of its sub-rays' hits (``beam_return="first"``, a
discrete-return scanner's first echo) or their mean (``"mean"``: a mixed pixel, which at
an edge lands between the surfaces, as real scans do); the point lies on the beam's axis
at that range and takes the labels of the sub-ray that gave it (for the mean: the sub-ray
nearest to it). A first-return point is off the surface by at most range·γ/2. γ = 0:
one ray on the axis.

**Range noise**: the range gains Gaussian noise of sigma ``range_noise`` (model units),
along the beam.

**Determinism.** Every random number is a counter-based hash (SplitMix64) of the seed,
the scanner, the beam and a stream number: a point does not depend on how the pairs are
chunked or binned, nor on the other beams, so a seed gives the same cloud every time.

**Labels** of each point: ``plant`` (the ``plant`` given per segment, or one number),
``part`` (:data:`PART_NAMES`: ``stem`` for a segment of branch order 0 of
:mod:`plantgen.geometry.skeletons.topology`, ``branch`` above, ``leaf`` for a leaf triangle),
``order`` (the branch order; a leaf: the order of the segment it hangs from, -1 for
none), ``segment`` (the skeleton segment; a leaf: the one it hangs from, -1 for none),
``leaf`` (the leaf polygon, -1 for wood) and ``scanner``.

**Speed.** Every beam (every sub-ray) is traced through the target's bounding volume
hierarchy (:mod:`plantgen.geometry.rays.bvh`, built once per target), which finds its nearest
hit among the primitives whose boxes it meets, nearest boxes first; the beams stream in
chunks (``max_pairs`` sub-rays, at most :data:`SCAN_CHUNK_RAYS`), so memory stays bounded
whatever their count. A scene (:func:`scan_scene`, :class:`SceneTarget`) is traced in
two levels, each distinct plant once and the beams moved into each copy's frame in
float64, so it costs the memory of its distinct plants, not of its copies placed.
``precision="float32"`` with a ``finder`` (``plantgen scan`` passes the GPU's search,
:func:`plantgen.gl.trace.trace_target`) finds each beam's primitive in float32 and solves
its range again in float64 against that primitive (the reference's ranges wherever both
find the same primitive); without one it tests the frusta in float32 relative to the
scanner on the CPU (leaves stay float64): ``python -m plantgen.benchmarks.scan`` measures
what each saves and costs.

Pure numpy, no GL, no click. Files: :mod:`plantgen.scanfiles` (LAS, LAZ, PLY).
"""

from __future__ import annotations

import math
from copy import copy as shallow_copy
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ...errors import PlantgenError
from ...knobs import check_knobs, knob
from ...limits import LimitError, Limits, hint
from ...limits import limits as default_limits
from ..meshes.polygons import Polygons
from ..skeletons.frusta import Frusta
from ..skeletons.skeleton import Skeleton
from ..skeletons.topology import Branches, branches
from ..vec import cross, dot, unit
from .reference import PairTester, row_boxes

__all__ = ["LABELS", "PART_NAMES", "SCAN_MODES", "AirborneBeams", "BeamReturns", "PointCloud", "ScanError",
           "ScanSettings", "ScanTarget", "TerrestrialBeams", "beam_grids", "expected_points", "beam_returns",
           "cast_first_returns",
           "SceneTarget", "primitive_labels", "scan_plant", "scan_points", "scan_scene", "scan_target",
           "scanner_positions", "scene_target", "target_hits"]

#: The parts a point may belong to, by the ``part`` label's value.
PART_NAMES = ("stem", "branch", "leaf")
STEM, BRANCH, LEAF = 0, 1, 2
#: How a scan is made.
SCAN_MODES = ("terrestrial", "airborne")
#: Vogel's golden angle, between successive sub-rays of a diverging beam.
GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))
#: Random streams of the counter-based generator.
_NOISE_A, _NOISE_B, _TURN = 1, 2, 3


class ScanError(PlantgenError, ValueError):
    """Scan settings or a scan that plantgen cannot make."""


def _positions(value) -> tuple | None:
    """Scanner positions as a tuple of (x, y, z) float triples, from 'x,y,z;x,y,z' or a
    sequence of triples; None stays None."""
    if value is None:
        return None
    given = value
    if isinstance(value, str):
        items = [p for p in value.replace(" ", "").split(";") if p]
        value = [p.split(",") for p in items]
    try:
        out = tuple(tuple(float(c) for c in p) for p in value)
    except (TypeError, ValueError):
        raise ScanError(f"--scanner-positions must be 'x,y,z;x,y,z...' (numbers), got {given!r}") from None
    if not out or any(len(p) != 3 or not all(math.isfinite(c) for c in p) for p in out):
        raise ScanError(f"--scanner-positions must be finite x,y,z triples separated by ';', got {given!r}")
    return out


@dataclass(frozen=True)
class ScanSettings:
    """A laser scan's knobs (see the module docstring). Lengths are model units (metres
    for the shipped grammars), angles degrees, the divergence milliradians."""

    mode: str = knob("terrestrial", "--scan-mode", "Terrestrial scanners around the plant, or airborne flight "
                     "lines over it.", kind="choice", choices=SCAN_MODES)
    angular_step: float = knob(0.05, "--angular-step", "Degrees between neighbouring beams (azimuth and elevation; "
                               "airborne: across the track).", lo=0.001, hi=10.0, metavar="DEG")
    range_noise: float = knob(0.0, "--range-noise", "Gaussian sigma of each range, model units (0: exact).",
                              lo=0.0, hi=1e6, metavar="SIGMA")
    divergence: float = knob(0.0, "--divergence", "Beam divergence, full angle in milliradians (0: ideal rays; "
                             "terrestrial scanners have about 0.3).", lo=0.0, hi=100.0, metavar="MRAD")
    beam_samples: int = knob(8, "--beam-samples", "Sub-rays sampled across a diverging beam.", kind="int", lo=1,
                             hi=256, metavar="N")
    beam_return: str = knob("first", "--beam-return", "A diverging beam's range: its sub-rays' nearest hit (first) "
                            "or their mean (mixed pixels at edges).", kind="choice", choices=("first", "mean"))
    scanners: int = knob(4, "--scanners", "Terrestrial scanners evenly on a circle around the plant.", kind="int",
                         lo=1, hi=360, metavar="N")
    distance: float | None = knob(None, "--scan-distance", "Radius of the scanners' circle around the plant's centre "
                                  "(model units; default: the plant's height plus half its width).", lo=1e-6,
                                  hi=1e9, metavar="D")
    scanner_height: float = knob(1.5, "--scanner-height", "Terrestrial scanners' height above the plant's base "
                                 "(model units).", lo=-1e9, hi=1e9, metavar="H")
    azimuth: float = knob(0.0, "--scan-azimuth", "Degrees: the first scanner's direction from the plant (0: +x, "
                          "90: +z); airborne: the flight lines' heading.", metavar="DEG")
    positions: tuple | None = knob(None, "--scanner-positions", "Terrestrial scanners at these points instead of "
                                   "the circle: 'x,y,z;x,y,z' (model units, the plant's frame).", kind="str",
                                   metavar="X,Y,Z;...")
    flight_height: float | None = knob(None, "--flight-height", "Airborne: the lines' height above the plant's base "
                                       "(default: twice the plant's height).", lo=1e-6, hi=1e9, metavar="H")
    line_spacing: float | None = knob(None, "--line-spacing", "Airborne: distance between flight lines (default: "
                                      "half the swath, or the pulse spacing for nadir lines).", lo=1e-9, hi=1e9,
                                      metavar="D")
    pulse_spacing: float | None = knob(None, "--pulse-spacing", "Airborne: distance between scan lines along the "
                                       "track (default: the beams' spacing at the nadir, on the ground).", lo=1e-9,
                                       hi=1e9, metavar="D")
    scan_angle: float = knob(30.0, "--scan-angle", "Airborne: the mirror's sweep, degrees either side of the nadir "
                             "(0: nadir beams only).", lo=0.0, hi=75.0, metavar="DEG")
    precision: str = knob("float64", "--scan-precision", "float64: the exact reference on the CPU; float32: each "
                          "beam's primitive found on the GPU in float32, its range then solved in float64 (the "
                          "reference's ranges; without GL the frusta tested in float32 on the CPU). plantgen scan "
                          "without it: float32 where a GL context exists, else float64.",
                          kind="choice", choices=("float64", "float32"))

    def __post_init__(self):
        check_knobs(self, ScanError)
        object.__setattr__(self, "positions", _positions(self.positions))
        if not math.isfinite(self.scanner_height) or not math.isfinite(self.azimuth):
            raise ScanError("--scanner-height and --scan-azimuth must be finite numbers")

    @property
    def sub_rays(self) -> int:
        """Rays cast per beam: ``beam_samples`` with a divergence, else 1."""
        return self.beam_samples if self.divergence > 0 else 1

    def describe(self) -> str:
        """One line: what the scan is."""
        beam = (f"divergence {self.divergence:g} mrad ({self.sub_rays} sub-rays, {self.beam_return} return)"
                if self.divergence > 0 else "ideal rays")
        return (f"{self.mode}, step {self.angular_step:g}°, range noise {self.range_noise:g}, {beam}, "
                f"{self.precision}")


# ============================================================================ the point cloud
#: Per-point label arrays of a :class:`PointCloud` and their dtypes.
LABELS = {"plant": np.int32, "part": np.uint8, "order": np.int16, "segment": np.int32, "leaf": np.int32,
          "scanner": np.uint16}


@dataclass(frozen=True, eq=False)
class PointCloud:
    """Points of a scan, in scan order (scanner by scanner, beam by beam), model units, y up.

    ======================  ==========  ========================================================
    ``xyz``                 (m, 3) f8   the points
    ``plant``               (m,) i4     the plant (the ``plant`` given to :func:`scan_plant`)
    ``part``                (m,) u1     index into :data:`PART_NAMES`: stem, branch, leaf
    ``order``               (m,) i2     branch order (a leaf: its segment's; -1: none)
    ``segment``             (m,) i4     skeleton segment (a leaf: the one it hangs from; -1)
    ``leaf``                (m,) i4     leaf polygon, -1 for wood
    ``scanner``             (m,) u2     the scanner (airborne: the flight line)
    ``scanners``            (s, 3) f8   each scanner's position (airborne: its line's centre)
    ``metadata``            dict        the settings and seed that made it (JSON values)
    ======================  ==========  ========================================================
    """

    xyz: np.ndarray
    plant: np.ndarray
    part: np.ndarray
    order: np.ndarray
    segment: np.ndarray
    leaf: np.ndarray
    scanner: np.ndarray
    scanners: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        xyz = np.ascontiguousarray(self.xyz, dtype=np.float64).reshape(-1, 3)
        object.__setattr__(self, "xyz", xyz)
        for name, dtype in LABELS.items():
            arr = np.ascontiguousarray(getattr(self, name), dtype=dtype).reshape(-1)
            if arr.shape != (len(xyz),):
                raise ValueError(f"PointCloud.{name} has {arr.shape[0]} values for {len(xyz)} points")
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "scanners", np.asarray(self.scanners, dtype=np.float64).reshape(-1, 3))

    def __len__(self) -> int:
        return len(self.xyz)

    @classmethod
    def empty(cls, scanners=None, metadata=None) -> PointCloud:
        return cls(np.zeros((0, 3)), *(np.zeros(0, dtype) for dtype in LABELS.values()),
                   scanners=np.zeros((0, 3)) if scanners is None else scanners, metadata=dict(metadata or {}))

    def labels(self) -> dict[str, np.ndarray]:
        """The label arrays by name (:data:`LABELS` order)."""
        return {name: getattr(self, name) for name in LABELS}

    def bounds(self) -> np.ndarray:
        """(2, 3) the points' box (zeros for none)."""
        if not len(self):
            return np.zeros((2, 3))
        return np.stack([self.xyz.min(axis=0), self.xyz.max(axis=0)])

    def subset(self, keep) -> PointCloud:
        """The points ``keep`` selects ((m,) bool or indices), same scanners and metadata."""
        return PointCloud(self.xyz[keep], *(a[keep] for a in self.labels().values()), scanners=self.scanners,
                          metadata=self.metadata)


# ============================================================================ what a scan sees
@dataclass(frozen=True, eq=False)
class ScanTarget:
    """The primitives a scan sees and their labels: the frusta's rows (primitives
    0..n-1) and the leaf triangles (n..n+t-1), each with an axis-aligned box ``lo``,
    ``hi`` ((n + t, 3)); per segment its branch order and plant, per leaf polygon its
    segment and plant."""

    frusta: Frusta
    triangles: np.ndarray            # (t, 3, 3) vertices
    triangle_polygon: np.ndarray     # (t,)
    lo: np.ndarray
    hi: np.ndarray
    segment_order: np.ndarray        # (segments,)
    segment_plant: np.ndarray        # (segments,)
    polygon_segment: np.ndarray      # (p,)
    polygon_plant: np.ndarray        # (p,)
    base: np.ndarray                 # (3,) the plant's base point

    @property
    def rows(self) -> int:
        return len(self.frusta)

    @cached_property
    def triangle_edges(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(t, 3) each: the triangles' first vertex, their two edges from it, and (t,) the
        product of the edges' lengths (the scale of a grazing ray's determinant)."""
        v0 = np.ascontiguousarray(self.triangles[:, 0])
        e1 = self.triangles[:, 1] - v0
        e2 = self.triangles[:, 2] - v0
        return v0, e1, e2, np.sqrt(dot(e1, e1) * dot(e2, e2))

    def __len__(self) -> int:
        return len(self.lo)

    @cached_property
    def bvh(self):
        """The :class:`~plantgen.geometry.rays.bvh.BVH` over the primitives' boxes (built on
        first use)."""
        from .bvh import build_bvh

        return build_bvh(self.lo, self.hi)

    def first_hits(self, origins, dirs, *, precision: str = "float64", origin=None, any_hit: bool = False,
                   t_min: float = 0.0, t_max=np.inf, packets: int = 0):
        """t (m,) and primitive (m,) of each ray's first hit in (t_min, t_max) (inf, -1:
        none; ``any_hit``: any hit), through the BVH (rows tested in ``precision``
        relative to ``origin``; ``packets`` as :func:`~plantgen.geometry.rays.bvh.trace_bvh`
        takes it)."""
        from .bvh import trace_bvh

        hits = target_hits(self, origin=origin, precision=precision, t_min=t_min)
        return trace_bvh(self.bvh, origins, dirs, hits, any_hit=any_hit, t_min=t_min, t_max=t_max,
                         boxes=self.box_columns, packets=packets)

    @cached_property
    def pair_tester(self) -> PairTester:
        """The rows' float64 :class:`~plantgen.geometry.rays.reference.PairTester` (uploaded on
        first use and kept: :func:`target_hits` copies it with its ``t_min``)."""
        return PairTester(self.frusta)

    @cached_property
    def box_columns(self) -> np.ndarray:
        """(6, n) the primitives' boxes by coordinate rows (the traversal's cull)."""
        from .bvh import box_columns

        return box_columns(self.lo, self.hi)

    def hit_distance(self, prim, origins, dirs, *, t_min: float = 0.0) -> np.ndarray:
        """t (k,) of rays (k,) against primitives ``prim`` (k,) in float64 (inf: a miss)."""
        return target_hits(self, t_min=t_min)(np.asarray(prim, np.int64), origins, dirs)

    def primitive_labels(self, prim) -> dict:
        """:func:`primitive_labels` of primitives ``prim``."""
        return primitive_labels(self, prim)

    def box(self) -> np.ndarray:
        """(2, 3) the box around every primitive (zeros for none)."""
        if not len(self):
            return np.zeros((2, 3))
        return np.stack([self.lo.min(axis=0), self.hi.max(axis=0)])


def _leaf_arrays(leaves: Polygons | None) -> tuple[np.ndarray, np.ndarray]:
    if leaves is None or not len(leaves.triangles):
        return np.zeros((0, 3, 3)), np.zeros(0, np.int64)
    return np.asarray(leaves.vertices, dtype=np.float64)[leaves.triangles], np.asarray(leaves.polygon, np.int64)


def scan_target(skeleton: Skeleton, leaves: Polygons | None = None, *, frusta: Frusta | None = None,
                plant=0, leaf_plant=None, topology: Branches | None = None) -> ScanTarget:
    """What a scan of ``skeleton`` (skinned here unless ``frusta`` are given) and its
    ``leaves`` sees. ``plant``: one number for every point, or (n,) per segment (a scene's
    instances); ``leaf_plant``: (p,) per leaf polygon (default: its segment's plant)."""
    from ..skeletons.skin import skin_skeleton  # skinning is the heavy import; a given frusta skips it

    frusta = skin_skeleton(skeleton) if frusta is None else frusta
    topology = topology or branches(skeleton)
    n = len(skeleton)
    p = len(leaves) if leaves is not None else 0
    for name, value, count, what in (("plant", plant, n, "segment"), ("leaf_plant", leaf_plant, p, "leaf")):
        if value is not None and np.ndim(value) and np.shape(value) != (count,):
            raise ScanError(f"{name} must be one number or one per {what} ({count}), got {np.shape(value)[0]}")
    segment_plant = np.broadcast_to(np.asarray(plant, dtype=np.int64), (n,)).copy()
    triangles, triangle_polygon = _leaf_arrays(leaves)
    polygon_segment = np.asarray(leaves.segment, np.int64) if p else np.zeros(0, np.int64)
    if leaf_plant is None:
        own = np.asarray(plant, dtype=np.int64)
        leaf_plant = np.full(p, int(own) if own.ndim == 0 else 0, dtype=np.int64)
        hung = polygon_segment >= 0
        leaf_plant[hung] = segment_plant[polygon_segment[hung]]
    lo, hi = row_boxes(frusta) if len(frusta) else (np.zeros((0, 3)), np.zeros((0, 3)))
    if len(triangles):
        t_lo, t_hi = triangles.min(axis=1), triangles.max(axis=1)
        pad = 1e-9 * np.maximum(np.abs(t_lo).max(axis=1), np.abs(t_hi).max(axis=1))[:, None] + 1e-12
        lo, hi = np.concatenate([lo, t_lo - pad]), np.concatenate([hi, t_hi + pad])
    base = skeleton.start[0].copy() if n else (triangles.reshape(-1, 3).min(axis=0) if len(triangles) else np.zeros(3))
    return ScanTarget(frusta, triangles, triangle_polygon, lo, hi, topology.segment_order.astype(np.int64)
                      if n else np.zeros(0, np.int64), segment_plant,
                      polygon_segment, np.broadcast_to(np.asarray(leaf_plant, np.int64), (p,)).copy(), base)


# ============================================================================ random numbers
_GAMMA = np.uint64(0x9E3779B97F4A7C15)


def _mix(x: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser of uint64 values (wrapping arithmetic)."""
    with np.errstate(over="ignore"):
        z = x + _GAMMA
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return z ^ (z >> np.uint64(31))


def _uniform(seed: int, scanner: int, stream: int, ids) -> np.ndarray:
    """(k,) uniform numbers in (0, 1), a function of (seed, scanner, stream, id) alone."""
    key = np.array([int(seed) & (2 ** 64 - 1)], dtype=np.uint64)
    for value in (scanner, stream):
        key = _mix(key ^ np.uint64(int(value) & (2 ** 64 - 1)))
    z = _mix(_mix(np.asarray(ids, dtype=np.int64).astype(np.uint64) ^ key))
    return ((z >> np.uint64(11)).astype(np.float64) + 0.5) * 2.0 ** -53


def _normal(seed: int, scanner: int, ids) -> np.ndarray:
    """(k,) standard normal numbers per id (Box-Muller of two streams)."""
    u1, u2 = _uniform(seed, scanner, _NOISE_A, ids), _uniform(seed, scanner, _NOISE_B, ids)
    return np.sqrt(-2.0 * np.log(u1)) * np.cos(2.0 * np.pi * u2)


# ============================================================================ beam grids
def _wrap(angle):
    """Angles brought into [-π, π)."""
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


#: How far past a grid step a box's edge may fall and still take that step's beam (in
#: steps): with the boxes' padding, what keeps rounding from losing a beam.
STEP_SLACK = 1e-9


def _first(x) -> np.ndarray:
    """The first grid index at or after ``x`` (in steps), less :data:`STEP_SLACK`."""
    return np.ceil(np.asarray(x) - STEP_SLACK).astype(np.int64)


def _last(x) -> np.ndarray:
    """The last grid index at or before ``x`` (in steps), plus :data:`STEP_SLACK`."""
    return np.floor(np.asarray(x) + STEP_SLACK).astype(np.int64)


def _xz_corners(lo, hi) -> np.ndarray:
    """(k, 4, 2) the corners of boxes' horizontal (x, z) rectangles."""
    x = np.stack([lo[:, 0], hi[:, 0], hi[:, 0], lo[:, 0]], axis=1)
    z = np.stack([lo[:, 2], lo[:, 2], hi[:, 2], hi[:, 2]], axis=1)
    return np.stack([x, z], axis=-1)


class TerrestrialBeams:
    """The beam grid of a scanner at ``position`` looking at the box (``lo``, ``hi``):
    beam (a, b) at azimuth φ_c + a·Δ and elevation b·Δ (module docstring), a in
    [a0, a0 + na), b in [b0, b0 + nb)."""

    def __init__(self, position, lo, hi, step: float):
        self.origin = np.asarray(position, dtype=np.float64)
        self.step = float(step)
        centre = (np.asarray(lo) + np.asarray(hi)) / 2
        offset = centre - self.origin
        self.phi = math.atan2(offset[2], offset[0]) if (offset[0] or offset[2]) else 0.0
        self.turns = int(math.ceil(2 * math.pi / self.step - 1e-9))
        self.pole = int(math.floor(math.pi / 2 / self.step + 1e-9))
        self.a0, self.a1 = -(self.turns // 2), -(self.turns // 2) + self.turns - 1
        self.b0, self.b1 = -self.pole, self.pole
        self.full_circle = True
        a_lo, a_hi, b_lo, b_hi = self.blocks(np.asarray(lo)[None], np.asarray(hi)[None])
        self.full_circle = bool(a_lo[0] == self.a0 and a_hi[0] == self.a1)
        self.a0, self.a1, self.b0, self.b1 = int(a_lo[0]), int(a_hi[0]), int(b_lo[0]), int(b_hi[0])
        self.na, self.nb = max(self.a1 - self.a0 + 1, 0), max(self.b1 - self.b0 + 1, 0)
        self.pad = 0.0

    @property
    def count(self) -> int:
        return self.na * self.nb

    def _azimuths(self, lo, hi) -> tuple[np.ndarray, np.ndarray]:
        corners = _xz_corners(lo, hi) - self.origin[[0, 2]]
        inside = (lo[:, 0] <= self.origin[0]) & (self.origin[0] <= hi[:, 0]) \
            & (lo[:, 2] <= self.origin[2]) & (self.origin[2] <= hi[:, 2])
        mid = corners.mean(axis=1)
        centre = np.arctan2(mid[:, 1], mid[:, 0])
        rel = _wrap(np.arctan2(corners[..., 1], corners[..., 0]) - centre[:, None])
        off = _wrap(centre - self.phi)
        a_lo = _first((off + rel.min(axis=1)) / self.step)
        a_hi = _last((off + rel.max(axis=1)) / self.step)
        full = inside | (rel.max(axis=1) - rel.min(axis=1) >= np.pi)
        if self.full_circle:                 # a range across the seam behind the plant: all of it
            full |= (a_lo < self.a0) | (a_hi > self.a1)
        return np.where(full, self.a0, np.maximum(a_lo, self.a0)), np.where(full, self.a1, np.minimum(a_hi, self.a1))

    def _elevations(self, lo, hi) -> tuple[np.ndarray, np.ndarray]:
        corners = _xz_corners(lo, hi) - self.origin[[0, 2]]
        far = np.sqrt((corners ** 2).sum(axis=-1)).max(axis=1)
        gap = np.maximum(np.maximum(lo[:, [0, 2]] - self.origin[[0, 2]], self.origin[[0, 2]] - hi[:, [0, 2]]), 0.0)
        near = np.hypot(gap[:, 0], gap[:, 1])
        top, bottom = hi[:, 1] - self.origin[1], lo[:, 1] - self.origin[1]
        theta_hi = np.arctan2(top, np.where(top >= 0, near, far))
        theta_lo = np.arctan2(bottom, np.where(bottom <= 0, near, far))
        b_lo = np.maximum(_first(theta_lo / self.step), self.b0)
        return b_lo, np.minimum(_last(theta_hi / self.step), self.b1)

    def blocks(self, lo, hi):
        """Per box (k,): the rectangle [a_lo, a_hi] × [b_lo, b_hi] of beams that can meet it
        (empty where a_lo > a_hi or b_lo > b_hi)."""
        return (*self._azimuths(lo, hi), *self._elevations(lo, hi))

    def rays(self, a, b) -> tuple[np.ndarray, np.ndarray]:
        """Origins (k, 3) and unit directions (k, 3) of beams (a, b)."""
        phi = self.phi + np.asarray(a, dtype=np.float64) * self.step
        theta = np.asarray(b, dtype=np.float64) * self.step
        c = np.cos(theta)
        d = np.stack([c * np.cos(phi), np.sin(theta), c * np.sin(phi)], axis=-1)
        return np.broadcast_to(self.origin, d.shape), d


class AirborneBeams:
    """One flight line: pulses at ``origin`` + a·``spacing``·``heading`` (a in [a0, a1]),
    each a fan of beams at b·Δ from the nadir across the track, |b| <= ``fan``."""

    def __init__(self, origin, heading, spacing: float, step: float, fan: int, a0: int, a1: int):
        self.origin = np.asarray(origin, dtype=np.float64)
        self.heading = np.asarray(heading, dtype=np.float64)
        self.across = np.array([-self.heading[2], 0.0, self.heading[0]])
        self.spacing, self.step = float(spacing), float(step)
        self.a0, self.a1, self.b0, self.b1 = int(a0), int(a1), -int(fan), int(fan)
        self.na, self.nb = self.a1 - self.a0 + 1, self.b1 - self.b0 + 1
        self.pad = 0.0

    @property
    def count(self) -> int:
        return self.na * self.nb

    def blocks(self, lo, hi):
        """As :meth:`TerrestrialBeams.blocks`: pulses whose fan plane crosses the box, and
        the across-track angles of the box seen from the pulse's line."""
        corners = _xz_corners(lo, hi) - self.origin[[0, 2]]
        along = corners @ self.heading[[0, 2]]
        across = corners @ self.across[[0, 2]]
        a_lo = np.maximum(_first(along.min(axis=1) / self.spacing), self.a0)
        a_hi = np.minimum(_last(along.max(axis=1) / self.spacing), self.a1)
        w_lo, w_hi = self.origin[1] - hi[:, 1], self.origin[1] - lo[:, 1]        # depth below the line
        u_lo, u_hi = across.min(axis=1), across.max(axis=1)
        angles = np.arctan2(np.stack([u_lo, u_hi, u_lo, u_hi], axis=1), np.stack([w_lo, w_lo, w_hi, w_hi], axis=1))
        b_lo = np.maximum(_first(angles.min(axis=1) / self.step), self.b0)
        b_hi = np.minimum(_last(angles.max(axis=1) / self.step), self.b1)
        inside = (u_lo <= 0) & (u_hi >= 0) & (w_lo <= 0)
        b_lo, b_hi = np.where(inside, self.b0, b_lo), np.where(inside, self.b1, b_hi)
        above = w_hi <= 0
        return a_lo, np.where(above, a_lo - 1, a_hi), b_lo, b_hi

    def rays(self, a, b) -> tuple[np.ndarray, np.ndarray]:
        s = np.asarray(a, dtype=np.float64) * self.spacing
        theta = np.asarray(b, dtype=np.float64) * self.step
        origins = self.origin + s[:, None] * self.heading
        d = np.cos(theta)[:, None] * np.array([0.0, -1.0, 0.0]) + np.sin(theta)[:, None] * self.across
        return origins, d


# ============================================================================ where the scanners are
def _terrestrial_positions(target: ScanTarget, settings: ScanSettings) -> np.ndarray:
    if settings.positions is not None:
        return np.array(settings.positions, dtype=np.float64)
    lo, hi = target.box()
    centre = (lo + hi) / 2
    height = max(float(hi[1] - target.base[1]), 0.0)
    radius = settings.distance
    if radius is None:
        radius = height + 0.5 * float(np.hypot(hi[0] - lo[0], hi[2] - lo[2]))
        radius = radius if radius > 0 else 1.0
    angle = np.radians(settings.azimuth) + 2 * np.pi * np.arange(settings.scanners) / settings.scanners
    y = np.full(settings.scanners, target.base[1] + settings.scanner_height)
    return np.stack([centre[0] + radius * np.cos(angle), y, centre[2] + radius * np.sin(angle)], axis=1)


def _airborne_lines(target: ScanTarget, settings: ScanSettings, limits: Limits | None = None) -> list[AirborneBeams]:
    lo, hi = target.box()
    centre = (lo + hi) / 2
    height = max(float(hi[1] - target.base[1]), 0.0)
    altitude = target.base[1] + (settings.flight_height or (2 * height if height > 0 else 1.0))
    step = math.radians(settings.angular_step)
    fan = int(math.floor(math.radians(settings.scan_angle) / step + 1e-9))
    depth = altitude - lo[1]
    pulse = settings.pulse_spacing or max(depth, 1e-9) * math.tan(step)
    half_swath = max(depth, 0.0) * math.tan(fan * step)
    spacing = settings.line_spacing or (half_swath if fan > 0 else pulse)
    heading = np.array([math.cos(math.radians(settings.azimuth)), 0.0, math.sin(math.radians(settings.azimuth))])
    across = np.array([-heading[2], 0.0, heading[0]])
    corners = _xz_corners(lo[None], hi[None])[0] - centre[[0, 2]]
    along, side = corners @ heading[[0, 2]], corners @ across[[0, 2]]
    # The beams counted in floats before any line is made: a tiny spacing, flight height
    # or pulse spacing (a denormal one too) is refused here, not after the lines fill memory.
    lines_f = (side.max() - side.min() + 2 * half_swath) / spacing + 3
    rays_f = ((along.max() - along.min()) / pulse + 3) * lines_f * (2 * fan + 1) * settings.sub_rays
    limit = (limits or default_limits).max_scan_rays
    if not rays_f <= limit:
        raise LimitError(f"an airborne scan: about {rays_f:.3g} rays ({lines_f:.3g} flight lines), over the "
                         f"limit of {limit:,} ({hint('scan_rays')}; or widen the line or pulse spacing, or "
                         "raise the flight height)")
    a0, a1 = int(math.floor(along.min() / pulse)), int(math.ceil(along.max() / pulse))
    l0 = int(math.floor((side.min() - half_swath) / spacing))
    l1 = int(math.ceil((side.max() + half_swath) / spacing))
    origin = np.array([centre[0], altitude, centre[2]])
    lines = []
    for line in range(l0, l1 + 1):
        beams = AirborneBeams(origin + line * spacing * across, heading, pulse, step, fan, a0, a1)
        beams.line, beams.line_spacing = line, spacing
        lines.append(beams)
    return lines


def scanner_positions(target: ScanTarget, settings: ScanSettings) -> np.ndarray:
    """(s, 3) where the scanners stand (airborne: each flight line's centre point)."""
    if settings.mode == "airborne":
        return np.array([line.origin for line in _airborne_lines(target, settings)]).reshape(-1, 3)
    return _terrestrial_positions(target, settings)


def _reach(origins: np.ndarray, lo, hi) -> float:
    """The farthest distance from any of ``origins`` (k, 3) to the box (lo, hi)."""
    far = np.maximum(np.abs(np.asarray(lo) - origins), np.abs(np.asarray(hi) - origins))
    return float(np.sqrt((far ** 2).sum(axis=1)).max())


def beam_grids(target: ScanTarget, settings: ScanSettings, limits: Limits | None = None) -> list:
    """The beam grid of every scanner (airborne: of every flight line):
    :class:`TerrestrialBeams` or :class:`AirborneBeams`, whose ``rays(a, b)`` gives any
    beam's origin and direction (beam k is (a0 + k // nb, b0 + k % nb)). With a divergence,
    a scanner's ``pad`` widens the box it looks at by the beam's radius at its farthest
    range, so that a beam whose axis misses the plant but a sub-ray hits is fired."""
    lo, hi = target.box()
    half = math.tan(settings.divergence / 2000.0)
    if settings.mode == "airborne":
        return _airborne_lines(target, settings, limits)
    step = math.radians(settings.angular_step)
    grids = []
    for p in _terrestrial_positions(target, settings):
        pad = _reach(p[None], lo, hi) * half * (1 + 1e-9)
        grid = TerrestrialBeams(p, lo - pad, hi + pad, step)
        grid.pad = pad
        grids.append(grid)
    return grids


# ============================================================================ casting
def _sub_rays(directions: np.ndarray, beam_ids: np.ndarray, seed: int, scanner: int, samples: int,
              half_angle: float) -> np.ndarray:
    """(m·s, 3) the s sub-rays of each beam (m,): a Vogel spiral over the cone of
    ``half_angle``, turned by a random angle per beam; sub-ray j of beam i is row i·s + j."""
    if samples == 1:
        return directions
    e1 = unit(cross(directions, np.where(np.abs(directions[:, 1:2]) < 0.9, [[0.0, 1, 0]], [[1.0, 0, 0]])))
    e2 = cross(directions, e1)
    turn = 2 * np.pi * _uniform(seed, scanner, _TURN, beam_ids)
    j = np.arange(samples)
    radius = np.tan(half_angle * np.sqrt((j + 0.5) / samples))                      # (s,)
    psi = turn[:, None] + GOLDEN_ANGLE * j[None, :]                                  # (m, s)
    off = (np.cos(psi)[..., None] * e1[:, None] + np.sin(psi)[..., None] * e2[:, None]) * radius[None, :, None]
    return unit(directions[:, None, :] + off).reshape(-1, 3)


def _triangle_hits(target: ScanTarget, tri: np.ndarray, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """(m,) t of rays (m,) against the target's triangles ``tri`` (m,) (Möller-Trumbore,
    both faces, float64; inf for a miss, a ray in the triangle's plane included)."""
    v0, e1, e2, size = (a[tri] for a in target.triangle_edges)
    p = cross(dirs, e2)
    det = dot(e1, p)
    scale = size * np.sqrt(dot(dirs, dirs))
    ok = np.abs(det) > 1e-12 * scale
    inv = 1.0 / np.where(ok, det, 1.0)
    s = origins - v0
    u = dot(s, p) * inv
    q = cross(s, e1)
    v = dot(dirs, q) * inv
    t = dot(e2, q) * inv
    ok &= (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    return np.where(ok, t, np.inf)


def target_hits(target: ScanTarget, *, t_min: float = 0.0, origin=None, precision: str = "float64"):
    """The primitive test of ``target`` for :func:`~plantgen.geometry.rays.bvh.trace_bvh`:
    ``hits(prims (k,), origins (k, 3), dirs (k, 3)) -> t (k,)`` (inf: a miss; only hits
    beyond ``t_min``): rows by the reference's pair test (in ``precision`` relative to
    ``origin``), leaf triangles by :func:`_triangle_hits`."""
    if not target.rows:
        tester = None
    elif precision == "float64" and origin is None:       # the rows uploaded once per target
        tester = shallow_copy(target.pair_tester)
        tester.t_min = float(t_min)
    else:
        tester = PairTester(target.frusta, dtype=np.dtype(precision), origin=origin, t_min=t_min)

    def hits(prim, origins, dirs):
        t, _ = cast_first_returns(target, origins, dirs, tester=tester, primitives=prim)
        return np.where(t > t_min, t, np.inf)

    return hits


def cast_first_returns(target: ScanTarget, origins, dirs, *, precision: str = "float64",
                       tester: PairTester | None = None, primitives=None) -> tuple[np.ndarray, np.ndarray]:
    """The first hit of each ray (m,) among ``primitives`` ((m,) the primitive to test
    each ray against; None: all of them, brute force, for small tests): t (m,) (inf: none)
    and the primitive hit (m,) (-1). Rays need unit directions for t to be a range."""
    O = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    D = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    if primitives is None:
        ray = np.repeat(np.arange(len(O)), len(target))
        prim = np.tile(np.arange(len(target)), len(O))
        t, hit = cast_first_returns(target, O[ray], D[ray], precision=precision, tester=tester, primitives=prim)
        best, where = np.full(len(O), np.inf), np.full(len(O), -1)
        order = np.lexsort((t, ray))
        first = order[np.r_[True, ray[order][1:] != ray[order][:-1]]] if len(order) else order
        best[ray[first]], where[ray[first]] = t[first], np.where(np.isfinite(t[first]), prim[first], -1)
        return best, where
    prim = np.asarray(primitives, dtype=np.int64)
    t = np.full(len(prim), np.inf)
    wood = prim < target.rows
    if wood.any():
        tester = tester or PairTester(target.frusta, dtype=np.dtype(precision), origin=O[wood][0])
        t[wood] = tester(prim[wood], O[wood], D[wood])[0]
    if (~wood).any():
        t[~wood] = _triangle_hits(target, prim[~wood] - target.rows, O[~wood], D[~wood])
    return t, np.where(np.isfinite(t), prim, -1)


#: Memory a returned point takes at a scan's peak (its range, primitive and sub-ray kept
#: while the scanner's beams are traced, their sort, then the point's compact columns and
#: the file's record), rounded up: the budget ``scan_bytes`` counts the points kept as they
#: come (measured: the forest from 2,1.5,10 at 0.05° and at 0.2°, 8,798,263 and 550,215
#: points, 1.34 GB and 0.32 GB peak resident: 124 bytes a point more).
POINT_BYTES = 160
#: Beams traced at a time (times a diverging beam's sub-rays): what bounds a scan's
#: working memory whatever its beam count.
SCAN_CHUNK_RAYS = 1 << 18
#: Neighbouring beams of a scanner (one origin) that walk the BVH's upper levels together.
PACKET_RAYS = 64


def _found_again(target, finder, origins, dirs) -> tuple[np.ndarray, np.ndarray]:
    """The first hits (t, primitive) of rays whose primitive ``finder(target, origins,
    dirs) -> (t, primitive)`` finds (the GPU's float32 search), each range solved again in
    float64 against that primitive (``target.hit_distance``); a ray whose primitive the
    float64 test then misses (a graze rounding decided the other way) is traced again by
    the float64 reference."""
    _, prim = finder(target, origins, dirs)
    prim = np.asarray(prim, np.int64).copy()
    t = np.full(len(prim), np.inf)
    found = np.flatnonzero(prim >= 0)
    t[found] = target.hit_distance(prim[found], origins[found], dirs[found])
    lost = found[~np.isfinite(t[found])]
    if len(lost):
        t[lost], prim[lost] = target.first_hits(origins[lost], dirs[lost])
    return t, np.where(np.isfinite(t), prim, -1)


def _candidates(target: ScanTarget, grid, settings: ScanSettings, seed: int, scanner: int, max_pairs: int,
                progress=None, finder=None, hold=None):
    """(sub-ray ids, t, primitive) of the first hit of each of the scanner's sub-rays that
    hits, traced through the target's BVH ``max_pairs`` sub-rays at a time (with a
    ``finder`` and precision float32: found by it, solved again in float64,
    :func:`_found_again`). ``hold(hits)`` is told each chunk's hits as they are kept (the
    scan's memory budget)."""
    s = settings.sub_rays
    step = max(1, min(max_pairs, SCAN_CHUNK_RAYS) // s)
    found = []
    for start in range(0, grid.count, step):
        beam = np.arange(start, min(start + step, grid.count), dtype=np.int64)
        origins, dirs = grid.rays(grid.a0 + beam // grid.nb, grid.b0 + beam % grid.nb)
        dirs = _sub_rays(dirs, beam, seed, scanner, s, settings.divergence / 2000.0)
        sub = (beam[:, None] * s + np.arange(s)).reshape(-1)
        if finder is not None and settings.precision == "float32":
            t, prim = _found_again(target, finder, np.repeat(origins, s, axis=0), dirs)
        else:
            t, prim = target.first_hits(np.repeat(origins, s, axis=0), dirs, precision=settings.precision,
                                        origin=grid.origin, packets=PACKET_RAYS)
        hit = np.isfinite(t)
        found.append((sub[hit], t[hit], prim[hit]))
        if hold is not None:
            hold(len(found[-1][0]))
        if progress is not None:
            progress(len(beam))
    if not found:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64)
    return tuple(np.concatenate(parts) for parts in zip(*found, strict=True))


def _nearest(key: np.ndarray, t: np.ndarray, *others) -> tuple:
    """The rows with the smallest t of each key, ordered by key."""
    order = np.lexsort((t, key))
    first = order[np.r_[True, key[order][1:] != key[order][:-1]]] if len(order) else order
    return (key[first], t[first], *(o[first] for o in others))


def _beam_returns(sub, t, prim, samples: int, how: str):
    """(beams, range, primitive) of every beam with a return, in beam order."""
    sub, t, prim = _nearest(sub, t, prim)              # each sub-ray's first hit
    beam = sub // samples
    if how == "first" or samples == 1:
        beam, t, prim = _nearest(beam, t, prim)
        return beam, t, prim
    starts = np.flatnonzero(np.r_[True, beam[1:] != beam[:-1]])
    counts = np.diff(np.r_[starts, len(beam)])
    mean = np.add.reduceat(t, starts) / counts
    group = np.repeat(np.arange(len(starts)), counts)
    closest = _nearest(group, np.abs(t - mean[group]), np.arange(len(t)))[2]
    return beam[starts], mean, prim[closest]


def primitive_labels(target: ScanTarget, prim: np.ndarray) -> dict:
    """The labels (plant, part, order, segment, leaf: (k,) each) of primitives ``prim`` (k,)."""
    wood = prim < target.rows
    row = np.where(wood, prim, 0)
    tri = np.where(wood, 0, prim - target.rows)
    polygon = target.triangle_polygon[tri] if len(target.triangles) else np.zeros(len(prim), np.int64)
    hang = target.polygon_segment[polygon] if len(target.polygon_segment) else np.full(len(prim), -1)
    segment = np.where(wood, target.frusta.segment[row] if target.rows else -1, hang)
    safe = np.maximum(segment, 0)
    has = segment >= 0
    order = np.where(has, target.segment_order[safe] if len(target.segment_order) else -1, -1)
    leaf_plant = target.polygon_plant[polygon] if len(target.polygon_plant) else np.zeros(len(prim), np.int64)
    plant = np.where(wood, target.segment_plant[safe] if len(target.segment_plant) else 0, leaf_plant)
    part = np.where(wood, np.where(order == 0, STEM, BRANCH), LEAF)
    return {"plant": plant, "part": part, "order": order, "segment": segment, "leaf": np.where(wood, -1, polygon)}


@dataclass(frozen=True, eq=False)
class BeamReturns:
    """One scanner's returns before noise: ``beam`` (k,) the beams with a return (index
    a·nb + b into the scanner's grid, increasing), ``range`` (k,) their exact ranges and
    ``primitive`` (k,) what each hit (a frustum row, or rows + a leaf triangle)."""

    scanner: int
    beam: np.ndarray
    range: np.ndarray
    primitive: np.ndarray
    beams: int                       # beams the scanner fired


def beam_returns(target: ScanTarget, settings: ScanSettings, seed: int = 0, *,
                 max_pairs: int = 1 << 20, finder=None) -> list[BeamReturns]:
    """Every scanner's :class:`BeamReturns` (what :func:`scan_plant` turns into points;
    the benchmark compares precisions beam by beam); ``finder`` as :func:`scan_points`."""
    out = []
    for k, grid in enumerate(beam_grids(target, settings)):
        sub, t, prim = _candidates(target, grid, settings, seed, k, max_pairs, finder=finder)
        beam, t, prim = _beam_returns(sub, t, prim, settings.sub_rays, settings.beam_return)
        out.append(BeamReturns(k, beam, t, prim, grid.count))
    return out


#: Beams a scanner samples (at random, a fixed seed) to estimate how many of its beams
#: return, before a scan starts (:func:`expected_points`).
RETURN_SAMPLE = 4096


def expected_points(target, grids, sample: int = RETURN_SAMPLE) -> float:
    """About how many points the scanners' beam ``grids`` return from ``target``: each
    grid's beam count times the share of ``sample`` of its beams (drawn at random, seed 0)
    that hit, traced by the float64 reference (with 4,096, a 3-sigma error of about 2 % of
    the beams; the scan's budget also counts the points as they come)."""
    rng = np.random.default_rng(0)
    out = 0.0
    for grid in grids:
        if grid.count <= 0:
            continue
        beam = np.unique(rng.integers(0, grid.count, min(grid.count, max(sample, 1)), dtype=np.int64))
        origins, dirs = grid.rays(grid.a0 + beam // grid.nb, grid.b0 + beam % grid.nb)
        t, _ = target.first_hits(origins, dirs, origin=grid.origin)
        out += grid.count * float(np.isfinite(t).mean())
    return out


#: Points labelled and placed at a time by :func:`_scan_one` (its temporaries' bound).
LABEL_CHUNK = 1 << 20


def _scan_one(target: ScanTarget, grid, settings: ScanSettings, seed: int, scanner: int, max_pairs: int,
              progress=None, finder=None, hold=None) -> dict:
    """One scanner's points as :class:`PointCloud`'s columns (its compact dtypes), labelled
    and placed :data:`LABEL_CHUNK` points at a time, so that no int64 or float64
    temporary of every point is made beside them."""
    sub, t, prim = _candidates(target, grid, settings, seed, scanner, max_pairs, progress, finder, hold)
    beam, t, prim = _beam_returns(sub, t, prim, settings.sub_rays, settings.beam_return)
    del sub
    if settings.range_noise > 0:
        t = t + settings.range_noise * _normal(seed, scanner, beam)
    n = len(beam)
    out = {"xyz": np.empty((n, 3)), **{name: np.empty(n, dtype) for name, dtype in LABELS.items()}}
    out["scanner"][:] = scanner
    for a in range(0, n, LABEL_CHUNK):
        part = slice(a, min(a + LABEL_CHUNK, n))
        b = beam[part]
        origins, dirs = grid.rays(grid.a0 + b // grid.nb, grid.b0 + b % grid.nb)
        out["xyz"][part] = origins + t[part, None] * dirs
        for name, values in target.primitive_labels(prim[part]).items():
            out[name][part] = values
    return out


def _metadata(settings: ScanSettings, seed: int) -> dict:
    from dataclasses import asdict

    meta = {k: (list(map(list, v)) if k == "positions" and v is not None else v) for k, v in asdict(settings).items()}
    return {"generator": "plantgen scan", "seed": int(seed), **meta}


def scan_plant(skeleton: Skeleton, leaves: Polygons | None = None, settings: ScanSettings | None = None,
               seed: int = 0, *, frusta: Frusta | None = None, plant=0, leaf_plant=None,
               topology: Branches | None = None, limits: Limits | None = None,
               max_pairs: int = 1 << 20, progress=None, finder=None) -> PointCloud:
    """A simulated laser scan of a plant (see the module docstring): ``skeleton`` (skinned
    here unless its ``frusta`` are given) and its ``leaves`` (or None), scanned as
    ``settings`` say, noise and beam turns drawn from ``seed``. ``plant`` labels the points
    (one number, or (n,) per segment: a scene's instances; ``leaf_plant`` (p,) per leaf).
    The beams fired (times the sub-rays of a diverging beam) are counted against the limit
    ``scan_rays`` before anything is cast; ``progress`` and ``finder`` as
    :func:`scan_points` takes them."""
    settings = settings or ScanSettings()
    target = scan_target(skeleton, leaves, frusta=frusta, plant=plant, leaf_plant=leaf_plant, topology=topology)
    return scan_points(target, settings, seed, limits=limits, max_pairs=max_pairs, progress=progress, finder=finder)


def scan_points(target, settings: ScanSettings, seed: int = 0, *, limits: Limits | None = None,
                max_pairs: int = 1 << 20, progress=None, finder=None) -> PointCloud:
    """The :class:`PointCloud` of a scan of ``target`` (a :class:`ScanTarget` or a
    :class:`SceneTarget`): what :func:`scan_plant` and :func:`scan_scene` return.
    ``progress("scan", beams done, beams)`` is called after each chunk of beams.
    ``finder``: with ``settings.precision`` float32, ``finder(target, origins, dirs) ->
    (t, primitive)`` finds each beam's primitive (the GPU's search,
    :func:`plantgen.gl.trace.trace_target`; this module draws nothing) and each range is
    solved again in float64 against it, so ranges are the reference's."""
    if not len(target):
        return PointCloud.empty(metadata=_metadata(settings, seed))
    grids = beam_grids(target, settings, limits)
    total = sum(g.count for g in grids)
    (limits or default_limits).check("scan_rays", total * settings.sub_rays, f"a scan of {len(grids)} scanners")
    most = (limits or default_limits).max_scan_bytes
    expected = expected_points(target, grids, min(RETURN_SAMPLE, max_pairs, SCAN_CHUNK_RAYS))
    if expected * POINT_BYTES > most:
        raise LimitError(f"a scan of {len(grids)} scanners: its {total:,} beams would return about {expected:,.0f} "
                         f"points (from a sample of its beams), about {expected * POINT_BYTES / 2**20:,.0f} MiB, over "
                         f"the limit of {most / 2**20:,.0f} MiB ({hint('scan_bytes')}; or a coarser --angular-step)")
    done, held = [0], [0]

    def step(beams: int) -> None:
        done[0] += beams
        if progress is not None:
            progress("scan", done[0], total)

    def hold(hits: int) -> None:         # the points kept so far, against the budget, as they come
        held[0] += hits
        if held[0] * POINT_BYTES > most:
            raise LimitError(f"a scan of {len(grids)} scanners: its first {done[0] + 1:,} of {total:,} beams "
                             f"already returned {held[0]:,} points, about {held[0] * POINT_BYTES / 2**20:,.0f} MiB, "
                             f"over the limit of {most / 2**20:,.0f} MiB ({hint('scan_bytes')}; or a coarser "
                             "--angular-step)")

    parts = [_scan_one(target, g, settings, seed, k, max_pairs, step, finder, hold) for k, g in enumerate(grids)]
    merged = {}
    for name in ("xyz", *LABELS):        # joined column by column, each scanner's freed as it goes
        merged[name] = parts[0][name] if len(parts) == 1 else np.concatenate([p[name] for p in parts])
        for p in parts:
            del p[name]
    return PointCloud(**merged, scanners=np.array([g.origin for g in grids]).reshape(-1, 3),
                      metadata=_metadata(settings, seed))


# ============================================================================ instanced scenes
@dataclass(frozen=True, eq=False)
class SceneTarget:
    """What a scan of an instanced scene sees without placing every copy: a
    :class:`ScanTarget` per distinct plant in its own frame (``targets``), the placements
    of its copies (``matrices[k]``, (c_k, 4, 4)) and, per copy (numbered plant by plant),
    its scene ``instance``; ``segment_offset`` and ``polygon_offset`` ((instances,)) turn a
    plant's segment and leaf numbers into the merged scene's. A primitive is
    ``copy · stride + the plant's primitive``. Traced through a two-level BVH
    (:func:`~plantgen.geometry.rays.bvh.scene_bvh`): memory is the distinct plants' plus a few
    hundred bytes a copy, whatever the copies."""

    targets: tuple
    matrices: tuple
    instance: np.ndarray
    segment_offset: np.ndarray
    polygon_offset: np.ndarray
    base: np.ndarray

    @cached_property
    def bvh(self):
        from .bvh import scene_bvh

        return scene_bvh([t.bvh for t in self.targets], self.matrices)

    @property
    def stride(self) -> int:
        return max((len(t) for t in self.targets), default=1) or 1

    def __len__(self) -> int:
        return sum(len(t) * len(m) for t, m in zip(self.targets, self.matrices, strict=True))

    def box(self) -> np.ndarray:
        """(2, 3) the box around every copy (zeros for none)."""
        if not len(self):
            return np.zeros((2, 3))
        keep = np.repeat([len(t) > 0 for t in self.targets], [len(m) for m in self.matrices])
        return np.stack([self.bvh.copy_lo[keep].min(axis=0), self.bvh.copy_hi[keep].max(axis=0)])

    def first_hits(self, origins, dirs, *, precision: str = "float64", origin=None, any_hit: bool = False,
                   t_min: float = 0.0, t_max=np.inf, packets: int = 0):
        """As :meth:`ScanTarget.first_hits`, each ray moved into the frames of the copies it
        meets (in float64); primitives as ``copy · stride + primitive``."""
        from .bvh import trace_scene

        hits = [target_hits(t, precision=precision, t_min=t_min) for t in self.targets]
        t, copy, prim = trace_scene(self.bvh, origins, dirs, hits, any_hit=any_hit, t_min=t_min, t_max=t_max,
                                    plant_boxes=[t.box_columns for t in self.targets])
        return t, np.where(copy >= 0, copy * self.stride + prim, -1)

    def split(self, key):
        """(copy, plant, primitive of the plant) (k,) each of primitives ``key`` (k,)."""
        key = np.asarray(key, dtype=np.int64)
        copy = key // self.stride
        return copy, self.bvh.plant[copy].astype(np.int64), key % self.stride

    def hit_distance(self, key, origins, dirs, *, t_min: float = 0.0) -> np.ndarray:
        """As :meth:`ScanTarget.hit_distance`, in each copy's frame."""
        copy, plant, prim = self.split(key)
        t = np.full(len(copy), np.inf)
        for k in np.unique(plant):
            sel = np.flatnonzero(plant == k)
            o, d = self.bvh.rays_to_copies(copy[sel], origins[sel], dirs[sel])
            t[sel] = self.targets[k].hit_distance(prim[sel], o, d, t_min=t_min)
        return t

    def primitive_labels(self, key) -> dict:
        """The labels of primitives ``key`` (``copy · stride + primitive``), numbered as the
        merged scene numbers its segments and leaves."""
        copy, plant, prim = self.split(key)
        out = {name: np.zeros(len(key), np.int64) for name in ("plant", "part", "order", "segment", "leaf")}
        for k in np.unique(plant):
            sel = np.flatnonzero(plant == k)
            local = primitive_labels(self.targets[k], prim[sel])
            inst = self.instance[copy[sel]]
            out["plant"][sel] = inst
            out["part"][sel], out["order"][sel] = local["part"], local["order"]
            out["segment"][sel] = np.where(local["segment"] >= 0, local["segment"] + self.segment_offset[inst], -1)
            out["leaf"][sel] = np.where(local["leaf"] >= 0, local["leaf"] + self.polygon_offset[inst], -1)
        return out


def scene_target(plants, *, skin=None) -> SceneTarget:
    """The :class:`SceneTarget` of a scene's distinct plants (``plants``: each with a
    ``skeleton`` and ``polygons`` (leaves or None) in its own frame, ``matrices`` (k, 4, 4)
    and ``instances`` (k,), as :meth:`plantgen.scene.Scene.plants` gives them), each
    skinned once by ``skin`` (a function of a skeleton; default
    :func:`~plantgen.geometry.skeletons.skin.skin_skeleton`)."""
    from ..skeletons.skin import skin_skeleton

    skin = skin or skin_skeleton
    plants = list(plants)
    count = 1 + max((int(np.max(p.instances)) for p in plants if len(p.instances)), default=-1)
    segments, polygons = np.zeros(count, np.int64), np.zeros(count, np.int64)
    targets, matrices, instance = [], [], []
    base, first = np.zeros(3), count
    for p in plants:
        leaves = p.polygons if p.polygons is not None and len(p.polygons.triangles) else None
        targets.append(scan_target(p.skeleton, leaves, frusta=skin(p.skeleton)))
        inst = np.asarray(p.instances, np.int64)
        matrices.append(np.asarray(p.matrices, np.float64).reshape(-1, 4, 4))
        instance.append(inst)
        segments[inst] = len(p.skeleton)
        polygons[inst] = len(p.polygons) if p.polygons is not None else 0
        if len(p.skeleton) and len(inst) and inst.min() < first:     # the merged skeleton's first point
            j = int(np.argmin(inst))
            first, base = int(inst[j]), matrices[-1][j, :3, :3] @ p.skeleton.start[0] + matrices[-1][j, :3, 3]
    offset = lambda sizes: np.concatenate([[0], np.cumsum(sizes)[:-1]]) if len(sizes) else sizes  # noqa: E731
    return SceneTarget(tuple(targets), tuple(matrices), np.concatenate(instance) if instance else
                       np.zeros(0, np.int64), offset(segments), offset(polygons), base)


def scan_scene(plants, settings: ScanSettings | None = None, seed: int = 0, *, skin=None,
               limits: Limits | None = None, max_pairs: int = 1 << 20, progress=None, finder=None) -> PointCloud:
    """A simulated laser scan of an instanced scene (its distinct ``plants``, as
    :func:`scene_target` takes them), each plant skinned once and its copies traced
    through a two-level BVH: the same points, labels numbered as for the merged scene,
    as :func:`scan_plant` of the merged skeleton gives (ranges to rounding), in the
    memory of the distinct plants."""
    settings = settings or ScanSettings()
    return scan_points(scene_target(plants, skin=skin), settings, seed, limits=limits, max_pairs=max_pairs,
                       progress=progress, finder=finder)
