"""Exports with levels of detail (issue 25, part 4): each plant's levels are prefixes of
the detail order the renderers draw, written as glTF's MSFT_lod (lower levels in nodes
outside the scene's tree, so readers without the extension show the full level) and as a
USD variantSet ``lod`` on each plant; only a scene with the ``lod`` effect, or an export
asked for levels, gets them."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from _cli import run_cli
from _node import assert_khronos_valid, needs_node, three_js_meshes

from plantgen.geometry.meshes.mesh import tessellate
from plantgen.geometry.rays.instances import detail_levels, detail_order
from plantgen.geometry.skeletons.frusta import frusta_bounds
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.pipeline import export_model, grow_file, plant_detail
from plantgen.settings import LevelSettings

GROVE = """\
name: grove
effects: [shadows, lod]
ground: {size: 40, material: grass}
instances:
  - {grammar: abop_monopodial, scale: 0.5, grid: {count: [2, 2], spacing: [6, 6], jitter: 0.3, seeds: 1}}
  - {grammar: broadleaf, seed: 2, position: [12, 0, 0], scale: 0.5}
"""


@pytest.fixture
def grove(tmp_path):
    path = tmp_path / "grove.yaml"
    path.write_text(GROVE)
    return path


def _without_lod(tmp_path):
    path = tmp_path / "still.yaml"
    path.write_text(GROVE.replace("effects: [shadows, lod]", "effects: [shadows]"))
    return path


def glb_json(path) -> tuple[dict, bytes]:
    data = path.read_bytes()
    length = struct.unpack_from("<I", data, 12)[0]
    return json.loads(data[20:20 + length]), data[20 + length + 8:]


def mesh_arrays(doc, blob, mesh) -> tuple[np.ndarray, int]:
    """(positions (v, 3) of every primitive, triangles) of glTF mesh ``mesh``."""
    points, triangles = [], 0
    for prim in doc["meshes"][mesh]["primitives"]:
        acc = doc["accessors"][prim["attributes"]["POSITION"]]
        view = doc["bufferViews"][acc["bufferView"]]
        points.append(np.frombuffer(blob, np.float32, acc["count"] * 3, view["byteOffset"]).reshape(-1, 3))
        triangles += doc["accessors"][prim["indices"]]["count"] // 3
    return np.concatenate(points), triangles


def _plant_details(scene_path, levels=4):
    """{plant name: (frusta, leaves, PlantDetail)} as the export builds them at m = 0."""
    out = {}
    for plant in grow_file(scene_path).scene.plants():
        frusta = skin_skeleton(plant.skeleton)
        mesh = tessellate(frusta, 0)
        leaves = plant.polygons if plant.polygons is not None and len(plant.polygons) else None
        out[plant.name] = (frusta, leaves, plant_detail(frusta, plant.skeleton.parent, mesh, leaves, levels, 2.0))
    return out


def test_levels_are_prefixes_of_the_detail_order_that_keep_their_parents(grove):
    for frusta, _leaves, detail in _plant_details(grove).values():
        levels = detail.levels
        assert len(levels) == 4 and len(levels[0].rows) == len(frusta)
        for above, level in zip(levels, levels[1:], strict=False):
            kept = np.zeros(len(frusta), bool)
            kept[level.rows] = True
            assert 0 < kept.sum() <= len(above.rows) // 2 + 1
            assert np.isin(level.rows, above.rows).all()          # a lower level never holds a dropped row
            parents = frusta.parent_row[level.rows]
            assert kept[parents[parents >= 0]].all()                # no missing parents
        coverage = detail.coverage
        assert len(coverage) == len(levels) and np.all(np.diff(coverage) <= 0) and 0 < coverage[-1] <= 1


def test_a_level_keeps_exactly_the_rows_above_its_size(grove):
    grown = grow_file(grove)
    for plant in grown.scene.plants():
        frusta = skin_skeleton(plant.skeleton)
        order, sizes = detail_order(frusta, plant.skeleton.parent)
        counts, thresholds = detail_levels(sizes, 4)
        full = np.empty(len(frusta))
        full[order] = sizes
        for count, threshold in zip(counts[1:], thresholds[1:], strict=True):
            assert count == (full > threshold).sum()                  # every row above the size, none below
            assert set(order[:count].tolist()) == set(np.flatnonzero(full > threshold).tolist())


def test_each_glb_level_is_the_tessellation_of_its_kept_rows(grove, tmp_path):
    out = tmp_path / "grove.glb"
    summary = export_model(grove, out, level=0, textures=False)
    doc, blob = glb_json(out)
    assert "MSFT_lod" in doc["extensionsUsed"] and "MSFT_lod" not in doc.get("extensionsRequired", [])
    details = _plant_details(grove)
    scene_nodes = set(doc["scenes"][0]["nodes"])
    checked = 0
    for node in doc["nodes"]:
        lod = node.get("extensions", {}).get("MSFT_lod")
        if lod is None:
            continue
        frusta, leaves, detail = details[node["name"].rsplit(" ", 1)[0] if node["name"] not in details
                                         else node["name"]]
        assert node["extras"]["MSFT_screencoverage"] == pytest.approx(detail.coverage.tolist())
        for k, index in enumerate([doc["nodes"].index(node), *lod["ids"]]):
            level = detail.levels[k]
            expected = tessellate(frusta.subset(level.rows), 0)
            leaf_triangles = 0 if leaves is None else np.isin(leaves.polygon, level.leaves).sum()
            points, triangles = mesh_arrays(doc, blob, doc["nodes"][index]["mesh"])
            assert triangles == len(expected.faces) + leaf_triangles
            if leaves is None:
                assert np.allclose(np.sort(points, axis=0), np.sort(expected.vertices.astype(np.float32), axis=0),
                                   atol=1e-5)
            if k:
                lower = doc["nodes"][index]
                assert index not in scene_nodes                    # readers without MSFT_lod never see it
                assert {key: lower.get(key) for key in ("translation", "rotation", "scale")} == \
                       {key: node.get(key) for key in ("translation", "rotation", "scale")}
        checked += 1
    assert checked == 5                                          # every copy's node
    assert [rows for rows, _ in summary["levels"]][0] == summary["rows"]


def test_leaves_stay_on_the_levels_that_keep_their_segment(grove):
    frusta, leaves, detail = _plant_details(grove)["broadleaf"]
    assert leaves is not None and len(detail.levels[0].leaves) == len(leaves)
    for level in detail.levels[1:]:
        kept_segments = frusta.segment[level.rows]
        assert np.isin(leaves.segment[level.leaves], kept_segments).all()
        dropped = np.setdiff1d(np.arange(len(leaves)), level.leaves)
        assert not np.isin(leaves.segment[dropped], kept_segments).any()


@needs_node
def test_the_lod_glb_is_valid_and_three_js_shows_the_full_level(grove, tmp_path):
    lod, plain = tmp_path / "lod.glb", tmp_path / "plain.glb"
    export_model(grove, lod, level=0, textures=False)
    export_model(grove, plain, level=0, textures=False, levels=LevelSettings(levels=1))
    report = assert_khronos_valid(lod)
    assert report["numErrors"] == 0
    shown = sorted((m["name"], m["triangles"]) for m in three_js_meshes(lod, tmp_path))
    assert shown == sorted((m["name"], m["triangles"]) for m in three_js_meshes(plain, tmp_path))


def test_usd_levels_are_a_variant_set_that_switches_the_mesh(grove, tmp_path):
    pytest.importorskip("pxr", reason="usd-core (plantgen[usd]) is not installed")
    from pxr import Usd, UsdGeom
    from test_export_scene import usd_problems

    details = _plant_details(grove)
    for instancing in ("nodes", "gpu"):
        out = tmp_path / f"grove_{instancing}.usda"
        export_model(grove, out, level=0, textures=False, instancing=instancing)
        assert usd_problems(out) == []
        stage = Usd.Stage.Open(str(out))
        holders = [p for p in stage.TraverseAll() if p.GetVariantSets().HasVariantSet("lod")]
        prims = [p for p in holders if p.GetParent().GetName() == "Prototypes"]
        assert sorted(p.GetName() for p in prims) == sorted(details)
        if instancing == "nodes":       # each copy holds the set too (its reference): an engine switches per copy
            assert len(holders) == len(prims) + 5
            copy = next(p for p in holders if p.GetName() == "abop_monopodial_1")
            copy.GetVariantSets().GetVariantSet("lod").SetVariantSelection("lod2")
            counts = len(UsdGeom.Mesh(copy.GetChild("Mesh")).GetFaceVertexCountsAttr().Get())
            frusta, _, detail = details["abop_monopodial"]
            assert counts == len(tessellate(frusta.subset(detail.levels[2].rows), 0).faces)
        for prim in prims:
            frusta, leaves, detail = details[prim.GetName()]
            variants = prim.GetVariantSets().GetVariantSet("lod")
            assert variants.GetVariantSelection() == "lod0"
            assert variants.GetVariantNames() == [f"lod{k}" for k in range(len(detail.levels))]
            for k, level in enumerate(detail.levels):
                variants.SetVariantSelection(f"lod{k}")
                mesh = UsdGeom.Mesh(prim.GetChild("Mesh"))
                expected = tessellate(frusta.subset(level.rows), 0)
                assert len(mesh.GetFaceVertexCountsAttr().Get()) == len(expected.faces)
                assert len(mesh.GetPointsAttr().Get()) == len(expected.vertices)
                has_leaves = leaves is not None and len(level.leaves) > 0
                assert prim.GetChild("Leaves").IsValid() == has_leaves


def test_a_scene_without_lod_writes_no_levels_unless_asked(grove, tmp_path):
    pytest.importorskip("pxr", reason="usd-core (plantgen[usd]) is not installed")
    from pxr import Usd

    still = _without_lod(tmp_path)
    out = tmp_path / "still.glb"
    summary = export_model(still, out, level=0, textures=False)
    doc, _ = glb_json(out)
    assert summary["levels"] == [] and "MSFT_lod" not in doc.get("extensionsUsed", [])
    assert not any("MSFT_lod" in n.get("extensions", {}) for n in doc["nodes"])
    usd = tmp_path / "still.usda"
    export_model(still, usd, level=0, textures=False)
    stage = Usd.Stage.Open(str(usd))
    assert not any(p.GetVariantSets().GetNames() for p in stage.TraverseAll())
    export_model(grove, out, level=0, textures=False, levels=LevelSettings(levels=1))
    assert "MSFT_lod" not in glb_json(out)[0].get("extensionsUsed", [])
    summary = export_model(still, out, level=0, textures=False, levels=LevelSettings(levels=2))
    assert len(summary["levels"]) == 2 and "MSFT_lod" in glb_json(out)[0]["extensionsUsed"]


def test_the_command_line_asks_for_levels_and_refuses_bad_ones(grove, tmp_path):
    out = tmp_path / "grove.glb"
    code, stdout, stderr = run_cli("export", grove, "-o", out, "--subdiv", "0", "--no-textures", "--lod-levels", "3")
    assert code == 0, stderr
    assert "levels of detail: 3" in stdout
    assert "level 0: " in stdout and " branch pieces, " in stdout and "rows" not in stdout   # plain words
    code, stdout, stderr = run_cli("export", grove, "-o", out, "--subdiv", "0", "--no-textures", "--lod-levels", "3",
                                   "--verbose")
    assert code == 0 and "lod0 " in stdout and " rows, " in stdout and " frusta, m = 0" in stdout, stderr
    code, _, stderr = run_cli("export", grove, "-o", out, "--lod-levels", "0")
    assert code == 2 and len(stderr.strip().splitlines()) == 1 and "--lod-levels" in stderr
    obj = tmp_path / "grove.obj"
    code, _, stderr = run_cli("export", _without_lod(tmp_path), "-o", obj, "--subdiv", "0", "--no-textures",
                              "--instancing", "off", "--lod-levels", "3")
    assert code == 0 and "no levels of detail" in stderr


def test_below_a_levels_coverage_the_rows_it_drops_span_under_the_pixels(grove):
    """A plant seen at just under coverage[k] (its bounding diameter over the image height)
    through a camera of any field of view: every row level k + 1 drops spans fewer than
    the pixels the coverages were made for; under the last, even the largest row does."""
    height, pixels = 768, 2.0
    for plant in grow_file(grove).scene.plants():
        frusta = skin_skeleton(plant.skeleton)
        _, sizes = detail_order(frusta, plant.skeleton.parent)
        detail = plant_detail(frusta, plant.skeleton.parent, tessellate(frusta, 0), None, 4, pixels, height=height)
        box = frusta_bounds(frusta)
        diameter = float(np.linalg.norm(box[1] - box[0]))
        dropped = [level.size for level in detail.levels[1:]] + [float(sizes[0])]
        for fov in (20.0, 60.0):
            focal = height / (2 * np.tan(np.radians(fov) / 2))
            for coverage, largest in zip(detail.coverage, dropped, strict=True):
                distance = diameter * focal / (0.99 * coverage * height)     # the plant spans 0.99 x coverage
                assert largest * focal / distance < pixels


def test_a_grammar_written_in_place_gets_levels_when_asked(tmp_path):
    import plantgen

    out = tmp_path / "tree.glb"
    summary = plantgen.export("abop_monopodial", out, subdiv=0, lod_levels=3, textures=False)
    doc, blob = glb_json(out)
    [root] = doc["scenes"][0]["nodes"]
    ids = doc["nodes"][root]["extensions"]["MSFT_lod"]["ids"]
    assert len(ids) == 2 and root not in ids
    triangles = [mesh_arrays(doc, blob, doc["nodes"][i]["mesh"])[1] for i in [root, *ids]]
    assert triangles == [t for _, t in summary["levels"]] and triangles[1] <= triangles[0] // 2 + 64


def test_the_export_limit_counts_the_levels(grove, tmp_path):
    """The levels hold under the full level's rows again: the triangle budget counts them
    as twice the full level, before anything is built."""
    out = tmp_path / "grove.glb"
    args = ("export", grove, "-o", out, "--subdiv", "0", "--no-textures", "--limit", "export_triangles=200000")
    code, _, stderr = run_cli(*args, "--lod-levels", "1")
    assert code == 0, stderr
    out.unlink()
    code, _, stderr = run_cli(*args)
    assert code == 2 and len(stderr.strip().splitlines()) == 1 and "export_triangles" in stderr
    assert not out.exists()
