"""One bench run: every model measured in the order the package docstring describes.

fps are ``1000 / median frame time``; frame times are measured by the renderers
(draw calls to ``glFinish``, excluding read-back), plus the per-frame CPU update of an
animated scene. Nothing is taken from the paper but its own columns, printed beside ours.
"""

from __future__ import annotations

import datetime
import os
import platform
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..geometry.meshes.mesh import triangle_count
from ..geometry.rays.reference import render_reference
from ..geometry.skeletons.materials import material_height_maps
from ..gl.context import gl_context, renderer_name
from ..gl.raster import PARALLAX_SCALE_BYTES, PARALLAX_SHELL_BYTES, gs_buffer_bytes
from ..gl.records import rc_buffer_bytes
from ..settings import ShadowSettings
from .configs import (
    LEVEL_METHODS,
    MAPPED_METHODS,
    MATCHED_AGAINST,
    METHODS,
    PARALLAX_SWEEPS,
    TABLE_METHODS,
    Config,
    level_config,
    parallax_configs,
    ray_cast_configs,
    relief_configs,
)
from .eval_window import eval_camera
from .figures import save_images
from .matching import LevelMatch, choose_relief_config, walk_levels
from .models import BenchModel, check_models, load_model
from .params import BenchOptions
from .quality import ERROR_FIELDS, image_error, require_skimage
from .renderers import Renderers, median_ms, shadow_box, time_configs
from .summary import summarise

__all__ = ["bench_model", "run_bench", "count_steps", "machine_info", "timing_fields"]


def timing_fields(samples: list) -> dict:
    """{"ms": median, "fps": 1000 / median, "ms_samples": samples} of frame times in ms."""
    ms = median_ms(samples)
    return {"ms": ms, "fps": 1000.0 / ms, "ms_samples": samples}


# ---------------------------------------------------------------------------- references
@dataclass
class _References:
    """The float64 references in the evaluation window."""

    distance: dict     # {relief: (H, W) distance along the unit rays, inf on a miss}
    seconds: float     # time the references took


def _render_references(model: BenchModel, camera, relief_samples: int) -> _References:
    """The reference without relief, and with it (``relief_samples`` linear samples before
    bisection) for a model with a relief shell."""
    t0 = time.perf_counter()
    refs = {False: render_reference(model.frusta, camera)}
    if model.relief:
        refs[True] = render_reference(model.frusta, camera, relief=True,
                                      relief_samples=relief_samples)
    seconds = time.perf_counter() - t0
    return _References({k: np.where(r.hit, r.t, np.inf) for k, r in refs.items()}, seconds)


