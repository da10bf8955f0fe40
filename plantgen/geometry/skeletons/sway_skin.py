"""Per-frame skinning of a swaying skeleton: :func:`~plantgen.geometry.skeletons.skin.skin_skeleton`
of :func:`~plantgen.geometry.skeletons.motion.pose`, with everything that does not change between
frames worked out once.

A swaying skeleton keeps its topology: which segment continues which, the side branches,
the chains of the texture frames, radii, lengths, materials. :class:`SwaySkin` keeps
those (index arrays, constants), so a frame is a few dozen numpy operations on
per-component arrays ((3, n) vectors, (n,) scalars):

* pose: every joint of an instance turns about the instance's axis k, so a segment's
  direction is its rest direction turned by the sum T of the angles on its path. T is a
  closed form in t (the sine of the wave splits into sin(2πft + φ) and cos(2πft + φ)
  terms with constant path sums); the parts of the rest directions ⟂ k are complex
  numbers in a frame ⟂ k, turned by e^(iT), and the end points are their sums along
  each root path (an Euler-tour cumulative sum: one pass, not one step per tree level);
* seams: the children's base radii that close the seams (skinning's ``seam_radii``)
  depend on radii and lengths only, not on the pose, so they are set once;
* joint planes (3)–(5): every vector of the construction lies in the medial plane, so it
  runs on 2-d coordinates in the frame (M1, n1) of each joint, both sides σ = ±1 at once;
* texture frames: the rotation-minimising transport from parent to child maps the
  frame (N_m, n1) of a joint to (N_m, n2), so a reference direction is an angle ψ in
  the frame ``any_perpendicular(axis)`` of its row, and ψ and the u offsets are sums
  along the continuing chains (the same cumulative sum).

The result equals ``skin_skeleton(pose(skeleton, rig, t))`` to float64 round-off
(tests/test_sway_skin.py) whenever no joint is sharp (no knuckle fan: past 120°, not
an ellipse cut, or planes crossing inside a segment next to a joint); :meth:`SwaySkin.skin`
returns None for such a frame and the caller skins it the general way. The frames' report
is None (the general path measures seam mismatches; nothing here reads them per frame).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...tolerances import tol
from ..vec import any_perpendicular, cross, reduce_to_root, tree_roots
from .frusta import Frusta
from .motion import SwayRig
from .skeleton import Skeleton
from .skin import continuing_children, crossing_rows_sampled, lead_forks, material_shell, seam_radii

__all__ = ["SwaySkin", "SwayPose", "PathSum", "BEND_LIMIT_COS", "SHARP_SAMPLES"]

_MAX_BEND_DEG = 120.0      # skin_skeleton's default
_TWO_PI = 2.0 * np.pi
_MIN_COS = np.cos(np.radians(_MAX_BEND_DEG))
#: The cosine of the sharpest bend a joint keeps its plane at (past it: knuckle fans).
BEND_LIMIT_COS = float(_MIN_COS)
#: Samples of each tree's wave phase in the table of where a joint may turn sharp
#: (:meth:`SwaySkin.sharp_cells`).
SHARP_SAMPLES = 128


class PathSum:
    """Sums (or products) of per-node values along every root path of a forest
    (``parent`` (n,), -1 for a root), inclusive, by pointer doubling: round r adds the
    sum of the 2^r nodes above each node, so ceil(log2(depth + 1)) vectorised rounds, each
    one gather and one add over all nodes (the jumps are worked out once)."""

    def __init__(self, parent: np.ndarray):
        n = len(parent)
        jump = np.append(np.where(parent >= 0, parent, n), n)      # slot n: past the root
        self.jumps = []
        while np.any(jump[:n] < n):
            self.jumps.append(jump)
            jump = jump.take(jump)
        self.n = n

    def __call__(self, values: np.ndarray) -> np.ndarray:
        return self._fold(values, 0, np.add)

    def product(self, values: np.ndarray) -> np.ndarray:
        """Products along the root paths (of complex rotations, say)."""
        return self._fold(values, 1, np.multiply)

    def _fold(self, values, identity, op):
        total = np.empty(self.n + 1, dtype=values.dtype)
        total[:self.n] = values
        total[self.n] = identity                 # slot n: past the root
        for jump in self.jumps:
            op(total, total.take(jump), out=total)
        return total[:self.n]


@dataclass(frozen=True, eq=False)
class SwayPose:
    """A frame's pose: ``start``, ``end``, unit ``axis`` (3, n) per component."""

    t: float
    start: np.ndarray
    end: np.ndarray
    axis: np.ndarray


