"""One plant of a batch, start to finish, in whichever process runs it (a Dask worker):
grow, write its files atomically, measure it, and return its manifest row.

It grows and skins through the same functions as ``plantgen render`` and ``plantgen export``
(:func:`plantgen.pipeline.grow_file`, :func:`plantgen.pipeline.skin_model`, a grammar's
``turtle: smooth_bends`` included), so a view is the PNG ``plantgen render`` draws from
:func:`view_camera` and the glb holds the triangles of ``plantgen export --subdiv m``.

A plant that fails (a bad sweep value, a limit) does not raise: its row says ``failed``
with the one-line error, and the batch goes on. Each process makes its GL context and
ray caster once, on its first render (:func:`_caster`).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..errors import PlantgenError
from ..exporters import export_mesh
from ..files import write_atomically
from ..geometry.meshes.mesh import tessellate
from ..geometry.rays.camera import Camera, auto_camera
from ..geometry.rays.scan import scan_plant
from ..geometry.skeletons.swc import write_swc
from ..geometry.skeletons.topology import branches
from ..gl.raycast import Raycaster, RaycastSettings, label_image
from ..images import write_png
from ..limits import Limits
from ..metrics import tree_metrics
from ..pipeline import check_export_size, check_finite_mesh, grow_file, model_leaves, skin_model
from ..scanfiles import write_points
from ..settings import LookSettings
from .schema import METRIC_COLUMNS, SINGLE_FILE_KINDS, empty_row
from .spec import Outputs, PlantTask

__all__ = ["make_plant", "plant_row", "output_kinds", "relative_files", "view_direction", "view_camera"]

_CASTER: list = []          # this process's Raycaster, made on first use


def _caster() -> Raycaster:
    if not _CASTER:                      # the GL context is made here, not on import
        _CASTER.append(Raycaster())
    return _CASTER[0]


def view_direction(azimuth_deg: float, elevation_deg: float = 15.0) -> tuple[float, float, float]:
    """From the plant towards the eye: ``azimuth`` degrees about +y from +z, raised by
    ``elevation``."""
    a, e = np.radians(azimuth_deg), np.radians(elevation_deg)
    return (float(np.sin(a) * np.cos(e)), float(np.sin(e)), float(np.cos(a) * np.cos(e)))


def view_camera(frusta, size: tuple[int, int], azimuth_deg: float, leaves=None) -> Camera:
    """The camera of one view: the plant's ``frusta`` and ``leaves`` (Polygons or None)
    framed to fill ``size`` (width, height) pixels from ``azimuth_deg`` (:func:`view_direction`)."""
    return auto_camera(frusta, int(size[0]), int(size[1]), direction=view_direction(azimuth_deg),
                       points=None if leaves is None else leaves.vertices)


def output_kinds(outputs: Outputs) -> list[str]:
    """The kinds of file each plant gets, in :data:`~plantgen.batch.spec.OUTPUT_KINDS` order
    (one folder each)."""
    flags = (("npz", outputs.npz), ("swc", outputs.swc), ("glb", outputs.glb is not None), ("png", outputs.png),
             ("depth", outputs.depth), ("mask", outputs.mask is not None), ("points", outputs.points is not None))
    return [kind for kind, on in flags if on]


def relative_files(task: PlantTask, outputs: Outputs) -> dict[str, list[str]]:
    """Relative paths of every file a plant gets, by kind."""
    views = [f"{task.id}_a{int(round(a)) % 360:03d}" for a in outputs.azimuths]
    names = {"npz": [f"npz/{task.id}.npz"], "swc": [f"swc/{task.id}.swc"], "glb": [f"glb/{task.id}.glb"],
             "png": [f"png/{v}.png" for v in views], "depth": [f"depth/{v}.npy" for v in views],
             "mask": [f"mask/{v}.png" for v in views], "points": [f"points/{task.id}.{outputs.points}"]}
    return {kind: names[kind] for kind in output_kinds(outputs)}


def files_column(files: dict[str, list[str]]) -> dict:
    """The manifest's ``files`` struct of :func:`relative_files`: a path for a kind with one
    file per plant, a list for a kind with one per view."""
    return {k: (v[0] if k in SINGLE_FILE_KINDS else v) for k, v in files.items()}


def _save_npy(path, array) -> None:
    with open(path, "wb") as fh:          # a handle: np.save would add .npy to a temporary name
        np.save(fh, array)


#: The label of every leaf in a branch-order mask (leaves hang from no one order).
LEAF_ORDER_LABEL = 255


def _leaf_labels(leaves, kind: str) -> np.ndarray:
    """(p,) label of each leaf polygon for a part mask: its material + 1, the leaf class
    (:data:`LEAF_ORDER_LABEL`) in an order mask, 1 in an instance mask."""
    if kind == "material":
        return leaves.material.astype(np.int64) + 1
    return np.full(len(leaves), LEAF_ORDER_LABEL if kind == "order" else 1, dtype=np.int64)


def _labels(frusta, skeleton, kind: str) -> np.ndarray:
    """(rows,) label of each frustum row for a part mask (1-based; 0 is the background)."""
    seg = frusta.segment
    if kind == "material":
        return frusta.material.astype(np.int64) + 1
    if kind == "order":
        return branches(skeleton).segment_order[seg] + 1
    return np.ones(len(seg), dtype=np.int64)          # instance: one plant per batch row


def _render_views(task, outputs: Outputs, frusta, skeleton, leaves, root: Path, timings: dict) -> None:
    t0 = time.perf_counter()
    caster = _caster()
    settings = RaycastSettings(relief=outputs.relief, look=LookSettings.defaults())
    labels = _labels(frusta, skeleton, outputs.mask) if outputs.mask else None
    top = 255 if leaves is None or outputs.mask != "order" else LEAF_ORDER_LABEL - 1
    if labels is not None and labels.max() > top:
        raise PlantgenError(f"{task.id}: {labels.max()} {outputs.mask} labels, over the {top} a mask PNG holds")
    names = relative_files(task, outputs)
    for i, az in enumerate(outputs.azimuths):
        camera = view_camera(frusta, outputs.size, az, leaves)
        result = caster.render(frusta, camera, settings, frusta.material_names, leaves=leaves)
        if outputs.png:
            write_png(root / names["png"][i], result.color)
        if outputs.depth:
            write_atomically(root / names["depth"][i], lambda p, d=result.distance: _save_npy(p, d))
        if labels is not None:
            mask = label_image(caster, frusta, camera, labels, settings, leaves=leaves,
                               leaf_labels=None if leaves is None else _leaf_labels(leaves, outputs.mask))
            write_png(root / names["mask"][i], mask)
    timings["render"] = time.perf_counter() - t0


def _write_skeleton_files(task, outputs: Outputs, skeleton, root: Path, timings: dict) -> None:
    names = relative_files(task, outputs)
    t0 = time.perf_counter()
    if outputs.npz:
        b = branches(skeleton)
        skeleton.save(root / names["npz"][0], extra={"branch_order": b.segment_order, "branch_id": b.branch})
    if outputs.swc:
        write_swc(skeleton, root / names["swc"][0])
    timings["skeleton_files"] = time.perf_counter() - t0


def _write_glb(task, outputs: Outputs, frusta, skeleton, leaves, root: Path, timings: dict,
               limits: Limits | None) -> None:
    """The mesh ``plantgen export --subdiv m`` makes (its size limits, its tessellation),
    with each vertex's branch order."""
    t0 = time.perf_counter()
    path = root / relative_files(task, outputs)["glb"][0]
    check_export_size([frusta], [leaves], len(skeleton), outputs.glb, "glb", limits, task.id, path)
    mesh = tessellate(frusta, outputs.glb)
    check_finite_mesh(mesh, frusta, task.id)
    order = branches(skeleton).segment_order[frusta.segment]
    export_mesh(mesh, path, labels={"_BRANCH_ORDER": order}, leaves=leaves)
    timings["glb"] = time.perf_counter() - t0


