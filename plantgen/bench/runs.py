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

from ..geometry.materials import material_height_maps
from ..geometry.mesh import triangle_count
from ..geometry.reference import render_reference
from ..render.context import gl_context, renderer_name
from ..render.passes import ShadowSettings
from ..render.raster import gs_buffer_bytes
from ..render.records import rc_buffer_bytes
from .configs import MATCHED_AGAINST, TABLE_METHODS, Config, bench_configs, default_relief_config, find_level
from .images import save_images
from .metrics import ERROR_FIELDS, image_error, matched_level
from .models import BenchModel, check_models, load_model
from .options import BenchOptions
from .renderers import Renderers, median_ms, shadow_box, time_configs
from .window import eval_camera

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
def _skipped_row(cfg: Config, frusta_rows: int, max_triangles: int) -> dict:
    triangles = triangle_count(frusta_rows, cfg.level, 0)
    return {**cfg.identity(),
            "skipped": f"{triangles:,} triangles over the budget of {max_triangles:,}"}


def _measure_configs(renderers: Renderers, configs, window, references: _References,
                     opts: BenchOptions, step) -> tuple[list, dict]:
    """Every configuration's error in the evaluation ``window`` and its bare frame time at
    full size. Returns (curve rows, {key: RenderResult in the window})."""
    model = renderers.model
    curve, results = [], {}
    for cfg in configs:
        step(f"{model.name}: {cfg.key}")
        res, _ = renderers.render_config(cfg, window)
        if res is None:
            curve.append(_skipped_row(cfg, len(model.frusta), opts.max_triangles))
            continue
        error = image_error(res.distance, references.distance[cfg.relief], window, model.light_dir)
        samples = time_configs(renderers, [cfg], model.camera, opts.curve_frames,
                               conditions=False)[cfg.key]
        row = {**cfg.identity(), **timing_fields(samples), **error.as_dict()}
        if cfg.level is not None:
            mesh = renderers.mesh(cfg.level, cfg.relief)
            row["triangles"] = len(mesh.faces)
            row["gpu_bytes"] = int(gs_buffer_bytes(mesh))
        curve.append(row)
        results[cfg.key] = res
        renderers.release_raster(cfg.key)
    return curve, results


def _measured(curve) -> dict:
    """{key: row} of the configurations that were built and measured."""
    return {r["key"]: r for r in curve if "error" in r}


# ---------------------------------------------------------------------------- Table 1
@dataclass
class _TableChoice:
    """The configuration of each Table 1 method, and the matched levels."""

    configs: dict      # {"rc" | "rcr" | "gs" | "gsr": Config or None}
    levels: dict       # {"gs" | "gsr": (level or None, matched)}

    @property
    def timed(self) -> list[Config]:
        return [c for c in self.configs.values() if c is not None]

    def mesh_keys(self) -> set:
        """The (level, relief) meshes the Table 1 timing draws."""
        return {(c.level, c.relief) for c in self.timed if c.level is not None}


def _match(curve, method: str, target: Config, opts: BenchOptions):
    """(level, matched) of ``method`` against the error of the ``target`` configuration."""
    errors = {r["value"]: r["error"] for r in curve if r["method"] == method and "error" in r}
    return matched_level(errors, _measured(curve)[target.key]["error"], opts.rel_tol, opts.abs_tol)


def _choose_table(configs, curve, opts: BenchOptions, relief: bool) -> _TableChoice:
    """The quality criterion (:data:`MATCHED_AGAINST`): GS matched against RC, GS+R against
    RC+R at the ray caster's default steps."""
    chosen = {"rc": next(c for c in configs if c.method == "RC"),
              "rcr": default_relief_config(configs) if relief else None}
    levels = {}
    for short, against in MATCHED_AGAINST.items():
        method, target = TABLE_METHODS[short], chosen[against]
        levels[short] = (None, False) if target is None else _match(curve, method, target, opts)
        chosen[short] = find_level(configs, method, levels[short][0])
    return _TableChoice(chosen, levels)


