"""The CPU tracer: the compiled traversal (:mod:`plantgen.geometry.rays.native_trace`) beside
the numpy one it replaces, on a scene's two-level BVH, in one run.

Run: ``python -m plantgen.benchmarks.cpu_trace [--scene forest] [--size 1024x768]
[--sample 8] [--scan-step 0.5] [--full-scan] [--out cpu_trace.md]`` (``--scene forest_cut``: the
looks bench's cut of the forest). The rays are made by :func:`scene_rays`, :func:`shadow_rays`
and :func:`scan_rays`, which the peer bench (:mod:`plantgen.benchmarks.peers`) shares.

Rows: the eye's rays of the scene's default camera at ``--size`` (closest hit), the
shadow rays of those that hit towards the scene's light (any hit, t_min 1e-4), and a
terrestrial scan of the scene from 2,1.5,10 at ``--scan-step`` (beams through
:func:`~plantgen.geometry.rays.scan.beam_returns`, float64). numpy traces every ``--sample``-th
ray (it is slow), the compiled walk every ray; both are given as rays a second, wall
and CPU (the process's CPU time, every thread: what another job's load changes least),
and beside them the share of the sampled rays where both find the same primitive and the
largest relative difference of their distances. The compile time is measured apart, in
fresh processes: numba compiling into an empty cache, then loading that cache.
``--full-scan`` also runs ``plantgen scan SCENE --scanner-positions 2,1.5,10
--angular-step 0.05`` (CPU path) in a child process: its wall time and peak memory,
growing the scene included.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from ..geometry.rays import native_trace
from ..geometry.rays.beams import beam_grids
from ..geometry.rays.scan import ScanSettings, beam_returns, scene_target
from ..pipeline import prepare_model, stage_model
from .arguments import image_size, report
from .looks import model_input
from .scan import machine

__all__ = ["SCANNER", "SHADOW_T_MIN", "compile_times", "full_scan", "main", "markdown", "measure", "scan_rays",
           "scan_settings", "scene_rays", "shadow_rays"]

#: Where the benches' terrestrial scanner stands (issue 44's rays: inside the forest).
SCANNER = "2,1.5,10"
#: Where a shadow ray starts counting hits, past the surface it leaves.
SHADOW_T_MIN = 1e-4


# ---------------------------------------------------------------------------- the rays (shared)
def scene_rays(scene: str, size) -> tuple:
    """``scene`` (a shipped name, a path, or ``forest_cut``: the looks bench's cut of the
    forest) grown and staged at ``size`` (width, height): (staging, its two-level
    :class:`~plantgen.geometry.rays.scan.SceneTarget`, the eye rays' origins (n, 3) and unit
    directions (n, 3), one a pixel of the scene's camera)."""
    model = prepare_model(model_input(scene))
    placed = model.placed if model.placed is not None else model.frusta_at(0)
    staging = stage_model(model.grown, placed, *size)
    target = scene_target(model.grown.scene.plants())
    O, D = (np.ascontiguousarray(a.reshape(-1, 3), dtype=np.float64) for a in staging.camera.rays())
    return staging, target, O, D


def shadow_rays(staging, origins, dirs, t) -> tuple[np.ndarray, np.ndarray]:
    """The shadow rays of the eye rays that hit (``t`` finite): from each hit point towards
    the scene's light (``staging.light_dir`` points at it), unit directions; trace them
    from ``t_min`` :data:`SHADOW_T_MIN` (any hit)."""
    hit = np.isfinite(t)
    light = np.asarray(staging.light_dir, np.float64)
    so = np.ascontiguousarray(origins[hit] + t[hit, None] * dirs[hit])
    return so, np.ascontiguousarray(np.broadcast_to(light / np.linalg.norm(light), so.shape))


def scan_settings(step: float) -> ScanSettings:
    """One terrestrial scanner at :data:`SCANNER`, ``step`` degrees between beams, ideal beams."""
    return ScanSettings(positions=SCANNER, angular_step=step)


def scan_rays(target, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Every beam of :func:`scan_settings` at ``step`` against ``target`` as plain rays:
    origins (n, 3) and unit directions (n, 3), in the scan's beam order (the beams
    :func:`~plantgen.geometry.rays.scan.beam_returns` traces, without its bookkeeping)."""
    parts = []
    for grid in beam_grids(target, scan_settings(step)):
        beam = np.arange(grid.count, dtype=np.int64)
        parts.append(grid.rays(grid.a0 + beam // grid.nb, grid.b0 + beam % grid.nb))
    if not parts:
        return np.zeros((0, 3)), np.zeros((0, 3))
    return tuple(np.ascontiguousarray(np.concatenate(p)) for p in zip(*parts, strict=True))


def _timed(run):
    c, t0 = time.process_time(), time.perf_counter()
    out = run()
    return out, time.perf_counter() - t0, time.process_time() - c


def _numpy_walk(on: bool):
    """Switch every float64 trace to the numpy traversal (``PLANTGEN_CPU_TRACER``)."""
    if on:
        os.environ["PLANTGEN_CPU_TRACER"] = "numpy"
    else:
        os.environ.pop("PLANTGEN_CPU_TRACER", None)


def _compare(target, O, D, sample: int, **kw) -> dict:
    """numpy on every ``sample``-th ray, compiled on all: rays/s and agreement."""
    pick = np.arange(0, len(O), sample)
    (a_t, a_p), wall_np, cpu_np = _timed(lambda: target.first_hits(O[pick], D[pick], native=False, **kw))
    (b_t, b_p), wall_nb, cpu_nb = _timed(lambda: target.first_hits(O, D, native=True, **kw))
    same = b_p[pick] == a_p if not kw.get("any_hit") else np.isfinite(b_t[pick]) == np.isfinite(a_t)
    fin = same & np.isfinite(a_t) & (b_p[pick] == a_p)
    rel = np.abs(b_t[pick][fin] - a_t[fin]) / np.maximum(np.abs(a_t[fin]), 1e-300)
    return {"rays": len(O), "sampled": len(pick), "hits": float(np.isfinite(b_t).mean()),
            "numpy": (len(pick) / wall_np, len(pick) / cpu_np), "numba": (len(O) / wall_nb, len(O) / cpu_nb),
            "same": float(same.mean()), "max_rel": float(rel.max()) if rel.size else 0.0,
            "hit_t": b_t, "hit_p": b_p}


def _scan(target, step: float) -> dict:
    """One terrestrial scanner at 2,1.5,10: beams/s numpy against compiled."""
    settings = scan_settings(step)
    out = {}
    for name, numpy_on in (("numba", False), ("numpy", True)):
        _numpy_walk(numpy_on)
        try:
            returns, wall, cpu = _timed(lambda: beam_returns(target, settings, seed=0))
        finally:
            _numpy_walk(False)
        beams = sum(r.beams for r in returns)
        out[name] = {"beams": beams, "points": sum(len(r.beam) for r in returns), "rate": (beams / wall, beams / cpu),
                     "prims": np.concatenate([r.primitive for r in returns]),
                     "range": np.concatenate([r.range for r in returns])}
    a, b = out["numpy"], out["numba"]
    same = len(a["prims"]) == len(b["prims"]) and bool((a["prims"] == b["prims"]).all())
    out["same"] = same
    return out


def compile_times() -> dict:
    """Seconds to compile into an empty cache and to load it, each in a fresh process."""
    code = "from plantgen.geometry.rays import native_trace as n; print(n.warm_up())"
    out = {}
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        env.pop("PLANTGEN_CPU_TRACER", None)
        for name in ("compile", "cached"):
            run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
            out[name] = float(run.stdout.strip().splitlines()[-1])
    return out


def full_scan(scene: str) -> dict:
    """``plantgen scan`` of ``scene`` at 0.05° from 2,1.5,10 on the CPU path, in a child
    process: wall seconds and peak resident memory (growing included)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "scan.ply"
        cmd = [sys.executable, "-m", "plantgen", "scan", scene, "--scanner-positions", "2,1.5,10",
               "--angular-step", "0.05", "--scan-precision", "float64", "-o", str(out), "-q"]
        t0 = time.perf_counter()
        run = subprocess.run(["/usr/bin/time", "-f", "%M %U %S", *cmd], capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if run.returncode:
            return {"error": run.stderr.strip().splitlines()[-1] if run.stderr.strip() else "failed"}
        kb, user, sys_ = run.stderr.strip().splitlines()[-1].split()
        return {"wall": wall, "cpu": float(user) + float(sys_), "peak_mb": int(kb) / 1024}


def measure(scene: str = "forest", size=(1024, 768), sample: int = 8, scan_step: float = 0.5,
            full: bool = False, say=print) -> dict:
    """Every row of the module docstring, in one run."""
    compiled = compile_times()
    say(f"compile {compiled['compile']:.1f} s, cached {compiled['cached']:.2f} s")
    native_trace.warm_up()
    staging, target, O, D = scene_rays(scene, size)
    _, build_wall, _ = _timed(lambda: (target.bvh, target.native))
    rows = {"eye rays (closest hit)": _compare(target, O, D, sample)}
    eye = rows["eye rays (closest hit)"]
    so, sd = shadow_rays(staging, O, D, eye["hit_t"])
    rows["shadow rays (any hit)"] = _compare(target, so, sd, sample, any_hit=True, t_min=SHADOW_T_MIN)
    for name, r in rows.items():
        say(f"{name}: numpy {r['numpy'][0]:,.0f}/s, numba {r['numba'][0]:,.0f}/s, same {r['same']:.6f}")
    scan = _scan(target, scan_step)
    say(f"scan {scan_step}°: numpy {scan['numpy']['rate'][0]:,.0f}/s, numba {scan['numba']['rate'][0]:,.0f}/s")
    result = {"scene": scene, "size": size, "sample": sample, "scan_step": scan_step, "compile": compiled,
              "gather_s": build_wall, "rows": rows, "scan": scan, "copies": target.bvh.copies,
              "primitives": sum(len(t) for t in target.targets), "threads": _threads(), "machine": machine(),
              "load": os.getloadavg(), "renderer": _renderer()}
    if full:
        result["full_scan"] = full_scan(scene)
        say(f"full scan: {result['full_scan']}")
    return result


def _renderer() -> str:
    """The GL renderer string of this machine (the GLSL tracer's device), or why there is none."""
    from ..gl.context import GLContextError, renderer_name

    try:
        return renderer_name()
    except GLContextError as exc:
        return f"none ({str(exc).splitlines()[0][:80]})"


def _threads() -> int:
    import numba

    return numba.get_num_threads()


def markdown(r: dict) -> str:
    w, h = r["size"]
    lines = [f"## {r['scene']}: {r['copies']:,} copies, {r['primitives']:,} distinct primitives; {w}x{h}",
             "", f"numpy traces every {r['sample']}th ray; numba every ray on {r['threads']} threads. "
             f"Compile: {r['compile']['compile']:.1f} s into an empty cache, {r['compile']['cached']:.2f} s "
             f"from it; gathering the arrays {1e3 * r['gather_s']:.0f} ms (BVH build included).", "",
             "| rays | count | hit | numpy rays/s (CPU) | numba rays/s (CPU) | ratio | same primitive | "
             "max rel. Δt |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for name, row in r["rows"].items():
        lines.append(f"| {name} | {row['rays']:,} | {row['hits']:.3f} | {row['numpy'][0]:,.0f} "
                     f"({row['numpy'][1]:,.0f}) | {row['numba'][0]:,.0f} ({row['numba'][1]:,.0f}) | "
                     f"{row['numba'][0] / row['numpy'][0]:.1f} | {row['same']:.6f} | {row['max_rel']:.1e} |")
    s = r["scan"]
    lines.append(f"| scan 2,1.5,10 at {r['scan_step']}° (beams) | {s['numba']['beams']:,} | "
                 f"{s['numba']['points'] / max(s['numba']['beams'], 1):.3f} | {s['numpy']['rate'][0]:,.0f} "
                 f"({s['numpy']['rate'][1]:,.0f}) | {s['numba']['rate'][0]:,.0f} ({s['numba']['rate'][1]:,.0f}) | "
                 f"{s['numba']['rate'][0] / s['numpy']['rate'][0]:.1f} | {'all' if s['same'] else 'not all'} | |")
    if "full_scan" in r:
        f = r["full_scan"]
        lines += ["", (f"`plantgen scan {r['scene']} --scanner-positions 2,1.5,10 --angular-step 0.05` (CPU, "
                       f"growing included): {f['wall']:.1f} s wall, {f['cpu']:.1f} s CPU, {f['peak_mb']:,.0f} MB peak")
                  if "error" not in f else f"full scan failed: {f['error']}"]
    lines += ["", f"Machine: {r['machine']}; GL renderer {r.get('renderer', 'not asked')}; load average at the end "
              f"{r['load'][0]:.2f}. "
              f"{datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}."]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="forest")
    parser.add_argument("--size", default="1024x768", type=image_size)
    parser.add_argument("--sample", default=8, type=int, help="numpy traces every Nth ray")
    parser.add_argument("--scan-step", default=0.5, type=float)
    parser.add_argument("--full-scan", action="store_true")
    parser.add_argument("--out", default=None)
    a = parser.parse_args(argv)
    r = measure(a.scene, a.size, a.sample, a.scan_step, a.full_scan)
    report(markdown(r), a.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
