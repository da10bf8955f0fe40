"""The compiled LBVH build: :func:`~plantgen.geometry.rays.bvh.build_bvh`'s ``lbvh`` tree,
node for node, in native code (numba), for the many small targets a stand's light builds
(one a plant a step). The primitives are sorted by their Morton codes as numpy sorts them;
the nodes are then laid out breadth first as the numpy build lays them out (a level's
leaves and splits in node order, the children of its internal nodes numbered in that
order), each split where the highest bit in which a node's first and last codes differ
flips (the middle where they are equal), and the node boxes are the unions of their
primitives' (leaves) and children's boxes: min and max, exact. So the arrays are the numpy
build's, bit for bit (the tests compare them). Compiled on first use and cached on disk as
the tracer is (:mod:`plantgen.geometry.rays.native_trace`)."""

from __future__ import annotations

import numpy as np

from ..compiled import njit

__all__ = ["lbvh_arrays"]


@njit(cache=True)
def _highest_bit(x):
    for s in (1, 2, 4, 8, 16, 32):
        x = x | (x >> np.uint64(s))
    return x ^ (x >> np.uint64(1))


@njit(cache=True)
def _split(codes, s, e):
    """Where node [s, e) splits: the first code with the parting bit set (the middle where
    every code is the same), as the numpy build's ``searchsorted`` finds it."""
    c0, c1 = codes[s], codes[e - 1]
    top = _highest_bit(c0 ^ c1)
    if top == 0:
        return (s + e) // 2
    value = c1 & ~(top - np.uint64(1))
    lo, hi = s, e                          # codes[lo - 1] < value <= codes[hi] within the node
    while lo < hi:
        mid = (lo + hi) // 2
        if codes[mid] < value:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True)
def _topology(codes, leaf_size):
    """``first``, ``count`` of every node and each level's first node (levels + 1 offsets)."""
    n = len(codes)
    cap = 2 * n - 1
    first, count = np.zeros(cap, np.int64), np.zeros(cap, np.int64)
    ids, s, e = np.zeros(cap, np.int64), np.zeros(cap, np.int64), np.zeros(cap, np.int64)
    nxt_ids, nxt_s, nxt_e = np.zeros(cap, np.int64), np.zeros(cap, np.int64), np.zeros(cap, np.int64)
    level_first = np.zeros(cap + 1, np.int64)
    e[0], k, nodes, levels = n, 1, 1, 0
    while k:
        level_first[levels] = ids[0]
        levels += 1
        m = 0
        for j in range(k):
            size = e[j] - s[j]
            if size <= leaf_size:
                first[ids[j]], count[ids[j]] = s[j], size
                continue
            mid = _split(codes, s[j], e[j])
            first[ids[j]] = nodes
            nxt_ids[m], nxt_s[m], nxt_e[m] = nodes, s[j], mid
            nxt_ids[m + 1], nxt_s[m + 1], nxt_e[m + 1] = nodes + 1, mid, e[j]
            nodes += 2
            m += 2
        ids, nxt_ids = nxt_ids, ids
        s, nxt_s = nxt_s, s
        e, nxt_e = nxt_e, e
        k = m
    level_first[levels] = nodes
    return first[:nodes], count[:nodes], level_first[:levels + 1]


@njit(cache=True)
def _boxes(lo, hi, order, first, count, level_first):
    """Each node's box: a leaf's its primitives' union, an internal node's its children's."""
    nodes = len(first)
    node_lo, node_hi = np.empty((nodes, 3)), np.empty((nodes, 3))
    for level in range(len(level_first) - 2, -1, -1):
        for node in range(level_first[level], level_first[level + 1]):
            for a in range(3):
                if count[node] > 0:
                    p = order[first[node]]
                    low, high = lo[p, a], hi[p, a]
                    for q in range(first[node] + 1, first[node] + count[node]):
                        p = order[q]
                        low, high = min(low, lo[p, a]), max(high, hi[p, a])
                else:
                    c = first[node]
                    low, high = min(node_lo[c, a], node_lo[c + 1, a]), max(node_hi[c, a], node_hi[c + 1, a])
                node_lo[node, a], node_hi[node, a] = low, high
    return node_lo, node_hi


def lbvh_arrays(lo: np.ndarray, hi: np.ndarray, codes: np.ndarray, order: np.ndarray, leaf_size: int):
    """(node lo, node hi, first, count) of the LBVH over boxes ``lo``, ``hi`` ((n, 3)
    float64, n >= 1, finite, checked) whose Morton ``codes`` sort as ``order`` (stable):
    the numpy build's arrays (module notes)."""
    sorted_codes = np.ascontiguousarray(codes[order], np.uint64)
    first, count, level_first = _topology(sorted_codes, int(leaf_size))
    node_lo, node_hi = _boxes(np.ascontiguousarray(lo), np.ascontiguousarray(hi), np.ascontiguousarray(order, np.int64),
                              first, count, level_first)
    return node_lo, node_hi, first, count
