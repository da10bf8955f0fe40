"""What the bounding volume hierarchy costs and buys: build rate (primitives a second) of
the LBVH against binned SAH, the trees' nodes, depth, SAH cost and memory, and the float64
reference traversal's rays a second (closest hit and any hit) on each tree.

Run: ``python -m plantgen.benchmarks.bvh [MODEL ...] [--random N] [--rays R] [--repeats K]
[--copies C] [--out FILE]``. Each model (shipped grammar or scene names; default
broadleaf, pine_needles and forest) is grown and skinned; its primitives are what a scan
sees (:func:`~plantgen.geometry.rays.scan.scan_target`: rows, relief shell left out, and leaf
triangles); a scene's are its distinct plants' in two levels, as the scan and
:func:`plantgen.trace` trace it (:func:`~plantgen.geometry.rays.scan.scene_target`; the
primitives counted once per distinct plant). ``--random N`` adds N random boxes (0:
none). Rays start outside the model's box and aim at random points inside it, so most
cross it. Times are medians of ``--repeats`` runs (SAH on more than 200,000 primitives:
one run). ``--copies C`` also builds a scene's two-level BVH (the plants once, a top level
over C copies: the scene's copies repeated on a grid) and times the top level alone. The
machine and its load average are printed with the table: the cores may be shared.
"""

from __future__ import annotations

import argparse
import statistics
import time
from datetime import UTC, datetime
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ..geometry.rays.bvh import (
    BVH_METHODS,
    TOP_LEAF_SIZE,
    build_bvh,
    build_scene_bvh,
    scene_bvh,
    trace_bvh,
    trace_scene,
)
from ..geometry.rays.scan import scan_target, scene_target, target_hits
from ..pipeline import grow_file, model_leaves, place_scene, skin_model
from .arguments import report
from .scan import machine

MODELS = ("broadleaf", "pine_needles", "forest")


