"""glTF 2.0, binary (``.glb``) or JSON with its buffer beside it (``.gltf`` + ``.bin``).

Each plant is one glTF mesh with one primitive per material (POSITION, NORMAL,
TEXCOORD_0 and indices; a metallic-roughness material per plantgen material with its
name and base colour, linear RGB as glTF defines it). Nodes:

- a model written in place (a grammar, a skeleton, a flattened scene): one node;
- a scene's plant with copies, ``instancing="nodes"`` (the default): one node per copy
  (translation, rotation, scale), all sharing the plant's mesh: core glTF, which every
  reader opens (Blender 3.4's importer refuses a file that requires an extension it
  lacks);
- ``instancing="gpu"`` (on request): one node whose
  ``EXT_mesh_gpu_instancing`` attributes hold the copies' TRANSLATION, ROTATION (unit
  quaternions) and SCALE; the extension is listed in ``extensionsUsed`` and
  ``extensionsRequired``, so a reader without it that follows the specification refuses
  the file instead of showing one plant in place of many (a core fallback would need the
  copies' nodes as well, which is ``"nodes"`` again: asking for ``gpu`` is asking for the
  extension);
- a plant with a single copy: one such node either way;
- a plant that sways (written with an ``animation``, :mod:`~plantgen.exporters.sway`):
  its primitives carry ``JOINTS_0`` (8-bit, 16-bit past 256 joints) and ``WEIGHTS_0``
  (normalized 8-bit, :func:`byte_weights`); per copy, whatever ``instancing`` says (each
  copy sways on its own phase, so copies cannot share one skin), a node placing the copy
  whose children are its joints (one per segment, nested as the segments are), a skin
  over them (the inverse bind matrices shared by the copies) and the mesh's node with
  that skin at the scene's root, untransformed. The document's one animation, ``"sway"``,
  holds a ``LINEAR`` rotation channel per turning joint of every swaying copy, its keys
  at the timeline's times.

A plant with levels of detail (:class:`~plantgen.exporters.plants.PlantDetail`):
each of its nodes (a copy's, the instanced node, the plant in place) carries ``MSFT_lod``
whose ``ids`` name one node per lower level (``"<name> lod<k>"``, that level's mesh, the
node's placement or instancing attributes), nodes outside the scene's tree, and
``extras.MSFT_screencoverage`` (one coverage per level: below ``coverage[k]`` level k + 1
may be shown; below the last, nothing). A swaying plant's levels are skinned on the same
joints: each copy's mesh node names its level nodes, each with the copy's one skin, so
the one ``"sway"`` animation drives every level. ``MSFT_lod`` is in ``extensionsUsed`` only: a
reader without it shows the full level.

A plant's leaves (a grammar's ``{ . }`` polygons) are primitives of its mesh too, one per
material, with a material of their own named ``"<material> (leaf)"`` that is
``doubleSided``, white, each vertex's ``COLOR_0`` its leaf's shade as the renderers draw
it (between the material's dark and light colour; with ``colours`` given: that colour,
no COLOR_0) (a leaf is seen from both sides; the frusta's materials stay single-sided,
so back faces are culled); NORMAL is the polygon's normal, TEXCOORD_0 spans each leaf's
bounding box in its plane (:func:`~plantgen.exporters.plants.leaf_uv`). Leaves written as
cards (a plant's ``cards``, :mod:`plantgen.geometry.meshes.leaf_cards`) are one quad each, in a
material ``"<material> (leaf card)"``: double-sided, ``alphaMode: MASK`` (cut-off 0.5), its
base colour texture the cards' atlas (white, alpha the shape; sampled clamped, without
mipmaps: averaged mipmaps would thin the cut-outs away with distance), each
vertex's ``COLOR_0`` its leaf's shade as for polygons, TEXCOORD_0 the card's tile.

A scene (``extras``, :class:`~plantgen.exporters.plants.SceneExtras`) adds, at the scene's
root: its ground, a mesh ``"Ground"`` (a square's two triangles or a disc's fan, facing up,
in a material named as the ground's: white times a texture of the ground as the renderers
draw it, its mottled albedo and an alpha fading to 0 over its outer ``fade``,
``alphaMode: BLEND``, so its edge does not show against the sky); its camera, a node ``"Camera"`` with a
perspective camera (``yfov`` the camera's fov_y, ``aspectRatio`` its width over height,
``znear`` and ``zfar`` 1/1000 and 1000 times the eye-target distance) placed at the eye,
looking at the target with the camera's up; its light, a node ``"Sun"`` with a
``KHR_lights_punctual`` directional light (white, ``intensity`` the scene light's, in
plantgen's units: 1 is the renderer's full light; glTF reads lux) shining along the scene
light's direction. ``KHR_lights_punctual`` is listed in ``extensionsUsed`` only: a reader
without it shows the scene without that light. All turn with the model (``up``).

A plant's per-row ``labels`` ({"_BRANCH_ORDER": ...}: ``plantgen batch`` labels each
mesh with its branch order) become application-specific vertex attributes of those
names (FLOAT scalars; glTF reserves names starting with ``_`` for this).

``up="z"`` turns the model (see :mod:`plantgen.geometry.skeletons.frames`); glTF's convention is y.
The file passes the Khronos glTF validator with no error and no warning (tested).
"""

