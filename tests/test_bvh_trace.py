"""The float64 BVH traversal (plantgen.geometry.rays.bvh): closest and any hit equal brute
force over every primitive, on plants with leaves and on the hard cases (far from the
origin, grazing rays, origins inside boxes, zero-length and very large rows), one level
and two (one plant placed 100,000 times)."""

from __future__ import annotations

import numpy as np
import pytest
from _geometry_helpers import chain_skeleton, random_tree
from hypothesis import given, settings
from hypothesis import strategies as st

from plantgen.geometry.rays.bvh import (
    BVH_METHODS,
    BVHError,
    box_columns,
    brute_force,
    build_bvh,
    build_scene_bvh,
    slab,
    trace_bvh,
    trace_scene,
)
from plantgen.geometry.rays.instances import PlacedPlants
from plantgen.geometry.rays.scan import scan_target, target_hits
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.pipeline import grow_file, model_leaves


def box_hits(lo, hi):
    """A primitive test where primitive i is the solid box i: t of entry (or of exit for
    an origin inside), so that random boxes make a hard, dense scene."""
    def hits(prim, O, D):
        near, far = slab(lo[prim], hi[prim], O, 1.0 / np.where(D == 0, 1e-300, D))
        t = np.where(near > 0, near, far)
        return np.where((near <= far) & (t > 0), t, np.inf)
    return hits


def random_rays(lo, hi, m, rng, scale=1.5):
    centre, size = (lo + hi) / 2, (hi - lo).max()
    origins = centre + (rng.random((m, 3)) - 0.5) * size * scale
    targets = centre + (rng.random((m, 3)) - 0.5) * size * 0.8
    return origins, targets - origins


def assert_same(bvh, n, O, D, hits, boxes=None, **kw):
    t, p = trace_bvh(bvh, O, D, hits, **kw)
    tb, pb = brute_force(n, O, D, hits, **kw)
    np.testing.assert_array_equal(t, tb)
    np.testing.assert_array_equal(p, pb)
    if boxes is not None:                     # the primitive-box cull changes nothing
        tc, pc = trace_bvh(bvh, O, D, hits, boxes=boxes, **kw)
        np.testing.assert_array_equal(tc, tb)
        np.testing.assert_array_equal(pc, pb)
    a_t, a_p = trace_bvh(bvh, O, D, hits, any_hit=True, **kw)
    np.testing.assert_array_equal(np.isfinite(a_t), np.isfinite(tb))          # any hit: hit or not
    got = np.flatnonzero(np.isfinite(a_t))
    np.testing.assert_array_equal(hits(a_p[got], O[got], D[got]), a_t[got])     # ... a real hit
    return t, p


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 300), st.sampled_from(BVH_METHODS), st.integers(1, 8), st.integers(0, 2 ** 31 - 1),
       st.floats(0.0, 2.0), st.booleans())
def test_closest_and_any_hit_equal_brute_force_on_random_boxes(n, method, leaf_size, seed, t_min, finite_max):
    rng = np.random.default_rng(seed)
    c = rng.normal(size=(n, 3)) * 5
    s = rng.random((n, 3)) ** 3 * np.where(rng.random((n, 1)) < 0.1, 0.0, 1.0)      # some zero-size boxes
    lo, hi = c - s, c + s
    bvh = build_bvh(lo, hi, method=method, leaf_size=leaf_size, bins=8)
    O, D = random_rays(lo.min(axis=0), hi.max(axis=0), 64, rng)
    t_max = rng.random(64) * 20 if finite_max else np.inf
    assert_same(bvh, n, O, D, box_hits(lo, hi), box_columns(lo, hi), t_min=t_min, t_max=t_max)


def test_coincident_boxes_tie_to_the_smallest_primitive():
    lo = np.zeros((50, 3))
    bvh = build_bvh(lo, lo + 1, leaf_size=3)
    O = np.array([[-1.0, 0.5, 0.5]] * 3)
    D = np.array([[1.0, 0, 0], [1.0, 0.1, 0], [1.0, 0, -0.1]])
    t, p = trace_bvh(bvh, O, D, box_hits(lo, lo + 1))
    np.testing.assert_array_equal(p, [0, 0, 0])
    np.testing.assert_allclose(t, 1.0)


@pytest.fixture(scope="module")
def bush():
    grown = grow_file("abop_bush")
    skin = skin_skeleton(grown.skeleton)
    return grown.skeleton, model_leaves(grown), skin


