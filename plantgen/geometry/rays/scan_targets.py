"""What a scan (or a trace) is cast against: :class:`ScanTarget`, one plant's frusta and leaf
triangles with their BVH and each primitive's labels, and :class:`SceneTarget`, a scene's
distinct plants and their placed copies; their first returns (exact cones, Möller-Trumbore
leaves) and the labels of what a ray hit. The scan itself: :mod:`plantgen.geometry.rays.scan`."""

from __future__ import annotations

import sys
from copy import copy as shallow_copy
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..meshes.polygons import Polygons
from ..skeletons.frusta import Frusta
from ..skeletons.skeleton import Skeleton
from ..skeletons.topology import Branches, branches
from ..vec import cross, dot
from .reference import PairTester, row_boxes
from .scan_settings import BRANCH, LEAF, STEM, ScanError


# ============================================================================ what a scan sees
def _native_on(native: bool | None) -> bool:
    """Whether a float64 trace walks the compiled traversal: not where ``native`` is False
    (the numpy oracle), nor where :func:`plantgen.geometry.rays.native_trace.available` is
    not (numba missing or failing: one line says so)."""
    if native is False:
        return False
    from .native_trace import available  # numba's import is paid by the first trace, not by every import

    return available()


#: How a target's BVH splits where the compiled build makes it. The forest's plants (91,264
#: primitives): 47 ms against the LBVH's 7 ms; the compiled walk over the SAH trees traced
#: 1.25x (primary), 1.26x (shadow) and 1.22x (scan beams) the rays a second of the LBVH's
#: (the peers bench's rays, 7 interleaved rounds).
COMPILED_METHOD = "sah"


def _compiled_ready() -> bool:
    """Whether the compiled kernels already run in this process (a trace warmed them up,
    :func:`plantgen.geometry.rays.native_trace.warm_up`): a target built where they do
    not (a GPU scan's) neither imports numba nor compiles for its BVH."""
    native = sys.modules.get(__package__ + ".native_trace")
    return native is not None and native.compile_seconds() is not None


@dataclass(frozen=True, eq=False)
class ScanTarget:
    """The primitives a scan sees and their labels: the frusta's rows (primitives
    0..n-1) and the leaf triangles (n..n+t-1), each with an axis-aligned box ``lo``,
    ``hi`` ((n + t, 3)); per segment its branch order and plant, per leaf polygon its
    segment and plant. ``split``: how its BVH splits (:attr:`bvh`): "auto", or a
    :data:`~plantgen.geometry.rays.bvh.BVH_METHODS` name."""

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
    split: str = "auto"

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
        """The :class:`~plantgen.geometry.rays.bvh.BVH` over the primitives' boxes, built on
        first use, by the compiled build where the compiled traversal already runs in this
        process (else numpy's). It splits as :attr:`split` says; "auto": by the binned SAH
        where compiled (:data:`COMPILED_METHOD`: a better tree than the LBVH, which the many
        rays a scan traces pay back), else the LBVH (a GPU scan's, without numba). Any tree
        gives the same hits."""
        from .bvh import build_bvh

        compiled = _compiled_ready()
        method = self.split if self.split != "auto" else (COMPILED_METHOD if compiled else "lbvh")
        return build_bvh(self.lo, self.hi, method=method, compiled=compiled)

    def first_hits(self, origins, dirs, *, precision: str = "float64", origin=None, any_hit: bool = False,
                   t_min: float = 0.0, t_max=np.inf, packets: int = 0, native: bool | None = None):
        """t (m,) and primitive (m,) of each ray's first hit in (t_min, t_max) (inf, -1:
        none; ``any_hit``: any hit), through the BVH (rows tested in ``precision``
        relative to ``origin``; ``packets`` as :func:`~plantgen.geometry.rays.bvh.trace_bvh`
        takes it). float64 walks the compiled traversal
        (:mod:`plantgen.geometry.rays.native_trace`) where it runs, else (and with ``native``
        False: the numpy oracle) :func:`~plantgen.geometry.rays.bvh.trace_bvh`."""
        from .bvh import trace_bvh

        if precision == "float64" and _native_on(native):
            t, _, prim = self.native.trace(origins, dirs, any_hit=any_hit, t_min=t_min, t_max=t_max, origin=origin)
            return t, prim
        hits = target_hits(self, origin=origin, precision=precision, t_min=t_min)
        return trace_bvh(self.bvh, origins, dirs, hits, any_hit=any_hit, t_min=t_min, t_max=t_max,
                         boxes=self.box_columns, packets=packets)

    @cached_property
    def native(self):
        """The compiled traversal's :class:`~plantgen.geometry.rays.native_trace.NativeScene`,
        from :attr:`bvh` (gathered on first use)."""
        from .native_trace import native_scene

        return native_scene(self)

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
        """t (k,) of rays (k,) against primitives ``prim`` (k,) in float64 (inf: a miss;
        compiled where :mod:`plantgen.geometry.rays.native_trace` runs)."""
        if len(self) and _native_on(None):
            return self.native.distances(0, prim, origins, dirs, t_min=t_min)
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


