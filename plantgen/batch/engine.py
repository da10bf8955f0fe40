"""Run a batch on Dask (dask.distributed): a ``LocalCluster`` of worker processes sized to
the machine by default, or an existing cluster by its scheduler's address.

The work streams: plants come one at a time from the spec (:meth:`BatchSpec.tasks`), a
plant the manifest lists as done is skipped, and the others are submitted as tasks with a
bounded number in flight (``as_completed``, one submitted as one finishes), so the
client's memory does not grow with the number of plants. Each plant is one task
(:func:`plantgen.batch.plant.make_plant`, ``pure=False``); Dask reschedules the tasks of a
worker that dies, and a plant's files depend only on its task, so the result does not
depend on which worker ran what. Rows go to the manifest's current part every
``save_every`` seconds (at most a tenth of the time) and at the end, Ctrl-C (and SIGTERM,
through the command) included.

Before any task is sent the client checks what it can: the output folder (made absolute:
a worker's working directory is its own), the manifest (one of another format is
refused), the scheduler's address (a short probe). Nothing is created before the cluster
answers.
"""

from __future__ import annotations

import itertools
import os
import tempfile
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import PlantgenError, missing_extra
from ..limits import Limits
from .manifest import MANIFEST_NAME, Manifest
from .plant import make_plant, output_kinds, plant_row
from .schema import METRIC_COLUMNS
from .spec import BatchError, BatchSpec

__all__ = ["BatchResult", "run_batch", "dask_client", "summary_lines", "tasks_in_flight", "CONNECT_SECONDS"]

#: Seconds to reach an existing scheduler before giving up.
CONNECT_SECONDS = 5
#: Failed rows a result keeps for its summary.
FAILURES_KEPT = 5


@dataclass
class BatchResult:
    """What a run did, kept up to date while it runs: plants in the spec, already done
    before (skipped), made now (ok), failed now, made again and why (``remade``: reason ->
    count, of the plants made now the manifest listed before), seconds in all, seconds
    before the first task was sent (``startup``: checks, the cluster) and to the first
    plant made, the dashboard's address, the manifest's path, the rows the manifest listed at the
    start and the first few failed rows."""

    total: int
    startup: float = 0.0
    skipped: int = 0
    done: int = 0
    failed: int = 0
    seconds: float = 0.0
    first_plant: float | None = None
    dashboard: str | None = None
    manifest: Path = Path(MANIFEST_NAME)
    listed: int = 0
    remade: dict = field(default_factory=dict)
    failures: list = field(default_factory=list)

    @property
    def rate(self) -> float:
        """Plants made (ok or failed) per second since the first task was sent."""
        busy = self.seconds - self.startup
        return (self.done + self.failed) / busy if busy > 0 else 0.0

    @property
    def finished(self) -> int:
        """Plants accounted for so far: skipped, made or failed."""
        return self.skipped + self.done + self.failed

    def record(self, row: dict, seconds: float) -> None:
        self.seconds = seconds
        if self.first_plant is None:
            self.first_plant = seconds
        if row["status"] == "ok":
            self.done += 1
        else:
            self.failed += 1
            if len(self.failures) < FAILURES_KEPT:
                self.failures.append({"id": row["id"], "error": row["error"]})


def _require_dask() -> None:
    try:
        import dask.distributed  # noqa: F401
        import pyarrow  # noqa: F401
    except ImportError:
        raise PlantgenError(missing_extra("plantgen batch", "batch")) from None


def _probe(scheduler: str) -> None:
    """One line unless a Dask scheduler answers at ``scheduler`` within CONNECT_SECONDS."""
    import asyncio

    from distributed.comm import connect

    async def reach():
        comm = await connect(scheduler, timeout=CONNECT_SECONDS)
        await comm.close()

    try:
        asyncio.get_running_loop()
        return                       # inside an event loop (a notebook): the Client itself says
    except RuntimeError:
        pass
    try:
        asyncio.run(reach())
    except (Exception, MemoryError) as exc:     # a bad address, a refusal, a time-out, something else answering
        text = str(exc).strip().splitlines()
        raise BatchError(f"--scheduler {scheduler}: cannot connect ({exc.__class__.__name__}"
                         f"{': ' + text[0][:200] if text else ''})") from None


