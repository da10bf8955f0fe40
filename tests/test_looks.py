"""Light that reads as daylight (issue 43, part 3): the looks, each an effect.

Physical invariants: the tone curves are monotone and map 0 to 0; a leaf lit from behind
glows, more with more transmission, and none goes black; the traced sky light is the open
hemisphere's on an open surface, nothing inside a closed tube, converges as its samples
grow, and is the same every time; the soft sun widens the shadow's edge; with the looks
off the programs carry none of their code and the frame is today's.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from plantgen.geometry.meshes.polygons import Polygons
from plantgen.geometry.rays.camera import Camera
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.geometry.stage import Ground
from plantgen.gl.material_uniforms import SKY
from plantgen.gl.passes import program_variants
from plantgen.gl.raycast import Raycaster
from plantgen.gl.rt import RayTracer
from plantgen.gl.shaders import build_program
from plantgen.gl.supersample import srgb_decode, srgb_encode, tone_curve
from plantgen.settings import (
    DEFAULT_EFFECTS,
    EffectSettings,
    LookSettings,
    RaycastSettings,
    RenderSettings,
    ShadowSettings,
)

NAMES = ("bark", "leaf")
PLAIN = LookSettings()                                   # every look off: today's shading
LOOK_DEFINES = ("TONE_MAP", "TONE_ACES", "TRANSLUCENT", "SKY_LIGHT", "SOFT_SUN", "GROUND_BOUNCE")


def column(base=(0.0, 0.0, 0.0), height: float = 2.0, radius: float = 0.3) -> Skeleton:
    b = np.asarray(base, np.float64)
    return Skeleton(np.array([b]), np.array([b + (0.0, height, 0.0)]), np.array([radius]), np.array([radius]),
                    np.array([-1]), np.array([False]), np.zeros(1, int), NAMES)


def square(centre, half: float, normal) -> Polygons:
    """One square leaf (material 1) of side 2*half centred at ``centre``, its normal ``normal``."""
    n = np.asarray(normal, np.float64)
    n = n / np.linalg.norm(n)
    a = np.cross(n, [0.0, 1.0, 0.0] if abs(n[1]) < 0.9 else [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    c = np.asarray(centre, np.float64)
    corners = np.array([c + half * (s * a + t * b) for s, t in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    return Polygons(corners, np.array([[0, 1, 2], [0, 2, 3]]), np.zeros(2, np.int64), np.array([1], np.int32),
                    n[None])


@pytest.fixture(scope="module")
def renderers():
    from plantgen.gl.context import gl_context
    ctx = gl_context()
    return {"rc": Raycaster(ctx), "rt": RayTracer(ctx)}


def draw(renderers, kind, frusta, camera, look, **kw):
    return renderers[kind].render(frusta, camera, RaycastSettings(look=look), NAMES, **kw)


def luminance(rgb) -> np.ndarray:
    c = np.asarray(rgb, np.float64)[..., :3] / 255.0
    return 0.2126 * c[..., 0] + 0.7152 * c[..., 1] + 0.0722 * c[..., 2]


# ---------------------------------------------------------------------- tone and encoding
@pytest.mark.parametrize("curve", ["filmic", "aces"])
def test_the_tone_curves_are_monotone_map_zero_to_zero_and_never_clip(curve):
    x = np.concatenate([np.linspace(0.0, 2.0, 2001), np.geomspace(2.0, 1e4, 200)])
    y = tone_curve(x, curve=curve)
    assert y[0] == 0.0
    assert np.all(np.diff(y) >= 0.0) and np.all(np.diff(y[:2001]) > 0.0)
    assert np.all(y <= 1.0) and y[2000] < 1.0          # 2.0 (twice a white sunlit surface) is not clipped
    if curve == "filmic":                                # shadows and mid-tones kept
        low = x < 0.7
        assert np.array_equal(y[low], x[low])


def test_srgb_is_the_standard_curve_and_round_trips():
    x = np.linspace(0.0, 1.0, 1001)
    assert np.allclose(srgb_decode(srgb_encode(x)), x, atol=1e-12)
    assert srgb_encode(0.0031308) == pytest.approx(0.04045, abs=1e-5)
    assert srgb_encode(0.18) == pytest.approx(0.4614, abs=1e-4)
    assert srgb_encode(1.0) == pytest.approx(1.0)


def sky_colour(d: np.ndarray) -> np.ndarray:
    """shading.glsl's sky_color (numpy), directions (..., 3) with y up."""
    up = d[..., 1:2]
    zen, hor, gnd = (np.asarray(SKY[k]) for k in ("sky_zenith", "sky_horizon", "ground_tint"))
    above = hor + (zen - hor) * np.maximum(up, 0.0) ** 0.6
    below = hor + (gnd - hor) * np.maximum(-up, 0.0) ** 0.5
    return np.where(up >= 0.0, above, below)