def _write_points(task, outputs: Outputs, frusta, skeleton, leaves, root: Path, timings: dict,
                  limits: Limits | None) -> int:
    """The plant's simulated laser scan (what ``plantgen scan`` makes with the same knobs
    and ``--scan-seed`` the plant's seed), z up as LAS has it; returns its point count."""
    t0 = time.perf_counter()
    cloud = scan_plant(skeleton, leaves, outputs.scan, task.seed, frusta=frusta, limits=limits)
    write_points(cloud, root / relative_files(task, outputs)["points"][0], up="z")
    timings["scan"] = time.perf_counter() - t0
    return len(cloud)


def measure(skeleton) -> dict:
    """The manifest's figures of a skeleton (:mod:`plantgen.batch.schema`): segments, tips,
    the tree metrics in metres (a model unit taken as a metre), the branch count per order
    and the geometry's box."""
    topology = branches(skeleton)
    metrics = tree_metrics(skeleton, topology=topology)
    figures = metrics.as_dict(metres=True)
    row = {k: figures[k] for k in METRIC_COLUMNS}
    row.update(segments=len(skeleton), tips=len(skeleton.tips),
               branches_per_order=np.bincount(topology.order).tolist() if len(topology) else [])
    for end, values in zip(("min", "max"), metrics.bounds, strict=True):
        row.update({f"bbox_{end}_{axis}": float(v) for axis, v in zip("xyz", values, strict=True)})
    return row


