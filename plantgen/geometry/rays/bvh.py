"""Bounding volume hierarchies over axis-aligned boxes: the one search structure that
rendering, scanning, light queries and :func:`plantgen.trace` share.

**One level** (:func:`build_bvh`): a binary tree over primitive boxes (frustum rows with
their relief shell and oblique ends, leaf triangles). Nodes are numbered breadth first,
node 0 the root; an internal node's children are ``first`` and ``first + 1``; a leaf holds
``prims[first:first + count]``. The build is vectorised numpy, level by level over every
open node at once, O(n log n), in one of two ways:

- ``method="lbvh"`` (the default): the primitives sorted by the 63-bit Morton code of
  their box centres (21 bits an axis over the centres' bounding cube); a node splits where
  the highest bit in which its first and last codes differ flips (one ``searchsorted``
  over the open nodes per level), in the middle where all its codes are equal. The sort
  is the only O(n log n) step; the levels cost O(nodes).
- ``method="sah"``: binned surface-area heuristic, ``bins`` bins along each axis over the
  node's centre bounds; the split with the least ``count_L·area_L + count_R·area_R``, the
  middle of the node where all centres coincide; each level partitions every open node's
  primitives in one stable O(n) pass. Each level bins every primitive three times
  (``np.minimum.at`` into the bins' boxes), so it costs O(n) a level, O(n log n) in all
  with a larger constant.

Measured (``python -m plantgen.benchmarks.bvh``, ``gallery/bench/llvmpipe/bvh.md``, 2
shared cores, load average 3-4): LBVH builds 1.5-1.7 M primitives a second on the
broadleaf (85,030 rows and leaf triangles) and the pine's needles (448,530), 1.3 M/s on a
million random boxes; binned SAH 0.09-0.12 M/s, 13-15 times slower. SAH's trees are
better (SAH cost 68 against 81 on the needles, 27 against 33 on the broadleaf) and trace
1.1-1.5 times faster there, as fast on the forest. LBVH is the default: its build meets
the goal of a million primitives a second, and a scan or a query pays it once per model;
``method="sah"`` is the knob for a model traced with far more rays than it has
primitives.

A node box is the union of its primitives' boxes, in float64, exactly (no rounding
padding: the primitive boxes carry their own). For the GPU, boxes go to float32
relative to a float64 frame origin rounded outward (:func:`float32_boxes`).

**Two levels** (:func:`build_scene_bvh`): one BVH per distinct plant in its own frame (a
BLAS), and a top-level BVH (TLAS) over the placed copies: a copy's box is the world box
of its plant's root box under the copy's similarity matrix. Per copy: the plant index,
the matrix and its inverse (float64). The top level holds :data:`TOP_LEAF_SIZE` copies a
leaf by default: 0.7 nodes a copy (LBVH), 23 of the 32-byte nodes' bytes, where two copies
a leaf take 1.3 nodes (41 bytes), so that a copy costs the GPU (its 32-byte map included,
:mod:`plantgen.gl.trace`) under 64 bytes.

Pure numpy, no GL; where the compiled traversal runs, a scan target's LBVH is laid out by
compiled code instead (:mod:`plantgen.geometry.rays.native_build`: the same tree, node for
node, without the per-level overhead that dominates the small trees a stand's light builds).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ...errors import PlantgenError
from .morton import highest_bit, morton_codes

__all__ = ["BVH", "BVH_METHODS", "BVHError", "SceneBVH", "TOP_LEAF_SIZE", "box_columns", "brute_force", "build_bvh",
           "build_scene_bvh", "copy_boxes", "float32_boxes", "morton_codes", "reduce_closest", "refit_bvh", "scene_bvh",
           "slab", "trace_bvh", "trace_scene"]

#: How :func:`build_bvh` may split nodes.
BVH_METHODS = ("lbvh", "sah")
#: Copies a leaf of a scene's top level (:func:`build_scene_bvh`'s default ``top_leaf_size``).
TOP_LEAF_SIZE = 4


class BVHError(PlantgenError, ValueError):
    """Boxes or build settings a BVH cannot be built from."""


@dataclass(frozen=True, eq=False)
class BVH:
    """A bounding volume hierarchy (module docstring): per node (``len(lo)`` of them) its
    box ``lo``, ``hi`` ((nodes, 3) float64), ``first`` ((nodes,) int32: an internal
    node's left child, the right one is ``first + 1``; a leaf's offset into ``prims``) and
    ``count`` ((nodes,) int32: 0 internal, >= 1 a leaf); ``prims`` ((n,) int32) the
    primitive ids in leaf order, each exactly once. No primitives: no nodes."""

    lo: np.ndarray
    hi: np.ndarray
    first: np.ndarray
    count: np.ndarray
    prims: np.ndarray

    @property
    def nodes(self) -> int:
        return len(self.first)

    @cached_property
    def columns(self) -> np.ndarray:
        """(6, nodes) the node boxes by coordinate (lo x, y, z, hi x, y, z): what the
        traversal gathers, one row a coordinate."""
        return box_columns(self.lo, self.hi)

    @property
    def leaves(self) -> int:
        return int((self.count > 0).sum())

    @property
    def nbytes(self) -> int:
        """Bytes of the arrays on the CPU."""
        return sum(a.nbytes for a in (self.lo, self.hi, self.first, self.count, self.prims))

    def depth(self) -> int:
        """The levels of the tree (0: empty, 1: a single leaf); counted by the compiled
        build where it built the tree."""
        known = self.__dict__.get("known_depth")
        return known if known is not None else len(self.levels())

    def levels(self) -> list[np.ndarray]:
        """The nodes of each level of the tree, the root's first (none: empty)."""
        levels, level = [], np.array([0]) if self.nodes else np.zeros(0, np.int64)
        while level.size:
            levels.append(level)
            inner = level[self.count[level] == 0]
            level = np.concatenate([self.first[inner], self.first[inner] + 1])
        return levels

    def sah_cost(self, traverse: float = 1.0, intersect: float = 1.0) -> float:
        """The tree's surface-area cost relative to its root box: ``traverse`` per internal
        node and ``intersect`` per primitive of a leaf, each weighted by its box's area over
        the root's (the expected work of a random ray through the root; smaller is better)."""
        if not self.nodes:
            return 0.0
        area = box_area(self.lo, self.hi)
        root = area[0] if area[0] > 0 else 1.0
        inner = self.count == 0
        return float((traverse * area[inner].sum() + intersect * (area * self.count)[~inner].sum()) / root)


