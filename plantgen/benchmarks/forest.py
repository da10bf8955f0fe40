"""The forest: memory and frame time of a thousand instanced plants, with and without the
level of detail, for RC, RC+R, GS and GS+R, and the error the detail costs.

Run as ``python -m plantgen.benchmarks.forest [--scene forest] [--size 1024x768]
[--lod 0,1,2,4,8] [--frames 2] [--gs-level 0] [--out forest.md]``.

For each renderer and each ``--lod`` threshold (pixels; 0 is full detail) the forest is
drawn once to warm up (that draw draws the shadow map: its milliseconds are the *light*
column) and ``--frames`` more times with the map kept; the table gives their median, the
rows (segments) and triangles drawn, and the image error of the frame against the same
renderer's full-detail frame (the bench's metric, :func:`plantgen.table1.quality.image_error`:
1 - SSIM of the depth shading + the silhouette mismatch; both parts are given too).
GPU bytes: what the GPU holds
for the plants (the distinct plants' records or meshes, the relief maps) against what a
merged record set or mesh of every drawn segment would hold; per copy nothing is stored
(52 bytes of uniforms cross per draw). Full-detail GS frames are drawn once, untimed
warm-up aside (they take minutes on llvmpipe).

A second table (:func:`rows_by_copy_size`, counted, not timed) says what impostors could
take off a frame: the visible copies by their size on screen (the pixels across each
copy's bounding ball) and the share of the rows drawn at each threshold that the copies
under a size hold.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from ..files import write_atomically
from ..geometry.rays.camera import box_corners
from ..geometry.rays.instances import PlacedMeshes, PlacedPlants
from ..geometry.skeletons.materials import material_height_maps
from ..gl.context import renderer_name
from ..gl.frame import frame_view
from ..gl.instanced import COPY_UNIFORM_BYTES, eye_copy_draws
from ..gl.raster import RasterRenderer, placed_buffer_bytes
from ..gl.raycast import Raycaster
from ..gl.records import RECORD_BYTES
from ..pipeline import frame_arguments, prepare_model, stage_model
from ..settings import RaycastSettings, ShadowSettings
from ..table1.quality import image_error
from .arguments import image_size

__all__ = ["measure", "markdown", "main", "RENDERERS", "COPY_SIZES", "rows_by_copy_size", "size_table"]

#: The renderers measured: label, relief, raster.
RENDERERS = (("RC", False, False), ("RC+R", True, False), ("GS", False, True), ("GS+R", True, True))


#: The on-screen sizes (pixels across a copy's bounding ball) of the impostor table.
COPY_SIZES = (50, 100, 200, 300, 400, 600)


def rows_by_copy_size(placed: PlacedPlants, camera, ground, thresholds, limits=COPY_SIZES) -> dict:
    """What impostors could take off a frame of ``placed`` seen by ``camera``: the eye's
    draws at each threshold (pixels; :func:`plantgen.gl.instanced.eye_copy_draws`, as the
    ray caster makes them), each visible copy's size on screen (the pixels its bounding
    ball spans at the image's centre, 2·asin(r/d) times the focal length) and, per size
    in ``limits``, the copies under it and the rows they draw. Returns {"copies": visible
    copies, "smallest": the smallest size, "rows": {threshold: rows drawn}, "under":
    [(limit, copies under it, {threshold: rows they draw})]}."""
    view = frame_view(camera, [box_corners(placed.box)] + ([] if ground is None else [ground.quad()]))
    focal = camera.height / (2.0 * np.tan(np.radians(camera.fov_y) / 2))
    rows = {}
    for px in thresholds:
        draws = eye_copy_draws(placed, view, px)
        per_copy = []
        for plant, d in zip(placed.plants, draws, strict=True):
            centres, radii = plant.copy_balls()
            dist = np.linalg.norm(centres[d.copies] - view.eye, axis=1)
            size = 2.0 * np.arcsin(np.minimum(radii[d.copies] / np.maximum(dist, 1e-12), 1.0)) * focal
            per_copy.append(np.stack([size, d.counts], axis=1))
        rows[px] = np.concatenate(per_copy) if per_copy else np.zeros((0, 2))
    full = rows[thresholds[0]]
    under = [(limit, int(np.sum(full[:, 0] < limit)),
              {px: int(t[t[:, 0] < limit, 1].sum()) for px, t in rows.items()}) for limit in limits]
    return {"copies": len(full), "smallest": float(full[:, 0].min()) if len(full) else float("nan"),
            "rows": {px: int(t[:, 1].sum()) for px, t in rows.items()}, "under": under}


def _frames(draw, frames: int) -> tuple[list, float, object]:
    """A warm-up draw (it draws the shadow map) and ``frames`` timed ones: (frame ms,
    the warm-up's light ms, the last result)."""
    first = draw()
    results = [draw() for _ in range(frames)]
    return [r.frame_ms for r in results] or [first.frame_ms], first.stats.shadow_ms, (results or [first])[-1]


def measure(scene: str = "forest", size=(1024, 768), thresholds=(0.0, 1.0, 2.0, 4.0), frames: int = 2,
            gs_level: int = 0, say=print, renderers=("RC", "RC+R", "GS", "GS+R")) -> dict:
    """Each of ``renderers`` at every threshold (the first must be 0: full detail; see the
    module's docstring); returns the rows and the scene's figures."""
    t0 = time.perf_counter()
    model = prepare_model(scene)
    placed = model.placed
    if placed is None:
        raise SystemExit(f"{scene}: not a scene with the lod effect")
    prepare_s = time.perf_counter() - t0
    staging = stage_model(model.grown, placed, *size)
    # one ray a pixel: the error is the depth's, and coverage anti-aliasing's thin pieces write no distance
    args = {**frame_arguments(placed, staging, ShadowSettings()), "aa": "none"}
    raster_args = {k: v for k, v in args.items() if k not in ("material_names", "leaves")}
    maps, _ = material_height_maps(placed.material_names)
    caster, raster, rows = Raycaster(), RasterRenderer(), []
    meshes = {}
    for label, relief, is_raster in (r for r in RENDERERS if r[0] in renderers):
        full = None
        for px in thresholds:
            if is_raster:
                mesh = meshes.setdefault(relief, PlacedMeshes.tessellate(placed, gs_level, relief))
                n = 0 if px == 0 else frames

                def draw(mesh=mesh, px=px):
                    return raster.render_placed(mesh, lod_pixels=px, **raster_args)
                gpu = placed_buffer_bytes(mesh)
            else:
                n = frames

                def draw(relief=relief, px=px):
                    return caster.render(placed, settings=RaycastSettings(relief=relief), lod_pixels=px, **args)
                gpu = placed.unique_rows * RECORD_BYTES
            times, light_ms, result = _frames(draw, n)
            full = result if px == 0 else full
            parts = image_error(result.distance, full.distance, staging.camera, staging.light_dir) \
                if full is not None else None
            error = parts.total if parts is not None else float("nan")
            row = {"renderer": label, "lod_pixels": px, "ms": statistics.median(times), "light_ms": light_ms,
                   "timed": len(times) if n else 0, "drawn": _drawn(result), "error": error,
                   "dssim": parts.dssim if parts is not None else float("nan"),
                   "silhouette": parts.silhouette if parts is not None else float("nan"),
                   "gpu_bytes": gpu + maps.nbytes * (5 if relief else 1)}
            rows.append(row)
            say(_line(row))
    by_size = rows_by_copy_size(placed, staging.camera, staging.ground, thresholds)
    return {"rows": rows, "by_size": by_size, "renderer": renderer_name(), "size": size, "scene": scene,
            "prepare_s": prepare_s,
            "copies": placed.copies, "plants": len(placed.plants), "unique": placed.unique_rows,
            "placed": len(placed), "gs_level": gs_level,
            "gs_unique_triangles": sum(len(m.faces) for m in meshes.get(False, PlacedMeshes(placed, (), 0)).meshes)}


def _drawn(result) -> str:
    stats = result.stats
    return f"{stats.segments:,} rows" if hasattr(stats, "segments") else f"{stats.triangles:,} triangles"


def _line(row: dict) -> str:
    return (f"{row['renderer']:5} lod {row['lod_pixels']:>4g} px: {row['ms']:9.1f} ms (light {row['light_ms']:8.1f} ms)"
            f", {row['drawn']}, error {row['error']:.4f}")


def markdown(result: dict) -> str:
    """The table, its heading (scene, GL renderer, size) and the memory lines."""
    w, h = result["size"]
    unique, placed = result["unique"], result["placed"]
    lines = [f"# Forest benchmark: `{result['scene']}`", "",
             f"GL renderer: {result['renderer']}; {w}x{h}; {result['copies']:,} copies of {result['plants']} "
             f"grown plants; {placed:,} segments placed, {unique:,} distinct (grown, skinned once: "
             f"{result['prepare_s']:.1f} s to grow and skin); GS level m = {result['gs_level']}.", "",
             f"Records on the GPU: {unique:,} x {RECORD_BYTES} B = {unique * RECORD_BYTES / 2**20:.1f} MiB "
             f"(merged, every placed segment: {placed * RECORD_BYTES / 2**20:.1f} MiB); per copy 0 B stored, "
             f"{COPY_UNIFORM_BYTES} B of uniforms per draw.", "",
             "| renderer | LOD (px) | frame ms (median, map kept) | light pass ms | timed | drawn | error vs full "
             "| of it: 1 - SSIM, silhouette | GPU bytes (plants + maps) |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    lines += [f"| {r['renderer']} | {r['lod_pixels']:g} | {r['ms']:.0f} | {r['light_ms']:.0f} | "
              f"{r['timed'] or 'once'} | {r['drawn']} | {r['error']:.4f} | "
              f"{r['dssim']:.4f}, {r['silhouette']:.4f} | "
              f"{r['gpu_bytes'] / 2**20:.1f} MiB |"
              for r in result["rows"]]
    lines += ["", *size_table(result["by_size"])]
    return "\n".join(lines) + "\n"


def size_table(by_size: dict) -> list[str]:
    """The lines of the impostor table (:func:`rows_by_copy_size`)."""
    thresholds = list(by_size["rows"])
    lines = [f"What impostors could take: the {by_size['copies']:,} visible copies by the pixels across their bounding "
             f"balls (the smallest {by_size['smallest']:.0f} px), and the share of each threshold's drawn rows that "
             "the copies under a size draw.", "",
             "| copies spanning under | copies | " + " | ".join(f"rows at {px:g} px" for px in thresholds) + " |",
             "| --- | --- | " + " | ".join("---" for _ in thresholds) + " |"]
    for limit, copies, rows in by_size["under"]:
        cells = [f"{rows[px]:,} ({rows[px] / max(by_size['rows'][px], 1):.1%})" for px in thresholds]
        lines.append(f"| {limit} px | {copies:,} | " + " | ".join(cells) + " |")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plantgen.benchmarks.forest", description=__doc__.split("\n")[0])
    parser.add_argument("--scene", default="forest")
    parser.add_argument("--size", type=image_size, default=(1024, 768))
    parser.add_argument("--lod", default="0,1,2,4,8", help="thresholds in pixels, 0 = full detail (first)")
    parser.add_argument("--frames", type=int, default=2)
    parser.add_argument("--gs-level", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None)
    a = parser.parse_args(argv)
    thresholds = sorted({float(x) for x in a.lod.split(",")})
    if not thresholds or thresholds[0] != 0:
        thresholds = [0.0, *thresholds]
    result = measure(a.scene, a.size, thresholds, a.frames, a.gs_level)
    text = markdown(result)
    if a.out is not None:
        write_atomically(a.out, lambda p: Path(p).write_text(text))
    sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
