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
``shell``       (n,) f8     relief shell thickness (0: no relief on this segment)
``segment``     (n,) i8     index of the skeleton segment this row came from (sharp-bend
                            splitting can give one skeleton segment several rows)
==============  ==========  ==============================================================

Extensions carried by :class:`Frusta` besides the rows above: ``material_names`` (tuple of
str), ``parent_row`` ((n,) i8, the row whose ``plane_hi`` this row shares as its
``plane_lo``, -1 for roots and side branches: an end is *open*, and capped with a flat
disc, unless a continuing row shares its plane) and ``report`` (a :class:`SkinReport`).
A joint whose two radii differ in the skeleton (a modelled radius step) shares its plane
but leaves ``parent_row`` at -1, so both ends are capped and the annulus between the radii
is closed. Rows are ordered parent first (``parent_row[i] < i``).

u and v of a surface point P (equations (6)–(7)), with frame b = axis × ref_dir::

    u = atan2((P - C1)·b, (P - C1)·ref_dir) / 2π + u_offset + v·twist     (mod 1)
    v = |P - P_l| / |P_u - P_l|

where P_l and P_u are the intersections of the generator through P (direction
axis + k·e_r, e_r the unit radial direction of P) with the lower and upper planes.
The interpolated normal (8) is normalize((1 - v)·N_l + v·N_u), N_l = normalize(P_l - C1),
N_u = normalize(P_u - C2).

