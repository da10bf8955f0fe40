"""Smooth bends: a skeleton refinement run before skinning (issue 17; the paper's §4.1
limitation: frusta meet at C0 joints, so bent chains read as polylines).

:func:`smooth_bends` replaces every continuing joint bent by more than a threshold by a
circular arc of short segments tangent to both segments, as a pipe bend is made:

- the bend θ is the angle between the parent's axis a_p and the child's axis a_c;
- the arc's radius (of its centre line) is R = min(``radius_factor``·r_J, fit), r_J the
  larger of the two radii at the joint J and fit = ``fit_fraction``·L_min / tan(θ/2), L_min
  the shorter of the two segments, so the arc always fits (both ends of a segment may be
  taken by arcs, hence ``fit_fraction`` < 1/2); a joint whose arc would be narrower than
  :data:`MIN_ARC_RATIO` joint radii (segments short for their thickness) is left a joint:
  the tube bent that tightly crushes its chords on the inside;
- both segments are shortened by the tangent length d = R·tan(θ/2): the parent ends at
  P0 = J - d·a_p, the child starts at P1 = J + d·a_c; their radii are the cones' own at
  those points, so the taper is kept;
- k = max(1, ceil(θ / ``step_deg``)) chords of the arc (at most :data:`MAX_CHORDS`) are
  inserted between P0 and P1 (or a fixed ``segments`` per arc); chord i takes slot i of k
  of the texture's v (``SmoothResult.v_part``, the frusta's ``v_part``), so the arc
  spans one texture period, as one segment does, and v runs on continuously; the arc's
  centre is C = P0 + R·n, n the unit direction in the bend plane perpendicular to a_p
  towards a_c, and vertex i is
  C - R·cos(φ_i)·n + R·sin(φ_i)·a_p with φ_i = θ·i/k; radii interpolate linearly in φ from
  the parent's radius at P0 to the child's at P1;
- side branches that started at J start instead on the middle chord's midpoint (J is off
  the bent tube's surface by R·(sec(θ/2) - 1)) and hang from that chord.

The arc segments continue their chain (``continues``), so the skinning's seam fit and its
texture frames carry v and u across them; they take the child's material. The result keeps
the skeleton's contract (parent < child). Pure numpy, vectorised over joints and arc
segments; nothing here imports GL.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ...tolerances import tol
from ..vec import dot, norm, unit
from .frusta import MAX_V_SLOTS
from .skeleton import Skeleton
from .topology import carried_on

__all__ = ["SmoothResult", "smooth_bends", "DEFAULT_STEP_DEG", "DEFAULT_RADIUS_FACTOR"]

#: Largest bend (degrees) of one arc chord when ``segments`` is not given.
DEFAULT_STEP_DEG = 10.0
#: The arc's centre-line radius as a multiple of the joint radius, when the segments allow.
DEFAULT_RADIUS_FACTOR = 3.0
#: Largest share of a segment's length one arc may take (an arc at each end must fit).
FIT_FRACTION = 0.45
#: The most chords one arc gets (its chords share the texture's v period in that many slots).
MAX_CHORDS = MAX_V_SLOTS
#: Smallest arc radius, in joint radii: a tighter arc leaves the joint as it is. Swept over
#: bends of 30-100°, tapers and 3-6° chords, arcs from 1.5 r up skin closed (the saguaro's
#: elbows, fitted between short segments, come to 1.95 r); below, rays escaped at 1.2-1.42 r.
MIN_ARC_RATIO = 1.5
#: Bends this close to 180° (degrees) are left to the skinning's knuckles.
MAX_SMOOTH_DEG = 179.0


@dataclass(frozen=True, eq=False)
class SmoothResult:
    """The refined skeleton, for each of its segments the original segment it comes from
    (``origin``; arc segments: the joint's child), and the joints smoothed."""

    skeleton: Skeleton
    origin: np.ndarray          # (m,) i8 index into the original skeleton
    joints: int                 # joints replaced by arcs
    added: int                  # segments added (m - n)
    child: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # (j,) each arc's child
    arc_radius: np.ndarray = field(default_factory=lambda: np.zeros(0))        # (j,) its R
    v_part: np.ndarray | None = None   # (m, 2) texture slot, slots per segment: an arc's chords share one period


def _joints(skeleton: Skeleton, min_bend_deg: float):
    """(parent, child, bend radians) of the continuing joints bent by more than
    ``min_bend_deg`` (and less than :data:`MAX_SMOOTH_DEG`)."""
    child = np.flatnonzero(carried_on(skeleton.parent, skeleton.continues))  # as skinning's joints
    parent = skeleton.parent[child]
    a_p = unit(skeleton.end[parent] - skeleton.start[parent])
    a_c = unit(skeleton.end[child] - skeleton.start[child])
    bend = np.arccos(np.clip(dot(a_p, a_c), -1.0, 1.0))
    ok = ((bend > np.radians(min_bend_deg)) & (bend < np.radians(MAX_SMOOTH_DEG))
          & (norm(skeleton.end[parent] - skeleton.start[parent]) > 0)
          & (norm(skeleton.end[child] - skeleton.start[child]) > 0))
    return parent[ok], child[ok], bend[ok], a_p[ok], a_c[ok]


def smooth_bends(skeleton: Skeleton, min_bend_deg: float, *, step_deg: float = DEFAULT_STEP_DEG,
                 segments: int | None = None,
                 radius_factor: float = DEFAULT_RADIUS_FACTOR) -> SmoothResult:
    """Replace continuing joints bent by more than ``min_bend_deg`` degrees by arcs (see
    the module docstring). ``segments`` fixes the chords per arc; otherwise
    k = ceil(θ / ``step_deg``). A skeleton with no such joint comes back unchanged."""
    if not (np.isfinite(min_bend_deg) and 0.0 <= min_bend_deg < 180.0):
        raise ValueError(f"smooth_bends must be an angle in [0, 180) degrees, got {min_bend_deg!r}")
    if not (np.isfinite(step_deg) and step_deg > 0.0) or (segments is not None and segments < 1):
        raise ValueError(f"smooth_bends: step_deg must be > 0 and segments >= 1, got {step_deg!r}, {segments!r}")
    n = len(skeleton)
    p, c, theta, a_p, a_c = _joints(skeleton, min_bend_deg)
    if not len(c):
        return SmoothResult(skeleton, np.arange(n), 0, 0, v_part=np.tile(np.array([0, 1], np.int64), (n, 1)))
    length = norm(skeleton.end - skeleton.start)
    r_joint = np.maximum(skeleton.r_end[p], skeleton.r_start[c])
    tan_half = np.tan(0.5 * theta)
    fit = FIT_FRACTION * np.minimum(length[p], length[c]) / tan_half
    R = np.minimum(radius_factor * r_joint, fit)
    # an arc barely wider than its tube squeezes its short thick chords until their planes
    # cross inside them (and at R <= r_J the torus folds through itself): that joint stays a
    # joint, which the skinning closes
    keep = MIN_ARC_RATIO * r_joint <= R
    if not keep.all():
        p, c, theta, a_p, a_c, r_joint, tan_half, R = (x[keep] for x in (p, c, theta, a_p, a_c, r_joint,
                                                                         tan_half, R))
        if not len(c):
            return SmoothResult(skeleton, np.arange(n), 0, 0, v_part=np.tile(np.array([0, 1], np.int64), (n, 1)))
    d = R * tan_half
    k = (np.full(len(c), int(segments)) if segments is not None
         else np.maximum(1, np.ceil(np.degrees(theta) / step_deg - tol.count_rounding)).astype(np.int64))
    k = np.minimum(k, MAX_CHORDS)
    # ---- shortened segments (a segment may lose length at both ends)
    d_start, d_end = np.zeros(n), np.zeros(n)
    d_start[c], d_end[p] = d, d
    axis = (skeleton.end - skeleton.start) / np.where(length > 0, length, 1.0)[:, None]
    slope = (skeleton.r_end - skeleton.r_start) / np.where(length > 0, length, 1.0)
    start = skeleton.start + d_start[:, None] * axis
    end = skeleton.end - d_end[:, None] * axis
    r_start = skeleton.r_start + slope * d_start
    r_end = skeleton.r_end - slope * d_end
    # ---- arc vertices, joint by joint (vectorised over all chords)
    jid = np.repeat(np.arange(len(c)), k)
    first = np.concatenate([[0], np.cumsum(k)[:-1]])
    i = np.arange(len(jid)) - first[jid]
    normal = unit(a_c - dot(a_c, a_p)[:, None] * a_p)
    P0 = skeleton.end[p] - d[:, None] * a_p
    centre = P0 + R[:, None] * normal

    def vertex(frac):
        phi = theta[jid] * frac
        return (centre[jid] - (R[jid] * np.cos(phi))[:, None] * normal[jid]
                + (R[jid] * np.sin(phi))[:, None] * a_p[jid])

    f0, f1 = i / k[jid], (i + 1) / k[jid]
    arc_start, arc_end = vertex(f0), vertex(f1)
    r0, r1 = r_end[p][jid], r_start[c][jid]
    arc_r_start, arc_r_end = r0 + (r1 - r0) * f0, r0 + (r1 - r0) * f1
    res = _assemble(skeleton, p, c, k, jid, i, (start, end, r_start, r_end),
                    (arc_start, arc_end, arc_r_start, arc_r_end))
    return dataclasses.replace(res, child=c, arc_radius=R)


def _assemble(skeleton: Skeleton, p, c, k, jid, i, seg, arc) -> SmoothResult:
    """Put each arc right after its parent segment (keeping parent < child), re-link parents
    and move side branches that started at a smoothed joint onto the middle chord."""
    n = len(skeleton)
    start, end, r_start, r_end = seg
    arc_start, arc_end, arc_r_start, arc_r_end = arc
    k_of_parent = np.zeros(n, np.int64)
    k_of_parent[p] = k
    block = 1 + k_of_parent
    new_idx = np.cumsum(block) - block                  # each segment, then its arc
    m = int(block.sum())
    arc_idx = new_idx[p][jid] + 1 + i
    old_parent = skeleton.parent
    parent = np.where(old_parent >= 0, new_idx[np.maximum(old_parent, 0)], -1)
    parent[c] = new_idx[p] + k                          # the child hangs from the arc's last chord
    arc_parent = np.where(i == 0, new_idx[p][jid], arc_idx - 1)
    start = start.copy()
    # side branches of a smoothed parent that start at its (old) end J: onto the middle chord
    mid_chord = new_idx[p] + 1 + k // 2
    smoothed_parent = np.full(n, -1, np.int64)
    smoothed_parent[p] = np.arange(len(p))
    has_parent = old_parent >= 0
    j_of = np.where(has_parent, smoothed_parent[np.maximum(old_parent, 0)], -1)
    moved = np.flatnonzero((j_of >= 0) & ~np.isin(np.arange(n), c))
    if moved.size:
        J = skeleton.end[p][j_of[moved]]
        near = norm(skeleton.start[moved] - J) <= np.maximum(skeleton.r_end[p][j_of[moved]], tol.tiny)
        moved = moved[near]
        chord = mid_chord[j_of[moved]]
        pos = np.searchsorted(arc_idx, chord)
        start[moved] = 0.5 * (arc_start[pos] + arc_end[pos])
        parent[moved] = chord
    out = _empty_like(skeleton, m)
    rows = (new_idx, arc_idx)
    for name, a, b in (("start", start, arc_start), ("end", end, arc_end), ("r_start", r_start, arc_r_start),
                       ("r_end", r_end, arc_r_end), ("parent", parent, arc_parent),
                       ("continues", skeleton.continues, np.ones(len(jid), bool)),
                       ("material", skeleton.material, skeleton.material[c][jid])):
        out[name][rows[0]] = a
        out[name][rows[1]] = b
    origin = np.empty(m, np.int64)
    origin[new_idx], origin[arc_idx] = np.arange(n), c[jid]
    refined = Skeleton(**out, material_names=skeleton.material_names)
    return SmoothResult(refined, origin, len(c), m - n,
                        v_part=_texture_slots(refined, new_idx[c], arc_idx, jid, i, k))


def _texture_slots(refined: Skeleton, child_rows, arc_idx, jid, i, k) -> np.ndarray:
    """(m, 2) texture slot, slots of each refined segment: chord i of an arc of k takes slot
    i of k, so the arc spans one period of the texture's v as a segment does; where what
    is left of the arc's child is shorter than the arc (an elbow between two bends), the
    child joins the arc's period as slot k of k + 1, so the texture keeps its density."""
    v_part = np.tile(np.array([0, 1], np.int64), (len(refined), 1))
    arc_length = np.bincount(jid, norm(refined.end[arc_idx] - refined.start[arc_idx]), minlength=len(k))
    left = norm(refined.end[child_rows] - refined.start[child_rows])
    joins = (left < arc_length) & (k < MAX_CHORDS)
    slots = k + joins
    v_part[arc_idx, 0], v_part[arc_idx, 1] = i, slots[jid]
    v_part[child_rows[joins], 0], v_part[child_rows[joins], 1] = k[joins], slots[joins]
    return v_part


def _empty_like(skeleton: Skeleton, m: int) -> dict:
    return {"start": np.empty((m, 3)), "end": np.empty((m, 3)), "r_start": np.empty(m),
            "r_end": np.empty(m), "parent": np.empty(m, np.int64), "continues": np.empty(m, bool),
            "material": np.empty(m, np.int32)}
