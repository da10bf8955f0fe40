"""Animated scenes on the CPU: pose what moves, re-skin only that, keep the rest.

Per frame (§4: "the splitting planes between segments have to be recomputed in each time
step"): the moving instances' skeleton is posed at time t
(:func:`plantgen.geometry.skeletons.motion.pose`) and skinned again (:func:`skin_skeleton`,
vectorised over every segment: cutting planes and texture offsets); the static instances
are skinned once. A scene without motion is skinned once, whatever the frame count.
Leaves (the grammar's polygons) move rigidly with the segment each hangs from: turned by
that segment's total turn about its instance's axis, about the segment's start
(:meth:`AnimatedScene.leaves_at`), as the pose turns the segment itself.

The GPU side is a record sink (:class:`plantgen.gl.records.RecordStream`): it packs
and uploads the static rows once and the moving rows every frame. A sink that poses on
the GPU (:class:`plantgen.gl.pose.PoseStream`, ``poses_on_gpu``) is handed the plan of
the moving rows instead (:class:`~plantgen.geometry.skeletons.sway_skin.SwaySkin`, rest data
uploaded once) and writes their records itself from t: the CPU's work per frame is a
few bytes and a dispatch. A frame where a joint may turn sharp (knuckle fans: more rows,
:meth:`SwaySkin.may_be_sharp`) is skinned on the CPU and written as before. The
vertex-skinned mesh (GS) takes each segment's posed start and turn from the same
program (:meth:`AnimatedScene.pose_segments`) and its rest mesh from
:meth:`AnimatedScene.rest_frusta` / :meth:`AnimatedScene.skinned`. This module imports no
GL: :meth:`AnimatedScene.upload` is handed the sink.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from .geometry.meshes.mesh import TessellatedMesh
from .geometry.meshes.polygons import Polygons
from .geometry.meshes.skinned_mesh import SkinnedMesh, bind_vertices
from .geometry.skeletons.frusta import Frusta, frusta_bounds
from .geometry.skeletons.motion import pose, sway_rig, turn_at, turn_coefficients
from .geometry.skeletons.skeleton import Skeleton
from .geometry.skeletons.skin import lead_forks, skin_skeleton
from .geometry.skeletons.sway_skin import SwaySkin
from .geometry.vec import rotate

__all__ = ["AnimatedScene", "FrameUpdate", "RecordSink", "PoseSink"]

#: Wave phases at which :meth:`AnimatedScene.motion_box` skins every tree.
BOX_SAMPLES = 16


class RecordSink(Protocol):
    """Where an animation's records go each frame (plantgen.gl.records.RecordStream)."""

    buffer: object

    def write(self, static: Frusta, moving: Frusta | None, origin) -> tuple[float, float, int]:
        """Returns (pack_ms, upload_ms, bytes uploaded)."""


class PoseSink(RecordSink, Protocol):
    """A sink that poses the moving rows itself (plantgen.gl.pose.PoseStream); its
    ``poses_on_gpu`` is True."""

    poses_on_gpu: bool

    def pose(self, plan: SwaySkin, static: Frusta, t: float, origin, box) -> tuple[float, int, object]:
        """Static records, then ``plan``'s rows posed at ``t``; returns (CPU ms, bytes
        uploaded, the rows to draw: their count, material names and ``box``)."""

    def pose_segments(self, plan: SwaySkin, t: float, origin):
        """The GPU buffer of every segment's posed start (relative to ``origin``) and turn."""


