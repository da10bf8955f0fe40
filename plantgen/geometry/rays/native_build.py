"""What a scan target is built from, compiled (numba): for the many small targets a
stand's light builds (one a plant a step) the LBVH and the rows' boxes, and for a scan's or
a trace's targets the SAH tree; each the numpy build's numbers, computed without numpy's
per-call overhead.

- :func:`lbvh_arrays`: :func:`~plantgen.geometry.rays.bvh.build_bvh`'s ``lbvh`` tree, node
  for node. The primitives are sorted by their Morton codes as numpy sorts them; the nodes
  are then laid out breadth first as the numpy build lays them out (a level's leaves and
  splits in node order, the children of its internal nodes numbered in that order), each
  split where the highest bit in which a node's first and last codes differ flips (the
  middle where they are equal), and the node boxes are the unions of their primitives'
  (leaves) and children's boxes: min and max, exact.
- :func:`sah_arrays`: the ``sah`` tree (binned surface-area heuristic), node for node: each
  split as ``_sah_splits`` chooses it (the centres' bins an axis, the cheapest of the
  ``bins - 1`` planes an axis, the first axis and plane on ties, the middle where no plane
  parts the centres) and its primitives partitioned stably; laid out as the LBVH is. A
  level's nodes are split on the threads at once (each node's range of the order is its
  own), so the thread count changes nothing. The forest's 20 plants (91,264 primitives):
  47 ms; the forest cut's 4 (458,816, the pine's needles among them): 240 ms, against
  the numpy build's 318 ms and 2.7 s.
- :func:`row_boxes`: :func:`~plantgen.geometry.rays.reference.row_boxes` (no relief
  shell), the bounding pyramids' corners and their pad row by row, every operation in
  numpy's order (no fused multiply-add: numba does not contract), numpy's NaN rule in
  min and max.

The tests compare every array, number for number. Compiled on first use and cached on
disk as the tracer is (:mod:`plantgen.geometry.rays.native_trace`)."""

from __future__ import annotations

import numpy as np

from ..compiled import njit, numba, prange
from .morton import spread21

__all__ = ["centre_codes", "lbvh_arrays", "leaf_boxes", "row_boxes", "sah_arrays"]


#: :func:`~plantgen.geometry.rays.morton.spread21`, compiled.
_spread21 = njit(cache=True, inline="always")(spread21)


@njit(cache=True)
def _centre_codes(lo, hi):
    """The Morton codes of the boxes' centres ``0.5 * (lo + hi)``, as
    :func:`~plantgen.geometry.rays.morton.morton_codes` computes them (n >= 1)."""
    n = len(lo)
    centre = np.empty((n, 3))
    for i in range(n):
        for a in range(3):
            centre[i, a] = 0.5 * (lo[i, a] + hi[i, a])
    low, extent = np.empty(3), 0.0
    for a in range(3):
        small, big = centre[0, a], centre[0, a]
        for i in range(1, n):
            small, big = min(small, centre[i, a]), max(big, centre[i, a])
        low[a] = small
        extent = max(extent, big - small) if a else big - small
    scale = extent if extent > 0 else np.inf
    top = float(2 ** 21 - 1)
    codes = np.empty(n, np.uint64)
    for i in range(n):
        code = np.uint64(0)
        for a in range(3):
            q = min(max((centre[i, a] - low[a]) / scale * top, 0.0), top)
            code = code | (_spread21(np.uint64(q)) << np.uint64(2 - a))
        codes[i] = code
    return codes


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


@njit(cache=True, inline="always")
def _area(x0, y0, z0, x1, y1, z1):
    """:func:`~plantgen.geometry.rays.bvh.box_area` of one box (empty or flat: 0)."""
    dx, dy, dz = max(x1 - x0, 0.0), max(y1 - y0, 0.0), max(z1 - z0, 0.0)
    return 2.0 * (dx * dy + dy * dz + dz * dx)


