"""Levels of detail that sway: every level of a swaying plant is skinned on the same
joints as level 0 (glTF: the copy's one skin, MSFT_lod; USD: UsdSkel under the variantSet
``lod``), so the one ``sway`` animation drives every level. At three times of the
animation, each level's vertices, played by three.js (or baked by UsdSkel), stay with
level 0's vertices where they are the same point at rest: within 1e-4 of the plant's
height where both follow the same joints, and where a level cuts a chain (its cap ring
follows its own segment alone, level 0's ring follows the dropped child halfway too)
within the chord 2 r sin(θ/4) of the widest ring r turning by the largest joint angle θ
of the animation."""

from __future__ import annotations

import json
import os
import subprocess

import numpy as np
import pytest
from _blender import blender_line
from _node import assert_khronos_valid, needs_node, node_modules, three_script
from scipy.spatial import cKDTree
from test_export_scene import glb_json, usd_problems

from plantgen.assets import AssetSettings
from plantgen.pipeline import export_model, grow_file
from plantgen.settings import LevelSettings

#: Seconds at which the animation is played: none on a key (keys every 1/24 s).
TIMES = (0.3, 0.77, 1.41)
#: Skinning in float32, per plant height: where a level and level 0 follow the same joints.
TIGHT = 1e-4
LEVELS = 3

# three.js: the scene's skinned meshes and, per node with MSFT_lod, each lower level's
# node loaded through the parser (GLTFLoader binds it to the skin's joints, the scene's
# own bones), skinned as three.js draws them at each time.
THREE_LOD_SWAY_JS = three_script(r"""
${THREE_PRELUDE}
const times = JSON.parse(process.argv[3]);
new GLTFLoader().parse(buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength), '', async (gltf) => {
  const json = gltf.parser.json;
  const levels = [];
  for (let i = 0; i < json.nodes.length; i++) {
    const lod = (json.nodes[i].extensions || {}).MSFT_lod;
    if (!lod) continue;
    const objects = [await gltf.parser.getDependency('node', i)];
    for (const id of lod.ids) objects.push(await gltf.parser.getDependency('node', id));
    levels.push({node: i, ids: lod.ids, objects});
  }
  const mixer = new THREE.AnimationMixer(gltf.scene);
  for (const clip of gltf.animations) mixer.clipAction(clip).play();
  const out = [];
  const v = new THREE.Vector3();
  const skinned = (o) => { const m = []; o.traverse((c) => { if (c.isSkinnedMesh) m.push(c); }); return m; };
  for (const t of times) {
    mixer.setTime(t);
    gltf.scene.updateMatrixWorld(true);
    const frame = [];
    for (const level of levels) {
      frame.push(level.objects.map((o) => {
        o.updateMatrixWorld(true);
        return skinned(o).map((m) => {
          m.skeleton.update();
          const n = m.geometry.attributes.position.count, p = [];
          for (let i = 0; i < n; i++) { m.getVertexPosition(i, v).applyMatrix4(m.matrixWorld); p.push(v.x, v.y, v.z); }
          return {material: m.material.name, bones: m.skeleton.bones.map((b) => b.uuid).join(), positions: p};
        });
      }));
    }
    out.push(frame);
  }
  console.log(JSON.stringify({levels: levels.map((l) => ({node: l.node, ids: l.ids})), frames: out,
                              animations: gltf.animations.map((a) => a.name)}));
}, (err) => { console.error(String(err)); process.exit(3); });
""")


def three_js_levels(path, tmp_path) -> dict:
    script = tmp_path / "levels_with_three.mjs"
    script.write_text(THREE_LOD_SWAY_JS)
    env = dict(os.environ, THREE_MODULES=str(node_modules("three")))
    done = subprocess.run(["node", str(script), str(path), json.dumps(list(TIMES))], capture_output=True,
                          text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout)


def largest_angle(doc, blob) -> float:
    """The largest turn (radians) any joint takes relative to its parent in the animation."""
    worst = 0.0
    for sampler in doc["animations"][0]["samplers"]:
        acc = doc["accessors"][sampler["output"]]
        view = doc["bufferViews"][acc["bufferView"]]
        q = np.frombuffer(blob, np.float32, 4 * acc["count"], view["byteOffset"] + acc.get("byteOffset", 0))
        worst = max(worst, float(2 * np.arccos(np.clip(np.abs(q.reshape(-1, 4)[:, 3]), 0, 1)).max()))
    return worst


