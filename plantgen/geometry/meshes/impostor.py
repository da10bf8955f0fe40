"""Octahedral impostors: a plant seen from N×N directions, each view a tile of one atlas,
the directions laid out on an (hemi-)octahedron so that the tile of any view direction
is found in closed form (what an engine's shader does to draw it).

**Layout.** Tile (i, j) (column i, row j, row 0 at the atlas's top, as glTF's v) is the
view from the direction :func:`octahedral_direction` of ``(i / (N - 1), j / (N - 1))``:
the grid's corners and edges are directions on the border of the (hemi-)octahedron, so
the views of one edge meet. Octahedral (``hemi=False``): the unit square folds onto the
whole sphere (the square's centre looks down from +y, its corners from -y).
Hemi-octahedral (``hemi=True``, upright plants seen from above the ground): the square
maps to the upper hemisphere: (x, z) = ((u - v), (u + v - 1)) ... rotated so that the
centre looks from +y and the square's border is the horizon; every tile sees the plant
from above its base, the resolution the whole budget spends on the views a camera takes.

**Views.** Each tile is the plant in an orthographic-like view (a camera far away, 200
times the bounding radius, with the field of view that spans the bounding sphere's
diameter: the projection strays from orthographic by under 0.5 %), looking at the
sphere's centre from the direction, its up the world's +y (the tile's top; +z for
directions within 1° of the pole). Tile texel (x, y): ``right·(2x/T - 1)·R - up·(2y/T -
1)·R`` off the centre in the plane facing the direction.

**Maps.** ``colour`` (RGBA: the base colour of what each texel sees, alpha 1 where the ray
hits, 0 else), ``normal`` (RGB: the world unit normal, ``0.5 n + 0.5``, alpha as
colour), ``depth`` (one channel: ``0.5 + 0.5 s / R`` where s is the hit's offset from the
sphere's centre plane towards the viewer; 0 where nothing is hit). Pure numpy: the
bake is :mod:`plantgen.gl.impostor`'s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Impostor", "frame_basis", "octahedral_direction", "octahedral_uv", "view_directions"]


def octahedral_direction(uv, hemi: bool = True) -> np.ndarray:
    """(..., 3) unit directions (towards the viewer, y up) of atlas coordinates ``uv``
    (..., 2) in [0, 1]² (see the module docstring)."""
    uv = np.asarray(uv, dtype=np.float64)
    a = 2.0 * uv - 1.0
    if hemi:
        x, z = (a[..., 0] + a[..., 1]) / 2, (a[..., 0] - a[..., 1]) / 2
        y = 1.0 - np.abs(x) - np.abs(z)
    else:
        x, z = a[..., 0], a[..., 1]
        y = 1.0 - np.abs(x) - np.abs(z)
        fx = np.where(y < 0, (1 - np.abs(z)) * np.sign(x), x)
        fz = np.where(y < 0, (1 - np.abs(x)) * np.sign(z), z)
        x, z = fx, fz
    d = np.stack([x, y, z], axis=-1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def octahedral_uv(direction, hemi: bool = True) -> np.ndarray:
    """(..., 2) atlas coordinates of unit ``direction`` (..., 3), the inverse of
    :func:`octahedral_direction` (a hemi-octahedral atlas takes a direction below the
    horizon at the horizon)."""
    d = np.asarray(direction, dtype=np.float64)
    if hemi:
        d = np.concatenate([d[..., :1], np.maximum(d[..., 1:2], 0.0), d[..., 2:]], axis=-1)
    d = d / np.sum(np.abs(d), axis=-1, keepdims=True)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    if hemi:
        a = np.stack([x + z, x - z], axis=-1)
    else:
        fx = np.where(y < 0, (1 - np.abs(z)) * np.sign(x), x)
        fz = np.where(y < 0, (1 - np.abs(x)) * np.sign(z), z)
        a = np.stack([fx, fz], axis=-1)
    return (a + 1.0) / 2.0


def view_directions(frames: int, hemi: bool = True) -> np.ndarray:
    """(N, N, 3) the view direction of tile (row j, column i)."""
    g = np.arange(frames) / max(frames - 1, 1)
    u, v = np.meshgrid(g, g)                   # [j, i]: u = column, v = row
    return octahedral_direction(np.stack([u, v], axis=-1), hemi)


def frame_basis(direction) -> tuple[np.ndarray, np.ndarray]:
    """(right, up) unit vectors of the tile seen from ``direction`` (towards the viewer):
    up the world's +y made perpendicular (+z within 1° of the pole), right = up × direction."""
    d = np.asarray(direction, dtype=np.float64)
    world = np.array([0.0, 1.0, 0.0]) if abs(d[1]) < np.cos(np.radians(1.0)) else np.array([0.0, 0.0, -np.sign(d[1])])
    up = world - d * np.dot(world, d)
    up /= np.linalg.norm(up)
    return np.cross(up, d), up


@dataclass(frozen=True, eq=False)
class Impostor:
    """A baked impostor (see the module docstring): ``colour`` and ``normal`` (H, W, 4)
    uint8, ``depth`` (H, W) uint8; ``frames`` N views a side; ``hemi``; ``centre`` (3,)
    and ``radius`` the bounding sphere (the plant's own frame, y up); ``renderer`` what
    baked it."""

    colour: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    frames: int
    hemi: bool
    centre: np.ndarray
    radius: float
    renderer: str = ""

    @property
    def size(self) -> int:
        return int(self.colour.shape[0])

    @property
    def tile(self) -> int:
        return self.size // self.frames

    @property
    def bytes(self) -> int:
        """Raw texel bytes of the three maps (what a GPU holds uncompressed)."""
        return int(self.colour.nbytes + self.normal.nbytes + self.depth.nbytes)

    def layout(self) -> dict:
        """The atlas's layout as a file's ``extras`` records it."""
        return {"frames": self.frames, "layout": "hemi-octahedral" if self.hemi else "octahedral",
                "atlasSize": self.size, "tileSize": self.tile, "centre": [float(c) for c in self.centre],
                "radius": float(self.radius), "tileCentres": "grid corners: tile (i, j) sees direction "
                "oct(i/(N-1), j/(N-1))", "depth": "0.5 + 0.5*s/radius, s towards the viewer from the centre plane",
                "normal": "world, 0.5*n + 0.5", "up": "world +y (tile top)"}