def plant_row(task: PlantTask, files: dict, error: str = "") -> dict:
    """A manifest row of ``task`` before it is measured (figures null): ``ok`` with
    ``files`` (kind -> relative paths), or ``failed`` with its one-line ``error``."""
    row = empty_row()
    row.update(id=task.id, grammar=task.name, index=task.index, seed=task.seed, defines=list(task.defines),
               status="failed" if error else "ok", error=error, files=files_column(files), fingerprint=task.fingerprint)
    return row


def make_plant(task: PlantTask, outputs: Outputs, out_dir: str, limits: Limits | None = None,
               allow_paths=()) -> dict:
    """Grow ``task``'s plant, write its ``outputs`` under ``out_dir`` (absolute: a worker's
    working directory is its own) and return its manifest row (a dict of the columns of
    :mod:`plantgen.batch.schema`). ``allow_paths``: folders a scene used as a grammar may
    read grammars from."""
    root = Path(out_dir)
    timings: dict = {}
    row = plant_row(task, relative_files(task, outputs))
    try:
        t0 = time.perf_counter()
        grown = grow_file(task.grammar, seed=task.seed, limits=limits, defines=dict(task.defines),
                          allow_paths=allow_paths, jobs=1)     # the batch's workers are its parallelism
        skeleton = grown.skeleton
        timings["grow"] = time.perf_counter() - t0
        if len(skeleton) == 0:
            raise PlantgenError(f"{task.name}: the grammar draws no segments")
        _write_skeleton_files(task, outputs, skeleton, root, timings)
        if outputs.glb is not None or outputs.views or outputs.points is not None:
            t0 = time.perf_counter()
            frusta = skin_model(grown, source=task.id)
            timings["skin"] = time.perf_counter() - t0
            leaves = model_leaves(grown)
            if outputs.glb is not None:
                _write_glb(task, outputs, frusta, skeleton, leaves, root, timings, limits)
            if outputs.views:
                _render_views(task, outputs, frusta, skeleton, leaves, root, timings)
            if outputs.points is not None:
                row["scan_points"] = _write_points(task, outputs, frusta, skeleton, leaves, root, timings, limits)
        t0 = time.perf_counter()
        row.update(measure(skeleton))
        timings["metrics"] = time.perf_counter() - t0
    except PlantgenError as exc:
        row.update(status="failed", error=str(exc).splitlines()[0][:500] if str(exc) else type(exc).__name__)
    except MemoryError:
        row.update(status="failed", error=f"{task.id}: out of memory")
    row["timings"] = {k: round(v, 6) for k, v in timings.items()}
    return row
