"""Leaves in both renderers (issue 17): a grammar's polygons are rasterised into the same
frame and depth buffer as the ray-cast frusta (RC) or the tessellated mesh (GS), cast and
receive shadows, are lit on both sides, and are left out of relief.

The invariants are physical: the distance a pixel reports is the analytic distance to the
leaf's plane or to the cylinder, whichever is nearer along the pixel's ray; a ground point
lies in the leaf's shadow exactly when the ray from it towards the light crosses the leaf.
"""

from __future__ import annotations

import numpy as np
import pytest

from plantgen.geometry.meshes.mesh import tessellate
from plantgen.geometry.meshes.polygons import Polygons
from plantgen.geometry.rays.camera import Camera
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.geometry.stage import Ground
from plantgen.gl.raster import RasterRenderer
from plantgen.gl.raycast import Raycaster
from plantgen.settings import RaycastSettings, ShadowSettings

NAMES = ("bark", "leaf")
RADIUS = 0.3


def column(offset=(0.0, 0.0, 0.0)) -> Skeleton:
    o = np.asarray(offset, np.float64)
    return Skeleton(np.array([o]), np.array([o + (0.0, 2.0, 0.0)]), np.array([RADIUS]), np.array([RADIUS]),
                    np.array([-1]), np.array([False]), np.zeros(1, int), NAMES)


def square(centre, half: float, normal_axis: int = 2, flip: bool = False, material: int = 1) -> Polygons:
    """One square leaf of side 2*half centred at ``centre``, facing +axis (-axis if ``flip``)."""
    c = np.asarray(centre, np.float64)
    a, b = [k for k in range(3) if k != normal_axis]
    corners = []
    for s, t in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
        p = c.copy()
        p[a] += s * half
        p[b] += t * half
        corners.append(p)
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    normal = np.zeros(3)
    normal[normal_axis] = 1.0
    # (a, b, normal) right-handed for axis 2 (x, y, z) and 0 (y, z, x); 1 is (x, z, y): left
    if normal_axis == 1:
        tris = tris[:, ::-1]
    if flip:
        tris, normal = tris[:, ::-1], -normal
    return Polygons(np.array(corners), tris.copy(), np.zeros(2, np.int64), np.array([material], np.int32),
                    normal[None])


@pytest.fixture(scope="module")
def renderers():
    from plantgen.gl.context import gl_context
    ctx = gl_context()
    return {"rc": Raycaster(ctx), "gs": RasterRenderer(ctx)}


def render(renderers, kind, frusta, camera, leaves, **kw):
    if kind == "rc":
        settings = RaycastSettings(relief=kw.pop("relief", False))
        return renderers["rc"].render(frusta, camera, settings, NAMES, leaves=leaves, **kw)
    kw.pop("relief", None)
    return renderers["gs"].render(tessellate(frusta, 3), frusta, camera, material_names=NAMES, leaves=leaves, **kw)


def front_camera(offset, size=(64, 64)) -> Camera:
    o = np.asarray(offset, np.float64)
    return Camera(tuple(o + (0.0, 1.0, 5.0)), tuple(o + (0.0, 1.0, 0.0)), (0.0, 1.0, 0.0), 30.0, *size)


@pytest.mark.parametrize("kind", ["rc", "gs"])
@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (3.0e5, 0.0, -2.0e5)])
@pytest.mark.parametrize("relief", [False, True])
def test_a_leaf_in_front_hides_the_stem_and_one_behind_is_hidden(renderers, kind, offset, relief):
    frusta = skin_skeleton(column(offset))
    camera = front_camera(offset)
    eye, dirs = camera.rays()
    o = np.asarray(offset, np.float64)
    for z, in_front in ((0.6, True), (-0.6, False)):
        leaf = square(o + (0.0, 1.0, z), 0.45)
        result = render(renderers, kind, frusta, camera, leaf, relief=relief)
        bare = render(renderers, kind, frusta, camera, None, relief=relief)
        # the leaf plane z = o.z + z along each pixel's ray
        t_leaf = (o[2] + z - eye[..., 2]) / dirs[..., 2]
        hit = eye + t_leaf[..., None] * dirs
        inside = np.all(np.abs(hit[..., :2] - (o[:2] + (0.0, 1.0))) < 0.45 - 0.03, axis=-1)
        stem = np.isfinite(bare.distance)
        assert inside.sum() > 200 and (inside & stem).sum() > 50
        if in_front:   # the leaf's distance wherever it lies, the stem's nowhere inside it
            assert np.allclose(result.distance[inside], t_leaf[inside], rtol=2e-5)
        else:          # behind: the stem's pixels unchanged, the leaf seen around the stem
            both = inside & stem
            assert np.array_equal(result.distance[both], bare.distance[both])
            assert np.array_equal(result.color[both], bare.color[both])
            leaf_only = inside & ~stem
            assert np.allclose(result.distance[leaf_only], t_leaf[leaf_only], rtol=2e-5)
        outside = ~np.all(np.abs(hit[..., :2] - (o[:2] + (0.0, 1.0))) < 0.45 + 0.03, axis=-1)
        assert np.array_equal(result.distance[outside], bare.distance[outside])


