"""Streaming and resuming a batch (issue 28): a plant is done only if made with the same
settings (a fingerprint per row; the summary says how many were made again and why), a
bounded number of tasks in flight, the manifest written in parts (a plant's newest row
only, once a run ends or the next one starts), ``--out`` made absolute before a worker
sees it, SIGTERM handled as Ctrl-C."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from _cli import run_cli
from PIL import Image

pytest.importorskip("dask.distributed", reason="plantgen[batch] (dask.distributed) is not installed")
pytest.importorskip("pyarrow", reason="plantgen[batch] (pyarrow) is not installed")

import pyarrow.parquet as pq  # noqa: E402
from test_batch import TWIG, rows_of, write_spec  # noqa: E402

from plantgen.batch import manifest as manifest_module  # noqa: E402
from plantgen.batch import parse_spec, run_batch, simple_spec, summary_lines  # noqa: E402
from plantgen.batch.engine import tasks_in_flight  # noqa: E402
from plantgen.batch.manifest import MANIFEST_NAME, Manifest, read_manifest  # noqa: E402
from plantgen.batch.plant import plant_row  # noqa: E402


def twig_spec(folder: Path, outputs: list[str], seeds: str = "0:5", **kw):
    path = folder / "twig.yaml"
    if not path.exists():
        path.write_text(TWIG)
    return simple_spec(str(path), seeds, outputs, **kw)


def test_a_rerun_makes_again_what_other_settings_made(tmp_path, client):
    out = tmp_path / "out"
    first = run_batch(twig_spec(tmp_path, ["npz"]), out, client=client)
    assert (first.done, first.remade) == (5, {})
    steps = [  # (spec, what the re-run must report)
        (twig_spec(tmp_path, ["npz", "png"], size="48x36"), {"other settings": 5}),     # png added
        (twig_spec(tmp_path, ["npz", "png"], size="48x36"), {}),                         # the same: all done
        (twig_spec(tmp_path, ["npz", "png"], size="64x48"), {"other settings": 5}),     # a new size
    ]
    for spec, remade in steps:
        result = run_batch(spec, out, client=client)
        assert result.remade == remade and result.done == sum(remade.values())
        assert result.skipped == 5 - result.done
    assert {np.asarray(Image.open(p)).shape for p in (out / "png").glob("*.png")} == {(48, 64, 3)}
    (tmp_path / "twig.yaml").write_text(TWIG.replace("a: 28", "a: 31"))             # the grammar edited
    (out / "npz" / "twig-000003.npz").unlink()
    result = run_batch(twig_spec(tmp_path, ["npz", "png"], size="64x48"), out, client=client)
    assert result.remade == {"other settings": 5}
    rows = rows_of(out)
    assert len(read_manifest(out)) == len(rows) == 5                 # one row per plant: old rows taken out
    assert len({r["fingerprint"] for r in rows.values()}) == 1
    (out / "png" / "twig-000002_a000.png").unlink()
    again = run_batch(twig_spec(tmp_path, ["npz", "png"], size="64x48"), out, client=client)
    assert (again.remade, again.skipped) == ({"files missing": 1}, 4)
    assert "made again: 1 listed before (1 files missing)" in summary_lines(again, {})


def test_failed_plants_are_made_again_and_listed_once(tmp_path, client):
    spec = parse_spec(write_spec(tmp_path, seeds="0:2", sweep={"grid": {"l": [0.5, 1.0e300]}}, outputs={"npz": True}))
    assert run_batch(spec, tmp_path / "out", client=client).failed == 2
    again = run_batch(spec, tmp_path / "out", client=client)
    assert (again.skipped, again.failed, again.remade) == (2, 2, {"failed before": 2})
    assert len(read_manifest(tmp_path / "out")) == 4


def test_the_command_says_why_plants_are_made_again(tmp_path):
    """The issue's case: --outputs npz, then npz,png into the same folder."""
    args = ("batch", "saguaro", "--seeds", "0:5", "--out", tmp_path / "out", "--workers", "1", "--size", "48x36")
    assert run_cli(*args, "--outputs", "npz")[0] == 0
    code, text, err = run_cli(*args, "--outputs", "npz,png")
    assert code == 0, err
    assert "5 plants: 5 made, 0 failed, 0 already done" in text
    assert "made again: 5 listed before (5 other settings)" in text
    assert len(list((tmp_path / "out" / "png").glob("*.png"))) == 5


