"""An animation's moving rows posed and skinned on the GPU (paper §4: "could be moved to
the vertex shader"): one compute program (``shaders/pose.glsl``) turns a
:class:`~plantgen.geometry.skeletons.sway_skin.SwaySkin` plan's rest data, uploaded once, into
the ray caster's 96-byte records at time t, straight into the record buffer the frame
draws; per frame the CPU writes the wave's phase per frequency (4 bytes each) and
dispatches. The same program without records writes each segment's posed start and
turn for the vertex-skinned mesh (GS, GS+R; ``shaders/raster.glsl``).

Precision: positions are relative to the eye, as :func:`plantgen.gl.records.pack_records`
makes them: each tree's root start is formed relative to the eye in float64 and rounded
once, each end's fixed part is uploaded relative to its root start, and the turned parts
the shader adds are plant-sized; plane offsets are relative to each row's base, formed
from lengths and angles only. So a record's position differs from the CPU's by the
rounding of |base - eye| plus a few float32 units of the plant's size per level of its
root path (tests/test_gpu_pose.py states and checks the bound).

A frame where a joint may turn sharp (:meth:`SwaySkin.may_be_sharp`: knuckle fans, more
rows) is skinned on the CPU instead (:meth:`plantgen.animation.AnimatedScene.upload`);
the program still counts the joints it finds sharp (:meth:`GpuPose.take_sharp_count`).
"""

from __future__ import annotations

import time

import numpy as np

from ..geometry.skeletons.sway_skin import BEND_LIMIT_COS, SwaySkin
from ..geometry.vec import ancestor_count, cross
from ..tolerances import tol
from .records import RecordStream, StreamedRows, record_tags
from .shaders import build_compute, set_uniforms

__all__ = ["GpuPose", "PoseStream", "POSE_MODES", "REST_BYTES", "SCRATCH_BYTES", "POSE_BYTES", "tree_groups"]

#: How a frame runs: ``"groups"``: work groups of :data:`GROUP_SIZE` invocations, each
#: taking whole trees (about :data:`ROWS_PER_GROUP` rows) through every step, level by
#: level down the trees and chains, with barriers between: one dispatch a frame;
#: ``"doubling"``: the same, but the ends by pointer doubling (ceil(log2(depth)) rounds of
#: every row) instead of level by level; ``"walks"``: one dispatch a phase, every row an
#: invocation walking its root path and its chain. The bench (``python -m
#: plantgen.benchmarks.effects``) measures all three.
POSE_MODES = ("groups", "doubling", "walks")
GROUP_SIZE = 64
ROWS_PER_GROUP = 4096

#: GPU bytes per moving row: rest data (uploaded once), scratch, the pose buffer (GS).
REST_BYTES = 96
SCRATCH_BYTES = 176
POSE_BYTES = 32

_SIDE, _JOINT, _LINKED = 1, 2, 4


def tree_groups(plan: SwaySkin, rows_per_group: int) -> list[np.ndarray]:
    """The rows of each work group: whole trees, in order, a group closed once it holds
    ``rows_per_group`` rows (a larger tree is a group of its own)."""
    counts = np.bincount(plan.tree_of, minlength=len(plan.roots))
    groups, current, size = [], [], 0
    for tree, count in enumerate(counts):
        if current and size + count > rows_per_group:
            groups.append(current)
            current, size = [], 0
        current.append(tree)
        size += count
    if current:
        groups.append(current)
    return [np.flatnonzero(np.isin(plan.tree_of, trees)) for trees in groups]


def _schedule(plan: SwaySkin, groups: list[np.ndarray]) -> np.ndarray:
    """(int32) ``pose.glsl``'s ``schedule`` for ``groups`` (each a sorted array of rows):
    where each group's block starts, then the blocks (see the shader)."""
    tree_depth, chain_depth = ancestor_count(plan.parent), ancestor_count(plan.parent_row)
    levels = (int(tree_depth.max()) + 1, int(chain_depth.max()) + 1)
    blocks, at = [], len(groups)
    for rows in groups:
        head = at + sum(levels) + 2
        parts, starts = [], []
        for depth, count in zip((tree_depth, chain_depth), levels, strict=True):
            order = rows[np.argsort(depth[rows], kind="stable")]
            starts.append(head + np.searchsorted(depth[order], np.arange(count + 1)))
            parts.append(order)
            head += len(order)
        block = np.concatenate([*starts, *parts])
        blocks.append(block)
        at += len(block)
    offsets = len(groups) + np.cumsum([0] + [len(b) for b in blocks[:-1]])
    return np.concatenate([offsets, *blocks]).astype(np.int32)