def target_case(skeleton, leaves=None, shift=(0.0, 0.0, 0.0)):
    """A scan target, its BVH and its primitive test; assert_same gets its boxes through
    ``target.box_columns`` where a test passes them."""
    move = np.eye(4)
    move[:3, 3] = shift
    skel = skeleton if not any(shift) else skeleton.transformed(move)
    target = scan_target(skel, _shifted(leaves, shift))
    return target, build_bvh(target.lo, target.hi), target_hits(target)


def _shifted(leaves, shift):
    if leaves is None or not any(shift):
        return leaves
    from dataclasses import replace
    return replace(leaves, vertices=np.asarray(leaves.vertices) + np.asarray(shift))


@pytest.mark.parametrize("shift", [(0.0, 0.0, 0.0), (1e4, 0.0, -1e4)])
def test_plant_with_leaves_equals_brute_force(bush, shift):
    skeleton, leaves, _ = bush
    target, bvh, hits = target_case(skeleton, leaves, shift)
    assert target.rows and len(target.triangles)
    rng = np.random.default_rng(5)
    O, D = random_rays(*target.box(), 40, rng)
    t, p = assert_same(bvh, len(target), O, D, hits, target.box_columns)
    assert np.isfinite(t).mean() > 0.2 and (p >= target.rows).any() and ((p >= 0) & (p < target.rows)).any()


def test_far_plant_ranges_match_the_plant_at_the_origin(bush):
    """The same rays, model and all moved 1e4 units: the same primitives, ranges to 1e-9."""
    skeleton, leaves, _ = bush
    near, bvh0, hits0 = target_case(skeleton, leaves)
    shift = np.array([1e4, 0.0, -1e4])
    far, bvh1, hits1 = target_case(skeleton, leaves, shift)
    O, D = random_rays(*near.box(), 300, np.random.default_rng(6))
    t0, p0 = trace_bvh(bvh0, O, D, hits0)
    t1, p1 = trace_bvh(bvh1, O + shift, D, hits1)
    assert (p0 == p1).mean() > 0.99
    same = (p0 == p1) & np.isfinite(t0)
    np.testing.assert_allclose(t1[same], t0[same], rtol=1e-9)


def test_origins_inside_boxes(bush):
    skeleton, leaves, skin = bush
    target, bvh, hits = target_case(skeleton, leaves)
    rng = np.random.default_rng(7)
    rows = rng.choice(target.rows, 40, replace=False)
    O = skin.base[rows] + 0.5 * skin.length[rows, None] * skin.axis[rows]          # on each row's axis
    D = rng.normal(size=(40, 3))
    t, p = assert_same(bvh, len(target), O, D, hits, target.box_columns)
    assert np.isfinite(t).all()                         # from inside a closed row, every ray leaves it


def test_grazing_rays_along_and_across_cylinders():
    skel = chain_skeleton(bends_deg=(0.0, 0.0, 30.0), lengths=1.0, radii=0.1)
    target, bvh, hits = target_case(skel)
    x = 0.1 * np.array([1.0, 1 - 1e-12, 1 + 1e-12, 1 - 1e-6])
    along = np.stack([x, np.full(4, -1.0), np.zeros(4)], axis=1)                  # parallel to the axis
    across = np.stack([x, np.full(4, 0.5), np.full(4, -1.0)], axis=1)              # tangent to the side
    O = np.concatenate([along, across])
    D = np.concatenate([np.tile([0.0, 1.0, 0.0], (4, 1)), np.tile([0.0, 0.0, 1.0], (4, 1))])
    t, _ = assert_same(bvh, len(target), O, D, hits, target.box_columns)
    assert np.isfinite(t[[3, 7]]).all()                 # just inside the rim: hit


def test_zero_length_and_very_large_rows():
    skel = chain_skeleton(bends_deg=(20.0, 0.0, 10.0), lengths=(1.0, 0.0, 1e3, 1e-3), radii=(0.2, 0.2, 0.2, 20.0, 0.1))
    target, bvh, hits = target_case(skel)
    O, D = random_rays(*target.box(), 80, np.random.default_rng(8), scale=1.2)
    assert_same(bvh, len(target), O, D, hits, target.box_columns)
    small = target.box()[0] + [0.0, 0.5, 0.0]
    O2, D2 = random_rays(small - 2, small + 2, 60, np.random.default_rng(9))      # near the small rows
    assert_same(bvh, len(target), O2, D2, hits)


