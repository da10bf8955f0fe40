"""The ray caster's per-segment records: packing, upload, and streaming what moves.

One float32 record of 24 values (96 bytes) per frustum row; the 8-corner, 12-triangle
bounding pyramid template (§2.6) is shared by every row and instanced in the vertex
shader (``shaders/raycast.glsl``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import PlantgenError
from ..geometry.rays.instances import PlacedPlants
from ..geometry.skeletons.frusta import PYRAMID_CORNERS as _CORNERS_F64
from ..geometry.skeletons.frusta import PYRAMID_TRIANGLES as _TRIANGLES_I64
from ..geometry.skeletons.frusta import frusta_bounds
from ..geometry.vec import in_threads

__all__ = ["RECORD_FLOATS", "RECORD_BYTES", "PYRAMID_CORNERS", "PYRAMID_TRIANGLES",
           "pack_records", "record_tags", "rc_buffer_bytes", "RecordStream", "StreamedRows", "rows_box",
           "RECORD_LAYOUT", "RECORD_ATTRIBUTES"]

#: float32 values in one segment's record: base, h, axis, r1, ref_dir, r2, plane_lo,
#: plane_hi, (u_offset, twist, shell, material).
RECORD_FLOATS = 24
RECORD_BYTES = 4 * RECORD_FLOATS
#: The record's vertex-array layout (per instance) and attribute names in raycast.glsl.
RECORD_LAYOUT = "4f 4f 4f 4f 4f 4f/i"
RECORD_ATTRIBUTES = ("rec0", "rec1", "rec2", "rec3", "rec4", "rec5")
#: Rows of a block of :func:`pack_records` (the blocks run on threads; 6 MiB of records).
PACK_BLOCK = 1 << 16

#: The bounding pyramid's template as uploaded: corner i is (sx, sz, end); 12 triangles
#: wound counter-clockwise seen from outside (plantgen.geometry.skeletons.frusta's, in GL types).
PYRAMID_CORNERS = _CORNERS_F64.astype(np.float32)
PYRAMID_TRIANGLES = _TRIANGLES_I64.astype(np.int32)


def pack_records(frusta, origin, out: np.ndarray | None = None) -> np.ndarray:
    """One float32 record per segment for upload.

    Parameters
    ----------
    frusta : Frusta (see plantgen.geometry.skeletons.frusta), n rows, float64, world units
    origin : (3,) float64, the render origin (the camera eye); positions and plane offsets
        are made relative to it in float64 before the cast to float32
    out : optional (n, 24) float32 C-contiguous array to write the records into (a buffer
        reused frame after frame); a new one when None

    Returns
    -------
    (n, 24) float32 (``out`` when given): base - origin, h | axis, r1 | ref_dir, r2 |
    plane_lo | plane_hi | u_offset, twist, shell, tag. Plane offsets are relative to the
    base point (d - n·base, formed in float64), as plantgen.geometry.rays.reference uploads them.
    96 bytes per segment. ``tag`` = material + 256·(lower end open) + 512·(upper end open)
    + 1024·slot + 131072·(slots - 1) (``v_part``: 7 bits each; under 2^24, exact in float32);
    an end is open unless a continuing row shares its plane (open ends are capped surfaces,
    shared joint planes are not). Every value is formed in float64 and rounded once to
    float32 as it is written.
    """
    origin = np.asarray(origin, dtype=np.float64)
    n = len(frusta.base)
    if out is None:
        out = np.empty((n, RECORD_FLOATS), dtype=np.float32)
    elif out.shape != (n, RECORD_FLOATS) or out.dtype != np.float32 or not out.flags.c_contiguous:
        raise ValueError(f"pack_records: out must be a C-contiguous ({n}, {RECORD_FLOATS}) float32 array")
    material = np.asarray(frusta.material)
    if n and (material.min() < 0 or material.max() > 255):
        raise PlantgenError("material indices must lie in 0..255 for the ray caster")
    open_lo, open_hi = np.asarray(frusta.open_lo), np.asarray(frusta.open_hi)

    def pack(start):        # a block of rows, every column (its cache lines are its own)
        rows = slice(start, min(start + PACK_BLOCK, n))
        block, base = out[rows], frusta.base[rows]
        np.subtract(base, origin, out=block[:, 0:3])
        block[:, 3] = frusta.length[rows]
        block[:, 4:7] = frusta.axis[rows]
        block[:, 7] = frusta.r1[rows]
        block[:, 8:11] = frusta.ref_dir[rows]
        block[:, 11] = frusta.r2[rows]
        for col, plane in ((12, frusta.plane_lo[rows]), (16, frusta.plane_hi[rows])):
            block[:, col:col + 3] = plane[:, :3]
            block[:, col + 3] = plane[:, 3] - np.einsum("ij,ij->i", plane[:, :3], base)
        block[:, 20] = frusta.u_offset[rows]
        block[:, 21] = frusta.twist[rows]
        block[:, 22] = frusta.shell[rows]
        block[:, 23] = record_tags(material[rows], open_lo[rows], open_hi[rows], frusta.v_part[rows])
    in_threads(pack, range(0, n, PACK_BLOCK))      # blocks of rows on threads: row by row the same values
    return out


def record_tags(material, open_lo, open_hi, v_part) -> np.ndarray:
    """(n,) int64 records' tags (:func:`pack_records`): material + 256·open_lo +
    512·open_hi + 1024·slot + 131072·(slots - 1), ``v_part`` (n, 2) (slot, slots), checked
    by the Frusta constructor (7 bits each)."""
    tag = np.asarray(material).astype(np.int64)
    tag += 256 * np.asarray(open_lo)
    tag += 512 * np.asarray(open_hi)
    tag += 1024 * v_part[:, 0] + 131072 * (v_part[:, 1] - 1)
    return tag


def rc_buffer_bytes(n_rows: int) -> int:
    """GPU buffer bytes of the ray caster's draw: one 96-byte record per row (the 8-corner,
    12-triangle pyramid template is shared by all rows and not counted)."""
    return RECORD_BYTES * int(n_rows)


class RecordStream:
    """One GPU buffer of records for an animation: the head holds the static rows, packed
    and uploaded once (again only if the origin changes or the buffer must grow), the tail
    the moving rows, written every frame. The camera stays fixed over an animation, so the
    static records (relative to the eye) stay valid."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.buffer = None
        self._origin = None
        self._static_records = None
        self._moving_records = None      # float32 records reused while the row count holds

    def write(self, static, moving, origin) -> tuple[float, float, int]:
        """Make :attr:`buffer` hold the records of ``static`` then ``moving`` (Frusta, or
        None when nothing moves) relative to ``origin`` (3,).

        Returns (pack_ms, upload_ms, bytes written to the GPU by this call).
        """
        origin = np.asarray(origin, dtype=np.float64)
        t0 = time.perf_counter()
        moving_records = None
        if moving is not None and len(moving):
            reuse = self._moving_records is not None and len(self._moving_records) == len(moving)
            moving_records = pack_records(moving, origin, self._moving_records if reuse else None)
            self._moving_records = moving_records
        t1 = time.perf_counter()
        static_ms, written = self.prepare(static, len(static) + (len(moving) if moving is not None else 0), origin)
        if moving_records is not None:
            self.buffer.write(moving_records, offset=len(static) * RECORD_BYTES)
            written += moving_records.nbytes
        t2 = time.perf_counter()
        return (t1 - t0) * 1e3 + static_ms, (t2 - t1) * 1e3 - static_ms, written

    def prepare(self, static, n_total: int, origin: np.ndarray) -> tuple[float, int]:
        """Make :attr:`buffer` hold room for ``n_total`` records, the first ``len(static)``
        being ``static``'s relative to ``origin`` (packed and written only when the origin
        changed or the buffer had to grow). Returns (pack ms, bytes written)."""
        first = self.buffer is None or self._origin is None or not np.array_equal(origin, self._origin)
        t0 = time.perf_counter()
        if first:
            self._static_records = pack_records(static, origin)
        pack_ms = (time.perf_counter() - t0) * 1e3
        need = max(n_total, 1) * RECORD_BYTES
        if self.buffer is None or self.buffer.size < need:
            if self.buffer is not None:
                self.buffer.release()
            self.buffer = self.ctx.buffer(reserve=need, dynamic=True)
            first = True
        written = 0
        if first and len(static):
            self.buffer.write(self._static_records.tobytes(), offset=0)
            written += self._static_records.nbytes
        self._origin = origin
        return pack_ms, written

    def release(self) -> None:
        if self.buffer is not None:
            self.buffer.release()
            self.buffer = None


@dataclass(frozen=True, eq=False)
class StreamedRows:
    """The rows of a frame whose records only the GPU holds (posed there by a compute
    pass, :class:`plantgen.gl.pose.PoseStream`): how many, their materials' names and a
    world ``box`` (2, 3) that holds them (the renderers' depth range and light window).
    :meth:`plantgen.gl.raycast.Raycaster.render` draws them from its ``record_buffer``."""

    count: int
    material_names: tuple
    box: np.ndarray

    def __len__(self) -> int:
        return self.count


def rows_box(rows) -> np.ndarray:
    """(2, 3) world box of ``rows``: a Frusta's bounds, or the ``box`` of a
    :class:`StreamedRows` or a :class:`~plantgen.geometry.rays.instances.PlacedPlants`."""
    return rows.box if isinstance(rows, (StreamedRows, PlacedPlants)) else frusta_bounds(rows)
