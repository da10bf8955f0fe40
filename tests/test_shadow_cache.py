"""A light pass paid once: the shadow map is drawn again exactly when what it depends on
changes (the light, the geometry, the map's size, the caster's knobs) and reused when only
the camera moves, and a reused map gives the same frame, pixel for pixel, as a fresh one."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from test_shadows import GROUND, light_towards

from plantgen.geometry.meshes.mesh import tessellate
from plantgen.geometry.meshes.polygons import Polygons
from plantgen.geometry.rays.camera import Camera
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.gl.frame import ShadowKey
from plantgen.gl.passes import LightWindow
from plantgen.gl.raster import RasterRenderer
from plantgen.gl.raycast import Raycaster
from plantgen.settings import RaycastSettings, ShadowSettings

RELIEF = RaycastSettings(relief=True)
SHADOWS = ShadowSettings(resolution=256)


def bent_trunk():
    """Two relief-mapped frusta bending over the ground: they shadow the ground and each other."""
    sk = Skeleton(np.array([[0.0, 0.0, 0.0], [0.0, 1.2, 0.0]]), np.array([[0.0, 1.2, 0.0], [0.6, 2.0, 0.2]]),
                  np.array([0.35, 0.3]), np.array([0.3, 0.08]), np.array([-1, 0]),
                  np.array([False, True]), np.zeros(2, int), ("bark",))
    return skin_skeleton(sk)


def leaf() -> Polygons:
    """One square leaf hanging beside the trunk (it casts on the ground too)."""
    v = np.array([[0.5, 1.0, 0.0], [0.9, 1.0, 0.0], [0.9, 1.0, 0.4], [0.5, 1.0, 0.4]])
    return Polygons(v, np.array([[0, 2, 1], [0, 3, 2]]), np.zeros(2, np.int64), np.zeros(1, np.int32),
                    np.array([[0.0, 1.0, 0.0]]))


CAMERAS = (Camera((3.0, 2.5, 4.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), 40.0, 80, 60),
           Camera((-2.5, 3.5, 3.0), (0.2, 0.8, 0.0), (0.0, 1.0, 0.0), 45.0, 80, 60),
           Camera((0.4, 7.0, 0.6), (0.0, 0.0, 0.0), (0.0, 0.0, -1.0), 50.0, 64, 64))


@pytest.fixture(scope="module")
def frusta():
    return bent_trunk()


LIGHT = light_towards(40.0)


def render(caster, frusta, camera=CAMERAS[0], *, light=LIGHT, shadows=SHADOWS, settings=RELIEF,
           leaves=None, ground=GROUND):
    return caster.render(frusta, camera, settings, ("bark",), light, ground, shadows=shadows, leaves=leaves)


def test_the_map_is_reused_when_only_the_camera_moves(gl_ctx, frusta):
    caster = Raycaster(gl_ctx)
    first = render(caster, frusta)
    assert not first.stats.shadow_cached and first.stats.shadow_ms > 0
    for camera in CAMERAS[1:] + CAMERAS[:1]:
        again = render(caster, frusta, camera)
        assert again.stats.shadow_cached and again.stats.shadow_ms == 0.0
        assert again.stats.passes[0] == "shadow"          # the frame still samples a map
    caster.release()


@pytest.mark.parametrize("leaves", [None, "leaf"])
def test_a_reused_map_gives_the_frame_a_fresh_map_gives(gl_ctx, frusta, leaves):
    """Seen from a camera other than the one the map was drawn for, the frame with the
    reused map equals, pixel for pixel and distance for distance, the frame of a renderer
    that draws its map fresh for that camera: the light's pass does not depend on the eye."""
    polygons = leaf() if leaves else None
    kept, fresh = Raycaster(gl_ctx), Raycaster(gl_ctx)
    render(kept, frusta, CAMERAS[0], leaves=polygons)
    for camera in CAMERAS[1:]:
        reused = render(kept, frusta, camera, leaves=polygons)
        drawn = render(fresh, frusta, camera, leaves=polygons)
        fresh.forget_shadow_maps()
        assert reused.stats.shadow_cached and not drawn.stats.shadow_cached
        assert np.array_equal(reused.color, drawn.color)
        assert np.array_equal(reused.distance, drawn.distance)
    # and the map holds a shadow that matters: the frame differs from one without shadows
    plain = kept.render(frusta, camera, RELIEF, ("bark",), light_towards(40.0), GROUND, leaves=polygons)
    assert np.abs(plain.color.astype(int) - reused.color.astype(int)).max() > 40
    kept.release()
    fresh.release()


def test_the_map_is_drawn_again_when_the_light_turns(gl_ctx, frusta):
    caster = Raycaster(gl_ctx)
    render(caster, frusta)
    turned = render(caster, frusta, CAMERAS[1], light=light_towards(40.0, azimuth_deg=60.0))
    assert not turned.stats.shadow_cached and turned.stats.shadow_ms > 0
    assert render(caster, frusta, CAMERAS[2], light=light_towards(40.0, azimuth_deg=60.0)).stats.shadow_cached
    caster.release()


