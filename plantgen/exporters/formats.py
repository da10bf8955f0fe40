"""The export formats: suffix, kind, up-axis convention, what each needs and costs.

=============  ========  ====  ==========  =========  ======================================
suffix         kind      up    instancing  animation  writer
=============  ========  ====  ==========  =========  ======================================
``.glb``       mesh      y     yes         yes        glTF 2.0 binary (plantgen's writer)
``.gltf``      mesh      y     yes         yes        glTF 2.0 JSON + ``.bin`` beside it
``.obj``       mesh      y     no          no         Wavefront OBJ + ``.mtl`` beside it
``.ply``       mesh      z     no          no         binary PLY (trimesh)
``.stl``       mesh      z     no          no         binary STL (trimesh)
``.usda``      mesh      y     yes         yes        USD text (usd-core: ``plantgen[usd]``)
``.usdc``      mesh      y     yes         yes        USD crate (binary)
``.usd``       mesh      y     yes         yes        USD, crate encoding
``.swc``       skeleton  y     --          no         SWC nodes (:mod:`plantgen.geometry.skeletons.swc`)
``.qsm.csv``   skeleton  z     --          no         TreeQSM cylinders + ``.treedata.csv`` beside it
``.qsm.mat``   skeleton  z     --          no         TreeQSM's MATLAB struct (scipy: ``plantgen[qsm]``)
=============  ========  ====  ==========  =========  ======================================

**Animation.** A scene that lists ``animation`` and sways (:mod:`plantgen.geometry.skeletons.motion`)
is written with its sway by the formats that hold animation: glTF as skins (a joint per
segment) with a rotation channel per joint, USD as UsdSkel skeletons with a
SkelAnimation per copy (:mod:`plantgen.exporters.sway`); the others write the plants at
rest.

**Scenes.** A scene's camera, light and ground are written by the formats that hold
them (glTF: a perspective camera, a ``KHR_lights_punctual`` directional light, a ground
mesh; USD: ``Camera``, ``DistantLight``, a ground ``Mesh``; the rows with ``scene``); OBJ,
PLY and STL hold the plants only. A grammar or a skeleton has no scene: none is added.

**Up.** plantgen models are y-up. Each format's default is its convention: glTF says +y
is up; OBJ has no rule, and y-up is what Blender's, Maya's and three.js's importers
assume; PLY and STL have none either, and the tools that open them (Blender, slicers,
MeshLab's scans) take z as up; USD records its axis in the stage (``upAxis``, y by
default here); SWC keeps plantgen's frame (neuron data has no up); TreeQSM's cylinder
models are z-up (terrestrial laser scans). ``up="z"`` turns the model +90° about x,
``(x, y, z)`` -> ``(x, -z, y)``, which keeps handedness and windings.

**Writers.** Each row of :data:`EXPORT_FORMATS` names the function that writes it, as a
``"module:function"`` reference imported on first use (:meth:`Format.load_writer`; a row
may hold the function itself), so that an optional package (usd-core, scipy) and a
writer's import cost stay off ``import plantgen``. Writers of a kind share one calling
convention: :class:`~plantgen.exporters.plants.MeshWriter` (called by
:func:`~plantgen.exporters.meshes.write_plants`) and
:class:`~plantgen.exporters.plants.SkeletonWriter` (called by
:func:`~plantgen.exporters.skeletons.write_skeleton`). Nothing chooses a writer by the
format's name: a new format is one row and its writer.
"""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ..errors import PlantgenError, missing_extra
from ..files import check_outputs
from ..geometry.skeletons.frames import UP_AXES

__all__ = ["EXPORT_FORMATS", "check_export_outputs", "companion_paths",
           "ExportError", "FORMAT_KINDS", "Format", "UP_AXES", "check_extra",
           "estimate_export_bytes", "export_format", "export_file_type"]

#: What a format holds: a mesh (written by a :class:`~plantgen.exporters.plants.MeshWriter`)
#: or a skeleton (a :class:`~plantgen.exporters.plants.SkeletonWriter`).
FORMAT_KINDS = ("mesh", "skeleton")


class ExportError(PlantgenError, ValueError):
    """An export target plantgen cannot write (unknown suffix, unwritable place)."""


@dataclass(frozen=True)
class Format:
    """One export format (see the module docstring) and the function that writes it.

    ``writer`` is a ``"module:function"`` reference, imported on first use, or the function
    itself; it follows its kind's convention (:data:`FORMAT_KINDS`)."""

    name: str
    suffix: str
    kind: str                    # "mesh" or "skeleton" (FORMAT_KINDS)
    up: str                      # the format's up-axis convention, the default of --up
    instancing: bool             # a scene's repeated plants can be written once
    bytes_per_triangle: int      # peak memory of writing, per triangle (mesh formats)
    writer: str | Callable       # "module:function", or the function
    module: str | None = None    # the optional package the writer needs
    extra: str | None = None     # the plantgen extra that installs it
    animation: bool = False      # writes a scene's sway as an animation
    scene: bool = False          # writes a scene's camera, light and ground
    textures: bool = False       # holds the relief's baked maps (plantgen.exporters.textures)

    def __post_init__(self) -> None:
        if self.kind not in FORMAT_KINDS:
            raise ValueError(f"{self.suffix}: kind must be one of {', '.join(FORMAT_KINDS)}, got {self.kind!r}")
        if not callable(self.writer) and self.writer.count(":") != 1:
            raise ValueError(f"{self.suffix}: writer must be a function or 'module:function', got {self.writer!r}")

    @property
    def install(self) -> str:
        """One line naming the extra this format needs and its install command."""
        return missing_extra(f"writing {self.suffix}", self.extra)

    def load_writer(self) -> Callable:
        """The writer function, its module imported now (check :func:`check_extra` first)."""
        if callable(self.writer):
            return self.writer
        module, function = self.writer.split(":")
        return getattr(importlib.import_module(module), function)


