"""The compiled BVH builds (plantgen.geometry.rays.native_build), LBVH and binned SAH: the
numpy build's tree, node for node: the same primitive order, the same first and count of
every node and the same node boxes, on random, coincident, flat and tiny sets of boxes and
every leaf size; so a target traced with it answers as with the numpy build."""

from __future__ import annotations

import numpy as np
import pytest

from plantgen.geometry.rays import native_trace
from plantgen.geometry.rays.bvh import build_bvh

pytestmark = pytest.mark.skipif(not native_trace.available(), reason="numba does not run here: the numpy build "
                                                                     "is the only one")


def _boxes(rng, n, kind):
    lo = rng.uniform(-5, 5, (n, 3))
    if kind == "coincident":            # many equal centres: equal Morton codes split in the middle
        lo = np.round(lo / 4) * 4
    hi = lo + (0.0 if kind == "flat" else rng.uniform(0, 1, (n, 3)))
    return lo, hi


@pytest.mark.parametrize("n", [1, 2, 3, 5, 8, 17, 200, 3000])
@pytest.mark.parametrize("kind", ["random", "coincident", "flat"])
@pytest.mark.parametrize("leaf_size", [1, 2, 4, 7])
@pytest.mark.parametrize("method,bins", [("lbvh", 16), ("sah", 16), ("sah", 2)])
def test_the_compiled_build_lays_out_the_numpy_builds_tree(n, kind, leaf_size, method, bins):
    lo, hi = _boxes(np.random.default_rng(n * 31 + leaf_size), n, kind)
    numpy_tree = build_bvh(lo, hi, leaf_size=leaf_size, method=method, bins=bins)
    compiled = build_bvh(lo, hi, leaf_size=leaf_size, method=method, bins=bins, compiled=True)
    assert compiled.nodes == numpy_tree.nodes
    for name in ("lo", "hi", "first", "count", "prims"):
        a, b = getattr(numpy_tree, name), getattr(compiled, name)
        assert a.dtype == b.dtype and a.shape == b.shape
        assert np.array_equal(a, b), name
    assert [len(level) for level in compiled.levels()] == [len(level) for level in numpy_tree.levels()]
    assert compiled.depth() == numpy_tree.depth() == len(numpy_tree.levels())


@pytest.mark.parametrize("n", [1, 2, 50, 4000])
def test_the_compiled_morton_codes_are_numpys(n):
    """The centres' codes, flat and coincident sets among them (a zero extent)."""
    from plantgen.geometry.rays.morton import morton_codes
    from plantgen.geometry.rays.native_build import centre_codes

    rng = np.random.default_rng(n)
    for lo, hi in (_boxes(rng, n, "random"), _boxes(rng, n, "coincident"), (np.ones((n, 3)), np.ones((n, 3))),
                   (rng.uniform(-1e6, 1e6, (n, 3)), np.full((n, 3), 1e6))):
        codes = centre_codes(lo, hi)
        assert codes.dtype == np.uint64
        assert np.array_equal(codes, morton_codes(0.5 * (lo + hi)))


