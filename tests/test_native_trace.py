"""The compiled CPU traversal (plantgen.geometry.rays.native_trace) against the numpy oracle
(plantgen.geometry.rays.bvh's float64 traversal with the reference's pair test): the same
primitive and the same t, closest and any hit, one level and two, on random rays and on
the hard cases (grazing rays, rays along an axis, far from the origin, zero-size rows and
copies, empty plants); the thread count changes nothing; without numba one line says so."""

from __future__ import annotations

import os
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from _geometry_helpers import chain_skeleton, random_tree
from hypothesis import given, settings
from hypothesis import strategies as st

from plantgen.geometry.rays import native_trace
from plantgen.geometry.rays.scan import scan_target, scene_target
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.pipeline import grow_file, model_leaves

pytestmark = pytest.mark.skipif(not native_trace.available(), reason="numba does not run here")


@pytest.fixture(scope="module")
def bush():
    grown = grow_file("abop_bush")
    return grown.skeleton, model_leaves(grown)


def random_rays(lo, hi, m, rng, scale=1.5):
    centre, size = (lo + hi) / 2, (hi - lo).max()
    origins = centre + (rng.random((m, 3)) - 0.5) * size * scale
    targets = centre + (rng.random((m, 3)) - 0.5) * size * 0.8
    return origins, targets - origins


def both(target, O, D, **kw):
    """(oracle, compiled) first hits, closest and any."""
    out = []
    for any_hit in (False, True):
        a = target.first_hits(O, D, native=False, any_hit=any_hit, **kw)
        b = target.first_hits(O, D, native=True, any_hit=any_hit, **kw)
        out.append((a, b))
    return out


def assert_same(target, O, D, exact=True, **kw):
    (closest, compiled), (any_np, any_nb) = both(target, O, D, **kw)
    if exact:
        np.testing.assert_array_equal(compiled[1], closest[1])
        np.testing.assert_array_equal(compiled[0], closest[0])
    else:                          # the copies' frames rounded apart: nearly every ray, t to 1e-9
        same = compiled[1] == closest[1]
        assert same.mean() >= 0.9999 or (~same).sum() <= 1
        fin = same & np.isfinite(closest[0])
        np.testing.assert_allclose(compiled[0][fin], closest[0][fin], rtol=1e-9)
    np.testing.assert_array_equal(np.isfinite(any_nb[0]), np.isfinite(closest[0]))        # any hit: hit or not
    got = np.flatnonzero(any_nb[1] >= 0)                                                  # ... and a real one
    np.testing.assert_array_equal(target.hit_distance(any_nb[1][got], O[got], D[got], **_tmin(kw)), any_nb[0][got])
    return closest


def _tmin(kw):
    return {"t_min": kw["t_min"]} if "t_min" in kw else {}


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 2 ** 31 - 1), st.sampled_from([(0.0, 0.0, 0.0), (1e4, 0.0, -1e4), (-3e3, 50.0, 7e3)]),
       st.floats(0.0, 0.5), st.booleans())
def test_plant_with_leaves_equals_the_oracle(bush, seed, shift, t_min, finite_max):
    skeleton, leaves = bush
    target = _moved(skeleton, leaves, shift)
    rng = np.random.default_rng(seed)
    O, D = random_rays(*target.box(), 300, rng)
    t_max = rng.random(300) * 3 if finite_max else np.inf
    t, p = assert_same(target, O, D, t_min=t_min, t_max=t_max)
    assert np.isfinite(t).mean() > 0.05


def _moved(skeleton, leaves, shift):
    from dataclasses import replace
    if not any(shift):
        return scan_target(skeleton, leaves)
    move = np.eye(4)
    move[:3, 3] = shift
    return scan_target(skeleton.transformed(move), replace(leaves, vertices=np.asarray(leaves.vertices) + shift))


def test_scanner_frame_origin_equals_the_oracle(bush):
    """The scan's rows relative to the scanner (``origin``), far from the world's origin."""
    skeleton, leaves = bush
    target = _moved(skeleton, leaves, (1e4, 0.0, -1e4))
    lo, hi = target.box()
    scanner = np.array([lo[0] - 2.0, lo[1] + 0.5, lo[2] - 1.0])
    D = lo + (hi - lo) * np.random.default_rng(4).random((500, 3)) - scanner
    O = np.broadcast_to(scanner, D.shape)
    assert_same(target, O, D, origin=scanner)


