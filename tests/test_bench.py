"""``plantgen bench``: the quick run end to end, the quality criterion, fps from timings.

The metric helpers (SSIM, silhouette mismatch, depth shading, matched level, Pareto front),
the level walk, the RC+R choice, the sweeps and the summary are tested on inputs with known
answers; the GL parts run on the shared context (llvmpipe in CI) with tiny images so the
file stays well under a minute.
"""

from __future__ import annotations

import csv
import json
import math
import sys

import numpy as np
import pytest
from _cli import run_cli

from plantgen import table1
from plantgen.errors import PlantgenError
from plantgen.geometry.rays.camera import Camera
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.table1 import (
    PAPER_TABLE1,
    RELIEF_ERROR,
    BenchOptions,
    Sweep,
    choose_relief_config,
    depth_shading,
    geometric_mean,
    image_error,
    matched_level,
    pareto_front,
    relief_configs,
    reports,
    silhouette_mismatch,
    ssim,
    summarise,
    summary_lines,
    walk_levels,
)


# ------------------------------------------------------------------------ metric helpers
def test_ssim_is_one_for_identical_images_and_falls_with_noise():
    rng = np.random.default_rng(1)
    image = rng.random((48, 64))
    assert ssim(image, image) == pytest.approx(1.0)
    slightly = np.clip(image + 0.02 * rng.standard_normal(image.shape), 0, 1)
    strongly = np.clip(image + 0.3 * rng.standard_normal(image.shape), 0, 1)
    assert 1.0 > ssim(image, slightly) > ssim(image, strongly)
    assert ssim(image, slightly) == pytest.approx(ssim(slightly, image))   # symmetric


def test_dssim_is_zero_for_identical_images_and_grows_with_noise_and_shift():
    """1 - SSIM: 0 for the same image, larger for a shifted one, and increasing with the
    noise added (the same noise pattern, scaled)."""
    rng = np.random.default_rng(2)
    y, x = np.mgrid[0:48, 0:64]
    image = 0.5 + 0.4 * np.sin(x / 5.0) * np.cos(y / 7.0)      # smooth, like a shading
    assert 1.0 - ssim(image, image) == pytest.approx(0.0, abs=1e-12)
    assert 1.0 - ssim(image, np.roll(image, 3, axis=1)) > 0.01
    pattern = rng.standard_normal(image.shape)
    dssim = [1.0 - ssim(image, np.clip(image + sigma * pattern, 0, 1)) for sigma in (0.0, 0.01, 0.03, 0.1, 0.3)]
    assert dssim[0] == pytest.approx(0.0, abs=1e-12)
    assert all(a < b for a, b in zip(dssim, dssim[1:], strict=False)), dssim


def test_ssim_of_flat_images_is_the_luminance_term():
    """Two constant images have no variance: SSIM = (2ab + C1) / (a² + b² + C1) with
    C1 = (0.01·data_range)², the data range scaling the constant."""
    a, b = np.full((20, 24), 0.2), np.full((20, 24), 0.6)
    for data_range in (1.0, 4.0):
        c1 = (0.01 * data_range) ** 2
        assert ssim(a, b, data_range) == pytest.approx((2 * 0.2 * 0.6 + c1) / (0.2 ** 2 + 0.6 ** 2 + c1))


def test_image_error_of_a_depth_image_against_itself_is_zero_and_a_moved_one_is_larger():
    camera = Camera((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0), 40.0, 48, 36)
    _, dirs = camera.rays()
    y, x = np.mgrid[0:36, 0:48]
    distance = (5.0 + 0.3 * np.sin(x / 3.0)) / dirs[..., 2]      # a corrugated wall
    distance[:, :6] = np.inf
    same = image_error(distance, distance, camera, (0.3, 0.4, -1.0))
    assert same.total == pytest.approx(0.0, abs=1e-12) and same.silhouette == 0.0
    moved = image_error(np.roll(distance, 2, axis=1), distance, camera, (0.3, 0.4, -1.0))
    assert moved.dssim > 0.01 and moved.silhouette > 0.0
    assert moved.total == pytest.approx(moved.dssim + moved.silhouette)


def test_a_missing_scikit_image_is_one_line_naming_the_extra(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "skimage", None)          # `import skimage...` raises ImportError
    monkeypatch.setitem(sys.modules, "skimage.metrics", None)
    with pytest.raises(PlantgenError, match=r"pip install '\.\[bench\]'"):
        ssim(np.zeros((16, 16)), np.zeros((16, 16)))
    code, stdout, stderr = run_cli("bench", "--quick", "--out", tmp_path / "b")
    assert code == 2
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "scikit-image" in lines[0] and "pip install '.[bench]'" in lines[0], stderr
    assert "Traceback" not in stderr
    assert not (tmp_path / "b").exists()


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


