"""Exports: meshes (glTF, OBJ + MTL, PLY, STL, USD), skeletons (SWC) and forestry cylinder
models (QSM), each in the form the tools that read it expect.

- :mod:`~plantgen.export.formats`: the formats, their suffixes and up-axis conventions;
- :mod:`~plantgen.export.plants`: what the writers take (:class:`Plant`: a mesh and a
  skeleton with the placements of its copies);
- :mod:`~plantgen.export.meshes`: :func:`export_mesh` (one mesh) and :func:`write_plants`
  (a scene's plants, instanced where the format can);
- :mod:`~plantgen.export.skeletons`: :func:`write_skeleton` (SWC, the cylinder models);
- :mod:`~plantgen.export.gltf`, :mod:`~plantgen.export.obj`, :mod:`~plantgen.export.usd`,
  :mod:`~plantgen.export.qsm`: the writers, each named by its format's row. SWC is
  :func:`plantgen.geometry.swc.write_swc`.

Every writer writes under temporary names and renames, so a failure leaves nothing
half-written.
"""

from .formats import (
           EXPORT_FORMATS,
           ExportError,
           Format,
           check_extra,
           estimate_export_bytes,
           export_file_type,
           export_format,
)
from .meshes import export_mesh, write_plants
from .plants import Plant
from .skeletons import write_skeleton

__all__ = ["EXPORT_FORMATS", "ExportError", "Format", "Plant", "check_extra", "estimate_export_bytes",
           "export_file_type", "export_format", "export_mesh", "write_plants", "write_skeleton"]
