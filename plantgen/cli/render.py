"""``plantgen render``: ray cast a grammar, scene or skeleton in GLSL into a PNG."""

from __future__ import annotations

from pathlib import Path

import click

from ..errors import PlantgenError
from ..gl.records import RECORD_BYTES
from ..images import parse_background
from ..pipeline import RenderReport, ShadowUse, render_file
from ..settings import RenderSettings
from .options import (
    allow_path_opt,
    input_arg,
    iterations_opt,
    jobs_opt,
    knob_options,
    limit_opt,
    limits_from,
    output_opt,
    quiet_opt,
    seed_opt,
    smooth_bends_opt,
    take_settings,
    verbose_opt,
)
from .progress import StageBars
from .sections import EFFECTS, OUTPUT, QUALITY, SectionedCommand

#: Where render's options that are not plain settings go in ``--help`` (and the settings
#: that belong elsewhere than their class's section).
SECTIONS = {"camera_out": OUTPUT, "depth_out": OUTPUT, "ssaa": QUALITY, "aa": QUALITY, "pose": QUALITY, "time": EFFECTS}


@click.command(cls=SectionedCommand, sections=SECTIONS)
@input_arg
@output_opt("the image (.png, .jpg or .webp), or with --frames the animation (.gif or .webp). Default: "
            "INPUT's name with .png (with --frames: .gif), in the current directory.", required=False)
@knob_options(RenderSettings)
@click.option("--camera-out", type=click.Path(path_type=Path),
              help="Write the camera used (eye, target, up, fov_y, width, height) as JSON.")
@click.option("--depth-out", type=click.Path(path_type=Path),
              help="Write float32 (height, width) distances along each pixel's ray from the "
                   "eye (.npy), inf for a miss; rays go through pixel centres of --camera-out.")
@seed_opt
@iterations_opt
@click.option("--time-frames", "timed_frames", type=click.IntRange(0, 10000), default=0, show_default=True,
              metavar="N", help="Draw a still N more times after the first and print the median "
                                "frame time (0: draw once).")
@smooth_bends_opt
@limit_opt
@allow_path_opt
@jobs_opt
@quiet_opt
@verbose_opt
def render(input: Path, output: Path | None, camera_out, depth_out, seed, iterations, timed_frames, smooth_bends,
           limit_values, allow_paths, jobs, quiet, verbose, **knobs) -> None:
    """Draw INPUT (a grammar or scene .yaml, a shipped name, or a skeleton .npz or .swc)
    into an image (.png, .jpg or .webp) or an animation.

    Each branch is drawn as a tapered tube, ray cast on the GPU (headless). Prints what
    was drawn, the effects and the frame time. Only the effects in use cost time: no
    shadows, no relief, no motion unless asked for (--effects, --relief, --shadows).

    The camera frames the model (or is the scene's); --azimuth, --elevation, --distance
    or --zoom and --fov turn it around the model, or --camera takes a camera JSON back.
    A still is drawn once; --time-frames N draws it N more times and prints the median.
    On a terminal, a line on stderr shows the stage and its progress. --verbose prints
    the detail in the renderer's own terms (RC, RT, frusta, rows), which the glossary
    explains (docs: reference/glossary.md).

    \b
    Examples:
      plantgen render pine                                  # writes pine.png
      plantgen render saguaro -o saguaro.png --relief --size 1024x768 \\
          --camera-out cam.json --depth-out depth.npy
      plantgen render pine -o pine.png --azimuth 60 --elevation 20 --zoom 1.5 --ssaa 3
      plantgen render elm -o elm.png --background none          # transparent PNG
      plantgen render dancing_cacti --frames 48 --fps 24 -o dance.gif
    """
    settings = take_settings(RenderSettings, knobs)
    try:
        parse_background(settings.image.background)
    except PlantgenError as exc:
        raise click.BadParameter(str(exc).removeprefix("background "), param_hint="'--background'") from None
    view = settings.view
    if not view.auto and not Path(view.camera).exists():
        raise PlantgenError(f"{view.camera}: no such camera file (use 'auto' or a camera JSON)")
    if not view.auto and not view.orbit.empty:
        raise click.UsageError("--azimuth, --elevation, --distance, --zoom and --fov turn the automatic "
                               "camera: leave them out with --camera FILE")
    output = output or Path(input.stem + (".gif" if settings.motion.frames is not None else ".png"))
    with StageBars(enabled=not quiet) as bars:
        report = render_file(input, output, settings, camera_out=camera_out, depth_out=depth_out, seed=seed,
                             iterations=iterations, timed_frames=timed_frames, progress=bars,
                             limits=limits_from(limit_values), allow_paths=allow_paths, smooth_bends=smooth_bends,
                             jobs=jobs)
    for line in report.warnings:     # never silenced, as in grow
        click.echo(line, err=True)
    if not quiet:
        print_report(report, verbose)


