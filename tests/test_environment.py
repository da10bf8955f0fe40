"""The environment that answers ?E (plantgen.environment): exact shapes, and the shipped
models that grow in one (a topiary clipped to a cone, a tree against a wall, a tree grown
by space colonisation), each checked by what it means physically."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from plantgen._resources import grammars_dir
from plantgen.environment import EnvError, environment_for
from plantgen.environment.nearest import nearest_within
from plantgen.environment.shapes import Shape, parse_shape
from plantgen.errors import PlantgenError
from plantgen.files import read_yaml
from plantgen.limits import LimitError, Limits
from plantgen.lsystem import derive, parse_grammar
from plantgen.lsystem.turtle import interpret_plant

GRAMMARS = grammars_dir()


def _grow(data, path, **kwargs):
    g = parse_grammar(data, str(path))
    ms = derive(g, environment=environment_for(g, **kwargs))
    return g, interpret_plant(ms, g.turtle, g.materials, str(path)).skeleton


def _shipped(name):
    path = GRAMMARS / f"{name}.yaml"
    return read_yaml(path), path


def _segment_distance(points, start, end, chunk=512):
    """(n,) the distance of each point to the nearest segment (exact, chunked)."""
    d = end - start
    dd = np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)
    out = np.empty(len(points))
    for lo in range(0, len(points), chunk):
        p = points[lo:lo + chunk, None]
        t = np.clip(np.einsum("pij,ij->pi", p - start, d) / dd, 0, 1)
        out[lo:lo + chunk] = np.linalg.norm(p - (start + t[..., None] * d), axis=2).min(axis=1)
    return out


# ------------------------------------------------------------------ shapes
def _surface(shape: Shape, n: int, rng) -> np.ndarray:
    """Points on the surface of ``shape``, dense (to compare distances with)."""
    if shape.kind == "ellipsoid":
        u = rng.standard_normal((n, 3))
        return shape.center + shape.size * u / np.linalg.norm(u, axis=1, keepdims=True)
    lo, hi = shape.bounds
    p = lo + (hi - lo) * rng.random((n * 4, 3))
    # project onto the surface by a few steps along the distance's gradient (numerical)
    for _ in range(12):
        g = np.stack([(shape.distance(p + e) - shape.distance(p - e)) / 2e-6 for e in np.eye(3) * 1e-6], axis=1)
        p = p - shape.distance(p)[:, None] * g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)
    return p


@pytest.mark.parametrize("spec", [
    {"shape": "box", "center": [1, 2, 3], "size": [2, 1, 4]},
    {"shape": "ellipsoid", "center": [0, 1, 0], "radii": [1, 2, 3]},
    {"shape": "ellipsoid", "center": [0, 0, 0], "radii": [2, 2, 2]},
    {"shape": "cylinder", "center": [0, 0, 0], "radius": 1.5, "height": 2},
    {"shape": "cone", "center": [0, 0.5, 0], "radius": 1, "height": 3},
])
def test_signed_distance_is_the_distance_to_the_surface(spec, tmp_path):
    shape = parse_shape(spec, "t", tmp_path, Limits())
    rng = np.random.default_rng(1)
    surface = _surface(shape, 20_000, rng)
    assert np.abs(shape.distance(surface)).max() < 1e-6           # the surface is the zero set
    lo, hi = shape.bounds
    q = lo - 1 + (hi - lo + 2) * rng.random((300, 3))
    d = shape.distance(q)
    spatial = pytest.importorskip("scipy.spatial", reason="the brute-force nearest surface point uses scipy's KD-tree")
    nearest = spatial.cKDTree(surface).query(q)[0]
    spacing = 0.1                                                   # about the surface sample's spacing
    assert np.all(np.abs(d) <= nearest + 1e-9)                      # never farther than a surface point
    assert np.all(np.abs(d) >= nearest - spacing)                   # nor nearer than the surface
    assert (d < 0).any() and (d > 0).any()


def test_the_ray_distance_of_a_sphere_and_a_box_is_the_closed_form(tmp_path):
    sphere = parse_shape({"shape": "ellipsoid", "center": [0, 0, 0], "radii": [1, 1, 1]}, "t", tmp_path, Limits())
    o = np.array([[-3.0, 0.5, 0.0], [-3.0, 1.5, 0.0], [0.0, 0.0, 0.0]])
    d = np.array([[1.0, 0, 0], [1.0, 0, 0], [0, 1.0, 0]])
    t = sphere.ray(o, d, 100.0)
    assert t[0] == pytest.approx(3 - np.sqrt(1 - 0.25), abs=1e-6) and np.isinf(t[1]) and t[2] == 0.0
    box = parse_shape({"shape": "box", "center": [0, 0, 0], "size": [2, 2, 2]}, "t", tmp_path, Limits())
    assert box.ray(o, d, 100.0).tolist() == [2.0, np.inf, 0.0]
    grazing = box.ray(np.array([[-3.0, 1.0, 0.0]]), np.array([[1.0, 0, 0]]), 100.0)   # along a face
    assert grazing[0] == 2.0


def test_a_mesh_envelope_is_read_only_inside_the_grammars_folder(tmp_path):
    import trimesh
    trimesh.creation.box(extents=[2, 2, 2]).export(tmp_path / "box.obj")
    shape = parse_shape({"shape": "mesh", "file": "box.obj"}, "t", tmp_path, Limits())
    d = shape.distance(np.array([[0.0, 0, 0], [0.5, 0, 0], [3.0, 0, 0], [2.0, 2.0, 1.0]]))
    np.testing.assert_allclose(d, [-1.0, -0.5, 2.0, np.sqrt(2)], atol=1e-12)
    # its rays go through the BVH's traversal: the same distances as the box's slabs
    box = parse_shape({"shape": "box", "size": [2, 2, 2]}, "t", tmp_path, Limits())
    rng = np.random.default_rng(0)
    o, v = rng.uniform(-4, 4, (400, 3)), rng.standard_normal((400, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    np.testing.assert_allclose(shape.ray(o, v, 100.0), box.ray(o, v, 100.0), atol=1e-12)
    for name in ("../box.obj", "/etc/passwd"):
        with pytest.raises(EnvError, match="outside the grammar's folder"):
            parse_shape({"shape": "mesh", "file": name}, "t", tmp_path / "sub", Limits())


@pytest.mark.parametrize("batch", [1, 50, 10_000])
def test_nearest_within_is_the_brute_force_nearest_site(batch):
    rng = np.random.default_rng(2)
    points, sites = rng.random((2000, 3)) * 10, np.round(rng.random((400, 3)) * 10, 1)   # rounded: ties
    sites[1] = sites[0]                                            # an exact tie: the lower index wins
    index, dist = nearest_within(points, sites, 0.8, batch)
    d = np.linalg.norm(points[:, None] - sites[None], axis=2)
    near = d.min(axis=1) <= 0.8
    np.testing.assert_array_equal(index[near], d[near].argmin(axis=1))
    np.testing.assert_allclose(dist[near], d[near].min(axis=1), rtol=1e-12)
    assert np.all(index[~near] == -1) and np.all(np.isinf(dist[~near]))


# ------------------------------------------------------------------ topiary
def test_topiary_no_shoot_ends_outside_the_shape_by_more_than_an_internode_and_the_shape_is_filled():
    data, path = _shipped("topiary")
    g, skel = _grow(data, path)
    cone = environment_for(g).parts[0].shape
    lengths = np.linalg.norm(skel.end - skel.start, axis=1)
    internode = lengths[1:].max()                                   # the trunk aside
    outside = cone.distance(skel.end)
    assert outside.max() <= internode
    assert (outside > 0).any()                                     # it was clipped: shoots did grow out
    rng = np.random.default_rng(0)
    lo, hi = cone.bounds
    p = lo + (hi - lo) * rng.random((20_000, 3))
    p = p[cone.distance(p) < 0][:4000]
    filled = np.mean(_segment_distance(p, skel.start, skel.end) <= data["defines"]["l"])
    print(f"topiary: {len(skel)} segments, max end outside {outside.max():.3f} (internode {internode:.3f}), "
          f"{filled:.1%} of the cone within one internode of a segment")
    assert filled > 0.8


# ------------------------------------------------------------------ wall
def _crown(skel):
    mid, length = (skel.start + skel.end) / 2, np.linalg.norm(skel.end - skel.start, axis=1)
    crown = mid[:, 1] > skel.end[0, 1]                            # above the trunk's first segment
    centroid = (mid[crown] * length[crown, None]).sum(axis=0) / length[crown].sum()
    radius = np.hypot(mid[crown, 0] - skel.start[0, 0], mid[crown, 2] - skel.start[0, 2]).max()
    return centroid, radius


@pytest.mark.parametrize("seed", [None, 2, 3, 4, 5, 6], ids=lambda s: f"seed {s or 'shipped'}")
def test_a_tree_against_a_wall_never_crosses_it_and_grows_away_from_it(seed):
    """The shipped seed and five others (39 of the seeds 1-40 meet the quarter radius; the
    docs state it): the wall's response does not hang on one seed."""
    data, path = _shipped("wall_tree")
    if seed is not None:
        data["seed"] = seed
    g, skel = _grow(data, path)
    wall = environment_for(g).parts[0].shapes[0]
    length = np.linalg.norm(skel.end - skel.start, axis=1)
    through = wall.ray(skel.start, (skel.end - skel.start) / length[:, None], 1e9)
    assert np.all(through > length) and np.all(wall.distance(skel.end) > 0)
    free = copy.deepcopy(data)
    free["environment"][0]["obstacle"]["shapes"][0]["center"] = [1000, 3, 0]   # the same grammar in the open
    _, open_skel = _grow(free, path)
    assert len(open_skel) > len(skel)
    (c_wall, _), (c_open, radius) = _crown(skel), _crown(open_skel)
    toward = np.array([1.0, 0.0, 0.0])                             # from the trunk towards the wall
    shift = (c_open - c_wall) @ toward
    print(f"wall, seed {data['seed']}: {len(skel)} segments (open: {len(open_skel)}), crown centroid {shift:.2f} m "
          f"further from the wall, crown radius {radius:.2f} m (quarter {radius / 4:.2f})")
    assert shift >= radius / 4


