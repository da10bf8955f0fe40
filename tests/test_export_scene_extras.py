"""Scenes export whole (issue 24): a scene's camera, light and ground go into glTF (a
perspective camera, a KHR_lights_punctual directional light, a ground mesh: read back by
three.js and the Khronos validator) and USD (Camera, DistantLight, a ground Mesh: read back
by usd-core); a grammar gets none of them. They turn with the model (--up z)."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from _cli import run_cli
from _node import assert_khronos_valid, needs_node, three_js_scene

from plantgen.geometry.skeletons.frames import up_rotation
from plantgen.pipeline import export_model, grow_file, scene_extras, skin_model, stage_model
from plantgen.settings import DEFAULT_SIZE

YARD = """\
name: yard
seed: 3
ground: {size: 30, height: -0.5, material: sand}
camera: {eye: [4, 6, 20], target: [1, 2, 0], up: [0, 1, 0], fov_y: 35}
light: {direction: [-0.4, -1, -0.3], intensity: 2.5}
instances:
  - grammar: abop_monopodial
    grid: {count: [2, 2], spacing: [8, 8]}
    scale: 0.02
"""


@pytest.fixture
def yard(tmp_path):
    path = tmp_path / "yard.yaml"
    path.write_text(YARD)
    return path


@pytest.fixture
def auto_yard(tmp_path):
    path = tmp_path / "auto.yaml"
    path.write_text(YARD.replace("camera: {eye: [4, 6, 20], target: [1, 2, 0], up: [0, 1, 0], fov_y: 35}",
                                 "camera: auto"))
    return path


def glb_json(path) -> dict:
    data = path.read_bytes()
    return json.loads(data[20:20 + struct.unpack_from("<I", data, 12)[0]])


def unit(v) -> np.ndarray:
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


def test_a_grammar_exports_no_camera_light_or_ground(tmp_path):
    assert export_model("saguaro", tmp_path / "s.glb", level=0)["scene"] == ()
    doc = glb_json(tmp_path / "s.glb")
    assert "cameras" not in doc and "extensions" not in doc and "extensionsUsed" not in doc
    assert [m["name"] for m in doc["meshes"]] == ["saguaro"]
    assert scene_extras(grow_file("saguaro")) is None


def test_a_grammar_exports_its_ground_disc_when_asked(tmp_path):
    """With ``ground=True`` a single plant's export carries the ground disc plantgen render
    draws under it (issue 43: a reference renderer sees the same ground), no camera or light."""
    assert export_model("saguaro", tmp_path / "s.glb", level=0, ground=True)["scene"] == ("ground",)
    doc = glb_json(tmp_path / "s.glb")
    assert "cameras" not in doc and "extensions" not in doc
    assert [m["name"] for m in doc["meshes"]] == ["saguaro", "Ground"]
    extras = scene_extras(grow_file("saguaro"), ground=True)
    assert extras.camera is None and extras.light is None and extras.ground.shape == "disc"
    code, _, err = run_cli("export", "saguaro", "-o", tmp_path / "c.glb", "--subdiv", "0", "--ground")
    assert code == 0, err
    assert [m["name"] for m in glb_json(tmp_path / "c.glb")["meshes"]] == ["saguaro", "Ground"]
    # every attribute of the disc has one entry a vertex (Blender's importer indexes the
    # texture coordinates by the vertex indices), the uv within the unit square
    ground = next(m for m in doc["meshes"] if m["name"] == "Ground")["primitives"][0]["attributes"]
    counts = {name: doc["accessors"][index]["count"] for name, index in ground.items()}
    assert len(set(counts.values())) == 1 and counts["POSITION"] > 4, counts
    from plantgen.exporters.plants import ground_mesh, ground_uv

    uv = ground_uv(ground_mesh(extras.ground)[0])
    assert uv.shape == (counts["POSITION"], 2) and uv.min() == 0.0 and uv.max() == 1.0


def test_auto_camera_is_the_one_render_frames(auto_yard):
    """camera: auto: the export's camera is the view plantgen render frames at its default size."""
    grown = grow_file(auto_yard)
    extras = scene_extras(grown)
    want = stage_model(grown, skin_model(grown), *DEFAULT_SIZE).camera
    assert extras.camera == want
    assert extras.light == grown.scene.light and extras.ground == grown.scene.ground