def twins(rest_level: np.ndarray, rest_full: np.ndarray, height: float) -> tuple[np.ndarray, np.ndarray]:
    """(index into the level's vertices, index of the level-0 vertex at the same point) of
    every level vertex that has one (a cap's centre has none)."""
    distance, index = cKDTree(rest_full).query(rest_level)
    has = distance < 1e-6 * height
    return np.flatnonzero(has), index[has]


@pytest.fixture(scope="module")
def cacti(tmp_path_factory):
    out = tmp_path_factory.mktemp("cacti") / "c.glb"
    info = export_model("dancing_cacti", out, level=1, levels=LevelSettings(levels=LEVELS), textures=False)
    return out, info


def test_a_swaying_plant_gets_its_levels(cacti):
    """The export counts its levels and its sway; every swaying copy names its levels (a
    small plant has fewer), each level node with the skin of the node that names it."""
    path, info = cacti
    assert len(info["levels"]) == LEVELS and info["animation"]["skins"] == 100
    assert info["levels"][0][1] > info["levels"][1][1] > info["levels"][2][1]
    doc, _ = glb_json(path)
    assert "MSFT_lod" in doc["extensionsUsed"] and "MSFT_lod" not in doc.get("extensionsRequired", [])
    named = [n for n in doc["nodes"] if "MSFT_lod" in n.get("extensions", {})]
    assert len(named) == 100
    for node in named:
        ids = node["extensions"]["MSFT_lod"]["ids"]
        assert 1 <= len(ids) <= LEVELS - 1 and len(node["extras"]["MSFT_screencoverage"]) == len(ids) + 1
        assert all(doc["nodes"][i]["skin"] == node["skin"] and "translation" not in doc["nodes"][i] for i in ids)
    assert [a["name"] for a in doc["animations"]] == ["sway"]


@needs_node
def test_the_levels_validate_and_three_js_sways_them_with_level_0(cacti, tmp_path):
    """Khronos validator: no error, no warning. three.js: at each time, every lower level's
    vertex within the bound of its level-0 twin (see the module docstring); the levels do
    move, well past the tight bound, and each level uses the very bones of level 0."""
    path, _ = cacti
    assert_khronos_valid(path)
    doc, blob = glb_json(path)
    report = three_js_levels(path, tmp_path)
    assert report["animations"] == ["sway"] and len(report["levels"]) == 100
    skeleton = grow_file("dancing_cacti").skeleton
    height = float(np.ptp(np.concatenate([skeleton.start, skeleton.end])[:, 1]))
    r_max = float(max(skeleton.r_start.max(), skeleton.r_end.max()))
    theta = largest_angle(doc, blob)
    loose = 2 * r_max * np.sin(theta / 4) + TIGHT * height
    assert 0 < theta < 1.0
    rest = three_js_levels_at_rest(path, tmp_path)
    worst_tight = worst_loose = moved = 0.0
    tight_share = []
    for k_time in range(len(TIMES)):
        for plant, levels in enumerate(report["frames"][k_time]):
            full = {m["material"]: m for m in levels[0]}
            for level in levels[1:]:
                for m in level:
                    twin = full[m["material"]]
                    assert m["bones"] == twin["bones"]                      # the same skeleton
                    rest_level = np.reshape(rest[plant][levels.index(level)][m["material"]], (-1, 3))
                    rest_full = np.reshape(rest[plant][0][m["material"]], (-1, 3))
                    mine, theirs = twins(rest_level, rest_full, height)
                    assert len(mine) >= 0.6 * len(rest_level)
                    got = np.reshape(m["positions"], (-1, 3))[mine]
                    want = np.reshape(twin["positions"], (-1, 3))[theirs]
                    gap = np.linalg.norm(got - want, axis=1)
                    same = gap <= TIGHT * height
                    tight_share.append(same.mean())
                    worst_loose = max(worst_loose, float(gap.max()))
                    worst_tight = max(worst_tight, float(np.median(gap)))
                    moved = max(moved, float(np.linalg.norm(got - rest_level[mine], axis=1).max()))
    assert worst_loose <= loose, (worst_loose, loose)
    assert worst_tight <= TIGHT * height and min(tight_share) > 0.5
    assert moved > 20 * TIGHT * height                                    # the levels sway