def test_a_scan_target_builds_its_tree_compiled_where_the_walk_runs_and_answers_the_same():
    """Where the compiled walk runs, a target's BVH is built compiled, by the SAH unless
    the target asks for the LBVH (a light's): each the numpy build's tree; and the walk
    over either gives the numpy oracle's hits."""
    from plantgen.geometry.rays.scan_targets import scan_target
    from plantgen.geometry.skeletons.skeleton import Skeleton

    rng = np.random.default_rng(3)
    n = 60
    start = rng.uniform(-1, 1, (n, 3))
    skel = Skeleton(start, start + rng.uniform(-0.3, 0.3, (n, 3)), np.full(n, 0.05), np.full(n, 0.04),
                    np.full(n, -1), np.zeros(n, bool), np.zeros(n, np.int32))
    origins = rng.uniform(-1.5, 1.5, (500, 3))
    dirs = rng.normal(size=(500, 3))
    native_trace.warm_up()
    for split, method in (("auto", "sah"), ("lbvh", "lbvh")):
        target = scan_target(skel, split=split)
        numpy_tree = build_bvh(target.lo, target.hi, method=method)
        for name in ("lo", "hi", "first", "count", "prims"):
            assert np.array_equal(getattr(target.bvh, name), getattr(numpy_tree, name)), (split, name)
        for any_hit in (True, False):
            t_native, p_native = target.first_hits(origins, dirs, any_hit=any_hit, origin=target.base)
            t_numpy, p_numpy = target.first_hits(origins, dirs, any_hit=any_hit, origin=target.base, native=False)
            assert np.isfinite(t_native).any() and not np.isfinite(t_native).all()
            assert np.array_equal(np.isfinite(t_native), np.isfinite(t_numpy))
            if not any_hit:                  # the closest hit: the same primitive, the same t
                assert np.array_equal(t_native, t_numpy) and np.array_equal(p_native, p_numpy)


def _random_rows(rng, n):
    """Rows of every kind the pyramids meet: ordinary joints, planes tilted towards the
    axis (grazing: the axial-extent fallback), planes parallel to it, cones past their
    apex, zero radii, zero slopes."""
    from plantgen.geometry.skeletons.frusta import Frusta

    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    ref = rng.normal(size=(n, 3))
    ref -= axis * np.einsum("ij,ij->i", ref, axis)[:, None]
    ref /= np.linalg.norm(ref, axis=1, keepdims=True)
    base = rng.uniform(-3, 3, (n, 3))
    length = rng.uniform(0.05, 1.0, n)
    r1 = rng.choice([0.0, 0.02, 0.1, 0.4], n) * rng.uniform(0.5, 1.5, n)
    r2 = np.where(rng.random(n) < 0.2, r1, rng.uniform(0, 0.4, n))
    planes = []
    for end in (0.0, 1.0):
        tilt = rng.choice([0.0, 0.3, 1.2, 1.5, np.pi / 2], n) * rng.uniform(0.9, 1.0, n)
        other = rng.normal(size=(n, 3))
        other -= axis * np.einsum("ij,ij->i", other, axis)[:, None]
        other /= np.linalg.norm(other, axis=1, keepdims=True)
        normal = np.cos(tilt)[:, None] * axis + np.sin(tilt)[:, None] * other
        point = base + (end * length)[:, None] * axis
        planes.append(np.concatenate([normal, np.einsum("ij,ij->i", normal, point)[:, None]], axis=1))
    return Frusta(base=base, axis=axis, length=length, r1=r1, r2=r2, plane_lo=planes[0], plane_hi=planes[1],
                  ref_dir=ref, u_offset=np.zeros(n), twist=np.zeros(n), material=np.zeros(n, np.int32),
                  shell=np.zeros(n), segment=np.arange(n))


def test_the_compiled_row_boxes_are_the_numpy_ones_number_for_number():
    """Random rows (grazing, parallel and past-the-apex ones among them) and a skinned
    tree: the compiled boxes are numpy's, each number and its sign; grazing rows (the
    axial-extent fallback) occur."""
    from plantgen.geometry.rays import native_build
    from plantgen.geometry.rays.reference import row_boxes
    from plantgen.geometry.skeletons.skin import skin_skeleton
    from plantgen.pipeline import grow_file

    rows = _random_rows(np.random.default_rng(11), 4000)
    tree = skin_skeleton(grow_file("self_organizing", iterations=8).skeleton)
    for frusta in (rows, tree):
        with np.errstate(all="ignore"):
            expected = row_boxes(frusta)
        got = native_build.row_boxes(frusta)
        for a, b in zip(expected, got, strict=True):
            assert np.array_equal(a, b, equal_nan=True)
            assert np.array_equal(np.signbit(a), np.signbit(b))
    lo, hi = native_build.row_boxes(rows)
    extent = (hi - lo).max(axis=1)
    size = rows.length + np.maximum(rows.r1, rows.r2)
    assert (extent > 50 * size).any()      # planes near the axis: grazing cuts and the fallback's long boxes
    assert (extent < 3 * size).sum() > len(rows) // 4