def test_level_walk_stops_at_the_first_qualifying_level():
    """m = 0, 1, ... are measured in turn; nothing past the first level within the bound
    (target·1.1 + 0.01) is built."""
    errors = {0: 0.5, 1: 0.2, 2: 0.03, 3: 0.001, 4: 0.0}
    built = []

    def measure(m):
        built.append(m)
        return errors[m]

    match = walk_levels("GS+R", "rc+r:linear=8", 0.02, measure, lambda m: 100 * 4 ** m, 10 ** 9)
    assert built == [0, 1, 2] and match.matched and match.level == 2
    assert match.bound == pytest.approx(0.02 * 1.1 + 0.01)
    record = match.as_dict()
    assert record["text"] == "matched at m=2" and record["stopped_by"] == "match"
    assert record["over_budget_level"] is None and record["target_key"] == "rc+r:linear=8"


def test_level_walk_goes_past_five_until_the_budget_and_reports_the_best_level():
    """No level qualifies: the walk goes on past m = 5 and stops at the first level whose
    triangle count is over the budget (not built); Table 1 gets the level of least error."""
    errors = {0: 0.6, 1: 0.4, 2: 0.3, 3: 0.2, 4: 0.15, 5: 0.12, 6: 0.08, 7: 0.09}
    built = []

    def measure(m):
        built.append(m)
        return errors[m]

    triangles = lambda m: 30 * 16 * 4 ** m   # noqa: E731
    match = walk_levels("GS+R", "rc+r:linear=8", 0.001, measure, triangles, triangles(7))
    assert built == [0, 1, 2, 3, 4, 5, 6, 7]
    assert not match.matched and match.level == 6 and match.over_budget == (8, triangles(8))
    record = match.as_dict()
    assert record["stopped_by"] == "budget" and record["error"] == 0.08
    assert record["text"] == (f"not matched: m=8 over the triangle budget ({triangles(8):,} triangles), "
                              "best measured error 0.0800 at m=6")
    nothing = walk_levels("GS", "rc", 0.0, measure, lambda m: 10 ** 7, 100).as_dict()
    assert nothing["level"] is None and not nothing["matched"]
    assert nothing["text"] == "not matched: m=0 over the triangle budget (10,000,000 triangles), no level built"


def test_relief_config_is_the_fastest_within_the_error_bound_else_the_most_accurate():
    rows = [{"key": "rc+r:linear=4", "ms": 10.0, "error": 0.02},
            {"key": "rc+r:linear=8", "ms": 12.0, "error": 0.008},
            {"key": "rc+r:linear=16", "ms": 15.0, "error": 0.002},
            {"key": "rc+r:binary=0", "ms": 11.0, "error": 0.009}]
    choice = choose_relief_config(rows, 0.01)
    assert choice["key"] == "rc+r:binary=0" and choice["within"]
    assert choose_relief_config(rows, 0.005)["key"] == "rc+r:linear=16"
    fallback = choose_relief_config(rows, 0.001)
    assert fallback["key"] == "rc+r:linear=16" and not fallback["within"]
    assert "most accurate" in fallback["rule"]


def test_relief_sweeps_vary_one_field_from_the_defaults_and_a_new_knob_is_one_sweep():
    from plantgen.gl.raycast import RaycastSettings

    opts = BenchOptions(linear_steps=(4, 32), binary_steps=(0, 6), march_densities=(1.0, 2.0))
    keys = [c.key for c in relief_configs(opts)]
    # binary = 6 with 32 linear steps is the linear sweep's 32, density 2 the default: each
    # measured once
    assert keys == ["rc+r:linear=4", "rc+r:linear=32", "rc+r:binary=0", "rc+r:density=1.0",
                    "rc+r:density=2.0", "rc+r:v=exact"]
    default = RaycastSettings(relief=True)
    fixed = RaycastSettings(relief=True, march="fixed", linear_steps=32, binary_steps=6)
    for c in relief_configs(opts):
        assert c.method == "RC+R" and c.settings.relief
        # one field varies, from the fixed march of the paper or from the default (adaptive)
        base = fixed if c.settings.march == "fixed" else default
        changed = {f for f in ("linear_steps", "binary_steps", "v_exact", "march_density")
                   if getattr(c.settings, f) != getattr(base, f)}
        assert len(changed) <= 1, (c.key, changed)
    # a further knob: one Sweep, optionally on top of another setting (``base``)
    extra = (Sweep("pad", "hull_padding", (0.05, 0.1), base=(("binary_steps", 2),)),)
    added = relief_configs(opts, extra)
    assert [c.key for c in added] == ["rc+r:pad=0.05", "rc+r:pad=0.1"]
    assert added[0].settings == RaycastSettings(relief=True, binary_steps=2, hull_padding=0.05)
    assert added[0].identity()["settings"]["hull_padding"] == 0.05


def _summary_model(name, rc_ms, rcr_ms, gsr_ms, matched):
    return {"model": name, "rc": {"ms": rc_ms, "fps": 1000 / rc_ms}, "rcr": {"ms": rcr_ms, "fps": 1000 / rcr_ms},
            "gsr": {"ms": gsr_ms, "fps": 1000 / gsr_ms}, "gsr_matched": matched}


