"""Skinning: a skeleton's segments become the rows of :class:`~plantgen.geometry.skeletons.frusta.Frusta`
(Bhagvat et al. 2009, §2), vectorised over all segments.

:func:`skin_skeleton` runs the phases in order, each a function below:

1. segment axes and lengths (:func:`_segment_axes`), continuing children and side
   branches (:func:`continuing_children`);
2. side-branch bases, moved back into the parent (:func:`_extend_side_branches`);
3. joint planes at continuing joints (:func:`_joint_cuts`). By default the seams close
   exactly: each continuing child's base radius is set so that both cones touch one
   sphere around the joint (:func:`seam_radii`, the closed form of §2.2's minor-axis
   fit), and the plane through the crossings of the boundary lines (3)–(5), found as
   tangents of that sphere (:func:`_sphere_planes`), then cuts both cones in the same
   ellipse. ``seam_fit=False`` keeps the paper's planes on the skeleton's radii
   (:func:`_joint_planes`); the report measures their seam mismatch either way
   (:func:`_seam_mismatch_at`);
4. sharp joints (:func:`_sharp_joints`) and their knuckle fans (:func:`_row_layout`,
   :func:`_fill_knuckle_fans`);
5. texture frames: reference directions carried along each chain
   (:func:`~plantgen.geometry.skeletons.texture_frames.reference_directions`) and u
   offsets (:func:`~plantgen.geometry.skeletons.texture_frames.u_offsets`, §2.3).

With ``smooth_bends=ANGLE``, :func:`skin_skeleton` first refines the skeleton
(:func:`plantgen.geometry.skeletons.smooth.smooth_bends`: joints bent past ANGLE become arcs of short
continuing segments tangent to both segments), skins the result as above and maps the
rows' ``segment`` back to the original segments.

Sharp bends (the paper's §4.1 leaves them open: past ``max_bend_deg``, a plane that no
longer cuts a cone in an ellipse, or two planes of a segment crossing inside it) become
*knuckles*: the two segments get planes perpendicular to their own axes through the joint
J, and a fan of cylinder rows of radius r_joint, all based at J, fills the bend. Slice i
(i = 0..m, m = ceil(bend / fan_step_deg)) has its axis turned by bend·i/m from the
parent's and its planes at bend·(i ∓ 1/2)/m (clamped to 0 and bend, so the end slices
meet their segments in the same circle). The two planes of a slice cross on the hinge
line through J ⟂ the medial plane, by design: the slice is the wedge on the outer side of
the bend; a second set of rows with the two planes swapped covers the opposite wedge on
the inner side (needed when the segments are short next to r·sin(bend)). Together they
sweep a ball of radius r_joint around J, as Max's cone-spheres do. Fan rows have
``length`` ``tol.fan_length``·r, r1 = r2, ``segment`` = the child segment; outer slices
continue the chain (shared planes, ``parent_row``), inner slices are open rows whose caps
lie inside the knuckle. Side branches start back along their own axis, inside the parent,
and their base is open (capped).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ...tolerances import tol
from ..vec import (
    ROW_BLOCK,
    any_perpendicular,
    by_rows,
    cross,
    dot,
    in_threads,
    norm,
    plane_through,
    rotate,
    unit,
)
from . import relief
from .frusta import Frusta, SkinReport, cone_slope, minor_semi_axis, plane_height
from .skeleton import Skeleton
from .smooth import DEFAULT_STEP_DEG
from .smooth import smooth_bends as smooth_bends_of
from .texture_frames import reference_directions, u_offsets

__all__ = ["skin_skeleton", "continuing_children", "lead_forks", "material_shell", "crossing_rows_sampled",
           "seam_radii", "sphere_base_radius", "FORK_LEAD_MAX_BEND_DEG"]

#: The largest bend (degrees) at which a fork's child may lead on from its parent
#: (:func:`lead_forks`); a fork whose children all turn further keeps its capped end.
FORK_LEAD_MAX_BEND_DEG = 90.0


def skin_skeleton(skeleton: Skeleton, *, smooth_bends: float | None = None,
                  smooth_step_deg: float = DEFAULT_STEP_DEG, lead: bool = True, **options) -> Frusta:
    """Skin a skeleton with conical frusta (§2), optionally smoothing its bends first.

    smooth_bends : None (the default: the skeleton as it is), or an angle in degrees:
        continuing joints bent by more than it are replaced by arcs of short segments
        tangent to both segments before skinning (:func:`plantgen.geometry.skeletons.smooth.smooth_bends`),
        each arc chord bending at most ``smooth_step_deg``. The frusta's ``segment`` still
        names the original skeleton's segments (an arc's rows: the joint's child), an arc's
        rows share one period of the texture's v (``v_part``), and the report counts the
        joints smoothed and the segments added (``smooth_joints``, ``smooth_segments``;
        ``n_segments`` is the original count).
    lead : let one child of every fork continue its parent (:func:`lead_forks`, the
        default): a fork's parent otherwise ends in a flat cap with its thinner children
        standing on it (a visible step). False: the skeleton's own ``continues``
    options : the keyword arguments of :func:`_skin` (shell, seam_fit, max_bend_deg,
        fan_step_deg, twist, extend_side_branches)
    """
    if lead:
        skeleton = lead_forks(skeleton)
    if smooth_bends is None:
        return _skin(skeleton, **options)
    refined = smooth_bends_of(skeleton, float(smooth_bends), step_deg=float(smooth_step_deg))
    frusta = _skin(refined.skeleton, **options)
    report = frusta.report
    report.n_segments, report.smooth_joints = len(skeleton), refined.joints
    report.smooth_segments = refined.added
    return dataclasses.replace(frusta, segment=refined.origin[frusta.segment], v_part=refined.v_part[frusta.segment],
                               report=report)


def _skin(skeleton: Skeleton, *, shell=None, seam_fit: bool = True,
          max_bend_deg: float = 120.0, fan_step_deg: float = 10.0, twist: float = 0.0,
          extend_side_branches: bool = True, texture: bool = True) -> Frusta:
    """Skin a skeleton with conical frusta, vectorised over all segments (§2).

    Parameters
    ----------
    skeleton : Skeleton with n segments (world units, y up)
    shell : dict material name -> relief shell thickness, or None for
        :data:`plantgen.geometry.skeletons.relief.DEFAULT_SHELL`. A value v >= 0 is a fraction
        of the radius: the relief is v·r(y) deep at every height y, so it is as deep on both
        sides of a joint (the row's ``shell``, its bound, is v times the segment's larger
        end radius; :func:`plantgen.geometry.skeletons.frusta.relief_scale`); a value v < 0
        means -v world units at the segment's thicker end, following the radius along it.
        Names missing from a given dict get 0 (no relief).
    seam_fit : close every continuing joint's seam exactly (the default): each continuing
        child's r1 is set so that the two cones touch one sphere around the joint, and the
        joint plane passes through the crossings of their boundary lines, which are then
        tangent to that sphere's great circle (:func:`seam_radii`, :func:`_sphere_planes`).
        This is §2.2's minor-axis fit in closed form. False: the paper's construction with
        the skeleton's radii (:func:`_joint_planes`), whose seams leave a gap at tapering,
        bent joints (measured in the report)
    max_bend_deg : joints bending more than this (degrees) become knuckles (a fan of short
        cylinder slices around the joint, see the module docstring), as do joints
        whose plane does not cut a cone in an ellipse and joints of segments whose two
        planes would cross inside them
    fan_step_deg : largest bend (degrees) of one knuckle fan slice
    twist : twist θ (turns per segment) stored on every row
    extend_side_branches : move each side branch's start back along its own axis into the
        parent (keeping its slope) by min(rc·tan β, (rp - rc)/sin β), β the branch
        angle: far enough that the base disc is under the parent's end plane, not so far
        that its rim leaves the parent's side; the base is capped
    texture : the rows' texture offsets ``u_offset`` (the default); False leaves them 0,
        for a target that reads no texture coordinate (a light's rays: every other number
        is the same)

    Returns
    -------
    Frusta, with ``report`` a :class:`~plantgen.geometry.skeletons.frusta.SkinReport`.
    """
    n = len(skeleton)
    report = SkinReport(n_segments=n)
    seg, joints, side = _segments_and_joints(skeleton, extend_side_branches)
    child = joints.child
    report.joints, report.side_branches = len(child), len(side)
    report.measure_paper_seams(lambda: _paper_seams(skeleton, extend_side_branches))
    lo = by_rows(plane_through, seg.axis, seg.base)
    hi = by_rows(plane_through, seg.axis, skeleton.end)
    sharp, bend, medial = np.zeros(0, dtype=bool), np.zeros(0), np.zeros((0, 3))
    if child.size:
        sharp, bend, medial = _joint_cuts(seg, joints, skeleton, lo, hi, seam_fit, max_bend_deg, report)

    rows, row_of_seg, fan_count = _row_layout(seg, lo, hi, joints, sharp, bend, skeleton,
                                              fan_step_deg)
    report.fan_rows = len(rows.length) - n
    report.n_rows = len(rows.length)
    if np.any(sharp):
        _fill_knuckle_fans(rows, seg, joints, np.flatnonzero(sharp), bend, medial, lo, hi,
                           row_of_seg, fan_count)

    n_rows = len(rows.length)
    ref_dir = reference_directions(rows.axis, rows.parent_row)
    row_twist = np.full(n_rows, float(twist))
    # the shell bounds a relief as deep as the material's fraction of the radius at every
    # height (relief_scale); a side branch's own radius, not the one moved into its parent
    thick_end = np.maximum(seg.r_start, seg.r_end)
    thick_end[side] = np.maximum(skeleton.r_start[side], skeleton.r_end[side])
    row_shell = material_shell(skeleton, shell, thick_end) if n else np.zeros(0)
    if n_rows != n:                      # fan rows: each row's segment's
        row_shell = row_shell[rows.segment]
    row_material = skeleton.material[rows.segment] if n else np.zeros(0, np.int32)
    u_offset = u_offsets(rows, ref_dir, row_twist) if texture else np.zeros(n_rows)
    return Frusta(base=rows.base, axis=rows.axis, length=rows.length, r1=rows.r1, r2=rows.r2,
                  plane_lo=rows.plane_lo, plane_hi=rows.plane_hi, ref_dir=ref_dir,
                  u_offset=u_offset, twist=row_twist, material=row_material, shell=row_shell,
                  segment=rows.segment, material_names=skeleton.material_names,
                  parent_row=rows.parent_row, report=report)


# ============================================================================ working state
@dataclass
class _Segments:
    """Per skeleton segment (n), as skinning refines them: ``base`` (n, 3) (side branches
    move back into their parent), unit ``axis`` (n, 3), ``length`` (n,), radii ``r_start``
    and ``r_end`` (n,) (seam fitting changes continuing children's ``r_start``)."""

    base: np.ndarray
    axis: np.ndarray
    length: np.ndarray
    r_start: np.ndarray
    r_end: np.ndarray

    @property
    def slope(self) -> np.ndarray:
        """(n,) k of every segment's cone."""
        return cone_slope(self.r_start, self.r_end, self.length)


@dataclass(frozen=True)
class _Joints:
    """The j continuing joints: ``child`` and ``parent`` (j,) segment indices, the joint
    ``point`` J (j, 3) (the child's skeleton start), the unit axes ``parent_axis`` M1 and
    ``child_axis`` M2 (j, 3)."""

    child: np.ndarray
    parent: np.ndarray
    point: np.ndarray
    parent_axis: np.ndarray
    child_axis: np.ndarray


@dataclass
class _Rows:
    """The rows of the frusta being built (segments and knuckle fan slices): the
    contract's arrays that skinning lays out before the texture frames."""

    base: np.ndarray
    axis: np.ndarray
    length: np.ndarray
    r1: np.ndarray
    r2: np.ndarray
    plane_lo: np.ndarray
    plane_hi: np.ndarray
    segment: np.ndarray
    parent_row: np.ndarray

    @classmethod
    def empty(cls, n_rows: int) -> _Rows:
        return cls(np.empty((n_rows, 3)), np.empty((n_rows, 3)), np.empty(n_rows), np.empty(n_rows),
                   np.empty(n_rows), np.empty((n_rows, 4)), np.empty((n_rows, 4)),
                   np.empty(n_rows, dtype=np.int64), np.full(n_rows, -1, dtype=np.int64))


# ============================================================================ segments
def _segments_and_joints(skeleton: Skeleton, extend_side_branches: bool):
    """The segments as skinning starts from them (:class:`_Segments`: side branches moved
    into their parents when ``extend_side_branches``), the continuing joints
    (:class:`_Joints`) and (s,) the side branches."""
    axis, length = _segment_axes(skeleton)
    seg = _Segments(skeleton.start.copy(), axis, length, skeleton.r_start.copy(),
                    skeleton.r_end.copy())
    child, side = continuing_children(skeleton)
    if extend_side_branches and side.size:
        _extend_side_branches(seg, skeleton.start, skeleton.parent[side], side)
    parent = skeleton.parent[child]
    point, parent_axis, child_axis = by_rows(lambda c, p: (skeleton.start[c], seg.axis[p], seg.axis[c]), child, parent)
    return seg, _Joints(child, parent, point, parent_axis, child_axis), side


def _segment_axes(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) unit axes and (n,) lengths of the segments; a zero-length segment points up
    and gets a length of ``tol.zero_length`` times its size."""
    def block(start, end, r_start, r_end):          # row-wise (by_rows)
        vec = end - start
        length = norm(vec)
        up = np.broadcast_to(np.array([0.0, 1.0, 0.0]), (len(vec), 3))
        axis = np.where(length[:, None] > 0, vec / np.where(length > 0, length, 1)[:, None], up)
        size = np.maximum(np.maximum(r_start, r_end), 1.0)
        return axis, np.where(length > 0, length, tol.zero_length * size)
    return by_rows(block, skeleton.start, skeleton.end, skeleton.r_start, skeleton.r_end)


def continuing_children(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """(j,) the continuing child of each parent that has one (the first marked
    ``continues``) and (s,) the side branches (every other segment with a parent)."""
    n = len(skeleton)
    parent = skeleton.parent
    cont = skeleton.continues & (parent >= 0)
    first_child = np.full(n, -1, dtype=np.int64)
    cand = np.flatnonzero(cont)[::-1]
    first_child[parent[cand]] = cand         # last write wins: the lowest index
    cont &= first_child[np.maximum(parent, 0)] == np.arange(n)
    return np.flatnonzero(cont), np.flatnonzero((parent >= 0) & ~cont)


def lead_forks(skeleton: Skeleton, max_bend_deg: float = FORK_LEAD_MAX_BEND_DEG) -> Skeleton:
    """The skeleton with one child of every fork continuing its parent (unchanged where
    there is no fork to lead; applying it twice changes nothing).

    A *fork* is a segment no child continues, with side branches of its material starting
    at its end point (L-system forks ``F [ +K ] [ -K ]`` bracket every child). Its end would
    be an open row, capped by a flat disc, with the children, thinner, standing on that
    disc: a collar at every fork. Its *leader*, the least bent of its thickest children
    (radii within ``tol.radius_step`` of the thickest; then the first), becomes the
    parent's continuing child, its base radius the parent's end radius: the parent flows
    into the leader in one surface (seam, texture frame and normals shared at the joint
    plane) that tapers to the leader's own radius along the leader's first segment, and
    the fork's other children grow out of that surface (side branches, started inside the
    parent). Children bent by more than ``max_bend_deg`` do not lead.

    The skeleton returned is marked as led at ``max_bend_deg`` (kept with it, as a Frusta
    keeps its box): leading it again at that angle returns it at once (a still render
    leads at rest, then skins, which leads again)."""
    if skeleton.__dict__.get("_led_at") == max_bend_deg:
        return skeleton
    led_skeleton = _lead_forks(skeleton, max_bend_deg)
    object.__setattr__(led_skeleton, "_led_at", max_bend_deg)
    return led_skeleton


def _lead_forks(skeleton: Skeleton, max_bend_deg: float) -> Skeleton:
    """:func:`lead_forks`' work: the skeleton itself where no fork is led."""
    n = len(skeleton)
    child, side = continuing_children(skeleton)
    if side.size == 0:
        return skeleton
    parent = skeleton.parent
    led = np.zeros(n, dtype=bool)
    led[parent[child]] = True
    host = parent[side]
    d_host = skeleton.end[host] - skeleton.start[host]
    d_side = skeleton.end[side] - skeleton.start[side]
    cos_b = dot(d_host, d_side) / np.maximum(norm(d_host) * norm(d_side), tol.tiny)
    size = np.maximum(np.maximum(skeleton.r_end[host], norm(d_host)), tol.tiny)
    at_end = norm(skeleton.start[side] - skeleton.end[host]) <= tol.same_length * size
    ok = (~led[host] & at_end & (skeleton.material[side] == skeleton.material[host])
          & (norm(d_side) > 0) & (cos_b > np.cos(np.radians(max_bend_deg))))
    if not ok.any():
        return skeleton
    cand, host, cos_b = side[ok], host[ok], cos_b[ok]
    radius = skeleton.r_start[cand]
    thickest = np.zeros(n)
    np.maximum.at(thickest, host, radius)
    thin = radius < (1.0 - tol.radius_step) * thickest[host]   # within radius_step: as thick
    order = np.lexsort((cand, -cos_b, thin, host))               # by host, best first
    first = np.ones(len(order), dtype=bool)
    first[1:] = host[order][1:] != host[order][:-1]
    leader = cand[order][first]
    continues, r_start = skeleton.continues.copy(), skeleton.r_start.copy()
    continues[leader] = True
    r_start[leader] = skeleton.r_end[parent[leader]]
    return dataclasses.replace(skeleton, r_start=r_start, continues=continues)


