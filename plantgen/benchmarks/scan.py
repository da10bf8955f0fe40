"""What a simulated laser scan's accuracy costs: points per second of the float64
reference against the float32 fast path, and the fast path's range error, beam by beam.

Run: ``python -m plantgen.benchmarks.scan [MODEL ...] [--step DEG] [--repeats R]
[--brute N]``. Each model (shipped grammar names; default pine, elm, broadleaf) is grown,
skinned and scanned by ``scanners`` terrestrial scanners at ``--step`` degrees
(:mod:`plantgen.geometry.rays.scan`), ``--repeats`` times per precision, interleaved; the
table gives the median time, points and beams per second, and for the fast path the
median and largest |range - reference range| over the beams both hit (model units, and
over the model's size), the beams whose range is off by more than 1e-4 of the size (a
thin twig missed at its edge, the one behind hit) and the beams only one of them hits
(silhouette pixels). Both
trace the beams through the target's BVH; ``--brute N`` also times the
reference without it (:func:`~plantgen.geometry.rays.reference.intersect_frusta`: every
beam against every row's box) on N random beams of the first scanner, extrapolated to
the whole scan: what the binning buys. The machine is printed with the table.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import numpy as np

from ..geometry.rays.reference import intersect_frusta
from ..geometry.rays.scan import ScanSettings, TerrestrialBeams, beam_returns, scan_target, scanner_positions
from ..pipeline import grow_file, skin_model

MODELS = ("pine", "elm", "broadleaf")


def machine() -> str:
    """One line: the processor, its cores and the numeric stack."""
    name = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            name = next((line.split(":", 1)[1].strip() for line in fh if line.startswith("model name")), name)
    except OSError:
        pass
    load = f", load average {os.getloadavg()[0]:.2f}" if hasattr(os, "getloadavg") else ""
    return (f"{name}, {os.cpu_count()} cores{load}, Python {platform.python_version()}, numpy {np.__version__}, "
            f"{platform.system()} {platform.release()}")


def _timed_scan(target, settings: ScanSettings) -> tuple[float, list]:
    t0 = time.perf_counter()
    returns = beam_returns(target, settings, seed=0)
    return time.perf_counter() - t0, returns


def _range_errors(reference: list, fast: list) -> tuple[np.ndarray, int]:
    """|fast - reference| over the beams both hit, and the beams only one hits."""
    errors, mismatched = [], 0
    for ref, got in zip(reference, fast, strict=True):
        common, i, j = np.intersect1d(ref.beam, got.beam, assume_unique=True, return_indices=True)
        errors.append(np.abs(got.range[j] - ref.range[i]))
        mismatched += len(ref.beam) + len(got.beam) - 2 * len(common)
    return np.concatenate(errors), mismatched


def _brute_rate(frusta, target, settings: ScanSettings, sample: int) -> float:
    """Beams per second of the unbinned reference on ``sample`` random beams of scanner 0."""
    lo, hi = target.box()
    grid = TerrestrialBeams(scanner_positions(target, settings)[0], lo, hi, np.radians(settings.angular_step))
    ids = np.random.default_rng(0).choice(grid.count, min(sample, grid.count), replace=False)
    origins, dirs = grid.rays(grid.a0 + ids // grid.nb, grid.b0 + ids % grid.nb)
    t0 = time.perf_counter()
    intersect_frusta(frusta, origins, dirs)
    return len(ids) / (time.perf_counter() - t0)


def _model_rows(name: str, args) -> list[str]:
    grown = grow_file(name)
    frusta = skin_model(grown)
    target = scan_target(grown.skeleton, grown.polygons, frusta=frusta)
    size = float(np.ptp(np.stack([target.lo.min(axis=0), target.hi.max(axis=0)]), axis=0).max())
    runs = {"float64": [], "float32": []}
    returns = {}
    _timed_scan(target, ScanSettings(angular_step=args.step, scanners=args.scanners))           # warm-up
    for _ in range(args.repeats):
        for precision in runs:
            settings = ScanSettings(angular_step=args.step, scanners=args.scanners, precision=precision)
            seconds, returns[precision] = _timed_scan(target, settings)
            runs[precision].append(seconds)
    beams = sum(r.beams for r in returns["float64"])
    head = f"{name:10s} {len(frusta):7,d} {len(target.triangles):7,d} {beams:10,d}"
    rows = []
    for precision, times in runs.items():
        seconds = statistics.median(times)
        points = sum(len(r.beam) for r in returns[precision])
        cells = f"{precision:8s} {seconds:8.2f} {points:9,d} {points / seconds:10,.0f} {beams / seconds:10,.0f}"
        if precision == "float64":
            rows.append(f"{head} {cells} {'reference':>41s}")
            continue
        err, mismatched = _range_errors(returns["float64"], returns[precision])
        stats = (f"{np.median(err):9.2e} {err.max():9.2e} {err.max() / size:8.1e} "
                 f"{int((err > 1e-4 * size).sum()):6,d} {mismatched:6,d}" if len(err) else f"{'-':>41s}")
        rows.append(f"{'':10s} {'':7s} {'':7s} {'':10s} {cells} {stats}")
    if args.brute:
        rate = _brute_rate(frusta, target, ScanSettings(angular_step=args.step, scanners=args.scanners), args.brute)
        rows.append(f"{'':10s} {'':7s} {'':7s} {'':10s} {'unbinned':8s} {beams / rate:8.0f}s (estimated from "
                    f"{args.brute:,} beams against the frusta alone: {rate:,.0f} beams/s)")
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="*", default=list(MODELS), help="shipped grammar names or paths")
    parser.add_argument("--step", type=float, default=0.05, help="angular step, degrees (default 0.05)")
    parser.add_argument("--scanners", type=int, default=4, help="terrestrial scanners (default 4)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per precision (default 3)")
    parser.add_argument("--brute", type=int, default=0, metavar="N",
                        help="also time the unbinned reference on N beams (0: no)")
    args = parser.parse_args(argv)
    print(f"plantgen scan benchmark: {args.scanners} terrestrial scanners, step {args.step:g}°, no noise; "
          f"medians of {args.repeats} runs")
    print(f"machine: {machine()}")
    print(f"{'model':10s} {'rows':>7s} {'leaf tri':>7s} {'beams':>10s} {'dtype':8s} {'seconds':>8s} {'points':>9s} "
          f"{'points/s':>10s} {'beams/s':>10s} {'|Δr| med':>9s} {'|Δr| max':>9s} {'max/size':>8s} {'off':>6s} "
          f"{'silh.':>6s}")
    for name in args.models:
        for row in _model_rows(name, args):
            print(row, flush=True)


if __name__ == "__main__":
    main()
