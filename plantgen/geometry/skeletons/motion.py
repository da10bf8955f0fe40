"""Skeleton motion: deterministic sway in time t, vectorised over every segment.

A swaying plant bends at every joint about one horizontal axis per instance. The joint
angle is a wave running up the plant::

    theta_i(t) = A / D · sin(2π f t + φ - 2π · depth_i / D)

with amplitude A (degrees, the total bend at the tip when the whole plant is in phase),
frequency f (Hz), phase φ per instance, depth_i the joint's distance in segments from the
root and D the deepest chain of the instance. Because every joint of an instance turns
about the same axis, a segment's world rotation is a rotation by the sum of the angles on
its path from the root, so the pose is a cumulative sum over the tree, done level by
level (one numpy step per tree depth, not per segment).

Segment lengths and radii are kept; every child still starts where its parent ends.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..stage import Sway
from ..vec import ancestor_count, rotate
from .skeleton import Skeleton

__all__ = ["SwayRig", "sway_rig", "joint_angles", "pose", "turn_coefficients", "turn_at"]


@dataclass(frozen=True, eq=False)
class SwayRig:
    """What the pose of a skeleton needs, computed once for a static topology.

    depth : (n,) int, segments between each segment and its root
    levels : list of (k,) int arrays, the segments at each depth
    axis : (n, 3) float, the unit bending axis of each segment's instance
    amplitude, frequency, phase : (n,) float, per segment (from its instance); radians, Hz
    max_depth : (n,) float, deepest chain of each segment's instance (>= 1)
    moving : (n,) bool, segments whose instance has motion
    """

    depth: np.ndarray
    levels: list
    axis: np.ndarray
    amplitude: np.ndarray
    frequency: np.ndarray
    phase: np.ndarray
    max_depth: np.ndarray
    moving: np.ndarray


def sway_rig(skeleton: Skeleton, segment_instance: np.ndarray,
             sways: Sequence[Sway | None]) -> SwayRig:
    """Prepare the sway of ``skeleton``.

    Parameters
    ----------
    skeleton : Skeleton in world coordinates (n segments)
    segment_instance : (n,) int, the instance of each segment
    sways : per instance, its :class:`~plantgen.geometry.stage.Sway`, or None (still)
    """
    n = len(skeleton)
    inst = np.asarray(segment_instance, dtype=np.int64)
    depth = ancestor_count(skeleton.parent)
    k = len(sways)
    amp = np.zeros(k)
    freq = np.zeros(k)
    phase = np.zeros(k)
    for i, sway in enumerate(sways):
        if sway is not None:
            amp[i] = np.radians(sway.amplitude)
            freq[i] = sway.frequency
            phase[i] = sway.phase
    # the bending axis is horizontal, turned by the phase so instances sway in different planes
    axes = np.stack([np.cos(phase), np.zeros(k), np.sin(phase)], axis=1)
    max_depth = np.ones(k)
    if n:
        np.maximum.at(max_depth, inst, depth + 1.0)
    levels = [np.flatnonzero(depth == d) for d in range(int(depth.max()) + 1)] if n else []
    return SwayRig(depth, levels, axes[inst], amp[inst], freq[inst], phase[inst], max_depth[inst],
                   amp[inst] != 0)


def joint_angles(rig: SwayRig, t, rates: bool = False):
    """The angle (radians) each joint turns at time ``t`` (seconds): ``theta_i(t)`` of the
    module docstring, the turn of segment i about its instance's axis relative to its
    parent (about its start). ``t`` a number gives (n,); an array of k times (k, n).
    ``rates``: also dtheta_i/dt (radians per second), the same shape: ``(angles, rates)``."""
    t = np.asarray(t, dtype=np.float64)[..., None]
    wave = 2 * np.pi * rig.frequency * t + rig.phase - 2 * np.pi * rig.depth / rig.max_depth
    size = rig.amplitude / rig.max_depth
    angles = size * np.sin(wave)
    if not rates:
        return angles
    return angles, size * 2 * np.pi * rig.frequency * np.cos(wave)


def pose(skeleton: Skeleton, rig: SwayRig, t: float) -> Skeleton:
    """The skeleton at time ``t`` (seconds). Deterministic in t; t = any value works."""
    theta = joint_angles(rig, t)
    total = np.zeros(len(skeleton))
    start = skeleton.start.copy()
    end = skeleton.end.copy()
    d = skeleton.end - skeleton.start
    parent = skeleton.parent
    for level in rig.levels:
        p = parent[level]
        has_p = p >= 0
        total[level] = np.where(has_p, total[np.where(has_p, p, 0)], 0.0) + theta[level]
        s = np.where(has_p[:, None], end[np.where(has_p, p, 0)], start[level])
        start[level] = s
        end[level] = s + rotate(d[level], rig.axis[level], total[level])
    return Skeleton(start, end, skeleton.r_start, skeleton.r_end, skeleton.parent, skeleton.continues,
                    skeleton.material, skeleton.material_names)


def turn_coefficients(skeleton: Skeleton, rig: SwayRig) -> tuple[np.ndarray, np.ndarray]:
    """(c, s), each (n,): the total turn of each segment (the sum of the joint angles on
    its path from the root, by which :func:`pose` rotates it about its instance's axis) at
    time t is ``c·sin X + s·cos X`` with ``X = 2π f t + φ`` (its instance's frequency and
    phase): each joint angle is ``A/D·sin(X - β)``, ``β = 2π·depth/D``, and
    ``sin(X - β) = sin X cos β - cos X sin β`` sums term by term along the path."""
    beta = 2 * np.pi * rig.depth / rig.max_depth
    own_c = rig.amplitude / rig.max_depth * np.cos(beta)
    own_s = -rig.amplitude / rig.max_depth * np.sin(beta)
    c, s = np.zeros(len(skeleton)), np.zeros(len(skeleton))
    parent = skeleton.parent
    for level in rig.levels:
        p = parent[level]
        has_p = p >= 0
        up = np.where(has_p, p, 0)
        c[level] = np.where(has_p, c[up], 0.0) + own_c[level]
        s[level] = np.where(has_p, s[up], 0.0) + own_s[level]
    return c, s


def turn_at(rig: SwayRig, coefficients, t: float, rows=None) -> np.ndarray:
    """The total turn (radians) at time ``t`` of the segments ``rows`` (default: all), from
    :func:`turn_coefficients`."""
    c, s = coefficients
    rows = slice(None) if rows is None else rows
    x = 2 * np.pi * rig.frequency[rows] * t + rig.phase[rows]
    return c[rows] * np.sin(x) + s[rows] * np.cos(x)