def three_js_levels_at_rest(path, tmp_path) -> list:
    """Per plant, per level, {material: rest positions} (the glTF's own POSITION, placed
    by nothing: a skinned node is untransformed, its joints place it)."""
    doc, blob = glb_json(path)
    from test_export_scene import accessor

    out = []
    for node in doc["nodes"]:
        lod = node.get("extensions", {}).get("MSFT_lod")
        if lod is None:
            continue
        per_level = []
        for index in [doc["nodes"].index(node), *lod["ids"]]:
            mesh = doc["meshes"][doc["nodes"][index]["mesh"]]
            per_level.append({doc["materials"][p["material"]]["name"]: accessor(doc, blob, p["attributes"]["POSITION"])
                              for p in mesh["primitives"]})
        out.append(per_level)
    return out


def test_usd_levels_are_bound_to_the_one_skeleton_and_sway_with_level_0(tmp_path):
    """usd-core: the stage is clean; each copy's variant ``lodk`` holds a Mesh bound to the
    copy's one Joints; UsdSkel bakes each selected level at three times within the bound of
    level 0's twin points (see the module docstring)."""
    pytest.importorskip("pxr", reason="usd-core (plantgen[usd]) is not installed")
    from pxr import Usd, UsdGeom, UsdSkel

    out = tmp_path / "c.usda"
    export_model("dancing_cacti", out, level=0, levels=LevelSettings(levels=2), textures=False)
    assert usd_problems(out) == []
    skeleton = grow_file("dancing_cacti").skeleton
    height = float(np.ptp(np.concatenate([skeleton.start, skeleton.end])[:, 1]))
    r_max = float(max(skeleton.r_start.max(), skeleton.r_end.max()))
    baked = {}
    for k in range(2):
        own = tmp_path / f"c{k}.usda"          # a layer of its own: the bake edits it
        own.write_bytes(out.read_bytes())
        stage = Usd.Stage.Open(str(own))
        copy = next(p for p in stage.Traverse() if p.GetVariantSets().HasVariantSet("lod")
                    and p.GetName().endswith("_1") and not p.IsAbstract())
        copy.GetVariantSets().GetVariantSet("lod").SetVariantSelection(f"lod{k}")
        mesh = stage.GetPrimAtPath(copy.GetPath().AppendChild("Mesh"))
        binding = UsdSkel.BindingAPI(mesh)
        assert binding.GetSkeletonRel().GetTargets() == [copy.GetPath().AppendChild("Joints")]
        rest = np.array(UsdGeom.Mesh(mesh).GetPointsAttr().Get(), np.float64)
        assert UsdSkel.BakeSkinning(stage.Traverse())
        codes = [t * stage.GetTimeCodesPerSecond() for t in TIMES]
        baked[k] = (rest, [np.array(UsdGeom.Mesh(mesh).GetPointsAttr().Get(c), np.float64) for c in codes])
        theta = max(2 * np.arccos(min(1.0, abs(q.GetReal())))
                    for c in codes for q in UsdSkel.Animation(stage.GetPrimAtPath(copy.GetPath().AppendChild("Sway")))
                    .GetRotationsAttr().Get(c))
    loose = 2 * r_max * np.sin(theta / 4) + TIGHT * height
    mine, theirs = twins(baked[1][0], baked[0][0], height)
    assert len(mine) >= 0.6 * len(baked[1][0])
    moved = 0.0
    for got, want in zip(baked[1][1], baked[0][1], strict=True):
        gap = np.linalg.norm(got[mine] - want[theirs], axis=1)
        assert gap.max() <= loose and np.median(gap) <= TIGHT * height
        moved = max(moved, float(np.linalg.norm(got[mine] - baked[1][0][mine], axis=1).max()))
    assert moved > 20 * TIGHT * height


BLENDER_LEVELS = """
import sys
import bpy
bpy.ops.import_scene.gltf(filepath=sys.argv[sys.argv.index("--") + 1])
arms = [o for o in bpy.data.objects if o.type == "ARMATURE"]
skinned = [o for o in bpy.data.objects if o.type == "MESH" and any(m.type == "ARMATURE" for m in o.modifiers)]
print("LEVELS", len(arms), len(skinned), len(bpy.data.actions))
"""


def test_blender_imports_the_levels_with_the_armature_and_the_action(blender, tmp_path):
    """Blender's glTF importer makes the armatures, skins the meshes and makes an action of
    the swaying game asset (levels, impostor; its importer reads the scene's level 0, the
    levels share its armature)."""
    export_model("dancing_cacti", tmp_path / "d.glb", level=0, textures=False,
                 asset=AssetSettings(asset="game", impostor_frames=4, impostor_size=128))
    words = blender_line(blender, BLENDER_LEVELS, tmp_path, "LEVELS", str(tmp_path / "d.glb")).split()
    assert int(words[0]) >= 1 and int(words[1]) >= 100 and int(words[2]) >= 1
