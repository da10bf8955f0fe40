"""Wind in the exports (part 4 of "Motion on the GPU, wind that travels"): a scene's sway
written as an animation other tools play. glTF: a skin per plant copy (a joint per
segment), a looping rotation channel per joint, played by three.js in Node; USD: UsdSkel
skeletons and SkelAnimations, skinned by usd-core. Both are compared vertex by vertex
with plantgen's own pose of every copy (tests/_sway.py) at three times between keys,
within 1e-3 of the copy's height. A still scene writes no animation."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from _blender import blender_line
from _cli import run_cli
from _node import assert_khronos_valid, needs_node, three_js_meshes, three_js_sway
from _sway import copy_height, placed, posed, texture_swim
from test_export_scene import glb_json, usd_problems
from test_leaf_exports import GRAMMAR, LEAF

from plantgen.errors import PlantgenError
from plantgen.exporters.gltf import byte_weights
from plantgen.exporters.plants import leaf_parts, material_parts
from plantgen.exporters.sway import common_period, sway_timeline, vertex_influences
from plantgen.geometry.meshes.mesh import tessellate
from plantgen.geometry.skeletons.frames import up_rotation
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.geometry.stage import Sway
from plantgen.pipeline import export_model, grow_file
from plantgen.settings import KeyframeSettings

#: Seconds at which the animations are played: none on a key (keys every 1/24 s).
TIMES = (0.3, 0.77, 1.41)
#: The skin and the keys together stay this close to plantgen's pose, per copy height.
TOLERANCE = 1e-3

#: A leafy deterministic grammar three times (one plant, three copies, each on its own
#: phase), a turned, scaled cactus on another frequency, and a still post twice.
BREEZE = """\
name: breeze
seed: 5
effects: [animation]
instances:
  - grammar: leafy.yaml
    grid: {count: [3, 1], spacing: [3, 3]}
    rotation: [0, 20, 0]
    scale: 1.5
    motion: {sway: {amplitude: 12, frequency: 0.5}}
  - grammar: cactus
    seed: 4
    position: [0, 0, 5]
    rotation: [8, 45, 0]
    scale: 0.8
    motion: {sway: {amplitude: 8, frequency: 0.25, phase: 1.0}}
  - skeleton:
      materials: [stone]
      segments:
        - {start: [0, 0, 0], end: [0, 1, 0], r_start: 0.2, r_end: 0.15}
    position: [5, 0, -3]
    grid: {count: [2, 1], spacing: [2, 2]}
