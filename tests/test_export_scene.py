"""Instanced scenes (issue 16): a scene's repeated plants are written once, with glTF's
EXT_mesh_gpu_instancing (Khronos validator, three.js) or core glTF nodes, and as a USD
PointInstancer or instanceable references; USD passes usd-core's compliance checker."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
import trimesh
from _cli import run_cli
from _node import assert_khronos_valid, needs_node, three_js_meshes

from plantgen.exporters import export_mesh
from plantgen.geometry.meshes.mesh import tessellate
from plantgen.geometry.skeletons.frames import turn_placements
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.pipeline import export_model, grow_file

ORCHARD = """\
name: orchard
seed: 3
instances:
  - grammar: abop_monopodial          # deterministic: six equal trees
    grid: {count: [3, 2], spacing: [8, 8], jitter: 0.3}
    scale: 0.02
  - skeleton:                          # a post with a leafy tip, twice
      materials: [stone, leaf]
      segments:
        - {start: [0, 0, 0], end: [0, 1, 0], r_start: 0.2, r_end: 0.15, material: stone}
        - {start: [0, 1, 0], end: [0.5, 1.6, 0], r_start: 0.1, r_end: 0.0, parent: 0, material: leaf}
    position: [20, 0, 0]
    rotation: [10, 30, 0]
    grid: {count: [2, 1], spacing: [3, 3]}
  - {grammar: saguaro, seed: 5, position: [-20, 0, 0], scale: 0.5}
"""
COPIES = {"abop_monopodial": 6, "skeleton": 2, "saguaro": 1}


@pytest.fixture
def orchard(tmp_path):
    path = tmp_path / "orchard.yaml"
    path.write_text(ORCHARD)
    return path


def placed_matrices(grown, up="y") -> dict:
    return {p.name: turn_placements(p.matrices, up) for p in grown.scene.plants()}


def test_a_scene_groups_equal_copies_into_one_plant(orchard):
    grown = grow_file(orchard)
    plants = grown.scene.plants()
    assert {p.name: len(p.matrices) for p in plants} == COPIES
    # The plants, placed where their copies stand, are the scene: same segments.
    placed = Skeleton.concatenate([p.skeleton.transformed(m) for p in plants for m in p.matrices])
    order = np.concatenate([p.instances for p in plants])
    whole = Skeleton.concatenate([grown.scene.instances[k].skeleton.transformed(grown.scene.instances[k].matrix)
                                  for k in order])
    assert len(placed) == len(grown.skeleton)
    assert np.allclose(placed.start, whole.start) and np.allclose(placed.end, whole.end)


def glb_json(path) -> tuple[dict, bytes]:
    data = path.read_bytes()
    length = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + length])
    return doc, data[20 + length + 8:]


def accessor(doc, blob, index) -> np.ndarray:
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc["type"]]
    assert acc["componentType"] == 5126 and "byteStride" not in view
    return np.frombuffer(blob, np.float32, acc["count"] * width, view["byteOffset"] + acc.get("byteOffset", 0)) \
        .reshape(acc["count"], width)


def trs_matrices(t, q, s) -> np.ndarray:
    x, y, z, w = q.T.astype(np.float64)
    rot = np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
                    np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
                    np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], 1)
    m = np.zeros((len(t), 4, 4))
    m[:, :3, :3] = rot * s[:, :1, None]
    m[:, :3, 3], m[:, 3, 3] = t, 1
    return m


@pytest.mark.parametrize("up", ["y", "z"])
def test_gltf_gpu_instancing_places_every_copy(orchard, tmp_path, up):
    info = export_model(orchard, tmp_path / "orchard.glb", up=up, instancing="gpu")
    doc, blob = glb_json(tmp_path / "orchard.glb")
    assert doc["extensionsRequired"] == ["EXT_mesh_gpu_instancing"]
    assert doc["extensionsUsed"] == ["EXT_mesh_gpu_instancing", "KHR_lights_punctual"]   # the scene's light
    want = placed_matrices(grow_file(orchard), up)
    nodes = {node["name"]: node for node in doc["nodes"] if "mesh" in node}      # not the camera, the light
    assert set(nodes) == set(COPIES)
    for name, copies in COPIES.items():
        node = nodes[name]
        if copies == 1:
            assert "extensions" not in node
            got = trs_matrices(np.array([node["translation"]]), np.array([node["rotation"]]),
                               np.array([node["scale"]]))
        else:
            attrs = node["extensions"]["EXT_mesh_gpu_instancing"]["attributes"]
            t, q, s = (accessor(doc, blob, attrs[k]) for k in ("TRANSLATION", "ROTATION", "SCALE"))
            assert len(t) == len(q) == len(s) == copies
            assert np.allclose(np.linalg.norm(q, axis=1), 1, atol=1e-6) and np.allclose(s, s[:, :1])
            got = trs_matrices(t, q, s)
        assert np.allclose(got, want[name], atol=1e-5)
    # Written once: the file holds each plant's triangles once; copies draw the rest.
    written = sum(doc["accessors"][p["indices"]]["count"] // 3 for m in doc["meshes"] for p in m["primitives"])
    assert written == info["triangles"] < info["drawn"]
    flat = export_model(orchard, tmp_path / "flat.glb", instancing="off", up=up)
    assert flat["triangles"] == info["drawn"]


def test_gltf_nodes_share_one_mesh_per_plant_and_load_anywhere(orchard, tmp_path):
    """--instancing nodes: core glTF (no extension), one node per copy, the mesh written
    once; trimesh draws every copy, the same solid as the flattened export."""
    info = export_model(orchard, tmp_path / "nodes.glb", instancing="nodes")
    doc, _ = glb_json(tmp_path / "nodes.glb")
    assert "extensionsRequired" not in doc and doc["extensionsUsed"] == ["KHR_lights_punctual"]   # its light
    assert len(doc["meshes"]) == len(COPIES)
    assert sum("mesh" in node for node in doc["nodes"]) == sum(COPIES.values())
    nodes = trimesh.load(tmp_path / "nodes.glb").to_geometry()
    export_model(orchard, tmp_path / "flat.glb", instancing="off")
    flat = trimesh.load(tmp_path / "flat.glb").to_geometry()
    assert len(nodes.faces) == len(flat.faces) == info["drawn"]
    assert nodes.volume == pytest.approx(flat.volume, rel=1e-6)
    # The polygons around a tilted copy start at another angle when it is skinned in place
    # (the texture frame's reference direction follows the world's axes), so their
    # corners may differ by up to r·(1 - cos π/N) = 0.0015 (r = 0.2, N = 16).
    assert np.allclose(nodes.bounds, flat.bounds, atol=0.0015)


@needs_node
@pytest.mark.parametrize("instancing", ["gpu", "nodes"])
def test_the_instanced_gltf_passes_the_khronos_validator(orchard, tmp_path, instancing):
    """The validator checks the document around the extension (accessors, views, nodes,
    meshes); EXT_mesh_gpu_instancing itself it does not know (its report says so, as an
    info), which three.js's loader checks below."""
    export_model(orchard, tmp_path / "orchard.glb", instancing=instancing)
    export_model(orchard, tmp_path / "orchard.gltf", instancing=instancing)
    assert_khronos_valid(tmp_path / "orchard.glb")
    assert_khronos_valid(tmp_path / "orchard.gltf")


