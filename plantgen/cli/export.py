"""``plantgen export``: tessellate a model (GS, GS+R) and write glTF / OBJ / PLY / STL."""

from __future__ import annotations

from pathlib import Path

import click

from . import cli


@cli.command()
@click.argument("input", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="Write the mesh here; the suffix picks the format: .glb, .obj, .ply, .stl.")
@click.option("--subdiv", "level", type=click.IntRange(0, 8), default=1, show_default=True,
              help="Subdivision level m: 16·4^m triangles per segment (Table 1).")
@click.option("--relief/--no-relief", default=False, show_default=True,
              help="Displace vertices onto the relief shell (GS+R).")
@click.option("--seed", type=click.IntRange(min=0), help="Override a grammar's or scene's seed.")
@click.option("-q", "--quiet", is_flag=True, help="Print nothing but errors.")
def export(input: Path, output: Path, level: int, relief: bool, seed, quiet) -> None:
    """Tessellate INPUT (a skeleton .npz, grammar or scene) and write a mesh file.

    Vertices lie on the exact frusta, with the normals (8) and (u, v) of the ray
    caster; open chain ends are capped. glTF keeps material colours and uv.

    \b
    Example:
      plantgen export pine.npz -o pine.glb --subdiv 2 --relief
    """
    from ..pipeline import export_model

    info = export_model(input, output, level=level, relief=relief, seed=seed)
    if quiet:
        return
    t = info["timings"]
    stages = ", ".join(f"{k} {v * 1000:.1f} ms" for k, v in t.items())
    click.echo(f"{info['segments']:,} segments -> {info['rows']:,} frusta, m = {level}"
               f"{' with relief' if relief else ''}: {info['triangles']:,} triangles "
               f"({info['caps']:,} caps), {info['vertices']:,} vertices")
    click.echo(f"time: {stages}")
    click.echo(f"wrote {info['path']}")
