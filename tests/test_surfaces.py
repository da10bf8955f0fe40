"""Issue 17: ABOP's predefined surfaces ``~(name, scale)`` (the built-in leaf blade and
needle tuft) and the shipped leafy grammars (abop_bush, broadleaf, pine_needles)."""

from __future__ import annotations

from math import cos, radians, sin

import numpy as np
import pytest
from _cli import run_cli
from scipy.spatial import cKDTree
from test_leaf_exports import gltf_json

from plantgen._resources import grammars_dir
from plantgen.geometry.meshes.surfaces import SURFACES, place, surface
from plantgen.geometry.skeletons.materials import material_colour
from plantgen.limits import LimitError, Limits
from plantgen.lsystem import derive, parse_grammar
from plantgen.lsystem.derive import apply_interpretation
from plantgen.lsystem.grammar import GrammarError
from plantgen.lsystem.turtle import interpret_plant
from plantgen.pipeline import export_model, grow_file


def grammar(**kw):
    kw.setdefault("iterations", 0)
    kw.setdefault("rules", [])
    return parse_grammar(kw, "test.yaml")


def draw(g, limits=None):
    d = interpret_plant(apply_interpretation(g, derive(g)), g.turtle, g.materials, "test.yaml", limits)
    d.skeleton.validate()
    return d


def rotation(axis, degrees):
    """The right-handed rotation by ``degrees`` about the unit ``axis`` (Rodrigues' matrix)."""
    x, y, z = axis
    c, s = cos(radians(degrees)), sin(radians(degrees))
    k = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return np.eye(3) * c + s * k + (1 - c) * np.outer(axis, axis)


def newell_area(points) -> float:
    """Area of a planar polygon: half the length of the sum of its edges' cross products."""
    p = np.asarray(points, float)
    return 0.5 * float(np.linalg.norm(np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0)))


# ------------------------------------------------------------------ the built-in set
@pytest.mark.parametrize("name", SURFACES)
def test_each_outline_is_planar_and_its_triangles_cover_its_area(name):
    s = surface(name)
    assert s.name == name and len(s.outlines) == len(s.polygons) >= 2
    for k, outline in enumerate(s.outlines):
        centred = outline - outline.mean(axis=0)
        assert np.linalg.svd(centred, compute_uv=False)[2] < 1e-12          # planar
        normal = s.polygons.normal[k]
        assert np.allclose(centred @ normal, 0, atol=1e-12)
        tris = s.polygons.polygon == k
        assert s.polygons.triangle_areas()[tris].sum() == pytest.approx(newell_area(outline), rel=1e-12)
        # counter-clockwise about the stored normal, as Polygons promises
        a, b, c = (s.polygons.vertices[s.polygons.triangles[tris, j]] for j in range(3))
        assert np.all(np.cross(b - a, c - a) @ normal > 0)


def test_leaf_blade_grows_along_h_from_the_turtle_in_the_h_l_plane():
    leaf = surface("leaf")
    v = leaf.polygons.vertices                           # local (h, l, u)
    assert 20 <= leaf.vertex_count <= 60
    assert np.isclose(v[:, 0].min(), 0) and np.isclose(v[:, 0].max(), 1)
    assert np.any(np.all(np.isclose(v, 0), axis=1))      # the base is at the turtle
    assert np.any(np.all(np.isclose(v, [1, 0, 0]), axis=1))   # the tip one unit along H
    width = np.ptp(v[:, 1])
    assert 0.2 < width < 0.6 and np.ptp(v[:, 2]) < 0.25 * width     # flat-ish, in the H-L plane
    # folded along the midrib: two halves, each tilted up towards U, neither flat
    n = leaf.polygons.normal
    assert np.all(n[:, 2] > 0.9) and not np.allclose(n[0], n[1])
    # widest at about a third of its length, and a pointed tip with a concave outline:
    # the edge's last points lie inside the chord from its point three quarters along to
    # the tip
    half = leaf.outlines[0]
    edge = half[2:][np.argsort(half[2:, 0])]
    assert 0.25 < edge[np.argmax(np.abs(edge[:, 1])), 0] < 0.45
    start = edge[np.searchsorted(edge[:, 0], 0.75)]
    beyond = edge[edge[:, 0] > start[0]]
    chord = np.abs(start[1]) * (1 - beyond[:, 0]) / (1 - start[0])
    assert len(beyond) >= 2 and np.all(np.abs(beyond[:, 1]) < chord)


