"""Write tessellated meshes (GS, GS+R) as glTF binary, OBJ, PLY or STL through trimesh.

The format follows the file suffix. glTF keeps one primitive per material with its base
colour, the vertex normals (8) and the texture coordinates; OBJ keeps normals and
texture coordinates; PLY keeps normals; STL keeps triangles only. Every writer writes to
a temporary name beside the target and renames it, so a failed export leaves nothing
half-written.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from .errors import PlantgenError
from .geometry.mesh import TessellatedMesh

__all__ = ["EXPORT_FORMATS", "MAX_EXPORT_TRIANGLES", "ExportError", "export_mesh", "export_model",
           "mesh_scene", "default_material_colour"]

#: Largest mesh ``export_model`` writes (about 60 bytes a triangle in memory while writing).
MAX_EXPORT_TRIANGLES = 100_000_000

#: File suffix -> trimesh file type.
EXPORT_FORMATS = {".glb": "glb", ".obj": "obj", ".ply": "ply", ".stl": "stl"}

class ExportError(PlantgenError, ValueError):
    """An export target plantgen cannot write (unknown suffix, unwritable place)."""


def default_material_colour(name: str) -> tuple[float, float, float]:
    """Linear RGB in [0, 1] for a material name: the mean of the ray caster's dark and light
    albedo for it (:func:`plantgen.render.raycast.material_palette`), so an exported mesh
    has the colour the renderers give it."""
    from .render.raycast import material_palette  # pure numpy: no GL context is made

    palette = material_palette([name])
    return tuple(float(x) for x in (palette["dark"][0] + palette["light"][0]) / 2)


def _colours(mesh: TessellatedMesh, colours) -> list[tuple[float, float, float]]:
    out = []
    for i, name in enumerate(mesh.material_names):
        if colours is None:
            c = default_material_colour(name)
        elif isinstance(colours, Mapping):
            c = colours.get(name, default_material_colour(name))
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
    import trimesh
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


def _file_type(path: Path) -> str:
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
    path : target file; written as ``NAME.part`` beside it, then renamed
    colours : material name -> linear RGB in [0, 1], or one colour per material index;
        default :func:`default_material_colour`

    Returns
    -------
    Path : the written file
    """
    import trimesh
    from trimesh.exchange.gltf import export_glb

    path = Path(path)
    file_type = _file_type(path)
    if not path.parent.is_dir():
        raise ExportError(f"{path}: directory {path.parent} does not exist")
    if len(mesh.faces) == 0:
        raise ExportError(f"{path}: nothing to export (the model has no segments)")
    tmp = path.with_name(path.name + ".part")
    try:
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
        mode = "w" if isinstance(data, str) else "wb"
        with open(tmp, mode) as fh:
            fh.write(data)
        tmp.replace(path)
    except OSError as exc:
        raise ExportError(f"{path}: cannot write ({exc.strerror or exc})") from None
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def export_model(input_path: str | os.PathLike, output_path: str | os.PathLike, *, level: int = 1,
                 relief: bool = False, seed: int | None = None) -> dict:
    """The library side of ``plantgen export``: input file -> skin -> tessellate -> file.

    ``input_path`` is a skeleton ``.npz`` (or a grammar or scene, through
    :func:`plantgen.pipeline.load_skeleton`). Returns a summary dict: ``segments``,
    ``rows``, ``caps``, ``triangles``, ``vertices``, ``level``, ``relief``, ``path``,
    ``timings`` (seconds per stage).
    """
    import time

    from .geometry.mesh import tessellate, triangle_count
    from .geometry.skeleton import Skeleton
    from .geometry.skin import skin_skeleton

    output_path = Path(output_path)
    _file_type(output_path)  # fail on a bad suffix before any work
    timings = {}
    t0 = time.perf_counter()
    try:
        from .pipeline import load_skeleton
    except ImportError:  # pragma: no cover - the pipeline ships with plantgen
        load_skeleton = None
    if load_skeleton is not None:
        skeleton = load_skeleton(input_path, seed=seed)
    else:  # pragma: no cover
        skeleton = Skeleton.load(input_path)
    if len(skeleton) == 0:
        raise ExportError(f"{input_path}: the model has no segments")
    skeleton.validate()
    t1 = time.perf_counter()
    frusta = skin_skeleton(skeleton)
    t2 = time.perf_counter()
    estimate = triangle_count(len(frusta), level, int(frusta.open_lo.sum() + frusta.open_hi.sum()))
    if estimate > MAX_EXPORT_TRIANGLES:
        raise ExportError(f"{input_path}: m = {level} gives {estimate:,} triangles, over the "
                          f"export limit of {MAX_EXPORT_TRIANGLES:,}; choose a lower --subdiv")
    mesh = tessellate(frusta, level, relief=relief)
    t3 = time.perf_counter()
    export_mesh(mesh, output_path)
    t4 = time.perf_counter()
    timings = {"load": t1 - t0, "skin": t2 - t1, "tessellate": t3 - t2, "write": t4 - t3}
    return {"segments": len(skeleton), "rows": mesh.n_rows, "caps": mesh.n_caps,
            "triangles": len(mesh.faces), "vertices": len(mesh.vertices), "level": level,
            "relief": relief, "path": output_path, "timings": timings}