# ---------------------------------------------------------------------------- accuracy curves
class _Meter:
    """Measures configurations one by one into the accuracy curve: each one's error in
    the evaluation ``window`` and its bare frame time at full size."""

    def __init__(self, renderers: Renderers, window, references: _References, opts: BenchOptions, step):
        self.renderers, self.window, self.references = renderers, window, references
        self.opts, self.step = opts, step
        self.curve: list = []      # rows, in the order measured
        self.results: dict = {}    # {key: RenderResult in the window}

    def measure(self, cfg: Config) -> dict | None:
        """Render, compare and time ``cfg``; returns its curve row (None over the budget)."""
        renderers, model = self.renderers, self.renderers.model
        self.step(f"{model.name}: {cfg.key}")
        res, _ = renderers.render_config(cfg, self.window)
        if res is None:
            self.skip(cfg)
            return None
        error = image_error(res.distance, self.references.distance[cfg.relief], self.window, model.light_dir)
        samples = time_configs(renderers, [cfg], model.camera, self.opts.curve_frames,
                               conditions=False)[cfg.key]
        row = {**cfg.identity(), **timing_fields(samples), **error.as_dict()}
        work = renderers.count_work(cfg, model.camera)
        row.update({k: work.as_dict()[k] for k in WORK_FIELDS})
        if cfg.level is not None:
            mesh = renderers.mesh(cfg.level, cfg.surface)
            row["triangles"] = len(mesh.faces)
            row["gpu_bytes"] = int(gs_buffer_bytes(mesh))
            if cfg.maps is not None:     # GS+N, GS+POM: their tangents and their maps besides
                row["texture_bytes"] = renderers.texture_bytes(cfg.level, cfg.maps)
                row["gpu_bytes"] += TANGENT_BYTES * len(mesh.vertices) + row["texture_bytes"]
            if cfg.parallax is not None:  # GS+POM: the rows' shell thickness, the vertices' uv scales
                row["gpu_bytes"] += PARALLAX_SHELL_BYTES * mesh.n_rows + PARALLAX_SCALE_BYTES * len(mesh.vertices)
        self.curve.append(row)
        self.results[cfg.key] = res
        renderers.release_raster(cfg.key)
        return row

    def skip(self, cfg: Config) -> None:
        """A level over the triangle budget: a curve row saying so, nothing built."""
        triangles = self.triangles(cfg.level)
        self.curve.append({**cfg.identity(), "triangles": triangles,
                           "skipped": f"{triangles:,} triangles over the budget of {self.opts.max_triangles:,}"})

    def triangles(self, level: int) -> int:
        """Triangles of the model's tessellation at ``level`` (what the budget counts)."""
        return triangle_count(len(self.renderers.model.frusta), level, 0)

    def walk(self, method: str, target: dict) -> LevelMatch:
        """A polygonal method from m = 0 up until a level matches ``target`` (a curve row) or
        the next one is over the budget (:func:`~plantgen.table1.matching.walk_levels`;
        GS+POM with the run's knobs)."""
        parallax = self.opts.parallax
        match = walk_levels(method, target["key"], target["error"],
                            lambda m: self.measure(level_config(method, m, parallax))["error"], self.triangles,
                            self.opts.max_triangles, self.opts.rel_tol, self.opts.abs_tol)
        if match.over_budget is not None:
            self.skip(level_config(method, match.over_budget[0]))
        return match

    def measured(self) -> dict:
        """{key: row} of the configurations that were built and measured."""
        return _measured(self.curve)


def _measured(curve) -> dict:
    """{key: row} of the configurations that were built and measured."""
    return {r["key"]: r for r in curve if "error" in r}


#: GPU bytes of one vertex's tangent (GS+N: vec4 float32).
TANGENT_BYTES = 16

#: What each measured row records of a counting render at the timed size: shaded
#: fragments per covered pixel, relief height samples per covered pixel.
WORK_FIELDS = ("overdraw", "samples_per_pixel")


# ---------------------------------------------------------------------------- Table 1
@dataclass
class _TableChoice:
    """The configuration of each Table 1 method, the RC+R choice and the level walks."""

    configs: dict          # {"rc" | "rcr" | "gs" | "gsr" | "gsn": Config or None}
    matches: dict          # {"gs" | "gsr" | "gsn": LevelMatch or None}
    relief_choice: dict | None   # :func:`choose_relief_config`'s record (None without relief)

    @property
    def timed(self) -> list[Config]:
        return [c for c in self.configs.values() if c is not None]

    def mesh_keys(self) -> set:
        """The (level, surface) meshes the Table 1 timing draws."""
        return {(c.level, c.surface) for c in self.timed if c.level is not None}


def _choose_table(meter: _Meter, ray_configs, opts: BenchOptions, relief: bool) -> _TableChoice:
    """RC+R's configuration from the curves (:func:`choose_relief_config`), then the quality
    criterion (:data:`MATCHED_AGAINST`): GS walked up against RC, GS+R, GS+N and GS+POM
    against that RC+R; then GS+POM's knobs swept at its level (:func:`parallax_configs`:
    the curves' points, Table 1 times the run's knobs)."""
    by_key = {c.key: c for c in ray_configs}
    chosen, choice = {"rc": ray_configs[0], "rcr": None}, None
    if relief:
        rows = [r for r in meter.curve if r["method"] == "RC+R" and "error" in r]
        choice = choose_relief_config(rows, opts.relief_error)
        chosen["rcr"] = by_key[choice["key"]]
    matches = {}
    for short, against in MATCHED_AGAINST.items():
        method, target = TABLE_METHODS[short], chosen[against]
        matches[short] = None if target is None else meter.walk(method, meter.measured()[target.key])
        level = None if matches[short] is None else matches[short].level
        chosen[short] = None if level is None else level_config(method, level, opts.parallax)
        if level is not None and chosen[short].parallax is not None:
            for cfg in parallax_configs(opts, method, level):
                meter.measure(cfg)
    return _TableChoice(chosen, matches, choice)


