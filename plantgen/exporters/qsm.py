"""Forestry cylinder models (QSM) in TreeQSM's fields: ``.qsm.csv`` and ``.qsm.mat``.

Foresters compare tree reconstructions with TreeQSM's cylinder model; rTwig, SimpleForest
and GroIMP read the same fields. A cylinder is ``start`` (its base centre), ``axis`` (unit
direction), ``length`` and ``radius``, with the tree's structure: ``parent`` (the cylinder
it grows from), ``extension`` (the cylinder that carries its branch on), ``branch``,
``BranchOrder`` (0 the trunk) and ``PositionInBranch``. As in TreeQSM, cylinder and
branch numbers start at 1 and 0 means none; branch 1 is the trunk (the chain of the first
segment, :mod:`plantgen.geometry.skeletons.topology`).

**Frusta to cylinders.** A segment is a conical frustum (radii r1, r2, length h). It is
split into k equal cylinders, each with the frustum's radius at its middle (the mean of
its end radii: what a fit to points on the frustum gives). Each cylinder then lacks
π·(h/k)·(Δr/k)²/12 of its frustum's volume (Δr = r1 - r2), so the segment lacks
Δr²/(4k²·(r1² + r1·r2 + r2²)) of its volume: k is the smallest count that keeps this
under ``tolerance`` (default 0.001: 0.1 %). A cylinder (r1 = r2) stays one; a cone
closing to a point needs 16 at 0.1 %; ``tolerance=1`` exports every segment as one
cylinder of its mean radius (up to 25 % short, for a cone).

**Units and frame.** Files are in metres: model units times ``unit`` (metres per model
unit, default 1), z up (TreeQSM's convention; ``up="y"`` keeps plantgen's frame).
Volumes are in litres and areas in m², as TreeQSM writes them.

**Files.** ``tree.qsm.csv``: one row per cylinder, the columns rTwig names TreeQSM's
fields by (``radius, length, start.x, start.y, start.z, axis.x, axis.y, axis.z, parent,
extension, added, UnmodRadius, branch, BranchOrder, PositionInBranch``; ``added`` is 0 and
``UnmodRadius`` the radius: nothing was filled in or corrected), and beside it
``tree.treedata.csv``: ``name, value, unit`` rows of the tree-level figures
(:mod:`plantgen.metrics`) under TreeQSM's names: ``TotalVolume``, ``TrunkVolume``,
``BranchVolume`` (litres, of the cylinders), ``TotalVolumeFrusta`` (litres, of the
frusta: the exact figure the cylinders approach), ``TreeHeight``, ``TrunkLength``,
``BranchLength``, ``NumberBranches``, ``MaxBranchOrder``, ``TotalArea``, ``DBHqsm`` (the
trunk's diameter 1.3 m along it; empty where the trunk is shorter), ``CrownDiamAve``,
``CrownDiamMax``, ``CrownAreaConv``, ``location``. ``tree.qsm.mat`` (scipy's
``savemat``; ``plantgen[qsm]``): the variable ``QSM``, a struct as TreeQSM saves it, with
``cylinder``, ``branch`` (``order, parent, volume, length, angle, height, azimuth,
diameter``), ``treedata`` (the figures above and ``StemTaper``), ``rundata`` (the
writer, units, tolerance), ``pmdistance`` (point-to-model distances: NaN, there is no
point cloud) and ``triangulation`` (0: none).
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..files import check_finite, write_all_atomically, write_atomically
from ..geometry.skeletons.frames import up_rotation
from ..geometry.skeletons.skeleton import Skeleton
from ..geometry.skeletons.topology import Branches, branches
from ..metrics import TreeMetrics, segment_lengths, segment_volumes, tree_metrics
from .formats import ExportError
from .gltf import generator

__all__ = ["CYLINDER_COLUMNS", "CylinderModel", "cylinder_model", "pieces_for", "treedata", "write_qsm"]

#: Columns of the ``.qsm.csv`` file (rTwig's names of TreeQSM's fields).
CYLINDER_COLUMNS = ("radius", "length", "start.x", "start.y", "start.z", "axis.x", "axis.y", "axis.z",
                    "parent", "extension", "added", "UnmodRadius", "branch", "BranchOrder", "PositionInBranch")
#: The finest split asked for: at most about 500 cylinders for a segment.
MIN_TOLERANCE = 1e-6


def pieces_for(r1: np.ndarray, r2: np.ndarray, tolerance: float) -> np.ndarray:
    """(n,) cylinders per frustum: the fewest k with Δr²/(4k²(r1² + r1·r2 + r2²)) <= tolerance."""
    r1, r2 = np.asarray(r1, dtype=np.float64), np.asarray(r2, dtype=np.float64)
    s = r1 * r1 + r1 * r2 + r2 * r2
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.ceil(np.abs(r1 - r2) / (2.0 * np.sqrt(tolerance * s)) - 1e-12)
    return np.maximum(np.where(s > 0, k, 1), 1).astype(np.int64)


@dataclass(frozen=True, eq=False)
class CylinderModel:
    """Cylinders of a skeleton in model units and plantgen's frame (y up); indices 0-based,
    -1 for none (the files add 1)."""

    start: np.ndarray            # (c, 3)
    axis: np.ndarray             # (c, 3) unit
    length: np.ndarray           # (c,)
    radius: np.ndarray           # (c,)
    parent: np.ndarray           # (c,) cylinder, -1
    extension: np.ndarray        # (c,) cylinder, -1
    branch: np.ndarray           # (c,) 0 the trunk
    order: np.ndarray            # (c,) branch order
    position: np.ndarray         # (c,) place in its branch, from 0
    segment: np.ndarray          # (c,) the skeleton segment it comes from
    tolerance: float

    def __len__(self) -> int:
        return len(self.length)

    @property
    def volume(self) -> np.ndarray:
        return np.pi * self.radius ** 2 * self.length


def cylinder_model(skeleton: Skeleton, tolerance: float = 1e-3, topology: Branches | None = None) -> CylinderModel:
    """Split every segment into the cylinders of the module docstring."""
    if not tolerance >= MIN_TOLERANCE:
        raise ExportError(f"the cylinder model's volume tolerance must be >= {MIN_TOLERANCE:g}, got {tolerance!r}")
    topology = topology or branches(skeleton)
    k = pieces_for(skeleton.r_start, skeleton.r_end, tolerance)
    segment = np.repeat(np.arange(len(skeleton)), k)
    first = np.cumsum(k) - k
    j = np.arange(len(segment)) - first[segment]                       # piece within its segment
    t0, t1 = j / k[segment], (j + 1) / k[segment]
    s, e = skeleton.start[segment], skeleton.end[segment]
    start = s + t0[:, None] * (e - s)
    lengths = segment_lengths(skeleton)
    axis = _axes(skeleton, lengths)[segment]
    r1, r2 = skeleton.r_start[segment], skeleton.r_end[segment]
    radius = r1 + (r2 - r1) * (t0 + t1) / 2
    last = first + k - 1
    parent_seg = skeleton.parent[segment]
    parent = np.where(j > 0, np.arange(len(segment)) - 1,
                      np.where(parent_seg >= 0, last[np.maximum(parent_seg, 0)], -1))
    following = topology.next[segment]
    extension = np.where(j < k[segment] - 1, np.arange(len(segment)) + 1,
                         np.where(following >= 0, first[np.maximum(following, 0)], -1))
    # Place in branch: the pieces of the earlier segments of the branch, then j.
    order = np.lexsort((topology.position, topology.branch))
    counts = k[order]
    before = np.cumsum(counts) - counts
    branch_first = np.full(len(topology), 0, dtype=np.int64)
    is_first = topology.position[order] == 0
    branch_first[topology.branch[order][is_first]] = before[is_first]
    offset = np.empty(len(skeleton), dtype=np.int64)
    offset[order] = before - branch_first[topology.branch[order]]
    return CylinderModel(start, axis, lengths[segment] / k[segment], radius, parent, extension,
                         topology.branch[segment], topology.segment_order[segment], offset[segment] + j,
                         segment, float(tolerance))


def _axes(skeleton: Skeleton, lengths: np.ndarray) -> np.ndarray:
    """Unit axis of every segment; a segment of zero length takes its parent's (up for a root)."""
    axes = np.zeros((len(skeleton), 3))
    axes[:, 1] = 1.0
    ok = lengths > 0
    axes[ok] = (skeleton.end[ok] - skeleton.start[ok]) / lengths[ok, None]
    for i in np.flatnonzero(~ok):                                        # rare: a loop is fine
        p = int(skeleton.parent[i])
        axes[i] = axes[p] if p >= 0 else axes[i]
    return axes