def _extend_side_branches(seg: _Segments, start, host, side) -> None:
    """Move the bases of side branches ``side`` (s,) back into their ``host`` (s,) segments
    along their own axes, keeping their slopes (in place).

    Far enough back that the base disc's rim is below the parent's end plane
    (rc·tan β), not so far that the rim leaves the parent's side ((rp - rc)/sin β):
    moving the base back by δ puts its centre δ·sin β off the parent's axis, so its rim
    stays inside the parent while δ·sin β + rc <= rp.
    """
    rp_side, rc_side = seg.r_end[host], seg.r_start[side]
    cos_b = np.clip(dot(seg.axis[side], seg.axis[host]), -1.0, 1.0)
    sin_b = np.sqrt(1.0 - cos_b * cos_b)
    room = np.maximum(rp_side - rc_side, 0.0) / np.maximum(sin_b, tol.parallel)
    need = np.where(cos_b > tol.parallel, rc_side * sin_b / np.maximum(cos_b, tol.parallel), np.inf)
    delta = np.minimum(need, room)
    k_side = cone_slope(seg.r_start[side], seg.r_end[side], seg.length[side])
    seg.base[side] = start[side] - delta[:, None] * seg.axis[side]
    seg.r_start[side] = np.maximum(seg.r_start[side] - k_side * delta, 0.0)
    seg.length[side] = seg.length[side] + delta


