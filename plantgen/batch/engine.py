"""Run a batch on Dask (dask.distributed): a ``LocalCluster`` of worker processes sized to
the machine by default, or an existing cluster by its scheduler's address.

Each plant is one task (:func:`plantgen.batch.plant.make_plant`, ``pure=False``), so
Dask balances them, and reschedules the tasks of a worker that dies; a plant's files
depend only on its task, so the result does not depend on which worker ran what. The
manifest is rewritten (atomically) at most every ``save_every`` seconds (and at most a
tenth of the time: a save rewrites every row, 0.6 s at 100,000 rows) and at the end,
Ctrl-C included, and a re-run skips every plant it lists as done.
"""

from __future__ import annotations

import os
import statistics
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import PlantgenError
from ..limits import Limits
from .manifest import Manifest
from .plant import make_plant, plant_row, relative_files
from .schema import METRIC_COLUMNS
from .spec import BatchSpec

__all__ = ["BatchResult", "run_batch", "dask_client"]


@dataclass
class BatchResult:
    """What a run did: plants in the spec, already done before, made now (ok), failed
    now, seconds, the dashboard address, the manifest's path and the rows made now."""

    total: int
    skipped: int
    done: int
    failed: int
    seconds: float
    dashboard: str | None
    manifest: Path
    rows: list = field(default_factory=list)

    @property
    def rate(self) -> float:
        """Plants made (ok or failed) per second of this run."""
        return (self.done + self.failed) / self.seconds if self.seconds > 0 else 0.0


def _require_dask() -> None:
    try:
        import dask.distributed  # noqa: F401
        import pyarrow  # noqa: F401
    except ImportError:
        raise PlantgenError("plantgen batch needs the batch extra: pip install 'plantgen[batch]'") from None


def dask_client(scheduler: str | None, workers: int | None):
    """(client, cluster or None): a client of the cluster at ``scheduler``, or of a new
    ``LocalCluster`` of ``workers`` single-threaded processes (default: the CPU count)."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise PlantgenError("plantgen batch needs the batch extra: pip install 'plantgen[batch]'") from None
    if scheduler:
        try:
            return Client(scheduler, timeout="20s"), None
        except (OSError, TimeoutError) as exc:
            raise PlantgenError(f"--scheduler {scheduler}: cannot connect ({exc.__class__.__name__})") from None
    n = workers or max(os.cpu_count() or 1, 1)
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=50)
    return Client(cluster), cluster


def _prepare(spec: BatchSpec, folder: Path) -> tuple[Manifest, list]:
    folder.mkdir(parents=True, exist_ok=True)
    manifest = Manifest(folder)
    todo = [t for t in spec.tasks if not manifest.done(t, spec.outputs, folder)]
    kinds = {k for t in todo[:1] for k in relative_files(t, spec.outputs)}
    for kind in kinds:
        (folder / kind).mkdir(exist_ok=True)
    return manifest, todo


def run_batch(spec: BatchSpec, folder: str | Path, *, scheduler: str | None = None, workers: int | None = None,
              limits: Limits | None = None, progress: Callable[[int, int, int, float], None] | None = None,
              on_start: Callable[[str | None, int, int], None] | None = None, save_every: float = 2.0,
              client=None) -> BatchResult:
    """Make every plant of ``spec`` not done yet under ``folder``; returns a
    :class:`BatchResult`. ``progress(done, failed, to_do, plants_per_second)`` is called
    as plants finish; ``on_start(dashboard, to_do, skipped)`` once the cluster is up.
    ``client``: an existing ``dask.distributed.Client`` (tests, notebooks) instead of
    ``scheduler`` / ``workers``."""
    folder = Path(folder)
    if client is None:
        _require_dask()              # before anything is written
    manifest, todo = _prepare(spec, folder)
    skipped = len(spec.tasks) - len(todo)
    own = client is None
    cluster = None
    if own and todo:
        client, cluster = dask_client(scheduler, workers)
    dashboard = getattr(client, "dashboard_link", None) if todo else None
    if on_start:
        on_start(dashboard, len(todo), skipped)
    t0 = time.perf_counter()
    made: list = []
    failed = 0
    futures = []
    try:
        if todo:
            from dask.distributed import as_completed

            # keys unique to this run: a run after an interrupt on the same cluster must not
            # share keys with the futures the interrupted run is still cancelling
            run = uuid.uuid4().hex[:8]
            futures = client.map(make_plant, todo, outputs=spec.outputs, out_dir=str(folder), limits=limits,
                                 pure=False, key=[f"plant-{t.id}-{run}" for t in todo], retries=1)
            task_of = dict(zip((f.key for f in futures), todo, strict=True))
            last_save, wait = time.perf_counter(), save_every
            for future in as_completed(futures):
                row = _row_of(future, task_of[future.key])
                manifest.add(row)
                made.append(row)
                failed += row["status"] != "ok"
                now = time.perf_counter()
                if progress:
                    progress(len(made) - failed, failed, len(todo), len(made) / max(now - t0, 1e-9))
                if now - last_save >= wait:
                    manifest.save()
                    last_save = time.perf_counter()
                    # a save rewrites every row: keep it under a tenth of the run's time
                    wait = max(save_every, 10.0 * (last_save - now))
    finally:
        if futures:
            client.cancel(futures)
        manifest.save()
        if own and client is not None and todo:
            client.close()
            if cluster is not None:
                cluster.close()
    return BatchResult(len(spec.tasks), skipped, len(made) - failed, failed, time.perf_counter() - t0,
                       dashboard, manifest.path, made)


def _row_of(future, task) -> dict:
    """The future's manifest row; a task that raised (a bug, or workers that kept dying on
    it) becomes a failed row with its one-line error, and the batch goes on."""
    try:
        return future.result()
    except Exception as exc:
        text = str(exc).strip().splitlines()
        return plant_row(task, {}, f"{exc.__class__.__name__}: {text[0][:400] if text else ''}")


def summary_lines(result: BatchResult, rows: list) -> list[str]:
    """A one-screen summary: counts, failures, throughput and percentiles of the metrics of
    ``rows`` (the manifest's ok rows)."""
    lines = [f"{result.total:,} plants: {result.done:,} made, {result.failed:,} failed, "
             f"{result.skipped:,} already done; {result.seconds:.1f} s, {result.rate:.2f} plants/s",
             f"manifest: {result.manifest}"]
    ok = [r for r in rows if r.get("status") == "ok"]
    shown = ("segments", "scan_points", *METRIC_COLUMNS)
    columns = {k: [float(r[k]) for r in ok if r.get(k) is not None] for k in shown}
    if ok:
        lines.append(f"{'metric':<22}{'p5':>12}{'median':>12}{'p95':>12}")
        for k, values in columns.items():
            if len(values) >= 1:
                unit = METRIC_COLUMNS.get(k, ("", ""))[1]
                qs = statistics.quantiles(values, n=20) if len(values) > 1 else [values[0]] * 19
                name = f"{k} ({unit})" if unit else k
                lines.append(f"{name:<22}{qs[0]:>12.4g}{statistics.median(values):>12.4g}{qs[-1]:>12.4g}")
    errors = [r for r in result.rows if r.get("status") != "ok"][:5]
    lines += [f"failed: {r['id']}: {r['error']}" for r in errors]
    return lines
