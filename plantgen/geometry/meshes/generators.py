"""The GS mesh's generators: columns and bands at each level, the triangle counts per row and
slice, and the surface points and normals at texture coordinates ``(u, v)`` (the inverse of (6)–(7)),
which :func:`plantgen.geometry.meshes.mesh.tessellate` places its vertices at."""

from __future__ import annotations

import numpy as np

from ...tolerances import tol
from ..skeletons.frusta import Frusta, plane_height


def columns_around(m: int) -> int:
    """Number of vertex columns around the axis at level ``m``: ``8·2^m``."""
    return 8 * 2 ** int(m)


def bands_along(m: int) -> int:
    """Number of bands (rings minus one) along the axis at level ``m``: ``2^m``."""
    return 2 ** int(m)


def lateral_triangles_per_row(m: int) -> int:
    """Lateral triangles per frustum row at level ``m``: ``16·4^m`` (Table 1's caption),
    a cone closing to a point included."""
    return 2 * columns_around(m) * bands_along(m)


def slice_triangles(m: int) -> int:
    """Triangles of one outer knuckle fan slice at level ``m``: ``(8·2^m - 2)·2^m``
    (its outer half, fanned at the two hinge points)."""
    return (columns_around(m) - 2) * bands_along(m)


# ---------------------------------------------------------------------------- geometry
def generator_points(frusta: Frusta, rows, u, v, offset=0.0, relief_slope=None):
    """Surface points at texture coordinates ``(u, v)``: the inverse of (6)–(7).

    The generator at angle ``φ = 2π(u - u_offset - v·twist)`` around the axis (``φ = 0``
    along ``ref_dir``) is cut by the two planes at ``P_l`` and ``P_u``; the point is
    ``P = P_l + v·(P_u - P_l)``. ``offset`` moves to the concentric cone with radii
    ``r1 + offset`` and ``r2 + offset`` (the relief shell of §3).

    All arguments broadcast against each other (numpy rules), so a grid of rows (k, 1, 1),
    rings (k, R, 1) and columns (1, 1, C) costs trigonometry only per column and per ring.

    Parameters
    ----------
    rows : int array, frustum row of each point
    u, v : float arrays, texture coordinates (u in turns, v in [0, 1])
    offset : float array or scalar, radial offset in model units
    relief_slope : optional pair ``(shell·∂w/∂u, shell·∂w/∂v)`` (model units per unit of
        u and v): tilt the normal by the relief's gradient as the ray caster shades
        relief (``N - shell·(∂w/∂u·t_u/|∂P/∂u| + ∂w/∂v·t_v/|∂P/∂v|)``, t_u around the
        axis, t_v along the generator, |∂P/∂u| = 2πρ, |∂P/∂v| the generator between
        the planes)

    Returns
    -------
    points : (..., 3) float64, model units
    normals : (..., 3) float64, unit interpolated normals (8)
    """
    rows = np.asarray(rows)
    u, v, offset = (np.asarray(x, dtype=np.float64) for x in (u, v, offset))
    length = frusta.length[rows]
    r1 = frusta.r1[rows]
    slope = frusta.slope[rows]
    axis = frusta.axis[rows]
    ref = frusta.ref_dir[rows]
    binormal = np.cross(axis, ref)
    # φ = 2πu - β with β = 2π(u_offset + v·twist): cos and sin by the angle-difference rule.
    beta = 2 * np.pi * (frusta.u_offset[rows] + v * frusta.twist[rows])
    cos_u, sin_u = np.cos(2 * np.pi * u), np.sin(2 * np.pi * u)
    cos_b, sin_b = np.cos(beta), np.sin(beta)
    cos_phi = cos_u * cos_b + sin_u * sin_b
    sin_phi = sin_u * cos_b - cos_u * sin_b
    start_radius = r1 + offset

    def axial_cut(plane):
        """Axial coordinate y (from C1) where each generator meets ``plane``."""
        normal, d = plane[rows, :3], plane[rows, 3]
        n_axis = np.einsum("...j,...j->...", normal, axis)
        n_radial = cos_phi * np.einsum("...j,...j->...", normal, ref) \
            + sin_phi * np.einsum("...j,...j->...", normal, binormal)
        # relative to C1 so far models keep digits; a generator ∥ the plane stays finite
        gap = d - np.einsum("...j,...j->...", normal, frusta.base[rows])
        return plane_height(gap, n_axis, n_radial, start_radius, slope,
                            guard=lambda rise: np.where(np.abs(rise) < tol.tiny,
                                                        np.copysign(tol.tiny, rise), rise))[0]

    y_lo, y_hi = axial_cut(frusta.plane_lo), axial_cut(frusta.plane_hi)
    y = y_lo + v * (y_hi - y_lo)  # P = P_l + v (P_u - P_l) along the straight generator
    radial = cos_phi[..., None] * ref + sin_phi[..., None] * binormal
    points = frusta.base[rows] + y[..., None] * axis + (start_radius + slope * y)[..., None] * radial

    cone_len = np.hypot(slope, 1.0)
    scale = np.maximum(np.maximum(np.abs(r1), np.abs(frusta.r2[rows])), length)
    n_axial, n_radial = _blended_normal(v, y_lo, y_hi, length, start_radius, slope, cone_len, scale)
    normals = n_axial[..., None] * axis + n_radial[..., None] * radial
    if relief_slope is not None:
        around = -sin_phi[..., None] * ref + cos_phi[..., None] * binormal  # axis × e_r
        along = (axis + slope[..., None] * radial) / cone_len[..., None]
        normals = _relief_tilted(normals, relief_slope, around, along, start_radius + slope * y,
                                 (y_hi - y_lo) * cone_len, tol.zero_length * scale)
    return points, normals


