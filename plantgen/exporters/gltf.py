"""glTF 2.0, binary (``.glb``) or JSON with its buffer beside it (``.gltf`` + ``.bin``).

Each plant is one glTF mesh with one primitive per material (POSITION, NORMAL,
TEXCOORD_0 and indices; a metallic-roughness material per plantgen material with its
name and base colour, linear RGB as glTF defines it). Nodes:

- a model written in place (a grammar, a skeleton, a flattened scene): one node;
- a scene's plant with copies, ``instancing="gpu"`` (the default): one node whose
  ``EXT_mesh_gpu_instancing`` attributes hold the copies' TRANSLATION, ROTATION (unit
  quaternions) and SCALE; the extension is listed in ``extensionsUsed`` and
  ``extensionsRequired``, so a reader without it that follows the specification refuses
  the file instead of showing one plant in place of many;
- ``instancing="nodes"``: one node per copy (translation, rotation, scale), all sharing
  the plant's mesh: core glTF, for readers without the extension;
- a plant with a single copy: one such node either way.

A plant's leaves (a grammar's ``{ . }`` polygons) are primitives of its mesh too, one per
material, with a material of their own named ``"<material> (leaf)"`` that is
``doubleSided`` (a leaf is seen from both sides; the frusta's materials stay single-sided,
so back faces are culled); NORMAL is the polygon's normal, TEXCOORD_0 spans each leaf's
bounding box in its plane (:func:`~plantgen.exporters.plants.leaf_uv`).

A plant's per-row ``labels`` ({"_BRANCH_ORDER": ...}: ``plantgen batch`` labels each
mesh with its branch order) become application-specific vertex attributes of those
names (FLOAT scalars; glTF reserves names starting with ``_`` for this).

``up="z"`` turns the model (see :mod:`plantgen.geometry.frames`); glTF's convention is y.
The file passes the Khronos glTF validator with no error and no warning (tested).
"""

from __future__ import annotations

import json
import struct
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from urllib.parse import quote

import numpy as np

from ..files import write_all_atomically, write_atomically
from ..geometry.frames import similarity_trs, turn_placements
from .formats import ExportError
from .plants import Colours, Plant, Progress, leaf_name, leaf_parts, material_colours, material_parts

__all__ = ["INSTANCING_EXTENSION", "gltf_document", "write_gltf"]

INSTANCING_EXTENSION = "EXT_mesh_gpu_instancing"
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
FLOAT, UNSIGNED_SHORT, UNSIGNED_INT = 5126, 5123, 5125
GLB_MAGIC, GLB_JSON, GLB_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942


def generator() -> str:
    try:
        return f"plantgen {version('plantgen')}"
    except PackageNotFoundError:
        return "plantgen"


