"""Wavefront OBJ with its material library: ``plant.obj`` and ``plant.mtl`` beside it.

The OBJ holds every vertex once with its texture coordinate and normal (``v``, ``vt``,
``vn``, same index), then the faces material by material, each run under a group named
after the material and a ``usemtl`` of it (``f a/a/a b/b/b c/c/c``, counter-clockwise seen
from outside). The MTL holds one material per plantgen material: ``Kd`` its colour
(linear RGB, the glTF base colour), no specular, opaque. Names keep plantgen's material
names, with white space and control characters turned to ``_`` (OBJ and MTL end a name at
white space).

Leaves (a grammar's ``{ . }`` polygons, ``leaves``) follow: their vertices and normals
(the polygon's) and texture coordinates (across each leaf's plane) after the frusta's,
then their faces material by material and shade by shade under materials named
``<material>_(leaf)_<k>``: OBJ has no per-vertex colour, so each leaf takes the nearest
of :data:`LEAF_SHADES` shades of the renderers' (each a distinct colour; with ``colours``
given, one material ``<material>_(leaf)`` in that colour). OBJ and MTL
have no double-sided flag; readers draw OBJ faces from both sides by default.

Coordinates are y-up by default (OBJ has no rule; Blender's, Maya's and three.js's
importers take y as up); ``up="z"`` turns the model. Both files are written under
temporary names and renamed together, the OBJ last.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..files import write_all_atomically
from ..geometry.meshes.mesh import TessellatedMesh
from ..geometry.meshes.polygons import Polygons
from ..geometry.skeletons.materials import material_palette
from .formats import ExportError
from .gltf import generator
from .plants import (
    Colours,
    Plant,
    Progress,
    SceneExtras,
    leaf_name,
    leaf_parts,
    material_colours,
    single_plant,
    turned_mesh,
    unique_name,
)
from .sway import Timeline
from .textures import Textures, png_writes, texture_files

__all__ = ["mtl_maps", "obj_names", "write_obj", "write_obj_plant"]

#: Rows formatted at a time (bounds the text held in memory; one progress step each).
ROWS = 1 << 16


def obj_names(names) -> list[str]:
    """Material names as OBJ/MTL can hold them: white space and control characters ->
    ``_``, made unique."""
    out: list[str] = []
    for name in names:
        printable = "".join(c if c.isprintable() else " " for c in name)     # no ESC, BEL, line breaks
        out.append(unique_name(re.sub(r"\s+", "_", printable.strip()) or "material", out))
    return out


def _rows(fh, prefix: str, fmt: str, array: np.ndarray, progress, done: list, total: int) -> None:
    """Write ``array`` (n, w) as lines ``prefix fmt`` in chunks of :data:`ROWS` rows."""
    line = f"{prefix} {fmt}\n"
    for lo in range(0, len(array), ROWS):
        chunk = array[lo:lo + ROWS]
        fh.write((line * len(chunk)) % tuple(chunk.ravel().tolist()))
        done[0] += 1
        if progress is not None:
            progress("write", done[0], total)


#: Shades a leaf material is written in (OBJ has no per-vertex colour): each leaf takes
#: the nearest of LEAF_SHADES tones spread over the renderers' range (leaf_tones: 0.25..0.85).
LEAF_SHADES = 8


def leaf_shades(names, material: int, colours: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The shade of each leaf vertex of ``material`` from its colour (v, 3): its level (v,)
    among :data:`LEAF_SHADES`, and the levels' colours (LEAF_SHADES, 3), linear RGB."""
    palette = material_palette(names)
    dark, light = palette["dark"][material].astype(np.float64), palette["light"][material].astype(np.float64)
    span = light - dark
    tone = (np.asarray(colours, np.float64) - dark) @ span / max(float(span @ span), 1e-30)
    level = np.clip(np.rint((tone - 0.25) / 0.6 * (LEAF_SHADES - 1)), 0, LEAF_SHADES - 1).astype(np.int64)
    tones = 0.25 + 0.6 * np.arange(LEAF_SHADES) / (LEAF_SHADES - 1)
    return level, dark + tones[:, None] * span


