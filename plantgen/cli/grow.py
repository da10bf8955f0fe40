"""``plantgen grow``: grammar or scene to skeleton."""

from __future__ import annotations

import time
from pathlib import Path

import click
import numpy as np

from ..errors import PlantgenError
from ..lsystem.derive import DEFAULT_MAX_MODULES
from ..pipeline import grow_file
from .options import (
    allow_path_opt,
    define_values,
    input_arg,
    iterations_opt,
    limit_opt,
    limits_from,
    output_opt,
    quiet_opt,
    seed_opt,
)

#: Seconds between two progress lines of a long derivation.
PROGRESS_EVERY = 1.0


@click.command()
@input_arg
@output_opt("the skeleton (.npz). Default: INPUT's name with .npz, in the current directory.",
            required=False)
@seed_opt
@iterations_opt
@click.option("--max-modules", type=click.IntRange(min=1),
              help="Stop with an error if the module string would grow past this many modules "
                   f"(default {DEFAULT_MAX_MODULES:,}; the same as --limit modules=N).")
@click.option("--define", "defines", multiple=True, metavar="NAME=VALUE",
              help="Set one of the grammar's defines (repeatable), e.g. --define angle=25; "
                   "as a batch's sweep does, so its manifest rows can be grown again alone.")
@click.option("--format", "formats", type=click.Choice(["npz", "swc"]), multiple=True,
              help="Also write these formats (repeatable); swc is written beside the .npz.")
@limit_opt
@allow_path_opt
@quiet_opt
def grow(input: Path, output: Path | None, seed, iterations, max_modules, defines, formats, limit_values,
         allow_paths, quiet) -> None:
    """Grow INPUT (a grammar or scene .yaml, or a shipped one by name) into a skeleton;
    a skeleton .npz or .swc is read back, checked and written again.

    Derives the L-system, walks the turtle, and writes the segment arrays (start, end,
    r_start, r_end, parent, continues, material, material_names) as .npz. A scene writes
    all its instances as one skeleton. Prints segments, branch tips, height, bounding box
    and the time of each stage.

    \b
    Example:
      plantgen grow grammars/pine.yaml -o pine.npz --seed 3 --format swc
    """
    t_start = time.perf_counter()
    shown = [t_start]

    def progress(step, n):
        # Only long derivations report progress, at most one line a PROGRESS_EVERY seconds,
        # so quick ones print a clean summary and a million steps print a few lines.
        now = time.perf_counter()
        if now - shown[0] >= PROGRESS_EVERY:
            shown[0] = now
            click.echo(f"  derivation step {step:,}: {n:,} modules", err=True)

    result = grow_file(input, seed=seed, iterations=iterations, max_modules=max_modules,
                       progress=progress if not quiet else None, limits=limits_from(limit_values),
                       allow_paths=allow_paths, defines=define_values(defines))
    skel = result.skeleton
    if len(skel) == 0:
        raise PlantgenError(f"{input}: the grammar draws no segments (no F in the derived string)")
    output = output or Path(input.stem + ".npz")
    if output.suffix.lower() != ".npz":
        raise PlantgenError(f"{output}: the skeleton output must end in .npz")
    try:
        skel.save(output)
        if "swc" in formats:
            skel.save_swc(output.with_suffix(".swc"))
    except OSError as exc:
        raise PlantgenError(f"{output}: cannot write ({exc.strerror or exc})") from None
    if quiet:
        return
    b = skel.bounds
    t = result.timings
    stages = ", ".join(f"{k} {v * 1000:.1f} ms" for k, v in t.items())
    click.echo(f"{result.name} ({result.kind}): {len(skel):,} segments, {len(skel.tips):,} branch tips, "
               f"{result.modules:,} modules")
    click.echo(f"height {skel.height:.4g}; bounds min {np.array2string(b[0], precision=3)} "
               f"max {np.array2string(b[1], precision=3)}")
    click.echo(f"time: {stages}; total {sum(t.values()) * 1000:.1f} ms")
    click.echo(f"wrote {output}" + (f" and {output.with_suffix('.swc')}" if "swc" in formats else ""))
