"""Knuckles of the GS mesh: a chain's sharp joints, found and cut for
:func:`plantgen.geometry.meshes.mesh.tessellate`.

**Knuckles** (``skin_skeleton(max_bend_deg=...)``: bends past 120° by default, and joints
whose plane would not cut a cone in an ellipse or whose segments' planes would cross).
Skinning gives the parent segment P and the child C planes ⟂ their axes through the
joint J and fills the bend with fan slices around the hinge line (through J, ⟂ the medial
plane): *outer* slices continue the chain and sweep the outer side, *inner* slices cover
the inner side (see :mod:`plantgen.geometry.skeletons.skin`). Their union is what the ray caster
draws; the mesh is its boundary:

- *outer side*: each outer slice is a cylinder strip between two planes through the
  hinge line; on the outer half (``N/2`` columns from hinge point to hinge point) it has
  width, on the inner half none. The mesh tessellates that half only, ``B`` bands across,
  the two columns at the hinge points as triangle fans: ``(N - 2)·B`` triangles a slice,
  every vertex on the slice's cylinder (the strips sweep the zone of the sphere of radius
  r around J that the paper's bend should show, to 10° slices). Columns are turned (by at
  most half a column, interpolated along P) so that two columns of P's top ring, of every
  slice ring and of C's bottom ring sit exactly on the hinge points.
- *inner side*: P's and C's cylinders overlap there; for equal radii the bisector
  ("mitre") plane through the hinge line, normal ``M1 + M2``, cuts both in the same
  ellipse and separates the parts that lie inside the other cylinder. P's generators on
  the inner half end at that plane instead of at P's ⟂ plane (``min`` of the two heights;
  they agree on the hinge line), C's start there; both rings keep ``N`` columns, every
  vertex on its own cone at the ray caster's ``(u, v)`` and normal (8), and C's inner half
  ring is a copy of P's. The inner slices lie inside P ∪ C and get no triangles, no caps.
- where the two cut curves differ (radii or tapers that differ, by more than
  ``tol.seam_snap`` of the radius), a *bridge* band of ``N - 2`` triangles (``N`` if the
  hinge points differ) joins P's curve to C's in the cutting plane: the part of one
  cross-section the other does not cover. It is counted with P's row.
- a trim may take at most 90 % of any generator of P or C (45 % at each end of a segment
  between two knuckles, so the two never cross). Where the mitre would cut deeper (bends
  near 180°, or segments shorter than about ``1.1·r·tan(bend/2)``, twice that between
  two knuckles) P and C are cut by planes turned less far (both by the smaller of their
  two limits, symmetric about the mitre), the bridge joins the two cuts, and the mesh is
  still closed, consistently wound and positive but overlaps itself there: the
  boundary of the union is then not local to the joint (it runs into the next segments
  and their caps, as it does where a chain crosses itself).
- a knuckle without bend (under ``tol.flat_bend`` rad) joins P's top ring to C's bottom
  ring directly (copies), or caps both where their radii differ (as a radius step).

So a chain with knuckles is one closed surface without zero-area triangles. Its rows no
longer all carry ``16·4^m`` triangles (:attr:`TessellatedMesh.uniform_rows` is False:
a renderer must take each face's row from ``face_row``, not from index // 16·4^m), and
:func:`triangle_count` given the frusta counts them exactly. Vertices that no face uses
(the inner half of slice rings, inner slices) are dropped, so meshes with knuckles have
no fixed vertex layout; texture coordinates stay continuous through the fan (its slices
advance u by their twist), C's trimmed vertices carry C's (u, v), P's carry P's (copies
at one position where they meet), so the mesh is closed once welded by position.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...tolerances import tol
from ..skeletons.frusta import Frusta, plane_height
from ..vec import any_perpendicular, cross, dot, norm, plane_through, unit

#: Most of a generator's length (between the row's own planes) a knuckle trim may take;
#: half of it at each end of a segment between two knuckles.
_TRIM_SHARE = 0.9


#: Generators sampled on the inner half to bound a trim and to compare the cut curves.
_TRIM_SAMPLES = 33


# ---------------------------------------------------------------------------- knuckles
@dataclass
class Knuckles:
    """The K knuckles of a frusta (see the module docstring), each the parent row P, its
    outer fan slices and the child row C, with the cuts the mesh uses.

    ``slices`` (S,) are the outer slice rows, knuckle by knuckle in chain order, knuckle k's
    at ``slices[start[k]:start[k + 1]]``; ``inner`` the inner slice rows. Per knuckle (K,):
    ``joint`` J, ``hinge`` the unit hinge direction k (the fan turns P's axis M1 about it
    to C's axis M2), ``inner_p`` = k × M1 and ``inner_c`` = k × M2 (towards the inside of
    the bend), ``bend`` (radians), ``radius_p``/``radius_c`` the radii at J, the trimming
    planes ``plane_p`` (P keeps n·x <= d) and ``plane_c`` (C keeps n·x >= d), and flags
    ``flat`` (no bend), ``merged`` (equal radii: one hinge point a side) and ``mitred``
    (the two cut curves are one). ``hinge_col`` is the column on the hinge point k.
    """

    parent: np.ndarray
    child: np.ndarray
    slices: np.ndarray
    start: np.ndarray
    inner: np.ndarray
    joint: np.ndarray = None
    hinge: np.ndarray = None
    inner_p: np.ndarray = None
    inner_c: np.ndarray = None
    bend: np.ndarray = None
    radius_p: np.ndarray = None
    radius_c: np.ndarray = None
    plane_p: np.ndarray = None
    plane_c: np.ndarray = None
    flat: np.ndarray = None
    merged: np.ndarray = None
    mitred: np.ndarray = None
    hinge_col: np.ndarray = None

    @property
    def slice_knuckle(self) -> np.ndarray:
        """(S,) the knuckle of each outer slice."""
        return np.repeat(np.arange(len(self.parent)), np.diff(self.start))


def find_knuckles(frusta: Frusta) -> Knuckles | None:
    """The knuckles of ``frusta``: runs of short continuing rows (fan slices) from a row
    with length P to one C, all based at one point J where P ends and C starts; their
    inner slices are the short open rows with an outer slice's planes swapped. Fan rows
    that do not fit (no C, no common point, no radius) stay ordinary rows. None: no
    knuckle."""
    n = len(frusta.length)
    short = ~frusta.has_length if n else np.zeros(0, bool)
    if not short.any():
        return None
    parent = frusta.parent_row
    has_parent = parent >= 0
    child_of = np.full(n, -1, np.int64)
    child_of[parent[has_parent]] = np.flatnonzero(has_parent)
    first = np.flatnonzero(short & has_parent)
    first = first[~short[parent[first]]]
    top = frusta.top
    rows_p, rows_c, slices, start = [], [], [], [0]
    for f in first:
        run, c = [int(f)], int(child_of[f])
        while c >= 0 and short[c]:
            run.append(c)
            c = int(child_of[c])
        if c < 0:
            continue
        p, joint = int(parent[f]), frusta.base[f]
        radius = max(frusta.r2[p], frusta.r1[c], float(frusta.r1[run].max()))
        slack = tol.joint_gap * max(1.0, float(np.abs(joint).max()) + radius)
        gaps = np.concatenate([norm(frusta.base[run] - joint), norm(top[[p]] - joint),
                               norm(frusta.base[[c]] - joint)])
        smallest = min(frusta.r2[p], frusta.r1[c], float(frusta.r1[run].min()))
        if gaps.max() > slack or not smallest > tol.zero_length * radius:
            continue
        rows_p.append(p)
        rows_c.append(c)
        slices.extend(run)
        start.append(len(slices))
    if not rows_p:
        return None
    outer = {frusta.plane_hi[o].tobytes() + frusta.plane_lo[o].tobytes() for o in slices}
    candidates = np.flatnonzero(short & ~has_parent & (child_of < 0))
    inner = [i for i in candidates
             if frusta.plane_lo[i].tobytes() + frusta.plane_hi[i].tobytes() in outer]
    kn = Knuckles(np.array(rows_p, np.int64), np.array(rows_c, np.int64),
                   np.array(slices, np.int64), np.array(start, np.int64), np.array(inner, np.int64))
    _knuckle_cuts(frusta, kn)
    return kn


def cut_height(frusta: Frusta, rows, e, plane):
    """Axial heights (and rises) where generators of ``rows`` in radial directions ``e``
    (..., 3) meet ``plane`` (..., 4) (:func:`plane_height`; arguments broadcast)."""
    n, d = plane[..., :3], plane[..., 3]
    return plane_height(d - dot(n, frusta.base[rows]), dot(n, frusta.axis[rows]), dot(n, e),
                        frusta.r1[rows], frusta.slope[rows])


def _inner_generators(frusta: Frusta, rows, hinge, inner):
    """(K, S, 3) radial directions of ``rows`` (K,) from the hinge k over the inner half
    (towards ``inner``), ends excluded."""
    beta = np.linspace(0.0, np.pi, _TRIM_SAMPLES + 2)[1:-1]
    axis = frusta.axis[rows]
    k_perp = unit(hinge - axis * dot(hinge, axis)[:, None])
    return (np.cos(beta)[None, :, None] * k_perp[:, None, :]
            + np.sin(beta)[None, :, None] * inner[:, None, :])


def _trim_plane(axis, inner, joint, gamma, below: bool):
    """(K, 4) the plane through the hinge line turned by ``gamma`` from the ⟂ plane of
    ``axis`` towards the inside (P: ``below``, it keeps n·x <= d) or back (C)."""
    normal = axis * np.cos(gamma)[:, None] + inner * (np.sin(gamma) * (1 if below else -1))[:, None]
    return plane_through(normal, joint)


def _trim_angle(frusta: Frusta, rows, joint, hinge, inner, limit, below: bool, share):
    """(K,) the largest turn of the trimming plane, up to ``limit`` (the mitre), whose cut
    takes at most ``share`` (K,) of each sampled inner generator of ``rows`` (K,)."""
    e = _inner_generators(frusta, rows, hinge, inner)
    r = rows[:, None]
    y_lo = cut_height(frusta, r, e, frusta.plane_lo[r])[0]
    y_hi = cut_height(frusta, r, e, frusta.plane_hi[r])[0]
    room = share[:, None] * (y_hi - y_lo)
    axis = frusta.axis[rows]

    def fits(gamma):
        y, rise = cut_height(frusta, r, e, _trim_plane(axis, inner, joint, gamma, below)[:, None, :])
        cut = y_hi - y if below else y - y_lo
        return np.all((rise > tol.generator_rise) & (np.abs(cut) <= room), axis=1)

    lo, hi = np.zeros_like(limit), limit.copy()
    whole = fits(hi)
    lo[whole] = hi[whole]
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        good = fits(mid)
        lo, hi = np.where(good, mid, lo), np.where(good, hi, mid)
    return lo


def _knuckle_cuts(frusta: Frusta, kn: Knuckles) -> None:
    """Hinge, bend, radii, trimming planes and flags of the knuckles (in place)."""
    head = kn.slices[kn.start[:-1]]
    n_lo, n_hi = frusta.plane_lo[kn.slices, :3], frusta.plane_hi[kn.slices, :3]
    turn = cross(n_lo, n_hi)
    kn.bend = np.add.reduceat(np.arctan2(norm(turn), dot(n_lo, n_hi)), kn.start[:-1])
    m1, m2 = frusta.axis[kn.parent], frusta.axis[kn.child]
    kn.flat = kn.bend < tol.flat_bend
    helper = any_perpendicular(m1)
    k = np.where(kn.flat[:, None], helper, unit(np.add.reduceat(turn, kn.start[:-1], axis=0), helper))
    kn.hinge = k = unit(k - m1 * dot(k, m1)[:, None], helper)
    kn.inner_p, kn.inner_c = unit(cross(k, m1)), unit(cross(k, m2))
    kn.joint = joint = frusta.base[head]
    kn.radius_p = frusta.r1[kn.parent] + frusta.slope[kn.parent] * dot(joint - frusta.base[kn.parent], m1)
    kn.radius_c = frusta.r1[kn.child] + frusta.slope[kn.child] * dot(joint - frusta.base[kn.child], m2)
    half = np.where(kn.flat, 0.0, 0.5 * kn.bend)
    both_ends = np.isin(kn.parent, kn.child), np.isin(kn.child, kn.parent)
    share_p, share_c = (np.where(b, 0.5 * _TRIM_SHARE, _TRIM_SHARE) for b in both_ends)
    gamma_p = _trim_angle(frusta, kn.parent, joint, k, kn.inner_p, half, True, share_p)
    gamma_c = _trim_angle(frusta, kn.child, joint, k, kn.inner_c, half, False, share_c)
    gamma_p = gamma_c = np.minimum(gamma_p, gamma_c)   # a short side holds both back
    kn.plane_p = _trim_plane(m1, kn.inner_p, joint, gamma_p, True)
    kn.plane_c = _trim_plane(m2, kn.inner_c, joint, gamma_c, False)
    at_mitre = (gamma_p == half) & (gamma_c == half) & ~kn.flat
    kn.plane_c[at_mitre] = kn.plane_p[at_mitre]          # one plane, bit for bit
    radius = np.maximum(kn.radius_p, kn.radius_c)
    kn.merged = np.abs(kn.radius_p - kn.radius_c) <= tol.seam_snap * radius
    # the two cut curves, generator by generator (the mitre maps P's β to C's β)
    ends = []
    for rows, inner, plane in ((kn.parent, kn.inner_p, kn.plane_p), (kn.child, kn.inner_c, kn.plane_c)):
        e = _inner_generators(frusta, rows, k, inner)
        r = rows[:, None]
        y = cut_height(frusta, r, e, plane[:, None, :])[0]
        ends.append(frusta.base[r] + y[..., None] * frusta.axis[r]
                    + (frusta.r1[r] + frusta.slope[r] * y)[..., None] * e)
    gap = norm(ends[0] - ends[1]).max(axis=1)
    kn.mitred = at_mitre & kn.merged & (gap <= tol.seam_snap * radius)