def test_summary_counts_wins_and_takes_geometric_means():
    models = [_summary_model("saguaro", 2.0, 8.0, 16.0, True),     # RC+R ÷ GS+R = 2, overhead 4
              _summary_model("well", 1.0, 9.0, 4.5, False),        # 0.5, overhead 9
              _summary_model("mine", 1.0, 1.0, 1.0, True)]         # 1 (not in the paper), overhead 1
    s = summarise(models)
    ratio = s["rcr_over_gsr"]
    assert ratio["models"] == 3 and ratio["at_least_one"] == 2 and ratio["matched"] == 2
    assert ratio["geomean"] == pytest.approx(geometric_mean([2.0, 0.5, 1.0])) == pytest.approx(1.0)
    assert ratio["geomean_matched"] == pytest.approx(math.sqrt(2.0))
    assert s["relief_overhead"]["geomean"] == pytest.approx(36 ** (1 / 3))
    paper = s["paper"]["rcr_over_gsr"]
    assert set(paper["per_model"]) == {"saguaro", "well"}
    assert paper["geomean"] == pytest.approx(math.sqrt(PAPER_TABLE1["saguaro"].rcr_over_gsr
                                                       * PAPER_TABLE1["well"].rcr_over_gsr))
    lines = summary_lines(s)
    assert lines[0] == ("- RC+R ÷ GS+R ≥ 1 on 2 of 3 models, geometric mean 1.00 (at matched quality on "
                        "2 of 3; geometric mean over those 1.41)")
    assert lines[1].startswith("- relief overhead RC+R ms ÷ RC ms: geometric mean 3.30 (per model: saguaro 4.00")
    assert any(line.startswith("- paper (8800 GTX): RC+R ÷ GS+R ≥ 1 on 2 of 2 models") for line in lines)


def test_pareto_front_keeps_only_undominated_points():
    ms = [1.0, 2.0, 3.0, 2.5, 10.0]
    err = [0.5, 0.2, 0.3, 0.1, 0.1]
    front = pareto_front(ms, err).tolist()
    assert front == [0, 1, 3]                 # (3.0, 0.3) and (10, 0.1) are dominated


# ------------------------------------------------------------------------ the reports
def _report_model(name, *, relief=True, gsr_matched=False):
    entry = {"fps": 100.0, "ms": 10.0, "error": 0.004, "key": "rc", "overdraw": 1.5, "samples_per_pixel": 3.0}
    match = {"matched": gsr_matched, "level": 3, "text": "matched at m=3" if gsr_matched else "not matched: m=4",
             "target_key": "rc+r:linear=8"}
    return {"model": name, "segments": 1234, "shadows": False, "animated": False, "notes": [],
            "rc": entry, "rcr": dict(entry, fps=50.0, ms=20.0) if relief else None, "gs": entry,
            "gsr": dict(entry, fps=25.0, ms=40.0), "gs_level": 1, "gs_matched": True, "gsr_level": 3,
            "gsr_matched": gsr_matched, "gs_match": {"matched": True, "text": "matched at m=1"}, "gsr_match": match,
            "rcr_choice": {"key": "rc+r:linear=8", "rule": "fastest", "within": True, "settings": {},
                           "error": 0.004, "ms": 20.0} if relief else None,
            "memory": {"rc_bytes": 100, "rcr_bytes": 200, "gs_bytes": 300, "gsr_bytes": None,
                       "relief_map_bytes": 64, "gs_over_rc": 3.0, "gsr_over_rcr": None},
            "curve": [{"method": "RC", "knob": "", "value": 0, "key": "rc", "ms": 10.0, "fps": 100.0,
                       "error": 0.004}]}


def _report_results():
    """A run's results as the bench records them, made up: one model of the paper's, one not."""
    return {"machine": {"gl_renderer": "test GL", "date_utc": "2024-01-01", "gl_version": "4.6", "cpu": "cpu",
                        "cpus": 2},
            "options": {"size": [64, 48], "frames": 3, "curve_frames": 2, "relief_error": 0.01, "eval_size": [32, 24],
                        "rel_tol": 0.1, "abs_tol": 0.001, "max_triangles": 1000},
            "wall_s": 1.0, "models": [_report_model("saguaro"), _report_model("mine", relief=False, gsr_matched=True)]}


def _cells(line: str) -> list[str]:
    assert line.startswith("| ") and line.endswith(" |"), line
    return line[2:-2].split(" | ")


@pytest.mark.parametrize("table", ["TABLE1_COLUMNS", "WORK_COLUMNS", "MEMORY_COLUMNS"])
def test_a_tables_header_rule_and_rows_have_one_cell_per_declared_column(table):
    columns = getattr(reports, table)
    results = _report_results()
    head, rule = reports.markdown_head(columns)
    headers = [c.header for c in columns if c.header is not None]
    assert _cells(head) == headers and rule == "|" + "---|" * len(headers)
    for m in results["models"]:
        assert len(_cells(reports.markdown_row(columns, m, results))) == len(headers)
    text = reports.markdown_table(results)
    assert f"{head}\n{rule}\n" in text


