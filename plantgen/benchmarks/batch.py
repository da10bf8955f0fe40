"""Batch throughput and scale on Dask.

Three sections (``--sections``, default all):

- ``throughput``: plants per second for a grammar with three kinds of output, at 1 and 2
  workers (and more with ``--workers``), the scaling efficiency, and Dask's own cost per
  task (an empty task's round trip). Each configuration runs a fresh batch folder on a
  fresh LocalCluster of single-threaded worker processes, after a warm-up plant on every
  worker (imports, the EGL context, shader compiles), and reports the median of
  ``--repeats`` runs.
- ``scale``: batches of ``--scale`` saguaros (npz; default 10,000 and 100,000) on one warm
  cluster: seconds from :func:`run_batch` to the first plant made, the client's resident
  memory (this process: the client, the LocalCluster's scheduler, the manifest) sampled
  every 0.1 s, and plants per second. ``--scale-plants N`` stops each batch after N plants
  (as Ctrl-C would; 0: run them all), so the sizes compare at the same work done.
- ``command``: ``plantgen batch saguaro --seeds 0:1000000 --outputs npz`` as a user runs it
  (``--command-plants``): seconds from the command to its first file, the peak resident
  memory of its process over ``--command-seconds``, then Ctrl-C, then the same command
  again: how many plants it finds done, and that it goes on.

Run as ``python -m plantgen.benchmarks.batch [--sections scale command] [--scale 10000
100000] [--scale-plants 2000]``. Prints the GL renderer string first.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from ..batch.engine import run_batch
from ..batch.spec import simple_spec

__all__ = ["CONFIGS", "main", "MemorySampler"]

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
    warm = simple_spec(grammar, f"1000000:{1000000 + len(client.nthreads())}", outputs, size=size, glb_level=1)
    rates = []
    with tempfile.TemporaryDirectory() as tmp:
        run_batch(warm, f"{tmp}/warm", client=client)
        for r in range(repeats):
            result = run_batch(spec, f"{tmp}/run{r}", client=client)
            rates.append(result.rate)
    return statistics.median(rates)


def _cluster(n: int):
    from dask.distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=50)
    return Client(cluster), cluster


def throughput(args) -> None:
    rates: dict = {}
    for n in args.workers:
        client, cluster = _cluster(n)
        with client:
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


class MemorySampler:
    """The resident memory of process ``pid`` (default: this one), sampled every
    ``interval`` seconds in a thread while in the ``with`` block: ``samples`` of (seconds,
    bytes), ``peak``."""

    def __init__(self, pid: int | None = None, interval: float = 0.1):
        import psutil

        self.process = psutil.Process(pid or os.getpid())
        self.interval, self.samples = interval, []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        t0 = time.perf_counter()
        while not self._stop.is_set():
            try:
                self.samples.append((time.perf_counter() - t0, self.process.memory_info().rss))
            except Exception:   # the process ended
                return
            self._stop.wait(self.interval)

    @property
    def peak(self) -> int:
        return max((b for _, b in self.samples), default=0)

    def at(self, fraction: float) -> int:
        """The sample ``fraction`` of the way through."""
        return self.samples[min(int(fraction * len(self.samples)), len(self.samples) - 1)][1] if self.samples else 0

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()


def scale_run(client, total: int, plants: int, folder: str) -> dict:
    """One batch of ``total`` saguaros (npz), stopped after ``plants`` (as Ctrl-C would; 0:
    none): its figures."""
    rss_before = MemorySampler().process.memory_info().rss
    spec = simple_spec("saguaro", f"0:{total}", ["npz"])
    seen: dict = {}

    def progress(result):
        seen["result"] = result          # the live result: run_batch completes it when it stops
        if plants and result.done + result.failed >= plants:
            raise KeyboardInterrupt

    with MemorySampler() as memory, contextlib.suppress(KeyboardInterrupt):
        run_batch(spec, folder, client=client, progress=progress)
    result = seen["result"]
    return {"total": total, "first": result.first_plant, "before": rss_before, "peak": memory.peak,
            "early": memory.at(0.25), "late": memory.at(0.95), "rate": result.rate}


def scale(args) -> None:
    client, cluster = _cluster(args.scale_workers)
    with client, tempfile.TemporaryDirectory() as tmp:
        run_batch(simple_spec("saguaro", "900000000:900000004", ["npz"]), f"{tmp}/warm", client=client)
        stop = f", stopped after {args.scale_plants:,} plants" if args.scale_plants else ""
        print(f"\nscale: saguaros (npz) on {args.scale_workers} workers{stop}; client = this process "
              "(client, scheduler, manifest)")
        print(f"  {'plants':>10} {'first plant':>12} {'RSS before':>11} {'at 25%':>8} {'at 95%':>8} {'peak':>8} "
              f"{'plants/s':>9}")
        for i, total in enumerate(args.scale):
            r = scale_run(client, total, args.scale_plants, f"{tmp}/scale{i}")
            mib = 1 << 20
            print(f"  {total:>10,} {r['first']:>10.2f} s {r['before'] / mib:>7.0f} MiB {r['early'] / mib:>4.0f} MiB "
                  f"{r['late'] / mib:>4.0f} MiB {r['peak'] / mib:>4.0f} MiB {r['rate']:>9.1f}")
    cluster.close()


def _run_command(argv: list[str], seconds: float, folder: Path) -> tuple[float | None, int, str]:
    """Run ``argv`` for ``seconds``, then Ctrl-C it: (seconds to the first new file in
    ``folder``/npz, peak resident bytes, its stderr)."""
    npz = folder / "npz"
    before = len(os.listdir(npz)) if npz.is_dir() else 0
    t0 = time.perf_counter()
    # Ctrl-C's default disposition, even where this benchmark runs in the background (where
    # the shell has it ignored, and Python would not turn it into KeyboardInterrupt)
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    first = None
    with MemorySampler(proc.pid) as memory:
        while time.perf_counter() - t0 < seconds and proc.poll() is None:
            if first is None and npz.is_dir() and len(os.listdir(npz)) > before:
                first = time.perf_counter() - t0
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=300)
    return first, memory.peak, err.decode(errors="replace")


def command(args) -> None:
    print(f"\ncommand: plantgen batch saguaro --seeds 0:{args.command_plants} --outputs npz (default workers), "
          f"{args.command_seconds:.0f} s, Ctrl-C, then again")
    with tempfile.TemporaryDirectory() as tmp:
        argv = [sys.executable, "-m", "plantgen", "batch", "saguaro", "--seeds", f"0:{args.command_plants}",
                "--outputs", "npz", "--out", f"{tmp}/out"]
        for run in ("first", "again"):
            first, peak, err = _run_command(argv, args.command_seconds, Path(tmp) / "out")
            counts = re.findall(r"([\d,]+)/[\d,]+ \(([\d,]+) already done", err.replace("\r", "\n"))
            done, skipped = counts[-1] if counts else ("?", "?")
            made = len(list((Path(tmp) / "out" / "npz").glob("*.npz")))
            print(f"  {run:>5}: first new file after {first if first is None else round(first, 2)} s; peak RSS "
                  f"{peak / (1 << 20):.0f} MiB; {done} of the plants accounted for ({skipped} found done); "
                  f"{made:,} npz files")


def main(argv=None) -> int:
    from ..gl.context import renderer_name

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sections", nargs="*", default=["throughput", "scale", "command"],
                        choices=["throughput", "scale", "command"])
    parser.add_argument("--grammar", default="pine")
    parser.add_argument("--plants", type=int, default=12)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--workers", type=int, nargs="*", default=[1, 2])
    parser.add_argument("--scale", type=int, nargs="*", default=[10_000, 100_000])
    parser.add_argument("--scale-plants", type=int, default=2000)
    parser.add_argument("--scale-workers", type=int, default=2)
    parser.add_argument("--command-plants", type=int, default=1_000_000)
    parser.add_argument("--command-seconds", type=float, default=20.0)
    args = parser.parse_args(argv)
    print(f"GL renderer: {renderer_name()}")
    for section in args.sections:
        {"throughput": throughput, "scale": scale, "command": command}[section](args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