def treedata(model: CylinderModel, metrics: TreeMetrics, skeleton: Skeleton, unit: float,
             rot: np.ndarray) -> dict:
    """TreeQSM's tree-level figures, metres, litres and m²: name -> (value, unit)."""
    trunk = model.branch == 0
    litres = 1000.0 * unit ** 3
    dbh = np.nan if metrics.dbh is None else metrics.dbh * unit
    return {
        "TotalVolume": (float(model.volume.sum()) * litres, "L"),
        "TrunkVolume": (float(model.volume[trunk].sum()) * litres, "L"),
        "BranchVolume": (float(model.volume[~trunk].sum()) * litres, "L"),
        "TotalVolumeFrusta": (float(segment_volumes(skeleton).sum()) * litres, "L"),
        "TreeHeight": (metrics.height * unit, "m"),
        "TrunkLength": (float(model.length[trunk].sum()) * unit, "m"),
        "BranchLength": (float(model.length[~trunk].sum()) * unit, "m"),
        "NumberBranches": (metrics.branches, ""),
        "MaxBranchOrder": (metrics.max_branch_order, ""),
        "TotalArea": (float(2 * np.pi * (model.radius * model.length).sum()) * unit ** 2, "m^2"),
        "DBHqsm": (dbh, "m"),
        "CrownDiamAve": (metrics.crown.mean_width * unit, "m"),
        "CrownDiamMax": (metrics.crown.max_width * unit, "m"),
        "CrownAreaConv": (metrics.crown.area * unit ** 2, "m^2"),
        "location": ((metrics.base @ rot.T) * unit, "m"),
    }


