"""``plantgen export`` from an input to a file: skin, tessellate and write a mesh (a
scene's repeated plants once, instanced, where the format can; its levels of detail, its
sway, its textures, the asset's cards and impostor), or write the skeleton as SWC or a
forestry cylinder model (:func:`export_model`).

Every check that needs no work comes first (the format, its extra, the outputs), then
the export's budget: triangles and memory estimated from the segments before anything is
skinned (:func:`check_export_size` once the frusta are known, :func:`check_sway_size` for
a sway's keys). The model is grown by :func:`~plantgen.pipeline.growing.grow_file` and
skinned as a render skins it (:func:`~plantgen.pipeline.render.skinning`); a scene's
camera is framed as a render frames it (:func:`scene_extras`).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..assets import AssetSettings, asset_lines, budget_warnings, finished_plants
from ..exporters import (
    DetailLevel,
    ExportError,
    Plant,
    PlantDetail,
    PlantSway,
    SceneExtras,
    Timeline,
    check_extra,
    estimate_export_bytes,
    export_format,
    sway_timeline,
    write_plants,
    write_skeleton,
)
from ..exporters.formats import check_export_outputs
from ..exporters.plants import level_plant
from ..exporters.textures import bake_textures, split_by_aspect
from ..geometry.meshes.mesh import tessellate, triangle_count
from ..geometry.meshes.polygons import Polygons
from ..geometry.rays.camera import frame_copies
from ..geometry.rays.instances import detail_levels, detail_order, screen_coverage
from ..geometry.skeletons.frames import UP_AXES
from ..geometry.skeletons.frusta import Frusta, frusta_bounds
from ..geometry.skeletons.skeleton import Skeleton
from ..geometry.skeletons.skin import skin_skeleton
from ..limits import LimitError, Limits, hint
from ..settings import DEFAULT_SIZE, DetailSettings, KeyframeSettings, LevelSettings
from .checks import SKIN_BYTES_PER_SEGMENT, check_finite_frusta, check_finite_mesh, distinct_segments, in_force
from .growing import GrowResult, grow_file
from .render import model_leaves, skinning, smoothing, stage_model

#: How ``export_model`` writes a scene's repeated plants (see :func:`export_model`).
INSTANCING = ("nodes", "gpu", "off")


#: The tessellation level an export makes when none is asked for, where it fits the limits.
DEFAULT_LEVEL = 1


def export_model(input_path, output_path, *, level: int | None = DEFAULT_LEVEL, relief: bool = False,
                 seed: int | None = None, limits: Limits | None = None, allow_paths=(),
                 up: str | None = None, instancing: str = "nodes", unit: float = 1.0,
                 qsm_tolerance: float = 1e-3, progress=None, smooth_bends: float | None = None,
                 keyframes: KeyframeSettings | None = None, textures: bool = True,
                 aspect_step: float | None = None, detail: DetailSettings | None = None,
                 levels: LevelSettings | None = None, asset: AssetSettings | None = None, ground=False,
                 jobs: int | None = None) -> dict:
    """The library side of ``plantgen export``: input file -> skin -> tessellate -> file,
    or, for a skeleton format (``.swc``, ``.qsm.csv``, ``.qsm.mat``), input -> file.

    Parameters
    ----------
    input_path : a skeleton ``.npz`` or ``.swc``, a grammar or a scene
    output_path : the file; its suffix names the format (:mod:`plantgen.exporters.formats`)
    level, relief, up : the tessellation (GS, GS+R; None: :func:`_fitting_level`); ``"y"``, ``"z"`` or the format's
    instancing : how a scene's repeated plants are written where the format can
        (glTF, USD): ``"nodes"`` (the default) once, with one node per copy sharing the
        plant's mesh (core glTF, which every reader opens; USD instanceable references);
        ``"gpu"`` once, with glTF's ``EXT_mesh_gpu_instancing`` (required by the file) or
        a USD ``PointInstancer``; ``"off"`` every copy's own mesh, as OBJ, PLY and STL
    unit : metres per model unit (USD's ``metersPerUnit``; QSM files are in metres)
    qsm_tolerance : the cylinder model's volume tolerance (:mod:`plantgen.exporters.qsm`)
    progress : ``progress(stage, done, total)``: :func:`grow_file`'s stages, ``tessellate``, ``write``
    smooth_bends : None, or bends past this many degrees become arcs of frusta before the
        mesh is made (:func:`skinning`; the summary's ``smooth_segments`` counts the segments they add)
    keyframes : the keys of the sway a glTF or USD export writes for a scene that lists
        ``animation`` and sways (:class:`~plantgen.settings.KeyframeSettings`; None: its
        defaults, over one common period); a format without animation writes the
        plants at rest and says so in ``warnings``
    textures, aspect_step : the relief baked into maps for glTF, OBJ, USD (with ``relief``: base
        colour only); with ``aspect_step``, normal maps per aspect bucket (:func:`_textured`)
    levels, detail : the levels of detail glTF and USD write (:meth:`LevelSettings.export_levels`: ``--lod-levels``,
        else 4 for a scene listing ``lod``; :func:`plant_detail`), their coverages for ``detail.lod_pixels``
    asset : leaf cards, impostor, a game asset (:class:`~plantgen.assets.AssetSettings`; None: its defaults)

    Returns a summary dict: ``format``, ``up``, ``segments``, ``paths`` (every file
    written), ``path`` (the main one), ``timings`` (seconds per stage) and, for meshes,
    ``rows``, ``caps``, ``triangles`` and ``vertices`` (written), ``plants`` and
    ``copies`` (distinct plants and their copies), ``drawn`` (triangles with every copy),
    ``level``, ``relief``, ``leaf_triangles`` (the leaf polygons of a grammar, or of a scene's plants (once
    per distinct plant when instanced), beside the frusta and counted in ``triangles``, ``vertices`` and
    ``drawn``), ``animation`` (None, or the
    sway written: ``keys``, ``duration``, ``rate``, ``loops``, ``joints``, ``skins``),
    ``levels`` ([(rows, triangles)] per level of detail, summed over the plants written
    once; empty: none), ``scene`` (what of a scene's ``"camera"``, ``"light"`` and ``"ground"`` the file holds
    besides its plants: glTF and USD, :func:`scene_extras`; a grammar's ground disc with ``ground``), ``textures``
    (:func:`_texture_summary`); for a cylinder model, what :func:`~plantgen.exporters.qsm.write_qsm`
    returns. Triangles and memory are estimated before anything is built and refused over ``limits``.
    """
    output_path, limits = Path(output_path), in_force(limits)
    fmt, asset = _export_checks(output_path, up, instancing, asset or AssetSettings(), unit)
    up, t0 = up or fmt.up, time.perf_counter()
    grown = grow_file(input_path, seed=seed, limits=limits, allow_paths=allow_paths, progress=progress, jobs=jobs)
    _export_budget(grown, fmt, instancing, 0 if level is None else level, limits, input_path, output_path)
    for skeleton in _distinct_skeletons(grown, fmt.kind == "skeleton"):
        skeleton.validate()
    timings = {"load": time.perf_counter() - t0}
    summary = {"format": fmt.name, "up": up, "segments": grown.segments, "timings": timings,
               "warnings": grown.warnings}
    timeline = _export_timeline(grown, fmt, keyframes, input_path, summary)
    if fmt.kind == "skeleton":
        return _export_skeleton(grown, fmt, output_path, up, unit, qsm_tolerance, summary)
    skin = skinning(smoothing(grown, smooth_bends))
    plants, smoothed, level = _tessellated_plants(grown, fmt, instancing if fmt.instancing else "off", level, relief,
                                                  limits, input_path, output_path, timings, progress, skin, timeline,
                                                  _export_detail(grown, fmt, asset.levels(levels), detail, summary),
                                                  summary)
    t3 = time.perf_counter()
    extras = (scene_extras(grown, skin, input_path, _per_copy(grown, fmt, instancing, limits), ground=ground)
              if fmt.scene else None)
    plants, baked = _finished(plants, asset, skin, relief, textures and fmt.textures and aspect_step, summary, progress)
    t4 = time.perf_counter()
    paths = write_plants(plants, output_path, up=up, instancing="gpu" if instancing == "gpu" else "nodes", unit=unit,
                         name=grown.name, progress=progress, animation=timeline, extras=extras, textures=baked)
    timings.update(finish=t4 - t3, write=time.perf_counter() - t4)   # finish: the camera, cards, textures
    summary.update(_mesh_counts(plants), level=level, relief=relief, paths=paths, path=paths[-1],
                   smooth_segments=smoothed, animation=_animation_counts(plants, timeline),
                   scene=_extras_written(extras), textures=_texture_summary(baked))
    return summary


def _extras_written(extras: SceneExtras | None) -> tuple[str, ...]:
    """Which of a scene's camera, light and ground an export's file holds."""
    return () if extras is None else tuple(k for k in ("camera", "light", "ground") if getattr(extras, k) is not None)


def _per_copy(grown: GrowResult, fmt, instancing: str, limits: Limits) -> bool:
    """Whether a scene's camera is framed per copy (:func:`scene_extras`): written
    instanced, with more placed segments than one model may have."""
    return bool(fmt.instancing and instancing != "off" and grown.segments > limits.max_segments)


def _export_checks(output_path: Path, up: str | None, instancing: str, asset: AssetSettings, unit: float = 1.0):
    """The export's format and ``asset``, after every check that needs no work: a known
    suffix, its extra installed, the up axis, the instancing, what the asset asks (cards
    and impostors: glTF), the unit, every output writable (one line each)."""
    if not 1e-9 <= unit <= 1e9:          # so a cylinder model's volumes (unit³) stay finite
        raise ExportError(f"the unit must be 1e-09..1e+09 metres, got {unit!r}")
    fmt = export_format(output_path)
    check_extra(fmt, output_path)
    asset.check(fmt, output_path)
    if up is not None and up not in UP_AXES:
        raise ExportError(f"up must be one of {', '.join(UP_AXES)}, got {up!r}")
    if instancing not in INSTANCING:
        raise ExportError(f"instancing must be one of {', '.join(INSTANCING)}, got {instancing!r}")
    check_export_outputs(output_path, fmt)
    return fmt, asset


def _export_budget(grown: GrowResult, fmt, instancing: str, level: int, limits: Limits, input_path,
                   output_path) -> None:
    """Refuse, before anything is skinned, a model with no segment or a mesh export whose
    memory is over ``limits.max_export_bytes`` at its least: the segments it skins (every
    placed copy where the format or ``instancing`` writes each copy, else each distinct
    plant once), 16·4^m triangles each at the format's bytes; and for a glTF or USD scene
    framed automatically, the skin of every placed copy its camera is framed on (written
    instanced with more placed segments than ``limits.max_segments``, the camera frames each
    distinct plant's bound per copy instead: :func:`scene_extras`)."""
    if grown.segments == 0:
        raise ExportError(f"{input_path}: the model has no segments" + (
            " (its polygons alone are not exported; plantgen render and scan draw them)"
            if model_leaves(grown) is not None else ""))
    if fmt.kind != "mesh":
        return
    each = instancing == "off" or not fmt.instancing or grown.scene is None
    skinned = grown.segments if each else distinct_segments(grown.scene)
    triangles = skinned * 16 * 4 ** int(level)
    if triangles > limits.max_export_triangles:
        raise ExportError(f"{input_path}: m = {level} gives at least {triangles:,} triangles, over the export limit "
                          f"of {limits.max_export_triangles:,}; choose a lower --subdiv ({hint('export_triangles')})")
    need = estimate_export_bytes(triangles, fmt.name) + skinned * SKIN_BYTES_PER_SEGMENT
    what = f"{skinned:,} segments{'' if each else ' (each distinct plant once)'} at m = {level}"
    if fmt.scene and (each or grown.segments <= limits.max_segments) and grown.scene is not None \
            and grown.scene.camera is None and grown.segments * SKIN_BYTES_PER_SEGMENT > need:   # skins every copy
        need = grown.segments * SKIN_BYTES_PER_SEGMENT
        what = f"framing the scene's camera on its {grown.segments:,} placed segments"
    if need > limits.max_export_bytes:
        raise LimitError(f"{output_path}: {what} needs at least {need / 2**20:,.0f} MiB to build and write as "
                         f"{fmt.name}, over the limit of {limits.max_export_bytes / 2**20:,.0f} MiB (choose a "
                         f"lower --subdiv, give a scene a camera, or {hint('export_bytes')})")


def _distinct_skeletons(grown: GrowResult, merged: bool) -> list[Skeleton]:
    """The skeletons an export checks: the whole model (``merged``, or not a scene), else a
    scene's distinct plants, each once (placing a valid plant keeps it valid: a placed
    copy was checked finite when the scene was read)."""
    if merged or grown.scene is None:
        return [grown.skeleton]
    return [plant.skeleton for plant in grown.scene.plants()]


def _finished(plants: list[Plant], asset: AssetSettings, skin, relief: bool, aspect_step, summary: dict,
              progress=None) -> tuple[list[Plant], object]:
    """The plants as written (:func:`~plantgen.assets.finished_plants`: an impostor, leaf
    cards, where ``asset`` asks; a game asset's levels over their budgets are warned of in
    ``summary``) and their textures (:func:`_textured`; ``aspect_step`` False: none)."""
    plants = finished_plants(plants, asset, skin, relief, progress)
    summary["warnings"] = (*summary["warnings"], *budget_warnings(_level_counts(plants), asset))
    summary["asset_lines"] = asset_lines(plants)
    return (plants, None) if aspect_step is False else _textured(plants, relief, aspect_step)


def _textured(plants: list[Plant], relief: bool, aspect_step: float | None) -> tuple[list[Plant], object]:
    """The plants (split by aspect where ``aspect_step`` is given and the mesh is not
    displaced: :func:`~plantgen.exporters.textures.split_by_aspect`) and their baked maps
    (:func:`~plantgen.exporters.textures.bake_textures`)."""
    bases = None
    if aspect_step and not relief:
        plants, bases = split_by_aspect(plants, aspect_step)
    return plants, bake_textures([p.mesh for p in plants], displaced=relief, bases=bases)


def _texture_summary(baked) -> dict:
    """{material: {"size": (H, W), "aspect", "kinds"}} of the baked textures (empty: none)."""
    if baked is None:
        return {}
    return {name: {"size": t.size.shape, "aspect": t.aspect, "kinds": baked.kinds}
            for name, t in baked.materials.items()}


def _export_skeleton(grown: GrowResult, fmt, output_path: Path, up: str, unit: float, tolerance: float,
                     summary: dict) -> dict:
    """:func:`export_model` of a skeleton format: ``summary`` with what the writer returns
    (a warning when a grammar's leaves are left out)."""
    if grown.polygons is not None and len(grown.polygons):
        summary["warnings"] = (*summary["warnings"], f"{fmt.suffix} carries the skeleton only: "
                               f"{len(grown.polygons)} leaf polygons not written (a mesh format keeps them)")
    t1 = time.perf_counter()
    summary.update(write_skeleton(grown.skeleton, output_path, up=up, unit=unit, tolerance=tolerance,
                                  name=grown.name))
    summary["timings"]["write"] = time.perf_counter() - t1
    return dict(summary, path=summary["paths"][-1])


def scene_extras(grown: GrowResult, skin=skin_skeleton, source=None, instanced: bool = False, *,
                 ground: bool = False) -> SceneExtras | None:
    """What a glTF or USD export writes around a scene's plants: the camera ``plantgen
    render`` would use at its default size (the scene's camera, or for ``camera: auto``
    the model framed as :func:`stage_model` frames it, its frusta skinned with ``skin``;
    ``instanced``: each distinct plant skinned once and its box framed per copy,
    :func:`~plantgen.geometry.rays.camera.frame_copies`), the scene's light and its
    ground; for a grammar or a skeleton, None, or with ``ground`` only the ground disc
    ``plantgen render`` draws under it (:func:`~plantgen.geometry.stage.model_ground`: a
    reference renderer sees what it sees)."""
    scene = grown.scene
    if scene is None:
        if not ground:
            return None
        frusta = check_finite_frusta(skin(grown.skeleton), source or grown.name)
        return SceneExtras(ground=stage_model(grown, frusta, *DEFAULT_SIZE, ground="auto").ground)
    width, height = DEFAULT_SIZE
    if scene.camera is not None:
        camera = scene.camera.at_size(width, height)
    elif instanced:
        camera = frame_copies([(check_finite_frusta(skin(p.skeleton), source or grown.name), p.matrices,
                                None if p.polygons is None else p.polygons.vertices) for p in scene.plants()],
                              width, height)
    else:
        camera = stage_model(grown, check_finite_frusta(skin(grown.skeleton), source or grown.name), width,
                             height).camera
    return SceneExtras(camera, scene.light, scene.ground)


def _export_timeline(grown: GrowResult, fmt, keyframes: KeyframeSettings | None, input_path,
                     summary: dict) -> Timeline | None:
    """The key times of the sway an export writes: a scene that lists ``animation`` and
    sways, written in a format that animates, unless ``keyframes.sway`` is off; else None (a warning in ``summary`` says
    when a format without animation leaves a sway out)."""
    scene, keyframes = grown.scene, keyframes or KeyframeSettings()
    if scene is None or "animation" not in scene.effects or not keyframes.sway:
        return None
    sways = [i.motion for i in scene.instances]
    if not fmt.animation:
        if any(s is not None and s.moves for s in sways):
            summary["warnings"] = (*summary["warnings"], f"{fmt.suffix} holds no animation: the scene's sway is "
                                   "not written, its plants stand at rest (glTF and USD carry the sway)")
        return None
    return sway_timeline(sways, keyframes, input_path)


def _animation_counts(plants: list[Plant], timeline: Timeline | None) -> dict | None:
    """What the sway written holds (see :func:`export_model`), or None."""
    swaying = [p for p in plants if timeline is not None and p.sway is not None and p.sway.moves]
    if not swaying:
        return None
    return dict(keys=timeline.keys, duration=timeline.duration, rate=timeline.rate, loops=timeline.loops,
                joints=sum(len(p.skeleton) * p.copies for p in swaying), skins=sum(p.copies for p in swaying))


def _export_detail(grown: GrowResult, fmt, levels: LevelSettings | None, detail: DetailSettings | None,
                   summary: dict) -> tuple[int, float]:
    """(levels, pixels) of the levels of detail the export writes (:func:`plant_detail`):
    1 (none) for a format without them, where a warning in ``summary`` says so if they
    were asked for."""
    asked, pixels = levels or LevelSettings(), (detail or DetailSettings()).lod_pixels
    count = asked.export_levels(grown.scene.effects if grown.scene is not None else ())
    if count > 1 and not fmt.instancing:
        if asked.levels is not None:
            summary["warnings"] = (*summary["warnings"], f"{fmt.suffix} holds no levels of detail: the full "
                                   "mesh only (glTF and USD carry them)")
        return 1, pixels
    return count, pixels


def plant_detail(frusta: Frusta, parent, mesh, leaves: Polygons | None, levels: int, pixels: float,
                 relief: bool = False, height: int = DEFAULT_SIZE[1]) -> PlantDetail | None:
    """A plant's levels of detail (None for ``levels`` < 2, or a plant too small to have
    two): level k tessellates the rows of ``frusta`` (``parent``: the skeleton's) that
    :func:`~plantgen.geometry.rays.instances.detail_levels` keeps, at ``mesh``'s level (with
    ``relief``: displaced), with the ``leaves`` hanging from a kept segment; the screen coverages are for
    ``pixels`` on an image ``height`` pixels high (:func:`screen_coverage`)."""
    if levels < 2:
        return None
    order, sizes = detail_order(frusta, parent)
    counts, thresholds = detail_levels(sizes, levels)
    if len(counts) < 2:
        return None
    out = [DetailLevel(np.arange(len(frusta)), mesh, np.arange(0 if leaves is None else len(leaves)), 0.0)]
    for count, size in zip(counts[1:].tolist(), thresholds[1:].tolist(), strict=True):
        rows = np.sort(order[:count])
        kept = np.flatnonzero(np.isin(leaves.segment, frusta.segment[rows])) if leaves is not None else np.zeros(0, int)
        out.append(DetailLevel(rows, tessellate(frusta.subset(rows), mesh.level, relief=relief), kept, size))
    box = frusta_bounds(frusta)
    diameter = float(np.linalg.norm(box[1] - box[0]))
    return PlantDetail(tuple(out), screen_coverage(thresholds, float(sizes[0]), diameter, pixels, height))


def _mesh_counts(plants: list[Plant]) -> dict:
    """What an export wrote: rows, caps, triangles, vertices, drawn, plants, copies and
    leaf_triangles (a grammar's leaves, counted in triangles, vertices and drawn too)."""
    meshes = [p.mesh for p in plants]
    leaves = [len(p.leaves.triangles) if p.has_leaves else 0 for p in plants]
    leaf_vertices = sum(len(p.leaves.vertices) for p in plants if p.has_leaves)
    return dict(rows=sum(m.n_rows for m in meshes), caps=sum(m.n_caps for m in meshes),
                triangles=sum(len(m.faces) for m in meshes) + sum(leaves),
                vertices=sum(len(m.vertices) for m in meshes) + leaf_vertices,
                drawn=sum((len(p.mesh.faces) + n) * p.copies for p, n in zip(plants, leaves, strict=True)),
                plants=len(plants), copies=sum(p.copies for p in plants), leaf_triangles=sum(leaves),
                levels=_level_counts(plants))


def _level_counts(plants: list[Plant]) -> list[tuple[int, int]]:
    """[(rows, triangles)] of each level of detail written, summed over the plants (each
    once; a plant with fewer levels counted at its last); empty when none has levels."""
    depth = max((len(p.detail.levels) for p in plants if p.detail is not None), default=0)
    out = []
    for k in range(depth):
        rows = triangles = 0
        for plant in plants:
            lod = 0 if plant.detail is None else min(k, len(plant.detail.levels) - 1)
            at = level_plant(plant, lod)
            rows += plant.mesh.n_rows if plant.detail is None else len(plant.detail.levels[lod].rows)
            triangles += len(at.mesh.faces) + (len(at.leaves.triangles) if at.has_leaves else 0)
        out.append((rows, triangles))
    return out


def _export_parts(grown: GrowResult, instanced: bool) -> list[tuple[str, Skeleton, np.ndarray | None,
                                                                   Polygons | None, tuple | None]]:
    """(name, skeleton in its own frame, placements or None, leaves in the same frame or
    None, sways) of every plant to write: a scene's distinct plants with their own
    grammar's leaves and their copies' placements when ``instanced``, else the whole model
    in place. ``sways`` (a scene's): (the sway group of each segment, per copy the
    :class:`~plantgen.geometry.stage.Sway` or None of each group), as
    :class:`~plantgen.exporters.PlantSway` takes them; None for a grammar or a skeleton."""
    scene = grown.scene
    if instanced and scene is not None:
        return [(p.name, p.skeleton, p.matrices, p.polygons,
                 (np.zeros(len(p.skeleton), np.int64), tuple((scene.instances[k].motion,) for k in p.instances)))
                for p in scene.plants() if len(p.skeleton)]
    sways = None if scene is None else (scene.segment_instance(), (tuple(i.motion for i in scene.instances),))
    return [(grown.name, grown.skeleton, None, grown.polygons, sways)]


def _leaves_of(polygons: Polygons | None, mesh, input_path) -> Polygons | None:
    """``polygons`` if any, their materials checked against the mesh's names; else None."""
    if polygons is None or len(polygons) == 0:
        return None
    if int(polygons.material.max()) >= len(mesh.material_names):
        raise ExportError(f"{input_path}: a leaf polygon has material {int(polygons.material.max())}, "
                          f"but the model names {len(mesh.material_names)} materials")
    return polygons


def check_export_size(frusta: list[Frusta], leaves: list, segments: int, level: int, fmt_name: str,
                      limits: Limits | None, source, output) -> int:
    """The triangles an export of ``frusta`` at level m and of ``leaves`` (Polygons or None,
    each written once) builds, refused before anything is built (one line naming ``source``
    or ``output``) over ``limits.max_export_triangles``, or over ``limits.max_export_bytes``
    to build and write as ``fmt_name`` with the skin of ``segments`` skeleton segments."""
    limits = in_force(limits)
    estimate = sum(triangle_count(len(f), level, int(f.open_lo.sum() + f.open_hi.sum())) for f in frusta)
    estimate += sum(len(p.triangles) for p in leaves if p is not None)
    if estimate > limits.max_export_triangles:
        raise ExportError(f"{source}: m = {level} gives {estimate:,} triangles, over the "
                          f"export limit of {limits.max_export_triangles:,}; choose a lower --subdiv "
                          f"({hint('export_triangles')})")
    need = estimate_export_bytes(estimate, fmt_name) + segments * SKIN_BYTES_PER_SEGMENT
    if need > limits.max_export_bytes:
        raise LimitError(f"{output}: m = {level} gives {estimate:,} triangles, about "
                         f"{need / 2**20:,.0f} MiB to build and write as {fmt_name}, over the limit of "
                         f"{limits.max_export_bytes / 2**20:,.0f} MiB; choose a lower --subdiv "
                         f"({hint('export_bytes')})")
    return estimate


def _tessellated_plants(grown: GrowResult, fmt, instancing: str, level: int, relief: bool, limits: Limits,
                        input_path, output_path, timings: dict, progress,
                        skin=skin_skeleton, timeline: Timeline | None = None,
                        detail: tuple[int, float] = (1, 0.0), summary: dict | None = None
                        ) -> tuple[list[Plant], int, int]:
    """Skin every plant with ``skin``, check the export's triangles and memory against the
    limits (and its sway's keys, with a ``timeline``), and tessellate (``timings`` gains
    ``skin`` and ``tessellate``), each plant at ``detail`` = (levels, pixels)
    (:func:`plant_detail`); also the segments smooth bends added and the level made
    (``level`` None: :func:`_fitting_level`, its warning added to ``summary``)."""
    t1 = time.perf_counter()
    parts = _export_parts(grown, instancing != "off")
    frusta = [check_finite_frusta(skin(part[1]), input_path) for part in parts]
    t2 = time.perf_counter()
    timings["skin"] = t2 - t1
    copies = 2 if detail[0] > 1 else 1      # the lower levels hold under n/2 + n/4 + ... rows: under the full's
    sizes = (frusta * copies, [part[3] for part in parts] * copies, sum(len(part[1]) for part in parts))
    if level is None:
        level, note = _fitting_level(sizes, fmt.name, limits, input_path, output_path)
        if note and summary is not None:
            summary["warnings"] = (*summary["warnings"], note)
    check_export_size(*sizes, level, fmt.name, limits, input_path, output_path)
    if timeline is not None:
        check_sway_size([(len(part[1]), 1 if part[2] is None else len(part[2])) for part in parts
                         if part[4] is not None and any(s is not None and s.moves for c in part[4][1] for s in c)],
                        timeline, limits, output_path)
    plants = []
    for k, ((name, skel, matrices, leaves, sways), fr) in enumerate(zip(parts, frusta, strict=True)):
        mesh = tessellate(fr, level, relief=relief)
        check_finite_mesh(mesh, fr, input_path)
        sway = PlantSway(sways[0], sways[1], fr.segment) if timeline is not None and sways is not None else None
        leaves = _leaves_of(leaves, mesh, input_path)
        lod = plant_detail(fr, skel.parent, mesh, leaves, *detail, relief=relief)
        plants.append(Plant(name, skel, mesh, matrices, leaves=leaves, sway=sway, detail=lod))
        if progress is not None:
            progress("tessellate", k + 1, len(parts))
    timings["tessellate"] = time.perf_counter() - t2
    return plants, sum(f.report.smooth_segments for f in frusta), level


def _fitting_level(sizes: tuple, fmt_name: str, limits: Limits, source, output) -> tuple[int, str]:
    """(level, note): :data:`DEFAULT_LEVEL` where its triangles and memory fit the limits
    (:func:`check_export_size` of ``sizes``: frusta, leaves, segments), else the finest
    lower level that fits and a line saying so (at level 0 the check's own refusal)."""
    for level in range(DEFAULT_LEVEL, 0, -1):
        try:
            check_export_size(*sizes, level, fmt_name, limits, source, output)
        except (ExportError, LimitError) as exc:
            over = str(exc)
            continue
        return level, "" if level == DEFAULT_LEVEL else _lowered(source, level, over)
    return 0, _lowered(source, 0, over)


def _lowered(source, level: int, over: str) -> str:
    """The warning of an export made at ``level`` below the default (``over``: the refusal
    of the level above)."""
    reason = over.split(": ", 1)[-1].split(";")[0]
    return (f"{source}: exported at --subdiv {level}, the finest level within the limits (the default, "
            f"--subdiv {DEFAULT_LEVEL}: {reason})")


#: Bytes a written joint takes apart from its keys (its node, skin entry, channel and
#: sampler, as Python objects and JSON), and a key while it is built and written
#: (float64 angles and quaternions, the float32 copy, the written bytes), rounded up.
SWAY_BYTES_PER_JOINT, SWAY_BYTES_PER_KEY = 2048, 160


def check_sway_size(plants, timeline: Timeline, limits: Limits | None, output) -> int:
    """The bytes writing a sway takes: ``plants`` [(segments, copies)] each a joint a
    segment for every copy, ``timeline.keys`` keys each; one line naming ``output`` over
    ``limits.max_export_bytes``."""
    limits = in_force(limits)
    joints = sum(segments * copies for segments, copies in plants)
    need = joints * (SWAY_BYTES_PER_JOINT + timeline.keys * SWAY_BYTES_PER_KEY)
    if need > limits.max_export_bytes:
        raise LimitError(f"{output}: the sway's {joints:,} joints x {timeline.keys:,} keys take about "
                         f"{need / 2**20:,.0f} MiB to build and write, over the limit of "
                         f"{limits.max_export_bytes / 2**20:,.0f} MiB; lower --key-rate or --duration "
                         f"({hint('export_bytes')})")
    return need
