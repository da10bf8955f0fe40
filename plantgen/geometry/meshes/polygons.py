"""Leaf polygons: the turtle's filled ``{ ... }`` outlines, triangulated.

A :class:`Polygons` of ``p`` polygons made of ``t`` triangles over ``v`` vertices:

==============  ===========  ============================================================
``vertices``    (v, 3) f8    vertex positions (y up, the skeleton's frame)
``triangles``   (t, 3) i8    vertex indices, counter-clockwise seen from the polygon's
                             ``normal`` (the right-hand rule gives the normal)
``polygon``     (t,) i8      the polygon each triangle belongs to
``material``    (p,) i4      material index per polygon (into the skeleton's names)
``normal``      (p, 3) f8    unit normal of each polygon's best-fit plane
``segment``     (p,) i8      the skeleton segment each polygon hangs from: the last one
                             the turtle drew on its path before ``{`` or ``~`` (-1: none);
                             a swaying animation moves the polygon with it
==============  ===========  ============================================================

The outlines are triangulated by :mod:`plantgen.geometry.meshes.outlines`
(:func:`triangulate`: one outline, any simple polygon, concave too, not necessarily planar,
by ear clipping in its best-fit plane; :class:`PolygonBuilder` triangulates the outlines
added to it all at once, the same triangles). Nothing here imports GL.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..vec import unit
from .outlines import best_fit_normal, triangulate, triangulate_outlines

__all__ = ["Polygons", "PolygonBuilder", "triangulate", "best_fit_normal"]


@dataclass(frozen=True, eq=False)
class Polygons:
    vertices: np.ndarray
    triangles: np.ndarray
    polygon: np.ndarray
    material: np.ndarray
    normal: np.ndarray
    segment: np.ndarray | None = None

    def __post_init__(self):
        if self.segment is None:
            object.__setattr__(self, "segment", np.full(len(self.material), -1, dtype=np.int64))

    @staticmethod
    def empty() -> Polygons:
        return Polygons(np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.int64),
                        np.zeros(0, np.int32), np.zeros((0, 3)))

    def __len__(self) -> int:
        return len(self.material)

    @cached_property
    def bounds(self) -> np.ndarray:
        """(2, 3) box of the vertices (computed once: renderers ask every frame)."""
        if len(self.vertices) == 0:
            return np.zeros((2, 3))
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    @property
    def vertex_polygon(self) -> np.ndarray:
        """(v,) i8: the polygon each vertex belongs to (0 for a vertex no triangle uses)."""
        owner = np.zeros(len(self.vertices), np.int64)
        if len(self.triangles):
            owner[self.triangles.ravel()] = np.repeat(self.polygon, 3)
        return owner

    @property
    def triangle_material(self) -> np.ndarray:
        """(t,) i4: the material of each triangle (its polygon's)."""
        return self.material[self.polygon]

    def triangle_areas(self) -> np.ndarray:
        """(t,) f8: the area of each triangle."""
        a, b, c = (self.vertices[self.triangles[:, k]] for k in range(3))
        return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)

    def transformed(self, matrix) -> Polygons:
        """The polygons under a 4x4 affine ``matrix``: vertices by the affine map, normals by
        the inverse transpose of its linear part, renormalised; a mirroring matrix (negative
        determinant) reverses each triangle so it stays counter-clockwise about its normal."""
        m = np.asarray(matrix, dtype=np.float64)
        lin, t = m[:3, :3], m[:3, 3]
        normal = self.normal @ np.linalg.inv(lin)          # (lin^-T n) for each row n
        normal = unit(normal)
        triangles = self.triangles if np.linalg.det(lin) > 0 else self.triangles[:, ::-1].copy()
        return Polygons(self.vertices @ lin.T + t, triangles, self.polygon, self.material, normal, self.segment)

    def with_materials(self, remap) -> Polygons:
        """The polygons with each material index ``i`` replaced by ``remap[i]``."""
        material = np.asarray(remap, dtype=np.int32)[self.material] if len(self) else self.material
        return Polygons(self.vertices, self.triangles, self.polygon, material, self.normal, self.segment)

    def hung_from(self, segment) -> Polygons:
        """The polygons with every polygon hanging from segment index ``segment`` (an int,
        or (p,) ints; -1: none)."""
        hang = np.broadcast_to(np.asarray(segment, dtype=np.int64), (len(self),)).copy()
        return Polygons(self.vertices, self.triangles, self.polygon, self.material, self.normal, hang)

    @staticmethod
    def concatenate(parts, segment_offsets=None) -> Polygons:
        """Join polygon sets into one (their material indices as they are: remap them first
        with :meth:`with_materials` where the parts name materials differently). With
        ``segment_offsets`` (one per part), each part's segment indices (those >= 0) are
        shifted by its offset, as skeletons joined in the same order number theirs."""
        offsets = [0] * len(parts) if segment_offsets is None else list(segment_offsets)
        kept = [(p, o) for p, o in zip(parts, offsets, strict=True) if p is not None]
        parts = [p for p, _ in kept]
        if not parts:
            return Polygons.empty()
        segment = np.concatenate([np.where(p.segment >= 0, p.segment + o, -1) for p, o in kept]).astype(np.int64)
        vertex_first = np.cumsum([0] + [len(p.vertices) for p in parts])
        polygon_first = np.cumsum([0] + [len(p) for p in parts])
        return Polygons(np.concatenate([p.vertices for p in parts]).reshape(-1, 3),
                        np.concatenate([p.triangles + v for p, v in zip(parts, vertex_first, strict=False)])
                        .reshape(-1, 3).astype(np.int64),
                        np.concatenate([p.polygon + k for p, k in zip(parts, polygon_first, strict=False)])
                        .astype(np.int64),
                        np.concatenate([p.material for p in parts]).astype(np.int32),
                        np.concatenate([p.normal for p in parts]).reshape(-1, 3), segment)