@njit(cache=True, inline="always")
def _bin(centre, p, a, low, ext, bins):
    return min(int((centre[p, a] - low) / ext * bins), bins - 1)


@njit(cache=True)
def _sah_split(lo, hi, centre, order, s, e, bins, cnt, box, spare, spare_order):
    """Where node [s, e) of ``order`` splits by the binned SAH (module notes), its
    primitives partitioned stably (the left ones first): the first right one. ``cnt``
    (3, bins), ``box`` (3, bins, 6), ``spare`` (bins,) and ``spare_order`` (n,): scratch."""
    c_lo, c_hi, ext = np.empty(3), np.empty(3), np.empty(3)
    for a in range(3):
        c_lo[a] = c_hi[a] = centre[order[s], a]
    for q in range(s + 1, e):
        p = order[q]
        for a in range(3):
            c_lo[a], c_hi[a] = min(c_lo[a], centre[p, a]), max(c_hi[a], centre[p, a])
    for a in range(3):
        ext[a] = c_hi[a] - c_lo[a] if c_hi[a] - c_lo[a] > 0 else np.inf     # flat: every centre in bin 0
    cnt[:, :] = 0
    box[:, :, :3], box[:, :, 3:] = np.inf, -np.inf
    for q in range(s, e):                            # every axis's bins in one pass
        p = order[q]
        for a in range(3):
            b = _bin(centre, p, a, c_lo[a], ext[a], bins)
            cnt[a, b] += 1
            for k in range(3):
                box[a, b, k], box[a, b, 3 + k] = min(box[a, b, k], lo[p, k]), max(box[a, b, 3 + k], hi[p, k])
    best_cost, best_axis, best_bin = np.inf, 0, 0
    for a in range(3):
        # spare[j]: the area of bins j + 1 .. bins - 1 together, swept from the right
        x0 = y0 = z0 = np.inf
        x1 = y1 = z1 = -np.inf
        for j in range(bins - 1, 0, -1):
            x0, y0, z0 = min(x0, box[a, j, 0]), min(y0, box[a, j, 1]), min(z0, box[a, j, 2])
            x1, y1, z1 = max(x1, box[a, j, 3]), max(y1, box[a, j, 4]), max(z1, box[a, j, 5])
            spare[j - 1] = _area(x0, y0, z0, x1, y1, z1)
        x0 = y0 = z0 = np.inf
        x1 = y1 = z1 = -np.inf
        n_left = 0
        for j in range(bins - 1):
            x0, y0, z0 = min(x0, box[a, j, 0]), min(y0, box[a, j, 1]), min(z0, box[a, j, 2])
            x1, y1, z1 = max(x1, box[a, j, 3]), max(y1, box[a, j, 4]), max(z1, box[a, j, 5])
            n_left += cnt[a, j]
            n_right = (e - s) - n_left
            if n_left > 0 and n_right > 0:
                cost = n_left * _area(x0, y0, z0, x1, y1, z1) + n_right * spare[j]
                if cost < best_cost:
                    best_cost, best_axis, best_bin = cost, a, j
    if not best_cost < np.inf:                       # every centre in one bin: halve the range
        return s + (e - s) // 2
    a = best_axis
    left = s
    right = 0
    for q in range(s, e):                            # stable: the left ones in place, the right ones aside
        p = order[q]
        if _bin(centre, p, a, c_lo[a], ext[a], bins) <= best_bin:
            order[left] = p
            left += 1
        else:
            spare_order[s + right] = p
            right += 1
    order[left:e] = spare_order[s:s + right]
    return left


@njit(cache=True, parallel=True)
def _sah_level(lo, hi, centre, order, s, e, k, leaf_size, bins, spare_order, mids, threads):
    """Where each of a level's ``k`` nodes [s, e) splits (``mids``; a leaf's untouched), the
    nodes shared among ``threads`` threads (each reorders its own ranges of ``order``)."""
    threads = min(threads, k)
    for c in prange(threads):
        cnt, box, spare = np.zeros((3, bins), np.int64), np.empty((3, bins, 6)), np.empty(bins)
        for j in range(c, k, threads):
            if e[j] - s[j] > leaf_size:
                mids[j] = _sah_split(lo, hi, centre, order, s[j], e[j], bins, cnt, box, spare, spare_order)


