"""``plantgen batch``: many plants on Dask, as a labelled dataset with a Parquet manifest."""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from pathlib import Path

import click

from ..batch import BatchError, parse_spec, run_batch, simple_spec, summary_lines
from ..batch.engine import MAX_WORKERS
from ..batch.spec import MASK_KINDS, MAX_VIEW_SIDE
from ..geometry.rays.scan import ScanSettings
from ..knobs import knob_of
from ..settings import MeshSettings
from .options import allow_path_opt, knob_option, knob_options, limit_opt, limits_from, quiet_opt, take_settings
from .progress import StageBars

__all__ = ["batch"]


@click.command()
@click.argument("source")
@click.option("--out", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Folder of the dataset: manifest.parquet (a folder of Parquet parts) and one folder per "
                   "output kind. A re-run skips the plants the manifest lists as done with the same settings.")
@click.option("--seeds", default=None, metavar="A:B",
              help="Without a spec: plant indices A..B-1 of the grammar SOURCE (each plant's seed "
                   "derives from --seed, the grammar and its index).")
@click.option("--outputs", default="npz", metavar="LIST", show_default=True,
              help="Without a spec: comma-separated outputs: npz, swc, glb, png, depth, mask, points (a "
                   "simulated laser scan as PLY, the scan knobs below; a spec may ask for LAS or LAZ).")
@click.option("--size", default=None, metavar="WxH",
              help=f"Without a spec: view size, sides 1..{MAX_VIEW_SIDE} (default 512x384).")
@click.option("--azimuths", default=None, metavar="LIST", help="Without a spec: view azimuths in degrees, "
              "comma-separated (default 0).")
@click.option("--relief/--no-relief", default=False, help="Without a spec: relief-map the views.")
@knob_option(knob_of(MeshSettings, "level"), MeshSettings().level, help="Without a spec: the glb's subdivision "
             "level m (16·4^m triangles per frustum, 8·2^m per cap).")
@click.option("--mask", type=click.Choice(MASK_KINDS), default="order", show_default=True,
              help="Without a spec: what the part mask labels.")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True,
              help="Without a spec: the batch seed.")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Run on an existing Dask cluster (e.g. tcp://host:8786) instead of a local one.")
@click.option("--workers", type=click.IntRange(1, MAX_WORKERS), default=None,
              help="Worker processes of the local cluster (default: one per CPU).")
@knob_options(ScanSettings)
@allow_path_opt
@limit_opt
@quiet_opt
def batch(source, out_dir, seeds, outputs, size, azimuths, relief, subdiv, mask, seed, scheduler, workers,
          allow_paths, limit_values, quiet, **scan_knobs) -> None:
    """Make many plants on Dask: SOURCE is a batch spec (.yaml with 'plants' and
    'outputs'; docs: how-to/batch.md) or, with --seeds, one grammar (a path or a shipped name).

    By default a LocalCluster of one single-threaded worker process per CPU runs the
    plants and stops at the end; --scheduler uses an existing cluster (--out must then be
    a folder every worker sees at the same absolute path). Plants stream: memory does not
    grow with their number. Each plant's files are written atomically; the manifest
    (Parquet parts, one row per plant, typed columns: seed, defines, files, tree figures in
    metres, timings, the error of a failed plant) is kept valid throughout, Ctrl-C and
    SIGTERM included, and a re-run makes only what is missing or was made with other
    settings. A spec reads grammars only from its own folder (and --allow-path folders).

    Exit status: 0 when every plant is made; 2 for a bad spec or option; otherwise 2 plus
    the number of plants that failed (at most 125), each a manifest row with its error.

    \b
    Examples:
      plantgen batch pine --seeds 0:1000 --outputs npz,png --out pines/
      plantgen batch my_dataset.yaml --out dataset/ --workers 2   # a spec you wrote
    """
    limits = limits_from(limit_values)
    if seeds is not None:
        az = None if azimuths is None else tuple(_floats(azimuths, "--azimuths"))
        spec = simple_spec(source, seeds, [o.strip() for o in outputs.split(",") if o.strip()], seed=seed,
                           size=size, azimuths=az and list(az), relief=relief, glb_level=subdiv, mask=mask,
                           limits=limits, scan=take_settings(ScanSettings, scan_knobs))
    else:
        if Path(source).suffix.lower() not in (".yaml", ".yml"):
            raise BatchError(f"{source}: give a batch spec (.yaml), or a grammar with --seeds A:B")
        spec = parse_spec(source, limits, allow_paths)

    def started(dashboard, result):
        if not quiet:
            click.echo(f"{result.total:,} plants (the manifest lists {result.listed:,})"
                       + (f"; Dask dashboard: {dashboard}" if dashboard else ""), err=True)

    with _sigterm_as_interrupt(), StageBars(enabled=not quiet) as bars:
        def progress(result):
            bars("plants", result.finished, result.total, f"{result.skipped:,} already done, {result.failed:,} "
                                                          f"failed, {result.rate:.2f} plants/s")

        result = run_batch(spec, out_dir, scheduler=scheduler, workers=workers, limits=limits, progress=progress,
                           on_start=started)
    if not quiet:
        from ..batch.manifest import figure_quantiles

        for line in summary_lines(result, figure_quantiles(result.manifest.parent)):
            click.echo(line)
    if result.failed:
        sys.exit(2 + min(result.failed, 123))


@contextlib.contextmanager
def _sigterm_as_interrupt():
    """SIGTERM raises KeyboardInterrupt, as Ctrl-C does, so the manifest is written before
    the process ends (in the main thread only; the previous handler is put back)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _floats(text: str, option: str) -> list[float]:
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise BatchError(f"{option}: {text!r} is not a comma-separated list of numbers") from None
