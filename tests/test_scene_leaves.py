"""Issue 17, leaves in scenes: a scene placing a leafy grammar carries every copy's leaf
polygons, placed by the copy's matrix, its materials merged by name as the skeletons' are;
scene exports carry them (each instanced prototype its own grammar's leaves in its own
frame, or the merged leaves in place), read back by trimesh and usd-core."""

from __future__ import annotations

import json
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation
from test_export_scene import usd_problems

from plantgen.geometry.meshes.polygons import Polygons
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.pipeline import export_model, grow_file
from plantgen.scene import Scene, SceneInstance

TWIG = Path(__file__).parent / "data" / "leafy_twig.yaml"

#: Two copies of the twig (by path and by plain name, other seeds, placements with tilt,
#: yaw and scale), after an explicit skeleton whose materials come in another order, so the
#: merged names are [leaf, stone, bark]: the twig's leaf (its 1) becomes 0, its bark 2.
GROVE = """\
name: grove
seed: 4
instances:
  - skeleton:
      materials: [leaf, stone]
      segments:
        - {start: [0, 0, 0], end: [0, 1, 0], r_start: 0.2, r_end: 0.1, material: stone}
    position: [-5, 0, 0]
  - grammar: leafy_twig.yaml
    position: [2, 0, 1]
    rotation: [20, 30, -10]
    scale: 0.5
  - grammar: leafy_twig
    position: [-2, 0.5, 3]
    rotation: [0, 135, 0]
    scale: 2
"""
#: (position, rotation in degrees about x then y then z, scale) of the two twigs above.
PLACED = [((2, 0, 1), (20, 30, -10), 0.5), ((-2, 0.5, 3), (0, 135, 0), 2.0)]


