"""Leaf outlines triangulated: one at a time (:func:`triangulate`) or all at once
(:func:`triangulate_outlines`, what :class:`~plantgen.geometry.meshes.polygons.PolygonBuilder`
does with the turtle's outlines when it builds its polygons).

:func:`triangulate` turns one outline (any simple polygon, concave too, not necessarily
planar) into triangles by ear clipping in its best-fit plane. :func:`triangulate_outlines`
gives, outline for outline, the same vertices, triangles and normals, bit for bit, in numpy
over every outline of one point count at a time (a forest's 17,144 leaf outlines took 7 s
one by one under load): it repeats :func:`triangulate`'s arithmetic operation for
operation, the norms of 3-vectors as ``np.linalg.norm`` takes them (BLAS's dot product,
one per row through a stacked ``matmul``), the sums as numpy's along one row, the plane
coordinates as a ``(k, 3) @ (3,)`` product each (BLAS's matrix-vector product, through a
stacked ``matmul``); the ear clipping takes every outline's corners at once, round by
round, each round clipping (or dropping) the first corner :func:`triangulate` would. An
outline it does not follow (a point that is not finite; no Newell normal, where the
least-squares plane's stands in; more than :data:`BATCH_POINTS` points) goes through
:func:`triangulate` on its own. Nothing
here imports GL.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...tolerances import tol

__all__ = ["triangulate", "best_fit_normal", "triangulate_outlines", "Triangulated"]


def best_fit_normal(points: np.ndarray) -> np.ndarray:
    """Unit normal of the plane that best fits an outline (Newell's method: exact for a
    planar polygon, oriented by its winding; the least-squares plane's normal when the
    Newell vector vanishes, e.g. for a self-cancelling figure eight)."""
    p = np.asarray(points, dtype=np.float64)
    q = np.roll(p, -1, axis=0)
    n = np.array([np.sum((p[:, 1] - q[:, 1]) * (p[:, 2] + q[:, 2])),
                  np.sum((p[:, 2] - q[:, 2]) * (p[:, 0] + q[:, 0])),
                  np.sum((p[:, 0] - q[:, 0]) * (p[:, 1] + q[:, 1]))])
    size = np.linalg.norm(n)
    scale = max(float(np.ptp(p, axis=0).max()), tol.polygon_area)
    if size > tol.polygon_area * scale * scale:
        return n / size
    _, _, vt = np.linalg.svd(p - p.mean(axis=0))
    return vt[2]


def _plane_coordinates(points: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(k, 2): the points in an orthonormal basis (e1, e2) of the plane with e1 × e2 = normal."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(normal, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    rel = points - points.mean(axis=0)
    return np.stack([rel @ e1, rel @ e2], axis=1)


def _dedupe(points: np.ndarray) -> np.ndarray:
    """The outline without repeated consecutive points (the closing one included)."""
    scale = max(float(np.ptp(points, axis=0).max()) if len(points) else 0.0, tol.polygon_area)
    keep = []
    for i, p in enumerate(points):
        if not keep or np.linalg.norm(p - points[keep[-1]]) > tol.outline_duplicate * scale:
            keep.append(i)
    if len(keep) > 1 and np.linalg.norm(points[keep[0]] - points[keep[-1]]) <= tol.outline_duplicate * scale:
        keep.pop()
    return points[keep]


def _cross2(o, a, b) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _inside(p, a, b, c) -> bool:
    """p inside or on the counter-clockwise triangle abc."""
    return _cross2(a, b, p) >= 0 and _cross2(b, c, p) >= 0 and _cross2(c, a, p) >= 0


def _ear_clip(uv: np.ndarray) -> list[tuple[int, int, int]]:
    """Triangles (index triples, counter-clockwise) of a counter-clockwise simple polygon
    in the plane. An outline with no ear left (self-intersecting) is finished as a fan of
    its remaining vertices rather than dropped."""
    idx = list(range(len(uv)))
    tris: list[tuple[int, int, int]] = []
    scale = max(float(np.ptp(uv, axis=0).max()), tol.polygon_area)
    flat = tol.polygon_area * scale * scale
    while len(idx) > 3:
        n = len(idx)
        for k in range(n):
            i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % n]
            a, b, c = uv[i0], uv[i1], uv[i2]
            turn = _cross2(a, b, c)
            if turn < -flat:
                continue                      # reflex corner
            if turn <= flat:
                del idx[k]                    # collinear corner: no triangle, drop it
                break
            if any(_inside(uv[j], a, b, c) for j in idx if j not in (i0, i1, i2)):
                continue
            tris.append((i0, i1, i2))
            del idx[k]
            break
        else:                                 # no ear: not a simple polygon
            tris.extend((idx[0], idx[m], idx[m + 1]) for m in range(1, len(idx) - 1))
            return tris
    if len(idx) == 3 and abs(_cross2(uv[idx[0]], uv[idx[1]], uv[idx[2]])) > flat:
        tris.append(tuple(idx))
    return tris


def triangulate(points) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Triangulate one outline in its best-fit plane.

    Returns (vertices (k, 3), triangles (t, 3) indices into them, counter-clockwise about
    the normal, unit normal (3,)), or None for an outline with fewer than three distinct
    points or no area.
    """
    pts = _dedupe(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    if len(pts) < 3:
        return None
    normal = best_fit_normal(pts)
    uv = _plane_coordinates(pts, normal)
    x, y = uv[:, 0], uv[:, 1]
    signed = 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    if signed < 0:            # clockwise about the normal (least-squares case): flip the normal
        normal = -normal
        uv = _plane_coordinates(pts, normal)
    tris = _ear_clip(uv)
    if not tris:
        return None
    return pts, np.array(tris, dtype=np.int64).reshape(-1, 3), normal



# ---------------------------------------------------------------------------- all at once
@dataclass(frozen=True, eq=False)
class Triangulated:
    """Outlines triangulated at once, in the order given: ``vertex_count`` (p,) and
    ``triangle_count`` (p,) of each (both 0 for an outline :func:`triangulate` drops),
    ``vertices`` (sum of vertex_count, 3) outline after outline, ``triangles`` (sum of
    triangle_count, 3) indices into their own outline's vertices, ``normal`` (p, 3) (zeros
    for one dropped)."""

    vertex_count: np.ndarray
    triangle_count: np.ndarray
    vertices: np.ndarray
    triangles: np.ndarray
    normal: np.ndarray


def _norms(v: np.ndarray) -> np.ndarray:
    """(n,) the norm of each row of (n, 3) ``v``, as ``np.linalg.norm`` of the row gives
    it (the square root of BLAS's dot product, which a stacked ``matmul`` of 1x3 by 3x1
    calls row by row), bit for bit."""
    v = np.ascontiguousarray(v)
    return np.sqrt((v[:, None, :] @ v[:, :, None])[:, 0, 0])


def _extents(p: np.ndarray) -> np.ndarray:
    """(n,) each outline's (n, k, d) largest extent along an axis, floored at
    ``tol.polygon_area`` (the ``scale`` of :func:`_dedupe` and :func:`_ear_clip`)."""
    return np.maximum((p.max(axis=1) - p.min(axis=1)).max(axis=1), tol.polygon_area)


def _dedupe_many(p: np.ndarray) -> np.ndarray:
    """(n, k) bool: the points of each (n, k, 3) outline that :func:`_dedupe` keeps."""
    near = tol.outline_duplicate * _extents(p)
    keep = np.zeros(p.shape[:2], bool)
    keep[:, 0] = True
    last = p[:, 0]
    for i in range(1, p.shape[1]):
        keep[:, i] = _norms(p[:, i] - last) > near
        last = np.where(keep[:, i, None], p[:, i], last)
    closing = (keep.sum(axis=1) > 1) & (_norms(p[:, 0] - last) <= near)
    rows = np.flatnonzero(closing)
    keep[rows, p.shape[1] - 1 - np.argmax(keep[rows, ::-1], axis=1)] = False
    return keep


def _newell_many(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unit normals (n, 3), found (n,)) of (n, k, 3) outlines as :func:`best_fit_normal`
    gives them where it takes the Newell vector (found); the others it fits by SVD."""
    q = np.roll(p, -1, axis=1)
    n = np.stack([((p[..., 1] - q[..., 1]) * (p[..., 2] + q[..., 2])).sum(axis=1),
                  ((p[..., 2] - q[..., 2]) * (p[..., 0] + q[..., 0])).sum(axis=1),
                  ((p[..., 0] - q[..., 0]) * (p[..., 1] + q[..., 1])).sum(axis=1)], axis=1)
    size = _norms(n)
    scale = _extents(p)
    found = size > tol.polygon_area * scale * scale
    return n / np.where(found, size, 1.0)[:, None], found


def _plane_many(p: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(n, k, 2): :func:`_plane_coordinates` of each (n, k, 3) outline and its normal."""
    helper = np.where((np.abs(normal[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    e1 = np.cross(normal, helper)
    e1 /= _norms(e1)[:, None]
    e2 = np.cross(normal, e1)
    rel = p - p.mean(axis=1, keepdims=True)
    return np.stack([(rel @ e1[:, :, None])[..., 0], (rel @ e2[:, :, None])[..., 0]], axis=2)


def _cross2_many(o, a, b) -> np.ndarray:
    """:func:`_cross2` of the last axis, broadcast (the same operations in the same order)."""
    return (a[..., 0] - o[..., 0]) * (b[..., 1] - o[..., 1]) - (a[..., 1] - o[..., 1]) * (b[..., 0] - o[..., 0])


def _first_events(uv: np.ndarray, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For (n, m, 2) polygons (m > 3) in their current order: (has (n,), corner (n,), ear
    (n,)): whether :func:`_ear_clip`'s scan of the corners finds one to act on, the first
    such (a collinear corner to drop, or an ear: convex with no other point inside or on
    its triangle), and whether it is an ear."""
    a, c = np.roll(uv, 1, axis=1), np.roll(uv, -1, axis=1)
    turn = _cross2_many(a, uv, c)
    reflex = turn < -flat[:, None]
    collinear = ~reflex & (turn <= flat[:, None])
    convex = ~reflex & ~(turn <= flat[:, None])
    A, B, C, Q = a[:, :, None], uv[:, :, None], c[:, :, None], uv[:, None, :]
    inside = (_cross2_many(A, B, Q) >= 0) & (_cross2_many(B, C, Q) >= 0) & (_cross2_many(C, A, Q) >= 0)
    m = uv.shape[1]
    apart = (np.arange(m)[None, :] - np.arange(m)[:, None]) % m
    others = (apart >= 2) & (apart <= m - 2)           # not the corner nor its two neighbours
    ear = convex & ~(inside & others).any(axis=2)
    event = collinear | ear
    corner = np.argmax(event, axis=1)
    rows = np.arange(len(uv))
    return event.any(axis=1), corner, ear[rows, corner]


def _ear_clip_many(uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(triangles (n, m - 2, 3), count (n,)): :func:`_ear_clip` of each (n, m, 2) polygon,
    its triangles in the order that gives them."""
    n, m = uv.shape[:2]
    scale = _extents(uv)
    flat = tol.polygon_area * scale * scale
    idx = np.broadcast_to(np.arange(m), (n, m)).copy()
    tris = np.zeros((n, max(m - 2, 1), 3), np.int64)
    count = np.zeros(n, np.int64)
    live = np.arange(n)                     # polygons still clipping, each with k corners left
    for k in range(m, 3, -1):
        if not len(live):
            break
        cur = idx[live, :k]
        has, corner, ear = _first_events(uv[live[:, None], cur], flat[live])
        fan, fan_idx = live[~has], cur[~has]       # no ear: finished as a fan of what is left
        for j in range(1, k - 1):
            tris[fan, count[fan]] = np.stack([fan_idx[:, 0], fan_idx[:, j], fan_idx[:, j + 1]], axis=1)
            count[fan] += 1
        live, cur, corner, ear = live[has], cur[has], corner[has], ear[has]
        at = np.arange(len(live))
        clip = live[ear]
        tris[clip, count[clip]] = np.stack([cur[at, corner - 1], cur[at, corner], cur[at, (corner + 1) % k]],
                                           axis=1)[ear]
        count[clip] += 1
        idx[live, :k - 1] = cur[np.arange(k)[None, :] != corner[:, None]].reshape(-1, k - 1)
    last = idx[live, :3]
    ok = np.abs(_cross2_many(uv[live, last[:, 0]], uv[live, last[:, 1]], uv[live, last[:, 2]])) > flat[live]
    tris[live[ok], count[live[ok]]] = last[ok]
    count[live[ok]] += 1
    return tris, count


def _clip_group(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(found (n,), then for those found: normals (f, 3), triangles (f, m - 2, 3), counts
    (f,)) of (n, m, 3) deduplicated outlines, as :func:`triangulate` gives them where it
    finds a Newell normal (``found``); the others are left to it."""
    normal, found = _newell_many(p)
    p, normal = p[found], normal[found]
    uv = _plane_many(p, normal)
    x, y = uv[..., 0], uv[..., 1]
    signed = 0.5 * (x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y).sum(axis=1)
    flip = signed < 0                    # clockwise about the normal: flip it
    if flip.any():
        normal[flip] = -normal[flip]
        uv[flip] = _plane_many(p[flip], normal[flip])
    tris, count = _ear_clip_many(uv)
    return found, normal, tris, count


#: Outlines of more points than this go through :func:`triangulate` one by one: each round
#: of :func:`_ear_clip_many` tests every corner against every point (m² tests a round, m
#: rounds), where :func:`_ear_clip` stops at the first ear (leaves have a handful of points).
BATCH_POINTS = 32

#: Corner-point pairs (outlines times m²) that one call of :func:`_clip_group` takes at
#: most: its temporaries stay a few tens of MB however many outlines come.
BATCH_PAIRS = 1 << 22


def _grouped(outlines: list[np.ndarray]) -> tuple[dict[int, list], list[int]]:
    """The outlines of three to :data:`BATCH_POINTS` points, deduplicated and grouped by
    the points kept: ({m: [(outline indices, (g, m, 3) points)]}, indices of those left to
    :func:`triangulate`: a point not finite, or more points)."""
    lengths = np.array([len(o) for o in outlines], np.int64)
    groups: dict[int, list] = {}
    alone: list[int] = np.flatnonzero(lengths > BATCH_POINTS).tolist()
    for k in np.unique(lengths[(lengths >= 3) & (lengths <= BATCH_POINTS)]).tolist():
        ids = np.flatnonzero(lengths == k)
        p = np.stack([outlines[i] for i in ids])
        finite = np.isfinite(p).all(axis=(1, 2))
        alone += ids[~finite].tolist()
        ids, p = ids[finite], p[finite]
        keep = _dedupe_many(p)
        kept = keep.sum(axis=1)
        for m in np.unique(kept[kept >= 3]).tolist():
            rows = kept == m
            groups.setdefault(m, []).append((ids[rows], p[rows][keep[rows]].reshape(-1, m, 3)))
    return groups, alone


def triangulate_outlines(outlines) -> Triangulated:
    """Triangulate many outlines at once: the :class:`Triangulated` whose outline ``i``
    is, bit for bit, :func:`triangulate` of ``outlines[i]`` (its vertices, triangles and
    normal; none where that gives None), in numpy over the outlines of one point count
    at a time (the module docstring)."""
    outlines = [np.asarray(o, dtype=np.float64).reshape(-1, 3) for o in outlines]
    count = len(outlines)
    vcount, tcount, normal = np.zeros(count, np.int64), np.zeros(count, np.int64), np.zeros((count, 3))
    done = []                          # (outline indices, (g, m, 3) points, (g, t, 3) triangles)
    groups, alone = _grouped(outlines)
    for m, parts in groups.items():
        every, points = np.concatenate([i for i, _ in parts]), np.concatenate([q for _, q in parts])
        rows = max(BATCH_PAIRS // (m * m), 1)
        for start in range(0, len(every), rows):
            ids, p = every[start:start + rows], points[start:start + rows]
            found, normals, tris, counts = _clip_group(p)
            alone += ids[~found].tolist()
            ids, p = ids[found], p[found]
            normal[ids], tcount[ids] = normals, counts
            vcount[ids] = np.where(counts > 0, m, 0)
            done.append((ids, p, tris))
    single = {}
    for i in alone:
        got = triangulate(outlines[i])
        if got is not None:
            single[i] = got
            vcount[i], tcount[i], normal[i] = len(got[0]), len(got[1]), got[2]
    vfirst, tfirst = np.cumsum(vcount) - vcount, np.cumsum(tcount) - tcount
    vertices, triangles = np.empty((int(vcount.sum()), 3)), np.empty((int(tcount.sum()), 3), np.int64)
    for ids, p, tris in done:
        used = tcount[ids] > 0
        vertices[vfirst[ids[used], None] + np.arange(p.shape[1])] = p[used]
        mask = np.arange(tris.shape[1]) < tcount[ids, None]
        triangles[(tfirst[ids, None] + np.arange(tris.shape[1]))[mask]] = tris[mask]
    for i, (pts, tris, _) in single.items():
        vertices[vfirst[i]:vfirst[i] + len(pts)] = pts
        triangles[tfirst[i]:tfirst[i] + len(tris)] = tris
    return Triangulated(vcount, tcount, vertices, triangles, normal)
