"""The compiled cull of a stand's leaves (:mod:`plantgen.environment.together`): which of
many boxes (clusters of leaf triangles) any of a batch of rays may meet, by a slab test
no tighter than the compiled walk's (:mod:`plantgen.geometry.rays.native_trace`), so that
a triangle inside a box no ray meets is one no ray's box test reaches, and leaving it out
of a target changes no ray's any hit. Compiled and cached as the walk is; where the walk
does not run, every box is met."""

from __future__ import annotations

import numpy as np

from ..compiled import njit, prange
from .native_trace import KERNEL_LOCK, available

__all__ = ["GROW", "boxes_met"]

#: How much a moved box grows, a fraction of its largest coordinate (plus as much).
GROW = 1e-7


@njit(cache=True, inline="always")
def _inv(d):
    return 1.0 / d if d != 0 else (np.inf if not np.signbit(d) else -np.inf)


@njit(cache=True, inline="always")
def _cull_axis(lo, hi, o, i, near, far):
    """(near, far) narrowed by one axis of a box; an axis whose product is NaN (a ray in
    a face plane, parallel to it) narrows nothing (looser than the walk's slab, never
    tighter)."""
    a, b = (lo - o) * i, (hi - o) * i
    if a != a or b != b:
        return near, far
    return max(near, min(a, b)), min(far, max(a, b))


@njit(cache=True, inline="always")
def _cull_meets(box, n, ox, oy, oz, ix, iy, iz, t_min):
    """Whether the ray may meet box ``n`` of ``box`` (k, 6) beyond ``t_min``: true
    wherever the walk's slab test of any box inside it passes."""
    near, far = _cull_axis(box[n, 0], box[n, 3], ox, ix, -np.inf, np.inf)
    near, far = _cull_axis(box[n, 1], box[n, 4], oy, iy, near, far)
    near, far = _cull_axis(box[n, 2], box[n, 5], oz, iz, near, far)
    return max(near, t_min) <= far and far > t_min


@njit(cache=True)
def _unions(box, first):
    """(k, 6) the box around each run ``box[first[j]:first[j + 1]]`` (k + 1 offsets)."""
    out = np.empty((len(first) - 1, 6))
    for j in range(len(first) - 1):
        for a in range(3):
            lo, hi = np.inf, -np.inf
            for n in range(first[j], first[j + 1]):
                lo, hi = min(lo, box[n, a]), max(hi, box[n, 3 + a])
            out[j, a], out[j, 3 + a] = lo, hi
    return out


@njit(cache=True)
def _move(box, n, M, out, k):
    """``out[k]``: box ``n`` of ``box`` moved by the 4 x 4 ``M`` and grown (:func:`boxes_met`)."""
    big = 0.0
    for a in range(3):
        c, h = M[a, 3], 0.0
        for b in range(3):
            centre = 0.5 * (box[n, b] + box[n, 3 + b])
            c += M[a, b] * centre
            h += abs(M[a, b]) * max(box[n, 3 + b] - centre, centre - box[n, b])
        out[k, a], out[k, 3 + a] = c, h
        big = max(big, abs(c) + h)
    grow = GROW * (big + 1.0)
    for a in range(3):
        c, h = out[k, a], out[k, 3 + a] + grow
        out[k, a], out[k, 3 + a] = c - h, c + h


@njit(cache=True)
def _moved(box, M):
    out = np.empty_like(box)
    for n in range(len(box)):
        _move(box, n, M, out, n)
    return out


@njit(cache=True, parallel=True)
def _boxes_met(box, block, group, skip, M, move, O, D, t_min, met):
    """``met`` (c,): whether any ray may meet each box; the boxes taken group by group (a
    plant's leaves: ``group`` offsets into the blocks), a group's box first, then block
    by block (``block`` offsets into the boxes), a block's box first; group ``skip`` is
    left out. With ``move`` every box is moved by ``M`` first (a box the first time a
    ray reaches its block). A block or group all met is not tested again."""
    bbox = _unions(box, block)
    if move:
        bbox = _moved(bbox, M)
    gbox = _unions(bbox, group)
    moved = np.empty_like(box) if move else box
    ready = np.zeros(len(block) - 1, np.bool_)
    block_left = block[1:] - block[:-1]
    for g in prange(len(group) - 1):
        left = 0 if g == skip else block[group[g + 1]] - block[group[g]]
        for r in range(len(O)):
            if left == 0:
                break
            ox, oy, oz = O[r, 0], O[r, 1], O[r, 2]
            ix, iy, iz = _inv(D[r, 0]), _inv(D[r, 1]), _inv(D[r, 2])
            if not _cull_meets(gbox, g, ox, oy, oz, ix, iy, iz, t_min):
                continue
            for b in range(group[g], group[g + 1]):
                if block_left[b] == 0 or not _cull_meets(bbox, b, ox, oy, oz, ix, iy, iz, t_min):
                    continue
                if move and not ready[b]:
                    for k in range(block[b], block[b + 1]):
                        _move(box, k, M, moved, k)
                    ready[b] = True
                for k in range(block[b], block[b + 1]):
                    if not met[k] and _cull_meets(moved, k, ox, oy, oz, ix, iy, iz, t_min):
                        met[k] = True
                        left -= 1
                        block_left[b] -= 1


def _rows3(a) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=np.float64).reshape(-1, 3)
    return a if a.flags.writeable else a.copy()


def boxes_met(lo, hi, block, group, origins, dirs, *, matrix=None, skip: int = -1, t_min: float = 0.0,
              box=None) -> np.ndarray:
    """(c,) bool: the boxes (``lo``, ``hi``: (c, 3) each) that a ray (``origins``, ``dirs``
    (m, 3)) may meet beyond ``t_min``, by a slab test no tighter than the compiled walk's:
    wherever a ray passes the walk's test of a box inside one, it meets that one.
    ``block`` ((b + 1,) offsets) gathers the boxes into blocks and ``group`` ((g + 1,)
    offsets) the blocks into groups (a plant's leaves), each tested by its box before
    what it holds; group ``skip`` is left out (all False). With ``matrix`` (4 x 4) the
    boxes are first moved by it and grown, each then holding the moved box and a leaf
    triangle's padded box (:func:`~plantgen.geometry.rays.scan_targets.scan_target`'s)
    around any triangle inside it however its vertices round on the way: a centre and a
    half size through the matrix and its absolute value, widened by :data:`GROW` of the
    largest coordinate plus :data:`GROW` (the rounding and the pad are below 1e-9 of
    it). A box is moved only once a ray reaches its block. True for all the others where
    the compiled walk does not run. ``box``: (c, 6) float64, C-contiguous, ``lo`` and
    ``hi`` side by side, where the caller keeps them so for many calls."""
    block = np.ascontiguousarray(block, np.int64)
    group = np.ascontiguousarray(group, np.int64)
    met = np.zeros(len(lo), np.bool_)
    O, D = _rows3(origins), _rows3(dirs)
    if not len(O):
        return met
    if not available():
        met[:] = True
        if 0 <= skip < len(group) - 1:
            met[block[group[skip]]:block[group[skip + 1]]] = False
        return met
    if box is None:
        box = np.ascontiguousarray(np.concatenate([np.reshape(lo, (-1, 3)), np.reshape(hi, (-1, 3))], axis=1),
                                   np.float64)
    M = np.ascontiguousarray(np.eye(4) if matrix is None else matrix, np.float64)
    with KERNEL_LOCK:
        _boxes_met(box, block, group, int(skip), M, matrix is not None, O, D, float(t_min), met)
    return met