def refit_bvh(bvh: BVH, lo, hi) -> BVH:
    """``bvh`` over its primitives moved to boxes ``lo``, ``hi`` ((n, 3) float64, the same
    n primitives): the same tree (nodes, leaves, primitive order), each leaf's box the union
    of its primitives' and each internal node's the union of its children's, bottom up a
    level at a time; O(n), no sort. The boxes are exact whatever the motion; the tree's
    quality (its SAH cost) drifts as the primitives move from where it was built, which a
    sway (every primitive near its rest place) hardly changes, and a rebuild resets."""
    lo, hi = _check_boxes(lo, hi)
    if len(lo) != len(bvh.prims):
        raise BVHError(f"refit_bvh: {len(lo)} primitive boxes for a BVH over {len(bvh.prims)}")
    new_lo, new_hi = np.empty_like(bvh.lo), np.empty_like(bvh.hi)
    leaf = np.flatnonzero(bvh.count > 0)
    if leaf.size:           # the leaves' ranges of `prims` partition it: reduce over them in order
        leaf = leaf[np.argsort(bvh.first[leaf], kind="stable")]
        start = bvh.first[leaf].astype(np.int64)
        new_lo[leaf] = np.minimum.reduceat(lo[bvh.prims], start, axis=0)
        new_hi[leaf] = np.maximum.reduceat(hi[bvh.prims], start, axis=0)
    for level in reversed(bvh.levels()):
        inner = level[bvh.count[level] == 0]
        left = bvh.first[inner]
        new_lo[inner] = np.minimum(new_lo[left], new_lo[left + 1])
        new_hi[inner] = np.maximum(new_hi[left], new_hi[left + 1])
    return BVH(new_lo, new_hi, bvh.first, bvh.count, bvh.prims)


def box_area(lo, hi) -> np.ndarray:
    """(k,) surface areas of boxes (a flat or empty box: 0)."""
    d = np.maximum(np.asarray(hi) - np.asarray(lo), 0.0)
    return 2.0 * (d[..., 0] * d[..., 1] + d[..., 1] * d[..., 2] + d[..., 2] * d[..., 0])


