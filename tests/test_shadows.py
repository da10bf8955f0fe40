"""Shadow maps (issue 6): the light's depth map holds the frusta's analytic intersection,
shadows fall where the light is blocked and nowhere else, stay attached at the feet,
and a lit surface does not shadow itself, even under grazing light."""

from __future__ import annotations

import numpy as np
import pytest

from plantgen.geometry.rays.camera import Camera
from plantgen.geometry.rays.reference import intersect_frusta
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.geometry.stage import Ground
from plantgen.gl.raycast import Raycaster
from plantgen.settings import RaycastSettings, ShadowSettings

GROUND = Ground(size=10.0, height=0.0, material="sand")
RADIUS = 0.3


def column(radius=RADIUS, height=2.0, r_top=None) -> Skeleton:
    """One upright frustum standing on the ground at the origin."""
    r_top = radius if r_top is None else r_top
    return Skeleton(np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, height, 0.0]]),
                    np.array([radius]), np.array([r_top]), np.array([-1]), np.array([False]),
                    np.zeros(1, int), ("bark",))


def light_towards(elevation_deg: float, azimuth_deg: float = 30.0) -> np.ndarray:
    """(3,) unit direction towards the light, ``elevation_deg`` above the horizon."""
    e, a = np.radians(elevation_deg), np.radians(azimuth_deg)
    return np.array([np.cos(e) * np.cos(a), np.sin(e), np.cos(e) * np.sin(a)])


@pytest.fixture(scope="module")
def caster():
    from plantgen.gl.context import gl_context
    return Raycaster(gl_context())


def top_down_camera(size=(96, 96), eye=(0.5, 9.0, 0.8)) -> Camera:
    return Camera(eye, (0.0, 0.0, 0.0), (0.0, 0.0, -1.0), 45.0, *size)


def analytic_shadow(frusta, points, to_light) -> np.ndarray:
    """(k,) bool: the ray from each point towards the light hits a frustum."""
    start = points + 1e-6 * to_light
    return intersect_frusta(frusta, start, np.broadcast_to(to_light, points.shape)).hit


@pytest.mark.parametrize("elevation", [45.0, 12.0, 5.0])
def test_ground_is_shadowed_exactly_where_the_light_is_blocked(gl_ctx, caster, elevation):
    """Ground pixels that the column blocks from the light are darker than without shadows;
    ground pixels it does not block are unchanged (no acne on the lit ground even at 5°
    above the horizon); only a band of a few shadow texels around the edge is soft."""
    frusta = skin_skeleton(column())
    to_light = light_towards(elevation)
    camera = top_down_camera()
    shadows = ShadowSettings(resolution=512)
    plain = caster.render(frusta, camera, RaycastSettings(), ("bark",), to_light, GROUND)
    shadowed = caster.render(frusta, camera, RaycastSettings(), ("bark",), to_light, GROUND,
                             shadows=shadows)
    window = shadowed.stats.light_window
    texel = window.texel_size(shadows.resolution)
    eye, dirs = camera.rays()
    points = eye + plain.distance[..., None].astype(np.float64) * dirs
    ground = np.isfinite(plain.distance) & (np.abs(points[..., 1]) < 1e-3)
    q = points[ground]
    # analytic shadow at the pixel and at points two texels (stretched along the light's
    # footprint) around it: all blocked = surely in shadow, none = surely lit
    along = to_light * np.array([1, 0, 1])
    along /= np.linalg.norm(along)
    across = np.cross(along, [0, 1, 0])
    stretch = 3 * texel / np.sin(np.radians(elevation))
    samples = [q] + [q + s * v for s, v in ((stretch, along), (-stretch, along),
                                            (3 * texel, across), (-3 * texel, across))]
    blocked = np.stack([analytic_shadow(frusta, s, to_light) for s in samples])
    surely_lit, surely_dark = ~blocked.any(axis=0), blocked.all(axis=0)
    assert surely_dark.sum() > 20 and surely_lit.sum() > 1000
    lum_plain = plain.color[ground].astype(int).sum(axis=1)
    lum_shadow = shadowed.color[ground].astype(int).sum(axis=1)
    assert np.abs(lum_shadow - lum_plain)[surely_lit].max() <= 3          # no acne
    darkening = (lum_plain - lum_shadow)[surely_dark]
    expected = max(20, int(0.25 * np.median(lum_plain[surely_dark]) * np.sin(np.radians(elevation))))
    assert darkening.min() >= min(expected, 60)