def _rest_data(plan: SwaySkin) -> np.ndarray:
    """(n, 24) the plan's rest data as ``pose.glsl``'s ``Rest`` (links as int32 bits)."""
    n = plan.n
    links = np.empty((n, 4), np.int32)
    links[:, 0] = plan.parent
    links[:, 1] = plan.parent_row
    links[:, 2] = -1
    links[plan.par, 2] = plan.child
    flags = np.zeros(n, np.int32)
    flags[plan.side] |= _SIDE
    flags[plan.child] |= _JOINT
    flags[plan.link_child] |= _LINKED
    links[:, 3] = plan.tree_of * 16 + flags
    rest = np.zeros((n, 24), np.float32)
    rest.view(np.int32)[:, 0:4] = links
    rest[:, 4:7] = plan.along.T
    rest[:, 7] = plan.inv_length
    rest[:, 8], rest[:, 9], rest[:, 10], rest[:, 11] = plan.z.real, plan.z.imag, plan.ca, plan.sa
    rest[:, 12:15] = (plan.fixed - plan.root_start.take(plan.tree_of, axis=1)).T
    rest[:, 15] = plan.length
    rest[:, 16], rest[:, 17], rest[:, 18] = plan.r_start, plan.r_end, plan.slope
    rest[plan.side, 19] = plan.side_room
    const = plan.constant
    rest[:, 21], rest[:, 22] = const["twist"], const["shell"]
    rest[:, 23] = record_tags(const["material"], plan.open_lo, plan.open_hi, const["v_part"])
    return rest