# ------------------------------------------------------------------ markers
def test_space_colonisation_grows_into_the_markers_volume_and_consumes_them():
    data, path = _shipped("colonised")
    data = {**data, "iterations": 25}
    g, skel = _grow(data, path)
    env = environment_for(g)
    markers = env.parts[0]
    before = len(markers.points)
    ms = derive(g, environment=env)
    assert len(markers.points) < before / 2                         # the crown consumed most of them
    crown = markers.shape.distance(skel.end) < 0.5
    assert crown.mean() > 0.9                                       # it grew into the volume, not elsewhere
    assert len(ms) > 100


def test_markers_answer_zero_without_markers_and_the_unit_mean_direction_otherwise(tmp_path):
    data = {"name": "t", "iterations": 1, "seed": 1, "axiom": "F(1) ?E(0, 0, 0) F(10) ?E(0, 0, 0)",
            "environment": [{"markers": {"shape": {"shape": "box", "center": [0, 1, 2], "size": [0.1, 0.1, 0.1]},
                                         "density": 100000, "influence": 3, "kill": 0.01}}]}
    g = parse_grammar(data, str(tmp_path / "t.yaml"))
    ms = derive(g, environment=environment_for(g))
    e = ms.params[ms.sym == ms.symbols.index("?E"), :3]
    # the first ?E, at (0, 1, 0) heading +y (H = +y, L = -x, U = +z): its markers lie along +z, its U
    np.testing.assert_allclose(e[0], [0, 0, 1], atol=0.01)
    np.testing.assert_array_equal(e[1], [0, 0, 0])                # 10 m away: none within its influence