@pytest.mark.parametrize("curve", ["filmic", "aces"])
def test_the_sky_goes_through_the_same_tone_curve_and_encoding_as_the_model(renderers, curve):
    frusta = skin_skeleton(column((0.0, 0.0, -40.0), 0.5, 0.05))
    camera = Camera((0.0, 1.0, 5.0), (0.0, 1.5, 0.0), (0.0, 1.0, 0.0), 60.0, 48, 40)
    result = draw(renderers, "rc", frusta, camera, LookSettings(tone=True, tone_curve=curve))
    sky = ~np.isfinite(result.distance)
    _, dirs = camera.rays()
    expected = 255.0 * srgb_encode(tone_curve(sky_colour(dirs), curve=curve))
    assert sky.sum() > 1000
    assert np.max(np.abs(result.color[sky].astype(float) - expected[sky])) <= 1.0


def test_supersampling_averages_in_the_frames_own_encoding(renderers):
    frusta = skin_skeleton(column())
    camera = Camera((1.5, 1.5, 4.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), 35.0, 24, 24)
    look = LookSettings(tone=True)
    big = draw(renderers, "rc", frusta, camera.scaled(2), look)
    small = draw(renderers, "rc", frusta, camera, look, ssaa=2)
    mean = srgb_decode(big.color / 255.0).reshape(24, 2, 24, 2, 3).mean(axis=(1, 3))
    assert np.max(np.abs(small.color - 255.0 * srgb_encode(mean))) <= 1.0


# ---------------------------------------------------------------------- looks off: today's code
def test_with_the_looks_off_no_program_has_their_defines_or_code(gl_ctx):
    for settings in (RaycastSettings(), RaycastSettings(relief=True)):
        for shadows in (None, ShadowSettings()):
            for _, defines in program_variants(settings, shadows, True, False, True):
                assert not any(defines.get(k) for k in LOOK_DEFINES)
    plain = build_program(gl_ctx, "leaf.glsl", {"SHADOWS": False, "LABELS": False})
    lit = build_program(gl_ctx, "leaf.glsl", {"SHADOWS": False, "LABELS": False, "TRANSLUCENT": True,
                                              "TONE_MAP": True})
    for name in ("leaf_transmission", "exposure", "tone_knee"):
        assert name not in plain and name in lit


def test_the_effects_turn_the_looks_on_and_off():
    assert set(DEFAULT_EFFECTS) == {"tone", "translucency"}
    assert EffectSettings().resolve(("relief",)) == ("relief", "tone", "translucency")
    assert EffectSettings(effects="relief").resolve(()) == ("relief",)           # --effects replaces all
    assert EffectSettings(tone=False, sky=True, bounce=False).resolve(()) == ("translucency", "sky")
    march, _ = RenderSettings().frame(("tone", "sky"))
    assert (march.look.tone, march.look.translucency, march.look.sky, march.look.bounce) == (True, False, True, False)
    march, _ = RenderSettings().frame(("bounce",))
    assert march.look.bounce and march.look.defines()["GROUND_BOUNCE"]
    march, _ = RenderSettings().frame(())
    assert march.look == PLAIN and not any(march.look.defines().values())