@pytest.mark.parametrize("kind", ["rc", "gs"])
def test_a_leaf_is_lit_the_same_from_either_winding(renderers, kind):
    # two-sided: the shading normal is the leaf's normal turned towards the eye, so a leaf
    # traced the other way round (its normal reversed) looks exactly the same
    frusta = skin_skeleton(column())
    camera = Camera((1.5, 3.0, 4.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), 35.0, 64, 64)
    light = np.array([0.3, 0.8, 0.5])
    for axis in (0, 1, 2):
        centre = np.array([0.0, 1.0, 0.0])
        centre[(axis + 1) % 3 if axis != 1 else 2] += 0.7
        one = render(renderers, kind, frusta, camera, square(centre, 0.4, axis), light_dir=light)
        other = render(renderers, kind, frusta, camera, square(centre, 0.4, axis, flip=True), light_dir=light)
        assert np.array_equal(np.isfinite(one.distance), np.isfinite(other.distance))
        seen = np.isfinite(one.distance)
        assert np.allclose(one.distance[seen], other.distance[seen], rtol=1e-6)
        assert np.abs(one.color.astype(int) - other.color.astype(int)).max() <= 1


@pytest.mark.parametrize("kind", ["rc", "gs"])
def test_a_leaf_facing_the_light_is_brighter_than_one_edge_on(renderers, kind):
    frusta = skin_skeleton(column())
    camera = Camera((0.0, 6.0, 0.01), (0.0, 0.0, 0.0), (0.0, 0.0, -1.0), 35.0, 64, 64)
    facing = render(renderers, kind, frusta, camera, square((1.2, 1.0, 0.0), 0.4, 1), light_dir=(0.0, 1.0, 0.0))
    tilted = render(renderers, kind, frusta, camera, square((1.2, 1.0, 0.0), 0.4, 1), light_dir=(1.0, 0.05, 0.0))
    eye, dirs = camera.rays()
    points = eye + facing.distance[..., None].astype(np.float64) * dirs
    leaf = np.isfinite(facing.distance) & (np.abs(points[..., 1] - 1.0) < 1e-3)
    assert leaf.sum() > 30
    assert facing.color[leaf].astype(int).sum(axis=1).mean() > 1.5 * tilted.color[leaf].astype(int).sum(axis=1).mean()


@pytest.mark.parametrize("kind", ["rc", "gs"])
def test_a_leaf_shadows_the_ground_where_the_light_is_blocked(renderers, kind):
    # a horizontal leaf held over the ground, the light from high up at an angle: ground
    # points whose ray towards the light crosses the leaf are darker than without the leaf
    frusta = skin_skeleton(column((-3.0, 0.0, -3.0)))
    to_light = np.array([0.4, 1.0, 0.2])
    to_light /= np.linalg.norm(to_light)
    leaf = square((0.5, 1.2, 0.5), 0.5, 1)
    camera = Camera((0.5, 9.0, 0.8), (0.5, 0.0, 0.5), (0.0, 0.0, -1.0), 40.0, 96, 96)
    ground = Ground(size=10.0, height=0.0, material="sand")
    shadows = ShadowSettings(resolution=512)
    box = np.array([[-3.5, 0.0, -3.5], [1.0, 2.0, 1.0]])   # one light window for both renders
    lit = render(renderers, kind, frusta, camera, None, light_dir=to_light, ground=ground, shadows=shadows,
                 shadow_box=box)
    shaded = render(renderers, kind, frusta, camera, leaf, light_dir=to_light, ground=ground, shadows=shadows,
                    shadow_box=box)
    eye, dirs = camera.rays()
    points = eye + shaded.distance[..., None].astype(np.float64) * dirs
    on_ground = np.isfinite(shaded.distance) & (np.abs(points[..., 1]) < 1e-3)
    # where the ray from the ground point to the light crosses y = 1.2
    cross = points + (1.2 - points[..., 1:2]) / to_light[1] * to_light
    offset = np.abs(cross[..., [0, 2]] - (0.5, 0.5)).max(axis=-1)
    dark, clear = on_ground & (offset < 0.5 - 0.06), on_ground & (offset > 0.5 + 0.06)
    assert dark.sum() > 40 and clear.sum() > 1000
    lum = shaded.color.astype(int).sum(axis=-1)
    lum_lit = lit.color.astype(int).sum(axis=-1)
    assert (lum_lit - lum)[dark].min() >= 30
    assert np.abs(lum_lit - lum)[clear].max() <= 3


