"""``plantgen render``: ray cast a grammar, scene or skeleton in GLSL into a PNG."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from ..errors import PlantgenError
from ..images import parse_background
from ..pipeline import RenderReport, render_file
from ..render.raycast import RaycastSettings
from ..render.records import RECORD_BYTES
from ..render.supersample import MAX_SSAA
from ..scene import EFFECTS, parse_effect_list
from .options import (
    allow_path_opt,
    finite,
    input_arg,
    iterations_opt,
    limit_opt,
    limits_from,
    orbit_from,
    orbit_options,
    output_opt,
    seed_opt,
    size_opt,
    smooth_bends_opt,
)

#: The ray caster's default knobs: the options' defaults.
MARCH = RaycastSettings()

#: How this command spells the knobs that the library's messages name.
OPTION_NAMES = {"frames": "--frames", "fps": "--fps", "depth_out": "--depth-out", "time_s": "--time",
                "ssaa": "--ssaa", "timed_frames": "--time-frames"}


@click.command()
@input_arg
@output_opt("the image (.png), or with --frames the animation (.gif or .webp).")
@click.option("--effects", metavar="LIST",
              help="Comma-separated effects replacing the scene's list, e.g. relief,shadows "
                   f"(known: {', '.join(EFFECTS)}).")
@click.option("--relief/--no-relief", default=None,
              help="Relief-map the frusta (§3). Default: on when the effects list it.")
@click.option("--shadows/--no-shadows", default=None,
              help="Shadow-map the light. Default: on when the effects list it.")
@click.option("--shadow-res", type=click.IntRange(16, 16384), default=2048, show_default=True,
              help="Shadow map texels per side.")
@click.option("--shadow-caster", type=click.Choice(["relief", "inner"]), default="relief",
              show_default=True, help="With relief: the relief surface casts the shadow, or "
                                      "the inner cone (cheaper).")
@click.option("--frames", type=click.IntRange(1, 100000),
              help="Write an animation of this many frames (-o .gif or .webp).")
@click.option("--fps", type=click.FloatRange(min=0, min_open=True), default=12.0, callback=finite,
              show_default=True, help="Frames per second of the animation.")
@click.option("--time", "time_s", type=float, metavar="T", callback=finite,
              help="Seconds: the pose of an animated scene for a still (default 0), or the "
                   "first frame's time.")
@size_opt(default="the camera file's, else 1024x768")
@click.option("--camera", default="auto", show_default=True, metavar="auto|FILE.json",
              help="'auto' frames the model to span most of the viewport (or uses the "
                   "scene's camera); a camera JSON written by --camera-out or by the viewer's "
                   "C key is taken back.")
@orbit_options
@click.option("--camera-out", type=click.Path(dir_okay=False, path_type=Path),
              help="Write the camera used (eye, target, up, fov_y, width, height) as JSON.")
@click.option("--depth-out", type=click.Path(dir_okay=False, path_type=Path),
              help="Write float32 (height, width) distances along each pixel's ray from the "
                   "eye (.npy), inf for a miss; rays go through pixel centres of --camera-out.")
@seed_opt
@iterations_opt
@click.option("--march", type=click.Choice(["adaptive", "fixed"]), default=MARCH.march, show_default=True,
              help="Relief: samples sized to what each pixel sees (adaptive), or --linear-steps "
                   "for every ray (fixed, the paper's).")
@click.option("--march-density", type=click.FloatRange(min=0, min_open=True), default=MARCH.march_density,
              callback=finite,
              show_default=True, help="Relief, adaptive march: samples per relief texel the ray crosses.")
@click.option("--linear-steps", type=click.IntRange(1, 4096), default=MARCH.linear_steps, show_default=True,
              help="Relief: uniform samples through the shell (adaptive march: the most).")
@click.option("--binary-steps", type=click.IntRange(0, 64), default=MARCH.binary_steps, show_default=True,
              help="Relief: bisection steps after the first sample below the surface (adaptive "
                   f"march: the most; it stops at {MARCH.march_precision:g} pixel).")
@click.option("--v-exact/--v-interpolated", default=False, show_default=True,
              help="Relief: v of (7) per sample, or interpolated between entry and exit "
                   "(the paper's fast path).")
@click.option("--ssaa", type=click.IntRange(1, MAX_SSAA), default=1, show_default=True, metavar="N",
              help="Supersampling: N x N rays a pixel, averaged in linear light (thin twigs stop "
                   "breaking into dots; the frame costs about N² times as much).")
@click.option("--background", default="sky", show_default=True, metavar="COLOUR|none",
              help="The background: 'sky', a colour (white, '#20304a') or 'none' for a "
                   "transparent PNG (RGBA: the alpha is the model's coverage).")
@click.option("--time-frames", "timed_frames", type=click.IntRange(0, 10000), default=0, show_default=True,
              metavar="N", help="Draw a still N more times after the first and print the median "
                                "frame time (0: draw once).")
@smooth_bends_opt
@limit_opt
@allow_path_opt
def render(input: Path, output: Path, effects, relief, shadows, shadow_res, shadow_caster, frames,
           fps, time_s, size, camera, azimuth, elevation, distance, zoom, fov, camera_out, depth_out, seed,
           iterations, march, march_density, linear_steps, binary_steps, v_exact, ssaa, background,
           timed_frames, smooth_bends, limit_values, allow_paths) -> None:
    """Ray cast INPUT (a grammar or scene .yaml, a shipped name, or a skeleton .npz or .swc)
    into a PNG.

    Skins the skeleton with conical frusta and renders them with the analytic GLSL ray
    caster (headless EGL). Prints the GL renderer, segment count and frame time. Only
    the effects in use are simulated: no shadow pass without shadows, no relief march
    without relief, no re-skinning of what does not move.

    The camera is framed automatically (or is the scene's); --azimuth, --elevation,
    --distance or --zoom and --fov turn it around the model, or --camera takes a camera
    JSON back. A still is drawn once; --time-frames N times N more draws and prints the
    median. An animation shows a progress bar on stderr.

    \b
    Examples:
      plantgen render grammars/saguaro.yaml -o saguaro.png --relief --size 1024x768 \\
          --camera-out cam.json --depth-out depth.npy
      plantgen render pine -o pine.png --azimuth 60 --elevation 20 --zoom 1.5 --ssaa 3
      plantgen render elm -o elm.png --background none          # transparent PNG
      plantgen render grammars/dancing_cacti.yaml --frames 48 --fps 24 -o dance.gif
    """
    orbit = orbit_from(azimuth, elevation, distance, zoom, fov)
    if camera != "auto" and not Path(camera).exists():
        raise PlantgenError(f"{camera}: no such camera file (use 'auto' or a camera JSON)")
    if camera != "auto" and not orbit.empty:
        raise click.UsageError("--azimuth, --elevation, --distance, --zoom and --fov turn the automatic "
                               "camera: leave them out with --camera FILE")
    chosen = parse_effect_list(effects) if effects is not None else None
    bar = None

    def progress(done, total):
        nonlocal bar
        if bar is None:
            bar = click.progressbar(length=total, label="rendering frames", file=sys.stderr)
            bar.__enter__()
        bar.update(1)
        if done == total:
            bar.__exit__(None, None, None)

    report = render_file(input, output, size=size, camera=camera, orbit=orbit, camera_out=camera_out,
                         depth_out=depth_out, seed=seed, iterations=iterations, relief=relief,
                         linear_steps=linear_steps, binary_steps=binary_steps, v_exact=v_exact,
                         march=march, march_density=march_density,
                         effects=chosen, shadows=shadows, shadow_res=shadow_res,
                         shadow_caster=shadow_caster, time_s=time_s, frames=frames, fps=fps,
                         background=parse_background(background), ssaa=ssaa, timed_frames=timed_frames,
                         progress=progress, names=OPTION_NAMES, limits=limits_from(limit_values),
                         allow_paths=allow_paths, smooth_bends=smooth_bends)
    for line in report.warnings:     # never silenced, as in grow
        click.echo(line, err=True)
    print_report(report)


def describe_method(s: RaycastSettings) -> str:
    """RC, or RC+R with its march, as the report and the viewer's heads-up line name it."""
    if not s.relief:
        return "RC"
    steps = (f"{s.linear_steps} linear + {s.binary_steps} binary steps" if s.march == "fixed" else
             f"adaptive march, {s.march_density:g} samples per texel, at most {s.linear_steps} linear "
             f"+ {s.binary_steps} binary steps")
    return f"RC+R ({steps}, v {'exact' if s.v_exact else 'interpolated'})"


def print_report(report: RenderReport) -> None:
    """The render's report on stdout: GL renderer, segments, effects, frame time, files."""
    mode = describe_method(report.settings)
    cam = report.camera
    click.echo(f"GL renderer: {report.renderer}")
    click.echo(f"segments: {report.segments:,} -> {report.rows:,} frusta ({RECORD_BYTES} bytes "
               f"each, {report.rows * RECORD_BYTES / 1024:.1f} KiB uploaded)")
    click.echo("effects: " + (", ".join(report.effects) or "none")
               + (f" (shadow map {report.shadows.resolution}²)" if report.shadows else ""))
    size = f"{cam.width}x{cam.height}"
    if report.ssaa > 1:
        n = report.ssaa
        size += (f" with {n}x{n} supersampling ({n * n} samples a pixel: a {cam.width * n}x{cam.height * n} "
                 f"frame, averaged down in {report.result.stats.resolve_ms:.0f} ms more)")
    if report.frames > 1:
        click.echo(f"frames: {report.frames}, median {report.frame_ms:.1f} ms render + "
                   f"{report.update_ms:.1f} ms update (pose, skin, upload) at {size}, {mode}")
    elif report.timed:
        click.echo(f"frame: {report.frame_ms:.1f} ms at {size}, {mode} "
                   f"(median of {report.timed} frames after a warm-up)")
    else:
        click.echo(f"frame: {report.frame_ms:.1f} ms at {size}, {mode} "
                   "(one draw, the driver's first: --time-frames N for a median)")
    click.echo("wrote " + ", ".join(str(p) for p in report.written))