def test_a_frame_with_the_looks_off_is_the_plain_frame(renderers):
    # looks off with their knobs set: the knobs alone change nothing
    frusta = skin_skeleton(column())
    camera = Camera((1.5, 2.5, 4.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), 35.0, 48, 48)
    leaf = square((0.6, 1.2, 0.5), 0.3, (0.3, 0.2, 1.0))
    knobs = LookSettings(transmission=0.9, exposure=2.0, sky_samples=3, tone_curve="aces")
    for kind in ("rc", "rt"):
        a = draw(renderers, kind, frusta, camera, PLAIN, leaves=leaf, shadows=ShadowSettings(resolution=256))
        b = draw(renderers, kind, frusta, camera, knobs, leaves=leaf, shadows=ShadowSettings(resolution=256))
        assert np.array_equal(a.color, b.color)


# ---------------------------------------------------------------------- translucent leaves
def back_lit(renderers, look, normal=(0.0, 0.0, 1.0), kind="rc"):
    """A leaf facing the eye (+z), the sun behind it: its pixels' colours (k, 3)."""
    frusta = skin_skeleton(column((5.0, 0.0, -5.0), 0.5, 0.05))
    camera = Camera((0.0, 1.0, 4.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), 30.0, 48, 48)
    leaf = square((0.0, 1.0, 0.0), 0.5, normal)
    result = draw(renderers, kind, frusta, camera, look, leaves=leaf, light_dir=(0.2, 0.3, -1.0))
    seen = np.isfinite(result.distance) & (np.abs(result.distance - 4.0) < 0.5)
    assert seen.sum() > 100
    return result.color[seen]


@pytest.mark.parametrize("kind", ["rc", "rt"])
def test_a_back_lit_leaf_glows_and_more_with_more_transmission(renderers, kind):
    plain = luminance(back_lit(renderers, PLAIN, kind=kind)).mean()
    glow = [luminance(back_lit(renderers, LookSettings(translucency=True, transmission=t), kind=kind)).mean()
            for t in (0.0, 0.25, 0.5, 1.0)]
    assert glow[0] == pytest.approx(plain, abs=1.5 / 255)            # nothing through: as before
    assert np.all(np.diff(glow) > 2 / 255)                              # rises with the transmission
    # the light through the leaf is its albedo's: green
    rgb = back_lit(renderers, LookSettings(translucency=True, transmission=1.0), kind=kind).mean(axis=0)
    assert rgb[1] > rgb[0] and rgb[1] > rgb[2]


def test_no_leaf_goes_black(renderers):
    # a leaf whose side seen faces down, the sun behind it: little sky and no sun on that
    # side (today: near black), lit through by both with translucency
    normal = (0.0, -0.8, 0.6)
    dark = luminance(back_lit(renderers, PLAIN, normal))
    lit = luminance(back_lit(renderers, LookSettings(tone=True, translucency=True), normal))
    assert dark.max() < 0.15 < lit.min() and lit.min() > 2 * dark.max()


# ---------------------------------------------------------------------- sky light
def sky_only(look: LookSettings) -> LookSettings:
    return replace(look, sky=True, tone=False, translucency=False)


