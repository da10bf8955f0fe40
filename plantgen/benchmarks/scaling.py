"""Forests of a thousand to a hundred thousand plants: how frame time, build time and GPU
memory grow with the copies, for RT (ray traced through the two-level BVH, every row)
beside RC at a level of detail (a pyramid per drawn row).

Run: ``python -m plantgen.benchmarks.scaling [--scene forest] [--copies 1000,10000,100000]
[--size 512x384] [--frames 3] [--lod 2] [--rc-max 100000] [--view scene|overview]
[--images DIR] [--out scaling.md]``.

Every forest is made of the same distinct plants as ``--scene`` (grown and skinned once):
its copies' placements are tiled (:func:`tile_placed`), the scene's whole grid shifted by
its extent across the view and away from the camera, the nearest tiles first, until there
are about N copies (each plant's grid cut in the same proportion: the copies counted are
the table's). The scene's light is kept, and its camera (``--view scene``: at eye height
inside the forest, so the tiles added lie mostly hidden behind the first) or each forest
framed whole from above (``--view overview``: every copy in view); the ground is widened
under every tile. Leaves (world polygons, not instanced) are left out, and so are relief and shadows:
the table measures the rows' cost as the copies grow.

For each N: *scene BVH s* builds the two levels (a BVH per distinct plant and the top level
over the copies, :func:`~plantgen.geometry.rays.bvh.build_scene_bvh`), *top level s* the top
level alone; *GPU MiB* is what the ray tracer uploads (nodes, primitives, records, copies);
*B/copy* what a copy adds to it: (bytes - the bytes of the same plants placed once each) /
(copies - plants); *of budget* the GPU bytes over the memory goal's budget, 1.2 times the
distinct plants' data (their row records, what RC uploads for them) plus 64 bytes a copy.
Frames: a warm-up (the driver compiles; RT builds and uploads its BVH) and ``--frames``
timed ones, their median. RC runs at ``--lod`` pixels up to ``--rc-max`` copies. The
growth columns divide a frame time by the previous N's (the same run).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from ..geometry.rays.bvh import TOP_LEAF_SIZE, build_bvh, build_scene_bvh
from ..geometry.rays.camera import Camera
from ..geometry.rays.instances import PlacedPlants
from ..gl.context import renderer_name
from ..gl.raycast import Raycaster
from ..gl.records import RECORD_BYTES
from ..gl.rt import RayTracer
from ..pipeline import frame_arguments, prepare_model, stage_model
from ..settings import RaycastSettings
from .arguments import image_size, report
from .scan import machine

__all__ = ["tile_placed", "median_frame", "measure", "markdown", "main", "VIEWS", "OVERVIEW", "BUDGET_DATA",
           "BUDGET_COPY"]

#: The cameras of ``--view``: the scene's own (at eye height inside the forest: the tiles
#: added lie behind the first, mostly hidden) or each forest framed whole from above.
VIEWS = ("scene", "overview")
#: The overview camera's direction (from the forest's centre towards the eye).
OVERVIEW = (0.35, 1.2, 1.0)
#: The memory goal: GPU bytes <= BUDGET_DATA x the distinct plants' row records + BUDGET_COPY a copy.
BUDGET_DATA, BUDGET_COPY = 1.2, 64


def tile_placed(placed: PlacedPlants, copies: int, toward=(0.0, 0.0, -1.0)) -> PlacedPlants:
    """``placed`` (a scene's plants and copies) with about ``copies`` copies of the same
    distinct plants: the scene's grid repeated as tiles of its extent, on both sides across x
    and stepping along ``toward`` (its z sign; away from the camera), the scene's own tile
    and then the nearest first; each
    plant keeps the share ``copies / placed.copies`` of its tiled copies (rounded up)."""
    lo, hi = placed.box
    step = hi - lo
    tiles = max(1, int(np.ceil(np.sqrt(copies / max(placed.copies, 1)))))
    across = [(-1) ** i * ((i + 1) // 2) for i in range(tiles)]      # 0, 1, -1, 2, -2, ...: the scene's own first
    grid = [(a * step[0], 0.0, j * step[2] * float(np.sign(toward[2]) or 1.0)) for a in across for j in range(tiles)]
    shifts = np.array(sorted(grid, key=lambda s: (abs(s[2]), abs(s[0]))), float)
    out = []
    for p in placed.plants:
        m = np.repeat(p.matrices[None], len(shifts), axis=0)
        m[..., :3, 3] += shifts[:, None]
        keep = int(np.ceil(len(p.matrices) * len(shifts) * copies / (placed.copies * len(shifts))))
        out.append(replace(p, matrices=m.reshape(-1, 4, 4)[:keep]))
    return PlacedPlants(tuple(out), placed.material_names)


def median_frame(draw, frames: int) -> tuple[float, object]:
    """A warm-up draw and ``frames`` timed ones: (their median frame ms, the last frame)."""
    results = [draw()]
    results += [draw() for _ in range(frames)]
    return statistics.median(r.frame_ms for r in results[1:] or results), results[-1]


def _write(folder: Path | None, name: str, frame) -> None:
    if folder is not None:
        from ..images import write_png
        folder.mkdir(parents=True, exist_ok=True)
        write_png(folder / name, frame.color)


def _timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def measure(scene: str = "forest", counts=(1_000, 10_000, 100_000), size=(512, 384), frames: int = 3,
            lod_pixels: float = 2.0, rc_max: int = 100_000, say=print, images: Path | None = None,
            view: str = "scene") -> dict:
    """The table's rows (module docstring), one per N in ``counts``; with ``images``, each
    frame is written there (PNG). ``view``: "scene" (the scene's camera, every N) or
    "overview" (each forest framed whole from above, :data:`OVERVIEW`)."""
    if view not in VIEWS:
        raise SystemExit(f"--view: one of {', '.join(VIEWS)}, not {view!r}")
    model = prepare_model(scene)
    base = model.placed
    if base is None:
        raise SystemExit(f"{scene}: not a scene with the lod effect (its plants are not instanced)")
    staging = stage_model(model.grown, base, *size)
    once = PlacedPlants(tuple(replace(p, matrices=p.matrices[:1]) for p in base.plants), base.material_names)
    settings = RaycastSettings(relief=False)
    rt, rc = RayTracer(), Raycaster()

    def arguments(placed):
        # one ray a pixel, RC and RT alike (coverage anti-aliasing casts only RC's thin rows at a floor)
        args = {**frame_arguments(placed, staging, None), "leaves": None, "aa": "none"}
        if view == "overview":
            args["camera"] = Camera.auto(placed.box, *size, direction=OVERVIEW)
        if args["ground"] is not None:
            lo, hi = placed.box
            reach = float(np.abs(np.concatenate([lo, hi])[[0, 2, 3, 5]]).max())
            args["ground"] = replace(args["ground"], size=max(args["ground"].size, 2.0 * reach))
        return args

    gpu_once = rt.gpu_bvh(once, None, staging.camera.eye)
    base_bytes, base_parts = gpu_once.nbytes, dict(gpu_once.parts)
    data_bytes = base.unique_rows * RECORD_BYTES
    rows = []
    for n in counts:
        placed = tile_placed(base, n)
        scene_s, bvh = _timed(lambda p=placed: build_scene_bvh(p))
        top_s, _ = _timed(lambda b=bvh: build_bvh(b.copy_lo, b.copy_hi, leaf_size=TOP_LEAF_SIZE))
        args = arguments(placed)
        rt_ms, rt_frame = median_frame(lambda p=placed, a=args: rt.render(p, settings=settings, **a), frames)
        gpu_bytes = rt.gpu_bvh(placed, None, args["camera"].eye).nbytes
        row = {"n": n, "copies": placed.copies, "segments": len(placed), "scene_s": scene_s, "top_s": top_s,
               "rt_ms": rt_ms, "gpu_bytes": gpu_bytes,
               "copy_bytes": (gpu_bytes - base_bytes) / max(placed.copies - len(once.plants), 1),
               "of_budget": gpu_bytes / (BUDGET_DATA * data_bytes + BUDGET_COPY * placed.copies),
               "rc_ms": float("nan")}
        if n <= rc_max:                       # N as asked (the tiles may hold a few more)
            row["rc_ms"], rc_frame = median_frame(lambda p=placed, a=args: rc.render(p, settings=settings,
                                                                                lod_pixels=lod_pixels, **a), frames)
            _write(images, f"rc_{placed.copies}_{view}.png", rc_frame)
        _write(images, f"rt_{placed.copies}_{view}.png", rt_frame)
        rows.append(row)
        say(f"N = {placed.copies:,}: RT {rt_ms:,.0f} ms, RC {row['rc_ms']:,.0f} ms, scene BVH {scene_s:.2f} s, "
            f"top level {top_s:.3f} s, GPU {gpu_bytes / 2**20:,.1f} MiB ({row['copy_bytes']:.1f} B/copy)")
    return {"scene": scene, "view": view, "size": size, "frames": frames, "lod_pixels": lod_pixels, "rc_max": rc_max,
            "plants": len(base.plants), "unique_rows": base.unique_rows, "base_bytes": base_bytes,
            "base_parts": base_parts,
            "data_bytes": data_bytes, "rows": rows,
            "renderer": renderer_name(), "machine": machine(), "date": f"{datetime.now(UTC):%Y-%m-%d %H:%M} UTC"}


def _growth(rows, key) -> list[str]:
    out, prev = [], None
    for r in rows:
        v = r[key]
        ok = prev is not None and np.isfinite(v) and np.isfinite(prev[key])
        # per 10x copies: the ratio scaled to a tenfold step in copies (log-log slope)
        out.append(f"{(v / prev[key]) ** (1 / np.log10(r['copies'] / prev['copies'])):.2f}x" if ok else "-")
        prev = r
    return out


_VIEW_TEXT = {"scene": "the scene's camera at eye height inside the forest, for every N (the tiles added lie "
                       "behind the scene's own, mostly hidden by it)",
              "overview": f"each forest framed whole from above (direction {OVERVIEW}): every copy in view"}


def markdown(result: dict) -> str:
    w, h = result["size"]
    rows = result["rows"]
    parts = ", ".join(f"{name} {b / 2**20:,.2f} MiB" if b >= 2**16 else f"{name} {b:,} B"
                      for name, b in result["base_parts"].items())
    lines = [f"### `{result['scene']}`'s plants from {rows[0]['copies']:,} to {rows[-1]['copies']:,} copies, "
             f"{result['view']} view",
             "", "| | |", "| --- | --- |",
             f"| GL renderer | {result['renderer']} |", f"| machine | {result['machine']} |",
             f"| date | {result['date']} |", f"| view | {_VIEW_TEXT[result['view']]} |",
             f"| frames | {w}x{h}, relief, shadows and leaves off; a warm-up and {result['frames']} timed, the median; "
             f"RT every row, RC at {result['lod_pixels']:g} px detail (up to {result['rc_max']:,} copies) |",
             f"| distinct plants | {result['plants']} grown plants, {result['unique_rows']:,} rows, their row records "
             f"{result['data_bytes'] / 2**20:,.2f} MiB; their BVH on the GPU (each placed once): "
             f"{result['base_bytes'] / 2**20:,.2f} MiB, {result['base_bytes'] / result['data_bytes']:.2f}x the "
             f"records ({parts}) |", "",
             "| copies | segments placed | RT ms | RT growth per 10x | RC ms | RC growth per 10x | scene BVH s | "
             "top level s | GPU MiB (RT) | B/copy (GPU) | of budget |",
             "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    rt_growth, rc_growth = _growth(rows, "rt_ms"), _growth(rows, "rc_ms")
    for r, g1, g2 in zip(rows, rt_growth, rc_growth, strict=True):
        rc = f"{r['rc_ms']:,.0f}" if np.isfinite(r["rc_ms"]) else "not run"
        lines.append(f"| {r['copies']:,} | {r['segments']:,} | {r['rt_ms']:,.0f} | {g1} | {rc} | {g2} | "
                     f"{r['scene_s']:.2f} | {r['top_s']:.3f} | {r['gpu_bytes'] / 2**20:,.2f} | "
                     f"{r['copy_bytes']:.1f} | {r['of_budget']:.2f} |")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    lines += ["", "Growth per 10x: a frame time over the previous row's, raised to 1 / log10 of the copies' ratio "
              "(a tenfold step). B/copy: (GPU bytes - the distinct plants' bytes) / (copies - plants): the "
              "copy's map and plant index, its share of the top level's nodes. Of budget: GPU bytes / "
              f"({BUDGET_DATA:g} x the plants' row records + {BUDGET_COPY} B a copy), the memory goal met at <= 1. "
              f"Load average after the run: {load:.2f}.", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plantgen.benchmarks.scaling",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="forest", help="a scene with the lod effect (default forest)")
    parser.add_argument("--copies", default="1000,10000,100000", help="the forests' copies, comma-separated")
    parser.add_argument("--size", type=image_size, default=(512, 384))
    parser.add_argument("--frames", type=int, default=3, help="timed frames per method and N (median)")
    parser.add_argument("--lod", type=float, default=2.0, help="RC's detail in pixels (default 2)")
    parser.add_argument("--rc-max", type=int, default=100_000, help="RC only up to this many copies")
    parser.add_argument("--view", default="scene", choices=VIEWS,
                        help="scene: the scene's camera for every N; overview: each forest framed whole from above")
    parser.add_argument("--images", type=Path, help="folder to write every frame into (PNG)")
    parser.add_argument("--out", type=Path)
    a = parser.parse_args(argv)
    counts = [int(x) for x in a.copies.split(",") if x.strip()]
    result = measure(a.scene, counts, a.size, a.frames, a.lod, a.rc_max, images=a.images, view=a.view)
    return report(markdown(result), a.out)


if __name__ == "__main__":
    raise SystemExit(main())
