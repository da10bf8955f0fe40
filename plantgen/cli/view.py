"""``plantgen view``: orbit a plant in a window, switch methods and knobs, and watch it
regrow when its grammar is saved."""

from __future__ import annotations

from pathlib import Path

import click

from ..geometry.camera import Camera
from ..images import parse_background
from ..render.raycast import RaycastSettings
from ..render.supersample import MAX_SSAA
from ..scene import EFFECTS, parse_effect_list
from ..viewer import ViewOptions, run_viewer
from ..viewer.keys import help_lines
from ..viewer.session import MAX_LEVEL, METHODS
from .options import (
    allow_path_opt,
    finite,
    input_arg,
    iterations_opt,
    limit_opt,
    limits_from,
    orbit_from,
    orbit_options,
    seed_opt,
    size_opt,
    smooth_bends_opt,
)

MARCH = RaycastSettings()


def _keys_epilog() -> str:
    width = max(len(k) for k, _ in help_lines())
    return "\b\nKeys and mouse (H shows them in the window):\n" + "\n".join(
        f"  {k.ljust(width)}  {t}" for k, t in help_lines())


@click.command(epilog=_keys_epilog())
@input_arg
@size_opt(what="Window size", default="the camera file's, else 1024x768")
@click.option("--camera", type=click.Path(dir_okay=False, path_type=Path), metavar="FILE.json",
              help="Start from a camera JSON (written by C or by plantgen render --camera-out).")
@orbit_options
@click.option("--method", type=click.Choice([m.lower() for m in METHODS], case_sensitive=False),
              help="Start with RC, RC+R (ray casting, without and with relief), GS or GS+R "
                   "(tessellated meshes). Default: RC+R when the effects list relief, else RC.")
@click.option("--subdiv", type=click.IntRange(0, MAX_LEVEL), default=1, show_default=True, metavar="M",
              help="GS subdivision level m (16·4^m triangles per frustum, 8·2^m per cap).")
@click.option("--effects", metavar="LIST",
              help=f"Comma-separated effects replacing the scene's list (known: {', '.join(EFFECTS)}).")
@click.option("--relief/--no-relief", default=None, help="Relief on or off at the start (default: the effects').")
@click.option("--shadows/--no-shadows", default=None, help="Shadows on or off at the start (default: the effects').")
@click.option("--shadow-res", type=click.IntRange(16, 16384), default=2048, show_default=True,
              help="Shadow map texels per side.")
@click.option("--ssaa", type=click.IntRange(1, MAX_SSAA), default=1, show_default=True, metavar="N",
              help="Supersampling, N x N rays a pixel (A cycles 1..4 in the window).")
@click.option("--background", default="sky", show_default=True, metavar="COLOUR|none",
              help="The background: 'sky', a colour or 'none' (transparent screenshots).")
@click.option("--time", "time_s", type=click.FloatRange(min=0), default=0.0, callback=finite, metavar="T",
              help="Seconds: the pose an animated scene starts at.")
@seed_opt
@iterations_opt
@click.option("--linear-steps", type=click.IntRange(1, 4096), help="Relief: linear steps at the start.")
@click.option("--binary-steps", type=click.IntRange(0, 64), help="Relief: binary steps at the start.")
@click.option("--march", type=click.Choice(["adaptive", "fixed"]), help="Relief: the march at the start.")
@click.option("--shots", type=click.Path(file_okay=False, path_type=Path), default=Path("."),
              show_default=True, help="Folder for screenshots (P) and cameras (C).")
@click.option("--watch/--no-watch", default=True, show_default=True,
              help="Re-grow the plant when the input file or a grammar it includes is saved.")
@click.option("--snapshot", type=click.Path(dir_okay=False, path_type=Path), metavar="FILE.png",
              help="Draw a few frames, save the window as shown (heads-up line included) and close: "
                   "a screenshot for documentation.")
@smooth_bends_opt
@limit_opt
@allow_path_opt
def view(input: Path, size, camera, azimuth, elevation, distance, zoom, fov, method, subdiv, effects, relief,
         shadows, shadow_res, ssaa, background, time_s, seed, iterations, linear_steps, binary_steps, march,
         shots, watch, snapshot, smooth_bends, limit_values, allow_paths) -> None:
    """Open INPUT (a grammar or scene .yaml, a shipped name, or a skeleton .npz or .swc)
    in a window and turn it around in real time.

    Frames come from the same ray caster (RC, RC+R) and raster renderer (GS, GS+R) as
    plantgen render; the heads-up line shows the frame time and fps (medians of the last
    frames), the segments, the method and its knobs and the GL renderer. P saves the frame
    and C the camera, as JSON that plantgen render --camera draws pixel for pixel (the
    command is printed). When the input file or a grammar it includes is saved, the plant
    is grown again and swapped in, keeping the camera; a broken edit keeps the last good
    plant and shows the error. Needs a display and the view extra:
    pip install 'plantgen[view]'.

    \b
    Examples:
      plantgen view pine
      plantgen view my_tree.yaml --method rc+r --ssaa 2 --azimuth 90
      plantgen view dancing_cacti                 # Space plays, , and . scrub
    """
    if camera is not None and not camera.is_file():
        raise click.BadParameter(f"{camera}: no such camera file", param_hint="--camera")
    limits = limits_from(limit_values)
    if size is None and camera is not None:
        saved = Camera.load(camera, limits)
        size = (saved.width, saved.height)
    if shots.exists() and not shots.is_dir():
        raise click.BadParameter(f"{shots} is not a folder", param_hint="--shots")
    if not shots.exists():
        raise click.BadParameter(f"{shots}: no such folder", param_hint="--shots")
    if snapshot is not None and snapshot.suffix.lower() != ".png":
        raise click.BadParameter(f"{snapshot}: the snapshot must end in .png", param_hint="--snapshot")
    options = ViewOptions(
        input=input, size=size or (1024, 768), seed=seed, iterations=iterations,
        effects=parse_effect_list(effects) if effects is not None else None, relief=relief, shadows=shadows,
        method=next((m for m in METHODS if m.lower() == method.lower()), None) if method else None,
        level=subdiv, ssaa=ssaa, background=parse_background(background),
        background_name=None if background == "sky" else background, camera=camera,
        orbit=orbit_from(azimuth, elevation, distance, zoom, fov), time_s=time_s, linear_steps=linear_steps,
        binary_steps=binary_steps, march=march, shadow_res=shadow_res, shots=shots, watch=watch, snapshot=snapshot,
        limits=limits, allow_paths=tuple(allow_paths), smooth_bends=smooth_bends)
    how = run_viewer(options, say=click.echo, warn=lambda line: click.echo(line, err=True))
    click.echo("interrupted: window closed" if how == "interrupted" else "window closed")
