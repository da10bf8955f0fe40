"""Sway motion: rigid per segment, joints stay joined, periodic and deterministic in t."""

import numpy as np
import pytest

from plantgen.geometry.skeletons.motion import pose, sway_rig
from plantgen.geometry.stage import Sway
from plantgen.lsystem import derive, interpret, parse_grammar


def two_plants():
    g = parse_grammar({"axiom": "!(0.2) A", "iterations": 4, "turtle": {"angle": 30},
                       "rules": ["A -> F [+A] [-A] /(90) F A"]}, "t.yaml")
    one = interpret(derive(g), g.turtle, g.materials)
    from plantgen.geometry.skeletons.skeleton import Skeleton
    m = np.eye(4)
    m[0, 3] = 10
    skel = Skeleton.concatenate([one, one.transformed(m)])
    inst = np.repeat([0, 1], len(one))
    return skel, inst, len(one)


MOTIONS = [Sway(amplitude=20, frequency=0.5, phase=1.0), None]


def test_pose_keeps_lengths_radii_and_joints():
    skel, inst, n1 = two_plants()
    rig = sway_rig(skel, inst, MOTIONS)
    for t in (0.0, 0.3, 1.7, 1e4):
        p = pose(skel, rig, t)
        p.validate(tol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(p.end - p.start, axis=1),
                                   np.linalg.norm(skel.end - skel.start, axis=1), rtol=1e-12)
        np.testing.assert_array_equal(p.r_start, skel.r_start)
        # the static instance does not move; the swaying one does
        np.testing.assert_array_equal(p.end[n1:], skel.end[n1:])
    assert not np.allclose(pose(skel, rig, 0.3).end[:n1], skel.end[:n1])


def test_pose_is_periodic_and_deterministic():
    skel, inst, _ = two_plants()
    rig = sway_rig(skel, inst, MOTIONS)
    np.testing.assert_allclose(pose(skel, rig, 0.4).end, pose(skel, rig, 0.4 + 2.0).end, atol=1e-9)
    np.testing.assert_array_equal(pose(skel, rig, 0.4).end, pose(skel, rig, 0.4).end)


def test_bend_is_bounded_by_the_amplitude():
    skel, inst, n1 = two_plants()
    rig = sway_rig(skel, inst, MOTIONS)
    for t in np.linspace(0, 2, 9):
        p = pose(skel, rig, t)
        a = skel.end[:n1] - skel.start[:n1]
        b = p.end[:n1] - p.start[:n1]
        cos = np.sum(a * b, axis=1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
        assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() <= 20 + 1e-9


@pytest.mark.parametrize("t", [0.0, 0.25])
def test_zero_amplitude_is_identity(t):
    skel, inst, _ = two_plants()
    rig = sway_rig(skel, inst, [None, None])
    np.testing.assert_array_equal(pose(skel, rig, t).end, skel.end)
    assert not rig.moving.any()
