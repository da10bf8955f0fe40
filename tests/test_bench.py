"""``plantgen bench``: the quick run end to end, the quality criterion, fps from timings.

The metric helpers (SSIM, silhouette mismatch, depth shading, matched level, Pareto front)
are tested on images with known answers; the GL parts run on the shared context
(llvmpipe in CI) with tiny images so the file stays well under a minute.
"""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from _cli import run_cli

from plantgen import bench
from plantgen.bench import (
    PAPER_TABLE1,
    BenchOptions,
    depth_shading,
    matched_level,
    pareto_front,
    silhouette_mismatch,
    ssim,
)
from plantgen.geometry.camera import Camera
from plantgen.geometry.skeleton import Skeleton


# ------------------------------------------------------------------------ metric helpers
def test_ssim_is_one_for_identical_images_and_falls_with_noise():
    rng = np.random.default_rng(1)
    image = rng.random((48, 64))
    assert ssim(image, image) == pytest.approx(1.0)
    slightly = np.clip(image + 0.02 * rng.standard_normal(image.shape), 0, 1)
    strongly = np.clip(image + 0.3 * rng.standard_normal(image.shape), 0, 1)
    assert 1.0 > ssim(image, slightly) > ssim(image, strongly)
    assert ssim(image, slightly) == pytest.approx(ssim(slightly, image))   # symmetric


def test_silhouette_mismatch_counts_pixels_covered_by_one_only():
    ref = np.zeros((10, 10), bool)
    ref[2:8, 2:8] = True                      # 36 pixels
    shifted = np.roll(ref, 1, axis=1)         # 6 gained, 6 lost
    assert silhouette_mismatch(ref, ref) == 0.0
    assert silhouette_mismatch(shifted, ref) == pytest.approx(12 / 36)


def test_depth_shading_of_a_plane_facing_the_light_is_uniform_and_bright():
    """A plane z = 5 in front of the eye, light along the plane's normal: every hit pixel
    gets 0.15 + 0.85, misses get 0."""
    camera = Camera((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0), 40.0, 32, 24)
    _, dirs = camera.rays()
    distance = 5.0 / dirs[..., 2]
    distance[:, :4] = np.inf
    shade = depth_shading(distance, camera, light_dir=(0.0, 0.0, -1.0))
    assert np.allclose(shade[:, 4:], 1.0)
    assert np.all(shade[:, :4] == 0.0)


def test_matched_level_is_the_smallest_within_tolerance():
    errors = {0: 0.30, 1: 0.05, 2: 0.021, 3: 0.019}
    assert matched_level(errors, 0.02, rel_tol=0.1, abs_tol=0.0) == (2, True)    # 0.021 <= 0.022
    assert matched_level(errors, 0.02, rel_tol=0.0, abs_tol=0.0) == (3, True)     # 0.021 > 0.02
    assert matched_level(errors, 0.001, rel_tol=0.1, abs_tol=0.0) == (3, False)  # best, unmatched
    assert matched_level({}, 0.1) == (None, False)


def test_pareto_front_keeps_only_undominated_points():
    ms = [1.0, 2.0, 3.0, 2.5, 10.0]
    err = [0.5, 0.2, 0.3, 0.1, 0.1]
    front = pareto_front(ms, err).tolist()
    assert front == [0, 1, 3]                 # (3.0, 0.3) and (10, 0.1) are dominated


