"""What a render returns: the image, the distance along each pixel's ray, and typed stats."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.rays.camera import Camera
from .passes import LightWindow

__all__ = ["RenderResult", "RenderStats", "RaycastStats", "RasterStats", "WorkCounts", "WorkCounter"]

#: Shader storage binding of the work counters (``STATS`` programs).
WORK_COUNTER_BINDING = 2


@dataclass(frozen=True)
class WorkCounts:
    """The work of one counting render (``count_work=True``): ``fragments`` the fragment
    shader ran for (atomics are side effects, so depth is tested late: no early rejection),
    ``samples`` height samples of the relief march (0 without relief), ``covered`` pixels
    with a hit (a frame without ground)."""

    fragments: int
    samples: int
    covered: int

    @property
    def overdraw(self) -> float:
        """Shaded fragments per covered pixel."""
        return self.fragments / max(self.covered, 1)

    @property
    def samples_per_pixel(self) -> float:
        """Mean relief height samples per covered pixel."""
        return self.samples / max(self.covered, 1)

    def as_dict(self) -> dict:
        return {"fragments": self.fragments, "samples": self.samples, "covered": self.covered,
                "overdraw": self.overdraw, "samples_per_pixel": self.samples_per_pixel}


class WorkCounter:
    """The zeroed counter buffer of one counting render, bound where ``STATS`` programs
    count (two uint32: fragments, samples)."""

    def __init__(self, ctx):
        self.buffer = ctx.buffer(np.zeros(4, np.uint32).tobytes())
        self.buffer.bind_to_storage_buffer(WORK_COUNTER_BINDING)

    def read(self, distance: np.ndarray) -> WorkCounts:
        """The counts (and the covered pixels of ``distance``); releases the buffer."""
        fragments, samples = (int(x) for x in np.frombuffer(self.buffer.read(), np.uint32)[:2])
        self.buffer.release()
        return WorkCounts(fragments, samples, int(np.isfinite(distance).sum()))


@dataclass(frozen=True)
class RenderStats:
    """What one frame did, whichever renderer drew it.

    passes : names of the passes run, in order (see :func:`plantgen.gl.passes.frame_passes`);
        ``shadow`` is there whenever the frame samples a shadow map, drawn or reused
    near, far : depth range of the frame (world units along the view direction)
    shadow_ms : milliseconds of the shadow pass (0 without shadows, and 0 when the map
        was reused)
    light_window : the light's window of the shadow map (relative to the eye), None
        without shadows
    upload_ms : CPU milliseconds spent uploading geometry inside the render call (a mesh
        for GS; 0 for the ray caster, whose records are timed by ``pack_ms``)
    ssaa : samples per pixel side the frame was drawn with; resolve_ms : CPU milliseconds
        averaging them down (0 without supersampling)
    shadow_cached : the shadow map was not drawn for this frame but reused: nothing it
        depends on changed since it was drawn (:class:`plantgen.gl.frame.ShadowKey`)
    """

    passes: list
    near: float
    far: float
    shadow_ms: float
    light_window: LightWindow | None
    upload_ms: float = 0.0
    ssaa: int = 1
    resolve_ms: float = 0.0
    shadow_cached: bool = False


@dataclass(frozen=True)
class RaycastStats(RenderStats):
    """segments : frusta rows drawn; record_bytes : bytes of one record; upload_bytes :
    record bytes uploaded by this call (0 when the caller supplied the buffer); pack_ms :
    CPU milliseconds packing records; program : (file, defines) of the frusta program;
    programs : (file, names of the defines switched on) of every program the frame used;
    work : the counts of a counting render, else None."""

    segments: int = 0
    record_bytes: int = 0
    upload_bytes: int = 0
    pack_ms: float = 0.0
    program: tuple = ()
    programs: list | None = None
    work: WorkCounts | None = None


@dataclass(frozen=True)
class RasterStats(RenderStats):
    """triangles, vertices : the mesh's counts; level : its subdivision level m;
    buffer_bytes : GPU bytes of the draw; draw_calls : draw calls of the frame; work : the
    counts of a counting render, else None."""

    triangles: int = 0
    vertices: int = 0
    level: int = 0
    buffer_bytes: int = 0
    draw_calls: int = 0
    work: WorkCounts | None = None


@dataclass
class RenderResult:
    """color: (height, width, 3) uint8, row 0 the top row; distance: (height, width) float32,
    distance from the eye along each pixel's ray, inf for a miss; frame_ms: GPU frame time
    (draw to finish, excluding upload and read-back); camera: the view rendered."""

    color: np.ndarray
    distance: np.ndarray
    frame_ms: float
    camera: Camera
    stats: RenderStats
