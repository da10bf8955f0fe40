"""The vertex-skinned mesh of a swaying scene (GS, GS+R): tessellated once at rest, posed
in the vertex shader (``shaders/raster.glsl``, ``SKINNED``), as a game engine skins a
character, instead of re-tessellating the posed frusta in numpy every frame.

Every vertex is bound to the segments whose faces use it (the rows' ``segment``; a
knuckle's slices count as their child segment). A vertex of one segment turns rigidly
with it: about the segment's start, by its total turn T (the sway turns each segment
about its tree's axis k, :mod:`plantgen.geometry.skeletons.motion`), and moves with the start. A
vertex two segments share (the ring of a continuing joint: tessellation gives parent and
child one ring) turns about the joint point, the child's start, by the mean of their two
turns, so the ring stays one ring and the mesh stays closed in every pose: the shader
moves the same vertex for both rows. Still rows' vertices stay where they are.

So away from joints a posed vertex lies on its segment's posed cone exactly (a rigid
motion of the rest cone: the ray caster's frustum at time t has the same cone; only its
cutting planes, a side branch's base and the texture frame are worked out anew), and a
joint ring lies between the two cones, off each by about r·|θ|/2 for a joint angle θ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mesh import TessellatedMesh

__all__ = ["SkinnedMesh", "bind_vertices", "skin_positions"]


@dataclass(frozen=True, eq=False)
class SkinnedMesh:
    """A rest mesh and its vertices' binding (V vertices).

    mesh : the :class:`TessellatedMesh` at rest
    pivot : (V,) int32, the segment (an index of the moving skeleton) about whose start the
        vertex turns; -1: a still vertex
    other : (V,) int32, the vertex turns by the mean of ``pivot``'s and ``other``'s turns
        (``other == pivot``: rigidly with ``pivot``)
    offset : (V, 3) float64, the rest position less the pivot's rest start (a still vertex:
        its position)
    """

    mesh: TessellatedMesh
    pivot: np.ndarray
    other: np.ndarray
    offset: np.ndarray

    @property
    def shared(self) -> np.ndarray:
        """(V,) bool: vertices two segments share (joint rings)."""
        return (self.pivot >= 0) & (self.pivot != self.other)


def bind_vertices(mesh: TessellatedMesh, row_segment, rest_start) -> SkinnedMesh:
    """Bind ``mesh``'s vertices (see the module docstring).

    Parameters
    ----------
    mesh : tessellated from rows whose moving segment is ``row_segment`` (rows,) (-1: a
        still row); the moving skeleton's parents precede their children, so a vertex's
        deepest segment is the child of a joint it sits on
    rest_start : (m, 3) the moving segments' starts at rest
    """
    row_segment = np.asarray(row_segment, dtype=np.int64)
    n_vertices = len(mesh.vertices)
    corner = np.repeat(row_segment[mesh.face_row], 3)
    index = mesh.faces.ravel()
    lo = np.full(n_vertices, np.iinfo(np.int64).max)
    hi = np.full(n_vertices, -1, dtype=np.int64)
    np.minimum.at(lo, index, corner)
    np.maximum.at(hi, index, corner)
    pivot = hi                                 # the deepest segment: a joint's child, whose start is J
    other = np.where((lo >= 0) & (lo <= hi), lo, hi)
    offset = np.array(mesh.vertices, dtype=np.float64)
    moving = pivot >= 0
    offset[moving] -= np.asarray(rest_start, dtype=np.float64)[pivot[moving]]
    return SkinnedMesh(mesh, pivot.astype(np.int32), other.astype(np.int32), offset)


def skin_positions(skinned: SkinnedMesh, start, turn, axis) -> np.ndarray:
    """(V, 3) float64 posed vertices, as the vertex shader places them: ``start`` (m, 3)
    the segments' posed starts, ``turn`` (m,) their total turns (radians), ``axis`` (m, 3)
    their trees' unit axes. The numpy twin of ``raster.glsl``'s ``SKINNED`` (tests)."""
    out = np.array(skinned.offset, dtype=np.float64)
    moving = skinned.pivot >= 0
    p, o = skinned.pivot[moving], skinned.other[moving]
    angle = 0.5 * (np.asarray(turn)[p] + np.asarray(turn)[o])
    k = np.asarray(axis, dtype=np.float64)[p]
    v = out[moving]
    cos, sin = np.cos(angle)[:, None], np.sin(angle)[:, None]
    turned = v * cos + np.cross(k, v) * sin + k * np.einsum("ij,ij->i", k, v)[:, None] * (1.0 - cos)
    out[moving] = np.asarray(start, dtype=np.float64)[p] + turned
    return out