@pytest.mark.parametrize("elevation", [60.0, 10.0, 3.0])
def test_a_convex_frustum_does_not_shadow_itself(gl_ctx, caster, elevation):
    """A single convex frustum cannot shadow any part of itself: with shadows on, its
    pixels equal those rendered without shadows, for grazing light too (no acne)."""
    frusta = skin_skeleton(column(r_top=0.15))
    to_light = light_towards(elevation, azimuth_deg=-60.0)
    camera = Camera((3.0, 2.5, 4.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), 40.0, 96, 96)
    plain = caster.render(frusta, camera, RaycastSettings(), ("bark",), to_light)
    shadowed = caster.render(frusta, camera, RaycastSettings(), ("bark",), to_light,
                             shadows=ShadowSettings(resolution=256))
    hit = np.isfinite(plain.distance)
    assert hit.sum() > 500
    diff = np.abs(plain.color[hit].astype(int) - shadowed.color[hit].astype(int)).max(axis=1)
    assert diff.max() <= 3, (diff.max(), (diff > 3).sum())


@pytest.mark.parametrize("elevation,azimuth", [(60.0, 30.0), (45.0, 30.0), (70.0, -60.0)])
def test_a_steep_relief_cone_in_the_sun_does_not_shadow_itself(gl_ctx, caster, elevation, azimuth):
    """A relief-mapped cone as steep as the well's roof (radius 1.35 closing to a point
    over 0.95), seen from the sun's side: the float64 reference's relief hardly shadows
    itself there, so with shadows on nearly every pixel keeps its light. The receiver
    plane is the relief surface's own; on the interpolated normal (8), nearly radial on so
    steep a cone, the map's taps fell behind the relief and 99 % of the pixels lost a
    tenth of their light."""
    from plantgen.geometry.rays.reference import intersect_frusta
    sk = Skeleton(np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 0.95, 0.0]]), np.array([1.35]), np.array([0.0]),
                  np.array([-1]), np.array([False]), np.zeros(1, int), ("bark",))
    frusta = skin_skeleton(sk)
    to_light = light_towards(elevation, azimuth)
    camera = Camera(tuple(4.5 * to_light + [0.0, 0.4, 0.0]), (0.0, 0.4, 0.0), (0.0, 1.0, 0.0), 40.0, 96, 96)
    settings = RaycastSettings(relief=True)
    plain = caster.render(frusta, camera, settings, ("bark",), to_light)
    shadowed = caster.render(frusta, camera, settings, ("bark",), to_light, shadows=ShadowSettings(resolution=1024))
    hit = np.isfinite(plain.distance)
    assert hit.sum() > 3000
    eye, dirs = camera.rays()
    points = (eye + plain.distance[..., None].astype(np.float64) * dirs)[hit]
    blocked = intersect_frusta(frusta, points + 2e-3 * to_light, np.broadcast_to(to_light, points.shape),
                               relief=True).hit
    assert blocked.mean() < 0.02                       # the sunlit side: the relief hardly shadows itself
    lum_plain = plain.color[hit].astype(float).sum(axis=1)
    lum_shadow = shadowed.color[hit].astype(float).sum(axis=1)
    assert lum_shadow.sum() / lum_plain.sum() > 0.97
    assert np.mean(lum_plain - lum_shadow > 10) < 0.2


def test_shadow_starts_at_the_foot(gl_ctx, caster):
    """No detached shadow: ground just outside the column's foot, on the side away from
    the light, is in shadow within two shadow texels of the surface."""
    frusta = skin_skeleton(column())
    to_light = light_towards(40.0)
    away = -to_light * np.array([1, 0, 1])
    away /= np.linalg.norm(away)
    camera = top_down_camera((160, 160), eye=tuple(3 * away + [0, 6, 0]))   # sees the shadow side
    shadows = ShadowSettings(resolution=1024)
    plain = caster.render(frusta, camera, RaycastSettings(), ("bark",), to_light, GROUND)
    result = caster.render(frusta, camera, RaycastSettings(), ("bark",), to_light, GROUND,
                           shadows=shadows)
    texel = result.stats.light_window.texel_size(shadows.resolution)
    eye, dirs = camera.rays()
    points = eye + plain.distance[..., None].astype(np.float64) * dirs
    ground = np.isfinite(plain.distance) & (np.abs(points[..., 1]) < 1e-3)
    radial = np.linalg.norm(points[..., [0, 2]], axis=-1)
    facing = (points[..., [0, 2]] @ away[[0, 2]]) / np.maximum(radial, 1e-9)
    foot = ground & (radial > RADIUS) & (radial < RADIUS + 2 * texel + 0.06) & (facing > 0.9)
    assert foot.sum() >= 3
    def lum(img):
        return img.astype(int).sum(axis=-1)
    assert (lum(plain.color)[foot] - lum(result.color)[foot]).min() >= 20


def light_rays(window, resolution: int, eye) -> tuple[np.ndarray, np.ndarray]:
    """World origins (on the window's near plane) and direction of the light's rays
    through the shadow map's texel centres; (res, res, 3), row 0 the window's bottom."""
    c = (np.arange(resolution) + 0.5) / resolution * 2 - 1
    x, y = np.meshgrid(c, c)
    origins = (np.asarray(eye) + window.origin + window.depth[0] * window.forward
               + x[..., None] * window.half[0] * window.right + y[..., None] * window.half[1] * window.up)
    return origins, window.forward


