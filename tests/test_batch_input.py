"""Bad batch input before any work (issue 28): sizes computed before anything is built
(seed ranges, grid products), grammar paths kept inside the spec's folder (the rule and
``--allow-path`` of scenes; an audit hook shows nothing outside is opened), and every OS
or address problem with the output or the scheduler one line with exit status 2, nothing
made. None of these starts a cluster."""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
import yaml
from _cli import run_cli

pytest.importorskip("dask.distributed", reason="plantgen[batch] (dask.distributed) is not installed")
pytest.importorskip("pyarrow", reason="plantgen[batch] (pyarrow) is not installed")

from test_batch import TWIG  # noqa: E402
from test_hostile import assert_refused, run_cases, write  # noqa: E402

from plantgen.batch import BatchError, parse_spec, simple_spec  # noqa: E402
from plantgen.batch.spec import DRAW_CHUNK, MAX_PLANTS, Sweep  # noqa: E402
from plantgen.errors import PlantgenError  # noqa: E402
from plantgen.files import write_atomically  # noqa: E402


def spec_file(folder: Path, plants: list, name: str = "spec.yaml", outputs=None) -> Path:
    return write(folder, name, yaml.safe_dump({"seed": 1, "plants": plants, "outputs": outputs or {"npz": True}}))


def one_line(code: int, err: str) -> str:
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, (code, err)
    return lines[0]


# ---------------------------------------------------------------------- sizes before work
def test_a_ten_million_plant_spec_is_counted_not_built():
    tracemalloc.start()
    try:
        spec = simple_spec("saguaro", "0:10000000", ["npz"])
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert spec.total == MAX_PLANTS
    assert peak < 4 << 20                                     # a few objects, not ten million
    first = [t.id for t, _ in zip(spec.tasks(), range(3), strict=False)]
    assert first == ["saguaro-000000", "saguaro-000001", "saguaro-000002"]
    with pytest.raises(BatchError, match="over the 10,000,000"):
        simple_spec("saguaro", "0:10000001", ["npz"])


def test_a_grid_of_a_trillion_points_is_refused_before_it_is_built(tmp_path):
    """The issue's spec: 49 KB, a grid of 10^12 points through YAML aliases."""
    values = ", ".join(str(i) for i in range(1, 10_001))
    text = f"plants:\n  - grammar: saguaro\n    sweep: {{grid: {{a: &v [{values}], b: *v, c: *v}}}}\n"
    big = write(tmp_path, "grid.yaml", text)
    assert 45_000 < big.stat().st_size < 60_000
    overflow = spec_file(tmp_path, [{"grammar": "saguaro", "seeds": "0:1000", "sweep": {"grid": {"a": list(range(
        100)), "b": list(range(200))}}}], "overflow.yaml")           # 20,000 points x 1,000 seeds
    results = run_cases(tmp_path, [["batch", big, "--out", tmp_path / "a"],
                                   ["batch", overflow, "--out", tmp_path / "b"]])
    assert_refused(results[0], ("1,000,000,000,000 points", "10,000,000"), outputs=[tmp_path / "a"])
    assert_refused(results[1], ("20,000,000 plants", "10,000,000"), outputs=[tmp_path / "b"])


def test_random_draws_do_not_depend_on_how_they_are_made():
    sweep = Sweep(("a", "b"), bounds=((0.0, 1.0), (10.0, 20.0)), count=2 * DRAW_CHUNK + 7, key="k")
    points = list(sweep.points())
    rng = np.random.default_rng(int.from_bytes(__import__("hashlib").blake2b(b"k", digest_size=8).digest(), "little"))
    reference = rng.uniform(0.0, 1.0, (sweep.count, 2))
    assert len(points) == sweep.count
    assert np.array_equal(np.array([[v for _, v in p] for p in points]), reference * [1.0, 10.0] + [0.0, 10.0])


def test_entries_whose_ids_would_clash_are_refused(tmp_path):
    write(tmp_path, "x.yaml", TWIG)
    write(tmp_path, "sub/x.yaml", TWIG)
    write(tmp_path, "x-s0001.yaml", TWIG)
    cases = {
        "same file twice": [{"grammar": "x.yaml", "seeds": "0:5"}, {"grammar": "x.yaml", "seeds": "4:8"}],
        "same stem": [{"grammar": "x.yaml", "seeds": "0:5"}, {"grammar": "sub/x.yaml", "seeds": "0:1"}],
        "sweep id": [{"grammar": "x.yaml", "seeds": "0:5", "sweep": {"grid": {"a": [1, 2]}}},
                     {"grammar": "x-s0001.yaml", "seeds": "3:4"}],
    }
    for i, plants in enumerate(cases.values()):
        with pytest.raises(BatchError, match=r"plants\[1\]: its plants' ids .* plants\[0\]"):
            parse_spec(spec_file(tmp_path, plants, f"c{i}.yaml"))
    fine = parse_spec(spec_file(tmp_path, [{"grammar": "x.yaml", "seeds": "0:5"}, {"grammar": "x.yaml",
                                                                                   "seeds": "5:9"}], "ok.yaml"))
    ids = [t.id for t in fine.tasks()]
    assert fine.total == len(set(ids)) == 9


