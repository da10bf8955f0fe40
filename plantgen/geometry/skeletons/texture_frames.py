"""Texture frames of skinned rows (Bhagvat et al. 2009, §2.3): the u = 0 reference
direction of every row, carried along its continuing chain by rotation-minimising
frames, and the u offsets that keep u continuous across each shared joint plane
(:func:`plantgen.geometry.skeletons.skin.skin_skeleton`'s last phase)."""

from __future__ import annotations

import numpy as np

from ...tolerances import tol
from ..vec import any_perpendicular, by_rows, cross, dot, norm, reduce_to_root, tree_roots
from .frusta import cone_slope, plane_height

__all__ = ["reference_directions", "u_offsets"]


def reference_directions(axis, parent_row) -> np.ndarray:
    """(n, 3) unit u = 0 directions ⟂ the row axes (n, 3): rotation-minimising frames
    carried along each continuing chain (``parent_row`` (n,)); a chain (root or side
    branch) starts from a fixed helper direction projected off its axis."""
    n_rows = len(axis)
    has_parent = parent_row >= 0
    quat = np.zeros((n_rows, 4))
    quat[:, 0] = 1.0
    if has_parent.any():
        with_parent = np.flatnonzero(has_parent)
        quat[with_parent] = by_rows(lambda rows: _min_rotation_quat(axis[parent_row[rows]], axis[rows]), with_parent)
    chain = reduce_to_root(parent_row, quat, _quat_mul, overwrite=True)
    roots = np.flatnonzero(~has_parent)
    root_perp = np.empty((n_rows, 3))
    root_perp[roots] = by_rows(any_perpendicular, axis[roots])
    return by_rows(lambda c, root, a: _carried_frame(c, root_perp[root], a), chain, tree_roots(parent_row), axis)


def _carried_frame(chain, root_perp, axis) -> np.ndarray:
    """(m, 3) the chains' start directions ``root_perp`` (m, 3) turned by the quaternions
    ``chain`` (m, 4) and made unit and ⟂ ``axis`` (m, 3) again (a direction left too short
    by the projection: :func:`any_perpendicular`). Row-wise."""
    ref = _quat_rotate(chain, root_perp)
    ref = ref - axis * dot(ref, axis)[:, None]
    length = norm(ref)
    weak = length < tol.frame_weak
    ref = ref / np.where(weak, 1.0, length)[:, None]
    if weak.any():
        ref[weak] = any_perpendicular(axis[weak])
    return ref


def u_offsets(rows, ref_dir, twist) -> np.ndarray:
    """(n,) u offsets (§2.3) of ``rows`` (skinning's rows: ``base``, ``axis``, ``length``,
    ``r1``, ``r2``, ``plane_hi``, ``parent_row``): the parent's u = 0 point on the shared plane gets the same u
    from the child; offsets accumulate along each continuing chain. (The point lies on the
    child's lower plane, v = 0 there, so the child's u is its angle alone.)"""
    c = np.flatnonzero(rows.parent_row >= 0)
    local = np.zeros(len(rows.length))
    if c.size:
        p = rows.parent_row[c]
        ref_p, a_p, base_p, r1_p = ref_dir[p], rows.axis[p], rows.base[p], rows.r1[p]
        k = cone_slope(rows.r1, rows.r2, rows.length)[p]
        nrm, d = rows.plane_hi[p, :3], rows.plane_hi[p, 3]
        y_u, _ = plane_height(d - dot(nrm, base_p), dot(nrm, a_p), dot(nrm, ref_p), r1_p, k)
        point = base_p + y_u[:, None] * a_p + (r1_p + k * y_u)[:, None] * ref_p
        rel = point - rows.base[c]
        a_c, ref_c = rows.axis[c], ref_dir[c]
        u_child = np.arctan2(dot(rel, cross(a_c, ref_c)), dot(rel, ref_c)) / (2 * np.pi)
        local[c] = twist[p] - u_child
    total = reduce_to_root(rows.parent_row, local, np.add, overwrite=True)
    wrapped = total - np.floor(total)
    return np.where(wrapped < 1.0, wrapped, 0.0)      # -1e-17 wraps to 1.0 in floats


def _quat_mul(p, q):
    """(m, 4) Hamilton products of (m, 4) quaternions (w, x, y, z)."""
    pw, px, py, pz = p[:, 0], p[:, 1], p[:, 2], p[:, 3]
    qw, qx, qy, qz = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    out = np.empty_like(p)
    out[:, 0] = pw * qw - px * qx - py * qy - pz * qz
    out[:, 1] = pw * qx + px * qw + py * qz - pz * qy
    out[:, 2] = pw * qy - px * qz + py * qw + pz * qx
    out[:, 3] = pw * qz + px * qy - py * qx + pz * qw
    return out


def _quat_rotate(q, v):
    """(m, 3) vectors ``v`` (m, 3) rotated by unit (m, 4) quaternions."""
    w, u = q[:, :1], q[:, 1:]
    t = 2.0 * cross(u, v)
    return v + w * t + cross(u, t)


def _min_rotation_quat(a, b):
    """(m, 4) unit quaternions of the smallest rotation taking unit a (m, 3) to unit b
    (m, 3): the normalised (1 + a·b, a × b); for a = -b (within ``tol.parallel``) a half
    turn about an axis ⟂ a."""
    q = np.empty((len(a), 4))
    q[:, 0] = 1.0 + dot(a, b)
    q[:, 1:] = cross(a, b)
    flat = q[:, 0] < tol.parallel
    if flat.any():
        q[flat, 0] = 0.0
        q[flat, 1:] = any_perpendicular(a[flat])
    return q / np.linalg.norm(q, axis=1, keepdims=True)
