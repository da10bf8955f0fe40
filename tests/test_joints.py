"""Joints that hold (issue 18): seams closed by construction at every taper and bend.

Invariants with a physical meaning: a ray from inside the solid (the medial axis) always
hits the skin; the child's cut of a joint's plane lies on the parent's cone (radial gap
0, float64); a camera inside the tube at a joint sees no background, in float64 and in
GLSL.
"""

from __future__ import annotations

import numpy as np
import pytest
from _geometry_helpers import chain_skeleton
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from plantgen.geometry.camera import Camera
from plantgen.geometry.frusta import cone_slope, seam_gap
from plantgen.geometry.reference import intersect_frusta, render_reference
from plantgen.geometry.skin import skin_skeleton, sphere_base_radius
from plantgen.geometry.stability import medial_axis_rays

# The issue's held-out chains: (bends in degrees, joint radii root first), lengths 1.
ISSUE_CHAINS = {
    "closing_after_20deg": ([20.0], [0.3, 0.18, 0.0]),
    "uneven_tapers": ([30.0, 35.0], [0.3, 0.28, 0.1, 0.04]),
    "steep_taper": ([20.0], [1.0, 0.3, 0.1]),
}


def fitted_joints(frusta):
    """(j,) bool over frusta's continuing rows: joints between two segments (not fan
    slices of a knuckle), in the order of :func:`seam_gap`."""
    c = np.flatnonzero(frusta.parent_row >= 0)
    return frusta.has_length[c] & frusta.has_length[frusta.parent_row[c]]


@st.composite
def chains(draw):
    """Random continuing chains: 2-4 segments, radii 1e-3..1 of the length, taper ratios
    up to 10:1 per segment (either way), bends 0-179° in turning planes."""
    n = draw(st.integers(2, 4))
    length = draw(st.floats(0.5, 2.0))
    r0 = length * 10 ** draw(st.floats(-3.0, 0.0))
    ratios = [10 ** draw(st.floats(-1.0, 1.0)) for _ in range(n)]
    radii = [r0]
    for q in ratios:
        radii.append(radii[-1] / q)
    if draw(st.booleans()):
        radii[-1] = 0.0                        # a cone that closes to a point
    radii = np.clip(radii, 0.0, length)
    bends = [draw(st.floats(0.0, 179.0)) for _ in range(n - 1)]
    turn = draw(st.floats(0.0, 180.0))
    return chain_skeleton(bends, length, radii, plane_turn_deg=turn)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(chains(), st.integers(0, 2**16))
def test_random_chains_have_no_holes(skeleton, seed):
    frusta = skin_skeleton(skeleton)
    o, d = medial_axis_rays(frusta, 600, seed=seed)
    hits = intersect_frusta(frusta, o, d)
    assert hits.hit.all(), f"{np.count_nonzero(~hits.hit)} of {len(o)} rays escaped"
    gap = seam_gap(frusta)[fitted_joints(frusta)]
    assert np.all(gap <= 1e-9), f"open seam: {gap.max():.3g} r"


@pytest.mark.parametrize("taper", [1.0, 1.5, 2.0, 3.3, 5.0, 10.0])
@pytest.mark.parametrize("bend", [0.0, 1e-6, 5.0, 20.0, 45.0, 90.0, 119.0])
def test_seams_close_over_tapers_and_bends(taper, bend):
    """The parent tapers ``taper``:1 into a child tapering 3:1; the paper's planes leave a
    gap wherever the two slopes differ and the joint bends, the fitted ones none."""
    skeleton = chain_skeleton([bend], 1.0, [0.3 * taper, 0.3, 0.1])
    closed = skin_skeleton(skeleton)
    if closed.report.sharp_joints:            # a knuckle: no shared plane to measure
        assert intersect_frusta(closed, *medial_axis_rays(closed, 800)).hit.all()
        return
    assert seam_gap(closed).max() <= 1e-12
    paper = skin_skeleton(skeleton, seam_fit=False)
    if bend >= 5.0 and taper >= 2.0 and not paper.report.sharp_joints:   # the test can fail:
        assert seam_gap(paper).max() > 1e-4    # the paper's seams gap here


def test_fitted_radii_put_both_cones_on_one_sphere():
    """seam_radii's closed form: the child's generators keep the parent's distance ρ from
    the joint, r1 / sqrt(1 + k²) = ρ, for cylinders, cones closing to a point, flares."""
    rng = np.random.default_rng(3)
    rho = rng.uniform(1e-3, 1.0, 500)
    r_end = np.concatenate([rng.uniform(0, 3, 400), np.zeros(100)]) * rho
    length = rng.uniform(0.05, 5.0, 500)
    r1 = sphere_base_radius(rho, r_end, length)
    inside = length**2 + r_end**2 <= rho**2       # the end rim inside the sphere: no cone
    assert inside.any() and np.isnan(r1[inside]).all()
    k = cone_slope(r1[~inside], r_end[~inside], length[~inside])
    np.testing.assert_allclose(r1[~inside] / np.sqrt(1 + k * k), rho[~inside], rtol=1e-12)
    cylinder = sphere_base_radius(np.array([0.2]), np.array([0.2]), np.array([1.0]))
    assert cylinder[0] == pytest.approx(0.2, rel=1e-15)


def inside_cameras(skeleton, views=12, size=64, seed=0):
    """Cameras on the parent's axis just before each joint (0.05..0.8 of its radius back),
    looking every way with a 100° field of view."""
    rng = np.random.default_rng(seed)
    for j in range(1, len(skeleton)):
        axis = skeleton.end[j - 1] - skeleton.start[j - 1]
        axis /= np.linalg.norm(axis)
        r = skeleton.r_end[j - 1]
        for _ in range(views):
            eye = skeleton.start[j] - axis * r * rng.uniform(0.05, 0.8)
            look = rng.normal(size=3)
            up = np.cross(look, rng.normal(size=3))
            yield Camera(tuple(eye), tuple(eye + look), tuple(up), 100.0, size, size)


@pytest.mark.parametrize("name", sorted(ISSUE_CHAINS))
def test_a_camera_inside_the_tube_sees_no_background(gl_ctx, name):
    from plantgen.render.raycast import Raycaster

    bends, radii = ISSUE_CHAINS[name]
    skeleton = chain_skeleton(bends, 1.0, radii)
    frusta = skin_skeleton(skeleton)
    caster = Raycaster(gl_ctx)
    for camera in inside_cameras(skeleton):
        assert render_reference(frusta, camera).hit.all()
        glsl = caster.render(frusta, camera, material_names=frusta.material_names).distance
        assert np.isfinite(glsl).all(), f"{np.count_nonzero(~np.isfinite(glsl))} background pixels"


def test_the_papers_planes_let_the_background_through():
    """The same check catches the open seams of the paper's construction (so the test
    above can fail)."""
    bends, radii = ISSUE_CHAINS["uneven_tapers"]
    skeleton = chain_skeleton(bends, 1.0, radii)
    paper = skin_skeleton(skeleton, seam_fit=False)
    misses = sum(int((~render_reference(paper, c).hit).sum()) for c in inside_cameras(skeleton))
    assert misses > 0
