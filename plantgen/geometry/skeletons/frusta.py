"""Conical frusta: the skinned skeleton, one row per segment (Bhagvat et al. 2009, §2).

Contract (float64 on the CPU; converted to float32 only at upload):

==============  ==========  ==============================================================
``base``        (n, 3) f8   C1, the axis point where the cone's radius is ``r1``
``axis``        (n, 3) f8   unit axis direction, base towards top
``length``      (n,) f8     h, the axis length; the top point is C2 = base + h·axis
``r1``, ``r2``  (n,) f8     radii at C1 and C2; the cone is r(y) = r1 + k·y with
                            k = (r2 - r1)/h (slope form: no special case for cylinders
                            or cones closing to a point); hits with r(y) < 0 are rejected
``plane_lo``    (n, 4) f8   lower cutting plane (nx, ny, nz, d): unit normal pointing
                            roughly along ``axis``; inside iff n·x - d >= 0
``plane_hi``    (n, 4) f8   upper cutting plane, same orientation; inside iff n·x - d <= 0.
                            A continuing child's ``plane_lo`` equals its parent's
                            ``plane_hi`` bit for bit (the joint's shared plane)
``ref_dir``     (n, 3) f8   unit vector ⟂ axis, the u = 0 direction (rotation-minimising
                            frame carried along each chain)
``u_offset``    (n,) f8     added to u (§2.3) so u is continuous across joints
``twist``       (n,) f8     twist angle θ in turns; u gains v·twist
``material``    (n,) i4     index into ``material_names``
``shell``       (n,) f8     relief shell thickness (0: no relief on this segment): the bound
                            of the relief, whose depth at axial height y is
                            shell·r(y)/max(r1, r2) (:func:`relief_scale`), so a shell that
                            is a fraction of the radius is as deep on both sides of a joint
``segment``     (n,) i8     index of the skeleton segment this row came from (sharp-bend
                            splitting can give one skeleton segment several rows)
``v_part``      (n, 2) i8   (slot, slots): the row's share of the texture's v, a slot of
                            ``slots`` equal ones (default (0, 1): the whole texture, the
                            paper's); the k chords of a smoothed bend's arc take slots
                            0..k-1 of k, so the arc spans one texture period, not k
==============  ==========  ==============================================================

Besides the rows above, a :class:`Frusta` (frozen, built once) holds ``material_names``
(tuple of str), ``parent_row`` ((n,) i8, the row whose ``plane_hi`` this row shares as
its ``plane_lo``, -1 for roots and side branches), ``open_lo`` and ``open_hi`` ((n,)
bool, derived from ``parent_row``: an end is *open*, and capped with a flat disc, unless
a continuing row shares its plane) and ``report`` (a :class:`SkinReport`). A joint whose
two radii differ in the skeleton (a modelled radius step) shares its plane but leaves
``parent_row`` at -1, so both ends are capped and the annulus between the radii is
closed. Rows are ordered parent first (``parent_row[i] < i``). Skinning
(:mod:`plantgen.geometry.skeletons.skin`) builds frusta from a skeleton, sharp bends included.

u and v of a surface point P (equations (6)–(7)), with frame b = axis × ref_dir::

    u = atan2((P - C1)·b, (P - C1)·ref_dir) / 2π + u_offset + v·twist     (mod 1)
    v = |P - P_l| / |P_u - P_l|

and the texture is looked up at ``v_tex = (slot + v) / slots`` (``v_part``; u keeps the
row's own v in its twist term). Where P_l and P_u are the intersections of the generator through P (direction
axis + k·e_r, e_r the unit radial direction of P) with the lower and upper planes.
The interpolated normal (8) is normalize((1 - v)·N_l + v·N_u), N_l = normalize(P_l - C1),
N_u = normalize(P_u - C2).

Along a generator, points are C1 + y·axis + (r1' + k·y)·e_r, so the planes are met at
``y_plane = (d - n·C1 - r1'·(n·e_r)) / (n·axis + k·(n·e_r))`` (:func:`plane_height`, the
one home of this formula; ``plane_height`` in ``shaders/cone.glsl`` is its GLSL twin) and
``v = (y_P - y_l) / (y_u - y_l)``. For a point off the surface (the relief shell of §3)
r1' is the radius of the concentric cone through P, r1' = r1 + (ρ_P - r(y_P)): the shell
shares (u, v).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ...tolerances import tol
from ..vec import ROW_BLOCK, ancestor_count, cross, dot, in_threads, norm, reduce_to_root, unit

__all__ = ["Frusta", "SkinReport", "ROW_FIELDS", "PYRAMID_CORNERS", "PYRAMID_TRIANGLES",
           "parent_rows_from_planes", "cone_slope", "plane_height", "plane_heights", "cone_radius_at", "relief_scale",
           "surface_uv", "surface_normals", "true_normals", "shade_rows_uv_normals",
           "frusta_bounds", "row_end_balls", "end_balls", "section_points", "bounding_pyramids", "pyramid_volume_ratio",
           "minor_semi_axis", "seam_mismatch", "seam_gap", "facing_normals", "MAX_V_SLOTS"]

#: Names of the per-row arrays of the contract, in contract order.
ROW_FIELDS = ("base", "axis", "length", "r1", "r2", "plane_lo", "plane_hi", "ref_dir",
              "u_offset", "twist", "material", "shell", "segment", "v_part")

#: dtype of each row array (float64 unless listed).
_ROW_DTYPES = {"material": np.int32, "segment": np.int64, "v_part": np.int64}

#: trailing shape of each row array (scalar per row unless listed).
_ROW_SHAPES = {"base": (3,), "axis": (3,), "plane_lo": (4,), "plane_hi": (4,), "ref_dir": (3,), "v_part": (2,)}

#: The most texture slots one row's ``v_part`` may name (the ray caster packs slot and
#: slots into 7 bits each).
MAX_V_SLOTS = 128


def _pyramid_template() -> tuple[np.ndarray, np.ndarray]:
    """Corner ``i``: sx = ±1 (bit 0, along ref_dir), sz = ±1 (bit 1, along ref_dir × axis),
    end = bit 2 (0: on the lower plane). Triangles wind counter-clockwise seen from outside
    in the right-handed frame (ref_dir, axis, ref_dir × axis)."""
    idx = np.arange(8)
    corners = np.stack([(idx & 1) * 2 - 1, (idx >> 1 & 1) * 2 - 1, idx >> 2 & 1], axis=1)
    quads = np.array([[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6],
                      [0, 2, 6, 4], [1, 3, 7, 5]])
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    box = np.stack([corners[:, 0], corners[:, 2] * 2 - 1, corners[:, 1]], axis=1).astype(float)
    a, b, c = box[tris[:, 0]], box[tris[:, 1]], box[tris[:, 2]]
    outward = np.einsum("ij,ij->i", np.cross(b - a, c - a), (a + b + c) / 3) > 0
    tris[~outward] = tris[~outward][:, [0, 2, 1]]
    return corners.astype(np.int8), tris.astype(np.int32)


#: (8, 3) int8 corner template (sx, sz, end) and (12, 3) int32 outward triangle indices.
PYRAMID_CORNERS, PYRAMID_TRIANGLES = _pyramid_template()


@dataclass
class SkinReport:
    """What skinning did to a skeleton, for logs and benchmarks.

    ``seam_mismatch_*`` are the largest and mean difference of the minor semi-axes of the
    two elliptical cuts at continuing joints, relative to the joint radius (§2.2): ``before``
    with the paper's planes on the skeleton's radii, ``after`` as built with the seams fitted
    (``skin_skeleton(seam_fit=True)``, the default; None without). Joints with a radius step of more
    than ``tol.radius_step`` (5 %, ``step_joints``) are left out of both: their mismatch is
    modelled. The ``before`` figures are worked out when first read
    (:meth:`measure_paper_seams`): fitted seams do not need the paper's planes, and a
    render never reads them (half the skinning time of a million segments).
    """

    n_segments: int = 0
    n_rows: int = 0
    joints: int = 0                 # continuing joints (shared planes)
    side_branches: int = 0
    step_joints: int = 0            # joints with a radius step > 5 % (not measured, not fitted)
    sharp_joints: int = 0           # joints resolved by a knuckle fan
    bend_limit: int = 0             # ... of which past max_bend_deg
    not_ellipse: int = 0            # ... of which the paper's plane is not an ellipse cut
    planes_crossing: int = 0        # ... of which next to a segment whose planes cross inside it
    fan_rows: int = 0
    seam_mismatch_max_after: float | None = None
    seam_mismatch_mean_after: float | None = None
    smooth_joints: int = 0          # joints replaced by arcs (skin_skeleton(smooth_bends=...))
    smooth_segments: int = 0        # segments those arcs added before skinning
    _paper_seams: Callable[[], tuple[float, float]] | tuple[float, float] = field(
        default=(0.0, 0.0), repr=False, compare=False)

    def measure_paper_seams(self, measure: Callable[[], tuple[float, float]]) -> None:
        """Work out the ``before`` figures with ``measure()`` -> (max, mean) when first read."""
        self._paper_seams = measure

    def _paper(self) -> tuple[float, float]:
        if callable(self._paper_seams):
            self._paper_seams = tuple(self._paper_seams())
        return self._paper_seams

    @property
    def seam_mismatch_max_before(self) -> float:
        """The largest seam mismatch with the paper's planes (0 without a smooth joint)."""
        return self._paper()[0]

    @property
    def seam_mismatch_mean_before(self) -> float:
        """The mean seam mismatch with the paper's planes (0 without a smooth joint)."""
        return self._paper()[1]

    def lines(self) -> list[str]:
        s = [f"{self.n_segments} segments -> {self.n_rows} rows; {self.joints} joints, "
             f"{self.side_branches} side branches, {self.step_joints} radius steps",
             f"sharp joints split into knuckles: {self.sharp_joints} (bend limit {self.bend_limit}, "
             f"not an ellipse {self.not_ellipse}, planes crossing {self.planes_crossing}); "
             f"{self.fan_rows} fan rows",
             f"seam mismatch (minor axes, / radius): max {self.seam_mismatch_max_before:.3g}, "
             f"mean {self.seam_mismatch_mean_before:.3g}"]
        if self.seam_mismatch_max_after is not None:
            s[-1] += (f"; fitted: max "
                      f"{self.seam_mismatch_max_after:.3g}, mean {self.seam_mismatch_mean_after:.3g}")
        if self.smooth_joints:
            s.append(f"smooth bends: {self.smooth_joints} joints -> arcs, +{self.smooth_segments} segments")
        return s


