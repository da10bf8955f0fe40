"""Which method draws a frame faster, the ray caster (RC) or the ray tracer (RT), and
whether ``--method auto`` picks it: single plants and cuts of the forest at full detail,
at two sizes, both methods timed in one run.

Run: ``python -m plantgen.benchmarks.method_choice [--models saguaro,pine,elm,broadleaf,stand]
[--copies 13,40,130] [--sizes 512x384,1024x768] [--frames 3] [--out method_choice.md]``.

For each input and size: the rows placed (what RC rasterises a pyramid for), the rows a
pixel, the median frame (after a warm-up: the programs compiled, RT's BVH built) of RC
and RT with the input's own effects, and the method :func:`plantgen.gl.rt.choose_method`
chooses. A single plant's rows are all distinct (RT builds its BVH over all of them); the
forest's cuts (:func:`plantgen.benchmarks.scaling.tile_placed`, the scene's camera, full
detail, relief and shadows off as the scaling bench draws them) place each distinct row
many times. *faster frame* compares the frames alone (what a viewer or --time-frames
sees after the first), *faster still* adds RT's BVH build, which a single still pays.
"""

from __future__ import annotations

import argparse
import os
import time
from datetime import UTC, datetime
from pathlib import Path

from ..gl.context import renderer_name
from ..gl.raycast import Raycaster
from ..gl.rt import RT_PLACED_PER_DISTINCT, RT_ROWS_PER_PIXEL, RayTracer, choose_method
from ..pipeline import frame_arguments, prepare_model, render_model, stage_model
from ..settings import RaycastSettings
from .arguments import image_size, report
from .scaling import median_frame, tile_placed
from .scan import machine

__all__ = ["measure", "markdown", "main", "summary"]


def _plant_row(name: str, size, frames: int) -> dict:
    ms = {}
    for method in ("rc", "rt"):
        report_ = render_model(name, timed_frames=frames, size=size, method=method)
        ms[method] = report_.frame_ms
    rows = report_.rows
    model = prepare_model(name)
    frusta = model.frusta_at(0)
    staging = stage_model(model.grown, frusta, *size)
    t0 = time.perf_counter()
    RayTracer().gpu_bvh(frusta, staging.leaves, staging.camera.eye)      # what RT's first frame builds
    return {"input": name, "size": size, "placed": rows, "distinct": rows, "rc_ms": ms["rc"], "rt_ms": ms["rt"],
            "build_ms": 1e3 * (time.perf_counter() - t0)}


def _forest_rows(copies, sizes, frames: int, scene: str = "forest") -> list[dict]:
    if not copies:
        return []
    model = prepare_model(scene)
    base = model.placed
    settings = RaycastSettings(relief=False)
    out = []
    for size in sizes:
        staging = stage_model(model.grown, base, *size)
        for n in copies:
            placed = tile_placed(base, n)
            # one ray a pixel, RC and RT alike (coverage anti-aliasing casts only RC's thin rows at a floor)
            args = {**frame_arguments(placed, staging, None), "leaves": None, "aa": "none"}
            rt, rc = RayTracer(), Raycaster()
            t0 = time.perf_counter()
            rt.render(placed, settings=settings, **args)          # builds and uploads the BVH
            build_ms = 1e3 * (time.perf_counter() - t0)

            def timed(r, p=placed, a=args):
                return median_frame(lambda: r.render(p, settings=settings, **a), frames)[0]

            out.append({"input": f"{scene} cut to {placed.copies:,} copies", "size": size, "placed": len(placed),
                        "distinct": placed.unique_rows, "rt_ms": timed(rt), "rc_ms": timed(rc),
                        "build_ms": build_ms})
    return out


def measure(models=("saguaro", "pine", "elm", "broadleaf", "stand"), copies=(13, 40, 130),
            sizes=((512, 384), (1024, 768)), frames: int = 3, say=print) -> dict:
    """The table's rows (module docstring)."""
    rows = []
    for size in sizes:
        for name in models:
            rows.append(_plant_row(name, size, frames))
            say(_line(rows[-1]))
    for row in _forest_rows(copies, sizes, frames):
        rows.append(row)
        say(_line(row))
    for row in rows:
        w, h = row["size"]
        row["auto"] = choose_method("auto", placed_rows=row["placed"], distinct_rows=row["distinct"], pixels=w * h)
        row["auto_frames"] = choose_method("auto", placed_rows=row["placed"], distinct_rows=row["distinct"],
                                           pixels=w * h, draws=1 + frames)
    return {"rows": rows, "frames": frames, "renderer": renderer_name(), "machine": machine(),
            "date": f"{datetime.now(UTC):%Y-%m-%d %H:%M} UTC", "load": os.getloadavg()[0]}


def _line(row: dict) -> str:
    w, h = row["size"]
    return (f"{row['input']} {w}x{h}: {row['placed']:,} rows ({row['placed'] / (w * h):.3f} a pixel), "
            f"RC {row['rc_ms']:,.0f} ms, RT {row['rt_ms']:,.0f} ms")