def test_the_csv_columns_are_the_declared_columns(tmp_path):
    """table1.csv's fields, TABLE_FIELDS and table_rows' keys all come from TABLE1_COLUMNS."""
    declared = [c.name for c in reports.TABLE1_COLUMNS if c.name is not None]
    assert len(set(declared)) == len(declared)
    assert declared == reports.TABLE_FIELDS
    results = _report_results()
    reports.write_outputs(results, tmp_path)
    with open(tmp_path / "table1.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == declared
    assert [list(r) for r in reports.table_rows(results)] == [declared] * 2
    assert [r["model"] for r in rows] == ["saguaro", "mine"]
    assert rows[0]["paper_segments"] == str(PAPER_TABLE1["saguaro"].segments) and rows[1]["paper_segments"] == ""
    assert rows[1]["rcr_fps"] == rows[1]["rcr_config"] == "" and rows[0]["rcr_config"] == "rc+r:linear=8"


def test_a_new_column_is_one_line(tmp_path, monkeypatch):
    """One Column in TABLE1_COLUMNS gives a CSV field, a Markdown header and a cell per row."""
    extra = reports.Column("gs_triangles", "GS triangles", lambda m, results: 1000 * m["gs_level"], ",")
    monkeypatch.setattr(reports, "TABLE1_COLUMNS", (*reports.TABLE1_COLUMNS, extra))
    reports.write_outputs(_report_results(), tmp_path)
    with open(tmp_path / "table1.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["gs_triangles"] for r in rows] == ["1000", "1000"]
    table = (tmp_path / "table.md").read_text().splitlines()
    head = next(line for line in table if line.startswith("| model | segments"))
    assert _cells(head)[-1] == "GS triangles"
    assert [_cells(line)[-1] for line in table if line.startswith(("| saguaro | 1,234", "| mine | 1,234"))] == [
        "1,000", "1,000"]
    with pytest.raises(ValueError, match="needs a CSV name, a Markdown header or both"):
        reports.Column(None)
    with pytest.raises(ValueError, match="'gs_triangles' needs a value"):
        reports.Column("gs_triangles", "GS triangles", cell=lambda m: "")


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
        for key in ("rc_fps", "rcr_fps", "gs_fps", "gsr_fps", "gsn_fps", "gspom_fps"):
            assert math.isfinite(float(r[key])) and float(r[key]) > 0
    with open(out / "curves.csv") as fh:
        curve = list(csv.DictReader(fh))
    methods = {r["method"] for r in curve}
    assert methods == {"RC", "RC+R", "GS", "GS+R", "GS+N", "GS+POM"}
    assert any(r["pareto"] == "True" for r in curve)
    assert (out / "images" / "saguaro_reference_relief.png").is_file()
    assert (out / "curves_saguaro.png").is_file()          # matplotlib is in the test extra
    assert (out / "images" / "saguaro_rc_color.png").is_file()
    # the well lists shadows: every method ran the shadow pass and drew the ground
    well = next(m for m in results["models"] if m["model"] == "well")
    for key in ("rc", "rcr", "gs", "gsr", "gsn", "gspom"):
        assert well[key]["passes"] == ["shadow", "sky", "ground", "frusta"], (key, well[key])
        assert well[key]["shadow_reused"] > 0, (key, well[key])      # a still scene: its map is kept
    # the ray caster agrees with the float64 reference far better than GS at level 0
    sag = next(m for m in results["models"] if m["model"] == "saguaro")
    gs0 = next(c for c in sag["curve"] if c["key"] == "gs:m=0")
    assert sag["rc"]["error"] < 0.01 < gs0["error"]
    for m in results["models"]:
        _check_relief_choice(m, results["options"]["relief_error"])
        for short in ("gs", "gsr", "gsn", "gspom"):
            _check_level_walk(m, short, results["options"])
        _check_mapped(m, curve, "gsn")
        _check_mapped(m, curve, "gspom")
        _check_parallax_sweeps(m, results["options"])
    _check_summary(results, (out / "table.md").read_text(), rows)


def _check_mapped(m, curve_rows, short):
    """GS+N and GS+POM: matched against RC+R's Table 1 configuration like GS+R, in the relief
    family's curves (and on its Pareto front or not, as any point), and their bytes are
    their mesh's, their tangents' and their maps' (more than GS's mesh at the same level,
    with as many triangles)."""
    spec = table1.METHODS[[mm.short for mm in table1.METHODS].index(short)]
    assert m[f"{short}_match"]["target_key"] == m["rcr_choice"]["key"]
    assert m[f"{short}_match"]["target_error"] == pytest.approx(m["rcr_choice"]["error"])
    rows = [r for r in curve_rows if r["model"] == m["model"] and r["method"] == spec.name and r["error"]]
    assert rows and all(r["pareto"] in ("True", "False") for r in rows)
    assert all(int(r["texture_bytes"]) > 0 for r in rows)
    memory, key = m["memory"], m[short]["key"]
    row = next(c for c in m["curve"] if c["key"] == key)
    assert memory[f"{short}_bytes"] == row["gpu_bytes"] and memory[spec.texture_field] == row["texture_bytes"] > 0
    gs = next((c for c in m["curve"] if c["key"] == key.replace(spec.name.lower(), "gs")), None)
    if gs is not None:       # as many triangles, with tangents and maps besides
        assert row["triangles"] == gs["triangles"]
        assert row["gpu_bytes"] - gs["gpu_bytes"] > row["texture_bytes"]


def _check_parallax_sweeps(m, options):
    """GS+POM's knobs were swept at its Table 1 level, one point per value not already
    measured with the run's knobs, each with the level's triangles and bytes."""
    level_row = next(c for c in m["curve"] if c["key"] == m["gspom"]["key"])
    swept = [c for c in m["curve"] if c["method"] == "GS+POM" and c["knob"] not in ("m",)]
    assert {c["knob"] for c in swept} == {"layers", "refine"}
    assert [c["value"] for c in swept if c["knob"] == "layers"] == [
        n for n in options["pom_layers"] if (max(1, n // 4), n) != (options["parallax"]["min_layers"],
                                                                    options["parallax"]["max_layers"])]
    for c in swept:
        assert c["level"] == m["gspom_level"] and c["triangles"] == level_row["triangles"]
        assert c["gpu_bytes"] == level_row["gpu_bytes"] and "error" in c


def _check_relief_choice(m, relief_error):
    """Table 1's RC+R is the fastest RC+R curve point within the error bound (else the most
    accurate one), timed under its key, and GS+R was matched against its error."""
    rcr = [c for c in m["curve"] if c["method"] == "RC+R" and "error" in c]
    within = [c for c in rcr if c["error"] <= relief_error]
    # ties: the more accurate among equally fast ones, the faster among equally accurate ones
    expected = (min(within, key=lambda c: (c["ms"], c["error"])) if within
                else min(rcr, key=lambda c: (c["error"], c["ms"])))
    choice = m["rcr_choice"]
    assert choice["key"] == expected["key"] == m["rcr"]["key"], (choice, expected)
    assert choice["within"] == bool(within)
    assert m["gsr_match"]["target_key"] == choice["key"]
    assert m["gsr_match"]["target_error"] == pytest.approx(expected["error"])


def _check_level_walk(m, short, options):
    """Levels were built from m = 0 up to the first one within the bound, and no further;
    or, unmatched, up to the one before the first level over the triangle budget, which
    has a 'skipped' row, and Table 1 times the level of least error."""
    match = m[f"{short}_match"]
    method = table1.configs.TABLE_METHODS[short]
    rows = [c for c in m["curve"] if c["method"] == method and c["knob"] == "m"]
    built = {c["value"]: c["error"] for c in rows if "error" in c}
    assert sorted(built) == list(range(len(built))) == match["levels_measured"]
    assert [v for v in built.values() if v <= match["bound"]] == ([built[max(built)]] if match["matched"] else [])
    assert m[f"{short}_matched"] == match["matched"] and m[f"{short}_level"] == match["level"]
    assert m[short]["key"] == f"{method.lower()}:m={match['level']}"
    if match["matched"]:
        assert match["level"] == max(built) and match["text"] == f"matched at m={match['level']}"
        assert not any("skipped" in c for c in rows)
    else:
        skipped = [c for c in rows if "skipped" in c]
        assert [c["value"] for c in skipped] == [match["over_budget_level"]] == [max(built) + 1]
        assert skipped[0]["triangles"] == match["over_budget_triangles"] > options["max_triangles"]
        assert match["level"] == min(built, key=built.get)
        assert match["text"].startswith(f"not matched: m={match['over_budget_level']} over the triangle budget")


def _check_summary(results, table, csv_rows):
    summary = results["summary"]
    ratios = {m["model"]: m["rcr"]["fps"] / m["gsr"]["fps"] for m in results["models"]}
    assert summary["rcr_over_gsr"]["per_model"] == pytest.approx(ratios)
    assert summary["rcr_over_gsr"]["matched"] == sum(m["gsr_matched"] for m in results["models"])
    assert summary["rcr_over_gsr"]["geomean"] == pytest.approx(math.exp(np.mean(np.log(list(ratios.values())))))
    assert "- RC+R ÷ GS+R ≥ 1 on " in table and "- relief overhead RC+R ms ÷ RC ms: geometric mean" in table
    assert "- paper (8800 GTX): RC+R ÷ GS+R ≥ 1 on 2 of 2 models" in table
    for m, row in zip(results["models"], csv_rows, strict=True):
        assert row["rcr_config"] == m["rcr_choice"]["key"]
        assert row["gsr_match"] == m["gsr_match"]["text"] and row["gs_match"] == m["gs_match"]["text"]
        assert row["rcr_over_gsr_matched"] == str(m["gsr_matched"])
        table_row = next(line for line in table.splitlines() if line.startswith(f"| {m['model']} |"))
        assert m["rcr_choice"]["key"].split(":", 1)[1] in table_row
        assert table_row.rstrip(" |").split(" | ")[-2].endswith("✗") == (not m["gsr_matched"])
        if not m["gsr_matched"]:
            assert f"{m['model']}: GS+R {m['gsr_match']['text']}" in table


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
    from plantgen.geometry.skeletons import relief

    monkeypatch.setitem(relief._GENERATORS, "ripple_coarse", _ripples(2))
    monkeypatch.setitem(relief._GENERATORS, "ripple_fine", _ripples(14))
    relief._cached.cache_clear()
    opts = BenchOptions(size=(160, 120), frames=1, eval_size=(64, 48), linear_steps=(32,),
                        binary_steps=(6,), reference_relief_samples=96)
    levels = {}
    try:
        for name in ("ripple_coarse", "ripple_fine"):
            path = tmp_path / f"{name}.npz"
            _column(name).save(path)
            result = table1.bench_model(str(path), opts)
            assert result["relief"]
            assert result["rcr"]["error"] < 0.05
            levels[name] = (result["gsr_level"], result["gsr_matched"])
            built = [c["value"] for c in result["curve"] if c["method"] == "GS+R"]
            assert built == list(range(result["gsr_level"] + 1))     # nothing past the match
            assert result["gsr_match"]["target_key"] == result["rcr_choice"]["key"] == result["rcr"]["key"]
    finally:
        relief._cached.cache_clear()
    assert levels["ripple_coarse"][1] and levels["ripple_fine"][1], levels
    assert levels["ripple_fine"][0] > levels["ripple_coarse"][0], levels


# ------------------------------------------------------------------------ honest timing
def test_fps_come_from_the_measured_frame_times(gl_ctx, monkeypatch):
    """Each fps is 1000 / median of its own frame samples; make the ray caster 200 ms
    slower per frame and its reported fps follows, while GS (not slowed) does not."""
    from plantgen.gl.raycast import Raycaster

    # a budget that stops GS and GS+R at m = 1 (30 segments x 64 triangles) keeps this short
    opts = BenchOptions.quick_run(models=("saguaro",), frames=3, max_triangles=2000,
                                  linear_steps=(8,), binary_steps=())
    fast = table1.bench_model("saguaro", opts)
    for key in ("rc", "rcr", "gs", "gsr", "gsn"):
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
    slow = table1.bench_model("saguaro", opts)
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


def test_an_unmatched_method_gets_a_note_with_the_budget_and_the_ray_casters_edge():
    """'m✗' is not a quality verdict on its own: the note says the budget stopped the walk,
    the best level measured, and that the ray caster is more accurate and how much faster
    or slower it ran; a matched method gets no note."""
    match = {"matched": False, "level": 5, "error": 0.148, "target_key": "rc+r:linear=8",
             "text": "not matched: m=6 over the triangle budget (524,288 triangles), best measured "
                     "error 0.1480 at m=5"}
    model = {"gs_match": {"matched": True, "text": "matched at m=3"}, "gsr_match": match,
             "rcr": {"fps": 20.0, "error": 0.002}, "gsr": {"fps": 10.0, "error": 0.148}}
    assert table1.match_notes(model) == [
        "GS+R not matched: m=6 over the triangle budget (524,288 triangles), best measured error 0.1480 "
        "at m=5 (--max-triangles); RC+R (rc+r:linear=8) is more accurate (err 0.0020 vs 0.1480) and "
        "2.00× faster than the best GS+R mesh within the budget (m=5)"]
    slower = table1.match_notes({**model, "rcr": {"fps": 4.0, "error": 0.002}})
    assert "2.50× slower" in slower[0]
    assert table1.match_notes({**model, "gsr_match": {**match, "matched": True}}) == []


def test_cli_passes_the_relief_error_and_the_budget(tmp_path, monkeypatch):
    """--relief-error and --max-triangles reach BenchOptions (the run itself is stubbed)."""
    from plantgen.cli import bench as cli_bench

    seen = []

    def stub(opts, progress, out_dir):
        seen.append(opts)
        raise PlantgenError("stopped by the test")

    monkeypatch.setattr(cli_bench, "run_bench", stub)
    code, _, stderr = run_cli("bench", "--quick", "--relief-error", "0.02", "--max-triangles", "1000",
                              "--out", tmp_path / "b")
    assert code == 2 and "stopped by the test" in stderr
    assert seen[0].relief_error == 0.02 and seen[0].max_triangles == 1000 and seen[0].quick
    assert BenchOptions().relief_error == RELIEF_ERROR == 0.01


def test_the_ablation_turns_each_lever_off_alone_and_scores_both_sides(gl_ctx):
    """Each eye lever's off settings differ from its on settings in that lever only, and a
    small run on a shadowed relief scene times and scores every lever."""
    import dataclasses

    from plantgen.benchmarks.ablation import EYE_LEVERS, markdown, measure_model
    from plantgen.gl.raycast import Raycaster

    for lever, on, off in EYE_LEVERS:
        changed = {f.name for f in dataclasses.fields(on) if getattr(on, f.name) != getattr(off, f.name)}
        marches = lever in ("march", "skipping bound")
        assert changed and (changed <= {"march", "linear_steps", "binary_steps"} if marches
                            else len(changed) == 1), (lever, changed)
    rows, lights = measure_model("well", (128, 96), (48, 36), 1, Raycaster(), rays=3000)
    assert [r["lever"] for r in rows] == [lever for lever, _, _ in EYE_LEVERS] + ["light march"]
    for r in rows:
        assert r["on_ms"] > 0 and r["off_ms"] > 0 and np.isfinite([r["on_error"], r["off_error"]]).all()
    # the float64 reference scores the light lever: both sides sit within a few % of texels
    assert rows[-1]["on_error"] < 0.05 and rows[-1]["off_error"] < 0.05
    text = markdown(rows, (128, 96), 1, lights)
    assert all(f"| well | {r['lever']} |" in text for r in rows)
    assert "| well | bisect |" in text and "| well | secant |" in text
    assert "Relief shadow pass ÷ plain shadow pass, before (bisect) -> after (secant): well" in text


def test_the_light_casters_are_timed_and_scored_against_the_float64_reference(gl_ctx):
    """Every shipped scene with shadows is measured; the relief casters (before and after)
    cast the relief (their depths sit on the float64 reference's, where the plain caster's
    miss it by texels), each knob's row has its error beside its time, and the march cut
    to its floor leaves more texels off."""
    from plantgen.benchmarks.light_caster import CASTERS, measure_scene, shadowed_scenes
    from plantgen.gl.raycast import Raycaster

    shadowed = set(shadowed_scenes())
    assert {"well", "desert", "oasis", "dancing_cacti"} <= shadowed     # shipped scenes that list shadows
    assert "forest" not in shadowed and "pine" not in shadowed          # a forest (lod) and a grammar are not
    rows = {r["caster"]: r for r in measure_scene("well", (64, 48), 1, 3000, 512, Raycaster())}
    assert [label.split(" (")[0] for label in rows] == [c.label for c in CASTERS]
    assert all(r["shadow_ms"] > 0 for r in rows.values()) and rows["plain"]["over_plain"] == 1.0
    assert rows["plain"]["half_texel"] > 0.5                           # no relief: texels off
    for label in ("bisect", "secant"):
        assert rows[label]["half_texel"] < 0.03 and rows[label]["coverage"] < 0.005, rows[label]
    assert rows["secant"]["median_texels"] < 0.05                      # regula falsi lands on it
    for label in ("secant, 4 samples, no refinement", "secant, 2 samples, 1 step"):   # the march's floor
        assert rows[label]["half_texel"] > 2 * rows["secant"]["half_texel"], rows[label]


def test_the_light_casters_can_be_timed_by_this_processs_cpu_time(gl_ctx):
    """``--cpu``: each caster's render in a frame so small that it is its light pass, timed
    by this process's CPU time (steady where the cores are shared); the relief caster's
    pass costs more than the plain one's, as the wall-clock timing has it."""
    from plantgen.benchmarks.light_caster import CASTERS, CPU_FRAME, markdown, time_casters
    from plantgen.gl.raycast import Raycaster
    from plantgen.table1.models import load_model

    model = load_model("well", CPU_FRAME)
    assert (model.camera.width, model.camera.height) == CPU_FRAME
    ms = time_casters(Raycaster(), model, CASTERS[:3], 1, cpu=True)
    assert set(ms) == {"plain", "bisect", "secant"} and all(v > 0 for v in ms.values())
    assert ms["secant"] > ms["plain"]
    row = {"scene": "well", "caster": "plain", "shadow_ms": ms["plain"], "over_plain": 1.0, "over_bisect": 1.0,
           "coverage": 0.0, "half_texel": 0.0, "two_texels": 0.0, "median_texels": 0.0}
    assert "CPU ms of the render" in markdown([row], (64, 48), 1, 10, 10, cpu=True)


# ------------------------------------------------------------------------ GS+N
def test_gs_n_is_measured_against_the_relief_reference_on_the_smooth_mesh():
    """GS+N is compared with the relief surface (as RC+R and GS+R), but draws GS's smooth
    mesh: only GS+R's vertices carry the relief."""
    from plantgen.table1.configs import level_config

    gs, gsr, gsn = (level_config(m, 2) for m in ("GS", "GS+R", "GS+N"))
    assert (gs.relief, gsr.relief, gsn.relief) == (False, True, True)
    assert (gs.displaced, gsr.displaced, gsn.displaced) == (False, True, False)
    assert [c.normal_mapped for c in (gs, gsr, gsn)] == [False, False, True]
    assert gsn.key == "gs+n:m=2" and not gsn.ray_cast


def test_gs_pom_is_declared_once_and_sweeps_its_knobs_at_its_level():
    """GS+POM's row of METHODS: measured against the relief reference, matched against
    RC+R, drawn on the outer shell with the parallax maps, in the relief family; its level
    configuration carries the run's knobs, and its sweeps leave out the run's own."""
    from plantgen.settings import ParallaxSettings
    from plantgen.table1.configs import (
        LEVEL_METHODS,
        MATCHED_AGAINST,
        TABLE_METHODS,
        level_config,
        parallax_configs,
    )
    from plantgen.table1.curves import FAMILIES

    assert TABLE_METHODS["gspom"] == "GS+POM" and MATCHED_AGAINST["gspom"] == "rcr"
    assert "GS+POM" in LEVEL_METHODS and "GS+POM" in FAMILIES["relief"]
    cfg = level_config("GS+POM", 2)
    assert (cfg.relief, cfg.surface, cfg.maps, cfg.key) == (True, "outer", "parallax", "gs+pom:m=2")
    assert cfg.parallax == ParallaxSettings() and not cfg.displaced and not cfg.normal_mapped
    assert level_config("GS+N", 2).parallax is None
    opts = BenchOptions(pom_layers=(4, 32, 64), pom_refine_steps=(0, 1, 4))
    swept = parallax_configs(opts, "GS+POM", 3)
    assert [c.key for c in swept] == ["gs+pom:layers=4", "gs+pom:layers=64", "gs+pom:refine=0",
                                      "gs+pom:refine=4"]
    assert swept[0].parallax == ParallaxSettings(min_layers=1, max_layers=4) and {c.level for c in swept} == {3}


def test_normal_map_bytes_count_every_layer_and_its_mipmaps():
    """RGB8 layers at the largest map's size, each halved down to 1x1: a (4, 8) map over
    two slots is (32 + 8 + 2 + 1) texels x 3 bytes x 2 layers."""
    from plantgen.gl.raster import normal_map_bytes

    small = np.zeros((2, 4, 3), np.uint8)
    big = np.zeros((4, 8, 3), np.uint8)
    assert normal_map_bytes(("bark", "stone"), {"bark": big, 1: small}) == (32 + 8 + 2 + 1) * 3 * 2
    assert normal_map_bytes(("bark",), {}) == 3            # no map: one flat 1x1 layer


def test_gs_n_draws_gs_depth_with_other_shading(gl_ctx):
    """At the same level GS+N's distance image is GS's to float precision (a normal map moves
    no surface: the bench's error, which is of the geometry, is the smooth mesh's against the
    relief reference) while its colours differ where the relief is (the map shades)."""
    from plantgen.table1.configs import level_config
    from plantgen.table1.models import load_model
    from plantgen.table1.renderers import Renderers

    model = load_model("saguaro", (160, 120))
    renderers = Renderers(model, 100_000)
    try:
        gs, _ = renderers.render_config(level_config("GS", 2), model.camera)
        gsn, _ = renderers.render_config(level_config("GS+N", 2), model.camera)
        assert renderers.texture_bytes(2, "normal") > 0 and set(renderers.maps(2, "normal")) <= set(model.names)
    finally:
        renderers.release()
    hit = np.isfinite(gs.distance)
    assert hit.sum() > 100 and np.array_equal(hit, np.isfinite(gsn.distance))
    np.testing.assert_allclose(gsn.distance[hit], gs.distance[hit], rtol=1e-5)
    differs = np.any(gs.color[hit][:, :3] != gsn.color[hit][:, :3], axis=-1)
    assert differs.mean() > 0.2, differs.mean()


def test_gs_pom_draws_the_relief_between_the_shells(gl_ctx):
    """At the same level GS+POM's relief (the distance to the displaced point) lies in front
    of GS's smooth mesh, the inner cone, nearly everywhere both cover (the relief rises from
    it), and its outline, the outer shell's, holds GS's; its RGBA maps take 4/3 of GS+N's."""
    from plantgen.table1.configs import level_config
    from plantgen.table1.models import load_model
    from plantgen.table1.renderers import Renderers

    model = load_model("saguaro", (160, 120))
    renderers = Renderers(model, 100_000)
    try:
        gs, _ = renderers.render_config(level_config("GS", 2), model.camera)
        pom, _ = renderers.render_config(level_config("GS+POM", 2), model.camera)
        assert renderers.texture_bytes(2, "parallax") == renderers.texture_bytes(2, "normal") * 4 // 3
    finally:
        renderers.release()
    hit = np.isfinite(gs.distance)
    assert hit.sum() > 100 and not np.any(hit & ~np.isfinite(pom.distance))
    assert np.mean(pom.distance[hit] <= gs.distance[hit] + 1e-4) > 0.95


def test_gs_n_draws_under_a_shadow_map_and_on_the_ground(gl_ctx):
    """The well lists shadows and a ground: GS+N's normal maps and the shadow map are
    bound side by side (on distinct texture units: the fixture fails on any GL error), and
    the frame runs the scene's passes as GS's does."""
    from plantgen.table1.configs import level_config
    from plantgen.table1.models import load_model
    from plantgen.table1.renderers import Renderers

    model = load_model("well", (96, 72))
    renderers = Renderers(model, 100_000)
    try:
        gs, _ = renderers.render_config(level_config("GS", 1), model.camera, conditions=True)
        gsn, _ = renderers.render_config(level_config("GS+N", 1), model.camera, conditions=True)
        pom, _ = renderers.render_config(level_config("GS+POM", 1), model.camera, conditions=True)
    finally:
        renderers.release()
    assert gsn.stats.passes == gs.stats.passes == pom.stats.passes == ["shadow", "sky", "ground", "frusta"]
    np.testing.assert_array_equal(np.isfinite(gsn.distance), np.isfinite(gs.distance))