def _branch_struct(model: CylinderModel, topology: Branches, unit: float, base_height: float) -> dict:
    """TreeQSM's ``branch`` struct: one entry per branch."""
    first = np.flatnonzero(model.position == 0)                      # first cylinder of each branch
    first = first[np.argsort(model.branch[first])]
    up = model.axis[first]
    parent_cyl = model.parent[first]
    parent_axis = np.where(parent_cyl[:, None] >= 0, model.axis[np.maximum(parent_cyl, 0)], up)
    angle = np.degrees(np.arccos(np.clip(np.sum(up * parent_axis, axis=1), -1.0, 1.0)))
    b = len(topology)
    def column(v):
        return np.asarray(v, dtype=np.float64).reshape(-1, 1)

    return {"order": column(topology.order), "parent": column(topology.parent + 1),
            "volume": column(np.bincount(model.branch, model.volume, b) * 1000.0 * unit ** 3),
            "length": column(np.bincount(model.branch, model.length, b) * unit),
            "angle": column(angle), "height": column((model.start[first, 1] - base_height) * unit),
            "azimuth": column(np.degrees(np.arctan2(-up[:, 2], up[:, 0]))),
            "diameter": column(2 * model.radius[first] * unit)}


def _stem_taper(model: CylinderModel, unit: float) -> np.ndarray:
    """(2, t+1): distance along the trunk and its diameter there, as TreeQSM's StemTaper."""
    trunk = np.flatnonzero(model.branch == 0)
    trunk = trunk[np.argsort(model.position[trunk])]
    r, length = model.radius[trunk], model.length[trunk]
    return np.vstack([np.concatenate([[0.0], np.cumsum(length)]) * unit,
                      np.concatenate([[2 * r[0]], 2 * r[1:], [2 * r[-1]]]) * unit])


def _cylinder_columns(model: CylinderModel, unit: float, rot: np.ndarray) -> dict:
    def column(v):
        return np.asarray(v, dtype=np.float64).reshape(len(model), -1)

    return {"radius": column(model.radius * unit), "length": column(model.length * unit),
            "start": column((model.start @ rot.T) * unit), "axis": column(model.axis @ rot.T),
            "parent": column(model.parent + 1), "extension": column(model.extension + 1),
            "added": np.zeros((len(model), 1), dtype=bool), "UnmodRadius": column(model.radius * unit),
            "branch": column(model.branch + 1), "BranchOrder": column(model.order),
            "PositionInBranch": column(model.position + 1)}


