"""The compiled CPU traversal: the two-level BVH and the exact primitive tests in native,
multi-threaded float64 code (numba).

It walks the very arrays the GPU upload is made from (:attr:`ScanTarget.bvh
<plantgen.geometry.rays.scan_targets.ScanTarget.bvh>`, :attr:`SceneTarget.bvh
<plantgen.geometry.rays.scan_targets.SceneTarget.bvh>` and its :attr:`~plantgen.geometry.rays.bvh.SceneBVH.flat`
node array): no second build. A ray walks the top level over the copies nearest box
first, is moved into a copy's frame in float64 and walks that plant's tree the same way;
a leaf's primitives are culled by their own boxes and then tested exactly. Closest hits
are walked a packet of :data:`RAY_BLOCK` neighbouring rays at a time (a scan's beams, a
camera's pixels, in the order given): ranged traversal, each node narrowing the packet's
range of rays to the first and last that meet it (each ray culled by its own best hit),
each leaf testing every ray of its range as a lone walk would; the nodes near the root are
then tested about once a packet instead of once a ray (the forest's scan beams: 1.5x). A
box (node or slot) meets the range's rays in one branch-free, vectorised loop (the lone
walk's slab arithmetic; the NaN rule ray by ray where a 1/d is infinite): 1.3-2.2x; an
inner node's two children in one such loop, only those met pushed: 1.07-1.11x.
Any hits (light, shadows) walk a ray at a time, stopping at the first hit. The exact tests
(:mod:`plantgen.geometry.rays.native_prims`): a frustum row by the reference's float64 pair
test, a leaf triangle by the scan's Möller-Trumbore test, each operation for operation.

The answer is the numpy traversal's (:func:`~plantgen.geometry.rays.bvh.trace_bvh`,
:func:`~plantgen.geometry.rays.bvh.trace_scene`): the smallest t in (t_min, t_max), ties to
the smaller copy, then primitive; with ``any_hit`` the first hit found. Rays are
independent (a packet tests, for each of its rays, every primitive a lone walk of that ray
would), so neither the packets nor the thread count change any result. Compiled on first use and cached
on disk (``cache=True``; numba falls back to its user-wide cache directory, or
``NUMBA_CACHE_DIR``, where the package's own is read-only).

Without numba (or where its compiler fails) :func:`available` is False, one line says
so, and the callers walk the numpy traversal instead.
"""

from __future__ import annotations

import os
import sys
import threading
import time

import numpy as np

from ..compiled import NUMBA_ERROR, njit, numba, prange
from .native_prims import prim_hit, row_hit, triangle_hit

__all__ = ["NativeScene", "available", "compile_seconds", "native_scene", "pair_distances", "warm_up"]

_NUMBA_ERROR = NUMBA_ERROR                    # numpy walks where numba does not import

#: Rays a worker thread takes at a time.
RAY_BLOCK = 64
#: Blocks of rays a thread takes at a time (numba's parallel chunk size): a scan's beams
#: cost unevenly (the sky against a crown), so threads take small chunks as they free up.
BLOCKS_A_CHUNK = 4
#: Row fields (columns of the row table): base (3), axis (3), h, r1, k, n_lo (3), n_hi (3),
#: d_lo, d_hi, open_lo, open_hi.
ROW_WIDTH = 19


# ============================================================================ the walk
@njit(cache=True, inline="always")
def _fmin(a, b):
    return b if a != a else (a if b != b else min(a, b))


@njit(cache=True, inline="always")
def _fmax(a, b):
    return b if a != a else (a if b != b else max(a, b))


@njit(cache=True, inline="always")
def _slab(box, n, ox, oy, oz, ix, iy, iz, careful):
    """(near, far) of the ray (o, 1/d) through box ``n`` of ``box`` (k, >= 6): the numpy
    traversal's slab test. Where 1/d is infinite (a ray parallel to a face) a product may
    be NaN (0·inf), which numpy's fmin / fmax skip: so does the slow path here; rays with
    every 1/d finite (``careful`` False) take the fast one (no NaN can arise there, the
    same numbers)."""
    if careful:
        return _slab_nan(box, n, ox, oy, oz, ix, iy, iz)
    t1, t2 = (box[n, 0] - ox) * ix, (box[n, 3] - ox) * ix
    near, far = (t1, t2) if t1 < t2 else (t2, t1)
    t1, t2 = (box[n, 1] - oy) * iy, (box[n, 4] - oy) * iy
    a, b = (t1, t2) if t1 < t2 else (t2, t1)
    near, far = near if near > a else a, far if far < b else b
    t1, t2 = (box[n, 2] - oz) * iz, (box[n, 5] - oz) * iz
    a, b = (t1, t2) if t1 < t2 else (t2, t1)
    return near if near > a else a, far if far < b else b


@njit(cache=True)
def _slab_nan(box, n, ox, oy, oz, ix, iy, iz):
    """:func:`_slab` with numpy's NaN rule (fmin / fmax skip a NaN)."""
    t1, t2 = (box[n, 0] - ox) * ix, (box[n, 3] - ox) * ix
    near, far = _fmin(t1, t2), _fmax(t1, t2)
    t1, t2 = (box[n, 1] - oy) * iy, (box[n, 4] - oy) * iy
    near, far = _fmax(near, _fmin(t1, t2)), _fmin(far, _fmax(t1, t2))
    t1, t2 = (box[n, 2] - oz) * iz, (box[n, 5] - oz) * iz
    return _fmax(near, _fmin(t1, t2)), _fmin(far, _fmax(t1, t2))


@njit(cache=True, inline="always")
def _inv(d):
    return 1.0 / d if d != 0 else (np.inf if not np.signbit(d) else -np.inf)