@needs_node
@pytest.mark.parametrize("up", ["y", "z"])
@pytest.mark.parametrize("auto", [False, True])
def test_three_js_reads_the_scene_camera_light_and_ground(yard, auto_yard, tmp_path, up, auto):
    source = auto_yard if auto else yard
    export_model(source, tmp_path / "yard.glb", level=0, up=up)
    assert_khronos_valid(tmp_path / "yard.glb")
    doc = glb_json(tmp_path / "yard.glb")
    assert "extensionsRequired" not in doc and doc["extensionsUsed"] == ["KHR_lights_punctual"]
    got = three_js_scene(tmp_path / "yard.glb", tmp_path)
    grown = grow_file(source)
    camera, rot = scene_extras(grown).camera, up_rotation(up)
    [cam] = got["cameras"]
    assert cam["fov"] == pytest.approx(camera.fov_y) and cam["aspect"] == pytest.approx(4 / 3)
    assert np.allclose(cam["position"], rot @ np.array(camera.eye), atol=1e-5)
    assert np.allclose(cam["direction"], rot @ unit(np.subtract(camera.target, camera.eye)), atol=1e-6)
    assert np.dot(cam["up"], rot @ np.array(camera.up)) > 0.5
    if not auto:
        assert cam["fov"] == pytest.approx(35)
    [light] = got["lights"]
    assert light["type"] == "DirectionalLight" and light["intensity"] == pytest.approx(2.5)
    assert np.allclose(light["direction"], rot @ unit([-0.4, -1, -0.3]), atol=1e-6)
    ground = np.array(got["ground"])
    assert len(ground) == 4
    assert np.allclose(ground, grown.scene.ground.quad() @ rot.T, atol=1e-6)
    sand = next(m for m in doc["materials"] if m["name"] == "sand")
    assert sand["pbrMetallicRoughness"]["baseColorFactor"] == [1.0, 1.0, 1.0, 1.0] and sand["alphaMode"] == "BLEND"
    texture = ground_texture_of(tmp_path / "yard.glb")
    inside = texture[..., 3] == 255
    linear = srgb_to_linear(texture[..., :3][inside])
    assert linear.mean(axis=0) == pytest.approx([0.575, 0.47, 0.3], abs=0.01)   # the sand's colour, mottled


def ground_texture_of(path) -> np.ndarray:
    """The decoded base colour texture of a glb's ground material, (n, n, 4) uint8."""
    import io

    from PIL import Image

    data = path.read_bytes()
    doc = glb_json(path)
    binary = data[20 + struct.unpack_from("<I", data, 12)[0] + 8:]
    ground = next(m for m in doc["meshes"] if m["name"] == "Ground")["primitives"][0]["material"]
    texture = doc["textures"][doc["materials"][ground]["pbrMetallicRoughness"]["baseColorTexture"]["index"]]
    view = doc["bufferViews"][doc["images"][texture["source"]]["bufferView"]]
    start = view.get("byteOffset", 0)
    return np.asarray(Image.open(io.BytesIO(binary[start:start + view["byteLength"]])).convert("RGBA"))