def _read_only(arr: np.ndarray) -> np.ndarray:
    """A read-only view of ``arr``: a Frusta's rows are a value (renderers key kept work,
    such as a shadow map, on the object), so writing into them in place is refused."""
    view = arr.view()
    view.setflags(write=False)
    return view


@dataclass(frozen=True, eq=False)
class Frusta:
    """The rows of the contract (see the module docstring), with ``material_names``,
    ``parent_row`` (default: every row starts a chain) and ``report``; ``open_lo`` and
    ``open_hi`` are derived from ``parent_row`` at construction. Frozen, its arrays read-only
    views: a changed copy is ``dataclasses.replace(frusta, ...)``."""

    base: np.ndarray
    axis: np.ndarray
    length: np.ndarray
    r1: np.ndarray
    r2: np.ndarray
    plane_lo: np.ndarray
    plane_hi: np.ndarray
    ref_dir: np.ndarray
    u_offset: np.ndarray
    twist: np.ndarray
    material: np.ndarray
    shell: np.ndarray
    segment: np.ndarray
    v_part: np.ndarray | None = None           # None: (0, 1) for every row
    material_names: tuple[str, ...] = ("bark",)
    parent_row: np.ndarray | None = None
    report: SkinReport | None = field(default=None, repr=False)
    open_lo: np.ndarray = field(init=False, repr=False)
    """(n,) bool: the lower end is capped (no continuing row shares its plane)."""
    open_hi: np.ndarray = field(init=False, repr=False)
    """(n,) bool: the upper end is capped (no row continues this one)."""

    def __post_init__(self) -> None:
        n = len(np.asarray(self.length))
        if self.v_part is None:
            object.__setattr__(self, "v_part", np.tile(np.array([0, 1], np.int64), (n, 1)))
        for f in ROW_FIELDS:
            arr = np.ascontiguousarray(getattr(self, f), dtype=_ROW_DTYPES.get(f, np.float64))
            want = (n,) + _ROW_SHAPES.get(f, ())
            if arr.shape != want:
                raise ValueError(f"Frusta.{f} has shape {arr.shape}, expected {want}")
            object.__setattr__(self, f, _read_only(arr))
        part = self.v_part
        if n and not (np.all(part[:, 0] >= 0) and np.all(part[:, 0] < part[:, 1])
                      and part[:, 1].max() <= MAX_V_SLOTS):
            raise ValueError(f"Frusta.v_part must hold 0 <= slot < slots <= {MAX_V_SLOTS}")
        parent_row = np.full(n, -1, dtype=np.int64) if self.parent_row is None else self.parent_row
        parent_row = np.ascontiguousarray(parent_row, dtype=np.int64)
        if parent_row.shape != (n,):
            raise ValueError(f"Frusta.parent_row has shape {parent_row.shape}, expected {(n,)}")
        open_hi = np.ones(n, dtype=bool)
        open_hi[parent_row[parent_row >= 0]] = False
        object.__setattr__(self, "parent_row", _read_only(parent_row))
        object.__setattr__(self, "open_lo", _read_only(parent_row < 0))
        object.__setattr__(self, "open_hi", _read_only(open_hi))
        object.__setattr__(self, "material_names", tuple(str(m) for m in self.material_names))

    def __len__(self) -> int:
        return len(self.length)

    @property
    def n_rows(self) -> int:
        return len(self.length)

    @property
    def slope(self) -> np.ndarray:
        """(n,) k = (r2 - r1)/h, dimensionless (:func:`cone_slope`)."""
        return cone_slope(self.r1, self.r2, self.length)

    @property
    def top(self) -> np.ndarray:
        """(n, 3) C2 = base + h·axis."""
        return self.base + self.length[:, None] * self.axis

    @property
    def side_dir(self) -> np.ndarray:
        """(n, 3) b = axis × ref_dir, the u = 1/4 direction."""
        return cross(self.axis, self.ref_dir)

    @property
    def chain_position(self) -> np.ndarray:
        """(n,) int64: how many rows precede each row in its continuing chain."""
        return ancestor_count(self.parent_row)

    @property
    def v_span(self) -> np.ndarray:
        """(n,) the share of the texture's v each row spans: 1 / slots."""
        return 1.0 / self.v_part[:, 1]

    @property
    def chain_texture_v(self) -> np.ndarray:
        """(n,) float64: the texture v, counted along the row's continuing chain in periods,
        where the row starts (the sum of the spans of the rows before it): what a mesh
        adds to its rows' v so that rows sharing a ring share its texture coordinate."""
        span = self.v_span
        return reduce_to_root(self.parent_row, span, np.add) - span

    @property
    def has_length(self) -> np.ndarray:
        """(n,) bool: rows longer than ``tol.short_row`` times their larger radius, i.e.
        segments, not knuckle fan slices."""
        return self.length > tol.short_row * np.maximum(self.r1, self.r2)

    # ------------------------------------------------------------------ new frusta
    @classmethod
    def empty(cls, material_names=("bark",)) -> Frusta:
        """No rows."""
        return cls(**{f: np.zeros((0,) + _ROW_SHAPES.get(f, ()), dtype=_ROW_DTYPES.get(f, np.float64))
                      for f in ROW_FIELDS}, material_names=material_names)

    @classmethod
    def from_rows(cls, rows: dict, material_names: tuple[str, ...], parent_row: np.ndarray,
                  open_lo: np.ndarray, open_hi: np.ndarray) -> Frusta:
        """Frusta from ``rows`` (every name of ROW_FIELDS) already of the contract's dtypes
        and shapes and C-contiguous, with ``parent_row`` and the ``open_lo``, ``open_hi``
        the constructor derives from it: no checks, no copies, no report. For producers
        that build the same kind of rows every frame (plantgen.geometry.skeletons.sway_skin; its
        tests compare them with the checked constructor's); anything else uses ``Frusta(...)``."""
        self = object.__new__(cls)
        for f in ROW_FIELDS:
            object.__setattr__(self, f, rows[f])
        for name, value in (("material_names", material_names), ("parent_row", parent_row),
                            ("open_lo", open_lo), ("open_hi", open_hi), ("report", None)):
            object.__setattr__(self, name, value)
        return self

    def subset_view(self, start: int, stop: int) -> Frusta:
        """Rows ``start:stop`` as a Frusta of views (no checks, no copies, no report), for
        row-wise work a block at a time; ``parent_row`` is not re-indexed (rows whose
        parent lies outside keep its index), so only row-wise work may use it."""
        pr = self.parent_row[start:stop]
        return Frusta.from_rows({f: getattr(self, f)[start:stop] for f in ROW_FIELDS}, self.material_names, pr,
                                self.open_lo[start:stop], self.open_hi[start:stop])

    def subset(self, rows) -> Frusta:
        """The given rows ((k,) int or (n,) bool) as a new Frusta (parent_row remapped; -1
        where the parent is dropped); no report."""
        rows = np.asarray(rows)
        if rows.dtype == bool:
            rows = np.flatnonzero(rows)
        remap = np.full(len(self), -1, dtype=np.int64)
        remap[rows] = np.arange(len(rows))
        pr = self.parent_row[rows]
        pr = np.where(pr >= 0, remap[np.maximum(pr, 0)], -1)
        return Frusta(**{f: getattr(self, f)[rows] for f in ROW_FIELDS},
                      material_names=self.material_names, parent_row=pr, report=None)

    @staticmethod
    def concatenate(parts: Sequence[Frusta]) -> Frusta:
        """The rows of every part, in order, as one Frusta: parent rows re-indexed,
        material names merged (first appearance order) and material indices remapped;
        no report."""
        names: list[str] = []
        for p in parts:
            names += [m for m in p.material_names if m not in names]
        if not parts:
            return Frusta.empty()
        offsets = np.cumsum([0] + [len(p) for p in parts[:-1]])
        rows = {f: np.concatenate([getattr(p, f) for p in parts]) for f in ROW_FIELDS}
        rows["material"] = np.concatenate([
            np.array([names.index(m) for m in p.material_names], dtype=np.int32)[p.material]
            if len(p) else p.material for p in parts])
        parent = np.concatenate([np.where(p.parent_row >= 0, p.parent_row + o, -1)
                                 for p, o in zip(parts, offsets, strict=True)])
        return Frusta(**rows, material_names=tuple(names), parent_row=parent)

    def translated(self, offset) -> Frusta:
        """The same frusta moved by ``offset`` (3,) world units (planes follow)."""
        off = np.asarray(offset, dtype=np.float64)
        lo, hi = self.plane_lo.copy(), self.plane_hi.copy()
        lo[:, 3] += lo[:, :3] @ off
        hi[:, 3] += hi[:, :3] @ off
        kw = {f: getattr(self, f) for f in ROW_FIELDS}
        kw.update(base=self.base + off, plane_lo=lo, plane_hi=hi)
        return Frusta(**kw, material_names=self.material_names, parent_row=self.parent_row,
                      report=self.report)


