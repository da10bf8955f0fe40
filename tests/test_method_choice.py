"""``--method auto``: the ray tracer for an instanced scene at full detail with many rows a
pixel, the ray caster everywhere else (plantgen.gl.rt.choose_method)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plantgen.gl.rt import RT_PLACED_PER_DISTINCT, RT_ROWS_PER_PIXEL, choose_method

MANY = {"placed_rows": 1_000_000, "distinct_rows": 10_000, "pixels": 512 * 384}


def test_an_explicit_method_is_kept_whatever_the_input():
    for method in ("rc", "rt"):
        assert choose_method(method, **MANY) == method
        assert choose_method(method, placed_rows=10, distinct_rows=10, pixels=10**7) == method


def test_auto_traces_a_large_instanced_scene_at_full_detail():
    assert choose_method("auto", **MANY) == "rt"


@pytest.mark.parametrize("why", [{"lod_pixels": 2.0}, {"animated": True}, {"labels": True}])
def test_auto_casts_where_a_level_of_detail_an_animation_or_labels_are_asked_for(why):
    assert choose_method("auto", **MANY, **why) == "rc"


def test_auto_casts_a_plant_placed_once_and_a_scene_with_few_rows_a_pixel():
    # every row distinct (a merged plant): the BVH's build costs more than RC's frame
    assert choose_method("auto", placed_rows=500_000, distinct_rows=500_000, pixels=1000) == "rc"
    # a few copies of each plant: RC for one still, RT once the build serves enough frames
    few = {"placed_rows": 400_000, "distinct_rows": 100_000, "pixels": 1000}
    assert choose_method("auto", **few) == "rc"
    assert choose_method("auto", **few, draws=int(RT_PLACED_PER_DISTINCT)) == "rt"
    # many copies, but few rows for the pixels
    pixels = 4096 * 4096
    rows = math.ceil(RT_ROWS_PER_PIXEL * pixels)
    assert choose_method("auto", placed_rows=rows - 1, distinct_rows=1000, pixels=pixels) == "rc"
    assert choose_method("auto", placed_rows=rows, distinct_rows=1000, pixels=pixels) == "rt"
    assert choose_method("auto", placed_rows=0, distinct_rows=0, pixels=1) == "rc"


@settings(max_examples=200, deadline=None)
@given(placed=st.integers(1, 10**9), distinct=st.integers(1, 10**7), pixels=st.integers(1, 10**8),
       more=st.integers(0, 10**9), wider=st.integers(0, 10**8), draws=st.integers(1, 100))
def test_auto_is_monotone_in_rows_pixels_and_draws(placed, distinct, pixels, more, wider, draws):
    """More placed rows or more draws never turn RT back to RC; more pixels never turn RC
    into RT."""
    case = {"distinct_rows": distinct, "draws": draws}
    before = choose_method("auto", placed_rows=placed, pixels=pixels, **case)
    if before == "rt":
        assert choose_method("auto", placed_rows=placed + more, pixels=pixels, **case) == "rt"
        assert choose_method("auto", placed_rows=placed, pixels=pixels, distinct_rows=distinct,
                             draws=draws + 1) == "rt"
        assert placed * draws >= RT_PLACED_PER_DISTINCT * distinct and placed >= RT_ROWS_PER_PIXEL * pixels
    else:
        assert choose_method("auto", placed_rows=placed, pixels=pixels + wider, **case) == "rc"


GROVE = ("effects: [shadows, lod]\nground: {size: 60, material: grass}\n"
         "camera: {eye: [0, 1.7, 30], target: [0, 4, 0], fov_y: 50}\n"
         "instances:\n  - {grammar: abop_monopodial, grid: {count: [4, 3], spacing: [8, 8], jitter: 0.3, seeds: 1,"
         " scale_jitter: 0.2}}\n  - {grammar: aloe, seed: 3, position: [2, 0, 12], grid: {count: [5, 2],"
         " spacing: [3, 3], jitter: 0.4, seeds: 2}}\n")


def test_render_chooses_per_input_and_says_so(tmp_path):
    """The grove (22 copies of 3 plants) at full detail, timed over 8 frames, is traced;
    with its level of detail, or with --method rc, it is cast; the report names the
    method used."""
    from _cli import run_cli

    scene = tmp_path / "grove.yaml"
    scene.write_text(GROVE)
    out = tmp_path / "grove.png"
    code, full, stderr = run_cli("render", scene, "-o", out, "--size", "64x48", "--lod-pixels", "0",
                                 "--time-frames", "8")
    assert code == 0, stderr
    assert "ray traced (--method auto)" in full and "shadow rays" in full
    code, lod, stderr = run_cli("render", scene, "-o", out, "--size", "64x48")
    assert code == 0, stderr
    assert "ray cast (--method auto)" in lod and "level of detail" in lod
    code, cast, stderr = run_cli("render", scene, "-o", out, "--size", "64x48", "--lod-pixels", "0", "--method", "rc")
    assert code == 0, stderr
    assert "ray cast" in cast and "--method auto" not in cast
    code, verbose, stderr = run_cli("render", scene, "-o", out, "--size", "64x48", "--verbose")
    assert code == 0 and "RC (--method auto)" in verbose, stderr


def test_the_method_bench_times_both_methods_and_checks_auto():
    from plantgen.benchmarks.method_choice import markdown, measure

    result = measure(models=("saguaro",), copies=(), sizes=((64, 48),), frames=1, say=lambda *_: None)
    (row,) = result["rows"]
    assert row["placed"] == row["distinct"] > 0 and row["rc_ms"] > 0 and row["rt_ms"] > 0 and row["build_ms"] > 0
    assert row["auto"] == "rc"                       # a plant placed once: never worth a BVH for one still
    text = markdown(result)
    assert "| saguaro | 64x48 |" in text and result["renderer"] in text
    assert "[start:summary] -->\n| inputs | size | faster frame | times faster |" in text     # what the docs quote
    assert f"| single plants | 64x48 | {'RC' if row['rc_ms'] < row['rt_ms'] else 'RT'} on 1 of 1 |" in text
