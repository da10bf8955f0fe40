"""What every command of the pipeline checks, at the bottom of it: the limits in force,
a skinned model's rows and a tessellation's vertices checked finite (one line naming the
degenerate segment), and the memory one skinned segment takes, which the render's and
the export's budgets both count."""

from __future__ import annotations

import numpy as np

from ..errors import PlantgenError
from ..geometry.skeletons.frusta import ROW_FIELDS, Frusta
from ..limits import Limits
from ..limits import limits as default_limits
from ..scene import Scene

#: Memory a render or an export takes per skinned segment, measured and rounded up:
SKIN_BYTES_PER_SEGMENT = 1024    # skinning (about 570 bytes a segment at its peak), records, knuckles


def in_force(given: Limits | None) -> Limits:
    """The limits a call runs under: the caller's, else the defaults."""
    return given if given is not None else default_limits


def check_finite_frusta(frusta: Frusta, source) -> Frusta:
    """``frusta`` if every row is finite; else one line naming the first segment whose skin
    is not (so no inf or NaN reaches a renderer or a file). NaN propagates through min and
    max and inf reaches them: rows whose every field has finite extremes are finite, found
    without a full-size temporary; the rows are searched only where one is not."""
    with np.errstate(invalid="ignore"):
        if all(np.isfinite(values.min()) and np.isfinite(values.max()) for values in
               (getattr(frusta, name) for name in ROW_FIELDS) if values.dtype.kind == "f" and values.size):
            return frusta
        bad = np.zeros(len(frusta), dtype=bool)
        for name in ROW_FIELDS:
            values = getattr(frusta, name)
            if values.dtype.kind == "f":
                bad |= ~np.isfinite(values).reshape(len(frusta), -1).all(axis=1) if len(frusta) else bad
    if bad.any():
        row = int(np.argmax(bad))
        raise PlantgenError(f"{source}: the skin of segment {int(frusta.segment[row])} is not finite "
                            f"(frustum row {row}): the segment is degenerate")
    return frusta


def check_finite_mesh(mesh, frusta: Frusta, source) -> None:
    """One line naming the first segment whose tessellation holds a non-finite vertex,
    normal or texture coordinate."""
    bad = ~(np.isfinite(mesh.vertices).all(axis=1) & np.isfinite(mesh.normals).all(axis=1)
            & np.isfinite(mesh.uv).all(axis=1))
    if bad.any():
        face = int(np.argmax(bad[mesh.faces].any(axis=1)))
        row = int(mesh.face_row[face])
        raise PlantgenError(f"{source}: the mesh of segment {int(frusta.segment[row])} is not finite "
                            f"(frustum row {row}): the segment is degenerate")


def distinct_segments(scene: Scene) -> int:
    """Segments of a scene's distinct plants, each once (what a placed scene skins)."""
    return sum(len(skeleton) for skeleton in {id(i.skeleton): i.skeleton for i in scene.instances}.values())
