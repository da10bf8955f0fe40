"""The relief's textures in the files, read back by other projects' readers: the Khronos
glTF validator and three.js (glTF), usd-core (USD: its shader network and compliance
checker), trimesh and meshio (OBJ), Pillow (the PNGs), Blender where it is installed."""

from __future__ import annotations

import io
import json
import struct
from pathlib import Path

import numpy as np
import pytest
from _blender import blender_line
from _cli import run_cli
from _node import assert_khronos_valid, khronos_issues, needs_node, three_js_materials
from PIL import Image

from plantgen.exporters import ExportError
from plantgen.exporters.textures import texture_image
from plantgen.geometry.meshes.textures import bake_material
from plantgen.pipeline import export_model


def _glb(path: Path) -> tuple[dict, bytes]:
    data = path.read_bytes()
    (json_len,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20:20 + json_len])
    return doc, data[20 + json_len + 8:]


def _png(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)))


def test_glb_materials_carry_the_baked_maps(tmp_path):
    summary = export_model("well", tmp_path / "well.glb")
    assert set(summary["textures"]) == {"stone", "bark"}
    doc, blob = _glb(tmp_path / "well.glb")
    materials = {m["name"]: m for m in doc["materials"]}
    for name in ("stone", "bark"):
        m = materials[name]
        pbr = m["pbrMetallicRoughness"]
        assert pbr["baseColorFactor"] == [1.0, 1.0, 1.0, 1.0]
        baked = bake_material(name, np.array([m["extras"]["plantgen"]["normalAspect"]]))
        for kind, index in (("basecolor", pbr["baseColorTexture"]["index"]),
                            ("normal", m["normalTexture"]["index"]),
                            ("height", m["extras"]["plantgen"]["heightTexture"])):
            image = doc["images"][doc["textures"][index]["source"]]
            view = doc["bufferViews"][image["bufferView"]]
            png = blob[view["byteOffset"]:view["byteOffset"] + view["byteLength"]]
            assert np.array_equal(_png(png), texture_image(baked, kind)), (name, kind)
        assert m["extras"]["plantgen"]["shellFraction"] == pytest.approx(baked.shell)
    # every primitive of a normal-mapped material has unit tangents with a sign
    textured = {i for i, m in enumerate(doc["materials"]) if "normalTexture" in m}
    prims = [p for mesh in doc["meshes"] for p in mesh["primitives"] if p["material"] in textured]
    assert prims and all("TANGENT" in p["attributes"] for p in prims)
    # the ground's material and every other one without relief stay plain
    assert all("normalTexture" not in m for n, m in materials.items() if n not in ("stone", "bark"))
    assert len(materials) > 2
    sampler = doc["samplers"][0]
    assert sampler["wrapS"] == sampler["wrapT"] == 10497       # REPEAT: v runs on along a chain


@needs_node
def test_the_validator_and_three_js_read_the_textured_glb(tmp_path):
    export_model("saguaro", tmp_path / "saguaro.glb")
    issues = assert_khronos_valid(tmp_path / "saguaro.glb")
    # the height map is named only by the material's extras: the validator notes it as unused
    assert [m["code"] for m in issues["messages"]] == ["UNUSED_OBJECT"]
    [material] = three_js_materials(tmp_path / "saguaro.glb", tmp_path)
    assert material["map"] == [256, 256] and material["normalMap"] == [256, 256]
    assert material["tangents"] and material["normalScale"] == [1, 1] and material["colorSpace"] == "srgb"


@needs_node
def test_gltf_names_its_texture_files_beside_it(tmp_path):
    paths = export_model("saguaro", tmp_path / "cactus.gltf")["paths"]
    names = sorted(p.name for p in paths)
    assert names == ["cactus.bin", "cactus.gltf", "cactus_cactus_basecolor.png", "cactus_cactus_height.png",
                     "cactus_cactus_normal.png"]
    assert khronos_issues(tmp_path / "cactus.gltf")["numErrors"] == 0     # it resolves the files
    doc = json.loads((tmp_path / "cactus.gltf").read_text())
    assert {im["uri"] for im in doc["images"]} == {n for n in names if n.endswith(".png")}


