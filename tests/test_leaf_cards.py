"""Leaf cards (``plantgen export --leaves cards``): each leaf polygon written as one
alpha-cut quad over an atlas of the distinct leaf shapes. The atlas covers each shape's
own area (the alpha's coverage times the card's area is the polygon's area), every
polygon lies on its card, a shape turned and scaled in space shares its tile, the leaves'
shades are kept, and the file passes the Khronos validator and loads in three.js with
the cut (alphaTest) and the vertex colours."""

from __future__ import annotations

import numpy as np
import pytest
from _cli import run_cli
from _node import assert_khronos_valid, needs_node, three_js_materials
from test_export_scene import accessor, glb_json
from test_leaf_exports import GRAMMAR, LEAF

from plantgen.assets import AssetSettings
from plantgen.geometry.meshes.leaf_cards import leaf_cards
from plantgen.geometry.meshes.polygons import PolygonBuilder
from plantgen.geometry.meshes.surfaces import SURFACES, place
from plantgen.pipeline import export_model, grow_file


def tile_coverage(cards) -> np.ndarray:
    """(shapes,) the mean alpha inside each tile's inner square (the card's unit square)."""
    atlas = cards.atlas
    t, m = atlas.tile, atlas.margin
    out = []
    for k in range(atlas.shapes):
        r, c = divmod(k, atlas.columns)
        out.append(atlas.image[r * t + m:(r + 1) * t - m, c * t + m:(c + 1) * t - m, 3].mean() / 255)
    return np.array(out)


def polygon_areas(polygons) -> np.ndarray:
    return np.bincount(polygons.polygon, weights=polygons.triangle_areas(), minlength=len(polygons))


@pytest.mark.parametrize("surface", range(len(SURFACES)))
def test_the_atlas_covers_each_predefined_surfaces_area(surface):
    """The predefined surfaces, placed at random frames and scales: per polygon, the
    atlas's coverage times the card's area is the polygon's area within 2 % (a needle is
    a sliver a few texels wide), and the polygons of one shape share a tile whatever their
    frame and scale."""
    rng = np.random.default_rng(3)
    n = 20
    frames = np.linalg.qr(rng.normal(size=(n, 3, 3)))[0]
    frames *= np.sign(np.linalg.det(frames))[:, None, None]
    polygons = place(surface, rng.normal(size=(n, 3)), frames, rng.uniform(0.2, 3.0, n), np.zeros(n, np.int32))
    cards = leaf_cards(polygons)
    per_surface = len(polygons) // n
    assert cards.atlas.shapes <= per_surface                     # each placement reuses the same tiles
    card_area = polygon_areas(cards.polygons)
    ratio = card_area * tile_coverage(cards)[cards.shape] / polygon_areas(polygons)
    assert np.abs(ratio - 1).max() < 0.02, ratio


def test_each_polygon_lies_on_its_card():
    """Every vertex of a polygon is in its card's plane and inside its rectangle."""
    polygons = grow_file("broadleaf").polygons
    cards = leaf_cards(polygons)
    quads = cards.polygons.vertices.reshape(-1, 4, 3)
    owner = polygons.vertex_polygon
    corner, u_edge, v_edge = quads[:, 0], quads[:, 1] - quads[:, 0], quads[:, 2] - quads[:, 0]
    d = polygons.vertices - corner[owner]
    normal = cards.polygons.normal[owner]
    size = np.linalg.norm(u_edge, axis=1)
    assert np.abs(np.einsum("ij,ij->i", d, normal)).max() < 1e-6 * size.max()
    for edge in (u_edge, v_edge):
        t = np.einsum("ij,ij->i", d, edge[owner]) / np.einsum("ij,ij->i", edge, edge)[owner]
        assert t.min() > -1e-6 and t.max() < 1 + 1e-6
    assert np.allclose(np.einsum("ij,ij->i", u_edge, v_edge), 0, atol=1e-9 * size.max() ** 2)


