"""The BVH build (plantgen.geometry.rays.bvh): structural invariants on random, degenerate and
coincident boxes, for both build methods."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plantgen.geometry.rays.bvh import BVH_METHODS, BVHError, build_bvh, float32_boxes, morton_codes, refit_bvh


def check_invariants(bvh, lo, hi, leaf_size):
    """Every node bounds its children and its primitives; every primitive is in exactly
    one leaf; children are adjacent and numbered after their parent."""
    n = len(lo)
    if n == 0:
        assert bvh.nodes == 0 and len(bvh.prims) == 0
        return
    nodes = bvh.nodes
    assert bvh.lo.shape == bvh.hi.shape == (nodes, 3)
    assert bvh.first.dtype == bvh.count.dtype == bvh.prims.dtype == np.int32
    assert nodes <= 2 * n - 1
    inner = np.flatnonzero(bvh.count == 0)
    leaf = np.flatnonzero(bvh.count > 0)
    left = bvh.first[inner]
    assert (left > inner).all() and (left + 1 < nodes).all()
    for child in (left, left + 1):
        assert (bvh.lo[child] >= bvh.lo[inner]).all() and (bvh.hi[child] <= bvh.hi[inner]).all()
    # every node but the root is the child of exactly one node
    children = np.concatenate([left, left + 1])
    assert np.array_equal(np.sort(children), np.arange(1, nodes))
    assert (bvh.count[leaf] <= leaf_size).all()
    slots = np.concatenate([np.arange(f, f + c) for f, c in zip(bvh.first[leaf], bvh.count[leaf], strict=True)])
    assert np.array_equal(np.sort(slots), np.arange(n))             # leaves tile prims exactly
    assert np.array_equal(np.sort(bvh.prims), np.arange(n))         # each primitive once
    owner = np.repeat(leaf, bvh.count[leaf])
    prim = np.concatenate([bvh.prims[f:f + c] for f, c in zip(bvh.first[leaf], bvh.count[leaf], strict=True)])
    assert (lo[prim] >= bvh.lo[owner]).all() and (hi[prim] <= bvh.hi[owner]).all()
    # the root is the union of everything, exactly
    assert np.array_equal(bvh.lo[0], lo.min(axis=0)) and np.array_equal(bvh.hi[0], hi.max(axis=0))


coord = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)
size = st.one_of(st.just(0.0), st.floats(0, 1e3, allow_nan=False, allow_infinity=False))


@st.composite
def boxes(draw):
    n = draw(st.integers(0, 60))
    centres = np.array(draw(st.lists(st.tuples(coord, coord, coord), min_size=n, max_size=n)), float).reshape(n, 3)
    sizes = np.array(draw(st.lists(st.tuples(size, size, size), min_size=n, max_size=n)), float).reshape(n, 3)
    if n and draw(st.booleans()):                   # many coincident boxes
        centres[: n // 2] = centres[0]
        sizes[: n // 2] = sizes[0]
    return centres - sizes, centres + sizes


@settings(max_examples=60, deadline=None)
@given(boxes(), st.sampled_from(BVH_METHODS), st.integers(1, 6), st.integers(2, 16))
def test_invariants_hold_on_random_boxes(box, method, leaf_size, bins):
    lo, hi = box
    check_invariants(build_bvh(lo, hi, method=method, leaf_size=leaf_size, bins=bins), lo, hi, leaf_size)


@settings(max_examples=40, deadline=None)
@given(boxes(), st.sampled_from(BVH_METHODS), st.integers(1, 6), st.integers(0, 2**32 - 1))
def test_a_refit_bounds_the_moved_boxes(box, method, leaf_size, seed):
    """A refit (an animation's frame) keeps the tree and bounds the primitives where they
    moved: every invariant of a build holds for the moved boxes; refitting the boxes the
    tree was built from gives the build's boxes exactly."""
    lo, hi = box
    bvh = build_bvh(lo, hi, method=method, leaf_size=leaf_size)
    same = refit_bvh(bvh, lo, hi)
    assert np.array_equal(same.lo, bvh.lo) and np.array_equal(same.hi, bvh.hi)
    rng = np.random.default_rng(seed)
    move = rng.normal(scale=10.0, size=lo.shape) * (rng.random((len(lo), 1)) < 0.7)     # some stay put
    grow = rng.random(lo.shape)
    moved = refit_bvh(bvh, lo + move - grow, hi + move + grow)
    assert moved.first is bvh.first and moved.prims is bvh.prims
    check_invariants(moved, lo + move - grow, hi + move + grow, leaf_size)


def test_a_refit_of_other_primitives_is_refused():
    bvh = build_bvh(np.zeros((3, 3)), np.ones((3, 3)))
    with pytest.raises(BVHError, match="3"):
        refit_bvh(bvh, np.zeros((4, 3)), np.ones((4, 3)))


@pytest.mark.parametrize("method", BVH_METHODS)
def test_empty_and_single(method):
    empty = build_bvh(np.zeros((0, 3)), np.zeros((0, 3)), method=method)
    assert empty.nodes == 0 and empty.depth() == 0
    one = build_bvh([[1.0, 2, 3]], [[1.0, 2, 3]], method=method)           # a zero-size box
    assert one.nodes == 1 and one.count[0] == 1 and one.prims.tolist() == [0] and one.depth() == 1
    check_invariants(one, np.array([[1.0, 2, 3]]), np.array([[1.0, 2, 3]]), 4)


@pytest.mark.parametrize("method", BVH_METHODS)
def test_coincident_boxes_still_split_to_leaf_size(method):
    lo = np.zeros((1000, 3))
    bvh = build_bvh(lo, lo + 1, method=method, leaf_size=2)
    check_invariants(bvh, lo, lo + 1, 2)
    assert bvh.depth() <= 12                      # halved, not peeled one by one


@pytest.mark.parametrize("method", BVH_METHODS)
def test_larger_random_sets_and_leaf_sizes(method):
    rng = np.random.default_rng(1)
    c = rng.normal(size=(5000, 3)) * [10, 1, 10] + 1e4        # far from the origin
    s = rng.random((5000, 3)) ** 4
    for leaf_size in (1, 4, 8):
        bvh = build_bvh(c - s, c + s, method=method, leaf_size=leaf_size)
        check_invariants(bvh, c - s, c + s, leaf_size)
        assert bvh.depth() < 40


def test_sah_beats_a_median_split_on_clustered_boxes():
    """Two far clusters: both methods separate them at the root."""
    rng = np.random.default_rng(2)
    c = np.concatenate([rng.random((300, 3)), rng.random((100, 3)) + 50])
    for method in BVH_METHODS:
        bvh = build_bvh(c, c + 0.01, method=method)
        root_kids = {tuple(np.round(bvh.hi[k]).astype(int)) for k in (1, 2)}
        assert (1, 1, 1) in root_kids, method


def test_morton_codes_order_along_a_line():
    t = np.linspace(0, 1, 50)
    codes = morton_codes(np.stack([t, t, t], axis=1))
    assert (np.diff(codes.astype(np.float64)) > 0).all()


def test_float32_boxes_hold_the_float64_boxes():
    rng = np.random.default_rng(3)
    c = rng.random((500, 3)) * 1e4 + 1e4
    bvh = build_bvh(c - 1e-3, c + 1e-3)
    origin = np.array([1.2e4, 0.0, 1.5e4])
    lo32, hi32 = float32_boxes(bvh, origin)
    assert lo32.dtype == np.float32
    assert (lo32.astype(np.float64) <= bvh.lo - origin).all() and (hi32.astype(np.float64) >= bvh.hi - origin).all()


@pytest.mark.parametrize("lo, hi, match", [
    (np.zeros((2, 2)), np.zeros((2, 2)), "shape"),
    (np.zeros((2, 3)), np.zeros((3, 3)), "shape"),
    (np.full((1, 3), np.nan), np.zeros((1, 3)), "finite"),
    (np.ones((1, 3)), np.zeros((1, 3)), "inverted"),
])
def test_bad_boxes_are_refused(lo, hi, match):
    with pytest.raises(BVHError, match=match):
        build_bvh(lo, hi)


def test_bad_knobs_are_refused():
    box = np.zeros((3, 3))
    for kw, match in (({"method": "kd"}, "method"), ({"leaf_size": 0}, "leaf_size"), ({"bins": 1}, "bins")):
        with pytest.raises(BVHError, match=match):
            build_bvh(box, box, **kw)