def test_the_map_is_drawn_again_when_the_geometry_changes(gl_ctx, frusta):
    """New rows (a moved copy, as an animation's next frame brings), leaves added or moved,
    another ground: each draws the map again; the same objects again reuse it."""
    caster = Raycaster(gl_ctx)
    render(caster, frusta)
    moved = frusta.translated((0.05, 0.0, 0.0))
    assert not render(caster, moved).stats.shadow_cached
    assert render(caster, moved, CAMERAS[1]).stats.shadow_cached
    assert not render(caster, moved, leaves=leaf()).stats.shadow_cached      # a new Polygons
    polygons = leaf()
    assert not render(caster, moved, leaves=polygons).stats.shadow_cached
    assert render(caster, moved, CAMERAS[2], leaves=polygons).stats.shadow_cached
    swayed = replace(polygons, vertices=polygons.vertices + (0.0, 0.0, 0.1))
    assert not render(caster, moved, leaves=swayed).stats.shadow_cached
    assert not render(caster, moved, leaves=swayed, ground=replace(GROUND, size=12.0)).stats.shadow_cached
    caster.release()


def test_the_map_is_drawn_again_when_its_size_or_caster_changes(gl_ctx, frusta):
    caster = Raycaster(gl_ctx)
    render(caster, frusta)
    assert not render(caster, frusta, shadows=replace(SHADOWS, resolution=128)).stats.shadow_cached
    assert render(caster, frusta, CAMERAS[1], shadows=replace(SHADOWS, resolution=128)).stats.shadow_cached
    for shadows, settings in ((replace(SHADOWS, resolution=128, march_density=1.0), RELIEF),
                              (replace(SHADOWS, resolution=128, march_density=1.0, march="bisect"), RELIEF),
                              (replace(SHADOWS, resolution=128, march_density=1.0, march="bisect"), RaycastSettings())):
        assert not render(caster, frusta, shadows=shadows, settings=settings).stats.shadow_cached
    # knobs the light's pass does not read leave the map as it is: the eye's relief density
    eye_only = replace(RaycastSettings(), march_density=4.0)
    assert render(caster, frusta, shadows=shadows, settings=eye_only).stats.shadow_cached
    caster.release()


def test_two_casters_alternating_keep_both_maps(gl_ctx, frusta):
    """The bench times RC and RC+R in alternation: both maps are kept and reused."""
    caster = Raycaster(gl_ctx)
    render(caster, frusta, settings=RaycastSettings())
    render(caster, frusta, settings=RELIEF)
    for camera in CAMERAS:
        assert render(caster, frusta, camera, settings=RaycastSettings()).stats.shadow_cached
        assert render(caster, frusta, camera, settings=RELIEF).stats.shadow_cached
    caster.release()


def test_without_the_cache_every_frame_draws_its_map(gl_ctx, frusta):
    caster = Raycaster(gl_ctx)
    uncached = replace(SHADOWS, cache=False)
    first = render(caster, frusta, shadows=uncached)
    again = render(caster, frusta, shadows=uncached)
    assert not again.stats.shadow_cached and again.stats.shadow_ms > 0
    assert np.array_equal(first.color, again.color)
    caster.release()


def test_records_the_caller_packed_draw_their_map_every_frame(gl_ctx, frusta):
    """An animation hands the renderer its own records (relative to the eye) and rewrites
    them in place: the renderer cannot vouch for their contents, so it draws their map in
    every frame, and that map equals the one it draws from the Frusta itself."""
    from plantgen.gl.records import pack_records
    caster, own = Raycaster(gl_ctx), Raycaster(gl_ctx)
    buf = gl_ctx.buffer(pack_records(frusta, CAMERAS[0].eye).tobytes())
    args = (RELIEF, ("bark",), LIGHT, GROUND)
    first = caster.render(frusta, CAMERAS[0], *args, shadows=SHADOWS, record_buffer=buf)
    same = caster.render(frusta, CAMERAS[0], *args, shadows=SHADOWS, record_buffer=buf)
    assert not first.stats.shadow_cached and not same.stats.shadow_cached and same.stats.shadow_ms > 0
    assert np.array_equal(first.color, same.color)
    moved = frusta.translated((0.0, 0.02, 0.0))
    buf.write(pack_records(moved, CAMERAS[0].eye).tobytes())
    from_buffer = caster.render(moved, CAMERAS[0], *args, shadows=SHADOWS, record_buffer=buf)
    packed_here = own.render(moved, CAMERAS[0], *args, shadows=SHADOWS)
    assert not from_buffer.stats.shadow_cached
    # the same shadows: the maps differ only by where float32 rounded (eye vs light anchor)
    assert np.mean(np.abs(from_buffer.color.astype(int) - packed_here.color.astype(int)).max(axis=-1) > 8) < 0.002
    buf.release()
    caster.release()
    own.release()


