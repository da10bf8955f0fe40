"""Engine assets (``plantgen export --asset game``): levels of detail within their triangle
budgets, leaf cards, and an octahedral impostor baked by the ray caster as the last glTF
level. The atlas's directions invert exactly; a baked cylinder's tiles hold its exact
silhouette, depth and normals; the file passes the Khronos validator and three.js loads
every level, the skin and the impostor card (Blender, in CI, imports the swaying game
asset: tests/test_sway_levels.py)."""

from __future__ import annotations

import json
import os
import subprocess

import numpy as np
import pytest
from _cli import run_cli
from _node import assert_khronos_valid, needs_node, node_modules, three_script
from test_export_scene import glb_json

from plantgen.geometry.meshes.impostor import frame_basis, octahedral_direction, octahedral_uv, view_directions
from plantgen.geometry.skeletons.frusta import Frusta
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.limits import GAME_LEVEL_TRIANGLES

SMALL = ("--impostor-frames", "4", "--impostor-size", "128")


# ---------------------------------------------------------------------------- the atlas's layout
@pytest.mark.parametrize("hemi", [True, False])
def test_atlas_coordinates_and_directions_invert(hemi):
    rng = np.random.default_rng(0)
    uv = rng.uniform(size=(500, 2))
    d = octahedral_direction(uv, hemi)
    assert np.allclose(np.linalg.norm(d, axis=1), 1)
    assert np.allclose(octahedral_uv(d, hemi), uv, atol=1e-12)
    if hemi:
        assert d[:, 1].min() >= 0                              # the upper hemisphere only
    grid = view_directions(5, hemi)
    assert np.allclose(grid[2, 2], [0, 1, 0])                  # the centre looks from above
    border = np.r_[grid[0], grid[-1], grid[:, 0], grid[:, -1]]
    assert np.allclose(border[:, 1], 0 if hemi else border[:, 1]) and (not hemi or np.allclose(border[:, 1], 0))


def test_frame_bases_are_orthonormal_and_upright():
    for d in view_directions(6, True).reshape(-1, 3):
        right, up = frame_basis(d)
        assert np.allclose([right @ up, right @ d, up @ d], 0, atol=1e-12)
        assert np.isclose(np.linalg.det(np.stack([right, up, d])), 1)
        assert up[1] >= -1e-12                                 # the world's up is the tile's top