def test_t_min_and_t_max_clip_the_hits(bush):
    skeleton, leaves, _ = bush
    target, bvh, _ = target_case(skeleton, leaves)
    hits = target_hits(target, t_min=0.3)
    O, D = random_rays(*target.box(), 40, np.random.default_rng(10))
    t, _ = assert_same(bvh, len(target), O, D, hits, t_min=0.3, t_max=0.9)
    assert ((t > 0.3) & (t < 0.9) | np.isinf(t)).all()


def test_bad_rays_are_refused():
    bvh = build_bvh(np.zeros((1, 3)), np.ones((1, 3)))
    with pytest.raises(BVHError, match="origins"):
        trace_bvh(bvh, np.zeros((2, 3)), np.ones((3, 3)), box_hits(np.zeros((1, 3)), np.ones((1, 3))))


# ------------------------------------------------------------------------------ two levels
def similarity(rng, n, spread):
    ang = rng.random(n) * 2 * np.pi
    tilt = rng.random(n) * 0.3
    scale = 0.5 + rng.random(n)
    m = np.zeros((n, 4, 4))
    cy, sy, ct, st_ = np.cos(ang), np.sin(ang), np.cos(tilt), np.sin(tilt)
    rot_y = np.zeros((n, 3, 3))
    rot_y[:, 0, 0], rot_y[:, 0, 2], rot_y[:, 1, 1], rot_y[:, 2, 0], rot_y[:, 2, 2] = cy, sy, 1, -sy, cy
    rot_x = np.zeros((n, 3, 3))
    rot_x[:, 0, 0], rot_x[:, 1, 1], rot_x[:, 1, 2], rot_x[:, 2, 1], rot_x[:, 2, 2] = 1, ct, -st_, st_, ct
    m[:, :3, :3] = scale[:, None, None] * rot_y @ rot_x
    m[:, :3, 3] = (rng.random((n, 3)) - 0.5) * spread * [1, 0.05, 1]
    m[:, 3, 3] = 1
    return m


def scene_case(plants):
    """PlacedPlants of (skeleton, matrices) pairs, their scene BVH and per-plant tests."""
    placed = PlacedPlants.build([(f"p{i}", skin_skeleton(s), s.parent, m) for i, (s, m) in enumerate(plants)])
    scene = build_scene_bvh(placed)
    hits = [target_hits(scan_target(s, frusta=p.frusta)) for (s, _), p in zip(plants, placed.plants, strict=True)]
    return placed, scene, hits


def brute_scene(placed, O, D, hits_of, copies=None):
    """Closest hits by testing every row of every copy (``copies``: only those), each ray
    moved into the copy's frame as the traversal moves it."""
    best_t, best_c, best_p = np.full(len(O), np.inf), np.full(len(O), -1), np.full(len(O), -1)
    c0 = 0
    for k, plant in enumerate(placed.plants):
        inv = np.linalg.inv(plant.matrices)
        for j in range(len(plant.matrices)):
            c = c0 + j
            if copies is not None and c not in copies:
                continue
            o = O @ inv[j, :3, :3].T + inv[j, :3, 3]
            d = D @ inv[j, :3, :3].T
            t, p = brute_force(len(plant.frusta), o, d, hits_of[k])
            better = t < best_t
            best_t[better], best_c[better], best_p[better] = t[better], c, p[better]
        c0 += len(plant.matrices)
    return best_t, best_c, best_p


def test_two_levels_equal_brute_force_over_every_copy():
    rng = np.random.default_rng(11)
    plants = [(random_tree(40, seed=1), similarity(rng, 12, 8.0)), (random_tree(25, seed=2), similarity(rng, 9, 8.0))]
    placed, scene, hits = scene_case(plants)
    assert len(scene.blas) == 2 and scene.copies == 21
    lo, hi = placed.box
    O, D = random_rays(lo, hi, 150, rng)
    t, c, p = trace_scene(scene, O, D, hits)
    tb, cb, pb = brute_scene(placed, O, D, hits)
    assert np.isfinite(tb).mean() > 0.2
    np.testing.assert_array_equal(c, cb)
    np.testing.assert_array_equal(p, pb)
    np.testing.assert_allclose(t, tb, rtol=1e-12)
    ta, ca, _ = trace_scene(scene, O, D, hits, any_hit=True)
    np.testing.assert_array_equal(np.isfinite(ta), np.isfinite(tb))