def material_shell(skeleton: Skeleton, shell, radius):
    """(n,) absolute shell thickness per segment from the per-material table ``shell``
    (see :func:`skin_skeleton`) and the (n,) radii its fractions apply to (each segment's
    larger end radius: the shell bounds a relief v·r(y) deep)."""
    table = dict(relief.DEFAULT_SHELL) if shell is None else dict(shell)
    per_mat = np.array([float(table.get(name, relief.default_shell(name) if shell is None else 0.0))
                        for name in skeleton.material_names] or [0.0])
    frac = per_mat[skeleton.material] if len(skeleton) else np.zeros(0)
    # positive: fraction of the radius; negative: absolute thickness -value
    return np.where(frac >= 0, frac * radius, -frac)


# ============================================================================ joint planes
def _joint_planes(J, M1, M2, rp, rc, kp, kc):
    """Cutting planes (3)–(5) at m joints, blended into the bisector where ill-conditioned.

    J (m, 3) joint points; M1, M2 (m, 3) unit axes of parent and child; rp, rc (m,) radii
    at J of parent and child; kp, kc (m,) slopes. Where the axes are collinear the medial
    plane's normal is any vector ⟂ M1 (the paper's coordinate-axis fallback).

    The boundary lines of each side σ = ±1 in the medial plane are
    J + σ·rp·n1 + s·(M1 + σ·kp·n1) and J + σ·rc·n2 + s·(M2 + σ·kc·n2), n_i = M_i × N_m.
    Their crossing is A (σ = +1) or B (σ = -1). Where the two boundary lines of a side are
    close to parallel (their cross product below half that of the axes: the bend equals
    the difference of the half-angles) the crossing of the axis-parallel lines through the
    same rim points stands in, blended by a smoothstep in that ratio (0.25..0.5).
    F_σ = J + σ·r̄·n_b is the rim point of the bisector plane (n_b = normalize(n1 + n2),
    r̄ = (rp + rc)/2, bisector direction b = normalize(M1 + M2)). Split A - F = o·b + g·n_b;
    the point used is F + w·o·b + clip(g, ±4r̄)·n_b with w = 1 while |o| <= r̄ and
    w = (r̄/|o|)^4 beyond, so a crossing that runs away (nearly parallel boundary lines,
    radius steps at small bends) fades continuously into the bisector plane, which is the
    perpendicular plane at zero bend; no threshold switches the construction.

    Returns plane normals (m, 3) (oriented along M1 + M2), plane points (m, 3), and the
    medial normal N_m (m, 3).
    """
    nm = _medial_normal(M1, M2)
    n1, n2 = cross(M1, nm), cross(M2, nm)
    nb = unit(n1 + n2, n1)
    bis = unit(M1 + M2, cross(nm, nb))
    rbar = 0.5 * (rp + rc)
    scale = np.maximum(rbar, tol.tiny)
    pts = []
    for sigma in (1.0, -1.0):
        p1 = J + sigma * rp[:, None] * n1
        p2 = J + sigma * rc[:, None] * n2
        d1 = M1 + sigma * kp[:, None] * n1
        d2 = M2 + sigma * kc[:, None] * n2
        s_slope, den = _line_crossing(p1, d1, p2, d2, nm, scale)
        s_cyl, den_cyl = _line_crossing(p1, M1, p2, M2, nm, scale)
        # conditioning of the slope lines' crossing relative to the axis-parallel lines'
        q = np.abs(den) / np.maximum(np.abs(den_cyl), tol.tiny)
        x = np.clip((q - 0.25) / 0.25, 0.0, 1.0)
        w_slope = x * x * (3 - 2 * x)
        A = (w_slope[:, None] * (p1 + s_slope[:, None] * d1)
             + (1 - w_slope)[:, None] * (p1 + s_cyl[:, None] * M1))
        F = J + sigma * rbar[:, None] * nb
        # offset of A from the bisector plane (along the bisector direction)
        off = dot(A - F, bis)
        with np.errstate(over="ignore", invalid="ignore"):
            w = np.where(np.abs(off) <= scale, 1.0, (scale / np.maximum(np.abs(off), scale)) ** 4)
        w = np.where(np.isfinite(off), w, 0.0)
        along = dot(A - F, nb)
        along = np.where(np.isfinite(along), np.clip(along, -4 * scale, 4 * scale), 0.0)
        pts.append(F + (w * np.where(np.isfinite(off), off, 0.0))[:, None] * bis
                   + along[:, None] * nb)
    A, B = pts
    normal = cross(A - B, nm)
    normal = unit(normal, unit(M1 + M2, M1))
    normal = np.where((dot(normal, bis) < 0)[:, None], -normal, normal)
    return normal, 0.5 * (A + B), nm


