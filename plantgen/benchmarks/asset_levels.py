"""The levels of a game asset side by side, and its impostor's atlas.

Run as ``python -m plantgen.benchmarks.asset_levels MODEL LEVELS.png ATLAS.png [--size W H]``.

LEVELS.png: from the front (the impostor's view from +z, a view the atlas holds), each
level of detail as ``plantgen export MODEL --asset game`` writes it (its triangles at
m = 0, the leaves as alpha-cut cards), then the impostor's tile, all drawn as the bench's
error metric sees them (the depth shading of :func:`plantgen.table1.quality.depth_shading`)
over their triangle counts; beside each level its image error against level 0. ATLAS.png:
the impostor's colour, normal and depth atlases (8×8 views, 1024², hemi-octahedral).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from ..geometry.meshes.leaf_cards import leaf_cards
from ..geometry.meshes.mesh import tessellate
from ..geometry.skeletons.skin import skin_skeleton
from ..geometry.stage import MODEL_LIGHT
from ..gl.impostor import bake_impostor, bounding_sphere, impostor_camera
from ..pipeline import grow_file, plant_detail
from ..table1.quality import depth_shading, image_error
from .engine_assets import LeafRaster, impostor_distances


def level_images(model: str, size: int, frames: int = 8, atlas: int = 1024):
    """([(label, distance image)] per level and the impostor, the impostor)."""
    grown = grow_file(model)
    frusta = skin_skeleton(grown.skeleton)
    leaves = grown.polygons
    mesh = tessellate(frusta, 0)
    detail = plant_detail(frusta, grown.skeleton.parent, mesh, leaves, 4, 2.0)
    cards = leaf_cards(leaves)
    imp = bake_impostor(frusta, frusta.material_names, leaves, frames=frames, size=atlas)
    centre, radius = bounding_sphere(frusta, leaves)
    d = np.array([0.0, 0.0, 1.0])
    raster = LeafRaster(size)
    out = []
    for k, level in enumerate(detail.levels):
        bark = raster.offsets(level.mesh.vertices, level.mesh.faces, centre, radius, d)
        kept = cards.subset(level.leaves)
        leaf = raster.offsets(kept.polygons.vertices, kept.polygons.triangles, centre, radius, d,
                              kept.uv.reshape(-1, 2), kept.atlas.image, mipmaps=False)
        s = np.fmax(bark, leaf)                               # the nearer surface (nan: none)
        out.append((f"lod{k}: {len(level.mesh.faces) + len(kept.polygons.triangles):,} triangles",
                    impostor_distances(s, radius)))
    t = imp.tile
    col, row = frames - 1, 0                                  # the view from +z: atlas (1, 0)
    depth = imp.depth[row * t:(row + 1) * t, col * t:(col + 1) * t].astype(np.float64)
    s = np.where(depth > 0, (2 * (depth - 1) / 254 - 1) * radius, np.nan)
    index = np.arange(size) * t // size                      # the tile drawn at the panel's size, nearest texel
    big = s[index][:, index]
    out.append((f"impostor: 2 triangles, {frames}x{frames} views", impostor_distances(big, radius)))
    return out, imp, impostor_camera(centre, radius, d, size)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model")
    parser.add_argument("levels", type=str)
    parser.add_argument("atlas", type=str)
    parser.add_argument("--size", type=int, nargs=2, default=(1280, 300), metavar=("W", "H"))
    args = parser.parse_args(argv)
    width, height = args.size
    for path in (args.levels, args.atlas):
        Path(path).parent.mkdir(parents=True, exist_ok=True)
    panel = min(width // 5, height - 44)
    images, imp, camera = level_images(args.model, panel)
    light = -np.asarray(MODEL_LIGHT.travel)
    canvas = Image.new("RGB", (width, height), (255, 255, 255))
    draw = ImageDraw.Draw(canvas)
    for k, (label, distance) in enumerate(images):
        shade = depth_shading(distance, camera, light)
        grey = np.where(np.isfinite(distance), shade * 255, 255).astype(np.uint8)
        canvas.paste(Image.fromarray(grey), (k * (width // 5), 0))
        error = image_error(distance, images[0][1], camera, light).total
        draw.text((k * (width // 5) + 4, panel + 4), label, fill=(0, 0, 0))
        draw.text((k * (width // 5) + 4, panel + 22), f"error vs lod0 {error:.3f}", fill=(0, 0, 0))
    canvas.save(args.levels)
    side = 512
    maps = [Image.fromarray(imp.colour), Image.fromarray(imp.normal), Image.fromarray(imp.depth).convert("RGBA")]
    sheet = Image.new("RGB", (3 * side, side), (40, 40, 40))
    for k, m in enumerate(maps):
        back = Image.new("RGBA", m.size, (40, 40, 40, 255))
        back.alpha_composite(m.convert("RGBA"))
        sheet.paste(back.convert("RGB").resize((side, side)), (k * side, 0))
    sheet.save(args.atlas)
    print(f"wrote {args.levels} and {args.atlas}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