@pytest.mark.parametrize("kind", ["rc", "rt"])
def test_an_open_surface_gets_the_open_hemispheres_sky(renderers, kind):
    # a tilted leaf with nothing around: its traced sky light is 0.5 + 0.5 n.y in the mean
    frusta = skin_skeleton(column((6.0, 0.0, -6.0), 0.5, 0.05))
    camera = Camera((0.0, 4.0, 3.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 40.0, 48, 48)
    leaf = square((0.0, 0.0, 0.0), 1.0, (0.0, 1.0, 1.0))
    below = (0.0, -1.0, 0.0)         # the sun under the leaf: the side seen gets sky alone
    plain = draw(renderers, kind, frusta, camera, PLAIN, leaves=leaf, light_dir=below)
    traced = draw(renderers, kind, frusta, camera, sky_only(LookSettings(sky_samples=64)), leaves=leaf,
                  light_dir=below)
    seen = np.isfinite(plain.distance) & (plain.distance < 10)
    assert seen.sum() > 300
    ratio = srgb_like(traced.color[seen]).mean(axis=0) / srgb_like(plain.color[seen]).mean(axis=0)
    assert np.allclose(ratio, 1.0, atol=0.03)


def srgb_like(rgb) -> np.ndarray:
    """Linear light of a plain frame's (c^(1/2.2)) colours."""
    return (np.asarray(rgb, np.float64) / 255.0) ** 2.2


@pytest.mark.parametrize("kind", ["rc", "rt"])
def test_inside_a_closed_tube_no_sky_reaches(renderers, kind):
    frusta = skin_skeleton(column((0.0, -20.0, 0.0), 40.0, 1.0))
    camera = Camera((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), 30.0, 32, 32)
    away = (1.0, 0.0, 0.0)           # the sun outside the wall seen: that wall gets sky alone
    plain = draw(renderers, kind, frusta, camera, PLAIN, light_dir=away)
    traced = draw(renderers, kind, frusta, camera, sky_only(LookSettings(sky_reach=2.0)), light_dir=away)
    wall = np.isfinite(plain.distance)
    assert wall.all() and srgb_like(plain.color).mean() > 0.005
    assert srgb_like(traced.color).mean() < 0.05 * srgb_like(plain.color).mean()


@pytest.mark.parametrize("kind", ["rc", "rt"])
def test_the_ground_traces_the_sky_too(renderers, kind):
    """The ground gets the sky light as the model does: open ground keeps the open
    hemisphere's light exactly; beside a post's foot the post hides part of the sky."""
    frusta = skin_skeleton(column((0.0, 0.0, 0.0), 2.5, 0.4))
    camera = Camera((0.0, 6.0, 3.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0), 45.0, 64, 64)
    kw = dict(ground=Ground(40.0), light_dir=(0.0, -1.0, 0.0))      # the sun below: the ground gets sky alone
    plain = draw(renderers, kind, frusta, camera, PLAIN, **kw)
    traced = draw(renderers, kind, frusta, camera, sky_only(LookSettings(sky_samples=64, sky_reach=0.3)), **kw)
    origins, dirs = camera.rays()
    hit = origins + np.where(np.isfinite(plain.distance), plain.distance, 0.0)[..., None] * dirs
    ground = np.isfinite(plain.distance) & (np.abs(hit[..., 1]) < 1e-2)
    r = np.hypot(hit[..., 0], hit[..., 2])
    far, near = ground & (r > 1.5), ground & (r < 0.6)
    assert far.sum() > 500 and near.sum() > 10
    assert np.abs(traced.color[far].astype(int) - plain.color[far].astype(int)).max() <= 1
    ratio = srgb_like(traced.color[near]).mean() / srgb_like(plain.color[near]).mean()
    assert ratio < 0.85, ratio


def partly_open(renderers, kind, samples):
    """A leaf on the ground beside a post, lit by the sky alone: linear colours (h, w, 3)."""
    frusta = skin_skeleton(column((0.0, 0.0, 0.0), 3.0, 0.6))
    camera = Camera((0.0, 4.0, 4.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0), 40.0, 40, 40)
    leaf = square((0.0, 0.02, 1.5), 1.2, (0.0, 1.0, 0.0))
    result = draw(renderers, kind, frusta, camera, sky_only(LookSettings(sky_samples=samples)), leaves=leaf,
                  light_dir=(0.0, -1.0, 0.0))
    return srgb_like(result.color), np.isfinite(result.distance)


@pytest.mark.parametrize("kind", ["rc", "rt"])
def test_more_sky_samples_lower_the_noise_and_a_frame_is_deterministic(renderers, kind):
    reference, seen = partly_open(renderers, kind, 256)
    errors = []
    for samples in (4, 64):
        a, _ = partly_open(renderers, kind, samples)
        b, _ = partly_open(renderers, kind, samples)
        assert np.array_equal(a, b)                                # no time seed
        errors.append(np.sqrt(np.mean((a[seen] - reference[seen]) ** 2)))
    assert errors[1] < 0.5 * errors[0]
    # the post darkens the leaf next to it: occlusion, not an open hemisphere
    assert reference[seen].min() < 0.8 * np.percentile(reference[seen], 95)


# ---------------------------------------------------------------------- the ground's light
BOUNCE = LookSettings(bounce=True)
LIGHT = (0.45, 0.8, 0.35)                     # the model light's, towards the sun


def shaded_side(renderers, kind, look, ground, leaf=None, height: float = 3.0, heights: bool = False):
    """A post on ``ground`` seen from the side the sun does not reach (its normals
    horizontal, turned from the light, so the sky and the ground light it alone):
    linear colours of its pixels (k, 3), and of the ground's (m, 3); with ``heights``
    also the post's pixels' heights (k,)."""
    frusta = skin_skeleton(column((0.0, 0.0, 0.0), height, 0.5))
    mid = 0.5 * height
    camera = Camera((-1.5 * height, mid, -1.17 * height), (0.0, mid, 0.0), (0.0, 1.0, 0.0), 30.0, 48, 48)
    result = draw(renderers, kind, frusta, camera, look, ground=ground, light_dir=LIGHT, leaves=leaf)
    origins, dirs = camera.rays()
    seen = np.isfinite(result.distance)
    hit = origins + np.where(seen, result.distance, 0.0)[..., None] * dirs
    post = seen & (hit[..., 1] > 0.1) & (np.hypot(hit[..., 0], hit[..., 2]) < 0.6)
    floor = seen & (np.abs(hit[..., 1]) < 1e-2) & (np.hypot(hit[..., 0], hit[..., 2]) > 1.0)
    assert post.sum() > 100
    if heights:
        return srgb_like(result.color[post]), hit[..., 1][post]
    return srgb_like(result.color[post]), srgb_like(result.color[floor])


@pytest.mark.parametrize("kind", ["rc", "rt"])
def test_the_sunlit_ground_lights_the_shaded_side_from_below(renderers, kind):
    """Cycles' reference of the looks bench lights a plant's shaded side with the sand's
    light; plantgen lit it with the sky alone, so the saguaro's shade was a third of the
    reference's. On a vertical surface turned from the sun the sky gives ambient / 2 and
    the ground ground_light / 2: each channel grows by 1 + ground_light / ambient,
    whatever the albedo."""
    from plantgen.gl.material_uniforms import AMBIENT_COLOR, ground_light

    sand = Ground(4000.0)                                     # the ground's edge far below the horizon
    plain, plain_floor = shaded_side(renderers, kind, PLAIN, sand)
    bounced, bounced_floor = shaded_side(renderers, kind, BOUNCE, sand)
    expected = 1.0 + np.asarray(ground_light(LIGHT, "sand")) / np.asarray(AMBIENT_COLOR)
    assert np.all(expected > 1.5)                             # the sand's light is not small beside the sky's
    ratio = bounced.mean(axis=0) / plain.mean(axis=0)
    assert ratio == pytest.approx(expected, rel=0.04), (ratio, expected)
    # the ground faces up: none of its own light reaches it
    assert len(plain_floor) > 50 and np.array_equal(bounced_floor, plain_floor)
    # no ground, no ground light
    alone, _ = shaded_side(renderers, kind, PLAIN, None)
    alone_bounce, _ = shaded_side(renderers, kind, BOUNCE, None)
    assert np.array_equal(alone, alone_bounce)


def test_the_ground_light_is_the_grounds_albedo_times_its_light():
    from plantgen.geometry.skeletons.materials import PALETTE
    from plantgen.gl.material_uniforms import AMBIENT_COLOR, LIGHT_COLOR, ground_light

    dark, light, _ = PALETTE["grass"]
    up = np.asarray(LIGHT) / np.linalg.norm(LIGHT)
    expected = 0.5 * (np.asarray(dark) + np.asarray(light)) * (np.asarray(LIGHT_COLOR) * up[1] + AMBIENT_COLOR)
    assert ground_light(LIGHT, "grass") == pytest.approx(expected, rel=1e-6)
    below = ground_light((0.0, -1.0, 0.0), "grass")               # the sun under the horizon: the sky alone
    assert below == pytest.approx(0.5 * (np.asarray(dark) + np.asarray(light)) * AMBIENT_COLOR, rel=1e-6)
    assert ground_light(LIGHT, None) == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("kind", ["rc", "rt"])
def test_the_traced_ground_light_is_the_open_ones_outside_and_none_inside_a_tube(renderers, kind):
    """With the sky light the ground's light is traced too (the rays below the horizon):
    an open surface gets the untraced share in the mean; a tube's inner wall, whose view
    of the ground its own wall hides, gets none, where the untraced term lights it."""
    sand = Ground(4000.0)
    traced = sky_only(LookSettings(sky_samples=64, sky_reach=4.0))
    sky, _ = shaded_side(renderers, kind, traced, sand)
    both, _ = shaded_side(renderers, kind, replace(traced, bounce=True), sand)
    plain, _ = shaded_side(renderers, kind, PLAIN, sand)
    bounced, _ = shaded_side(renderers, kind, BOUNCE, sand)
    gained, expected = (both - sky).mean(axis=0), (bounced - plain).mean(axis=0)
    assert np.all(expected > 0.004) and gained == pytest.approx(expected, rel=0.08)

    frusta = skin_skeleton(column((0.0, -20.0, 0.0), 40.0, 1.0))
    camera = Camera((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), 30.0, 32, 32)
    kw = dict(ground=Ground(4000.0, height=-30.0), light_dir=(1.0, 0.0, 0.0))   # the sun outside the wall seen
    wall_open = draw(renderers, kind, frusta, camera, BOUNCE, **kw)
    wall_traced = draw(renderers, kind, frusta, camera, replace(sky_only(LookSettings(sky_reach=2.0)), bounce=True),
                       **kw)
    assert np.isfinite(wall_open.distance).all()
    assert srgb_like(wall_traced.color).mean() < 0.05 * srgb_like(wall_open.color).mean()


def test_a_leaf_takes_the_ground_light_through_it(renderers):
    """A translucent leaf facing up, seen from above: its far side faces the ground, whose
    light comes through it with the bounce (its near side, facing up, gets none)."""
    frusta = skin_skeleton(column((5.0, 0.0, -5.0), 0.5, 0.05))
    camera = Camera((0.0, 4.0, 0.5), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), 30.0, 40, 40)
    leaf = square((0.0, 1.0, 0.0), 0.6, (0.0, 1.0, 0.0))
    kw = dict(leaves=leaf, ground=Ground(40.0), light_dir=LIGHT)
    through = LookSettings(translucency=True)
    a = draw(renderers, "rc", frusta, camera, through, **kw)
    b = draw(renderers, "rc", frusta, camera, replace(through, bounce=True), **kw)
    seen = np.isfinite(a.distance) & (a.distance < 3.5)
    assert seen.sum() > 100
    assert srgb_like(b.color[seen]).mean() > 1.05 * srgb_like(a.color[seen]).mean()