@njit(cache=True, inline="always")
def _enter(box, n, ox, oy, oz, ix, iy, iz, careful, t_min):
    """(max(near, t_min), far) of the ray through box ``n`` (:func:`_slab`)."""
    near, far = _slab(box, n, ox, oy, oz, ix, iy, iz, careful)
    return max(near, t_min), far


@njit(cache=True, inline="always")
def _better(t, copy, g, best_t, best_c, best_g):
    """Whether the hit (t, copy, g) beats the best so far: the smaller t, ties to the
    smaller copy, then primitive (the numpy traversal's rule)."""
    return t < best_t or (t == best_t and (copy < best_c or (copy == best_c and g < best_g)))


@njit(cache=True)
def _slot_hit(slot_kind, R, T, s, ox, oy, oz, dx, dy, dz, t_min, t_hi, origin):
    """t of the ray at the primitive of leaf slot ``s`` within (t_min, t_hi), else inf."""
    k = slot_kind[s]
    t = row_hit(R, k, ox, oy, oz, dx, dy, dz, t_min, origin) if k >= 0 else \
        triangle_hit(T, -1 - k, ox, oy, oz, dx, dy, dz)
    return t if t > t_min and t < t_hi else np.inf


@njit(cache=True)
def _walk(nodes, slot_box, prims, slot_kind, R, T, root, ox, oy, oz, dx, dy, dz, t_min, t_hi, copy,
          best_t, best_c, best_g, any_hit, stack, origin):
    """One ray through one plant's tree from node ``root`` (in its frame), nearest child
    first, culled by the best hit so far: the new best (t, copy, primitive) and whether
    ``any_hit`` found one."""
    i0, i1, i2 = _inv(dx), _inv(dy), _inv(dz)
    careful = abs(i0) == np.inf or abs(i1) == np.inf or abs(i2) == np.inf
    near, far = _enter(nodes, root, ox, oy, oz, i0, i1, i2, careful, t_min)
    if not (near <= far and far > t_min and near < t_hi):
        return best_t, best_c, best_g, False
    below = np.nextafter(t_hi, -np.inf)               # a box must start before the ray's end
    top = 0
    stack[0] = root
    while top >= 0:
        node = stack[top]
        top -= 1
        first, count = int(nodes[node, 6]), int(nodes[node, 7])
        if count > 0:
            for s in range(first, first + count):
                near, far = _enter(slot_box, s, ox, oy, oz, i0, i1, i2, careful, t_min)
                if not (near <= far and far > t_min and near <= min(t_hi, best_t)):
                    continue
                t = _slot_hit(slot_kind, R, T, s, ox, oy, oz, dx, dy, dz, t_min, t_hi, origin)
                if t < np.inf and _better(t, copy, prims[s], best_t, best_c, best_g):
                    best_t, best_c, best_g = t, copy, prims[s]
                    if any_hit:
                        return best_t, best_c, best_g, True
            continue
        hi = min(below, best_t)
        n0, f0 = _enter(nodes, first, ox, oy, oz, i0, i1, i2, careful, t_min)
        n1, f1 = _enter(nodes, first + 1, ox, oy, oz, i0, i1, i2, careful, t_min)
        top = _push(stack, top, first, n0 <= f0 and f0 > t_min and n0 <= hi, n1 <= f1 and f1 > t_min and n1 <= hi,
                    n1 < n0)
    return best_t, best_c, best_g, False


@njit(cache=True)
def _push(stack, top, left, ok0, ok1, right_first):
    """Push the children met, the nearer one last (popped first); the new top."""
    if ok0 and ok1:
        stack[top + 1], stack[top + 2] = (left, left + 1) if right_first else (left + 1, left)
        return top + 2
    if ok0 or ok1:
        stack[top + 1] = left if ok0 else left + 1
        return top + 1
    return top


@njit(cache=True)
def _moved(m, o0, o1, o2, d0, d1, d2):
    """The ray (o, d) moved by the 4x4 ``m`` (float64, t kept)."""
    return (m[0, 0] * o0 + m[0, 1] * o1 + m[0, 2] * o2 + m[0, 3],
            m[1, 0] * o0 + m[1, 1] * o1 + m[1, 2] * o2 + m[1, 3],
            m[2, 0] * o0 + m[2, 1] * o1 + m[2, 2] * o2 + m[2, 3],
            m[0, 0] * d0 + m[0, 1] * d1 + m[0, 2] * d2,
            m[1, 0] * d0 + m[1, 1] * d1 + m[1, 2] * d2,
            m[2, 0] * d0 + m[2, 1] * d1 + m[2, 2] * d2)


@njit(cache=True)
def _sorted_copies(top, node, o0, o1, o2, i0, i1, i2, careful, t_min, t_hi, order_t, order_c):
    """The copies of top-level leaf ``node`` the ray meets, sorted by entry distance (ties
    by copy) into ``order_t``, ``order_c``: their count."""
    t_nodes, t_prims, copy_box, copy_plant, roots = top[1], top[2], top[3], top[4], top[6]
    k = 0
    for s in range(t_nodes[node, 0], t_nodes[node, 0] + t_nodes[node, 1]):
        c = t_prims[s]
        near, far = _enter(copy_box, c, o0, o1, o2, i0, i1, i2, careful, t_min)
        if roots[copy_plant[c]] < 0 or not (near <= far and far > t_min and near < t_hi):
            continue
        j = k                                   # insertion by entry distance, ties by copy
        while j > 0 and (order_t[j - 1] > near or (order_t[j - 1] == near and order_c[j - 1] > c)):
            order_t[j], order_c[j] = order_t[j - 1], order_c[j - 1]
            j -= 1
        order_t[j], order_c[j] = near, c
        k += 1
    return k


