"""The reference ray caster: exact ray/frustum hits in numpy, the ground truth of plantgen.

Layout (as pbrt splits shapes): :func:`intersect_frusta` only finds hits (t, row, point);
:func:`shade_hits` turns hits into (u, v) and normals with the helpers of
:mod:`plantgen.geometry.skeletons.frusta`. :func:`render_reference` does both for a Camera, binning
the bounding pyramids in screen tiles so that only nearby rows are tested per pixel.

One row, one ray (``_pair_hits``; the GLSL caster mirrors it line by line):

1. Upload: C1 - origin and the plane offsets relative to C1 are formed in float64, then
   everything is cast to ``dtype`` (float32 emulates the GPU).
2. E = O - C1. With ``recenter``, E moves to the ray point nearest the axis segment:
   with b = D·a, d = D·E, e = a·E, the axis point s = clamp(e + b·(b·e - d)/(D·D - b²),
   0, h) (s = h/2 when D·D - b² <= ``tol.recenter_parallel``·D·D, a ray along the axis),
   t0 = (s·b - d)/D·D, E += t0·D. The quadratic then sees numbers of the size of the
   ray's distance from the axis (about r near a hit), not of the eye distance.
3. Cone r(y) = r1 + k·y, y = X·a (:func:`cone_quadratic`): with e_y = E·a, d_y = D·a,
   E⊥ = E - e_y·a, D⊥ = D - d_y·a, R0 = r1 + k·e_y: A = D⊥·D⊥ - k²·d_y²,
   B = E⊥·D⊥ - k·d_y·R0, C = E⊥·E⊥ - R0². A t² + 2B t + C = 0 is solved as pbrt-v4
   does (:func:`solve_quadratic`): B² - AC as a difference of exact products,
   q = -(B + copysign(√(B² - AC), B)), t = q/A, t = C/q (finite as A → 0: a ray
   parallel to a generator). These functions and ``shaders/cone.glsl`` are twins.
4. A root counts if r(y) >= 0 (not the mirror nappe), n_lo·X - d_lo >= 0 and
   n_hi·X - d_hi <= 0 (between the planes, each up to :func:`_joint_slack` beyond a
   plane shared with a continuing neighbour, the rounding of this test) and t > t_min.
5. Open ends (rows no continuing row shares the plane with) are capped: the plane's hit
   counts if |X⊥| <= r(y) and it lies on the inner side of the other plane.
6. The nearest counting t (+ t0) is the hit.

Relief (§3, float64 only): the outer cone r + shell bounds a height field
r(y) + shell·σ(y)·h(u, v), σ(y) = r(y)/max(r1, r2) (``relief_scale``: the relief follows
the radius, as deep on both sides of a joint), (u, v) of the concentric cone through the
point (so the shell shares the surface's (u, v)); w of (11)–(12) is (ρ - r(y))/(shell·σ(y)). The ray interval
inside the row's planes and bounding sphere is sampled densely (``relief_samples``)
and the first inside sample is refined by bisection to below ``tol.relief_bisection``
(relative to the row's size).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...tolerances import tol
from ..skeletons import relief as relief_module
from ..skeletons.frusta import (
    Frusta,
    bounding_pyramids,
    facing_normals,
    relief_scale,
    shade_rows_uv_normals,
    surface_uv,
    true_normals,
)
from ..vec import dot
from .camera import Camera

__all__ = ["Hits", "ReferenceImage", "PairTester", "intersect_frusta", "shade_hits", "render_reference",
           "inside_frusta", "march_rays", "cone_quadratic", "solve_quadratic",
           "difference_of_products", "row_boxes"]


@dataclass
class Hits:
    """Hits of (...) rays. ``t``: distance along each ray in units of |direction| (inf for
    a miss); ``row``: frusta row (-1); ``segment``: skeleton segment (-1); ``point``:
    (..., 3) world point (0 for a miss); ``cap``: the hit is on a cap disc."""

    hit: np.ndarray
    t: np.ndarray
    row: np.ndarray
    segment: np.ndarray
    point: np.ndarray
    cap: np.ndarray


@dataclass
class ReferenceImage:
    """Per-pixel reference render, arrays of shape (height, width[, 3]). ``normal`` is the
    shading normal: (8) facing the eye (:func:`shade_hits` with ``to_eye``)."""

    hit: np.ndarray
    t: np.ndarray
    row: np.ndarray
    segment: np.ndarray
    u: np.ndarray
    v: np.ndarray
    normal: np.ndarray
    camera: Camera


def _resolve_relief(frusta: Frusta, relief):
    """None, or a function height(rows (m,), u (m,), v (m,)) -> (m,) in [0, 1]."""
    if relief is None or relief is False:
        return None
    if callable(relief):
        return relief
    if relief is True:
        maps = {i: relief_module.height_map(name) for i, name in enumerate(frusta.material_names)}
    else:
        maps = {i: relief_module.height_map(name) if name not in relief else np.asarray(relief[name])
                for i, name in enumerate(frusta.material_names)}
    mat = frusta.material

    def height(rows, u, v):
        out = np.zeros(len(rows))
        m = mat[rows]
        for i in np.unique(m):
            sel = m == i
            out[sel] = relief_module.sample_height(maps[int(i)], u[sel], v[sel])
        return out

    return height


class _Upload:
    """Row parameters in ``dtype``, positions relative to ``origin`` (formed in float64)."""

    def __init__(self, frusta: Frusta, dtype, origin):
        self.dtype = np.dtype(dtype)
        o = np.zeros(3) if origin is None else np.asarray(origin, dtype=np.float64)
        cast = lambda x: np.asarray(x, dtype=np.float64).astype(self.dtype)  # noqa: E731
        self.c1 = cast(frusta.base - o)
        self.a = cast(frusta.axis)
        self.h = cast(frusta.length)
        self.r1 = cast(frusta.r1)
        self.k = cast(frusta.slope)
        self.n_lo = cast(frusta.plane_lo[:, :3])
        self.n_hi = cast(frusta.plane_hi[:, :3])
        # plane offsets relative to C1 formed as the GPU records form them (pack_records)
        self.d_lo = cast(frusta.plane_lo[:, 3] - np.einsum("ij,ij->i", frusta.plane_lo[:, :3], frusta.base))
        self.d_hi = cast(frusta.plane_hi[:, 3] - np.einsum("ij,ij->i", frusta.plane_hi[:, :3], frusta.base))
        self.open_lo = frusta.open_lo
        self.open_hi = frusta.open_hi
        self.origin = o


# ------------------------------------------------------------------------------ the cone quadratic
# Twins of two_product, difference_of_products, solve_quadratic and cone_quadratic in
# shaders/cone.glsl, line for line.
def _two_product(a, b):
    """p = a·b rounded and e with p + e = a·b exactly (Dekker's product with Veltkamp's split
    into half-width halves; float32 or float64 arrays, the dtype's own split)."""
    dtype = np.result_type(a, b)
    split = dtype.type(2.0 ** ((np.finfo(dtype).nmant + 2) // 2) + 1)   # 2^12 + 1, 2^27 + 1
    a_big = split * a
    a_hi = a_big - (a_big - a)
    a_lo = a - a_hi
    b_big = split * b
    b_hi = b_big - (b_big - b)
    b_lo = b - b_hi
    product = a * b
    return product, ((a_hi * b_hi - product) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo


def difference_of_products(a, b, c, d):
    """(...) a·b - c·d within about an ulp even where the two products nearly cancel (as
    pbrt-v4's ``DifferenceOfProducts``, with exact products instead of fma): the products'
    difference is exact there, and their rounding errors are added back."""
    ab, ab_error = _two_product(a, b)
    cd, cd_error = _two_product(c, d)
    return (ab - cd) + (ab_error - cd_error)


def solve_quadratic(a, b, c):
    """The roots of a·t² + 2b·t + c = 0 (half-b form), as pbrt-v4's ``Quadratic``.

    The discriminant b² - a·c is a difference of products; q = -(b + copysign(√disc, b));
    t_q = q/a and t_c = c/q (neither cancels; where a = 0, a line, c/q = -c/(2b) is its one
    root). All arrays (...) of one float dtype.

    Returns
    -------
    disc : (...) the discriminant (no real root where negative)
    t_q : (...) q/a, inf where a = 0
    t_c : (...) c/q, t_q where q = 0 (b = 0 and a·c = 0)
    """
    disc = difference_of_products(b, b, a, c)
    root = np.sqrt(np.maximum(disc, disc.dtype.type(0)))
    q = -(b + np.where(b >= 0, root, -root))     # copysign(root, b)
    t_q = np.where(a != 0, q / np.where(a != 0, a, 1), np.inf)
    t_c = np.where(q != 0, c / np.where(q != 0, q, 1), t_q)
    return disc, t_q, t_c


def cone_quadratic(e, d, axis, r1, slope, dr=0.0):
    """The cone r(y) = r1 + dr + k·y along rays e + t·d (e relative to the base C1):
    g(t) = a·t² + 2b·t + c <= 0 inside the double cone.

    With e_y = e·axis, d_y = d·axis, the parts E, D perpendicular to the axis and the radius
    at e's height r0 = r1 + dr + k·e_y: a = D·D - (k·d_y)², b = E·D - k·d_y·r0,
    c = E·E - r0².

    Parameters
    ----------
    e, d : (m, 3) ray origins (relative to C1) and directions
    axis : (m, 3) unit cone axes
    r1, slope : (m,) radius at C1 and slope k
    dr : scalar or (m,) growth of the radius (a concentric cone)

    Returns
    -------
    a, b, c, e_y, d_y : (m,) each, ``e``'s dtype
    """
    e_y, d_y = dot(e, axis), dot(d, axis)
    e_perp = e - e_y[:, None] * axis
    d_perp = d - d_y[:, None] * axis
    r0 = r1 + dr + slope * e_y
    a = dot(d_perp, d_perp) - slope * slope * d_y * d_y
    b = dot(e_perp, d_perp) - slope * d_y * r0
    c = dot(e_perp, e_perp) - r0 * r0
    return a, b, c, e_y, d_y


def _joint_slack(up: _Upload, rows):
    """(m,) each, in ``up.dtype``: how far beyond its lower and upper plane a lateral hit of
    rows (m,) still counts (0 at open ends): ``tol.joint_slack`` units of the dtype's
    rounding times |base| + h, as ``joint_slack`` in shaders/cone.glsl."""
    unit = np.finfo(up.dtype).eps / 2
    size = np.sqrt(dot(up.c1[rows], up.c1[rows])) + up.h[rows]
    slack = (tol.joint_slack * unit * size).astype(up.dtype)
    zero = np.zeros_like(slack)
    return np.where(up.open_lo[rows], zero, slack), np.where(up.open_hi[rows], zero, slack)


def _pair_hits(up: _Upload, rows, O, D, recenter: bool, t_min: float):
    """Nearest hit of ray i (O[i], D[i] in up.dtype, origin-relative) with row rows[i].

    Returns t (m,) float64 (inf: none) and kind (m,) int8 (0 lateral, 1 lower cap, 2 upper cap).
    """
    dt = up.dtype
    c1, a, h, r1, k = up.c1[rows], up.a[rows], up.h[rows], up.r1[rows], up.k[rows]
    n_lo, n_hi, d_lo, d_hi = up.n_lo[rows], up.n_hi[rows], up.d_lo[rows], up.d_hi[rows]
    E = O - c1
    dd = dot(D, D)
    slack_lo, slack_hi = _joint_slack(up, rows)
    if recenter:
        # the ray point nearest the axis segment {s·a, 0 <= s <= h}
        b_ = dot(D, a)
        d_ = dot(D, E)
        e_ = dot(a, E)
        denom = dd - b_ * b_
        par = denom <= dt.type(tol.recenter_parallel) * dd
        with np.errstate(invalid="ignore", divide="ignore"):
            s_axis = e_ + b_ * (b_ * e_ - d_) / np.where(par, dd, denom)
        s_axis = np.where(par, h * dt.type(0.5), np.clip(s_axis, dt.type(0), h))
        t0 = (s_axis * b_ - d_) / dd
        E = E + t0[:, None] * D
    else:
        t0 = np.zeros(len(rows), dtype=dt)
    A, B, C, _, _ = cone_quadratic(E, D, a, r1, k)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        disc, t1, t2 = solve_quadratic(A, B, C)
        has_root = disc >= 0
        best = np.full(len(rows), np.inf)
        kind = np.zeros(len(rows), dtype=np.int8)
        tmin_local = (t_min - t0.astype(np.float64))
        for t in (t1, t2):
            X = E + t[:, None] * D
            y = dot(X, a)
            ok = has_root & np.isfinite(t) & (r1 + k * y >= 0)
            ok &= (dot(n_lo, X) - d_lo >= -slack_lo) & (dot(n_hi, X) - d_hi <= slack_hi)
            tt = t.astype(np.float64)
            ok &= tt > tmin_local
            better = ok & (tt < best)
            best = np.where(better, tt, best)
        for cap_kind, n_c, d_c, n_o, d_o, sign_o, open_, slack_o in (
                (1, n_lo, d_lo, n_hi, d_hi, -1, up.open_lo[rows], slack_hi),
                (2, n_hi, d_hi, n_lo, d_lo, 1, up.open_hi[rows], -slack_lo)):
            if not open_.any():
                continue
            den = dot(n_c, D)
            t = (d_c - dot(n_c, E)) / np.where(den != 0, den, 1)
            X = E + t[:, None] * D
            y = dot(X, a)
            rr = r1 + k * y
            perp = X - y[:, None] * a
            ok = open_ & (den != 0) & np.isfinite(t) & (rr >= 0) & (dot(perp, perp) <= rr * rr)
            other = dot(n_o, X) - d_o
            ok &= (other <= slack_o) if sign_o < 0 else (other >= slack_o)
            tt = t.astype(np.float64)
            ok &= tt > tmin_local
            better = ok & (tt < best)
            best = np.where(better, tt, best)
            kind = np.where(better, np.int8(cap_kind), kind)
        kind = np.where(np.isfinite(best), kind, np.int8(0))
    return best + t0.astype(np.float64), kind


# ------------------------------------------------------------------------------ relief
def _inside_relief(frusta, rows, points, height):
    """(m,) bool: point inside row's relief solid (between planes, ρ <= r(y) + shell·σ(y)·h,
    σ = :func:`~plantgen.geometry.skeletons.frusta.relief_scale`)."""
    rel = points - frusta.base[rows]
    a = frusta.axis[rows]
    y = dot(rel, a)
    rho = np.linalg.norm(rel - y[:, None] * a, axis=1)
    r_in = frusta.r1[rows] + frusta.slope[rows] * y
    lo, hi = frusta.plane_lo[rows], frusta.plane_hi[rows]
    between = (dot(lo[:, :3], points) - lo[:, 3] >= 0) & (dot(hi[:, :3], points) - hi[:, 3] <= 0)
    shell = frusta.shell[rows] * relief_scale(frusta, rows, y)
    u, v = surface_uv(frusta, rows, points)
    w = height(rows, u, v) if height is not None else np.zeros(len(rows))
    top = r_in + shell * w
    return between & (top >= 0) & (rho <= top)


#: Relief samples marched at once by the reference (bounds its memory to about a gigabyte).
RELIEF_CHUNK_POINTS = 1 << 20


def _relief_pair_hits(frusta, rows, O, D, height, t_min, samples, spheres):
    """Nearest crossing into the relief solid of row rows[i] along ray i (float64)."""
    m = len(rows)
    lo, hi = frusta.plane_lo[rows], frusta.plane_hi[rows]
    ta = np.full(m, -np.inf)
    tb = np.full(m, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for plane, sign in ((lo, 1.0), (hi, -1.0)):
            # sign·(n·(O + tD) - d) >= 0
            s0 = sign * (dot(plane[:, :3], O) - plane[:, 3])
            s1 = sign * dot(plane[:, :3], D)
            tc = -s0 / s1
            ta = np.where(s1 > 0, np.maximum(ta, tc), ta)
            tb = np.where(s1 < 0, np.minimum(tb, tc), tb)
            dead = (s1 == 0) & (s0 < 0)
            ta = np.where(dead, np.inf, ta)
        centre, radius = spheres[0][rows], spheres[1][rows]
        oc = O - centre
        disc, t_q, t_c = solve_quadratic(dot(D, D), dot(oc, D), dot(oc, oc) - radius * radius)
        ta = np.maximum(ta, np.where(disc >= 0, np.minimum(t_q, t_c), np.inf))
        tb = np.minimum(tb, np.where(disc >= 0, np.maximum(t_q, t_c), -np.inf))
    ta = np.maximum(ta, t_min)
    live = ta < tb
    t_hit = np.full(m, np.inf)
    if not live.any():
        return t_hit
    # Dense samples, a chunk of pairs at a time: at most RELIEF_CHUNK_POINTS points in
    # flight, so memory stays bounded however many pairs and samples are asked for.
    idx = np.flatnonzero(live)
    frac = np.linspace(0.0, 1.0, samples)
    chunk = max(1, RELIEF_CHUNK_POINTS // samples)
    found, entry, before = [], [], []
    for start in range(0, len(idx), chunk):
        part = idx[start:start + chunk]
        ts = ta[part][:, None] + (tb[part] - ta[part])[:, None] * frac[None, :]
        rr = np.repeat(rows[part], samples)
        pts = (O[part][:, None, :] + ts[..., None] * D[part][:, None, :]).reshape(-1, 3)
        inside = _inside_relief(frusta, rr, pts, height).reshape(len(part), samples)
        sel = np.flatnonzero(inside.any(axis=1))
        if sel.size == 0:
            continue
        j = np.argmax(inside[sel], axis=1)
        found.append(part[sel])
        entry.append(ts[sel, j])
        before.append(np.where(j > 0, ts[sel, np.maximum(j - 1, 0)], np.nan))   # nan: first sample
    if not found:
        return t_hit
    hit_idx = np.concatenate(found)
    t_in = np.concatenate(entry)
    t_out = np.concatenate(before)
    need = ~np.isnan(t_out)
    t_out = np.where(need, t_out, t_in)
    O_s, D_s, rows_s = O[hit_idx], D[hit_idx], rows[hit_idx]
    scale = np.maximum(frusta.length[rows_s], np.maximum(frusta.r1[rows_s], frusta.r2[rows_s]) + frusta.shell[rows_s])
    for _ in range(80):
        if not need.any():
            break
        mid = 0.5 * (t_in + t_out)
        ins = _inside_relief(frusta, rows_s, O_s + mid[:, None] * D_s, height)
        t_in = np.where(need & ins, mid, t_in)
        t_out = np.where(need & ~ins, mid, t_out)
        need &= (t_in - t_out) > tol.relief_bisection * scale
    t_hit[hit_idx] = t_in
    return t_hit


# ------------------------------------------------------------------------------ pairs
class PairTester:
    """Steps 1-6 of the module docstring for (ray, row) pairs a caller makes itself (a
    laser scanner's angular bins, :mod:`plantgen.geometry.rays.scan`): the rows are uploaded
    once, in ``dtype`` relative to ``origin``; each call tests pairs.

    ``tester(rows (m,), origins (m, 3), dirs (m, 3))`` -> (t (m,) float64, inf for a miss,
    in units of |dir|; cap (m,) bool: the hit is on an end disc). Analytic cones only (no
    relief); only hits with t > ``t_min`` count."""

    def __init__(self, frusta: Frusta, *, dtype=np.float64, origin=None, recenter: bool = True,
                 t_min: float = 0.0):
        self.frusta = frusta
        self.upload = _Upload(frusta, dtype, origin)
        self.recenter = recenter
        self.t_min = float(t_min)

    def __call__(self, rows, origins, dirs) -> tuple[np.ndarray, np.ndarray]:
        rows = np.asarray(rows, dtype=np.int64)
        if rows.size == 0:
            return np.zeros(0), np.zeros(0, dtype=bool)
        up = self.upload
        O = (np.asarray(origins, dtype=np.float64) - up.origin).astype(up.dtype)
        D = np.asarray(dirs, dtype=np.float64).astype(up.dtype)
        t, kind = _pair_hits(up, rows, O, D, self.recenter, self.t_min)
        return t, kind > 0


def row_boxes(frusta: Frusta, shell: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) low and high corners of an axis-aligned box around each row: its bounding
    pyramid's (relief shell included where ``shell``), padded as the reference pads them
    so that rounding loses no ray."""
    lo, hi, _ = _boxes(frusta, shell)
    return lo, hi


# ------------------------------------------------------------------------------ hits
def _reduce_nearest(n_rays, ray_idx, rows, t, kind, best_t, best_row, best_kind):
    """Keep, per ray, the smallest t seen so far (in place)."""
    fin = np.isfinite(t)
    if not fin.any():
        return
    ray_idx, rows, t, kind = ray_idx[fin], rows[fin], t[fin], kind[fin]
    order = np.lexsort((t, ray_idx))
    ray_s = ray_idx[order]
    first = np.ones(len(order), dtype=bool)
    first[1:] = ray_s[1:] != ray_s[:-1]
    pick = order[first]
    r = ray_idx[pick]
    better = t[pick] < best_t[r]
    r = r[better]
    best_t[r] = t[pick][better]
    best_row[r] = rows[pick][better]
    best_kind[r] = kind[pick][better]


def _bounding_spheres(corners):
    """Centres (n, 3) and radii (n,) of spheres around bounding pyramids' corners (n, 8, 3)."""
    centre = corners.mean(axis=1)
    return centre, np.linalg.norm(corners - centre[:, None], axis=2).max(axis=1)


def _boxes(frusta, with_shell):
    corners = bounding_pyramids(frusta, shell=with_shell)
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    pad = tol.box_pad * np.maximum(np.abs(lo).max(axis=1), np.abs(hi).max(axis=1))[:, None] \
        + tol.box_pad_floor
    return lo - pad, hi + pad, corners


def _test_pairs(frusta, up, ray_idx, rows, O, D, recenter, t_min, height, spheres, samples):
    Ou = (O[ray_idx] - up.origin).astype(up.dtype)
    Du = D[ray_idx].astype(up.dtype)
    t, kind = _pair_hits(up, rows, Ou, Du, recenter, t_min)
    if height is not None:
        rel = frusta.shell[rows] > 0
        if rel.any():
            tr = _relief_pair_hits(frusta, rows[rel], O[ray_idx[rel]], D[ray_idx[rel]], height,
                                   t_min, samples, spheres)
            t = t.copy()
            t[rel] = np.minimum(t[rel], tr)
            kind = kind.copy()
            kind[rel] = np.where(tr <= t[rel], 0, kind[rel])
    return t, kind


def intersect_frusta(frusta: Frusta, origins, dirs, *, relief=None, dtype=np.float64,
                     recenter: bool = True, origin=None, t_min: float = 0.0,
                     relief_samples: int = 512, chunk_pairs: int = 1 << 21) -> Hits:
    """Nearest hit of each ray with the frusta (skin, caps on open ends, relief shells).

    Parameters
    ----------
    frusta : Frusta, n rows
    origins, dirs : (..., 3) float64 ray origins (world units) and directions (any length;
        t is in units of |dir|)
    relief : None/False (analytic cones), True (the material height maps of
        :mod:`plantgen.geometry.skeletons.relief`), a dict material name -> (H, W) uint8 map, or a
        function height(rows, u, v) -> [0, 1]; applies to rows with ``shell > 0``
    dtype : float64 (reference) or float32 (emulates the GPU; relief stays float64)
    recenter : move the ray origin next to the segment before solving
    origin : (3,) float64 point subtracted before the cast to ``dtype`` (the GPU renderer
        uploads positions relative to the eye); None: world coordinates are cast as they are
    t_min : only hits with t > t_min count

    Candidates come from a slab test of each ray against the rows' bounding-pyramid boxes.
    """
    O = np.asarray(origins, dtype=np.float64)
    D = np.asarray(dirs, dtype=np.float64)
    O, D = np.broadcast_arrays(O, D)
    shape = O.shape[:-1]
    O = O.reshape(-1, 3)
    D = D.reshape(-1, 3)
    n_rays = len(O)
    height = _resolve_relief(frusta, relief)
    up = _Upload(frusta, dtype, origin)
    box_lo, box_hi, corners = _boxes(frusta, height is not None)
    spheres = _bounding_spheres(corners)
    best_t = np.full(n_rays, np.inf)
    best_row = np.full(n_rays, -1, dtype=np.int64)
    best_kind = np.zeros(n_rays, dtype=np.int8)
    n = len(frusta)
    if n and n_rays:
        step = max(1, chunk_pairs // max(n, 1))
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / D
        for s in range(0, n_rays, step):
            o, iv = O[s:s + step], inv[s:s + step]
            with np.errstate(invalid="ignore"):
                t1 = (box_lo[None] - o[:, None]) * iv[:, None]
                t2 = (box_hi[None] - o[:, None]) * iv[:, None]
            t1 = np.where(np.isnan(t1), -np.inf, t1)
            t2 = np.where(np.isnan(t2), np.inf, t2)
            tn = np.minimum(t1, t2).max(axis=2)
            tf = np.maximum(t1, t2).min(axis=2)
            ri, rows = np.nonzero((tn <= tf) & (tf > t_min))
            ri = ri + s
            t, kind = _test_pairs(frusta, up, ri, rows, O, D, recenter, t_min, height, spheres,
                                  relief_samples)
            _reduce_nearest(n_rays, ri, rows, t, kind, best_t, best_row, best_kind)
    return _make_hits(frusta, O, D, best_t, best_row, best_kind, shape)


def _make_hits(frusta, O, D, best_t, best_row, best_kind, shape):
    hit = np.isfinite(best_t)
    point = np.where(hit[:, None], O + np.where(hit, best_t, 0.0)[:, None] * D, 0.0)
    seg = np.where(hit, frusta.segment[np.maximum(best_row, 0)] if len(frusta) else -1, -1)
    return Hits(hit=hit.reshape(shape), t=best_t.reshape(shape), row=best_row.reshape(shape),
                segment=seg.reshape(shape), point=point.reshape(shape + (3,)),
                cap=((best_kind > 0) & hit).reshape(shape))


def shade_hits(frusta: Frusta, hits: Hits, *, interpolated: bool = True, to_eye=None):
    """(u, v, normal) at the hits: (...) u, v (0 for misses) and (..., 3) unit normals
    (equation (8) if ``interpolated``, else the true cone normal; the plane's outward
    normal on caps; 0 for misses). With ``to_eye`` ((..., 3) unit directions from the hits
    to the eye) the lateral normals are the ones shading uses: (8) bent so that it faces
    the eye (:func:`~plantgen.geometry.skeletons.frusta.facing_normals`), as the GLSL caster does."""
    shape = hits.t.shape
    hit = hits.hit.ravel()
    rows = hits.row.ravel()[hit]
    pts = hits.point.reshape(-1, 3)[hit]
    u = np.zeros(hit.shape)
    v = np.zeros(hit.shape)
    nrm = np.zeros(hit.shape + (3,))
    if rows.size:
        uu, vv, nn = shade_rows_uv_normals(frusta, rows, pts, interpolated)
        if to_eye is not None:
            nn = facing_normals(nn, true_normals(frusta, rows, pts), np.reshape(to_eye, (-1, 3))[hit])
        cap = hits.cap.ravel()[hit]
        if cap.any():
            lo_side = np.abs(dot(frusta.plane_lo[rows[cap], :3], pts[cap]) - frusta.plane_lo[rows[cap], 3]) <= \
                np.abs(dot(frusta.plane_hi[rows[cap], :3], pts[cap]) - frusta.plane_hi[rows[cap], 3])
            nn[cap] = np.where(lo_side[:, None], -frusta.plane_lo[rows[cap], :3], frusta.plane_hi[rows[cap], :3])
        u[hit], v[hit], nrm[hit] = uu, vv, nn
    return u.reshape(shape), v.reshape(shape), nrm.reshape(shape + (3,))


# ------------------------------------------------------------------------------ camera render
def render_reference(frusta: Frusta, camera: Camera, *, relief=None, dtype=np.float64,
                     recenter: bool = True, origin="eye", tile: int = 32,
                     interpolated: bool = True, relief_samples: int = 512,
                     max_pairs: int = 1 << 21) -> ReferenceImage:
    """Per-pixel hit, distance, row, segment, (u, v) and normal seen by ``camera``.

    Rows are binned into ``tile`` × ``tile`` pixel tiles by the screen box of their
    bounding pyramid (rows reaching behind the eye go to every tile); each tile tests its
    rays against its rows only. ``origin="eye"`` uploads positions relative to the eye, as
    the GPU renderer does; pass None for world coordinates. Other arguments as
    :func:`intersect_frusta`.
    """
    O, D = camera.rays()
    H, W = camera.height, camera.width
    O = O.reshape(-1, 3)
    D = D.reshape(-1, 3)
    height = _resolve_relief(frusta, relief)
    eye = np.asarray(camera.eye, dtype=np.float64)
    up = _Upload(frusta, dtype, eye if isinstance(origin, str) else origin)
    best_t = np.full(H * W, np.inf)
    best_row = np.full(H * W, -1, dtype=np.int64)
    best_kind = np.zeros(H * W, dtype=np.int8)
    if len(frusta):
        corners = bounding_pyramids(frusta, shell=height is not None)
        spheres = _bounding_spheres(corners)
        for ri, rows in _tile_pairs(corners, camera, tile, max_pairs):
            t, kind = _test_pairs(frusta, up, ri, rows, O, D, recenter, 0.0, height, spheres,
                                  relief_samples)
            _reduce_nearest(H * W, ri, rows, t, kind, best_t, best_row, best_kind)
    hits = _make_hits(frusta, O, D, best_t, best_row, best_kind, (H, W))
    u, v, nrm = shade_hits(frusta, hits, interpolated=interpolated, to_eye=-D)
    return ReferenceImage(hit=hits.hit, t=hits.t, row=hits.row, segment=hits.segment, u=u, v=v,
                          normal=nrm, camera=camera)


def _tile_bins(corners, camera: Camera, tile: int):
    """Rows binned into the camera's ``tile`` × ``tile`` pixel tiles by the screen box of
    their bounding pyramids' ``corners`` (n, 8, 3) (rows reaching behind the eye go to every
    tile): (nx, ny) tiles, the rows (k,) sorted by tile, and where each tile's rows begin
    (nx·ny + 1,)."""
    H, W = camera.height, camera.width
    n = len(corners)
    right, upv, fwd = camera.basis()
    rel = corners - np.asarray(camera.eye, dtype=np.float64)
    z = rel @ fwd
    tan_y = np.tan(np.radians(camera.fov_y) / 2)
    tan_x = tan_y * camera.aspect
    scale = np.abs(rel).max(axis=(1, 2))
    behind = (z <= tol.behind_eye * np.maximum(scale, tol.tiny)[:, None]).any(axis=1)
    zc = np.where(z > 0, z, 1.0)
    px = ((rel @ right) / zc / tan_x + 1) / 2 * W - 0.5
    py = (1 - (rel @ upv) / zc / tan_y) / 2 * H - 0.5
    nx, ny = (W + tile - 1) // tile, (H + tile - 1) // tile
    tx0 = np.where(behind, 0, np.clip(np.floor((px.min(1) - 1) / tile), 0, nx)).astype(np.int64)
    tx1 = np.where(behind, nx - 1, np.clip(np.floor((px.max(1) + 1) / tile), -1, nx - 1)).astype(np.int64)
    ty0 = np.where(behind, 0, np.clip(np.floor((py.min(1) - 1) / tile), 0, ny)).astype(np.int64)
    ty1 = np.where(behind, ny - 1, np.clip(np.floor((py.max(1) + 1) / tile), -1, ny - 1)).astype(np.int64)
    cx = np.maximum(tx1 - tx0 + 1, 0)
    cy = np.maximum(ty1 - ty0 + 1, 0)
    cnt = cx * cy
    row_of = np.repeat(np.arange(n), cnt)
    k = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    tile_x = tx0[row_of] + k % np.repeat(np.maximum(cx, 1), cnt)
    tile_y = ty0[row_of] + k // np.repeat(np.maximum(cx, 1), cnt)
    tile_id = tile_y * nx + tile_x
    order = np.argsort(tile_id, kind="stable")
    tile_id, row_of = tile_id[order], row_of[order]
    return nx, ny, row_of, np.searchsorted(tile_id, np.arange(nx * ny + 1))


def _tile_pairs(corners, camera: Camera, tile: int, max_pairs: int):
    """Batches (pixel indices (k,), rows (k,)) of the (pixel, row) pairs to test, tile by
    tile (:func:`_tile_bins`); a batch closes once it holds ``max_pairs`` pairs or more."""
    H, W = camera.height, camera.width
    nx, ny, row_of, bounds = _tile_bins(corners, camera, tile)
    pending_r, pending_rows, pending = [], [], 0
    for tid in range(nx * ny):
        a, b = bounds[tid], bounds[tid + 1]
        if a == b:
            continue
        ty, tx = divmod(tid, nx)
        ys = np.arange(ty * tile, min((ty + 1) * tile, H))
        xs = np.arange(tx * tile, min((tx + 1) * tile, W))
        pix = (ys[:, None] * W + xs[None, :]).ravel()
        rows = row_of[a:b]
        pending_r.append(np.repeat(pix, len(rows)))
        pending_rows.append(np.tile(rows, len(pix)))
        pending += len(pix) * len(rows)
        if pending >= max_pairs:
            yield np.concatenate(pending_r), np.concatenate(pending_rows)
            pending_r, pending_rows, pending = [], [], 0
    if pending_r:
        yield np.concatenate(pending_r), np.concatenate(pending_rows)


# ------------------------------------------------------------------------------ brute force
def inside_frusta(frusta: Frusta, points, rows=None) -> np.ndarray:
    """(m,) bool: point lies inside the union of the frusta solids (float64; rows (k,) limits
    the test to some rows). A row's solid: between its planes, r(y) >= 0, |X⊥| <= r(y)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    rows = np.arange(len(frusta)) if rows is None else np.asarray(rows)
    out = np.zeros(len(pts), dtype=bool)
    for s in range(0, len(rows), 256):
        r = rows[s:s + 256]
        rel = pts[:, None, :] - frusta.base[r][None]
        a = frusta.axis[r][None]
        y = dot(rel, a)
        rad2 = dot(rel, rel) - y * y
        rr = frusta.r1[r][None] + frusta.slope[r][None] * y
        lo = dot(pts[:, None, :], frusta.plane_lo[r][None, :, :3]) - frusta.plane_lo[r][None, :, 3]
        hi = dot(pts[:, None, :], frusta.plane_hi[r][None, :, :3]) - frusta.plane_hi[r][None, :, 3]
        out |= ((rr >= 0) & (rad2 <= rr * rr) & (lo >= 0) & (hi <= 0)).any(axis=1)
    return out


def march_rays(frusta: Frusta, origins, dirs, t_max: float, *, samples: int = 4000,
               bisect: int = 50) -> np.ndarray:
    """(m,) t where each ray first enters the union of the solids, by dense marching
    (``samples`` steps over [0, t_max]) and bisection; inf if it never does. Brute force,
    for tests: independent of the quadratic and of the caps logic."""
    O = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    D = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    ts = np.linspace(0.0, t_max, samples)
    out = np.full(len(O), np.inf)
    prev = np.zeros(len(O))
    found = np.zeros(len(O), dtype=bool)
    step = max(1, 200000 // max(len(O), 1))
    for s in range(0, samples, step):
        tt = ts[s:s + step]
        pts = O[:, None, :] + tt[None, :, None] * D[:, None, :]
        ins = inside_frusta(frusta, pts.reshape(-1, 3)).reshape(len(O), len(tt))
        first = np.argmax(ins, axis=1)
        newly = ins.any(axis=1) & ~found
        t_in = tt[first]
        t_out = np.where(first > 0, tt[np.maximum(first - 1, 0)], prev)
        idx = np.flatnonzero(newly)
        lo_t, hi_t = t_out[idx], t_in[idx]
        for _ in range(bisect):
            mid = 0.5 * (lo_t + hi_t)
            ins_m = inside_frusta(frusta, O[idx] + mid[:, None] * D[idx])
            hi_t = np.where(ins_m, mid, hi_t)
            lo_t = np.where(ins_m, lo_t, mid)
        out[idx] = hi_t
        found |= newly
        prev = np.where(found, prev, tt[-1])
        if found.all():
            break
    return out
