"""Write one tessellated mesh (GS, GS+R) in any mesh format: :func:`export_mesh`.

The format follows the file suffix (:mod:`plantgen.exporters.formats`): glTF (``.glb``,
``.gltf`` + ``.bin``) and OBJ (+ ``.mtl``) through plantgen's writers, keeping material
names, colours, normals and texture coordinates; PLY (normals) and STL (triangles only)
through trimesh; USD through usd-core. A plant's leaves (a grammar's ``{ . }`` polygons)
go with it in every mesh format (see each writer; PLY and STL add them as plain
triangles after the frusta's). ``up`` (default: the format's convention) turns the
model. Every writer writes under temporary names and renames, so a failed export leaves
nothing half-written.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..files import write_atomically
from ..geometry.mesh import TessellatedMesh
from ..geometry.polygons import Polygons
from ..geometry.skeleton import Skeleton
from .formats import ExportError, check_extra, export_format
from .plants import Colours, Plant, Progress, leaf_parts, turned_mesh

__all__ = ["export_mesh", "write_plants", "write_trimesh"]


def write_trimesh(mesh: TessellatedMesh, path: str | Path, *, up: str, leaves: Polygons | None = None) -> Path:
    """Binary PLY (with vertex normals) or binary STL through trimesh; ``leaves`` follow the
    frusta as plain triangles (their vertices, normals and faces after the mesh's)."""
    import trimesh  # here, not at the top: importing trimesh takes about a second

    path = Path(path)
    vertices, normals = turned_mesh(mesh, up)
    faces = [mesh.faces]
    vertex_list, normal_list, first = [vertices], [normals], len(vertices)
    for part in leaf_parts(leaves, up):
        vertex_list.append(part.vertices)
        normal_list.append(part.normals)
        faces.append(part.faces + first)
        first += len(part.vertices)
    if len(faces) > 1:
        vertices, normals = np.concatenate(vertex_list), np.concatenate(normal_list)
    whole = trimesh.Trimesh(vertices, np.concatenate(faces) if len(faces) > 1 else mesh.faces,
                            vertex_normals=normals, process=False, validate=False)
    if path.suffix.lower() == ".ply":
        data = trimesh.exchange.ply.export_ply(whole, encoding="binary", vertex_normal=True)
    else:
        data = trimesh.exchange.stl.export_stl(whole)
    return write_atomically(path, lambda tmp: Path(tmp).write_bytes(data), ExportError)


def write_plants(plants: list[Plant], path: str | Path, *, up: str | None = None, colours: Colours = None,
                 instancing: str = "gpu", unit: float = 1.0, name: str | None = None,
                 progress: Progress = None) -> list[Path]:
    """Write ``plants`` (see :class:`~plantgen.exporters.plants.Plant`) in the mesh format
    ``path`` names; ``name`` names the scene (default: the file's stem). Formats without
    instancing take one plant written in place. Returns the written paths (a ``.gltf`` or
    ``.obj`` brings a second file)."""
    path = Path(path)
    fmt = export_format(path)
    if fmt.kind != "mesh":
        raise ExportError(f"{path}: {fmt.suffix} holds a skeleton, not a mesh")
    check_extra(fmt, path)
    if not path.parent.is_dir():
        raise ExportError(f"{path}: directory {path.parent} does not exist")
    up = up or fmt.up
    if not any(p.mesh is not None and len(p.mesh.faces) for p in plants):
        raise ExportError(f"{path}: nothing to export (the model has no segments)")
    if fmt.name in ("glb", "gltf"):
        from .gltf import write_gltf
        return write_gltf(plants, path, up=up, colours=colours, instancing=instancing, name=name,
                          progress=progress)
    if fmt.name.startswith("usd"):
        from .usd import write_usd
        return write_usd(plants, path, up=up, colours=colours, instancing=instancing, unit=unit, name=name,
                         progress=progress)
    if len(plants) != 1 or plants[0].matrices is not None:
        raise ExportError(f"{path}: {fmt.suffix} holds one mesh in place; flatten the scene first")
    if fmt.name == "obj":
        from .obj import write_obj
        return write_obj(plants[0].mesh, path, up=up, colours=colours, progress=progress, leaves=plants[0].leaves)
    return [write_trimesh(plants[0].mesh, path, up=up, leaves=plants[0].leaves)]


def export_mesh(mesh: TessellatedMesh, path: str | os.PathLike, colours: Colours = None, *,
                up: str | None = None, name: str | None = None, labels=None, leaves: Polygons | None = None) -> Path:
    """Write ``mesh`` to ``path`` in the format its suffix names (.glb, .gltf, .obj, .ply,
    .stl, .usda, .usdc, .usd).

    Parameters
    ----------
    mesh : the tessellation to write (coordinates in model units, y up)
    path : target file; written under a temporary name beside it, then renamed (a
        ``.gltf``'s ``.bin`` and an ``.obj``'s ``.mtl`` are written beside it too)
    colours : material name -> linear RGB in [0, 1], or one colour per material index;
        default :func:`plantgen.geometry.materials.material_colour`
    up : ``"y"`` or ``"z"``; default the format's convention (:mod:`plantgen.exporters.formats`)
    name : the model's name in the file (default: the file's stem)
    labels : {name: (rows,) values} per mesh row, written by glTF as vertex attributes of
        those names (start them with ``_``; other formats ignore them)
    leaves : the model's leaf polygons (a grammar's ``GrowResult.polygons``), written beside
        the mesh as every format writes a grammar's leaves; None: none

    Returns
    -------
    Path : the written file
    """
    path = Path(path)
    plant = Plant(name or path.name.split(".")[0] or "plant", Skeleton.empty(mesh.material_names), mesh,
                  labels=labels, leaves=leaves if leaves is not None and len(leaves) else None)
    return write_plants([plant], path, up=up, colours=colours)[-1]