def test_the_default_scene_gltf_requires_no_extension(orchard, tmp_path):
    """Issue 24: the default glTF of a scene with repeated plants opens in every reader
    (Blender 3.4 refuses a file that requires EXT_mesh_gpu_instancing): core glTF nodes,
    one per copy, sharing their plant's mesh."""
    export_model(orchard, tmp_path / "orchard.glb")
    doc, _ = glb_json(tmp_path / "orchard.glb")
    assert "extensionsRequired" not in doc
    assert "EXT_mesh_gpu_instancing" not in doc.get("extensionsUsed", [])
    assert len(doc["meshes"]) == len(COPIES)
    assert sum("mesh" in n for n in doc["nodes"]) == sum(COPIES.values())


@needs_node
@pytest.mark.parametrize("instancing", ["nodes", "gpu"])
def test_three_js_loads_the_instanced_gltf_with_every_copy_in_place(orchard, tmp_path, instancing):
    """Default (nodes): a mesh per copy, the plant's geometry shared; gpu: an
    InstancedMesh per repeated plant."""
    info = export_model(orchard, tmp_path / "orchard.glb", instancing=instancing)
    if instancing == "nodes":
        assert_khronos_valid(tmp_path / "orchard.glb")
    meshes = three_js_meshes(tmp_path / "orchard.glb", tmp_path)
    want = placed_matrices(grow_file(orchard))
    drawn, got_by_plant = 0, {}
    for mesh in meshes:
        plant = next(name for name in COPIES if mesh["name"].startswith(name))
        assert mesh["instanced"] == (instancing == "gpu" and COPIES[plant] > 1)
        got = np.array(mesh["matrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)       # column-major
        got_by_plant.setdefault(plant, {}).setdefault(mesh["material"], []).extend(got)
        drawn += mesh["triangles"] * len(got)
    for plant, by_material in got_by_plant.items():
        for got in by_material.values():
            got = np.array(got)
            assert got.shape[0] == COPIES[plant]
            order = np.lexsort(got[:, :3, 3].T)
            want_sorted = want[plant][np.lexsort(want[plant][:, :3, 3].T)]
            assert np.allclose(got[order], want_sorted, atol=1e-5)
    assert drawn == info["drawn"]
    assert {m["material"] for m in meshes} == {"bark", "stone", "leaf", "cactus"}


# ---------------------------------------------------------------------------- USD
def usd_problems(path) -> list[str]:
    """What usd-core's compliance checker (UsdUtils.ComplianceChecker, usdchecker's engine
    until 26.8) and its UsdValidation validators (usdchecker's since) find."""
    import warnings

    from pxr import Usd, UsdUtils, UsdValidation

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        checker = UsdUtils.ComplianceChecker()
    checker.CheckCompliance(str(path))
    problems = [*checker.GetErrors(), *checker.GetFailedChecks(), *checker.GetWarnings()]
    context = UsdValidation.ValidationContext(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    problems += [e.GetMessage() for e in context.Validate(Usd.Stage.Open(str(path)))]
    return problems


def test_the_usd_checks_catch_a_broken_stage(tmp_path):
    """The checks bite: a stage without a default prim, with an unbound material binding
    API and a mesh without extent, fails them."""
    from pxr import Usd, UsdGeom, UsdShade

    stage = Usd.Stage.CreateNew(str(tmp_path / "broken.usda"))
    mesh = UsdGeom.Mesh.Define(stage, "/a/mesh")
    mesh.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0)])
    material = UsdShade.Material.Define(stage, "/a/material")
    UsdShade.MaterialBindingAPI(mesh.GetPrim()).Bind(material)     # bound without applying the API
    stage.Save()
    assert usd_problems(tmp_path / "broken.usda")