def _leaf_boxes(leaves: Polygons | None, compiled: bool):
    """The leaf triangles' corners (t, 3, 3), polygons (t,) and padded boxes (lo, hi):
    the corners' min and max, widened by 1e-9 of the largest coordinate plus 1e-12
    (compiled where ``compiled``: :func:`~plantgen.geometry.rays.native_build.leaf_boxes`,
    the same numbers)."""
    if compiled and leaves is not None and len(leaves.triangles):
        from .native_build import leaf_boxes

        triangles, t_lo, t_hi = leaf_boxes(leaves.vertices, np.asarray(leaves.triangles).reshape(-1, 3))
        return triangles, np.asarray(leaves.polygon, np.int64), t_lo, t_hi
    triangles, triangle_polygon = _leaf_arrays(leaves)
    if not len(triangles):
        return triangles, triangle_polygon, np.zeros((0, 3)), np.zeros((0, 3))
    v0, v1, v2 = triangles[:, 0], triangles[:, 1], triangles[:, 2]   # min / max pairwise: exact, and fast
    t_lo, t_hi = np.minimum(np.minimum(v0, v1), v2), np.maximum(np.maximum(v0, v1), v2)
    big = np.maximum(np.abs(t_lo), np.abs(t_hi))
    pad = 1e-9 * np.maximum(np.maximum(big[:, 0], big[:, 1]), big[:, 2])[:, None] + 1e-12
    return triangles, triangle_polygon, t_lo - pad, t_hi + pad


def scan_target(skeleton: Skeleton, leaves: Polygons | None = None, *, frusta: Frusta | None = None,
                plant=0, leaf_plant=None, topology: Branches | None = None, compiled: bool = False,
                split: str = "auto") -> ScanTarget:
    """What a scan of ``skeleton`` (skinned here unless ``frusta`` are given) and its
    ``leaves`` sees. ``plant``: one number for every point, or (n,) per segment (a scene's
    instances); ``leaf_plant``: (p,) per leaf polygon (default: its segment's plant).
    ``compiled``: the rows' and leaves' boxes computed by compiled code
    (:func:`plantgen.geometry.rays.native_build.row_boxes` and
    :func:`~plantgen.geometry.rays.native_build.leaf_boxes`: the same numbers), for a
    caller that has checked the compiled code runs (a light traced many times a step).
    ``split``: how its BVH splits (:class:`ScanTarget`)."""
    from ..skeletons.skin import skin_skeleton  # skinning is the heavy import; a given frusta skips it

    frusta = skin_skeleton(skeleton) if frusta is None else frusta
    topology = topology or branches(skeleton)
    n = len(skeleton)
    p = len(leaves) if leaves is not None else 0
    for name, value, count, what in (("plant", plant, n, "segment"), ("leaf_plant", leaf_plant, p, "leaf")):
        if value is not None and np.ndim(value) and np.shape(value) != (count,):
            raise ScanError(f"{name} must be one number or one per {what} ({count}), got {np.shape(value)[0]}")
    segment_plant = np.broadcast_to(np.asarray(plant, dtype=np.int64), (n,)).copy()
    triangles, triangle_polygon, t_lo, t_hi = _leaf_boxes(leaves, compiled)
    polygon_segment = np.asarray(leaves.segment, np.int64) if p else np.zeros(0, np.int64)
    if leaf_plant is None:
        own = np.asarray(plant, dtype=np.int64)
        leaf_plant = np.full(p, int(own) if own.ndim == 0 else 0, dtype=np.int64)
        hung = polygon_segment >= 0
        leaf_plant[hung] = segment_plant[polygon_segment[hung]]
    if compiled and len(frusta):
        from .native_build import row_boxes as compiled_row_boxes

        lo, hi = compiled_row_boxes(frusta)
    else:
        lo, hi = row_boxes(frusta) if len(frusta) else (np.zeros((0, 3)), np.zeros((0, 3)))
    lo, hi = np.concatenate([lo, t_lo]), np.concatenate([hi, t_hi])
    base = skeleton.start[0].copy() if n else (triangles.reshape(-1, 3).min(axis=0) if len(triangles) else np.zeros(3))
    return ScanTarget(frusta, triangles, triangle_polygon, lo, hi, topology.segment_order.astype(np.int64)
                      if n else np.zeros(0, np.int64), segment_plant,
                      polygon_segment, np.broadcast_to(np.asarray(leaf_plant, np.int64), (p,)).copy(), base, split)


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

    @cached_property
    def native(self):
        """The compiled traversal's arrays, from :attr:`bvh` (gathered on first use)."""
        from .native_trace import native_scene

        return native_scene(self)

    @property
    def stride(self) -> int:
        return max((len(t) for t in self.targets), default=1) or 1

    def __len__(self) -> int:
        return sum(len(t) * len(m) for t, m in zip(self.targets, self.matrices, strict=True))

    def box(self) -> np.ndarray:
        """(2, 3) the box around every copy (zeros for none)."""
        if not len(self):
            return np.zeros((2, 3))
        # the copies' boxes as scene_bvh makes them (a plant's root box is its primitives'
        # union), without building the trees: a scan sizes its beams before its budget checks
        from .bvh import copy_boxes

        parts = [copy_boxes(t.lo.min(axis=0), t.hi.max(axis=0), m) for t, m in zip(self.targets, self.matrices,
                                                                                  strict=True) if len(t) and len(m)]
        return np.stack([np.concatenate([p[0] for p in parts]).min(axis=0),
                         np.concatenate([p[1] for p in parts]).max(axis=0)])

    def first_hits(self, origins, dirs, *, precision: str = "float64", origin=None, any_hit: bool = False,
                   t_min: float = 0.0, t_max=np.inf, packets: int = 0, native: bool | None = None):
        """As :meth:`ScanTarget.first_hits`, each ray moved into the frames of the copies it
        meets (in float64); primitives as ``copy · stride + primitive``."""
        from .bvh import trace_scene

        if precision == "float64" and _native_on(native):
            t, copy, prim = self.native.trace(origins, dirs, any_hit=any_hit, t_min=t_min, t_max=t_max)
            return t, np.where(copy >= 0, copy * self.stride + prim, -1)
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
