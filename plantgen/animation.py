"""Animated scenes on the CPU: pose what moves, re-skin only that, keep the rest.

Per frame (§4: "the splitting planes between segments have to be recomputed in each time
step"): the moving instances' skeleton is posed at time t
(:func:`plantgen.geometry.motion.pose`) and skinned again (:func:`skin_skeleton`,
vectorised over every segment: cutting planes and texture offsets); the static instances
are skinned once. A scene without motion is skinned once, whatever the frame count.
Leaves (the grammar's polygons) move rigidly with the segment each hangs from: turned by
that segment's total turn about its instance's axis, about the segment's start
(:meth:`AnimatedScene.leaves_at`), as the pose turns the segment itself.

The GPU side is a record sink (:class:`plantgen.gl.records.RecordStream`): it packs
and uploads the static rows once and the moving rows every frame. This module imports no
GL: :meth:`AnimatedScene.upload` is handed the sink.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from .geometry.frusta import Frusta, frusta_bounds
from .geometry.motion import pose, sway_rig, turn_at, turn_coefficients
from .geometry.polygons import Polygons
from .geometry.skeleton import Skeleton
from .geometry.skin import skin_skeleton
from .geometry.sway_skin import SwaySkin
from .geometry.vec import rotate

__all__ = ["AnimatedScene", "FrameUpdate", "RecordSink"]


class RecordSink(Protocol):
    """Where an animation's records go each frame (plantgen.gl.records.RecordStream)."""

    buffer: object

    def write(self, static: Frusta, moving: Frusta | None, origin) -> tuple[float, float, int]:
        """Returns (pack_ms, upload_ms, bytes uploaded)."""


@dataclass
class FrameUpdate:
    """What one frame's update did. ``pose_ms``, ``skin_ms``, ``pack_ms``, ``upload_ms``
    are CPU milliseconds; ``rows_reskinned`` frusta rows skinned this frame (0 for a
    static scene after the first); ``upload_bytes`` bytes written to the GPU this frame."""

    t: float
    rows_reskinned: int
    upload_bytes: int
    pose_ms: float = 0.0
    skin_ms: float = 0.0
    pack_ms: float = 0.0
    upload_ms: float = 0.0

    @property
    def total_ms(self) -> float:
        return self.pose_ms + self.skin_ms + self.pack_ms + self.upload_ms