from __future__ import annotations

import json
import os
import struct
from collections import deque
from dataclasses import replace
from importlib.metadata import PackageNotFoundError, version
from itertools import islice
from pathlib import Path
from urllib.parse import quote

import numpy as np

from ..files import write_all_atomically, write_atomically
from ..geometry.meshes.textures import COMPILED_FACES, mesh_tangents
from ..geometry.skeletons.frames import similarity_trs, turn_placements, up_rotation
from ..images import png_bytes
from .formats import ExportError
from .impostors import impostor_coverages, impostor_part
from .plants import (
    Colours,
    Part,
    Plant,
    Progress,
    SceneExtras,
    camera_pose,
    ground_mesh,
    ground_texture,
    ground_uv,
    leaf_name,
    leaf_parts,
    level_plant,
    light_rotation,
    material_colours,
    material_parts,
)
from .sway import JointRig, Timeline, copy_rotations, joint_rig, level_rig
from .textures import Textures, png_writes, texture_files, texture_image

__all__ = ["INSTANCING_EXTENSION", "LIGHTS_EXTENSION", "LOD_EXTENSION", "byte_weights", "gltf_document", "write_gltf"]

INSTANCING_EXTENSION = "EXT_mesh_gpu_instancing"
LOD_EXTENSION = "MSFT_lod"
LIGHTS_EXTENSION = "KHR_lights_punctual"
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
FLOAT, UNSIGNED_BYTE, UNSIGNED_SHORT, UNSIGNED_INT = 5126, 5121, 5123, 5125
GLB_MAGIC, GLB_JSON, GLB_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942
LINEAR, LINEAR_MIPMAP_LINEAR, REPEAT, CLAMP_TO_EDGE = 9729, 9987, 10497, 33071
#: Pieces one ``os.writev`` call takes (POSIX guarantees at least 16; Linux and macOS take 1,024).
WRITE_PIECES = min(max(os.sysconf("SC_IOV_MAX"), 16), 1024) \
    if hasattr(os, "sysconf") and "SC_IOV_MAX" in os.sysconf_names else 16


def generator() -> str:
    try:
        return f"plantgen {version('plantgen')}"
    except PackageNotFoundError:
        return "plantgen"


class _Buffer:
    """The binary buffer, its buffer views and accessors, built up in order."""

    def __init__(self) -> None:
        self.chunks: list[tuple[int, object]] = []   # (offset, bytes or a contiguous array)
        self.size = 0
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def add(self, array: np.ndarray, kind: str, component: int, target: int | None = None,
            bounds: bool = False, normalized: bool = False) -> int:
        """Append ``array`` ((count, width) or (count,)) as one view and one accessor; its index."""
        view = self._view(np.ascontiguousarray(array), target)
        accessor = {"bufferView": view, "componentType": component, "count": int(len(array)), "type": kind}
        if normalized:
            accessor["normalized"] = True
        if bounds:
            lo, hi = _bounds(array)
            accessor["min"], accessor["max"] = [float(v) for v in lo], [float(v) for v in hi]
        self.accessors.append(accessor)
        return len(self.accessors) - 1

    def add_blocks(self, blocks: np.ndarray, kind: str, component: int) -> list[int]:
        """Append ``blocks`` (b, count, width) as one view holding b accessors, one a block
        (float32 or 4-byte-aligned rows); their indices."""
        view = self._view(np.ascontiguousarray(blocks), None)
        size = blocks[0].nbytes if len(blocks) else 0
        first = len(self.accessors)
        self.accessors += [{"bufferView": view, "byteOffset": b * size, "componentType": component,
                            "count": int(blocks.shape[1]), "type": kind} for b in range(len(blocks))]
        return list(range(first, len(self.accessors)))

    def _view(self, data, target: int | None) -> int:
        """A view of ``data`` (bytes, or a contiguous array: kept, not copied, until the
        buffer is written) at the next 4-byte boundary; its index."""
        self.size += (-self.size) % 4
        length = data.nbytes if isinstance(data, np.ndarray) else len(data)
        view = {"buffer": 0, "byteOffset": self.size, "byteLength": length}
        if target is not None:
            view["target"] = target
        self.chunks.append((self.size, data))
        self.size += length
        self.views.append(view)
        return len(self.views) - 1

    def pieces(self) -> list:
        """The buffer's :attr:`size` bytes as pieces in order: each view's bytes (an
        array's own memory, not copied) and the zeros that align the next one."""
        out, at = [], 0
        for offset, data in self.chunks:
            if offset > at:
                out.append(bytes(offset - at))
            out.append(memoryview(data.reshape(-1).view(np.uint8)) if isinstance(data, np.ndarray) else data)
            at = offset + len(out[-1])
        return out

    def data(self) -> bytes:
        return b"".join(self.pieces())


