"""``plantgen export``: tessellate a model (GS, GS+R) and write a mesh (glTF, OBJ, PLY,
STL, USD), or write its skeleton (SWC) or forestry cylinder model (QSM)."""

from __future__ import annotations

from pathlib import Path

import click

from ..assets import AssetSettings
from ..exporters import EXPORT_FORMATS
from ..geometry.skeletons.frames import UP_AXES
from ..knobs import knob_of
from ..pipeline import INSTANCING, export_model
from ..settings import DetailSettings, KeyframeSettings, LevelSettings, MeshSettings
from .options import (
    allow_path_opt,
    finite,
    input_arg,
    jobs_opt,
    knob_option,
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
from .sections import OUTPUT, QUALITY, SectionedCommand

_SUFFIXES = ", ".join(EXPORT_FORMATS)


#: Where export's options go in ``--help`` (beside the settings' own sections).
SECTIONS = {"subdiv": QUALITY, "relief": QUALITY, "textures": OUTPUT, "aspect_step": QUALITY, "up": OUTPUT,
            "instancing": OUTPUT, "unit": OUTPUT, "qsm_tolerance": QUALITY, "lod_pixels": OUTPUT, "ground_disc": OUTPUT}


@click.command(cls=SectionedCommand, sections=SECTIONS)
@input_arg
@output_opt(f"its suffix names the format: {_SUFFIXES}. A .gltf gets its .bin beside it, an "
            ".obj its .mtl, a .qsm.csv a .treedata.csv. Default: INPUT's name with .glb, in the current directory.",
            required=False)
@knob_option(knob_of(MeshSettings, "level"), MeshSettings().level,
             help="Subdivision level m: 16·4^m triangles per frustum, plus 8·2^m per cap. Not given: 1, or "
                  "the finest level under it whose triangles and memory fit the limits (a line says so).")
@click.option("--relief/--no-relief", default=MeshSettings().relief, show_default=True,
              help="Displace vertices onto the relief shell (GS+R).")
@click.option("--textures/--no-textures", default=True, show_default=True,
              help="glTF, OBJ, USD: bake each relief material into PNG maps (base colour, tangent-space "
                   "normal, height) the file's materials use; with --relief the base colour only.")
@click.option("--aspect-step", type=click.FloatRange(min=1, min_open=True), default=None, callback=finite,
              metavar="RATIO",
              help="Normal maps per aspect: split each relief material's segments into buckets RATIO apart in "
                   "radius over length, each with its own normal map (exact for its aspect; e.g. 2). "
                   "Default: one normal map per material, at its median aspect.")
@click.option("--ground/--no-ground", "ground_disc", default=False, show_default=True,
              help="glTF, USD: under a single plant (a grammar or a skeleton), write the ground disc that "
                   "plantgen render draws there (glTF: its mottle and its fade at the rim in a texture; USD: "
                   "flat). A scene writes its own ground either way.")
@click.option("--up", type=click.Choice(UP_AXES), default=None,
              help="The up axis of the file. Default: the format's convention: y for glTF, OBJ, "
                   "USD and SWC; z for PLY, STL and QSM. z turns the model +90° about x.")
@click.option("--instancing", type=click.Choice(INSTANCING), default="nodes", show_default=True,
              help="A scene's repeated plants in glTF and USD: nodes writes each once with one "
                   "node per copy sharing its mesh (core glTF, which every reader opens; USD "
                   "instanceable references); gpu writes each once with glTF's "
                   "EXT_mesh_gpu_instancing, which the file then requires (Blender 3.4 refuses it) "
                   "/ a USD PointInstancer; off writes every copy's own mesh. OBJ, PLY and STL are "
                   "always off.")
@click.option("--unit", type=click.FloatRange(min=0, min_open=True), default=1.0, show_default=True,
              callback=finite, metavar="METRES",
              help="The length of one model unit in metres: USD's metersPerUnit; QSM files are "
                   "written in metres and DBH is taken 1.3 m along the trunk.")
@click.option("--qsm-tolerance", type=click.FloatRange(min=1e-6), default=1e-3, show_default=True,
              callback=finite,
              help="QSM: split each frustum into the fewest cylinders (of its radius at their middle) "
                   "that lose at most this fraction of its volume; 1 writes one cylinder per segment.")
@knob_options(KeyframeSettings, AssetSettings)
@knob_options(LevelSettings, DetailSettings, helps={
    "lod_pixels": "glTF, USD levels of detail: their screen coverages let a level go where the segments it drops "
                  "span fewer pixels than this (on a 768-pixel-high image)."})
@seed_opt
@smooth_bends_opt
@limit_opt
@allow_path_opt
@jobs_opt
@quiet_opt
@verbose_opt
def export(input: Path, output: Path | None, subdiv: int, relief: bool, textures: bool, aspect_step, up, instancing,
           unit, qsm_tolerance, ground_disc, seed, smooth_bends, limit_values, allow_paths, jobs, quiet, verbose,
           **keys) -> None:
    """Write INPUT (a skeleton .npz or .swc, a grammar or a scene) as a mesh, an SWC
    skeleton or a forestry cylinder model; the format follows OUTPUT's suffix.

    Meshes: vertices lie on the exact branch surfaces, with the normals and texture
    coordinates the renderer uses; open branch ends are capped. glTF, OBJ and USD keep material names and
    colours. A scene's repeated plants are written once and instanced in glTF and USD
    (core glTF nodes by default, which every reader opens). glTF and USD carry a scene's
    camera, light and ground too (the camera render would use, a directional light, the
    ground square in its material); a grammar only its ground disc, with --ground. glTF, OBJ and USD carry the
    relief as textures: per relief material a base colour, a tangent-space normal map
    and a height map, PNG (inside a .glb, beside the others; --no-textures: none).
    A grammar's leaves ({ . } polygons) go into every mesh format beside the branches, in
    their material (a scene's too: an instanced plant carries its own grammar's): glTF
    gives them double-sided "<material> (leaf)" materials, USD a double-sided Leaves
    mesh, PLY and STL plain triangles. SWC and the cylinder models carry the skeleton
    only (a warning says so when leaves are dropped).

    A scene that lists the animation effect and sways is written with its sway by glTF
    (a skin per plant copy, a joint per segment, a rotation channel per joint) and USD
    (UsdSkel): keys at --key-rate a second over one period of the sway, so the
    animation loops (or over --duration seconds); --no-sway, and the other formats,
    write the plants at rest (a warning says so for the formats).

    A scene that lists the lod effect is written with levels of detail (--lod-levels,
    default 4): glTF MSFT_lod (used, not required: other readers show the full level)
    with screen coverages for --lod-pixels, and a USD variantSet "lod" per plant.

    \b
    Examples:
      plantgen export pine                          # writes pine.glb
      plantgen export pine -o pine.glb --subdiv 2 --relief
      plantgen export well -o well.obj              # and well.mtl
      plantgen export oasis -o oasis.usda           # instanceable references, y-up stage
      plantgen export oasis -o oasis.glb --instancing gpu   # EXT_mesh_gpu_instancing
      plantgen export forest -o forest.glb          # 4 levels of detail per plant (MSFT_lod)
      plantgen export dancing_cacti -o dance.glb    # 100 swaying skins, one looping animation
      plantgen export broadleaf -o tree.glb --asset game    # levels, leaf cards, impostor, textures
      plantgen export saguaro -o saguaro.stl        # z-up, as slicers and Blender expect
      plantgen export elm -o elm.qsm.csv            # TreeQSM cylinders + elm.treedata.csv
      plantgen export pine -o pine.swc --up z

    --verbose prints the summary in the renderer's own terms (frusta, rows, m), which the
    glossary explains (docs: reference/glossary.md).
    """
    output = output or Path(input.stem + ".glb")
    asset = take_settings(AssetSettings, keys)
    if click.get_current_context().get_parameter_source("subdiv").name == "DEFAULT":
        # a game asset's levels within their budgets; else the default, or the finest level that fits the limits
        subdiv = 0 if asset.game else None
    with StageBars(enabled=not quiet) as bars:
        info = export_model(input, output, level=subdiv, relief=relief, seed=seed,
                            limits=limits_from(limit_values), allow_paths=allow_paths, up=up,
                            instancing=instancing, unit=unit, qsm_tolerance=qsm_tolerance, progress=bars,
                            smooth_bends=smooth_bends, keyframes=take_settings(KeyframeSettings, keys),
                            textures=textures, aspect_step=aspect_step, detail=take_settings(DetailSettings, keys),
                            levels=take_settings(LevelSettings, keys), asset=asset, ground=ground_disc, jobs=jobs)
    for line in info["warnings"]:    # never silenced by --quiet, as in grow
        click.echo(line, err=True)
    if quiet:
        return
    if "triangles" in info:
        _mesh_summary(info, verbose)
    elif "cylinders" in info:
        _qsm_summary(info)
    else:
        click.echo(f"{info['segments']:,} segments as SWC, {info['up']}-up")
    click.echo("time: " + ", ".join(f"{k} {v * 1000:.1f} ms" for k, v in info["timings"].items()))
    click.echo("wrote " + " and ".join(str(p) for p in info["paths"]))


def _leaves(info: dict) -> str:
    leaves = info.get("leaf_triangles", 0)
    return f", {leaves:,} of leaves, double-sided" if leaves else ""


def _mesh_summary(info: dict, verbose: bool = False) -> None:
    relief = " with relief" if info["relief"] else ""
    if verbose:
        made = f"{info['segments']:,} segments -> {info['rows']:,} frusta, m = {info['level']}{relief}"
    else:
        pieces = f" ({info['rows']:,} pieces written)" if info["rows"] != info["segments"] else ""
        made = f"{info['segments']:,} branch segments{pieces} at subdivision level {info['level']}{relief}"
    click.echo(f"{made}: {info['triangles']:,} triangles ({info['caps']:,} caps{_leaves(info)}), "
               f"{info['vertices']:,} vertices, {info['up']}-up")
    if info.get("smooth_segments"):
        click.echo(f"smooth bends: +{info['smooth_segments']:,} arc segments")
    if info["copies"] > 1:
        click.echo(f"{info['plants']:,} distinct plants written once for {info['copies']:,} copies: "
                   f"{info['drawn']:,} triangles drawn")
    if info.get("scene"):
        click.echo(f"scene: {', '.join(info['scene'])} written with the plants")
    for name, baked in info.get("textures", {}).items():
        kinds = {"basecolor": "base colour", "normal": "normal", "height": "height"}
        click.echo(f"textures of {name}: {baked['size'][1]}x{baked['size'][0]} "
                   f"({', '.join(kinds[k] for k in baked['kinds'])}"
                   f"{'; normal map at r/L ' + format(baked['aspect'], '.3g') if 'normal' in baked['kinds'] else ''})")
    _levels_summary(info, verbose)
    for line in info.get("asset_lines", ()):
        click.echo(line)
    sway = info.get("animation")
    if sway:
        click.echo(f"sway: {sway['keys']:,} keys over {sway['duration']:g} s ({sway['rate']:g} a second, "
                   f"{'looping' if sway['loops'] else 'not a whole period: no loop'}), {sway['joints']:,} joints "
                   f"in {sway['skins']:,} {'skin' if sway['skins'] == 1 else 'skins'}")


def _levels_summary(info: dict, verbose: bool = False) -> None:
    levels = info.get("levels")
    if levels:
        each = "lod{k} {rows:,} rows, {triangles:,} triangles" if verbose else \
            "level {k}: {rows:,} branch pieces, {triangles:,} triangles"
        click.echo(f"levels of detail: {len(levels)} (" + "; ".join(
            each.format(k=k, rows=rows, triangles=triangles) for k, (rows, triangles) in enumerate(levels))
            + "; each plant written once)")


def _qsm_summary(info: dict) -> None:
    m = info["metrics"]
    unit = m.unit
    lost = 1 - info["volume"] / info["volume_frusta"] if info["volume_frusta"] else 0.0
    click.echo(f"{info['segments']:,} segments -> {info['cylinders']:,} cylinders "
               f"(volume {lost:.3%} under the tapered branches'; tolerance {info['tolerance']:g}), "
               f"{info['up']}-up, metres")
    dbh = (f"DBH {m.dbh * unit:.4g} m" if m.dbh is not None
           else f"no DBH (the trunk is shorter than {m.breast_height * unit:g} m)")
    click.echo(f"height {m.height * unit:.4g} m; {dbh}; wood volume {m.volume * unit ** 3:.4g} m³ "
               f"({m.trunk_volume * unit ** 3:.4g} trunk); crown {m.crown.area * unit ** 2:.4g} m², "
               f"width {m.crown.max_width * unit:.4g} m (mean {m.crown.mean_width * unit:.4g})")
