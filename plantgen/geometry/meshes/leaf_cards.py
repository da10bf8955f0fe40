"""Leaf cards: each leaf polygon as a rectangle in its plane (two triangles) carrying an
alpha-cut picture of its shape, as engines draw leaves.

A polygon's card lies in its plane on its own axes: ``u`` the major axis of its vertices
(their principal direction in the plane), pointing from the centroid away from the
polygon's first vertex (a predefined leaf's base, so a blade's tip is at +u), ``v =
normal × u``; the card is the polygon's bounding box on those axes. The polygon's
vertices and triangles scaled into the box's unit square are its *shape*: polygons of
one shape (the same outline at any size, turned anyhow in space) share one picture.
Shapes are told apart by their unit-square vertices rounded to ``1/key_steps``.

Each distinct shape is rasterised into a ``tile``×``tile`` tile of an RGBA atlas (white,
alpha the coverage of the texel by the shape's triangles, from ``supersample``² samples
a texel), a margin of ``margin`` texels around each so mipmaps bleed no neighbour into
it; a card's corners sample its tile's inner square. With an alpha cut-off of 0.5 the cut
edge is the shape's own outline to within half a texel of the tile. Pure numpy, no GL.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .polygons import Polygons

__all__ = ["CardAtlas", "LeafCards", "leaf_cards"]


@dataclass(frozen=True, eq=False)
class CardAtlas:
    """The shapes' pictures: ``image`` (H, W, 4) uint8 RGBA (white, alpha the coverage;
    row 0 at v = 0), ``tile`` texels a shape, ``columns`` tiles a row, ``shapes`` of them."""

    image: np.ndarray
    tile: int
    columns: int
    shapes: int
    margin: int

    def corners(self, shape: np.ndarray) -> np.ndarray:
        """(p, 4, 2) float32 texture coordinates of the cards' corners ((0, 0), (1, 0),
        (0, 1), (1, 1) of each shape's unit square) in ``shape``'s (p,) tiles."""
        h, w = self.image.shape[:2]
        col, row = shape % self.columns, shape // self.columns
        unit = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], np.float64)
        inner = self.tile - 2 * self.margin
        x = (col[:, None] * self.tile + self.margin + unit[None, :, 0] * inner) / w
        y = (row[:, None] * self.tile + self.margin + unit[None, :, 1] * inner) / h
        return np.stack([x, y], axis=-1).astype(np.float32)


@dataclass(frozen=True, eq=False)
class LeafCards:
    """Leaves as cards: ``polygons`` one quad (4 vertices, 2 triangles) per leaf polygon, in
    the leaves' order, with their materials, normals and segments (vertices 4i .. 4i + 3
    are polygon i's: the corners (0, 0), (1, 0), (0, 1), (1, 1) of its box); ``uv``
    (p, 4, 2) their corners' texture coordinates in ``atlas``; ``shape`` (p,) each
    polygon's shape (its tile)."""

    polygons: Polygons
    uv: np.ndarray
    shape: np.ndarray
    atlas: CardAtlas

    def subset(self, keep) -> LeafCards:
        """The cards of the polygons ``keep`` ((k,) int, ascending), the atlas shared."""
        keep = np.asarray(keep, dtype=np.int64)
        p = self.polygons
        vertices = (4 * keep[:, None] + np.arange(4)).ravel()
        triangles = (4 * np.arange(len(keep))[:, None, None] + _QUAD[None]).reshape(-1, 3)
        quads = Polygons(p.vertices[vertices], triangles, np.repeat(np.arange(len(keep)), 2), p.material[keep],
                         p.normal[keep], p.segment[keep])
        return LeafCards(quads, self.uv[keep], self.shape[keep], self.atlas)


#: A quad's two triangles over its corners (0, 0), (1, 0), (0, 1), (1, 1), counter-clockwise
#: seen from the side the normal points to.
_QUAD = np.array([[0, 1, 3], [0, 3, 2]], np.int64)


