"""The skeleton: branching line segments with radii, the contract between stages.

A skeleton of ``n`` segments is a set of parallel arrays (y-up coordinates, as in
Bhagvat et al. 2009):

===============  ============  ==========================================================
``start``        (n, 3) f8     first end point of each segment
``end``          (n, 3) f8     second end point
``r_start``      (n,) f8       radius at ``start`` (>= 0)
``r_end``        (n,) f8       radius at ``end`` (>= 0)
``parent``       (n,) i8       index of the parent segment, -1 for a root; parent < child
``continues``    (n,) bool     True: the segment carries on its parent's axis and shares
                               the joint's cutting plane; False: a root or a side branch
``material``     (n,) i4       index into ``material_names``
===============  ============  ==========================================================

The file format (``.npz``) stores these arrays under the same names, plus
``material_names`` as a unicode array. :meth:`Skeleton.load` reads it as untrusted input:
each array's header is checked (no pickled object arrays, the expected kinds and shapes,
sizes within the limits) before its data is read, and the result is validated. Nothing
here imports GL or click.
"""

from __future__ import annotations

import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ... import tolerances
from ...errors import PlantgenError
from ...files import open_input, write_atomically
from ...limits import LimitError, Limits, hint
from ...limits import limits as default_limits
from ..vec import ROW_BLOCK, by_rows, in_threads

#: The most material names a skeleton file (.npz, .swc) may hold: a grammar has at most
#: 16, a scene's merged skeleton the distinct ones of its plants.
MAX_MATERIAL_NAMES = 256

__all__ = ["Skeleton", "SkeletonError"]

#: The arrays of the ``.npz`` format: (dtype kinds accepted, columns or None for (n,)).
NPZ_ARRAYS = {
    "start": ("fiu", 3), "end": ("fiu", 3), "r_start": ("fiu", None), "r_end": ("fiu", None),
    "parent": ("iu", None), "continues": ("biu", None), "material": ("iu", None),
    "material_names": ("U", None),
}


class SkeletonError(PlantgenError, ValueError):
    """A skeleton whose arrays break the contract above."""


