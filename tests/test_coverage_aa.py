"""Coverage anti-aliasing (``--aa coverage``, the default; issue 43): a twig thinner than a
pixel is drawn as a continuous faint line instead of dots, ``--aa none`` draws what the
ray caster drew before, and wide surfaces keep their colours."""

from __future__ import annotations

import numpy as np
import pytest
from _relief_frustum import face_on_camera, relief_frustum

from plantgen.geometry.meshes.polygons import Polygons
from plantgen.geometry.rays.camera import Camera
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.gl.frame import coverage_aa
from plantgen.gl.leaf_layer import thin_leaf_data
from plantgen.pipeline import frame_arguments, prepare_model, render_model, stage_model
from plantgen.settings import AA_FLOOR_PIXELS, ImageSettings, RaycastSettings, RenderSettings

WIDTH, HEIGHT, DISTANCE, FOV = 128, 96, 10.0, 40.0
BACKGROUND = (0.9, 0.9, 0.9, 1.0)      # flat and opaque: a thin row blends with it
SIZE = (160, 120)


def pixel_world() -> float:
    """The world size of a pixel at the twig's distance."""
    return 2.0 * DISTANCE * np.tan(np.radians(FOV) / 2) / HEIGHT


def thin_twig(radius_pixels: float):
    """A straight twig across most of the view, rising 6 pixels over its length, of radius
    ``radius_pixels`` pixel footprints, in four segments (a chain, as a grammar makes)."""
    px = pixel_world()
    xs = np.linspace(-50 * px, 50 * px, 5)
    ys = np.linspace(-3 * px, 3 * px, 5)
    starts = np.stack([xs[:-1], ys[:-1], np.zeros(4)], axis=1)
    ends = np.stack([xs[1:], ys[1:], np.zeros(4)], axis=1)
    r = np.full(4, radius_pixels * px)
    skeleton = Skeleton(starts, ends, r, r, np.array([-1, 0, 1, 2]), np.zeros(4, bool), np.zeros(4, int), ("bark",))
    return skin_skeleton(skeleton)


def twig_camera() -> Camera:
    return Camera((0.0, 0.0, DISTANCE), (0.0, 0.0, 0.0), (0, 1, 0), FOV, WIDTH, HEIGHT)


def draw(caster, frusta, camera, **kw):
    return caster.render(frusta, camera, material_names=("bark",), background=BACKGROUND, **kw)


def twig_columns(color) -> np.ndarray:
    """(w,) whether each column has a pixel that is not the background."""
    level = np.round(255 * np.array(BACKGROUND[:3]))
    return (np.abs(color[..., :3].astype(float) - level).max(axis=-1) > 2).any(axis=0)


@pytest.fixture(scope="module")
def twig_frames():
    """The twig 0.2 pixel across, drawn without and with the anti-aliasing and with 4 x 4
    supersampling (the tests ask for gl_ctx first: no GL context, they skip)."""
    from plantgen.gl.raycast import Raycaster
    caster, frusta, camera = Raycaster(), thin_twig(0.1), twig_camera()
    return {aa: draw(caster, frusta, camera, aa=aa).color for aa in ("none", "coverage")} | {
        "ssaa4": draw(caster, frusta, camera, ssaa=4).color}