def _check_boxes(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    if lo.ndim != 2 or lo.shape[1:] != (3,) or hi.shape != lo.shape:
        raise BVHError(f"BVH boxes need lo and hi of shape (n, 3), got {lo.shape} and {hi.shape}")
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise BVHError("BVH boxes must be finite")
    if (lo > hi).any():
        raise BVHError(f"BVH boxes need lo <= hi, {int((lo > hi).any(axis=1).sum())} boxes are inverted")
    if len(lo) >= 2 ** 31 - 1:
        raise BVHError(f"a BVH holds fewer than 2**31 primitives, got {len(lo)}")
    return lo, hi


# ------------------------------------------------------------------------------ the splits
def _lbvh_splits(codes: np.ndarray):
    """A split function over primitives already sorted by ``codes``."""

    def split(order, s, e):
        c0, c1 = codes[s], codes[e - 1]
        top = highest_bit(c0 ^ c1)
        value = c1 & ~(top - np.uint64(1))
        mid = np.searchsorted(codes, value, side="left")
        return np.where(top == 0, (s + e) // 2, mid)

    return split


def _ranges(s: np.ndarray, e: np.ndarray):
    """Per element of the concatenated ranges [s, e): its range (m,) and its position."""
    size = e - s
    offsets = np.concatenate([[0], np.cumsum(size)])
    node = np.repeat(np.arange(len(s)), size)
    pos = s[node] + (np.arange(offsets[-1]) - offsets[node])
    return node, pos, offsets


def _sah_splits(lo: np.ndarray, hi: np.ndarray, bins: int):
    centre = 0.5 * (lo + hi)
    lo_t, hi_t = np.ascontiguousarray(lo.T), np.ascontiguousarray(hi.T)

    def split(order, s, e):
        k = len(s)
        node, pos, offsets = _ranges(s, e)
        prim = order[pos]
        c = np.take(centre, prim, axis=0)
        c_lo = np.minimum.reduceat(c, offsets[:-1], axis=0)
        c_hi = np.maximum.reduceat(c, offsets[:-1], axis=0)
        ext = c_hi - c_lo
        ext = np.where(ext > 0, ext, np.inf)[node]                     # flat: every centre in bin 0
        b = np.minimum(((c - c_lo[node]) / ext * bins).astype(np.int64), bins - 1)
        p_lo, p_hi = np.take(lo_t, prim, axis=1), np.take(hi_t, prim, axis=1)
        best_cost = np.full(k, np.inf)
        best_axis = np.zeros(k, np.int64)
        best_bin = np.zeros(k, np.int64)
        for axis in range(3):
            key = node * bins + b[:, axis]
            cnt = np.bincount(key, minlength=k * bins).reshape(k, bins)
            b_lo = np.full((3, k * bins), np.inf)
            b_hi = np.full((3, k * bins), -np.inf)
            for col in range(3):          # 1-D ufunc.at is several times faster than 2-D
                np.minimum.at(b_lo[col], key, p_lo[col])
                np.maximum.at(b_hi[col], key, p_hi[col])
            b_lo, b_hi = b_lo.T.reshape(k, bins, 3), b_hi.T.reshape(k, bins, 3)
            n_left = np.cumsum(cnt, axis=1)[:, :-1]
            n_right = np.cumsum(cnt[:, ::-1], axis=1)[:, ::-1][:, 1:]
            a_left = box_area(np.minimum.accumulate(b_lo, axis=1), np.maximum.accumulate(b_hi, axis=1))[:, :-1]
            a_right = box_area(np.minimum.accumulate(b_lo[:, ::-1], axis=1)[:, ::-1],
                               np.maximum.accumulate(b_hi[:, ::-1], axis=1)[:, ::-1])[:, 1:]
            cost = np.where((n_left > 0) & (n_right > 0), n_left * a_left + n_right * a_right, np.inf)
            j = cost.argmin(axis=1)
            c_best = cost[np.arange(k), j]
            better = c_best < best_cost
            best_cost = np.where(better, c_best, best_cost)
            best_axis = np.where(better, axis, best_axis)
            best_bin = np.where(better, j, best_bin)
        size = e - s
        local = pos - s[node]
        median = ~np.isfinite(best_cost)          # all centres coincide: halve the range
        left = np.where(median[node], local < size[node] // 2,
                        b[np.arange(len(prim)), best_axis[node]] <= best_bin[node])
        # stable partition of each node's range: its left primitives first
        rank = np.cumsum(left) - left
        rank_left = rank - rank[offsets[:-1]][node]
        n_left = np.add.reduceat(left.astype(np.int64), offsets[:-1])
        rank_right = local - rank_left
        order[np.where(left, s[node] + rank_left, s[node] + n_left[node] + rank_right)] = prim
        return s + n_left

    return split


# ------------------------------------------------------------------------------ the build
def build_bvh(lo, hi, *, leaf_size: int = 4, method: str = "lbvh", bins: int = 16, compiled: bool = False) -> BVH:
    """A :class:`BVH` over the boxes (``lo``, ``hi``) ((n, 3) each, float64, lo <= hi;
    primitive i is box i). A node with at most ``leaf_size`` primitives is a leaf; larger
    ones split (``method``: "lbvh" Morton order or "sah" binned surface-area heuristic with
    ``bins`` bins an axis; module docstring). Zero-size and coincident boxes are fine.
    ``compiled``: the nodes laid out by the compiled build
    (:mod:`plantgen.geometry.rays.native_build`: the same tree and boxes, without numpy's
    per-level overhead, which dominates small trees, and the SAH's per-node work); the
    caller checks that the compiled code runs (:func:`plantgen.geometry.rays.native_trace.available`)."""
    lo, hi = _check_boxes(lo, hi)
    if method not in BVH_METHODS:
        raise BVHError(f"BVH method must be one of {', '.join(BVH_METHODS)}, got {method!r}")
    if int(leaf_size) != leaf_size or leaf_size < 1:
        raise BVHError(f"BVH leaf_size must be a whole number >= 1, got {leaf_size!r}")
    if int(bins) != bins or bins < 2:
        raise BVHError(f"BVH bins must be a whole number >= 2, got {bins!r}")
    leaf_size, n = int(leaf_size), len(lo)
    if n == 0:
        return BVH(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int32), np.zeros(0, np.int32),
                   np.zeros(0, np.int32))
    if compiled:
        from .native_build import centre_codes, lbvh_arrays, sah_arrays

        if method == "lbvh":
            codes = centre_codes(lo, hi)
            order = np.argsort(codes, kind="stable")
            node_lo, node_hi, first, count, levels = lbvh_arrays(lo, hi, codes, order, leaf_size)
        else:
            node_lo, node_hi, first, count, order, levels = sah_arrays(lo, hi, leaf_size, int(bins))
        tree = BVH(node_lo, node_hi, first.astype(np.int32), count.astype(np.int32), order.astype(np.int32))
        tree.__dict__["known_depth"] = int(levels)        # the build counted the levels: depth() need not walk
        return tree
    if method == "lbvh":
        codes = morton_codes(0.5 * (lo + hi))
        order = np.argsort(codes, kind="stable")
        split = _lbvh_splits(codes[order])
    else:
        order = np.arange(n, dtype=np.int64)
        split = _sah_splits(lo, hi, int(bins))
    first, count, levels = _topology(n, leaf_size, order, split)
    node_lo, node_hi = _node_boxes(np.take(lo, order, axis=0), np.take(hi, order, axis=0), first, count, levels)
    return BVH(node_lo, node_hi, first.astype(np.int32), count.astype(np.int32), order.astype(np.int32))


def _topology(n: int, leaf_size: int, order: np.ndarray, split):
    """Top-down, level by level: ``first``, ``count`` (leaves: offset and size in
    ``order``) and the node id ranges of the levels."""
    cap = 2 * n - 1
    first = np.zeros(cap, np.int64)
    count = np.zeros(cap, np.int64)
    ids, s, e = np.array([0]), np.array([0]), np.array([n])
    nodes, levels = 1, []
    while ids.size:
        levels.append((int(ids[0]), int(ids[-1]) + 1))
        size = e - s
        leaf = size <= leaf_size
        first[ids[leaf]], count[ids[leaf]] = s[leaf], size[leaf]
        inner = ~leaf
        if not inner.any():
            break
        s, e, ids = s[inner], e[inner], ids[inner]
        mid = split(order, s, e)
        k = len(ids)
        children = nodes + 2 * np.arange(k)
        first[ids] = children
        nodes += 2 * k
        ids = np.stack([children, children + 1], axis=1).reshape(-1)
        s, e = np.stack([s, mid], axis=1).reshape(-1), np.stack([mid, e], axis=1).reshape(-1)
    return first[:nodes], count[:nodes], levels


def _node_boxes(lo_sorted, hi_sorted, first, count, levels):
    """Boxes of every node: leaves over their primitives, then level by level upwards."""
    nodes = len(first)
    node_lo, node_hi = np.empty((nodes, 3)), np.empty((nodes, 3))
    leaves = np.flatnonzero(count > 0)
    leaves = leaves[np.argsort(first[leaves], kind="stable")]
    starts = first[leaves]
    node_lo[leaves] = np.minimum.reduceat(lo_sorted, starts, axis=0)
    node_hi[leaves] = np.maximum.reduceat(hi_sorted, starts, axis=0)
    for a, b in reversed(levels):
        ids = np.arange(a, b)
        ids = ids[count[ids] == 0]
        left = first[ids]
        node_lo[ids] = np.minimum(node_lo[left], node_lo[left + 1])
        node_hi[ids] = np.maximum(node_hi[left], node_hi[left + 1])
    return node_lo, node_hi


def float32_boxes(bvh: BVH, origin=None) -> tuple[np.ndarray, np.ndarray]:
    """The node boxes as the GPU holds them: float32, relative to ``origin`` (float64,
    default 0), rounded outward so that a float32 box holds its float64 box."""
    o = np.zeros(3) if origin is None else np.asarray(origin, dtype=np.float64)
    lo, hi = bvh.lo - o, bvh.hi - o
    lo32, hi32 = lo.astype(np.float32), hi.astype(np.float32)
    lo32 = np.where(lo32.astype(np.float64) > lo, np.nextafter(lo32, np.float32(-np.inf)), lo32)
    hi32 = np.where(hi32.astype(np.float64) < hi, np.nextafter(hi32, np.float32(np.inf)), hi32)
    return lo32, hi32


# ============================================================================ float64 traversal
# The numpy traversal: the oracle of plantgen.geometry.rays.native_trace (the compiled
# walk every CPU ray takes where numba runs) and its fallback where numba does not.
# A batch of rays walks the tree breadth first, one level of (ray, node) pairs at a
# time (a slab test per pair, inner nodes replaced by their two children). Closest
# hit: the leaves a ray meets are then tested nearest first, by their
# boxes' entry distance, in rounds of 1, 2, 4, ... leaves a ray; after each round a ray
# drops the leaves that its closest hit so far lies before. The result is the stack
# traversal's: the smallest t in (t_min, t_max), ties to the smaller primitive id. Any
# hit (shadow rays): each level's leaves are tested as the walk reaches them, and a ray
# that has hit leaves the walk, no deeper than the level where it first hit (hit or
# not, the answer is the closest hit's; which hit, not). On the
# self-organizing tree's light after 33 steps (144,403 rays, 212,475 primitives) it
# tests 31 M boxes where the rounds tested 39 M, and sorts no leaf pairs; a depth-first
# walk (each ray its own stack, the nearer child first) tests 18 M but costs more in
# numpy, one round per node a ray visits, than it saves.

#: Rays traversed together (the breadth-first frontier grows with them).
TRACE_BATCH = 1 << 13
#: (ray, node) pairs a frontier may hold before its batch is halved.
MAX_FRONTIER = 1 << 22


def slab(lo, hi, origins, inv_dirs) -> tuple[np.ndarray, np.ndarray]:
    """Entry and exit t (k,) of rays (``origins``, 1 / direction) through boxes (k, 3)
    (empty where entry > exit). A ray in a box's face plane, parallel to it, is inside."""
    with np.errstate(invalid="ignore"):
        t1 = (lo - origins) * inv_dirs
        t2 = (hi - origins) * inv_dirs
    near = np.fmin(t1, t2)
    far = np.fmax(t1, t2)
    near = np.where(np.isnan(near), -np.inf, near).max(axis=1)
    far = np.where(np.isnan(far), np.inf, far).min(axis=1)
    return near, far


def _inverse(dirs):
    with np.errstate(divide="ignore"):
        return 1.0 / dirs


def _slab_columns(box, ray):
    """Entry and exit t (k,) from boxes (6, k) and rays (6, k) (origin, 1 / direction) by
    coordinate rows: :func:`slab` without reductions over the short axis."""
    with np.errstate(invalid="ignore"):
        t1 = (box[:3] - ray[:3]) * ray[3:]
        t2 = (box[3:] - ray[:3]) * ray[3:]
    near = np.fmin(t1, t2)
    far = np.fmax(t1, t2)
    # fmax / fmin skip a NaN (a ray in a face plane, parallel to it: inside along that axis)
    return np.fmax(np.fmax(near[0], near[1]), near[2]), np.fmin(np.fmin(far[0], far[1]), far[2])


def _slab_taken(boxes, index, rays, ray):
    """:func:`_slab_columns` of boxes ``index`` (k,) of ``boxes`` (6, n) and rays ``ray``
    (k,) of ``rays`` (6, m): the same numbers, its arithmetic done in place in the gathered
    arrays (a wide frontier's temporaries cost more than their arithmetic)."""
    b = np.take(boxes, index, axis=1)
    r = np.take(rays, ray, axis=1)
    o, inv = r[:3], r[3:]
    with np.errstate(invalid="ignore"):
        for half in (b[:3], b[3:]):
            np.subtract(half, o, out=half)
            np.multiply(half, inv, out=half)
    near = np.fmin(b[:3], b[3:], out=o)
    far = np.fmax(b[:3], b[3:], out=b[:3])
    # fmax / fmin skip a NaN (a ray in a face plane, parallel to it: inside along that axis)
    np.fmax(near[0], near[1], out=near[0])
    np.fmin(far[0], far[1], out=far[0])
    return np.fmax(near[0], near[2], out=near[0]), np.fmin(far[0], far[2], out=far[0])


def _meets(boxes, node, rays, ray, t_min: float, t_hi):
    """Entry t (k,) of rays ``ray`` into boxes ``node`` (as :func:`_slab_taken` takes them)
    and whether each ray's segment (t_min, t_hi) meets its box (``t_hi``: (m,), or None
    where every ray is unbounded)."""
    near, far = _slab_taken(boxes, node, rays, ray)
    np.maximum(near, t_min, out=near)
    ok = near <= far
    ok &= far > t_min
    ok &= near < (np.inf if t_hi is None else t_hi[ray])
    return near, ok


def _bound(t_hi: np.ndarray):
    """``t_hi``, or None where every ray is unbounded (no per-pair gather of infinities)."""
    return None if np.isposinf(t_hi).all() else t_hi


#: Rays of one packet at most (:func:`trace_bvh`'s ``packets``).
PACKET_RAYS = 64


def _packets(O, D, size: int):
    """Runs of at most ``size`` consecutive rays with one origin: (first ray (p,), rays
    (p,), origin (p, 3), unit axis (p, 3), half-angle (p,)) of the cone around each
    run's directions."""
    m = len(O)
    new = np.ones(m, bool)
    new[1:] = (O[1:] != O[:-1]).any(axis=1)
    run = np.cumsum(new) - 1
    start = np.flatnonzero(new)
    new |= ((np.arange(m) - start[run]) % size) == 0              # long runs cut into packets
    first = np.flatnonzero(new)
    count = np.diff(np.r_[first, m])
    unit = D / np.sqrt((D * D).sum(axis=1))[:, None]
    axis = np.add.reduceat(unit, first, axis=0)
    axis /= np.maximum(np.sqrt((axis * axis).sum(axis=1)), 1e-300)[:, None]
    packet = np.repeat(np.arange(len(first)), count)
    cos = np.clip((unit * axis[packet]).sum(axis=1), -1.0, 1.0)
    half = np.maximum.reduceat(np.arccos(cos), first) * (1 + 1e-9) + 1e-12
    return first, count, O[first], axis, half


def _packet_frontier(bvh: BVH, O, D, size: int):
    """(ray, node) pairs to start the per-ray walk from: packets of rays with one origin
    walk the tree together while a node looks larger from the origin than the packet's
    cone is wide (a node none of the cone meets is dropped for all of them)."""
    first, count, origin, axis, half = _packets(O, D, size)
    centre = 0.5 * (bvh.lo + bvh.hi)
    radius = 0.5 * np.sqrt(((bvh.hi - bvh.lo) ** 2).sum(axis=1)) * (1 + 1e-9) + 1e-300
    packet = np.arange(len(first))
    node = np.zeros(len(first), np.int64)
    done_p, done_n = [], []
    while packet.size:
        v = centre[node] - origin[packet]
        dist = np.sqrt((v * v).sum(axis=1))
        inside = dist <= radius[node]
        with np.errstate(invalid="ignore", divide="ignore"):
            seen = np.arcsin(np.minimum(radius[node] / dist, 1.0))
            angle = np.arccos(np.clip((v * axis[packet]).sum(axis=1) / dist, -1.0, 1.0))
        hit = inside | (angle <= half[packet] + seen)
        packet, node, seen, inside = packet[hit], node[hit], seen[hit], inside[hit]
        stop = (bvh.count[node] > 0) | (~inside & (seen < half[packet]))        # small: ray by ray
        done_p.append(packet[stop])
        done_n.append(node[stop])
        go = ~stop
        packet = np.repeat(packet[go], 2)
        node = np.repeat(bvh.first[node[go]].astype(np.int64), 2)
        node[1::2] += 1
    packet, node = np.concatenate(done_p), np.concatenate(done_n)
    k = count[packet]
    ray = np.repeat(first[packet] - np.cumsum(k) + k, k) + np.arange(k.sum())
    return ray, np.repeat(node, k)


def _leaf_pairs(bvh: BVH, O, inv, t_min: float, t_hi: np.ndarray, start=None):
    """(ray, leaf, entry t) of every leaf each ray's segment (t_min, t_hi) meets, or None
    where the frontier outgrows :data:`MAX_FRONTIER`; from the (ray, node) pairs
    ``start`` (default: every ray at the root)."""
    rays = np.ascontiguousarray(np.concatenate([O, inv], axis=1).T)
    boxes, hi = bvh.columns, _bound(t_hi)
    ray, node = start if start is not None else (np.arange(len(O)), np.zeros(len(O), np.int64))
    out = []
    while ray.size:
        if ray.size > MAX_FRONTIER and len(O) > 1:
            return None
        near, ok = _meets(boxes, node, rays, ray, t_min, hi)
        ray, node, near = ray[ok], node[ok], near[ok]
        count = bvh.count[node]
        leaf = count > 0
        out.append((ray[leaf], node[leaf], near[leaf]))
        inner = ~leaf
        ray = np.repeat(ray[inner], 2)
        node = np.repeat(bvh.first[node[inner]].astype(np.int64), 2)
        node[1::2] += 1
    if not out:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    return tuple(np.concatenate(a) for a in zip(*out, strict=True))


def _group_rank(key: np.ndarray) -> np.ndarray:
    """Rank of each element among the equal keys before it (``key`` sorted)."""
    if not key.size:
        return key.copy()
    start = np.r_[True, key[1:] != key[:-1]]
    idx = np.arange(key.size)
    return idx - np.maximum.accumulate(np.where(start, idx, 0))


def reduce_closest(key, t, *values, best_t, best_values, strict_ties=True):
    """Fold candidate hits (key (k,) the ray, t (k,), ``values`` tie-breaking ids) into
    ``best_t`` (m,) and ``best_values`` (arrays (m,)) in place: per ray the smallest t, ties
    to the smallest ids (in ``values`` order)."""
    fin = np.isfinite(t)
    if not fin.any():
        return
    key, t, values = key[fin], t[fin], [v[fin] for v in values]
    order = np.lexsort((*reversed(values), t, key))
    k = key[order]
    pick = order[np.r_[True, k[1:] != k[:-1]]]
    r, tt = key[pick], t[pick]
    better = tt < best_t[r]
    tie = tt == best_t[r]
    if tie.any():                                    # equal t: the smaller ids win
        smaller = np.zeros(len(r), bool)
        decided = np.zeros(len(r), bool)
        for v, bv in zip(values, best_values, strict=True):
            a, b = v[pick], bv[r]
            smaller |= ~decided & (a < b)
            decided |= a != b
        better |= tie & smaller
    r = r[better]
    best_t[r] = tt[better]
    for v, bv in zip(values, best_values, strict=True):
        bv[r] = v[pick][better]


def _trace_batch(bvh: BVH, O, D, hits, t_min: float, t_hi: np.ndarray, any_hit: bool, boxes=None,
                 packets: int = 0, roots=None):
    m = len(O)
    best_t = np.full(m, np.inf)
    best_p = np.full(m, -1, np.int64)
    inv = _inverse(D)
    if roots is not None:
        start = (np.arange(m), np.asarray(roots, np.int64))
    else:
        start = _packet_frontier(bvh, O, D, packets) if packets > 1 else None
    rays = np.ascontiguousarray(np.concatenate([O, inv], axis=1).T)
    if any_hit:
        pairs = _any_hit_walk(bvh, O, D, rays, hits, t_min, t_hi, start, boxes, best_t, best_p)
    else:
        pairs = _leaf_pairs(bvh, O, inv, t_min, t_hi, start)
    if pairs is None:                                # too wide a frontier: halve the batch
        h = m // 2
        r = (None, None) if roots is None else (roots[:h], roots[h:])
        a = _trace_batch(bvh, O[:h], D[:h], hits, t_min, t_hi[:h], any_hit, boxes, packets, r[0])
        b = _trace_batch(bvh, O[h:], D[h:], hits, t_min, t_hi[h:], any_hit, boxes, packets, r[1])
        return np.concatenate([a[0], b[0]]), np.concatenate([a[1], b[1]])
    if any_hit:
        return best_t, best_p
    ray, leaf, near = pairs
    order = np.lexsort((near, ray))
    ray, leaf, near = ray[order], leaf[order], near[order]
    per_round = 1
    while ray.size:
        rank = _group_rank(ray)
        now = rank < per_round
        _test_leaves(bvh, ray[now], leaf[now], O, D, rays, hits, t_min, t_hi, boxes, best_t, best_p)
        ray, leaf, near = ray[~now], leaf[~now], near[~now]
        keep = near <= best_t[ray]
        ray, leaf, near = ray[keep], leaf[keep], near[keep]
        per_round *= 2
    return best_t, best_p


def _test_leaves(bvh: BVH, r, lf, O, D, rays, hits, t_min: float, t_hi, boxes, best_t, best_p):
    """Test the primitives of leaves ``lf`` against rays ``r`` ((k,) pairs) and fold their
    hits into ``best_t``, ``best_p`` (the primitive's own box first where ``boxes``)."""
    cnt = bvh.count[lf].astype(np.int64)
    rr = np.repeat(r, cnt)
    slot = np.repeat(bvh.first[lf].astype(np.int64) - np.cumsum(cnt) + cnt, cnt) + np.arange(cnt.sum())
    prim = bvh.prims[slot].astype(np.int64)
    if boxes is not None:                        # the primitive's own box first: a cheap cull
        near_p, far_p = _slab_taken(boxes, prim, rays, rr)
        inside = (np.maximum(near_p, t_min) <= far_p) & (far_p > t_min) \
            & (near_p <= np.minimum(t_hi[rr], best_t[rr]))
        rr, prim = rr[inside], prim[inside]
    t = hits(prim, O[rr], D[rr])
    t = np.where((t > t_min) & (t < t_hi[rr]), t, np.inf)
    reduce_closest(rr, t, prim, best_t=best_t, best_values=[best_p])


def _any_hit_walk(bvh: BVH, O, D, rays, hits, t_min: float, t_hi: np.ndarray, start, boxes, best_t, best_p):
    """Any hit: :func:`_leaf_pairs`'s walk, each level's leaves tested as soon as they are
    reached and a ray that has hit dropped from the walk (a shadow ray in a crown stops at
    its first leaf, however much lies beyond). Fills ``best_t``, ``best_p``; returns None
    where the frontier outgrows :data:`MAX_FRONTIER` (else True)."""
    columns, hi = bvh.columns, _bound(t_hi)
    ray, node = start if start is not None else (np.arange(len(O)), np.zeros(len(O), np.int64))
    while ray.size:
        if ray.size > MAX_FRONTIER and len(O) > 1:
            return None
        _, ok = _meets(columns, node, rays, ray, t_min, hi)
        ray, node = ray[ok], node[ok]
        leaf = bvh.count[node] > 0
        go = ~leaf
        if leaf.any():
            _test_leaves(bvh, ray[leaf], node[leaf], O, D, rays, hits, t_min, t_hi, boxes, best_t, best_p)
            go &= ~np.isfinite(best_t[ray])
        ray = np.repeat(ray[go], 2)
        node = np.repeat(bvh.first[node[go]].astype(np.int64), 2)
        node[1::2] += 1
    return True


def _rays(origins, dirs) -> tuple[np.ndarray, np.ndarray]:
    O = np.ascontiguousarray(origins, dtype=np.float64).reshape(-1, 3)
    D = np.ascontiguousarray(dirs, dtype=np.float64).reshape(-1, 3)
    if O.shape != D.shape:
        raise BVHError(f"rays need as many origins as directions, got {len(O)} and {len(D)}")
    return O, D


def _t_max(t_max, m: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(t_max, dtype=np.float64), (m,))


def trace_bvh(bvh: BVH, origins, dirs, hits, *, any_hit: bool = False, t_min: float = 0.0,
              t_max=np.inf, batch: int = TRACE_BATCH, boxes=None, packets: int = 0,
              roots=None) -> tuple[np.ndarray, np.ndarray]:
    """Float64 closest (or any) hit of rays (``origins``, ``dirs``: (m, 3)) among the
    primitives of ``bvh``: ``hits(prims (k,), origins (k, 3), dirs (k, 3))`` gives the t
    of each (primitive, ray) pair (inf: a miss; hits at t <= ``t_min`` count as misses,
    the caller's test applies it). Returns t (m,) (inf: no hit in (t_min, t_max)) and the
    primitive (m,) (-1). ``t_max``: one number or (m,). ``boxes``: the primitives' boxes
    by coordinate rows ((6, n): lo x, y, z, hi x, y, z; :func:`box_columns`), where the
    caller has them: a ray then tests only the primitives of a leaf whose own box it meets
    (the same hits, fewer exact tests). ``packets``: up to this many consecutive rays with
    one origin (a scanner's neighbouring beams) walk the upper tree together, as one cone
    (the same hits, fewer box tests; 0: ray by ray). ``roots``: (m,) the node each ray
    starts from (default the root; :attr:`SceneBVH.flat` holds several trees)."""
    O, D = _rays(origins, dirs)
    m = len(O)
    hi = _t_max(t_max, m)
    best_t, best_p = np.full(m, np.inf), np.full(m, -1, np.int64)
    if not bvh.nodes:
        return best_t, best_p
    roots = None if roots is None else np.broadcast_to(np.asarray(roots, np.int64), (m,))
    for s in range(0, m, max(1, int(batch))):
        e = min(s + batch, m)
        best_t[s:e], best_p[s:e] = _trace_batch(bvh, O[s:e], D[s:e], hits, float(t_min), hi[s:e], any_hit,
                                                boxes, int(packets), None if roots is None else roots[s:e])
    return best_t, best_p


def box_columns(lo, hi) -> np.ndarray:
    """(6, n) boxes (``lo``, ``hi``: (n, 3)) by coordinate rows, as :func:`trace_bvh` takes them."""
    return np.ascontiguousarray(np.concatenate([np.asarray(lo, np.float64), np.asarray(hi, np.float64)], axis=1).T)


def brute_force(n: int, origins, dirs, hits, *, any_hit: bool = False, t_min: float = 0.0, t_max=np.inf):
    """What :func:`trace_bvh` finds, by testing every ray against every one of ``n``
    primitives (for tests; (m·n) pairs). For ``any_hit`` it gives the closest hit too."""
    O, D = _rays(origins, dirs)
    m = len(O)
    ray = np.repeat(np.arange(m), n)
    prim = np.tile(np.arange(n), m)
    t = hits(prim, O[ray], D[ray]) if len(ray) else np.zeros(0)
    t = np.where((t > t_min) & (t < _t_max(t_max, m)[ray]), t, np.inf)
    best_t, best_p = np.full(m, np.inf), np.full(m, -1, np.int64)
    reduce_closest(ray, t, prim, best_t=best_t, best_values=[best_p])
    return best_t, best_p


# ============================================================================ two levels
@dataclass(frozen=True, eq=False)
class SceneBVH:
    """A two-level BVH of an instanced scene (module docstring): ``blas`` one
    :class:`BVH` per distinct plant over its rows in its own frame; ``tlas`` a :class:`BVH`
    over the copies (primitive c is copy c: the plants' copies in order, plant by plant);
    per copy its ``plant`` ((c,) int32), ``matrix`` and ``inverse`` ((c, 4, 4) float64,
    plant frame to world and back) and world box ``copy_lo``, ``copy_hi`` ((c, 3));
    ``first_copy`` ((plants + 1,)) where each plant's copies start."""

    blas: tuple
    tlas: BVH
    plant: np.ndarray
    matrix: np.ndarray
    inverse: np.ndarray
    copy_lo: np.ndarray
    copy_hi: np.ndarray
    first_copy: np.ndarray

    @property
    def copies(self) -> int:
        return len(self.plant)

    def copy_bytes(self) -> float:
        """CPU bytes a copy costs: its plant index, matrix, inverse, box and its share of the
        top level."""
        if not self.copies:
            return 0.0
        per = self.plant.nbytes + self.matrix.nbytes + self.inverse.nbytes + self.copy_lo.nbytes \
            + self.copy_hi.nbytes + self.tlas.nbytes
        return per / self.copies

    @property
    def nbytes(self) -> int:
        return int(self.copy_bytes() * self.copies) + sum(b.nbytes for b in self.blas)

    @cached_property
    def flat(self) -> tuple[BVH, np.ndarray, np.ndarray]:
        """Every plant's BVH in one node array, as the CPU traversal walks them: that
        :class:`BVH` (plant k's nodes and primitives after those of plants 0..k-1, its
        primitives numbered on from theirs), each plant's root node (plants,) and first
        primitive (plants + 1,)."""
        nodes = np.cumsum([0] + [b.nodes for b in self.blas])
        prims = np.cumsum([0] + [len(b.prims) for b in self.blas])
        cat = lambda name: np.concatenate([getattr(b, name) for b in self.blas]) if self.blas else \
            np.zeros((0, 3) if name in ("lo", "hi") else 0)  # noqa: E731
        first = np.concatenate([np.where(b.count == 0, b.first + nodes[k], b.first + prims[k])
                                for k, b in enumerate(self.blas)]) if self.blas else np.zeros(0)
        prim = np.concatenate([b.prims + prims[k] for k, b in enumerate(self.blas)]) if self.blas else np.zeros(0)
        flat = BVH(cat("lo"), cat("hi"), first.astype(np.int32), cat("count").astype(np.int32), prim.astype(np.int32))
        return flat, nodes[:-1].astype(np.int64), prims.astype(np.int64)

    def rays_to_copies(self, copy, origins, dirs) -> tuple[np.ndarray, np.ndarray]:
        """Rays (k, 3) moved into the frames of copies ``copy`` (k,), in float64 (t is kept:
        a point at t along the world ray is at t along the moved one)."""
        inv = self.inverse[copy]
        o = np.einsum("kij,kj->ki", inv[:, :3, :3], origins) + inv[:, :3, 3]
        d = np.einsum("kij,kj->ki", inv[:, :3, :3], dirs)
        return o, d


def copy_boxes(lo, hi, matrices) -> tuple[np.ndarray, np.ndarray]:
    """World boxes (k, 3) of the box (``lo``, ``hi``) under similarity ``matrices``
    (k, 4, 4): the box around its eight moved corners, padded outward for rounding."""
    corners = np.stack(np.meshgrid(*zip(lo, hi, strict=True), indexing="ij"), axis=-1).reshape(8, 3)
    m = np.asarray(matrices, dtype=np.float64).reshape(-1, 4, 4)
    pts = np.einsum("kij,cj->kci", m[:, :3, :3], corners) + m[:, None, :3, 3]
    c_lo, c_hi = pts.min(axis=1), pts.max(axis=1)
    pad = 1e-12 * np.maximum(np.abs(c_lo), np.abs(c_hi)).max(axis=1, keepdims=True) + 1e-300
    return c_lo - pad, c_hi + pad


def build_scene_bvh(placed, *, leaf_size: int = 4, method: str = "lbvh", bins: int = 16,
                    top_leaf_size: int = TOP_LEAF_SIZE, shell: bool = True) -> SceneBVH:
    """The two-level BVH of ``placed`` (a :class:`~plantgen.geometry.rays.instances.PlacedPlants`):
    a BLAS per distinct plant over its rows' boxes (relief shell included where ``shell``),
    built once whatever its copies; a TLAS over the copies (``top_leaf_size`` copies a
    leaf). A copy whose matrix is not finite or scales by 0 is refused."""
    from .reference import row_boxes

    blas = []
    for p in placed.plants:
        lo, hi = row_boxes(p.frusta, shell=shell) if len(p.frusta) else (np.zeros((0, 3)), np.zeros((0, 3)))
        blas.append(build_bvh(lo, hi, leaf_size=leaf_size, method=method, bins=bins))
    return scene_bvh(blas, [p.matrices for p in placed.plants], top_leaf_size=top_leaf_size, method=method,
                     bins=bins)


def scene_bvh(blas, matrices, *, top_leaf_size: int = TOP_LEAF_SIZE, method: str = "lbvh", bins: int = 16) -> SceneBVH:
    """A :class:`SceneBVH` from a BVH per distinct plant (``blas``) and its copies'
    placements (``matrices[k]``: (c_k, 4, 4) similarity transforms); copies are numbered
    plant by plant. A copy whose matrix is not finite or scales by 0 is refused."""
    plant, mats, los, his = [], [], [], []
    for k, (b, m) in enumerate(zip(blas, matrices, strict=True)):
        m = np.asarray(m, dtype=np.float64).reshape(-1, 4, 4)
        mats.append(m)
        plant.append(np.full(len(m), k, np.int32))
        if len(m) and b.nodes and np.isfinite(m).all():
            c_lo, c_hi = copy_boxes(b.lo[0], b.hi[0], m)
        else:                                           # an empty plant: a point that holds nothing
            c_lo = c_hi = m[:, :3, 3].copy()
        los.append(c_lo)
        his.append(c_hi)
    matrix = np.concatenate(mats) if mats else np.zeros((0, 4, 4))
    det = np.linalg.det(matrix[:, :3, :3]) if len(matrix) else np.zeros(0)
    bad = ~np.isfinite(matrix).all(axis=(1, 2)) | ~(np.abs(det) > 0) | ~np.isfinite(det)
    if bad.any():
        raise BVHError(f"{int(bad.sum())} placed copies have a matrix that is not finite or scales by 0 "
                       f"(the first: copy {int(np.flatnonzero(bad)[0])})")
    copy_lo = np.concatenate(los) if los else np.zeros((0, 3))
    copy_hi = np.concatenate(his) if his else np.zeros((0, 3))
    tlas = build_bvh(copy_lo, copy_hi, leaf_size=top_leaf_size, method=method, bins=bins)
    counts = [len(m) for m in mats]
    return SceneBVH(tuple(blas), tlas, np.concatenate(plant) if plant else np.zeros(0, np.int32), matrix,
                    np.linalg.inv(matrix) if len(matrix) else matrix.copy(), copy_lo, copy_hi,
                    np.concatenate([[0], np.cumsum(counts)]).astype(np.int64))


def trace_scene(scene: SceneBVH, origins, dirs, plant_hits, *, any_hit: bool = False, t_min: float = 0.0,
                t_max=np.inf, batch: int = TRACE_BATCH, plant_boxes=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`trace_bvh` through a :class:`SceneBVH`: ``plant_hits[k]`` is plant k's
    primitive test in its own frame. The copies a ray's segment meets are visited nearest
    first (rounds of 1, 2, 4, ... copies a ray), the ray moved into each one's frame in
    float64 and traced through its plant's BVH up to the closest hit so far. Returns t
    (m,), the copy (m,) and the primitive of its plant (m,) (-1 for a miss); ties go to
    the smaller copy, then primitive. ``plant_boxes[k]``: plant k's primitive boxes as
    :func:`trace_bvh` takes them (or None)."""
    O, D = _rays(origins, dirs)
    m = len(O)
    hi = _t_max(t_max, m)
    best_t, best_c, best_p = np.full(m, np.inf), np.full(m, -1, np.int64), np.full(m, -1, np.int64)
    if not scene.tlas.nodes:
        return best_t, best_c, best_p
    step = max(1, int(batch))
    for s in range(0, m, step):
        e = min(s + step, m)
        out = _trace_scene_batch(scene, O[s:e], D[s:e], plant_hits, float(t_min), hi[s:e], any_hit, step,
                                 plant_boxes)
        best_t[s:e], best_c[s:e], best_p[s:e] = out
    return best_t, best_c, best_p


def _trace_scene_batch(scene: SceneBVH, O, D, plant_hits, t_min, t_hi, any_hit, batch, plant_boxes=None):
    m = len(O)
    best_t, best_c, best_p = np.full(m, np.inf), np.full(m, -1, np.int64), np.full(m, -1, np.int64)
    inv = _inverse(D)
    pairs = _leaf_pairs(scene.tlas, O, inv, t_min, t_hi)
    if pairs is None:
        h = m // 2
        a = _trace_scene_batch(scene, O[:h], D[:h], plant_hits, t_min, t_hi[:h], any_hit, batch, plant_boxes)
        b = _trace_scene_batch(scene, O[h:], D[h:], plant_hits, t_min, t_hi[h:], any_hit, batch, plant_boxes)
        return tuple(np.concatenate([x, y]) for x, y in zip(a, b, strict=True))
    ray, leaf, _ = pairs
    cnt = scene.tlas.count[leaf].astype(np.int64)
    ray = np.repeat(ray, cnt)
    slot = np.repeat(scene.tlas.first[leaf].astype(np.int64) - np.cumsum(cnt) + cnt, cnt) + np.arange(cnt.sum())
    copy = scene.tlas.prims[slot].astype(np.int64)
    near, far = slab(scene.copy_lo[copy], scene.copy_hi[copy], O[ray], inv[ray])
    near = np.maximum(near, t_min)
    filled = np.array([b.nodes > 0 for b in scene.blas], bool)
    ok = (near <= far) & (far > t_min) & (near < t_hi[ray]) & filled[scene.plant[copy]]
    ray, copy, near = ray[ok], copy[ok], near[ok]
    order = np.lexsort((copy, near, ray))
    ray, copy, near = ray[order], copy[order], near[order]
    flat, roots, prim_first = scene.flat
    hits = _flat_hits(plant_hits, prim_first)
    boxes = None if plant_boxes is None else np.concatenate(plant_boxes, axis=1)
    per_round = 1
    while ray.size:
        now = _group_rank(ray) < per_round
        r, c = ray[now], copy[now]
        o, d = scene.rays_to_copies(c, O[r], D[r])
        limit = np.minimum(t_hi[r], best_t[r])
        if not any_hit:
            limit = np.nextafter(limit, np.inf)        # a tie at the best t may still win on ids
        plant = scene.plant[c]
        t, prim = trace_bvh(flat, o, d, hits, any_hit=any_hit, t_min=t_min, t_max=limit, batch=batch,
                            boxes=boxes, roots=roots[plant])
        prim = np.where(prim >= 0, prim - prim_first[plant], -1)         # the plant's own numbering
        t = np.where(t < t_hi[r], t, np.inf)
        reduce_closest(r, t, c, prim, best_t=best_t, best_values=[best_c, best_p])
        ray, copy, near = ray[~now], copy[~now], near[~now]
        keep = ~np.isfinite(best_t[ray]) if any_hit else near <= best_t[ray]
        ray, copy, near = ray[keep], copy[keep], near[keep]
        per_round *= 2
    return best_t, best_c, best_p


def _flat_hits(plant_hits, prim_first):
    """The primitive test over :attr:`SceneBVH.flat`'s numbering from each plant's own."""
    def hits(prim, origins, dirs):
        plant = np.searchsorted(prim_first, prim, side="right") - 1
        t = np.full(len(prim), np.inf)
        for k in np.unique(plant):
            sel = np.flatnonzero(plant == k)
            t[sel] = plant_hits[k](prim[sel] - prim_first[k], origins[sel], dirs[sel])
        return t
    return hits