class SwaySkin:
    """What :meth:`pose` and :meth:`skin` need of a swaying skeleton, computed once (see
    the module docstring). Build with :meth:`plan`."""

    @classmethod
    def plan(cls, skeleton: Skeleton, rig: SwayRig) -> SwaySkin | None:
        """The plan for ``skeleton`` moving by ``rig``, or None where the pose is not a
        turn about one axis per tree (a tree mixing instances), the skeleton is empty, or a
        seam would move a radius past ``tol.seam_radius_change`` (a knuckle in every pose)."""
        n = len(skeleton)
        par = skeleton.parent
        has_p = par >= 0
        if n == 0:
            return None
        p = par[has_p]
        for name in ("axis", "amplitude", "frequency", "phase", "max_depth"):
            values = getattr(rig, name)
            if not np.array_equal(values[has_p], values[p]):
                return None
        self = cls()
        skeleton = lead_forks(skeleton)        # as skin_skeleton does: fixed at rest, once
        self._plan_pose(skeleton, rig)
        self._plan_skin(skeleton)
        moved = np.abs(self.rc - self.r0c) > tol.seam_radius_change * np.maximum(self.r0c, tol.tiny)
        if np.any(moved[self.linked]) or self.seam_failed.any():   # knuckles in every pose
            return None
        return self

    # ------------------------------------------------------------------ pose
    def _plan_pose(self, sk: Skeleton, rig: SwayRig) -> None:
        n = len(sk)
        self.n = n
        self.tree = PathSum(sk.parent)
        d = sk.end - sk.start
        k = rig.axis
        kd = k * (k[:, 0] * d[:, 0] + k[:, 1] * d[:, 1] + k[:, 2] * d[:, 2])[:, None]
        self.parent = sk.parent
        self.along = kd.T.copy()                # (3, n) the rest directions' parts along k
        perp = d - kd
        u1 = any_perpendicular(k)
        u2 = cross(k, u1)
        self.z = np.einsum("ij,ij->i", perp, u1) + 1j * np.einsum("ij,ij->i", perp, u2)
        self.u = np.stack([u1.T, u2.T])                                   # (2, 3, n)
        roots = np.flatnonzero(sk.parent < 0)
        root_of = tree_roots(sk.parent)
        self.fixed = (sk.start[root_of] + reduce_to_root(sk.parent, kd, np.add)).T.copy()
        self.roots = roots
        self.root_start = sk.start[roots].T.copy()
        self.parent_or_self = np.where(sk.parent >= 0, sk.parent, np.arange(n))
        # T(t) = sin(2πft + φ)·CA - cos(2πft + φ)·SA with CA, SA sums along the root path
        wave = rig.amplitude / rig.max_depth
        lag = _TWO_PI * rig.depth / rig.max_depth
        self.ca = self.tree(wave * np.cos(lag))
        self.sa = self.tree(wave * np.sin(lag))
        self.omega = _TWO_PI * rig.frequency[roots]
        self.phase = rig.phase[roots]
        tree_index = np.zeros(n, dtype=np.int64)
        tree_index[roots] = np.arange(len(roots))
        self.tree_of = tree_index[root_of]
        length = np.linalg.norm(d, axis=1)
        self.zero = np.flatnonzero(length == 0)
        self.zero_from = sk.parent[self.zero]
        self.inv_length = np.where(length > 0, 1.0 / np.where(length > 0, length, 1.0), 0.0)

    def pose(self, t: float) -> SwayPose:
        """The skeleton at time ``t`` (seconds), as :func:`plantgen.geometry.skeletons.motion.pose`."""
        return self.pose_at_phase(self.omega * t + self.phase, t)

    def pose_at_phase(self, x: np.ndarray, t: float = 0.0) -> SwayPose:
        """The skeleton with tree j at wave phase ``x[j]`` (radians: 2πf·t + φ at time t),
        stamped with time ``t``."""
        total = np.sin(x).take(self.tree_of)
        total *= self.ca
        total -= np.cos(x).take(self.tree_of) * self.sa
        turn = np.empty(self.n, dtype=complex)           # e^(i·total)
        np.cos(total, out=turn.real)
        np.sin(total, out=turn.imag)
        end = self._ends(turn)
        start = end.take(self.parent_or_self, axis=1)
        start[:, self.roots] = self.root_start
        axis = end - start
        axis *= self.inv_length
        if self.zero.size:
            axis[:, self.zero] = np.array([[0.0], [1.0], [0.0]])
        return SwayPose(float(t), start, end, axis)

    def _ends(self, turn: np.ndarray) -> np.ndarray:
        """(3, n) end points with each segment's ⟂ part turned by ``turn`` (n,) complex."""
        turned = self.tree(turn * self.z)
        end = self.u[0] * turned.real
        end += self.fixed
        end += self.u[1] * turned.imag
        for i, p in zip(self.zero, self.zero_from, strict=True):   # zero length: end = start
            end[:, i] = end[:, p] if p >= 0 else self.root_start[:, self.tree_of[i]]
        return end

    def turn_amplitude(self) -> np.ndarray:
        """(n,) the largest total turn (radians) each segment reaches: |T(t)| <= hypot(CA, SA)."""
        return np.hypot(self.ca, self.sa)

    def reach_box(self, pad: np.ndarray) -> np.ndarray:
        """(2, 3) world box that holds every segment's frustum in every pose: each end
        point moves at most sum over its root path of |z|·|e^(iT) - 1| (<= 2·sin(T_max / 2))
        from where it rests, and ``pad`` (n,) bounds how far a row's surface reaches past
        its end points (radius, relief shell, oblique cuts, a side branch's base)."""
        rest = self._ends(np.ones(self.n, dtype=complex))
        swing = 2.0 * np.sin(np.minimum(self.turn_amplitude(), np.pi) / 2.0)
        move = self.tree(np.abs(self.z) * swing)
        start = rest.take(self.parent_or_self, axis=1)
        start[:, self.roots] = self.root_start
        move_start = np.where(self.parent_or_self == np.arange(self.n), 0.0, move.take(self.parent_or_self))
        reach = [np.asarray(pad) + move, np.asarray(pad) + move_start]
        lo = np.minimum((rest - reach[0]).min(axis=1), (start - reach[1]).min(axis=1))
        hi = np.maximum((rest + reach[0]).max(axis=1), (start + reach[1]).max(axis=1))
        return np.stack([lo, hi])

    def drift(self, dx: float) -> float:
        """The farthest any point of a row's surface moves when its tree's wave phase
        changes by ``dx`` radians: a segment's turn changes by at most hypot(CA, SA)·dx,
        which moves its end by |z| times that, summed down its root path, and its surface
        (radius and shell) about its axis."""
        rate = self.turn_amplitude()
        reach = np.maximum(np.abs(self.r_start), np.abs(self.r_end)) + self.constant["shell"]
        return float(np.max(self.tree(np.abs(self.z) * rate) + reach * rate) * abs(dx)) if self.n else 0.0

    # ------------------------------------------------------------------ sharp frames
    def sharp_cells(self) -> np.ndarray:
        """(trees, :data:`SHARP_SAMPLES`) bool, worked out once: True where tree j's wave
        phase in [2πk/K, 2π(k+1)/K) may make one of its joints sharp (:meth:`skin` would
        return None). A tree's shape is a function of its phase alone, so each test of
        :meth:`skin` (the bend limit, the two ellipse cuts, the planes' room) is sampled
        at K phases, all trees at once; a cell is safe when the test's slack at both of its
        ends exceeds twice the most it changes from one sample to the next anywhere (a
        smooth slack cannot dip from there to 0 inside the cell)."""
        if self._sharp is None:
            k = SHARP_SAMPLES
            trees = len(self.roots)
            with np.errstate(all="ignore"):
                slack = np.stack([self._slack(self.pose_at_phase(np.full(trees, x)))
                                  for x in np.arange(k) * (_TWO_PI / k)])
                after = np.roll(slack, -1, axis=0)
                finite = np.isfinite(slack) & np.isfinite(after)
                step = np.where(finite, np.abs(after - slack), 0.0)
                margin = 2.0 * step.max(axis=0)
                risky = ~(np.minimum(slack, after) > margin)              # (K, tests)
            cells = np.zeros((trees, k), dtype=bool)
            np.logical_or.at(cells, self._test_tree, risky.T)
            self._sharp = cells
            self._sharp_trees = np.flatnonzero(cells.any(axis=1))
        return self._sharp

    def may_be_sharp(self, t: float) -> bool:
        """Whether a joint may be sharp at time ``t`` (:meth:`sharp_cells`; False means
        :meth:`skin` returns frusta, not None)."""
        cells = self.sharp_cells()
        trees = self._sharp_trees
        if not trees.size:
            return False
        x = np.mod(self.omega[trees] * float(t) + self.phase[trees], _TWO_PI)
        cell = np.minimum((x * (SHARP_SAMPLES / _TWO_PI)).astype(np.int64), SHARP_SAMPLES - 1)
        return bool(cells[trees, cell].any())

    def _slack(self, posed: SwayPose) -> np.ndarray:
        """(tests,) the slack of each of :meth:`skin`'s tests in ``posed``, above 0 where
        it passes: per joint the bend limit and the two ellipse cuts, per row next to a
        joint its planes' room (call under ``np.errstate``: a sharp joint gives NaN)."""
        seg = _FrameSegments.of(self, posed)
        values: list = []
        joints = _frame_joints(self, posed, seg, values)
        return np.concatenate([*values, self._crossing_room(seg, joints)[self.at_joint]])

    def skeleton(self, posed: SwayPose, like: Skeleton) -> Skeleton:
        """``posed`` as a Skeleton with the radii, topology and materials of ``like``."""
        return Skeleton(posed.start.T, posed.end.T, like.r_start, like.r_end, like.parent,
                        like.continues, like.material, like.material_names)

    # ------------------------------------------------------------------ skin
    def _plan_skin(self, sk: Skeleton) -> None:
        n = self.n
        child, side = continuing_children(sk)
        par = sk.parent[child]
        self.child, self.par, self.side, self.host = child, par, side, sk.parent[side]
        size = np.maximum(np.maximum(sk.r_start, sk.r_end), 1.0)
        rest = np.linalg.norm(sk.end - sk.start, axis=1)
        self.length = np.where(rest > 0, rest, tol.zero_length * size)
        r0p, r0c = sk.r_end[par], sk.r_start[child]
        self.r0c = r0c
        stepped = np.abs(r0p - r0c) > tol.same_length * np.maximum(r0p, r0c)
        self.linked = np.flatnonzero(~stepped)          # joints whose child continues the chain
        # the seams' radii do not depend on the pose: set once (skinning's seam_radii)
        self.r_start, self.r_end = sk.r_start.copy(), sk.r_end.copy()
        self.seam_failed = seam_radii(self.r_start, self.r_end, self.length, par[~stepped], child[~stepped])
        self.slope = (self.r_end - self.r_start) / self.length
        self.side_slope = self.slope[side]
        self.side_r_start, self.side_r_end = self.r_start[side], self.r_end[side]
        self.side_length = self.length[side]
        self.side_room = np.maximum(self.r_end[self.host] - self.r_start[side], 0.0)
        self.rp, self.rc = self.r_end[par], self.r_start[child]
        self.abs_r_end = np.abs(self.r_end)
        parent_row = np.full(n, -1, dtype=np.int64)
        parent_row[child[~stepped]] = par[~stepped]
        self.parent_row = parent_row
        self.chains = PathSum(parent_row)
        self.lo_free = np.setdiff1d(np.arange(n), child)
        self.hi_free = np.setdiff1d(np.arange(n), par)
        self.at_joint = np.zeros(n, dtype=bool)
        self.at_joint[child] = self.at_joint[par] = True
        self.link_par, self.link_child = par[self.linked], child[self.linked]
        kc = self.slope[child]
        self.sin_c = np.abs(kc) / np.sqrt(1 + kc * kc)
        sigma = np.array([[1.0], [-1.0]])               # (2, 1): the joint's two sides
        sc = np.sqrt(1.0 + kc * kc)
        self.medial = {"sigma": sigma, "rp": self.rp, "rho_c": self.rc / sc,
                       "ec_m": -kc / sc, "ec_n": sigma / sc}
        thick_end = np.maximum(self.r_start, self.r_end)     # as skinning: seam radii, not moved sides
        self.constant = {"twist": np.zeros(n), "material": sk.material.astype(np.int32),
                         "shell": material_shell(sk, None, thick_end), "segment": np.arange(n),
                         "v_part": np.tile(np.array([0, 1], np.int64), (n, 1))}
        for arr in (self.r_start, self.r_end, self.length):
            arr.setflags(write=False)
        self.material_names = tuple(str(m) for m in sk.material_names)
        self.open_lo = parent_row < 0
        self.open_hi = np.ones(n, dtype=bool)
        self.open_hi[parent_row[parent_row >= 0]] = False
        for arr in (*self.constant.values(), parent_row, self.open_lo, self.open_hi):
            arr.setflags(write=False)
        joint_tree = self.tree_of[child]
        self._test_tree = np.concatenate([joint_tree, joint_tree, joint_tree, self.tree_of[self.at_joint]])
        self._sharp = self._sharp_trees = None

    def skin(self, posed: SwayPose) -> Frusta | None:
        """The frusta of ``posed``, equal to ``skin_skeleton`` of it (to round-off), or None
        if a joint is sharp (the caller then skins the general way)."""
        seg = _FrameSegments.of(self, posed)
        joints = _frame_joints(self, posed, seg)
        if joints is None or self._planes_cross(seg, joints):
            return None
        turn, u_offset = _texture_frames(self, seg, joints)
        n = self.n
        ref = np.empty((n, 3))
        np.multiply(seg.e1, turn.real, out=ref.T)
        ref.T[...] += seg.e2 * turn.imag
        lo, hi = np.empty((n, 4)), np.empty((n, 4))
        for rows, ends, joint_rows in ((lo, seg.base, self.child), (hi, seg.end, self.par)):
            rows.T[:3] = seg.axis
            rows.T[3] = _dot3(seg.axis, ends)            # free ends: ⟂ the axis
            rows.T[:, joint_rows] = joints.plane
        rows = dict(self.constant, base=_rows(seg.base), axis=_rows(seg.axis), length=seg.length,
                    r1=seg.r1, r2=self.r_end, plane_lo=lo, plane_hi=hi, ref_dir=ref, u_offset=u_offset)
        return Frusta.from_rows(rows, self.material_names, self.parent_row, self.open_lo, self.open_hi)

    def _crossing_room(self, seg, joints) -> np.ndarray:
        """(n,) how far apart each row's two planes stay inside it, less the spread of
        their sections (the cheap exclusion of skinning's crossing test, on the joint
        planes; free planes are ⟂ their axes: centred at 0 and at the length, no spread):
        above 0 where they cannot cross."""
        k = np.abs(seg.slope)
        rmax = np.maximum(np.abs(seg.r1), self.abs_r_end) + k * seg.length
        centre = [np.zeros(self.n), seg.length.copy()]
        spread = [np.zeros(self.n), np.zeros(self.n)]
        gaps = (joints.gap, joints.gap + seg.length.take(self.par) * joints.alpha)
        for side, rows, na, gap in ((0, self.child, joints.n_child, gaps[0]),
                                    (1, self.par, joints.alpha, gaps[1])):
            kr = k.take(rows)
            nperp = np.sqrt(np.maximum(1 - na * na, 0.0))
            den = na - kr * nperp
            centre[side][rows] = gap / na                  # na > sin + margin > 0 here
            rises = den > tol.section_rise
            spread[side][rows] = (np.where(rises, rmax.take(rows) * nperp / np.where(rises, den, 1),
                                           np.inf) * (1 + kr))
        return (centre[1] - centre[0]) - (1.01 * (spread[0] + spread[1]) + tol.zero_length * seg.length)

    def _planes_cross(self, seg, joints) -> bool:
        """Whether a segment next to a joint has its two planes cross inside it
        (skinning's crossing test: its cheap exclusion here (:meth:`_crossing_room`), then
        its sampled test on the rows the exclusion leaves)."""
        maybe = ~(self._crossing_room(seg, joints) > 0)
        maybe &= self.at_joint
        if not maybe.any():
            return False
        m = np.flatnonzero(maybe)
        lo = np.concatenate([seg.axis[:, m].T, np.zeros((len(m), 1))], axis=1)
        hi = lo.copy()
        lo[:, 3] = _dot3(seg.axis[:, m], seg.base[:, m])
        hi[:, 3] = _dot3(seg.axis[:, m], seg.end[:, m])
        jc = np.full(self.n, -1)
        jc[self.child] = np.arange(len(self.child))
        jp = np.full(self.n, -1)
        jp[self.par] = np.arange(len(self.par))
        lo[jc[m] >= 0] = joints.plane[:, jc[m][jc[m] >= 0]].T
        hi[jp[m] >= 0] = joints.plane[:, jp[m][jp[m] >= 0]].T
        return bool(crossing_rows_sampled(seg.base[:, m].T, seg.axis[:, m].T, seg.length[m],
                                          seg.r1[m], self.r_end[m], lo, hi, 24).any())


