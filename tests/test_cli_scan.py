"""``plantgen scan``: a model to labelled points on disk; --help; one line and exit status
2 for bad input, nothing written."""

from __future__ import annotations

import numpy as np
import pytest
from _cli import run_cli

from plantgen.scanfiles import read_points

pytest.importorskip("laspy", reason="laspy (plantgen[scan]) is not installed")


def test_help_names_the_knobs():
    code, out, _ = run_cli("scan", "--help")
    assert code == 0
    for option in ("--angular-step", "--range-noise", "--divergence", "--scan-mode", "--scanner-positions",
                   "--scan-seed", "--up"):
        assert option in out


def test_a_scene_is_scanned_with_its_instances_as_plants(tmp_path):
    code, out, err = run_cli("scan", "desert", "-o", tmp_path / "d.las", "--angular-step", "0.3",
                             "--range-noise", "0.002")
    assert code == 0, err
    assert "points from 4 scanners" in out and "wrote" in out and "z-up" in out
    cloud = read_points(tmp_path / "d.las")
    assert len(cloud) > 1000 and len(np.unique(cloud.plant)) > 1
    assert cloud.metadata["range_noise"] == 0.002 and cloud.metadata["seed"] == 0


def test_the_same_seed_writes_the_same_file(tmp_path):
    for name in ("a.ply", "b.ply"):
        assert run_cli("scan", "saguaro", "-o", tmp_path / name, "--angular-step", "0.5", "--range-noise", "0.01",
                       "--scan-seed", "3", "-q")[0] == 0
    assert (tmp_path / "a.ply").read_bytes() == (tmp_path / "b.ply").read_bytes()


@pytest.mark.parametrize("args, words", [
    (("saguaro", "-o", "x.xyz"), "unknown point cloud format"),
    (("saguaro", "-o", "x.las", "--angular-step", "0"), "--angular-step"),
    (("saguaro", "-o", "x.las", "--scanner-positions", "1,2"), "--scanner-positions"),
    (("no_such_model", "-o", "x.las"), "no such file"),
    (("saguaro", "-o", "x.las", "--angular-step", "0.001"), "scan_rays"),
    (("saguaro", "-o", "missing/x.las"), "no such folder"),
])
def test_bad_input_is_one_line_and_status_2(tmp_path, monkeypatch, args, words):
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli("scan", *args)
    assert code == 2 and words in err and len(err.strip().splitlines()) == 1
    assert not any(tmp_path.rglob("*.*"))


def test_the_options_are_the_scan_settings_knobs():
    """Read from ScanSettings, never restated: every knob is an option with its default,
    range or choices, and the command builds the settings from them."""
    import click

    from plantgen.cli.scan import scan
    from plantgen.geometry.rays.scan import ScanSettings
    from plantgen.knobs import knob_fields

    params = {p.name: p for p in scan.params}
    for _, k, default in knob_fields(ScanSettings):
        p = params[k.name]
        assert p.default == default and k.option in p.opts, k.name
        if k.kind == "choice":
            assert tuple(p.type.choices) == k.choices
        elif k.lo is not None or k.hi is not None:
            assert isinstance(p.type, click.IntRange | click.FloatRange)
            assert (p.type.min, p.type.max, p.type.min_open, p.type.max_open) == (k.lo, k.hi, k.lo_open, k.hi_open)


def test_no_gpu_device_node_scans_on_the_cpu_without_a_gl_context(tmp_path, monkeypatch):
    """Where the machine has no GPU device node, ``plantgen scan`` takes the compiled CPU
    walk without creating a GL context (llvmpipe's, only to learn it is software); where
    one is listed, the context is asked as before."""
    import plantgen.cli.scan as scan_cli
    import plantgen.gl.context as context
    from plantgen.geometry.rays import native_trace

    if not native_trace.available():
        pytest.skip("numba does not run here: the scan asks GL for its float32 search instead")
    asked = []

    def no_context():
        asked.append(True)
        raise context.GLContextError("asked for a GL context")

    monkeypatch.setattr(context, "gl_context", no_context)
    monkeypatch.setattr(scan_cli, "gpu_device_nodes", list)
    code, out, err = run_cli("scan", "saguaro", "-o", tmp_path / "s.ply", "--angular-step", "1")
    assert code == 0, err
    assert asked == [] and "float64" in out and "wrote" in out
    monkeypatch.setattr(scan_cli, "gpu_device_nodes", lambda: ["/dev/dri/renderD128"])
    code, out, err = run_cli("scan", "saguaro", "-o", tmp_path / "t.ply", "--angular-step", "1")
    assert code == 0, err
    assert asked == [True] and "float64" in out         # no context: the float64 CPU walk all the same



def test_a_refused_scan_does_not_wait_for_the_compile(tmp_path, monkeypatch):
    """The path is chosen without compiling the CPU tracer (numba's cold compile takes tens
    of seconds on a fresh machine): a scan refused by its ray budget exits 2 without a
    compile, and the compile comes with the first trace of a scan that goes ahead."""
    import plantgen.cli.scan as scan_cli
    from plantgen.geometry.rays import native_trace

    compiles = []
    monkeypatch.setattr(native_trace, "warm_up", lambda: compiles.append(True) or 0.0)
    monkeypatch.setattr(native_trace, "_STATE", {"failed": None, "compile_s": None, "noticed": False})
    monkeypatch.setattr(scan_cli, "gpu_device_nodes", list)
    code, _, err = run_cli("scan", "saguaro", "-o", tmp_path / "s.ply", "--angular-step", "0.001")
    assert code == 2 and "scan_rays" in err
    assert compiles == [] and not (tmp_path / "s.ply").exists()
