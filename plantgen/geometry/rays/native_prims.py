"""The exact primitive tests of the compiled CPU tracer (:mod:`plantgen.geometry.rays.native_trace`),
float64, each operation for operation the numpy reference's:

- :func:`row_hit`: a frustum row by the reference's pair test
  (:class:`~plantgen.geometry.rays.reference.PairTester`, recentred: the slope-form cone, the
  quadratic in pbrt-v4's stable form with the discriminant as a difference of exact
  products, the oblique cutting planes with their joint slack, open ends capped);
- :func:`triangle_hit`: a leaf triangle by the scan's Möller-Trumbore test (both faces; a
  ray in its plane misses);
- :func:`prim_hit`: either, by the primitive's kind.
"""

from __future__ import annotations

import numpy as np

from ...tolerances import tol
from ..compiled import njit

__all__ = ["JOINT_SLACK", "RECENTER_PARALLEL", "SPLIT", "prim_hit", "row_hit", "triangle_hit"]

#: Half an ulp of 1.0 times the joint slack (:func:`plantgen.geometry.rays.reference._joint_slack`'s factor).
JOINT_SLACK = float(tol.joint_slack * (np.finfo(np.float64).eps / 2))
RECENTER_PARALLEL = float(tol.recenter_parallel)
SPLIT = 2.0 ** 27 + 1.0                       # Veltkamp's split of a float64


# ============================================================================ the primitive tests
@njit(cache=True, inline="always")
def _dot(ax, ay, az, bx, by, bz):
    return ax * bx + ay * by + az * bz