#: Peak bytes per triangle of tessellating and writing (the process's peak resident size
#: over the tessellation and the write, coconut at m = 2, 1.08 M triangles: glb 170, gltf
#: 173, obj 151, ply 186, stl 412, usda 175, usdc 117; the whole process's peak resident
#: size, baseline included, pine at m = 2, 5.17 M triangles with its baked textures: glb
#: 348, obj 348, ply 225), rounded up.
EXPORT_FORMATS = {f.suffix: f for f in (
    Format("glb", ".glb", "mesh", "y", True, 350, "plantgen.exporters.gltf:write_gltf", animation=True, scene=True,
           textures=True),
    Format("gltf", ".gltf", "mesh", "y", True, 350, "plantgen.exporters.gltf:write_gltf", animation=True,
           scene=True, textures=True),
    Format("obj", ".obj", "mesh", "y", False, 350, "plantgen.exporters.obj:write_obj_plant", textures=True),
    Format("ply", ".ply", "mesh", "z", False, 400, "plantgen.exporters.meshes:write_ply"),
    Format("stl", ".stl", "mesh", "z", False, 650, "plantgen.exporters.meshes:write_stl"),
    Format("usda", ".usda", "mesh", "y", True, 400, "plantgen.exporters.usd:write_usd", "pxr", "usd",
           animation=True, scene=True, textures=True),
    Format("usdc", ".usdc", "mesh", "y", True, 350, "plantgen.exporters.usd:write_usd", "pxr", "usd",
           animation=True, scene=True, textures=True),
    Format("usd", ".usd", "mesh", "y", True, 350, "plantgen.exporters.usd:write_usd", "pxr", "usd",
           animation=True, scene=True, textures=True),
    Format("swc", ".swc", "skeleton", "y", False, 0, "plantgen.exporters.skeletons:write_swc_skeleton"),
    Format("qsm.csv", ".qsm.csv", "skeleton", "z", False, 0, "plantgen.exporters.qsm:write_qsm"),
    Format("qsm.mat", ".qsm.mat", "skeleton", "z", False, 0, "plantgen.exporters.qsm:write_qsm", "scipy", "qsm"),
)}


def export_format(path: str | Path) -> Format:
    """The format ``path``'s suffix names (the longest that matches), or one line naming
    the known ones."""
    name = Path(path).name.lower()
    for suffix in sorted(EXPORT_FORMATS, key=len, reverse=True):
        if name.endswith(suffix) and len(name) > len(suffix):
            return EXPORT_FORMATS[suffix]
    known = ", ".join(EXPORT_FORMATS)
    hint = " (a cylinder model ends in .qsm.csv or .qsm.mat)" if name.endswith((".csv", ".mat")) else ""
    raise ExportError(f"{path}: unknown export format {Path(path).suffix!r}{hint} (known: {known})")


def export_file_type(path: str | Path) -> str:
    """The name of ``path``'s format (``"glb"``, ``"qsm.csv"``, ...)."""
    return export_format(path).name


def check_extra(fmt: Format, path) -> None:
    """One line naming the install command when the package ``fmt``'s writer needs is missing."""
    if fmt.module is not None and importlib.util.find_spec(fmt.module) is None:
        raise ExportError(f"{path}: {fmt.install} ({fmt.module} missing)")


def writable_format(path: str | Path, kind: str) -> Format:
    """The format of ``path``, checked before any work: of ``kind`` ("mesh" or "skeleton"),
    its optional package installed, its folder there (one line for each refusal)."""
    path = Path(path)
    fmt = export_format(path)
    if fmt.kind != kind:
        other = "mesh" if kind == "skeleton" else "skeleton"
        raise ExportError(f"{path}: {fmt.suffix} holds a {other}, not a {kind}")
    check_extra(fmt, path)
    check_export_outputs(path, fmt)
    return fmt


def companion_paths(path: str | Path, fmt: Format) -> list[Path]:
    """The files written beside ``path`` that its name fixes: a .gltf's .bin, an .obj's
    .mtl, a .qsm.csv's .treedata.csv (texture PNGs are named by material, checked as they
    are written)."""
    path = Path(path)
    if fmt.suffix == ".gltf":
        return [path.with_suffix(".bin")]
    if fmt.suffix == ".obj":
        return [path.with_suffix(".mtl")]
    if fmt.suffix == ".qsm.csv":
        return [path.with_name(path.name[: -len(".qsm.csv")] + ".treedata.csv")]
    return []


def check_export_outputs(path: str | Path, fmt: Format) -> list[Path]:
    """Every file an export to ``path`` writes whose name is known before the work,
    checked (:func:`plantgen.files.check_output`: one line ``PATH: cannot write (...)``)."""
    return check_outputs([Path(path), *companion_paths(path, fmt)], ExportError)


def estimate_export_bytes(triangles: int, file_type: str) -> int:
    """Memory an export of ``triangles`` triangles as ``file_type`` takes at its peak."""
    fmt = next((f for f in EXPORT_FORMATS.values() if f.name == file_type), None)
    if fmt is None:
        raise ExportError(f"unknown export format {file_type!r}")
    return int(triangles) * fmt.bytes_per_triangle
