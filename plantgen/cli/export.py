"""``plantgen export``: tessellate a model (GS, GS+R) and write glTF / OBJ / PLY / STL."""

from __future__ import annotations

from pathlib import Path

import click

from ..pipeline import export_model
from .options import allow_path_opt, input_arg, limit_opt, limits_from, output_opt, quiet_opt, seed_opt


@click.command()
@input_arg
@output_opt("the mesh, in the format its suffix names: .glb, .obj, .ply or .stl.")
@click.option("--subdiv", "level", type=click.IntRange(0, 8), default=1, show_default=True,
              help="Subdivision level m: 16·4^m triangles per segment (Table 1).")
@click.option("--relief/--no-relief", default=False, show_default=True,
              help="Displace vertices onto the relief shell (GS+R).")
@seed_opt
@limit_opt
@allow_path_opt
@quiet_opt
def export(input: Path, output: Path, level: int, relief: bool, seed, limit_values, allow_paths, quiet) -> None:
    """Tessellate INPUT (a skeleton .npz or .swc, grammar or scene) and write a mesh file.

    Vertices lie on the exact frusta, with the normals (8) and (u, v) of the ray
    caster; open chain ends are capped. glTF keeps material colours and uv.

    \b
    Example:
      plantgen export pine.npz -o pine.glb --subdiv 2 --relief
    """
    info = export_model(input, output, level=level, relief=relief, seed=seed, limits=limits_from(limit_values),
                        allow_paths=allow_paths)
    if quiet:
        return
    t = info["timings"]
    stages = ", ".join(f"{k} {v * 1000:.1f} ms" for k, v in t.items())
    click.echo(f"{info['segments']:,} segments -> {info['rows']:,} frusta, m = {level}"
               f"{' with relief' if relief else ''}: {info['triangles']:,} triangles "
               f"({info['caps']:,} caps), {info['vertices']:,} vertices")
    click.echo(f"time: {stages}")
    click.echo(f"wrote {info['path']}")