def parent_rows_from_planes(rows) -> np.ndarray:
    """The row whose ``plane_hi`` each row shares as its ``plane_lo``, found from the
    planes alone (for row arrays that come without ``parent_row``).

    A row continues another when its lower cutting plane is bit for bit the other's
    upper plane (the contract's shared joint plane) and its base is the other's top point
    (within ``tol.joint_match`` of the row's size).

    Parameters
    ----------
    rows : any object with the contract's ``base``, ``axis``, ``length``, ``r1``, ``r2``,
        ``plane_lo`` and ``plane_hi`` arrays (n rows)

    Returns
    -------
    (n,) int64 : index of the continued row, -1 for roots, side branches and chain starts
    """
    n = len(rows.length)
    if n == 0:
        return np.zeros(0, np.int64)
    hi = np.ascontiguousarray(rows.plane_hi, dtype=np.float64).view(np.int64)
    lo = np.ascontiguousarray(rows.plane_lo, dtype=np.float64).view(np.int64)
    _, inverse = np.unique(np.concatenate([hi, lo]), axis=0, return_inverse=True)
    inverse = inverse.ravel()
    hi_key, lo_key = inverse[:n], inverse[n:]
    owner = np.full(inverse.max() + 1, -1, dtype=np.int64)
    owner[hi_key] = np.arange(n)
    parent = owner[lo_key]
    ok = (parent >= 0) & (parent != np.arange(n))
    top = rows.base + rows.length[:, None] * rows.axis
    gap = np.full(n, np.inf)
    gap[ok] = np.linalg.norm(rows.base[ok] - top[parent[ok]], axis=1)
    scale = np.maximum(np.maximum(rows.r1, rows.r2), tol.joint_match * rows.length)
    ok &= gap <= tol.joint_match * np.maximum(scale, tol.tiny)
    return np.where(ok, parent, -1)


