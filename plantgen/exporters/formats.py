"""The export formats: suffix, kind, up-axis convention, what each needs and costs.

=============  ========  ====  ==========  =================================================
suffix         kind      up    instancing  writer
=============  ========  ====  ==========  =================================================
``.glb``       mesh      y     yes         glTF 2.0 binary (plantgen's writer)
``.gltf``      mesh      y     yes         glTF 2.0 JSON + ``.bin`` beside it
``.obj``       mesh      y     no          Wavefront OBJ + ``.mtl`` beside it
``.ply``       mesh      z     no          binary PLY (trimesh)
``.stl``       mesh      z     no          binary STL (trimesh)
``.usda``      mesh      y     yes         USD text (usd-core: ``plantgen[usd]``)
``.usdc``      mesh      y     yes         USD crate (binary)
``.usd``       mesh      y     yes         USD, crate encoding
``.swc``       skeleton  y     --          SWC nodes (:mod:`plantgen.geometry.swc`)
``.qsm.csv``   skeleton  z     --          TreeQSM cylinders + ``.treedata.csv`` beside it
``.qsm.mat``   skeleton  z     --          TreeQSM's MATLAB struct (scipy: ``plantgen[qsm]``)
=============  ========  ====  ==========  =================================================

**Up.** plantgen models are y-up. Each format's default is its convention: glTF says +y
is up; OBJ has no rule, and y-up is what Blender's, Maya's and three.js's importers
assume; PLY and STL have none either, and the tools that open them (Blender, slicers,
MeshLab's scans) take z as up; USD records its axis in the stage (``upAxis``, y by
default here); SWC keeps plantgen's frame (neuron data has no up); TreeQSM's cylinder
models are z-up (terrestrial laser scans). ``up="z"`` turns the model +90° about x,
``(x, y, z)`` -> ``(x, -z, y)``, which keeps handedness and windings.
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from pathlib import Path

from ..errors import PlantgenError
from ..geometry.frames import UP_AXES

__all__ = ["EXPORT_FORMATS", "ExportError", "Format", "UP_AXES", "check_extra", "estimate_export_bytes",
           "export_format", "export_file_type"]


class ExportError(PlantgenError, ValueError):
    """An export target plantgen cannot write (unknown suffix, unwritable place)."""


@dataclass(frozen=True)
class Format:
    """One export format (see the module docstring)."""

    name: str
    suffix: str
    kind: str                    # "mesh" or "skeleton"
    up: str                      # the format's up-axis convention, the default of --up
    instancing: bool             # a scene's repeated plants can be written once
    bytes_per_triangle: int      # peak memory of writing, per triangle (mesh formats)
    module: str | None = None    # the optional package the writer needs
    extra: str | None = None     # the plantgen extra that installs it

    @property
    def install(self) -> str:
        return f"pip install 'plantgen[{self.extra}]'"


#: Peak bytes per triangle of tessellating and writing (the process's peak resident size
#: over the tessellation and the write, coconut at m = 2, 1.08 M triangles: glb 170, gltf
#: 173, obj 151, ply 186, stl 412, usda 175, usdc 117), rounded up generously.
EXPORT_FORMATS = {f.suffix: f for f in (
    Format("glb", ".glb", "mesh", "y", True, 250),
    Format("gltf", ".gltf", "mesh", "y", True, 250),
    Format("obj", ".obj", "mesh", "y", False, 250),
    Format("ply", ".ply", "mesh", "z", False, 400),
    Format("stl", ".stl", "mesh", "z", False, 650),
    Format("usda", ".usda", "mesh", "y", True, 300, "pxr", "usd"),
    Format("usdc", ".usdc", "mesh", "y", True, 250, "pxr", "usd"),
    Format("usd", ".usd", "mesh", "y", True, 250, "pxr", "usd"),
    Format("swc", ".swc", "skeleton", "y", False, 0),
    Format("qsm.csv", ".qsm.csv", "skeleton", "z", False, 0),
    Format("qsm.mat", ".qsm.mat", "skeleton", "z", False, 0, "scipy", "qsm"),
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
        raise ExportError(f"{path}: writing {fmt.suffix} needs the optional package '{fmt.module}': "
                          f"{fmt.install}")


def estimate_export_bytes(triangles: int, file_type: str) -> int:
    """Memory an export of ``triangles`` triangles as ``file_type`` takes at its peak."""
    fmt = next((f for f in EXPORT_FORMATS.values() if f.name == file_type), None)
    if fmt is None:
        raise ExportError(f"unknown export format {file_type!r}")
    return int(triangles) * fmt.bytes_per_triangle