def _rows(soa: np.ndarray) -> np.ndarray:
    """(n, k) rows of a (k, n) per-component array."""
    out = np.empty(soa.shape[::-1])
    out.T[...] = soa
    return out


def _dot3(a, b):
    """(n,) a·b of (3, n) arrays: ((a0·b0 + a1·b1) + a2·b2), the rows summed in order."""
    return np.multiply(a, b).sum(axis=0)


_NEXT, _PREV = np.array([1, 2, 0]), np.array([2, 0, 1])


def _cross3(a, b):
    """(3, n) a × b of (3, n) arrays."""
    out = a.take(_NEXT, 0) * b.take(_PREV, 0)
    out -= a.take(_PREV, 0) * b.take(_NEXT, 0)
    return out


@dataclass
class _FrameSegments:
    """Per segment, this frame (3, n) / (n,): ``base`` (side branches moved back into
    their parent), ``end``, ``axis``, ``length``, ``r1``, ``slope``, and the texture
    helper frame ``e1`` = any_perpendicular(axis), ``e2`` = axis × e1."""

    base: np.ndarray
    end: np.ndarray
    axis: np.ndarray
    length: np.ndarray
    r1: np.ndarray
    slope: np.ndarray
    e1: np.ndarray
    e2: np.ndarray

    @classmethod
    def of(cls, plan: SwaySkin, posed: SwayPose) -> _FrameSegments:
        a = posed.axis
        base = posed.start
        length, r1, slope = plan.length, plan.r_start, plan.slope
        side = plan.side
        if side.size:
            a_s = a.take(side, 1)
            cos_b = np.minimum(np.maximum(_dot3(a_s, a.take(plan.host, 1)), -1.0), 1.0)
            sin_b = np.sqrt(1.0 - cos_b * cos_b)
            room = plan.side_room / np.maximum(sin_b, tol.parallel)
            need = np.where(cos_b > tol.parallel,
                            plan.side_r_start * sin_b / np.maximum(cos_b, tol.parallel), np.inf)
            delta = np.minimum(need, room)
            base = base.copy()
            base[:, side] -= delta * a_s
            length, r1, slope = length.copy(), r1.copy(), slope.copy()
            r1_side = np.maximum(plan.side_r_start - plan.side_slope * delta, 0.0)
            length_side = plan.side_length + delta
            r1[side] = r1_side
            length[side] = length_side
            slope[side] = (plan.side_r_end - r1_side) / length_side
        # any_perpendicular: x (z where the axis is near x) with its axis part removed
        near_x = np.abs(a[0]) >= 0.9
        e1 = a * -np.where(near_x, a[2], a[0])
        e1[0] += ~near_x
        e1[2] += near_x
        e1 *= 1.0 / np.sqrt(_dot3(e1, e1))
        return cls(base, posed.end, a, length, r1, slope, e1, _cross3(a, e1))