def shadow_line(use: ShadowUse, cache: bool = True) -> str:
    """How the render paid for its shadow map: drawn how often (and its median ms), reused
    by how many draws; why every draw drew it (``cache`` off, or the geometry moves)."""
    drawn = "drawn once" if use.drawn == 1 else f"drawn {use.drawn} times"
    text = f"shadow map: {drawn} ({use.ms:.1f} ms{'' if use.drawn == 1 else ' median'})"
    if use.reused:
        return text + f", reused by {use.reused} draw{'s' if use.reused > 1 else ''} (the light and the geometry held)"
    if use.drawn <= 1:
        return text
    return text + (", every draw (the geometry moves)" if cache else ", every draw (--no-shadow-cache)")


def model_line(report: RenderReport, verbose: bool = False) -> str:
    """What was drawn: the branch segments and the pieces on the GPU (``verbose``: in the
    renderer's terms, frusta and rows)."""
    placed = report.placed
    traced = report.settings.method == "rt"
    if placed is None:
        kib = report.rows * RECORD_BYTES / 1024
        if verbose:
            return (f"segments: {report.segments:,} -> {report.rows:,} frusta ({RECORD_BYTES} bytes "
                    f"each, {kib:.1f} KiB uploaded)")
        pieces = f", drawn as {report.rows:,} pieces" if report.rows != report.segments else ""
        return f"model: {report.segments:,} branch segments{pieces} ({kib:.1f} KiB on the GPU)"
    drawn = report.result.stats.segments
    kib = placed.unique_rows * RECORD_BYTES / 1024
    copies = f"{placed.copies:,} copies of {len(placed.plants)} plants"
    if verbose:
        detail = "traced (every row: a BVH of each plant, one over the copies)" if traced else \
            f"drawn (level of detail: {report.lod_pixels:g} px)"
        return (f"segments: {report.segments:,} placed ({copies}), {placed.unique_rows:,} frusta on the GPU "
                f"({kib:.1f} KiB), {drawn:,} {detail}")
    detail = "all traced" if traced else f"{drawn:,} drawn (level of detail: {report.lod_pixels:g} px)"
    return (f"scene: {copies}, {report.segments:,} branch segments in all; {placed.unique_rows:,} branch pieces "
            f"on the GPU ({kib:.1f} KiB), {detail}")


def frame_line(report: RenderReport, verbose: bool = False) -> str:
    """The frame's (or the frames' median) time, size and way of drawing."""
    cam = report.camera
    traced = report.settings.method == "rt"
    mode = report.settings.describe() if verbose else report.settings.summary()
    mode += " (--method auto)" if report.request.march.method == "auto" else ""
    size = f"{cam.width}x{cam.height}"
    if report.ssaa > 1:
        n = report.ssaa
        size += (f" with {n}x{n} supersampling ({n * n} samples a pixel: a {cam.width * n}x{cam.height * n} "
                 f"frame, averaged down in {report.result.stats.resolve_ms:.0f} ms more)")
    elif report.request.image.aa == "edges" and report.result is not None and report.result.stats.resolve_ms > 0:
        size += f" with the edge pass ({report.result.stats.resolve_ms:.0f} ms more, read back included)"
    if report.frames > 1:
        where = (f"on the GPU in {report.gpu_frames} of {report.frames} frames" if report.gpu_frames
                 else "on the CPU")
        work = f"pose, skin, {'BVH refit, ' if traced else ''}upload: {where}" if verbose else f"posed {where}"
        return (f"frames: {report.frames}, median {report.frame_ms:.1f} ms render + "
                f"{report.update_ms:.2f} ms update ({work}) at {size}, {mode}")
    if report.timed:
        return f"frame: {report.frame_ms:.1f} ms at {size}, {mode} (median of {report.timed} frames after a warm-up)"
    return (f"frame: {report.frame_ms:.1f} ms at {size}, {mode} "
            "(one draw, the driver's first: --time-frames N for a median)")


def print_report(report: RenderReport, verbose: bool = False) -> None:
    """The render's report on stdout: GL renderer, what was drawn, effects, frame time,
    files; in plain words, or with ``verbose`` in the renderer's terms (RC+R, frusta, rows)."""
    click.echo(f"GL renderer: {report.renderer}")
    click.echo(model_line(report, verbose))
    traced = report.settings.method == "rt"
    shadows = "shadow rays" if traced else f"shadow map {report.shadows.resolution}²" if report.shadows else ""
    click.echo("effects: " + (", ".join(report.effects) or "none") + (f" ({shadows})" if report.shadows else ""))
    if report.shadow_use is not None:
        click.echo(shadow_line(report.shadow_use, report.shadows.cache))
    click.echo(frame_line(report, verbose))
    click.echo("wrote " + ", ".join(str(p) for p in report.written))