@pytest.mark.parametrize("name", ["colonised", "topiary"])
def test_a_seed_gives_the_same_plant_however_the_queries_are_batched(name):
    data, path = _shipped(name)
    data = {**data, "iterations": min(data["iterations"], 14)}
    grown = []
    for batch in (13, 97, 100_000):
        d = copy.deepcopy(data)
        for part in d["environment"]:
            next(iter(part.values()))["batch"] = batch
        grown.append(_grow(d, path)[1])
    for other in grown[1:]:
        np.testing.assert_array_equal(other.end, grown[0].end)


# ------------------------------------------------------------------ hostile input
@pytest.mark.parametrize("environment, match", [
    ("wall", "must be a list of parts"),
    ([{"sunshine": {}}], "must be one of envelope"),
    ([{"envelope": {"shape": "torus"}}], "shape must be one of"),
    ([{"envelope": {"shape": "box", "size": [1, -1, 1]}}], "size must be positive"),
    ([{"envelope": {"shape": "box", "size": [1, 1, 1], "batch": 0}}], "batch must be an integer"),
    ([{"obstacle": {"shapes": []}}], "non-empty list"),
    ([{"markers": {"shape": {"shape": "box", "size": [1e6, 1e6, 1e6]}, "density": 1}}], "over the limit"),
    ([{"markers": {"shape": {"shape": "box", "size": [1, 1, 1]}, "influence": 1, "kill": 2}}], "kill must be at most"),
])
def test_a_bad_environment_is_one_line(environment, match):
    g = parse_grammar({"name": "t", "axiom": "F ?E(0)", "environment": environment}, "t.yaml")
    with pytest.raises((EnvError, LimitError), match=match) as info:
        environment_for(g)
    assert "\n" not in str(info.value)


def test_the_answer_count_must_match_the_communication_modules():
    g = parse_grammar({"name": "t", "axiom": "F ?E(0)", "iterations": 1,
                       "environment": [{"obstacle": {"shapes": [{"shape": "box", "size": [1, 1, 1]}]}}]}, "t.yaml")
    with pytest.raises(PlantgenError, match="has 1 parameter.* answers 2"):
        derive(g, environment=environment_for(g))


def test_queries_count_against_their_limit():
    g = parse_grammar({"name": "t", "axiom": "A", "iterations": 20, "rules": ["A -> F ?P(0, 0, 0) A"]}, "t.yaml")
    with pytest.raises(LimitError, match="limit queries"):
        derive(g, limits=Limits(max_queries=50))


@pytest.mark.parametrize("environment, extra, match", [
    ("[{envelope: {shape: mesh, file: ../../etc/passwd}}]", (), "outside the grammar's folder"),
    ("[{markers: {shape: {shape: box, size: [4, 4, 4]}, density: 10}}]", ("--limit", "markers=100"),
     "raise it with --limit markers=N"),
])
def test_the_command_line_refuses_a_bad_environment_in_one_line(tmp_path, environment, extra, match):
    from _cli import run_cli

    grammar = tmp_path / "g.yaml"
    grammar.write_text(f'name: g\naxiom: "F ?E(0, 0, 0)"\niterations: 2\nenvironment: {environment}\n')
    code, _, err = run_cli("grow", grammar, "-o", tmp_path / "g.npz", *extra)
    assert code == 2 and match in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "g.npz").exists()