@pytest.mark.parametrize("relief,march", [(False, "default"), (True, "fine"), (True, "default"),
                                          (True, "bisect"), (True, "bisect-fine")])
def test_light_depth_map_holds_the_analytic_intersection(gl_ctx, caster, relief, march):
    """Each texel of the light's depth map holds the depth of the light ray's first hit
    with the true frustum (float64 reference), not with its bounding pyramid; with
    relief the relief surface casts (between the inner cone and the shell): to float32
    precision with a fine march, and within a fraction of a map texel (below the receivers'
    half-texel bias) with the default march sized to the map's texels; the light's own
    (secant) march and the eye's (bisect) alike."""
    sk = Skeleton(np.array([[0.0, 0.0, 0.0], [0.0, 1.2, 0.0]]), np.array([[0.0, 1.2, 0.0], [0.5, 2.1, 0.2]]),
                  np.array([0.45, 0.35]), np.array([0.35, 0.05]), np.array([-1, 0]),
                  np.array([False, True]), np.zeros(2, int), ("bark",))
    frusta = skin_skeleton(sk)
    to_light = light_towards(35.0)
    camera = Camera((3.0, 2.0, 4.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), 40.0, 32, 32)
    res = 96
    knobs = {"march_density": 8.0, "march_precision": 1e-3} if march.endswith("fine") else {}
    knobs |= {"march": "bisect"} if march.startswith("bisect") else {}
    caster.render(frusta, camera, RaycastSettings(relief=relief), ("bark",), to_light,
                  shadows=ShadowSettings(resolution=res, **knobs))
    depths = caster.shadow_depths()   # the map of the last render
    window = caster.last_light_window
    origins, direction = light_rays(window, res, camera.eye)
    span = window.depth[1] - window.depth[0]
    inner = intersect_frusta(frusta, origins, np.broadcast_to(direction, origins.shape))
    drawn = depths < 1.0
    if not relief:
        # coverage: the frustum's, not the pyramid's (pyramid area is ~27 % larger)
        mismatch = drawn != inner.hit
        assert mismatch.mean() < 0.01
        both = drawn & inner.hit
        err = np.abs(depths[both] * span - inner.t[both])
        assert err.max() < 1e-4 * span + 1e-5
    else:
        # the relief surface casts: the float64 reference's relief hits (same height maps)
        relief_hits = intersect_frusta(frusta, origins, np.broadcast_to(direction, origins.shape),
                                       relief=True)
        assert frusta.shell.max() > 0
        z = depths * span
        assert np.mean(drawn != relief_hits.hit) < 0.01
        both = drawn & relief_hits.hit
        err = np.abs(z[both] - relief_hits.t[both])
        if march.endswith("fine"):
            assert np.median(err) < 1e-4 * span and np.mean(err > 5e-3 * span) < 0.005
        else:
            texel = window.texel_size(res)
            assert np.median(err) < 0.25 * texel and np.mean(err > 0.5 * texel) < 0.01, \
                (np.median(err) / texel, np.mean(err > 0.5 * texel))
        # and it is not the inner cone's shadow: relief stands proud of it on many texels
        on_inner = both & inner.hit
        assert np.mean(z[on_inner] < inner.t[on_inner] - 1e-3 * span) > 0.2


def test_one_corner_texel_holds_the_four_heights_a_gather_returns():
    """The light's march fetches a bilinear cell's four heights in one texel
    (material_uniforms.corner_maps): interpolating them as shaders/heights.glsl does gives
    the reference's bilinear height (u repeats, v clamps), at the map's edges too."""
    from plantgen.geometry.skeletons.relief import height_map, sample_height
    from plantgen.gl.material_uniforms import corner_maps

    maps = np.stack([height_map("bark", (16, 24)), height_map("stone", (16, 24))])
    cells = corner_maps(maps).astype(np.float64) / 255.0
    rng = np.random.default_rng(3)
    u, v = rng.uniform(-0.5, 1.5, 400), np.concatenate([rng.uniform(-0.2, 1.2, 396), [0.0, 1.0, 0.01, 0.99]])
    for layer in range(2):
        h, w = maps[layer].shape
        x = (u - np.floor(u)) * w - 0.5
        y = np.clip(v, 0.0, 1.0) * h - 0.5
        cx, cy = np.floor(x), np.floor(y)
        fx, fy = x - cx, y - cy
        g = cells[layer, cy.astype(int) + 1, np.where(cx < 0, cx + w, cx).astype(int)]
        got = (g[:, 3] * (1 - fx) + g[:, 2] * fx) * (1 - fy) + (g[:, 0] * (1 - fx) + g[:, 1] * fx) * fy
        assert np.allclose(got, sample_height(maps[layer], u, v), atol=1e-12)