# ---------------------------------------------------------------------- paths stay in the folder
def test_a_spec_reads_grammars_only_inside_its_folder(tmp_path):
    """../x, /etc/passwd, /proc/self/environ, a link out, an absolute path elsewhere: one
    line naming --allow-path, and nothing outside the spec's folder opened (audit hook)."""
    specs = tmp_path / "specs"
    elsewhere = write(tmp_path, "elsewhere/tree.yaml", TWIG)
    specs.mkdir()
    (specs / "link.yaml").symlink_to(elsewhere)
    refs = ["../elsewhere/tree.yaml", "../../../../../../etc/passwd", "/etc/passwd", "/proc/self/environ",
            "link.yaml", str(elsewhere)]
    cases = [["batch", spec_file(specs, [{"grammar": ref}], f"s{i}.yaml"), "--out", tmp_path / f"out{i}"]
             for i, ref in enumerate(refs)]
    results = run_cases(tmp_path, cases)
    for i, result in enumerate(results):
        assert_refused(result, ("outside the spec's folder", "--allow-path"), outputs=[tmp_path / f"out{i}"])
        outside = [p for p in result["opened"] if not p.startswith(str(specs))]
        assert outside == [], outside           # the grammar elsewhere, /etc/passwd: never opened
    allowed = parse_spec(specs / "s0.yaml", allow_paths=[elsewhere.parent])
    assert next(allowed.tasks()).grammar == str(elsewhere.resolve())
    assert parse_spec(spec_file(specs, [{"grammar": "saguaro"}], "shipped.yaml")).total == 1


def test_the_command_takes_allow_path(tmp_path):
    specs = tmp_path / "specs"
    elsewhere = write(tmp_path, "elsewhere/tree.yaml", TWIG)
    spec = spec_file(specs, [{"grammar": "../elsewhere/tree.yaml"}])
    code, _, err = run_cli("batch", spec, "--out", tmp_path / "out", "--scheduler", "garbage://x")
    assert "outside the spec's folder" in one_line(code, err)
    code, _, err = run_cli("batch", spec, "--out", tmp_path / "out", "--allow-path", elsewhere.parent,
                           "--scheduler", "garbage://x")
    assert "--scheduler garbage://x" in one_line(code, err)       # past the paths, to the scheduler


# ---------------------------------------------------------------------- output and scheduler problems
def test_an_out_folder_under_a_file_is_one_line(tmp_path):
    (tmp_path / "file").write_text("x")
    for out in (tmp_path / "file", tmp_path / "file" / "sub"):
        code, _, err = run_cli("batch", "saguaro", "--seeds", "0:2", "--out", out, "-q")
        assert str(tmp_path / "file") in one_line(code, err)
    assert (tmp_path / "file").read_text() == "x"


@pytest.fixture
def read_only_folder(tmp_path):
    """A folder on a read-only file system (a tmpfs mounted read-only), unmounted after."""
    folder = tmp_path / "ro"
    folder.mkdir()
    if shutil.which("mount") is None or os.geteuid() != 0:
        pytest.skip("mounting a read-only tmpfs needs root and mount(8)")
    proc = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(folder)], capture_output=True)
    if proc.returncode != 0:
        pytest.skip(f"cannot mount a read-only tmpfs here: {proc.stderr.decode(errors='replace').strip()}")
    try:
        yield folder
    finally:
        subprocess.run(["umount", str(folder)], check=False)


def test_a_read_only_file_system_is_one_line(read_only_folder):
    code, _, err = run_cli("batch", "saguaro", "--seeds", "0:2", "--out", read_only_folder / "out", "-q")
    assert "read-only file system" in one_line(code, err)
    # write_atomically's own clean-up (unlinking the temporary name) fails there too: still one line
    with pytest.raises(PlantgenError) as caught:
        write_atomically(read_only_folder / "x.bin", lambda tmp: tmp.write_bytes(b"x"))
    assert "x.bin" in str(caught.value) and "\n" not in str(caught.value)


@pytest.fixture
def unwritable_folder(tmp_path):
    """A folder no one may add to: mode 0o555 for a user; immutable (chattr +i) for root,
    whom modes do not stop."""
    folder = tmp_path / "locked"
    folder.mkdir()
    if os.geteuid() != 0:
        folder.chmod(0o555)
        yield folder
        folder.chmod(0o755)
        return
    if shutil.which("chattr") is None:
        pytest.skip("as root only an immutable folder refuses writes, and chattr(1) is not installed")
    proc = subprocess.run(["chattr", "+i", str(folder)], capture_output=True)
    if proc.returncode != 0:
        pytest.skip(f"this file system does not take chattr +i: {proc.stderr.decode(errors='replace').strip()}")
    try:
        yield folder
    finally:
        subprocess.run(["chattr", "-i", str(folder)], check=False)


def test_permission_denied_is_one_line(unwritable_folder):
    code, _, err = run_cli("batch", "saguaro", "--seeds", "0:2", "--out", unwritable_folder / "out", "-q",
                           "--workers", "1")
    line = one_line(code, err)
    assert str(unwritable_folder / "out") in line
    assert os.strerror(errno.EPERM) in line or os.strerror(errno.EACCES) in line or "permission denied" in line
    assert not (unwritable_folder / "out").exists()


@pytest.mark.parametrize("address", ["garbage://x", "tcp://127.0.0.1:1", "nonsense", "tcp://127.0.0.1:x"])
def test_a_bad_scheduler_is_one_line_and_makes_nothing(tmp_path, address):
    out = tmp_path / "out"
    code, _, err = run_cli("batch", "saguaro", "--seeds", "0:2", "--out", out, "--scheduler", address, "-q")
    line = one_line(code, err)
    assert f"--scheduler {address}: cannot connect" in line
    assert not out.exists()                              # no empty npz/ (nor out/) left behind


def test_a_view_size_over_the_batch_limit_names_the_limit(tmp_path):
    code, _, err = run_cli("batch", "saguaro", "--seeds", "0:1", "--outputs", "png", "--size", "5000x10",
                           "--out", tmp_path / "out")
    line = one_line(code, err)
    assert "--size" in line and "1..4096" in line and "16384" not in line
