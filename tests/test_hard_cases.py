"""The hard-case suite (README.md, "Accuracy and stability"), one test per case
(plantgen.geometry.rays.stability): finite outputs, hits on the skin between the planes,
nearest against brute-force marching, no holes from the medial axis, and float32 (the
GPU) close to float64."""

import numpy as np
import pytest
from _geometry_helpers import chain_skeleton, y_junction

from plantgen.geometry.rays.reference import intersect_frusta
from plantgen.geometry.rays.stability import HARD_CASES, evaluate_case, medial_axis_rays, model_size
from plantgen.geometry.skeletons.skin import skin_skeleton


@pytest.mark.parametrize("case", HARD_CASES, ids=[c.name for c in HARD_CASES])
def test_hard_case(case):
    res = evaluate_case(case, count=80)
    f = skin_skeleton(case.build())
    size = model_size(f)
    far = float(np.abs(np.concatenate([f.base, f.top])).max()) + 3 * size
    r_min = float(np.maximum(f.r1, f.r2).min())
    slack = 1e-12 * far / r_min          # rounding of points |X| from the origin, / radius
    assert res["hits"] > 0
    assert res["nonfinite"] == 0
    assert res["surface"] < 1e-9 + slack
    assert res["planes"] < 1e-9 + slack
    assert res["later"] < 1e-9 + 1e-12 * far / size       # never behind a marched entry
    assert res["march_only"] == 0                         # no ray enters the solid unseen
    if case.special != "inside":      # (an eye inside the solid has no entry to march to)
        assert res["nearest"] < 1e-9 + 1e-12 * far / size
    assert res["holes"] == 0
    # float32, re-centred, eye-relative upload: the accuracy the GLSL caster is held to
    assert res["f32"] < 3e-4 and res["px"] < 0.5
    assert res["flips_off_silhouette"] == 0
    assert res["far_side"] == 0          # no float32 ray sees through a joint (thin_closeup)
    assert res["flips"] <= (40 if case.special == "grazing" else 2)


def test_recentring_reduces_float32_depth_error_over_the_suite():
    raw, rec = [], []
    for case in HARD_CASES:
        if case.special in ("axis", "generator", "inside", "closeup"):
            continue
        res = evaluate_case(case, count=40, march=False)
        raw.append(res["f32_raw"])
        rec.append(res["f32"])
    assert np.median(np.array(raw) / np.maximum(rec, 1e-30)) > 5


def test_far_model_needs_eye_relative_upload():
    case = next(c for c in HARD_CASES if c.name == "far_1e4")
    res = evaluate_case(case, count=60, march=False)
    assert res["f32"] < 1e-4 < res["f32_world"]


@pytest.mark.parametrize("bend", [0.0, 1e-9, 1.0, 30.0, 45.0, 90.0, 119.0, 121.0, 135.0, 150.0,
                                  170.0, 179.0, 180.0])
def test_no_holes_from_the_medial_axis_across_bends(bend):
    """Equal-taper chains (exact seams) at every bend; the knuckle fan past 120°."""
    sk = chain_skeleton([bend], [1.0, 1.0], [0.2, 0.15, 0.1])
    f = skin_skeleton(sk)
    o, d = medial_axis_rays(f, 1500, seed=7)
    h = intersect_frusta(f, o, d)
    assert h.hit.all(), f"{np.count_nonzero(~h.hit)} of {len(o)} rays escaped"


@pytest.mark.parametrize("bend", [20.0, 70.0, 110.0])
def test_no_holes_with_seam_fitting_on_uneven_tapers(bend):
    sk = chain_skeleton([bend, bend / 2], [1.0, 0.3, 1.2], [0.25, 0.12, 0.11, 0.02])
    f = skin_skeleton(sk, seam_fit=True)
    o, d = medial_axis_rays(f, 1500, seed=8)
    assert intersect_frusta(f, o, d).hit.all()


@pytest.mark.parametrize("angle", [15.0, 45.0, 90.0, 150.0])
def test_no_holes_at_side_branch_junctions(angle):
    f = skin_skeleton(y_junction(angle))
    o, d = medial_axis_rays(f, 1500, seed=9)
    assert intersect_frusta(f, o, d).hit.all()
