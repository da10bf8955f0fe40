"""The peer bench (plantgen.benchmarks.peers): plantgen's CPU and GLSL tracers and Mitsuba 3
on the same rays of a tiny instanced scene (where the peers extra is installed), the
shared rays of the CPU-tracer bench, and the one line a run without Mitsuba prints."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from plantgen.benchmarks import cpu_trace, peers
from plantgen.errors import PlantgenError
from plantgen.geometry.rays.beams import beam_grids

#: Two copies of one aloe (leaves: triangles) and a small saguaro (frusta only), close up.
TINY = """name: tiny
seed: 1
camera: {eye: [0, 1.2, 3.2], target: [0, 0.7, 0], up: [0, 1, 0], fov_y: 45}
light: {direction: [-0.75, -0.6, 0.3]}
instances:
  - {grammar: aloe, seed: 1, position: [0, 0, 0], scale: 3, grid: {count: [2, 1], spacing: [2.5, 2.5], seeds: 1}}
  - {grammar: saguaro, seed: 1, position: [0, 0, -2], scale: 0.35}
"""


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    path = tmp_path_factory.mktemp("peers") / "tiny.yaml"
    path.write_text(TINY)
    return str(path)


def test_the_shared_rays_point_at_the_sun_and_the_plants(tiny):
    staging, target, O, D = cpu_trace.scene_rays(tiny, (32, 24))
    assert O.shape == D.shape == (32 * 24, 3)
    assert [len(m) for m in target.matrices] == [2, 1]                       # the aloe's two copies: one plant
    t, _ = target.first_hits(O, D)
    so, sd = cpu_trace.shadow_rays(staging, O, D, t)
    light = np.asarray(staging.light_dir) / np.linalg.norm(staging.light_dir)
    assert len(so) == np.isfinite(t).sum() > 0 and np.allclose(sd, light) and light[1] > 0   # up, at the sun
    origins, dirs = cpu_trace.scan_rays(target, 2.0)
    assert np.allclose(origins, [2, 1.5, 10]) and np.allclose(np.linalg.norm(dirs, axis=1), 1)
    assert len(dirs) == sum(g.count for g in beam_grids(target, cpu_trace.scan_settings(2.0))) > 0
    assert (dirs[:, 2] < 0).all() and np.isfinite(target.first_hits(origins, dirs)[0]).any()   # at the plants


def test_the_peers_trace_what_plantgen_traces(tiny, gl_ctx, tmp_path):
    pytest.importorskip("mitsuba", reason="Mitsuba 3 (the peers extra) is not installed: pip install '.[peers]'")
    try:
        mitsuba = peers.load_mitsuba()
    except PlantgenError as exc:               # installed, but its LLVM backend finds no libLLVM here
        pytest.skip(f"Mitsuba is installed but its LLVM backend cannot start here: {exc}")
    result = peers.measure_scene(tiny, mitsuba, size=(48, 36), scan_step=2.0, rounds=1, say=lambda *_: None)
    rows = result["rows"]
    assert list(rows) == [peers.NUMBA, peers.GLSL, peers.CURVES, peers.TRIANGLES]
    assert result["counts"]["primary"] == 48 * 36 and result["counts"]["scan"] > 0
    assert 0.05 < result["hits"] < 0.95
    assert rows[peers.GLSL]["agree"] >= 0.995 and rows[peers.GLSL]["depth_diff"] < 1e-4
    for name in (peers.CURVES, peers.TRIANGLES):     # other primitives (round curves, 16 facets): most rays
        assert rows[name]["agree"] >= 0.98, (name, rows[name]["agree"])
        assert rows[name]["depth_diff"] < 1e-3, (name, rows[name]["depth_diff"])
        assert rows[name]["agree_shadow"] >= 0.9, (name, rows[name]["agree_shadow"])   # round caps, facets
    for row in rows.values():
        assert all(rate > 0 for rate in row["rate"].values()) and row["build_s"] > 0
    text = peers.markdown([result])
    for name in rows:
        assert f"| {name} | " in text
    assert "| primary rays/s | shadow rays/s | scan rays/s |" in text
    assert f"GL renderer: {result['notes']['renderer']};" in text
    assert peers.main(["--scene", tiny, "--size", "16x12", "--scan-step", "5", "--rounds", "1", "--no-gl",
                       "--out", str(tmp_path / "peers.md")]) == 0
    written = (tmp_path / "peers.md").read_text()
    assert f"| {peers.CURVES} | " in written and f"| {peers.GLSL} | " not in written


def test_without_mitsuba_one_line_naming_the_extra(monkeypatch, capsys, tmp_path):
    monkeypatch.setitem(sys.modules, "mitsuba", None)
    assert peers.main(["--scene", "forest", "--out", str(tmp_path / "peers.md")]) == 2
    captured = capsys.readouterr()
    assert captured.err == f"error: {peers.INSTALL}\n" and "peers extra" in peers.INSTALL
    assert not (tmp_path / "peers.md").exists()


def test_the_split_bench_builds_both_trees_and_they_answer_alike(tiny):
    """The LBVH-against-SAH bench (plantgen.benchmarks.bvh_split) on the tiny scene: both
    trees built compiled over the same primitives, every ray answered alike on both, a
    rate for every ray kind, and its table."""
    from plantgen.benchmarks import bvh_split
    from plantgen.geometry.rays import native_trace

    if not native_trace.available():
        pytest.skip("numba does not run here: the bench compares the compiled walk's trees")
    r = bvh_split.measure_scene(tiny, size=(40, 30), scan_step=2.0, rounds=1, say=lambda *_: None)
    assert r["same"] == {"primary": True, "shadow": True, "scan": True}
    assert r["counts"]["primary"] == 40 * 30 and r["counts"]["shadow"] > 0 and r["counts"]["scan"] > 0
    lbvh, sah = r["rows"]["lbvh"], r["rows"]["sah"]
    assert lbvh["nodes"] > 0 and sah["nodes"] > 0
    assert sah["sah_cost"] <= lbvh["sah_cost"] * 1.05          # the heuristic's own measure: no worse
    assert all(row[k] > 0 for row in (lbvh, sah) for k in ("primary", "shadow", "scan"))
    table = bvh_split.markdown([r])
    assert "| lbvh |" in table and "| sah |" in table and "primary yes, shadow yes, scan yes" in table
