"""Benchmark: what the light's accuracy costs, per derivation step.

Run as ``python -m plantgen.benchmarks.light_queries [--steps K] [--directions 16,32,...]
[--reference N] [--repeats R] [--out FILE]``. The shipped ``self_organizing`` tree is
grown K steps; the query state of its last step (its buds, its branches and leaves) is
then answered by its ``light`` part with each number of sky directions, and by a
reference of N directions. For each it prints the median time of one step's light (the
BVH built over what has grown, and every bud's rays traced by the float64 traversal), the
rays per second, and the light's error against the reference: the mean and the largest
absolute difference of q over the buds (q is a fraction of the open sky's light, 0 to 1).
"""

from __future__ import annotations

import argparse
import copy
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from .._resources import shipped_grammar
from ..environment.light import Light
from ..files import read_yaml
from ..limits import Limits
from ..lsystem import derive, parse_grammar
from .arguments import report

__all__ = ["last_state", "main", "measure"]


class _Keep:
    """An environment that answers as the grammar's own and keeps the last state it saw."""

    def __init__(self, inner):
        self.inner, self.width, self.state = inner, inner.width, None

    def answer(self, state):
        self.state = state
        return self.inner.answer(state)


def last_state(steps: int):
    """The ``self_organizing`` tree's query state after ``steps`` steps, and its light settings."""
    from ..environment import environment_for

    path = shipped_grammar("self_organizing")
    data = read_yaml(path)
    data["iterations"] = steps
    grammar = parse_grammar(data, str(path))
    keep = _Keep(environment_for(grammar))
    derive(grammar, environment=keep)
    return keep.state, data["environment"][0]["light"], Path(path).parent


def measure(state, settings: dict, base: Path, directions: list[int], reference: int, repeats: int) -> list[dict]:
    """One row per number of directions (the reference last): time, rays/s, error of q."""
    rows, answers = [], {}
    for n in [*directions, reference]:
        light = Light({**copy.deepcopy(settings), "directions": n}, "bench", base, Limits(), 0)
        times = []
        for _ in range(repeats if n != reference else 1):
            t0 = time.perf_counter()
            answers[n] = light.answer(state)[:, 0]
            times.append(time.perf_counter() - t0)
        rays = len(state) * light.rays_per_query
        rows.append({"directions": n, "rays": rays, "seconds": statistics.median(times),
                     "rays_per_s": rays / statistics.median(times)})
    for row in rows:
        err = np.abs(answers[row["directions"]] - answers[reference])
        row["mean_error"], row["max_error"] = float(err.mean()), float(err.max())
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--directions", default="16,32,48,96,192")
    parser.add_argument("--reference", type=int, default=2048)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    state, settings, base = last_state(args.steps)
    rows = measure(state, settings, base, [int(x) for x in args.directions.split(",")], args.reference,
                   args.repeats)
    skel = state.drawing.skeleton
    lines = [f"self_organizing after {args.steps} steps: {len(skel):,} segments, {len(state.drawing.polygons):,} "
             f"leaves, {len(state):,} buds; light per step (median of {args.repeats}), error of q against "
             f"{args.reference} directions", "",
             "| directions | rays | s / step | rays / s | mean error | max error |",
             "| --- | --- | --- | --- | --- | --- |"]
    lines += [f"| {r['directions']} | {r['rays']:,} | {r['seconds']:.3f} | {r['rays_per_s']:,.0f} | "
              f"{r['mean_error']:.4f} | {r['max_error']:.4f} |" for r in rows]
    return report("\n".join(lines), args.out)


if __name__ == "__main__":
    sys.exit(main())
