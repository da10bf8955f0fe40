"""Row-wise vector helpers and tree walks (plantgen.geometry.vec) against plain references."""

import numpy as np
import pytest
from _geometry_helpers import random_tree
from scipy.spatial.transform import Rotation

from plantgen.geometry.vec import (
    ancestor_count,
    any_perpendicular,
    by_rows,
    cross,
    dot,
    in_threads,
    norm,
    plane_through,
    reduce_to_root,
    rotate,
    tree_roots,
    unit,
)


@pytest.fixture
def vectors():
    rng = np.random.default_rng(0)
    return rng.normal(size=(200, 3)), rng.normal(size=(200, 3))


def test_dot_cross_norm_match_numpy(vectors):
    a, b = vectors
    np.testing.assert_allclose(dot(a, b), np.einsum("ij,ij->i", a, b), rtol=1e-14, atol=1e-14)
    np.testing.assert_array_equal(cross(a, b), np.cross(a, b))
    np.testing.assert_allclose(norm(a), np.linalg.norm(a, axis=1), rtol=1e-15)
    # broadcasting: one vector against many
    np.testing.assert_array_equal(dot(a, b[:1]), dot(a, np.repeat(b[:1], len(a), 0)))


def test_unit_vectors_and_their_fallback(vectors):
    a, _ = vectors
    np.testing.assert_allclose(norm(unit(a)), 1.0, rtol=1e-15)
    zero = np.zeros((2, 3))
    assert np.array_equal(unit(zero), zero)
    fallback = np.array([[0.0, 1.0, 0.0]])
    assert np.array_equal(unit(zero, fallback), np.repeat(fallback, 2, 0))


def test_unit_rows_far_below_one_keep_unit_length(vectors):
    """A row whose squares are subnormal (length under 1e-154) loses its norm's digits: it
    is rescaled first, so its unit row has unit length (a segment 1e-155 long along x gave
    -1.0000000000000067, which put a crown's hull a radius wide of its disc). Rows under
    tol.tiny still take the fallback, and every ordinary row is divided as before."""
    a, _ = vectors
    for scale in (1e-155, 1e-160, 3e-200, 1e-290):
        rows = unit(a * scale, np.zeros(3))
        np.testing.assert_allclose(norm(rows), 1.0, rtol=1e-15)
        np.testing.assert_allclose(rows, unit(a), rtol=1e-14, atol=1e-15)
    along_x = unit(np.array([[-1.2705465286743225e-155, 0.0, 0.0]]), np.zeros(3))
    assert along_x.tolist() == [[-1.0, 0.0, 0.0]]
    fallback = np.array([[0.0, 1.0, 0.0]])
    assert np.array_equal(unit(np.array([[1e-301, 0.0, 0.0]]), fallback), fallback)
    assert np.array_equal(unit(a), a / np.sqrt(dot(a, a))[:, None])


def test_any_perpendicular_is_a_unit_normal(vectors):
    a = unit(vectors[0])
    p = any_perpendicular(a)
    np.testing.assert_allclose(norm(p), 1.0, rtol=1e-15)
    assert np.abs(dot(p, a)).max() < 1e-15


def test_rotation_is_rodrigues(vectors):
    v, axis = vectors
    axis = unit(axis)
    angle = np.random.default_rng(1).uniform(-np.pi, np.pi, len(v))
    expected = Rotation.from_rotvec(axis * angle[:, None]).apply(v)
    np.testing.assert_allclose(rotate(v, axis, angle), expected, rtol=1e-12, atol=1e-12)


def test_planes_pass_through_their_points(vectors):
    n, p = unit(vectors[0]), vectors[1]
    plane = plane_through(n, p)
    np.testing.assert_allclose(dot(plane[:, :3], p) - plane[:, 3], 0.0, atol=1e-15)


def _walk(parent, i):
    path = [i]
    while parent[path[-1]] >= 0:
        path.append(parent[path[-1]])
    return path


def test_pointer_jumping_matches_a_walk_up_the_tree():
    parent = random_tree(300, seed=4).parent
    paths = [_walk(parent, i) for i in range(len(parent))]
    assert ancestor_count(parent).tolist() == [len(p) - 1 for p in paths]
    assert tree_roots(parent).tolist() == [p[-1] for p in paths]
    values = np.random.default_rng(2).normal(size=len(parent))
    kept = values.copy()
    summed = reduce_to_root(parent, values, np.add)
    np.testing.assert_allclose(summed, [values[p].sum() for p in paths], rtol=1e-12)
    assert np.array_equal(values, kept)                 # the caller's values untouched
    given = values.copy()                               # overwrite: combined in place, the same bytes
    assert reduce_to_root(parent, given, np.add, overwrite=True) is given and given.tobytes() == summed.tobytes()
    # an order-sensitive combine: own value first, then the ancestors'
    labels = np.array([f"{i}," for i in range(len(parent))], dtype=object)
    joined = reduce_to_root(parent, labels, lambda own, up: own + up)
    assert joined.tolist() == ["".join(f"{j}," for j in p) for p in paths]


def test_by_rows_gives_the_whole_call_bit_for_bit_a_block_at_a_time():
    """by_rows evaluates a row-wise function a block at a time into results allocated
    once: the same bytes as one call, for one result or several, ragged last block and
    fewer rows than a block included."""
    rng = np.random.default_rng(7)
    a, b = rng.normal(size=(1000, 3)), rng.normal(size=(1000, 3))
    calls = []

    def planes(x, y):
        calls.append(len(x))
        return unit(cross(x, y)), dot(x, y), (x[:, 0] > 0)
    whole = planes(a, b)
    calls.clear()
    blocked = by_rows(planes, a, b, block=64)
    assert sorted(calls, reverse=True) == [64] * 15 + [40]      # the blocks after the first on threads
    for w, got in zip(whole, blocked, strict=True):
        assert w.dtype == got.dtype and w.shape == got.shape and w.tobytes() == got.tobytes()
    single = by_rows(lambda x: norm(x), a, block=300)
    assert single.tobytes() == norm(a).tobytes()
    assert by_rows(lambda x: norm(x), a[:5], block=300).tobytes() == norm(a[:5]).tobytes()
    assert by_rows(lambda x: norm(x), a[:0]).shape == (0,)


def test_in_threads_keeps_the_order_the_first_failure_and_the_callers_errstate():
    """in_threads gives the items' results in their order on two threads as on one; the
    first item's exception in that order is raised (after every call ended); each call
    runs under the caller's np.errstate, so a division by zero raises in a worker too."""
    done = []

    def square(i):
        done.append(i)
        return i * i
    assert in_threads(square, range(50), workers=2) == [i * i for i in range(50)]
    assert in_threads(square, range(50), workers=1) == [i * i for i in range(50)]
    done.clear()

    def fail(i):
        done.append(i)
        if i in (3, 7):
            raise ValueError(f"item {i}")
        return i
    with pytest.raises(ValueError, match="item 3"):
        in_threads(fail, range(10), workers=2)
    assert sorted(done) == list(range(10))
    with np.errstate(divide="raise"), pytest.raises(FloatingPointError):
        in_threads(lambda x: np.ones(4) / x, [np.ones(4), np.zeros(4)], workers=2)
    with np.errstate(divide="ignore"):
        assert np.isinf(in_threads(lambda x: np.ones(4) / x, [np.ones(4), np.zeros(4)], workers=2)[1]).all()
