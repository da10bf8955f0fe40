"""Animated scenes: pose, re-skin only what moves, upload only the per-segment records.

Per frame (§4: "the splitting planes between segments have to be recomputed in each time
step"): the moving instances' skeleton is posed at time t
(:func:`plantgen.geometry.motion.pose`), skinned again (:func:`skin_skeleton`, vectorised
over every segment: cutting planes and texture offsets), packed into 96-byte records and
written into the tail of one GPU buffer whose head holds the static instances' records,
packed and uploaded once. A scene without motion is skinned once, whatever the frame
count. The camera stays fixed over an animation, so the static records (relative to the
eye) stay valid, and so does the light's window (one box for all frames: shadows do not
shimmer).

Writers: GIF and WebP through Pillow, to a temporary name renamed at the end.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import PlantgenError
from ..geometry.frusta import ROW_FIELDS, Frusta
from ..geometry.motion import pose, sway_rig
from ..geometry.skeleton import Skeleton
from ..geometry.skin import skin_skeleton
from ..geometry.stage import Sway
from .raycast import RECORD_BYTES, frusta_bounds, pack_records

__all__ = ["AnimatedScene", "FrameUpdate", "skeleton_rows", "concatenate_frusta",
           "write_animation", "ANIMATION_SUFFIXES"]

ANIMATION_SUFFIXES = (".gif", ".webp")


def skeleton_rows(skeleton: Skeleton, rows) -> Skeleton:
    """The segments ``rows`` ((k,) int, closed under parents) as a skeleton, parents re-indexed."""
    rows = np.asarray(rows, dtype=np.int64)
    remap = np.full(len(skeleton), -1, dtype=np.int64)
    remap[rows] = np.arange(len(rows))
    parent = skeleton.parent[rows]
    parent = np.where(parent >= 0, remap[np.maximum(parent, 0)], -1)
    return Skeleton(skeleton.start[rows], skeleton.end[rows], skeleton.r_start[rows],
                    skeleton.r_end[rows], parent, skeleton.continues[rows], skeleton.material[rows],
                    skeleton.material_names)


def concatenate_frusta(first: Frusta, second: Frusta) -> Frusta:
    """Rows of ``first`` then ``second`` (same material names); parent rows re-indexed."""
    n = len(first)
    parent = np.concatenate([first.parent_row,
                             np.where(second.parent_row >= 0, second.parent_row + n, -1)])
    return Frusta(**{f: np.concatenate([getattr(first, f), getattr(second, f)]) for f in ROW_FIELDS},
                  material_names=first.material_names, parent_row=parent)


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
    motions : per instance, None or a motion mapping (see plantgen.scene)
    skin : the skinning function (``skin_skeleton`` or one with bound options)
    """

    skeleton: Skeleton
    segment_instance: np.ndarray
    motions: list
    skin: object = skin_skeleton
    skin_calls: int = 0
    updates: list = field(default_factory=list)

    def __post_init__(self):
        self.segment_instance = np.asarray(self.segment_instance, dtype=np.int64)
        moving_instance = np.array([bool(m and m.get("sway") and m["sway"].get("amplitude", 0))
                                    for m in self.motions] or [False])
        moving = (moving_instance[self.segment_instance] if len(self.skeleton)
                  else np.zeros(0, dtype=bool))
        self.moving_segments = np.flatnonzero(moving)
        self.static_segments = np.flatnonzero(~moving)
        self._moving_skeleton = skeleton_rows(self.skeleton, self.moving_segments)
        self._rig = sway_rig(self._moving_skeleton, self.segment_instance[self.moving_segments],
                             [Sway(**m["sway"]) if m and "sway" in m else None for m in self.motions])
        self._static = self._skin(skeleton_rows(self.skeleton, self.static_segments))
        self._static_records = None
        self._buffer = None
        self._origin = None

    @classmethod
    def from_scene(cls, scene, skin=skin_skeleton) -> "AnimatedScene":
        return cls(scene.skeleton(), scene.segment_instance(), [i.motion for i in scene.instances],
                   skin)

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
        posed = pose(self._moving_skeleton, self._rig, t) if self.animated else None
        t1 = time.perf_counter()
        moving = self._skin(posed) if self.animated else None
        t2 = time.perf_counter()
        frusta = self._static if moving is None else concatenate_frusta(self._static, moving)
        update = FrameUpdate(float(t), len(moving) if moving is not None else 0, 0,
                             (t1 - t0) * 1e3, (t2 - t1) * 1e3)
        return frusta, moving, update

    def bounds(self, times) -> np.ndarray:
        """(2, 3) world box around every row at each of ``times``: one light window for
        all frames. Costs one pose and skin per time."""
        boxes = [frusta_bounds(self.frusta_at(t)) for t in times]
        return np.stack([np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)])

    def upload(self, ctx, t: float, origin):
        """Pose and skin what moves at ``t``; write only the moving rows' records to the GPU.

        Returns (frusta, buffer, update): all rows (for bounds), the moderngl buffer holding
        every row's record relative to ``origin`` (3,) (the fixed camera eye), and the
        :class:`FrameUpdate`. The static rows are packed and uploaded on the first call
        (or when the origin changes) only.
        """
        origin = np.asarray(origin, dtype=np.float64)
        frusta, moving, update = self._frame(t)
        n_static = len(self._static)
        n_total = len(frusta)
        first = self._buffer is None or self._origin is None or not np.array_equal(origin, self._origin)
        t0 = time.perf_counter()
        moving_records = pack_records(moving, origin) if moving is not None and len(moving) else None
        if first:
            self._static_records = pack_records(self._static, origin)
        t1 = time.perf_counter()
        need = max(n_total, 1) * RECORD_BYTES
        if self._buffer is None or self._buffer.size < need:
            if self._buffer is not None:
                self._buffer.release()
            self._buffer = ctx.buffer(reserve=need, dynamic=True)
            first = True
        written = 0
        if first and n_static:
            self._buffer.write(self._static_records.tobytes(), offset=0)
            written += self._static_records.nbytes
        if moving_records is not None:
            self._buffer.write(moving_records.tobytes(), offset=n_static * RECORD_BYTES)
            written += moving_records.nbytes
        self._origin = origin
        t2 = time.perf_counter()
        update.pack_ms, update.upload_ms, update.upload_bytes = (t1 - t0) * 1e3, (t2 - t1) * 1e3, written
        self.updates.append(update)
        return frusta, self._buffer, update

    def release(self) -> None:
        if self._buffer is not None:
            self._buffer.release()
            self._buffer = None


