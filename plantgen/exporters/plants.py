"""What the writers take: plants (a mesh and a skeleton in the plant's own frame, and
where its copies stand), material colours, and meshes split by material."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Protocol

import numpy as np

from ..geometry.meshes.impostor import Impostor
from ..geometry.meshes.leaf_cards import LeafCards
from ..geometry.meshes.mesh import TessellatedMesh
from ..geometry.meshes.polygons import Polygons
from ..geometry.meshes.textures import bake_base_colour, linear_to_srgb
from ..geometry.rays.camera import Camera
from ..geometry.skeletons.frames import up_rotation
from ..geometry.skeletons.materials import leaf_colours, leaf_tones, material_colour
from ..geometry.skeletons.skeleton import Skeleton
from ..geometry.stage import Ground, Light
from ..geometry.vec import by_rows
from .formats import ExportError, export_format
from .sway import PlantSway, Timeline

__all__ = ["Colours", "DetailLevel", "MeshWriter", "PlantDetail", "Part", "Plant", "Progress", "SceneExtras",
           "SkeletonWriter", "camera_pose", "GROUND_TEXEL", "GROUND_TEXTURE_SIDES",
           "ground_colour", "ground_mesh", "ground_texture", "ground_uv", "leaf_name", "leaf_parts",
           "leaf_subset",
           "leaf_uv", "level_plant", "light_rotation", "material_colours", "material_parts", "merged_materials",
           "single_plant", "turned_mesh"]

#: Material name -> linear RGB in [0, 1], or one colour per material index, or None (the
#: renderers' palette).
Colours = Mapping[str, Sequence[float]] | Sequence | None
#: ``progress(stage, done, total)``: a writer reports its steps (may be None).
Progress = Callable[[str, int, int], None] | None


@dataclass(frozen=True, eq=False)
class DetailLevel:
    """One level of detail of a plant: ``rows`` (r,) the mesh rows it keeps (ascending; a
    prefix of the detail order, :func:`~plantgen.geometry.rays.instances.detail_levels`, so
    every kept row's parent is kept), ``mesh`` their tessellation (its row i is the plant
    mesh's row ``rows[i]``; chains cut where a child is dropped are capped), ``leaves`` (p,)
    the leaf polygons it keeps (those hanging from a kept segment) and ``size``: the kept
    rows' detail sizes are above it (0: every row)."""

    rows: np.ndarray
    mesh: TessellatedMesh
    leaves: np.ndarray
    size: float


@dataclass(frozen=True, eq=False)
class PlantDetail:
    """A plant's levels of detail, level 0 (every row) first, and ``coverage`` (L,): the
    screen coverage (projected bounding diameter over the image height) below which level
    k + 1 may stand in for level k (the last: below it the plant may be left out);
    :func:`~plantgen.geometry.rays.instances.screen_coverage`."""

    levels: tuple
    coverage: np.ndarray


@dataclass(frozen=True, eq=False)
class Plant:
    """One plant of an export.

    ``mesh`` (None for the skeleton formats) and ``skeleton`` lie in the plant's own
    frame; ``matrices`` (k, 4, 4) places its k copies (similarity transforms), or is None
    for a model written where it is (a grammar, a skeleton file, a scene flattened).
    ``leaves``: the grammar's filled polygons in the same frame, their material indices
    into ``mesh.material_names`` (None or empty: no leaves; written double-sided).
    ``sway``: how its copies sway (:class:`~plantgen.exporters.sway.PlantSway`), for the
    formats that write an animation; None: the plant stands still. ``detail``: its levels
    of detail (:class:`PlantDetail`), written by glTF and USD; None: the full mesh only.
    ``cards``: the leaves as cards (:class:`~plantgen.geometry.meshes.leaf_cards.LeafCards`, whose
    quads ``leaves`` then is; :func:`~plantgen.exporters.cards.card_plant`), written by glTF
    with their atlas; None: the leaves are polygons."""

    name: str
    skeleton: Skeleton
    mesh: TessellatedMesh | None = None
    matrices: np.ndarray | None = None
    labels: Mapping[str, np.ndarray] | None = None   # per mesh row, by attribute name (glTF)
    leaves: Polygons | None = None
    sway: PlantSway | None = None
    detail: PlantDetail | None = None
    cards: LeafCards | None = None     # ``leaves`` are these cards' quads (glTF: alpha-cut, MASK)
    impostor: Impostor | None = None   # glTF: the last level of detail (:mod:`plantgen.exporters.impostors`)

    @property
    def has_leaves(self) -> bool:
        return self.leaves is not None and len(self.leaves.triangles) > 0

    @property
    def copies(self) -> int:
        return 1 if self.matrices is None else len(self.matrices)


@dataclass(frozen=True)
class SceneExtras:
    """What a scene adds around its plants, written by the formats that hold it (glTF:
    a camera, ``KHR_lights_punctual``, a ground mesh; USD: ``Camera``, ``DistantLight``,
    a ground ``Mesh``), in the model's frame (y up; a writer turns them with the model).

    ``camera``: the view plantgen render would use (a scene's camera, or for ``camera:
    auto`` the model framed as the renderer frames it; its width and height give the
    aspect ratio); ``light``: the scene's directional light; ``ground``: its ground
    square. Each may be None (not written)."""

    camera: Camera | None = None
    light: Light | None = None
    ground: Ground | None = None


def camera_pose(camera: Camera, up: str = "y") -> tuple[np.ndarray, np.ndarray]:
    """The camera's eye (3,) and its rotation (3, 3) in the ``up`` frame, as glTF and USD
    place a camera: its columns the camera's right, up and back (it looks down its -z)."""
    rot = up_rotation(up)
    right, upward, forward = (np.asarray(v, np.float64) for v in camera.basis())
    return rot @ np.asarray(camera.eye, np.float64), rot @ np.stack([right, upward, -forward], axis=1)


def light_rotation(light: Light, up: str = "y") -> np.ndarray:
    """(3, 3) rotation whose -z column is the direction ``light`` travels, in the ``up``
    frame (glTF's and USD's directional lights shine down their -z)."""
    travel = up_rotation(up) @ np.asarray(light.travel, np.float64)
    back = -travel / np.linalg.norm(travel)
    helper = np.array([0.0, 1.0, 0.0]) if abs(back[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    helper = up_rotation(up) @ helper
    x = np.cross(helper, back)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(back, x), back], axis=1)


#: The rim vertices of an exported ground disc.
DISC_SIDES = 64


def ground_mesh(ground: Ground, up: str = "y") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ground's vertices (k, 3), unit normals (k, 3) and triangles (t, 3), facing up,
    in the ``up`` frame: a square's two triangles, or a disc's fan of :data:`DISC_SIDES`
    (its rim's polygon; the renderers' fade into the sky is the alpha of
    :func:`ground_texture`, which glTF writes)."""
    rot = up_rotation(up)
    if ground.shape == "disc":
        angle = np.linspace(0.0, 2 * np.pi, DISC_SIDES, endpoint=False)
        cx, cz = ground.centre
        rim = np.stack([cx + ground.half * np.cos(angle), np.full(DISC_SIDES, float(ground.height)),
                        cz - ground.half * np.sin(angle)], axis=1)
        vertices = np.concatenate([[[cx, float(ground.height), cz]], rim])
        k = np.arange(DISC_SIDES)
        faces = np.stack([np.zeros(DISC_SIDES, int), 1 + k, 1 + (k + 1) % DISC_SIDES], axis=1)
    else:
        vertices, faces = ground.quad(), np.array([[0, 1, 2], [2, 1, 3]])
    normals = np.tile(rot @ np.array([0.0, 1.0, 0.0]), (len(vertices), 1))
    return vertices @ rot.T, normals, faces


def ground_uv(vertices: np.ndarray) -> np.ndarray:
    """(k, 2) float32 texture coordinates of a ground's vertices (k, 3), y up: x and z
    scaled to [0, 1] over its extent (a square's corners get 0 and 1, a disc's rim its
    circle inscribed in the unit square), one per vertex."""
    horizontal = np.asarray(vertices, dtype=np.float64)[:, [0, 2]]
    lo, hi = horizontal.min(axis=0), horizontal.max(axis=0)
    return ((horizontal - lo) / np.where(hi > lo, hi - lo, 1.0)).astype(np.float32)


def ground_colour(ground: Ground, colours: Colours = None) -> tuple[float, float, float]:
    """The linear RGB of the ground's material: ``colours``' entry of its name where
    ``colours`` is a mapping, else plantgen's palette."""
    if isinstance(colours, Mapping):
        return material_colours([ground.material], colours)[0]
    return material_colours([ground.material])[0]


#: An exported ground texture's texel, at most, in world units (the mottle's waves are
#: about 2.4 units and longer), and its side's bounds in texels (a power of two).
GROUND_TEXEL = 0.25
GROUND_TEXTURE_SIDES = (64, 1024)


def ground_texture(ground: Ground, colours: Colours = None) -> np.ndarray:
    """(n, n, 4) uint8 RGBA: the ground as the renderers draw it, over its square (the
    disc's bounding square), row 0 at the square's -z edge and column 0 at its -x edge
    (:func:`ground_uv`'s v and u, y up). RGB: its albedo, sRGB, the material's dark and
    light colour mixed by the procedural mottle (:meth:`~plantgen.geometry.stage.Ground.mottle`),
    or ``colours``' flat colour where it names the ground's material; alpha (linear): its
    opacity, fading to 0 at its edge (:meth:`~plantgen.geometry.stage.Ground.opacity`), so
    the sky shows through its rim as in the renderers. ``n``: the power of two that keeps a
    texel within :data:`GROUND_TEXEL`, within :data:`GROUND_TEXTURE_SIDES`."""
    lo, hi = GROUND_TEXTURE_SIDES
    n = int(min(hi, max(lo, 2 ** int(np.ceil(np.log2(max(float(ground.size) / GROUND_TEXEL, 1.0)))))))
    t = (np.arange(n) + 0.5) / n
    x = ground.centre[0] - ground.half + 2 * ground.half * t[None, :]
    z = ground.centre[1] - ground.half + 2 * ground.half * t[:, None]
    x, z = np.broadcast_arrays(x, z)
    if isinstance(colours, Mapping) and ground.material in colours:
        rgb = linear_to_srgb(np.broadcast_to(ground_colour(ground, colours), (n, n, 3)))
    else:
        rgb = bake_base_colour(ground.material, ground.mottle(x, z))
    alpha = np.rint(255.0 * ground.opacity(x, z)).astype(np.uint8)
    return np.dstack([rgb, alpha])


class MeshWriter(Protocol):
    """How every mesh format's writer is called (:data:`~plantgen.exporters.formats.EXPORT_FORMATS`
    names it; :func:`~plantgen.exporters.meshes.write_plants` calls it, the arguments checked).

    Parameters
    ----------
    plants : the plants to write (:class:`Plant`); a format without instancing takes one
        plant in place (:func:`single_plant`)
    path : the file; its suffix is the format's
    up : ``"y"`` or ``"z"``
    colours : the material colours (:data:`Colours`)
    instancing : ``"nodes"`` or ``"gpu"``: how a scene's copies are written where the format can
    unit : metres per model unit, where the format records it (USD)
    name : the model's name in the file (None: the file's stem)
    progress : reports the writer's steps (:data:`Progress`)
    animation : the key times of the plants' sway (:class:`~plantgen.exporters.sway.Timeline`),
        written by the formats that animate (glTF, USD) for the plants with a ``sway``;
        None: no animation
    extras : a scene's camera, light and ground (:class:`SceneExtras`), written by the
        formats that hold them (glTF, USD; OBJ, PLY and STL hold the plants only); None: none
    textures : the relief's baked maps (:class:`~plantgen.exporters.textures.Textures`),
        given to the formats whose row says ``textures`` (glTF, OBJ, USD); None: none

    A writer ignores what its format has no place for. Returns the written paths, the
    main file last.
    """

    def __call__(self, plants: list[Plant], path: Path, *, up: str, colours: Colours, instancing: str,
                 unit: float, name: str | None, progress: Progress, animation: Timeline | None,
                 extras: SceneExtras | None, textures=None) -> list[Path]: ...


class SkeletonWriter(Protocol):
    """How every skeleton format's writer is called (:data:`~plantgen.exporters.formats.EXPORT_FORMATS`
    names it; :func:`~plantgen.exporters.skeletons.write_skeleton` calls it).

    Parameters
    ----------
    skeleton : the model's skeleton (a scene's plants together)
    path : the file; its suffix is the format's
    up : ``"y"`` or ``"z"``
    unit : metres per model unit, where the format records lengths in metres (QSM)
    tolerance : a cylinder model's volume tolerance (:mod:`plantgen.exporters.qsm`)
    name : the model's name, where the format records it

    A writer ignores what its format has no place for. Returns a summary: ``paths`` (the
    written files, the main one last) and what else the format reports.
    """

    def __call__(self, skeleton: Skeleton, path: Path, *, up: str, unit: float, tolerance: float,
                 name: str) -> dict: ...


def single_plant(plants: list[Plant], path: str | Path) -> Plant:
    """The one plant that a format without instancing (``path``'s) writes in place, or one
    line saying the scene must be flattened first."""
    if len(plants) != 1 or plants[0].matrices is not None:
        raise ExportError(f"{path}: {export_format(path).suffix} holds one mesh in place; flatten the scene first")
    return plants[0]


@dataclass(frozen=True, eq=False)
class Part:
    """The faces of one material of a mesh, with only the vertices they use."""

    material: int
    vertices: np.ndarray      # (v, 3) float64
    normals: np.ndarray       # (v, 3) float32, unit
    uv: np.ndarray            # (v, 2) float32
    faces: np.ndarray         # (f, 3) int, indices into this part's vertices
    labels: dict | None = None  # name -> (v,) float32 per vertex (from per-row labels)
    leaf: bool = False        # leaf polygons (double-sided where the format says so)
    joints: np.ndarray | None = None    # (v, 4) int, the joints each vertex follows (a swaying plant)
    weights: np.ndarray | None = None   # (v, 4) float, their weights (summing to 1)
    colours: np.ndarray | None = None   # (v, 3) float32 linear RGB per vertex (leaves: each leaf's shade)


def unique_name(base: str, taken) -> str:
    """``base``, or ``base_2``, ``base_3``, ... : the first not in ``taken``."""
    name, k = base, 1
    while name in taken:
        k += 1
        name = f"{base}_{k}"
    return name


def material_colours(names, colours: Colours = None) -> list[tuple[float, float, float]]:
    """Linear RGB of every material name (see :data:`Colours`)."""
    out = []
    for i, name in enumerate(names):
        if colours is None:
            c = material_colour(name)
        elif isinstance(colours, Mapping):
            c = colours.get(name, material_colour(name))
        else:
            c = colours[i]
        c = tuple(float(x) for x in c)
        if len(c) != 3 or not all(0.0 <= x <= 1.0 for x in c):
            raise ExportError(f"material {name!r}: colour must be three numbers in [0, 1], got {c}")
        out.append(c)
    return out


def turned_mesh(mesh: TessellatedMesh, up: str) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (float64) and unit normals (float32) of ``mesh`` in the ``up`` frame."""
    rot = up_rotation(up)

    def turned_normals(normals):         # row-wise: a block of rows at a time (by_rows)
        # einsum, not ``@``: a threaded BLAS matrix product of (n, 3) by (3, 3) crawls on busy cores
        normals = np.einsum("ij,kj->ik", normals.astype(np.float64), rot)
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
        return normals.astype(np.float32)
    return np.einsum("ij,kj->ik", mesh.vertices, rot), by_rows(turned_normals, mesh.normals)


def vertex_labels(mesh: TessellatedMesh, labels: Mapping[str, np.ndarray] | None) -> dict:
    """Per-row ``labels`` ({name: (rows,) values}) as per-vertex float32 arrays: each vertex
    takes the value of a row whose faces use it (a ring shared along a continuing chain
    lies on rows of one branch, so labels by branch agree there)."""
    out = {}
    for name, values in (labels or {}).items():
        values = np.asarray(values, dtype=np.float32)
        if values.shape != (mesh.n_rows,):
            raise ExportError(f"label {name}: {values.shape} values for {mesh.n_rows} mesh rows")
        per_vertex = np.zeros(len(mesh.vertices), dtype=np.float32)
        per_vertex[mesh.faces.ravel()] = np.repeat(values[mesh.face_row], 3)
        out[name] = per_vertex
    return out


def material_parts(mesh: TessellatedMesh, up: str = "y", labels: Mapping[str, np.ndarray] | None = None,
                   influences: tuple[np.ndarray, np.ndarray] | None = None) -> list[Part]:
    """One :class:`Part` per material the mesh uses, in material order; ``labels``: per-row
    values carried to the part's vertices (:func:`vertex_labels`); ``influences``: (joints,
    weights), each (v, 4), per mesh vertex, carried likewise (a swaying plant's skin)."""
    vertices, normals = turned_mesh(mesh, up)
    per_vertex = vertex_labels(mesh, labels)
    face_material = mesh.face_material
    used = np.unique(face_material)
    parts = []
    for mat in used:
        faces = mesh.faces if len(used) == 1 else mesh.faces[face_material == mat]
        keep, inverse = _used_vertices(faces, len(vertices))
        joints, weights = (None, None) if influences is None else (influences[0][keep], influences[1][keep])
        parts.append(Part(int(mat), vertices[keep], normals[keep], mesh.uv[keep].astype(np.float32),
                          inverse.reshape(faces.shape), {k: v[keep] for k, v in per_vertex.items()} or None,
                          joints=joints, weights=weights))
    return parts


def _used_vertices(faces: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """(keep, inverse): the vertices ``faces`` use, ascending, and the faces renumbered
    into them (``np.unique(faces, return_inverse=True)``, by a mask of ``count``
    vertices: linear, not a sort); where they use every vertex, ``keep`` is ``slice(None)``
    and ``inverse`` the faces (int64), so nothing is gathered or renumbered."""
    used = np.zeros(count, dtype=bool)
    used[faces.ravel()] = True
    if used.all():
        return slice(None), faces.astype(np.int64, copy=False).ravel()
    keep = np.flatnonzero(used)
    rank = np.cumsum(used, dtype=np.int64) - 1
    return keep, rank[faces.ravel()]


def leaf_name(material: str) -> str:
    """The name of the double-sided material leaves of ``material`` are written with."""
    return f"{material} (leaf)"


def leaf_uv(polygons: Polygons) -> np.ndarray:
    """(v, 2) float32 texture coordinates of the leaf vertices: each vertex's coordinates in
    its polygon's plane (u along ``normal × x``, or ``normal × y`` for a polygon facing
    ±x; v = normal × u), scaled so the polygon's bounding box spans [0, 1]² (a leaf texture
    fills the leaf)."""
    owner = np.zeros(len(polygons.vertices), dtype=np.int64)
    owner[polygons.triangles] = polygons.polygon[:, None]
    normal = polygons.normal[owner]
    helper = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(normal, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(normal, e1)
    uv = np.stack([np.einsum("ij,ij->i", polygons.vertices, e1), np.einsum("ij,ij->i", polygons.vertices, e2)], 1)
    lo = np.full((len(polygons), 2), np.inf)
    hi = np.full((len(polygons), 2), -np.inf)
    np.minimum.at(lo, owner, uv)
    np.maximum.at(hi, owner, uv)
    return ((uv - lo[owner]) / np.maximum(hi - lo, 1e-30)[owner]).astype(np.float32)


def leaf_parts(polygons: Polygons | None, up: str = "y", joints: np.ndarray | None = None,
               names=None, uv: np.ndarray | None = None) -> list[Part]:
    """One leaf :class:`Part` per material the polygons use, in material order: each vertex
    (a polygon's own) takes its polygon's unit normal and :func:`leaf_uv`; ``leaf`` is set.
    ``joints``: (v,) the one joint each leaf vertex follows (a swaying plant's skin);
    ``names``: the material names, to give each vertex its leaf's colour (``colours``: the
    renderers' shade of that leaf, :func:`~plantgen.geometry.skeletons.materials.leaf_colours`);
    ``uv``: (v, 2) the vertices' texture coordinates (a card's in its atlas) in place of
    :func:`leaf_uv`."""
    if polygons is None or len(polygons.triangles) == 0:
        return []
    rot = up_rotation(up)
    vertices = polygons.vertices @ rot.T
    per_vertex = np.zeros_like(polygons.vertices)
    per_vertex[polygons.triangles] = polygons.normal[polygons.polygon][:, None, :]
    normals = (per_vertex @ rot.T).astype(np.float32)
    uv = leaf_uv(polygons) if uv is None else np.asarray(uv, np.float32)
    shade = None
    if names is not None:
        owner = polygons.vertex_polygon
        shade = leaf_colours(names, polygons.material[owner], leaf_tones(len(polygons))[owner]).astype(np.float32)
    triangle_material = polygons.triangle_material
    parts = []
    for mat in np.unique(triangle_material):
        faces = polygons.triangles[triangle_material == mat]
        keep, inverse = _used_vertices(faces, len(vertices))
        skin = {}
        if joints is not None:
            kept = len(vertices) if isinstance(keep, slice) else len(keep)
            skin["joints"] = np.zeros((kept, 4), np.int64)
            skin["joints"][:, 0] = joints[keep]
            skin["weights"] = np.zeros((kept, 4))
            skin["weights"][:, 0] = 1.0
        parts.append(Part(int(mat), vertices[keep], normals[keep], uv[keep], inverse.reshape(faces.shape),
                          leaf=True, colours=None if shade is None else shade[keep], **skin))
    return parts


def merged_materials(plant: Plant) -> Plant:
    """``plant`` with its materials of one name made one (a grammar's ``'`` steps through
    its material list, which may name a material many times: ``[bark, bark, stem, leaf,
    leaf, ...]``): names kept in order of first appearance, the mesh rows' and leaves'
    indices mapped onto them. A plant whose names are distinct comes back as it is."""
    if plant.mesh is None:
        return plant
    names = plant.mesh.material_names
    unique = tuple(dict.fromkeys(names))
    if len(unique) == len(names):
        return plant
    index = np.array([unique.index(n) for n in names], dtype=np.int32)
    mesh = replace(plant.mesh, material=index[plant.mesh.material], material_names=unique)
    leaves = plant.leaves if plant.leaves is None else replace(plant.leaves, material=index[plant.leaves.material])
    return replace(plant, mesh=mesh, leaves=leaves)


def leaf_subset(polygons: Polygons, keep) -> Polygons:
    """The polygons ``keep`` ((p,) int) of ``polygons``, with only the vertices they use."""
    keep = np.asarray(keep, dtype=np.int64)
    renumber = np.full(len(polygons), -1, dtype=np.int64)
    renumber[keep] = np.arange(len(keep))
    triangles = np.flatnonzero(renumber[polygons.polygon] >= 0)
    used, inverse = np.unique(polygons.triangles[triangles], return_inverse=True)
    return Polygons(polygons.vertices[used], inverse.reshape(-1, 3), renumber[polygons.polygon[triangles]],
                    polygons.material[keep], polygons.normal[keep], polygons.segment[keep])


def level_plant(plant: Plant, level: int) -> Plant:
    """``plant`` at its level of detail ``level`` (0: itself): the level's mesh, its rows'
    materials and labels taken from the plant's mesh (so a renaming of the plant's
    materials holds for every level), the leaves it keeps and its sway's rows' segments
    (so a level's rig follows the same joints: :func:`~plantgen.exporters.sway.level_rigs`);
    no levels of its own."""
    if level == 0 or plant.detail is None:
        return plant
    lod = plant.detail.levels[level]
    mesh = replace(lod.mesh, material=plant.mesh.material[lod.rows], material_names=plant.mesh.material_names)
    labels = None if plant.labels is None else {k: np.asarray(v)[lod.rows] for k, v in plant.labels.items()}
    leaves = None if not plant.has_leaves or not len(lod.leaves) else leaf_subset(plant.leaves, lod.leaves)
    sway = None if plant.sway is None else replace(plant.sway, row_segment=plant.sway.row_segment[lod.rows])
    cards = None if plant.cards is None or leaves is None else plant.cards.subset(lod.leaves)
    return replace(plant, mesh=mesh, labels=labels, leaves=leaves, sway=sway, detail=None, cards=cards)