def _axes(polygons: Polygons, owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(u, v) (p, 3) each: every polygon's in-plane axes (see the module docstring)."""
    n = len(polygons)
    count = np.maximum(np.bincount(owner, minlength=n), 1)[:, None]
    centroid = np.zeros((n, 3))
    np.add.at(centroid, owner, polygons.vertices)
    centroid /= count
    d = polygons.vertices - centroid[owner]
    cov = np.zeros((n, 3, 3))
    np.add.at(cov, owner, d[:, :, None] * d[:, None, :])
    normal = polygons.normal / np.linalg.norm(polygons.normal, axis=1, keepdims=True)
    flat = np.eye(3)[None] - normal[:, :, None] * normal[:, None, :]
    cov = flat @ cov @ flat
    _, vectors = np.linalg.eigh(cov)
    u = vectors[:, :, 2]
    first = np.full(n, len(polygons.vertices), np.int64)
    np.minimum.at(first, owner, np.arange(len(polygons.vertices)))
    towards_first = np.einsum("ij,ij->i", polygons.vertices[np.minimum(first, len(owner) - 1)] - centroid, u)
    u = np.where((towards_first > 0)[:, None], -u, u)
    u -= normal * np.einsum("ij,ij->i", u, normal)[:, None]
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, np.cross(normal, u)


def _coverage(points: np.ndarray, triangles: np.ndarray, tile: int, margin: int, supersample: int) -> np.ndarray:
    """(tile, tile) coverage in [0, 1] of one shape (``points`` (k, 2) in its unit square)."""
    inner = tile - 2 * margin
    s = (np.arange(tile * supersample) + 0.5) / supersample - margin
    x, y = np.meshgrid(s / inner, s / inner)
    inside = np.zeros(x.shape, bool)
    for a, b, c in points[triangles]:
        d1 = (x - b[0]) * (a[1] - b[1]) - (a[0] - b[0]) * (y - b[1])
        d2 = (x - c[0]) * (b[1] - c[1]) - (b[0] - c[0]) * (y - c[1])
        d3 = (x - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (y - a[1])
        neg = (d1 < 0) | (d2 < 0) | (d3 < 0)
        pos = (d1 > 0) | (d2 > 0) | (d3 > 0)
        inside |= ~(neg & pos)
    return inside.reshape(tile, supersample, tile, supersample).mean(axis=(1, 3))


def leaf_cards(polygons: Polygons, tile: int = 64, supersample: int = 4, margin: int = 2,
               key_steps: int = 256, max_shapes: int = 1024) -> LeafCards:
    """The :class:`LeafCards` of ``polygons`` (see the module docstring); ``ValueError``
    when they have more than ``max_shapes`` distinct shapes (an atlas of that many tiles)."""
    if tile < 4 or margin < 0 or 2 * margin >= tile or supersample < 1:
        raise ValueError(f"tile {tile}, margin {margin}, supersample {supersample}: need tile > 2·margin, tile ≥ 4")
    n = len(polygons)
    owner = polygons.vertex_polygon
    u, v = _axes(polygons, owner)
    coords = np.stack([np.einsum("ij,ij->i", polygons.vertices, u[owner]),
                       np.einsum("ij,ij->i", polygons.vertices, v[owner])], axis=1)
    lo = np.full((n, 2), np.inf)
    hi = np.full((n, 2), -np.inf)
    np.minimum.at(lo, owner, coords)
    np.maximum.at(hi, owner, coords)
    unit = (coords - lo[owner]) / np.maximum(hi - lo, 1e-30)[owner]
    first = np.searchsorted(owner, np.arange(n))        # a polygon's vertices are consecutive
    counts = np.bincount(owner, minlength=n)
    keys: dict = {}
    shape = np.empty(n, np.int64)
    examples = []
    rounded = np.round(unit * key_steps).astype(np.int32)
    for i in range(n):
        key = rounded[first[i]:first[i] + counts[i]].tobytes()
        k = keys.setdefault(key, len(keys))
        if k == len(examples):
            examples.append(i)
            if len(examples) > max_shapes:
                raise ValueError(f"the leaves have more than {max_shapes:,} distinct shapes: no card atlas")
        shape[i] = k
    columns = max(1, math.ceil(math.sqrt(len(examples))))
    rows = max(1, math.ceil(len(examples) / columns))
    image = np.zeros((rows * tile, columns * tile, 4), np.uint8)
    image[..., :3] = 255
    tri_polygon = polygons.polygon
    for k, i in enumerate(examples):
        local = polygons.triangles[tri_polygon == i] - first[i]
        cover = _coverage(unit[first[i]:first[i] + counts[i]], local, tile, margin, supersample)
        r, c = divmod(k, columns)
        image[r * tile:(r + 1) * tile, c * tile:(c + 1) * tile, 3] = np.round(cover * 255).astype(np.uint8)
    atlas = CardAtlas(image, tile, columns, len(examples), margin)
    corner = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], np.float64)
    box = lo[:, None, :] + corner[None] * (hi - lo)[:, None, :]               # (p, 4, 2) in (u, v)
    plane = np.einsum("ij,ij->i", polygons.vertices[np.minimum(first, len(owner) - 1)],
                      polygons.normal / np.linalg.norm(polygons.normal, axis=1, keepdims=True))
    normal = polygons.normal / np.linalg.norm(polygons.normal, axis=1, keepdims=True)
    origin = normal * plane[:, None]
    vertices = origin[:, None, :] + box[..., :1] * u[:, None, :] + box[..., 1:] * v[:, None, :]
    triangles = (4 * np.arange(n)[:, None, None] + _QUAD[None]).reshape(-1, 3)
    quads = Polygons(vertices.reshape(-1, 3), triangles, np.repeat(np.arange(n), 2), polygons.material,
                     normal, polygons.segment)
    return LeafCards(quads, atlas.corners(shape), shape, atlas)