# ------------------------------------------------------------------------ GL: end to end
def test_quick_bench_runs_end_to_end(gl_ctx, tmp_path):
    """`plantgen bench --quick` writes the table, CSV, JSON (with the GL renderer), the
    compared images on request, and every fps is finite and positive."""
    out = tmp_path / "bench"
    code, stdout, stderr = run_cli("bench", "--quick", "--images", "--out", out)
    assert code == 0, stderr
    assert "| saguaro |" in stdout and "| well |" in stdout
    assert "bench" in stderr                              # the progress bar went to stderr
    results = json.loads((out / "results.json").read_text())
    renderer = results["machine"]["gl_renderer"]
    assert renderer and renderer in (out / "table.md").read_text()
    with open(out / "table1.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["model"] for r in rows] == ["saguaro", "well"]
    for r in rows:
        assert r["gl_renderer"] == renderer
        for key in ("rc_fps", "rcr_fps", "gs_fps", "gsr_fps"):
            assert math.isfinite(float(r[key])) and float(r[key]) > 0
    with open(out / "curves.csv") as fh:
        curve = list(csv.DictReader(fh))
    methods = {r["method"] for r in curve}
    assert methods == {"RC", "RC+R", "GS", "GS+R"}
    assert any(r["pareto"] == "True" for r in curve)
    assert (out / "images" / "saguaro_reference_relief.png").is_file()
    assert (out / "curves_saguaro.png").is_file()          # matplotlib is in the test extra
    assert (out / "images" / "saguaro_rc_color.png").is_file()
    # the well lists shadows: all four methods ran the shadow pass and drew the ground
    well = next(m for m in results["models"] if m["model"] == "well")
    for key in ("rc", "rcr", "gs", "gsr"):
        assert well[key]["passes"] == ["shadow", "sky", "ground", "frusta"], (key, well[key])
    # the ray caster agrees with the float64 reference far better than GS at level 0
    sag = next(m for m in results["models"] if m["model"] == "saguaro")
    gs0 = next(c for c in sag["curve"] if c["key"] == "gs:m=0")
    assert sag["rc"]["error"] < 0.01 < gs0["error"]


# ------------------------------------------------------------------------ the criterion
def _ripples(cycles):
    """Height map generator: ``cycles`` smooth ribs around u, constant along v."""
    def generate(rng, shape):
        h, w = shape
        u = (np.arange(w) + 0.5) / w
        return np.broadcast_to(0.5 + 0.5 * np.cos(2 * np.pi * cycles * u), shape).copy()
    return generate


def _column(material: str) -> Skeleton:
    """A short, thick column of two collinear segments (radius 0.5, height 2)."""
    start = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    end = np.array([[0.0, 1.0, 0.0], [0.0, 2.0, 0.0]])
    return Skeleton(start, end, np.array([0.5, 0.5]), np.array([0.5, 0.5]), np.array([-1, 0]),
                    np.array([False, True]), np.array([0, 0]), (material,))


def test_quality_criterion_picks_a_higher_level_for_a_finer_relief_map(gl_ctx, tmp_path, monkeypatch):
    """Same column, relief of 2 ribs vs 14 ribs around: GS+R needs more columns (a higher
    m) to match the ray caster's error on the fine map; the ray caster's own error stays
    small on both."""
    from plantgen.geometry import relief

    monkeypatch.setitem(relief._GENERATORS, "ripple_coarse", _ripples(2))
    monkeypatch.setitem(relief._GENERATORS, "ripple_fine", _ripples(14))
    relief._cached.cache_clear()
    opts = BenchOptions(size=(160, 120), frames=1, eval_size=(64, 48), levels=(0, 1, 2, 3, 4, 5),
                        linear_steps=(32,), binary_steps=(6,), reference_relief_samples=96)
    levels = {}
    try:
        for name in ("ripple_coarse", "ripple_fine"):
            path = tmp_path / f"{name}.npz"
            _column(name).save(path)
            result = bench.bench_model(str(path), opts)
            assert result["relief"]
            assert result["rcr"]["error"] < 0.05
            levels[name] = (result["gsr_level"], result["gsr_matched"])
    finally:
        relief._cached.cache_clear()
    assert levels["ripple_coarse"][1] and levels["ripple_fine"][1], levels
    assert levels["ripple_fine"][0] > levels["ripple_coarse"][0], levels


# ------------------------------------------------------------------------ honest timing
def test_fps_come_from_the_measured_frame_times(gl_ctx, monkeypatch):
    """Each fps is 1000 / median of its own frame samples; make the ray caster 200 ms
    slower per frame and its reported fps follows, while GS (not slowed) does not."""
    from plantgen.render.raycast import Raycaster

    opts = BenchOptions.quick_run(models=("saguaro",), frames=3, levels=(0, 1),
                                  linear_steps=(8,), binary_steps=())
    fast = bench.bench_model("saguaro", opts)
    for key in ("rc", "rcr", "gs", "gsr"):
        entry = fast[key]
        assert len(entry["ms_samples"]) == opts.frames
        assert entry["fps"] == pytest.approx(1000.0 / np.median(entry["ms_samples"]))
    paper = PAPER_TABLE1["saguaro"]
    assert fast["segments"] == 30 and fast["rc"]["fps"] not in (paper[1], paper[2])

    original = Raycaster.render

    def slow_render(self, *args, **kwargs):
        result = original(self, *args, **kwargs)
        result.frame_ms += 200.0
        return result

    monkeypatch.setattr(Raycaster, "render", slow_render)
    slow = bench.bench_model("saguaro", opts)
    assert slow["rc"]["fps"] < 5.0 < fast["rc"]["fps"]
    assert slow["rcr"]["fps"] < 5.0
    assert slow["gs"]["fps"] > 5.0


def test_unknown_model_is_one_line_error_before_any_work(tmp_path):
    code, stdout, stderr = run_cli("bench", "--models", "saguaro,no_such_plant", "--out", tmp_path / "b")
    assert code == 2
    assert stderr.strip().splitlines() == [
        "plantgen: error: no such model: no_such_plant (a shipped grammar/scene name such as "
        "coconut, pine, elm, or a path)"]
    assert not (tmp_path / "b").exists()


def test_levels_left_out_by_the_triangle_budget_are_named_when_no_level_matched():
    """'>m' from a budget is not a quality verdict: the table says which levels were not
    built; a matched method, or one with nothing skipped, gets no such note."""
    curve = [{"method": "GS+R", "value": 2, "error": 0.2},
             {"method": "GS+R", "value": 3, "skipped": "17 triangles over the budget of 6"},
             {"method": "GS", "value": 1, "error": 0.0}]
    model = {"gs_matched": True, "gsr_matched": False, "curve": curve}
    notes = bench.budget_notes(model)
    assert notes == ["GS+R m = 3 not built: 17 triangles over the budget of 6 (--max-triangles)"]
    assert bench.budget_notes({**model, "gsr_matched": True}) == []