# ---------------------------------------------------------------------------- the bake (GL)
def test_a_baked_cylinder_has_its_exact_silhouette_depth_and_normals():
    """One vertical cylinder (radius r, height h): seen from the horizon its tile's lit
    columns span 2r of the sphere's 2R within a texel, the depth at its axis is 0.5 +
    0.5 r/R (the nearest surface, to 1/254), and the normal there faces the viewer."""
    from plantgen.gl.impostor import bake_impostor

    r, h = 0.2, 2.0
    skeleton = Skeleton(np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, h, 0.0]]), np.array([r]), np.array([r]),
                        np.array([-1]), np.array([False]), np.array([0], np.int32))
    frusta: Frusta = skin_skeleton(skeleton)
    imp = bake_impostor(frusta, frusta.material_names, frames=4, size=256, relief=False)
    t, radius = imp.tile, imp.radius
    assert np.hypot(r, h / 2) <= radius <= h / 2 + 1.5 * r              # a ball around the whole cylinder
    col, row = np.round(octahedral_uv(np.array([0.0, 0.0, 1.0])) * 3).astype(int)
    tile = (slice(row * t, (row + 1) * t), slice(col * t, (col + 1) * t))
    alpha = imp.colour[tile][..., 3] > 0
    middle = alpha[t // 2]
    assert abs(middle.sum() - 2 * r / (2 * radius) * t) <= 1.5
    centre = t // 2 if middle[t // 2] else t // 2 - 1
    depth = imp.depth[tile][t // 2, centre]
    assert (depth - 1) / 254 == pytest.approx(0.5 + 0.5 * r / radius, abs=2 / 254)
    n = imp.normal[tile][t // 2, centre, :3] / 255 * 2 - 1
    assert n @ np.array([0.0, 0.0, 1.0]) > 0.95
    assert (imp.colour[..., 3] == 0).sum() > 0 and set(np.unique(imp.colour[..., 3])) <= {0, 255}


# ---------------------------------------------------------------------------- the command
@pytest.fixture(scope="module")
def broadleaf_game(tmp_path_factory):
    out = tmp_path_factory.mktemp("game") / "tree.glb"
    code, text, err = run_cli("export", "broadleaf", "-o", out, "--asset", "game", *SMALL)
    assert code == 0, err
    return out, text, err


def test_the_game_asset_is_levels_cards_and_an_impostor_within_budget(broadleaf_game):
    """m = 0 (the default for a game asset), 4 levels each within its budget, cards, the
    impostor last with its layout; coverages fall level by level."""
    out, text, err = broadleaf_game
    assert "at subdivision level 0" in text and "leaf cards:" in text and "impostor: 4x4 views" in text
    assert "over its budget" not in err
    doc, _ = glb_json(out)
    root = next(n for n in doc["nodes"] if "MSFT_lod" in n.get("extensions", {}))
    ids = root["extensions"]["MSFT_lod"]["ids"]
    coverage = root["extras"]["MSFT_screencoverage"]
    assert len(ids) == 4 and len(coverage) == 5 and np.all(np.diff(coverage) < 0)
    meshes = [doc["meshes"][root["mesh"]], *(doc["meshes"][doc["nodes"][i]["mesh"]] for i in ids)]
    triangles = [sum(doc["accessors"][p["indices"]]["count"] // 3 for p in m["primitives"]) for m in meshes]
    assert all(t <= b for t, b in zip(triangles[:4], GAME_LEVEL_TRIANGLES, strict=True)), triangles
    assert triangles[4] == 2
    card = doc["materials"][meshes[4]["primitives"][0]["material"]]
    layout = card["extras"]["plantgen"]["impostor"]
    assert card["alphaMode"] == "MASK" and layout["frames"] == 4 and layout["atlasSize"] == 128
    assert layout["layout"] == "hemi-octahedral" and layout["radius"] > 0
    leaf = [doc["materials"][p["material"]] for p in meshes[0]["primitives"]]
    assert any(m["name"].endswith("(leaf card)") and m["alphaMode"] == "MASK" for m in leaf)


def test_a_game_asset_is_glb_only(tmp_path):
    code, _, err = run_cli("export", "broadleaf", "-o", tmp_path / "t.usda", "--asset", "game")
    assert code == 2 and "glTF" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "t.usda").exists()


# three.js: every node that names levels, each level node loaded through the parser: its
# meshes' triangles, materials (the map's size, alphaTest) and whether skinned.
THREE_LEVELS_JS = three_script(r"""
${THREE_PRELUDE}
new GLTFLoader().parse(buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength), '', async (gltf) => {
  const json = gltf.parser.json, out = [];
  for (let i = 0; i < json.nodes.length; i++) {
    const lod = (json.nodes[i].extensions || {}).MSFT_lod;
    if (!lod) continue;
    const levels = [];
    for (const id of [i, ...lod.ids]) {
      const o = await gltf.parser.getDependency('node', id), meshes = [];
      o.traverse((m) => { if (m.isMesh) meshes.push({triangles: m.geometry.index.count / 3, skinned: !!m.isSkinnedMesh,
        material: m.material.name, alphaTest: m.material.alphaTest, map: m.material.map ? [m.material.map.image.width,
        m.material.map.image.height] : null, bones: m.isSkinnedMesh ? m.skeleton.bones.length : 0}); });
      levels.push(meshes);
    }
    out.push(levels);
  }
  console.log(JSON.stringify({levels: out, animations: gltf.animations.map((a) => a.name)}));
}, (err) => { console.error(String(err)); process.exit(3); });
""")


def three_js_levels(path, tmp_path) -> dict:
    script = tmp_path / "levels.mjs"
    script.write_text(THREE_LEVELS_JS)
    env = dict(os.environ, THREE_MODULES=str(node_modules("three")))
    done = subprocess.run(["node", str(script), str(path)], capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout)


@needs_node
def test_the_game_asset_validates_and_three_js_loads_every_level_and_the_impostor(broadleaf_game, tmp_path):
    out, _, _ = broadleaf_game
    assert_khronos_valid(out)
    report = three_js_levels(out, tmp_path)
    (levels,) = report["levels"]
    assert len(levels) == 5
    counts = [sum(m["triangles"] for m in level) for level in levels]
    assert counts[0] > counts[1] > counts[2] > counts[3] > counts[4] == 2
    (card,) = levels[4]
    assert card["map"] == [128, 128] and card["alphaTest"] == 0.5
    assert any(m["material"].endswith("(leaf card)") and m["alphaTest"] == 0.5 and m["map"] for m in levels[0])


@needs_node
def test_a_swaying_game_asset_skins_every_level_and_stands_its_impostor_where_the_copy_stands(tmp_path):
    """The dancing cacti: three.js loads each copy's levels skinned on its bones and the
    impostor card unskinned, placed as the copy's joints are; the sway animation is there."""
    out = tmp_path / "d.glb"
    code, text, err = run_cli("export", "dancing_cacti", "-o", out, "--asset", "game", *SMALL, "--no-textures")
    assert code == 0, err
    assert_khronos_valid(out)
    doc, _ = glb_json(out)
    report = three_js_levels(out, tmp_path)
    assert report["animations"] == ["sway"] and len(report["levels"]) == 100
    for levels in report["levels"]:
        assert all(m["skinned"] and m["bones"] > 0 for level in levels[:-1] for m in level)
        assert [m["skinned"] for m in levels[-1]] == [False] and levels[-1][0]["triangles"] == 2
    holders = {n["name"][:-len(" joints")]: n for n in doc["nodes"] if n["name"].endswith(" joints")}
    for node in (n for n in doc["nodes"] if "MSFT_lod" in n.get("extensions", {})):
        card = doc["nodes"][node["extensions"]["MSFT_lod"]["ids"][-1]]
        assert "skin" not in card and card["translation"] == holders[node["name"]]["translation"]