def test_relief_meshes_get_the_base_colour_only_and_no_textures_means_none(tmp_path):
    export_model("saguaro", tmp_path / "r.glb", relief=True)
    doc, _ = _glb(tmp_path / "r.glb")
    [m] = doc["materials"]
    assert "baseColorTexture" in m["pbrMetallicRoughness"] and "normalTexture" not in m and "extras" not in m
    assert all("TANGENT" not in p["attributes"] for p in doc["meshes"][0]["primitives"])
    export_model("saguaro", tmp_path / "n.glb", textures=False)
    doc, _ = _glb(tmp_path / "n.glb")
    assert "images" not in doc and "textures" not in doc
    assert export_model("saguaro", tmp_path / "n.obj", textures=False)["textures"] == {}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["n.glb", "n.mtl", "n.obj", "r.glb"]


def test_obj_mtl_names_its_maps_and_trimesh_reads_them(tmp_path):
    import trimesh

    export_model("well", tmp_path / "well.obj")
    mtl = (tmp_path / "well.mtl").read_text()
    block = mtl.split("newmtl stone")[1].split("newmtl")[0]
    for line in ("map_Kd well_stone_basecolor.png", "norm well_stone_normal.png", "map_Bump well_stone_normal.png",
                 "disp well_stone_height.png", "Kd 1.000000 1.000000 1.000000"):
        assert line in block
    for png in ("basecolor", "normal", "height"):
        assert (tmp_path / f"well_stone_{png}.png").is_file()
    scene = trimesh.load(tmp_path / "well.obj", process=False)
    meshes = scene.geometry.values() if hasattr(scene, "geometry") else [scene]
    stone = [m for m in meshes if getattr(m.visual.material, "name", "") == "stone"]
    assert stone and stone[0].visual.material.image.size == (256, 256)
    # trimesh's own sampling of the image (nearest texel, v = 0 at the bottom row) gives at
    # (u, v) the baked colour of v's row: the image is right side up for OBJ's convention
    uv = np.random.default_rng(5).random((500, 2))
    colours = trimesh.visual.uv_to_color(uv, stone[0].visual.material.image)[:, :3]
    baked = bake_material("stone").base_colour
    rows, cols = np.rint(uv[:, 1] * 255).astype(int), np.rint(uv[:, 0] * 255).astype(int)
    assert np.array_equal(colours, baked[rows, cols])
    assert not np.array_equal(colours, baked[255 - rows, cols])


def test_meshio_reads_the_textured_obj(tmp_path):
    meshio = pytest.importorskip("meshio", reason="meshio is in the test extra; install '.[test]'")
    summary = export_model("saguaro", tmp_path / "s.obj")
    mesh = meshio.read(tmp_path / "s.obj")
    assert len(mesh.points) == summary["vertices"]


def test_usd_shader_network_resolves_its_textures(tmp_path):
    pytest.importorskip("pxr", reason="usd-core (plantgen[usd]) is not installed")
    from pxr import Usd, UsdShade
    from test_export_scene import usd_problems

    export_model("saguaro", tmp_path / "s.usda")
    assert usd_problems(tmp_path / "s.usda") == []
    stage = Usd.Stage.Open(str(tmp_path / "s.usda"))
    surface = UsdShade.Shader(stage.GetPrimAtPath("/saguaro/Materials/cactus/PreviewSurface"))
    baked = bake_material("cactus", np.array([0.3]))
    for target, kind in (("diffuseColor", "basecolor"), ("normal", "normal"), ("displacement", "height")):
        source, _, _ = surface.GetInput(target).GetConnectedSource()
        texture = UsdShade.Shader(source.GetPrim())
        assert texture.GetIdAttr().Get() == "UsdUVTexture"
        asset = texture.GetInput("file").Get()
        assert Path(asset.resolvedPath).is_file(), asset
        image = _png(Path(asset.resolvedPath).read_bytes())
        if kind != "normal":       # the normal map's x and y depend on the aspect it was baked at
            assert np.array_equal(image, texture_image(baked, kind, v_up=True))
        space = texture.GetInput("sourceColorSpace").Get()
        assert space == ("sRGB" if kind == "basecolor" else "raw")
        reader, _, _ = texture.GetInput("st").GetConnectedSource()
        assert UsdShade.Shader(reader.GetPrim()).GetInput("varname").Get() == "st"


def test_a_failed_textured_export_leaves_nothing(tmp_path):
    (tmp_path / "s_cactus_normal.png").mkdir()          # a PNG target that cannot be written
    with pytest.raises(ExportError):
        export_model("saguaro", tmp_path / "s.obj")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s_cactus_normal.png"]


def test_the_command_reports_the_texture_sizes(tmp_path):
    code, out, _ = run_cli("export", "saguaro", "-o", tmp_path / "s.glb")
    assert code == 0 and "textures of cactus: 256x256 (base colour, normal, height" in out


