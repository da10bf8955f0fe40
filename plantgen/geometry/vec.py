"""Row-wise vector helpers and tree walks on numpy arrays, shared by every geometry stage.

Vectors are the last axis of ``(..., 3)`` float64 arrays; each helper works on every row
at once. The arithmetic order is part of the contract (outputs are compared bit for
bit): :func:`dot` sums ``a0·b0 + a1·b1 + a2·b2`` left to right, which ``np.einsum`` does
not promise.

Trees are parent arrays: ``parent[i]`` is the parent of node ``i``, -1 for a root. The
walks use pointer jumping: each round combines a node's value with its current jump
target's and doubles the jump, so ``log2(depth)`` vectorised rounds replace a walk along
every path.
"""

from __future__ import annotations

import contextvars
import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..tolerances import tol

__all__ = ["dot", "norm", "cross", "unit", "any_perpendicular", "rotate", "plane_through",
           "by_rows", "ROW_BLOCK", "MAX_ROW_WORKERS", "row_workers", "in_threads", "reduce_to_root",
           "ancestor_count", "tree_roots"]

#: Rows a block of :func:`by_rows` (the temporaries of a few dozen (rows, 3) float64
#: operations stay in the cache and are reused, not faulted in afresh per operation).
ROW_BLOCK = 1 << 14

#: Most threads :func:`by_rows` runs blocks on (beyond a few, the interpreter's share of
#: each block's work leaves the extra threads waiting).
MAX_ROW_WORKERS = 4


# ============================================================================ vectors
def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(...) row-wise dot products of (..., 3) arrays (broadcast), summed left to right."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


#: Below this length a row's squared components are subnormal (under 2.2e-308) and its
#: norm loses digits: :func:`unit` rescales such rows first.
SQUARE_SAFE = 1e-150


def norm(a: np.ndarray) -> np.ndarray:
    """(...) row-wise lengths of (..., 3) arrays."""
    return np.sqrt(dot(a, a))


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., 3) row-wise cross products of (..., 3) arrays (broadcast); ``np.cross``'s
    arithmetic without its axis juggling (about 5x faster)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def unit(v: np.ndarray, fallback: np.ndarray | None = None) -> np.ndarray:
    """(..., 3) the rows of ``v`` (..., 3) scaled to unit length.

    Rows of length 0 stay 0; with ``fallback`` (broadcast against ``v``), rows shorter than
    ``tol.tiny`` (no direction) take the fallback's row instead. A row whose components
    are all under :data:`SQUARE_SAFE` (its squares fall among the subnormals, or to 0, and
    its norm loses its digits) is scaled by its largest component first, so its unit row
    has unit length too; every other row is divided by its norm as it is.
    """
    n = norm(v)[..., None]
    length = n
    if np.any(n < SQUARE_SAFE):                        # short rows, or rows of zero
        big = np.max(np.abs(v), axis=-1, keepdims=True)
        short = (big > 0) & (big < SQUARE_SAFE)
        if np.any(short):
            v = np.where(short, v / np.where(short, big, 1.0), v)
            n = np.where(short, norm(v)[..., None], n)
            length = np.where(short, big * n, n)
    if fallback is None:
        return v / np.where(n > 0, n, 1.0)
    return np.where(length > tol.tiny, v / np.where(n > 0, n, 1.0), fallback)


def any_perpendicular(a: np.ndarray) -> np.ndarray:
    """(m, 3) unit vectors ⟂ the unit rows of ``a`` (m, 3): x (or z where ``a`` is near x)
    with its ``a`` part removed, a smooth choice within each of the two half-spaces."""
    helper = np.where(np.abs(a[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0.0, 0, 1]]))
    return unit(helper - a * dot(helper, a)[:, None])