def _times(x: float) -> str:
    """A ratio as the summary prints it: one decimal under 10, none above."""
    return f"{x:.1f}" if x < 9.95 else f"{x:.0f}"


def summary(rows: list[dict]) -> list[str]:
    """The table the docs quote, between snippet section markers (``--8<--
    "llvmpipe/method_choice.md:summary"``): per kind of input (single plants, instanced
    scenes) and size, which method draws the faster frame on how many inputs and by how
    much (the slower frame over the faster, least to most), from ``rows``' ``rc_ms`` and
    ``rt_ms``."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        kind = "instanced scenes" if r["placed"] > r["distinct"] else "single plants"
        groups.setdefault((kind, tuple(r["size"])), []).append(r)
    lines = ["<!-- --8<-- [start:summary] -->", "| inputs | size | faster frame | times faster |",
             "| --- | --- | --- | --- |"]
    for (kind, (w, h)), group in sorted(groups.items(), key=lambda item: (item[0][0] != "single plants", item[0][1])):
        for method, key, other in (("RC", "rc_ms", "rt_ms"), ("RT", "rt_ms", "rc_ms")):
            won = [r[other] / r[key] for r in group if r[key] < r[other]]
            if won:
                span = " to ".join(dict.fromkeys(_times(x) for x in (min(won), max(won))))
                lines.append(f"| {kind} | {w}x{h} | {method} on {len(won)} of {len(group)} | {span} |")
    return lines + ["<!-- --8<-- [end:summary] -->"]


def markdown(result: dict) -> str:
    lines = ["### RC or RT: which is faster, and what `--method auto` picks", "",
             "| | |", "| --- | --- |",
             f"| GL renderer | {result['renderer']} |", f"| machine | {result['machine']} |",
             f"| date | {result['date']} |",
             f"| frames | a warm-up and {result['frames']} timed, the median; single plants with their own effects, "
             "the forest's cuts at full detail without relief, shadows or leaves |",
             f"| auto's rule | RT where placed rows >= {RT_ROWS_PER_PIXEL:g} a pixel and >= "
             f"{RT_PLACED_PER_DISTINCT:g}x the distinct rows, at full detail; else RC |", "",
             "| input | size | rows placed | distinct | rows a pixel | RC ms | RT ms | RC / RT | RT build ms | "
             "auto (a still) | faster still | auto (a warm-up and the timed frames) | faster frame |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- | --- | --- | --- |"]
    frame_right = still_right = 0
    for r in result["rows"]:
        w, h = r["size"]
        frame = "rt" if r["rt_ms"] < r["rc_ms"] else "rc"
        still = "rt" if r["rt_ms"] + r["build_ms"] < r["rc_ms"] else "rc"
        frame_right += r["auto_frames"] == frame
        still_right += r["auto"] == still
        lines.append(f"| {r['input']} | {w}x{h} | {r['placed']:,} | {r['distinct']:,} | {r['placed'] / (w * h):.3f} | "
                     f"{r['rc_ms']:,.0f} | {r['rt_ms']:,.0f} | {r['rc_ms'] / r['rt_ms']:.2f} | {r['build_ms']:,.0f} | "
                     f"{r['auto'].upper()} | {still.upper()} | {r['auto_frames'].upper()} | {frame.upper()} |")
    n = len(result["rows"])
    lines += ["", "Which is faster, by kind of input:", "", *summary(result["rows"])]
    lines += ["", f"Auto chose the method of the faster still (one frame, RT's BVH build included) on {still_right} "
              f"of {n} inputs, and, told of the warm-up and the {result['frames']} timed frames, the method of the "
              f"faster frame (a frame after the first) on {frame_right} of {n}. RT build "
              "ms: the BVH built and uploaded before RT's first frame (a plant's over all its rows, a scene's over its "
              f"distinct plants and copies). Load average after the run: {result['load']:.2f}.", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plantgen.benchmarks.method_choice",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--models", default="saguaro,pine,elm,broadleaf,stand", help="grammars, comma-separated")
    parser.add_argument("--copies", default="13,40,130", help="the forest's cuts, copies, comma-separated")
    parser.add_argument("--sizes", default="512x384,1024x768", help="frame sizes, comma-separated")
    parser.add_argument("--frames", type=int, default=3, help="timed frames per method (median)")
    parser.add_argument("--out", type=Path)
    a = parser.parse_args(argv)
    models = [m for m in a.models.split(",") if m.strip()]
    copies = [int(x) for x in a.copies.split(",") if x.strip()]
    sizes = [image_size(s) for s in a.sizes.split(",") if s.strip()]
    return report(markdown(measure(models, copies, sizes, max(a.frames, 1))), a.out)


if __name__ == "__main__":
    raise SystemExit(main())