def _timed(fn, repeats: int):
    times, out = [], None
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def _rays(lo, hi, m: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    centre, size = (lo + hi) / 2, float((hi - lo).max()) or 1.0
    direction = rng.normal(size=(m, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    origins = centre + direction * size                                   # outside the box, all round
    targets = lo + (hi - lo) * rng.random((m, 3))
    return origins, targets - origins


def _rows(name: str, lo, hi, hits, args) -> list[str]:
    n = len(lo)
    O, D = _rays(lo.min(axis=0), hi.max(axis=0), args.rays)
    rows = []
    for method in BVH_METHODS:
        repeats = 1 if method == "sah" and n > 200_000 else args.repeats
        seconds, bvh = _timed(lambda m=method: build_bvh(lo, hi, method=m), repeats)
        cells = (f"| {name} | {n:,} | {method} | {seconds:.3f} | {n / seconds / 1e6:.2f} | {bvh.nodes:,} | "
                 f"{bvh.depth()} | {bvh.sah_cost():.1f} | {bvh.nbytes / n:.1f} |")
        if hits is None:
            rows.append(cells + " - | - | - |")
            continue
        rows.append(cells + _trace_cells(lambda any_hit, b=bvh: trace_bvh(b, O, D, hits, any_hit=any_hit), args))
    return rows


def _trace_cells(trace, args) -> str:
    closest, (t, *_) = _timed(lambda: trace(False), 1)
    shadow, _ = _timed(lambda: trace(True), 1)
    return f" {args.rays / closest:,.0f} | {args.rays / shadow:,.0f} | {np.isfinite(t).mean():.0%} |"


def _scene_rows(name: str, target, args) -> list[str]:
    """Two levels: every distinct plant's BVH and the top level over the copies."""
    lo, hi = target.box()
    O, D = _rays(lo, hi, args.rays)
    hits = [target_hits(t) for t in target.targets]
    n = sum(len(t) for t in target.targets)
    rows = []
    for method in BVH_METHODS:
        def build(m=method):
            return scene_bvh([build_bvh(t.lo, t.hi, method=m) for t in target.targets], target.matrices, method=m)

        seconds, scene = _timed(build, 1 if method == "sah" else args.repeats)
        nodes = sum(b.nodes for b in scene.blas) + scene.tlas.nodes
        depth = max(b.depth() for b in scene.blas) + scene.tlas.depth()
        cells = (f"| {name} (two levels: {len(target.targets)} plants, {scene.copies:,} copies) | {n:,} | {method} "
                 f"| {seconds:.3f} | {n / seconds / 1e6:.2f} | {nodes:,} | {depth} | - | {scene.nbytes / n:.1f} |")
        rows.append(cells + _trace_cells(lambda any_hit, sc=scene: trace_scene(sc, O, D, hits, any_hit=any_hit),
                                         args))
    return rows


def _model(name: str, args) -> tuple[list[str], object]:
    grown = grow_file(name)
    if grown.scene is not None:
        return _scene_rows(name, scene_target(grown.scene.plants()), args), grown
    target = scan_target(grown.skeleton, model_leaves(grown), frusta=skin_model(grown))
    return _rows(name, target.lo, target.hi, target_hits(target), args), grown


def _copies(grown, copies: int, args) -> list[str]:
    """Two levels: the scene's plants once, its copies repeated on a grid to ``copies``."""
    placed = place_scene(grown.scene)
    lo, hi = placed.box
    step = (hi - lo) * [1.0, 0.0, 1.0]
    total = placed.copies
    tiles = int(np.ceil(np.sqrt(copies / max(total, 1))))
    shifts = np.array([[i, 0, j] for i in range(tiles) for j in range(tiles)], float) * step
    plants = []
    for p in placed.plants:
        m = np.repeat(p.matrices[None], len(shifts), axis=0).copy()
        m[..., :3, 3] += shifts[:, None]
        m = m.reshape(-1, 4, 4)
        keep = int(np.ceil(len(m) * copies / (total * len(shifts))))
        plants.append(SimpleNamespace(name=p.name, frusta=p.frusta, matrices=m[:keep]))
    big = SimpleNamespace(plants=plants)
    seconds, scene = _timed(lambda: build_scene_bvh(big), 1)
    top, _ = _timed(lambda: build_bvh(scene.copy_lo, scene.copy_hi, leaf_size=TOP_LEAF_SIZE), args.repeats)
    rows_ = sum(len(p.frusta) for p in big.plants)
    return [f"| {grown.name} × {scene.copies:,} copies | {len(big.plants)} plants, {rows_:,} rows | "
            f"{seconds:.2f} | {top:.3f} | {scene.tlas.nodes:,} | {scene.tlas.depth()} | "
            f"{sum(b.nbytes for b in scene.blas) / 1e6:.1f} | {scene.copy_bytes():.0f} |"]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="*", default=list(MODELS), help="shipped grammar or scene names, or paths")
    parser.add_argument("--random", type=int, default=1_000_000, help="random boxes (default 1,000,000; 0: none)")
    parser.add_argument("--rays", type=int, default=20_000, help="rays traced per tree (default 20,000)")
    parser.add_argument("--repeats", type=int, default=3, help="timed builds (default 3)")
    parser.add_argument("--copies", type=int, default=100_000, help="copies of a scene's two levels (0: none)")
    parser.add_argument("--out", type=Path, default=None, help="also write the Markdown table here")
    args = parser.parse_args(argv)
    lines = [f"# BVH build and float64 traversal ({datetime.now(UTC):%Y-%m-%d %H:%M} UTC)", "",
             f"machine: {machine()}", "",
             "| input | primitives | method | build s | M prims/s | nodes | depth | SAH cost | B/prim | "
             "closest rays/s | any-hit rays/s | rays hit |",
             "| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    scenes = []
    for name in args.models:
        rows, grown = _model(name, args)
        lines += rows
        if grown.scene is not None and args.copies:
            scenes.append(grown)
        print("\n".join(rows), flush=True)
    if args.random:
        rng = np.random.default_rng(1)
        c = rng.random((args.random, 3)) * 100
        s = rng.random((args.random, 3)) ** 2
        lines += _rows(f"random boxes (n = {args.random:,})", c - s, c + s, None, args)
    if scenes:
        lines += ["", "Two levels (a BLAS per distinct plant, a TLAS over the copies):", "",
                  "| scene | distinct | scene BVH s | top level s | top nodes | top depth | plants MB | "
                  "B/copy (CPU) |", "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
        for grown in scenes:
            lines += _copies(grown, args.copies, args)
    lines += ["", f"load average after the run: {machine().split('load average ')[-1].split(',')[0]}"]
    return report("\n".join(lines) + "\n", args.out)


if __name__ == "__main__":
    raise SystemExit(main())
