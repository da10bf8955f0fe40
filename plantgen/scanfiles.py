"""Point clouds (:class:`~plantgen.geometry.rays.scan.PointCloud`) to files and back: LAS 1.4
and LAZ through laspy (the scan extra: ``pip install '.[scan]'``), binary PLY by numpy.

:func:`write_points` picks the format by the suffix (``.las``, ``.laz``, ``.ply``) and
writes atomically (:func:`plantgen.files.write_atomically`): nothing half-written is
left. Both formats carry the same per-point labels:

================  ==========  ==============================================================
name              type        meaning
================  ==========  ==============================================================
``plant``         int32       the plant (a scene's instance)
``part``          uint8       0 stem (branch order 0), 1 branch, 2 leaf
``branch_order``  int16       the segment's branch order (a leaf: its segment's; -1: none)
``segment``       int32       the skeleton segment (a leaf: the one it hangs from; -1: none)
``leaf``          int32       the leaf polygon, -1 for wood
``scanner``       uint16      the scanner (airborne: the flight line)
================  ==========  ==============================================================

**LAS** (``.las``; ``.laz`` compressed by laspy's LAZ backend, lazrs, which the ``scan``
extra installs): version 1.4, point format 6; the labels are extra bytes dimensions
(named as above, each with its description), ``point_source_id`` is the scanner as well,
every point is the first of one return. Coordinates are stored as int32 counts of a
``scale`` from an ``offset``: the scale is 10^(floor(log10(size)) - 6) for a scene whose
largest box side is ``size`` (1e-5 for a 25 m tree) and the offset the box's centre, so
a coordinate is off by at most scale/2 (5 µm there; at most 5e-7 of the scene's size) and
the counts stay below 10^7, far inside int32. The scan's settings, seed, up axis and
scanner positions are a JSON variable-length record (user id ``plantgen``, record 1).

**PLY** (``.ply``): binary little-endian, one ``vertex`` element with ``x, y, z`` as
doubles (no quantisation) and the labels as the properties above; comments give the up
axis, the part names, each scanner's position and the metadata as JSON.

**Up.** Files are z-up by default (LAS is geospatial, and the tools that open PLY scans
take z as up): ``up="z"`` turns plantgen's y-up points +90° about x, ``(x, y, z)`` ->
``(x, -z, y)``, as the mesh exports do; ``up="y"`` keeps plantgen's frame.
"""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import numpy as np

from .errors import PlantgenError, missing_extra
from .files import check_finite, check_output, write_atomically
from .geometry.rays.scan import LABELS, PART_NAMES, PointCloud
from .geometry.skeletons.frames import UP_AXES, up_rotation

__all__ = ["FILE_LABELS", "POINT_SUFFIXES", "PointFileError", "check_point_output", "las_scale", "point_format",
           "read_points", "write_points"]

#: The suffixes :func:`write_points` knows.
POINT_SUFFIXES = (".las", ".laz", ".ply")
#: How to install what LAS and LAZ need.
INSTALL = missing_extra("LAS and LAZ support", "scan")
#: The labels' names in the files (``order`` is ``branch_order`` there) and descriptions.
FILE_LABELS = {"plant": ("plant", "plant (scene instance)"),
               "part": ("part", "0 stem, 1 branch, 2 leaf"),
               "order": ("branch_order", "branch order, -1 none"),
               "segment": ("segment", "skeleton segment, -1 none"),
               "leaf": ("leaf", "leaf polygon, -1 wood"),
               "scanner": ("scanner", "scanner or flight line")}
_PLY_TYPES = {np.dtype(np.int32): "int", np.dtype(np.uint8): "uchar", np.dtype(np.int16): "short",
              np.dtype(np.uint16): "ushort", np.dtype(np.float64): "double", np.dtype(np.float32): "float",
              np.dtype(np.int8): "char", np.dtype(np.uint32): "uint"}
_PLY_DTYPES = {v: k for k, v in _PLY_TYPES.items()}


class PointFileError(PlantgenError, ValueError):
    """A point file plantgen cannot write or read (unknown suffix, missing package)."""


def point_format(path) -> str:
    """``"las"``, ``"laz"`` or ``"ply"`` from ``path``'s suffix, or one line naming the known ones."""
    suffix = Path(path).suffix.lower()
    if suffix not in POINT_SUFFIXES:
        raise PointFileError(f"{path}: unknown point cloud format {Path(path).suffix!r} "
                             f"(known: {', '.join(POINT_SUFFIXES)})")
    return suffix[1:]


def check_point_output(path, *, place: bool = True) -> str:
    """The format of ``path``, checked before any work: a known suffix, laspy installed for
    LAS and a LAZ backend for LAZ, and (``place``) the path writable
    (:func:`plantgen.files.check_output`); one line for each refusal."""
    fmt = point_format(path)
    if fmt in ("las", "laz") and importlib.util.find_spec("laspy") is None:
        raise PointFileError(f"{path}: {INSTALL} (laspy missing)")
    if fmt == "laz":
        import laspy

        if not laspy.LazBackend.detect_available():
            raise PointFileError(f"{path}: {INSTALL} (laspy's LAZ backend, lazrs, missing)")
    if place:
        check_output(path, PointFileError)
    return fmt