@pytest.mark.parametrize("kind", ["rc", "gs"])
def test_a_leaf_shadows_the_stem_behind_it(renderers, kind):
    # the light straight from the camera's side: a leaf between the light and the stem
    # darkens the stem's lit face; without shadows the face is unchanged
    frusta = skin_skeleton(column())
    camera = Camera((2.5, 1.0, 4.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), 30.0, 64, 64)
    to_light = np.array([1.0, 0.0, 0.0])
    leaf = square((1.0, 1.0, 0.0), 0.25, 0)
    shadows = ShadowSettings(resolution=512)
    with_leaf = render(renderers, kind, frusta, camera, leaf, light_dir=to_light, shadows=shadows)
    without = render(renderers, kind, frusta, camera, None, light_dir=to_light, shadows=shadows)
    eye, dirs = camera.rays()
    points = eye + with_leaf.distance[..., None].astype(np.float64) * dirs
    on_stem = np.isfinite(with_leaf.distance) & (np.abs(np.hypot(points[..., 0], points[..., 2]) - RADIUS) < 2e-3)
    behind = on_stem & (np.abs(points[..., 1] - 1.0) < 0.15) & (np.abs(points[..., 2]) < 0.15) & (points[..., 0] > 0.1)
    assert behind.sum() > 5
    lum = with_leaf.color.astype(int).sum(axis=-1)
    assert (without.color.astype(int).sum(axis=-1) - lum)[behind].min() >= 20


def test_only_a_model_with_leaves_builds_the_leaf_programs(renderers):
    caster = renderers["rc"]
    frusta = skin_skeleton(column())
    camera = front_camera((0.0, 0.0, 0.0))
    caster.programs_used.clear()
    bare = caster.render(frusta, camera, RaycastSettings(), NAMES, shadows=ShadowSettings(resolution=256))
    assert not any(name == "leaf.glsl" for name, _ in caster.programs_used)
    assert "leaves" not in bare.stats.passes
    caster.programs_used.clear()
    leafy = caster.render(frusta, camera, RaycastSettings(), NAMES, shadows=ShadowSettings(resolution=256),
                          leaves=square((0.0, 1.0, 0.6), 0.3))
    assert {("leaf.glsl", ("SHADOW_PASS",)), ("leaf.glsl", ("SHADOWS",))} <= caster.programs_used
    assert leafy.stats.passes[-1] == "leaves"


def test_render_frames_and_draws_a_grammars_leaves(tmp_path):
    # a stem with one big leaf held out sideways, past the stem's own extent: the auto
    # camera keeps every leaf vertex inside the image, and the leaf pass is drawn
    from plantgen.pipeline import grow_file, render_model

    path = tmp_path / "flag.yaml"
    path.write_text('name: flag\naxiom: "F(2)[+(90){.G(1.5).-(90)G(0.6).-(90)G(1.5).}]"\n'
                    'materials: [bark, leaf]\nturtle: {angle: 90, step: 1.0}\nrules: []\n')
    leaves = grow_file(path).polygons
    assert len(leaves) == 1
    report = render_model(path, size=(96, 72))
    assert report.result.stats.passes[-2:] == ["frusta", "leaves"]
    camera = report.camera
    right, up, fwd = camera.basis()
    rel = leaves.vertices - np.asarray(camera.eye)
    depth = rel @ fwd
    tan_y = np.tan(np.radians(camera.fov_y) / 2)
    assert np.all(np.abs(rel @ up / depth) <= tan_y) and np.all(np.abs(rel @ right / depth) <= tan_y * camera.aspect)
    # the leaf is what the image's seen pixels mostly are: far more than the thin stem
    assert np.isfinite(report.result.distance).mean() > 0.1


def test_the_leaf_benchmark_times_every_variant_of_both_renderers():
    from plantgen.benchmarks.leaf_cost import VARIANTS, measure
    from plantgen.pipeline import grow_file

    row = measure("abop_bush", 64, 48, 1, 0)
    assert row["leaf_triangles"] == len(grow_file("abop_bush").polygons.triangles) > 0
    for method in ("RC", "GS"):
        assert all(row[f"{method} {label}"] > 0 for label, _, _ in VARIANTS)