@pytest.mark.parametrize("kind", ["rc", "rt"])
def test_the_ground_light_wanes_with_the_height_above_a_small_ground(renderers, kind):
    """Above a ground of radius R (to its fade's middle) a vertical surface at height h
    sees the ground below the depression angle d = atan(h / R): the cosine-weighted share
    (acos(sin d) - sin d cos d) / pi of its hemisphere, 1/2 at the ground, less higher up."""
    from plantgen.gl.material_uniforms import AMBIENT_COLOR, ground_light

    sand = Ground(8.0)
    reach = sand.half * (1.0 - 0.5 * sand.fade)
    plain, h = shaded_side(renderers, kind, PLAIN, sand, height=6.0, heights=True)
    bounced, _ = shaded_side(renderers, kind, BOUNCE, sand, height=6.0, heights=True)
    # plain = albedo * ambient / 2, bounced - plain = albedo * ground_light * share
    green = 1
    share = (bounced[:, green] / plain[:, green] - 1.0) * 0.5 * AMBIENT_COLOR[green] \
        / ground_light(LIGHT, "sand")[green]
    sin_d = h / np.hypot(h, reach)
    expected = (np.arccos(sin_d) - sin_d * np.sqrt(1.0 - sin_d ** 2)) / np.pi
    low, high = h < 1.0, h > 4.0
    assert low.sum() > 10 and high.sum() > 10
    assert share[low].mean() == pytest.approx(expected[low].mean(), abs=0.03)
    assert share[high].mean() == pytest.approx(expected[high].mean(), abs=0.03)
    assert share[high].mean() < 0.6 * share[low].mean()


