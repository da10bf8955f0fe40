"""``plantgen view``: orbit a plant in a window, switch methods and knobs, and watch it
regrow when its grammar is saved."""

from __future__ import annotations

from pathlib import Path

import click

from ..files import check_folder, check_output
from ..geometry.rays.camera import Camera
from ..knobs import knob_of
from ..pipeline import existing_input
from ..settings import DEFAULT_SIZE, MeshSettings, RenderSettings
from ..viewer import ViewOptions, run_viewer
from ..viewer.keys import help_lines
from ..viewer.session import METHODS
from .options import (
    allow_path_opt,
    input_arg,
    iterations_opt,
    knob_option,
    knob_options,
    limit_opt,
    limits_from,
    seed_opt,
    smooth_bends_opt,
    take_settings,
)
from .sections import EFFECTS, MODEL, OUTPUT, QUALITY, SectionedCommand


def _keys_epilog() -> str:
    width = max(len(k) for k, _ in help_lines())
    return "\b\nKeys and mouse (H shows them in the window):\n" + "\n".join(
        f"  {k.ljust(width)}  {t}" for k, t in help_lines())


#: Where view's options go in ``--help`` (beside the settings' own sections).
SECTIONS = {"size": OUTPUT, "ssaa": QUALITY, "aa": QUALITY, "pose": QUALITY, "time": EFFECTS, "start_method": QUALITY,
            "subdiv": QUALITY, "shots": OUTPUT, "snapshot": OUTPUT, "watch": MODEL}


@click.command(epilog=_keys_epilog(), cls=SectionedCommand, sections=SECTIONS)
@input_arg
@knob_options(RenderSettings, skip=("frames", "fps", "method"), helps={
    "size": "Window size (WIDTHxHEIGHT pixels; default: the camera file's, else "
            f"{DEFAULT_SIZE[0]}x{DEFAULT_SIZE[1]}).",
    "time": "Seconds: the pose an animated scene starts at.",
    "ssaa": "Supersampling, N x N rays a pixel (A cycles 1..4 in the window)."})
@click.option("--method", "start_method", type=click.Choice([m.lower() for m in METHODS], case_sensitive=False),
              help="Start with RC, RC+R (ray casting, without and with relief), GS or GS+R "
                   "(tessellated meshes), RT or RT+R (ray tracing through a BVH). Default: RC+R when the "
                   "effects list relief, else RC.")
@knob_option(knob_of(MeshSettings, "level"), MeshSettings().level,
             help="GS subdivision level m at the start (16·4^m triangles per frustum, 8·2^m per cap).")
@seed_opt
@iterations_opt
@click.option("--shots", type=click.Path(path_type=Path), default=Path("."),
              show_default=True, help="Folder for screenshots (P) and cameras (C).")
@click.option("--watch/--no-watch", default=True, show_default=True,
              help="Re-grow the plant when the input file or a grammar it includes is saved.")
@click.option("--snapshot", type=click.Path(path_type=Path), metavar="FILE.png",
              help="Draw a few frames, save the window as shown (heads-up line included) and close: "
                   "a screenshot for documentation.")
@smooth_bends_opt
@limit_opt
@allow_path_opt
def view(input: Path, start_method, subdiv, seed, iterations, shots, watch, snapshot, smooth_bends, limit_values,
         allow_paths, **knobs) -> None:
    """Open INPUT (a grammar or scene .yaml, a shipped name, or a skeleton .npz or .swc)
    in a window and turn it around in real time.

    Frames come from the same ray caster (RC, RC+R) and raster renderer (GS, GS+R) as
    plantgen render; the heads-up line shows the frame time and fps (medians of the last
    frames), the segments, the method and its knobs and the GL renderer. P saves the frame
    and C the camera, as JSON that plantgen render --camera draws pixel for pixel (the
    command is printed). When the input file or a grammar it includes is saved, the plant
    is grown again and swapped in, keeping the camera; a broken edit keeps the last good
    plant and shows the error. Needs a display and the view extra:
    pip install '.[view]' (in plantgen's folder).

    \b
    Examples:
      plantgen view pine
      plantgen view my_tree.yaml --method rc+r --ssaa 2 --azimuth 90
      plantgen view dancing_cacti                 # Space plays, , and . scrub
    """
    existing_input(input)           # a mistyped name is one line before the display is looked for
    settings = take_settings(RenderSettings, knobs)
    camera, size = settings.view.camera, settings.image.size
    if not settings.view.auto and not Path(camera).is_file():
        raise click.BadParameter(f"{camera}: no such camera file", param_hint="--camera")
    limits = limits_from(limit_values)
    if size is None and not settings.view.auto:
        saved = Camera.load(camera, limits)
        size = (saved.width, saved.height)
    check_folder(shots)          # where screenshots go: there, a folder, writable
    if snapshot is not None and snapshot.suffix.lower() != ".png":
        raise click.BadParameter(f"{snapshot}: the snapshot must end in .png", param_hint="--snapshot")
    if snapshot is not None:
        check_output(snapshot)
    options = ViewOptions(
        input=input, settings=settings, size=size or DEFAULT_SIZE, seed=seed, iterations=iterations,
        method=next((m for m in METHODS if m.lower() == start_method.lower()), None) if start_method else None,
        level=subdiv, shots=shots, watch=watch, snapshot=snapshot, limits=limits, allow_paths=tuple(allow_paths),
        smooth_bends=smooth_bends)
    how = run_viewer(options, say=click.echo, warn=lambda line: click.echo(line, err=True))
    click.echo("interrupted: window closed" if how == "interrupted" else "window closed")