# ============================================================================ the cone
def cone_slope(r1, r2, length):
    """(...) k = (r2 - r1)/h of cones with radii ``r1``, ``r2`` at the ends of axes of
    ``length`` (broadcast): the one home of the slope (:attr:`Frusta.slope`, and skinning
    before the rows are a Frusta)."""
    return (r2 - r1) / length


def plane_height(gap, n_axis, n_radial, r1, slope,
                 guard: Callable[[np.ndarray], np.ndarray] | None = None):
    """Axial height where a generator of the cone r(y) = r1 + k·y meets a plane: the one
    home of this formula (its GLSL twin is ``plane_height`` in ``shaders/cone.glsl``).

    The generator in radial direction e is C1 + y·a + (r1 + k·y)·e, and n·x = d on the
    plane, so ``y = (d - n·C1 - r1·(n·e)) / (n·a + k·(n·e))``. Arguments broadcast.

    Parameters
    ----------
    gap : (...) d - n·C1, the plane's offset from the base point
    n_axis : (...) n·a
    n_radial : (...) n·e
    r1 : (...) the radius at C1 (of a concentric cone: r1 + offset)
    slope : (...) k
    guard : optional ``guard(rise) -> divisor`` for callers that must stay finite where a
        generator runs parallel to the plane

    Returns
    -------
    height : (...) y, world units from C1 along the axis
    rise : (...) n·a + k·(n·e), the generator's approach to the plane per unit of y
        (unguarded; 0 for a generator parallel to the plane)
    """
    rise = n_axis + slope * n_radial
    return (gap - r1 * n_radial) / (rise if guard is None else guard(rise)), rise


def plane_heights(frusta: Frusta, rows, e_r, offset=0.0):
    """Axial heights (y_l, y_u), each (m,), where the generator in radial direction ``e_r``
    (m, 3) of the concentric cone r(y) + ``offset`` meets the lower and upper planes of
    rows ``rows`` (m,) (:func:`plane_height`)."""
    rows = np.asarray(rows)
    c1, a = frusta.base[rows], frusta.axis[rows]
    k = frusta.slope[rows]
    r1 = frusta.r1[rows] + offset
    out = []
    for plane in (frusta.plane_lo[rows], frusta.plane_hi[rows]):
        n, d = plane[:, :3], plane[:, 3]
        out.append(plane_height(d - dot(n, c1), dot(n, a), dot(n, e_r), r1, k)[0])
    return out[0], out[1]