def _medial_normal(M1, M2):
    """(m, 3) unit normal N_m of the medial plane (3) of unit axes M1, M2 (m, 3), ⟂ M1 to
    round-off at every bend; where they are collinear, any vector ⟂ M1 (the paper's
    coordinate-axis fallback)."""
    axes_cross = cross(M1, M2)
    sin_t = norm(axes_cross)
    nm = axes_cross / np.where(sin_t > tol.tiny, sin_t, 1.0)[:, None]
    collinear = sin_t <= tol.tiny
    if collinear.any():
        nm[collinear] = cross(M1[collinear], any_perpendicular(M1[collinear]))
    # M1 × M2 of nearly collinear axes loses digits to cancellation (relative error
    # 1e-16 / sin of the bend), also along M1: remove that part so N_m ⟂ M1 exactly
    return unit(nm - dot(nm, M1)[:, None] * M1)


def _sphere_planes(J, M1, M2, rp, rc, kp, kc):
    """The joint planes that close the seam exactly (arguments as :func:`_joint_planes`).

    A cone of revolution r = r1 + k·y touches the sphere around an axis point J of radius
    ρ = r(J)/sqrt(1 + k²) along a circle (ρ is the distance from J to the cone's
    generators). Two cones that touch the same sphere meet in two plane conics (two
    quadrics inscribed in one quadric intersect in plane curves), so when
    ``rp/sqrt(1 + kp²) = rc/sqrt(1 + kc²)`` (:func:`seam_radii` makes it so) the plane of
    one of those conics cuts both cones in the same ellipse: the seam is closed, not
    nearly closed. In the medial plane each side's two boundary lines are tangent to the
    circle of radius ρ around J, at the unit directions e_p = (σ·n1 - kp·M1)/sqrt(1 + kp²)
    and e_c = (σ·n2 - kc·M2)/sqrt(1 + kc²); they cross at J + ρ·(e_p + e_c)/(1 + e_p·e_c)
    (A for σ = +1, B for σ = -1: the paper's (4)-(5) points, found without intersecting
    two nearly parallel lines: at a steep taper the two lines of one side nearly coincide,
    and their crossing is then near their common tangent point). The plane holds A and B
    and is ⟂ the medial plane. With unequal ρ (a radius step, capped on both sides) the
    mean ρ is used. Points are found relative to J, so far from the origin the plane's
    direction keeps its digits. Where 1 + e_p·e_c vanishes (the lines are parallel on
    opposite sides of the circle, a fold-back) the plane falls back to the bisector; such a
    joint is a knuckle anyway (:func:`_sharp_joints`).

    Returns plane normals (m, 3) (oriented along M1 + M2), plane points (m, 3), and the
    medial normal N_m (m, 3).
    """
    nm = _medial_normal(M1, M2)
    n1, n2 = cross(M1, nm), cross(M2, nm)
    sp, sc = np.sqrt(1.0 + kp * kp)[:, None], np.sqrt(1.0 + kc * kc)[:, None]
    rho = 0.5 * (rp[:, None] / sp + rc[:, None] / sc)
    rel = []
    parallel = np.zeros(len(J), dtype=bool)
    for sigma in (1.0, -1.0):
        ep = (sigma * n1 - kp[:, None] * M1) / sp
        ec = (sigma * n2 - kc[:, None] * M2) / sc
        den = 1.0 + dot(ep, ec)
        far = den <= tol.parallel
        parallel |= far
        rel.append(rho * (ep + ec) / np.where(far, 1.0, den)[:, None])
    bis = unit(M1 + M2, cross(nm, unit(n1 + n2, n1)))
    normal = unit(cross(rel[0] - rel[1], nm), bis)
    normal = np.where((dot(normal, bis) < 0)[:, None], -normal, normal)
    point = J + 0.5 * (rel[0] + rel[1])
    if parallel.any():
        normal[parallel], point[parallel] = bis[parallel], J[parallel]
    return normal, point, nm


