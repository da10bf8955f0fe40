"""An impostor as a file's last level of detail: a card (two triangles, the bounding
sphere's diameter a side, facing +z of the plant's frame at its centre) whose texture
coordinates span the atlas tile seen from +z (what a reader without an impostor shader
shows), the atlas's layout (:meth:`~plantgen.geometry.meshes.impostor.Impostor.layout`) beside
it for the shader that picks the tile of each view (see the docs' engine assets page)."""

from __future__ import annotations

import numpy as np

from ..geometry.meshes.impostor import Impostor, octahedral_uv
from ..geometry.skeletons.frames import up_rotation
from .plants import Part

__all__ = ["IMPOSTOR_HEIGHT", "impostor_coverages", "impostor_part"]

#: The image height the impostor's screen coverage is stated for (the written camera's).
IMPOSTOR_HEIGHT = 768


def impostor_part(impostor: Impostor, up: str = "y") -> Part:
    """The impostor's card as a :class:`~plantgen.exporters.plants.Part` (material 0)."""
    corner = np.array([[-1, -1], [1, -1], [-1, 1], [1, 1]], np.float64)
    vertices = impostor.centre + impostor.radius * np.c_[corner, np.zeros(4)]
    n = impostor.frames
    uv0 = octahedral_uv(np.array([0.0, 0.0, 1.0]), impostor.hemi)
    col, row = (np.round(uv0 * (n - 1))).astype(int)
    span = 1.0 / n
    uv = np.c_[(col + (corner[:, 0] + 1) / 2) * span, (row + (1 - corner[:, 1]) / 2) * span].astype(np.float32)
    rot = up_rotation(up)
    normals = np.tile((rot @ np.array([0.0, 0.0, 1.0])).astype(np.float32), (4, 1))
    return Part(0, vertices @ rot.T, normals, uv, np.array([[0, 1, 3], [0, 3, 2]]))


def impostor_coverages(coverage, impostor: Impostor, height: int = IMPOSTOR_HEIGHT) -> list[float]:
    """The screen coverages of a plant's levels (``coverage``: its levels of detail's, or
    None: none) with the impostor after the last. With levels, it stands in where the last
    level would give way to nothing (every level keeps its range); without, where the plant
    spans no more pixels than one of its tiles. Under one pixel (or half the last level's
    coverage, where that is lower) it gives way to nothing."""
    if coverage is None:
        return [min(1.0, impostor.tile / height), 1.0 / height]
    above = [float(c) for c in coverage]
    return [*above, min(1.0 / height, above[-1] / 2)]