@dataclass
class _FrameJoints:
    """Per continuing joint, this frame: the shared ``plane`` (4, j); its normal's
    components ``alpha`` along M1 and ``gamma`` along n1, its cosine with M2
    (``n_child``), ``gap`` = normal·(point - J); the medial normal ``nm`` (3, j); the
    bend's cosine ``c`` and sine ``s``."""

    plane: np.ndarray
    alpha: np.ndarray
    gamma: np.ndarray
    n_child: np.ndarray
    gap: np.ndarray
    nm: np.ndarray
    c: np.ndarray
    s: np.ndarray


def _frame_joints(plan: SwaySkin, posed: SwayPose, seg: _FrameSegments, slack: list | None = None
                  ) -> _FrameJoints | None:
    """The joint planes (skinning's ``_joint_planes`` in each joint's medial frame), or
    None if a joint is past the bend limit or its plane is not an ellipse cut. With
    ``slack`` (a list), the joints are built whatever their bends and the list receives
    (j,) arrays, one per test, each above 0 where its joint passes it."""
    par, child = plan.par, plan.child
    m1, m2 = seg.axis.take(par, 1), seg.axis.take(child, 1)
    c = _dot3(m1, m2)
    if slack is None and np.any(c < _MIN_COS):
        return None
    x = _cross3(m1, m2)
    s = np.sqrt(_dot3(x, x))
    collinear = s <= tol.tiny
    if collinear.any():
        nm = x / np.where(collinear, 1.0, s)
        m1c = m1[:, collinear].T
        nm[:, collinear] = cross(m1c, any_perpendicular(m1c)).T
    else:
        nm = x * (1.0 / s)
    nm -= m1 * _dot3(nm, m1)                   # ⟂ M1 to round-off (skinning's _medial_normal)
    nm *= 1.0 / np.sqrt(_dot3(nm, nm))
    kp = seg.slope.take(par)
    alpha, gamma, xi, eta = _medial_planes(plan, c, s, kp)
    n_child = alpha * c - gamma * s
    sin_p = np.abs(kp) / np.sqrt(1 + kp * kp)
    if slack is not None:
        slack += [c - _MIN_COS, alpha - (sin_p + tol.ellipse_margin), n_child - (plan.sin_c + tol.ellipse_margin)]
    elif np.any((alpha <= sin_p + tol.ellipse_margin) | (n_child <= plan.sin_c + tol.ellipse_margin)):
        return None
    n1 = _cross3(m1, nm)
    plane = np.empty((4, len(c)))
    normal = plane[:3]
    np.multiply(alpha, m1, out=normal)
    normal += gamma * n1
    point = posed.start.take(child, 1)
    point += xi * m1
    point += eta * n1
    plane[3] = _dot3(normal, point)
    return _FrameJoints(plane, alpha, gamma, n_child, alpha * xi + gamma * eta, nm, c, s)