@njit(cache=True)
def _trace_one(scene, top, o0, o1, o2, d0, d1, d2, t_min, t_hi, any_hit, tstack, stack, order_t, order_c, origin):
    """One ray through the copies (the top level ``top``, nearest box first), each copy's
    plant walked in its frame: (t, copy, global primitive) of its hit (inf, -1, -1)."""
    nodes, slot_box, prims, slot_kind, R, T = scene
    t_box, t_nodes, inverse, plant_of, roots = top[0], top[1], top[5], top[4], top[6]
    best_t, best_c, best_g = np.inf, -1, -1
    i0, i1, i2 = _inv(d0), _inv(d1), _inv(d2)
    careful = abs(i0) == np.inf or abs(i1) == np.inf or abs(i2) == np.inf
    near, far = _enter(t_box, 0, o0, o1, o2, i0, i1, i2, careful, t_min)
    if not (near <= far and far > t_min and near < t_hi):
        return best_t, best_c, best_g
    below = np.nextafter(t_hi, -np.inf)
    sp = 0
    tstack[0] = 0
    while sp >= 0:
        node = tstack[sp]
        sp -= 1
        first = t_nodes[node, 0]
        if t_nodes[node, 1] > 0:
            k = _sorted_copies(top, node, o0, o1, o2, i0, i1, i2, careful, t_min, t_hi, order_t, order_c)
            for j in range(k):
                if order_t[j] > best_t:             # every later copy starts beyond the best hit
                    break
                c = order_c[j]
                ox, oy, oz, dx, dy, dz = _moved(inverse[c], o0, o1, o2, d0, d1, d2)
                best_t, best_c, best_g, done = _walk(nodes, slot_box, prims, slot_kind, R, T, roots[plant_of[c]],
                                                     ox, oy, oz, dx, dy, dz, t_min, t_hi, c, best_t, best_c, best_g,
                                                     any_hit, stack, origin)
                if done:
                    return best_t, best_c, best_g
            continue
        hi = min(below, best_t)
        n0, f0 = _enter(t_box, first, o0, o1, o2, i0, i1, i2, careful, t_min)
        n1, f1 = _enter(t_box, first + 1, o0, o1, o2, i0, i1, i2, careful, t_min)
        sp = _push(tstack, sp, first, n0 <= f0 and f0 > t_min and n0 <= hi, n1 <= f1 and f1 > t_min and n1 <= hi,
                   n1 < n0)
    return best_t, best_c, best_g


# ============================================================================ packets
# Closest-hit rays are walked a packet (:data:`RAY_BLOCK` neighbouring rays) at a time, by
# ranged traversal: a node holds the range [f, l] of the packet's rays that may meet it,
# narrowed at each node to its first and last ray that do (each ray culled by its own best
# hit, exactly as alone); a leaf tests each ray of its range as a lone walk would. Every
# primitive a lone walk tests is tested, so each ray's hit is the lone walk's, bit for
# bit; neighbouring rays (a scan's beams, a camera's pixels) share the nodes near the root.
@njit(cache=True, inline="always")
def _box_meets(b0, b1, b2, b3, b4, b5, ox, oy, oz, ix, iy, iz, t_min, lim):
    """Whether the ray (o, 1/d) meets the box in (t_min, lim]: :func:`_slab`'s fast path, branch-free."""
    t1, t2 = (b0 - ox) * ix, (b3 - ox) * ix
    near, far = (t1, t2) if t1 < t2 else (t2, t1)
    t1, t2 = (b1 - oy) * iy, (b4 - oy) * iy
    a, b = (t1, t2) if t1 < t2 else (t2, t1)
    near, far = near if near > a else a, far if far < b else b
    t1, t2 = (b2 - oz) * iz, (b5 - oz) * iz
    a, b = (t1, t2) if t1 < t2 else (t2, t1)
    near, far = near if near > a else a, far if far < b else b
    near = max(near, t_min)
    return (near <= far) & (far > t_min) & (near <= lim)


@njit(cache=True)
def _range(box, n, S, care, any_care, f, l, t_min, lim, mask):
    """The first and last rays of [f, l] meeting box ``n`` before ``lim`` (f > l: none), ``mask``
    each; ``S`` (6, P): origins, 1 / directions; ``any_care``: some 1/d infinite (the NaN rule)."""
    if any_care:
        for r in range(f, l + 1):
            near, far = _enter(box, n, S[0, r], S[1, r], S[2, r], S[3, r], S[4, r], S[5, r], care[r], t_min)
            mask[r] = near <= far and far > t_min and near <= lim[r]
    else:
        b0, b1, b2, b3, b4, b5 = box[n, 0], box[n, 1], box[n, 2], box[n, 3], box[n, 4], box[n, 5]
        for i in range(f, l + 1):
            r = np.uint64(i)                  # an unsigned index: no wraparound per lane, the loop vectorises
            mask[r] = _box_meets(b0, b1, b2, b3, b4, b5, S[0, r], S[1, r], S[2, r], S[3, r], S[4, r], S[5, r], t_min,
                                 lim[r])
    return _first_last(mask, f, l)


@njit(cache=True)
def _first_last(mask, f, l):
    """The first and last ``mask``-ed rays of [f, l] (f > l: none)."""
    while f <= l and not mask[f]:
        f += 1
    while l > f and not mask[l]:
        l -= 1
    return f, l


