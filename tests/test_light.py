"""The light environment: sky and sun traced against what has grown (the BVH's float64
traversal) and the obstacles; Borchert–Honda allocation; a self-organizing tree that
grows towards the light."""

from __future__ import annotations

import copy
import functools
from pathlib import Path

import numpy as np
import pytest

from plantgen._resources import grammars_dir
from plantgen.environment import environment_for
from plantgen.environment.light import Light, allocate, sky_directions
from plantgen.files import read_yaml
from plantgen.geometry.meshes.polygons import PolygonBuilder, Polygons
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.limits import LimitError, Limits
from plantgen.lsystem import derive, parse_grammar
from plantgen.lsystem.queries import QueryState
from plantgen.lsystem.turtle import Drawing, interpret_plant


def _state(points, drawing, segment=None, side=None):
    k = len(points)
    frame = [np.tile(v, (k, 1)) for v in ([0, 1.0, 0], [-1.0, 0, 0], [0, 0, 1.0])]
    return QueryState(1, np.arange(k), np.asarray(points, float), *frame, drawing, None, segment, side)


@functools.lru_cache
def _disc(radius, height, sides=256) -> Polygons:
    """A regular polygon (its inscribed circle's radius within 1e-4 of ``radius``)."""
    b = PolygonBuilder()
    a = np.linspace(0, 2 * np.pi, sides + 1)[:-1]
    b.add([(radius * np.cos(t), height, radius * np.sin(t)) for t in a], 0, -1)
    return b.build()


def _light(**settings):
    return Light(settings, "t", Path("."), Limits(), 0)


def test_sky_directions_cover_the_hemisphere_evenly():
    dirs, w = sky_directions(4096)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0)
    assert dirs[:, 1].min() > 0 and w.sum() == pytest.approx(1.0)
    assert np.abs(dirs.mean(axis=0) - [0, 0.5, 0]).max() < 1e-3     # the hemisphere's mean direction
    _, w = sky_directions(4096, "overcast")
    assert w[0] / w[-1] == pytest.approx(3.0, rel=1e-3)             # zenith three times the horizon


@pytest.mark.parametrize("sky", ["uniform", "overcast"])
@pytest.mark.parametrize("n", [64, 256, 1024])
def test_a_point_under_a_disc_receives_the_sky_its_solid_angle_leaves(sky, n):
    """Under a disc of half-angle α the uniform sky's open fraction is cos α (the disc's
    solid angle is 2π(1 - cos α)); the overcast sky's, (cos α + cos² α) / 2. The
    tolerance the ray count states: 1/√N."""
    light = _light(directions=n, sky=sky, offset=0.0)
    for radius, height in ((1.0, 1.0), (2.0, 0.5), (0.5, 2.0)):
        q = light.answer(_state([[0.0, 0.0, 0.0]], Drawing(Skeleton.empty(), _disc(radius, height))))[0, 0]
        c = height / np.hypot(radius, height)
        expected = c if sky == "uniform" else (c + c * c) / 2
        assert abs(q - expected) <= 1 / np.sqrt(n), (radius, height, q, expected)


def test_the_open_direction_points_away_from_the_shade_in_the_modules_frame():
    light = _light(directions=512, offset=0.0)
    half = _disc(1.0, 0.0)                                         # a roof over +x only
    roof = Polygons(half.vertices + [1.0, 0.5, 0.0], half.triangles, half.polygon, half.material, half.normal)
    ans = light.answer(_state([[0.0, 0.0, 0.0]], Drawing(Skeleton.empty(), roof)))[0]
    # frame H = +y, L = -x, U = +z: the open sky leans to -x, that is along +L
    assert ans[2] > 0.2 and ans[1] > 0 and abs(ans[3]) < 0.05


def test_obstacles_and_the_sun_block_and_light():
    wall = {"shape": "box", "center": [0, 5, 0], "size": [2000, 1, 2000]}
    roofed = _light(directions=64, obstacles=[wall], sun={"direction": [0, -1, 0], "share": 0.4})
    open_sky = _light(directions=64, sun={"direction": [0, -1, 0], "share": 0.4})
    empty = Drawing(Skeleton.empty(), Polygons.empty())
    assert roofed.answer(_state([[0.0, 0.0, 0.0]], empty))[0, 0] < 0.05
    assert open_sky.answer(_state([[0.0, 0.0, 0.0]], empty))[0, 0] == pytest.approx(1.0)
    sun_only = _light(directions=8, sun={"direction": [1, -1, 0], "share": 1.0},
                      obstacles=[{"shape": "box", "center": [-3, 3, 0], "size": [1, 1, 1]}])
    q = sun_only.answer(_state([[0.0, 0.0, 0.0], [0.0, 0.0, 2.0]], empty))[:, 0]
    assert q.tolist() == [0.0, 1.0]                                # the sun behind the box, and beside it


