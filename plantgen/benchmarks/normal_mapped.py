"""The RC+R | GS+N | GS image of one model: the ray caster's relief, the smooth mesh with the
exported normal maps (what a glTF reader shows of ``plantgen export``), the mesh without;
with ``--parallax``, RC+R | GS+POM | GS+N | GS: the mesh on the relief's outer shell with
parallax occlusion mapping of the same maps' height besides.

Run as ``python -m plantgen.benchmarks.normal_mapped MODEL OUT.png [--level M] [--zoom F]
[--raise F] [--size W H] [--aspect-step R] [--parallax]``. The normal maps are the ones ``plantgen
export`` bakes (:func:`plantgen.exporters.textures.bake_textures`: one per material, at
its median aspect, or one per aspect bucket), drawn by plantgen's rasteriser as a glTF
reader draws them (``raster.glsl``'s NORMAL_MAP). Each panel is labelled; the camera is
the gallery's (:func:`~plantgen.benchmarks.side_by_side.gallery_camera`).
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np
from PIL import Image

from ..exporters import Plant
from ..exporters.textures import bake_textures, split_by_aspect
from ..geometry.meshes.mesh import outer_shell_mesh, tessellate
from ..geometry.meshes.textures import parallax_map
from ..geometry.skeletons.skeleton import Skeleton
from ..gl.context import gl_context
from ..gl.raster import RasterRenderer
from ..gl.raycast import Raycaster
from ..settings import ParallaxSettings, RaycastSettings
from .arguments import view_options
from .side_by_side import labelled_panels, model_view

__all__ = ["main", "normal_mapped"]


def normal_mapped(frusta, camera, *, level: int = 2, aspect_step: float | None = None,
                  parallax: ParallaxSettings | None = None) -> np.ndarray:
    """RC+R | GS+N | GS of ``frusta`` seen by ``camera``, labelled, (h, 3w, 3) uint8; with
    ``aspect_step`` GS+N has a normal map per aspect bucket (``plantgen export
    --aspect-step``), each bucket drawn in a material slot of its own; with ``parallax``,
    RC+R | GS+POM | GS+N | GS, (h, 4w, 3): the same maps' height marched on the mesh at
    the outer shell with these knobs."""
    names = frusta.material_names
    ctx = gl_context()
    rc = Raycaster(ctx).render(frusta, camera, RaycastSettings(relief=True), names)
    mesh = tessellate(frusta, level, caps="tips")
    plant, bases = Plant("model", Skeleton.empty(names), mesh), {}
    if aspect_step:
        [plant], bases = split_by_aspect([plant], aspect_step)
    baked = bake_textures([plant.mesh], bases=bases)
    slots = [bases.get(n, n) for n in plant.mesh.material_names]      # a bucket's relief and colours: its material's
    maps = {k: baked.get(n).normal for k, n in enumerate(plant.mesh.material_names) if baked.get(n) is not None}
    raster = RasterRenderer(ctx)
    slotted = replace(frusta, material=plant.mesh.material.astype(np.int32))    # rows in their bucket's slot
    gs_n = raster.render(plant.mesh, slotted, camera, material_names=slots, normal_maps=maps)
    gs = raster.render(mesh, frusta, camera, material_names=names)
    pom = None
    if parallax is not None:
        relief_maps = {k: parallax_map(baked.get(n)) for k, n in enumerate(plant.mesh.material_names)
                       if baked.get(n) is not None}
        pom = raster.render(outer_shell_mesh(slotted, level, caps="tips"), slotted, camera, material_names=slots,
                            normal_maps=relief_maps, parallax=parallax)
    raster.release()
    maps = len(baked)
    panels = [(rc.color, f"RC+R: {len(frusta.length):,} frusta"),
              *([] if pom is None else [(pom.color, f"GS+POM m={level}: {parallax.min_layers}-"
                                                    f"{parallax.max_layers} layers, outer shell")]),
              (gs_n.color, f"GS+N m={level}: {len(mesh.faces):,} triangles, {maps} normal map{'s' * (maps > 1)}"),
              (gs.color, f"GS m={level}: no normal map")]
    return labelled_panels(panels, camera.width)


def main(argv=None) -> None:
    """``python -m plantgen.benchmarks.normal_mapped MODEL OUT.png``: the RC+R | GS+N | GS image."""
    parser = argparse.ArgumentParser(description=main.__doc__.splitlines()[0])
    parser.add_argument("model", help="grammar, scene or skeleton .npz")
    parser.add_argument("output")
    parser.add_argument("--level", type=int, default=2, help="GS subdivision level (default 2)")
    parser.add_argument("--aspect-step", type=float, default=None, help="normal maps per aspect bucket (ratio)")
    parser.add_argument("--parallax", action="store_true",
                        help="a GS+POM panel besides (parallax occlusion mapping, ParallaxSettings' defaults)")
    view_options(parser)
    args = parser.parse_args(argv)
    frusta, camera = model_view(args)
    image = normal_mapped(frusta, camera, level=args.level, aspect_step=args.aspect_step,
                          parallax=ParallaxSettings() if args.parallax else None)
    Image.fromarray(image).save(args.output)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
