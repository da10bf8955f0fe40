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

Measured (``python -m plantgen.benchmarks.bvh``; the table under ``gallery/bench/``):
LBVH builds several times faster than binned SAH and the trees trace at a similar rate on
plant rows (long thin boxes along branches, spread evenly), so LBVH is the default and
SAH stays a knob for the scenes where its tighter upper levels pay.

A node box is the union of its primitives' boxes, in float64, exactly (no rounding
padding: the primitive boxes carry their own). For the GPU, boxes go to float32
relative to a float64 frame origin rounded outward (:func:`float32_boxes`).

**Two levels** (:func:`build_scene_bvh`): one BVH per distinct plant in its own frame (a
BLAS), and a top-level BVH (TLAS) over the placed copies: a copy's box is the world box
of its plant's root box under the copy's similarity matrix. Per copy: the plant index,
the matrix and its inverse (float64).

Pure numpy, no GL.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import PlantgenError

__all__ = ["BVH", "BVH_METHODS", "BVHError", "build_bvh", "float32_boxes", "morton_codes"]

#: How :func:`build_bvh` may split nodes.
BVH_METHODS = ("lbvh", "sah")


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

    @property
    def leaves(self) -> int:
        return int((self.count > 0).sum())

    @property
    def nbytes(self) -> int:
        """Bytes of the arrays on the CPU."""
        return sum(a.nbytes for a in (self.lo, self.hi, self.first, self.count, self.prims))

    def depth(self) -> int:
        """The levels of the tree (0: empty, 1: a single leaf)."""
        if not self.nodes:
            return 0
        level, depth = np.array([0]), 0
        while level.size:
            depth += 1
            inner = level[self.count[level] == 0]
            level = np.concatenate([self.first[inner], self.first[inner] + 1])
        return depth

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


# ------------------------------------------------------------------------------ Morton codes
def _spread21(x: np.ndarray) -> np.ndarray:
    """uint64 values of 21 bits spread out to every third bit."""
    x = x & np.uint64(0x1FFFFF)
    x = (x | (x << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
    x = (x | (x << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
    x = (x | (x << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
    x = (x | (x << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
    x = (x | (x << np.uint64(2))) & np.uint64(0x1249249249249249)
    return x


def morton_codes(points: np.ndarray) -> np.ndarray:
    """(n,) uint64 63-bit Morton codes of points (n, 3): 21 bits an axis over the points'
    bounding cube (x in the highest of each three bits)."""
    points = np.asarray(points, dtype=np.float64)
    if not len(points):
        return np.zeros(0, np.uint64)
    lo = points.min(axis=0)
    extent = float((points.max(axis=0) - lo).max())
    q = np.clip((points - lo) / (extent if extent > 0 else np.inf) * (2 ** 21 - 1), 0, 2 ** 21 - 1)
    q = q.astype(np.uint64)
    return (_spread21(q[:, 0]) << np.uint64(2)) | (_spread21(q[:, 1]) << np.uint64(1)) | _spread21(q[:, 2])


def _highest_bit(x: np.ndarray) -> np.ndarray:
    """The highest set bit of each uint64 (0 for 0), exactly."""
    for s in (1, 2, 4, 8, 16, 32):
        x = x | (x >> np.uint64(s))
    return x ^ (x >> np.uint64(1))


# ------------------------------------------------------------------------------ the splits
def _lbvh_splits(codes: np.ndarray):
    """A split function over primitives already sorted by ``codes``."""

    def split(order, s, e):
        c0, c1 = codes[s], codes[e - 1]
        top = _highest_bit(c0 ^ c1)
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
def build_bvh(lo, hi, *, leaf_size: int = 4, method: str = "lbvh", bins: int = 16) -> BVH:
    """A :class:`BVH` over the boxes (``lo``, ``hi``) ((n, 3) each, float64, lo <= hi;
    primitive i is box i). A node with at most ``leaf_size`` primitives is a leaf; larger
    ones split (``method``: "lbvh" Morton order or "sah" binned surface-area heuristic with
    ``bins`` bins an axis; module docstring). Zero-size and coincident boxes are fine."""
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