Along a generator, points are C1 + y·axis + (r1' + k·y)·e_r, so the planes are met at
``y_plane = (d - n·C1 - r1'·(n·e_r)) / (n·axis + k·(n·e_r))`` and ``v = (y_P - y_l) /
(y_u - y_l)``. For a point off the surface (the relief shell of §3) r1' is the radius of
the concentric cone through P, r1' = r1 + (ρ_P - r(y_P)): the shell shares (u, v).

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
``length`` 1e-9·r, r1 = r2, ``segment`` = the child segment; outer slices continue the
chain (shared planes, ``parent_row``), inner slices are open rows whose caps lie inside
the knuckle. Side branches start back along their own axis, inside the parent (see
:func:`skin_skeleton`), and their base is open (capped).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .skeleton import Skeleton

__all__ = ["Frusta", "SkinReport", "skin_skeleton", "surface_uv", "surface_normals",
           "true_normals", "cone_radius_at", "shade_rows_uv_normals", "plane_heights", "bounding_pyramids",
           "pyramid_volume_ratio", "seam_mismatch", "PYRAMID_CORNERS", "PYRAMID_TRIANGLES",
           "ROW_FIELDS"]

#: Names of the per-row arrays of the contract, in contract order.
ROW_FIELDS = ("base", "axis", "length", "r1", "r2", "plane_lo", "plane_hi", "ref_dir",
              "u_offset", "twist", "material", "shell", "segment")


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
    two elliptical cuts at continuing joints, relative to the joint radius (§2.2); the
    ``after`` values are None unless seam fitting ran. Joints with a radius step of more
    than 5 % (``step_joints``) are left out of both: their mismatch is modelled.
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
    seam_mismatch_max_before: float = 0.0
    seam_mismatch_mean_before: float = 0.0
    seam_mismatch_max_after: float | None = None
    seam_mismatch_mean_after: float | None = None
    seam_fit_iterations: int = 0

    def lines(self) -> list[str]:
        s = [f"{self.n_segments} segments -> {self.n_rows} rows; {self.joints} joints, "
             f"{self.side_branches} side branches, {self.step_joints} radius steps",
             f"sharp joints split into knuckles: {self.sharp_joints} (bend limit {self.bend_limit}, "
             f"not an ellipse {self.not_ellipse}, planes crossing {self.planes_crossing}); "
             f"{self.fan_rows} fan rows",
             f"seam mismatch (minor axes, / radius): max {self.seam_mismatch_max_before:.3g}, "
             f"mean {self.seam_mismatch_mean_before:.3g}"]
        if self.seam_mismatch_max_after is not None:
            s[-1] += (f"; after fitting ({self.seam_fit_iterations} iterations): max "
                      f"{self.seam_mismatch_max_after:.3g}, mean {self.seam_mismatch_mean_after:.3g}")
        return s


@dataclass(eq=False)
class Frusta:
    """The rows of the contract above (see the module docstring), plus ``material_names``,
    ``parent_row`` and ``report``."""

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
    material_names: tuple[str, ...] = ("bark",)
    parent_row: np.ndarray | None = None
    report: SkinReport | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        n = len(np.asarray(self.length))
        shapes = {"base": (n, 3), "axis": (n, 3), "plane_lo": (n, 4), "plane_hi": (n, 4),
                  "ref_dir": (n, 3)}
        for f in ROW_FIELDS:
            dtype = {"material": np.int32, "segment": np.int64}.get(f, np.float64)
            arr = np.ascontiguousarray(getattr(self, f), dtype=dtype)
            want = shapes.get(f, (n,))
            if arr.shape != want:
                raise ValueError(f"Frusta.{f} has shape {arr.shape}, expected {want}")
            setattr(self, f, arr)
        if self.parent_row is None:
            self.parent_row = np.full(n, -1, dtype=np.int64)
        self.parent_row = np.ascontiguousarray(self.parent_row, dtype=np.int64)
        self.material_names = tuple(str(m) for m in self.material_names)

    def __len__(self) -> int:
        return len(self.length)

    @property
    def n_rows(self) -> int:
        return len(self.length)

    @property
    def slope(self) -> np.ndarray:
        """(n,) k = (r2 - r1)/h, dimensionless."""
        return (self.r2 - self.r1) / self.length

    @property
    def top(self) -> np.ndarray:
        """(n, 3) C2 = base + h·axis."""
        return self.base + self.length[:, None] * self.axis

    @property
    def side_dir(self) -> np.ndarray:
        """(n, 3) b = axis × ref_dir, the u = 1/4 direction."""
        return _cross(self.axis, self.ref_dir)

    @property
    def open_lo(self) -> np.ndarray:
        """(n,) bool: the lower end is capped (no continuing row shares its plane)."""
        return self.parent_row < 0

    @property
    def open_hi(self) -> np.ndarray:
        """(n,) bool: the upper end is capped (no row continues this one)."""
        out = np.ones(len(self), dtype=bool)
        out[self.parent_row[self.parent_row >= 0]] = False
        return out

    def subset(self, rows) -> "Frusta":
        """The given rows as a new Frusta (parent_row remapped; -1 where the parent is dropped)."""
        rows = np.asarray(rows)
        if rows.dtype == bool:
            rows = np.flatnonzero(rows)
        remap = np.full(len(self), -1, dtype=np.int64)
        remap[rows] = np.arange(len(rows))
        pr = self.parent_row[rows]
        pr = np.where(pr >= 0, remap[np.maximum(pr, 0)], -1)
        return Frusta(**{f: getattr(self, f)[rows] for f in ROW_FIELDS},
                      material_names=self.material_names, parent_row=pr, report=None)

    def translated(self, offset) -> "Frusta":
        """The same frusta moved by ``offset`` (3,) world units (planes follow)."""
        off = np.asarray(offset, dtype=np.float64)
        lo, hi = self.plane_lo.copy(), self.plane_hi.copy()
        lo[:, 3] += lo[:, :3] @ off
        hi[:, 3] += hi[:, :3] @ off
        kw = {f: getattr(self, f) for f in ROW_FIELDS}
        kw.update(base=self.base + off, plane_lo=lo, plane_hi=hi)
        return Frusta(**kw, material_names=self.material_names, parent_row=self.parent_row,
                      report=self.report)


# ============================================================================ small vector helpers
def _dot(a, b):
    """Row-wise dot product of (..., 3) arrays."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _norm(a):
    """Row-wise length of (..., 3) arrays."""
    return np.sqrt(_dot(a, a))


def _cross(a, b):
    """Cross product of (..., 3) arrays (np.cross without its axis juggling: ~5x faster)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def _unit(v, fallback=None):
    n = _norm(v)[..., None]
    if fallback is None:
        return v / np.where(n > 0, n, 1.0)
    return np.where(n > 1e-300, v / np.where(n > 0, n, 1.0), fallback)


def _any_perpendicular(a):
    """(m, 3) unit vectors ⟂ the unit vectors ``a`` (m, 3), a smooth choice per half-space."""
    helper = np.where(np.abs(a[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0.0, 0, 1]]))
    return _unit(helper - a * _dot(helper, a)[:, None])


def _rotate(v, axis, angle):
    """Rotate (m, 3) vectors ``v`` about unit (m, 3) ``axis`` by (m,) ``angle`` radians."""
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return v * c + _cross(axis, v) * s + axis * _dot(axis, v)[:, None] * (1 - c)


def _plane(normal, point):
    return np.concatenate([normal, _dot(normal, point)[:, None]], axis=1)


# ============================================================================ public helpers
def cone_radius_at(frusta: Frusta, rows, y, offset=0.0) -> np.ndarray:
    """Radius r(y) = r1 + offset + k·y of rows ``rows`` (m,) at axial heights ``y`` (m,)
    (world units from C1); ``offset`` (scalar or (m,)) selects a concentric cone."""
    rows = np.asarray(rows)
    k = (frusta.r2[rows] - frusta.r1[rows]) / frusta.length[rows]
    return frusta.r1[rows] + offset + k * np.asarray(y, dtype=np.float64)


def _local(frusta, rows, points):
    """Axial height y (m,), radial distance ρ (m,), unit radial e_r (m, 3) of points."""
    rel = np.asarray(points, dtype=np.float64) - frusta.base[rows]
    a = frusta.axis[rows]
    y = _dot(rel, a)
    radial = rel - y[:, None] * a
    rho = _norm(radial)
    e_r = np.where(rho[:, None] > 0, radial / np.where(rho > 0, rho, 1.0)[:, None],
                   frusta.ref_dir[rows])
    return y, rho, e_r


def plane_heights(frusta: Frusta, rows, e_r, offset=0.0):
    """Axial heights (y_l, y_u) where the generator in radial direction ``e_r`` (m, 3) of the
    concentric cone r(y) + ``offset`` meets the lower and upper planes of rows ``rows`` (m,).

    The generator is C1 + y·axis + (r1 + offset + k·y)·e_r, hence
    y = (d - n·C1 - (r1 + offset)·(n·e_r)) / (n·axis + k·(n·e_r)).
    """
    rows = np.asarray(rows)
    c1, a = frusta.base[rows], frusta.axis[rows]
    k = (frusta.r2[rows] - frusta.r1[rows]) / frusta.length[rows]
    r1 = frusta.r1[rows] + offset
    out = []
    for plane in (frusta.plane_lo[rows], frusta.plane_hi[rows]):
        n, d = plane[:, :3], plane[:, 3]
        ne = _dot(n, e_r)
        out.append((d - _dot(n, c1) - r1 * ne) / (_dot(n, a) + k * ne))
    return out[0], out[1]


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
    v : (m,) float, 0 on the lower plane, 1 on the upper plane, along the generator
    """
    rows = np.asarray(rows)
    y, rho, e_r = _local(frusta, rows, points)
    k = (frusta.r2[rows] - frusta.r1[rows]) / frusta.length[rows]
    offset = rho - (frusta.r1[rows] + k * y)
    y_l, y_u = plane_heights(frusta, rows, e_r, offset)
    v = (y - y_l) / (y_u - y_l)
    b = _cross(frusta.axis[rows], frusta.ref_dir[rows])
    u = np.arctan2(_dot(e_r, b), _dot(e_r, frusta.ref_dir[rows])) / (2 * np.pi)
    u = u + frusta.u_offset[rows] + v * frusta.twist[rows]
    if wrap:
        u = u - np.floor(u)
        u = np.where(u < 1.0, u, 0.0)
    return u, v


def true_normals(frusta: Frusta, rows, points) -> np.ndarray:
    """(m, 3) unit normals of the cone surface itself: normalize(e_r - k·axis)."""
    rows = np.asarray(rows)
    _, _, e_r = _local(frusta, rows, points)
    k = (frusta.r2[rows] - frusta.r1[rows]) / frusta.length[rows]
    return _unit(e_r - k[:, None] * frusta.axis[rows])


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
    k = (frusta.r2[rows] - frusta.r1[rows]) / frusta.length[rows]
    r1 = frusta.r1[rows] + (rho - (frusta.r1[rows] + k * y))
    y_l, y_u = plane_heights(frusta, rows, e_r, r1 - frusta.r1[rows])
    v = np.clip((y - y_l) / (y_u - y_l), 0.0, 1.0)
    # P - C1 and P - C2 on the generator, written relative to the axis points
    n_l = y_l[:, None] * a + (r1 + k * y_l)[:, None] * e_r
    n_u = (y_u - frusta.length[rows])[:, None] * a + (r1 + k * y_u)[:, None] * e_r
    n_l = _unit(n_l, n_true)
    n_u = _unit(n_u, n_true)
    return _unit((1 - v)[:, None] * n_l + v[:, None] * n_u, n_true)


def shade_rows_uv_normals(frusta: Frusta, rows, points, interpolated: bool = True):
    """(u, v, normals) of points (m, 3) on rows (m,): :func:`surface_uv` and
    :func:`surface_normals` in one call (the shading step of every renderer)."""
    u, v = surface_uv(frusta, rows, points)
    return u, v, surface_normals(frusta, rows, points, interpolated)


def bounding_pyramids(frusta: Frusta, shell: bool = True) -> np.ndarray:
    """(n, 8, 3) float64 corners of each row's obliquely cut pyramidal frustum (§2.6).

    The square pyramid circumscribes the cone (r + shell, if ``shell``); its four edge
    lines are cut by the two planes. Corner order is :data:`PYRAMID_CORNERS`, faces are
    :data:`PYRAMID_TRIANGLES`. Where an edge line meets a plane at a grazing angle (the
    plane almost parallel to a pyramid edge) the row falls back to planes perpendicular to
    the axis at the frustum's axial extent; where the two planes cross inside (knuckle fan
    rows) each edge keeps the lower and higher of its two cuts. Either way the hull holds
    the whole frustum: side faces are the pyramid's planes and top and bottom triangles lie
    above (below) the convex (concave) max (min) of the two plane heights.
    """
    n = len(frusta)
    thick = frusta.shell if shell else np.zeros(n)
    k = frusta.slope
    r1 = frusta.r1 + thick
    a, ref = frusta.axis, frusta.ref_dir
    side = _cross(ref, a)
    sx = PYRAMID_CORNERS[:4, 0].astype(float)
    sz = PYRAMID_CORNERS[:4, 1].astype(float)
    q = sx[None, :, None] * ref[:, None, :] + sz[None, :, None] * side[:, None, :]  # (n,4,3)
    ys, denoms = [], []
    for plane in (frusta.plane_lo, frusta.plane_hi):
        nrm, d = plane[:, None, :3], plane[:, 3]
        nq = _dot(nrm, q)
        den = _dot(nrm, a[:, None, :]) + k[:, None] * nq
        ys.append(((d - _dot(plane[:, :3], frusta.base))[:, None] - r1[:, None] * nq) / den)
        denoms.append(den)
    y_lo, y_hi = np.minimum(ys[0], ys[1]), np.maximum(ys[0], ys[1])
    # fallback: axial extent of the frustum (extremes of the Möbius map in n·e_r at ±|n_perp|)
    ext_lo, ext_hi = _axial_extent(frusta, thick)
    n_dot_a = np.minimum(_dot(frusta.plane_lo[:, :3], a), _dot(frusta.plane_hi[:, :3], a))
    grazing = np.any(np.minimum(denoms[0], denoms[1]) < 0.05 * np.maximum(n_dot_a, 1e-3)[:, None],
                     axis=1) | ~np.all(np.isfinite(y_lo) & np.isfinite(y_hi), axis=1)
    y_lo = np.where(grazing[:, None], ext_lo[:, None], y_lo)
    y_hi = np.where(grazing[:, None], ext_hi[:, None], y_hi)
    y = np.concatenate([y_lo, y_hi], axis=1)                                   # (n, 8)
    qq = np.concatenate([q, q], axis=1)
    rad = r1[:, None] + k[:, None] * y
    rad = np.maximum(rad, 0.0)   # past an apex the square shrinks to the axis
    return frusta.base[:, None, :] + y[..., None] * a[:, None, :] + rad[..., None] * qq


def _axial_extent(frusta, thick):
    """(n,) lowest y on the lower plane and highest y on the upper plane over all generators."""
    k = frusta.slope
    r1 = frusta.r1 + thick
    lo_vals, hi_vals = [], []
    for plane, store in ((frusta.plane_lo, lo_vals), (frusta.plane_hi, hi_vals)):
        nrm, d = plane[:, :3], plane[:, 3]
        na = _dot(nrm, frusta.axis)
        nperp = np.sqrt(np.maximum(1 - na * na, 0.0))
        for s in (-1.0, 1.0):
            ne = s * nperp
            den = na + k * ne
            yv = (d - _dot(nrm, frusta.base) - r1 * ne) / np.where(np.abs(den) > 1e-12, den, 1e-12)
            store.append(yv)
    lo = np.minimum(*lo_vals)
    hi = np.maximum(*hi_vals)
    lo = np.minimum(lo, np.minimum(*hi_vals))
    hi = np.maximum(hi, np.maximum(*lo_vals))
    # never past the apex of a closing cone on the side where it closes
    return lo, hi


def _triangle_volume(corners):
    """(n,) volume enclosed by the 12 pyramid triangles (divergence theorem)."""
    tri = corners[:, PYRAMID_TRIANGLES]              # (n, 12, 3, 3)
    centre = corners.mean(axis=1)[:, None, None, :]
    t = tri - centre
    return np.abs(np.einsum("nti,nti->n", t[:, :, 0], _cross(t[:, :, 1], t[:, :, 2])) / 6.0)


def pyramid_volume_ratio(frusta: Frusta, shell: bool = True) -> np.ndarray:
    """(n,) bounding-pyramid volume over the frustum's volume π·h·(r1² + r1·r2 + r2²)/3
    (the volume between two planes through the axis end points, exact for cylinders;
    the outer shell radii where ``shell``). The ideal ratio for a straight cylinder is 4/π."""
    thick = frusta.shell if shell else 0.0
    r1, r2 = frusta.r1 + thick, frusta.r2 + thick
    vol = np.pi * frusta.length * (r1 * r1 + r1 * r2 + r2 * r2) / 3.0
    return _triangle_volume(bounding_pyramids(frusta, shell)) / np.maximum(vol, 1e-300)


# ============================================================================ joints
def _joint_planes(J, M1, M2, rp, rc, kp, kc, ref_hint):
    """Cutting planes (3)–(5) at m joints, blended into the bisector where ill-conditioned.

    J (m, 3) joint points; M1, M2 (m, 3) unit axes of parent and child; rp, rc (m,) radii
    at J of parent and child; kp, kc (m,) slopes; ref_hint (m, 3) a unit vector ⟂ M1 used
    as medial-plane normal when the axes are collinear (the paper's coordinate-axis fallback).

    The boundary lines of each side σ = ±1 in the medial plane are
    J + σ·rp·n1 + s·(M1 + σ·kp·n1) and J + σ·rc·n2 + s·(M2 + σ·kc·n2), n_i = M_i × N_m.
    Their crossing is A (σ = +1) or B (σ = -1). Where the two boundary lines of a side are
    close to parallel (their cross product below half that of the axes: the bend equals
    the difference of the half-angles) the crossing of the axis-parallel lines through the
    same rim points stands in, blended by a smoothstep in that ratio (0.25..0.5). F_σ = J + σ·r̄·n_b is the rim point of the
    bisector plane (n_b = normalize(n1 + n2), r̄ = (rp + rc)/2, bisector direction
    b = normalize(M1 + M2)). Split A - F = o·b + g·n_b; the point used is
    F + w·o·b + clip(g, ±4r̄)·n_b with w = 1 while |o| <= r̄ and w = (r̄/|o|)^4 beyond,
    so a crossing that runs away (nearly parallel boundary lines, radius steps at small
    bends) fades continuously into the bisector plane, which is the perpendicular plane at
    zero bend; no threshold switches the construction.

    Returns plane normals (m, 3) (oriented along M1 + M2), plane points (m, 3), and the
    medial normal N_m (m, 3).
    """
    cross = _cross(M1, M2)
    sin_t = _norm(cross)
    nm = cross / np.where(sin_t > 1e-300, sin_t, 1.0)[:, None]
    collinear = sin_t <= 1e-300
    if collinear.any():
        hint = _any_perpendicular(M1[collinear]) if ref_hint is None else ref_hint[collinear]
        nm[collinear] = _cross(M1[collinear], hint)
    nm = _unit(nm)
    n1, n2 = _cross(M1, nm), _cross(M2, nm)
    nb = _unit(n1 + n2, n1)
    bis = _unit(M1 + M2, _cross(nm, nb))
    rbar = 0.5 * (rp + rc)
    pts = []
    for sigma in (1.0, -1.0):
        p1 = J + sigma * rp[:, None] * n1
        p2 = J + sigma * rc[:, None] * n2
        d1 = M1 + sigma * kp[:, None] * n1
        d2 = M2 + sigma * kc[:, None] * n2
        scale = np.maximum(rbar, 1e-300)
        tiny = 1e-300
        den = _dot(_cross(d1, d2), nm)
        den_cyl = _dot(_cross(M1, M2), nm)
        num = _dot(_cross(p2 - p1, d2), nm)
        num_cyl = _dot(_cross(p2 - p1, M2), nm)
        s_slope = np.clip(num / np.where(np.abs(den) > tiny, den, tiny), -1e100 * scale, 1e100 * scale)
        s_cyl = np.clip(num_cyl / np.where(np.abs(den_cyl) > tiny, den_cyl, tiny), -1e100 * scale, 1e100 * scale)
        # conditioning of the slope lines' crossing relative to the axis-parallel lines'
        q = np.abs(den) / np.maximum(np.abs(den_cyl), tiny)
        x = np.clip((q - 0.25) / 0.25, 0.0, 1.0)
        w_slope = x * x * (3 - 2 * x)
        A = (w_slope[:, None] * (p1 + s_slope[:, None] * d1)
             + (1 - w_slope)[:, None] * (p1 + s_cyl[:, None] * M1))
        F = J + sigma * rbar[:, None] * nb
        # offset of A from the bisector plane (along the bisector direction)
        off = _dot(A - F, bis)
        lim = 1.0 * scale
        with np.errstate(over="ignore", invalid="ignore"):
            w = np.where(np.abs(off) <= lim, 1.0, (lim / np.maximum(np.abs(off), lim)) ** 4)
        w = np.where(np.isfinite(off), w, 0.0)
        along = _dot(A - F, nb)
        along = np.where(np.isfinite(along), np.clip(along, -4 * scale, 4 * scale), 0.0)
        pts.append(F + (w * np.where(np.isfinite(off), off, 0.0))[:, None] * bis
                   + along[:, None] * nb)
    A, B = pts
    normal = _cross(A - B, nm)
    normal = _unit(normal, _unit(M1 + M2, M1))
    normal = np.where((_dot(normal, bis) < 0)[:, None], -normal, normal)
    return normal, 0.5 * (A + B), nm


def _minor_semi_axis(centre, C, a, r1, k):
    """(m,) minor semi-axis of a cut of cone (C, a, r1, k) whose ellipse centre (m, 3) is
    given: the half chord through the centre ⟂ the medial plane (N_m ⟂ a), so
    b = sqrt(r(y)² - ρ²) at the centre's axial height y and axis distance ρ."""
    rel = centre - C
    y = _dot(rel, a)
    rho2 = _dot(rel, rel) - y * y
    r = r1 + k * y
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
        t = _unit(nrm - a * _dot(nrm, a)[:, None], frusta.ref_dir[rows])
        ends = []
        for e in (t, -t):
            n_e = _dot(nrm, e)
            k = frusta.slope[rows]
            y = (plane[:, 3] - _dot(nrm, frusta.base[rows]) - frusta.r1[rows] * n_e) / (_dot(nrm, a) + k * n_e)
            ends.append(frusta.base[rows] + y[:, None] * a + (frusta.r1[rows] + k * y)[:, None] * e)
        centre = 0.5 * (ends[0] + ends[1])
        widths.append(_minor_semi_axis(centre, frusta.base[rows], a, frusta.r1[rows],
                                       frusta.slope[rows]))
    return np.abs(widths[0] - widths[1]) / np.maximum(frusta.r1[c], 1e-300)


# ============================================================================ skinning
def _material_shell(skeleton: Skeleton, shell, radius_mean):
    """(n,) absolute shell thickness per segment from the per-material table."""
    from . import relief as _relief

    table = dict(_relief.DEFAULT_SHELL) if shell is None else dict(shell)
    per_mat = np.array([float(table.get(name, _relief.default_shell(name) if shell is None else 0.0))
                        for name in skeleton.material_names] or [0.0])
    frac = per_mat[skeleton.material] if len(skeleton) else np.zeros(0)
    # positive: fraction of the segment's mean radius; negative: absolute thickness -value
    return np.where(frac >= 0, frac * radius_mean, -frac)


def _quat_mul(p, q):
    """Hamilton products of (m, 4) quaternions (w, x, y, z)."""
    pw, px, py, pz = p[:, 0], p[:, 1], p[:, 2], p[:, 3]
    qw, qx, qy, qz = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    out = np.empty_like(p)
    out[:, 0] = pw * qw - px * qx - py * qy - pz * qz
    out[:, 1] = pw * qx + px * qw + py * qz - pz * qy
    out[:, 2] = pw * qy - px * qz + py * qw + pz * qx
    out[:, 3] = pw * qz + px * qy - py * qx + pz * qw
    return out


def _quat_rotate(q, v):
    """Rotate (m, 3) vectors by unit (m, 4) quaternions."""
    w, u = q[:, :1], q[:, 1:]
    t = 2.0 * _cross(u, v)
    return v + w * t + _cross(u, t)


def _min_rotation_quat(a, b):
    """(m, 4) unit quaternions of the smallest rotation taking unit a to unit b: the
    normalised (1 + a·b, a × b); for a = -b a half turn about an axis ⟂ a."""
    q = np.empty((len(a), 4))
    q[:, 0] = 1.0 + _dot(a, b)
    q[:, 1:] = _cross(a, b)
    flat = q[:, 0] < 1e-12
    if flat.any():
        q[flat, 0] = 0.0
        q[flat, 1:] = _any_perpendicular(a[flat])
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _chain_product(parent, local):
    """Per row, the product local[i] · local[parent[i]] · ... down to its root (quaternions
    (n, 4)), by pointer jumping (log2 depth vectorised rounds)."""
    prod = local.copy()
    jump = parent.copy()
    live = np.flatnonzero(jump >= 0)
    while live.size:
        anc = jump[live]
        prod[live] = _quat_mul(prod[live], prod[anc])
        jump[live] = jump[anc]
        live = live[jump[live] >= 0]
    return prod


def _chain_sum(parent, local):
    """Per row, local[i] + local[parent[i]] + ... (pointer jumping)."""
    total = local.copy()
    jump = parent.copy()
    live = np.flatnonzero(jump >= 0)
    while live.size:
        anc = jump[live]
        total[live] = total[live] + total[anc]
        jump[live] = jump[anc]
        live = live[jump[live] >= 0]
    return total


def _crossing_rows(base, axis, length, r1, r2, lo, hi, samples=24):
    """(n,) bool: the two planes meet inside the cone (y_hi <= y_lo on some generator) or a
    plane does not cut every generator going forward (not an ellipse)."""
    k = (r2 - r1) / length
    # cheap exclusion: axial spread of each plane over the rim vs the gap between centres
    rmax = np.maximum(np.abs(r1), np.abs(r2)) + np.abs(k) * length
    centre_y, spread = [], []
    for plane in (lo, hi):
        na = _dot(plane[:, :3], axis)
        nperp = np.sqrt(np.maximum(1 - na * na, 0.0))
        den = na - np.abs(k) * nperp
        centre_y.append((plane[:, 3] - _dot(plane[:, :3], base)) / np.where(na != 0, na, 1e-300))
        spread.append(np.where(den > 1e-9, rmax * nperp / np.where(den > 1e-9, den, 1), np.inf)
                      * (1 + np.abs(k)))
    maybe = ~(centre_y[1] - centre_y[0] > 1.01 * (spread[0] + spread[1]) + 1e-12 * length)
    bad = np.zeros(len(length), dtype=bool)
    if maybe.any():
        m = np.flatnonzero(maybe)
        bad[m] = _crossing_rows_sampled(base[m], axis[m], length[m], r1[m], r2[m], lo[m], hi[m], samples)
    return bad


def _crossing_rows_sampled(base, axis, length, r1, r2, lo, hi, samples):
    k = (r2 - r1) / length
    ref = _any_perpendicular(axis)
    side = _cross(axis, ref)
    psi = np.linspace(0, 2 * np.pi, samples, endpoint=False)
    e = np.cos(psi)[None, :, None] * ref[:, None, :] + np.sin(psi)[None, :, None] * side[:, None, :]
    ys = []
    for plane in (lo, hi):
        nrm = plane[:, None, :3]
        ne = _dot(nrm, e)
        den = _dot(plane[:, :3], axis)[:, None] + k[:, None] * ne
        y = ((plane[:, 3] - _dot(plane[:, :3], base))[:, None] - r1[:, None] * ne) / np.where(
            den > 1e-12, den, 1e-12)
        ys.append(np.where(den > 1e-12, y, np.nan))
    gap = ys[1] - ys[0]
    bad = ~np.all(gap > 1e-9 * np.maximum(length, np.maximum(r1, r2))[:, None], axis=1)
    return bad


def skin_skeleton(skeleton: Skeleton, *, shell=None, seam_fit: bool = False,
                  seam_tol: float = 1e-9, seam_max_iter: int = 50, max_bend_deg: float = 120.0,
                  fan_step_deg: float = 10.0, twist: float = 0.0,
                  extend_side_branches: bool = True) -> Frusta:
    """Skin a skeleton with conical frusta, vectorised over all segments (§2).

    Parameters
    ----------
    skeleton : Skeleton with n segments (world units, y up)
    shell : dict material name -> relief shell thickness, or None for
        :data:`plantgen.geometry.relief.DEFAULT_SHELL`. A value v >= 0 is a fraction of the
        segment's mean radius (r_start + r_end)/2; a value v < 0 means an absolute
        thickness of -v world units. Names missing from a given dict get 0 (no relief).
    seam_fit : run the minor-axis seam fitting of §2.2 (iterate each continuing child's
        r1 until the minor semi-axes of the two cuts agree to ``seam_tol`` · radius)
    max_bend_deg : joints bending more than this (degrees) become knuckles, as do joints
        whose plane does not cut a cone in an ellipse and joints of segments whose two
        planes would cross inside them
    fan_step_deg : largest bend (degrees) of one knuckle fan slice
    twist : twist θ (turns per segment) stored on every row
    extend_side_branches : move each side branch's start back along its own axis into the
        parent (keeping its slope) by min(rc·tan β, (rp - rc)/sin β), β the branch
        angle: far enough that the base disc is under the parent's end plane, not so far
        that its rim leaves the parent's side; the base is capped

    Returns
    -------
    Frusta, with ``report`` a :class:`SkinReport`.
    """
    n = len(skeleton)
    report = SkinReport(n_segments=n)
    start, end = skeleton.start, skeleton.end
    r_s, r_e = skeleton.r_start.copy(), skeleton.r_end.copy()
    parent = skeleton.parent
    vec = end - start
    length = _norm(vec)
    up = np.broadcast_to(np.array([0.0, 1.0, 0.0]), (n, 3))
    axis = np.where(length[:, None] > 0, vec / np.where(length > 0, length, 1)[:, None], up)
    length = np.where(length > 0, length, 1e-12 * np.maximum(np.maximum(r_s, r_e), 1.0))

    # the continuing child of each parent: the first one marked `continues`
    cont = skeleton.continues & (parent >= 0)
    first_child = np.full(n, -1, dtype=np.int64)
    cand = np.flatnonzero(cont)[::-1]
    first_child[parent[cand]] = cand         # last write wins: the lowest index
    cont &= first_child[np.maximum(parent, 0)] == np.arange(n)
    child = np.flatnonzero(cont)
    par = parent[child]
    side = np.flatnonzero((parent >= 0) & ~cont)
    report.joints, report.side_branches = len(child), len(side)

    # side branches: start extended into the parent along the branch's own axis
    base = start.copy()
    if extend_side_branches and side.size:
        # back far enough that the base disc's rim is below the parent's end plane
        # (rc·tan β), not so far that the rim leaves the parent's side ((rp - rc)/sin β)
        rp_side, rc_side = r_e[parent[side]], r_s[side]
        cos_b = np.clip(_dot(axis[side], axis[parent[side]]), -1.0, 1.0)
        sin_b = np.sqrt(1.0 - cos_b * cos_b)
        # moving the base back by delta puts its centre delta·sin β off the parent's axis,
        # so its rim stays inside the parent while delta·sin β + rc <= rp
        room = np.maximum(rp_side - rc_side, 0.0) / np.maximum(sin_b, 1e-12)
        need = np.where(cos_b > 1e-12, rc_side * sin_b / np.maximum(cos_b, 1e-12), np.inf)
        delta = np.minimum(need, room)
        k_side = (r_e[side] - r_s[side]) / length[side]
        base[side] = start[side] - delta[:, None] * axis[side]
        r_s[side] = np.maximum(r_s[side] - k_side * delta, 0.0)
        length[side] = length[side] + delta

    k = (r_e - r_s) / length
    lo = _plane(axis, base)
    hi = _plane(axis, end)

    if child.size:
        J, M1, M2 = start[child], axis[par], axis[child]
        rp, kp = r_e[par], k[par]
        rc = r_s[child].copy()
        normal, point, nm = _joint_planes(J, M1, M2, rp, rc, kp, k[child], None)
        mism = _joint_minor_mismatch(normal, point, nm, base, axis, r_s, k, par, child, rc, r_e, length)
        rel = mism / np.maximum(rp, 1e-300)
        # a radius step at a joint (|rp - rc| > 5 %) is modelled, not a seam error: it is
        # neither measured nor fitted
        smooth = np.abs(rp - rc) <= 0.05 * np.maximum(rp, rc)
        report.step_joints = int((~smooth).sum())
        if smooth.any():
            report.seam_mismatch_max_before = float(rel[smooth].max())
            report.seam_mismatch_mean_before = float(rel[smooth].mean())
        if seam_fit:
            report.seam_mismatch_max_after = report.seam_mismatch_mean_after = 0.0
        if seam_fit and smooth.any():
            sm = np.flatnonzero(smooth)
            rc_fit, n_fit, p_fit, nm_fit, it, rel_after = _fit_seams(
                J[sm], M1[sm], M2[sm], rp[sm], kp[sm], rc[sm], r_e[child[sm]], length[child[sm]],
                None, base, axis, r_s, k, par[sm], child[sm], r_e, length,
                seam_tol, seam_max_iter)
            rc[sm], normal[sm], point[sm], nm[sm] = rc_fit, n_fit, p_fit, nm_fit
            r_s[child] = rc
            k = (r_e - r_s) / length
            kp = k[par]
            report.seam_mismatch_max_after = float(rel_after.max())
            report.seam_mismatch_mean_after = float(rel_after.mean())
            report.seam_fit_iterations = it
        joint_plane = np.concatenate([normal, _dot(normal, point)[:, None]], axis=1)
        lo[child] = joint_plane
        hi[par] = joint_plane

        # sharp joints: bend limit, plane not an ellipse cut, planes crossing inside a segment
        cos_b = np.clip(_dot(M1, M2), -1, 1)
        bend = np.degrees(np.arccos(cos_b))
        past_limit = bend > max_bend_deg
        sin_p = np.abs(kp) / np.sqrt(1 + kp * kp)
        sin_c = np.abs(k[child]) / np.sqrt(1 + k[child] ** 2)
        not_ellipse = (_dot(normal, M1) <= sin_p + 1e-3) | (_dot(normal, M2) <= sin_c + 1e-3)
        sharp = past_limit | not_ellipse
        joint_of_child = np.full(n, -1, dtype=np.int64)
        joint_of_child[child] = np.arange(len(child))
        joint_of_parent = np.full(n, -1, dtype=np.int64)
        joint_of_parent[par] = np.arange(len(child))
        crossing_flag = np.zeros(len(child), dtype=bool)
        for _ in range(8):
            lo_now, hi_now = lo.copy(), hi.copy()
            perp = _plane(M1[sharp], J[sharp])
            hi_now[par[sharp]] = perp
            lo_now[child[sharp]] = _plane(M2[sharp], J[sharp])
            bad_rows = _crossing_rows(base, axis, length, r_s, r_e, lo_now, hi_now)
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
        hi[par[sharp]] = _plane(M1[sharp], J[sharp])
        lo[child[sharp]] = _plane(M2[sharp], J[sharp])
    else:
        sharp = np.zeros(0, dtype=bool)
        bend = np.zeros(0)
        if seam_fit:
            report.seam_mismatch_max_after = report.seam_mismatch_mean_after = 0.0

    # ---------------------------------------------------------------- knuckle fans
    sj = np.flatnonzero(sharp)
    n_fan = np.zeros(n, dtype=np.int64)          # fan rows inserted before each segment
    if sj.size:
        theta = np.radians(bend[sj])
        steps = np.maximum(1, np.ceil(np.degrees(theta) / fan_step_deg - 1e-9)).astype(np.int64)
        n_fan[child[sj]] = 2 * (steps + 1)  # slices centred on 0, θ/m, ..., θ; outer + inner
    row_of_seg = np.arange(n) + np.cumsum(n_fan)
    n_rows = n + int(n_fan.sum())
    report.fan_rows = n_rows - n
    report.n_rows = n_rows

    R_base = np.empty((n_rows, 3))
    R_axis = np.empty((n_rows, 3))
    R_len = np.empty(n_rows)
    R_r1 = np.empty(n_rows)
    R_r2 = np.empty(n_rows)
    R_lo = np.empty((n_rows, 4))
    R_hi = np.empty((n_rows, 4))
    R_seg = np.empty(n_rows, dtype=np.int64)
    R_parent = np.full(n_rows, -1, dtype=np.int64)
    R_base[row_of_seg], R_axis[row_of_seg], R_len[row_of_seg] = base, axis, length
    R_r1[row_of_seg], R_r2[row_of_seg] = r_s, r_e
    R_lo[row_of_seg], R_hi[row_of_seg] = lo, hi
    R_seg[row_of_seg] = np.arange(n)
    # a radius step leaves an annulus on the shared plane: such joints are not continuing
    # for capping (both ends open, capped); the plane is still shared bit for bit
    r_end0, r_start0 = skeleton.r_end[par], skeleton.r_start[child]
    stepped = np.abs(r_end0 - r_start0) > 1e-9 * np.maximum(r_end0, r_start0)
    R_parent[row_of_seg[child[~stepped]]] = row_of_seg[par[~stepped]]

    if sj.size:
        cnt = n_fan[child[sj]]
        fan_joint = np.repeat(np.arange(len(sj)), cnt)
        first = np.cumsum(cnt) - cnt
        slot_all = np.arange(len(fan_joint)) - np.repeat(first, cnt)
        total = cnt[fan_joint] // 2             # slices per side
        inner = slot_all >= total
        slot = slot_all - inner * total
        m_steps = total - 1
        jj = sj[fan_joint]                          # index into joint arrays
        Jf, M1f, M2f = J[jj], M1[jj], M2[jj]
        th = np.radians(bend[jj])
        # slice i has its axis at angle θ·i/m; its planes at θ·(i ∓ 1/2)/m, the end slices
        # are half wedges whose outer planes are the segments' own perpendicular planes, so
        # each end slice meets its segment in the same circle
        ang0 = th * np.maximum(slot - 0.5, 0.0) / m_steps
        ang1 = th * np.minimum(slot + 0.5, m_steps) / m_steps
        rot_axis = _unit(_cross(M1f, M2f), nm[jj])
        n0 = np.where((slot == 0)[:, None], M1f, _rotate(M1f, rot_axis, ang0))
        n1_ = np.where((slot + 1 == total)[:, None], M2f, _rotate(M1f, rot_axis, ang1))
        mid = np.where((slot == 0)[:, None], M1f,
                       np.where((slot + 1 == total)[:, None], M2f,
                                _rotate(M1f, rot_axis, th * slot / m_steps)))
        t = slot / m_steps
        radius = (1 - t) * r_e[par[jj]] + t * r_s[child[jj]]
        rows = row_of_seg[child[jj]] - 2 * total + slot_all
        R_base[rows] = Jf
        R_axis[rows] = mid
        R_len[rows] = 1e-9 * np.maximum(radius, 1e-300)
        R_r1[rows] = R_r2[rows] = radius
        R_seg[rows] = child[jj]
        out = ~inner
        lo_out = np.where((slot == 0)[:, None], hi[par[jj]], _plane(n0, Jf))
        hi_out = np.where((slot + 1 == total)[:, None], lo[child[jj]], _plane(n1_, Jf))
        R_lo[rows[out]], R_hi[rows[out]] = lo_out[out], hi_out[out]
        # bit-for-bit sharing along the outer fan
        later = out & (slot > 0)
        R_lo[rows[later]] = R_hi[rows[later] - 1]
        # inner slices: the same cylinders on the other side of the hinge line, i.e. the
        # opposite dihedral wedge {n1·x >= d, n0·x <= d}: planes swapped (still facing along
        # the slice axis). They cover the inside of the bend when the segments are short
        # next to r·sin(bend); their ends are open (capped, hidden inside the knuckle).
        R_lo[rows[inner]] = R_hi[rows[inner] - total[inner]]
        R_hi[rows[inner]] = R_lo[rows[inner] - total[inner]]
        R_parent[rows[out]] = np.where(slot[out] == 0, row_of_seg[par[jj[out]]], rows[out] - 1)
        last_out = out & (slot + 1 == total)
        R_parent[row_of_seg[child[jj[last_out]]]] = rows[last_out]

    # ---------------------------------------------------------------- texture frames
    # rotation-minimising frames carried along each continuing chain; a chain (root or
    # side branch) starts from a fixed helper direction projected off its axis
    transport_parent = R_parent
    has_tp = transport_parent >= 0
    quat = np.zeros((n_rows, 4))
    quat[:, 0] = 1.0
    if has_tp.any():
        quat[has_tp] = _min_rotation_quat(R_axis[transport_parent[has_tp]], R_axis[has_tp])
    chain = _chain_product(transport_parent, quat)
    root_row = _chain_root(transport_parent)
    roots = np.flatnonzero(transport_parent < 0)
    root_perp = np.empty((n_rows, 3))
    root_perp[roots] = _any_perpendicular(R_axis[roots])
    root_ref = root_perp[root_row]
    ref = _quat_rotate(chain, root_ref)
    ref = ref - R_axis * _dot(ref, R_axis)[:, None]
    norm = _norm(ref)
    weak = norm < 1e-6
    ref = ref / np.where(weak, 1.0, norm)[:, None]
    if weak.any():
        ref[weak] = _any_perpendicular(R_axis[weak])

    R_twist = np.full(n_rows, float(twist))
    R_shell = np.zeros(n_rows)
    mean_r = 0.5 * (skeleton.r_start + skeleton.r_end)
    R_shell[:] = _material_shell(skeleton, shell, mean_r)[R_seg] if n else 0.0
    R_material = skeleton.material[R_seg] if n else np.zeros(0, np.int32)

    frusta = Frusta(base=R_base, axis=R_axis, length=R_len, r1=R_r1, r2=R_r2, plane_lo=R_lo,
                    plane_hi=R_hi, ref_dir=ref, u_offset=np.zeros(n_rows), twist=R_twist,
                    material=R_material, shell=R_shell, segment=R_seg,
                    material_names=skeleton.material_names, parent_row=R_parent, report=report)
    frusta.u_offset = _u_offsets(frusta)
    return frusta


def _chain_root(parent):
    """(n,) the root row of each row's tree (pointer jumping)."""
    idx = np.arange(len(parent))
    root = np.where(parent >= 0, parent, idx)
    while True:
        nxt = root[root]
        if np.array_equal(nxt, root):
            return root
        root = nxt


def _u_offsets(frusta: Frusta) -> np.ndarray:
    """(n,) u offsets (§2.3): the parent's u = 0 point on the shared plane gets the same u
    from the child; offsets accumulate along each continuing chain. (The point lies on the
    child's lower plane, v = 0 there, so the child's u is its angle alone.)"""
    c = np.flatnonzero(frusta.parent_row >= 0)
    local = np.zeros(len(frusta))
    if c.size:
        p = frusta.parent_row[c]
        ref_p, a_p = frusta.ref_dir[p], frusta.axis[p]
        k = frusta.slope[p]
        nrm, d = frusta.plane_hi[p, :3], frusta.plane_hi[p, 3]
        ne = _dot(nrm, ref_p)
        y_u = (d - _dot(nrm, frusta.base[p]) - frusta.r1[p] * ne) / (_dot(nrm, a_p) + k * ne)
        point = frusta.base[p] + y_u[:, None] * a_p + (frusta.r1[p] + k * y_u)[:, None] * ref_p
        rel = point - frusta.base[c]
        a_c, ref_c = frusta.axis[c], frusta.ref_dir[c]
        u_child = np.arctan2(_dot(rel, _cross(a_c, ref_c)), _dot(rel, ref_c)) / (2 * np.pi)
        local[c] = frusta.twist[p] - u_child
    total = _chain_sum(frusta.parent_row, local)
    wrapped = total - np.floor(total)
    return np.where(wrapped < 1.0, wrapped, 0.0)      # -1e-17 wraps to 1.0 in floats


def _joint_minor_mismatch(normal, point, nm, base, axis, r_s, k, par, child, rc, r_e, length):
    """(j,) |minor semi-axis (parent cut) - minor semi-axis (child cut)| at each joint."""
    bp = _minor_semi_axis(point, base[par], axis[par], r_s[par], k[par])
    kc = (r_e[child] - rc) / length[child]
    bc = _minor_semi_axis(point, base[child], axis[child], rc, kc)
    return np.abs(bp - bc)


def _fit_seams(J, M1, M2, rp, kp, rc, r2c, hc, hint, base, axis, r_s, k, par, child, r_e,
               length, tol, max_iter):
    """Secant iteration on each child's r1 until the two minor semi-axes agree (§2.2).

    All joints iterate together; a child that is itself a parent at the next joint passes
    its new slope on at once (the coupling along a chain), so the iteration works on the
    current radii of every segment each round."""
    r_s = r_s.copy()

    def residual(rc_try):
        r_s[child] = rc_try
        k_all = (r_e - r_s) / length
        normal, point, nm = _joint_planes(J, M1, M2, rp, rc_try, k_all[par], k_all[child], hint)
        bp = _minor_semi_axis(point, base[par], axis[par], r_s[par], k_all[par])
        bc = _minor_semi_axis(point, base[child], axis[child], rc_try, k_all[child])
        return bp - bc, (normal, point, nm)

    scale = np.maximum(rp, 1e-300)
    x0 = rc.copy()
    f0, planes = residual(x0)
    x1 = np.maximum(x0 + f0, 0.0)
    f1, planes = residual(x1)
    it = 1
    while it < max_iter and np.max(np.abs(f1) / scale) > tol:
        den = f1 - f0
        secant = f1 * (x1 - x0) / np.where(den != 0, den, 1)
        step = np.where((np.abs(den) > 1e-300) & np.isfinite(secant), secant, -f1)
        x0, f0 = x1, f1
        x1 = np.maximum(x1 - step, 0.0)
        f1, planes = residual(x1)
        it += 1
    return x1, planes[0], planes[1], planes[2], it, np.abs(f1) / scale
