"""What an engine asset's shortcuts cost: leaf cards against the leaf polygons, and the
octahedral impostor against the plant, in triangles, bytes and image error.

Run as ``python -m plantgen.benchmarks.engine_assets [--model broadleaf] [--views 8]
[--frames 4,8,16] [--sizes 256,512,1024,2048] [--size 256] [--out engine_assets.md]``.

**Error.** The bench's metric (:func:`plantgen.table1.quality.image_error`: 1 - SSIM of
the depth shading plus the silhouette mismatch) between distance images, from ``--views``
random directions of the upper hemisphere (seeded; elevation 0 to 80 degrees), each seen
as the impostor's views are (:func:`plantgen.gl.impostor.impostor_camera`: a camera 200
bounding radii away framing the bounding sphere).

- *Leaf cards*: the leaves alone, polygons against cards, drawn by a small z-buffer pass
  here (the cards cut where their atlas's alpha is under 0.5, as ``alphaMode: MASK``
  draws them), at ``--size`` pixels.
- *Impostor*: the reference is RC+R's render of the plant (frusta, relief, leaves) at the
  impostor's tile size (where an engine switches to the impostor, the plant spans no more
  pixels than a tile); the impostor's image is its nearest view's tile (the view whose
  atlas coordinates are nearest the direction's: what a one-frame impostor shader draws),
  its depth read back to distances. Two more columns split the error: the impostor on
  three of its own views (the bake's own error: 8-bit depth, the tile's texels) and the
  plant itself rendered from the nearest view against the random view (the floor of any
  one-view impostor: what N buys). Its draw cost is two triangles and one atlas sample a
  pixel (three with normal and depth), whatever N and the atlas size.

Bytes: the PNG bytes a .glb holds for the maps, and the raw texels a GPU holds (RGBA8
colour and normal, R8 depth, without mipmaps).
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from ..files import write_atomically
from ..geometry.meshes.impostor import frame_basis, octahedral_uv, view_directions
from ..geometry.meshes.leaf_cards import leaf_cards
from ..geometry.skeletons.skin import skin_skeleton
from ..geometry.stage import MODEL_LIGHT
from ..gl.context import gl_context, renderer_name
from ..gl.impostor import DISTANCE_FACTOR, bake_impostor, bounding_sphere, impostor_camera
from ..gl.raycast import Raycaster
from ..images import png_bytes
from ..pipeline import grow_file
from ..settings import RaycastSettings
from ..table1.quality import image_error

VERTEX = """
#version 330
in vec3 position; in vec2 uv; out vec2 v_uv; out float v_s;
uniform mat3 basis; uniform vec3 centre; uniform float radius;
void main() {
  vec3 p = basis * (position - centre);          // right, up, towards the viewer
  v_uv = uv; v_s = p.z;
  gl_Position = vec4(p.x / radius, p.y / radius, -p.z / radius, 1.0);
}
"""
FRAGMENT = """
#version 330
in vec2 v_uv; in float v_s; out float s;
uniform sampler2D atlas; uniform bool cut;
void main() {
  if (cut && texture(atlas, v_uv).a < 0.5) discard;
  s = v_s;
}
"""


def random_directions(count: int, seed: int = 7) -> np.ndarray:
    """(count, 3) unit directions, azimuth uniform, elevation 0 to 80 degrees."""
    rng = np.random.default_rng(seed)
    azimuth = rng.uniform(0, 2 * np.pi, count)
    elevation = np.radians(rng.uniform(0, 80, count))
    return np.stack([np.cos(elevation) * np.sin(azimuth), np.sin(elevation), np.cos(elevation) * np.cos(azimuth)], 1)


class LeafRaster:
    """A z-buffer pass drawing triangles (cut by an atlas's alpha where given) into an
    image of each texel's offset towards the viewer from the sphere's centre plane."""

    def __init__(self, size: int):
        self.ctx = gl_context()
        self.program = self.ctx.program(vertex_shader=VERTEX, fragment_shader=FRAGMENT)
        self.size = size
        self.colour = self.ctx.renderbuffer((size, size), 1, dtype="f4")
        self.depth = self.ctx.depth_renderbuffer((size, size))
        self.fbo = self.ctx.framebuffer([self.colour], self.depth)

    def offsets(self, vertices, triangles, centre, radius, direction, uv=None, atlas=None,
                mipmaps: bool = True) -> np.ndarray:
        """(size, size) offsets s (nan where nothing is drawn), row 0 at the top; the atlas
        sampled trilinearly from mipmaps averaged as a GPU builds them, or (``mipmaps``
        False) bilinearly from its full level."""
        right, up = frame_basis(direction)
        self.program["basis"].write(np.stack([right, up, direction]).T.astype("f4").tobytes())
        self.program["centre"].value = tuple(float(c) for c in centre)
        self.program["radius"].value = float(radius)
        self.program["cut"].value = atlas is not None
        data = np.c_[vertices[triangles.ravel()], (uv if uv is not None else np.zeros((len(vertices), 2)))
                     [triangles.ravel()]].astype("f4")
        buffer = self.ctx.buffer(data.tobytes())
        vao = self.ctx.vertex_array(self.program, [(buffer, "3f 2f", "position", "uv")])
        texture = None
        if atlas is not None:
            texture = self.ctx.texture(atlas.shape[1::-1], 4, np.ascontiguousarray(atlas).tobytes())
            if mipmaps:
                texture.build_mipmaps()
            else:
                texture.filter = (self.ctx.LINEAR, self.ctx.LINEAR)
            texture.use(0)
            self.program["atlas"].value = 0
        self.fbo.use()
        self.ctx.enable(self.ctx.DEPTH_TEST)
        self.ctx.disable(self.ctx.CULL_FACE)
        self.fbo.clear(float("nan"), 0, 0, 0, depth=1.0)
        vao.render()
        out = np.frombuffer(self.fbo.read(components=1, dtype="f4"), "f4").reshape(self.size, self.size)[::-1]
        for o in (vao, buffer, texture):
            if o is not None:
                o.release()
        return out.astype(np.float64)


def impostor_distances(s: np.ndarray, radius: float) -> np.ndarray:
    """Distances along the view of offsets ``s`` (inf where nothing is drawn)."""
    return np.where(np.isfinite(s), DISTANCE_FACTOR * radius - s, np.inf)


def leaf_card_rows(model: str, views: np.ndarray, size: int, tile: int = 64) -> list[dict]:
    """Polygons and cards of ``model``'s leaves: triangles, bytes, mean/max image error."""
    grown = grow_file(model)
    polygons = grown.polygons
    frusta = skin_skeleton(grown.skeleton)
    centre, radius = bounding_sphere(frusta, polygons)
    cards = leaf_cards(polygons, tile=tile)
    raster = LeafRaster(size)
    errors: dict = {True: [], False: []}
    for d in views:
        camera = impostor_camera(centre, radius, d, size)
        ref = impostor_distances(raster.offsets(polygons.vertices, polygons.triangles, centre, radius, d), radius)
        for mipmaps in (True, False):
            quads = cards.polygons
            got = impostor_distances(raster.offsets(quads.vertices, quads.triangles, centre, radius, d,
                                                    cards.uv.reshape(-1, 2), cards.atlas.image, mipmaps), radius)
            errors[mipmaps].append(image_error(got, ref, camera, -np.asarray(MODEL_LIGHT.travel)))
    # vertex bytes as glTF writes leaves: POSITION, NORMAL, TEXCOORD_0, COLOR_0 (float32), and the indices
    # (32-bit past 65,536 vertices: the polygons; 16-bit: the cards)
    per_vertex = 4 * (3 + 3 + 2 + 3)
    polygon_bytes = len(polygons.vertices) * per_vertex + polygons.triangles.size * 4
    card_bytes = len(cards.polygons.vertices) * per_vertex + cards.polygons.triangles.size * 2
    atlas_png = len(png_bytes(cards.atlas.image))
    rows = [dict(kind="polygons (the reference)", triangles=len(polygons.triangles), bytes=polygon_bytes, texture=0,
                 error=0.0, worst=0.0, dssim=0.0, silhouette=0.0)]
    for mipmaps, how in ((False, "as written: no mipmaps"), (True, "with mipmaps a GPU averages")):
        e = errors[mipmaps]
        rows.append(dict(kind=f"cards ({cards.atlas.shapes} shapes, {tile}² tiles; {how})",
                         triangles=len(cards.polygons.triangles), bytes=card_bytes, texture=atlas_png,
                         error=float(np.mean([x.total for x in e])), worst=float(np.max([x.total for x in e])),
                         dssim=float(np.mean([x.dssim for x in e])),
                         silhouette=float(np.mean([x.silhouette for x in e]))))
    return rows


def impostor_rows(model: str, views: np.ndarray, frames: list[int], sizes: list[int]) -> list[dict]:
    """Per N and atlas size: the impostor's bytes, bake time and image error (mean, max)."""
    grown = grow_file(model)
    frusta = skin_skeleton(grown.skeleton)
    leaves = grown.polygons if grown.polygons is not None and len(grown.polygons) else None
    caster = Raycaster(gl_context())
    centre, radius = bounding_sphere(frusta, leaves)
    names = frusta.material_names
    references: dict = {}
    rows = []
    for n in frames:
        for size in sizes:
            if size % n or size // n < 8:
                continue
            t0 = time.perf_counter()
            imp = bake_impostor(frusta, names, leaves, frames=n, size=size, caster=caster)
            bake = time.perf_counter() - t0
            tile = imp.tile
            errors, floor = [], []
            grid = view_directions(n).reshape(-1, 3)
            on_grid = grid[np.linspace(0, len(grid) - 1, 3).astype(int)]

            def reference(d, tile=tile):
                key = (tuple(np.round(d, 12)), tile)
                if key not in references:
                    references[key] = caster.render(frusta, impostor_camera(centre, radius, d, tile),
                                                    RaycastSettings(relief=True), names, leaves=leaves).distance
                return references[key]
            for d in [*views, *on_grid]:
                camera = impostor_camera(centre, radius, d, tile)
                i, j = np.round(octahedral_uv(d) * (n - 1)).astype(int)
                if len(floor) < len(views):               # the plant itself from the nearest view: a one-view floor
                    floor.append(image_error(reference(view_directions(n)[j, i]), reference(d), camera,
                                             -np.asarray(MODEL_LIGHT.travel)).total)
                depth = imp.depth[j * tile:(j + 1) * tile, i * tile:(i + 1) * tile].astype(np.float64)
                s = np.where(depth > 0, (2 * (depth - 1) / 254 - 1) * radius, np.nan)
                errors.append(image_error(impostor_distances(s, radius), reference(d), camera,
                                          -np.asarray(MODEL_LIGHT.travel)).total)
            errors, grid_errors = errors[:len(views)], errors[len(views):]
            png = sum(len(png_bytes(m)) for m in (imp.colour, imp.normal, imp.depth))
            nearest = np.degrees(np.arccos(np.clip([max(view_directions(n).reshape(-1, 3) @ d) for d in views],
                                                   -1, 1)))
            rows.append(dict(frames=n, size=size, tile=tile, png=png, raw=imp.bytes, bake=bake,
                             error=float(np.mean(errors)), worst=float(np.max(errors)),
                             angle=float(np.mean(nearest)), grid=float(np.mean(grid_errors)),
                             floor=float(np.mean(floor))))
            print(f"N={n} atlas={size}: tile {tile}, error {rows[-1]['error']:.4f} (max {rows[-1]['worst']:.4f}), "
                  f"{png / 1024:.0f} KiB PNG, bake {bake:.1f} s", file=sys.stderr)
    return rows


def markdown(model: str, cards: list[dict], impostors: list[dict], views: int, size: int, elapsed: float) -> str:
    when = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    lines = [f"# Engine assets: {model}", "",
             f"{when}; {platform.machine()} {platform.system()}, {renderer_name()}; {views} random views "
             f"(elevation 0-80°, seed 7); {elapsed:.0f} s (2 CPU cores shared with other work).", "",
             f"## Leaf cards against leaf polygons (the leaves alone, {size}² pixels)", "",
             "| leaves | triangles | vertex + index bytes | atlas PNG bytes | image error (mean) | its DSSIM | "
             "its silhouette | worst view |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    lines += [f"| {r['kind']} | {r['triangles']:,} | {r['bytes']:,} | {r['texture']:,} | {r['error']:.4f} | "
              f"{r['dssim']:.4f} | {r['silhouette']:.4f} | {r['worst']:.4f} |" for r in cards]
    lines += ["", "## Impostor against the plant (RC+R, at the impostor's tile size)", "",
              "Draw cost: 2 triangles; one colour sample a pixel (plus one normal and one depth sample for lit, "
              "depth-correct impostors), for every N and atlas size.", "",
              "| N×N views | atlas | tile | nearest view (mean °) | PNG bytes | GPU bytes (raw) | bake s | "
              "image error (mean) | worst view | on its own views | the plant from the nearest view |",
              "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in impostors:
        lines.append(f"| {r['frames']}×{r['frames']} | {r['size']} | {r['tile']} | {r['angle']:.1f} | {r['png']:,} | "
                     f"{r['raw']:,} | {r['bake']:.1f} | {r['error']:.4f} | {r['worst']:.4f} | {r['grid']:.4f} | "
                     f"{r['floor']:.4f} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", default="broadleaf")
    parser.add_argument("--views", type=int, default=8)
    parser.add_argument("--frames", default="4,8,16")
    parser.add_argument("--sizes", default="256,512,1024,2048")
    parser.add_argument("--size", type=int, default=256, help="leaf cards: pixels a side")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    views = random_directions(args.views)
    cards = leaf_card_rows(args.model, views, args.size)
    impostors = impostor_rows(args.model, views, [int(x) for x in args.frames.split(",")],
                              [int(x) for x in args.sizes.split(",")])
    text = markdown(args.model, cards, impostors, args.views, args.size, time.perf_counter() - t0)
    if args.out is None:
        print(text)
    else:
        write_atomically(args.out, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))
        print(f"wrote {args.out}")
    return 0


__all__ = ["LeafRaster", "impostor_distances", "impostor_rows", "leaf_card_rows", "main", "random_directions"]

if __name__ == "__main__":
    sys.exit(main())