class _Buffer:
    """The binary buffer, its buffer views and accessors, built up in order."""

    def __init__(self) -> None:
        self.chunks: list[bytes] = []
        self.size = 0
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def add(self, array: np.ndarray, kind: str, component: int, target: int | None = None,
            bounds: bool = False) -> int:
        """Append ``array`` ((count, width) or (count,)) as one view and one accessor; its index."""
        data = np.ascontiguousarray(array).tobytes()
        pad = (-self.size) % 4
        if pad:
            self.chunks.append(bytes(pad))
            self.size += pad
        view = {"buffer": 0, "byteOffset": self.size, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        self.chunks.append(data)
        self.size += len(data)
        self.views.append(view)
        accessor = {"bufferView": len(self.views) - 1, "componentType": component, "count": int(len(array)),
                    "type": kind}
        if bounds:
            accessor["min"] = [float(v) for v in np.min(array, axis=0)]
            accessor["max"] = [float(v) for v in np.max(array, axis=0)]
        self.accessors.append(accessor)
        return len(self.accessors) - 1

    def data(self) -> bytes:
        return b"".join(self.chunks)


def _primitive(buffer: _Buffer, part, material: int) -> dict:
    positions = part.vertices.astype(np.float32)
    index_type = UNSIGNED_SHORT if len(positions) < 65536 else UNSIGNED_INT
    indices = part.faces.astype(np.uint16 if index_type == UNSIGNED_SHORT else np.uint32).ravel()
    attributes = {"POSITION": buffer.add(positions, "VEC3", FLOAT, ARRAY_BUFFER, bounds=True),
                  "NORMAL": buffer.add(part.normals, "VEC3", FLOAT, ARRAY_BUFFER),
                  "TEXCOORD_0": buffer.add(part.uv, "VEC2", FLOAT, ARRAY_BUFFER)}
    for name, values in (part.labels or {}).items():     # application-specific: "_NAME"
        attributes[name] = buffer.add(values.astype(np.float32), "SCALAR", FLOAT, ARRAY_BUFFER)
    return {"attributes": attributes, "indices": buffer.add(indices, "SCALAR", index_type, ELEMENT_ARRAY_BUFFER),
            "material": material, "mode": 4}


def _material(name: str, rgb, double_sided: bool) -> dict:
    material = {"name": name, "pbrMetallicRoughness": {
        "baseColorFactor": [*rgb, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.8}}
    if double_sided:
        material["doubleSided"] = True
    return material


def _trs_nodes(name: str, mesh: int, matrices: np.ndarray) -> list[dict]:
    t, q, s = similarity_trs(matrices)
    return [{"name": f"{name} {k + 1}" if len(matrices) > 1 else name, "mesh": mesh,
             "translation": [float(v) for v in t[k]], "rotation": [float(v) for v in q[k]],
             "scale": [float(s[k])] * 3} for k in range(len(matrices))]


def _gpu_node(buffer: _Buffer, name: str, mesh: int, matrices: np.ndarray) -> dict:
    t, q, s = similarity_trs(matrices)
    scale = np.repeat(s[:, None], 3, axis=1)
    attributes = {"TRANSLATION": buffer.add(t.astype(np.float32), "VEC3", FLOAT),
                  "ROTATION": buffer.add(q.astype(np.float32), "VEC4", FLOAT),
                  "SCALE": buffer.add(scale.astype(np.float32), "VEC3", FLOAT)}
    return {"name": name, "mesh": mesh, "extensions": {INSTANCING_EXTENSION: {"attributes": attributes}}}


def gltf_document(plants: list[Plant], *, up: str = "y", colours: Colours = None, instancing: str = "gpu",
                  name: str = "plantgen", progress: Progress = None) -> tuple[dict, bytes]:
    """The glTF JSON (without ``buffers``) and the binary buffer of ``plants``."""
    if instancing not in ("gpu", "nodes"):
        raise ValueError(f"instancing must be 'gpu' or 'nodes', got {instancing!r}")
    buffer = _Buffer()
    material_index: dict[str, int] = {}
    materials, meshes, nodes = [], [], []
    used_extension = False
    for done, plant in enumerate(plants):
        names = plant.mesh.material_names
        rgb = material_colours(names, colours)
        primitives = []
        for part in material_parts(plant.mesh, up, plant.labels) + leaf_parts(plant.leaves, up):
            mat_name = leaf_name(names[part.material]) if part.leaf else names[part.material]
            if mat_name not in material_index:
                material_index[mat_name] = len(materials)
                materials.append(_material(mat_name, rgb[part.material], part.leaf))
            primitives.append(_primitive(buffer, part, material_index[mat_name]))
        meshes.append({"name": plant.name, "primitives": primitives})
        mesh = len(meshes) - 1
        if plant.matrices is None:
            nodes.append({"name": plant.name, "mesh": mesh})
        elif instancing == "gpu" and len(plant.matrices) > 1:
            nodes.append(_gpu_node(buffer, plant.name, mesh, turn_placements(plant.matrices, up)))
            used_extension = True
        else:
            nodes += _trs_nodes(plant.name, mesh, turn_placements(plant.matrices, up))
        if progress is not None:
            progress("write", done + 1, len(plants))
    doc = {"asset": {"version": "2.0", "generator": generator()}, "scene": 0,
           "scenes": [{"name": name, "nodes": list(range(len(nodes)))}], "nodes": nodes, "meshes": meshes,
           "materials": materials, "accessors": buffer.accessors, "bufferViews": buffer.views}
    if used_extension:
        doc["extensionsUsed"] = [INSTANCING_EXTENSION]
        doc["extensionsRequired"] = [INSTANCING_EXTENSION]
    return doc, buffer.data()


def _glb(doc: dict, data: bytes) -> bytes:
    doc = dict(doc, buffers=[{"byteLength": len(data)}])
    text = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    text += b" " * ((-len(text)) % 4)
    data += bytes((-len(data)) % 4)
    total = 12 + 8 + len(text) + 8 + len(data)
    return b"".join([struct.pack("<III", GLB_MAGIC, 2, total), struct.pack("<II", len(text), GLB_JSON), text,
                     struct.pack("<II", len(data), GLB_BIN), data])


def write_gltf(plants: list[Plant], path: str | Path, *, up: str = "y", colours: Colours = None,
               instancing: str = "gpu", unit: float = 1.0, name: str | None = None,
               progress: Progress = None) -> list[Path]:
    """Write ``plants`` as ``.glb``, or as ``.gltf`` with its ``.bin`` beside it (see the
    module docstring); nothing is left half-written. Returns the written paths (a
    :class:`~plantgen.exporters.plants.MeshWriter`; ``unit`` is not written: glTF has no unit
    field, and the model is written in model units)."""
    path = Path(path)
    if not any(plant.mesh is not None and len(plant.mesh.faces) for plant in plants):
        raise ExportError(f"{path}: nothing to export (the model has no segments)")
    doc, data = gltf_document(plants, up=up, colours=colours, instancing=instancing,
                              name=name or path.name.split(".")[0] or "plantgen", progress=progress)
    if path.suffix.lower() == ".glb":
        blob = _glb(doc, data)
        return [write_atomically(path, lambda tmp: Path(tmp).write_bytes(blob), ExportError)]
    bin_path = path.with_suffix(".bin")
    doc = dict(doc, buffers=[{"byteLength": len(data), "uri": quote(bin_path.name)}])
    text = json.dumps(doc, indent=1)
    return write_all_atomically([(bin_path, lambda tmp: Path(tmp).write_bytes(data)),
                                 (path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))], ExportError)