"""


@pytest.fixture(scope="module")
def breeze(tmp_path_factory):
    root = tmp_path_factory.mktemp("breeze")
    (root / "leafy.yaml").write_text(GRAMMAR.format(leaf=LEAF))
    (root / "breeze.yaml").write_text(BREEZE)
    return root / "breeze.yaml"


def copies(path, instanced: bool = True) -> list[dict]:
    """Every copy of every plant of the scene at ``path``, named as the writers name them;
    not ``instanced``: the scene as one plant in place, a sway group per instance."""
    grown = grow_file(path)
    scene = grown.scene
    if not instanced:
        return [{"name": grown.name, "plant": grown.name, "copy": 0, "skeleton": grown.skeleton,
                 "leaves": grown.polygons, "matrix": None, "groups": scene.segment_instance(),
                 "sway": [i.motion for i in scene.instances]}]
    out = []
    for plant in scene.plants():
        for c, (k, matrix) in enumerate(zip(plant.instances, plant.matrices, strict=True)):
            out.append({"name": f"{plant.name} {c + 1}" if len(plant.matrices) > 1 else plant.name,
                        "plant": plant.name, "copy": c, "skeleton": plant.skeleton, "leaves": plant.polygons,
                        "matrix": matrix, "sway": scene.instances[k].motion, "groups": None})
    return out


def expected_parts(copy: dict, t: float, level: int) -> list[np.ndarray]:
    """The copy's vertices at ``t`` in the scene (y up), primitive by primitive as the glTF
    writer splits the plant: its materials' parts, then its leaves'."""
    mesh, leaves = posed(copy["skeleton"], copy["sway"], t, level, copy["matrix"], copy["leaves"],
                         groups=copy["groups"])
    parts = [p.vertices for p in material_parts(mesh)]
    if leaves is not None:
        parts += [p.vertices for p in leaf_parts(dataclasses.replace(copy["leaves"], vertices=leaves))]
    return [placed(p, copy["matrix"]) for p in parts]


# ---------------------------------------------------------------------------- what is written
def test_a_still_scene_writes_no_animation(breeze, tmp_path):
    """Only what the scene calls for: the well (no motion) and the breeze without the
    animation effect write no skin, no animation, no time codes."""
    still = tmp_path / "still.yaml"
    still.write_text(BREEZE.replace("effects: [animation]", "effects: []"))
    (tmp_path / "leafy.yaml").write_text(GRAMMAR.format(leaf=LEAF))
    for source in ("well", still):
        info = export_model(source, tmp_path / "still.glb")
        assert info["animation"] is None
        doc, _ = glb_json(tmp_path / "still.glb")
        assert "animations" not in doc and "skins" not in doc
        assert not any("JOINTS_0" in p["attributes"] for m in doc["meshes"] for p in m["primitives"])
    pytest.importorskip("pxr", reason="usd-core (plantgen[usd]) is not installed")
    from pxr import Usd

    export_model(still, tmp_path / "still.usda")
    stage = Usd.Stage.Open(str(tmp_path / "still.usda"))
    assert not stage.HasAuthoredTimeCodeRange()
    assert not [p for p in stage.Traverse() if p.GetTypeName() in ("SkelRoot", "Skeleton", "SkelAnimation")]


def test_the_dancing_cacti_glb_holds_one_looping_sway(tmp_path):
    """100 skins (one per cactus, a joint per segment), one animation "sway" with a
    rotation channel per joint, keys 24 a second over one period (2 s), interpolated
    linearly; each skinned node is a root without transform, its joints under a node
    placing the copy."""
    info = export_model("dancing_cacti", tmp_path / "d.glb")
    sway = info["animation"]
    assert sway == {"keys": 49, "duration": 2.0, "rate": 24.0, "loops": True, "joints": info["segments"],
                    "skins": 100}
    doc, blob = glb_json(tmp_path / "d.glb")
    assert len(doc["skins"]) == 100 and "extensionsRequired" not in doc
    (animation,) = doc["animations"]
    assert animation["name"] == "sway" and len(animation["channels"]) == info["segments"]
    assert {c["target"]["path"] for c in animation["channels"]} == {"rotation"}
    assert {s["interpolation"] for s in animation["samplers"]} == {"LINEAR"}
    times = doc["accessors"][animation["samplers"][0]["input"]]
    assert times["count"] == 49 and times["min"] == [0.0] and times["max"] == [2.0]
    roots = doc["scenes"][0]["nodes"]
    skinned = [n for n in doc["nodes"] if "skin" in n]
    assert len(skinned) == 100 and all(doc["nodes"].index(n) in roots for n in skinned)
    assert not any(key in n for n in skinned for key in ("translation", "rotation", "scale", "matrix"))
    for skin in doc["skins"]:
        assert skin["skeleton"] in roots and "translation" in doc["nodes"][skin["skeleton"]]


def test_no_sway_writes_the_swaying_scene_still_where_its_copies_stand(tmp_path):
    """``--no-sway``: no skin and no animation, and every cactus placed by its node as in
    a still scene (the skins' root nodes carry no placement, so a reader that ignores
    skins would stack them): the file's plant vertices span the scene's grid as the
    rendered skeleton's do."""
    code, out, err = run_cli("export", "dancing_cacti", "-o", tmp_path / "d.glb", "--no-sway")
    assert code == 0, err
    assert "sway:" not in out
    doc, _ = glb_json(tmp_path / "d.glb")
    assert "animations" not in doc and "skins" not in doc
    assert not any("JOINTS_0" in p["attributes"] for m in doc["meshes"] for p in m["primitives"])
    import trimesh

    scene = trimesh.load(tmp_path / "d.glb", force="scene")
    placed_parts = []
    for node in scene.graph.nodes_geometry:
        matrix, name = scene.graph[node]
        if "ground" not in name.lower():
            vertices = np.asarray(scene.geometry[name].vertices, dtype=np.float64)
            placed_parts.append(vertices @ matrix[:3, :3].T + matrix[:3, 3])
    plants = np.vstack(placed_parts)
    skeleton = grow_file("dancing_cacti").skeleton
    lo, hi = np.minimum(skeleton.start, skeleton.end).min(0), np.maximum(skeleton.start, skeleton.end).max(0)
    spread = hi - lo
    got = plants.max(0) - plants.min(0)
    assert np.all(got[[0, 2]] > 0.9 * spread[[0, 2]])     # the grid's width in x and z, not one cactus's