def _csv_text(columns: dict) -> str:
    table = np.hstack([np.asarray(v, dtype=np.float64) for v in columns.values()])
    integers = {"parent", "extension", "added", "branch", "BranchOrder", "PositionInBranch"}
    fmt = ",".join("%d" if name in integers else "%.9g" for name in CYLINDER_COLUMNS)
    out = io.StringIO()
    np.savetxt(out, table, fmt=fmt, delimiter=",", header=",".join(CYLINDER_COLUMNS), comments="")
    return out.getvalue()


def _treedata_text(figures: dict) -> str:
    rows = ["name,value,unit"]
    for name, (value, unit) in figures.items():
        if name == "location":
            rows += [f"location.{axis},{v:.9g},{unit}" for axis, v in zip("xyz", value, strict=True)]
        else:
            rows.append(f"{name},{'' if value is None or value != value else format(value, '.9g')},{unit}")
    return "\n".join(rows) + "\n"


def write_qsm(skeleton: Skeleton, path: str | Path, *, up: str = "z", unit: float = 1.0,
              tolerance: float = 1e-3, name: str = "plant") -> dict:
    """Write the cylinder model of ``skeleton`` as ``.qsm.csv`` (with ``.treedata.csv``
    beside it) or ``.qsm.mat`` (see the module docstring). Returns a summary: ``paths``,
    ``cylinders``, ``segments``, ``volume`` (cylinders) and ``volume_frusta`` (model
    units³), and ``metrics`` (:class:`~plantgen.metrics.TreeMetrics`)."""
    path = Path(path)
    if len(skeleton) == 0:
        raise ExportError(f"{path}: nothing to export (the model has no segments)")
    if not unit > 0:
        raise ExportError(f"{path}: the unit must be a positive number of metres, got {unit!r}")
    topology = branches(skeleton)
    model = cylinder_model(skeleton, tolerance, topology)
    metrics = tree_metrics(skeleton, unit=unit, topology=topology)
    rot = up_rotation(up)
    figures = treedata(model, metrics, skeleton, unit, rot)
    columns = _cylinder_columns(model, unit, rot)
    check_finite(path, "a cylinder", *columns.values(), error=ExportError)
    # a figure a tree does not have (None, NaN: written blank) is fine; an infinite one is not
    values = (np.asarray(v, dtype=np.float64) for v, _ in figures.values() if v is not None)
    check_finite(path, "a tree figure", *(v[~np.isnan(v)] for v in values), error=ExportError)
    if path.name.lower().endswith(".mat"):
        paths = [_write_mat(path, columns, figures, model, topology, unit, metrics, up, name)]
    else:
        beside = path.with_name(path.name[: -len(".qsm.csv")] + ".treedata.csv")
        csv, tree = _csv_text(columns), _treedata_text(figures)
        paths = write_all_atomically([(beside, lambda tmp: Path(tmp).write_text(tree, encoding="utf-8")),
                                      (path, lambda tmp: Path(tmp).write_text(csv, encoding="utf-8"))],
                                     ExportError)
    return {"paths": paths, "cylinders": len(model), "segments": len(skeleton),
            "volume": float(model.volume.sum()), "volume_frusta": metrics.volume, "metrics": metrics,
            "tolerance": model.tolerance}


def _write_mat(path, columns, figures, model, topology, unit, metrics, up, name) -> Path:
    from scipy.io import savemat  # the optional extra plantgen[qsm]

    tree = {key: (np.nan if value is None else np.asarray(value, dtype=np.float64).reshape(1, -1)
                  if key == "location" else value) for key, (value, _) in figures.items()}
    tree["StemTaper"] = _stem_taper(model, unit)
    qsm = {"cylinder": columns,
           "branch": _branch_struct(model, topology, unit, float(metrics.base[1])),
           "treedata": tree,
           "rundata": {"version": generator(), "model": name, "units": "m, L, m^2", "up": up,
                       "metres_per_model_unit": float(unit), "volume_tolerance": model.tolerance},
           "pmdistance": {"median": np.nan, "mean": np.nan, "max": np.nan, "std": np.nan},
           "triangulation": 0}

    def write(tmp):
        with open(tmp, "wb") as fh:
            savemat(fh, {"QSM": qsm}, do_compression=True, oned_as="column")
    return write_atomically(path, write, ExportError)
