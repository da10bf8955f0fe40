"""Issue 17: every mesh export carries a grammar's leaves ({ . } polygons), read back by
independent readers (trimesh, meshio, usd-core, the glTF JSON and the Khronos validator);
glTF and USD mark them double-sided; SWC and QSM carry the skeleton only and say so; a
grammar without leaves writes what the frusta-only writer writes."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import meshio
import numpy as np
import pytest
import trimesh
from _cli import run_cli
from _node import assert_khronos_valid, needs_node
from test_export_scene import usd_problems

from plantgen.exporters import export_mesh
from plantgen.exporters.plants import leaf_uv
from plantgen.geometry.meshes.mesh import tessellate
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.pipeline import export_model, grow_file

GRAMMAR = """\
name: leafy
axiom: A
iterations: 3
seed: 2
materials: [bark, leaf]
turtle: {{angle: 40}}
rules:
  - "A -> F[+L]F[-L]A"
interpretation:
  - "L -> {leaf}"
"""
#: Bracketed, so the turtle comes back where it was: the leafless grammar draws the same
#: skeleton. Two polygons per leaf, each with four vertices (two triangles), in material 1.
LEAF = "['{.+G.-G.-G.}][-'{.G.+G(0.3).+G.}]"


@pytest.fixture(scope="module")
def grammars(tmp_path_factory):
    root = tmp_path_factory.mktemp("grammars")
    leafy, bare = root / "leafy.yaml", root / "bare.yaml"
    leafy.write_text(GRAMMAR.format(leaf=LEAF))
    bare.write_text(GRAMMAR.format(leaf="[]"))
    return leafy, bare


def counts(path: Path):
    """(frusta triangles, leaf triangles, leaf polygons) of the grammar at ``path``."""
    grown = grow_file(path)
    mesh = tessellate(skin_skeleton(grown.skeleton), 1)
    return len(mesh.faces), len(grown.polygons.triangles), len(grown.polygons)


def gltf_json(path: Path) -> dict:
    if path.suffix == ".gltf":
        return json.loads(path.read_text())
    data = path.read_bytes()
    length, kind = struct.unpack_from("<II", data, 12)
    assert kind == 0x4E4F534A
    return json.loads(data[20:20 + length])


def test_the_grammar_has_leaves_and_the_same_skeleton_as_the_bare_one(grammars):
    leafy, bare = grammars
    frusta, leaf_tris, polygons = counts(leafy)
    assert polygons == 12 and leaf_tris == 24          # 6 leaves of two quadrilaterals
    assert counts(bare) == (frusta, 0, 0)


@pytest.mark.parametrize("suffix", [".glb", ".gltf", ".obj", ".ply", ".stl"])
def test_trimesh_reads_frusta_and_leaf_triangles(grammars, tmp_path, suffix):
    leafy, _ = grammars
    frusta, leaf_tris, _ = counts(leafy)
    path = tmp_path / f"plant{suffix}"
    summary = export_model(leafy, path)
    assert summary["leaf_triangles"] == leaf_tris
    assert summary["triangles"] == frusta + leaf_tris
    loaded = trimesh.load(path)
    if isinstance(loaded, trimesh.Scene):
        loaded = loaded.to_geometry()
    assert len(loaded.faces) == frusta + leaf_tris
    # the leaves lie where the grammar put them: their area survives the write
    areas = grow_file(leafy).polygons.triangle_areas().sum()
    bare = tessellate(skin_skeleton(grow_file(leafy).skeleton), 1)
    frusta_area = 0.5 * np.linalg.norm(np.cross(*(bare.vertices[bare.faces[:, k]] - bare.vertices[bare.faces[:, 0]]
                                                  for k in (1, 2))), axis=1).sum()
    assert loaded.area == pytest.approx(frusta_area + areas, rel=1e-5)


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".stl"])
def test_meshio_reads_the_leaf_triangles(grammars, tmp_path, suffix):
    leafy, _ = grammars
    frusta, leaf_tris, _ = counts(leafy)
    path = tmp_path / f"plant{suffix}"
    export_model(leafy, path)
    back = meshio.read(path)
    assert sum(len(c.data) for c in back.cells if c.type == "triangle") == frusta + leaf_tris


def test_gltf_leaves_have_their_own_double_sided_material(grammars, tmp_path):
    leafy, _ = grammars
    frusta, leaf_tris, _ = counts(leafy)
    path = tmp_path / "plant.glb"
    export_model(leafy, path)
    doc = gltf_json(path)
    materials = doc["materials"]
    assert [m["name"] for m in materials] == ["bark", "leaf (leaf)"]
    assert materials[1]["doubleSided"] is True
    assert "doubleSided" not in materials[0]                # the frusta keep back-face culling
    # bark's colour is its baked map, each leaf's its vertices' COLOR_0 (the leaf material white)
    assert "baseColorTexture" in materials[0]["pbrMetallicRoughness"]
    assert all("COLOR_0" in p["attributes"] for p in doc["meshes"][0]["primitives"] if p["material"] == 1)
    by_material = {}
    for prim in doc["meshes"][0]["primitives"]:
        count = doc["accessors"][prim["indices"]]["count"] // 3
        by_material[materials[prim["material"]]["name"]] = count
        uv = doc["accessors"][prim["attributes"]["TEXCOORD_0"]]
        assert uv["count"] == doc["accessors"][prim["attributes"]["POSITION"]]["count"]
    assert by_material == {"bark": frusta, "leaf (leaf)": leaf_tris}


def test_gltf_leaf_normals_are_the_polygon_normals(grammars, tmp_path):
    leafy, _ = grammars
    path = tmp_path / "plant.glb"
    export_model(leafy, path)
    scene = trimesh.load(path)
    polygons = grow_file(leafy).polygons
    leaves = [g for g in scene.geometry.values() if len(g.faces) == len(polygons.triangles)]
    assert len(leaves) == 1
    normals = np.asarray(leaves[0].vertex_normals)
    # each triangle's geometric normal agrees with its vertices' normals (windings kept)
    assert np.all(np.einsum("ij,ij->i", leaves[0].face_normals, normals[leaves[0].faces[:, 0]]) > 0.99)


def test_leaf_texture_coordinates_span_each_leaf(grammars):
    polygons = grow_file(grammars[0]).polygons
    uv = leaf_uv(polygons).astype(np.float64)
    for p in range(len(polygons)):
        corners = uv[np.unique(polygons.triangles[polygons.polygon == p])]
        assert np.allclose(corners.min(axis=0), 0) and np.allclose(corners.max(axis=0), 1)
    # a similarity of the plane: a triangle's uv area over its area is one scale per polygon
    a, b, c = (uv[polygons.triangles[:, k]] for k in range(3))
    ratio = np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]) / 2 / polygons.triangle_areas()
    for p in range(len(polygons)):
        r = ratio[polygons.polygon == p]
        assert np.allclose(r, r[0], rtol=1e-4)


@needs_node
@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_gltf_with_leaves_passes_the_khronos_validator(grammars, tmp_path, suffix):
    path = tmp_path / f"plant{suffix}"
    export_model(grammars[0], path)
    assert_khronos_valid(path)


def test_obj_leaves_use_their_own_mtl_material(grammars, tmp_path):
    leafy, _ = grammars
    _, leaf_tris, _ = counts(leafy)
    path = tmp_path / "plant.obj"
    export_model(leafy, path)
    # one material per shade the leaves take (OBJ has no vertex colours), each a distinct colour
    mtl = (tmp_path / "plant.mtl").read_text().split("newmtl ")[1:]
    shades = {block.split()[0]: block.split("Kd ")[1].split("\n")[0] for block in mtl
              if block.startswith("leaf_(leaf)_")}
    assert shades and len(set(shades.values())) == len(shades)
    lines = path.read_text().splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("usemtl leaf_(leaf)"))
    faces = [ln for ln in lines[start + 1:] if ln.startswith("f ")]
    assert len(faces) == leaf_tris


def test_usd_leaf_mesh_is_double_sided(grammars, tmp_path):
    pytest.importorskip("pxr", reason="usd-core is the optional extra plantgen[usd]")
    from pxr import Usd, UsdGeom

    leafy, _ = grammars
    frusta, leaf_tris, _ = counts(leafy)
    path = tmp_path / "plant.usda"
    export_model(leafy, path)
    stage = Usd.Stage.Open(str(path))
    root = stage.GetDefaultPrim().GetPath()
    leaves = UsdGeom.Mesh(stage.GetPrimAtPath(root.AppendChild("Leaves")))
    body = UsdGeom.Mesh(stage.GetPrimAtPath(root.AppendChild("Mesh")))
    assert leaves.GetDoubleSidedAttr().Get() is True
    assert not body.GetDoubleSidedAttr().Get()
    assert len(leaves.GetFaceVertexCountsAttr().Get()) == leaf_tris
    assert len(body.GetFaceVertexCountsAttr().Get()) == frusta
    assert usd_problems(path) == []


@pytest.mark.parametrize("suffix", [".swc", ".qsm.csv"])
def test_skeleton_formats_say_they_drop_the_leaves(grammars, tmp_path, suffix):
    leafy, bare = grammars
    summary = export_model(leafy, tmp_path / f"plant{suffix}")
    assert any("skeleton only" in w and "12 leaf polygons" in w for w in summary["warnings"])
    assert not export_model(bare, tmp_path / f"bare{suffix}")["warnings"]


def test_cli_export_warns_on_stderr_for_swc(grammars, tmp_path):
    code, _, err = run_cli("export", grammars[0], "-o", tmp_path / "plant.swc")
    assert code == 0
    assert "skeleton only" in err


def test_cli_export_counts_the_leaf_triangles(grammars, tmp_path):
    frusta, leaf_tris, _ = counts(grammars[0])
    code, out, _ = run_cli("export", grammars[0], "-o", tmp_path / "plant.glb")
    assert code == 0
    assert f"{frusta + leaf_tris:,} triangles" in out and f"{leaf_tris} of leaves, double-sided" in out


@pytest.mark.parametrize("suffix", [".glb", ".gltf", ".obj", ".ply", ".stl"])
def test_a_grammar_without_leaves_writes_what_the_frusta_writer_writes(grammars, tmp_path, suffix):
    _, bare = grammars
    grown = grow_file(bare)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    export_model(bare, tmp_path / "a" / f"{grown.name}{suffix}")
    export_mesh(tessellate(skin_skeleton(grown.skeleton), 1), tmp_path / "b" / f"{grown.name}{suffix}",
                textures=True)
    for a in sorted((tmp_path / "a").iterdir()):
        assert a.read_bytes() == (tmp_path / "b" / a.name).read_bytes(), a.name