BLENDER_MATERIALS = """
import bpy, json, sys
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=sys.argv[-1])
out = {}
for m in bpy.data.materials:
    if not m.use_nodes:
        continue
    links = [(l.from_node.type, l.to_node.type, l.to_socket.name) for l in m.node_tree.links]
    images = [n.image.size[:] for n in m.node_tree.nodes if n.type == 'TEX_IMAGE' and n.image]
    out[m.name] = {"links": links, "images": images}
objects = sorted(o.type for o in bpy.data.objects)
print('RESULT' + json.dumps({"materials": out, "objects": objects}))
"""


def _blender_scene(blender, tmp_path, name: str) -> dict:
    """What Blender made of ``tmp_path / name``: its materials' links and images, its objects' types."""
    return json.loads(blender_line(blender, BLENDER_MATERIALS, tmp_path, "RESULT", str(tmp_path / name)))


def test_blender_imports_the_textured_glb(blender, tmp_path):
    """In Blender the baked maps arrive as images linked to the material: the base colour
    into the shader's Base Color, the normal map through a Normal Map node."""
    export_model("saguaro", tmp_path / "s.glb")
    cactus = _blender_scene(blender, tmp_path, "s.glb")["materials"]["cactus"]
    links = {tuple(x) for x in cactus["links"]}
    assert ("TEX_IMAGE", "BSDF_PRINCIPLED", "Base Color") in links
    assert ("TEX_IMAGE", "NORMAL_MAP", "Color") in links and ("NORMAL_MAP", "BSDF_PRINCIPLED", "Normal") in links
    assert all(w > 1 and h > 1 for w, h in cactus["images"])


def test_blender_imports_a_scene_whole(blender, tmp_path):
    """A scene's glb brings its camera and its sun into Blender beside the plants."""
    export_model("desert", tmp_path / "d.glb")
    objects = _blender_scene(blender, tmp_path, "d.glb")["objects"]
    assert objects.count("CAMERA") == 1 and objects.count("LIGHT") == 1 and objects.count("MESH") >= 2


def _leaf_colours(doc: dict, blob: bytes) -> np.ndarray:
    leaf = {i for i, m in enumerate(doc["materials"]) if m["name"].endswith("(leaf)")}
    out = []
    for prim in (p for mesh in doc["meshes"] for p in mesh["primitives"] if p["material"] in leaf):
        accessor = doc["accessors"][prim["attributes"]["COLOR_0"]]
        view = doc["bufferViews"][accessor["bufferView"]]
        out.append(np.frombuffer(blob, np.float32, accessor["count"] * 3, view["byteOffset"]).reshape(-1, 3))
    return np.concatenate(out)


def test_bush_materials_are_one_per_name_and_leaves_keep_their_shades(tmp_path):
    """abop_bush's colour table names bark twice and leaf 13 times (' steps through it):
    one material of each name, and each leaf its own shade (glTF: COLOR_0)."""
    from plantgen.geometry.skeletons.materials import material_palette

    export_model("abop_bush", tmp_path / "bush.glb", level=0)
    doc, blob = _glb(tmp_path / "bush.glb")
    names = [m["name"] for m in doc["materials"]]
    assert sorted(names) == ["bark", "leaf", "leaf (leaf)", "stem"]
    colours = _leaf_colours(doc, blob)
    palette = material_palette(["leaf"])
    dark, light = palette["dark"][0], palette["light"][0]
    tone = (colours - dark) @ (light - dark) / np.sum((light - dark) ** 2)
    assert np.allclose(dark + tone[:, None] * (light - dark), colours, atol=1e-6)   # on the dark-light line
    assert tone.min() >= 0.25 - 1e-6 and tone.max() <= 0.85 + 1e-6
    assert len(np.unique(np.round(tone, 5))) > 100                                  # leaf by leaf
    leaf = next(m for m in doc["materials"] if m["name"] == "leaf (leaf)")
    assert leaf["pbrMetallicRoughness"]["baseColorFactor"] == [1.0, 1.0, 1.0, 1.0]


@needs_node
def test_three_js_colours_the_leaves_by_vertex(tmp_path):
    export_model("abop_bush", tmp_path / "bush.glb", level=0)
    materials = {m["material"]: m for m in three_js_materials(tmp_path / "bush.glb", tmp_path)}
    assert materials["leaf (leaf)"]["vertexColors"] and not materials["bark"]["vertexColors"]
    assert materials["bark"]["map"] == [256, 256]


