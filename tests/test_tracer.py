"""plantgen.trace: the public ray query (float64 path; the float32 hook with a stand-in)."""

from __future__ import annotations

import sys
import types

import numpy as np
import pytest
from _geometry_helpers import chain_skeleton

import plantgen
from plantgen.errors import PlantgenError
from plantgen.geometry.rays.scan import cast_first_returns, scan_target
from plantgen.limits import LimitError, Limits
from plantgen.tracer import TraceError, trace_target


def rays_at(box, m, seed):
    rng = np.random.default_rng(seed)
    lo, hi = box
    centre, size = (lo + hi) / 2, (hi - lo).max()
    O = centre + (rng.random((m, 3)) - 0.5) * size * 1.6
    return O, centre + (rng.random((m, 3)) - 0.5) * size * 0.7 - O


@pytest.fixture(scope="module")
def bush():
    target = plantgen.tracer._target("abop_bush", Limits())
    return target


def test_trace_equals_brute_force_with_labels_and_normals(bush):
    O, D = rays_at(bush.box(), 60, 1)
    res = plantgen.trace(bush, O, D)
    t, prim = cast_first_returns(bush, O, D)                      # every primitive, no BVH
    np.testing.assert_allclose(res.t, t, rtol=1e-13)              # (its pair test works relative to ray 0)
    np.testing.assert_array_equal(res.primitive, prim)
    assert res.hit.sum() >= 10
    wood = res.hit & (res.primitive < bush.rows)
    leaf = res.hit & (res.primitive >= bush.rows)
    assert wood.any() and leaf.any()
    assert (res.part[leaf] == res.part_names.index("leaf")).all() and (res.leaf[leaf] >= 0).all()
    assert (res.leaf[wood] == -1).all() and np.isin(res.part[wood], [0, 1]).all()
    np.testing.assert_array_equal(res.segment[wood], bush.frusta.segment[res.primitive[wood]])
    assert (res.plant[res.hit] == 0).all() and (res.plant[~res.hit] == -1).all()
    n = res.normal[res.hit]
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    assert ((n * D[res.hit]).sum(axis=1) <= 0).all()                     # facing against the ray
    assert (res.normal[~res.hit] == 0).all() and np.isinf(res.t[~res.hit]).all()


