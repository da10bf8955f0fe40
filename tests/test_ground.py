"""The ground (issue 43): a single plant stands on a disc that fades into the sky and takes
its shadow; a scene's square fades at its edge; ``--ground none`` draws none."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from plantgen.geometry.stage import Ground, model_ground
from plantgen.pipeline import frame_arguments, prepare_model, render_model, stage_model
from plantgen.settings import ImageSettings, RenderSettings

SIZE = (160, 120)


def luminance(rgb) -> np.ndarray:
    return np.asarray(rgb, np.float64) @ np.array([0.2126, 0.7152, 0.0722])


@pytest.fixture(scope="module")
def saguaro():
    # without anti-aliasing: its edge pass mixes a ground pixel beside the plant with the
    # plant's edge, which the rim's steps below would count as the ground's
    return render_model("saguaro", size=SIZE, aa="none")


def test_the_disc_is_under_the_plant_and_reaches_past_its_shadow():
    box = np.array([[-1.0, -0.1, -2.0], [3.0, 6.0, 2.0]])
    ground = model_ground(box)
    assert ground.shape == "disc" and ground.height == -0.1 and ground.centre == (1.0, 0.0)
    assert ground.half >= 2 * (box[1, 1] - box[0, 1])
    quad = ground.quad()
    assert np.allclose(quad[:, 1], -0.1) and np.allclose(np.ptp(quad[:, [0, 2]], axis=0), 2 * ground.half)
    with pytest.raises(ValueError):
        Ground(shape="hexagon")


def test_a_single_plant_stands_on_ground_that_recedes_to_the_horizon(gl_ctx, saguaro):
    """Every pixel of the bottom rows sees the ground; up a column beside the plant the
    ground's distance grows towards the horizon, then the sky begins (a miss)."""
    distance = saguaro.result.distance
    assert np.isfinite(distance[-8:]).all()
    column = distance[::-1, 8]                   # bottom to top, at the image's left
    ground = column[np.isfinite(column)]
    assert len(ground) > 10 and np.all(np.diff(ground) > 0)
    assert not np.isfinite(distance[0]).any()    # the top row is sky


def test_the_discs_rim_shows_no_edge_against_the_sky(gl_ctx, saguaro):
    """Where a column passes from the ground to the sky, the colour steps by no more than
    a few levels: the ground has faded into the sky behind it."""
    model = prepare_model("saguaro")
    ground = stage_model(model.grown, model.frusta_at(0.0), *SIZE, ground="auto").ground
    steps = ground_steps(saguaro, ground.height)
    assert len(steps) > 10 and max(steps) <= 4.0, (len(steps), max(steps))


def test_ground_none_draws_what_a_plant_without_ground_draws(gl_ctx):
    from plantgen.gl.raycast import Raycaster
    report = render_model("saguaro", size=SIZE, ground="none")
    assert not np.isfinite(report.result.distance[-8:, :20]).any()      # beside the trunk: sky
    model = prepare_model("saguaro")
    frusta = model.frusta_at(0.0)
    staging = stage_model(model.grown, frusta, *SIZE)
    assert staging.ground is None               # what the benches and the old renders drew
    settings, _ = RenderSettings().frame(model.effects)
    plain = Raycaster().render(frusta, settings=settings, **frame_arguments(frusta, staging, None, ImageSettings()))
    assert np.array_equal(report.result.color, plain.color)


def test_a_transparent_background_keeps_the_plants_coverage(gl_ctx):
    report = render_model("saguaro", size=SIZE, background="none")
    alpha = report.result.color[..., 3]
    assert np.array_equal(alpha == 255, np.isfinite(report.result.distance))


def test_the_ground_takes_the_plants_shadow(gl_ctx):
    lit = render_model("coconut", size=SIZE)
    shaded = render_model("coconut", size=SIZE, shadows=True)
    on_ground = np.isfinite(lit.result.distance) & (lit.result.distance == shaded.result.distance)
    drop = luminance(lit.result.color) - luminance(shaded.result.color)
    assert (drop[on_ground] > 10).sum() > 50          # the shadow
    assert (drop[on_ground] < -3).sum() == 0          # nothing brighter


def ground_steps(report, height: float) -> list:
    """Luminance steps between horizontal or vertical neighbours where one sees the ground
    (a point at y = ``height``) and the other the sky (a miss)."""
    distance, color = report.result.distance, report.result.color.astype(np.float64)
    eye, dirs = report.camera.rays()
    with np.errstate(invalid="ignore"):
        points = eye + np.where(np.isfinite(distance), distance, 0.0)[..., None] * dirs
    on_ground = np.isfinite(distance) & (np.abs(points[..., 1] - height) < 1e-2)
    sky = ~np.isfinite(distance)
    lum = luminance(color[..., :3])
    steps = []
    for a, b in ((np.s_[:, :-1], np.s_[:, 1:]), (np.s_[:-1, :], np.s_[1:, :])):
        edge = (on_ground[a] & sky[b]) | (sky[a] & on_ground[b])
        steps.extend(np.abs(lum[a] - lum[b])[edge])
    return steps


def test_a_scenes_square_fades_at_its_edge(gl_ctx):
    """The desert's ground meets the sky without a step where its square ends."""
    report = render_model("desert", size=SIZE, effects="none", aa="none")   # as the saguaro fixture's
    steps = ground_steps(report, 0.0)
    assert len(steps) > 20 and max(steps) <= 4.0, (len(steps), max(steps))


@pytest.mark.parametrize("background, tone", [("sky", True), ("none", True), ("sky", False), ("none", False)])
@pytest.mark.parametrize("n", [2, 3])
def test_the_gpu_resolve_is_the_cpu_average(gl_ctx, background, tone, n):
    """Supersampling averages on the GPU (GpuResolve): the same pixels as the CPU's
    reference average of the large frame, in the frame's own encoding (sRGB with the tone
    effect, else c^(1/2.2)), to one level of 255, and the same distances."""
    from plantgen.gl.raycast import Raycaster
    from plantgen.gl.supersample import resolve_supersamples
    model = prepare_model("pine")
    frusta = model.frusta_at(0.0)
    settings, _ = RenderSettings().frame(model.effects)
    settings = replace(settings, look=replace(settings.look, tone=tone))
    staging = stage_model(model.grown, frusta, 96, 72, ground="auto")
    caster = Raycaster()
    result = caster.render(frusta, settings=settings,
                           **frame_arguments(frusta, staging, None, ImageSettings(ssaa=n, background=background)))
    fbo, k = caster._fbo, result.color.shape[-1]
    large = np.frombuffer(fbo.read(components=k, attachment=0, alignment=1), np.uint8).reshape(72 * n, 96 * n, k)
    distance = np.frombuffer(fbo.read(components=1, attachment=1, dtype="f4", alignment=1), np.float32)
    color, centre = resolve_supersamples(large[::-1], distance.reshape(72 * n, 96 * n)[::-1], n, srgb=tone)
    assert color.shape == result.color.shape
    assert np.abs(color.astype(int) - result.color.astype(int)).max() <= 1
    assert np.array_equal(centre, result.distance)