def _medial_planes(plan: SwaySkin, c, s, kp):
    """skinning's ``_sphere_planes`` in 2-d: coordinates along M1 and n1 = M1 × N_m of each
    joint (M2 = (c, -s), n2 = (s, c)), both sides σ = ±1 as the rows of (2, j) arrays.
    The tangent directions are e_p = (-kp, σ)/sqrt(1 + kp²) and e_c = σ·n2 - kc·M2 over
    sqrt(1 + kc²); each side's point is ρ·(e_p + e_c)/(1 + e_p·e_c). Returns the unit
    normal (alpha, gamma) and the plane point (xi, eta) relative to J, (j,) each."""
    k = plan.medial                  # constants per joint: see _plan_skin
    inv_sp = 1.0 / np.sqrt(1.0 + kp * kp)
    rho = k["rp"] * inv_sp
    rho += k["rho_c"]
    rho *= 0.5
    ep_x, ep_y = -kp * inv_sp, k["sigma"] * inv_sp          # (j,), (2, j)
    ec_x = k["ec_n"] * s                                     # σ·s/sc - kc·c/sc
    ec_x += k["ec_m"] * c
    ec_y = k["ec_n"] * c                                     # σ·c/sc + kc·s/sc
    ec_y -= k["ec_m"] * s
    den = ep_x * ec_x
    den += ep_y * ec_y
    den += 1.0
    far = den <= tol.parallel                                # parallel on opposite sides
    scale = rho / np.where(far, 1.0, den)
    pt_x = (ep_x + ec_x) * scale
    pt_y = (ep_y + ec_y) * scale
    a_x, a_y = pt_x[0] - pt_x[1], pt_y[0] - pt_y[1]
    n_x, n_y = -a_y, a_x                                     # (A - B) × N_m
    length = np.sqrt(n_x * n_x + n_y * n_y)
    ok = length > tol.tiny
    n_x, n_y = n_x / np.where(ok, length, 1.0), n_y / np.where(ok, length, 1.0)
    if not ok.all():         # A = B: the bisector's direction M1 + M2
        fb = 1.0 / np.sqrt((1.0 + c) ** 2 + s * s)
        n_x, n_y = np.where(ok, n_x, (1.0 + c) * fb), np.where(ok, n_y, -s * fb)
    flip = n_x * (1.0 + c) - n_y * s < 0
    np.negative(n_x, out=n_x, where=flip)
    np.negative(n_y, out=n_y, where=flip)
    xi, eta = 0.5 * (pt_x[0] + pt_x[1]), 0.5 * (pt_y[0] + pt_y[1])
    far = far[0] | far[1]
    if far.any():            # the bisector plane through J, as skinning falls back
        fb = 1.0 / np.sqrt((1.0 + c) ** 2 + s * s)
        n_x, n_y = np.where(far, (1.0 + c) * fb, n_x), np.where(far, -s * fb, n_y)
        xi, eta = np.where(far, 0.0, xi), np.where(far, 0.0, eta)
    return n_x, n_y, xi, eta