def test_grazing_and_axis_rays():
    skel = chain_skeleton(bends_deg=(0.0, 0.0, 30.0), lengths=1.0, radii=0.1)
    target = scan_target(skel)
    x = 0.1 * np.array([1.0, 1 - 1e-12, 1 + 1e-12, 1 - 1e-6, 1 + 1e-15, 1 - 1e-15])
    k = len(x)
    along = np.stack([x, np.full(k, -1.0), np.zeros(k)], axis=1)                   # parallel to the axis
    across = np.stack([x, np.full(k, 0.5), np.full(k, -1.0)], axis=1)              # tangent to the side
    axis = np.array([[0.0, -1.0, 0.0], [0.0, 5.0, 0.0], [1e-9, -1.0, 0.0], [0.0, 0.5, 0.0]])      # on the axis
    O = np.concatenate([along, across, axis])
    D = np.concatenate([np.tile([0.0, 1.0, 0.0], (k, 1)), np.tile([0.0, 0.0, 1.0], (k, 1)),
                        [[0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 1.0, 0.0], [1e-12, 1.0, 0.0]]])
    t, _ = assert_same(target, O, D)
    assert np.isfinite(t[[3, k + 3]]).all() and np.isfinite(t[2 * k:]).all()


def test_packets_mixing_axis_parallel_and_oblique_rays(bush):
    """A packet's boxes are tested branch-free where every ray's 1/d is finite, ray by ray
    (numpy's NaN rule) where one is not: packets of both kinds, and mixed, answer as the
    oracle and as each ray traced alone; a scanner's fan (one origin) likewise."""
    skeleton, leaves = bush
    target = scan_target(skeleton, leaves)
    rng = np.random.default_rng(12)
    O, D = random_rays(*target.box(), 3 * native_trace.RAY_BLOCK, rng)
    n = native_trace.RAY_BLOCK
    mixed = slice(n, 2 * n)                                 # the second packet: every 3rd ray along an axis plane
    D[mixed][::3, rng.integers(0, 3)] = 0.0
    D[2 * n + 5, :2] = -0.0                                 # one ray of the third packet along the z axis
    t, _ = assert_same(target, O, D)
    alone = [target.first_hits(O[i:i + 1], D[i:i + 1]) for i in range(0, len(O), 7)]
    np.testing.assert_array_equal(np.concatenate([a[0] for a in alone]), t[::7])
    scanner = target.box()[0] - 0.3
    fan = target.box()[0] + rng.random((2 * n, 3)) * (target.box()[1] - target.box()[0]) - scanner
    fan[::5, 0] = 0.0
    assert_same(target, np.broadcast_to(scanner, fan.shape).copy(), fan)


def test_cones_closing_to_a_point_zero_length_and_huge_rows():
    skel = chain_skeleton(bends_deg=(20.0, 0.0, 10.0), lengths=(1.0, 0.0, 1e3, 1e-3),
                          radii=(0.2, 0.2, 0.2, 20.0, 0.0))
    target = scan_target(skel)
    rng = np.random.default_rng(8)
    assert_same(target, *random_rays(*target.box(), 400, rng, scale=1.2))
    small = target.box()[0] + [0.0, 0.5, 0.0]
    assert_same(target, *random_rays(small - 2, small + 2, 300, rng))


def test_rays_from_inside_rows_always_leave(bush):
    skeleton, leaves = bush
    target = scan_target(skeleton, leaves)
    f = target.frusta
    rng = np.random.default_rng(7)
    rows = rng.choice(target.rows, 60, replace=False)
    O = f.base[rows] + 0.5 * f.length[rows, None] * f.axis[rows]
    t, _ = assert_same(target, O, rng.normal(size=(60, 3)))
    assert np.isfinite(t).all()


# ------------------------------------------------------------------------------ two levels
def similarity(rng, n, spread, scale=None):
    ang = rng.random(n) * 2 * np.pi
    m = np.zeros((n, 4, 4))
    s = 0.5 + rng.random(n) if scale is None else np.full(n, scale)
    c, si = np.cos(ang), np.sin(ang)
    m[:, 0, 0], m[:, 0, 2], m[:, 1, 1], m[:, 2, 0], m[:, 2, 2] = c * s, si * s, s, -si * s, c * s
    m[:, :3, 3] = (rng.random((n, 3)) - 0.5) * spread * [1, 0.05, 1]
    m[:, 3, 3] = 1
    return m


