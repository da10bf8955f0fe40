"""Benchmark: how fast ``plantgen grow`` derives and interprets the big Table 1 models.

Run as ``python -m plantgen.benchmarks.grow [--repeats R] [NAME ...]`` (default: pine
and oasis, the largest grammar and the largest scene of Table 1). Each model is grown
R times (after one warm-up run) with ``plantgen.pipeline.grow_file``, which times every
stage; the script prints medians over the runs:

- derivation speed: modules of the final derived strings per second of ``derive``,
- interpretation speed: modules walked by the turtle per second of ``interpret``,
- the total grow time (parse + derive + interpret + placing scene instances) and the
  segment count.

For a scene the module count and stage times add up over its grown instances (instances
that share grammar, seed and iterations are grown once).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

from .._resources import shipped_grammar
from ..pipeline import grow_file

__all__ = ["measure", "main"]


def measure(name: str, repeats: int = 7) -> dict:
    """Grow the shipped model ``name`` ``repeats`` times; medians of rates and times.

    Returns a dict with ``segments``, ``modules``, ``derive_modules_per_s``,
    ``interpret_modules_per_s``, ``derive_s``, ``interpret_s`` and ``total_s`` (seconds).
    """
    path = shipped_grammar(name)
    grow_file(path)                                   # warm-up: imports, caches
    rows = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = grow_file(path)
        total = time.perf_counter() - t0
        rows.append((result.modules, result.timings["derive"], result.timings["interpret"],
                     total, len(result.skeleton)))
    modules = rows[0][0]
    return {
        "segments": rows[0][4],
        "modules": modules,
        "derive_modules_per_s": statistics.median(m / d for m, d, *_ in rows),
        "interpret_modules_per_s": statistics.median(m / i for m, _, i, *_ in rows),
        "derive_s": statistics.median(r[1] for r in rows),
        "interpret_s": statistics.median(r[2] for r in rows),
        "total_s": statistics.median(r[3] for r in rows),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", default=["pine", "oasis"])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args(argv)
    print(f"grow benchmark, median of {args.repeats} runs after one warm-up")
    print(f"{'model':<14}{'segments':>9}{'modules':>9}{'derive Mmod/s':>15}"
          f"{'interp Mmod/s':>15}{'derive ms':>11}{'interp ms':>11}{'total ms':>10}")
    for name in args.names:
        r = measure(name, args.repeats)
        print(f"{name:<14}{r['segments']:>9,}{r['modules']:>9,}"
              f"{r['derive_modules_per_s'] / 1e6:>15.3f}{r['interpret_modules_per_s'] / 1e6:>15.3f}"
              f"{r['derive_s'] * 1e3:>11.1f}{r['interpret_s'] * 1e3:>11.1f}{r['total_s'] * 1e3:>10.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