@dataclass(frozen=True, eq=False)
class Skeleton:
    start: np.ndarray
    end: np.ndarray
    r_start: np.ndarray
    r_end: np.ndarray
    parent: np.ndarray
    continues: np.ndarray
    material: np.ndarray
    material_names: tuple[str, ...] = field(default=("bark",))

    def __post_init__(self) -> None:
        n = len(np.asarray(self.start))
        conv = {
            "start": (np.float64, (n, 3)),
            "end": (np.float64, (n, 3)),
            "r_start": (np.float64, (n,)),
            "r_end": (np.float64, (n,)),
            "parent": (np.int64, (n,)),
            "continues": (np.bool_, (n,)),
            "material": (np.int32, (n,)),
        }
        for name, (dtype, shape) in conv.items():
            arr = np.asarray(getattr(self, name))
            if arr.size == 0:
                arr = arr.reshape(shape)
            if arr.shape != shape:
                raise SkeletonError(f"{name} has shape {arr.shape}, expected {shape}")
            object.__setattr__(self, name, np.ascontiguousarray(arr, dtype=dtype))
        object.__setattr__(self, "material_names", tuple(str(m) for m in self.material_names))

    # ------------------------------------------------------------------ basics
    def __len__(self) -> int:
        return len(self.start)

    @property
    def n_segments(self) -> int:
        return len(self.start)

    @property
    def tips(self) -> np.ndarray:
        """(k,) int indices of branch tips: segments with no child at all."""
        has_child = np.zeros(len(self), dtype=bool)
        has_child[self.parent[self.parent >= 0]] = True
        return np.flatnonzero(~has_child)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float: axis-aligned box of the segment end points, widened by radii in
        every direction: a safe box, larger than the model (its exact box is
        :func:`plantgen.metrics.geometry_bounds`)."""
        if len(self) == 0:
            return np.zeros((2, 3))
        def block(s):           # a block at a time: min and max are exact
            return [((pts - r).min(axis=0), (pts + r).max(axis=0))
                    for pts, r in ((self.start[s:s + ROW_BLOCK], self.r_start[s:s + ROW_BLOCK, None]),
                                   (self.end[s:s + ROW_BLOCK], self.r_end[s:s + ROW_BLOCK, None]))]
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for extremes in in_threads(block, range(0, len(self), ROW_BLOCK)):    # folded in row order
            for low, high in extremes:
                lo, hi = np.minimum(lo, low), np.maximum(hi, high)
        return np.stack([lo, hi])

    @property
    def height(self) -> float:
        """Extent of :attr:`bounds` along y (up) (the model's height is
        :func:`plantgen.metrics.tree_metrics`' ``height``)."""
        b = self.bounds
        return float(b[1, 1] - b[0, 1])

    def validate(self, tol: float = tolerances.tol.joint_gap) -> None:
        """Raise SkeletonError if an invariant of the format does not hold.

        Invariants: finite coordinates and radii within ``tol.max_coordinate``, radii >= 0,
        parents precede children, every segment with a parent starts where its parent ends
        (within ``tol`` times the model size, at least 1), roots do not continue,
        materials index ``material_names``.
        """
        n = len(self)
        for name in ("start", "end", "r_start", "r_end"):
            values = getattr(self, name)
            # NaN propagates through min and max, inf reaches them: finite extremes mean
            # finite values, found without a full-size temporary
            top = max(float(values.max()), -float(values.min())) if n else 0.0
            if not np.isfinite(top):
                bad = int(np.flatnonzero(~np.isfinite(values).reshape(n, -1).all(axis=1))[0])
                raise SkeletonError(f"{name} holds NaN or inf (segment {bad})")
            if top > tolerances.tol.max_coordinate:
                raise SkeletonError(f"{name} holds values beyond {tolerances.tol.max_coordinate:g}")
        if np.any(self.r_start < 0) or np.any(self.r_end < 0):
            raise SkeletonError("negative radius")
        idx = np.arange(n)
        if np.any(self.parent >= idx) or np.any(self.parent < -1):
            raise SkeletonError("every parent index must be -1 or smaller than its child's")
        has_p = self.parent >= 0
        if np.any(self.continues & ~has_p):
            raise SkeletonError("a root segment cannot continue a parent")
        scale = max(1.0, float(np.abs(self.bounds).max())) if n else 1.0
        child = np.flatnonzero(has_p)
        gap = by_rows(lambda rows: np.linalg.norm(self.start[rows] - self.end[self.parent[rows]], axis=1), child)
        if gap.size and gap.max() > tol * scale:
            bad = int(child[np.argmax(gap)])
            raise SkeletonError(f"segment {bad} does not start where its parent ends (gap {gap.max():.3g})")
        if n and (self.material.min() < 0 or self.material.max() >= len(self.material_names)):
            raise SkeletonError("material index outside material_names")

    # ------------------------------------------------------------------ building
    @classmethod
    def empty(cls, material_names=("bark",)) -> Skeleton:
        z3 = np.zeros((0, 3))
        z = np.zeros(0)
        return cls(z3, z3, z, z, np.zeros(0, int), np.zeros(0, bool), np.zeros(0, int), material_names)

    def transformed(self, matrix: np.ndarray) -> Skeleton:
        """Apply a 4x4 similarity transform (rotation, uniform scale, translation).

        Radii scale by the matrix's uniform scale factor.
        """
        m = np.asarray(matrix, dtype=np.float64)
        lin, t = m[:3, :3], m[:3, 3]
        s = float(np.cbrt(abs(np.linalg.det(lin))))
        return Skeleton(
            self.start @ lin.T + t, self.end @ lin.T + t, self.r_start * s, self.r_end * s,
            self.parent, self.continues, self.material, self.material_names,
        )

    def subset(self, rows) -> Skeleton:
        """The segments ``rows`` ((k,) int, closed under parents: a kept segment's parent
        is kept) as a skeleton, in the given order, parents re-indexed."""
        rows = np.asarray(rows, dtype=np.int64)
        remap = np.full(len(self), -1, dtype=np.int64)
        remap[rows] = np.arange(len(rows))
        parent = self.parent[rows]
        parent = np.where(parent >= 0, remap[np.maximum(parent, 0)], -1)
        return Skeleton(self.start[rows], self.end[rows], self.r_start[rows], self.r_end[rows],
                        parent, self.continues[rows], self.material[rows], self.material_names)

    @staticmethod
    def merged_material_names(parts: list[Skeleton]) -> tuple[str, ...]:
        """The material names of :meth:`concatenate`'s result: every part's names, in order
        of first appearance (a part's index ``i`` becomes the merged index of its name ``i``)."""
        names: list[str] = []
        for p in parts:
            for m in p.material_names:
                if m not in names:
                    names.append(m)
        return tuple(names)

    @staticmethod
    def concatenate(parts: list[Skeleton]) -> Skeleton:
        """Join skeletons into one, re-indexing parents and merging material names
        (:meth:`merged_material_names`)."""
        names = list(Skeleton.merged_material_names(parts))
        if not parts:
            return Skeleton.empty()
        arrays = {k: [] for k in ("start", "end", "r_start", "r_end", "parent", "continues", "material")}
        offset = 0
        for p in parts:
            remap = np.array([names.index(m) for m in p.material_names], dtype=np.int32)
            arrays["start"].append(p.start)
            arrays["end"].append(p.end)
            arrays["r_start"].append(p.r_start)
            arrays["r_end"].append(p.r_end)
            arrays["parent"].append(np.where(p.parent >= 0, p.parent + offset, -1))
            arrays["continues"].append(p.continues)
            arrays["material"].append(remap[p.material] if len(p) else p.material)
            offset += len(p)
        return Skeleton(**{k: np.concatenate(v) for k, v in arrays.items()}, material_names=tuple(names))

    # ------------------------------------------------------------------ files
    def save(self, path: str | Path, extra=None) -> None:
        """Write the ``.npz`` format; written to a temporary name, then renamed. ``extra``:
        further (n,) per-segment arrays by name (labels such as ``branch_order``), written
        beside the contract's; :meth:`load` reads the contract's only."""
        extra = dict(extra or {})
        clash = sorted(set(extra) & (set(NPZ_ARRAYS) | {"material_names"}))
        if clash:
            raise SkeletonError(f"{path}: extra arrays may not replace {', '.join(clash)}")

        def write(tmp):
            with open(tmp, "wb") as fh:
                np.savez_compressed(
                    fh, start=self.start, end=self.end, r_start=self.r_start, r_end=self.r_end,
                    parent=self.parent, continues=self.continues, material=self.material,
                    material_names=np.array(self.material_names, dtype=str),
                    **{k: np.asarray(v) for k, v in extra.items()},
                )
        write_atomically(path, write, SkeletonError)

    @classmethod
    def load(cls, path: str | Path, limits: Limits | None = None) -> Skeleton:
        """Read and validate the ``.npz`` format. Every failure is one line naming the file:
        not a regular file or over ``max_skeleton_bytes``, a corrupt archive, a pickled
        (object) array, a missing array, a wrong kind or shape, over ``max_segments``
        segments, and a skeleton that breaks the contract (:meth:`validate`)."""
        limits = limits or default_limits
        with open_input(path, SkeletonError, max_bytes=limits.max_skeleton_bytes, limit="skeleton_bytes",
                        what="skeleton") as fh:
            try:
                arrays = _read_npz(fh, path, limits)
            except PlantgenError:
                raise
            except (zipfile.BadZipFile, zlib.error, EOFError, OSError, ValueError, NotImplementedError) as exc:
                raise SkeletonError(f"{path}: not a plantgen skeleton (corrupt .npz: "
                                    f"{str(exc).splitlines()[0][:80] or exc.__class__.__name__})") from None
        raw_names = arrays.pop("material_names", ("bark",))
        if len(raw_names) > MAX_MATERIAL_NAMES:
            raise SkeletonError(f"{path}: {len(raw_names):,} material names, over the {MAX_MATERIAL_NAMES} a "
                                "skeleton file may hold")
        names = tuple(str(x) for x in raw_names)
        try:
            skel = cls(**arrays, material_names=names)
            skel.validate()
        except SkeletonError as exc:
            raise SkeletonError(f"{path}: {exc}") from None
        return skel


def _read_npz(fh, path, limits: Limits) -> dict:
    """The arrays of a skeleton ``.npz`` (an open binary file), each header checked before
    its data is read: the kinds and shapes of :data:`NPZ_ARRAYS`, no object array (numpy
    would unpickle it), at most ``max_segments`` rows, at most ``max_skeleton_bytes``
    unpacked. The members are inflated on :func:`~plantgen.geometry.vec.in_threads`'
    threads (zlib lets go of the interpreter); a failure is the first array's, in
    :data:`NPZ_ARRAYS` order, as when they are read one by one."""
    with zipfile.ZipFile(fh) as archive:
        members = {info.filename: info for info in archive.infolist()}
        unpacked = sum(info.file_size for info in members.values())
        if unpacked > limits.max_skeleton_bytes:
            raise LimitError(f"{path}: unpacks to {unpacked:,} bytes, over the limit of "
                             f"{limits.max_skeleton_bytes:,} ({hint('skeleton_bytes')})")
        names, missing = [], None
        for name in NPZ_ARRAYS:
            if f"{name}.npy" in members:
                names.append(name)
            elif name != "material_names":
                missing = name
                break

        def read(name):
            kinds, columns = NPZ_ARRAYS[name]
            with archive.open(members[f"{name}.npy"]) as member:
                return _read_npy(member, name, kinds, columns, path, limits)
        out = dict(zip(names, in_threads(read, names), strict=True))
    if missing is not None:
        raise SkeletonError(f"{path}: not a plantgen skeleton (missing array '{missing}')")
    return out


def _read_npy(member, name: str, kinds: str, columns, path, limits: Limits) -> np.ndarray:
    """One ``.npy`` member: header first (version, dtype, shape), then exactly its data."""
    fmt = np.lib.format
    version = fmt.read_magic(member)
    if version not in ((1, 0), (2, 0)):
        raise SkeletonError(f"{path}: array '{name}' has an unknown .npy version {version}")
    read_header = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
    shape, fortran, dtype = read_header(member)
    if dtype.hasobject:
        raise SkeletonError(f"{path}: array '{name}' holds Python objects (pickled data), which "
                            "plantgen never loads")
    want = (-1,) if columns is None else (-1, columns)
    if dtype.kind not in kinds or len(shape) != len(want) or (columns is not None and shape[1] != columns):
        expected = "(n,)" if columns is None else f"(n, {columns})"
        raise SkeletonError(f"{path}: array '{name}' is {dtype.str} {shape}, expected {expected} of kind "
                            f"{'/'.join(kinds)}")
    limits.check("segments", shape[0], f"{path}: array '{name}' rows")
    count = int(np.prod(shape, dtype=np.int64))
    data = member.read(count * dtype.itemsize)
    if len(data) != count * dtype.itemsize:
        raise SkeletonError(f"{path}: array '{name}' is cut short")
    return np.frombuffer(data, dtype=dtype).reshape(shape, order="F" if fortran else "C")