def test_needle_tuft_is_long_thin_needles_radiating_forward_in_different_planes():
    tuft = surface("needles")
    assert len(tuft.outlines) >= 5
    for outline in tuft.outlines:
        lengths = np.linalg.norm(outline, axis=1)
        tip = outline[np.argmax(lengths)]
        assert tip[0] > 0.8 * lengths.max()             # forward, along H
        base = outline[[0, -1]]
        assert np.linalg.norm(base[0] - base[1]) < 0.05 * lengths.max()   # thin: over 20:1
    normals = tuft.polygons.normal
    # the needles' planes face many ways: from any side some needle is seen face-on
    for side in ([0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1], [0, 0.7071, 0.7071]):
        assert np.abs(normals @ side).max() > 0.7


# ------------------------------------------------------------------ the turtle places them
@pytest.mark.parametrize("name", SURFACES)
def test_surface_follows_the_turtle(name):
    # the turtle's frame after f(2) +(30) &(40) /(25) f(1.5) -(10), computed here with
    # rotation matrices about the current axes (the README's senses: + turns H towards L
    # about U, & pitches H down about L, / rolls right about H)
    g = grammar(axiom=f"f(2) +(30) &(40) /(25) f(1.5) -(10) ~({name}, 0.7)")
    H, L, U = np.array([0.0, 1, 0]), np.array([-1.0, 0, 0]), np.array([0.0, 0, 1])
    p = 2 * H
    for axis, angle in (("U", 30), ("L", 40), ("H", -25)):
        r = rotation({"H": H, "L": L, "U": U}[axis], angle)
        H, L, U = r @ H, r @ L, r @ U
    p = p + 1.5 * H
    r = rotation(U, -10)
    H, L, U = r @ H, r @ L, r @ U
    local = surface(name).polygons
    expected = p + 0.7 * (local.vertices[:, :1] * H + local.vertices[:, 1:2] * L + local.vertices[:, 2:] * U)
    d = draw(g)
    assert np.allclose(d.polygons.vertices, expected, atol=1e-12)
    assert np.array_equal(d.polygons.triangles, local.triangles)
    frame = np.stack([H, L, U], axis=1)                  # columns: local axes -> world
    assert np.allclose(d.polygons.normal, local.normal @ frame.T, atol=1e-12)
    assert len(d.skeleton) == 0 and d.warnings == ()     # '~' no longer warns


def test_surface_does_not_move_the_turtle():
    d = draw(grammar(axiom="F ~(leaf) F"))
    assert np.allclose(d.skeleton.start[1], [0, 1, 0]) and d.skeleton.continues[1]


@pytest.mark.parametrize("scale", [0.25, 1.0, 3.7])
@pytest.mark.parametrize("name", SURFACES)
def test_scale_scales_area_by_its_square(name, scale):
    one = draw(grammar(axiom=f"+(33) ~({name})")).polygons
    scaled = draw(grammar(axiom=f"+(33) ~({name}, {scale})")).polygons
    assert scaled.triangle_areas().sum() == pytest.approx(scale ** 2 * one.triangle_areas().sum(), rel=1e-12)
    assert one.triangle_areas().sum() == pytest.approx(surface(name).polygons.triangle_areas().sum(), rel=1e-12)


def test_scale_zero_draws_nothing_and_a_negative_one_is_an_error(tmp_path):
    assert len(draw(grammar(axiom="~(leaf, 0)")).polygons) == 0
    src = tmp_path / "neg.yaml"
    src.write_text('axiom: "A(1)"\niterations: 1\nrules: ["A(x) -> ~(needles, -x)"]\n')
    code, _, err = run_cli("grow", src, "-o", tmp_path / "neg.npz")
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "neg.yaml" in err and "negative scale -1" in err and "Traceback" not in err
    assert not (tmp_path / "neg.npz").exists()


def test_material_follows_semicolon_and_tick():
    g = grammar(axiom="~(leaf) ;(2) ~(leaf) ' ~(needles) [ ;(1) ~(leaf) ] ' ~(leaf)",
                materials=["bark", "leaf", "needle", "other"])
    polygons = draw(g).polygons
    n = surface("needles").polygons
    expected = [0, 0, 2, 2, *[3] * len(n), 1, 1, 0, 0]       # ' wraps from 3 to 0
    assert polygons.material.tolist() == expected


def test_surfaces_follow_the_brace_polygons_in_string_order():
    d = draw(grammar(axiom="~(needles) {.f.+f.} F ~(leaf) ~(needles)", turtle={"angle": 90}))
    leaf, tuft = surface("leaf").polygons, surface("needles").polygons
    assert len(d.polygons) == 1 + len(tuft) + len(leaf) + len(tuft)
    areas = np.bincount(d.polygons.polygon, d.polygons.triangle_areas())
    assert areas[0] == pytest.approx(0.5)                            # the triangle of { }
    assert np.allclose(areas[1:1 + len(tuft)], np.bincount(tuft.polygon, tuft.triangle_areas()))


