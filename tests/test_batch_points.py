"""Issue 27, simulated laser scans in a dataset: ``points`` among a batch's outputs. A row's
file is the scan ``plantgen scan`` makes of the same plant with the same knobs (its noise
drawn from the plant's seed); its points lie on the plant's surface and carry their
labels; LAS/LAZ read back with laspy; bad knobs are one line before any work."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from _cli import run_cli
from _scan_helpers import labelled_residuals

pytest.importorskip("dask.distributed", reason="plantgen[batch] (dask.distributed) is not installed")
pytest.importorskip("pyarrow", reason="plantgen[batch] (pyarrow) is not installed")

from test_batch import TWIG  # noqa: E402

from plantgen.batch import parse_spec, run_batch  # noqa: E402
from plantgen.batch.manifest import read_manifest  # noqa: E402
from plantgen.pipeline import grow_file, skin_model  # noqa: E402
from plantgen.scanfiles import read_points  # noqa: E402

NOISE = 0.001
KNOBS = {"angular_step": 0.5, "range_noise": NOISE, "scanners": 3}


def spec_file(folder: Path, points, seeds="0:2") -> Path:
    (folder / "twig.yaml").write_text(TWIG)
    path = folder / "spec.yaml"
    path.write_text(yaml.safe_dump({"seed": 3, "plants": [{"grammar": "twig.yaml", "seeds": seeds}],
                                    "outputs": {"npz": True, "points": points}}))
    return path


def test_a_rows_points_are_the_scan_plantgen_scan_makes_of_that_plant(tmp_path, client):
    pytest.importorskip("laspy", reason="plantgen[scan] (laspy) is not installed: LAZ needs it")
    import laspy

    spec = spec_file(tmp_path, {"format": "laz", **KNOBS})
    result = run_batch(parse_spec(spec), tmp_path / "out", client=client)
    assert (result.done, result.failed) == (2, 0)
    rows = read_manifest(tmp_path / "out").to_pylist()
    for row in rows:
        path = tmp_path / "out" / row["files"]["points"]
        assert path.suffix == ".laz" and row["timings"]["scan"] > 0
        cloud = read_points(path)
        assert len(cloud) == row["scan_points"] > 100
        # the same plant scanned by the command, with the same knobs and the plant's seed
        code, _, err = run_cli("scan", tmp_path / "twig.yaml", "--seed", row["seed"], "--scan-seed", row["seed"],
                               "--angular-step", KNOBS["angular_step"], "--range-noise", NOISE, "--scanners",
                               KNOBS["scanners"], "--up", "z", "-q", "-o", tmp_path / "alone.laz")
        assert code == 0, err
        alone = read_points(tmp_path / "alone.laz")
        assert np.array_equal(cloud.xyz, alone.xyz)
        for label in ("plant", "part", "order", "segment", "scanner"):
            assert np.array_equal(getattr(cloud, label), getattr(alone, label)), label
        # on the plant's surface within the noise (distances from the frusta's definition)
        frusta = skin_model(grow_file(tmp_path / "twig.yaml", seed=row["seed"]))
        assert np.quantile(labelled_residuals(frusta, cloud, 1e-6), 0.99) < 4 * NOISE
        # and another project's reader sees the labels as extra dimensions
        las = laspy.read(path)
        assert len(las.points) == row["scan_points"]
        assert {"plant", "part", "segment"} <= set(las.point_format.extra_dimension_names)
    seeds = [r["seed"] for r in rows]
    assert len(set(seeds)) == 2        # two plants, two seeds: two different scans
    a, b = (read_points(tmp_path / "out" / r["files"]["points"]) for r in rows)
    assert len(a) != len(b) or not np.array_equal(a.xyz, b.xyz)


def test_the_command_line_writes_ply_with_the_scan_options(tmp_path):
    out = tmp_path / "out"
    code, stdout, err = run_cli("batch", "saguaro", "--seeds", "0:1", "--outputs", "npz,points",
                                "--angular-step", "1", "--workers", "1", "-q", "--out", out)
    assert code == 0, err
    (row,) = read_manifest(out).to_pylist()
    cloud = read_points(out / row["files"]["points"])
    assert row["files"]["points"].endswith(".ply") and len(cloud) == row["scan_points"] > 0
    assert set(np.unique(cloud.part)) <= {0, 1}          # stem and branches: the saguaro has no leaves


@pytest.mark.parametrize("points, words", [({"format": "xyz"}, "format"), ({"angular_step": -1}, "angular"),
                                           ({"bogus": 1}, "bogus")])
def test_bad_scan_knobs_in_a_spec_are_one_line_before_any_work(tmp_path, points, words):
    spec = spec_file(tmp_path, points)
    code, _, err = run_cli("batch", spec, "--out", tmp_path / "out", "-q")
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "points" in lines[0] and words in lines[0], err
    assert not (tmp_path / "out").exists()


def test_a_bad_scan_option_is_one_line(tmp_path):
    code, _, err = run_cli("batch", "saguaro", "--seeds", "0:1", "--outputs", "points", "--angular-step", "-1",
                           "--out", tmp_path / "out")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--angular-step" in err
    assert not (tmp_path / "out").exists()


def test_a_rerun_with_other_scan_knobs_scans_again_and_an_npz_batch_does_not_care(tmp_path):
    """The scan's knobs are part of a row's fingerprint where there are points, and only
    there: a coarser --angular-step makes the points again, the same knobs skip them, and
    an npz-only batch is done whatever the scan options say."""
    def run(out, *args):
        code, stdout, err = run_cli("batch", "saguaro", "--seeds", "0:1", "--workers", "1", "--out", out, *args)
        assert code == 0, err
        return read_manifest(out).to_pylist(), stdout + err

    (first,), _ = run(tmp_path / "p", "--outputs", "npz,points", "--angular-step", "1")
    (same,), text = run(tmp_path / "p", "--outputs", "npz,points", "--angular-step", "1")
    assert same["fingerprint"] == first["fingerprint"] and "1 already done" in text
    (coarser,), text = run(tmp_path / "p", "--outputs", "npz,points", "--angular-step", "2")
    assert coarser["fingerprint"] != first["fingerprint"] and "made again" in text
    assert 0 < coarser["scan_points"] < first["scan_points"]
    run(tmp_path / "n", "--outputs", "npz", "--angular-step", "1")
    _, text = run(tmp_path / "n", "--outputs", "npz", "--angular-step", "2")
    assert "1 already done" in text and "made again" not in text