def test_a_format_without_animation_says_it_leaves_the_sway_out(tmp_path):
    code, out, err = run_cli("export", "dancing_cacti", "-o", tmp_path / "d.obj")
    assert code == 0 and ".obj holds no animation" in err
    code, out, err = run_cli("export", "dancing_cacti", "-o", tmp_path / "d.glb", "--key-rate", "12",
                             "--duration", "4")
    assert code == 0 and "sway: 49 keys over 4 s (12 a second, looping), 2,151 joints in 100 skins" in out


# ---------------------------------------------------------------------------- glTF in three.js
@needs_node
@pytest.mark.parametrize("source, instancing, up", [("dancing_cacti", "gpu", "y"), ("breeze", "gpu", "y"),
                                                   ("breeze", "nodes", "y"), ("breeze", "off", "z")])
def test_three_js_plays_the_sway_as_plantgen_poses_it(source, instancing, up, breeze, tmp_path):
    """three.js's GLTFLoader and AnimationMixer, at three times between keys: every
    skinned vertex of every copy (leaves included) within 1e-3 of the copy's height of
    plantgen's pose; the copies of one plant sway on their own phases; the still posts
    stay instanced (EXT_mesh_gpu_instancing) or nodes; a scene written in place is one
    skin (a sway group per instance; the posts' joints never turn), z-up too; the
    validator finds no error and no warning."""
    path = breeze if source == "breeze" else source
    level = 1
    export_model(path, tmp_path / "s.glb", level=level, instancing=instancing, up=up)
    assert_khronos_valid(tmp_path / "s.glb")
    if source == "breeze":
        export_model(path, tmp_path / "s.gltf", level=level, instancing=instancing, up=up)
        assert_khronos_valid(tmp_path / "s.gltf")
    doc, _ = glb_json(tmp_path / "s.glb")
    report, frames = three_js_sway(tmp_path / "s.glb", TIMES, tmp_path)
    assert [a["name"] for a in report["animations"]] == ["sway"]
    by_copy: dict[str, dict[int, int]] = {}
    for k, mesh in enumerate(report["meshes"]):
        by_copy.setdefault(doc["nodes"][mesh["node"]]["name"], {})[mesh["primitive"]] = k
    swaying = [c for c in copies(path, instancing != "off") if c["sway"] is not None]
    assert sorted(by_copy) == sorted(c["name"] for c in swaying)
    worst, moved = 0.0, {}
    for copy in swaying:
        height = copy_height(copy["skeleton"], copy["matrix"])
        for t, frame in zip(TIMES, frames, strict=True):
            for primitive, want in enumerate(expected_parts(copy, t, level)):
                got = frame[by_copy[copy["name"]][primitive]]
                worst = max(worst, float(np.linalg.norm(got - want @ up_rotation(up).T, axis=1).max()) / height)
        first = frames[0][by_copy[copy["name"]][0]]
        moved[copy["name"]] = np.linalg.norm(frames[1][by_copy[copy["name"]][0]] - first, axis=1).max() / height
    assert worst < TOLERANCE, worst
    assert min(moved.values()) > 5 * TOLERANCE             # they do sway, well past the tolerance
    if source == "breeze" and instancing != "off":
        leafy = [c for c in swaying if c["plant"] == "leafy"]
        assert len(leafy) == 3 and len({c["sway"].phase for c in leafy}) == 3
        posts = [m for m in three_js_meshes(tmp_path / "s.glb", tmp_path) if m["material"] == "stone"]
        assert [len(m["matrices"]) for m in posts] == ([2] if instancing == "gpu" else [1, 1])


