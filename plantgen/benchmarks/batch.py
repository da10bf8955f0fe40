"""Batch throughput on Dask: plants per second for a grammar with three kinds of output, at
1 and 2 workers (and more with ``--workers``), the scaling efficiency, and Dask's own cost
per task (an empty task's round trip).

Run as ``python -m plantgen.benchmarks.batch [--grammar pine] [--plants 12]
[--workers 1 2]``. Each configuration runs a fresh batch folder on a fresh LocalCluster of
single-threaded worker processes, after a warm-up plant on every worker (imports, the EGL
context, shader compiles), and reports the median of ``--repeats`` runs. Prints the GL
renderer string first.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time

from ..batch.engine import run_batch
from ..batch.spec import simple_spec

__all__ = ["CONFIGS", "main"]

#: (label, outputs, view size) of each measured configuration.
CONFIGS = (("grow + npz", ["npz"], None), ("grow + png 512x384", ["png"], "512x384"),
           ("grow + glb m=1", ["glb"], None), ("grow + points (scan, PLY)", ["points"], None))


def _noop(x):
    return x


def task_overhead(client, tasks: int = 200) -> float:
    """Median milliseconds of an empty task's round trip (submit, run, gather), one at a time."""
    times = []
    for i in range(tasks):
        t0 = time.perf_counter()
        client.submit(_noop, i, pure=False).result()
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def measure(client, grammar: str, outputs, size, plants: int, repeats: int) -> float:
    """Median plants per second of ``plants`` plants over ``repeats`` fresh batches."""
    spec = simple_spec(grammar, f"0:{plants}", outputs, size=size, glb_level=1)
    warm = simple_spec(grammar, f"1000000:{1000000 + len(client.scheduler_info()['workers'])}", outputs,
                       size=size, glb_level=1)
    rates = []
    with tempfile.TemporaryDirectory() as tmp:
        run_batch(warm, f"{tmp}/warm", client=client)
        for r in range(repeats):
            result = run_batch(spec, f"{tmp}/run{r}", client=client)
            rates.append(result.rate)
    return statistics.median(rates)


def main(argv=None) -> int:
    from dask.distributed import Client, LocalCluster

    from ..gl.context import renderer_name

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grammar", default="pine")
    parser.add_argument("--plants", type=int, default=12)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--workers", type=int, nargs="*", default=[1, 2])
    args = parser.parse_args(argv)
    print(f"GL renderer: {renderer_name()}")
    rates: dict = {}
    for n in args.workers:
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                               silence_logs=50)
        with Client(cluster) as client:
            print(f"\n{n} worker(s): empty task round trip {task_overhead(client):.2f} ms (median of 200)")
            for label, outputs, size in CONFIGS:
                rates[(label, n)] = measure(client, args.grammar, outputs, size, args.plants, args.repeats)
                print(f"  {args.grammar}, {label:<22} {rates[(label, n)]:7.2f} plants/s "
                      f"(median of {args.repeats} batches of {args.plants})")
        cluster.close()
    base = min(args.workers)
    print(f"\nscaling efficiency (plants/s at n workers / (n/{base} x plants/s at {base})):")
    for label, _, _ in CONFIGS:
        cells = [f"{n}: {rates[(label, n)] / (n / base * rates[(label, base)]):.2f}" for n in args.workers]
        print(f"  {label:<22} " + ", ".join(cells))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