def sphere_base_radius(rho, r_end, length):
    """(m,) the base radius r1 of cones ending in ``r_end`` (m,) after ``length`` (m,)
    whose generators keep the distance ``rho`` (m,) from the base centre:
    r1/sqrt(1 + k²) = ρ with k = (r_end - r1)/length. Squared, a quadratic in r1; its
    positive root, written without cancellation, is
    ρ·(L² + R²) / (ρ·R + L·sqrt(L² + R² - ρ²)). NaN where there is none: the end rim lies
    within the sphere (L² + R² <= ρ²), so no generator through it can touch the sphere."""
    ll = length * length + r_end * r_end
    outside = ll > rho * rho
    den = rho * r_end + length * np.sqrt(np.where(outside, ll - rho * rho, 0.0))
    ok = outside & (den > 0)
    return np.where(ok, rho * ll / np.where(ok, den, 1.0), np.nan)


def seam_radii(r_start, r_end, length, parent, child) -> np.ndarray:
    """Set the base radii of the continuing children ``child`` (j,) of ``parent`` (j,) in
    ``r_start`` (n,) (in place) so that at every joint the two cones touch one sphere
    around the joint (see :func:`_sphere_planes`): r1 = ``sphere_base_radius`` of the
    parent's ρ = r_end/sqrt(1 + k²). ``r_end`` and ``length`` are kept, so a child's slope
    changes with its r1, and so does ρ at its own joint below: chains are resolved from
    their roots, one joint per chain at a time. The shape changes little where it did not
    already gap: ρ is unchanged between cones of equal slope, and the radius moves by
    about r·(k_c² - k_p²)/2 for small slopes (§2.2's fit, which iterates to this).

    Returns (j,) bool: the joints with no such radius (:func:`sphere_base_radius` is NaN);
    their children keep their radius, and the caller must make them knuckles."""
    n = len(r_start)
    j = len(child)
    joint_of_child = np.full(n, -1, dtype=np.int64)
    joint_of_child[child] = np.arange(j)
    above = joint_of_child[parent]            # the joint whose child is this joint's parent
    below = np.full(j, -1, dtype=np.int64)
    below[above[above >= 0]] = np.flatnonzero(above >= 0)
    failed = np.zeros(j, dtype=bool)
    frontier = np.flatnonzero(above < 0)
    while frontier.size:
        p, c = parent[frontier], child[frontier]
        kp = cone_slope(r_start[p], r_end[p], length[p])
        rho = r_end[p] / np.sqrt(1.0 + kp * kp)
        r1 = sphere_base_radius(rho, r_end[c], length[c])
        none = np.isnan(r1)
        failed[frontier] = none
        r_start[c] = np.where(none, r_start[c], r1)
        frontier = below[frontier]
        frontier = frontier[frontier >= 0]
    return failed


def _line_crossing(p1, d1, p2, d2, nm, scale):
    """Where the lines p1 + s·d1 and p2 + s'·d2 (m, 3) of the planes ⟂ ``nm`` (m, 3) cross:
    s (m,) along the first line, clipped to ±``tol.runaway``·``scale`` (m,), and the
    denominator (d1 × d2)·nm (m,) (0: parallel lines)."""
    den = dot(cross(d1, d2), nm)
    num = dot(cross(p2 - p1, d2), nm)
    s = num / np.where(np.abs(den) > tol.tiny, den, tol.tiny)
    return np.clip(s, -tol.runaway * scale, tol.runaway * scale), den


