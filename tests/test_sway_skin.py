"""The per-frame skinning of swaying skeletons (plantgen.geometry.skeletons.sway_skin) equals the
general path, skin_skeleton(pose(...)), at every frame: same rows, same planes, frames
and u offsets to float64 round-off; sharp frames are handed back to the general path."""

import numpy as np
import pytest

from plantgen.animation import AnimatedScene
from plantgen.geometry.skeletons.frusta import ROW_FIELDS
from plantgen.geometry.skeletons.motion import pose, sway_rig
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.geometry.skeletons.sway_skin import PathSum, SwaySkin
from plantgen.geometry.stage import Sway
from plantgen.pipeline import grow_file

TIMES = (0.0, 0.37, 1.1, 2.9, 1e3)


def _general_spread(skeleton, rig, t, rng):
    """How far the general path's planes move when the posed end points move by 1e-15:
    near-zero bends make the joint plane's construction ill-conditioned (its crossing
    points run away and fade), so the planes can only agree to this."""
    posed = pose(skeleton, rig, t)
    end = posed.end + rng.normal(size=posed.end.shape) * 1e-15
    start = posed.start.copy()
    has_p = posed.parent >= 0
    start[has_p] = end[posed.parent[has_p]]
    moved = Skeleton(start, end, posed.r_start, posed.r_end, posed.parent, posed.continues,
                     posed.material, posed.material_names)
    a, b = skin_skeleton(posed), skin_skeleton(moved)
    return max(np.abs(a.plane_lo - b.plane_lo).max(), np.abs(a.plane_hi - b.plane_hi).max())


def assert_same_frusta(fast, general, plane_tol=1e-12):
    assert len(fast) == len(general)
    assert fast.material_names == general.material_names
    for name in ROW_FIELDS:
        got, want = getattr(fast, name), getattr(general, name)
        if name in ("material", "segment"):
            np.testing.assert_array_equal(got, want, err_msg=name)
        elif name == "u_offset":      # in turns, mod 1: 0.999... and 0.0 are the same u
            np.testing.assert_allclose((got - want + 0.5) % 1.0 - 0.5, 0.0, atol=1e-11, err_msg=name)
            assert np.all((got >= 0) & (got < 1))
        elif name.startswith("plane"):
            np.testing.assert_allclose(got, want, rtol=0, atol=plane_tol, err_msg=name)
        else:
            np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12, err_msg=name)
    np.testing.assert_array_equal(fast.parent_row, general.parent_row)
    np.testing.assert_array_equal(fast.open_lo, general.open_lo)
    np.testing.assert_array_equal(fast.open_hi, general.open_hi)
    # the contract: a continuing row shares its parent's plane bit for bit
    c = np.flatnonzero(fast.parent_row >= 0)
    np.testing.assert_array_equal(fast.plane_lo[c], fast.plane_hi[fast.parent_row[c]])


@pytest.fixture(scope="module")
def cacti():
    anim = AnimatedScene.from_scene(grow_file("dancing_cacti").scene)
    return anim._moving_skeleton, anim._rig


@pytest.mark.parametrize("t", TIMES)
def test_dancing_cacti_frames_equal_the_general_path(cacti, t):
    skeleton, rig = cacti
    plan = SwaySkin.plan(skeleton, rig)
    posed = plan.pose(t)
    general_pose = pose(skeleton, rig, t)
    np.testing.assert_allclose(posed.start.T, general_pose.start, rtol=0, atol=1e-12)
    np.testing.assert_allclose(posed.end.T, general_pose.end, rtol=0, atol=1e-12)
    fast = plan.skin(posed)
    assert fast is not None
    spread = _general_spread(skeleton, rig, t, np.random.default_rng(1))
    assert_same_frusta(fast, skin_skeleton(general_pose), plane_tol=max(1e-12, 50 * spread))


def small_scene():
    """Two hand-made plants. The first: straight joints (zero bends), a 40° bend, a
    radius step into a cone closing to a point at a tip, side branches (one starting at
    radius 0), a bend at a side branch's joint. The second: a 150° bend (a knuckle every
    frame) followed by a segment of zero length."""
    up, tilt = np.array([0.0, 1.0, 0.0]), np.array([np.sin(0.7), np.cos(0.7), 0.0])
    p0, p1, p2 = np.zeros(3), up, 2 * up
    p3 = p2 + tilt
    p4 = p3 + 0.5 * tilt
    side_end = p2 + np.array([0.6, 0.4, 0.2])
    start = [p0, p1, p2, p3, p2, side_end, side_end]
    end = [p1, p2, p3, p4, side_end, side_end + np.array([-0.3, 0.2, 0.1]),
           side_end + np.array([0.1, 0.4, -0.5])]
    a = Skeleton(np.array(start), np.array(end), [0.3, 0.28, 0.26, 0.2, 0.1, 0.0, 0.05],
                 [0.28, 0.26, 0.24, 0.0, 0.05, 0.03, 0.04], [-1, 0, 1, 2, 1, 4, 4],
                 [False, True, True, True, False, False, True], np.zeros(7, int), ("bark",))
    bend = np.array([3.0 + np.sin(2.6), 1 + np.cos(2.6), 0])
    b = Skeleton(np.array([[3.0, 0, 0], [3.0, 1, 0], bend]), np.array([[3.0, 1, 0], bend, bend]),
                 [0.2, 0.2, 0.15], [0.2, 0.15, 0.15], [-1, 0, 1], [False, True, True], [0, 0, 0],
                 ("bark",))
    return a, b