def _blended_normal(v, y_lo, y_hi, length, start_radius, slope, cone_len, scale):
    """(axial, radial) components of the interpolated normal (8) at ``v`` on generators cut
    at axial heights ``y_lo`` and ``y_hi`` (from C1) of cones ``r(y) = start_radius +
    slope·y`` of axial ``length``; ``cone_len = √(1 + slope²)``, ``scale`` the rows' size.

    N_l = P_l - C1, N_u = P_u - C2, each made unit, blended by v. Both lie in the plane of
    the axis and the radial direction, so the blend is done on (axial, radial) components.
    Where a cone closes to a point on a plane (P_l = C1 or P_u = C2) the cone's own outward
    normal on that generator, (-k, 1), stands in.
    """
    def unit_or_cone(axial, radius):
        norm = np.hypot(axial, radius)
        tiny = norm <= tol.zero_length * scale
        safe = np.where(tiny, 1.0, norm)
        return (np.where(tiny, -slope / cone_len, axial / safe),
                np.where(tiny, 1.0 / cone_len, radius / safe))

    lo_axial, lo_radial = unit_or_cone(y_lo, start_radius + slope * y_lo)
    hi_axial, hi_radial = unit_or_cone(y_hi - length, start_radius + slope * y_hi)
    n_axial = (1 - v) * lo_axial + v * hi_axial
    n_radial = (1 - v) * lo_radial + v * hi_radial
    norm = np.hypot(n_axial, n_radial)
    degenerate = norm <= 0
    norm = np.where(degenerate, 1.0, norm)
    return (np.where(degenerate, -slope / cone_len, n_axial / norm),
            np.where(degenerate, 1.0 / cone_len, n_radial / norm))


def _relief_tilted(normals, relief_slope, around, along, radius, generator_length, floor):
    """(..., 3) unit ``normals`` tilted by the relief's gradient ``relief_slope`` (see
    :func:`generator_points`): ``around`` and ``along`` are the unit tangents t_u and t_v,
    ``radius`` ρ and ``generator_length`` (|∂P/∂v|) are floored at ``floor``."""
    du, dv = (np.asarray(x, dtype=np.float64) for x in relief_slope)
    radius = np.maximum(radius, floor)
    generator_length = np.maximum(generator_length, floor)
    tilted = normals - (du / (2 * np.pi * radius))[..., None] * around \
        - (dv / generator_length)[..., None] * along
    return tilted / np.linalg.norm(tilted, axis=-1, keepdims=True)