def _seam_mismatch_at(seg: _Segments, k, par, child, point, rc) -> np.ndarray:
    """(m,) minor semi-axis of the parent's cut minus the child's at joint planes through
    ``point`` (m, 3), at the joints of segments ``par`` and ``child`` (m,), the children
    starting with radii ``rc`` (m,) (§2.2); ``k`` (n,) the segments' slopes. Row-wise."""
    b_parent = minor_semi_axis(point, seg.base[par], seg.axis[par], seg.r_start[par], k[par])
    kc = cone_slope(rc, seg.r_end[child], seg.length[child])
    return b_parent - minor_semi_axis(point, seg.base[child], seg.axis[child], rc, kc)


def _paper_mismatch(seg: _Segments, joints: _Joints, k, rp, rc, rows) -> np.ndarray:
    """(r,) |seam mismatch| / rp with the paper's planes (:func:`_joint_planes`) at the
    joints ``rows`` (r,), the children's radii ``rc`` (j,), the parents' ``rp`` (j,),
    evaluated a block of joints at a time (:func:`by_rows`): only the planes' points are
    kept, and only at the joints measured."""
    par, child = joints.parent, joints.child

    def block(s):
        _, point, _ = _joint_planes(joints.point[s], joints.parent_axis[s], joints.child_axis[s], rp[s], rc[s],
                                    k[par[s]], k[child[s]])
        return np.abs(_seam_mismatch_at(seg, k, par[s], child[s], point, rc[s])) / np.maximum(rp[s], tol.tiny)
    return by_rows(block, rows)


def _smooth_joints(rp, rc) -> np.ndarray:
    """(j,) bool: the joints whose radii ``rp``, ``rc`` (j,) agree within ``tol.radius_step``
    (the others are radius steps: modelled, not measured as seam errors)."""
    return np.abs(rp - rc) <= tol.radius_step * np.maximum(rp, rc)


def _paper_seams(skeleton: Skeleton, extend_side_branches: bool) -> tuple[float, float]:
    """(max, mean) seam mismatch with the paper's planes on the skeleton's radii at its
    smooth joints (0, 0 without one): the report's ``before`` figures, worked out from the
    skeleton when first read (:meth:`SkinReport.measure_paper_seams`)."""
    seg, joints, _ = _segments_and_joints(skeleton, extend_side_branches)
    rp, rc = seg.r_end[joints.parent], seg.r_start[joints.child]
    smooth = _smooth_joints(rp, rc)
    if not smooth.any():
        return 0.0, 0.0
    rel = _paper_mismatch(seg, joints, seg.slope, rp, rc, np.flatnonzero(smooth))
    return float(rel.max()), float(rel.mean())


def _joint_cuts(seg: _Segments, joints: _Joints, skeleton: Skeleton, lo, hi, seam_fit: bool,
                max_bend_deg: float, report: SkinReport):
    """Cut every continuing joint: set the shared planes in ``lo`` and ``hi`` (n, 4), and
    the sharp joints' perpendicular planes, in place. Returns (j,) sharp, (j,) bends in
    degrees and (j, 3) medial normals.

    The report gets the paper's seam mismatch (§2.2: its planes, the skeleton's radii) at
    smooth joints (radii within ``tol.radius_step``; a radius step is modelled, not a seam
    error) and, with ``seam_fit``, the mismatch left at the linked joints that are not
    knuckles. With ``seam_fit`` the linked joints' children get :func:`seam_radii` (in
    ``seg.r_start``) and :func:`_sphere_planes`; a knuckle keeps the skeleton's radius
    (its fan is a cylinder of that radius), as does a joint whose child's radius would
    move more than ``tol.seam_radius_change`` or has no closing radius; as that changes the radii below it, the
    planes and knuckles are found again until no new knuckle appears. Row-wise work runs
    a block of joints at a time (:func:`by_rows`).
    """
    par, child = joints.parent, joints.child
    J, M1, M2 = joints.point, joints.parent_axis, joints.child_axis
    rp, rc0 = seg.r_end[par], seg.r_start[child].copy()
    k = seg.slope
    report.step_joints = int((~_smooth_joints(rp, rc0)).sum())
    sharp = np.zeros(len(child), dtype=bool)
    if not seam_fit:
        normal, point, nm = by_rows(_joint_planes, J, M1, M2, rp, rc0, k[par], k[child])
        _set_joint_planes(lo, hi, joints, normal, point)
        sharp, bend = _sharp_joints(seg, joints, normal, lo, hi, max_bend_deg, report)
    else:
        linked = _linked(skeleton, par, child)
        for _ in range(4):
            seg.r_start[child] = rc0
            fit = linked & ~sharp
            failed = np.zeros(len(child), dtype=bool)
            failed[fit] = seam_radii(seg.r_start, seg.r_end, seg.length, par[fit], child[fit])
            k = seg.slope
            normal, point, nm = by_rows(_sphere_planes, J, M1, M2, rp, seg.r_start[child], k[par], k[child])
            _set_joint_planes(lo, hi, joints, normal, point)
            found, bend = _sharp_joints(seg, joints, normal, lo, hi, max_bend_deg, report)
            moved = np.abs(seg.r_start[child] - rc0) > tol.seam_radius_change * np.maximum(rc0, tol.tiny)
            found |= fit & (moved | failed)
            if not (found & ~sharp).any():
                break
            sharp |= found
        report.sharp_joints = int(sharp.sum())
        left = by_rows(lambda s: np.abs(_seam_mismatch_at(seg, k, par[s], child[s], point[s], seg.r_start[child[s]]))
                       / np.maximum(rp[s], tol.tiny), np.flatnonzero(linked & ~sharp))
        report.seam_mismatch_max_after = float(left.max()) if left.size else 0.0
        report.seam_mismatch_mean_after = float(left.mean()) if left.size else 0.0
    hi[par[sharp]] = plane_through(M1[sharp], J[sharp])
    lo[child[sharp]] = plane_through(M2[sharp], J[sharp])
    return sharp, bend, nm


