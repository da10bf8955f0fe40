"""Instanced plants: one set of frusta per distinct plant, a similarity transform per copy,
and the level of detail that follows the pixel.

A forest repeats a few grown plants many times. :class:`PlacedPlants` keeps each distinct
plant's frusta once, in its own frame, with the (k, 4, 4) placements of its k copies; the
renderers (:mod:`plantgen.gl.raycast`, :mod:`plantgen.gl.raster`) draw every copy from the
one record set or mesh, so memory grows with the distinct plants, not the drawn ones.

Level of detail: each plant's rows are sorted once (:func:`detail_order`) so that any
prefix is "every row whose subtree is at least this large": a row's *detail size* is the
largest diameter (:func:`row_spheres`) of the rows of its segment's subtree, so sizes never
grow from parent to child, and the sort (descending, stable, parents first) keeps every
prefix closed under parents. Per copy, :func:`detail_counts` draws the prefix of rows whose
detail size, seen from the copy's nearest point, spans at least the threshold in pixels:
a row left out spans fewer (its projected size is bounded by its diameter over the copy's
nearest distance, times the camera's largest pixels per radian).

:class:`PlacedMeshes` is the same for the raster renderer: each plant tessellated once,
its faces sorted by row so that a prefix of rows is a prefix of faces.

Pure numpy: no GL, no CLI.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..meshes.mesh import tessellate
from ..skeletons.frusta import ROW_FIELDS, Frusta, frusta_bounds, row_end_balls
from ..vec import reduce_to_root

__all__ = ["PlacedPlants", "PlantCopies", "PlacedMesh", "PlacedMeshes", "place_frusta", "row_spheres",
           "detail_sizes", "detail_order", "detail_counts", "detail_levels", "screen_coverage", "similarity_parts",
           "pixels_per_radian"]


def similarity_parts(matrices) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(k, 4, 4) similarity transforms as (rotation (k, 3, 3), scale (k,), translation (k, 3)),
    float64: ``M x = scale · rotation · x + translation``. A copy that scales by 0 has no
    rotation (NaN, without a floating-point warning): its users refuse it in one line."""
    m = np.asarray(matrices, dtype=np.float64).reshape(-1, 4, 4)
    scale = np.cbrt(np.abs(np.linalg.det(m[:, :3, :3])))
    turn = np.divide(m[:, :3, :3], scale[:, None, None], out=np.full((len(m), 3, 3), np.nan),
                     where=scale[:, None, None] > 0)
    return turn, scale, m[:, :3, 3].copy()


def place_frusta(frusta: Frusta, matrix) -> Frusta:
    """``frusta`` moved by the similarity ``matrix`` (4, 4), in float64: points and
    directions turned, lengths, radii and shells scaled, planes carried along (the
    instanced renderers' transform, done on the CPU; the merged reference)."""
    turn, scale, shift = (p[0] for p in similarity_parts(matrix))
    kw = {f: getattr(frusta, f) for f in ROW_FIELDS}
    planes = {}
    for name in ("plane_lo", "plane_hi"):
        plane = getattr(frusta, name)
        normal = plane[:, :3] @ turn.T
        planes[name] = np.concatenate([normal, (scale * plane[:, 3] + normal @ shift)[:, None]], axis=1)
    kw.update(base=scale * frusta.base @ turn.T + shift, axis=frusta.axis @ turn.T, ref_dir=frusta.ref_dir @ turn.T,
              length=scale * frusta.length, r1=scale * frusta.r1, r2=scale * frusta.r2, shell=scale * frusta.shell,
              **planes)
    return Frusta(**kw, material_names=frusta.material_names, parent_row=frusta.parent_row)


def row_spheres(frusta: Frusta) -> tuple[np.ndarray, np.ndarray]:
    """(centres (n, 3), radii (n,)): a ball around each row, relief shell and oblique
    end sections included (the smallest ball around the two end balls of
    :func:`plantgen.geometry.skeletons.frusta.frusta_bounds`)."""
    (c_lo, r_lo), (c_hi, r_hi) = row_end_balls(frusta)
    half = 0.5 * np.linalg.norm(c_hi - c_lo, axis=1)
    radius = np.maximum(half + np.maximum(r_lo, r_hi), np.maximum(r_lo, r_hi))
    return 0.5 * (c_lo + c_hi), radius


def detail_sizes(frusta: Frusta, segment_parent) -> np.ndarray:
    """(n,) float64 world units: each row's detail size, the largest diameter
    (:func:`row_spheres`) of any row of its segment's subtree (``segment_parent`` (m,) the
    skeleton's parents, -1 for roots): never larger on a child than on its parent."""
    parent = np.asarray(segment_parent, dtype=np.int64)
    diameter = 2.0 * row_spheres(frusta)[1]
    size = np.zeros(len(parent))
    np.maximum.at(size, frusta.segment, diameter)
    depth = reduce_to_root(parent, np.ones(len(parent), np.int64), np.add)
    for level in range(int(depth.max(initial=0)), 1, -1):     # deepest first: children into parents
        kids = np.flatnonzero(depth == level)
        np.maximum.at(size, parent[kids], size[kids])
    return size[frusta.segment]