@needs_node
def test_three_js_loops_the_sway_seamlessly(tmp_path):
    """One period later the cacti are where they were: the animation loops."""
    export_model("dancing_cacti", tmp_path / "d.glb", level=0)
    _, frames = three_js_sway(tmp_path / "d.glb", (0.3, 2.3, 4.3), tmp_path)
    for a, b, c in zip(*frames, strict=True):
        assert np.allclose(a, b, atol=1e-5) and np.allclose(a, c, atol=1e-5)


# ---------------------------------------------------------------------------- USD (UsdSkel)
def usd_points(stage, prim, t: float) -> np.ndarray:
    """World points of ``prim`` (baked) at ``t`` seconds."""
    from pxr import UsdGeom

    code = t * stage.GetTimeCodesPerSecond()
    points = np.array(UsdGeom.PointBased(prim).GetPointsAttr().Get(code), dtype=np.float64)
    matrix = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(code)).T
    return points @ matrix[:3, :3].T + matrix[:3, 3]


@pytest.mark.parametrize("source, suffix, up", [("dancing_cacti", ".usdc", "y"), ("breeze", ".usda", "z")])
def test_usd_skel_skins_the_sway_as_plantgen_poses_it(source, suffix, up, breeze, tmp_path):
    """usd-core reads the stage (compliance checker and validators clean), its time codes
    span the loop, UsdSkel bakes the skinning (UsdSkel.BakeSkinning) and every point of
    every copy's Mesh and Leaves at three times lies within 1e-3 of the copy's height of
    plantgen's pose (z-up too)."""
    pytest.importorskip("pxr", reason="usd-core (plantgen[usd]) is not installed")
    from pxr import Usd, UsdGeom, UsdSkel

    path = breeze if source == "breeze" else source
    level = 1
    info = export_model(path, tmp_path / f"s{suffix}", level=level, up=up)
    assert usd_problems(tmp_path / f"s{suffix}") == []
    stage = Usd.Stage.Open(str(tmp_path / f"s{suffix}"))
    sway = info["animation"]
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, sway["keys"] - 1)
    assert stage.GetTimeCodesPerSecond() == stage.GetFramesPerSecond() == 24
    assert UsdGeom.GetStageUpAxis(stage) == up.upper()
    assert UsdSkel.BakeSkinning(stage.Traverse())
    root = stage.GetDefaultPrim().GetPath()
    turn = up_rotation(up)
    worst = 0.0
    for copy in (c for c in copies(path) if c["sway"] is not None):
        prim = root.AppendChild(f"{copy['plant'].replace('-', '_')}_{copy['copy'] + 1}")
        height = copy_height(copy["skeleton"], copy["matrix"])
        for t in TIMES:
            mesh, leaves = posed(copy["skeleton"], copy["sway"], t, level, copy["matrix"], copy["leaves"])
            want = [placed(mesh.vertices, copy["matrix"])]
            got = [usd_points(stage, stage.GetPrimAtPath(prim.AppendChild("Mesh")), t)]
            if leaves is not None:
                want.append(placed(leaves, copy["matrix"]))
                got.append(usd_points(stage, stage.GetPrimAtPath(prim.AppendChild("Leaves")), t))
            for g, w in zip(got, want, strict=True):
                worst = max(worst, float(np.linalg.norm(g - w @ turn.T, axis=1).max()) / height)
    assert worst < TOLERANCE, worst