class GpuPose:
    """One plan's rest data on the GPU and the programs that pose it (see the module's
    docstring). ``mode``: one of :data:`POSE_MODES`; ``rows_per_group``: how many rows a
    work group takes (``"groups"``)."""

    def __init__(self, ctx, plan: SwaySkin, mode: str = "groups", rows_per_group: int = ROWS_PER_GROUP):
        if mode not in POSE_MODES:
            raise ValueError(f"pose mode must be one of {POSE_MODES}, got {mode!r}")
        self.ctx, self.plan, self.mode, self.n = ctx, plan, mode, plan.n
        self.groups = tree_groups(plan, rows_per_group)
        self.rest = ctx.buffer(_rest_data(plan).tobytes())
        self.scratch = ctx.buffer(reserve=SCRATCH_BYTES * self.n)
        self.poses = None                                       # made for the first GS frame
        self.report = ctx.buffer(np.zeros(1, np.uint32).tobytes())
        self.schedule = ctx.buffer(_schedule(plan, self.groups).tobytes())
        omegas, slot = np.unique(plan.omega, return_inverse=True)
        self.frequencies = omegas / (2.0 * np.pi)
        self.cycles = ctx.buffer(reserve=4 * len(omegas))
        trees = len(plan.roots)
        self._tree_frame = np.zeros((trees, 16), np.float32)
        u1, u2 = plan.u[0].take(plan.roots, axis=1).T, plan.u[1].take(plan.roots, axis=1).T
        self._tree_frame[:, 3] = np.mod(plan.phase, 2.0 * np.pi) / (2.0 * np.pi)
        self._tree_frame[:, 4:7], self._tree_frame[:, 7] = u1, slot
        self._tree_frame[:, 8:11], self._tree_frame[:, 12:15] = u2, cross(u1, u2)
        self.trees = ctx.buffer(reserve=self._tree_frame.nbytes)
        self.origin = None
        self.defines = {"MAX_DEPTH": int(ancestor_count(plan.parent).max()) + 1,
                        "MAX_CHAIN": int(ancestor_count(plan.parent_row).max()) + 1,
                        "MIN_BEND_COS": float(BEND_LIMIT_COS), "ELLIPSE_MARGIN": float(tol.ellipse_margin),
                        "PARALLEL": float(tol.parallel)}

    def programs(self, records: bool) -> list:
        """The compute programs of one frame, in order (built on first use)."""
        base = {**self.defines, "RECORDS": records}
        if self.mode != "walks":
            rounds = int(np.ceil(np.log2(self.defines["MAX_DEPTH"]))) if self.mode == "doubling" else None
            return [build_compute(self.ctx, "pose.glsl", {**base, "GROUPS": True, "GROUP_SIZE": GROUP_SIZE,
                                                          "DOUBLING": rounds})]
        return [build_compute(self.ctx, "pose.glsl", {**base, "PHASE": phase, "GROUP_SIZE": GROUP_SIZE})
                for phase in ((1, 2, 3, 4) if records else (1, 2, 3))]

    def set_origin(self, origin) -> int:
        """Upload the trees' frames with their root starts relative to ``origin`` (3,)
        (the eye) when it changed; returns the bytes written."""
        origin = np.asarray(origin, dtype=np.float64)
        if self.origin is not None and np.array_equal(origin, self.origin):
            return 0
        frame = self._tree_frame
        frame[:, 0:3] = self.plan.root_start.T - origin
        self.trees.write(frame.tobytes())
        self.origin = origin.copy()
        return frame.nbytes

    def run(self, t: float, target, row_offset: int = 0, records: bool = True, dry: bool = False) -> int:
        """Pose every row at time ``t`` (seconds) into ``target``: records from record
        ``row_offset`` on (``records``), else the pose buffer's (posed start - eye, turn),
        (axis, 0) per segment. Returns the bytes written to the GPU (the phases). ``dry``:
        every call but with no work group dispatched (the CPU's own share, for the bench)."""
        cycles = np.mod(self.frequencies * float(t), 1.0).astype(np.float32)
        self.cycles.write(cycles.tobytes())
        for binding, buf in enumerate((self.rest, self.trees, self.cycles, self.scratch, target, self.report,
                                       self.schedule)):
            buf.bind_to_storage_buffer(binding)
        programs = self.programs(records)
        groups = 0 if dry else -(-self.n // GROUP_SIZE) if self.mode == "walks" else len(self.groups)
        for i, program in enumerate(programs):
            if i:
                self.ctx.memory_barrier()
            set_uniforms(program, n_rows=self.n, row_offset=int(row_offset))
            program.run(groups)
        self.ctx.memory_barrier()          # the draw reads the records as vertex attributes
        return cycles.nbytes

    def pose_buffer(self, t: float):
        """The pose buffer at time ``t``: per segment (posed start - eye, total turn) and
        (the tree's unit axis, 0), 32 bytes, for the vertex-skinned mesh."""
        if self.poses is None:
            self.poses = self.ctx.buffer(reserve=POSE_BYTES * self.n)
        self.run(t, self.poses, 0, records=False)
        return self.poses

    def take_sharp_count(self) -> int:
        """Joints the program found sharp since the last call (read back: tests only)."""
        count = int(np.frombuffer(self.report.read(), np.uint32)[0])
        self.report.write(np.zeros(1, np.uint32).tobytes())
        return count

    def gpu_bytes(self) -> int:
        """GPU bytes this plan holds (rest data, scratch, trees, pose buffer)."""
        return sum(b.size for b in self._buffers() if b is not None)

    def _buffers(self) -> tuple:
        return self.rest, self.scratch, self.trees, self.cycles, self.report, self.schedule, self.poses

    def release(self) -> None:
        for buf in self._buffers():
            if buf is not None:
                buf.release()
        self.poses = None


class PoseStream(RecordStream):
    """A record sink (:class:`RecordStream`) that also poses an animation's moving rows on
    the GPU (:meth:`pose`): the static rows are packed and uploaded once, the moving ones
    written by the compute program. :class:`plantgen.animation.AnimatedScene` uses
    :meth:`pose` when it has a plan and the frame has no sharp joint, else :meth:`write`."""

    poses_on_gpu = True

    def __init__(self, ctx, mode: str = "groups", rows_per_group: int = ROWS_PER_GROUP):
        super().__init__(ctx)
        self.mode, self.rows_per_group = mode, rows_per_group
        self._gpu: GpuPose | None = None

    def gpu(self, plan: SwaySkin) -> GpuPose:
        """The GPU side of ``plan`` (uploaded on first use, again for another plan)."""
        if self._gpu is None or self._gpu.plan is not plan:
            if self._gpu is not None:
                self._gpu.release()
            self._gpu = GpuPose(self.ctx, plan, self.mode, self.rows_per_group)
        return self._gpu

    def pose(self, plan: SwaySkin, static, t: float, origin, box) -> tuple[float, int, StreamedRows]:
        """Make :attr:`buffer` hold ``static``'s records, then the plan's rows posed at
        ``t`` (relative to ``origin``); ``box`` (2, 3) holds every row. Returns (CPU ms,
        bytes uploaded, the :class:`StreamedRows` to draw)."""
        origin = np.asarray(origin, dtype=np.float64)
        t0 = time.perf_counter()
        gpu = self.gpu(plan)
        _, written = self.prepare(static, len(static) + plan.n, origin)
        written += gpu.set_origin(origin)
        written += gpu.run(t, self.buffer, len(static))
        ms = (time.perf_counter() - t0) * 1e3
        return ms, written, StreamedRows(len(static) + plan.n, tuple(plan.material_names), np.asarray(box))

    def pose_segments(self, plan: SwaySkin, t: float, origin):
        """The pose buffer of ``plan`` at ``t`` relative to ``origin`` (GS: the
        vertex-skinned mesh, :meth:`GpuPose.pose_buffer`)."""
        gpu = self.gpu(plan)
        gpu.set_origin(origin)
        return gpu.pose_buffer(t)

    def release(self) -> None:
        super().release()
        if self._gpu is not None:
            self._gpu.release()
            self._gpu = None