@njit(cache=True)
def _topology(codes, leaf_size, lo, hi, order, bins, sah, threads):
    """``first``, ``count`` of every node and each level's first node (levels + 1 offsets):
    split by the sorted Morton ``codes``, or (``sah``) by the binned SAH over boxes ``lo``,
    ``hi``, reordering ``order`` as it goes."""
    n = len(order)
    centre = 0.5 * (lo + hi)                       # (0, 3) for the LBVH
    spare_order = np.empty(n if sah else 0, np.int64)
    cap = 2 * n - 1
    first, count = np.zeros(cap, np.int64), np.zeros(cap, np.int64)
    ids, s, e = np.zeros(cap, np.int64), np.zeros(cap, np.int64), np.zeros(cap, np.int64)
    nxt_ids, nxt_s, nxt_e = np.zeros(cap, np.int64), np.zeros(cap, np.int64), np.zeros(cap, np.int64)
    level_first = np.zeros(cap + 1, np.int64)
    mids = np.zeros(cap if sah else 0, np.int64)
    e[0], k, nodes, levels = n, 1, 1, 0
    while k:
        level_first[levels] = ids[0]
        levels += 1
        if sah:                                    # the level's splits first, in parallel; then the layout
            _sah_level(lo, hi, centre, order, s, e, k, leaf_size, bins, spare_order, mids, threads)
        m = 0
        for j in range(k):
            size = e[j] - s[j]
            if size <= leaf_size:
                first[ids[j]], count[ids[j]] = s[j], size
                continue
            mid = mids[j] if sah else _split(codes, s[j], e[j])
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


