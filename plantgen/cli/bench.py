"""``plantgen bench``: Table 1 of the paper on this machine, accuracy against time, memory."""

from __future__ import annotations

import time
from pathlib import Path

import click

from ..errors import PlantgenError
from ..settings import ParallaxSettings
from ..table1 import RELIEF_ERROR, BenchOptions, check_models, count_steps, require_skimage, run_bench, write_outputs
from .options import knob_options, quiet_opt, size_opt, take_settings
from .progress import StageBars


@click.command()
@click.option("--models", metavar="LIST",
              help="Comma-separated grammar/scene names or paths (default: the nine models of "
                   "Table 1; with --quick: saguaro,well).")
@size_opt(what="Timed frame size", default="1024x768, as the paper; --quick: 256x192")
@click.option("--frames", type=click.IntRange(1, 10000),
              help="Timed frames of each Table 1 method after a warm-up (default 9; --quick: 2); "
                   "the curves' configurations use at most 5.")
@size_opt("--eval-size", what="Evaluation window against the float64 reference, at the timed "
                              "frames' angle per pixel", default="128x96; --quick: 64x48")
@click.option("--max-triangles", type=click.IntRange(min=1),
              help="Triangle budget: GS, GS+R, GS+N and GS+POM go up from m = 0 until a level matches the ray "
                   "caster's quality or the next level has more triangles than this (not built; "
                   "default 6,000,000; --quick: 500,000).")
@click.option("--relief-error", type=click.FloatRange(min=0.0),
              help=f"Table 1 times the fastest RC+R configuration of the curves with an error at "
                   f"most this (default {RELIEF_ERROR:g}), else the most accurate one; GS+R, "
                   "GS+N and GS+POM are matched against it.")
@knob_options(ParallaxSettings)
@click.option("--quick", is_flag=True, help="A small run (two tiny models, small images): CI drives it.")
@click.option("--images", is_flag=True, help="Also write the compared images into OUT/images.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              default=Path("bench-out"), show_default=True,
              help="Directory for table.md, table1.csv, curves.csv, results.json and plots.")
@quiet_opt
def bench(models, size, frames, eval_size, max_triangles, relief_error, quick, images, out_dir, quiet, **knobs):
    """Reproduce Table 1 (RC, RC+R, GS, GS+R fps, and GS+N: GS's mesh with baked normal
    maps, GS+POM: the mesh on the relief's outer shell with parallax occlusion mapping;
    RC+R at the fastest configuration within --relief-error, GS levels matched to the ray
    caster's quality by a computed criterion or stopped by the triangle budget) and measure
    error against ms per frame for every accuracy knob. Prints the Markdown table. On a
    terminal a line on stderr shows the step it is on; where stderr is a log, one line
    per step with the seconds since the start (-q: neither)."""

    overrides = {"parallax": take_settings(ParallaxSettings, knobs)}
    if models:
        overrides["models"] = tuple(s.strip() for s in models.split(",") if s.strip())
        if not overrides["models"]:
            raise PlantgenError("--models: no model named")
    given = {"size": size, "frames": frames, "eval_size": eval_size, "max_triangles": max_triangles,
             "relief_error": relief_error}
    overrides.update({key: value for key, value in given.items() if value is not None})
    overrides["images"] = images
    opts = BenchOptions.quick_run(**overrides) if quick else BenchOptions(**overrides)
    if frames is not None:   # the curves' many configurations use at most their default
        opts.curve_frames = min(frames, opts.curve_frames)

    check_models(opts.models)   # before the progress bar: a typo fails at once
    require_skimage()           # so does a missing scikit-image (the error metric's SSIM)
    total = count_steps(opts)
    start = time.perf_counter()
    with StageBars(enabled=not quiet) as bars:
        log = not quiet and not bars.enabled     # a log file gets one line per step instead
        done = [0]

        def progress(label):
            done[0] += 1
            bars("bench", min(done[0], total), total, label)
            if log:
                click.echo(f"[{time.perf_counter() - start:6.0f} s] {label}", err=True)

        results = run_bench(opts, progress, out_dir)
    written = write_outputs(results, out_dir)
    if quiet:
        return
    click.echo(written["markdown"])
    if written["plots"]:
        click.echo(f"plantgen: {written['plots']}", err=True)
    click.echo(f"wrote {', '.join(str(p) for p in written['files'])} "
               f"in {time.perf_counter() - start:.0f} s", err=True)