def _set_joint_planes(lo, hi, joints: _Joints, normal, point) -> None:
    """Share each joint's plane (normals, points (j, 3)) between its parent's ``hi`` and
    its child's ``lo`` (n, 4), in place, bit for bit."""
    child, parent = joints.child, joints.parent

    def share(s):           # a block of joints: their rows are theirs alone (one continuing child a parent)
        plane = plane_through(normal[s:s + ROW_BLOCK], point[s:s + ROW_BLOCK])
        lo[child[s:s + ROW_BLOCK]] = plane
        hi[parent[s:s + ROW_BLOCK]] = plane
    in_threads(share, range(0, len(child), ROW_BLOCK))


def _linked(skeleton: Skeleton, parent, child) -> np.ndarray:
    """(j,) bool: the joints whose child continues the chain's surface (the skeleton's radii
    agree to ``tol.same_length``); the others are radius steps, capped on both sides."""
    def linked(p, c):       # row-wise (by_rows)
        r_end0, r_start0 = skeleton.r_end[p], skeleton.r_start[c]
        return np.abs(r_end0 - r_start0) <= tol.same_length * np.maximum(r_end0, r_start0)
    return by_rows(linked, parent, child)


# ============================================================================ sharp joints
def _sharp_joints(seg: _Segments, joints: _Joints, normal, lo, hi, max_bend_deg: float,
                  report: SkinReport) -> tuple[np.ndarray, np.ndarray]:
    """(j,) bool: the joints that become knuckles, and (j,) their bends in degrees.

    Sharp: past ``max_bend_deg``; or the joint plane (normals (j, 3)) does not cut a cone
    in an ellipse (within ``tol.ellipse_margin``); or a segment next to the joint would
    have its two planes cross inside it, with the sharp joints so far given perpendicular
    planes (``lo``, ``hi`` (n, 4): the planes before that; repeated while new joints turn
    sharp). Counts go to ``report``.
    """
    n = len(seg.length)
    k = seg.slope
    par, child = joints.parent, joints.child
    M1, M2, J = joints.parent_axis, joints.child_axis, joints.point

    def joint_tests(p, c, m1, m2, nrm):     # row-wise (by_rows): the bend, past the limit, not an ellipse
        kp, kc = k[p], k[c]
        bend = np.degrees(np.arccos(np.clip(dot(m1, m2), -1, 1)))
        sin_p = np.abs(kp) / np.sqrt(1 + kp * kp)
        sin_c = np.abs(kc) / np.sqrt(1 + kc ** 2)
        return bend, bend > max_bend_deg, ((dot(nrm, m1) <= sin_p + tol.ellipse_margin)
                                           | (dot(nrm, m2) <= sin_c + tol.ellipse_margin))
    bend, past_limit, not_ellipse = by_rows(joint_tests, par, child, M1, M2, normal)
    sharp = past_limit | not_ellipse
    joint_of_child = np.full(n, -1, dtype=np.int64)
    joint_of_child[child] = np.arange(len(child))
    joint_of_parent = np.full(n, -1, dtype=np.int64)
    joint_of_parent[par] = np.arange(len(child))
    crossing_flag = np.zeros(len(child), dtype=bool)
    for _ in range(8):
        lo_now, hi_now = lo, hi
        if sharp.any():
            lo_now, hi_now = lo.copy(), hi.copy()
            hi_now[par[sharp]] = plane_through(M1[sharp], J[sharp])
            lo_now[child[sharp]] = plane_through(M2[sharp], J[sharp])
        bad_rows = by_rows(_crossing_rows, seg.base, seg.axis, seg.length, seg.r_start, seg.r_end,
                           lo_now, hi_now)
        jl, jh = joint_of_child[bad_rows], joint_of_parent[bad_rows]
        marks = np.concatenate([jl[jl >= 0], jh[jh >= 0]])
        new = marks[~sharp[marks]]
        if new.size == 0:
            break
        crossing_flag[new] = True
        sharp[new] = True
    report.bend_limit = int(past_limit.sum())
    report.not_ellipse = int((not_ellipse & ~past_limit).sum())
    report.planes_crossing = int((crossing_flag & ~past_limit & ~not_ellipse).sum())
    report.sharp_joints = int(sharp.sum())
    return sharp, bend


def _crossing_rows(base, axis, length, r1, r2, lo, hi, samples=24):
    """(n,) bool: the two planes meet inside the cone (y_hi <= y_lo on some generator) or a
    plane does not cut every generator going forward (not an ellipse)."""
    k = cone_slope(r1, r2, length)
    # cheap exclusion: axial spread of each plane over the rim vs the gap between centres
    rmax = np.maximum(np.abs(r1), np.abs(r2)) + np.abs(k) * length
    centre_y, spread = [], []
    for plane in (lo, hi):
        na = dot(plane[:, :3], axis)
        nperp = np.sqrt(np.maximum(1 - na * na, 0.0))
        den = na - np.abs(k) * nperp
        centre_y.append((plane[:, 3] - dot(plane[:, :3], base)) / np.where(na != 0, na, tol.tiny))
        rises = den > tol.section_rise
        spread.append(np.where(rises, rmax * nperp / np.where(rises, den, 1), np.inf) * (1 + np.abs(k)))
    maybe = ~(centre_y[1] - centre_y[0] > 1.01 * (spread[0] + spread[1]) + tol.zero_length * length)
    bad = np.zeros(len(length), dtype=bool)
    if maybe.any():
        m = np.flatnonzero(maybe)
        bad[m] = crossing_rows_sampled(base[m], axis[m], length[m], r1[m], r2[m], lo[m], hi[m], samples)
    return bad


def crossing_rows_sampled(base, axis, length, r1, r2, lo, hi, samples):
    """(m,) bool: on some of ``samples`` generators the planes are closer than
    ``tol.same_length`` of the row's size, in the wrong order, or one is not met."""
    k = cone_slope(r1, r2, length)
    ref = any_perpendicular(axis)
    side = cross(axis, ref)
    psi = np.linspace(0, 2 * np.pi, samples, endpoint=False)
    e = np.cos(psi)[None, :, None] * ref[:, None, :] + np.sin(psi)[None, :, None] * side[:, None, :]
    ys = []
    for plane in (lo, hi):
        y, rise = plane_height((plane[:, 3] - dot(plane[:, :3], base))[:, None],
                               dot(plane[:, :3], axis)[:, None], dot(plane[:, None, :3], e),
                               r1[:, None], k[:, None],
                               guard=lambda rise: np.where(rise > tol.generator_rise, rise,
                                                           tol.generator_rise))
        ys.append(np.where(rise > tol.generator_rise, y, np.nan))
    gap = ys[1] - ys[0]
    return ~np.all(gap > tol.same_length * np.maximum(length, np.maximum(r1, r2))[:, None], axis=1)


