"""Drawing a :class:`~plantgen.geometry.rays.instances.PlacedPlants`: one GPU copy per distinct
plant, a few uniforms per placed copy.

Both renderers draw a forest the same way: per distinct plant one vertex array (the ray
caster's records, the raster renderer's mesh), then per copy that the view can see one
draw with the copy's placement in three uniforms (``copy_turn`` (mat3), ``copy_scale``,
``copy_offset`` = the copy's origin minus the render origin, formed in float64 here so a
copy far from the world's origin keeps float32's digits) and as many rows (or
triangles) as its level of detail asks for: a prefix of the plant's detail order
(:func:`plantgen.geometry.rays.instances.detail_counts`). Per copy 52 bytes cross to the GPU
per draw and nothing is stored there, so the GPU holds the distinct plants only.

Which copies: those whose ball meets the view's frustum (:func:`visible_copies`); in the
light's pass every copy (its window holds them all), its detail measured in the map's
texels, which do not move with the eye, so the kept shadow map stays right.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.rays.instances import PlacedPlants, PlantCopies, detail_counts, pixels_per_radian, similarity_parts

__all__ = ["CopyDraws", "copy_uniform_bytes", "visible_copies", "eye_copy_draws", "light_copy_draws",
           "draw_copies", "COPY_UNIFORM_BYTES", "IDENTITY_TURN", "IDENTITY_PLACEMENT"]

#: Bytes of one copy's placement as sent per draw: mat3 + float + vec3, float32.
COPY_UNIFORM_BYTES = 4 * (9 + 1 + 3)


@dataclass(frozen=True)
class CopyDraws:
    """The draws of one plant in one pass: ``copies`` (c,) the copies drawn, ``counts``
    (c,) the rows (prefix of the detail order) each draws, ``uniforms`` their
    (copy_turn, copy_scale, copy_offset) as float32 bytes."""

    copies: np.ndarray
    counts: np.ndarray
    uniforms: list

    @property
    def rows(self) -> int:
        return int(self.counts.sum())


def copy_uniform_bytes(plant: PlantCopies, copies, origin, local_origin=None) -> list:
    """[(turn, scale, offset) float32 bytes] of ``copies`` (c,) of ``plant``: the mat3
    column-major, the offset = the placed ``local_origin`` (3,) (the point of the plant's
    frame its uploaded positions are relative to; default its origin) - ``origin`` (3,),
    formed in float64."""
    turn, scale, shift = similarity_parts(plant.matrices[copies])
    if local_origin is not None:
        shift = shift + scale[:, None] * (turn @ np.asarray(local_origin, dtype=np.float64))
    offset = shift - np.asarray(origin, dtype=np.float64)
    columns = np.ascontiguousarray(np.transpose(turn, (0, 2, 1)), dtype=np.float32)
    return [(columns[i].tobytes(), np.float32(scale[i]).tobytes(), offset[i].astype(np.float32).tobytes())
            for i in range(len(copies))]


def visible_copies(centres, radii, view) -> np.ndarray:
    """(k,) bool: the copies whose balls (``centres`` (k, 3) world, ``radii`` (k,)) meet
    ``view``'s (a :class:`~plantgen.gl.frame.FrameView`) frustum, its far plane aside."""
    rel = np.asarray(centres, dtype=np.float64) - view.eye
    x, y, z = rel @ view.right, rel @ view.up, rel @ view.forward
    tan_y = np.tan(np.radians(view.camera.fov_y) / 2)
    tan_x = tan_y * view.camera.aspect
    inside = z > view.near - radii
    for offset, tan in ((x, tan_x), (y, tan_y)):
        inside &= np.abs(offset) - z * tan <= radii * np.sqrt(1.0 + tan * tan)
    return inside


def eye_copy_draws(placed: PlacedPlants, view, lod_pixels: float, local_origins=None) -> list[CopyDraws]:
    """Per plant the :class:`CopyDraws` of the eye's pass: the copies ``view`` can see, each
    drawing the rows whose detail spans at least ``lod_pixels`` pixels (0: all);
    ``local_origins``: per plant the point its uploaded positions are relative to."""
    out = []
    ppr = pixels_per_radian(view.camera)
    for k, plant in enumerate(placed.plants):
        centres, radii = plant.copy_balls()
        seen = np.flatnonzero(visible_copies(centres, radii, view))
        distance = np.maximum(np.linalg.norm(centres[seen] - view.eye, axis=1) - radii[seen], 0.0)
        scale = similarity_parts(plant.matrices[seen])[1]
        counts = detail_counts(plant.sizes, scale, distance, ppr, lod_pixels)
        keep = counts > 0
        seen, counts = seen[keep], counts[keep]
        local = None if local_origins is None else local_origins[k]
        out.append(CopyDraws(seen, counts, copy_uniform_bytes(plant, seen, view.eye, local)))
    return out


def light_copy_draws(placed: PlacedPlants, anchor, texel: float, lod_pixels: float,
                     local_origins=None) -> list[CopyDraws]:
    """Per plant the :class:`CopyDraws` of the light's pass (relative to ``anchor``): every
    copy, drawing the rows whose detail spans at least ``lod_pixels`` texels of ``texel``
    world units (0: all). Independent of the eye."""
    out = []
    for k, plant in enumerate(placed.plants):
        copies = np.arange(len(plant.matrices))
        scale = similarity_parts(plant.matrices)[1]
        counts = detail_counts(plant.sizes, scale, np.full(len(copies), texel), 1.0, lod_pixels)
        keep = counts > 0
        copies, counts = copies[keep], counts[keep]
        local = None if local_origins is None else local_origins[k]
        out.append(CopyDraws(copies, counts, copy_uniform_bytes(plant, copies, anchor, local)))
    return out


def draw_copies(program, vao, draws: CopyDraws, render, offset_name: str = "copy_offset") -> None:
    """Draw ``draws`` through ``vao``: per copy its uniforms written into ``program`` (the
    offset into ``offset_name``), then ``render(vao, count)``."""
    turn, scale, offset = program["copy_turn"], program["copy_scale"], program[offset_name]
    for (t, s, o), count in zip(draws.uniforms, draws.counts.tolist(), strict=True):
        turn.write(t)
        scale.write(s)
        offset.write(o)
        render(vao, count)


#: The identity turn and scale: what a merged draw sets (exact in float32).
IDENTITY_TURN = {"copy_turn": tuple(np.eye(3, dtype=np.float32).ravel().tolist()), "copy_scale": 1.0}
#: The ray caster's identity placement (its offset too).
IDENTITY_PLACEMENT = {**IDENTITY_TURN, "copy_offset": (0.0, 0.0, 0.0)}