def test_a_twig_a_fifth_of_a_pixel_across_is_a_continuous_line(gl_ctx, twig_frames):
    """Between its ends (a few pixels in), every column the twig crosses has a pixel of it
    with the anti-aliasing on; with it off the single ray a pixel misses it in many columns."""
    span = slice(WIDTH // 2 - 44, WIDTH // 2 + 44)
    on = twig_columns(twig_frames["coverage"])[span]
    off = twig_columns(twig_frames["none"])[span]
    assert on.all(), np.where(~on)[0]
    assert (~off).sum() > 20, (~off).sum()          # dots and gaps


def test_the_line_is_connected_and_faint(gl_ctx, twig_frames):
    """The twig's pixels form one chain: in neighbouring columns its darkest pixels are at
    most a row apart; it is faint (its share of the pixel), not the bark's full colour."""
    color = twig_frames["coverage"][..., :3].astype(float)
    darkness = (np.round(255 * np.array(BACKGROUND[:3])) - color).max(axis=-1)
    span = np.arange(WIDTH // 2 - 44, WIDTH // 2 + 44)
    rows = darkness[:, span].argmax(axis=0)
    assert np.abs(np.diff(rows)).max() <= 1, rows
    full = twig_frames["none"][..., :3].astype(float)
    full_darkness = (np.round(255 * np.array(BACKGROUND[:3])) - full).max(axis=-1).max()
    assert darkness[:, span].max(axis=0).max() < 0.6 * full_darkness


def test_the_line_is_nearer_the_supersampled_twig(gl_ctx, twig_frames):
    """Against 16 rays a pixel, the mean error over the image is lower with the anti-aliasing."""
    reference = twig_frames["ssaa4"].astype(float)
    error = {aa: np.abs(twig_frames[aa].astype(float) - reference).mean() for aa in ("none", "coverage")}
    assert error["coverage"] < 0.6 * error["none"], error


def test_a_wide_surface_keeps_its_colours(gl_ctx):
    """A branch many pixels wide is drawn as before: with ``coverage`` pixel for pixel (it
    is no thin row); with ``edges`` no darkening (the mean moves by under a quarter level
    inside its outline), the edge pass softening a few pixels of the bark's pattern by a few
    levels."""
    from plantgen.gl.raycast import Raycaster
    caster, frusta, camera = Raycaster(gl_ctx), relief_frustum("bark"), face_on_camera(96, 96)
    none, coverage, edges = (caster.render(frusta, camera, material_names=("bark",), background=BACKGROUND, aa=aa)
                             for aa in ("none", "coverage", "edges"))
    assert np.array_equal(none.color, coverage.color)
    hit = np.isfinite(none.distance)
    inside = hit.copy()
    for axis in (0, 1):
        for shift in (-2, -1, 1, 2):
            inside &= np.roll(hit, shift, axis=axis)
    assert inside.sum() > 500
    a, b = none.color[inside].astype(float), edges.color[inside].astype(float)
    change = np.abs(a - b).max(axis=-1)
    assert abs(a.mean() - b.mean()) < 0.25 and change.max() <= 8 and (change == 0).mean() > 0.8
    assert not np.array_equal(none.color, edges.color)
    assert np.array_equal(none.distance, edges.distance)       # the distances are the centre rays'


def test_a_cone_closing_to_a_point_stays_opaque_with_its_relief(gl_ctx):
    """A wide cone closing to a point (the well's roof, a branch's last tip) is thinner than
    the floor at one end only: it is drawn as without the anti-aliasing, pixel for pixel,
    its relief and its distances kept (it was once cast in the thin pieces' blended pass,
    which drops the relief, and the well's shingles went flat)."""
    from plantgen.gl.raycast import Raycaster
    px = pixel_world()
    skeleton = Skeleton(np.array([[0.0, -30 * px, 0.0]]), np.array([[0.0, 30 * px, 0.0]]), np.array([25 * px]),
                        np.array([0.0]), np.array([-1]), np.zeros(1, bool), np.zeros(1, int), ("bark",))
    cone, camera = skin_skeleton(skeleton), twig_camera()
    caster = Raycaster(gl_ctx)
    settings = RaycastSettings(relief=True)
    none, coverage = (caster.render(cone, camera, settings, material_names=("bark",), background=BACKGROUND, aa=aa)
                      for aa in ("none", "coverage"))
    assert np.isfinite(none.distance).sum() > 1000
    assert np.array_equal(none.color, coverage.color)
    assert np.array_equal(none.distance, coverage.distance)


def bent_twigs(seed: int = 3, chains: int = 12, links: int = 5):
    """Thin twigs (0.05 to 0.4 pixel in radius) bending every way over the view, its corners
    included, one pointing straight at the eye (end-on) and one leaving it sideways: chains
    of ``links`` segments, skinned with their tilted joint planes."""
    rng = np.random.default_rng(seed)
    px = pixel_world()
    starts, ends, parents = [], [], []
    for c in range(chains):
        point = np.array([rng.uniform(-60, 60) * px, rng.uniform(-45, 45) * px, rng.uniform(-3, 3)])
        if c == 0:
            point = np.zeros(3)
        for k in range(links):
            step = rng.normal(size=3) * np.array([8 * px, 8 * px, 0.5])
            if c == 0:
                step = np.array([0.0, 0.0, 0.6])                      # along the view: end-on
            elif c == 1:
                step = np.array([14 * px, 2 * px, 0.0])               # out of the view sideways
            parents.append(len(starts) - 1 if k else -1)
            starts.append(point)
            point = point + step
            ends.append(point)
    n = len(starts)
    r = rng.uniform(0.05, 0.4, n) * px
    skeleton = Skeleton(np.array(starts), np.array(ends), r, 0.8 * r, np.array(parents), np.zeros(n, bool),
                        np.zeros(n, int), ("bark",))
    return skin_skeleton(skeleton)


def test_the_thin_rows_quads_draw_what_their_pyramids_drew(gl_ctx):
    """Coverage anti-aliasing's pass of thin rows draws each as one screen quad around it
    (raycast.glsl's THIN_RIBBON): the same image and distances, bit for bit, as the
    pyramids' back faces drew (the quad holds every pixel whose ray meets the row, and no
    pixel twice; its fragments are not the pyramids'); twigs every way and the coconut's
    fronds."""
    from plantgen.gl.raycast import Raycaster
    ribbon, pyramid = Raycaster(gl_ctx), Raycaster(gl_ctx)
    pyramid.thin_ribbons = False
    model = prepare_model("coconut")
    coconut = model.frusta_at(0.0)
    staging = stage_model(model.grown, coconut, *SIZE, ground="auto")
    settings, _ = RenderSettings().frame(model.effects)
    cases = [(bent_twigs(), {"camera": twig_camera(), "material_names": ("bark",), "background": BACKGROUND,
                             "aa": "coverage"}),
             (coconut, {**frame_arguments(coconut, staging, None, ImageSettings()), "settings": settings})]
    for frusta, args in cases:
        a, b = ribbon.render(frusta, **args), pyramid.render(frusta, **args)
        assert np.array_equal(a.color, b.color)
        assert np.array_equal(a.distance, b.distance)
        assert not np.array_equal(a.color, ribbon.render(frusta, **{**args, "aa": "none"}).color)   # thin rows
        work = [c.render(frusta, **args, count_work=True).stats.work.fragments for c in (ribbon, pyramid)]
        assert work[0] != work[1], work        # the quads were drawn


def test_aa_none_draws_what_the_ray_caster_drew(gl_ctx):
    """``--aa none`` is the frame the ray caster draws without the argument (today's); the
    default differs from it."""
    from plantgen.gl.raycast import Raycaster
    model = prepare_model("broadleaf")
    frusta = model.frusta_at(0.0)
    staging = stage_model(model.grown, frusta, *SIZE)
    settings, _ = RenderSettings().frame(model.effects)
    args = {k: v for k, v in frame_arguments(frusta, staging, None, ImageSettings()).items() if k != "aa"}
    before = Raycaster().render(frusta, settings=settings, **args).color
    off = render_model("broadleaf", size=SIZE, aa="none", ground="none")
    on = render_model("broadleaf", size=SIZE, ground="none")
    assert np.array_equal(off.result.color, before)
    assert not np.array_equal(on.result.color, before)


def test_supersampling_replaces_it(gl_ctx):
    a = render_model("saguaro", size=(64, 48), ssaa=2)
    b = render_model("saguaro", size=(64, 48), ssaa=2, aa="none")
    assert np.array_equal(a.result.color, b.result.color)


def test_where_it_applies():
    assert coverage_aa("coverage") and coverage_aa("edges") and not coverage_aa("none")
    assert not coverage_aa("coverage", ssaa=2)                         # supersampling instead
    assert not coverage_aa("coverage", labels=True)                    # a part mask's labels
    assert not coverage_aa("coverage", background=(0.0, 0.0, 0.0, 0.0))   # nothing to blend with
    assert coverage_aa("coverage", background=BACKGROUND)
    assert ImageSettings().aa == "coverage" and AA_FLOOR_PIXELS == 1.0
    with pytest.raises(ValueError):
        coverage_aa("fxaa")


def test_the_bench_writes_its_table(gl_ctx, tmp_path):
    """``python -m plantgen.benchmarks.anti_aliasing``: a row per variant, ``--aa none``'s
    ratios 1, the renderer named."""
    from plantgen.benchmarks import anti_aliasing
    out = tmp_path / "aa.md"
    assert anti_aliasing.main(["saguaro", "--sizes", "64x48", "--frames", "1", "--out", str(out)]) == 0
    text = out.read_text(encoding="utf-8")
    rows = [line for line in text.splitlines() if line.startswith("| saguaro |")]
    assert [r.split("|")[3].strip() for r in rows] == ["`--aa none`", "`--aa coverage`", "`--aa edges`",
                                                        "`--ssaa 2`"]
    assert rows[0].split("|")[6:8] == [" 1.00 ", " 1.00 "] and "GL renderer:" in text


def needle(width_pixels: float, height_pixels: float = 20.0) -> Polygons:
    """A needle: a flat quad facing the eye across most of the view, ``height_pixels``
    above the centre, rising 6 pixels over its length, ``width_pixels`` across."""
    px = pixel_world()
    x0, x1, y0, y1, w = -50 * px, 50 * px, (height_pixels - 3) * px, (height_pixels + 3) * px, width_pixels * px / 2
    vertices = np.array([[x0, y0 - w, 0.0], [x1, y1 - w, 0.0], [x1, y1 + w, 0.0], [x0, y0 + w, 0.0]])
    return Polygons(vertices, np.array([[0, 1, 2], [0, 2, 3]]), np.array([0, 0]), np.array([1], np.int32),
                    np.array([[0.0, 0.0, 1.0]]))


def test_thin_leaf_data_measures_a_leaf_across_its_long_axis():
    data = thin_leaf_data(needle(0.5), origin=(0.0, 0.0, 0.0))
    px = pixel_world()
    assert np.allclose(data[:, 6], 0.5 * px * np.cos(np.arctan2(6, 100)), rtol=1e-3)   # across the slanted axis
    assert np.allclose(data[:, 0:3], [0.0, 20 * px, 0.0], atol=1e-6)                  # the centroid
    across = data[:, 3:6] / np.linalg.norm(data[:, 3:6], axis=1, keepdims=True)
    assert np.allclose(np.abs(across @ np.array([6.0, -100.0, 0.0]) / np.hypot(6, 100)), 1.0, atol=1e-3)


def test_a_needle_a_fifth_of_a_pixel_across_is_a_continuous_line(gl_ctx):
    """A leaf polygon thinner than a pixel (a pine needle) is widened to the floor and
    blended: a line in every column with the anti-aliasing, dots and gaps without."""
    from plantgen.gl.raycast import Raycaster
    caster, camera = Raycaster(gl_ctx), twig_camera()
    leaves, span = needle(0.2), slice(WIDTH // 2 - 44, WIDTH // 2 + 44)
    top = slice(0, HEIGHT // 2 - 8)                     # the needle's rows, clear of the twig
    colors = {aa: caster.render(thin_twig(0.1), camera, material_names=("bark", "needle"), leaves=leaves,
                                background=BACKGROUND, aa=aa).color for aa in ("none", "coverage")}
    on, off = (twig_columns(colors[aa][top])[span] for aa in ("coverage", "none"))
    assert on.all(), np.where(~on)[0]
    assert (~off).sum() > 20, (~off).sum()


def test_the_distances_are_the_opaque_surfaces(gl_ctx):
    """The thin pieces write no distance (their pass blends colour alone): the distances
    are ``--aa none``'s but where a thin piece is the nearest on a pixel centre's ray;
    ``--depth-out`` draws once more without the anti-aliasing for them."""
    from plantgen.gl.raycast import Raycaster
    caster, frusta, camera = Raycaster(gl_ctx), thin_twig(0.1), twig_camera()
    off, on = (draw(caster, frusta, camera, aa=aa).distance for aa in ("none", "coverage"))
    assert np.isfinite(off).sum() > 10 and not np.isfinite(on).any()
    wide = render_model("saguaro", size=SIZE)      # no piece thinner than a pixel
    np.testing.assert_array_equal(wide.result.distance, render_model("saguaro", size=SIZE, aa="none").result.distance)


def test_depth_out_draws_the_distances_without_it(gl_ctx):
    """``--depth-out`` (exact distances) gets those of one ray a pixel, thin twigs included."""
    exact = render_model("broadleaf", size=SIZE, exact_distance=True)
    plain = render_model("broadleaf", size=SIZE, aa="none")
    np.testing.assert_array_equal(exact.distance, plain.result.distance)
    assert not np.array_equal(exact.result.distance, exact.distance)     # the frame's own lack the twigs


def test_a_leaf_pass_that_would_draw_no_leaf_is_skipped(gl_ctx, monkeypatch):
    """Where every leaf is thinner than the floor at its distance (a needle), the opaque
    pass leaves the leaves out; where none is, the thin pass is not drawn: the same image
    and distances as both passes drew (each draws every leaf and keeps those of its own)."""
    from plantgen.gl.leaf_layer import LeafLayer
    from plantgen.gl.raycast import Raycaster
    camera, floor = twig_camera(), 0.5 * pixel_world() / DISTANCE
    layer = LeafLayer(gl_ctx)
    thin, wide = needle(0.3), needle(3.0)
    assert layer.thin_share(thin, (0.0, 0.0, 0.0), camera.eye, floor) == "all"
    assert layer.thin_share(wide, (0.0, 0.0, 0.0), camera.eye, floor) == "none"
    assert layer.thin_share(thin, (0.0, 0.0, 0.0), camera.eye, floor * 0.25) == "none"
    layer.release()
    frames = {}
    for share in ("skipped", "both"):
        if share == "both":
            monkeypatch.setattr(LeafLayer, "thin_share", lambda *args: "some")
        caster = Raycaster(gl_ctx)
        frames[share] = [caster.render(thin_twig(0.1), camera, material_names=("bark", "needle"), leaves=leaves,
                                       background=BACKGROUND, aa="coverage") for leaves in (thin, wide)]
    for skipped, both in zip(frames["skipped"], frames["both"], strict=True):
        assert np.array_equal(skipped.color, both.color)
        assert np.array_equal(skipped.distance, both.distance)