@pytest.fixture(scope="module")
def grove(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("grove")
    shutil.copy(TWIG, root / "leafy_twig.yaml")
    (root / "grove.yaml").write_text(GROVE)
    return root / "grove.yaml"


@pytest.fixture(scope="module")
def twig():
    grown = grow_file(TWIG)
    assert len(grown.polygons) == 4 and set(grown.polygons.material.tolist()) == {1}   # the test's premise
    return grown


def placed(points: np.ndarray, position, rotation, scale) -> np.ndarray:
    """Points moved as the scene file says, computed apart from plantgen (scipy's rotation:
    extrinsic x, then y, then z)."""
    rot = Rotation.from_euler("xyz", rotation, degrees=True).as_matrix()
    return scale * points @ rot.T + np.asarray(position, dtype=float)


def test_a_scene_carries_every_copys_leaves_where_its_placement_puts_them(grove, twig):
    grown = grow_file(grove)
    leaves, one = grown.polygons, twig.polygons
    assert len(leaves) == 2 * len(one) and len(leaves.triangles) == 2 * len(one.triangles)
    assert len(leaves.vertices) == 2 * len(one.vertices)
    nv, nt, npoly = len(one.vertices), len(one.triangles), len(one)
    for k, (position, rotation, scale) in enumerate(PLACED):
        vertices = leaves.vertices[k * nv:(k + 1) * nv]
        assert np.allclose(vertices, placed(one.vertices, position, rotation, scale), atol=1e-12)
        # a similarity turns normals as it turns directions
        rot = Rotation.from_euler("xyz", rotation, degrees=True).as_matrix()
        assert np.allclose(leaves.normal[k * npoly:(k + 1) * npoly], one.normal @ rot.T, atol=1e-12)
        assert np.array_equal(leaves.triangles[k * nt:(k + 1) * nt], one.triangles + k * nv)
        assert np.array_equal(leaves.polygon[k * nt:(k + 1) * nt], one.polygon + k * npoly)
    assert grown.scene.polygon_instance().tolist() == [1] * npoly + [2] * npoly
    # the leaves' area scales with the copies' scales squared
    assert leaves.triangle_areas().sum() == pytest.approx(one.triangle_areas().sum() * (0.5**2 + 2.0**2))


def test_a_scenes_leaves_are_placed_on_first_use(grove):
    """A scan traces a scene's copies through two levels: growing it places no leaves in
    the world (the stage ``place`` is not timed) until ``polygons`` is first read, which
    places them once, as Scene.polygons does."""
    grown = grow_file(grove)
    assert "place" not in grown.timings and "_polygons" in vars(grown) and vars(grown)["_polygons"] is None
    leaves = grown.polygons
    assert "place" in grown.timings and grown.polygons is leaves
    expected = grown.scene.polygons()
    for name in ("vertices", "triangles", "polygon", "material", "normal", "segment"):
        assert np.array_equal(getattr(leaves, name), getattr(expected, name)), name
    grown.polygons = None                          # set by hand: kept as set, then placed again on reading
    assert grown.polygons is not leaves and len(grown.polygons) == len(leaves)


def test_scene_leaf_normals_are_unit_and_follow_the_winding(grove):
    leaves = grow_file(grove).polygons
    assert np.allclose(np.linalg.norm(leaves.normal, axis=1), 1.0)
    a, b, c = (leaves.vertices[leaves.triangles[:, k]] for k in range(3))
    cross = np.cross(b - a, c - a)
    cosine = np.einsum("ij,ij->i", cross, leaves.normal[leaves.polygon]) / np.linalg.norm(cross, axis=1)
    assert np.all(cosine > 1 - 1e-9)         # counter-clockwise about the normal; the leaf is flat


def test_scene_leaves_keep_their_material_by_name(grove, twig):
    grown = grow_file(grove)
    names = grown.skeleton.material_names
    assert names == ("leaf", "stone", "bark")
    assert {names[m] for m in grown.polygons.material} == {"leaf"}
    assert [names[m] for m in grown.polygons.material] == ["leaf"] * 8
    # the skeleton's materials moved with them: the twigs' segments are bark, the post stone
    assert [names[m] for m in grown.skeleton.material] == ["stone"] + ["bark"] * 2 * len(twig.skeleton)


def test_equal_twigs_are_one_plant_with_its_own_leaves_in_its_own_frame(grove, twig):
    plants = grow_file(grove).scene.plants()
    assert {p.name: len(p.matrices) for p in plants} == {"skeleton": 1, "leafy_twig": 2}
    [twigs] = [p for p in plants if p.name == "leafy_twig"]
    assert np.array_equal(twigs.polygons.vertices, twig.polygons.vertices)
    assert np.array_equal(twigs.polygons.material, twig.polygons.material)   # its own names' indices
    assert twigs.skeleton.material_names == ("bark", "leaf")
    [post] = [p for p in plants if p.name == "skeleton"]
    assert post.polygons is None


def test_copies_with_one_skeleton_but_other_leaves_are_two_plants(twig):
    skel, leaves = twig.skeleton, twig.polygons
    moved = Polygons(leaves.vertices + [0.0, 0.1, 0.0], leaves.triangles, leaves.polygon, leaves.material,
                     leaves.normal)

    def scene(*polygons):
        return Scene("s", "", (), tuple(SceneInstance("twig", k, np.eye(4), skel, None, p)
                                        for k, p in enumerate(polygons)))

    assert len(scene(leaves, moved).plants()) == 2
    assert len(scene(leaves, leaves).plants()) == 1
    assert len(scene(None, leaves).plants()) == 2       # a leafless copy is another plant


@pytest.mark.parametrize("mirror", [False, True])
def test_transformed_polygons_stay_counter_clockwise_about_their_normals(twig, mirror):
    rng = np.random.default_rng(3)
    lin = Rotation.random(random_state=5).as_matrix() @ np.diag([1.0, 2.0, 0.5])   # sheared too
    if mirror:
        lin = lin @ np.diag([1.0, 1.0, -1.0])
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = lin, rng.normal(size=3)
    out = twig.polygons.transformed(m)
    assert np.allclose(out.vertices, twig.polygons.vertices @ lin.T + m[:3, 3])
    a, b, c = (out.vertices[out.triangles[:, k]] for k in range(3))
    cross = np.cross(b - a, c - a)
    cosine = np.einsum("ij,ij->i", cross, out.normal[out.polygon]) / np.linalg.norm(cross, axis=1)
    assert np.allclose(np.linalg.norm(out.normal, axis=1), 1.0) and np.all(cosine > 1 - 1e-9)
    # the areas are the mapped triangles' own (the same faces, only their order may turn)
    assert out.triangle_areas().sum() == pytest.approx(0.5 * np.linalg.norm(cross, axis=1).sum())


def test_skeleton_merge_and_polygon_merge_agree_on_names():
    a = Skeleton.empty(("bark", "leaf"))
    b = Skeleton.empty(("leaf", "stone"))
    assert Skeleton.merged_material_names([a, b]) == ("bark", "leaf", "stone")
    assert Skeleton.concatenate([b, a]).material_names == ("leaf", "stone", "bark")


# ---------------------------------------------------------------------- exports
def glb_json(path: Path) -> dict:
    data = path.read_bytes()
    length, kind = struct.unpack_from("<II", data, 12)
    assert kind == 0x4E4F534A
    return json.loads(data[20:20 + length])


def gltf_leaf_triangles(doc: dict) -> dict:
    """{mesh name: leaf triangles} of a glTF document (primitives of a "(leaf)" material)."""
    out = {}
    for mesh in doc["meshes"]:
        for prim in mesh["primitives"]:
            material = doc["materials"][prim["material"]]
            if material["name"].endswith("(leaf)"):
                assert material["doubleSided"] is True
                out[mesh["name"]] = out.get(mesh["name"], 0) + doc["accessors"][prim["indices"]]["count"] // 3
    return out


@pytest.mark.parametrize("instancing", ["gpu", "nodes"])
def test_instanced_gltf_writes_each_plants_leaves_once(grove, twig, tmp_path, instancing):
    path = tmp_path / "grove.glb"
    info = export_model(grove, path, instancing=instancing)
    n = len(twig.polygons.triangles)
    assert info["leaf_triangles"] == n and info["copies"] == 3
    leafy = gltf_leaf_triangles(glb_json(path))
    assert list(leafy.values()) == [n]                  # one mesh, the twig's, holds leaves
    # every copy draws them: two twigs' leaves in the triangles drawn
    flat = export_model(grove, tmp_path / "flat.glb", instancing="off")
    assert flat["leaf_triangles"] == 2 * n and flat["triangles"] == info["drawn"]
    loaded = trimesh.load(tmp_path / "flat.glb").to_geometry()
    assert len(loaded.faces) == flat["triangles"]
    assert sum(gltf_leaf_triangles(glb_json(tmp_path / "flat.glb")).values()) == 2 * n


def test_obj_of_a_scene_carries_the_leaves_in_place(grove, twig, tmp_path):
    info = export_model(grove, tmp_path / "grove.obj")
    assert info["leaf_triangles"] == 2 * len(twig.polygons.triangles)
    loaded = trimesh.load(tmp_path / "grove.obj", group_material=True)
    geometry = loaded.geometry if isinstance(loaded, trimesh.Scene) else {"all": loaded}
    assert sum(len(g.faces) for g in geometry.values()) == info["triangles"]
    leaves = [g for name, g in geometry.items() if name.startswith("leaf_(leaf)_")]   # one per shade
    assert {name for name in geometry if not name.startswith("leaf_(leaf)_")} == {"stone", "bark"}
    assert sum(len(g.faces) for g in leaves) == 2 * len(twig.polygons.triangles)
    assert sum(g.area for g in leaves) == pytest.approx(grow_file(grove).polygons.triangle_areas().sum(), rel=1e-5)


def usd_leaves(stage) -> dict:
    """{path: (points, face count, doubleSided)} of every Mesh named Leaves (through
    instance proxies too)."""
    from pxr import Usd, UsdGeom

    out = {}
    for prim in stage.Traverse(predicate=Usd.TraverseInstanceProxies()):
        if prim.GetName() == "Leaves" and prim.IsA(UsdGeom.Mesh):
            mesh = UsdGeom.Mesh(prim)
            out[str(prim.GetPath())] = (np.array(mesh.GetPointsAttr().Get()), len(mesh.GetFaceVertexCountsAttr().Get()),
                                        mesh.GetDoubleSidedAttr().Get())
    return out


def test_usd_point_instancer_prototypes_carry_their_leaves(grove, twig, tmp_path):
    from pxr import Usd, UsdGeom

    info = export_model(grove, tmp_path / "grove.usda", instancing="gpu")
    assert not usd_problems(info["path"])
    stage = Usd.Stage.Open(str(info["path"]))
    [prim] = [p for p in stage.Traverse() if p.IsA(UsdGeom.PointInstancer)]
    targets = UsdGeom.PointInstancer(prim).GetPrototypesRel().GetTargets()
    assert sorted(t.name for t in targets) == ["leafy_twig", "skeleton"]
    leaves = usd_leaves(stage)
    [(path, (points, faces, double))] = leaves.items()
    assert path.endswith("/Prototypes/leafy_twig/Leaves") and double is True
    assert faces == len(twig.polygons.triangles)
    # in the prototype's own frame: the grammar's leaves as grown alone
    assert np.allclose(points, twig.polygons.vertices, atol=1e-5)


def test_usd_instanceable_references_place_each_copys_leaves(grove, twig, tmp_path):
    """The default USD scene (instanceable references): each copy's leaves, read through
    its instance proxy and its world transform, lie where the scene file puts them."""
    from pxr import Usd, UsdGeom

    info = export_model(grove, tmp_path / "grove.usda")
    assert not usd_problems(info["path"])
    stage = Usd.Stage.Open(str(info["path"]))
    assert not [p for p in stage.Traverse() if p.IsA(UsdGeom.PointInstancer)]
    cache = UsdGeom.XformCache()
    placed_copies = []
    for prim in stage.Traverse(predicate=Usd.TraverseInstanceProxies()):
        if prim.GetName() == "Leaves" and prim.IsA(UsdGeom.Mesh):
            points = np.array(UsdGeom.Mesh(prim).GetPointsAttr().Get(), dtype=np.float64)
            world = np.array(cache.GetLocalToWorldTransform(prim), dtype=np.float64)   # row vectors
            placed_copies.append(points @ world[:3, :3] + world[3, :3])
    assert len(placed_copies) == len(PLACED)
    for position, rotation, scale in PLACED:
        want = placed(twig.polygons.vertices, position, rotation, scale)
        assert any(got.shape == want.shape and np.allclose(got, want, atol=1e-4) for got in placed_copies)


def test_usd_without_instancing_holds_the_merged_leaves_in_place(grove, tmp_path):
    from pxr import Usd

    info = export_model(grove, tmp_path / "grove.usdc", instancing="off")
    assert not usd_problems(info["path"])
    [(points, faces, double)] = usd_leaves(Usd.Stage.Open(str(info["path"]))).values()
    merged = grow_file(grove).polygons
    assert faces == len(merged.triangles) and double is True
    assert np.allclose(points, merged.vertices, atol=1e-5)


def test_usd_instanceable_references_carry_the_leaves(grove, twig, tmp_path):
    from pxr import Usd

    info = export_model(grove, tmp_path / "grove.usda", instancing="nodes")
    assert not usd_problems(info["path"])
    leaves = usd_leaves(Usd.Stage.Open(str(info["path"])))
    # each of the two twig copies shows the (abstract) prototype's leaves, in its own frame
    assert sorted(leaves) == ["/grove/leafy_twig_1/Leaves", "/grove/leafy_twig_2/Leaves"]
    for points, faces, double in leaves.values():
        assert faces == len(twig.polygons.triangles) and double is True
        assert np.allclose(points, twig.polygons.vertices, atol=1e-5)


@pytest.mark.parametrize("suffix", [".swc", ".qsm.csv"])
def test_skeleton_formats_of_a_scene_say_the_leaves_are_left_out(grove, tmp_path, suffix):
    info = export_model(grove, tmp_path / f"grove{suffix}")
    assert any("skeleton only" in w and "8 leaf polygons" in w for w in info["warnings"])