@njit(cache=True)
def _children(box, n, S, care, any_care, f, l, t_min, lim, mask, mask2):
    """:func:`_range` of sibling boxes ``n`` and ``n + 1`` in one pass over the rays of [f, l]
    (each ray's origin and 1/d read once): (f0, l0, f1, l1)."""
    if any_care:
        for r in range(f, l + 1):
            near, far = _enter(box, n, S[0, r], S[1, r], S[2, r], S[3, r], S[4, r], S[5, r], care[r], t_min)
            mask[r] = near <= far and far > t_min and near <= lim[r]
            near, far = _enter(box, n + 1, S[0, r], S[1, r], S[2, r], S[3, r], S[4, r], S[5, r], care[r], t_min)
            mask2[r] = near <= far and far > t_min and near <= lim[r]
    else:
        b0, b1, b2, b3, b4, b5 = box[n, 0], box[n, 1], box[n, 2], box[n, 3], box[n, 4], box[n, 5]
        c0, c1, c2 = box[n + 1, 0], box[n + 1, 1], box[n + 1, 2]
        c3, c4, c5 = box[n + 1, 3], box[n + 1, 4], box[n + 1, 5]
        for i in range(f, l + 1):
            r = np.uint64(i)
            ox, oy, oz, ix, iy, iz, lm = S[0, r], S[1, r], S[2, r], S[3, r], S[4, r], S[5, r], lim[r]
            mask[r] = _box_meets(b0, b1, b2, b3, b4, b5, ox, oy, oz, ix, iy, iz, t_min, lm)
            mask2[r] = _box_meets(c0, c1, c2, c3, c4, c5, ox, oy, oz, ix, iy, iz, t_min, lm)
    f0, l0 = _first_last(mask, f, l)
    f1, l1 = _first_last(mask2, f, l)
    return f0, l0, f1, l1


@njit(cache=True)
def _right_first(box, n, S, care, r, t_min):
    """Whether child ``n + 1`` is nearer than child ``n`` along ray ``r`` (a miss: farthest)."""
    n0, f0 = _enter(box, n, S[0, r], S[1, r], S[2, r], S[3, r], S[4, r], S[5, r], care[r], t_min)
    n1, f1 = _enter(box, n + 1, S[0, r], S[1, r], S[2, r], S[3, r], S[4, r], S[5, r], care[r], t_min)
    return not (n0 <= f0) or (n1 <= f1 and n1 < n0)


@njit(cache=True)
def _leaf_packet(slot_box, prims, slot_kind, R, T, first, count, S, cd, cc, any_care, f, l, t_min, t_hi, below, lim,
                 hits, copy, best_t, best_c, best_g, origin):
    """The rays of [f, l] (those that met the leaf's box at its parent) against its slots, a
    slot's box against them at once (``hits``), each ray culled by its own best hit as a lone
    walk is: their best hits (and ``lim``) updated."""
    for s in range(first, first + count):
        if any_care:
            for r in range(f, l + 1):
                near, far = _enter(slot_box, s, S[0, r], S[1, r], S[2, r], S[3, r], S[4, r], S[5, r], cc[r], t_min)
                hits[r] = near <= far and far > t_min and near <= min(t_hi[r], best_t[r])
        else:
            b0, b1, b2 = slot_box[s, 0], slot_box[s, 1], slot_box[s, 2]
            b3, b4, b5 = slot_box[s, 3], slot_box[s, 4], slot_box[s, 5]
            for i in range(f, l + 1):
                r = np.uint64(i)
                hits[r] = _box_meets(b0, b1, b2, b3, b4, b5, S[0, r], S[1, r], S[2, r], S[3, r], S[4, r], S[5, r],
                                     t_min, min(t_hi[r], best_t[r]))
        k, g = slot_kind[s], prims[s]
        for r in range(f, l + 1):
            if not hits[r]:
                continue
            ox, oy, oz, dx, dy, dz = S[0, r], S[1, r], S[2, r], cd[r, 0], cd[r, 1], cd[r, 2]
            t = row_hit(R, k, ox, oy, oz, dx, dy, dz, t_min, origin) if k >= 0 else \
                triangle_hit(T, -1 - k, ox, oy, oz, dx, dy, dz)
            if not (t > t_min and t < t_hi[r]):
                continue
            bt = best_t[r]
            if t < bt or (t == bt and (copy < best_c[r] or (copy == best_c[r] and g < best_g[r]))):
                best_t[r], best_c[r], best_g[r] = t, copy, g
                lim[r] = min(below[r], t)


@njit(cache=True)
def _walk_packet(nodes, slot_box, prims, slot_kind, R, T, root, S, cd, cc, any_care, f, l, t_min, t_hi, below, lim,
                 mask, hits, copy, best_t, best_c, best_g, sn, sf, sl, origin):
    """Rays [f, l] of a packet through one plant's tree from ``root``, in a copy's frame
    (origins and 1 / directions ``S`` (6, P), directions ``cd``, careful ``cc``); each
    ray's best hit updated; ``sn``, ``sf``, ``sl``: the stack's nodes and ranges. A node
    on the stack holds the range of rays that met its box when its parent was walked; an
    inner node tests both children's boxes in one pass and pushes those met, the nearer
    (along the range's first ray) on top."""
    f, l = _range(nodes, root, S, cc, any_care, f, l, t_min, lim, mask)
    if f > l:
        return
    sp = 0
    sn[0], sf[0], sl[0] = root, f, l
    while sp >= 0:
        node, f, l = sn[sp], sf[sp], sl[sp]
        sp -= 1
        count = int(nodes[node, 7])
        first = int(nodes[node, 6])
        if count > 0:
            _leaf_packet(slot_box, prims, slot_kind, R, T, first, count, S, cd, cc, any_care, f, l, t_min, t_hi, below,
                         lim, hits, copy, best_t, best_c, best_g, origin)
            continue
        f0, l0, f1, l1 = _children(nodes, first, S, cc, any_care, f, l, t_min, lim, mask, hits)
        if f0 > l0 or f1 > l1:
            if f0 <= l0 or f1 <= l1:
                sp += 1
                sn[sp], sf[sp], sl[sp] = (first, f0, l0) if f0 <= l0 else (first + 1, f1, l1)
            continue
        right = _right_first(nodes, first, S, cc, min(f0, f1), t_min)
        sn[sp + 1], sf[sp + 1], sl[sp + 1] = (first, f0, l0) if right else (first + 1, f1, l1)
        sn[sp + 2], sf[sp + 2], sl[sp + 2] = (first + 1, f1, l1) if right else (first, f0, l0)
        sp += 2


