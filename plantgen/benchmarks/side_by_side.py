"""The RC+R | GS | GS+R gallery image of one model, each panel labelled with its GPU bytes.

Run as ``python -m plantgen.benchmarks.side_by_side MODEL OUT.png [--gs M] [--gsr M]
[--zoom F] [--raise F] [--size W H]``. The camera frames the model as ``Camera.auto`` does
from direction (0.3, 0.1, 1), then moves ``--zoom`` of the way towards a target raised by
``--raise`` of the model height.
"""

from __future__ import annotations

import argparse

import numpy as np
from PIL import Image, ImageDraw

from ..geometry.meshes.mesh import tessellate
from ..geometry.rays.camera import Camera
from ..geometry.skeletons.frusta import frusta_bounds
from ..geometry.skeletons.skin import skin_skeleton
from ..gl.context import gl_context
from ..gl.raster import RasterRenderer, gs_buffer_bytes
from ..gl.raycast import Raycaster
from ..gl.records import rc_buffer_bytes
from ..pipeline import load_skeleton
from ..settings import RaycastSettings
from .arguments import view_options

__all__ = ["side_by_side", "labelled_panels", "gallery_camera", "model_view", "main"]

#: The direction the gallery camera looks from (as ``Camera.auto``'s ``direction``).
GALLERY_DIRECTION = (0.3, 0.1, 1.0)


def side_by_side(frusta, camera: Camera, *, gs_level: int = 2, gsr_level: int = 4,
                 material_names=("bark",), linear_steps: int = 64, binary_steps: int = 8) -> np.ndarray:
    """RC+R | GS | GS+R images of one model and camera, labelled, as one (h, 3w, 3) uint8 image.

    GS+R takes its heights from :mod:`plantgen.geometry.skeletons.relief`, the maps the ray caster samples.
    """
    ctx = gl_context()
    rc = Raycaster(ctx).render(frusta, camera, RaycastSettings(relief=True, linear_steps=linear_steps,
                                                               binary_steps=binary_steps),
                               material_names)
    raster = RasterRenderer(ctx)
    gs_mesh = tessellate(frusta, gs_level, caps="tips")  # side branch bases sit unseen in parents
    gs = raster.render(gs_mesh, frusta, camera, material_names=material_names)
    gsr_mesh = tessellate(frusta, gsr_level, relief=True, caps="tips")
    gsr = raster.render(gsr_mesh, frusta, camera, material_names=material_names)
    raster.release()
    n = len(frusta.length)
    panels = [(rc.color, f"RC+R: {n:,} frusta, {rc_buffer_bytes(n):,} B"),
              (gs.color, f"GS m={gs_level}: {len(gs_mesh.faces):,} triangles, "
                         f"{gs_buffer_bytes(gs_mesh):,} B"),
              (gsr.color, f"GS+R m={gsr_level}: {len(gsr_mesh.faces):,} triangles, "
                          f"{gs_buffer_bytes(gsr_mesh):,} B")]
    return labelled_panels(panels, camera.width)


def labelled_panels(panels, width: int) -> np.ndarray:
    """(h, k·width, 3) uint8: the images of ``panels`` ((image (h, width, 3 or 4), label),
    ...) side by side, each labelled in its top-left corner."""
    image = Image.fromarray(np.concatenate([p[0][..., :3] for p in panels], axis=1))
    draw = ImageDraw.Draw(image)
    for i, (_, label) in enumerate(panels):
        x = i * width + 4
        draw.rectangle(draw.textbbox((x, 3), label), fill=(255, 255, 255))
        draw.text((x, 3), label, fill=(0, 0, 0))
    return np.asarray(image)


def gallery_camera(frusta, width: int, height: int, zoom: float = 1.0, lift: float = 0.0) -> Camera:
    """The auto camera from :data:`GALLERY_DIRECTION`, moved ``zoom`` of the way to a target
    raised by ``lift`` times the model's (3,) extent along y."""
    box = frusta_bounds(frusta)
    full = Camera.auto(box, width, height, direction=GALLERY_DIRECTION)
    target = np.asarray(full.target) + np.array([0.0, lift, 0.0]) * (box[1] - box[0])
    eye = target + (np.asarray(full.eye) - np.asarray(full.target)) * zoom
    return Camera(tuple(eye), tuple(target), (0.0, 1.0, 0.0), full.fov_y, width, height)


def model_view(args):
    """(frusta, camera) of ``args.model`` skinned and framed by :func:`gallery_camera` with
    the options of :func:`~plantgen.benchmarks.arguments.view_options`."""
    frusta = skin_skeleton(load_skeleton(args.model))
    return frusta, gallery_camera(frusta, *args.size, zoom=args.zoom, lift=args.lift)


def main(argv=None) -> None:
    """``python -m plantgen.benchmarks.side_by_side MODEL OUT.png``: the RC+R | GS | GS+R gallery image."""
    parser = argparse.ArgumentParser(description=main.__doc__.splitlines()[0])
    parser.add_argument("model", help="grammar, scene or skeleton .npz")
    parser.add_argument("output")
    parser.add_argument("--gs", type=int, default=2, help="GS subdivision level")
    parser.add_argument("--gsr", type=int, default=4, help="GS+R subdivision level")
    view_options(parser)
    args = parser.parse_args(argv)
    frusta, camera = model_view(args)
    image = side_by_side(frusta, camera, gs_level=args.gs, gsr_level=args.gsr,
                         material_names=frusta.material_names)
    Image.fromarray(image).save(args.output)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