def write_animation(path, frames, fps: float) -> None:
    """Write (h, w, 3) uint8 ``frames`` as an animated GIF or WebP at ``fps``, to a
    temporary name renamed onto ``path`` at the end. A GIF uses one palette for every
    frame (taken from frames spread over the clip), so colours do not flicker."""
    from PIL import Image

    from .raycast import _write_atomically

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in ANIMATION_SUFFIXES:
        raise PlantgenError(f"{path}: an animation must end in {' or '.join(ANIMATION_SUFFIXES)}")
    images = [Image.fromarray(np.ascontiguousarray(f)) for f in frames]
    if not images:
        raise PlantgenError("an animation needs at least one frame")
    duration = max(int(round(1000.0 / fps)), 10)

    def save(tmp):
        if suffix == ".gif":
            picks = np.linspace(0, len(images) - 1, min(len(images), 4)).astype(int)
            strip = np.concatenate([np.asarray(images[i]) for i in picks], axis=0)
            palette = Image.fromarray(strip).quantize(colors=255, method=Image.Quantize.MEDIANCUT)
            frames_p = [im.quantize(palette=palette, dither=Image.Dither.NONE) for im in images]
            frames_p[0].save(tmp, format="GIF", save_all=True, append_images=frames_p[1:],
                             duration=duration, loop=0, optimize=False, disposal=1)
        else:
            images[0].save(tmp, format="WEBP", save_all=True, append_images=images[1:],
                           duration=duration, loop=0, quality=85, method=4)

    _write_atomically(path, save)