def _texture_frames(plan: SwaySkin, seg: _FrameSegments, joints: _FrameJoints):
    """(n,) unit complex e^(iψ): each row's reference direction in its frame (e1, e2),
    and (n,) u offsets (skinning's
    :func:`~plantgen.geometry.skeletons.texture_frames.u_offsets`), from the medial frames
    (N_m, n1) and (N_m, n2) of the linked joints, which the transport maps onto each other."""
    li = plan.linked
    p, ch = plan.link_par, plan.link_child
    nm = joints.nm.take(li, 1)
    at_p, at_c = np.empty(len(li), dtype=complex), np.empty(len(li), dtype=complex)
    for at, rows in ((at_p, p), (at_c, ch)):
        at.real = _dot3(nm, seg.e1.take(rows, 1))
        at.imag = _dot3(nm, seg.e2.take(rows, 1))
    np.conjugate(at_p, out=at_p)
    step = np.ones(plan.n, dtype=complex)
    step[ch] = at_c * at_p
    turn = plan.chains.product(step)
    turn /= np.abs(turn)
    chi = turn.take(p)
    chi *= at_p
    cos_x, sin_x = chi.real, chi.imag
    alpha, gamma = joints.alpha.take(li), joints.gamma.take(li)
    c, s = joints.c.take(li), joints.s.take(li)
    len_p, r1_p, k_p = seg.length.take(p), seg.r1.take(p), seg.slope.take(p)
    n_r = gamma * sin_x
    y = (joints.gap.take(li) + len_p * alpha - r1_p * n_r) / (alpha + k_p * n_r)
    rho = r1_p + k_p * y
    back = y - len_p
    along_ref = back * s * sin_x + rho * (cos_x * cos_x + c * sin_x * sin_x)
    along_side = back * s * cos_x + rho * sin_x * cos_x * (c - 1.0)
    local = np.zeros(plan.n)
    local[ch] = np.arctan2(along_side, along_ref) * (-1.0 / _TWO_PI)
    total = plan.chains(local)
    wrapped = total - np.floor(total)
    return turn, np.where(wrapped < 1.0, wrapped, 0.0)