@njit(cache=True)
def _to_copy(m, O, D, a, cf, cl, S, cd, cc):
    """Rays [cf, cl] of packet ``a`` moved by the 4x4 ``m`` into ``S``, ``cd``, ``cc``: any careful?"""
    any_care = False
    for r in range(cf, cl + 1):
        o0, o1, o2 = O[a + r, 0], O[a + r, 1], O[a + r, 2]
        d0, d1, d2 = D[a + r, 0], D[a + r, 1], D[a + r, 2]
        S[0, r] = m[0, 0] * o0 + m[0, 1] * o1 + m[0, 2] * o2 + m[0, 3]
        S[1, r] = m[1, 0] * o0 + m[1, 1] * o1 + m[1, 2] * o2 + m[1, 3]
        S[2, r] = m[2, 0] * o0 + m[2, 1] * o1 + m[2, 2] * o2 + m[2, 3]
        x = m[0, 0] * d0 + m[0, 1] * d1 + m[0, 2] * d2
        y = m[1, 0] * d0 + m[1, 1] * d1 + m[1, 2] * d2
        z = m[2, 0] * d0 + m[2, 1] * d1 + m[2, 2] * d2
        cd[r, 0], cd[r, 1], cd[r, 2] = x, y, z
        i0, i1, i2 = _inv(x), _inv(y), _inv(z)
        S[3, r], S[4, r], S[5, r] = i0, i1, i2
        cc[r] = abs(i0) == np.inf or abs(i1) == np.inf or abs(i2) == np.inf
        any_care = any_care or cc[r]
    return any_care


@njit(cache=True)
def _packet_rays(O, D, a, n, t_hi, W, wc, below, lim, best_t, best_c, best_g):
    """The packet's world rays ``W``, careful ``wc``, ends and no hit yet: whether any is careful."""
    any_care = False
    for r in range(n):
        i0, i1, i2 = _inv(D[a + r, 0]), _inv(D[a + r, 1]), _inv(D[a + r, 2])
        W[0, r], W[1, r], W[2, r] = O[a + r, 0], O[a + r, 1], O[a + r, 2]
        W[3, r], W[4, r], W[5, r] = i0, i1, i2
        wc[r] = abs(i0) == np.inf or abs(i1) == np.inf or abs(i2) == np.inf
        any_care = any_care or wc[r]
        below[r] = np.nextafter(t_hi[a + r], -np.inf)
        lim[r] = min(below[r], np.inf)
        best_t[r], best_c[r], best_g[r] = np.inf, -1, -1
    return any_care


@njit(cache=True)
def _trace_packet(nodes, slot_box, prims, slot_kind, R, T, t_box, t_nodes, t_prims, copy_box, copy_plant, inverse,
                  roots, O, D, a, n, t_min, t_hi, W, wc, below, lim, mask, hits, S, cd, cc, best_t, best_c, best_g,
                  tn, tf, tl, sn, sf, sl, origin):
    """Rays ``a`` .. ``a + n - 1`` (one packet) through the copies: their closest hits in
    ``best_t``, ``best_c``, ``best_g`` (t, copy, global primitive)."""
    w_care = _packet_rays(O, D, a, n, t_hi, W, wc, below, lim, best_t, best_c, best_g)
    th = t_hi[a:a + n]
    sp = 0
    tn[0], tf[0], tl[0] = 0, 0, n - 1
    while sp >= 0:
        node, f, l = tn[sp], tf[sp], tl[sp]
        sp -= 1
        f, l = _range(t_box, node, W, wc, w_care, f, l, t_min, lim, mask)
        if f > l:
            continue
        first, count = t_nodes[node, 0], t_nodes[node, 1]
        if count > 0:
            for s in range(first, first + count):
                c = t_prims[s]
                root = roots[copy_plant[c]]
                if root < 0:
                    continue
                cf, cl = _range(copy_box, c, W, wc, w_care, f, l, t_min, lim, mask)
                if cf > cl:
                    continue
                c_care = _to_copy(inverse[c], O, D, a, cf, cl, S, cd, cc)
                _walk_packet(nodes, slot_box, prims, slot_kind, R, T, root, S, cd, cc, c_care, cf, cl, t_min, th,
                             below, lim, mask, hits, c, best_t, best_c, best_g, sn, sf, sl, origin)
            continue
        nearer_right = _right_first(t_box, first, W, wc, f, t_min)
        x, y = (first, first + 1) if nearer_right else (first + 1, first)
        tn[sp + 1], tf[sp + 1], tl[sp + 1] = x, f, l
        tn[sp + 2], tf[sp + 2], tl[sp + 2] = y, f, l
        sp += 2