@njit(cache=True, inline="always")
def _two_product(a, b):
    """:func:`plantgen.geometry.rays.reference._two_product` for float64 scalars (its split
    2^27 + 1), operation for operation; the reference's works on arrays of either dtype,
    which numba does not compile."""
    a_big = SPLIT * a
    a_hi = a_big - (a_big - a)
    a_lo = a - a_hi
    b_big = SPLIT * b
    b_hi = b_big - (b_big - b)
    b_lo = b - b_hi
    p = a * b
    return p, ((a_hi * b_hi - p) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo


@njit(cache=True)
def _solve(A, B, C):
    """solve_quadratic of reference.py: (disc, t_q, t_c)."""
    bb, bb_e = _two_product(B, B)
    ac, ac_e = _two_product(A, C)
    disc = (bb - ac) + (bb_e - ac_e)
    root = np.sqrt(max(disc, 0.0))
    q = -(B + (root if B >= 0 else -root))
    t_q = q / A if A != 0 else np.inf
    t_c = C / q if q != 0 else t_q
    return disc, t_q, t_c


@njit(cache=True)
def _lateral(R, i, ex, ey, ez, dx, dy, dz, t_lo, s_lo, s_hi, best):
    """The nearest lateral root beyond ``t_lo`` between the planes (reference step 4)."""
    ax, ay, az, r1, k = R[i, 3], R[i, 4], R[i, 5], R[i, 7], R[i, 8]
    e_y = _dot(ex, ey, ez, ax, ay, az)
    d_y = _dot(dx, dy, dz, ax, ay, az)
    epx, epy, epz = ex - e_y * ax, ey - e_y * ay, ez - e_y * az
    dpx, dpy, dpz = dx - d_y * ax, dy - d_y * ay, dz - d_y * az
    r0 = r1 + 0.0 + k * e_y
    A = _dot(dpx, dpy, dpz, dpx, dpy, dpz) - k * k * d_y * d_y
    B = _dot(epx, epy, epz, dpx, dpy, dpz) - k * d_y * r0
    C = _dot(epx, epy, epz, epx, epy, epz) - r0 * r0
    disc, t1, t2 = _solve(A, B, C)
    if not disc >= 0:
        return best
    for j in range(2):
        t = t1 if j == 0 else t2
        if not np.isfinite(t):
            continue
        X, Y, Z = ex + t * dx, ey + t * dy, ez + t * dz
        y = _dot(X, Y, Z, ax, ay, az)
        if not (r1 + k * y >= 0):
            continue
        if not (_dot(R[i, 9], R[i, 10], R[i, 11], X, Y, Z) - R[i, 15] >= -s_lo):
            continue
        if not (_dot(R[i, 12], R[i, 13], R[i, 14], X, Y, Z) - R[i, 16] <= s_hi):
            continue
        if t > t_lo and t < best:
            best = t
    return best


@njit(cache=True)
def _cap(R, i, upper, ex, ey, ez, dx, dy, dz, t_lo, slack_o, best):
    """An open end's disc (reference step 5): the lower (``upper`` False) or upper one."""
    c, o = (12, 9) if upper else (9, 12)
    dc, do = (16, 15) if upper else (15, 16)
    ax, ay, az, r1, k = R[i, 3], R[i, 4], R[i, 5], R[i, 7], R[i, 8]
    den = _dot(R[i, c], R[i, c + 1], R[i, c + 2], dx, dy, dz)
    if den == 0:
        return best
    t = (R[i, dc] - _dot(R[i, c], R[i, c + 1], R[i, c + 2], ex, ey, ez)) / den
    if not np.isfinite(t):
        return best
    X, Y, Z = ex + t * dx, ey + t * dy, ez + t * dz
    y = _dot(X, Y, Z, ax, ay, az)
    rr = r1 + k * y
    px, py, pz = X - y * ax, Y - y * ay, Z - y * az
    if not (rr >= 0 and _dot(px, py, pz, px, py, pz) <= rr * rr):
        return best
    other = _dot(R[i, o], R[i, o + 1], R[i, o + 2], X, Y, Z) - R[i, do]
    if not ((other >= slack_o) if upper else (other <= slack_o)):
        return best
    if t > t_lo and t < best:
        return t
    return best


@njit(cache=True)
def row_hit(R, i, ox, oy, oz, dx, dy, dz, t_min, origin):
    """t of the ray (o, d) at row ``i`` of the row table ``R`` (inf: a miss), the rows
    relative to ``origin`` (3,): the reference's float64 pair test, recentred."""
    cx, cy, cz = R[i, 0] - origin[0], R[i, 1] - origin[1], R[i, 2] - origin[2]
    ax, ay, az, h = R[i, 3], R[i, 4], R[i, 5], R[i, 6]
    ex, ey, ez = (ox - origin[0]) - cx, (oy - origin[1]) - cy, (oz - origin[2]) - cz
    dd = _dot(dx, dy, dz, dx, dy, dz)
    size = np.sqrt(_dot(cx, cy, cz, cx, cy, cz)) + h
    slack = JOINT_SLACK * size
    s_lo = 0.0 if R[i, 17] != 0 else slack
    s_hi = 0.0 if R[i, 18] != 0 else slack
    b_ = _dot(dx, dy, dz, ax, ay, az)
    d_ = _dot(dx, dy, dz, ex, ey, ez)
    e_ = _dot(ax, ay, az, ex, ey, ez)
    denom = dd - b_ * b_
    if denom <= RECENTER_PARALLEL * dd:
        s_axis = h * 0.5
    else:
        s_axis = min(max(e_ + b_ * (b_ * e_ - d_) / denom, 0.0), h)
    t0 = (s_axis * b_ - d_) / dd
    ex, ey, ez = ex + t0 * dx, ey + t0 * dy, ez + t0 * dz
    t_lo = t_min - t0
    best = _lateral(R, i, ex, ey, ez, dx, dy, dz, t_lo, s_lo, s_hi, np.inf)
    if R[i, 17] != 0:
        best = _cap(R, i, False, ex, ey, ez, dx, dy, dz, t_lo, s_hi, best)
    if R[i, 18] != 0:
        best = _cap(R, i, True, ex, ey, ez, dx, dy, dz, t_lo, -s_lo, best)
    return best + t0


@njit(cache=True)
def triangle_hit(T, j, ox, oy, oz, dx, dy, dz):
    """t of the ray (o, d) at triangle ``j`` of the table ``T`` (v0, e1, e2, size): the
    scan's Möller-Trumbore test, both faces (inf: a miss)."""
    e1x, e1y, e1z, e2x, e2y, e2z = T[j, 3], T[j, 4], T[j, 5], T[j, 6], T[j, 7], T[j, 8]
    px, py, pz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x
    det = _dot(e1x, e1y, e1z, px, py, pz)
    scale = T[j, 9] * np.sqrt(_dot(dx, dy, dz, dx, dy, dz))
    if not (abs(det) > 1e-12 * scale):
        return np.inf
    inv = 1.0 / det
    sx, sy, sz = ox - T[j, 0], oy - T[j, 1], oz - T[j, 2]
    u = _dot(sx, sy, sz, px, py, pz) * inv
    qx, qy, qz = sy * e1z - sz * e1y, sz * e1x - sx * e1z, sx * e1y - sy * e1x
    v = _dot(dx, dy, dz, qx, qy, qz) * inv
    t = _dot(e2x, e2y, e2z, qx, qy, qz) * inv
    if u >= 0 and v >= 0 and u + v <= 1 and t > 0:
        return t
    return np.inf


@njit(cache=True)
def prim_hit(kind, R, T, g, ox, oy, oz, dx, dy, dz, t_min, origin):
    """t of primitive ``g`` (its ``kind``: a row >= 0, a triangle -1 - j), only beyond ``t_min``."""
    k = kind[g]
    if k >= 0:
        t = row_hit(R, k, ox, oy, oz, dx, dy, dz, t_min, origin)
    else:
        t = triangle_hit(T, -1 - k, ox, oy, oz, dx, dy, dz)
    return t if t > t_min else np.inf
