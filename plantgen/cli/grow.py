"""``plantgen grow``: grammar or scene to skeleton."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from ..errors import PlantgenError
from ..files import check_outputs, write_all_atomically
from ..geometry.skeletons.frames import UP_AXES
from ..geometry.skeletons.swc import write_swc
from ..lsystem.derive import DEFAULT_MAX_MODULES
from ..metrics import geometry_bounds
from ..pipeline import grow_file, model_leaves
from .options import (
    allow_path_opt,
    define_values,
    input_arg,
    iterations_opt,
    jobs_opt,
    limit_opt,
    limits_from,
    output_opt,
    quiet_opt,
    seed_opt,
)
from .progress import StageBars


@click.command()
@input_arg
@output_opt("the skeleton: .npz (plantgen's arrays, y-up) or .swc. Default: INPUT's name with "
            ".npz, in the current directory.", required=False)
@seed_opt
@iterations_opt
@click.option("--max-modules", type=click.IntRange(min=1),
              help="Stop with an error if the module string would grow past this many modules "
                   f"(default {DEFAULT_MAX_MODULES:,}; the same as --limit modules=N).")
@click.option("--define", "defines", multiple=True, metavar="NAME=VALUE",
              help="Set one of the grammar's defines (repeatable), e.g. --define angle=25; "
                   "as a batch's sweep does, so its manifest rows can be grown again alone.")
@click.option("--format", "formats", type=click.Choice(["npz", "swc"]), multiple=True,
              help="Also write these formats beside the output, under its name (repeatable).")
@click.option("--up", type=click.Choice(UP_AXES), default="y", show_default=True,
              help="The up axis of SWC output (z turns the model +90° about x; the file says so and "
                   "reads back upright). The .npz is always y-up.")
@limit_opt
@allow_path_opt
@jobs_opt
@quiet_opt
def grow(input: Path, output: Path | None, seed, iterations, max_modules, defines, formats, up, limit_values,
         allow_paths, jobs, quiet) -> None:
    """Grow INPUT (a grammar or scene .yaml, or a shipped one by name) into a skeleton;
    a skeleton .npz or .swc is read back, checked and written again.

    Derives the L-system, walks the turtle, and writes the segment arrays (start, end,
    r_start, r_end, parent, continues, material, material_names) as .npz, or the
    skeleton as SWC (docs: reference/formats.md). A scene writes all its instances as one
    skeleton. Prints segments, branch tips, the height and bounding box of the geometry
    (the frusta, radii included where they reach) and the time of each stage.

    \b
    Examples:
      plantgen grow pine --seed 3 --format swc      # pine.npz and pine.swc
      plantgen grow desert -o desert.swc
    """
    output = output or Path(input.stem + ".npz")
    _check_outputs(output, formats, up)
    with StageBars(enabled=not quiet) as bars:
        result = grow_file(input, seed=seed, iterations=iterations, max_modules=max_modules, progress=bars,
                           limits=limits_from(limit_values), allow_paths=allow_paths, defines=define_values(defines),
                           jobs=jobs)
    skel = result.skeleton
    if len(skel) == 0 and model_leaves(result) is None:     # refused in one line, before any warning
        raise PlantgenError(f"{input}: the grammar draws no segments (no F in the derived string)")
    for line in result.warnings:     # never silenced by --quiet: a symbol not drawn is news
        click.echo(line, err=True)
    written = _write_outputs(skel, output, formats, up)
    leaves = result.polygons
    if leaves is not None and len(leaves):       # like SWC, the skeleton files hold no leaves
        click.echo(f"warning: {', '.join(p.suffix for p in written)} carries the skeleton only: {len(leaves):,} "
                   f"leaf polygons not written (plantgen render and export grow them from the grammar)", err=True)
    if quiet:
        return
    b = geometry_bounds(skel)
    t = result.timings
    stages = ", ".join(f"{k} {v * 1000:.1f} ms" for k, v in t.items())
    leafy = (f", {len(leaves):,} leaf polygons ({len(leaves.triangles):,} triangles)"
             if leaves is not None and len(leaves) else "")
    click.echo(f"{result.name} ({result.kind}): {len(skel):,} segments, {len(skel.tips):,} branch tips, "
               f"{result.modules:,} modules{leafy}")
    click.echo(f"height {b[1, 1] - b[0, 1]:.4g}; bounds min {np.array2string(b[0], precision=3)} "
               f"max {np.array2string(b[1], precision=3)}")
    click.echo(f"time: {stages}; total {sum(t.values()) * 1000:.1f} ms")
    click.echo("wrote " + " and ".join(str(p) for p in written))


def _check_outputs(output: Path, formats, up: str) -> None:
    """Refuse, before any work, an output grow cannot write."""
    kind = output.suffix.lower().lstrip(".")
    if kind not in ("npz", "swc"):
        raise PlantgenError(f"{output}: the skeleton output must end in .npz or .swc")
    if up != "y" and "swc" not in (kind, *formats):
        raise PlantgenError("--up z applies to SWC output; the .npz skeleton is always y-up")
    check_outputs(_output_paths(output, formats))


def _output_paths(output: Path, formats) -> list[Path]:
    kind = output.suffix.lower().lstrip(".")
    return [output] + [output.with_suffix(f".{f}") for f in dict.fromkeys(formats) if f != kind]


def _write_outputs(skel, output: Path, formats, up: str) -> list[Path]:
    """Write the skeleton as ``output`` (.npz or .swc) and as each of ``formats`` beside it."""
    return write_all_atomically([(path, (lambda tmp: write_swc(skel, tmp, up=up)) if path.suffix.lower() == ".swc"
                                  else skel.save) for path in _output_paths(output, formats)])