def test_branches_shade_the_buds_below_them():
    """A bud under a flat canopy of branches gets less light than the same bud above it."""
    g = parse_grammar({"name": "t", "axiom": "F(2) [ ?E(0, 0, 0, 0) ] C F(1) ?E(0, 0, 0, 0)", "iterations": 1,
                       "rules": ["C -> " + " ".join(f"[ /({a}) &(90) !(0.15) F(1.2) ]" for a in range(0, 360, 20))],
                       "environment": [{"light": {"directions": 128}}]}, "t.yaml")
    env = environment_for(g)
    ms = derive(g, environment=env)
    q = ms.params[ms.sym == ms.symbols.index("?E"), 0]
    assert q[1] > 0.95 and q[0] < 0.75


def test_borchert_honda_conserves_the_resource_and_shares_it_by_lambda():
    # a trunk (0) with a main continuation (1) and a lateral (2); a bud at the tip of each
    skel = Skeleton(start=np.array([[0, 0, 0], [0, 1, 0], [0, 1, 0]], float),
                    end=np.array([[0, 1, 0], [0, 2, 0], [1, 2, 0]], float), r_start=np.full(3, 0.1),
                    r_end=np.full(3, 0.1), parent=np.array([-1, 0, 0]), continues=np.array([False, True, False]),
                    material=np.zeros(3, np.int32))
    state = _state(np.zeros((2, 3)), Drawing(skel, Polygons.empty()), np.array([1, 2]), np.array([False, True]))
    q = np.array([1.0, 1.0])
    for lam in (0.3, 0.5, 0.7):
        v = allocate(state, q, 2.0, lam)
        assert v.sum() == pytest.approx(2.0 * q.sum())                 # alpha times the light, all of it
        assert v[0] / v[1] == pytest.approx(lam / (1 - lam))           # main : lateral = lambda : 1 - lambda


def _self_organizing(iterations, obstacles=None, batch=None):
    path = grammars_dir() / "self_organizing.yaml"
    data = copy.deepcopy(read_yaml(path))
    data["iterations"] = iterations
    light = data["environment"][0]["light"]
    if obstacles:
        light["obstacles"] = obstacles
    if batch:
        light["batch"] = batch
    g = parse_grammar(data, str(path))
    return interpret_plant(derive(g, environment=environment_for(g)), g.turtle, g.materials).skeleton


def _volume_centroid(skel):
    r = (skel.r_start + skel.r_end) / 2
    v = np.pi * r * r * np.linalg.norm(skel.end - skel.start, axis=1)
    return ((skel.start + skel.end) / 2 * v[:, None]).sum(axis=0) / v.sum()


def test_a_self_organizing_tree_beside_a_shade_grows_towards_the_lit_side():
    shade = [{"shape": "box", "center": [2.0, 2.5, 0], "size": [0.4, 5, 10]}]    # a screen on the +x side
    lit, shaded = _self_organizing(18), _self_organizing(18, shade)
    c_lit, c_shaded = _volume_centroid(lit), _volume_centroid(shaded)
    print(f"self-organizing: {len(lit)} segments in the open, {len(shaded)} beside the screen; volume "
          f"centroid x {c_lit[0]:+.3f} -> {c_shaded[0]:+.3f} m")
    assert c_shaded[0] < c_lit[0] - 0.1 and c_shaded[0] < 0          # away from the screen, onto the lit side


def test_the_self_organizing_tree_is_the_same_however_its_light_is_batched():
    a, b = _self_organizing(14, batch=3), _self_organizing(14, batch=100_000)
    np.testing.assert_array_equal(a.end, b.end)


def test_light_rays_count_against_their_limit():
    light = Light({"directions": 100}, "t", Path("."), Limits(max_light_rays=500), 0)
    with pytest.raises(LimitError, match="light rays: 1,000 over the limit of 500"):
        light.answer(_state(np.zeros((10, 3)), Drawing(Skeleton.empty(), Polygons.empty())))


