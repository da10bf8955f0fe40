"""Benchmark: how fast plants grow in their environment.

Run as ``python -m plantgen.benchmarks.environment_speed [--iterations N] [--only NAMES]
[--out FILE]``. Grows, once each: ``self_organizing`` with N steps (default 34: about
10,000 segments, where the shipped model stops at 26), the 25-tree ``stand`` (one string)
and the scene ``grove`` (25 self-organizing trees grown together). For each it prints the
segments, the steps, the wall and CPU seconds of the whole growth (``time.process_time``
beside the wall clock: the cores may be shared), the rays its ``light`` parts traced, the
seconds those answers took and the rays a second of that time. No GL: every ray is traced
by the float64 traversal on the CPU, and answers the same as the reference however it is
batched.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ..environment.light import Light
from ..pipeline import grow_file
from .arguments import report
from .scan import machine

__all__ = ["MODELS", "main", "measure"]

#: The models grown, in order.
MODELS = ("self_organizing", "stand", "grove")


class _Counted:
    """While open, every :meth:`Light.answer` is counted: its rays, its seconds and the
    last derivation step it answered."""

    def __enter__(self):
        self.rays, self.seconds, self.steps, self.inner = 0, 0.0, 0, Light.answer

        def answer(light, state):
            t0 = time.perf_counter()
            try:
                return self.inner(light, state)
            finally:
                self.seconds += time.perf_counter() - t0
                self.rays += len(state) * light.rays_per_query
                self.steps = max(self.steps, int(state.step))

        Light.answer = answer
        return self

    def __exit__(self, *exc):
        Light.answer = self.inner


def measure(model: str, iterations: int | None = None) -> dict:
    """Grow ``model`` once (``iterations`` steps, default its own): a row of the table."""
    with _Counted() as counted:
        t0, c0 = time.perf_counter(), time.process_time()
        grown = grow_file(model, iterations=iterations)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"model": model, "segments": len(grown.skeleton), "steps": counted.steps, "wall": wall, "cpu": cpu,
            "rays": counted.rays, "light_s": counted.seconds,
            "rays_per_s": counted.rays / counted.seconds if counted.seconds > 0 else 0.0}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=34, help="self_organizing's steps (default 34)")
    parser.add_argument("--only", default=",".join(MODELS), help="models, comma separated (default: all)")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    names = [n for n in args.only.split(",") if n]
    unknown = [n for n in names if n not in MODELS]
    if unknown:
        parser.error(f"unknown model {unknown[0]!r} (models: {', '.join(MODELS)})")
    lines = [f"machine: {machine()}", "",
             "| model | segments | steps | wall s | CPU s | light rays | light s | rays / s |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for name in names:
        r = measure(name, args.iterations if name == "self_organizing" else None)
        label = f"{name} ({args.iterations} steps)" if name == "self_organizing" else name
        lines.append(f"| {label} | {r['segments']:,} | {r['steps']} | {r['wall']:.1f} | {r['cpu']:.1f} | "
                     f"{r['rays']:,} | {r['light_s']:.1f} | {r['rays_per_s']:,.0f} |")
        print(lines[-1], file=sys.stderr, flush=True)
    lines += ["", f"load average after the run: {machine().split('load average ')[-1].split(',')[0]}"]
    return report("\n".join(lines), args.out)


if __name__ == "__main__":
    sys.exit(main())
