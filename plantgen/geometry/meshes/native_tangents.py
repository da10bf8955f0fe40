"""The glTF tangents of a large mesh in compiled code (numba): the numpy
:func:`~plantgen.geometry.meshes.textures.mesh_tangents`' numbers bit for bit, in one pass
over the faces and one over the vertices, without its temporaries.

Operation for operation the numpy code's float64 arithmetic (no fast-math, no fused
multiply-adds: LLVM contracts none unless told to): each face's ∂P/∂u and ∂P/∂v
(:func:`~plantgen.geometry.meshes.textures.face_derivatives`), made unit and weighted by
the face's area; each vertex's sums added corner by corner in the bincount's order (every
face's first corner, then second, then third); each vertex's tangent made ⟂ its normal,
unit, and its sign (a vertex whose sum leaves no tangent, a cap's, any unit vector ⟂ its
normal: :func:`~plantgen.geometry.vec.any_perpendicular`'s). The tests compare the two on
shipped and synthetic meshes.

:func:`~plantgen.geometry.meshes.textures.mesh_tangents` asks for it only from
:data:`~plantgen.geometry.meshes.textures.COMPILED_FACES` faces on:
numba's import and its cache's load (or, the first time on a machine, the compile) cost
more than numpy spends on a smaller mesh. Compiled on first use and cached on disk
(``cache=True``, as :mod:`plantgen.geometry.rays.native_trace`); without numba, or where
its compiler fails, or with ``PLANTGEN_COMPILED_TANGENTS=0`` in the environment,
:func:`tangent_kernels` is None and numpy computes every tangent.
"""

from __future__ import annotations

import os
import threading
import time

import numpy as np

from ..compiled import NUMBA_ERROR, njit

__all__ = ["compile_seconds", "face_sums", "tangent_kernels", "vertex_tangents"]


@njit(cache=True)
def _unit_weighted(x, y, z, weight):
    """(x, y, z) / max(|(x, y, z)|, 1e-300) * weight, as numpy rounds it."""
    length = np.sqrt((x * x + y * y) + z * z)
    if not (length >= 1e-300) and not np.isnan(length):
        length = 1e-300
    return (x / length) * weight, (y / length) * weight, (z / length) * weight


@njit(cache=True)
def face_sums(vertices, uv, faces, n_vertices):
    """(V, 6) per vertex: the area-weighted unit ∂P/∂u (columns 0-2) and ∂P/∂v (3-5) of
    the faces that use it, summed corner by corner as the bincount does."""
    count = faces.shape[0]
    weighted = np.empty((count, 6))
    for f in range(count):
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        e1x, e1y, e1z = vertices[i1, 0] - vertices[i0, 0], vertices[i1, 1] - vertices[i0, 1], \
            vertices[i1, 2] - vertices[i0, 2]
        e2x, e2y, e2z = vertices[i2, 0] - vertices[i0, 0], vertices[i2, 1] - vertices[i0, 1], \
            vertices[i2, 2] - vertices[i0, 2]
        u0, v0 = np.float64(uv[i0, 0]), np.float64(uv[i0, 1])
        d1u, d1v = np.float64(uv[i1, 0]) - u0, np.float64(uv[i1, 1]) - v0
        d2u, d2v = np.float64(uv[i2, 0]) - u0, np.float64(uv[i2, 1]) - v0
        det = d1u * d2v - d2u * d1v
        cx, cy, cz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
        area = 0.5 * np.sqrt((cx * cx + cy * cy) + cz * cz)
        ok = np.abs(det) > 1e-12
        safe = det if ok else 1.0
        weight = area if ok else 0.0
        a = _unit_weighted((e1x * d2v - e2x * d1v) / safe, (e1y * d2v - e2y * d1v) / safe,
                           (e1z * d2v - e2z * d1v) / safe, weight)
        b = _unit_weighted((e2x * d1u - e1x * d2u) / safe, (e2y * d1u - e1y * d2u) / safe,
                           (e2z * d1u - e1z * d2u) / safe, weight)
        weighted[f, 0], weighted[f, 1], weighted[f, 2] = a
        weighted[f, 3], weighted[f, 4], weighted[f, 5] = b
    sums = np.zeros((n_vertices, 6))
    for corner in range(3):
        for f in range(count):
            v = faces[f, corner]
            for k in range(6):
                sums[v, k] += weighted[f, k]
    return sums


