"""Forests: the instanced ray caster draws what the merged one draws, a copy far from the
origin keeps its digits, the level of detail never leaves out a segment larger than its
threshold and keeps a small forest within the bench's error, and the shadow map is kept
exactly while what it depends on holds."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from plantgen.geometry.rays.camera import Camera
from plantgen.geometry.rays.instances import PlacedPlants, detail_order, place_frusta, similarity_parts
from plantgen.geometry.skeletons.frusta import section_points
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.geometry.stage import Ground
from plantgen.gl.frame import frame_view
from plantgen.gl.instanced import eye_copy_draws
from plantgen.gl.raycast import Raycaster
from plantgen.pipeline import grow_file
from plantgen.scene import rotation_matrix
from plantgen.settings import RaycastSettings, ShadowSettings
from plantgen.table1.quality import image_error

SHADOWS = ShadowSettings(resolution=512)
LIGHT = (0.45, 0.8, 0.35)


@cache
def _tree(grammar: str = "abop_ternary"):
    skeleton = grow_file(f"grammars/{grammar}.yaml").skeleton
    return skeleton, skin_skeleton(skeleton)


def _placement(position, yaw: float, scale: float) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = scale * rotation_matrix([0.0, yaw, 0.0])
    m[:3, 3] = position
    return m


def _grove(origin=(0.0, 0.0, 0.0)) -> tuple[PlacedPlants, Camera, Ground]:
    """Three turned and scaled copies of a tree, the camera looking at them from 40 units."""
    skeleton, frusta = _tree()
    o = np.asarray(origin, dtype=np.float64)
    mats = [_placement(o, 0.0, 1.0), _placement(o + [12, 0, 3], 37.0, 0.8), _placement(o + [-10, 0, -6], 200.0, 1.3)]
    placed = PlacedPlants.build([("ternary", frusta, skeleton.parent, mats)])
    camera = Camera(tuple(o + [0, 8, 40]), tuple(o + [0, 5, 0]), (0, 1, 0), 40.0, 256, 192)
    return placed, camera, Ground(size=60.0, height=float(o[1]), material="grass")


def _pair(placed, camera, ground, relief: bool):
    caster = Raycaster()
    kw = dict(settings=RaycastSettings(relief=relief), material_names=placed.material_names, light_dir=LIGHT,
              ground=ground, shadows=SHADOWS, shadow_box=placed.box)
    merged = caster.render(placed.merged(), camera, **kw)
    instanced = caster.render(placed, camera, **kw)
    return merged, instanced


@pytest.mark.parametrize("origin", [(0.0, 0.0, 0.0), (1e4, 0.0, -1e4)])
def test_instanced_ray_casting_draws_the_merged_scene(origin):
    """Records per plant plus a transform per copy (applied relative to the eye, the copy's
    offset in float64) give the merged records' image: the same pixels covered, the same
    distances to float32 rounding and colours within one level of rounding but where two
    surfaces cross (the nearer one decided by that rounding: a few pixels along the
    trunks' feet in the ground); 1e4 units from the origin as near it."""
    placed, camera, ground = _grove(origin)
    merged, instanced = _pair(placed, camera, ground, relief=False)
    hit = np.isfinite(merged.distance)
    assert hit.sum() > 2000
    np.testing.assert_array_equal(np.isfinite(instanced.distance), hit)
    close = np.isclose(instanced.distance[hit], merged.distance[hit], rtol=4e-6, atol=0)
    assert close.mean() >= 0.995
    same = np.abs(instanced.color.astype(int) - merged.color).max(axis=-1) <= 1
    assert same[hit].mean() >= 0.995 and same[~hit].all()
    assert instanced.stats.segments == len(placed) == merged.stats.segments


def test_instanced_relief_agrees_with_merged():
    """RC+R: the relief march amplifies float32 rounding only at a few grazing samples."""
    placed, camera, ground = _grove((1e4, 0.0, 0.0))
    merged, instanced = _pair(placed, camera, ground, relief=True)
    hit = np.isfinite(merged.distance)
    np.testing.assert_array_equal(np.isfinite(instanced.distance), hit)
    close = np.isclose(instanced.distance[hit], merged.distance[hit], rtol=1e-4, atol=0)
    assert close.mean() >= 0.99
    off = np.abs(instanced.color.astype(int) - merged.color).max(axis=-1) > 1
    assert off.sum() <= 0.02 * hit.sum()


def test_placed_frusta_are_the_transformed_rows():
    """place_frusta moves every row as its similarity moves points: the top point, a point
    on each plane and the radii follow."""
    _, frusta = _tree()
    m = _placement((3.0, -2.0, 5.0), 63.0, 1.7)
    moved = place_frusta(frusta, m)
    turn, scale, shift = (p[0] for p in similarity_parts(m))
    np.testing.assert_allclose(moved.top, scale * frusta.top @ turn.T + shift, atol=1e-9)
    np.testing.assert_allclose(moved.r2, scale * frusta.r2)
    on_plane = frusta.plane_lo[:, :3] * frusta.plane_lo[:, 3:]
    moved_point = scale * on_plane @ turn.T + shift
    np.testing.assert_allclose(np.einsum("ij,ij->i", moved.plane_lo[:, :3], moved_point), moved.plane_lo[:, 3],
                               atol=1e-9)


def test_the_shadow_map_is_kept_for_a_placed_scene_while_its_detail_holds():
    placed, camera, ground = _grove()
    caster = Raycaster()
    kw = dict(material_names=placed.material_names, light_dir=LIGHT, ground=ground, shadows=SHADOWS)
    first = caster.render(placed, camera, lod_pixels=1.0, **kw)
    moved = Camera((5.0, 6.0, 35.0), camera.target, camera.up, camera.fov_y, camera.width, camera.height)
    again = caster.render(placed, moved, lod_pixels=1.0, **kw)
    other = caster.render(placed, moved, lod_pixels=3.0, **kw)
    assert not first.stats.shadow_cached and again.stats.shadow_cached and not other.stats.shadow_cached


def _pixel_extent(points: np.ndarray, camera: Camera) -> np.ndarray:
    """(n,) the pixel extent (bounding box diagonal) of each row's (n, k, 3) points; inf
    for a row reaching behind the eye."""
    right, up, fwd = camera.basis()
    rel = points - np.asarray(camera.eye)
    z = rel @ fwd
    tan_y = np.tan(np.radians(camera.fov_y) / 2)
    px = (rel @ right) / np.maximum(z, 1e-12) / (tan_y * camera.aspect) * camera.width / 2
    py = (rel @ up) / np.maximum(z, 1e-12) / tan_y * camera.height / 2
    extent = np.hypot(px.max(axis=1) - px.min(axis=1), py.max(axis=1) - py.min(axis=1))
    return np.where((z > 0).all(axis=1), extent, np.inf)


@pytest.mark.parametrize("threshold", [1.0, 4.0])
def test_detail_never_leaves_out_a_segment_larger_than_its_threshold(threshold):
    """Copies from 5 to 400 units away: every row a copy leaves out spans fewer pixels than
    the threshold (its sections' points projected), and what it draws holds every drawn
    row's parent."""
    skeleton, frusta = _tree()
    mats = [_placement((0.0, 0.0, -z), 30.0 * k, 0.5 + 0.25 * k) for k, z in enumerate([5, 60, 300, 900, 2500])]
    placed = PlacedPlants.build([("ternary", frusta, skeleton.parent, mats)])
    plant = placed.plants[0]
    camera = Camera((0.0, 3.0, 10.0), (0.0, 3.0, -100.0), (0, 1, 0), 50.0, 640, 480)
    draws = eye_copy_draws(placed, frame_view(camera, [placed.box]), threshold)[0]
    counts = np.zeros(len(mats), dtype=np.int64)      # a copy left out whole draws none
    counts[draws.copies] = draws.counts
    assert counts.min() < len(plant.frusta) == counts.max()
    for copy, count in enumerate(counts):
        rows = place_frusta(plant.frusta, plant.matrices[copy])
        points = section_points(rows)[0].reshape(len(rows), -1, 3)
        assert _pixel_extent(points[count:], camera).max(initial=0.0) < threshold
        parents = plant.frusta.parent_row[:count]
        assert np.all(parents < count)


def test_detail_order_puts_parents_first_and_sizes_down():
    skeleton, frusta = _tree()
    order, sizes = detail_order(frusta, skeleton.parent)
    assert np.all(np.diff(sizes) <= 0)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    seg_rows = {int(s): i for i, s in enumerate(frusta.segment)}
    has = skeleton.parent >= 0
    child_rank = rank[[seg_rows[s] for s in np.flatnonzero(has)]]
    parent_rank = rank[[seg_rows[int(p)] for p in skeleton.parent[has]]]
    assert np.all(parent_rank < child_rank)


def test_a_small_forest_with_detail_stays_within_the_error_goal():
    """An 8 x 16 stand seen at eye height: 1.5 pixels of detail against full detail, by
    the bench's image error (1 - SSIM of the depth shading + silhouette mismatch)."""
    skeleton, frusta = _tree()
    rng = np.random.default_rng(5)
    mats = [_placement((x * 9 + rng.uniform(-2, 2), 0.0, -z * 9 - 15), rng.uniform(0, 360), rng.uniform(0.7, 1.2))
            for x in range(-4, 4) for z in range(16)]
    placed = PlacedPlants.build([("ternary", frusta, skeleton.parent, mats)])
    camera = Camera((0.0, 1.7, 10.0), (0.0, 6.0, -40.0), (0, 1, 0), 50.0, 320, 240)
    caster = Raycaster()
    full = caster.render(placed, camera, light_dir=LIGHT, material_names=placed.material_names)
    lod = caster.render(placed, camera, light_dir=LIGHT, material_names=placed.material_names, lod_pixels=1.5)
    assert lod.stats.segments < 0.9 * full.stats.segments
    assert image_error(lod.distance, full.distance, camera, LIGHT).total <= 0.01


@pytest.mark.parametrize("relief", [False, True])
def test_instanced_raster_draws_the_merged_mesh(relief):
    """GS (and GS+R): each plant's mesh once, a copy per draw, gives the image of the
    copies' meshes placed on the CPU and merged (the same tessellation, moved in float64)."""
    from plantgen.geometry.meshes.mesh import tessellate
    from plantgen.geometry.rays.instances import PlacedMeshes
    from plantgen.gl.raster import RasterRenderer

    placed, camera, ground = _grove((1e4, 0.0, 0.0))
    meshes = PlacedMeshes.tessellate(placed, 1, relief=relief)
    merged_frusta = placed.merged()
    merged_mesh = tessellate(merged_frusta, 1, relief=relief)
    renderer = RasterRenderer()
    kw = dict(light_dir=LIGHT, ground=ground, shadows=SHADOWS, shadow_box=placed.box)
    merged = renderer.render(merged_mesh, merged_frusta, camera, material_names=placed.material_names, **kw)
    instanced = renderer.render_placed(meshes, camera, **kw)
    hit = np.isfinite(merged.distance)
    assert hit.sum() > 2000
    # the same coverage but where a silhouette crosses a pixel centre (float32 placement
    # 1e4 from the origin against float64): a pixel that differs has a neighbour on the
    # other side of the merged image's silhouette, and such pixels are a few in 10,000
    differs = np.isfinite(instanced.distance) != hit
    padded = np.pad(hit, 1, mode="edge")
    edge = ((padded[1:-1, :-2] != hit) | (padded[1:-1, 2:] != hit)
            | (padded[:-2, 1:-1] != hit) | (padded[2:, 1:-1] != hit))
    assert not (differs & ~edge).any() and differs.mean() <= 1e-4, np.argwhere(differs)
    hit &= np.isfinite(instanced.distance)
    rel = np.abs(instanced.distance[hit] / merged.distance[hit] - 1)
    assert np.quantile(rel, 0.99) <= 4e-6       # the last percent: where surfaces cross
    same = np.abs(instanced.color.astype(int) - merged.color).max(axis=-1) <= 1
    assert same[hit].mean() >= 0.99
    assert instanced.stats.triangles == meshes.triangles == len(merged_mesh.faces)
    assert instanced.stats.buffer_bytes < 0.5 * merged.stats.buffer_bytes


GROVE = ("effects: [relief, shadows, lod]\nground: {size: 60, material: grass}\n"
         "camera: {eye: [0, 1.7, 30], target: [0, 4, 0], fov_y: 50}\n"
         "instances:\n  - {grammar: abop_monopodial, grid: {count: [4, 3], spacing: [8, 8], jitter: 0.3, seeds: 1,"
         " scale_jitter: 0.2}}\n  - {grammar: aloe, seed: 3, position: [2, 0, 12], grid: {count: [5, 2],"
         " spacing: [3, 3], jitter: 0.4, seeds: 2}}\n")


def test_a_grove_renders_instanced_from_the_command_line(tmp_path):
    from _cli import run_cli

    scene = tmp_path / "grove.yaml"
    scene.write_text(GROVE)
    out = tmp_path / "grove.png"
    code, stdout, stderr = run_cli("render", scene, "-o", out, "--size", "160x120", "--lod-pixels", "1.5")
    assert code == 0, stderr
    assert "22 copies of 3 plants" in stdout and "level of detail: 1.5 px" in stdout
    assert out.is_file()


def test_placed_segments_have_a_limit_the_command_line_raises(tmp_path):
    from _cli import run_cli

    scene = tmp_path / "grove.yaml"
    scene.write_text(GROVE)
    out = tmp_path / "grove.npz"
    code, _, stderr = run_cli("grow", scene, "-o", out, "--limit", "drawn_segments=5000")
    assert code == 2 and len(stderr.strip().splitlines()) == 1 and "drawn_segments" in stderr
    assert not out.exists()
    code, _, stderr = run_cli("grow", scene, "-o", out, "--limit", "drawn_segments=20000")
    assert code == 0, stderr
    code, _, stderr = run_cli("grow", scene, "-o", out, "--limit", "instances=10")
    assert code == 2 and "instances" in stderr


def test_grid_seeds_cycle_and_scales_jitter():
    from plantgen.scene import parse_scene

    grown = []

    def grow(path, seed, iterations):
        grown.append(seed)
        return _tree("aloe")[0]

    scene = parse_scene({"instances": [{"grammar": "aloe", "seed": 4, "grid": {
        "count": [5, 4], "spacing": [3, 3], "jitter": 0.2, "seeds": 3, "scale_jitter": 0.25}}]},
        "grammars/x.yaml", grow_grammar=grow)
    assert sorted(set(grown)) == [4, 5, 6] and len(grown) == 3       # each seed grown once
    assert [i.seed for i in scene.instances[:4]] == [4, 5, 6, 4]
    scales = similarity_parts(np.stack([i.matrix for i in scene.instances]))[1]
    assert scales.min() >= 0.75 and scales.max() <= 1.25 and scales.std() > 0.05


def test_the_shipped_forest_is_a_thousand_plants_from_a_few_grown_ones():
    grown = grow_file("grammars/forest.yaml")
    scene = grown.scene
    plants = scene.plants()
    assert len(scene.instances) >= 1000 and len(plants) >= 10
    # a million segments placed, 20 times what is grown (the pines' needles are sprays of
    # leaf polygons, so fewer segments than the leafless forest's 6 million)
    assert grown.segments >= 1_000_000 and "skeleton" not in vars(grown)     # never merged here
    assert grown.segments >= 20 * sum(len(p.skeleton) for p in plants)
    assert {"lod", "shadows", "relief"} <= set(scene.effects)
    assert scene.camera.eye[1] < 2.0          # eye height


def test_the_forest_bench_keeps_a_small_forest_within_the_error_goal(tmp_path):
    """The bench's own measure on a CI-sized forest (pines far off, ABOP trees near, seen
    at eye height): one pixel of detail draws far fewer rows at an error of at most 0.01."""
    from plantgen.benchmarks.forest import markdown, measure

    scene = tmp_path / "stand.yaml"
    scene.write_text("effects: [relief, shadows, lod]\nground: {size: 200, material: grass}\n"
                     "camera: {eye: [0, 1.7, 60], target: [0, 6, 0], fov_y: 50}\ninstances:\n"
                     "  - {grammar: abop_ternary, position: [0, 0, -20], grid: {count: [6, 6], spacing: [9, 9],"
                     " jitter: 0.3, seeds: 1, scale_jitter: 0.2}}\n"
                     "  - {grammar: pine, seed: 1, position: [0, 0, -100], grid: {count: [4, 2], spacing: [10, 10],"
                     " jitter: 0.3, seeds: 1}}\n")
    result = measure(str(scene), (256, 192), (0.0, 1.0), frames=0, say=lambda line: None, renderers=("RC+R",))
    full, lod = result["rows"]
    assert lod["error"] <= 0.01 and lod["dssim"] + lod["silhouette"] == pytest.approx(lod["error"])
    assert full["error"] == 0.0 and lod["silhouette"] > 0.0        # leaving twigs out loses pixels
    drawn = [int(r["drawn"].split()[0].replace(",", "")) for r in (full, lod)]
    assert drawn[0] == result["placed"] and drawn[1] < 0.6 * drawn[0]
    assert "| RC+R | 1 |" in markdown(result)


def test_the_impostor_table_counts_what_the_caster_draws_and_sizes_hold_each_copy():
    """rows_by_copy_size on a stand of copies 5 to 900 units off: its rows at each threshold
    are the rows the ray caster draws; every copy's rows project within its size (the
    pixels across its ball); a size over every copy holds every copy and row, one under
    every copy none."""
    from plantgen.benchmarks.forest import rows_by_copy_size, size_table

    skeleton, frusta = _tree()
    mats = [_placement((3.0 * k, 0.0, -z), 40.0 * k, 0.6 + 0.2 * k) for k, z in enumerate([5, 30, 120, 400, 900])]
    placed = PlacedPlants.build([("ternary", frusta, skeleton.parent, mats)])
    camera = Camera((0.0, 3.0, 10.0), (0.0, 3.0, -100.0), (0, 1, 0), 50.0, 320, 240)
    thresholds = (0.0, 2.0)
    table = rows_by_copy_size(placed, camera, None, thresholds, limits=(1, 1e6))
    caster = Raycaster()
    for px in thresholds:
        drawn = caster.render(placed, camera, light_dir=LIGHT, material_names=placed.material_names, lod_pixels=px)
        assert table["rows"][px] == drawn.stats.segments
    assert table["copies"] == len(mats)
    (_, none, rows_none), (_, every, rows_every) = table["under"]
    assert none == 0 and every == len(mats) and rows_every == table["rows"] and not any(rows_none.values())
    # each copy's points project inside the size the table gives it (the smallest bounds them all)
    plant = placed.plants[0]
    extents = [_pixel_extent(section_points(place_frusta(plant.frusta, m))[0].reshape(1, -1, 3), camera)[0]
               for m in plant.matrices]
    assert min(extents) <= table["smallest"] * np.sqrt(2) + 1e-6
    sizes = rows_by_copy_size(placed, camera, None, (0.0,), limits=sorted(e / np.sqrt(2) for e in extents))["under"]
    assert all(copies <= k for k, (_, copies, _) in enumerate(sizes))
    assert "| 1 px | 0 |" in "\n".join(size_table(table))