def test_cylinder_normals_and_distances():
    skel = chain_skeleton(lengths=2.0, radii=0.5)
    O = np.array([[3.0, 1.0, 0.0], [0.0, 1.2, -4.0], [0.0, 5.0, 0.0]])
    D = np.array([[-2.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    res = plantgen.trace(skel, O, D)
    np.testing.assert_allclose(res.t, [1.25, 3.5, 3.0], rtol=1e-12)        # t in units of |direction|
    np.testing.assert_allclose(res.normal, [[1, 0, 0], [0, 0, -1], [0, 1, 0]], atol=1e-12)
    assert res.part.tolist() == [0, 0, 0] and res.segment.tolist() == [0, 0, 0]


def test_shapes_any_hit_and_limits(bush):
    O, D = rays_at(bush.box(), 24, 2)
    grid = plantgen.trace(bush, O.reshape(4, 6, 3), D.reshape(4, 6, 3))
    assert grid.t.shape == (4, 6) and grid.normal.shape == (4, 6, 3)
    flat = plantgen.trace(bush, O, D)
    np.testing.assert_array_equal(grid.t.ravel(), flat.t)
    shadow = plantgen.trace(bush, O, D, any_hit=True)
    np.testing.assert_array_equal(shadow.hit, flat.hit)
    near = plantgen.trace(bush, O, D, t_max=np.nanmedian(np.where(flat.hit, flat.t, np.nan)))
    assert near.hit.sum() < flat.hit.sum() and (near.t[near.hit] == flat.t[near.hit]).all()
    beyond = plantgen.trace(bush, O, D, t_min=0.5)
    assert (beyond.t[beyond.hit] > 0.5).all()
    one = plantgen.trace(bush, O[0], D[0])                               # a single ray: 0-d arrays
    assert one.t.shape == () and one.normal.shape == (3,)


@pytest.mark.parametrize("origins, directions, match", [
    (np.zeros((3, 2)), np.ones((3, 2)), "shape"),
    (np.zeros((3, 3)), np.ones((2, 3)), "broadcast"),
    (np.full((2, 3), np.nan), np.ones((2, 3)), "finite origins"),
    (np.zeros((2, 3)), np.array([[1.0, 0, 0], [0, 0, 0]]), "non-zero directions"),
    ("abc", np.ones(3), "numbers"),
])
def test_bad_rays_are_one_line_errors(bush, origins, directions, match):
    with pytest.raises(TraceError, match=match) as err:
        plantgen.trace(bush, origins, directions)
    assert "\n" not in str(err.value)


def test_bad_options_and_models():
    skel = chain_skeleton()
    for kw, match in (({"precision": "float16"}, "precision"), ({"t_min": -1.0}, "t_min"),
                      ({"t_min": 2.0, "t_max": 1.0}, "t_max")):
        with pytest.raises(TraceError, match=match):
            plantgen.trace(skel, np.zeros(3), np.ones(3), **kw)
    with pytest.raises(TraceError, match="model"):
        plantgen.trace(42, np.zeros(3), np.ones(3))
    with pytest.raises(LimitError, match="scan_rays"):
        plantgen.trace(skel, np.zeros((11, 3)), np.ones(3), limits=Limits(max_scan_rays=10))
    with pytest.raises(PlantgenError):
        plantgen.trace("no/such/grammar.yaml", np.zeros(3), np.ones(3))


def test_float32_hook(monkeypatch):
    """Without plantgen.gl.trace.trace_target: one clear line. With one, its primitives are
    kept and their distances solved again in float64."""
    target = scan_target(chain_skeleton(bends_deg=(30.0,), radii=0.3))
    O, D = rays_at(target.box(), 30, 3)
    bare = types.ModuleType("plantgen.gl.trace")
    monkeypatch.setitem(sys.modules, "plantgen.gl.trace", bare)
    monkeypatch.setattr(plantgen.gl, "trace", bare, raising=False)
    with pytest.raises(TraceError, match="GPU traversal .* not available yet"):
        trace_target(target, O, D, precision="float32")
    exact = trace_target(target, O, D)

    def trace_target_gpu(tg, origins, dirs, *, any_hit, t_min, t_max):
        t, prim = cast_first_returns(tg, origins, dirs)
        return (t * (1 + 1e-6)).astype(np.float32), prim             # float32 distances, right primitives

    bare.trace_target = trace_target_gpu
    got = trace_target(target, O, D, precision="float32")
    assert exact.hit.sum() >= 5
    np.testing.assert_array_equal(got.primitive, exact.primitive)
    np.testing.assert_array_equal(got.t, exact.t)


def test_a_scene_is_traced_through_two_levels():
    """desert by name: its copies' hits carry the merged scene's labels; normals turned
    into the world face the rays and are unit."""
    from plantgen.geometry.rays.scan import SceneTarget
    from plantgen.pipeline import grow_file, model_leaves, skin_model

    two = plantgen.tracer._target("desert", Limits())
    assert isinstance(two, SceneTarget)
    grown = grow_file("desert")
    merged = scan_target(grown.skeleton, model_leaves(grown), frusta=skin_model(grown),
                         plant=grown.scene.segment_instance())
    O, D = rays_at(merged.box(), 1500, 4)
    res = plantgen.trace(two, O, D)
    ref = plantgen.trace(merged, O, D)
    np.testing.assert_array_equal(res.hit, ref.hit)
    assert res.hit.sum() > 30
    same = res.segment == ref.segment
    assert same.mean() > 0.99 and (res.plant[same] == ref.plant[same]).all()
    np.testing.assert_allclose(res.t[same & res.hit], ref.t[same & res.hit], rtol=1e-9)
    np.testing.assert_allclose(res.normal[same], ref.normal[same], atol=1e-9)
    shadow = plantgen.trace(two, O, D, any_hit=True)
    np.testing.assert_array_equal(shadow.hit, ref.hit)
