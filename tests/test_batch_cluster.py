"""``plantgen batch --scheduler`` on a real cluster started by hand, as a user would: a
``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1 (ports the system picks),
one worker killed mid-batch. Nothing is lost: every plant is ok, and the files are those
of a clean local run. The client runs in another working directory than the workers and
names ``--out`` relative to its own: the files land there."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("dask.distributed", reason="plantgen[batch] (dask.distributed) is not installed")
pytest.importorskip("pyarrow", reason="plantgen[batch] (pyarrow) is not installed")

from test_batch import dataset, rows_of  # noqa: E402

PLANTS = 32
#: Seconds any one step may take on a loaded machine before the test gives up.
STEP = 90


def _dask_command() -> list[str]:
    """The ``dask`` command of this Python (its console script beside the interpreter)."""
    script = Path(sys.executable).with_name("dask")
    if script.is_file():
        return [str(script)]
    return [sys.executable, "-m", "dask"]


def _wait_for(predicate, what: str, timeout: float = STEP, step: float = 0.05):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(step)
    raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")


def _stop(proc: subprocess.Popen) -> None:
    """End a process this test started: SIGTERM, then SIGKILL if it lingers."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)


@pytest.fixture
def cluster(tmp_path):
    """(scheduler address, [worker processes]): a scheduler and two single-threaded workers
    without nannies (a killed worker stays dead), on 127.0.0.1 only; all ended at teardown."""
    procs: list[subprocess.Popen] = []
    log = open(tmp_path / "cluster.log", "wb")          # noqa: SIM115 (closed at teardown)
    try:
        info = tmp_path / "scheduler.json"
        procs.append(subprocess.Popen([*_dask_command(), "scheduler", "--host", "127.0.0.1", "--port", "0",
                                       "--no-dashboard", "--scheduler-file", str(info)],
                                      stdout=log, stderr=log, cwd=tmp_path))
        address = _wait_for(lambda: info.is_file() and json.loads(info.read_text() or "{}").get("address"),
                            "the scheduler's address")
        assert address.startswith("tcp://127.0.0.1:")
        procs += [subprocess.Popen([*_dask_command(), "worker", address, "--name", name, "--nthreads", "1",
                                    "--no-nanny", "--host", "127.0.0.1", "--no-dashboard", "--death-timeout", "60"],
                                   stdout=log, stderr=log, cwd=tmp_path) for name in ("w0", "w1")]
        from dask.distributed import Client

        with Client(address, timeout=STEP) as client:
            client.wait_for_workers(2, timeout=STEP)
        yield address, procs[1:]
    finally:
        for proc in reversed(procs):
            _stop(proc)
        log.close()


def _batch(*args, cwd=None) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "plantgen", "batch", "saguaro", "--seeds", f"0:{PLANTS}",
                             "--outputs", "npz,png", "--size", "96x72", *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=cwd)


def test_a_worker_killed_mid_batch_on_a_real_cluster_loses_nothing(tmp_path, cluster):
    address, workers = cluster
    here = tmp_path / "client"        # the workers run in tmp_path: a relative --out is the client's
    here.mkdir()
    out = here / "out"
    batch = _batch("--out", "out", "--scheduler", address, cwd=here)
    try:
        _wait_for(lambda: len(list((out / "png").glob("*.png"))) >= 2 if (out / "png").is_dir() else False,
                  "the first plants")
        made_before_kill = len(list((out / "png").glob("*.png")))
        assert batch.poll() is None and made_before_kill < PLANTS, "the batch ended before a worker was killed"
        os.kill(workers[0].pid, signal.SIGKILL)
        workers[0].wait(timeout=STEP)
        stdout, stderr = batch.communicate(timeout=3 * STEP)
    finally:
        _stop(batch)
    assert batch.returncode == 0, stderr.decode(errors="replace")[-2000:]
    assert f"{PLANTS} plants: {PLANTS} made, 0 failed" in stdout.decode()
    rows = rows_of(out)
    assert len(rows) == PLANTS and all(r["status"] == "ok" for r in rows.values())

    local = _batch("--out", tmp_path / "local", "--workers", "1", "-q")
    try:
        _, stderr = local.communicate(timeout=3 * STEP)
    finally:
        _stop(local)
    assert local.returncode == 0, stderr.decode(errors="replace")[-2000:]
    assert dataset(out) == dataset(tmp_path / "local")