@dataclass
class FrameUpdate:
    """What one frame's update did. ``pose_ms``, ``skin_ms``, ``pack_ms``, ``upload_ms``
    are CPU milliseconds; ``rows_reskinned`` frusta rows skinned this frame (0 for a
    static scene after the first); ``upload_bytes`` bytes written to the GPU this frame.
    ``on_gpu``: the GPU posed and skinned the moving rows, ``pose_ms`` is the CPU time of
    that (on a software rasteriser such as llvmpipe, which runs the compute program inside
    the dispatch call, the program's time too)."""

    t: float
    rows_reskinned: int
    upload_bytes: int
    pose_ms: float = 0.0
    skin_ms: float = 0.0
    pack_ms: float = 0.0
    upload_ms: float = 0.0
    on_gpu: bool = False       # posed and skinned by the GPU (pose_ms: the CPU's calls)

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
        # the forks' leaders chosen once, at rest (skin_skeleton would choose them again in
        # every pose, and a near tie could change hands while the plant sways)
        self.skeleton = lead_forks(self.skeleton)
        self.segment_instance = np.asarray(self.segment_instance, dtype=np.int64)
        moving_instance = np.array([m is not None and m.moves for m in self.motions] or [False])
        moving = (moving_instance[self.segment_instance] if len(self.skeleton)
                  else np.zeros(0, dtype=bool))
        self.moving_segments = np.flatnonzero(moving)
        self.static_segments = np.flatnonzero(~moving)
        self._moving_skeleton = self.skeleton.subset(self.moving_segments)
        self._rig = sway_rig(self._moving_skeleton, self.segment_instance[self.moving_segments],
                             self.motions)
        static = len(self.static_segments) == len(self.skeleton)     # all: the skeleton as it is
        self._static = self._skin(self.skeleton if static else self.skeleton.subset(self.static_segments))
        # the per-frame path of the default skinning: topology worked out once
        self._plan = (SwaySkin.plan(self._moving_skeleton, self._rig)
                      if self.animated and self.skin is skin_skeleton else None)
        self._leaf_rig = self._rig_leaves() if self.animated and self.leaves is not None else None
        self._starts = (None, None)      # (t, (m, 3) posed starts of the moving segments)
        self._box = self._rest = None    # motion_box, rest_frusta: worked out on first use

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

    @property
    def plan(self) -> SwaySkin | None:
        """The moving rows' :class:`SwaySkin` plan (what the GPU poses), or None: a still
        scene, a bound skinning function, a tree mixing instances."""
        return self._plan

    def _skin(self, skeleton: Skeleton) -> Frusta:
        self.skin_calls += 1
        return self.skin(skeleton)

    def frusta_at(self, t: float) -> Frusta:
        """Every row at time ``t`` (seconds): static rows first, then the moving ones."""
        return self._frame(t)[0]

    def posed(self, t: float) -> tuple[Frusta, FrameUpdate]:
        """Every row at time ``t``, posed and skinned on the CPU (what a renderer that needs
        the rows themselves takes, the ray tracer's BVH refit), and the frame's
        :class:`FrameUpdate` (kept in :attr:`updates`)."""
        frusta, _, update = self._frame(t)
        self.updates.append(update)
        return frusta, update

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
        with it); still ones as grown. Uses the pose of the last frame drawn at ``t`` (a
        frame posed on the GPU: the plan's pose, no skin)."""
        rig = self._leaf_rig
        if rig is None:
            return self.leaves
        if self._starts[0] != float(t):
            self._starts = (float(t), self._plan.pose(t).start.T if self._plan is not None
                            else pose(self._moving_skeleton, self._rig, t).start)
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

    def motion_box(self) -> np.ndarray:
        """(2, 3) world box that holds every row in every pose (worked out once): the
        static rows, and each tree skinned at :data:`BOX_SAMPLES` wave phases, grown by
        the most an end point moves between two of them (:meth:`SwaySkin.drift`). The
        renderers' depth range and light window for frames posed on the GPU."""
        if self._box is None:
            boxes = [frusta_bounds(self._static)] if len(self._static) else []
            plan = self._plan
            if plan is not None:
                trees, grow = len(plan.roots), plan.drift(np.pi / BOX_SAMPLES)
                for x in np.arange(BOX_SAMPLES) * (2.0 * np.pi / BOX_SAMPLES):
                    posed = plan.pose_at_phase(np.full(trees, x))
                    frusta = plan.skin(posed)
                    if frusta is None:
                        frusta = self.skin(plan.skeleton(posed, self._moving_skeleton))
                    box = frusta_bounds(frusta)
                    boxes.append(np.stack([box[0] - grow, box[1] + grow]))
            elif self.animated:
                boxes.append(self.bounds(np.linspace(0.0, 10.0, BOX_SAMPLES)))
            self._box = (np.stack([np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)])
                         if boxes else np.zeros((2, 3)))
        return self._box

    def gpu_frame(self, sink, t: float) -> bool:
        """Whether the frame at ``t`` is posed by ``sink`` on the GPU: it can
        (``poses_on_gpu``), there is a plan, and no joint may be sharp at ``t``."""
        return (self._plan is not None and getattr(sink, "poses_on_gpu", False)
                and not self._plan.may_be_sharp(t))

    def upload(self, sink: RecordSink, t: float, origin):
        """Pose and skin what moves at ``t`` and hand the rows to ``sink``, which uploads
        the static rows once and the moving rows every frame, relative to ``origin`` (3,)
        (the fixed camera eye). A sink that poses on the GPU (:class:`PoseSink`) poses
        and skins the moving rows itself, unless a joint may be sharp at ``t``.

        Returns (rows, buffer, update): all rows (a Frusta, or the sink's rows posed on
        the GPU: their count, material names and :meth:`motion_box`), the sink's GPU
        buffer holding every row's record, and the :class:`FrameUpdate`.
        """
        if self.gpu_frame(sink, t):
            ms, written, rows = sink.pose(self._plan, self._static, float(t), origin, self.motion_box())
            update = FrameUpdate(float(t), self._plan.n, written, pose_ms=ms, on_gpu=True)
            self.updates.append(update)
            return rows, sink.buffer, update
        frusta, moving, update = self._frame(t)
        update.pack_ms, update.upload_ms, update.upload_bytes = sink.write(self._static, moving, origin)
        self.updates.append(update)
        return frusta, sink.buffer, update


    # ------------------------------------------------------------------ the vertex-skinned mesh
    def rest_frusta(self) -> tuple[Frusta, np.ndarray]:
        """The rows at rest (every turn 0: the scene as grown), static rows first, and (rows,)
        the moving segment each row belongs to (-1: a static row): what the vertex-skinned
        mesh is tessellated from, once (cached)."""
        if self._rest is None:
            moving = self.skin(self._moving_skeleton) if self.animated else Frusta.empty()
            frusta = Frusta.concatenate([self._static, moving]) if len(moving) else self._static
            segment = np.concatenate([np.full(len(self._static), -1, np.int64), np.asarray(moving.segment)])
            self._rest = (frusta, segment)
        return self._rest

    def skinned(self, mesh: TessellatedMesh) -> SkinnedMesh:
        """``mesh`` (tessellated from :meth:`rest_frusta`) with each vertex bound to the
        segments that move it (:func:`plantgen.geometry.meshes.skinned_mesh.bind_vertices`)."""
        return bind_vertices(mesh, self.rest_frusta()[1], self._moving_skeleton.start)

    def pose_segments(self, sink: PoseSink, t: float, origin):
        """Every moving segment's posed start (relative to ``origin``) and turn at ``t``,
        on the GPU (``sink.pose_segments``); returns (the GPU buffer, :class:`FrameUpdate`).
        Needs :attr:`plan`."""
        t0 = time.perf_counter()
        buffer = sink.pose_segments(self._plan, float(t), origin)
        update = FrameUpdate(float(t), 0, 0, pose_ms=(time.perf_counter() - t0) * 1e3, on_gpu=True)
        self.updates.append(update)
        return buffer, update
