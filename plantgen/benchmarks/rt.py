"""Rays through the BVH against the ray caster: the forest's frame by RT+R (ray traced,
shadow rays) beside RC+R (a pyramid per row, the shadow map), both at full detail, in
one run; and a scan's beams per second, the float64 CPU reference beside the GPU's float32
search with its ranges solved again in float64.

Run: ``python -m plantgen.benchmarks.rt [--scene forest] [--size 1024x768] [--frames 1]
[--scan-model pine] [--scan-step 0.2] [--out rt.md]``; ``--work`` instead measures the
traversal alone (below).

Frames: each renderer draws once to warm up (the driver compiles its programs; RC+R's
warm-up draws the shadow map, its milliseconds are the *light* column) and ``--frames``
more times (RC+R's map kept); the table gives their median. RT+R builds its BVH once
(*build*, CPU) and uploads it (*upload*); *GPU MiB* is what each holds for the plants
(RC: the distinct plants' records; RT: the BVH, records, copies). The error columns
compare RT+R's frame with RC+R's: pixels covered by one of them only, and the share of the
pixels both cover whose distances agree to float32 rounding (4e-6 relative) or within
twice the relief march's final bracket (its asked accuracy); shading
differs where shadows do (rays against the map). The scan table: beams per second of
each path, points, and beam for beam the share of the reference's primitives the GPU
path finds (its ranges are then the reference's, solved in float64). The GL renderer and
the machine (with its load: this machine is shared) are printed with the tables.

``--work``: the work a ray costs, RT alone on ``--scene``: the eye's rays (every pixel,
rows and leaves, closest hit; through ``shaders/trace.glsl``) and the shadow rays of those
that hit (any hit), each with the nodes a ray walks and the primitives it tests (the
traversal's ``BVH_COUNT``: also the rows among the primitives, those that passed the
rows' cheap reject and those whose test hit), wall and CPU milliseconds (the process's CPU
time, llvmpipe's threads included: what another job's load changes least), and RT's frames
without relief and shadows, RT+R without shadows and RT+R with shadow rays. Where the time
goes: the eye's rays again with the primitive tests skipped (``BVH_NO_PRIMS``: the node
steps alone; nothing is hit, so the rays walk more nodes) and with every primitive tested
twice (``BVH_PRIMS_TWICE``: the difference is what the tests cost); the frames' differences
give the relief march and the shadow rays. ``--ab`` runs every row without and with the
rows' cheap reject (``BVH_ROW_BOUND``), interleaved. Compare designs by running it on each.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from ..geometry.rays.scan import ScanSettings, beam_returns, scan_target, scene_target
from ..gl import trace
from ..gl.context import renderer_name
from ..gl.raycast import Raycaster
from ..gl.records import RECORD_BYTES
from ..gl.rt import RayTracer
from ..gl.shaders import build_compute, set_uniforms
from ..gl.trace import trace_rays, trace_target
from ..pipeline import frame_arguments, grow_file, model_leaves, prepare_model, skin_model, stage_model
from ..settings import RaycastSettings, ShadowSettings
from .arguments import image_size, report
from .scan import machine

__all__ = ["measure_frames", "measure_scan", "measure_work", "work_markdown", "markdown", "main"]


def _timed(draw, frames: int):
    """A warm-up draw and ``frames`` timed ones: (median ms, warm-up result, last result)."""
    first = draw()
    results = [draw() for _ in range(frames)] or [first]
    return statistics.median(r.frame_ms for r in results), first, results[-1]


def measure_frames(scene: str = "forest", size=(1024, 768), frames: int = 1, say=print) -> dict:
    """RC+R and RT+R with shadows at full detail on ``scene``, in this order, in one run."""
    model = prepare_model(scene)
    placed = model.placed if model.placed is not None else model.frusta_at(0)
    staging = stage_model(model.grown, placed, *size)
    # one ray a pixel, RC and RT alike (coverage anti-aliasing casts only RC's thin rows at a floor)
    args = {**frame_arguments(placed, staging, ShadowSettings()), "aa": "none"}
    settings = RaycastSettings(relief=True)
    rows = {}
    rc = Raycaster()
    ms, first, rc_frame = _timed(lambda: rc.render(placed, settings=settings, **args), frames)
    rows["RC+R"] = {"ms": ms, "light_ms": first.stats.shadow_ms, "build_ms": 0.0, "upload_ms": 0.0,
                    "gpu_bytes": getattr(placed, "unique_rows", len(placed)) * RECORD_BYTES}
    say(f"RC+R: {ms:.0f} ms (light {first.stats.shadow_ms:.0f} ms)")
    rt = RayTracer()
    t0 = time.perf_counter()
    rt.gpu_bvh(placed, args["leaves"], staging.camera.eye)
    build_ms, upload_ms = rt.last_build_ms, rt.last_upload_ms
    ready_ms = (time.perf_counter() - t0) * 1e3
    ms, _, rt_frame = _timed(lambda: rt.render(placed, settings=settings, **args), frames)
    rows["RT+R"] = {"ms": ms, "light_ms": 0.0, "build_ms": build_ms, "upload_ms": upload_ms,
                    "gpu_bytes": rt.gpu_bvh(placed, args["leaves"], staging.camera.eye).nbytes}
    say(f"RT+R: {ms:.0f} ms (BVH build {build_ms:.0f} ms, upload {upload_ms:.0f} ms, ready {ready_ms:.0f} ms)")
    a, b = np.isfinite(rc_frame.distance), np.isfinite(rt_frame.distance)
    both = a & b
    close = np.isclose(rt_frame.distance[both], rc_frame.distance[both], rtol=4e-6, atol=0)
    # the relief march's own accuracy: its bisection stops within march_precision pixel
    # footprints (the footprint at distance s is 2 tan(fov_y / 2) / height * s)
    cam = staging.camera
    footprint = 2.0 * np.tan(np.radians(cam.fov_y) / 2) / cam.height * rc_frame.distance[both]
    bracket = np.abs(rt_frame.distance[both] - rc_frame.distance[both]) <= 2 * settings.march_precision * footprint
    return {"scene": scene, "size": size, "frames": frames, "rows": rows, "renderer": renderer_name(),
            "segments": len(placed), "copies": getattr(placed, "copies", 1),
            "covered": int(a.sum()), "cover_mismatch": int((a != b).sum()), "depth_agree": float(close.mean()),
            "depth_bracket": float((close | bracket).mean()), "march_precision": settings.march_precision,
            "images": (rc_frame.color, rt_frame.color)}


def _dispatch(gpu, origins, directions, any_hit: bool, t_min: float, defines=None) -> np.ndarray:
    """One dispatch of ``shaders/trace.glsl`` over the rays with extra ``defines`` (the
    bench's variants): its (n, 4) int32 words (with BVH_COUNT the traversal's counts)."""
    ctx = gpu.ctx
    program = build_compute(ctx, "trace.glsl", {**gpu.defines(), **(defines or {})})
    n = len(origins)
    words = np.zeros((n, 8), np.float32)
    words[:, 0:3], words[:, 3] = origins - gpu.origin, t_min
    words[:, 4:7], words[:, 7] = directions, 3.0e38
    rays, hits = ctx.buffer(words.tobytes()), ctx.buffer(reserve=16 * n)
    try:
        gpu.bind()
        rays.bind_to_storage_buffer(0)
        hits.bind_to_storage_buffer(1)
        set_uniforms(program, any_hit=int(any_hit), ray_count=n)
        program.run(group_x=(n + 63) // 64)
        return np.frombuffer(hits.read(), np.int32).reshape(n, 4)
    finally:
        rays.release()
        hits.release()


def _work_counts(gpu, origins, directions, any_hit: bool, t_min: float, defines=None) -> dict:
    """Mean nodes walked, primitives tested, rows tested, rows that passed the cheap reject
    and rows whose test hit, a ray (the traversal's BVH_COUNT variant)."""
    words = _dispatch(gpu, origins, directions, any_hit, t_min, {**(defines or {}), "BVH_COUNT": True})
    steps, rows = words[:, 3], words[:, 2]
    return {"nodes": float((steps & 0xFFFF).mean()), "prims": float((steps >> 16).mean()),
            "rows": float(words[:, 1].mean()), "passed": float((rows >> 16).mean()),
            "hits": float((rows & 0xFFFF).mean())}


def measure_work(scene: str = "forest", size=(512, 384), frames: int = 3, say=print, ab: bool = False) -> dict:
    """The traversal's work and time on ``scene`` (module docstring, ``--work``); with
    ``ab`` each row twice, without and with the rows' cheap reject (``BVH_ROW_BOUND``),
    interleaved run by run."""
    model = prepare_model(scene)
    placed = model.placed if model.placed is not None else model.frusta_at(0)
    staging = stage_model(model.grown, placed, *size)
    # one ray a pixel, RC and RT alike (coverage anti-aliasing casts only RC's thin rows at a floor)
    args = {**frame_arguments(placed, staging, ShadowSettings()), "aa": "none"}
    rt = RayTracer()
    camera = staging.camera
    saved, trace.ROW_BOUND = trace.ROW_BOUND, trace.ROW_BOUND or ab      # with --ab: the bounds uploaded
    try:
        gpu = rt.gpu_bvh(placed, args["leaves"], camera.eye)
    finally:
        trace.ROW_BOUND = saved
    o, d = (a.reshape(-1, 3) for a in camera.rays())
    t, prim, _, _ = trace_rays(gpu, o, d)
    hit = prim >= 0
    light = np.asarray(args["light_dir"], np.float64)
    so = o[hit] + t[hit, None] * d[hit]
    sd = np.broadcast_to(light / np.linalg.norm(light), so.shape)
    quiet = {**args, "shadows": None}
    twice = {"BVH_PRIMS_TWICE": True}
    runs = {
        "eye rays": (len(o), lambda: trace_rays(gpu, o, d), (o, d, False, 0.0, None)),
        "eye rays, node steps only": (len(o), lambda: _dispatch(gpu, o, d, False, 0.0, {"BVH_NO_PRIMS": True}),
                                      (o, d, False, 0.0, {"BVH_NO_PRIMS": True})),
        "eye rays, each primitive tested twice": (len(o), lambda: _dispatch(gpu, o, d, False, 0.0, twice),
                                                  (o, d, False, 0.0, twice)),
        "shadow rays": (len(so), lambda: trace_rays(gpu, so, sd, any_hit=True, t_min=1e-4), (so, sd, True, 1e-4, None)),
        "RT frame": (None, lambda: rt.render(placed, settings=RaycastSettings(relief=False), **quiet), None),
        "RT+R frame": (None, lambda: rt.render(placed, settings=RaycastSettings(relief=True), **quiet), None),
        "RT+R frame, shadow rays": (None, lambda: rt.render(placed, settings=RaycastSettings(relief=True), **args),
                                    None),
    }
    variants = {"no reject": False, "reject": True} if ab else {"": None}
    times = {(v, name): ([], []) for v in variants for name in runs}
    for rep in range(frames + 1):            # the first: a warm-up (programs compiled)
        for name, (_, run, _) in runs.items():
            for v, on in variants.items():
                gpu.row_bound = on
                c, t0 = time.process_time(), time.perf_counter()
                run()
                if rep:
                    times[v, name][0].append(time.perf_counter() - t0)
                    times[v, name][1].append(time.process_time() - c)
    rows = {}
    for (v, name), (wall, cpu) in times.items():
        rays, _, count = runs[name]
        gpu.row_bound = variants[v]
        work = _work_counts(gpu, *count) if count is not None else None
        label = f"{name} ({v})" if v else name
        rows[label] = {"rays": rays, "wall": 1e3 * statistics.median(wall), "cpu": 1e3 * statistics.median(cpu),
                       "work": work}
        say(f"{label}: {rows[label]['wall']:.0f} ms ({rows[label]['cpu']:.0f} ms CPU)")
    gpu.row_bound = None
    return {"scene": scene, "size": size, "frames": frames, "rows": rows, "renderer": renderer_name(),
            "leaf_size": rt.leaf_size, "gpu_bytes": gpu.nbytes, "load": os.getloadavg()}


def work_markdown(work: dict) -> str:
    w, h = work["size"]
    lines = [f"# The traversal's work: {work['scene']} at {w}x{h} ({datetime.now(UTC):%Y-%m-%d %H:%M} UTC)", "",
             f"GL renderer: {work['renderer']}  ", f"Machine: {machine()} (shared by other jobs: under load)  ",
             "Load average at the end: " + ", ".join(f"{x:.2f}" for x in work["load"]) + "  ",
             f"BVH leaves of at most {work['leaf_size']} primitives, {work['gpu_bytes'] / 2**20:.1f} MiB on the GPU; "
             f"medians of {work['frames']} runs", "",
             "| what | rays | ms | CPU ms | nodes a ray | primitives a ray | rows tested | rows past the reject "
             "| rows hit |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, r in work["rows"].items():
        rays = f"{r['rays']:,}" if r["rays"] is not None else ""
        keys = ("nodes", "prims", "rows", "passed", "hits")
        counts = [f"{r['work'][k]:.2f}" for k in keys] if r["work"] else [""] * len(keys)
        lines.append(f"| {name} | {rays} | {r['wall']:,.0f} | {r['cpu']:,.0f} | " + " | ".join(counts) + " |")
    return "\n".join(lines + [""])


def measure_scan(model: str = "pine", step: float = 0.2, positions=None, say=print) -> dict:
    """Beams per second of the float64 reference and of the GPU's float32 search (ranges
    solved again in float64) on ``model`` (four terrestrial scanners at ``step`` degrees,
    or scanners at ``positions`` 'x,y,z;...'; a scene in two levels), and beam for beam the
    primitives they agree on."""
    grown = grow_file(model)
    if grown.scene is not None:
        target = scene_target(grown.scene.plants())
    else:
        target = scan_target(grown.skeleton, model_leaves(grown), frusta=skin_model(grown))
    assert target.bvh is not None                         # built once, outside the timings
    trace_target(target, target.box()[:1], np.ones((1, 3)))       # the GPU's upload and compile
    out = {}
    for name, precision, finder in (("float64 (CPU)", "float64", None),
                                    ("float32 (GPU) + float64 range", "float32",
                                     lambda tg, o, d: trace_target(tg, o, d))):
        settings = ScanSettings(angular_step=step, precision=precision, positions=positions)
        t0 = time.perf_counter()
        returns = beam_returns(target, settings, finder=finder)
        seconds = time.perf_counter() - t0
        beams = sum(r.beams for r in returns)
        out[name] = {"s": seconds, "beams": beams, "points": sum(len(r.beam) for r in returns), "returns": returns}
        say(f"scan {name}: {beams / seconds:,.0f} beams/s")
    ref, gpu = (v["returns"] for v in out.values())
    same = total = 0
    for a, b in zip(ref, gpu, strict=True):
        _, i, j = np.intersect1d(a.beam, b.beam, return_indices=True)
        same += int((a.primitive[i] == b.primitive[j]).sum())
        total += max(len(a.beam), len(b.beam))
    return {"model": model, "step": step, "positions": positions, "paths": out, "same": same / max(total, 1)}


def markdown(frames: dict | None, scan: dict | None) -> str:
    lines = [f"# RT+R against RC+R, and the scan on the GPU ({datetime.now(UTC):%Y-%m-%d %H:%M} UTC)", "",
             f"GL renderer: {renderer_name()}  ", f"Machine: {machine()} (shared by other jobs: under load)", ""]
    if frames is not None:
        lines += _frame_lines(frames)
    if scan is not None:
        lines += _scan_lines(scan)
    return "\n".join(lines)


def _frame_lines(frames: dict) -> list:
    w, h = frames["size"]
    lines = [f"## {frames['scene']} at {w}x{h}, full detail, relief and shadows "
             f"({frames['segments']:,} segments placed, {frames['copies']:,} copies)", "",
             "| method | frame ms (median) | light ms | BVH build ms | upload ms | GPU MiB |",
             "|---|---:|---:|---:|---:|---:|"]
    for name, r in frames["rows"].items():
        lines.append(f"| {name} | {r['ms']:,.0f} | {r['light_ms']:,.0f} | {r['build_ms']:,.0f} | "
                     f"{r['upload_ms']:,.0f} | {r['gpu_bytes'] / 2**20:,.1f} |")
    rc, rt = frames["rows"]["RC+R"]["ms"], frames["rows"]["RT+R"]["ms"]
    return lines + ["", f"RT+R / RC+R: {rt / rc:.2f} (same run). RT+R against RC+R: {frames['cover_mismatch']:,} of "
                    f"{frames['covered']:,} covered pixels covered by one only; distances agree to 4e-6 on "
                    f"{100 * frames['depth_agree']:.2f} % of the pixels both cover, and within twice the relief "
                    f"march's bracket ({frames['march_precision']:g} pixel footprint: the accuracy it is asked for; "
                    f"RC+R turns each copy's rows into the world, RT+R the ray into the copy, so their samples round "
                    f"apart) on {100 * frames['depth_bracket']:.2f} %.", ""]


def _scan_lines(scan: dict) -> list:
    where = f"scanners at {scan['positions']}" if scan["positions"] else "four terrestrial scanners"
    lines = [f"## Scan: {scan['model']}, {where}, step {scan['step']:g}°", "",
             "| path | seconds | beams | beams/s | points |", "|---|---:|---:|---:|---:|"]
    for name, p in scan["paths"].items():
        lines.append(f"| {name} | {p['s']:.2f} | {p['beams']:,} | {p['beams'] / p['s']:,.0f} | {p['points']:,} |")
    return lines + ["", f"Beam for beam the GPU path hits the reference's primitive on {100 * scan['same']:.3f} % of "
                    "the beams either hits (and there its range is the reference's).", ""]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="forest")
    parser.add_argument("--size", type=image_size, default=(1024, 768))
    parser.add_argument("--frames", type=int, default=1)
    parser.add_argument("--scan-model", default="pine")
    parser.add_argument("--scan-step", type=float, default=0.2)
    parser.add_argument("--scanner-positions", default=None, help="'x,y,z;...' (default: four around the model)")
    parser.add_argument("--no-frames", action="store_true")
    parser.add_argument("--no-scan", action="store_true")
    parser.add_argument("--work", action="store_true", help="the traversal's work a ray and its time alone")
    parser.add_argument("--ab", action="store_true",
                        help="with --work: each row without and with the rows' cheap reject, interleaved")
    parser.add_argument("--images", type=Path, help="folder to write both frames into (PNG)")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    if args.work:
        return report(work_markdown(measure_work(args.scene, args.size, max(args.frames, 1), ab=args.ab)), args.out)
    frames = None if args.no_frames else measure_frames(args.scene, args.size, args.frames)
    if args.images is not None and frames is not None:
        from ..images import write_png
        args.images.mkdir(parents=True, exist_ok=True)
        for name, image in zip(("rc_r", "rt_r"), frames["images"], strict=True):
            write_png(args.images / f"{args.scene}_{name}.png", image)
    scan = None if args.no_scan else measure_scan(args.scan_model, args.scan_step, args.scanner_positions)
    return report(markdown(frames, scan), args.out)


if __name__ == "__main__":
    raise SystemExit(main())