def test_place_batches_copies_in_input_order():
    frames = [np.eye(3), rotation([0, 1, 0], 90)]
    got = place(0, [[0, 0, 0], [5, 0, 0]], frames, [1.0, 2.0], [3, 4])
    leaf = surface(0).polygons
    nv = len(leaf.vertices)
    assert np.allclose(got.vertices[:nv], leaf.vertices)
    assert np.allclose(got.vertices[nv:], [5, 0, 0] + 2 * leaf.vertices @ frames[1])
    assert got.material.tolist() == [3] * len(leaf) + [4] * len(leaf)
    assert got.triangles.max() == 2 * nv - 1


# ------------------------------------------------------------------ grammar-level errors
@pytest.mark.parametrize(("axiom", "match"), [
    ("~(tree, 1)", "one of leaf, needles; got 'tree'"),
    ("~(1)", "one of leaf, needles; got '1'"),
    ("~(leaf + 1)", "got 'leaf + 1'"),
    ("~(__import__)", "got '__import__'"),
    ("~", "wrong parameter count for '~'"),
    ("~(leaf, 1, 2)", "wrong parameter count for '~'"),
    ("~(leaf, leaf)", "undefined name 'leaf'"),      # names are surfaces only in first place
])
def test_bad_surface_arguments_are_grammar_errors(axiom, match):
    with pytest.raises(GrammarError, match=match.replace("(", r"\(").replace("+", r"\+")):
        grammar(axiom=axiom)


def test_unknown_surface_is_one_line_and_exit_2_from_the_cli(tmp_path):
    src = tmp_path / "bad.yaml"
    src.write_text('axiom: "A"\niterations: 2\nrules: ["A -> F ~(fern, 0.5) A"]\n')
    code, out, err = run_cli("export", src, "-o", tmp_path / "bad.glb")
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "bad.yaml" in err and "rule 1" in err and "leaf, needles" in err and "'fern'" in err
    assert not (tmp_path / "bad.glb").exists()


def test_a_surface_index_the_grammar_did_not_make_is_refused():
    # a module string built by other means (not a grammar) cannot name a surface that
    # does not exist
    g = grammar(axiom="~(leaf, 1)")
    ms = derive(g)
    ms.params[0, 0] = 7
    with pytest.raises(Exception, match="names no surface"):
        interpret_plant(ms, g.turtle, g.materials, "test.yaml")


def test_polygon_vertices_are_counted_against_their_limit(tmp_path):
    # 2^16 tufts of 56 vertices (3.7 million) pass the default limit of 4 million; 2^17
    # are refused before the turtle walks, and --limit raises the budget
    g = grammar(axiom="A", iterations=16, rules=["A -> AA"], interpretation=["A -> ~(needles, 0.1)"])
    tight = Limits(max_polygon_vertices=56 * 2 ** 16 - 1)
    with pytest.raises(LimitError, match="polygon vertices: 3,670,016 over the limit .*--limit polygon_vertices=N"):
        draw(g, tight)
    src = tmp_path / "many.yaml"
    src.write_text('axiom: "A"\niterations: 17\nrules: ["A -> AA"]\ninterpretation: ["A -> ~(needles, 0.1)"]\n')
    code, _, err = run_cli("grow", src, "-o", tmp_path / "many.npz")
    assert code == 2 and "polygon vertices: 7,340,032 over the limit of 4,000,000" in err
    assert len(err.strip().splitlines()) == 1
    # the dots count too
    dots = grammar(axiom="A", iterations=3, rules=["A -> AA"], interpretation=["A -> {.f.+f.}"])
    assert len(draw(dots, Limits(max_polygon_vertices=24)).polygons) == 8
    with pytest.raises(LimitError, match="polygon vertices: 24 over"):
        draw(dots, Limits(max_polygon_vertices=23))


# ------------------------------------------------------------------ exports
def test_glb_export_carries_the_surfaces(tmp_path):
    src = tmp_path / "tufts.yaml"
    src.write_text('axiom: "A"\niterations: 3\nmaterials: [bark, needle]\n'
                   'rules: ["A -> F [ ;(1) +(30) ~(needles, 0.4) ] [ ;(1) -(30) ~(leaf, 0.3) ] A"]\n')
    grown = grow_file(src)
    tuft, leaf = surface("needles").polygons, surface("leaf").polygons
    assert len(grown.polygons) == 3 * (len(tuft) + len(leaf))
    assert len(grown.polygons.triangles) == 3 * (len(tuft.triangles) + len(leaf.triangles))
    path = tmp_path / "tufts.glb"
    summary = export_model(src, path)
    assert summary["leaf_triangles"] == len(grown.polygons.triangles)
    doc = gltf_json(path)
    materials = doc["materials"]
    leaves = [p for p in doc["meshes"][0]["primitives"] if materials[p["material"]].get("doubleSided")]
    assert len(leaves) == 1
    assert doc["accessors"][leaves[0]["indices"]]["count"] // 3 == len(grown.polygons.triangles)