@pytest.mark.parametrize("t", TIMES)
def test_small_scene_equals_the_general_path(t):
    a, b = small_scene()
    rig = sway_rig(a, np.zeros(len(a), int), [Sway(amplitude=35, frequency=0.7, phase=0.4)])
    plan = SwaySkin.plan(a, rig)
    fast = plan.skin(plan.pose(t))
    general = skin_skeleton(pose(a, rig, t))
    assert general.report.sharp_joints == 0 and fast is not None
    spread = _general_spread(a, rig, t, np.random.default_rng(2))
    assert_same_frusta(fast, general, plane_tol=max(1e-12, 50 * spread))


def test_sharp_frames_fall_back_to_knuckles_in_the_animation():
    a, b = small_scene()
    skeleton = Skeleton.concatenate([a, b])
    inst = np.repeat([0, 1], [len(a), len(b)])
    motions = [Sway(amplitude=35, frequency=0.7, phase=0.4), Sway(amplitude=10, frequency=0.3, phase=2.0)]
    anim = AnimatedScene(skeleton, inst, motions)
    rig = sway_rig(skeleton, inst, motions)
    for t in TIMES:
        plan = anim._plan
        assert plan.skin(plan.pose(t)) is None          # the 150° joint is a knuckle
        calls = anim.skin_calls
        got = anim.frusta_at(t)
        assert anim.skin_calls == calls + 1
        general = skin_skeleton(pose(skeleton, rig, t))
        assert general.report.sharp_joints >= 1 and general.report.fan_rows > 0
        assert_same_frusta(got, general, plane_tol=1e-9)


def test_plan_needs_one_instance_per_tree_and_the_default_skin():
    a, _ = small_scene()
    inst = np.array([0, 0, 1, 1, 0, 1, 1])               # a tree mixing two instances
    rig = sway_rig(a, inst, [Sway(10, 0.5, 0.0), Sway(10, 0.5, 1.0)])
    assert SwaySkin.plan(a, rig) is None
    anim = AnimatedScene(a, inst, [Sway(10, 0.5, 0.0), Sway(10, 0.5, 1.0)])
    assert_same_frusta(anim.frusta_at(0.4), skin_skeleton(pose(a, rig, 0.4)))
    bound = AnimatedScene(a, np.zeros(len(a), int), [Sway(10, 0.5, 0.0)],
                          skin=lambda s: skin_skeleton(s, twist=0.25))
    assert bound._plan is None


def test_path_sums_and_products_follow_the_root_paths():
    parent = np.array([-1, 0, 1, 1, -1, 4, 2, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16])
    values = np.arange(1.0, len(parent) + 1)
    want = np.zeros(len(parent))
    for i in range(len(parent)):
        j = i
        while j >= 0:
            want[i] += values[j]
            j = parent[j]
    paths = PathSum(parent)
    np.testing.assert_array_equal(paths(values), want)
    turns = np.exp(1j * values)
    np.testing.assert_allclose(paths.product(turns), np.exp(1j * want), rtol=1e-13)


def test_per_frame_frusta_are_what_the_checked_constructor_builds(cacti):
    """Frusta.from_rows skips the checks: the fast path's rows must already have the
    contract's dtypes, shapes and layout, and open ends as the constructor derives them;
    the records packed into a reused buffer equal freshly packed ones."""
    from plantgen.geometry.skeletons.frusta import Frusta
    from plantgen.gl.records import pack_records

    skeleton, rig = cacti
    plan = SwaySkin.plan(skeleton, rig)
    fast = plan.skin(plan.pose(0.37))
    checked = Frusta(**{f: getattr(fast, f) for f in ROW_FIELDS}, material_names=fast.material_names,
                     parent_row=fast.parent_row)
    for name in (*ROW_FIELDS, "parent_row", "open_lo", "open_hi"):
        got, want = getattr(fast, name), getattr(checked, name)
        assert got.dtype == want.dtype and got.shape == want.shape and got.flags.c_contiguous, name
        np.testing.assert_array_equal(got, want, err_msg=name)
    assert fast.material_names == checked.material_names and fast.report is None
    origin = np.array([1.5, 2.0, -3.0])
    buffer = np.full((len(fast), 24), np.nan, dtype=np.float32)
    assert pack_records(fast, origin, out=buffer) is buffer
    np.testing.assert_array_equal(buffer, pack_records(checked, origin))
    with pytest.raises(ValueError):
        pack_records(fast, origin, out=np.empty((len(fast), 24)))