def _leaf_runs(leaves: Polygons | None, up: str, first: int, names, shaded: bool):
    """Leaf vertices, normals and runs (material name, linear RGB, faces 1-based) of
    :func:`~plantgen.exporters.plants.leaf_parts`, numbered after ``first`` vertices; with
    ``shaded`` one run per shade a material's leaves take (:func:`leaf_shades`), else one
    per material in its colour (None: the MTL's)."""
    parts = leaf_parts(leaves, up, names=names if shaded else None)
    vertices = [p.vertices for p in parts]
    normals = [p.normals.astype(np.float64) for p in parts]
    uv = [p.uv.astype(np.float64) for p in parts]
    runs = []
    for part in parts:
        faces = part.faces.astype(np.int64) + 1 + first
        name = leaf_name(names[part.material])
        if part.colours is None:
            runs.append((name, None, part.material, faces))
        else:
            level, shades = leaf_shades(names, part.material, part.colours)
            face_level = level[part.faces[:, 0]]
            runs += [(f"{name} {k + 1}", tuple(shades[k]), part.material, faces[face_level == k])
                     for k in np.unique(face_level)]
        first += len(part.vertices)
    return parts, vertices, uv, normals, runs


def write_obj(mesh: TessellatedMesh, path: str | Path, *, up: str = "y", colours: Colours = None,
              progress: Progress = None, leaves: Polygons | None = None,
              textures: Textures | None = None) -> list[Path]:
    """Write ``mesh`` (and ``leaves``, its material indices into ``mesh.material_names``) as
    ``path`` (.obj) and its ``.mtl`` (see the module docstring), with ``textures`` the
    relief's maps as PNG files beside them (:func:`mtl_maps`)."""
    path = Path(path)
    if len(mesh.faces) == 0:
        raise ExportError(f"{path}: nothing to export (the model has no segments)")
    mtl_path = path.with_suffix(".mtl")
    parts, leaf_vertices, leaf_uv, leaf_normals, runs = _leaf_runs(leaves, up, len(mesh.vertices),
                                                                   mesh.material_names, colours is None)
    names = obj_names([*mesh.material_names, *(run[0] for run in runs)])
    rgb = material_colours(mesh.material_names, colours)
    rgb += [rgb[material] if shade is None else shade for _, shade, material, _ in runs]
    leaf_runs = [(len(mesh.material_names) + k, run[3]) for k, run in enumerate(runs)]
    vertices, normals = turned_mesh(mesh, up)
    order = np.argsort(mesh.face_material, kind="stable")
    face_material = mesh.face_material[order]
    faces = mesh.faces[order].astype(np.int64) + 1
    runs = np.flatnonzero(np.diff(face_material)) + 1
    starts = np.concatenate([[0], runs])
    ends = np.concatenate([runs, [len(faces)]])
    total = 3 * -(-len(vertices) // ROWS) + sum(-(-(b - a) // ROWS) for a, b in zip(starts, ends, strict=True))
    total += sum(3 * -(-len(v) // ROWS) for v in leaf_vertices) + sum(-(-len(f) // ROWS) for _, f in leaf_runs)
    n_faces = len(faces) + sum(len(f) for _, f in leaf_runs)
    n_vertices = len(vertices) + sum(len(v) for v in leaf_vertices)

    files = {} if textures is None else texture_files(path, textures, mesh.material_names, v_up=True)
    maps = {i: mtl_maps(files[name], textures.get(name), colours is None)
            for i, name in enumerate(mesh.material_names) if name in files}

    def write_mtl(tmp):
        lines = [f"# {generator()}: materials of {path.name}"]
        for i, name in enumerate(names):
            r, g, b = (1.0, 1.0, 1.0) if any(m.startswith("map_Kd") for m in maps.get(i, ())) else rgb[i]
            lines += ["", f"newmtl {name}", "Ka 0 0 0", f"Kd {r:.6f} {g:.6f} {b:.6f}", "Ks 0 0 0", "Ns 10",
                      "d 1", "illum 1", *maps.get(i, ())]
        Path(tmp).write_text("\n".join(lines) + "\n", encoding="utf-8")

    def write_geometry(tmp):
        done = [0]
        with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(f"# {generator()}: {n_faces:,} triangles, {n_vertices:,} vertices, {up}-up\n"
                     f"mtllib {mtl_path.name}\no {obj_names([path.stem])[0]}\n")
            _rows(fh, "v", "%.9g %.9g %.9g", vertices, progress, done, total)
            _rows(fh, "vt", "%.7g %.7g", mesh.uv.astype(np.float64), progress, done, total)
            _rows(fh, "vn", "%.7g %.7g %.7g", normals.astype(np.float64), progress, done, total)
            for a, b in zip(starts, ends, strict=True):
                name = names[int(face_material[a])]
                fh.write(f"g {name}\nusemtl {name}\n")
                _rows(fh, "f", "%d/%d/%d %d/%d/%d %d/%d/%d", np.repeat(faces[a:b], 3, axis=1), progress,
                      done, total)
            for v in leaf_vertices:     # after the frusta's faces: vt and vn keep the v numbering
                _rows(fh, "v", "%.9g %.9g %.9g", v, progress, done, total)
            for t in leaf_uv:
                _rows(fh, "vt", "%.7g %.7g", t, progress, done, total)
            for n in leaf_normals:
                _rows(fh, "vn", "%.7g %.7g %.7g", n, progress, done, total)
            for material, leaf_faces in leaf_runs:
                fh.write(f"g {names[material]}\nusemtl {names[material]}\n")
                _rows(fh, "f", "%d/%d/%d %d/%d/%d %d/%d/%d", np.repeat(leaf_faces, 3, axis=1), progress, done,
                      total)

    pngs = png_writes(files)
    return write_all_atomically([*pngs, (mtl_path, write_mtl), (path, write_geometry)], ExportError)


def mtl_maps(files: dict, baked, base_colour: bool = True) -> list[str]:
    """The MTL lines naming a material's maps ``files`` ({kind: (path, bytes)}):
    ``map_Kd`` the base colour (where ``base_colour``: no colour was given), ``norm``
    (the PBR extension's tangent-space normal map) and ``map_Bump`` naming the same
    normal map (what Blender's importer reads as one), ``disp`` the height map, its
    amplitude in a comment (the shell of a segment of the median radius)."""
    lines = []
    if "basecolor" in files and base_colour:
        lines.append(f"map_Kd {files['basecolor'][0].name}")
    if "normal" in files:
        lines += [f"norm {files['normal'][0].name}", f"map_Bump {files['normal'][0].name}"]
    if "height" in files:
        lines += [f"# height: 0..1 of the relief shell, {baked.amplitude:.6g} model units at the median radius "
                  f"(shell {baked.shell:g} of the radius)", f"disp {files['height'][0].name}"]
    return lines


def write_obj_plant(plants: list[Plant], path: str | Path, *, up: str = "y", colours: Colours = None,
                    instancing: str = "off", unit: float = 1.0, name: str | None = None,
                    progress: Progress = None, animation: Timeline | None = None,
                    extras: SceneExtras | None = None, textures: Textures | None = None) -> list[Path]:
    """:func:`write_obj` of the one plant of ``plants``, in place, with its leaves (a
    :class:`~plantgen.exporters.plants.MeshWriter`; OBJ has no instancing and no units, and
    its name is the file's; a scene's camera, light and ground are not written: OBJ has no
    camera or light, and a ground square would be taken for part of the model)."""
    plant = single_plant(plants, path)
    return write_obj(plant.mesh, path, up=up, colours=colours, progress=progress, leaves=plant.leaves,
                     textures=textures)