# ============================================================================ knuckle fans
def _row_layout(seg: _Segments, lo, hi, joints: _Joints, sharp, bend, skeleton: Skeleton,
                fan_step_deg: float):
    """The rows: each segment's row, after ``2·(m + 1)`` rows for the knuckle fan of its
    joint if that is sharp (m slices per side, ``fan_step_deg`` at most each).

    Returns the :class:`_Rows` (segment rows filled, fan rows still empty), the row of
    each segment (n,) and the fan rows before each segment (n,). A radius step in the
    skeleton (beyond ``tol.same_length``) leaves an annulus on the shared plane: such
    joints are not continuing for capping (both ends open, capped); the plane is still
    shared bit for bit.
    """
    n = len(seg.length)
    child, par = joints.child, joints.parent
    sj = np.flatnonzero(sharp)
    fan_count = np.zeros(n, dtype=np.int64)          # fan rows inserted before each segment
    if sj.size:
        theta = np.radians(bend[sj])
        steps = np.maximum(1, np.ceil(np.degrees(theta) / fan_step_deg - tol.count_rounding))
        fan_count[child[sj]] = 2 * (steps.astype(np.int64) + 1)   # outer + inner slices
    row_of_seg = np.arange(n) + np.cumsum(fan_count)
    if not sj.size:      # no fan: the segments' arrays are the rows, as they are
        rows = _Rows(seg.base, seg.axis, seg.length, seg.r_start, seg.r_end, lo, hi, np.arange(n),
                     np.full(n, -1, dtype=np.int64))
    else:
        rows = _Rows.empty(n + int(fan_count.sum()))
        rows.base[row_of_seg], rows.axis[row_of_seg], rows.length[row_of_seg] = seg.base, seg.axis, seg.length
        rows.r1[row_of_seg], rows.r2[row_of_seg] = seg.r_start, seg.r_end
        rows.plane_lo[row_of_seg], rows.plane_hi[row_of_seg] = lo, hi
        rows.segment[row_of_seg] = np.arange(n)
    linked = _linked(skeleton, par, child)
    rows.parent_row[row_of_seg[child[linked]]] = row_of_seg[par[linked]]
    return rows, row_of_seg, fan_count


def _fill_knuckle_fans(rows: _Rows, seg: _Segments, joints: _Joints, sj, bend, medial, lo, hi,
                       row_of_seg, fan_count) -> None:
    """Fill the fan rows of the sharp joints ``sj`` (s,) (see the module docstring), in
    place. ``bend`` (j,) degrees and ``medial`` (j, 3) medial normals per joint; ``lo``,
    ``hi`` (n, 4) the segments' planes."""
    child, par = joints.child, joints.parent
    cnt = fan_count[child[sj]]
    fan_joint = np.repeat(np.arange(len(sj)), cnt)
    first = np.cumsum(cnt) - cnt
    slot_all = np.arange(len(fan_joint)) - np.repeat(first, cnt)
    total = cnt[fan_joint] // 2             # slices per side
    inner = slot_all >= total
    slot = slot_all - inner * total
    m_steps = total - 1
    jj = sj[fan_joint]                          # index into joint arrays
    Jf, M1f, M2f = joints.point[jj], joints.parent_axis[jj], joints.child_axis[jj]
    th = np.radians(bend[jj])
    # slice i has its axis at angle θ·i/m; its planes at θ·(i ∓ 1/2)/m, the end slices
    # are half wedges whose outer planes are the segments' own perpendicular planes, so
    # each end slice meets its segment in the same circle
    ang0 = th * np.maximum(slot - 0.5, 0.0) / m_steps
    ang1 = th * np.minimum(slot + 0.5, m_steps) / m_steps
    first_slice, last_slice = (slot == 0)[:, None], (slot + 1 == total)[:, None]
    rot_axis = unit(cross(M1f, M2f), medial[jj])
    n0 = np.where(first_slice, M1f, rotate(M1f, rot_axis, ang0))
    n1 = np.where(last_slice, M2f, rotate(M1f, rot_axis, ang1))
    mid = np.where(first_slice, M1f,
                   np.where(last_slice, M2f, rotate(M1f, rot_axis, th * slot / m_steps)))
    t = slot / m_steps
    radius = (1 - t) * seg.r_end[par[jj]] + t * seg.r_start[child[jj]]
    fan = row_of_seg[child[jj]] - 2 * total + slot_all
    rows.base[fan] = Jf
    rows.axis[fan] = mid
    rows.length[fan] = tol.fan_length * np.maximum(radius, tol.tiny)
    rows.r1[fan] = rows.r2[fan] = radius
    rows.segment[fan] = child[jj]
    out = ~inner
    lo_out = np.where(first_slice, hi[par[jj]], plane_through(n0, Jf))
    hi_out = np.where(last_slice, lo[child[jj]], plane_through(n1, Jf))
    rows.plane_lo[fan[out]], rows.plane_hi[fan[out]] = lo_out[out], hi_out[out]
    # bit-for-bit sharing along the outer fan
    later = out & (slot > 0)
    rows.plane_lo[fan[later]] = rows.plane_hi[fan[later] - 1]
    # inner slices: the same cylinders on the other side of the hinge line, i.e. the
    # opposite dihedral wedge {n1·x >= d, n0·x <= d}: planes swapped (still facing along
    # the slice axis). They cover the inside of the bend when the segments are short
    # next to r·sin(bend); their ends are open (capped, hidden inside the knuckle).
    rows.plane_lo[fan[inner]] = rows.plane_hi[fan[inner] - total[inner]]
    rows.plane_hi[fan[inner]] = rows.plane_lo[fan[inner] - total[inner]]
    rows.parent_row[fan[out]] = np.where(slot[out] == 0, row_of_seg[par[jj[out]]], fan[out] - 1)
    last_out = out & (slot + 1 == total)
    rows.parent_row[row_of_seg[child[jj[last_out]]]] = fan[last_out]
