"""Baking an octahedral impostor with the ray caster (RC, RC+R with ``relief``): each of
the N×N views of :mod:`plantgen.geometry.meshes.impostor` is one render of the plant's frusta
and leaves, whose hits give the tile's base colour (the material's colour, a leaf's shade
in 16 tones, through the renderer's label pass: the same hits as its colour render),
depth (the exact ray distance) and normal (the cross product of the hit points'
differences across neighbouring texels, taken one-sided on the side whose depth is
closer, so a silhouette's step is never differenced; facing the viewer)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..geometry.meshes.impostor import Impostor, frame_basis, view_directions
from ..geometry.meshes.textures import linear_to_srgb
from ..geometry.rays.camera import Camera
from ..geometry.skeletons.frusta import ROW_FIELDS, Frusta, frusta_bounds, row_end_balls
from ..geometry.skeletons.materials import leaf_colours, leaf_tones, material_colour
from ..settings import RaycastSettings
from .context import gl_context, renderer_name
from .raycast import Raycaster

__all__ = ["DISTANCE_FACTOR", "bake_impostor", "bounding_sphere", "impostor_camera"]

#: The bake's cameras stand this many bounding radii from the centre.
DISTANCE_FACTOR = 200.0
#: Leaf shades baked: a leaf's tone is rounded to one of these.
LEAF_TONES = 16


def impostor_camera(centre, radius: float, direction, size: int) -> Camera:
    """The near-orthographic camera of one view (see :mod:`plantgen.geometry.meshes.impostor`)."""
    centre = np.asarray(centre, dtype=np.float64)
    _, up = frame_basis(direction)
    distance = DISTANCE_FACTOR * radius
    fov = float(np.degrees(2 * np.arctan(radius / distance)))
    return Camera(tuple(centre + distance * np.asarray(direction)), tuple(centre), tuple(up), fov, size, size)


def bounding_sphere(frusta: Frusta, leaves=None) -> tuple[np.ndarray, float]:
    """(centre, radius) of a ball around the frusta's balls (relief shells included) and
    the leaf vertices: centred on their box, through its farthest ball or vertex."""
    balls = row_end_balls(frusta)
    pts = np.concatenate([c for c, _ in balls])
    r = np.concatenate([r for _, r in balls])
    box = frusta_bounds(frusta)
    if leaves is not None and len(leaves.vertices):
        pts, r = np.concatenate([pts, leaves.vertices]), np.concatenate([r, np.zeros(len(leaves.vertices))])
        box = np.stack([np.minimum(box[0], leaves.vertices.min(axis=0)),
                        np.maximum(box[1], leaves.vertices.max(axis=0))])
    centre = box.mean(axis=0)
    return centre, float((np.linalg.norm(pts - centre, axis=1) + r).max())


def _palette(names, leaves) -> np.ndarray:
    """(256, 3) linear RGB of each label: 1 + m a row of material m, 128 + 16·m + k a leaf
    of material m (m < 8) at tone bucket k."""
    table = np.zeros((256, 3))
    for m, name in enumerate(names[:127]):
        table[1 + m] = material_colour(name)
    for m in range(min(len(names), 8)):
        tones = 0.25 + 0.6 * (np.arange(LEAF_TONES) + 0.5) / LEAF_TONES
        table[128 + 16 * m: 128 + 16 * m + LEAF_TONES] = leaf_colours(names, np.full(LEAF_TONES, m), tones)
    return table


def _leaf_labels(leaves) -> np.ndarray:
    tone = leaf_tones(len(leaves))
    bucket = np.clip(((tone - 0.25) / 0.6 * LEAF_TONES).astype(np.int64), 0, LEAF_TONES - 1)
    return 128 + 16 * np.minimum(leaves.material, 7) + bucket


def _normals(points: np.ndarray, hit: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(H, W, 3) unit normals from the hit ``points`` (see the module docstring)."""
    def diff(axis):
        fwd = np.roll(points, -1, axis) - points
        back = points - np.roll(points, 1, axis)
        fok = np.roll(hit, -1, axis) & hit
        bok = np.roll(hit, 1, axis) & hit
        use_back = bok & (~fok | (np.linalg.norm(np.where(bok[..., None], back, 0), axis=-1)
                                  < np.linalg.norm(np.where(fok[..., None], fwd, 0), axis=-1)))
        out = np.where(use_back[..., None], back, np.where(fok[..., None], fwd, 0.0))
        return out
    n = np.cross(diff(1), diff(0))
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    n = np.where(length > 0, n / np.maximum(length, 1e-300), direction)
    return np.where((np.einsum("...k,k->...", n, direction) < 0)[..., None], -n, n)


def bake_impostor(frusta: Frusta, material_names, leaves=None, *, frames: int = 8, size: int = 1024,
                  hemi: bool = True, relief: bool = True, caster: Raycaster | None = None,
                  progress=None) -> Impostor:
    """The :class:`~plantgen.geometry.meshes.impostor.Impostor` of a plant (its ``frusta``,
    ``material_names`` and ``leaves``, a Polygons or None, in its own frame, y up):
    ``frames``² views in a ``size``² atlas (``size`` a multiple of ``frames``), by RC+R
    (``relief``) or RC. ``progress(stage, done, total)`` per view."""
    if frames < 2 or size % frames or size // frames < 4:
        raise ValueError(f"an impostor of {frames}x{frames} views needs an atlas size that is a multiple of "
                         f"{frames} with at least 4 texels a view, got {size}")
    caster = caster or Raycaster(gl_context())
    names = tuple(material_names)
    centre, radius = bounding_sphere(frusta, leaves)
    tile = size // frames
    palette = _palette(names, leaves)
    tagged = Frusta.from_rows({f: getattr(frusta, f) for f in ROW_FIELDS}
                              | {"material": (1 + np.minimum(frusta.material, 126)).astype(np.int32)},
                              frusta.material_names, frusta.parent_row, frusta.open_lo, frusta.open_hi)
    leaf_labels = _leaf_labels(leaves) if leaves is not None and len(leaves) else None
    settings = replace(RaycastSettings(relief=relief), labels=True)
    colour = np.zeros((size, size, 4), np.uint8)
    normal = np.zeros((size, size, 4), np.uint8)
    depth = np.zeros((size, size), np.uint8)
    directions = view_directions(frames, hemi)
    for j in range(frames):
        for i in range(frames):
            d = directions[j, i]
            camera = impostor_camera(centre, radius, d, tile)
            result = caster.render(tagged, camera, settings, names, leaves=leaves if leaf_labels is not None else None,
                                   leaf_labels=leaf_labels)
            hit = np.isfinite(result.distance)
            label = np.where(hit, result.color[..., 0], 0).astype(np.int64)
            _, rays = camera.rays()
            points = np.asarray(camera.eye) + rays * np.where(hit, result.distance, 0.0)[..., None]
            s = np.einsum("...k,k->...", points - centre, d)
            block = (slice(j * tile, (j + 1) * tile), slice(i * tile, (i + 1) * tile))
            alpha = np.where(hit, 255, 0).astype(np.uint8)
            colour[block] = np.dstack([linear_to_srgb(np.clip(palette[label], 0, 1)), alpha])
            n = _normals(points, hit, d)
            normal[block] = np.dstack([np.round((0.5 * n + 0.5) * 255).astype(np.uint8), alpha])
            depth[block] = np.where(hit, np.clip(np.round((0.5 + 0.5 * s / radius) * 254) + 1, 1, 255), 0)
            if progress is not None:
                progress("impostor", j * frames + i + 1, frames * frames)
    return Impostor(colour, normal, depth, frames, hemi, centre, radius, renderer_name())