@njit(cache=True, parallel=True)
def _trace_all(scene, top, O, D, t_min, t_hi, any_hit, depth, widest, origin, out_t, out_c, out_p):
    """Every ray (m,), in blocks of :data:`RAY_BLOCK` across the threads: closest hits a
    packet a block, any hits a ray at a time."""
    nodes, slot_box, prims, slot_kind, R, T = scene
    t_box, t_nodes, t_prims, copy_box, copy_plant, inverse, roots = top
    m, P = len(O), RAY_BLOCK
    for b in prange((m + P - 1) // P):
        a = b * P
        n = min(m, a + P) - a
        tn, tf, tl = np.empty(depth, np.int64), np.empty(depth, np.int64), np.empty(depth, np.int64)
        if any_hit:
            order_t, order_c = np.empty(widest), np.empty(widest, np.int64)
            for r in range(a, a + n):
                out_t[r], out_c[r], out_p[r] = _trace_one(scene, top, O[r, 0], O[r, 1], O[r, 2], D[r, 0], D[r, 1],
                                                          D[r, 2], t_min, t_hi[r], True, tn, tf, order_t, order_c,
                                                          origin)
            continue
        sn, sf, sl = np.empty(depth, np.int64), np.empty(depth, np.int64), np.empty(depth, np.int64)
        W, S, cd = np.empty((6, P)), np.empty((6, P)), np.empty((P, 3))
        wc, cc, mask, hits = np.empty(P, np.bool_), np.empty(P, np.bool_), np.empty(P, np.bool_), np.empty(P, np.bool_)
        below, lim, best_t = np.empty(P), np.empty(P), np.empty(P)
        best_c, best_g = np.empty(P, np.int64), np.empty(P, np.int64)
        _trace_packet(nodes, slot_box, prims, slot_kind, R, T, t_box, t_nodes, t_prims, copy_box, copy_plant,
                      inverse, roots, O, D, a, n, t_min, t_hi, W, wc, below, lim, mask, hits, S, cd, cc, best_t, best_c,
                      best_g, tn, tf, tl, sn, sf, sl, origin)
        out_t[a:a + n], out_c[a:a + n], out_p[a:a + n] = best_t[:n], best_c[:n], best_g[:n]


@njit(cache=True, parallel=True)
def _pairs_all(kind, R, T, prim, O, D, t_min, origin, out_t):
    """t of each ray (k,) at its primitive ``prim`` (k,) (global ids; -1: inf)."""
    for r in prange(len(prim)):
        g = prim[r]
        out_t[r] = np.inf if g < 0 else prim_hit(kind, R, T, g, O[r, 0], O[r, 1], O[r, 2], D[r, 0], D[r, 1],
                                                 D[r, 2], t_min, origin)


# ============================================================================ the Python side
_STATE = {"failed": None, "compile_s": None, "noticed": False}
#: One kernel call at a time: numba's default threading layer (workqueue) aborts the
#: process where two Python threads (a Dask worker's, say) launch parallel kernels at once.
_LOCK = threading.RLock()
#: The same lock, for the compiled kernels of other modules (:mod:`plantgen.geometry.rays.native_cull`).
KERNEL_LOCK = _LOCK


def _notice(why: str) -> None:
    """One line on stderr, once: the compiled traversal is off and why."""
    if not _STATE["noticed"]:
        _STATE["noticed"] = True
        print(f"plantgen: the compiled CPU tracer is off ({why}); rays are traced by the numpy traversal",
              file=sys.stderr)


def wanted() -> bool:
    """Whether the compiled traversal is meant to run here, known without compiling it:
    numba imports and ``PLANTGEN_CPU_TRACER`` is not ``numpy``. A command chooses its path
    with this before any budget check, so that a refusal never waits on the compile; the
    compile (or its failure, and then the numpy traversal) comes with the first trace."""
    return os.environ.get("PLANTGEN_CPU_TRACER", "").lower() != "numpy" and _NUMBA_ERROR is None


def available() -> bool:
    """Whether the compiled traversal runs here: numba imports, its compile succeeded
    (tried on first call, :func:`warm_up`) and ``PLANTGEN_CPU_TRACER`` is not ``numpy``.
    Where it does not, one line on stderr says why (once) and False is returned."""
    if os.environ.get("PLANTGEN_CPU_TRACER", "").lower() == "numpy":
        return False
    if _NUMBA_ERROR is not None:
        _notice(f"numba does not import: {type(_NUMBA_ERROR).__name__}: {_NUMBA_ERROR}".splitlines()[0])
        return False
    if _STATE["compile_s"] is None and _STATE["failed"] is None:
        warm_up()
    return _STATE["failed"] is None


def warm_up() -> float:
    """Compile the kernels (or load them from numba's cache) on a tiny scene; the seconds
    it took (:func:`compile_seconds`). A failure turns the traversal off with one line."""
    with _LOCK:                                          # one thread compiles, the others wait for it
        if _STATE["compile_s"] is not None or _STATE["failed"] is not None or _NUMBA_ERROR is not None:
            return _STATE["compile_s"] or 0.0
        start = time.perf_counter()
        try:
            tiny = _tiny()
            tiny.trace(np.array([[0.0, -1.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]), any_hit=False)
            tiny.distances(0, np.zeros(1, np.int64), np.array([[0.0, -1.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
        except Exception as error:                       # noqa: BLE001 - numba's errors are many
            _STATE["failed"] = error
            _notice(f"numba could not compile it: {type(error).__name__}: {error}".splitlines()[0])
            return 0.0
        _STATE["compile_s"] = time.perf_counter() - start
        return _STATE["compile_s"]


def compile_seconds() -> float | None:
    """Seconds the first :func:`warm_up` took (compiling, or loading numba's cache); None
    before it ran."""
    return _STATE["compile_s"]


def _tiny() -> NativeScene:
    """One unit cylinder row and one triangle in one leaf (the kernels' types, compiled)."""
    R = np.zeros((1, ROW_WIDTH))
    R[0, 3:9] = [0.0, 1.0, 0.0, 1.0, 1.0, 0.0]
    R[0, 9:17] = [0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0]
    R[0, 17:19] = 1.0
    T = np.array([[[2.0, 0.0, 0.0], [3.0, 0.0, 0.0], [2.0, 0.0, 1.0]]])     # v0, v0 + e1, v0 + e2
    box = np.array([[-1.0, 0.0, -1.0, 3.0, 1.0, 1.0]])
    two = (np.repeat(box[:, :3], 2, 0), np.repeat(box[:, 3:], 2, 0))
    return NativeScene(nodes_f=box.copy(), nodes_i=np.array([[0, 2]], np.int64), prim_box=two,
                       prims=np.arange(2, dtype=np.int64), kind=np.array([0, -1], np.int64), rows=R, triangles=T,
                       roots=np.zeros(1, np.int64), prim_first=np.array([0, 2], np.int64), top=_one_copy(box[0]),
                       depth=4)


def _one_copy(box) -> dict:
    """A top level of one copy (the identity) around ``box`` (6,): a single plant's."""
    box = np.asarray(box, np.float64).reshape(1, 6)
    return {"t_box": box.copy(), "t_nodes": np.array([[0, 1]], np.int64), "t_prims": np.zeros(1, np.int64),
            "copy_box": box.copy(), "copy_plant": np.zeros(1, np.int64), "inverse": np.eye(4)[None].copy()}


class NativeScene:
    """The arrays the compiled walk reads (module docstring), gathered once per target from
    its BVHs and rows: ``nodes_f`` (N, 6) node boxes, ``nodes_i`` (N, 2) first and count
    (the plants' trees in one array, :attr:`~plantgen.geometry.rays.bvh.SceneBVH.flat`),
    ``prim_box`` (lo, hi) (G, 3) each: the primitives' own boxes, ``prims`` the leaves'
    primitives,
    ``kind`` (G,) a row (>= 0) or a triangle (-1 - j), the ``rows`` (:data:`ROW_WIDTH`
    columns) table and the leaf ``triangles``' corners (T, 3, 3) (their table, v0, e1, e2
    and size, is made from them: :func:`_gather`), each plant's root node and first
    primitive, and the top level (``top``: a dict of the copies' arrays)."""

    def __init__(self, *, nodes_f, nodes_i, prim_box, prims, kind, rows, triangles, roots, prim_first, top, depth):
        c = np.ascontiguousarray
        prims = c(prims, np.int64)
        nodes = np.concatenate([np.asarray(nodes_f, np.float64), np.asarray(nodes_i, np.float64)], axis=1)
        # what a walk reads, in the order it reads it: a node's box, first and count in one
        # 64-byte row; a leaf's primitives' boxes, kinds and tables in its slots' order
        # (:func:`_gather`: the tables reordered as the slots list their primitives)
        kind, slot_kind, rows, triangles, slot_box = _gather(
            prims, c(kind, np.int64), c(prim_box[0], np.float64), c(prim_box[1], np.float64),
            c(rows, np.float64).reshape(-1, ROW_WIDTH), c(triangles, np.float64).reshape(-1, 3, 3))
        self.scene = (c(nodes), slot_box, prims, slot_kind, rows, triangles)
        self.kind = kind
        self.roots = c(roots, np.int64)
        self.prim_first = c(prim_first, np.int64)
        self.top = (c(top["t_box"], np.float64), c(top["t_nodes"], np.int64), c(top["t_prims"], np.int64),
                    c(top["copy_box"], np.float64), c(top["copy_plant"], np.int64), c(top["inverse"], np.float64),
                    self.roots)
        self.depth = int(depth) + 2
        self.widest = max(int(self.top[1][:, 1].max(initial=0)), 1)     # copies in the largest top leaf
        self.copy_plant = self.top[4]

    def trace(self, origins, dirs, *, any_hit: bool = False, t_min: float = 0.0, t_max=np.inf,
              origin=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """t (m,), copy (m,) and the primitive of its plant (m,) of each ray's closest hit
        in (t_min, t_max) (``any_hit``: a hit; inf, -1, -1: none), rows tested relative
        to ``origin`` (3,) of the plants' frame (None: 0)."""
        O = _rows3(origins)
        D = _rows3(dirs)
        m = len(O)
        t_hi = np.empty(m)
        t_hi[:] = t_max                                   # writable and contiguous: one compiled type
        out_t, out_c, out_p = np.full(m, np.inf), np.full(m, -1, np.int64), np.full(m, -1, np.int64)
        if m and len(self.scene[0]) and len(self.top[1]):
            with _LOCK:                       # numba's workqueue threads serve one caller at a time
                was = numba.set_parallel_chunksize(BLOCKS_A_CHUNK)      # blocks handed out as threads free up
                try:
                    _trace_all(self.scene, self.top, O, D, float(t_min), t_hi, bool(any_hit), self.depth,
                               self.widest, _origin(origin), out_t, out_c, out_p)
                finally:
                    numba.set_parallel_chunksize(was)
        hit = out_c >= 0
        out_p[hit] -= self.prim_first[self.copy_plant[out_c[hit]]]
        return out_t, out_c, out_p

    def distances(self, plant: int, prim, origins, dirs, *, t_min: float = 0.0, origin=None) -> np.ndarray:
        """t (k,) of rays (k,) at plant ``plant``'s primitives ``prim`` (k,), in its frame
        (inf: a miss, or a primitive -1)."""
        prim = np.asarray(prim, np.int64).reshape(-1)
        g = np.where(prim >= 0, prim + self.prim_first[plant], -1).astype(np.int64)
        O = _rows3(origins)
        D = _rows3(dirs)
        out = np.empty(len(g))
        if len(g):
            with _LOCK:
                _pairs_all(self.kind, self.scene[4], self.scene[5], g, O, D, float(t_min), _origin(origin), out)
        return out


@njit(cache=True, inline="always")
def _triangle_row(corners, j, out):
    """``out`` (10,): triangle ``j``'s v0, e1 = v1 - v0, e2 = v2 - v0 and the edges'
    lengths' product sqrt((e1·e1)(e2·e2)), the numbers of
    :attr:`~plantgen.geometry.rays.scan_targets.ScanTarget.triangle_edges`."""
    for a in range(3):
        out[a] = corners[j, 0, a]
        out[3 + a] = corners[j, 1, a] - corners[j, 0, a]
        out[6 + a] = corners[j, 2, a] - corners[j, 0, a]
    out[9] = np.sqrt((out[3] * out[3] + out[4] * out[4] + out[5] * out[5])
                     * (out[6] * out[6] + out[7] * out[7] + out[8] * out[8]))


@njit(cache=True)
def _gather(prims, kind, lo, hi, rows, corners):
    """The row table and the triangles' (:func:`_triangle_row`, from their ``corners``)
    in the order the leaves' slots ``prims`` list their primitives, ``kind`` (by global
    primitive, G) pointing into them, each slot's kind, and (G, 6) each slot's
    primitive's box (lo, hi): one pass over the slots."""
    n = len(prims)
    out_kind = np.empty(len(kind), np.int64)
    rows_out, tris_out = np.empty(rows.shape), np.empty((len(corners), 10))
    slot_kind, slot_box = np.empty(n, np.int64), np.empty((n, 6))
    n_rows = n_tris = 0
    for s in range(n):
        g = prims[s]
        k = kind[g]
        if k >= 0:
            rows_out[n_rows] = rows[k]
            out_kind[g] = n_rows
            n_rows += 1
        else:
            _triangle_row(corners, -1 - k, tris_out[n_tris])
            out_kind[g] = -1 - n_tris
            n_tris += 1
        slot_kind[s] = out_kind[g]
        for a in range(3):
            slot_box[s, a], slot_box[s, 3 + a] = lo[g, a], hi[g, a]
    return out_kind, slot_kind, rows_out[:n_rows], tris_out[:n_tris], slot_box


def _rows3(a) -> np.ndarray:
    """(m, 3) float64, C-contiguous and writable: the one array type the kernels are
    compiled for (a read-only view, a broadcast's, would compile them again)."""
    a = np.ascontiguousarray(a, dtype=np.float64).reshape(-1, 3)
    return a if a.flags.writeable else a.copy()


def _origin(origin) -> np.ndarray:
    return np.zeros(3) if origin is None else np.array(origin, dtype=np.float64).reshape(3)


def _row_table(targets) -> np.ndarray:
    """(rows, :data:`ROW_WIDTH`) the targets' rows as the float64 pair test uploads them
    (:class:`~plantgen.geometry.rays.reference.PairTester`, origin 0)."""
    parts = []
    for target in targets:
        if not target.rows:
            continue
        up = target.pair_tester.upload
        parts.append(np.column_stack([up.c1, up.a, up.h, up.r1, up.k, up.n_lo, up.n_hi, up.d_lo, up.d_hi,
                                      up.open_lo, up.open_hi]).astype(np.float64, copy=False))
    return np.concatenate(parts) if parts else np.zeros((0, ROW_WIDTH))


def _joined(targets, *names) -> tuple:
    """Each of the targets' arrays ``names`` joined plant by plant (one target's: as is)."""
    if len(targets) == 1:
        return tuple(getattr(targets[0], n) for n in names)
    return tuple(np.concatenate([getattr(t, n) for t in targets]) for n in names)


def _kinds(targets) -> np.ndarray:
    """(G,) each primitive's row (>= 0) or triangle (-1 - j) in the tables, plant by plant."""
    out, rows, tris = [], 0, 0
    for t in targets:
        n, k = t.rows, len(t.triangles)
        out += [np.arange(rows, rows + n), -1 - np.arange(tris, tris + k)]
        rows, tris = rows + n, tris + k
    return np.concatenate(out).astype(np.int64) if out else np.zeros(0, np.int64)


def native_scene(target) -> NativeScene:
    """The :class:`NativeScene` of a :class:`~plantgen.geometry.rays.scan_targets.ScanTarget` (one copy,
    the identity) or a :class:`~plantgen.geometry.rays.scan_targets.SceneTarget` (its two-level BVH),
    from the BVHs they hold (built once, shared with the GPU upload)."""
    boxes = lambda lo, hi: np.concatenate([lo, hi], axis=1)  # noqa: E731
    if hasattr(target, "targets"):
        targets, sb = tuple(target.targets), target.bvh
        flat, roots, prim_first = sb.flat
        roots = np.where([b.nodes > 0 for b in sb.blas], roots, -1) if len(roots) else roots
        top = {"t_box": boxes(sb.tlas.lo, sb.tlas.hi), "t_nodes": np.column_stack([sb.tlas.first, sb.tlas.count]),
               "t_prims": sb.tlas.prims, "copy_box": boxes(sb.copy_lo, sb.copy_hi), "copy_plant": sb.plant,
               "inverse": sb.inverse}
        depth = max([sb.tlas.depth()] + [b.depth() for b in sb.blas])
    else:
        targets, flat = (target,), target.bvh
        roots, prim_first = np.zeros(1, np.int64), np.array([0, len(target)], np.int64)
        top = _one_copy(np.concatenate([flat.lo[0], flat.hi[0]]) if flat.nodes else np.zeros(6))
        depth = flat.depth()
    return NativeScene(nodes_f=boxes(flat.lo, flat.hi), nodes_i=np.column_stack([flat.first, flat.count]),
                       prim_box=_joined(targets, "lo", "hi"),
                       prims=flat.prims, kind=_kinds(targets), rows=_row_table(targets),
                       triangles=_joined(targets, "triangles")[0], roots=roots, prim_first=prim_first, top=top,
                       depth=depth)


def pair_distances(target, prim, origins, dirs, *, t_min: float = 0.0) -> np.ndarray:
    """t (k,) of rays (k,) at a :class:`~plantgen.geometry.rays.scan_targets.ScanTarget`'s primitives
    ``prim`` (k,), float64 (the scan's re-solve), compiled."""
    return target.native.distances(0, prim, origins, dirs, t_min=t_min)