def centre_codes(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(n,) uint64 the Morton codes of the centres of boxes ``lo``, ``hi`` ((n, 3) float64,
    finite, n >= 1): ``morton_codes(0.5 * (lo + hi))``, the same codes."""
    return _centre_codes(np.ascontiguousarray(lo, np.float64), np.ascontiguousarray(hi, np.float64))


def lbvh_arrays(lo: np.ndarray, hi: np.ndarray, codes: np.ndarray, order: np.ndarray, leaf_size: int):
    """(node lo, node hi, first, count, levels) of the LBVH over boxes ``lo``, ``hi`` ((n, 3)
    float64, n >= 1, finite, checked) whose Morton ``codes`` sort as ``order`` (stable):
    the numpy build's arrays (module notes)."""
    sorted_codes = np.ascontiguousarray(codes[order], np.uint64)
    none = np.zeros((0, 3))
    order = np.ascontiguousarray(order, np.int64)
    first, count, level_first = _topology(sorted_codes, int(leaf_size), none, none, order, 2, False, 1)
    node_lo, node_hi = _boxes(np.ascontiguousarray(lo), np.ascontiguousarray(hi), order, first, count, level_first)
    return node_lo, node_hi, first, count, len(level_first) - 1


def sah_arrays(lo: np.ndarray, hi: np.ndarray, leaf_size: int, bins: int):
    """(node lo, node hi, first, count, order, levels) of the binned SAH tree over boxes
    ``lo``, ``hi`` ((n, 3) float64, n >= 1, finite, checked) with ``bins`` bins an axis:
    the numpy build's arrays (module notes)."""
    lo, hi = np.ascontiguousarray(lo, np.float64), np.ascontiguousarray(hi, np.float64)
    order = np.arange(len(lo), dtype=np.int64)
    first, count, level_first = _topology(np.zeros(0, np.uint64), int(leaf_size), lo, hi, order, int(bins), True,
                                          numba.get_num_threads())
    node_lo, node_hi = _boxes(lo, hi, order, first, count, level_first)
    return node_lo, node_hi, first, count, order, len(level_first) - 1


# ============================================================================ the rows' boxes
@njit(cache=True, inline="always")
def _nmin(a, b):
    """numpy's ``minimum`` (a NaN wins)."""
    return a if a != a else (b if b != b else (a if a < b else b))


@njit(cache=True, inline="always")
def _nmax(a, b):
    """numpy's ``maximum`` (a NaN wins)."""
    return a if a != a else (b if b != b else (a if a > b else b))


@njit(cache=True, inline="always")
def _dot3(P, i, c, V, j):
    """``P[i, c:c + 3]`` · ``V[j, :3]``, left to right (:func:`plantgen.geometry.vec.dot`)."""
    return P[i, c] * V[j, 0] + P[i, c + 1] * V[j, 1] + P[i, c + 2] * V[j, 2]


@njit(cache=True)
def _extent(P, base, axis, i, r1, k, generator_rise):
    """The heights of plane ``P[i]`` on the cone's generators at n·e = -|n_perp| and
    +|n_perp| (``_axial_extent`` of :mod:`plantgen.geometry.skeletons.frusta`, one plane)."""
    na = _dot3(P, i, 0, axis, i)
    nperp = np.sqrt(_nmax(1 - na * na, 0.0))
    gap = P[i, 3] - _dot3(P, i, 0, base, i)
    radial = -1.0 * nperp
    rise = na + k * radial
    low = (gap - r1 * radial) / (rise if abs(rise) > generator_rise else generator_rise)
    radial = 1.0 * nperp
    rise = na + k * radial
    return low, (gap - r1 * radial) / (rise if abs(rise) > generator_rise else generator_rise)


@njit(cache=True)
def _row_box(base, axis, ref, r1_, r2, length, plane_lo, plane_hi, i, grazing_tol, tilt_cos, generator_rise,
             box_pad, box_pad_floor, lo, hi, side, q, ys, rises, y_lo, y_hi):
    """Row ``i``'s padded box into ``lo[i]``, ``hi[i]``: the bounding pyramid's corners
    (no shell), then ``row_boxes``' pad, every operation as numpy does it."""
    k = (r2[i] - r1_[i]) / length[i]
    r1 = r1_[i] + 0.0
    side[0] = ref[i, 1] * axis[i, 2] - ref[i, 2] * axis[i, 1]
    side[1] = ref[i, 2] * axis[i, 0] - ref[i, 0] * axis[i, 2]
    side[2] = ref[i, 0] * axis[i, 1] - ref[i, 1] * axis[i, 0]
    for c in range(4):
        sx, sz = (-1.0 if c % 2 == 0 else 1.0), (-1.0 if c < 2 else 1.0)
        for a in range(3):
            q[c, a] = sx * ref[i, a] + sz * side[a]
    for p in range(2):
        P = plane_lo if p == 0 else plane_hi
        gap = P[i, 3] - _dot3(P, i, 0, base, i)
        n_axis = _dot3(P, i, 0, axis, i)
        for c in range(4):
            radial = P[i, 0] * q[c, 0] + P[i, 1] * q[c, 1] + P[i, 2] * q[c, 2]
            rise = n_axis + k * radial
            rises[p, c] = rise
            ys[p, c] = (gap - r1 * radial) / rise
    lo_v, hi_v = _extent(plane_lo, base, axis, i, r1, k, generator_rise), \
        _extent(plane_hi, base, axis, i, r1, k, generator_rise)
    ext_lo = _nmin(_nmin(lo_v[0], lo_v[1]), _nmin(hi_v[0], hi_v[1]))
    ext_hi = _nmax(_nmax(hi_v[0], hi_v[1]), _nmax(lo_v[0], lo_v[1]))
    n_dot_a = _nmin(_dot3(plane_lo, i, 0, axis, i), _dot3(plane_hi, i, 0, axis, i))
    limit = grazing_tol * _nmax(n_dot_a, tilt_cos)
    grazing = False
    for c in range(4):
        y_lo[c], y_hi[c] = _nmin(ys[0, c], ys[1, c]), _nmax(ys[0, c], ys[1, c])
        if _nmin(rises[0, c], rises[1, c]) < limit or not (np.isfinite(y_lo[c]) and np.isfinite(y_hi[c])):
            grazing = True
    big = 0.0
    for a in range(3):
        low, high = np.inf, -np.inf
        for c in range(8):
            y = (ext_lo if c < 4 else ext_hi) if grazing else (y_lo[c] if c < 4 else y_hi[c - 4])
            rad = _nmax(r1 + k * y, 0.0)
            v = base[i, a] + y * axis[i, a] + rad * q[c % 4, a]
            if c == 0:
                low, high = v, v
            else:
                low, high = _nmin(low, v), _nmax(high, v)
        lo[i, a], hi[i, a] = low, high
        big = _nmax(big, _nmax(abs(low), abs(high))) if a else _nmax(abs(low), abs(high))
    pad = box_pad * big + box_pad_floor
    for a in range(3):
        lo[i, a], hi[i, a] = lo[i, a] - pad, hi[i, a] + pad


@njit(cache=True)
def _row_boxes(base, axis, ref, r1, r2, length, plane_lo, plane_hi, grazing_tol, tilt_cos, generator_rise, box_pad,
               box_pad_floor):
    n = len(base)
    lo, hi = np.empty((n, 3)), np.empty((n, 3))
    side, q, ys, rises, y_lo, y_hi = np.empty(3), np.empty((4, 3)), np.empty((2, 4)), np.empty((2, 4)), np.empty(4), \
        np.empty(4)
    for i in range(n):
        _row_box(base, axis, ref, r1, r2, length, plane_lo, plane_hi, i, grazing_tol, tilt_cos, generator_rise,
                 box_pad, box_pad_floor, lo, hi, side, q, ys, rises, y_lo, y_hi)
    return lo, hi


def row_boxes(frusta) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~plantgen.geometry.rays.reference.row_boxes` of ``frusta`` (no relief shell),
    compiled: the bounding pyramids' corners and the pad, operation for operation as numpy
    computes them (the same numbers; the tests compare them)."""
    from ...tolerances import tol

    c = np.ascontiguousarray
    return _row_boxes(c(frusta.base), c(frusta.axis), c(frusta.ref_dir), c(frusta.r1), c(frusta.r2), c(frusta.length),
                      c(frusta.plane_lo), c(frusta.plane_hi), float(tol.pyramid_grazing), float(tol.plane_tilt_cos),
                      float(tol.generator_rise), float(tol.box_pad), float(tol.box_pad_floor))


@njit(cache=True)
def _leaf_boxes(vertices, index):
    n = len(index)
    tri, lo, hi = np.empty((n, 3, 3)), np.empty((n, 3)), np.empty((n, 3))
    for i in range(n):
        for c in range(3):
            for a in range(3):
                tri[i, c, a] = vertices[index[i, c], a]
        big = 0.0
        for a in range(3):
            low = _nmin(_nmin(tri[i, 0, a], tri[i, 1, a]), tri[i, 2, a])
            high = _nmax(_nmax(tri[i, 0, a], tri[i, 1, a]), tri[i, 2, a])
            lo[i, a], hi[i, a] = low, high
            size = _nmax(abs(low), abs(high))
            big = _nmax(big, size) if a else size
        pad = 1e-9 * big + 1e-12
        for a in range(3):
            lo[i, a], hi[i, a] = lo[i, a] - pad, hi[i, a] + pad
    return tri, lo, hi


def leaf_boxes(vertices: np.ndarray, index: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, 3, 3) the leaf triangles' corners (``vertices[index]``) and their padded boxes
    (lo, hi) as :func:`~plantgen.geometry.rays.scan_targets.scan_target` pads them: the
    corners' min and max, widened by 1e-9 of the largest coordinate plus 1e-12."""
    return _leaf_boxes(np.ascontiguousarray(vertices, np.float64), np.ascontiguousarray(index, np.int64))