def cone_radius_at(frusta: Frusta, rows, y, offset=0.0) -> np.ndarray:
    """(m,) radius r(y) = r1 + offset + k·y of rows ``rows`` (m,) at axial heights ``y``
    (m,) (world units from C1); ``offset`` (scalar or (m,)) selects a concentric cone."""
    rows = np.asarray(rows)
    return frusta.r1[rows] + offset + frusta.slope[rows] * np.asarray(y, dtype=np.float64)


def relief_scale(frusta: Frusta, rows, y) -> np.ndarray:
    """(m,) the relief's depth at axial heights ``y`` (m,) of rows ``rows`` (m,), as a
    fraction of their shell: r(y)/max(r1, r2), clamped to [0, 1] (1 where both radii are
    0). The relief follows the radius, so with a shell that is a fraction f of the radius
    (skinning's default) it is f·r(y) deep on either side of a joint: no step at the
    shared plane. GLSL twin: ``relief_scale`` in ``shaders/cone.glsl``."""
    rows = np.asarray(rows)
    big = np.maximum(frusta.r1[rows], frusta.r2[rows])
    radius = frusta.r1[rows] + frusta.slope[rows] * np.asarray(y, dtype=np.float64)
    return np.where(big > 0, np.clip(radius / np.where(big > 0, big, 1.0), 0.0, 1.0), 1.0)


def _local(frusta, rows, points):
    """Axial height y (m,), radial distance ρ (m,), unit radial e_r (m, 3) of points (m, 3)
    (e_r = ref_dir on the axis)."""
    rel = np.asarray(points, dtype=np.float64) - frusta.base[rows]
    a = frusta.axis[rows]
    y = dot(rel, a)
    radial = rel - y[:, None] * a
    rho = norm(radial)
    e_r = np.where(rho[:, None] > 0, radial / np.where(rho > 0, rho, 1.0)[:, None],
                   frusta.ref_dir[rows])
    return y, rho, e_r


def surface_uv(frusta: Frusta, rows, points, *, wrap: bool = True):
    """Texture coordinates (6)–(7) of points on (or in the relief shell of) rows ``rows``.

    Parameters
    ----------
    frusta : Frusta
    rows : (m,) int, the row of each point
    points : (m, 3) float64 world coordinates; points off the surface are parametrised on
        the concentric cone through them (the shell of §3)
    wrap : reduce u to [0, 1)

    Returns
    -------
    u : (m,) float, turns around the axis (+ u_offset + v·twist)
    v : (m,) float, the texture's v: the row's own v (0 on the lower plane, 1 on the
        upper plane, along the generator) in its slot, ``(slot + v) / slots``
        (``Frusta.v_part``; the paper's v where the row has the whole texture)
    """
    rows = np.asarray(rows)
    y, rho, e_r = _local(frusta, rows, points)
    offset = rho - (frusta.r1[rows] + frusta.slope[rows] * y)
    y_l, y_u = plane_heights(frusta, rows, e_r, offset)
    v = (y - y_l) / (y_u - y_l)
    b = cross(frusta.axis[rows], frusta.ref_dir[rows])
    u = np.arctan2(dot(e_r, b), dot(e_r, frusta.ref_dir[rows])) / (2 * np.pi)
    u = u + frusta.u_offset[rows] + v * frusta.twist[rows]
    if wrap:
        u = u - np.floor(u)
        u = np.where(u < 1.0, u, 0.0)
    part = frusta.v_part[rows]
    return u, (part[:, 0] + v) / part[:, 1]


def true_normals(frusta: Frusta, rows, points) -> np.ndarray:
    """(m, 3) unit normals of the cone surface itself at points (m, 3) of rows (m,):
    normalize(e_r - k·axis)."""
    rows = np.asarray(rows)
    _, _, e_r = _local(frusta, rows, points)
    return unit(e_r - frusta.slope[rows][:, None] * frusta.axis[rows])


def surface_normals(frusta: Frusta, rows, points, interpolated: bool = True) -> np.ndarray:
    """(m, 3) unit normals at points (m, 3) on rows (m,).

    interpolated=True gives equation (8): normalize((1 - v)·N_l + v·N_u) with
    N_l = normalize(P_l - C1), N_u = normalize(P_u - C2); where P_l or P_u is the axis point
    itself (a cone closing to a point there) the true cone normal stands in for it.
    interpolated=False gives the true cone normal.
    """
    rows = np.asarray(rows)
    n_true = true_normals(frusta, rows, points)
    if not interpolated:
        return n_true
    y, rho, e_r = _local(frusta, rows, points)
    a = frusta.axis[rows]
    k = frusta.slope[rows]
    r1 = frusta.r1[rows] + (rho - (frusta.r1[rows] + k * y))
    y_l, y_u = plane_heights(frusta, rows, e_r, r1 - frusta.r1[rows])
    v = np.clip((y - y_l) / (y_u - y_l), 0.0, 1.0)
    # P - C1 and P - C2 on the generator, written relative to the axis points
    n_l = y_l[:, None] * a + (r1 + k * y_l)[:, None] * e_r
    n_u = (y_u - frusta.length[rows])[:, None] * a + (r1 + k * y_u)[:, None] * e_r
    n_l = unit(n_l, n_true)
    n_u = unit(n_u, n_true)
    return unit((1 - v)[:, None] * n_l + v[:, None] * n_u, n_true)


