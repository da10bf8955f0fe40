"""render --method rt (plantgen.gl.rt): the ray tracer shows the ray caster's surfaces
(the same covered pixels, depths within float32 rounding, the same shading), for one
plant and for an instanced scene (two levels, also 1e4 units from the origin); its
shadows come from shadow rays and agree with the ray caster's shadow map where a map
can tell; an animation's frames refit the BVH to the posed rows and still show RC's
surfaces; the command line takes --method rt for stills and animations.
Images are small (at most 256x192) so the file runs in well under a minute on llvmpipe."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from _cli import run_cli

from plantgen.geometry.rays.camera import Camera
from plantgen.geometry.rays.instances import PlacedPlants
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.geometry.stage import Ground
from plantgen.gl.raycast import Raycaster
from plantgen.gl.rt import RayTracer
from plantgen.pipeline import frame_arguments, grow_file, prepare_model, stage_model
from plantgen.scene import rotation_matrix
from plantgen.settings import RaycastSettings, ShadowSettings

LIGHT = (0.45, 0.8, 0.35)


def _agree(rc, rt, *, cover=0.0005, depth=0.995, color=0.995, colors=True):
    """RT's frame against RC's: covered pixels equal but for a ``cover`` fraction (where two
    surfaces cross, which one is nearer is decided by rounding), distances within float32
    rounding for a ``depth`` fraction of the pixels both cover, colours within one level."""
    a, b = np.isfinite(rc.distance), np.isfinite(rt.distance)
    assert a.sum() > 1000
    assert (a != b).sum() <= cover * a.sum(), (a != b).sum()
    both = a & b
    close = np.isclose(rt.distance[both], rc.distance[both], rtol=4e-6, atol=0)
    assert close.mean() >= depth, close.mean()
    if colors:
        same = np.abs(rt.color.astype(int) - rc.color).max(axis=-1) <= 1
        assert same[both].mean() >= color and same[~a & ~b].all()


@cache
def _staged(name: str):
    model = prepare_model(name)
    frusta = model.frusta_at(0)
    # at one ray a pixel: coverage anti-aliasing casts RC's thin rows at a floor radius, RT's not
    return frusta, {**frame_arguments(frusta, stage_model(model.grown, frusta, 192, 144), None), "aa": "none"}


@pytest.mark.parametrize("relief", [False, True], ids=["RT", "RT+R"])
@pytest.mark.parametrize("name", ["pine", "saguaro", "aloe", "desert"])
def test_rt_shows_the_ray_casters_surfaces(gl_ctx, name, relief):
    frusta, view = _staged(name)
    settings = RaycastSettings(relief=relief)
    rc = Raycaster(gl_ctx).render(frusta, settings=settings, **view)
    tracer = RayTracer(gl_ctx)
    rt = tracer.render(frusta, settings=settings, **view)
    _agree(rc, rt)
    assert rt.stats.program[0] == "rt.glsl" and "shadow" not in rt.stats.passes
    again = tracer.render(frusta, settings=settings, **view)       # the BVH is kept
    assert tracer.last_build_ms == 0.0 and tracer.last_upload_ms == 0.0
    np.testing.assert_array_equal(again.color, rt.color)


@cache
def _tree():
    skeleton = grow_file("grammars/abop_ternary.yaml").skeleton
    return skeleton, skin_skeleton(skeleton)


def _grove(origin):
    """Three turned and scaled copies of a tree seen from 40 units, and its ground."""
    skeleton, frusta = _tree()
    o = np.asarray(origin, dtype=np.float64)
    mats = []
    for shift, yaw, scale in (([0, 0, 0], 0.0, 1.0), ([12, 0, 3], 37.0, 0.8), ([-10, 0, -6], 200.0, 1.3)):
        m = np.eye(4)
        m[:3, :3] = scale * rotation_matrix([0.0, yaw, 0.0])
        m[:3, 3] = o + shift
        mats.append(m)
    placed = PlacedPlants.build([("ternary", frusta, skeleton.parent, mats)])
    camera = Camera(tuple(o + [0, 8, 40]), tuple(o + [0, 5, 0]), (0, 1, 0), 40.0, 256, 192)
    return placed, camera, Ground(size=60.0, height=float(o[1]), material="grass")


@pytest.mark.parametrize("origin", [(0.0, 0.0, 0.0), (1e4, 0.0, -1e4)], ids=["origin", "far"])
def test_rt_traces_an_instanced_scene_as_rc_draws_it_merged(gl_ctx, origin):
    """Two levels (a BVH per distinct plant, a top level over the copies, the ray moved
    into each copy's frame in float32 from offsets formed in float64) against the merged
    rows ray cast: the same pixels and distances, 1e4 units from the origin as near it."""
    placed, camera, ground = _grove(origin)
    kw = dict(settings=RaycastSettings(), material_names=placed.material_names, light_dir=LIGHT, ground=ground)
    rc = Raycaster(gl_ctx).render(placed.merged(), camera, **kw)
    rt = RayTracer(gl_ctx).render(placed, camera, **kw)
    assert dict(rt.stats.program[1])["TWO_LEVEL"]
    # where a trunk enters the ground the nearer surface is decided by rounding (RC turns
    # the records into the world, RT the ray into the copy): a few pixels there
    _agree(rc, rt, cover=0.001, depth=0.99, color=0.99)


def test_rt_shadows_are_shadow_rays_that_agree_with_the_map(gl_ctx):
    """With shadows RT draws no map: each receiver (rows and ground) traces a shadow ray.
    Shading only darkens (visibility in [0, 1]); the ground is shadowed under the trees;
    and where RC's shadow map is sure (away from shadow edges) the two agree."""
    placed, camera, ground = _grove((0.0, 0.0, 0.0))
    kw = dict(settings=RaycastSettings(), material_names=placed.material_names, light_dir=LIGHT, ground=ground)
    tracer = RayTracer(gl_ctx)
    lit = tracer.render(placed, camera, **kw)
    shadowed = tracer.render(placed, camera, shadows=ShadowSettings(resolution=2048), **kw)
    rc = Raycaster(gl_ctx).render(placed.merged(), camera, shadows=ShadowSettings(resolution=2048),
                                  shadow_box=placed.box, **kw)
    np.testing.assert_array_equal(np.isfinite(shadowed.distance), np.isfinite(lit.distance))
    luma = [r.color.astype(int).sum(axis=-1) for r in (lit, shadowed, rc)]
    assert (luma[1] <= luma[0] + 3).all()
    dark = luma[1] < luma[0] - 20
    trees = np.isfinite(lit.distance) & (lit.distance < 60)
    assert dark.sum() > 200 and dark[trees].any()
    rc_dark = luma[2] < luma[0] - 20
    # away from the map's edges (2 pixels either side of its mask's boundary) they agree
    sure = ~_grown(~rc_dark, 2) | ~_grown(rc_dark, 2)
    assert (dark[sure] == rc_dark[sure]).mean() >= 0.97


def _grown(mask, pixels: int):
    """``mask`` grown by ``pixels`` (8-neighbour steps)."""
    out = mask.copy()
    for _ in range(pixels):
        padded = np.pad(out, 1)
        out = np.zeros_like(out)
        for dy in (0, 1, 2):
            for dx in (0, 1, 2):
                out |= padded[dy:dy + mask.shape[0], dx:dx + mask.shape[1]]
    return out


def test_render_method_rt_from_the_command_line(tmp_path):
    out = tmp_path / "sag.png"
    code, stdout, stderr = run_cli("render", "saguaro", "-o", out, "--method", "rt", "--relief", "--size", "96x72")
    assert code == 0, stderr
    assert "ray traced with relief mapping" in stdout and "RT+R" not in stdout and out.exists()
    gif = tmp_path / "d.gif"
    code, stdout, stderr = run_cli("render", "dancing_cacti", "-o", gif, "--method", "rt", "--frames", "2",
                                   "--size", "96x72")
    assert code == 0, stderr
    from PIL import Image
    with Image.open(gif) as im:
        assert im.n_frames == 2


def test_a_swaying_plants_frames_refit_the_bvh_and_show_rcs_surfaces(gl_ctx):
    """An animation's frames (rows posed on the CPU): the tracer refits its BVH instead of
    building another; the refitted tree bounds every posed row; each frame covers RC's
    pixels with RC's depths, though the rows have moved from where the tree was built."""
    from plantgen.geometry.rays.reference import row_boxes

    model = prepare_model("dancing_cacti")
    anim = model.anim
    rest = model.frusta_at(0.0)
    view = {**frame_arguments(rest, stage_model(model.grown, rest, 192, 144), None), "aa": "none"}   # as _staged
    tracer, caster = RayTracer(gl_ctx, refit=True), Raycaster(gl_ctx)
    settings = RaycastSettings(relief=False)
    moved = 0.0
    for t in (0.0, 0.6, 1.3):
        frusta, _ = anim.posed(t)
        moved = max(moved, float(np.abs(frusta.base - rest.base).max()))
        rt = tracer.render(frusta, settings=settings, **view)
        _agree(caster.render(frusta, settings=settings, **view), rt)
        bvh = tracer._built[2][0].bvh
        lo, hi = row_boxes(frusta, shell=True)
        leaf = np.flatnonzero(bvh.count > 0)
        owner = np.repeat(leaf, bvh.count[leaf])
        prim = np.concatenate([bvh.prims[f:f + c] for f, c in zip(bvh.first[leaf], bvh.count[leaf], strict=True)])
        assert (lo[prim] >= bvh.lo[owner]).all() and (hi[prim] <= bvh.hi[owner]).all()
        inner = np.flatnonzero(bvh.count == 0)
        for child in (bvh.first[inner], bvh.first[inner] + 1):
            assert (bvh.lo[child] >= bvh.lo[inner]).all() and (bvh.hi[child] <= bvh.hi[inner]).all()
    assert tracer.refits == 2 and moved > 0.02 * np.ptp(rest.base[:, 1])      # the rows swayed (their height's 2 %)


def test_a_bvh_over_the_render_memory_limit_is_refused_in_one_line(gl_ctx):
    from plantgen.limits import LimitError, Limits

    frusta, view = _staged("pine")
    tracer = RayTracer(gl_ctx, limits=Limits(max_render_bytes=100_000))
    with pytest.raises(LimitError, match="render_bytes") as info:
        tracer.render(frusta, **view)
    assert "\n" not in str(info.value) and tracer._gpu is None