def las_scale(lo, hi) -> tuple[float, np.ndarray]:
    """(scale, offset (3,)) of LAS coordinates for points in the box (lo, hi): the scale
    10^(floor(log10(size)) - 6), size the largest side (floored at 1e-6 of the box's
    distance from the origin, and at 1e-9), the offset the centre on the scale's grid."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    centre = (lo + hi) / 2
    size = max(float((hi - lo).max()), 1e-6 * float(np.abs(centre).max()), 1e-9)
    scale = 10.0 ** (math.floor(math.log10(size)) - 6)
    return scale, np.round(centre / scale) * scale


def _check_up(up: str) -> None:
    if up not in UP_AXES:
        raise PointFileError(f"up must be one of {', '.join(UP_AXES)}, got {up!r}")


def _metadata(cloud: PointCloud, up: str, scanners: np.ndarray) -> dict:
    return {**cloud.metadata, "up": up, "parts": list(PART_NAMES), "scanners": scanners.tolist(),
            "labels": {FILE_LABELS[k][0]: FILE_LABELS[k][1] for k in LABELS}}


def _write_las(cloud: PointCloud, path: Path, fmt: str, up: str) -> None:
    import laspy

    _check_up(up)
    rot = up_rotation(up)
    scanners = cloud.scanners @ rot.T
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.add_extra_dims([laspy.ExtraBytesParams(name=FILE_LABELS[k][0], type=dtype, description=FILE_LABELS[k][1])
                           for k, dtype in LABELS.items()])
    n = len(cloud)

    def axis(i: int) -> np.ndarray:      # one turned coordinate of every point (not all three at once)
        return cloud.xyz @ rot[i]

    lo, hi = np.zeros(3), np.zeros(3)
    for i in range(3):
        if n:
            c = axis(i)
            lo[i], hi[i] = c.min(), c.max()
    scale, offset = las_scale(lo, hi)
    header.scales, header.offsets = np.full(3, scale), offset
    header.generating_software = "plantgen"
    header.system_identifier = "plantgen simulated laser scan"
    las = laspy.LasData(header)
    for name, i in (("X", 0), ("Y", 1), ("Z", 2)):
        c = axis(i)
        c -= offset[i]
        c /= scale
        setattr(las, name, np.round(c, out=c).astype(np.int32))
    las.return_number = np.ones(n, np.uint8)
    las.number_of_returns = np.ones(n, np.uint8)
    las.point_source_id = cloud.scanner
    for name, values in cloud.labels().items():
        las[FILE_LABELS[name][0]] = values
    meta = json.dumps(_metadata(cloud, up, scanners), sort_keys=True).encode("utf-8")
    las.vlrs.append(laspy.VLR(user_id="plantgen", record_id=1, description="scan metadata (JSON)",
                              record_data=meta))

    def write(tmp):
        las.write(str(tmp), do_compress=fmt == "laz")
    write_atomically(path, write, PointFileError)


#: Points whose PLY rows are made and written at a time (the vertex table's bytes of a
#: whole scan, 41 a point, are never in memory beside the points).
PLY_CHUNK = 1 << 18


def _turned_axis(xyz: np.ndarray, row: np.ndarray) -> np.ndarray:
    """One turned coordinate of the points, ``xyz @ row`` as BLAS gives it: for a signed
    axis (every up axis's row) the coordinate itself, negated where the row says, with a
    zero written as +0 (BLAS sums the three products from +0: -0 comes out +0)."""
    axis = np.flatnonzero(row)
    if len(axis) == 1 and abs(row[axis[0]]) == 1.0:
        column = xyz[:, axis[0]]
        return (column if row[axis[0]] > 0 else -column) + 0.0
    return xyz @ row


def _ply_header(cloud: PointCloud, up: str) -> tuple[bytes, np.dtype]:
    """The PLY header and the dtype of a vertex row (little-endian, packed)."""
    scanners = cloud.scanners @ up_rotation(up).T
    fields = [("x", np.float64), ("y", np.float64), ("z", np.float64)]
    fields += [(FILE_LABELS[k][0], dtype) for k, dtype in LABELS.items()]
    lines = ["ply", "format binary_little_endian 1.0", "comment plantgen simulated laser scan", f"comment up {up}",
             "comment part " + " ".join(f"{i}={n}" for i, n in enumerate(PART_NAMES))]
    lines += [f"comment scanner {k} {p[0]:.17g} {p[1]:.17g} {p[2]:.17g}" for k, p in enumerate(scanners)]
    lines.append("comment metadata " + json.dumps(_metadata(cloud, up, scanners), sort_keys=True))
    lines.append(f"element vertex {len(cloud)}")
    lines += [f"property {_PLY_TYPES[np.dtype(t)]} {n}" for n, t in fields]
    lines.append("end_header")
    return ("\n".join(lines) + "\n").encode("utf-8"), np.dtype([(n, np.dtype(t).newbyteorder("<")) for n, t in fields])


def _write_ply(path, cloud: PointCloud, up: str) -> None:
    """Write the header, then the vertex rows :data:`PLY_CHUNK` points at a time (each
    point's coordinates turned to ``up`` and its labels)."""
    header, row = _ply_header(cloud, up)
    rot, labels = up_rotation(up), cloud.labels()
    with open(path, "wb") as fh:
        fh.write(header)
        for start in range(0, len(cloud), PLY_CHUNK):
            part = slice(start, min(start + PLY_CHUNK, len(cloud)))
            table = np.empty(part.stop - start, dtype=row)
            for i, name in enumerate("xyz"):
                table[name] = _turned_axis(cloud.xyz[part], rot[i])
            for name, values in labels.items():
                table[FILE_LABELS[name][0]] = values[part]
            fh.write(table.view(np.uint8))


def write_points(cloud: PointCloud, path, *, up: str = "z") -> Path:
    """Write ``cloud`` to ``path`` as LAS, LAZ or PLY by its suffix (module docstring),
    atomically; one :class:`PointFileError` line for an unknown suffix, a missing package
    or an unwritable place. Returns the path."""
    path = Path(path)
    fmt = check_point_output(path)
    check_finite(path, "a point", cloud.xyz, cloud.scanners, error=PointFileError)
    if fmt == "ply":
        _check_up(up)                        # refused before any file is made
        return write_atomically(path, lambda tmp: _write_ply(tmp, cloud, up), PointFileError)
    _write_las(cloud, path, fmt, up)
    return path


# ---------------------------------------------------------------------------- reading back
def _from_file_frame(xyz: np.ndarray, up: str) -> np.ndarray:
    return xyz @ up_rotation(up if up in UP_AXES else "z")


def _cloud(xyz, labels: dict, meta: dict) -> PointCloud:
    up = meta.get("up", "z")
    scanners = np.asarray(meta.get("scanners", []), dtype=np.float64).reshape(-1, 3)
    kept = {k: v for k, v in meta.items() if k not in ("up", "parts", "scanners", "labels")}
    return PointCloud(_from_file_frame(xyz, up), **labels, scanners=_from_file_frame(scanners, up), metadata=kept)


def _read_las(path: Path) -> PointCloud:
    import laspy

    try:
        las = laspy.read(str(path))
    except Exception as exc:      # laspy's errors have no common base: one line, the file named
        raise PointFileError(f"{path}: not a LAS file plantgen wrote ({str(exc).splitlines()[0][:100]})") from None
    meta = next((json.loads(v.record_data) for v in las.vlrs if v.user_id == "plantgen"), {})
    names = set(las.point_format.dimension_names)
    missing = [FILE_LABELS[k][0] for k in LABELS if FILE_LABELS[k][0] not in names]
    if missing:
        raise PointFileError(f"{path}: no {', '.join(missing)} dimension (not a plantgen scan)")
    xyz = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1)
    return _cloud(xyz, {k: np.asarray(las[FILE_LABELS[k][0]]) for k in LABELS}, meta)


def _read_ply(path: Path) -> PointCloud:
    if not path.is_file():
        raise PointFileError(f"{path}: no such file")
    data = path.read_bytes()
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        raise PointFileError(f"{path}: not a PLY file")
    header = data[:end].decode("utf-8", "replace").splitlines()
    if "format binary_little_endian 1.0" not in header:
        raise PointFileError(f"{path}: plantgen reads binary little-endian PLY only")
    fields, count, meta = [], 0, {}
    for line in header:
        words = line.split()
        if words[:2] == ["element", "vertex"]:
            count = int(words[2])
        elif words[:1] == ["property"] and len(words) == 3 and words[1] in _PLY_DTYPES:
            fields.append((words[2], _PLY_DTYPES[words[1]].newbyteorder("<")))
        elif words[:2] == ["comment", "metadata"]:
            meta = json.loads(line.split(" ", 2)[2])
    dtype = np.dtype(fields)
    body = data[end + len(b"end_header\n"):]
    if len(body) < count * dtype.itemsize:
        raise PointFileError(f"{path}: truncated ({len(body):,} bytes for {count:,} points)")
    table = np.frombuffer(body, dtype=dtype, count=count)
    xyz = np.stack([table["x"], table["y"], table["z"]], axis=1).astype(np.float64)
    return _cloud(xyz, {k: table[FILE_LABELS[k][0]] for k in LABELS}, meta)


def read_points(path) -> PointCloud:
    """A point cloud :func:`write_points` wrote, back in plantgen's frame (y up) (a file
    of one's own: it is read whole, with no budget)."""
    path = Path(path)
    fmt = point_format(path)
    if fmt == "ply":
        return _read_ply(path)
    if importlib.util.find_spec("laspy") is None:
        raise PointFileError(f"{path}: {INSTALL} (laspy missing)")
    return _read_las(path)
