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

:func:`triangulate` turns one outline (any simple polygon, concave too, not necessarily
planar) into triangles by ear clipping in its best-fit plane. Nothing here imports GL.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ...tolerances import tol
from ..vec import unit

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


def best_fit_normal(points: np.ndarray) -> np.ndarray:
    """Unit normal of the plane that best fits an outline (Newell's method: exact for a
    planar polygon, oriented by its winding; the least-squares plane's normal when the
    Newell vector vanishes, e.g. for a self-cancelling figure eight)."""
    p = np.asarray(points, dtype=np.float64)
    q = np.roll(p, -1, axis=0)
    n = np.array([np.sum((p[:, 1] - q[:, 1]) * (p[:, 2] + q[:, 2])),
                  np.sum((p[:, 2] - q[:, 2]) * (p[:, 0] + q[:, 0])),
                  np.sum((p[:, 0] - q[:, 0]) * (p[:, 1] + q[:, 1]))])
    size = np.linalg.norm(n)
    scale = max(float(np.ptp(p, axis=0).max()), tol.polygon_area)
    if size > tol.polygon_area * scale * scale:
        return n / size
    _, _, vt = np.linalg.svd(p - p.mean(axis=0))
    return vt[2]


def _plane_coordinates(points: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(k, 2): the points in an orthonormal basis (e1, e2) of the plane with e1 × e2 = normal."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(normal, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    rel = points - points.mean(axis=0)
    return np.stack([rel @ e1, rel @ e2], axis=1)


def _dedupe(points: np.ndarray) -> np.ndarray:
    """The outline without repeated consecutive points (the closing one included)."""
    scale = max(float(np.ptp(points, axis=0).max()) if len(points) else 0.0, tol.polygon_area)
    keep = []
    for i, p in enumerate(points):
        if not keep or np.linalg.norm(p - points[keep[-1]]) > tol.outline_duplicate * scale:
            keep.append(i)
    if len(keep) > 1 and np.linalg.norm(points[keep[0]] - points[keep[-1]]) <= tol.outline_duplicate * scale:
        keep.pop()
    return points[keep]


def _cross2(o, a, b) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _inside(p, a, b, c) -> bool:
    """p inside or on the counter-clockwise triangle abc."""
    return _cross2(a, b, p) >= 0 and _cross2(b, c, p) >= 0 and _cross2(c, a, p) >= 0


def _ear_clip(uv: np.ndarray) -> list[tuple[int, int, int]]:
    """Triangles (index triples, counter-clockwise) of a counter-clockwise simple polygon
    in the plane. An outline with no ear left (self-intersecting) is finished as a fan of
    its remaining vertices rather than dropped."""
    idx = list(range(len(uv)))
    tris: list[tuple[int, int, int]] = []
    scale = max(float(np.ptp(uv, axis=0).max()), tol.polygon_area)
    flat = tol.polygon_area * scale * scale
    while len(idx) > 3:
        n = len(idx)
        for k in range(n):
            i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % n]
            a, b, c = uv[i0], uv[i1], uv[i2]
            turn = _cross2(a, b, c)
            if turn < -flat:
                continue                      # reflex corner
            if turn <= flat:
                del idx[k]                    # collinear corner: no triangle, drop it
                break
            if any(_inside(uv[j], a, b, c) for j in idx if j not in (i0, i1, i2)):
                continue
            tris.append((i0, i1, i2))
            del idx[k]
            break
        else:                                 # no ear: not a simple polygon
            tris.extend((idx[0], idx[m], idx[m + 1]) for m in range(1, len(idx) - 1))
            return tris
    if len(idx) == 3 and abs(_cross2(uv[idx[0]], uv[idx[1]], uv[idx[2]])) > flat:
        tris.append(tuple(idx))
    return tris


def triangulate(points) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Triangulate one outline in its best-fit plane.

    Returns (vertices (k, 3), triangles (t, 3) indices into them, counter-clockwise about
    the normal, unit normal (3,)), or None for an outline with fewer than three distinct
    points or no area.
    """
    pts = _dedupe(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    if len(pts) < 3:
        return None
    normal = best_fit_normal(pts)
    uv = _plane_coordinates(pts, normal)
    x, y = uv[:, 0], uv[:, 1]
    signed = 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    if signed < 0:            # clockwise about the normal (least-squares case): flip the normal
        normal = -normal
        uv = _plane_coordinates(pts, normal)
    tris = _ear_clip(uv)
    if not tris:
        return None
    return pts, np.array(tris, dtype=np.int64).reshape(-1, 3), normal


class PolygonBuilder:
    """Collects outlines as the turtle closes them and builds the :class:`Polygons`."""

    def __init__(self) -> None:
        self._verts: list[np.ndarray] = []
        self._tris: list[np.ndarray] = []
        self._poly: list[np.ndarray] = []
        self._mats: list[int] = []
        self._normals: list[np.ndarray] = []
        self._segments: list[int] = []
        self._count = 0
        self.degenerate = 0       # outlines dropped: under three distinct points or no area

    def add(self, outline, material: int, segment: int = -1) -> None:
        got = triangulate(outline) if len(outline) >= 3 else None
        if got is None:
            self.degenerate += 1
            return
        verts, tris, normal = got
        self._tris.append(tris + self._count)
        self._poly.append(np.full(len(tris), len(self._mats), dtype=np.int64))
        self._verts.append(verts)
        self._count += len(verts)
        self._mats.append(material)
        self._normals.append(normal)
        self._segments.append(segment)

    def extend(self, polygons: Polygons) -> None:
        """Append polygons already triangulated (placed surfaces), after those added so far."""
        if not len(polygons):
            return
        self._tris.append(polygons.triangles + self._count)
        self._poly.append(polygons.polygon + len(self._mats))
        self._verts.append(polygons.vertices)
        self._count += len(polygons.vertices)
        self._mats.extend(polygons.material.tolist())
        self._normals.extend(polygons.normal)
        self._segments.extend(polygons.segment.tolist())

    def build(self) -> Polygons:
        if not self._mats:
            return Polygons.empty()
        return Polygons(np.concatenate(self._verts), np.concatenate(self._tris), np.concatenate(self._poly),
                        np.array(self._mats, dtype=np.int32), np.array(self._normals, dtype=np.float64),
                        np.array(self._segments, dtype=np.int64))