def detail_order(frusta: Frusta, segment_parent) -> tuple[np.ndarray, np.ndarray]:
    """(order (n,) int, sizes (n,) float64): the row permutation by descending detail size
    (:func:`detail_sizes`; stable, so a parent row, which precedes its children and is at
    least as large, stays before them) and the sizes in that order (non-increasing)."""
    sizes = detail_sizes(frusta, segment_parent)
    order = np.argsort(-sizes, kind="stable")
    return order, sizes[order]


def pixels_per_radian(camera) -> float:
    """The most pixels one radian spans anywhere in ``camera``'s image: the focal length
    in pixels over cos² of the half diagonal field (a pinhole's image stretches towards
    its corners)."""
    tan_y = np.tan(np.radians(camera.fov_y) / 2)
    focal = camera.height / (2.0 * tan_y)
    tan_diag = tan_y * np.hypot(1.0, camera.aspect)
    return float(focal * (1.0 + tan_diag ** 2))


def detail_counts(sizes, copy_scale, copy_distance, pixels_per_radian: float, threshold: float) -> np.ndarray:
    """(k,) int: how many rows of a plant's detail order each copy draws.

    sizes : (n,) detail sizes, non-increasing (:func:`detail_order`), the plant's units
    copy_scale : (k,) each copy's scale
    copy_distance : (k,) the distance from the eye to each copy's bounding ball (0 when
        the eye is inside it: every row is drawn)
    pixels_per_radian : the camera's most pixels per radian (:func:`pixels_per_radian`)
    threshold : pixels; 0 draws every row

    A row is drawn when ``size · scale · pixels_per_radian / distance >= threshold``: a
    ball of diameter D whose nearest point lies at distance d or more subtends at most
    D / d radians, so a row left out spans fewer than ``threshold`` pixels.
    """
    sizes = np.asarray(sizes, dtype=np.float64)
    if threshold <= 0:
        return np.full(len(np.atleast_1d(copy_scale)), len(sizes), dtype=np.int64)
    distance = np.asarray(copy_distance, dtype=np.float64)
    with np.errstate(divide="ignore"):
        smallest = np.where(distance > 0, threshold * distance / (np.asarray(copy_scale) * pixels_per_radian), 0.0)
    # rows with size >= smallest: sizes are non-increasing, so count via the negated order
    return np.searchsorted(-sizes, -smallest, side="right").astype(np.int64)


def detail_levels(sizes, levels: int) -> tuple[np.ndarray, np.ndarray]:
    """(counts (L,) int, thresholds (L,) float64): the levels of detail an export writes
    for a plant whose detail sizes (:func:`detail_order`, non-increasing) are ``sizes``.

    Level 0 is every row (threshold 0). Level k keeps the prefix of rows whose detail size
    is above its threshold, the size of the first row past ``n / 2^j`` rows (j >= k: the
    next halving that drops rows), so each level holds at most half the rows of the one
    above it and every kept row's parent (a prefix of the detail order). Fewer than
    ``levels`` levels come back where the rows run out (a level must keep a row and drop
    one)."""
    sizes = np.asarray(sizes, dtype=np.float64)
    counts, thresholds = [len(sizes)], [0.0]
    target = len(sizes)
    while len(counts) < levels and target > 1:
        target //= 2
        size = float(sizes[target])
        count = int(np.searchsorted(-sizes, -size, side="left"))     # rows strictly larger
        if count == 0:
            break
        if count < counts[-1]:
            counts.append(count)
            thresholds.append(size)
    return np.asarray(counts, dtype=np.int64), np.asarray(thresholds)


def screen_coverage(thresholds, largest: float, diameter: float, pixels: float, height: int) -> np.ndarray:
    """(L,) MSFT_lod's screen coverage per level: below ``coverage[k]`` (the plant's
    bounding ball's projected diameter over the image's ``height`` pixels) an engine may
    draw level k + 1, whose dropped rows (detail size at most ``thresholds[k + 1]``) then
    span fewer than ``pixels`` pixels; below the last, even the ``largest`` row does (draw
    nothing, as the renderers do). A row of size s at distance d spans s·f/d pixels and
    the plant D·f/d, so the coverage is ``pixels · diameter / (s · height)``, capped at 1."""
    sizes = np.append(np.asarray(thresholds, dtype=np.float64)[1:], largest)
    return np.minimum(1.0, pixels * diameter / (np.maximum(sizes, 1e-300) * height))