def _stand(positions, iterations=16, seed=5):
    """The shipped stand's rules with trunks at ``positions`` ((x, z) pairs): the trees,
    each a list of its segments' (start, end)."""
    path = grammars_dir() / "stand.yaml"
    data = copy.deepcopy(read_yaml(path))
    data.update(iterations=iterations, seed=seed,
                axiom=" ".join(f"[ &(90) G({-z}) ^(90) +(90) G({-x}) -(90) !(0.008) F(0.6) ?E(1, 0, 0, 0, 0) "
                               "A(0.008) ]" for x, z in positions))
    g = parse_grammar(data, str(path))
    skel = interpret_plant(derive(g, environment=environment_for(g)), g.turtle, g.materials).skeleton
    root = np.arange(len(skel))
    for s in range(len(skel)):
        if skel.parent[s] >= 0:
            root[s] = root[skel.parent[s]]
    roots = np.flatnonzero(skel.parent < 0)
    return [(skel.start[root == r], skel.end[root == r]) for r in roots]


def _reach(tree, base, towards):
    """How far the tree's crown reaches from its trunk ``base`` along ``towards`` (unit, horizontal)."""
    return float(((tree[1] - base) @ towards).max())


def _crown_shape(trees, grid) -> float:
    """The trees' mean height over crown width (each tree's width: twice its farthest tip
    from its trunk, horizontally)."""
    ratios = []
    for (_, end), (x, z) in zip(trees, grid, strict=True):
        ratios.append(end[:, 1].max() / (2 * np.hypot(end[:, 0] - x, end[:, 2] - z).max()))
    return float(np.mean(ratios))


def _overlap(trees, grid, spacing) -> float:
    """How far side-by-side neighbours' crowns reach into each other, summed (m)."""
    total = 0.0
    for a in range(len(grid)):
        for b in range(a + 1, len(grid)):
            pa, pb = np.array([grid[a][0], 0, grid[a][1]]), np.array([grid[b][0], 0, grid[b][1]])
            d = np.linalg.norm(pb - pa)
            if d > spacing * 1.2:
                continue
            u = (pb - pa) / d
            total += max(0.0, _reach(trees[a], pa, u) + _reach(trees[b], pb, -u) - d)
    return total


def test_a_stand_grows_taller_for_its_width_with_less_overlap_than_the_same_trees_apart():
    spacing = 1.6
    grid = [(i * spacing, j * spacing) for i in (-1, 0, 1) for j in (-1, 0, 1)]
    stand = _stand(grid)
    apart = [_stand([p], seed=5 + k)[0] for k, p in enumerate(grid)]
    shape, overlap = (_crown_shape(stand, grid), _crown_shape(apart, grid)), (_overlap(stand, grid, spacing),
                                                                              _overlap(apart, grid, spacing))
    print(f"stand of 9: height / crown width {shape[0]:.2f} (apart {shape[1]:.2f}); overlap of neighbours "
          f"{overlap[0]:.2f} m (apart {overlap[1]:.2f} m)")
    assert _crown_shape(stand, grid) > _crown_shape(apart, grid)
    assert _overlap(stand, grid, spacing) < _overlap(apart, grid, spacing)


def test_a_scene_grown_together_against_the_same_scene_grown_apart(tmp_path):
    """grow: together: the same nine self_organizing trees (same seeds, same places)."""
    from plantgen.pipeline import grow_file

    spacing, grown = 1.6, {}
    for mode in ("together", "apart"):
        (tmp_path / f"{mode}.yaml").write_text(
            f"name: {mode}\nseed: 5\ngrow: {mode}\ninstances:\n  - grammar: self_organizing\n    iterations: 16\n"
            f"    grid: {{count: [3, 3], spacing: [{spacing}, {spacing}]}}\n")
        scene = grow_file(tmp_path / f"{mode}.yaml").scene
        placed = [i.skeleton.transformed(i.matrix) for i in scene.instances]
        grown[mode] = ([(s.start, s.end) for s in placed], [(i.matrix[0, 3], i.matrix[2, 3]) for i in scene.instances])
    (together, grid), (apart, _) = grown["together"], grown["apart"]
    shape = _crown_shape(together, grid), _crown_shape(apart, grid)
    overlap = _overlap(together, grid, spacing), _overlap(apart, grid, spacing)
    print(f"grove of 9 (grow: together vs apart): height / crown width {shape[0]:.2f} vs {shape[1]:.2f}; overlap "
          f"of neighbours {overlap[0]:.2f} m vs {overlap[1]:.2f} m")
    assert shape[0] > shape[1] and overlap[0] < overlap[1]