def _bounds(array: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An accessor's ``min`` and ``max``: per column of ``array`` ((count, width) or (count,)).
    A column at a time (a strided reduction: about twenty times as fast as numpy's along
    axis 0 over (count, 3) rows); where a bound is zero, whose sign the two reductions
    may pick differently among -0.0 and 0.0, numpy's along axis 0, as written before."""
    if not len(array):                    # numpy's own error for an empty accessor
        return np.atleast_1d(np.min(array, axis=0)), np.atleast_1d(np.max(array, axis=0))
    columns = array.reshape(len(array), -1)
    lo = np.array([columns[:, k].min() for k in range(columns.shape[1])])
    hi = np.array([columns[:, k].max() for k in range(columns.shape[1])])
    if not (np.all(lo) and np.all(hi)):
        return np.atleast_1d(np.min(array, axis=0)), np.atleast_1d(np.max(array, axis=0))
    return lo, hi


def byte_weights(weights: np.ndarray) -> np.ndarray:
    """(v, 4) uint8 normalized skin weights of (v, 4) weights that sum to 1: each rounded
    down to 1/255ths, the shortfall given back one 1/255th at a time to the first nonzero
    ones, so every row sums to 255 exactly (halves: 128 and 127)."""
    weights = np.asarray(weights, dtype=np.float64)
    out = np.floor(weights * 255.0 + 1e-9)
    short = 255.0 - out.sum(axis=1)
    nonzero = weights > 0
    out += nonzero & (np.cumsum(nonzero, axis=1) <= short[:, None])
    return out.astype(np.uint8)


def _primitive(buffer: _Buffer, part, material: int, joint_count: int = 0) -> dict:
    positions = part.vertices.astype(np.float32)
    index_type = UNSIGNED_SHORT if len(positions) < 65536 else UNSIGNED_INT
    indices = part.faces.astype(np.uint16 if index_type == UNSIGNED_SHORT else np.uint32).ravel()
    attributes = {"POSITION": buffer.add(positions, "VEC3", FLOAT, ARRAY_BUFFER, bounds=True),
                  "NORMAL": buffer.add(part.normals, "VEC3", FLOAT, ARRAY_BUFFER),
                  "TEXCOORD_0": buffer.add(part.uv, "VEC2", FLOAT, ARRAY_BUFFER)}
    if part.colours is not None:
        attributes["COLOR_0"] = buffer.add(part.colours.astype(np.float32), "VEC3", FLOAT, ARRAY_BUFFER)
    for name, values in (part.labels or {}).items():     # application-specific: "_NAME"
        attributes[name] = buffer.add(values.astype(np.float32), "SCALAR", FLOAT, ARRAY_BUFFER)
    if part.joints is not None:
        joints = part.joints.astype(np.uint8 if joint_count <= 256 else np.uint16)
        attributes["JOINTS_0"] = buffer.add(joints, "VEC4", UNSIGNED_BYTE if joint_count <= 256 else UNSIGNED_SHORT,
                                            ARRAY_BUFFER)
        attributes["WEIGHTS_0"] = buffer.add(byte_weights(part.weights), "VEC4", UNSIGNED_BYTE, ARRAY_BUFFER,
                                             normalized=True)
    return {"attributes": attributes, "indices": buffer.add(indices, "SCALAR", index_type, ELEMENT_ARRAY_BUFFER),
            "material": material, "mode": 4}


def _material(name: str, rgb, double_sided: bool) -> dict:
    material = {"name": name, "pbrMetallicRoughness": {
        "baseColorFactor": [*rgb, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.8}}
    if double_sided:
        material["doubleSided"] = True
    return material


def _trs(matrices: np.ndarray) -> list[dict]:
    """A node's translation, rotation and scale for each placement (k, 4, 4)."""
    t, q, s = similarity_trs(matrices)
    return [{"translation": [float(v) for v in t[k]], "rotation": [float(v) for v in q[k]],
             "scale": [float(s[k])] * 3} for k in range(len(matrices))]


def _trs_nodes(name: str, mesh: int, matrices: np.ndarray) -> list[dict]:
    return [{"name": f"{name} {k + 1}" if len(matrices) > 1 else name, "mesh": mesh, **trs}
            for k, trs in enumerate(_trs(matrices))]


def _pose(rotation: np.ndarray, translation=None) -> dict:
    """A node's rotation (a unit quaternion, x y z w) of ``rotation`` (3, 3), and its
    translation where given."""
    matrix = np.eye(4)
    matrix[:3, :3] = rotation
    _, q, _ = similarity_trs(matrix[None])
    pose = {"rotation": [float(v) for v in q[0]]}
    if translation is not None:
        pose["translation"] = [float(v) for v in translation]
    return pose


def _gpu_node(buffer: _Buffer, name: str, mesh: int, matrices: np.ndarray) -> dict:
    t, q, s = similarity_trs(matrices)
    scale = np.repeat(s[:, None], 3, axis=1)
    attributes = {"TRANSLATION": buffer.add(t.astype(np.float32), "VEC3", FLOAT),
                  "ROTATION": buffer.add(q.astype(np.float32), "VEC4", FLOAT),
                  "SCALE": buffer.add(scale.astype(np.float32), "VEC3", FLOAT)}
    return {"name": name, "mesh": mesh, "extensions": {INSTANCING_EXTENSION: {"attributes": attributes}}}


class _Document:
    """The document being built: buffer, materials, meshes, nodes (the scene's roots
    among them), skins and the sway animation's channels."""

    def __init__(self, up: str, colours: Colours, animation: Timeline | None,
                 textures: Textures | None = None, image_uris: dict | None = None) -> None:
        self.up, self.colours, self.animation = up, colours, animation
        self.textures, self.image_uris = textures, image_uris
        self.images: list[dict] = []
        self.texture_list: list[dict] = []
        self.texture_keys: dict = {}
        self.samplers_tex = [{"magFilter": LINEAR, "minFilter": LINEAR_MIPMAP_LINEAR, "wrapS": REPEAT,
                              "wrapT": REPEAT}]
        self.buffer = _Buffer()
        self.material_index: dict[str, int] = {}
        self.materials, self.meshes, self.nodes, self.roots = [], [], [], []
        self.skins, self.channels, self.samplers = [], [], []
        self.times: int | None = None
        self.used_extension = False
        self.used_lod = False
        self.cameras: list[dict] = []
        self.lights: list[dict] = []
        self.card_materials: dict = {}
        self.card_textures: dict = {}
        self.card_sampler = 0
        self.impostors: set = set()
        self.compiled_tangents = False      # every primitive's tangents compiled (:func:`_document`)

    def node(self, node: dict, root: bool = True) -> int:
        self.nodes.append(node)
        if root:
            self.roots.append(len(self.nodes) - 1)
        return len(self.nodes) - 1

    def mesh(self, plant: Plant, rig: JointRig | None) -> int:
        """The plant's mesh: a primitive per material of its frusta and of its leaves (with
        their joints and weights when ``rig`` skins it); its index."""
        names = plant.mesh.material_names
        rgb = material_colours(names, self.colours)
        skin = None if rig is None else (rig.vertex_joints, rig.vertex_weights)
        cards = plant.cards if plant.has_leaves else None
        parts = (material_parts(plant.mesh, self.up, plant.labels, skin)
                 + leaf_parts(plant.leaves, self.up, None if rig is None else rig.leaf_joints,
                              names if self.colours is None else None,
                              None if cards is None else cards.uv.reshape(-1, 2)))
        primitives = []
        for part in parts:
            mat_name = leaf_name(names[part.material]) if part.leaf else names[part.material]
            white = part.colours is not None          # COLOR_0 holds each leaf's own colour
            colour = (1.0, 1.0, 1.0) if white else rgb[part.material]
            if part.leaf and cards is not None:
                material = self.card_material(f"{names[part.material]} (leaf card)", colour, cards.atlas)
            else:
                material = self.material(mat_name, colour, part.leaf)
            primitives.append(_primitive(self.buffer, part, material, 0 if rig is None else rig.joints))
            if self.normal_mapped(mat_name, part.leaf):
                tangents = mesh_tangents(part.vertices, part.normals, part.uv, part.faces,
                                         compiled=True if self.compiled_tangents else None)
                primitives[-1]["attributes"]["TANGENT"] = self.buffer.add(tangents, "VEC4", FLOAT, ARRAY_BUFFER)
        self.meshes.append({"name": plant.name, "primitives": primitives})
        return len(self.meshes) - 1

    def material(self, name: str, rgb, leaf: bool = False) -> int:
        """The index of the material ``name``, made on first use."""
        if name not in self.material_index:
            self.material_index[name] = len(self.materials)
            self.materials.append(_material(name, rgb, leaf))
            if not leaf and self.textures is not None and self.textures.get(name) is not None:
                self.textured(self.materials[-1], name)
        return self.material_index[name]

    def card_material(self, name: str, rgb, atlas) -> int:
        """A double-sided leaf-card material: base colour ``rgb`` times the card ``atlas``
        (:class:`~plantgen.geometry.meshes.leaf_cards.CardAtlas`, clamped at its edges), cut where
        its alpha is under 0.5 (``alphaMode: MASK``); one per name and atlas."""
        key = (name, id(atlas))
        if key not in self.card_materials:
            if id(atlas) not in self.card_textures:
                self.images.append({"name": "leaf cards", "mimeType": "image/png",
                                    "bufferView": self.buffer._view(png_bytes(atlas.image), None)})
                self.texture_list.append({"sampler": self.clamped_sampler(), "source": len(self.images) - 1})
                self.card_textures[id(atlas)] = len(self.texture_list) - 1
            material = _material(name, rgb, True)
            material["pbrMetallicRoughness"]["baseColorTexture"] = {"index": self.card_textures[id(atlas)]}
            material.update(alphaMode="MASK", alphaCutoff=0.5)
            self.materials.append(material)
            self.card_materials[key] = len(self.materials) - 1
        return self.card_materials[key]

    def normal_mapped(self, name: str, leaf: bool) -> bool:
        """Whether the material ``name`` has a normal map (its primitives need TANGENT)."""
        return (not leaf and self.textures is not None and "normal" in self.textures.kinds
                and self.textures.get(name) is not None)

    def texture(self, name: str, kind: str) -> int:
        """A texture (repeat, trilinear) of the map ``kind`` of material ``name``: its image
        in the buffer, or a file named by ``image_uris``; its index."""
        baked = self.textures.get(name)
        key = (name if kind == "normal" else baked.base or name, kind)   # buckets share colour and height
        if key in self.texture_keys:
            return self.texture_keys[key]
        image = {"name": f"{key[0]} {kind}", "mimeType": "image/png"}
        if self.image_uris is not None:
            image = {"name": image["name"], "uri": quote(self.image_uris[name][kind][0].name)}
        else:
            image["bufferView"] = self.buffer._view(png_bytes(texture_image(self.textures.get(name), kind)), None)
        self.images.append(image)
        self.texture_list.append({"sampler": 0, "source": len(self.images) - 1})
        self.texture_keys[key] = len(self.texture_list) - 1
        return len(self.texture_list) - 1

    def textured(self, material: dict, name: str) -> None:
        """Give ``material`` the baked maps of ``name``: base colour (where ``colours`` does
        not set one), normal map (TANGENT on its primitives), the height map in ``extras``."""
        baked, kinds = self.textures.get(name), self.textures.kinds
        pbr = material["pbrMetallicRoughness"]
        if "basecolor" in kinds and self.colours is None:
            pbr["baseColorTexture"] = {"index": self.texture(name, "basecolor")}
            pbr["baseColorFactor"] = [1.0, 1.0, 1.0, 1.0]
        if "normal" in kinds:
            material["normalTexture"] = {"index": self.texture(name, "normal")}
        if "height" in kinds:
            material["extras"] = {"plantgen": {
                "heightTexture": self.texture(name, "height"), "shellFraction": baked.shell,
                "displacement": baked.amplitude, "normalAspect": baked.aspect}}

    def extras(self, extras: SceneExtras) -> None:
        """A scene's ground (a mesh of its material), camera (perspective) and light
        (``KHR_lights_punctual``, directional), each a node at the scene's root."""
        if extras.ground is not None:
            vertices, normals, faces = ground_mesh(extras.ground, self.up)
            part = Part(0, vertices, normals.astype(np.float32), ground_uv(vertices @ up_rotation(self.up)), faces)
            material = self.ground_material(extras.ground)
            self.meshes.append({"name": "Ground", "primitives": [_primitive(self.buffer, part, material)]})
            self.node({"name": "Ground", "mesh": len(self.meshes) - 1})
        if extras.camera is not None:
            camera = extras.camera
            eye, rotation = camera_pose(camera, self.up)
            distance = float(np.linalg.norm(np.subtract(camera.target, camera.eye)))
            self.cameras.append({"name": "Camera", "type": "perspective", "perspective": {
                "yfov": float(np.radians(camera.fov_y)), "aspectRatio": camera.width / camera.height,
                "znear": distance / 1000, "zfar": distance * 1000}})
            self.node({"name": "Camera", "camera": len(self.cameras) - 1, **_pose(rotation, eye)})
        if extras.light is not None:
            self.lights.append({"name": "Sun", "type": "directional", "color": [1.0, 1.0, 1.0],
                                "intensity": float(extras.light.intensity)})
            self.node({"name": "Sun", **_pose(light_rotation(extras.light, self.up)),
                       "extensions": {LIGHTS_EXTENSION: {"light": len(self.lights) - 1}}})

    def ground_material(self, ground) -> int:
        """The ground's material, named as its material: white times its texture
        (:func:`~plantgen.exporters.plants.ground_texture`: the mottled albedo, and the
        opacity fading to 0 at its rim), ``alphaMode: BLEND``, so what lies behind its rim
        (the sky) shows through it as in plantgen's renders; its index."""
        self.images.append({"name": f"{ground.material} ground", "mimeType": "image/png",
                            "bufferView": self.buffer._view(png_bytes(ground_texture(ground, self.colours)), None)})
        self.texture_list.append({"sampler": 0, "source": len(self.images) - 1})
        material = _material(ground.material, (1.0, 1.0, 1.0), False)
        material["pbrMetallicRoughness"]["baseColorTexture"] = {"index": len(self.texture_list) - 1}
        material["alphaMode"] = "BLEND"
        self.materials.append(material)
        return len(self.materials) - 1

    def still(self, plant: Plant, mesh: int, instancing: str, lower: list[int] = (), coverage=None) -> None:
        """A plant that does not sway: one node, its copies instanced or one node each;
        with ``lower`` (the meshes of its levels of detail below the full one) each node
        names its levels' nodes in ``MSFT_lod`` (:meth:`levels`)."""
        if plant.matrices is None:
            nodes = [{"name": plant.name, "mesh": mesh}]
        elif instancing == "gpu" and len(plant.matrices) > 1:
            nodes = [_gpu_node(self.buffer, plant.name, mesh, turn_placements(plant.matrices, self.up))]
            self.used_extension = True
        else:
            nodes = _trs_nodes(plant.name, mesh, turn_placements(plant.matrices, self.up))
        for node in nodes:
            self.node(node)
            if lower:
                self.levels(node, lower, coverage)

    def impostor_mesh(self, name: str, impostor) -> int:
        """The impostor's card (:func:`~plantgen.exporters.impostors.impostor_part`): a
        double-sided material ``"<name> impostor"`` whose base colour is the colour atlas
        (``alphaMode: MASK``, clamped), its normal and depth atlases and the layout in
        ``extras.plantgen.impostor``; its mesh's index."""
        textures = {}
        for kind, image in (("colour", impostor.colour), ("normal", impostor.normal), ("depth", impostor.depth)):
            self.images.append({"name": f"{name} impostor {kind}", "mimeType": "image/png",
                                "bufferView": self.buffer._view(png_bytes(image), None)})
            self.texture_list.append({"sampler": self.clamped_sampler(), "source": len(self.images) - 1})
            textures[kind] = len(self.texture_list) - 1
        material = _material(f"{name} impostor", (1.0, 1.0, 1.0), True)
        material["pbrMetallicRoughness"]["baseColorTexture"] = {"index": textures["colour"]}
        material.update(alphaMode="MASK", alphaCutoff=0.5, extras={"plantgen": {"impostor": dict(
            impostor.layout(), normalTexture=textures["normal"], depthTexture=textures["depth"],
            renderer=impostor.renderer)}})
        self.materials.append(material)
        part = impostor_part(impostor, self.up)
        self.meshes.append({"name": f"{name} impostor",
                            "primitives": [_primitive(self.buffer, part, len(self.materials) - 1)]})
        self.impostors.add(len(self.meshes) - 1)
        return len(self.meshes) - 1

    def clamped_sampler(self) -> int:
        """The sampler of the alpha-cut atlases (leaf cards, impostors): bilinear from the
        full level, no mipmaps (mipmaps averaged from it thin a cut-out away with distance:
        a leaf's alpha falls under the cut-off; ``plantgen.benchmarks.engine_assets``
        measures it), clamped to the edge; made on first use."""
        if not self.card_sampler:
            self.samplers_tex.append({"magFilter": LINEAR, "minFilter": LINEAR,
                                      "wrapS": CLAMP_TO_EDGE, "wrapT": CLAMP_TO_EDGE})
            self.card_sampler = len(self.samplers_tex) - 1
        return self.card_sampler

    def levels(self, node: dict, lower: list[int], coverage, placement: dict | None = None) -> None:
        """``node`` (the full level) gains ``MSFT_lod``: per lower level a node outside the
        scene's tree (a reader without the extension shows the full level only) with that
        level's mesh and the node's placement; ``extras.MSFT_screencoverage`` the coverage
        below which each level gives way to the next (after the last: nothing)."""
        ids = []
        for k, mesh in enumerate(lower, start=1):
            level = {key: value for key, value in node.items() if key not in ("name", "mesh")}
            if mesh in self.impostors and "skin" in level:     # a card does not sway: the copy's placement
                level = dict(placement or {})
            ids.append(self.node({"name": f"{node['name']} lod{k}", "mesh": mesh, **level}, root=False))
        node.setdefault("extensions", {})[LOD_EXTENSION] = {"ids": ids}
        node["extras"] = {"MSFT_screencoverage": [float(c) for c in coverage]}
        self.used_lod = True

    def swaying(self, plant: Plant, mesh: int, rig: JointRig, lower: list[int] = (), coverage=None) -> None:
        """A swaying plant: per copy, a node placing its joints (one per segment, nested as
        the segments are), a skin over them, the mesh's node with that skin (at the root,
        untransformed: the joints place it) and, where the copy sways, a rotation channel
        per turning joint. With ``lower`` (its levels' meshes, skinned on the same joints)
        the mesh's node names in ``MSFT_lod`` one node per level with the same skin, so
        the one animation drives every level (:meth:`levels`)."""
        ibm = np.tile(np.eye(4, dtype=np.float32), (rig.joints, 1, 1))
        ibm[:, 3, :3] = -rig.bind                           # column-major: the translation is the 4th column
        inverse_binds = self.buffer.add(ibm.reshape(-1, 16), "MAT4", FLOAT)
        placements = None if plant.matrices is None else turn_placements(plant.matrices, self.up)
        children: list[list[int]] = [[] for _ in range(rig.joints)]
        for joint, parent in enumerate(rig.parent.tolist()):
            if parent >= 0:
                children[parent].append(joint)
        for copy in range(plant.copies):
            name = f"{plant.name} {copy + 1}" if plant.copies > 1 else plant.name
            first = len(self.nodes) + 1
            roots = np.flatnonzero(rig.parent < 0).tolist()
            holder = {"name": f"{name} joints", "children": [first + j for j in roots]}
            if placements is not None:
                holder.update(_trs(placements[copy:copy + 1])[0])
            skeleton = self.node(holder)
            for joint in range(rig.joints):
                node = {"name": f"s{joint}", "translation": [float(v) for v in rig.offset[joint]]}
                if children[joint]:
                    node["children"] = [first + c for c in children[joint]]
                self.node(node, root=False)
            self.skins.append({"name": name, "inverseBindMatrices": inverse_binds, "skeleton": skeleton,
                               "joints": list(range(first, first + rig.joints))})
            node = {"name": name, "mesh": mesh, "skin": len(self.skins) - 1}
            self.node(node)
            if lower:
                self.levels(node, lower, coverage, {} if placements is None else _trs(placements[copy:copy + 1])[0])
            if plant.sway.copy_moves(copy):
                self.animate(first, copy_rotations(plant.skeleton, plant.sway, copy,
                                                   None if plant.matrices is None else plant.matrices[copy],
                                                   self.animation.times, self.up, rig.joints))

    def animate(self, first: int, rotations: np.ndarray) -> None:
        """Rotation channels for the joints ``first + j`` that turn: ``rotations`` (k, j, 4)
        at the animation's key times, interpolated linearly (slerp)."""
        if self.times is None:
            self.times = self.buffer.add(self.animation.times.astype(np.float32), "SCALAR", FLOAT, bounds=True)
        turning = np.flatnonzero(np.any(rotations[..., :3] != 0, axis=(0, 2)))
        outputs = self.buffer.add_blocks(rotations[:, turning].transpose(1, 0, 2).astype(np.float32), "VEC4", FLOAT)
        for joint, output in zip(turning.tolist(), outputs, strict=True):
            self.channels.append({"sampler": len(self.samplers), "target": {"node": first + joint, "path": "rotation"}})
            self.samplers.append({"input": self.times, "output": output, "interpolation": "LINEAR"})

    def json(self, name: str) -> dict:
        doc = {"asset": {"version": "2.0", "generator": generator()}, "scene": 0,
               "scenes": [{"name": name, "nodes": self.roots}], "nodes": self.nodes, "meshes": self.meshes,
               "materials": self.materials, "accessors": self.buffer.accessors, "bufferViews": self.buffer.views}
        if self.texture_list:
            doc.update(images=self.images, textures=self.texture_list, samplers=self.samplers_tex)
        if self.skins:
            doc["skins"] = self.skins
        if self.channels:
            doc["animations"] = [{"name": "sway", "channels": self.channels, "samplers": self.samplers}]
        if self.cameras:
            doc["cameras"] = self.cameras
        used = [INSTANCING_EXTENSION] if self.used_extension else []
        if self.used_lod:     # used, not required: a reader without it shows the full level
            used.append(LOD_EXTENSION)
        if self.lights:       # used, not required: a reader without it shows the scene unlit
            doc["extensions"] = {LIGHTS_EXTENSION: {"lights": self.lights}}
            used.append(LIGHTS_EXTENSION)
        if used:
            doc["extensionsUsed"] = used
        if self.used_extension:
            doc["extensionsRequired"] = [INSTANCING_EXTENSION]
        return doc


def gltf_document(plants: list[Plant], **options) -> tuple[dict, bytes]:
    """The glTF JSON (without ``buffers``) and the binary buffer of ``plants``; ``options``:
    ``up``, ``colours``, ``instancing``, ``name``, ``progress``; ``animation``: the plants
    that sway are skinned and their sway is the animation ``"sway"``; ``extras``: the
    scene's ground, camera and light; ``textures``: the relief's maps (images in the
    buffer, or the files ``image_uris`` names:
    :func:`~plantgen.exporters.textures.texture_files`) (see the module docstring)."""
    doc, buffer = _document(plants, **options)
    return doc, buffer.data()


def _document(plants: list[Plant], *, up: str = "y", colours: Colours = None, instancing: str = "nodes",
              name: str = "plantgen", progress: Progress = None,
              animation: Timeline | None = None, extras: SceneExtras | None = None,
              textures: Textures | None = None, image_uris: dict | None = None) -> tuple[dict, _Buffer]:
    """:func:`gltf_document` with the buffer unwritten (its views' arrays kept)."""
    if instancing not in ("gpu", "nodes"):
        raise ValueError(f"instancing must be 'gpu' or 'nodes', got {instancing!r}")
    doc = _Document(up, colours, animation, textures, image_uris)
    # numba's load is paid once an export: where the plants' faces together reach the
    # threshold, every primitive's tangents are compiled (1,024 saguaros, say), not only a large one's
    doc.compiled_tangents = textures is not None and sum(
        len(plant.mesh.faces) for plant in plants if plant.mesh is not None) >= COMPILED_FACES
    for done, plant in enumerate(plants):
        sways = animation is not None and plant.sway is not None and plant.sway.moves
        rig = joint_rig(plant.skeleton, plant.mesh, plant.sway, plant.leaves, up, plant.name) if sways else None
        mesh = doc.mesh(plant, rig)
        levels = [] if plant.detail is None else [replace(level_plant(plant, k), name=f"{plant.name} lod{k}")
                                                  for k in range(1, len(plant.detail.levels))]
        if rig is None:
            lower = [doc.mesh(level, None) for level in levels]
        else:
            lower = [doc.mesh(level, level_rig(rig, level.skeleton, level.mesh, level.sway, level.leaves, up,
                                               plant.name)) for level in levels]
        coverage = None if plant.detail is None else plant.detail.coverage
        if plant.impostor is not None:
            lower.append(doc.impostor_mesh(plant.name, plant.impostor))
            coverage = impostor_coverages(coverage, plant.impostor)
        if rig is None:
            doc.still(plant, mesh, instancing, lower, coverage)
        else:
            doc.swaying(plant, mesh, rig, lower, coverage)
        if progress is not None:
            progress("write", done + 1, len(plants))
    if extras is not None:
        doc.extras(extras)
    return doc.json(name), doc.buffer


def _glb(doc: dict, buffer: _Buffer) -> list:
    """The ``.glb`` file as pieces in order (its header, JSON chunk and binary chunk: each
    view's bytes as the buffer holds them, not copied), written in one go by
    :func:`_write_pieces`."""
    doc = dict(doc, buffers=[{"byteLength": buffer.size}])
    text = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    text += b" " * ((-len(text)) % 4)
    size = buffer.size + (-buffer.size) % 4
    total = 12 + 8 + len(text) + 8 + size
    head = b"".join([struct.pack("<III", GLB_MAGIC, 2, total), struct.pack("<II", len(text), GLB_JSON), text,
                     struct.pack("<II", size, GLB_BIN)])
    return [head, *buffer.pieces(), bytes(size - buffer.size)]


def _write_pieces(path: Path, pieces: list) -> None:
    """Write ``pieces`` (bytes-like, in order) as the file ``path``: one gathering write
    (``os.writev``, up to :data:`WRITE_PIECES` pieces a call, again for what a call leaves
    unwritten), not a copy of them into one block first; one write each where the system
    has no ``writev``."""
    views = deque(memoryview(p).cast("B") for p in pieces if len(p))
    with open(path, "wb", buffering=0) as file:
        if not hasattr(os, "writev"):
            for view in views:
                file.write(view)
            return
        while views:
            written = os.writev(file.fileno(), list(islice(views, WRITE_PIECES)))
            while written:
                if written >= len(views[0]):
                    written -= len(views.popleft())
                else:
                    views[0], written = views[0][written:], 0


def write_gltf(plants: list[Plant], path: str | Path, *, up: str = "y", colours: Colours = None,
               instancing: str = "nodes", unit: float = 1.0, name: str | None = None,
               progress: Progress = None, animation: Timeline | None = None,
               extras: SceneExtras | None = None, textures: Textures | None = None) -> list[Path]:
    """Write ``plants`` as ``.glb``, or as ``.gltf`` with its ``.bin`` beside it (see the
    module docstring); ``textures``: the relief's maps, inside the ``.glb``, or as PNG files
    beside a ``.gltf`` (``<stem>_<material>_<kind>.png``); nothing is left half-written.
    Returns the written paths (a :class:`~plantgen.exporters.plants.MeshWriter`; ``unit`` is
    not written: glTF has no unit field, and the model is written in model units)."""
    path = Path(path)
    if not any(plant.mesh is not None and len(plant.mesh.faces) for plant in plants):
        raise ExportError(f"{path}: nothing to export (the model has no segments)")
    glb = path.suffix.lower() == ".glb"
    files = None
    if textures is not None and not glb:
        files = texture_files(path, textures, [n for p in plants for n in p.mesh.material_names], v_up=False)
    doc, buffer = _document(plants, up=up, colours=colours, instancing=instancing,
                            name=name or path.name.split(".")[0] or "plantgen", progress=progress,
                            animation=animation, extras=extras, textures=textures, image_uris=files)
    if glb:
        pieces = _glb(doc, buffer)
        return [write_atomically(path, lambda tmp: _write_pieces(Path(tmp), pieces), ExportError)]
    bin_path = path.with_suffix(".bin")
    doc = dict(doc, buffers=[{"byteLength": buffer.size, "uri": quote(bin_path.name)}])
    text = json.dumps(doc, indent=1)
    return write_all_atomically([*_png_writes(files, doc),
                                 (bin_path, lambda tmp: _write_pieces(Path(tmp), buffer.pieces())),
                                 (path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))], ExportError)


def _png_writes(files: dict | None, doc: dict) -> list:
    """The (path, write) pairs of the texture files the document names (see
    :func:`~plantgen.exporters.textures.texture_files`), each once."""
    named = {image.get("uri") for image in doc.get("images", [])}
    return [(png, write) for png, write in png_writes(files or {}) if quote(png.name) in named]
