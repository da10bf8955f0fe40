"""Exports: meshes (glTF, OBJ + MTL, PLY, STL, USD), skeletons (SWC) and forestry cylinder
models (QSM), each in the form the tools that read it expect.

- :mod:`~plantgen.exporters.formats`: the formats, their suffixes and up-axis conventions;
- :mod:`~plantgen.exporters.plants`: what the writers take (:class:`Plant`: a mesh and a
  skeleton with the placements of its copies; :class:`SceneExtras`: a scene's camera,
  light and ground);
- :mod:`~plantgen.exporters.meshes`: :func:`export_mesh` (one mesh) and :func:`write_plants`
  (a scene's plants, instanced where the format can);
- :mod:`~plantgen.exporters.skeletons`: :func:`write_skeleton` (SWC, the cylinder models);
- :mod:`~plantgen.exporters.sway`: a scene's sway as joints, skin weights and keys (glTF
  skins, UsdSkel): :class:`PlantSway`, :func:`sway_timeline`;
- :mod:`~plantgen.exporters.gltf`, :mod:`~plantgen.exporters.obj`, :mod:`~plantgen.exporters.usd`,
  :mod:`~plantgen.exporters.qsm`: the writers, each named by its format's row. SWC is
  :func:`plantgen.geometry.skeletons.swc.write_swc`.

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
from .plants import DetailLevel, Plant, PlantDetail, SceneExtras
from .skeletons import write_skeleton
from .sway import PlantSway, Timeline, sway_timeline

__all__ = ["EXPORT_FORMATS", "DetailLevel", "ExportError", "Format", "Plant", "PlantDetail", "PlantSway",
           "SceneExtras", "Timeline", "check_extra",
           "estimate_export_bytes", "export_file_type", "export_format", "export_mesh", "sway_timeline",
           "write_plants", "write_skeleton"]