# ---------------------------------------------------------------------- soft sun
def shadowed_ground(renderers, kind, angle):
    """A post's shadow on the ground (sand) under a sun ``angle`` degrees wide: luminance."""
    frusta = skin_skeleton(column((0.0, 0.0, 0.0), 2.5, 0.25))
    camera = Camera((0.0, 6.0, 3.0), (0.0, 0.0, 1.5), (0.0, 1.0, 0.0), 45.0, 64, 64)
    result = draw(renderers, kind, frusta, camera, LookSettings(sun_angle=angle, sun_samples=32),
                  ground=Ground(12.0), shadows=ShadowSettings(resolution=1024), light_dir=(0.0, 1.0, -0.8))
    return luminance(result.color)


@pytest.mark.parametrize("kind", ["rc", "rt"])
def test_a_wider_sun_widens_the_shadows_edge_and_keeps_the_rest(renderers, kind):
    hard = shadowed_ground(renderers, kind, 0.0)
    changed = [np.abs(shadowed_ground(renderers, kind, a) - hard) > 0.04 for a in (2.0, 8.0)]
    assert 10 < changed[0].sum() < changed[1].sum()        # a penumbra, wider with a wider sun
    assert changed[1].mean() < 0.1                           # far from the shadow's edge: as before
    assert np.array_equal(shadowed_ground(renderers, kind, 8.0), shadowed_ground(renderers, kind, 8.0))