def facing_normals(normals, true_normals, to_eye, facing_min: float = tol.facing_min) -> np.ndarray:
    """(m, 3) shading normals that never turn their back on the eye (the GLSL twin is
    ``facing_normal`` in ``shaders/cone.glsl``).

    ``normals`` (m, 3) are the interpolated normals (8), ``true_normals`` (m, 3) the
    surface's own, ``to_eye`` (m, 3) unit directions from the points to the eye. Where the
    surface is seen from behind (true·to_eye < 0: from inside a tube) both are negated
    first, as shading always did. Then where (8) makes a cosine c below ``facing_min`` with
    the eye it becomes normalize(n + λ·n_true), λ = (facing_min - c)/(n_true·to_eye): the
    bend towards the true normal that brings its cosine before normalising back to
    ``facing_min`` (after normalising it is positive: the normal faces the eye). λ is 0 at
    c = facing_min and grows continuously below it, so the
    shading stays continuous where the old rule (negate n) jumped to a normal facing down:
    the black slivers on the inside of bends.
    """
    n = np.asarray(normals, dtype=np.float64)
    nt = np.asarray(true_normals, dtype=np.float64)
    behind = dot(nt, to_eye) < 0
    sign = np.where(behind, -1.0, 1.0)[:, None]
    n, nt = n * sign, nt * sign
    c = dot(n, to_eye)
    c_true = np.maximum(dot(nt, to_eye), tol.tiny)
    lam = np.where(c < facing_min, (facing_min - c) / c_true, 0.0)
    return unit(n + lam[:, None] * nt, nt)


def shade_rows_uv_normals(frusta: Frusta, rows, points, interpolated: bool = True):
    """(u, v, normals) of points (m, 3) on rows (m,): :func:`surface_uv` and
    :func:`surface_normals` in one call (the shading step of every renderer)."""
    u, v = surface_uv(frusta, rows, points)
    return u, v, surface_normals(frusta, rows, points, interpolated)


# ============================================================================ bounds
# frusta_bounds and section_points dot with np.einsum, as the renderer's originals did:
# their rounding reaches the automatic camera, which must not move.
def row_end_balls(frusta: Frusta) -> list[tuple[np.ndarray, np.ndarray]]:
    """[(centres (n, 3), radii (n,)) of the lower ends, those of the upper ends]: a ball
    around each end section of each row, relief shell included.

    An oblique cutting plane cuts the cone in an ellipse that reaches past the axis end
    point (up to R / cos θ from it, θ the plane's tilt from the axis), so each end is a
    ball of that radius around where its plane crosses the axis.
    """
    h = frusta.length
    k = frusta.slope
    slope = np.abs(k)
    out = []
    for plane, r_end, y_end in ((frusta.plane_lo, frusta.r1, 0.0), (frusta.plane_hi, frusta.r2, h)):
        normal, offset = plane[:, :3], plane[:, 3]
        cos_t = np.clip(np.einsum("ij,ij->i", normal, frusta.axis), tol.plane_tilt_cos, 1.0)
        sin_t = np.sqrt(1.0 - cos_t ** 2)
        y_cross = (offset - np.einsum("ij,ij->i", normal, frusta.base)) / cos_t
        y_cross = np.where(np.isfinite(y_cross), y_cross, y_end)
        radius = np.maximum(frusta.r1 + k * y_cross, 0.0) + frusta.shell
        grow = 1.0 / np.maximum(cos_t - slope * sin_t, tol.section_reach_cos)
        out.append((frusta.base + frusta.axis * y_cross[:, None], np.maximum(radius, r_end + frusta.shell) * grow))
    return out


def frusta_bounds(frusta: Frusta) -> np.ndarray:
    """(2, 3) float64 axis-aligned box around every frustum, relief shells included (the
    balls of :func:`row_end_balls`). Worked out once a Frusta (its rows are a value: kept
    with it, as renderers keep their work on it) and a copy handed out."""
    box = frusta.__dict__.get("_bounds")
    if box is None:
        box = _bounds(frusta)
        object.__setattr__(frusta, "_bounds", box)
    return box.copy()


def _bounds(frusta: Frusta) -> np.ndarray:
    return _ball_blocks(frusta)


def end_balls(frusta: Frusta) -> tuple[np.ndarray, np.ndarray]:
    """(centres (2n, 3), radii (2n,)): :func:`row_end_balls` of every row, the lower ends'
    then the upper ends', worked out a block of rows at a time on
    :func:`~plantgen.geometry.vec.in_threads`; :func:`frusta_bounds`' box is kept from the
    same balls (the automatic camera needs both)."""
    n = len(frusta.base)
    centres, radii = np.empty((2 * n, 3)), np.empty(2 * n)
    box = _ball_blocks(frusta, centres, radii)
    if frusta.__dict__.get("_bounds") is None:
        object.__setattr__(frusta, "_bounds", box)
    return centres, radii


def _ball_blocks(frusta: Frusta, centres=None, radii=None) -> np.ndarray:
    """(2, 3) the box of the rows' end balls, a block of rows at a time (min and max are
    exact; the blocks' extremes are folded in row order, as one by one), on threads; with
    ``centres`` (2n, 3) and ``radii`` (2n,), the balls are written there too."""
    n = len(frusta.base)
    if n == 0:
        return np.zeros((2, 3))

    def block(s):
        e = min(s + ROW_BLOCK, n)
        balls = row_end_balls(frusta.subset_view(s, e))
        if centres is not None:
            for (c, r), at in zip(balls, (s, n + s), strict=True):
                centres[at:at + e - s], radii[at:at + e - s] = c, r
        return [((c - r[:, None]).min(axis=0), (c + r[:, None]).max(axis=0)) for c, r in balls]
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for extremes in in_threads(block, range(0, n, ROW_BLOCK)):
        for low, high in extremes:
            lo, hi = np.minimum(lo, low), np.maximum(hi, high)
    return np.stack([lo, hi])