def _time_table(renderers: Renderers, table: _TableChoice, curve, frames: int) -> dict:
    """The methods timed in one interleaved run under the paper's conditions.
    Returns {"rc" | "rcr" | "gs" | "gsr" | "gsn": results entry or None}."""
    passes: dict = {}
    reused: dict = {}
    samples = time_configs(renderers, table.timed, renderers.model.camera, frames,
                           conditions=True, passes=passes, reused=reused)
    measured = _measured(curve)

    def entry(cfg):
        if cfg is None or not samples.get(cfg.key):
            return None
        row = measured[cfg.key]
        return {"key": cfg.key, **timing_fields(samples[cfg.key]),
                "passes": passes.get(cfg.key, []), "shadow_reused": reused.get(cfg.key, 0),
                **{k: row[k] for k in (*ERROR_FIELDS, *WORK_FIELDS)}}

    return {short: entry(cfg) for short, cfg in table.configs.items()}


def _memory(model: BenchModel, table: _TableChoice, curve) -> dict:
    """Bytes on the GPU of each method (height maps counted for the relief methods; GS+N's
    and GS+POM's mesh with its tangents and its maps' texture array): ``rc_bytes``,
    ``relief_map_bytes``, ``rcr_bytes``, per polygonal method ``<short>_bytes`` and its
    ratio to the method it is matched against ``<short>_over_<against>``, and each mapped
    method's :attr:`Method.texture_field`."""
    measured = _measured(curve)

    def row(short):
        cfg = table.configs[short]
        return {} if cfg is None else measured.get(cfg.key, {})

    rc_bytes = rc_buffer_bytes(len(model.frusta))
    map_bytes = int(material_height_maps(model.names)[0].nbytes) if model.relief else 0
    out = {"rc_bytes": rc_bytes, "relief_map_bytes": map_bytes, "rcr_bytes": rc_bytes + map_bytes}
    for short in MATCHED_AGAINST:
        out[f"{short}_bytes"] = row(short).get("gpu_bytes")
    for short, against in MATCHED_AGAINST.items():
        mine = out[f"{short}_bytes"]
        out[f"{short}_over_{against}"] = mine / out[f"{against}_bytes"] if mine else None
    for method in MAPPED_METHODS:
        out[method.texture_field] = row(method.short).get("texture_bytes")
    return out


def _notes(model: BenchModel) -> list[str]:
    notes = []
    if model.shadows:
        notes.append(f"shadow map ({ShadowSettings().resolution}², PCF) and ground for "
                     f"{', '.join(m.name for m in METHODS)} alike")
    if model.animation is not None:
        notes.append("animated: posed and skinned on the GPU in every frame (RC: a compute pass writes the "
                     "records; GS: the mesh built once at rest, posed by the vertex shader), the dispatch "
                     "counted in the frame")
        if model.relief and model.animation.plan is not None:
            notes.append(f"{' and '.join(m.name for m in MAPPED_METHODS)} timed without their maps (GS+POM: its "
                         "outer shell): the rasteriser draws a vertex-skinned mesh without maps")
    return notes


# ---------------------------------------------------------------------------- one model
def _model_record(model: BenchModel, window, references: _References, table: _TableChoice,
                  entries: dict, curve: list) -> dict:
    """The JSON-ready results of one model."""
    record = {"model": model.name, "segments": len(model.frusta), "relief": model.relief,
              "shadows": model.shadows, "animated": model.animation is not None,
              "ground": model.ground is not None,
              "camera": model.camera.to_dict(), "eval_camera": window.to_dict(),
              "reference_s": references.seconds}
    for short in TABLE_METHODS:
        record[short] = entries[short]
        if short in table.matches:
            match = table.matches[short]
            record[f"{short}_level"] = None if match is None else match.level
            record[f"{short}_matched"] = match is not None and match.matched
            record[f"{short}_match"] = None if match is None else match.as_dict()
    record["rcr_choice"] = table.relief_choice
    record.update(memory=_memory(model, table, curve), curve=curve, notes=_notes(model))
    return record


