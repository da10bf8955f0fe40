"""Write tessellated meshes (GS, GS+R) as glTF binary, OBJ, PLY or STL through trimesh.

The format follows the file suffix. glTF keeps one primitive per material with its base
colour, the vertex normals (8) and the texture coordinates; OBJ keeps normals and
texture coordinates; PLY keeps normals; STL keeps triangles only. Every writer writes to
a temporary name beside the target and renames it, so a failed export leaves nothing
half-written.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from .errors import PlantgenError
from .files import write_atomically
from .geometry.materials import material_colour
from .geometry.mesh import TessellatedMesh

__all__ = ["EXPORT_FORMATS", "ExportError", "estimate_export_bytes", "export_mesh", "export_file_type",
           "mesh_scene"]

#: File suffix -> trimesh file type.
EXPORT_FORMATS = {".glb": "glb", ".obj": "obj", ".ply": "ply", ".stl": "stl"}

#: Peak bytes per triangle of tessellating and writing each file type (tracemalloc on the
#: shipped models at m = 1 and 2: the mesh about 110, then glb 250, obj 715, ply 275, stl
#: 500 while writing), rounded up.
EXPORT_BYTES_PER_TRIANGLE = {"glb": 400, "obj": 900, "ply": 400, "stl": 650}

class ExportError(PlantgenError, ValueError):
    """An export target plantgen cannot write (unknown suffix, unwritable place)."""


def estimate_export_bytes(triangles: int, file_type: str) -> int:
    """Memory an export of ``triangles`` triangles as ``file_type`` takes at its peak."""
    return int(triangles) * EXPORT_BYTES_PER_TRIANGLE[file_type]


def _colours(mesh: TessellatedMesh, colours) -> list[tuple[float, float, float]]:
    out = []
    for i, name in enumerate(mesh.material_names):
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


def _submesh(mesh: TessellatedMesh, face_mask: np.ndarray | None):
    """Vertices, normals, uv and re-indexed faces of the faces in ``face_mask`` (all if None)."""
    if face_mask is None:
        return mesh.vertices, mesh.normals, mesh.uv, mesh.faces
    faces = mesh.faces[face_mask]
    used, inverse = np.unique(faces, return_inverse=True)
    return (mesh.vertices[used], mesh.normals[used], mesh.uv[used],
            inverse.reshape(faces.shape).astype(np.int64))


def mesh_scene(mesh: TessellatedMesh, colours: Mapping[str, Sequence[float]] | Sequence | None = None):
    """A ``trimesh.Scene`` with one geometry per material used, named after the material.

    Each geometry carries vertex normals and a ``TextureVisuals`` with the uv and a
    ``PBRMaterial`` whose base colour is the material colour (linear RGB, opaque).
    """
    import trimesh  # here, not at the top: importing trimesh takes about a second
    from trimesh.visual.material import PBRMaterial
    rgb = _colours(mesh, colours)
    scene = trimesh.Scene()
    face_material = mesh.face_material
    used = np.unique(face_material)
    for mat in used:
        mask = None if len(used) == 1 else face_material == mat
        verts, norms, uv, faces = _submesh(mesh, mask)
        name = mesh.material_names[int(mat)]
        material = PBRMaterial(name=name, baseColorFactor=[*rgb[int(mat)], 1.0],
                               metallicFactor=0.0, roughnessFactor=0.8)
        geom = trimesh.Trimesh(verts, faces, vertex_normals=norms,
                               visual=trimesh.visual.TextureVisuals(uv=uv, material=material),
                               process=False, validate=False)
        scene.add_geometry(geom, geom_name=name, node_name=name)
    return scene


def export_file_type(path: Path) -> str:
    """The trimesh file type of ``path``'s suffix (one line naming the known ones if none)."""
    try:
        return EXPORT_FORMATS[path.suffix.lower()]
    except KeyError:
        known = ", ".join(EXPORT_FORMATS)
        raise ExportError(f"{path}: unknown export format {path.suffix!r} (known: {known})") from None


def export_mesh(mesh: TessellatedMesh, path: str | os.PathLike,
                colours: Mapping[str, Sequence[float]] | Sequence | None = None) -> Path:
    """Write ``mesh`` to ``path``; the format follows the suffix (.glb, .obj, .ply, .stl).

    Parameters
    ----------
    mesh : the tessellation to write (coordinates in model units, y up, as glTF expects)
    path : target file; written under a temporary name beside it, then renamed
    colours : material name -> linear RGB in [0, 1], or one colour per material index;
        default :func:`plantgen.geometry.materials.material_colour`

    Returns
    -------
    Path : the written file
    """
    import trimesh  # here, not at the top: importing trimesh takes about a second
    from trimesh.exchange.gltf import export_glb

    path = Path(path)
    file_type = export_file_type(path)
    if not path.parent.is_dir():
        raise ExportError(f"{path}: directory {path.parent} does not exist")
    if len(mesh.faces) == 0:
        raise ExportError(f"{path}: nothing to export (the model has no segments)")
    if file_type == "glb":
        data = export_glb(mesh_scene(mesh, colours), include_normals=True)
    else:
        whole = trimesh.Trimesh(mesh.vertices, mesh.faces, vertex_normals=mesh.normals,
                                process=False, validate=False)
        if file_type == "obj":
            whole.visual = trimesh.visual.TextureVisuals(uv=mesh.uv)
            data = trimesh.exchange.obj.export_obj(whole, include_normals=True,
                                                   include_color=False, include_texture=True,
                                                   write_texture=False, mtl_name=None)
        elif file_type == "ply":
            data = trimesh.exchange.ply.export_ply(whole, encoding="binary", vertex_normal=True)
        else:
            data = trimesh.exchange.stl.export_stl(whole)

    def write(tmp):
        with open(tmp, "w" if isinstance(data, str) else "wb") as fh:
            fh.write(data)
    return write_atomically(path, write, ExportError)