def section_points(frusta: Frusta, samples: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Points around the two plane sections of every frustum's outer (relief) surface.

    Returns
    -------
    points : (n, 2, samples, 3) float64, world units; [:, 0] on ``plane_lo``, [:, 1] on
        ``plane_hi``. The solid frustum is the convex hull of its two sections.
    slack : (n, 2, samples) float64, how far the true section may bulge past the polygon
        through the samples (its radius times 1/cos(π/samples) - 1), world units
    """
    phi = 2 * np.pi * np.arange(samples) / samples
    side = np.cross(frusta.ref_dir, frusta.axis)
    e = (np.cos(phi)[None, :, None] * frusta.ref_dir[:, None, :]
         + np.sin(phi)[None, :, None] * side[:, None, :])                  # (n, S, 3)
    k = frusta.slope[:, None]
    r_base = (frusta.r1 + frusta.shell)[:, None]
    out, slack = [], []
    for plane, y_end in ((frusta.plane_lo, 0.0), (frusta.plane_hi, frusta.length)):
        normal = plane[:, None, :3]
        gap = (plane[:, 3] - np.einsum("ij,ij->i", plane[:, :3], frusta.base))[:, None]
        n_e = np.sum(normal * e, axis=-1)
        n_axis = np.einsum("ij,ij->i", plane[:, :3], frusta.axis)[:, None]
        y, rise = plane_height(gap, n_axis, n_e, r_base, k,
                               guard=lambda rise: np.maximum(rise, tol.section_rise))
        y = np.where(rise > tol.section_rise, y,
                     np.broadcast_to(np.asarray(y_end, dtype=np.float64).reshape(-1, 1), n_e.shape))
        ring = np.maximum(r_base + k * y, 0.0)
        out.append(frusta.base[:, None, :] + y[..., None] * frusta.axis[:, None, :] + ring[..., None] * e)
        slack.append(ring * (1 / np.cos(np.pi / samples) - 1))
    return np.stack(out, axis=1), np.stack(slack, axis=1)


# ============================================================================ bounding pyramids
def bounding_pyramids(frusta: Frusta, shell: bool = True) -> np.ndarray:
    """(n, 8, 3) float64 corners of each row's obliquely cut pyramidal frustum (§2.6).

    The square pyramid circumscribes the cone (r + shell, if ``shell``); its four edge
    lines are cut by the two planes. Corner order is :data:`PYRAMID_CORNERS`, faces are
    :data:`PYRAMID_TRIANGLES`. Where an edge line meets a plane at a grazing angle (the
    plane almost parallel to a pyramid edge: ``tol.pyramid_grazing``) the row falls back to
    planes perpendicular to the axis at the frustum's axial extent; where the two planes
    cross inside (knuckle fan rows) each edge keeps the lower and higher of its two cuts.
    Either way the hull holds the whole frustum: side faces are the pyramid's planes and
    top and bottom triangles lie above (below) the convex (concave) max (min) of the two
    plane heights. The GPU builds the same corners (``pyramid_corner`` in
    ``shaders/raycast.glsl``).
    """
    n = len(frusta)
    thick = frusta.shell if shell else np.zeros(n)
    k = frusta.slope
    r1 = frusta.r1 + thick
    a, ref = frusta.axis, frusta.ref_dir
    side = cross(ref, a)
    sx = PYRAMID_CORNERS[:4, 0].astype(float)
    sz = PYRAMID_CORNERS[:4, 1].astype(float)
    q = sx[None, :, None] * ref[:, None, :] + sz[None, :, None] * side[:, None, :]  # (n,4,3)
    ys, rises = [], []
    for plane in (frusta.plane_lo, frusta.plane_hi):
        nrm, d = plane[:, None, :3], plane[:, 3]
        y, rise = plane_height((d - dot(plane[:, :3], frusta.base))[:, None], dot(nrm, a[:, None, :]),
                               dot(nrm, q), r1[:, None], k[:, None])
        ys.append(y)
        rises.append(rise)
    y_lo, y_hi = np.minimum(ys[0], ys[1]), np.maximum(ys[0], ys[1])
    # fallback: axial extent of the frustum (extremes of the Möbius map in n·e_r at ±|n_perp|)
    ext_lo, ext_hi = _axial_extent(frusta, thick)
    n_dot_a = np.minimum(dot(frusta.plane_lo[:, :3], a), dot(frusta.plane_hi[:, :3], a))
    limit = tol.pyramid_grazing * np.maximum(n_dot_a, tol.plane_tilt_cos)
    grazing = np.any(np.minimum(rises[0], rises[1]) < limit[:, None], axis=1) \
        | ~np.all(np.isfinite(y_lo) & np.isfinite(y_hi), axis=1)
    y_lo = np.where(grazing[:, None], ext_lo[:, None], y_lo)
    y_hi = np.where(grazing[:, None], ext_hi[:, None], y_hi)
    y = np.concatenate([y_lo, y_hi], axis=1)                                   # (n, 8)
    qq = np.concatenate([q, q], axis=1)
    rad = r1[:, None] + k[:, None] * y
    rad = np.maximum(rad, 0.0)   # past an apex the square shrinks to the axis
    return frusta.base[:, None, :] + y[..., None] * a[:, None, :] + rad[..., None] * qq


def _axial_extent(frusta, thick):
    """(n,) lowest y on either plane and highest y on either plane over all generators of
    the cone r1 + thick + k·y: the plane heights at n·e_r = ±|n_perp| (the GLSL twin is
    ``plane_axial_range`` in ``shaders/raycast.glsl``). No clamp at the apex: the
    pyramid's radius is clamped at 0 instead."""
    k = frusta.slope
    r1 = frusta.r1 + thick
    lo_vals, hi_vals = [], []
    for plane, store in ((frusta.plane_lo, lo_vals), (frusta.plane_hi, hi_vals)):
        nrm, d = plane[:, :3], plane[:, 3]
        na = dot(nrm, frusta.axis)
        nperp = np.sqrt(np.maximum(1 - na * na, 0.0))
        for s in (-1.0, 1.0):
            y, _ = plane_height(d - dot(nrm, frusta.base), na, s * nperp, r1, k,
                                guard=lambda rise: np.where(np.abs(rise) > tol.generator_rise,
                                                            rise, tol.generator_rise))
            store.append(y)
    lo = np.minimum(*lo_vals)
    hi = np.maximum(*hi_vals)
    lo = np.minimum(lo, np.minimum(*hi_vals))
    hi = np.maximum(hi, np.maximum(*lo_vals))
    return lo, hi


def _triangle_volume(corners):
    """(n,) volume enclosed by the 12 pyramid triangles of corners (n, 8, 3) (divergence
    theorem)."""
    tri = corners[:, PYRAMID_TRIANGLES]              # (n, 12, 3, 3)
    centre = corners.mean(axis=1)[:, None, None, :]
    t = tri - centre
    return np.abs(np.einsum("nti,nti->n", t[:, :, 0], cross(t[:, :, 1], t[:, :, 2])) / 6.0)


def pyramid_volume_ratio(frusta: Frusta, shell: bool = True) -> np.ndarray:
    """(n,) bounding-pyramid volume over the frustum's volume π·h·(r1² + r1·r2 + r2²)/3
    (the volume between two planes through the axis end points, exact for cylinders;
    the outer shell radii where ``shell``). The ideal ratio for a straight cylinder is 4/π."""
    thick = frusta.shell if shell else 0.0
    r1, r2 = frusta.r1 + thick, frusta.r2 + thick
    vol = np.pi * frusta.length * (r1 * r1 + r1 * r2 + r2 * r2) / 3.0
    return _triangle_volume(bounding_pyramids(frusta, shell)) / np.maximum(vol, tol.tiny)


# ============================================================================ seams
def minor_semi_axis(centre, base, axis, r1, slope) -> np.ndarray:
    """(m,) minor semi-axis of a plane's cut of the cones (base (m, 3), unit axis (m, 3),
    r1 (m,), slope (m,)) whose ellipse centres ``centre`` (m, 3) are given: the half chord
    through the centre ⟂ the medial plane (N_m ⟂ axis), so b = sqrt(r(y)² - ρ²) at the
    centre's axial height y and axis distance ρ."""
    rel = centre - base
    y = dot(rel, axis)
    rho2 = dot(rel, rel) - y * y
    r = r1 + slope * y
    return np.sqrt(np.maximum(r * r - rho2, 0.0))


def seam_mismatch(frusta: Frusta) -> np.ndarray:
    """(j,) |b_parent - b_child| / r at every continuing joint of ``frusta``: the difference
    of the minor semi-axes of the two elliptical cuts of the shared plane (§2.2), relative
    to the child's radius at its base. Each cut's major axis joins the generators in the
    plane's tilt direction ±t; its centre O gives b = sqrt(r(y_O)² - ρ_O²)."""
    c = np.flatnonzero(frusta.parent_row >= 0)
    if c.size == 0:
        return np.zeros(0)
    p = frusta.parent_row[c]
    plane = frusta.plane_lo[c]
    widths = []
    for rows in (p, c):
        a = frusta.axis[rows]
        nrm = plane[:, :3]
        t = unit(nrm - a * dot(nrm, a)[:, None], frusta.ref_dir[rows])
        k = frusta.slope[rows]
        ends = []
        for e in (t, -t):
            y, _ = plane_height(plane[:, 3] - dot(nrm, frusta.base[rows]), dot(nrm, a), dot(nrm, e),
                                frusta.r1[rows], k)
            ends.append(frusta.base[rows] + y[:, None] * a + (frusta.r1[rows] + k * y)[:, None] * e)
        centre = 0.5 * (ends[0] + ends[1])
        widths.append(minor_semi_axis(centre, frusta.base[rows], a, frusta.r1[rows], k))
    return np.abs(widths[0] - widths[1]) / np.maximum(frusta.r1[c], tol.tiny)


def seam_gap(frusta: Frusta, samples: int = 256) -> np.ndarray:
    """(j,) the largest radial gap of every continuing joint's seam, relative to the
    child's base radius, in float64: points of the child's cut (its generators at
    ``samples`` angles meeting the shared plane) measured against the parent's cone
    (|axis distance - r(y)| at their axial height on the parent). 0 where the two cuts are
    the same ellipse; the rim gap a ray from inside can escape through otherwise."""
    c = np.flatnonzero(frusta.parent_row >= 0)
    if c.size == 0:
        return np.zeros(0)
    p = frusta.parent_row[c]
    plane = frusta.plane_lo[c]
    a, base, r1, k = frusta.axis[c], frusta.base[c], frusta.r1[c], frusta.slope[c]
    e1 = frusta.ref_dir[c]
    e2 = np.cross(a, e1)
    psi = np.linspace(0.0, 2.0 * np.pi, samples, endpoint=False)
    e = np.cos(psi)[None, :, None] * e1[:, None, :] + np.sin(psi)[None, :, None] * e2[:, None, :]
    nrm = plane[:, None, :3]
    with np.errstate(divide="ignore", invalid="ignore"):
        y, _ = plane_height((plane[:, 3] - dot(plane[:, :3], base))[:, None], dot(plane[:, :3], a)[:, None],
                            dot(nrm, e), r1[:, None], k[:, None])
    point = base[:, None, :] + y[..., None] * a[:, None, :] + (r1[:, None] + k[:, None] * y)[..., None] * e
    rel = point - frusta.base[p][:, None, :]
    ap = frusta.axis[p][:, None, :]
    yp = dot(rel, ap)
    radial = norm(rel - yp[..., None] * ap)
    gap = np.abs(radial - (frusta.r1[p][:, None] + frusta.slope[p][:, None] * yp))
    return np.max(np.where(np.isfinite(gap), gap, np.inf), axis=1) / np.maximum(r1, tol.tiny)