# ---------------------------------------------------------------------------- the pieces
def test_the_common_period_of_the_sways():
    assert common_period([0.5]) == 2.0
    assert common_period([0.5, 0.7, 0.0, -0.25]) == 20.0
    assert common_period([0.0]) is None
    still, slow = Sway(0.0, 3.0), Sway(8.0, 0.5)
    assert sway_timeline([still, None]) is None
    timeline = sway_timeline([slow, Sway(5.0, 0.75)])
    assert (timeline.keys, timeline.duration, timeline.loops) == (97, 4.0, True)
    timeline = sway_timeline([slow], KeyframeSettings(rate=10, duration=3.0))
    assert (timeline.keys, timeline.duration, timeline.loops) == (31, 3.0, False)
    with pytest.raises(PlantgenError, match="no common period under 3600 s.*--duration"):
        sway_timeline([Sway(1.0, 1 / 9973), Sway(1.0, 1 / 9967)], source="odd.yaml")
    with pytest.raises(PlantgenError, match="--key-rate"):
        KeyframeSettings(rate=0)


def test_rings_shared_by_two_segments_follow_both_halfway():
    """A two-segment chain: the ring on the joint's plane follows both joints (1/2 each),
    every other vertex its own segment's; glTF's byte weights sum to 255 exactly."""
    skeleton = Skeleton(np.array([[0, 0, 0], [0, 1, 0.0]]), np.array([[0, 1, 0], [0.3, 1.9, 0.0]]),
                        np.array([0.2, 0.18]), np.array([0.18, 0.12]), np.array([-1, 0]), np.array([False, True]),
                        np.zeros(2, int))
    frusta = skin_skeleton(skeleton)
    mesh = tessellate(frusta, 1)
    joints, weights = vertex_influences(mesh.faces, frusta.segment[mesh.face_row], len(mesh.vertices))
    shared = weights[:, 1] > 0
    assert shared.sum() == 17                                  # one ring: 16 columns and the seam's copy
    assert np.allclose(weights[shared, :2], 0.5) and (joints[shared, :2] == [0, 1]).all()
    assert np.allclose(weights[~shared, 0], 1.0)
    assert np.allclose(np.linalg.norm(mesh.vertices[shared] - [0, 1, 0], axis=1), frusta.r2[0], rtol=0.2)
    packed = byte_weights(np.array([[0.5, 0.5, 0, 0], [1, 0, 0, 0], [1 / 3] * 3 + [0], [0.25] * 4]))
    assert packed.sum(axis=1).tolist() == [255] * 4 and packed[0].tolist() == [128, 127, 0, 0]


def test_plantgen_re_skinning_slides_its_texture_frames_a_skin_does_not():
    """Why the reference carries the rest's texture frames: re-skinning the pose
    transports them again, which slides the vertices around the axes (the surface stays
    the same); here by more than the skin's whole error, so a comparison without the
    carried frames would measure plantgen's texture swim, not the export."""
    scene = grow_file("dancing_cacti").scene
    instance = scene.instances[2]
    swim = texture_swim(instance.skeleton, instance.motion, TIMES, 1)
    assert swim > TOLERANCE * copy_height(instance.skeleton)


BLENDER_IMPORT = """
import bpy, sys
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=sys.argv[-1])
armatures = [o for o in bpy.data.objects if o.type == 'ARMATURE']
actions = list(bpy.data.actions)
print('ARMATURES', len(armatures), 'ACTIONS', len(actions),
      'RANGE', *(actions[0].frame_range if actions else (0, 0)))
"""


def test_blender_imports_the_swaying_cacti(blender, tmp_path):
    """Blender's glTF importer makes armatures of the skins and an action of the sway."""
    export_model("dancing_cacti", tmp_path / "d.glb", level=0)
    counts = blender_line(blender, BLENDER_IMPORT, tmp_path, "ARMATURES", str(tmp_path / "d.glb"))
    words = ("ARMATURES" + counts).split()
    assert int(words[1]) >= 1 and int(words[3]) >= 1 and float(words[6]) > float(words[5])   # armatures, a sway
