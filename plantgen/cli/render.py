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
    knob_options,
    limit_opt,
    limits_from,
    output_opt,
    quiet_opt,
    seed_opt,
    smooth_bends_opt,
    take_settings,
)
from .progress import StageBars


@click.command()
@input_arg
@output_opt("the image (.png), or with --frames the animation (.gif or .webp). Default: INPUT's name "
            "with .png (with --frames: .gif), in the current directory.", required=False)
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
@quiet_opt
def render(input: Path, output: Path | None, camera_out, depth_out, seed, iterations, timed_frames, smooth_bends,
           limit_values, allow_paths, quiet, **knobs) -> None:
    """Ray cast INPUT (a grammar or scene .yaml, a shipped name, or a skeleton .npz or .swc)
    into a PNG.

    Skins the skeleton with conical frusta and renders them with the analytic GLSL ray
    caster (headless EGL). Prints the GL renderer, segment count and frame time. Only
    the effects in use are simulated: no shadow pass without shadows, no relief march
    without relief, no re-skinning of what does not move.

    The camera is framed automatically (or is the scene's); --azimuth, --elevation,
    --distance or --zoom and --fov turn it around the model, or --camera takes a camera
    JSON back. A still is drawn once; --time-frames N times N more draws and prints the
    median. On a terminal, a line on stderr shows the stage and its progress.

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
                             limits=limits_from(limit_values), allow_paths=allow_paths, smooth_bends=smooth_bends)
    for line in report.warnings:     # never silenced, as in grow
        click.echo(line, err=True)
    if not quiet:
        print_report(report)


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


def print_report(report: RenderReport) -> None:
    """The render's report on stdout: GL renderer, segments, effects, frame time, files."""
    mode = report.settings.describe() + (" (--method auto)" if report.request.march.method == "auto" else "")
    cam = report.camera
    click.echo(f"GL renderer: {report.renderer}")
    placed = report.placed
    traced = report.settings.method == "rt"
    if placed is not None:
        drawn = report.result.stats.segments
        detail = "traced (every row: a BVH of each plant, one over the copies)" if traced else \
            f"drawn (level of detail: {report.lod_pixels:g} px)"
        click.echo(f"segments: {report.segments:,} placed ({placed.copies:,} copies of {len(placed.plants)} plants), "
                   f"{placed.unique_rows:,} frusta on the GPU ({placed.unique_rows * RECORD_BYTES / 1024:.1f} KiB), "
                   f"{drawn:,} {detail}")
    else:
        click.echo(f"segments: {report.segments:,} -> {report.rows:,} frusta ({RECORD_BYTES} bytes "
                   f"each, {report.rows * RECORD_BYTES / 1024:.1f} KiB uploaded)")
    shadows = "shadow rays" if traced else f"shadow map {report.shadows.resolution}²" if report.shadows else ""
    click.echo("effects: " + (", ".join(report.effects) or "none") + (f" ({shadows})" if report.shadows else ""))
    if report.shadow_use is not None:
        click.echo(shadow_line(report.shadow_use, report.shadows.cache))
    size = f"{cam.width}x{cam.height}"
    if report.ssaa > 1:
        n = report.ssaa
        size += (f" with {n}x{n} supersampling ({n * n} samples a pixel: a {cam.width * n}x{cam.height * n} "
                 f"frame, averaged down in {report.result.stats.resolve_ms:.0f} ms more)")
    if report.frames > 1:
        where = (f"on the GPU in {report.gpu_frames} of {report.frames} frames" if report.gpu_frames
                 else "on the CPU")
        click.echo(f"frames: {report.frames}, median {report.frame_ms:.1f} ms render + "
                   f"{report.update_ms:.2f} ms update (pose, skin, {'BVH refit, ' if traced else ''}upload: {where}) "
                   f"at {size}, {mode}")
    elif report.timed:
        click.echo(f"frame: {report.frame_ms:.1f} ms at {size}, {mode} "
                   f"(median of {report.timed} frames after a warm-up)")
    else:
        click.echo(f"frame: {report.frame_ms:.1f} ms at {size}, {mode} "
                   "(one draw, the driver's first: --time-frames N for a median)")
    click.echo("wrote " + ", ".join(str(p) for p in report.written))