@njit(cache=True)
def _perpendicular(nx, ny, nz):
    """:func:`~plantgen.geometry.vec.any_perpendicular` of one unit vector, as numpy rounds it."""
    hx, hz = (1.0, 0.0) if np.abs(nx) < 0.9 else (0.0, 1.0)
    along = (hx * nx + 0.0 * ny) + hz * nz
    vx, vy, vz = hx - nx * along, 0.0 - ny * along, hz - nz * along
    length = np.sqrt((vx * vx + vy * vy) + vz * vz)
    if not length > 0:
        length = 1.0
    return vx / length, vy / length, vz / length


@njit(cache=True)
def vertex_tangents(sums, normals):
    """(V, 4) float32 tangents of the vertices whose face sums are ``sums`` (V, 6)
    (:func:`face_sums`), with ``normals`` (V, 3); a vertex whose sum leaves no tangent
    takes any unit vector ⟂ its normal, as the numpy code does."""
    count = sums.shape[0]
    out = np.empty((count, 4), dtype=np.float32)
    for i in range(count):
        nx, ny, nz = np.float64(normals[i, 0]), np.float64(normals[i, 1]), np.float64(normals[i, 2])
        length = np.sqrt((nx * nx + ny * ny) + nz * nz)
        if not (length >= 1e-300) and not np.isnan(length):
            length = 1e-300
        nx, ny, nz = nx / length, ny / length, nz / length
        sx, sy, sz = sums[i, 0], sums[i, 1], sums[i, 2]
        along = (sx * nx + sy * ny) + sz * nz
        tx, ty, tz = sx - along * nx, sy - along * ny, sz - along * nz
        length = np.sqrt((tx * tx + ty * ty) + tz * tz)
        if length < 1e-12:
            tx, ty, tz = _perpendicular(nx, ny, nz)
            length = np.sqrt((tx * tx + ty * ty) + tz * tz)
        tx, ty, tz = tx / length, ty / length, tz / length
        side = ((ny * tz - nz * ty) * sums[i, 3] + (nz * tx - nx * tz) * sums[i, 4]) \
            + (nx * ty - ny * tx) * sums[i, 5]
        out[i, 0], out[i, 1], out[i, 2] = np.float32(tx), np.float32(ty), np.float32(tz)
        out[i, 3] = np.float32(-1.0) if side > 0 else np.float32(1.0)
    return out


_STATE: dict = {"failed": None, "compile_s": None}
_LOCK = threading.RLock()


def tangent_kernels():
    """(:func:`face_sums`, :func:`vertex_tangents`) compiled (or loaded from numba's
    cache: the first call compiles them on a tiny mesh), or None where numba does not
    import or compile, or ``PLANTGEN_COMPILED_TANGENTS`` is ``0``."""
    if os.environ.get("PLANTGEN_COMPILED_TANGENTS", "") == "0" or NUMBA_ERROR is not None:
        return None
    with _LOCK:
        if _STATE["compile_s"] is None and _STATE["failed"] is None:
            start = time.perf_counter()
            try:
                faces = np.array([[0, 1, 2]], dtype=np.int64)
                sums = face_sums(np.eye(3), np.array([[0, 0], [1, 0], [0, 1]], np.float32), faces, 3)
                vertex_tangents(sums, np.ones((3, 3), np.float32))
            except Exception as error:           # noqa: BLE001 - numba's errors are many
                _STATE["failed"] = error
            else:
                _STATE["compile_s"] = time.perf_counter() - start
    return None if _STATE["failed"] is not None else (face_sums, vertex_tangents)


def compile_seconds() -> float | None:
    """Wall seconds the first :func:`tangent_kernels` took (compiling, or loading numba's
    cache); None before it ran or where it failed."""
    return _STATE["compile_s"]