def plant(skeleton, matrices, first):
    return SimpleNamespace(skeleton=skeleton, polygons=None, matrices=matrices,
                           instances=np.arange(first, first + len(matrices)))


def test_two_levels_equal_the_oracle_with_tiny_and_empty_copies():
    rng = np.random.default_rng(11)
    tiny = similarity(rng, 3, 4.0, scale=1e-9)
    plants = [plant(random_tree(40, seed=1), np.concatenate([similarity(rng, 12, 8.0), tiny]), 0),
              plant(random_tree(25, seed=2), similarity(rng, 9, 8.0), 15),
              plant(Skeleton.empty(), similarity(rng, 2, 8.0), 24)]
    target = scene_target(plants)
    lo, hi = target.box()
    O, D = random_rays(lo, hi, 600, rng)
    t, _ = assert_same(target, O, D, exact=False)
    assert np.isfinite(t).mean() > 0.2
    O2 = tiny[:, :3, 3] + [0.0, -1.0, 0.0]                   # straight at the tiny copies
    assert_same(target, O2, np.tile([0.0, 1.0, 0.0], (3, 1)), exact=False)


def test_thread_count_changes_nothing(bush):
    import numba

    skeleton, leaves = bush
    target = scan_target(skeleton, leaves)
    O, D = random_rays(*target.box(), 5000, np.random.default_rng(1))
    was = numba.get_num_threads()
    try:
        runs = []
        for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(threads)
            runs.append([target.first_hits(O, D, any_hit=a) for a in (False, True)])
    finally:
        numba.set_num_threads(was)
    for (t1, p1), (t2, p2) in zip(*runs, strict=True):
        np.testing.assert_array_equal(t1, t2)
        np.testing.assert_array_equal(p1, p2)


def test_hit_distance_is_the_oracles(bush):
    skeleton, leaves = bush
    target = scan_target(skeleton, leaves)
    rng = np.random.default_rng(4)
    O, D = random_rays(*target.box(), 2000, rng)
    prim = rng.integers(-1, len(target), 2000)
    from plantgen.geometry.rays.scan import target_hits
    want = np.full(2000, np.inf)
    ok = prim >= 0
    want[ok] = target_hits(target, t_min=0.1)(prim[ok], O[ok], D[ok])
    np.testing.assert_array_equal(target.hit_distance(prim, O, D, t_min=0.1), want)


def test_without_numba_one_line_and_the_numpy_walk():
    code = ("import sys; sys.modules['numba'] = None\n"
            "import numpy as np\n"
            "from _geometry_helpers import random_tree\n"
            "from plantgen.geometry.rays.scan import scan_target\n"
            "t = scan_target(random_tree(10, seed=1))\n"
            "print(np.isfinite(t.first_hits(np.array([[0.0, -5, 0]]), np.array([[0.0, 1, 0]]))[0]).sum())\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([os.path.dirname(__file__), *sys.path])}
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stderr.strip().count("\n") == 0 and "numba does not import" in run.stderr
    assert "Traceback" not in run.stderr


def test_trace_device_choice():
    import plantgen
    from plantgen.tracer import TraceError

    skel = random_tree(20, seed=3)
    target = scan_target(skel)
    O, D = random_rays(*target.box(), 200, np.random.default_rng(5))
    cpu = plantgen.trace(skel, O, D, device="cpu")
    default = plantgen.trace(skel, O, D)
    np.testing.assert_array_equal(cpu.t, default.t)
    np.testing.assert_array_equal(cpu.primitive, default.primitive)
    want, _ = target.first_hits(O, D, native=False)
    np.testing.assert_array_equal(cpu.t, want)
    with pytest.raises(TraceError, match="device must be one of"):
        plantgen.trace(skel, O, D, device="tpu")
    with pytest.raises(TraceError, match="use device='gl'"):
        plantgen.trace(skel, O, D, device="cpu", precision="float32")


def test_python_threads_may_trace_at_once(bush):
    """Two Python threads (a Dask worker's) tracing together: the same answers, no abort."""
    from concurrent.futures import ThreadPoolExecutor

    skeleton, leaves = bush
    target = scan_target(skeleton, leaves)
    O, D = random_rays(*target.box(), 3000, np.random.default_rng(9))
    want = target.first_hits(O, D)
    with ThreadPoolExecutor(4) as pool:
        got = list(pool.map(lambda _: target.first_hits(O, D), range(8)))
    for t, p in got:
        np.testing.assert_array_equal(t, want[0])
        np.testing.assert_array_equal(p, want[1])