@dataclass
class AnimatedScene:
    """A scene's skeleton split into the instances that move and those that do not.

    Parameters
    ----------
    skeleton : the scene's skeleton in world coordinates (n segments)
    segment_instance : (n,) int, the instance of each segment
    motions : per instance, None or its :class:`plantgen.geometry.stage.Sway`
    skin : the skinning function (``skin_skeleton`` or one with bound options)
    leaves : the scene's leaf polygons in world coordinates (``Polygons.segment``: the
        segment each hangs from), or None
    """

    skeleton: Skeleton
    segment_instance: np.ndarray
    motions: list
    skin: object = skin_skeleton
    skin_calls: int = 0
    updates: list = field(default_factory=list)
    leaves: Polygons | None = None

    def __post_init__(self):
        self.segment_instance = np.asarray(self.segment_instance, dtype=np.int64)
        moving_instance = np.array([m is not None and m.moves for m in self.motions] or [False])
        moving = (moving_instance[self.segment_instance] if len(self.skeleton)
                  else np.zeros(0, dtype=bool))
        self.moving_segments = np.flatnonzero(moving)
        self.static_segments = np.flatnonzero(~moving)
        self._moving_skeleton = self.skeleton.subset(self.moving_segments)
        self._rig = sway_rig(self._moving_skeleton, self.segment_instance[self.moving_segments],
                             self.motions)
        self._static = self._skin(self.skeleton.subset(self.static_segments))
        # the per-frame path of the default skinning: topology worked out once
        self._plan = (SwaySkin.plan(self._moving_skeleton, self._rig)
                      if self.animated and self.skin is skin_skeleton else None)
        self._leaf_rig = self._rig_leaves() if self.animated and self.leaves is not None else None
        self._starts = (None, None)      # (t, (m, 3) posed starts of the moving segments)

    def _rig_leaves(self):
        """What posing the leaves needs, once: per polygon and per vertex the moving segment
        it hangs from (-1: still), and the turns' coefficients (None: no leaf moves)."""
        leaves = self.leaves
        moving_index = np.full(len(self.skeleton) + 1, -1, dtype=np.int64)
        moving_index[self.moving_segments] = np.arange(len(self.moving_segments))
        anchor = moving_index[np.where(leaves.segment >= 0, leaves.segment, len(self.skeleton))]
        if not np.any(anchor >= 0):
            return None
        return {"polygon": anchor, "vertex": anchor[leaves.vertex_polygon],
                "coefficients": turn_coefficients(self._moving_skeleton, self._rig)}

    @classmethod
    def from_scene(cls, scene, skin=skin_skeleton) -> AnimatedScene:
        """Every instance of ``scene`` (plantgen.scene.Scene), moving as its motion says."""
        leaves = scene.polygons()
        return cls(scene.skeleton(), scene.segment_instance(), [i.motion for i in scene.instances],
                   skin, leaves=leaves if len(leaves) else None)

    @classmethod
    def still(cls, skeleton: Skeleton, skin=skin_skeleton, leaves: Polygons | None = None) -> AnimatedScene:
        """A skeleton that does not move: skinned once (its ``leaves`` stay as they are)."""
        return cls(skeleton, np.zeros(len(skeleton), dtype=np.int64), [None], skin, leaves=leaves)

    @property
    def animated(self) -> bool:
        return len(self.moving_segments) > 0

    def _skin(self, skeleton: Skeleton) -> Frusta:
        self.skin_calls += 1
        return self.skin(skeleton)

    def frusta_at(self, t: float) -> Frusta:
        """Every row at time ``t`` (seconds): static rows first, then the moving ones."""
        return self._frame(t)[0]

    def _frame(self, t: float):
        t0 = time.perf_counter()
        if self._plan is not None:
            posed = self._plan.pose(t)
            t1 = time.perf_counter()
            moving = self._plan.skin(posed)
            if moving is None:          # a sharp joint this frame: knuckle fans
                moving = self._skin(self._plan.skeleton(posed, self._moving_skeleton))
            else:
                self.skin_calls += 1
        else:
            posed = pose(self._moving_skeleton, self._rig, t) if self.animated else None
            t1 = time.perf_counter()
            moving = self._skin(posed) if self.animated else None
        t2 = time.perf_counter()
        if posed is not None:
            self._starts = (float(t), posed.start.T if self._plan is not None else posed.start)
        frusta = self._static if moving is None else Frusta.concatenate([self._static, moving])
        update = FrameUpdate(float(t), len(moving) if moving is not None else 0, 0,
                             (t1 - t0) * 1e3, (t2 - t1) * 1e3)
        return frusta, moving, update

    def leaves_at(self, t: float) -> Polygons | None:
        """The leaves at time ``t``: each moving one turned with the segment it hangs from
        (its vertices about the segment's start, which moves to the posed start; its normal
        with it); still ones as grown. Uses the pose of the last frame drawn at ``t``."""
        rig = self._leaf_rig
        if rig is None:
            return self.leaves
        if self._starts[0] != float(t):
            self._frame(t)
        posed_start = self._starts[1]
        rest_start = self._moving_skeleton.start
        leaves, vertex, polygon = self.leaves, rig["vertex"], rig["polygon"]
        turn = turn_at(self._rig, rig["coefficients"], float(t))      # per moving segment, once
        axis = self._rig.axis
        moves, turning = vertex >= 0, polygon >= 0
        seg, pseg = vertex[moves], polygon[turning]
        vertices = leaves.vertices.copy()
        vertices[moves] = posed_start[seg] + rotate(leaves.vertices[moves] - rest_start[seg], axis[seg], turn[seg])
        normal = leaves.normal.copy()
        normal[turning] = rotate(leaves.normal[turning], axis[pseg], turn[pseg])
        return replace(leaves, vertices=vertices, normal=normal)

    def bounds(self, times) -> np.ndarray:
        """(2, 3) world box around every row at each of ``times``: one light window for
        all frames. Costs one pose and skin per time."""
        boxes = [frusta_bounds(self.frusta_at(t)) for t in times]
        return np.stack([np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)])

    def upload(self, sink: RecordSink, t: float, origin):
        """Pose and skin what moves at ``t`` and hand the rows to ``sink``, which uploads
        the static rows once and the moving rows every frame, relative to ``origin`` (3,)
        (the fixed camera eye).

        Returns (frusta, buffer, update): all rows (for bounds), the sink's GPU buffer
        holding every row's record, and the :class:`FrameUpdate`.
        """
        frusta, moving, update = self._frame(t)
        update.pack_ms, update.upload_ms, update.upload_bytes = sink.write(self._static, moving, origin)
        self.updates.append(update)
        return frusta, sink.buffer, update