def _time_table(renderers: Renderers, table: _TableChoice, curve, frames: int) -> dict:
    """The four methods timed in one interleaved run under the paper's conditions.
    Returns {"rc" | "rcr" | "gs" | "gsr": results entry or None}."""
    passes: dict = {}
    samples = time_configs(renderers, table.timed, renderers.model.camera, frames,
                           conditions=True, passes=passes)
    measured = _measured(curve)

    def entry(cfg):
        if cfg is None or not samples.get(cfg.key):
            return None
        row = measured[cfg.key]
        return {"key": cfg.key, **timing_fields(samples[cfg.key]),
                "passes": passes.get(cfg.key, []), **{k: row[k] for k in ERROR_FIELDS}}

    return {short: entry(cfg) for short, cfg in table.configs.items()}


def _memory(model: BenchModel, table: _TableChoice, curve) -> dict:
    """Bytes on the GPU of each method (height maps counted for the relief methods)."""
    measured = _measured(curve)

    def gpu_bytes(cfg):
        return None if cfg is None else measured.get(cfg.key, {}).get("gpu_bytes")

    rc_bytes = rc_buffer_bytes(len(model.frusta))
    map_bytes = int(material_height_maps(model.names)[0].nbytes) if model.relief else 0
    gs_bytes, gsr_bytes = gpu_bytes(table.configs["gs"]), gpu_bytes(table.configs["gsr"])
    return {"rc_bytes": rc_bytes, "relief_map_bytes": map_bytes, "rcr_bytes": rc_bytes + map_bytes,
            "gs_bytes": gs_bytes, "gsr_bytes": gsr_bytes,
            "gs_over_rc": gs_bytes / rc_bytes if gs_bytes else None,
            "gsr_over_rcr": gsr_bytes / (rc_bytes + map_bytes) if gsr_bytes else None}


def _notes(model: BenchModel) -> list[str]:
    notes = []
    if model.shadows:
        notes.append(f"shadow map ({ShadowSettings().resolution}², PCF) and ground for RC, RC+R, "
                     "GS and GS+R alike")
    if model.animation is not None:
        notes.append("animated: pose + re-skin (+ re-tessellate for GS) counted in every frame")
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
        if short in table.levels:
            record[f"{short}_level"], record[f"{short}_matched"] = table.levels[short]
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
    configs = bench_configs(opts, model.relief)
    try:
        # 1. evaluation window, from the timing image's coverage
        first, _ = renderers.render_config(configs[0], model.camera)
        window = eval_camera(model.camera, np.isfinite(first.distance), opts.eval_size)
        step(f"{model.name}: reference")
        references = _render_references(model, window, opts.reference_relief_samples)
        # 2. every configuration: error in the window, time at full size
        curve, window_results = _measure_configs(renderers, configs, window, references, opts, step)
        # 3. the quality criterion
        table = _choose_table(configs, curve, opts, model.relief)
        renderers.keep_meshes(table.mesh_keys())
        # 4. Table 1 timing: the four methods interleaved, under the paper's conditions
        step(f"{model.name}: Table 1 timing")
        entries = _time_table(renderers, table, curve, opts.frames)
        if images_dir is not None:
            save_images(images_dir, model.name, window, model.light_dir, references.distance,
                        window_results, [c.key for c in table.timed])
        return _model_record(model, window, references, table, entries, curve)
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
    """Progress steps of a run (an upper bound: reference, configurations, table timing)."""
    relief_cfgs = len(opts.linear_steps) + len(opts.binary_steps) + 1 + len(opts.levels)
    return len(opts.models) * (3 + len(opts.levels) + relief_cfgs)


def run_bench(opts: BenchOptions, progress=None, out_dir: str | Path | None = None) -> dict:
    """Run the bench over ``opts.models``; returns the JSON-ready results.

    progress : callable(label) called at each step (:func:`count_steps` of them at most)
    out_dir : where ``--images`` go (``out_dir/images``)
    """
    check_models(opts.models)
    t0 = time.perf_counter()
    info = machine_info()
    images_dir = Path(out_dir) / "images" if (opts.images and out_dir is not None) else None
    models = [bench_model(name, opts, progress, images_dir) for name in opts.models]
    return {"machine": info, "options": opts.as_json(), "models": models,
            "wall_s": time.perf_counter() - t0}