@dataclass(frozen=True, eq=False)
class PlantCopies:
    """One distinct plant and its copies. ``frusta`` in the plant's frame, rows in detail
    order (:func:`detail_order`), materials indexing :attr:`PlacedPlants.material_names`;
    ``sizes`` (n,) their detail sizes; ``matrices`` (k, 4, 4) the copies' placements;
    ``centre`` (3,) and ``radius``: a ball around the plant in its frame."""

    name: str
    frusta: Frusta
    sizes: np.ndarray
    matrices: np.ndarray
    centre: np.ndarray
    radius: float

    def copy_balls(self) -> tuple[np.ndarray, np.ndarray]:
        """(centres (k, 3), radii (k,)): each copy's ball in world units."""
        turn, scale, shift = similarity_parts(self.matrices)
        return scale[:, None] * (turn @ self.centre) + shift, scale * self.radius


@dataclass(frozen=True, eq=False)
class PlacedPlants:
    """A scene's plants as the instanced renderers draw them: :class:`PlantCopies` per
    distinct plant, one material list. ``len()`` is the rows drawn at full detail (every
    copy's), :attr:`unique_rows` the rows stored. Frozen and compared by identity: the
    renderers upload it once and key the shadow map on it."""

    plants: tuple
    material_names: tuple
    box: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        boxes = []
        for plant in self.plants:
            centres, radii = plant.copy_balls()
            boxes += [centres - radii[:, None], centres + radii[:, None]]
        points = np.concatenate(boxes) if boxes else np.zeros((1, 3))
        object.__setattr__(self, "box", np.stack([points.min(axis=0), points.max(axis=0)]))

    def __len__(self) -> int:
        return sum(len(p.frusta) * len(p.matrices) for p in self.plants)

    @property
    def unique_rows(self) -> int:
        return sum(len(p.frusta) for p in self.plants)

    @property
    def copies(self) -> int:
        return sum(len(p.matrices) for p in self.plants)

    @classmethod
    def build(cls, plants) -> PlacedPlants:
        """From ``plants``: (name, local Frusta, segment parents (m,), matrices (k, 4, 4))
        each; rows sorted into detail order, materials merged (first appearance order)."""
        names: list[str] = []
        for _, frusta, _, _ in plants:
            names += [m for m in frusta.material_names if m not in names]
        out = []
        for name, frusta, parent, matrices in plants:
            order, sizes = detail_order(frusta, parent)
            remap = np.array([names.index(m) for m in frusta.material_names], dtype=np.int32)
            ordered = frusta.subset(order)
            rows = {f: getattr(ordered, f) for f in ROW_FIELDS}
            rows["material"] = remap[ordered.material] if len(ordered) else ordered.material
            local = Frusta(**rows, material_names=tuple(names), parent_row=ordered.parent_row)
            box = frusta_bounds(local)
            centre = 0.5 * (box[0] + box[1])
            out.append(PlantCopies(name, local, sizes, np.asarray(matrices, np.float64).reshape(-1, 4, 4),
                                   centre, float(0.5 * np.linalg.norm(box[1] - box[0]))))
        return cls(tuple(out), tuple(names))

    def merged(self) -> Frusta:
        """Every copy's rows placed in world units (float64) as one Frusta, plant by plant,
        copy by copy: what the instanced draw shows, for the merged path and the tests."""
        parts = [place_frusta(p.frusta, m) for p in self.plants for m in p.matrices]
        return Frusta.concatenate(parts) if parts else Frusta.empty(self.material_names)


@dataclass(frozen=True, eq=False)
class PlacedMesh:
    """One distinct plant's tessellation for the instanced raster renderer: ``mesh`` in the
    plant's frame, its faces sorted by row (stable) so that the faces of the first r rows
    of the detail order are the first ``row_faces[r]`` faces; ``face_row`` (F,) their rows."""

    mesh: object
    faces: np.ndarray
    face_row: np.ndarray
    row_faces: np.ndarray


@dataclass(frozen=True, eq=False)
class PlacedMeshes:
    """A :class:`PlacedPlants` tessellated: a :class:`PlacedMesh` per plant (the GS twin of
    the ray caster's records per plant)."""

    placed: PlacedPlants
    meshes: tuple
    level: int

    @classmethod
    def tessellate(cls, placed: PlacedPlants, level: int, relief: bool = False) -> PlacedMeshes:
        """Each plant tessellated once (:func:`plantgen.geometry.meshes.mesh.tessellate`)."""
        out = []
        for plant in placed.plants:
            mesh = tessellate(plant.frusta, level, relief=relief)
            order = np.argsort(mesh.face_row, kind="stable")
            face_row = np.ascontiguousarray(mesh.face_row[order], dtype=np.int32)
            row_faces = np.searchsorted(face_row, np.arange(len(plant.frusta) + 1), side="left")
            out.append(PlacedMesh(mesh, np.ascontiguousarray(mesh.faces[order]), face_row, row_faces))
        return cls(placed, tuple(out), int(level))

    @property
    def triangles(self) -> int:
        """Triangles drawn at full detail (every copy's)."""
        return sum(len(m.faces) * len(p.matrices) for m, p in zip(self.meshes, self.placed.plants, strict=True))
