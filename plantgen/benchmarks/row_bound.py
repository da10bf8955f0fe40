"""The GPU traversal's cheap reject before a row's test (``BVH_ROW_BOUND``,
:func:`plantgen.gl.trace.row_bounds`), off and on, interleaved in one run: the forest's RT
frame (no relief, no shadows) and RT+R frame with shadow rays, the scan from inside the
forest (the GPU's float32 search with its ranges solved again in float64, beams a second),
and single plants' RT+R against RC+R (``plantgen render NAME --relief --time-frames N
--method rc|rt``, in this process).

Run: ``python -m plantgen.benchmarks.row_bound [--frames 3] [--plants saguaro,elm,pine]
[--out row_bound.md]``. Medians of ``--frames`` runs of each after a warm-up; the GL
renderer, the machine and its load average are printed with the table.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from datetime import UTC, datetime
from pathlib import Path

from ..geometry.rays.scan import ScanSettings, beam_returns, scene_target
from ..gl import trace
from ..gl.context import renderer_name
from ..gl.rt import RayTracer
from ..pipeline import frame_arguments, grow_file, prepare_model, render_model, stage_model
from ..settings import RaycastSettings, ShadowSettings
from .arguments import report
from .scan import machine

__all__ = ["measure", "markdown", "main"]

_VARIANTS = {"reject": True, "no reject": False}    # the first run of each uploads its bounds


def _frame_runs(say) -> dict:
    """The forest's frames: name -> a draw returning its frame ms."""
    model = prepare_model("forest")
    placed = model.placed
    runs = {}
    for name, size, relief, shadows in (("forest RT 512x384", (512, 384), False, False),
                                        ("forest RT+R, shadow rays, 1024x768", (1024, 768), True, True)):
        staging = stage_model(model.grown, placed, *size)
        args = {**frame_arguments(placed, staging, ShadowSettings()), "aa": "none"}   # one ray a pixel, as RT
        if not shadows:
            args = {**args, "shadows": None}
        rt = RayTracer()
        settings = RaycastSettings(relief=relief)
        runs[name] = (lambda rt=rt, s=settings, a=args: rt.render(placed, settings=s, **a).frame_ms)
    say("forest ready")
    return runs


def _scan_run(step: float, positions: str, say):
    target = scene_target(grow_file("forest").scene.plants())
    settings = ScanSettings(angular_step=step, precision="float32", positions=positions)
    trace.trace_target(target, target.box()[:1], [[1.0, 1.0, 1.0]])      # upload and compile

    def run():
        t0 = time.perf_counter()
        returns = beam_returns(target, settings, finder=trace.trace_target)
        return sum(r.beams for r in returns) / (time.perf_counter() - t0)
    say("scan ready")
    return run


def _render(name: str, method: str, frames: int) -> float:
    """``plantgen render NAME --relief --time-frames N --method M``'s median frame ms."""
    return render_model(name, relief=True, method=method, timed_frames=frames).frame_ms


def measure(frames: int = 3, plants=("saguaro", "elm", "pine"), scan_step: float = 0.5,
            positions: str = "2,1.5,10", say=print) -> dict:
    runs = _frame_runs(say)
    runs[f"forest scan {scan_step:g}° from {positions} (beams/s)"] = _scan_run(scan_step, positions, say)
    for plant in plants:
        runs[f"{plant} RT+R ({frames} frames' median)"] = (lambda p=plant: _render(p, "rt", frames))
    rc = {f"{p} RC+R ({frames} frames' median)": (lambda p=p: _render(p, "rc", frames)) for p in plants}
    got = {(v, name): [] for v in _VARIANTS for name in runs}
    got.update({("", name): [] for name in rc})
    saved = trace.ROW_BOUND
    try:
        for rep in range(frames + 1):          # the first: a warm-up
            for name, run in runs.items():
                for v, on in _VARIANTS.items():
                    trace.ROW_BOUND = on
                    value = run()
                    if rep:
                        got[v, name].append(value)
            for name, run in rc.items():
                value = run()
                if rep:
                    got["", name].append(value)
            say(f"run {rep} done, load {os.getloadavg()[0]:.2f}")
    finally:
        trace.ROW_BOUND = saved
    return {"medians": {k: statistics.median(v) for k, v in got.items()}, "all": got, "frames": frames,
            "renderer": renderer_name(), "load": os.getloadavg()}


def markdown(m: dict) -> str:
    med = m["medians"]
    lines = [f"# The rows' cheap reject, off and on ({datetime.now(UTC):%Y-%m-%d %H:%M} UTC)", "",
             f"GL renderer: {m['renderer']}  ", f"Machine: {machine()}  ",
             "Load average at the end: " + ", ".join(f"{x:.2f}" for x in m["load"]) + "  ",
             f"Medians of {m['frames']} interleaved runs (ms a frame; the scan in beams a second)", "",
             "| what | no reject | reject | ratio (no reject / reject; the scan: reject / no reject) | RC+R |",
             "|---|---:|---:|---:|---:|"]
    names = [n for v, n in med if v == "reject"]     # in the order run
    for name in names:
        a, b = med["no reject", name], med["reject", name]
        ratio = b / a if "beams" in name else a / b
        rc_name = name.replace("RT+R", "RC+R")
        rc = f"{med['', rc_name]:,.1f}" if ("", rc_name) in med else ""
        lines.append(f"| {name} | {a:,.1f} | {b:,.1f} | {ratio:.2f} | {rc} |")
    return "\n".join(lines + [""])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=3)
    parser.add_argument("--plants", default="saguaro,elm,pine")
    parser.add_argument("--scan-step", type=float, default=0.5)
    parser.add_argument("--scanner-positions", default="2,1.5,10")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    plants = tuple(p for p in args.plants.split(",") if p)
    return report(markdown(measure(max(args.frames, 1), plants, args.scan_step, args.scanner_positions)), args.out)


if __name__ == "__main__":
    raise SystemExit(main())