def test_the_mesh_renderer_reuses_its_map_the_same_way(gl_ctx, frusta):
    raster, fresh = RasterRenderer(gl_ctx), RasterRenderer(gl_ctx)
    mesh = tessellate(frusta, 2)
    args = dict(material_names=("bark",), light_dir=light_towards(40.0), ground=GROUND, shadows=SHADOWS)
    first = raster.render(mesh, frusta, CAMERAS[0], **args)
    reused = raster.render(mesh, frusta, CAMERAS[1], **args)
    drawn = fresh.render(mesh, frusta, CAMERAS[1], **args)
    assert not first.stats.shadow_cached and reused.stats.shadow_cached and not drawn.stats.shadow_cached
    assert np.array_equal(reused.color, drawn.color)
    other = tessellate(frusta, 1)
    assert not raster.render(other, frusta, CAMERAS[1], **args).stats.shadow_cached
    raster.release()
    fresh.release()


def test_the_key_compares_geometry_by_identity_and_the_rest_by_value(frusta):
    window = LightWindow(np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0]),
                         np.array([1.0, 1.0]), np.array([0.0, 2.0]))
    key = ShadowKey(("a", 1), (frusta, None), GROUND, 256, (0.0, 0.0, 0.0), window)
    assert key == ShadowKey(("a", 1), (frusta, None), replace(GROUND), 256, np.zeros(3), window)
    assert key != ShadowKey(("a", 1), (frusta.translated((0, 0, 0)), None), GROUND, 256, (0.0, 0.0, 0.0), window)
    assert key != ShadowKey(("a", 1), (frusta, None), GROUND, 256, (0.0, 0.0, 1e-9), window)
    assert key != ShadowKey(("a", 1), (frusta, None), GROUND, 256, (0.0, 0.0, 0.0), window.shifted((0, 1e-9, 0)))


def test_a_frusta_cannot_be_changed_in_place_under_a_kept_map(frusta):
    """The key holds the geometry by identity, so the geometry must be a value: writing into
    a Frusta's rows is refused (a changed copy is a new object, and draws its map again)."""
    for name in ("base", "axis", "r1", "plane_hi", "material", "parent_row"):
        with pytest.raises(ValueError):
            getattr(frusta, name)[...] = 0
    moved = replace(frusta, base=frusta.base + 1.0)
    assert moved is not frusta and not moved.base.flags.writeable


# ---------------------------------------------------------------- the paths that redraw
def test_render_time_frames_draws_the_map_once_and_says_so(gl_ctx, tmp_path):
    from _cli import run_cli

    from plantgen.pipeline import render_model
    report = render_model("well", size=(48, 36), shadow_res=128, timed_frames=3)
    use = report.shadow_use
    assert (use.drawn, use.reused) == (1, 3) and use.ms > 0
    assert report.result.stats.shadow_cached and report.result.stats.shadow_ms == 0.0
    code, stdout, stderr = run_cli("render", "well", "-o", tmp_path / "w.png", "--size", "48x36",
                                   "--shadow-res", "128", "--time-frames", "2")
    assert code == 0, stderr
    assert "shadow map: drawn once" in stdout and "reused by 2 draws" in stdout
    code, stdout, stderr = run_cli("render", "well", "-o", tmp_path / "w.png", "--size", "48x36",
                                   "--shadow-res", "128", "--time-frames", "2", "--no-shadow-cache")
    assert code == 0 and "shadow map: drawn 3 times" in stdout and "reused" not in stdout
    assert "every draw (--no-shadow-cache)" in stdout and "geometry moves" not in stdout   # the cause, not motion


def test_an_animation_whose_rows_move_draws_its_map_every_frame(gl_ctx):
    from plantgen.pipeline import render_model
    report = render_model("dancing_cacti", size=(40, 30), shadow_res=64, frames=3)
    assert report.shadow_use.drawn == 4 and report.shadow_use.reused == 0     # the warm-up and 3 frames


def test_the_viewer_reuses_the_map_while_the_camera_orbits_and_says_so(gl_ctx, tmp_path):
    from plantgen.pipeline import prepare_model
    from plantgen.viewer.session import ViewerSession, ViewOptions
    options = ViewOptions(input="well", size=(64, 48), watch=False, shots=tmp_path)
    s = ViewerSession(gl_ctx, options, prepare_model("well"), say=lambda line: None, warn=lambda line: None)
    try:
        assert not s.draw(64, 48).stats.shadow_cached
        assert "shadows on (map drawn" in s.hud_lines()[0][0]
        s.orbit(25.0, 10.0)
        s.zoom(1.3)
        assert s.draw(64, 48).stats.shadow_cached
        assert "shadows on (map reused)" in s.hud_lines()[0][0]
        s.key("S")                                     # shadows off and on: nothing it depends on moved
        s.key("S")
        assert s.draw(64, 48).stats.shadow_cached
    finally:
        s.release()
