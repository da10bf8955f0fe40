"""Frames for files: the up axis other tools expect, and placements as translation,
rotation and scale (what glTF nodes, glTF's instancing extension and USD's
PointInstancer store).

plantgen's models are y-up. A file written z-up turns the model +90° about x:
``(x, y, z)`` -> ``(x, -z, y)`` (y becomes z; right-handed both, so triangle windings
keep their sense). A placement ``M`` (4x4) of a model then becomes ``R·M·Rᵀ`` for the
turned model, so copies land where the turned whole would be.
"""

from __future__ import annotations

import numpy as np

from ...tolerances import tol

__all__ = ["UP_AXES", "similarity_trs", "turn_placements", "up_rotation"]

UP_AXES = ("y", "z")


def up_rotation(up: str) -> np.ndarray:
    """(3, 3) rotation from plantgen's y-up frame to a file's ``up`` frame."""
    if up == "y":
        return np.eye(3)
    if up == "z":
        return np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    raise ValueError(f"up must be 'y' or 'z', got {up!r}")


def turn_placements(matrices: np.ndarray, up: str) -> np.ndarray:
    """(k, 4, 4) placements of copies of a model turned to ``up``: ``R·M·Rᵀ``."""
    r = np.eye(4)
    r[:3, :3] = up_rotation(up)
    return r @ np.asarray(matrices, dtype=np.float64) @ r.T


def similarity_trs(matrices: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Translation (k, 3), unit quaternion (k, 4) as (x, y, z, w) with w >= 0, and uniform
    scale (k,) of similarity transforms (k, 4, 4) (rotation times a positive uniform
    scale, plus a translation), such that ``M·p = t + s·q(p)``."""
    m = np.asarray(matrices, dtype=np.float64)
    lin = m[:, :3, :3]
    scale = np.cbrt(np.linalg.det(lin))
    if np.any(scale <= 0):
        raise ValueError("a placement that mirrors or collapses the model is not a similarity transform")
    rot = lin / scale[:, None, None]
    return m[:, :3, 3].copy(), _quaternions(rot), scale


def _quaternions(rot: np.ndarray) -> np.ndarray:
    """(k, 4) unit quaternions (x, y, z, w), w >= 0, of rotation matrices (k, 3, 3): from
    the largest of the four squared components (stable for every angle)."""
    trace = np.trace(rot, axis1=1, axis2=2)
    squares = np.stack([1 + 2 * rot[:, 0, 0] - trace, 1 + 2 * rot[:, 1, 1] - trace,
                        1 + 2 * rot[:, 2, 2] - trace, 1 + trace], axis=1)      # 4·(x², y², z², w²)
    big = np.argmax(squares, axis=1)
    q = np.empty((len(rot), 4))
    sym = {(0, 1): rot[:, 1, 0] + rot[:, 0, 1], (0, 2): rot[:, 0, 2] + rot[:, 2, 0],
           (1, 2): rot[:, 2, 1] + rot[:, 1, 2]}
    skew = {0: rot[:, 2, 1] - rot[:, 1, 2], 1: rot[:, 0, 2] - rot[:, 2, 0], 2: rot[:, 1, 0] - rot[:, 0, 1]}
    for k in range(4):
        sel = big == k
        if not sel.any():
            continue
        root = np.sqrt(np.maximum(squares[sel, k], tol.tiny))      # 2·|q_k|
        comp = np.empty((int(sel.sum()), 4))
        comp[:, k] = root / 2
        for j in range(4):
            if j == k:
                continue
            if 3 in (j, k):
                value = skew[min(j, k)][sel]
            else:
                value = sym[(min(j, k), max(j, k))][sel]
            comp[:, j] = value / (2 * root)
        q[sel] = comp
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return np.where(q[:, 3:4] < 0, -q, q)
