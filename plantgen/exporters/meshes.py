"""Write one tessellated mesh (GS, GS+R) in any mesh format: :func:`export_mesh`.

The format follows the file suffix (:mod:`plantgen.exporters.formats`): glTF (``.glb``,
``.gltf`` + ``.bin``) and OBJ (+ ``.mtl``) through plantgen's writers, keeping material
names, colours, normals and texture coordinates; PLY (normals) and STL (triangles only)
through trimesh; USD through usd-core. Each format's row names its writer
(:data:`~plantgen.exporters.formats.EXPORT_FORMATS`), called the same way for every format
(:class:`~plantgen.exporters.plants.MeshWriter`). A plant's leaves (a grammar's ``{ . }`` polygons)
go with it in every mesh format (see each writer; PLY and STL add them as plain
triangles after the frusta's). ``up`` (default: the format's convention) turns the
model. Every writer writes under temporary names and renames, so a failed export leaves
nothing half-written.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..files import check_finite, write_atomically
from ..geometry.meshes.mesh import TessellatedMesh
from ..geometry.meshes.polygons import Polygons
from ..geometry.skeletons.skeleton import Skeleton
from .formats import ExportError, writable_format
from .plants import (
    Colours,
    MeshWriter,
    Plant,
    Progress,
    SceneExtras,
    leaf_parts,
    merged_materials,
    single_plant,
    turned_mesh,
)
from .sway import Timeline
from .textures import Textures, bake_textures

__all__ = ["export_mesh", "write_plants", "write_ply", "write_stl"]


def _write_trimesh(plants: list[Plant], path: str | Path, up: str, encode) -> list[Path]:
    """The one plant of ``plants`` as a trimesh mesh with its vertex normals, its leaves
    after the frusta as plain triangles (their vertices, normals and faces after the
    mesh's), written as ``encode(trimesh.exchange, mesh)``."""
    plant = single_plant(plants, path)
    import trimesh  # here, not at the top: importing trimesh takes about a second

    mesh = plant.mesh
    vertices, normals = turned_mesh(mesh, up)
    faces = [mesh.faces]
    vertex_list, normal_list, first = [vertices], [normals], len(vertices)
    for part in leaf_parts(plant.leaves, up):
        vertex_list.append(part.vertices)
        normal_list.append(part.normals)
        faces.append(part.faces + first)
        first += len(part.vertices)
    if len(faces) > 1:
        vertices, normals = np.concatenate(vertex_list), np.concatenate(normal_list)
    whole = trimesh.Trimesh(vertices, np.concatenate(faces) if len(faces) > 1 else mesh.faces,
                            vertex_normals=normals, process=False, validate=False)
    data = encode(trimesh.exchange, whole)
    return [write_atomically(Path(path), lambda tmp: Path(tmp).write_bytes(data), ExportError)]


def write_ply(plants: list[Plant], path: str | Path, *, up: str = "z", colours: Colours = None,
              instancing: str = "off", unit: float = 1.0, name: str | None = None,
              progress: Progress = None, animation: Timeline | None = None,
              extras: SceneExtras | None = None, textures: Textures | None = None) -> list[Path]:
    """Binary PLY with vertex normals through trimesh: the one plant of ``plants`` in place,
    its leaves as plain triangles after the frusta (a
    :class:`~plantgen.exporters.plants.MeshWriter`; PLY keeps no materials, names or units)."""
    return _write_trimesh(plants, path, up, lambda exchange, whole: exchange.ply.export_ply(
        whole, encoding="binary", vertex_normal=True))


def write_stl(plants: list[Plant], path: str | Path, *, up: str = "z", colours: Colours = None,
              instancing: str = "off", unit: float = 1.0, name: str | None = None,
              progress: Progress = None, animation: Timeline | None = None,
              extras: SceneExtras | None = None, textures: Textures | None = None) -> list[Path]:
    """Binary STL (triangles only) through trimesh: the one plant of ``plants`` in place,
    its leaves as plain triangles after the frusta (a
    :class:`~plantgen.exporters.plants.MeshWriter`; STL keeps no materials, names or units)."""
    return _write_trimesh(plants, path, up, lambda exchange, whole: exchange.stl.export_stl(whole))


def write_plants(plants: list[Plant], path: str | Path, *, up: str | None = None, colours: Colours = None,
                 instancing: str = "nodes", unit: float = 1.0, name: str | None = None,
                 progress: Progress = None, animation: Timeline | None = None,
                 extras: SceneExtras | None = None, textures: Textures | None = None) -> list[Path]:
    """Write ``plants`` (see :class:`~plantgen.exporters.plants.Plant`) in the mesh format
    ``path`` names, with the writer its row names
    (:data:`~plantgen.exporters.formats.EXPORT_FORMATS`); ``name`` names the scene (default:
    the file's stem). Formats without instancing take one plant written in place; formats
    with animation write the sway of the plants that have one at the key times
    ``animation`` (the others ignore it); ``extras``: a scene's camera, light and ground
    (:class:`~plantgen.exporters.plants.SceneExtras`), written by glTF and USD; ``textures``:
    the relief's maps (:func:`~plantgen.exporters.textures.bake_textures`), written by glTF,
    OBJ and USD (PLY and STL have no place for them). Returns
    the written paths (a ``.gltf`` or ``.obj`` brings a second file)."""
    path = Path(path)
    fmt = writable_format(path, "mesh")
    if not any(p.mesh is not None and len(p.mesh.faces) for p in plants):
        raise ExportError(f"{path}: nothing to export (the model has no segments)")
    def scaled(values):     # times the unit (a copy of every vertex) only where the unit scales
        return None if values is None else values * unit if unit != 1.0 else values
    for p in plants:        # no writer writes NaN or infinity
        check_finite(path, "a vertex", scaled(None if p.mesh is None else p.mesh.vertices), p.matrices,
                     scaled(None if p.leaves is None else p.leaves.vertices), error=ExportError)
    writer: MeshWriter = fmt.load_writer()
    plants = [merged_materials(p) for p in plants]      # one material of each name
    return writer(plants, path, up=up or fmt.up, colours=colours, instancing=instancing, unit=unit, name=name,
                  progress=progress, animation=animation if fmt.animation else None, extras=extras,
                  textures=textures if fmt.textures else None)


def export_mesh(mesh: TessellatedMesh, path: str | os.PathLike, colours: Colours = None, *,
                up: str | None = None, name: str | None = None, labels=None, leaves: Polygons | None = None,
                textures: bool | Textures = False) -> Path:
    """Write ``mesh`` to ``path`` in the format its suffix names (.glb, .gltf, .obj, .ply,
    .stl, .usda, .usdc, .usd).

    Parameters
    ----------
    mesh : the tessellation to write (coordinates in model units, y up)
    path : target file; written under a temporary name beside it, then renamed (a
        ``.gltf``'s ``.bin`` and an ``.obj``'s ``.mtl`` are written beside it too)
    colours : material name -> linear RGB in [0, 1], or one colour per material index;
        default :func:`plantgen.geometry.skeletons.materials.material_colour`
    up : ``"y"`` or ``"z"``; default the format's convention (:mod:`plantgen.exporters.formats`)
    name : the model's name in the file (default: the file's stem)
    labels : {name: (rows,) values} per mesh row, written by glTF as vertex attributes of
        those names (start them with ``_``; other formats ignore them)
    leaves : the model's leaf polygons (a grammar's ``GrowResult.polygons``), written beside
        the mesh as every format writes a grammar's leaves; None: none
    textures : True: bake the relief's maps from ``mesh`` (not displaced: GS) and write them
        where the format holds them; or the maps (:func:`~plantgen.exporters.textures.
        bake_textures`); False: none

    Returns
    -------
    Path : the written file
    """
    path = Path(path)
    plant = Plant(name or path.name.split(".")[0] or "plant", Skeleton.empty(mesh.material_names), mesh,
                  labels=labels, leaves=leaves if leaves is not None and len(leaves) else None)
    if textures is True:
        textures = bake_textures([mesh]) if writable_format(path, "mesh").textures else None
    return write_plants([plant], path, up=up, colours=colours, textures=textures or None)[-1]