class PolygonBuilder:
    """Collects outlines as the turtle closes them and builds the :class:`Polygons`. The
    outlines added are triangulated together (:func:`triangulate_outlines`) when the
    polygons are built, when polygons already triangulated are appended after them
    (:meth:`extend`) or when :attr:`degenerate` is asked; the polygons are those
    :func:`triangulate` of each outline in turn gives, in the order added."""

    def __init__(self) -> None:
        self._parts: list[Polygons] = []         # triangulated so far, in order
        self._outlines: list[np.ndarray] = []    # added since, not yet triangulated
        self._mats: list[int] = []
        self._segments: list[int] = []
        self._dropped = 0

    @property
    def degenerate(self) -> int:
        """Outlines dropped: under three distinct points or no area."""
        self._triangulate()
        return self._dropped

    def add(self, outline, material: int, segment: int = -1) -> None:
        self._outlines.append(np.array(outline, dtype=np.float64).reshape(-1, 3))
        self._mats.append(material)
        self._segments.append(segment)

    def _triangulate(self) -> None:
        """Triangulate the outlines added since the last time, as one more part."""
        if not self._outlines:
            return
        got = triangulate_outlines(self._outlines)
        kept = got.triangle_count > 0
        self._dropped += int((~kept).sum())
        first = np.cumsum(got.vertex_count) - got.vertex_count
        self._parts.append(Polygons(
            got.vertices, got.triangles + np.repeat(first, got.triangle_count)[:, None],
            np.repeat(np.arange(int(kept.sum()), dtype=np.int64), got.triangle_count[kept]),
            np.array(self._mats, dtype=np.int32)[kept], got.normal[kept],
            np.array(self._segments, dtype=np.int64)[kept]))
        self._outlines, self._mats, self._segments = [], [], []

    def extend(self, polygons: Polygons) -> None:
        """Append polygons already triangulated (placed surfaces), after those added so far."""
        if not len(polygons):
            return
        self._triangulate()
        self._parts.append(polygons)

    def build(self) -> Polygons:
        self._triangulate()
        parts = [p for p in self._parts if len(p)]
        if not parts:
            return Polygons.empty()
        vertex_first = np.cumsum([0] + [len(p.vertices) for p in parts])
        polygon_first = np.cumsum([0] + [len(p) for p in parts])
        return Polygons(np.concatenate([p.vertices for p in parts]),
                        np.concatenate([p.triangles + v for p, v in zip(parts, vertex_first, strict=False)]),
                        np.concatenate([p.polygon + k for p, k in zip(parts, polygon_first, strict=False)]),
                        np.concatenate([p.material for p in parts]).astype(np.int32),
                        np.concatenate([p.normal for p in parts]).astype(np.float64),
                        np.concatenate([p.segment for p in parts]).astype(np.int64))