def rotate(v: np.ndarray, axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(m, 3) Rodrigues rotation of the rows of ``v`` (m, 3) about the unit rows of ``axis``
    (m, 3) by ``angle`` (m,) radians (right-handed)::

        v·cos θ + (axis × v)·sin θ + axis·((axis·v)·(1 - cos θ))

    (the order of plantgen.lsystem.turtle's scalar rotation).
    """
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return v * c + cross(axis, v) * s + axis * (dot(axis, v)[:, None] * (1 - c))


def plane_through(normal: np.ndarray, point: np.ndarray) -> np.ndarray:
    """(m, 4) planes ``(nx, ny, nz, d)`` with unit normals ``normal`` (m, 3) through the
    points ``point`` (m, 3): ``d = n·point``. Written into one array (a concatenate of an
    (m, 3) and an (m, 1) array copies a row at a time)."""
    d = dot(normal, point)
    out = np.empty((len(normal), 4), dtype=np.result_type(normal, d))
    out[:, :3] = normal
    out[:, 3] = d
    return out


def by_rows(fn: Callable, *arrays: np.ndarray, block: int = ROW_BLOCK):
    """``fn(*arrays)`` for a function that works row by row (row i of each result depends
    on row i of each argument only), evaluated a ``block`` of rows at a time into results
    allocated once: bit for bit the whole call's results, without its full-size
    temporaries (at a million rows each operation of the whole call faults in and writes
    24 MB that the next reads back from memory; a block's stay in the cache).

    ``arrays`` share their first dimension; ``fn`` returns an array or a tuple of arrays
    whose first dimension is that too, and changes nothing it did not make: with more
    than one core (:func:`row_workers`) the blocks after the first run on
    :func:`row_workers` threads at once, every n-th block on the n-th thread (numpy lets
    go of the interpreter inside its operations), each in a copy of the caller's context
    (its ``np.errstate``), each writing its own rows. Returns what ``fn`` does."""
    m = len(arrays[0])
    if m <= block:
        return fn(*arrays)
    first = fn(*(a[:block] for a in arrays))
    single = not isinstance(first, tuple)
    parts = (first,) if single else first
    out = tuple(np.empty((m,) + p.shape[1:], dtype=p.dtype) for p in parts)
    for o, p in zip(out, parts, strict=True):
        o[:block] = p

    def blocks(starts):
        for s in starts:
            got = fn(*(a[s:s + block] for a in arrays))
            for o, p in zip(out, (got,) if single else got, strict=True):
                o[s:s + block] = p
    starts, workers = range(block, m, block), row_workers()
    in_threads(blocks, [starts[i::workers] for i in range(workers)])    # every workers-th block a thread
    return out[0] if single else out


def row_workers() -> int:
    """Threads :func:`by_rows` and :func:`in_threads` use: the CPU cores this process may
    run on (its affinity where the system says), at most :data:`MAX_ROW_WORKERS`."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):          # no affinity on this system (macOS, Windows)
        cores = os.cpu_count() or 1
    return max(min(cores, MAX_ROW_WORKERS), 1)


def in_threads(work: Callable, items, workers: int | None = None) -> list:
    """``[work(item) for item in items]``, on ``workers`` threads (default
    :func:`row_workers`; one: in this thread, in order), each call in a copy of the
    caller's context (``np.errstate`` holds in the workers too). Results in the items'
    order; the first item's exception, in that order, is raised after every call ended.
    ``work`` must change nothing that another call reads."""
    items = list(items)
    workers = row_workers() if workers is None else workers
    if workers <= 1 or len(items) <= 1:
        return [work(item) for item in items]
    with ThreadPoolExecutor(max_workers=min(workers, len(items))) as pool:
        futures = [pool.submit(contextvars.copy_context().run, work, item) for item in items]
    return [f.result() for f in futures]


# ============================================================================ trees
def reduce_to_root(parent: np.ndarray, values: np.ndarray,
                   combine: Callable[[np.ndarray, np.ndarray], np.ndarray], overwrite: bool = False) -> np.ndarray:
    """Per node ``i``: ``combine(values[i], combine(values[parent[i]], ...))`` down to its
    root, by pointer jumping.

    Parameters
    ----------
    parent : (n,) int, parent of each node, -1 for a root
    values : (n, ...) per-node values
    combine : associative ``combine(own, ancestors)`` on (k, ...) rows, row-wise (row i of
        the result from row i of each argument), e.g. ``np.add``: each round combines a
        block of nodes at a time (:func:`by_rows`, on threads), every read before any write
    overwrite : ``values`` is the caller's to give: combined in place (returned), not copied

    Returns
    -------
    (n, ...) combined values, ``values``' dtype
    """
    total = values if overwrite else values.copy()
    jump = np.asarray(parent, dtype=np.int64).copy()
    live = np.flatnonzero(jump >= 0)
    while live.size:
        ancestor = jump[live]
        total[live] = by_rows(lambda own, up: combine(total[own], total[up]), live, ancestor)
        jump[live] = jump[ancestor]
        live = live[jump[live] >= 0]
    return total


def ancestor_count(parent: np.ndarray) -> np.ndarray:
    """(n,) int64: how many ancestors each node has (0 for a root)."""
    parent = np.asarray(parent, dtype=np.int64)
    return reduce_to_root(parent, (parent >= 0).astype(np.int64), np.add, overwrite=True)


def tree_roots(parent: np.ndarray) -> np.ndarray:
    """(n,) int64: the root of each node's tree (a root is its own)."""
    parent = np.asarray(parent, dtype=np.int64)
    return reduce_to_root(parent, np.arange(len(parent)), lambda own, ancestor: ancestor, overwrite=True)