class CountingClient:
    """A client that counts the tasks in flight (submitted, not yet reported finished)."""

    def __init__(self, client):
        self.client, self.flying, self.peak = client, 0, 0

    def submit(self, *args, **kw):
        self.flying += 1
        self.peak = max(self.peak, self.flying)
        return self.client.submit(*args, **kw)

    def __getattr__(self, name):
        return getattr(self.client, name)


def test_tasks_in_flight_are_bounded_and_the_manifest_comes_in_parts(tmp_path, client, monkeypatch):
    monkeypatch.setattr(manifest_module, "PART_ROWS", 7)
    counting = CountingClient(client)

    def finished(result):
        counting.flying -= 1

    spec = twig_spec(tmp_path, ["npz"], seeds="0:40")
    result = run_batch(spec, tmp_path / "out", client=counting, progress=finished, save_every=0.0)
    assert result.done == 40
    assert 0 < counting.peak <= tasks_in_flight(client) < 40
    parts = sorted((tmp_path / "out" / MANIFEST_NAME).iterdir())
    sizes = [len(pq.read_table(p)) for p in parts]
    assert len(parts) >= 2 and all(p.name.startswith("part-") for p in parts)
    assert sum(sizes) == 40 and min(sizes[:-1]) >= 7          # a part is left once it holds PART_ROWS rows
    assert sorted(rows_of(tmp_path / "out")) == [t.id for t in spec.tasks()]


def test_a_relative_out_is_the_clients_not_the_workers(tmp_path, client, monkeypatch):
    """The workers started elsewhere (another working directory): the files land in the
    folder the client named."""
    here = tmp_path / "here"
    here.mkdir()
    spec = twig_spec(tmp_path, ["npz"], seeds="0:3")
    monkeypatch.chdir(here)
    result = run_batch(spec, "rel/out", client=client)
    assert result.done == 3 and result.manifest == here / "rel" / "out" / MANIFEST_NAME
    assert len(list((here / "rel" / "out" / "npz").glob("*.npz"))) == 3


def test_rows_a_killed_run_left_twice_are_listed_once(tmp_path):
    spec = twig_spec(tmp_path, ["npz"], seeds="0:3")
    tasks = list(spec.tasks())
    first = Manifest(tmp_path)
    for t in tasks:
        first.add(plant_row(t, {}))
    first.close()
    killed = Manifest(tmp_path)                      # a run killed after its first flush: no close
    killed.add({**plant_row(tasks[1], {}), "status": "failed", "error": "x"})
    killed.flush()
    rows = rows_of(tmp_path)
    assert len(rows) == 3 and rows[tasks[1].id]["status"] == "failed"          # the newest row
    nxt = Manifest(tmp_path)
    assert len(nxt.index) == 3 and len(nxt.index.stale) == 1
    nxt.close()
    assert len(pq.read_table(tmp_path / MANIFEST_NAME)) == 3


def test_sigterm_writes_the_manifest_as_ctrl_c_does(tmp_path):
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "plantgen", "batch", "saguaro", "--seeds", "0:2000",
                             "--outputs", "npz", "--workers", "1", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and len(list((out / "npz").glob("*.npz")) if (out / "npz").is_dir()
                                                  else []) < 3:
            time.sleep(0.05)
        assert proc.poll() is None, "the batch ended before it was sent SIGTERM"
        proc.send_signal(signal.SIGTERM)
        _, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130 and stderr.decode().strip().splitlines()[-1] == "plantgen: aborted"
    rows = rows_of(out)
    files = list((out / "npz").glob("*.npz"))
    assert len(rows) >= 1 and len(files) - len(rows) <= tasks_in_flight(None)        # at most the tasks in flight
    assert all((out / r["files"]["npz"]).is_file() for r in rows.values())
    top = max(r["index"] for r in rows.values()) + 1
    again = run_batch(simple_spec("saguaro", f"0:{top}", ["npz"]), out, workers=1)
    assert again.skipped == len(rows) and again.skipped + again.done == top


def test_readers_leave_a_running_batchs_temporary_part_alone(tmp_path):
    spec = twig_spec(tmp_path, ["npz"], seeds="0:2")
    manifest = Manifest(tmp_path)
    for t in spec.tasks():
        manifest.add(plant_row(t, {}))
    manifest.flush()
    writing = tmp_path / MANIFEST_NAME / ".part-000001.parquet.part.parquet"     # a part being written
    writing.write_bytes(b"half")
    assert len(read_manifest(tmp_path)) == 2 and writing.exists()
    Manifest(tmp_path)                                # a run starting: what a killed run left goes
    assert not writing.exists()