#: The most worker processes a local cluster starts (each is a Python process of its own).
MAX_WORKERS = 256


def dask_client(scheduler: str | None, workers: int | None):
    """(client, cluster or None): a client of the cluster at ``scheduler``, or of a new
    ``LocalCluster`` of ``workers`` single-threaded processes (default: the CPU count)."""
    _require_dask()
    from dask.distributed import Client, LocalCluster

    if scheduler:
        _probe(scheduler)
        try:
            return Client(scheduler, timeout=f"{CONNECT_SECONDS}s"), None
        except (OSError, TimeoutError, ValueError) as exc:
            raise BatchError(f"--scheduler {scheduler}: cannot connect ({exc.__class__.__name__})") from None
    n = workers or max(os.cpu_count() or 1, 1)
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=50)
    return Client(cluster), cluster


def check_out_folder(folder: Path) -> None:
    """One line if the batch folder cannot be made or written (a file in the way, a
    read-only file system, no permission), before anything is made."""
    p = folder
    while not p.exists():
        if p.is_symlink():
            raise BatchError(f"{folder}: cannot write ('{p}' is a link to nothing)")
        p = p.parent
    if not p.is_dir():
        raise BatchError(f"{folder}: cannot write ('{p}' is not a folder)")
    try:
        read_only = bool(os.statvfs(p).f_flag & os.ST_RDONLY)
    except OSError:
        read_only = False
    if read_only:
        raise BatchError(f"{folder}: cannot write (read-only file system)")
    if not os.access(p, os.W_OK | os.X_OK):
        raise BatchError(f"{folder}: cannot write (permission denied in '{p}')")


def make_folders(folder: Path, spec: BatchSpec) -> None:
    """The batch folder, its manifest folder and one folder per output kind, each shown
    writable by a file made and removed there; one line for an OS error."""
    for path in (folder, folder / MANIFEST_NAME, *(folder / k for k in output_kinds(spec.outputs))):
        try:
            path.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryFile(dir=path, prefix=".plantgen-"):
                pass
        except OSError as exc:
            raise BatchError(f"{path}: cannot write ({exc.strerror or exc.__class__.__name__})") from None


def _to_make(spec: BatchSpec, manifest: Manifest, result: BatchResult, progress) -> Iterator:
    """The plants of ``spec`` still to make, one at a time; the rest counted as skipped,
    the plants made again counted by reason."""
    shown = time.perf_counter()
    for task in spec.tasks():
        reason = manifest.check(task, spec.outputs)
        if reason is None:
            result.skipped += 1
            if progress and time.perf_counter() - shown > 0.5:
                shown = time.perf_counter()
                progress(result)
            continue
        if reason != "new":
            result.remade[reason] = result.remade.get(reason, 0) + 1
        yield task


def tasks_in_flight(client) -> int:
    """Tasks kept in flight: four per worker thread of ``client``'s cluster (so none
    waits), at least 16."""
    try:
        threads = sum(client.nthreads().values())
    except Exception:   # a scheduler that does not say
        threads = 0
    return max(16, 4 * threads)