def test_two_levels_match_the_merged_plants():
    """Rays moved into each copy's frame find what the copies placed in world units give."""
    rng = np.random.default_rng(12)
    plants = [(random_tree(30, seed=3), similarity(rng, 15, 6.0))]
    placed, scene, hits = scene_case(plants)
    merged = placed.merged()
    target = scan_target(_merged_skeleton(placed), frusta=merged)
    bvh = build_bvh(target.lo, target.hi)
    O, D = random_rays(*placed.box, 200, rng)
    t, c, p = trace_scene(scene, O, D, hits)
    tm, pm = trace_bvh(bvh, O, D, target_hits(target))
    rows = len(placed.plants[0].frusta)
    assert (pm == np.where(c >= 0, c * rows + p, -1)).mean() > 0.99
    same = (pm == c * rows + p) & np.isfinite(t)
    np.testing.assert_allclose(t[same], tm[same], rtol=1e-9)


def _merged_skeleton(placed):
    from plantgen.geometry.skeletons.skeleton import Skeleton
    f = placed.merged()
    n = len(f)
    return Skeleton(f.base, f.base + f.axis * f.length[:, None], f.r1, f.r2, np.full(n, -1), np.zeros(n, bool),
                    np.zeros(n, int), ("bark",))


def test_one_plant_placed_100000_times():
    rng = np.random.default_rng(13)
    skel = random_tree(30, seed=4)
    placed, scene, hits = scene_case([(skel, similarity(rng, 100_000, 3000.0))])
    assert scene.copies == 100_000 and len(scene.blas) == 1
    assert scene.nbytes < len(placed.plants[0].frusta) * 1000 + 100_000 * 600        # the plant once
    lo, hi = placed.box
    O = lo + (hi - lo) * rng.random((60, 3))
    O[:, 1] = rng.uniform(0, 2, 60)
    D = rng.normal(size=(60, 3)) * [1, 0.1, 1]
    t, c, p = trace_scene(scene, O, D, hits)
    assert np.isfinite(t).sum() >= 10
    # brute force over the copies whose boxes each ray meets (every copy is far too many)
    cand = set()
    inv = 1.0 / D
    for i in range(len(O)):
        near, far = slab(scene.copy_lo, scene.copy_hi, np.broadcast_to(O[i], scene.copy_lo.shape),
                         np.broadcast_to(inv[i], scene.copy_lo.shape))
        cand |= set(np.flatnonzero((near <= far) & (far > 0)).tolist())
    tb, cb, pb = brute_scene(placed, O, D, hits, copies=cand)
    np.testing.assert_array_equal(c, cb)
    np.testing.assert_array_equal(p, pb)
    np.testing.assert_allclose(t, tb, rtol=1e-12)


def test_degenerate_copies_are_refused():
    m = np.eye(4)[None].repeat(2, axis=0)
    m[1, :3, :3] = 0
    skel = random_tree(5)
    placed = PlacedPlants.build([("p", skin_skeleton(skel), skel.parent, m)])
    with pytest.raises(BVHError, match="scales by 0"):
        build_scene_bvh(placed)


@pytest.mark.parametrize("size", [2, 16, 64])
def test_packets_of_rays_from_one_origin_find_the_same_hits(bush, size):
    """Fans of rays from three scanner positions (one inside the plant's box) walk the
    upper tree as cones: the hits are those of brute force."""
    skeleton, leaves, _ = bush
    target, bvh, hits = target_case(skeleton, leaves)
    lo, hi = target.box()
    rng = np.random.default_rng(14)
    origins = np.array([lo - (hi - lo), (lo + hi) / 2, [hi[0] * 2, lo[1], lo[2]]])
    O = np.repeat(origins, 70, axis=0)
    aim = lo + (hi - lo) * rng.random((3, 3))
    spread = rng.normal(size=(210, 3)) * 0.05 * (hi - lo).max()
    D = np.repeat(aim, 70, axis=0) + np.cumsum(spread, axis=0) * 0.1 - O          # neighbouring directions
    t, p = trace_bvh(bvh, O, D, hits, packets=size, boxes=target.box_columns)
    tb, pb = brute_force(len(target), O, D, hits)
    assert np.isfinite(tb).sum() > 20
    np.testing.assert_array_equal(t, tb)
    np.testing.assert_array_equal(p, pb)