def srgb_to_linear(c) -> np.ndarray:
    c = np.asarray(c, np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def test_the_exported_ground_fades_into_the_sky_at_its_rim_as_the_render_draws_it(tmp_path):
    """Issue 43: the ground's texture is plantgen's ground, its mottle and its fade: opaque
    inside, its alpha falling to 0 at the rim (the disc's and the square's), its colour the
    renderer's mottled albedo; a valid glTF that trimesh loads."""
    import trimesh

    from plantgen.geometry.skeletons.materials import material_palette
    from plantgen.geometry.stage import Ground

    export_model("saguaro", tmp_path / "s.glb", level=0, ground=True)
    texture = ground_texture_of(tmp_path / "s.glb")
    n = texture.shape[0]
    alpha = texture[..., 3].astype(float) / 255
    assert alpha[n // 2, n // 2] == 1.0 and alpha[0, 0] == 0.0 and alpha[n // 2, 0] < 0.01   # the rim's
    assert 0.2 < alpha[n // 2, int(0.1 * n)] < 0.8                                           # fading
    row = alpha[n // 2, : n // 2]
    assert np.all(np.diff(row) >= 0)                   # rising monotonely from the rim inwards
    extras = scene_extras(grow_file("saguaro"), ground=True)
    ground = extras.ground
    t = (np.arange(n) + 0.5) / n
    x, z = np.meshgrid(ground.centre[0] + ground.half * (2 * t - 1), ground.centre[1] + ground.half * (2 * t - 1))
    palette = material_palette(["sand"])
    want = palette["dark"][0] + (palette["light"][0] - palette["dark"][0]) * ground.mottle(x, z)[..., None]
    assert np.abs(srgb_to_linear(texture[..., :3]) - want).max() < 0.01    # column: x, row: z
    assert trimesh.load(tmp_path / "s.glb").geometry["Ground"].visual.material.baseColorTexture.size == (n, n)
    square = Ground(size=8.0, fade=0.25)
    assert square.opacity(0.0, 0.0) == 1.0 and square.opacity(2.9, 0.0) == 1.0
    assert square.opacity(3.9, 3.0) < 0.05 and square.opacity(4.1, 0.0) == 0.0 and 0 < square.opacity(3.5, 3.5) < 1


@pytest.mark.parametrize("up", ["y", "z"])
@pytest.mark.parametrize("instancing", ["nodes", "gpu", "off"])
def test_usd_holds_the_scene_camera_light_and_ground(yard, tmp_path, up, instancing):
    from pxr import Gf, Usd, UsdGeom, UsdLux
    from test_export_scene import usd_problems

    info = export_model(yard, tmp_path / "yard.usda", level=0, up=up, instancing=instancing)
    assert usd_problems(info["path"]) == []
    stage = Usd.Stage.Open(str(info["path"]))
    rot = up_rotation(up)
    root = stage.GetDefaultPrim().GetPath()
    camera = UsdGeom.Camera(stage.GetPrimAtPath(root.AppendChild("Camera")))
    gf = camera.GetCamera(Usd.TimeCode.Default())
    assert gf.projection == Gf.Camera.Perspective
    assert gf.GetFieldOfView(Gf.Camera.FOVVertical) == pytest.approx(35, abs=1e-4)
    assert gf.aspectRatio == pytest.approx(4 / 3)
    frustum = gf.frustum
    assert np.allclose(frustum.GetPosition(), rot @ np.array([4, 6, 20]), atol=1e-5)
    assert np.allclose(frustum.ComputeViewDirection(), rot @ unit([-3, -4, -20]), atol=1e-6)
    assert np.dot(frustum.ComputeUpVector(), rot @ np.array([0, 1, 0])) > 0.5
    light = UsdLux.DistantLight(stage.GetPrimAtPath(root.AppendChild("Sun")))
    assert light.GetIntensityAttr().Get() == pytest.approx(2.5)
    matrix = UsdGeom.Xformable(light).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    shines = np.array(matrix.TransformDir(Gf.Vec3d(0, 0, -1)))
    assert np.allclose(unit(shines), rot @ unit([-0.4, -1, -0.3]), atol=1e-6)
    ground = UsdGeom.Mesh(stage.GetPrimAtPath(root.AppendChild("Ground").AppendChild("Mesh")))
    assert np.allclose(np.array(ground.GetPointsAttr().Get()), grow_file(yard).scene.ground.quad() @ rot.T)
    normals = np.array(ground.GetNormalsAttr().Get())
    assert np.allclose(normals, rot @ np.array([0, 1, 0]))


def test_obj_of_a_scene_holds_the_plants_only(yard, tmp_path):
    info = export_model(yard, tmp_path / "yard.obj", level=0)
    assert "Ground" not in (tmp_path / "yard.obj").read_text() and info["path"].exists()


def test_the_export_command_says_what_of_the_scene_it_wrote(yard, tmp_path):
    from _cli import run_cli

    code, stdout, stderr = run_cli("export", yard, "-o", tmp_path / "yard.glb", "--subdiv", "0")
    assert code == 0, stderr
    assert "scene: camera, light, ground written with the plants" in stdout
    code, stdout, stderr = run_cli("export", yard, "-o", tmp_path / "yard.ply", "--subdiv", "0",
                                   "--instancing", "off")
    assert code == 0, stderr
    assert "scene:" not in stdout