def run_batch(spec: BatchSpec, folder: str | Path, *, scheduler: str | None = None, workers: int | None = None,
              limits: Limits | None = None, progress: Callable[[BatchResult], None] | None = None,
              on_start: Callable[[str | None, BatchResult], None] | None = None, save_every: float = 2.0,
              client=None) -> BatchResult:
    """Make every plant of ``spec`` not done yet under ``folder``; returns a
    :class:`BatchResult`. ``progress(result)`` is called as plants finish (and while done
    plants are skipped); ``on_start(dashboard, result)`` once the cluster is up.
    ``client``: an existing ``dask.distributed.Client`` (tests, notebooks) instead of
    ``scheduler`` / ``workers``."""
    start = time.perf_counter()
    folder = Path(folder).absolute()
    if workers is not None and not 1 <= int(workers) <= MAX_WORKERS:
        raise BatchError(f"--workers must be 1..{MAX_WORKERS} worker processes, got {workers}")
    _require_dask()
    check_out_folder(folder)
    manifest = Manifest(folder)                 # one of another format: refused here
    result = BatchResult(spec.total, manifest=manifest.path, listed=len(manifest.index))
    own = client is None
    cluster = None
    flying: dict = {}
    made_folders = False
    try:
        if own:
            client, cluster = dask_client(scheduler, workers)
        make_folders(folder, spec)
        made_folders = True
        result.dashboard = getattr(client, "dashboard_link", None)
        if on_start:
            on_start(result.dashboard, result)
        _stream(client, spec, folder, manifest, result, limits, progress, save_every, flying, start)
    finally:
        if flying:
            client.cancel([f for f, _ in flying.values()])
        if made_folders:                 # nothing is written before the work starts
            manifest.close()
        if own and client is not None:
            client.close()
            if cluster is not None:
                cluster.close()
        result.seconds = time.perf_counter() - start
    return result


def _stream(client, spec: BatchSpec, folder: Path, manifest: Manifest, result: BatchResult, limits, progress,
            save_every: float, flying: dict, start: float) -> None:
    """Submit the plants still to make, a bounded number in flight, and record each row as
    it comes back."""
    from dask.distributed import as_completed

    run = uuid.uuid4().hex[:8]       # keys unique to this run (an interrupted run's may still be cancelling)
    todo = _to_make(spec, manifest, result, progress)
    finished = as_completed()

    def submit(n: int) -> None:
        for task in itertools.islice(todo, n):
            future = client.submit(make_plant, task, spec.outputs, str(folder), limits, spec.allow_paths,
                                   key=f"plant-{task.id}-{run}", pure=False, retries=1)
            flying[future.key] = (future, task)
            finished.add(future)

    result.startup = time.perf_counter() - start
    submit(tasks_in_flight(client))
    last_save, wait = time.perf_counter(), save_every
    for future in finished:
        _, task = flying.pop(future.key)
        row = _row_of(future, task)
        manifest.add(row)
        result.record(row, time.perf_counter() - start)
        if progress:
            progress(result)
        submit(1)
        now = time.perf_counter()
        if now - last_save >= wait:
            manifest.flush()
            last_save = time.perf_counter()
            wait = max(save_every, 10.0 * (last_save - now))     # a flush: under a tenth of the time


def _row_of(future, task) -> dict:
    """The future's manifest row; a task that raised (a bug, or workers that kept dying on
    it) becomes a failed row with its one-line error, and the batch goes on."""
    try:
        return future.result()
    except Exception as exc:
        text = str(exc).strip().splitlines()
        return plant_row(task, {}, f"{exc.__class__.__name__}: {text[0][:400] if text else ''}")


def summary_lines(result: BatchResult, quantiles: dict) -> list[str]:
    """A one-screen summary: counts, plants made again and why, failures, throughput and
    ``quantiles`` (figure -> 5th, 50th, 95th percentile: :func:`~plantgen.batch.manifest.figure_quantiles`)."""
    lines = [f"{result.total:,} plants: {result.done:,} made, {result.failed:,} failed, "
             f"{result.skipped:,} already done; {result.seconds:.1f} s, {result.rate:.2f} plants/s"]
    if result.remade:
        why = ", ".join(f"{n:,} {reason}" for reason, n in sorted(result.remade.items()))
        lines.append(f"made again: {sum(result.remade.values()):,} listed before ({why})")
    lines.append(f"manifest: {result.manifest}")
    if quantiles:
        lines.append(f"{'figure':<22}{'p5':>12}{'median':>12}{'p95':>12}")
        for k, (p5, p50, p95) in quantiles.items():
            unit = METRIC_COLUMNS.get(k, ("", ""))[1]
            name = f"{k} ({unit})" if unit else k
            lines.append(f"{name:<22}{p5:>12.4g}{p50:>12.4g}{p95:>12.4g}")
    lines += [f"failed: {r['id']}: {r['error']}" for r in result.failures]
    return lines