@pytest.mark.parametrize("suffix", [".usda", ".usdc", ".usd"])
def test_a_usd_plant_passes_the_compliance_checker_with_its_materials(tmp_path, suffix):
    from pxr import Usd, UsdGeom, UsdShade

    info = export_model("well", tmp_path / f"well{suffix}", level=1)
    assert usd_problems(info["path"]) == []
    stage = Usd.Stage.Open(str(info["path"]))
    assert UsdGeom.GetStageUpAxis(stage) == "Y" and UsdGeom.GetStageMetersPerUnit(stage) == 1
    prims = list(Usd.PrimRange(stage.GetPseudoRoot(), Usd.TraverseInstanceProxies()))   # the copies' too
    meshes = [UsdGeom.Mesh(p) for p in prims if p.IsA(UsdGeom.Mesh) and "Ground" not in str(p.GetPath())]
    triangles = sum(len(m.GetFaceVertexCountsAttr().Get()) for m in meshes)
    assert triangles == info["drawn"]
    bound = set()
    for prim in prims:
        if prim.IsA(UsdGeom.Subset):
            material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
            bound.add(material.GetPrim().GetDisplayName() or material.GetPath().name)
    assert bound == {"stone", "bark"}


def usd_volume(stage, mesh_prim, matrix=None) -> float:
    from pxr import UsdGeom

    mesh = UsdGeom.Mesh(mesh_prim)
    points = np.array(mesh.GetPointsAttr().Get(), dtype=np.float64)
    faces = np.array(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
    tm = trimesh.Trimesh(points, faces, process=False)
    tm.merge_vertices()
    return tm.volume * (1.0 if matrix is None else abs(np.linalg.det(matrix[:3, :3])))


def test_usd_and_gltf_hold_the_same_solid(tmp_path):
    from pxr import Usd, UsdGeom

    export_model("saguaro", tmp_path / "s.usdc", level=2)
    export_model("saguaro", tmp_path / "s.glb", level=2)
    stage = Usd.Stage.Open(str(tmp_path / "s.usdc"))
    mesh = next(p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
    glb = trimesh.load(tmp_path / "s.glb").to_geometry()
    glb.merge_vertices()
    assert usd_volume(stage, mesh) == pytest.approx(glb.volume, rel=1e-6)


@pytest.mark.parametrize("up", ["y", "z"])
def test_a_usd_scene_is_a_point_instancer_over_one_prototype_per_plant(orchard, tmp_path, up):
    from pxr import Usd, UsdGeom

    info = export_model(orchard, tmp_path / "orchard.usda", up=up, unit=0.01, instancing="gpu")
    assert usd_problems(info["path"]) == []
    stage = Usd.Stage.Open(str(info["path"]))
    assert UsdGeom.GetStageUpAxis(stage) == up.upper() and UsdGeom.GetStageMetersPerUnit(stage) == 0.01
    assert stage.GetDefaultPrim().GetName() == "orchard"
    [prim] = [p for p in stage.Traverse() if p.IsA(UsdGeom.PointInstancer)]
    instancer = UsdGeom.PointInstancer(prim)
    prototypes = [t.name for t in instancer.GetPrototypesRel().GetTargets()]
    assert prototypes == list(COPIES)
    index = np.array(instancer.GetProtoIndicesAttr().Get())
    assert np.bincount(index).tolist() == list(COPIES.values())
    got = np.array([np.array(m).T for m in instancer.ComputeInstanceTransformsAtTime(
        Usd.TimeCode.Default(), Usd.TimeCode.Default())])
    want = placed_matrices(grow_file(orchard), up)
    for k, name in enumerate(prototypes):
        assert np.allclose(got[index == k], want[name], atol=1e-5)
    # Every prototype's mesh written once; the copies draw the flattened scene's triangles.
    meshes = {p.GetParent().GetName(): UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)}
    per_plant = {name: len(m.GetFaceVertexCountsAttr().Get()) for name, m in meshes.items()}
    assert sum(per_plant.values()) == info["triangles"]
    assert sum(per_plant[name] * copies for name, copies in COPIES.items()) == info["drawn"]


def test_usd_skeleton_curves_carry_diameters(tmp_path):
    """The skeleton is a BasisCurves guide: one curve per branch, widths = 2·radius."""
    from pxr import Usd, UsdGeom

    from plantgen.geometry.skeletons.topology import branches

    skel = grow_file("saguaro").skeleton
    export_model("saguaro", tmp_path / "s.usda", level=0)
    stage = Usd.Stage.Open(str(tmp_path / "s.usda"))
    [prim] = [p for p in stage.Traverse() if p.IsA(UsdGeom.BasisCurves)]
    curves = UsdGeom.BasisCurves(prim)
    assert curves.GetPurposeAttr().Get() == UsdGeom.Tokens.guide and curves.GetTypeAttr().Get() == "linear"
    counts = list(curves.GetCurveVertexCountsAttr().Get())
    assert len(counts) == len(branches(skel))
    points = np.array(curves.GetPointsAttr().Get(), dtype=np.float64)
    widths = np.array(curves.GetWidthsAttr().Get(), dtype=np.float64)
    assert curves.GetWidthsInterpolation() == UsdGeom.Tokens.vertex and len(widths) == len(points)
    for seg in range(len(skel)):       # every segment's end point carries its diameter
        at = np.flatnonzero(np.linalg.norm(points - skel.end[seg], axis=1) < 1e-5)
        assert np.any(np.isclose(widths[at], 2 * skel.r_end[seg], rtol=1e-6))


def test_usd_nodes_are_instanceable_references(orchard, tmp_path):
    from pxr import Usd, UsdGeom

    info = export_model(orchard, tmp_path / "orchard.usda")       # the default: nodes
    assert usd_problems(info["path"]) == []
    stage = Usd.Stage.Open(str(info["path"]))
    copies = [p for p in stage.GetDefaultPrim().GetChildren() if p.IsInstance()]
    assert len(copies) == sum(COPIES.values())
    drawn = sum(len(UsdGeom.Mesh(p).GetFaceVertexCountsAttr().Get())
                for p in Usd.PrimRange(stage.GetPseudoRoot(), Usd.TraverseInstanceProxies()) if p.IsA(UsdGeom.Mesh))
    assert drawn == info["drawn"]


def test_the_export_command_says_what_instancing_saved(orchard, tmp_path):
    code, stdout, stderr = run_cli("export", orchard, "-o", tmp_path / "o.glb", "--subdiv", "0")
    assert code == 0, stderr
    assert "3 distinct plants written once for 9 copies" in stdout


def test_export_mesh_of_a_tessellation_writes_usd(tmp_path):
    mesh = tessellate(skin_skeleton(grow_file("saguaro").skeleton), 1)
    path = export_mesh(mesh, tmp_path / "plant.usda")
    assert usd_problems(path) == []