def test_a_hand_drawn_polygon_is_cut_to_its_outline():
    """A concave L-shaped polygon (its card on its diagonal, the L's major axis): the
    coverage times the card's area is the L's area, and the notch and the box's corners
    outside the L are empty."""
    builder = PolygonBuilder()
    builder.add(np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]], float), 0)
    polygons = builder.build()
    cards = leaf_cards(polygons, tile=32, margin=0)
    alpha = cards.atlas.image[..., 3] / 255
    area = polygon_areas(cards.polygons)[0]
    assert tile_coverage(cards)[0] * area == pytest.approx(3.0, rel=0.01)
    assert (alpha < 0.5).mean() == pytest.approx(1 - 3.0 / area, abs=0.03) and (alpha == 1).mean() > 0.4


def test_too_many_shapes_is_one_clear_error():
    rng = np.random.default_rng(1)
    builder = PolygonBuilder()
    for _ in range(5):
        builder.add(np.c_[rng.uniform(size=(5, 2)) * [1, 1], np.zeros(5)][np.argsort(rng.uniform(size=5))][:3], 0)
    with pytest.raises(ValueError, match="distinct shapes"):
        leaf_cards(builder.build(), max_shapes=2)


@pytest.fixture(scope="module")
def exports(tmp_path_factory):
    root = tmp_path_factory.mktemp("cards")
    (root / "leafy.yaml").write_text(GRAMMAR.format(leaf=LEAF))
    polygons = export_model(root / "leafy.yaml", root / "p.glb", level=1, textures=False)
    cards = export_model(root / "leafy.yaml", root / "c.glb", level=1, textures=False,
                         asset=AssetSettings(leaves="cards"))
    return root, polygons, cards


def test_cards_take_two_triangles_a_leaf_and_keep_its_shade(exports):
    """Two triangles a leaf polygon; the card material is double-sided, MASK at 0.5, its
    base colour the atlas; each card's COLOR_0 is its polygon's shade."""
    root, polygons, cards = exports
    n = len(grow_file(root / "leafy.yaml").polygons)
    assert cards["leaf_triangles"] == 2 * n <= polygons["leaf_triangles"]   # these leaves are quads already
    doc, blob = glb_json(root / "c.glb")
    material = next(m for m in doc["materials"] if m["name"].endswith("(leaf card)"))
    assert material["alphaMode"] == "MASK" and material["alphaCutoff"] == 0.5 and material["doubleSided"]
    texture = doc["textures"][material["pbrMetallicRoughness"]["baseColorTexture"]["index"]]
    sampler = doc["samplers"][texture["sampler"]]
    assert sampler["wrapS"] == 33071 and sampler["minFilter"] == 9729        # clamped, no mipmaps
    shade = {}
    for name in ("p.glb", "c.glb"):
        d, b = glb_json(root / name)
        leaf = next(p for p in d["meshes"][0]["primitives"] if "COLOR_0" in p["attributes"])
        shade[name] = np.unique(np.round(accessor(d, b, leaf["attributes"]["COLOR_0"]), 5), axis=0)
    assert len(shade["c.glb"]) > 1 and np.array_equal(shade["p.glb"], shade["c.glb"])


@needs_node
def test_the_card_glb_validates_and_three_js_cuts_it(exports, tmp_path):
    root, _, _ = exports
    assert_khronos_valid(root / "c.glb")
    materials = three_js_materials(root / "c.glb", tmp_path)
    card = next(m for m in materials if m["material"].endswith("(leaf card)"))
    assert card["map"] is not None and card["vertexColors"]


def test_cards_are_glb_only_and_the_command_says_so(exports, tmp_path):
    root, _, _ = exports
    code, out, err = run_cli("export", root / "leafy.yaml", "-o", tmp_path / "l.obj", "--leaves", "cards")
    assert code == 2 and "glTF" in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "l.obj").exists()
    code, out, err = run_cli("export", root / "leafy.yaml", "-o", tmp_path / "l.glb", "--leaves", "cards",
                             "--no-textures")
    assert code == 0 and "of leaves" in out and (tmp_path / "l.glb").exists()
