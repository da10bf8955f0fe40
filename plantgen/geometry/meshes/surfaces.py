"""Predefined surfaces: the shapes ABOP's ``~`` places (section 5.1), built in.

A surface is a few planar polygons in the turtle's local frame, where a point ``(h, l, u)``
lies at ``position + scale·(h·H + l·L + u·U)`` once placed: ``h`` along the heading, ``l``
to the left, ``u`` up. Each surface has length 1 along ``H`` at scale 1 and its base at the
origin, so ``~(leaf, 0.3)`` is a blade 0.3 long growing from the turtle.

============  ======================================================================
``leaf``      a blade (ovate, widest at about a third of its length, drawn out into a
              pointed tip: the outline is concave towards the tip), 0.4 wide, lying in
              the H-L plane and folded along its midrib: each half is tilted 12° up
              towards U, so the blade is a shallow V opening upwards. 2 polygons,
              26 vertices.
``needles``   a fascicle of 8 needles radiating forward from the turtle, 15° and 35°
              away from H (alternately) at 8 turns about it, 1 and 0.85 long. Each
              needle is a thin tapering strip (0.03 wide at its base, a point at its
              tip) whose plane contains the needle and is tangent to the cone it
              lies on, so the tuft shows needles face-on and edge-on from any side.
              8 polygons, 56 vertices.
============  ======================================================================

:data:`SURFACES` lists them; a surface's index in it is what the turtle's ``~`` carries
(the grammar turns the name into it). :func:`place` transforms a surface to many turtle
frames at once. Pure numpy, no GL.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from math import cos, pi, radians, sin

import numpy as np

from .polygons import Polygons, triangulate

__all__ = ["SURFACES", "Surface", "place", "surface", "surface_index"]


@dataclass(frozen=True, eq=False)
class Surface:
    """One built-in surface, triangulated in the local (h, l, u) frame.

    ``outlines`` are the polygons as drawn (each (k, 3), planar); ``polygons`` their
    triangulation (a :class:`Polygons` with material 0)."""

    name: str
    description: str
    outlines: tuple[np.ndarray, ...]
    polygons: Polygons

    @property
    def vertex_count(self) -> int:
        return len(self.polygons.vertices)


def _leaf_outlines(samples: int = 11, half_width: float = 0.2, fold: float = 12.0) -> tuple[np.ndarray, ...]:
    """The blade's two halves: midrib from the base (0) to the tip (1), back along the edge.

    The half-width along the blade is ``t^0.7 (1 - t)^1.3``, scaled so its maximum is
    ``half_width``: round at the base, widest at t = 0.35, and falling to the tip faster
    than linearly, so the outline is concave there and the tip is drawn out."""
    t = np.linspace(0.0, 1.0, samples + 2)[1:-1]
    w = t ** 0.7 * (1.0 - t) ** 1.3
    w *= half_width / w.max()
    c, s = cos(radians(fold)), sin(radians(fold))
    halves = []
    for side in (1.0, -1.0):
        edge = np.stack([t, side * w * c, w * s], axis=1)[::-1]    # tip to base
        rib = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
        outline = np.concatenate([rib, edge])
        halves.append(outline if side > 0 else outline[::-1])   # both counter-clockwise about +U
    return tuple(halves)


def _needle_outlines(count: int = 8, half_width: float = 0.015) -> tuple[np.ndarray, ...]:
    """``count`` needles: each a strip from a base of width 2·half_width, narrowing at
    0.5 and 0.85 of its length, to a point."""
    stations = np.array([0.0, 0.5, 0.85])
    widths = half_width * np.array([1.0, 0.8, 0.45])
    out = []
    for i in range(count):
        tilt = radians(15.0 if i % 2 else 35.0)
        length = 0.85 if i % 2 else 1.0
        turn = 2 * pi * i / count
        radial = np.array([0.0, cos(turn), sin(turn)])
        d = cos(tilt) * np.array([1.0, 0.0, 0.0]) + sin(tilt) * radial      # along the needle
        across = np.array([0.0, -sin(turn), cos(turn)])                      # tangent to the cone
        right = [length * a * d - w * across for a, w in zip(stations, widths, strict=True)]
        left = [length * a * d + w * across for a, w in zip(stations, widths, strict=True)]
        out.append(np.array([*right, length * d, *left[::-1]]))
    return tuple(out)


def _build(name: str, description: str, outlines: tuple[np.ndarray, ...]) -> Surface:
    verts, tris, poly, normals, count = [], [], [], [], 0
    for k, outline in enumerate(outlines):
        pts, t, normal = triangulate(outline)
        verts.append(pts)
        tris.append(t + count)
        poly.append(np.full(len(t), k, dtype=np.int64))
        normals.append(normal)
        count += len(pts)
    polys = Polygons(np.concatenate(verts), np.concatenate(tris), np.concatenate(poly),
                     np.zeros(len(outlines), dtype=np.int32), np.array(normals))
    return Surface(name, description, outlines, polys)


@cache
def _surfaces() -> tuple[Surface, ...]:
    return (
        _build("leaf", "a pointed blade folded along its midrib, base at the turtle, along H, in the H-L plane",
               _leaf_outlines()),
        _build("needles", "a fascicle of 8 thin needles radiating forward from the turtle", _needle_outlines()),
    )


#: The built-in surfaces' names, in index order.
SURFACES: tuple[str, ...] = ("leaf", "needles")


def surface(index_or_name: int | str) -> Surface:
    """The built-in surface with this index in :data:`SURFACES` or this name."""
    index = surface_index(index_or_name) if isinstance(index_or_name, str) else index_or_name
    return _surfaces()[index]


def surface_index(name: str) -> int:
    """The index of a surface name; ValueError naming the known ones for another name."""
    if name not in SURFACES:
        raise ValueError(f"unknown surface {name!r} (known: {', '.join(SURFACES)})")
    return SURFACES.index(name)


def place(index: int, origins, frames, scales, materials) -> Polygons:
    """Surface ``index`` placed at ``n`` turtle states at once.

    origins (n, 3) positions; frames (n, 3, 3) rows H, L, U (orthonormal, right-handed);
    scales (n,) > 0; materials (n,) material index of each copy. Copy i's vertices are
    ``origins[i] + scales[i]·(local @ frames[i])`` and its normals ``normal @ frames[i]``;
    the copies follow each other in input order (each copy's polygons together)."""
    s = surface(index).polygons
    origins = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    frames = np.asarray(frames, dtype=np.float64).reshape(-1, 3, 3)
    scales = np.asarray(scales, dtype=np.float64).reshape(-1)
    n, nv, npoly = len(origins), len(s.vertices), len(s.material)
    verts = origins[:, None, :] + scales[:, None, None] * np.einsum("vk,nkj->nvj", s.vertices, frames)
    normals = np.einsum("pk,nkj->npj", s.normal, frames)
    normals /= np.linalg.norm(normals, axis=2, keepdims=True)
    tris = s.triangles[None, :, :] + (nv * np.arange(n))[:, None, None]
    poly = s.polygon[None, :] + (npoly * np.arange(n))[:, None]
    mats = np.repeat(np.asarray(materials, dtype=np.int32).reshape(-1), npoly)
    return Polygons(verts.reshape(-1, 3), tris.reshape(-1, 3), poly.reshape(-1), mats,
                    normals.reshape(-1, 3)) if n else Polygons.empty()