def _ignore_progress(label: str) -> None:
    pass


def bench_model(name: str, opts: BenchOptions, progress=None, images_dir: Path | None = None) -> dict:
    """Everything the bench measures for one model (a JSON-ready dict).

    progress : callable(label) called at each step; images_dir : where the compared
    images go (None: not written)
    """
    step = progress if progress is not None else _ignore_progress
    model = load_model(name, opts.size)
    renderers = Renderers(model, opts.max_triangles, shadow_box(model, opts.frames))
    configs = ray_cast_configs(opts, model.relief)
    try:
        # 1. evaluation window, from the timing image's coverage
        first, _ = renderers.render_config(configs[0], model.camera)
        window = eval_camera(model.camera, np.isfinite(first.distance), opts.eval_size)
        step(f"{model.name}: reference")
        references = _render_references(model, window, opts.reference_relief_samples)
        # 2. the ray caster's configurations: error in the window, time at full size
        meter = _Meter(renderers, window, references, opts, step)
        for cfg in configs:
            meter.measure(cfg)
        # 3. RC+R's Table 1 configuration, then GS, GS+R, GS+N and GS+POM walked up to the
        #    criterion, GS+POM's knobs swept at its level
        table = _choose_table(meter, configs, opts, model.relief)
        renderers.keep_meshes(table.mesh_keys())
        # 4. Table 1 timing: the methods interleaved, under the paper's conditions
        step(f"{model.name}: Table 1 timing")
        entries = _time_table(renderers, table, meter.curve, opts.frames)
        if images_dir is not None:
            save_images(images_dir, model.name, window, model.light_dir, references.distance,
                        meter.results, [c.key for c in table.timed])
        return _model_record(model, window, references, table, entries, meter.curve)
    finally:
        renderers.release()


# ---------------------------------------------------------------------------- the run
def _cpu_name() -> str:
    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return cpu


def machine_info() -> dict:
    """The GL renderer, CPU, platform and versions the run measured on, and the date."""
    ctx = gl_context()
    return {"gl_renderer": renderer_name(), "gl_version": str(ctx.info.get("GL_VERSION", "")),
            "gl_vendor": str(ctx.info.get("GL_VENDOR", "")), "cpu": _cpu_name(), "cpus": os.cpu_count(),
            "platform": platform.platform(), "python": platform.python_version(),
            "numpy": np.__version__,
            "date_utc": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")}


def count_steps(opts: BenchOptions) -> int:
    """Progress steps of a run (an upper bound: reference, configurations, the GS, GS+R,
    GS+N and GS+POM levels a one-segment model could reach within the budget, GS+POM's
    swept knobs, table timing)."""
    levels = 0
    while triangle_count(1, levels, 0) <= opts.max_triangles:
        levels += 1
    swept = sum(len(getattr(opts, sweep.values)) for sweep in PARALLAX_SWEEPS)
    return len(opts.models) * (3 + len(relief_configs(opts)) + len(LEVEL_METHODS) * levels + swept)


def run_bench(opts: BenchOptions, progress=None, out_dir: str | Path | None = None) -> dict:
    """Run the bench over ``opts.models``; returns the JSON-ready results.

    progress : callable(label) called at each step (:func:`count_steps` of them at most)
    out_dir : where ``--images`` go (``out_dir/images``)
    """
    check_models(opts.models)
    require_skimage()
    t0 = time.perf_counter()
    info = machine_info()
    images_dir = Path(out_dir) / "images" if (opts.images and out_dir is not None) else None
    models = [bench_model(name, opts, progress, images_dir) for name in opts.models]
    return {"machine": info, "options": opts.as_json(), "models": models, "summary": summarise(models),
            "wall_s": time.perf_counter() - t0}