def test_a_native_scenes_tables_are_its_targets_in_slot_order():
    """The compiled walk's tables (gathered in one compiled pass): the rows and triangles
    in the order the BVH's leaves list them, each primitive's kind pointing at its own
    table row, each slot's box its primitive's."""
    from _geometry_helpers import random_tree

    from plantgen.geometry.meshes.polygons import Polygons
    from plantgen.geometry.rays.native_trace import ROW_WIDTH, native_scene
    from plantgen.geometry.rays.scan_targets import scan_target

    rng = np.random.default_rng(5)
    skel = random_tree(80, seed=2)
    v = rng.uniform(-1, 1, (60, 3))
    leaves = Polygons(v, rng.integers(0, 60, (40, 3)), np.arange(40), np.zeros(40, np.int32), np.zeros((40, 3)),
                      rng.integers(0, 80, 40))
    target = scan_target(skel, leaves)
    scene = native_scene(target)
    nodes, slot_box, prims, slot_kind, rows, triangles = scene.scene
    n_rows = target.rows
    assert np.array_equal(prims, target.bvh.prims)
    assert np.array_equal(slot_box, np.concatenate([target.lo[prims], target.hi[prims]], axis=1))
    assert np.array_equal(slot_kind, scene.kind[prims])
    is_row = prims < n_rows
    assert np.array_equal(slot_kind[is_row], np.arange(is_row.sum()))           # rows in slot order
    assert np.array_equal(-1 - slot_kind[~is_row], np.arange((~is_row).sum()))  # and triangles
    up = target.pair_tester.upload
    row_table = np.column_stack([up.c1, up.a, up.h, up.r1, up.k, up.n_lo, up.n_hi, up.d_lo, up.d_hi, up.open_lo,
                                 up.open_hi]).astype(np.float64)
    assert rows.shape == (n_rows, ROW_WIDTH) and np.array_equal(rows, row_table[prims[is_row]])
    v0, e1, e2, size = target.triangle_edges
    tri = prims[~is_row] - n_rows
    assert np.array_equal(triangles, np.column_stack([v0, e1, e2, size])[tri])


def test_a_target_built_compiled_is_the_numpy_built_one():
    """scan_target(compiled=True) (rows' and leaves' boxes compiled) gives the numpy
    build's triangles and boxes, number for number and sign for sign; so does a target
    with no leaves or no branches."""
    from _geometry_helpers import random_tree

    from plantgen.geometry.meshes.polygons import Polygons
    from plantgen.geometry.rays.scan_targets import scan_target
    from plantgen.geometry.skeletons.skeleton import Skeleton

    rng = np.random.default_rng(9)
    v = rng.uniform(-2, 2, (90, 3))
    v[:10, 1] = 0.0                          # corners on a coordinate plane: zeros in the boxes
    v[10:20, 0] = -0.0
    leaves = Polygons(v, rng.integers(0, 90, (70, 3)), np.arange(70), np.zeros(70, np.int32), np.zeros((70, 3)),
                      rng.integers(-1, 50, 70))
    unhung = Polygons(leaves.vertices, leaves.triangles, leaves.polygon, leaves.material, leaves.normal,
                      np.full(70, -1))
    for skel, polys in ((random_tree(50, seed=4), leaves), (random_tree(50, seed=4), None),
                        (Skeleton.empty(), unhung)):
        a, b = scan_target(skel, polys), scan_target(skel, polys, compiled=True)
        for name in ("triangles", "triangle_polygon", "lo", "hi", "base"):
            x, y = getattr(a, name), getattr(b, name)
            assert x.dtype == y.dtype and x.shape == y.shape, name
            assert np.array_equal(x, y) and np.array_equal(np.signbit(x), np.signbit(y)), name