# ------------------------------------------------------------------ shipped leafy grammars
def is_green(name: str) -> bool:
    r, g, b = material_colour(name)
    return g > 1.3 * r and g > 1.3 * b


def test_abop_bush_has_its_3891_segments_and_green_leaves():
    grown = grow_file(grammars_dir() / "abop_bush.yaml")
    assert len(grown.skeleton) == 3891
    polygons = grown.polygons
    assert len(polygons) == 1284 and grown.warnings == ()
    names = grown.skeleton.material_names
    assert all(is_green(names[m]) for m in np.unique(polygons.material))
    assert len(np.unique(polygons.material)) > 5                      # the ' steps show
    # the stems: woody (not green) where they start, at the base of the bush
    base = grown.skeleton.start[:, 1] < 0.05
    assert not any(is_green(names[m]) for m in np.unique(grown.skeleton.material[base]))


def surface_bases(polygons, name: str) -> np.ndarray:
    """(n, 3): where the turtle stood for each placed copy of surface ``name``: the local
    origin mapped like the vertices (the leaf's base vertex; for the tuft, halfway between
    the base corners of its first needle, whose outline comes first)."""
    s = surface(name)
    local = s.polygons.vertices
    at_origin = np.flatnonzero(np.linalg.norm(local, axis=1) < 1e-12)
    pick = at_origin[:1] if len(at_origin) else np.array([0, len(s.outlines[0]) - 1])
    assert np.allclose(local[pick].mean(axis=0), 0)
    return polygons.vertices.reshape(-1, len(local), 3)[:, pick].mean(axis=1)


@pytest.mark.parametrize(("name", "kind", "lo", "hi"), [("broadleaf", "leaf", 1000, 10_000),
                                                        ("pine_needles", "needles", 3000, 30_000)])
def test_leafy_trees_carry_their_surfaces_on_their_branches(name, kind, lo, hi):
    grown = grow_file(grammars_dir() / f"{name}.yaml")
    skel, polygons = grown.skeleton, grown.polygons
    per = len(surface(kind).polygons)
    assert len(polygons) % per == 0 and lo <= len(polygons) // per <= hi
    assert len(skel) < 6000 and grown.warnings == ()
    names = skel.material_names
    assert all(is_green(names[m]) for m in np.unique(polygons.material))
    # each copy grows from a branch: the turtle stood at a segment's end point
    ends = cKDTree(np.concatenate([skel.start, skel.end]))
    dist, _ = ends.query(surface_bases(polygons, kind))
    assert dist.max() < 1e-9
    # and grows out of it: hardly a tip (a leaf's, a needle's) lies inside a branch
    # thicker than 3 cm (within 0.9 of its radius of its axis); a few needles of a twig's
    # tuft may cross the branch the twig grows from
    local = surface(kind).polygons.vertices
    tips = np.flatnonzero(np.linalg.norm(local, axis=1) > 0.8)
    v = polygons.vertices.reshape(-1, len(local), 3)[:, tips].reshape(-1, 3)
    inside = np.zeros(len(v), dtype=bool)
    for i in np.flatnonzero(np.minimum(skel.r_start, skel.r_end) > 0.03):
        a, axis = skel.start[i], skel.end[i] - skel.start[i]
        t = np.clip((v - a) @ axis / (axis @ axis), 0, 1)
        inside |= np.linalg.norm(v - (a + t[:, None] * axis), axis=1) < 0.9 * min(skel.r_start[i], skel.r_end[i])
    assert inside.mean() < 0.002


def test_broadleaf_blades_face_the_sky():
    # every leaf is rolled level ($) before it is placed, so its blade's up side faces up
    polygons = grow_file(grammars_dir() / "broadleaf.yaml").polygons
    assert (polygons.normal[:, 1] > 0).all()


def test_pine_needles_keeps_the_pines_trunk_and_table1_pine_is_unchanged():
    pine = grow_file(grammars_dir() / "pine.yaml", defines={"foliage": 0})      # Table 1's variant
    needles = grow_file(grammars_dir() / "pine_needles.yaml")
    assert len(pine.skeleton) == 16816 and len(pine.polygons) == 0
    trunk = lambda s: s.start[(s.parent < 0) | s.continues][:34]   # noqa: E731
    assert np.allclose(trunk(pine.skeleton)[:8], trunk(needles.skeleton)[:8])   # the same bare bole
    height = lambda s: np.ptp(np.concatenate([s.start[:, 1], s.end[:, 1]]))   # noqa: E731
    assert abs(height(pine.skeleton) - height(needles.skeleton)) < 1.0