def test_the_ray_caster_and_the_ray_tracer_trace_the_same_sky(renderers):
    # the same rows, the same BVH, the same per-pixel sequence: the same light
    rc, seen = partly_open(renderers, "rc", 8)
    rt, seen_rt = partly_open(renderers, "rt", 8)
    assert np.array_equal(seen, seen_rt)
    assert np.mean(np.abs(rc[seen] - rt[seen])) < 0.01


def test_the_leaves_depth_pass_ahead_of_the_sky_changes_no_pixel(renderers, monkeypatch):
    # with the sky light, the leaves' depth is drawn first so only the nearest leaf of a
    # pixel traces its rays: the frame is the one every leaf shaded in turn gives
    from plantgen.gl.leaf_layer import LeafLayer

    frusta = skin_skeleton(column((0.0, 0.0, 0.0), 2.0, 0.1))
    camera = Camera((0.0, 1.0, 4.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), 35.0, 40, 40)
    leaves = [square((0.1 * k, 1.0 + 0.05 * k, 0.3 * k - 0.5), 0.4, (0.2, 0.3, 1.0)) for k in range(4)]
    stack = Polygons(np.concatenate([p.vertices for p in leaves]),
                     np.concatenate([p.triangles + 4 * k for k, p in enumerate(leaves)]),
                     np.repeat(np.arange(4), 2), np.ones(4, np.int32), np.concatenate([p.normal for p in leaves]))
    look = LookSettings(sky=True, translucency=True, tone=True, sky_samples=4)
    for kind in ("rc", "rt"):
        first = draw(renderers, kind, frusta, camera, look, leaves=stack)
        monkeypatch.setattr(LeafLayer, "_nearest_first", lambda *args: None)
        each = draw(renderers, kind, frusta, camera, look, leaves=stack)
        monkeypatch.undo()
        assert np.array_equal(first.color, each.color) and np.array_equal(first.distance, each.distance)
