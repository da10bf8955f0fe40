"""``plantgen scan``'s budget: a laser scan's memory, refused before anything is skinned.
The scan itself (:mod:`plantgen.geometry.rays.scan`) and its files (:mod:`plantgen.scanfiles`)
are run by the command (:mod:`plantgen.cli.scan`) on a grown, skinned model
(:func:`~plantgen.pipeline.growing.grow_file`, :func:`~plantgen.pipeline.render.skin_model`)."""

from __future__ import annotations

from ..limits import LimitError, Limits, hint
from .checks import distinct_segments, in_force
from .growing import GrowResult

#: Memory a laser scan takes per placed segment (its skin, boxes and labels; leaves
#: included), measured (about 1.3 KB) and rounded up.
SCAN_BYTES_PER_SEGMENT = 2048


def check_scan_memory(grown: GrowResult, limits: Limits | None, source) -> None:
    """Refuse, before anything is skinned, a scan whose skinned segments (a scene's
    distinct plants once: its copies are traced through two levels; else every segment)
    would take more than ``limits.max_scan_bytes``."""
    limits = in_force(limits)
    segments = distinct_segments(grown.scene) if grown.scene is not None else grown.segments
    need = segments * SCAN_BYTES_PER_SEGMENT
    if need > limits.max_scan_bytes:
        raise LimitError(f"{source}: a scan skinning {segments:,} segments needs about {need / 2**20:,.0f} "
                         f"MiB, over the limit of {limits.max_scan_bytes / 2**20:,.0f} MiB ({hint('scan_bytes')})")