def test_bush_obj_has_no_duplicate_materials(tmp_path):
    export_model("abop_bush", tmp_path / "bush.obj", level=0)
    blocks = (tmp_path / "bush.mtl").read_text().split("newmtl ")[1:]
    names = [b.split()[0] for b in blocks]
    kd = [b.split("Kd ")[1].split("\n")[0] for b in blocks]
    assert len(set(names)) == len(names) and len(names) <= 3 + 8      # was 28
    leaf_kd = [k for n, k in zip(names, kd, strict=True) if n.startswith("leaf_(leaf)")]
    assert len(leaf_kd) > 1 and len(set(leaf_kd)) == len(leaf_kd)


def test_usd_leaves_carry_their_shades(tmp_path):
    pytest.importorskip("pxr", reason="usd-core (plantgen[usd]) is not installed")
    from pxr import Usd, UsdGeom, UsdShade
    from test_export_scene import usd_problems

    export_model("abop_bush", tmp_path / "bush.usda", level=0)
    assert usd_problems(tmp_path / "bush.usda") == []
    stage = Usd.Stage.Open(str(tmp_path / "bush.usda"))
    leaves = stage.GetDefaultPrim().GetChild("Leaves")
    colours = np.array(UsdGeom.PrimvarsAPI(leaves).GetPrimvar("displayColor").Get())
    assert len(colours) == len(UsdGeom.Mesh(leaves).GetPointsAttr().Get())
    assert len(np.unique(np.round(colours, 5), axis=0)) > 100
    material, _ = UsdShade.MaterialBindingAPI(leaves).ComputeBoundMaterial()
    surface = material.ComputeSurfaceSource()[0]
    source, _, _ = surface.GetInput("diffuseColor").GetConnectedSource()
    reader = UsdShade.Shader(source.GetPrim())
    assert reader.GetIdAttr().Get() == "UsdPrimvarReader_float3" and reader.GetInput("varname").Get() == "displayColor"
    names = [c.GetName() for c in stage.GetDefaultPrim().GetChild("Materials").GetChildren()]
    assert sorted(names) == ["bark", "leaf", "leaf_leaf", "stem"]


def test_aspect_buckets_give_their_rows_their_own_normal_maps(tmp_path):
    """--aspect-step: the well's stone and bark rows split by aspect, each bucket a material
    with its own normal map baked at its rows' aspect; the base colour and height are the
    material's, written once."""
    summary = export_model("well", tmp_path / "well.obj", aspect_step=2.0)
    buckets = {n: t for n, t in summary["textures"].items() if " (r/L " in n}
    assert buckets and {n.split(" (")[0] for n in buckets} == {"stone", "bark"}
    aspects = [t["aspect"] for n, t in summary["textures"].items() if n.startswith("stone")]
    assert max(aspects) / min(aspects) > 8                      # the well's stone spans a wide range
    mtl = (tmp_path / "well.mtl").read_text()
    blocks = {b.split("\n")[0]: b for b in mtl.split("newmtl ")[1:]}
    stone_buckets = [b for n, b in blocks.items() if n.startswith("stone_(r/L")]
    assert stone_buckets and all("map_Kd well_stone_basecolor.png" in b for b in stone_buckets)
    normals = {line.split()[1] for b in blocks.values() for line in b.splitlines() if line.startswith("norm ")}
    assert len(normals) == len(summary["textures"])             # one normal map per material and bucket
    pngs = sorted(p.name for p in tmp_path.glob("*.png"))
    assert len(pngs) == len(normals) + 4                        # + stone's and bark's colour and height, once


@needs_node
def test_aspect_buckets_pass_the_validator(tmp_path):
    export_model("well", tmp_path / "well.glb", aspect_step=2.0)
    assert_khronos_valid(tmp_path / "well.glb")
    doc, _ = _glb(tmp_path / "well.glb")
    stone = [m for m in doc["materials"] if m["name"].startswith("stone")]
    assert len(stone) > 1 and len({m["pbrMetallicRoughness"]["baseColorTexture"]["index"] for m in stone}) == 1
    assert len({m["normalTexture"]["index"] for m in stone}) == len(stone)


def test_the_aspect_benchmark_prints_its_table(capsys):
    from plantgen.benchmarks import texture_aspects

    assert texture_aspects.main(["saguaro", "--step", "2"]) == 0
    out = capsys.readouterr().out
    assert "| saguaro | cactus |" in out
    assert texture_aspects.main(["saguaro", "--step", "1"]) == 2
