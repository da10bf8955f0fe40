"""How the distinct plants' trees split, for the compiled CPU tracer: the LBVH against the
binned SAH (:data:`~plantgen.geometry.rays.scan_targets.COMPILED_METHOD`), each built by the
compiled build, on the peer bench's rays, in one run.

Run: ``python -m plantgen.benchmarks.bvh_split [--scene forest,forest_cut] [--size 1024x768]
[--scan-step 0.5] [--rounds 7] [--out bvh_split.md]``.

For each scene (:func:`~plantgen.benchmarks.cpu_trace.scene_rays`: its distinct plants, a
top level over the copies) every plant's tree is built both ways (the compiled build,
:mod:`plantgen.geometry.rays.native_build`: the median of 3 builds of all the plants; the
top level is the LBVH in both), then the primary, shadow and scan rays of the peer bench
(:mod:`plantgen.benchmarks.peers`) are traced by the compiled walk over each tree in turn,
``--rounds`` times after a warm-up: rays/s of wall time (the median), the SAH's over the
LBVH's, the trees' nodes and SAH cost, and whether every ray got the same answer (closest
hits: t, copy and primitive; any hits: blocked or not).
"""

from __future__ import annotations

import argparse
import statistics
import time
from dataclasses import replace
from datetime import UTC, datetime

import numpy as np

from ..geometry.rays import native_trace
from ..geometry.rays.bvh import build_bvh, scene_bvh
from ..geometry.rays.native_trace import native_scene
from .arguments import image_size, report
from .cpu_trace import SHADOW_T_MIN, scan_rays, scene_rays, shadow_rays
from .scan import machine

__all__ = ["SPLITS", "main", "markdown", "measure_scene"]

#: The splits compared, the first the base of the ratios.
SPLITS = ("lbvh", "sah")


def _trees(target, split: str, repeats: int = 3) -> tuple[float, list]:
    """The median seconds to build every distinct plant's tree by ``split`` (compiled), and the trees."""
    times, trees = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        trees = [build_bvh(t.lo, t.hi, method=split, compiled=True) for t in target.targets]
        times.append(time.perf_counter() - t0)
    return statistics.median(times), trees


def _split_target(target, trees):
    """``target`` with these plant trees (and a top level over its copies)."""
    plants = tuple(replace(t) for t in target.targets)
    for t, tree in zip(plants, trees, strict=True):
        t.__dict__["bvh"] = tree
    out = replace(target, targets=plants)
    out.__dict__["bvh"] = scene_bvh(list(trees), target.matrices)
    return out


def measure_scene(scene: str, size=(1024, 768), scan_step: float = 0.5, rounds: int = 7, say=print) -> dict:
    """Every row of the module docstring for one scene."""
    native_trace.warm_up()
    staging, target, O, D = scene_rays(scene, size)
    built = {s: _trees(target, s) for s in SPLITS}
    walks = {s: native_scene(_split_target(target, trees)) for s, (_, trees) in built.items()}
    t, _, _ = walks[SPLITS[0]].trace(O, D)
    so, sd = shadow_rays(staging, O, D, t)
    co, cd = scan_rays(target, scan_step)
    kinds = {"primary": (O, D, False, 0.0), "shadow": (so, sd, True, SHADOW_T_MIN), "scan": (co, cd, False, 0.0)}
    answers = {s: {k: w.trace(o, d, any_hit=a, t_min=tm) for k, (o, d, a, tm) in kinds.items()}
               for s, w in walks.items()}                                   # the warm-up
    same = {}
    for k, (_, _, any_hit, _) in kinds.items():
        a, b = (answers[s][k] for s in SPLITS)
        same[k] = bool(np.array_equal(np.isfinite(a[0]), np.isfinite(b[0])) if any_hit else
                       all(np.array_equal(x, y) for x, y in zip(a, b, strict=True)))
    rates = {(s, k): [] for s in SPLITS for k in kinds}
    for r in range(rounds):
        for s, w in walks.items():
            for k, (o, d, a, tm) in kinds.items():
                t0 = time.perf_counter()
                w.trace(o, d, any_hit=a, t_min=tm)
                rates[s, k].append(len(o) / (time.perf_counter() - t0))
        say(f"{scene}: round {r + 1} of {rounds}")
    return {"scene": scene, "size": size, "scan_step": scan_step, "rounds": rounds,
            "counts": {k: len(v[0]) for k, v in kinds.items()}, "copies": len(target.bvh.plant),
            "primitives": sum(len(t) for t in target.targets), "same": same,
            "rows": {s: {"build": built[s][0], "nodes": sum(b.nodes for b in built[s][1]),
                         "sah_cost": sum(b.sah_cost() * len(b.prims) for b in built[s][1]) /
                         max(sum(len(b.prims) for b in built[s][1]), 1),
                         **{k: statistics.median(rates[s, k]) for k in kinds}} for s in SPLITS},
            "machine": machine()}


def markdown(results: list[dict]) -> str:
    lines = []
    for r in results:
        w, h = r["size"]
        c = r["counts"]
        base = r["rows"][SPLITS[0]]
        lines += [f"## {r['scene']}: {r['copies']:,} copies, {r['primitives']:,} distinct primitives; {w}x{h}", "",
                  f"Rays: {c['primary']:,} primary (closest hit), {c['shadow']:,} shadow (any hit), {c['scan']:,} "
                  f"scan beams at {r['scan_step']}° (closest hit). Rays/s of wall time, the median of "
                  f"{r['rounds']} interleaved rounds; in brackets the ratio to the LBVH's.", "",
                  "| plants' trees | build ms | nodes | SAH cost (the plants', weighted by their primitives) | "
                  "primary rays/s | shadow rays/s | scan rays/s |", "|---|---:|---:|---:|---:|---:|---:|"]
        for s, row in r["rows"].items():
            cells = " | ".join(f"{row[k]:,.0f} ({row[k] / base[k]:.2f})" for k in ("primary", "shadow", "scan"))
            lines.append(f"| {s} | {1e3 * row['build']:,.0f} | {row['nodes']:,} | {row['sah_cost']:.1f} | {cells} |")
        lines += ["", "Every ray the same answer on both trees: " +
                  ", ".join(f"{k} {'yes' if v else 'NO'}" for k, v in r["same"].items()) + ".", ""]
    lines.append(f"Machine: {results[-1]['machine']} (at the end); numba {native_trace.numba.get_num_threads()} "
                 f"threads. {datetime.now(UTC):%Y-%m-%d %H:%M} UTC.")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="forest,forest_cut",
                        help="scenes, comma-separated (default forest,forest_cut)")
    parser.add_argument("--size", default="1024x768", type=image_size)
    parser.add_argument("--scan-step", default=0.5, type=float)
    parser.add_argument("--rounds", default=7, type=int)
    parser.add_argument("--out", default=None)
    a = parser.parse_args(argv)
    if not native_trace.available():
        parser.exit(2, "plantgen: the compiled CPU tracer does not run here (numba); this bench compares its trees\n")
    results = [measure_scene(s.strip(), a.size, a.scan_step, a.rounds) for s in a.scene.split(",") if s.strip()]
    return report(markdown(results), a.out)


if __name__ == "__main__":
    raise SystemExit(main())
