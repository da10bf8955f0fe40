"""Leaves on the grammar side: ABOP polygons ({ . } G f), the colour step ', the cut %,
interpretation rules, and the warning for ABOP symbols plantgen does not draw."""

import numpy as np
import pytest
from _cli import run_cli
from hypothesis import given, settings
from hypothesis import strategies as st

from plantgen._resources import grammars_dir
from plantgen.geometry.meshes.polygons import triangulate
from plantgen.lsystem import derive, parse_grammar
from plantgen.lsystem.derive import apply_interpretation, cut_branches
from plantgen.lsystem.grammar import GrammarError
from plantgen.lsystem.turtle import MAX_POLYGON_VERTICES, interpret_plant
from plantgen.pipeline import grow_file


def grammar(**kw):
    kw.setdefault("iterations", 0)
    kw.setdefault("rules", [])
    kw.setdefault("turtle", {"angle": 90})
    return parse_grammar(kw, "test.yaml")


def draw(g, **kw):
    ms = apply_interpretation(g, derive(g, **kw))
    d = interpret_plant(ms, g.turtle, g.materials, "test.yaml")
    d.skeleton.validate()
    return d


def outline(d, p=0):
    """The distinct vertices of polygon p, in the order the triangles first use them."""
    tris = d.polygons.triangles[d.polygons.polygon == p]
    return d.polygons.vertices[np.unique(tris)]


def as_set(points):
    return {tuple(np.round(p, 9) + 0.0) for p in points}


def total_area(d, p=0):
    return d.polygons.triangle_areas()[d.polygons.polygon == p].sum()


def shoelace(uv):
    x, y = np.asarray(uv, float).T
    return 0.5 * abs(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


# ------------------------------------------------------------------ ABOP constructions
def test_chapter1_polygon_records_start_and_every_f():
    # ABOP 1.10.3: with no '.', the position at '{' and after each f are the vertices.
    # Heading +y, left -x: the square (0,0) (0,1) (-1,1) (-1,0), turning left, so its
    # normal is the turtle's up, +z.
    d = draw(grammar(axiom="{f+f+f+f}"))
    assert as_set(outline(d)) == {(0, 0, 0), (0, 1, 0), (-1, 1, 0), (-1, 0, 0)}
    assert len(d.skeleton) == 0                       # f draws nothing
    assert np.allclose(d.polygons.normal[0], [0, 0, 1])
    assert total_area(d) == pytest.approx(1.0)


def test_dots_record_and_G_f_only_move():
    # ABOP chapter 5: '.' records; G moves without recording. With a '.' in the polygon,
    # f moves without recording too.
    d = draw(grammar(axiom="{.G.+G.}"))
    assert as_set(outline(d)) == {(0, 0, 0), (0, 1, 0), (-1, 1, 0)}
    d = draw(grammar(axiom="{.f.+f+f.}"))
    assert as_set(outline(d)) == {(0, 0, 0), (0, 1, 0), (-1, 0, 0)}
    assert len(d.skeleton) == 0


def test_G_moves_like_f_outside_polygons():
    d = draw(grammar(axiom="F G(2) F"))
    assert len(d.skeleton) == 2
    assert np.allclose(d.skeleton.start[1], [0, 3, 0])
    assert d.skeleton.parent[1] == -1                 # a new root, as after f


def test_branches_inside_a_polygon_add_to_it_and_restore_the_turtle():
    # ABOP figure 5.5's fan: vertices recorded inside [ ] belong to the enclosing polygon,
    # and the turtle comes back to where the branch started.
    d = draw(grammar(axiom="{.[+G.][G.][-G.]}F"))
    assert as_set(outline(d)) == {(-1, 0, 0), (0, 1, 0), (1, 0, 0)}   # (0,0,0) lies on an edge
    assert total_area(d) == pytest.approx(1.0)
    assert np.allclose(d.skeleton.start[0], [0, 0, 0]) and np.allclose(d.skeleton.end[0], [0, 1, 0])


def test_nested_polygons():
    # The inner polygon closes first; the outer one resumes where the turtle stands.
    d = draw(grammar(axiom="{.G.{.+G.-G.}+G.}"))
    assert len(d.polygons) == 2
    assert as_set(outline(d, 0)) == {(0, 1, 0), (-1, 1, 0), (-1, 2, 0)}
    assert as_set(outline(d, 1)) == {(0, 0, 0), (0, 1, 0), (-2, 2, 0)}


def test_polygon_follows_the_turtle_orientation():
    # & (90) turns H towards -U: the heading becomes -z, the up +y; + then turns to L = -x.
    d = draw(grammar(axiom="&{.G.+G.}"))
    assert as_set(outline(d)) == {(0, 0, 0), (0, 0, -1), (-1, 0, -1)}
    assert abs(d.polygons.normal[0] @ [0, 1, 0]) == pytest.approx(1.0)


def test_unbalanced_polygons_are_one_line_errors():
    for axiom in ("{.G.+G.", "F}"):
        with pytest.raises(Exception, match="polygon") as info:
            draw(grammar(axiom=axiom))
        assert "\n" not in str(info.value)


def test_a_polygon_past_the_vertex_limit_is_refused_in_one_line():
    with pytest.raises(Exception, match="more than 4,096 vertices") as info:
        draw(grammar(axiom="{" + "+(1)G(0.01)." * (MAX_POLYGON_VERTICES + 1) + "}"))
    assert "\n" not in str(info.value)


# ------------------------------------------------------------------ triangulation
def test_concave_turtle_polygon_has_the_shoelace_area_in_its_tilted_plane():
    # An L of area 3 (a 2x2 square less a unit corner), drawn after pitching and rolling,
    # so its plane is not a coordinate plane.
    d = draw(grammar(axiom="&(30)/(20){.G(2).+G.+G.-G.+G.}"))
    assert len(d.polygons) == 1
    assert total_area(d) == pytest.approx(3.0)
    n = d.polygons.normal[0]
    v = d.polygons.vertices
    assert np.allclose((v - v[0]) @ n, 0.0, atol=1e-12)


def _star(k, radii, phase):
    a = phase + 2 * np.pi * np.arange(k) / k
    return np.stack([np.cos(a) * radii, np.sin(a) * radii], axis=1)


@settings(max_examples=60, deadline=None)
@given(k=st.integers(3, 24), seed=st.integers(0, 2**32 - 1), reverse=st.booleans())
def test_star_polygons_triangulate_to_their_area_with_consistent_winding(k, seed, reverse):
    rng = np.random.default_rng(seed)
    uv = _star(k, rng.uniform(0.2, 2.0, k), rng.uniform(0, 2 * np.pi))   # star-shaped: simple, often concave
    if reverse:
        uv = uv[::-1]
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))            # a random plane in space
    pts = np.c_[uv, np.zeros(k)] @ q.T + rng.normal(size=3)
    verts, tris, normal = triangulate(pts)
    a, b, c = (verts[tris[:, j]] for j in range(3))
    cross = np.cross(b - a, c - a)
    assert 0.5 * np.linalg.norm(cross, axis=1).sum() == pytest.approx(shoelace(uv), rel=1e-9)
    # every triangle faces the polygon's normal: none flipped, so none overlap
    assert np.all(cross @ normal > -1e-12)
    assert abs(normal @ q[:, 2]) == pytest.approx(1.0)


def test_degenerate_polygon_is_dropped_with_a_warning():
    d = draw(grammar(axiom="{.G.G.}"))                    # collinear: no area
    assert len(d.polygons) == 0
    assert any("no area" in w for w in d.warnings)


# ------------------------------------------------------------------ materials
def test_tick_steps_to_the_next_material_and_polygons_carry_it():
    g = grammar(axiom="F'F'F'F ;(1)'{.G.+G.} '{.G.+G.}", materials=["bark", "leaf", "flower"])
    d = draw(g)
    assert d.skeleton.material.tolist() == [0, 1, 2, 0]
    assert d.polygons.material.tolist() == [2, 0]         # ;(1)' -> 2, then ' wraps to 0
    assert np.all(d.polygons.triangle_material == d.polygons.material[d.polygons.polygon])


def test_tick_is_part_of_the_turtle_state():
    d = draw(grammar(axiom="F['F]F", materials=["bark", "leaf"]))
    assert d.skeleton.material.tolist() == [0, 1, 0]


def test_tick_takes_no_parameter():
    with pytest.raises(GrammarError, match="'"):
        grammar(axiom="'(2)F")


# ------------------------------------------------------------------ cut
def _reference_cut(text):
    """Drop each % and what follows it up to the ] closing its branch (kept)."""
    out, skip_depth, depth = [], None, 0
    for ch in text:
        if skip_depth is not None:
            if ch == "[":
                depth += 1
            elif ch == "]":
                if depth == skip_depth:
                    skip_depth = None
                    depth -= 1
                    out.append(ch)
                    continue
                depth -= 1
            continue
        if ch == "%":
            skip_depth = depth
            continue
        if ch == "[":
            depth += 1
        elif ch == "]":
            depth -= 1
        out.append(ch)
    return "".join(out)


def test_cut_removes_exactly_the_rest_of_its_branch():
    g = grammar(axiom="A[B%C[E]F]G[H]%K[L]M")
    assert derive(g).to_text() == "A[B]G[H]"
    d = draw(grammar(axiom="F[F%F[F]F]F[F]"))
    assert len(d.skeleton) == 4


def test_cut_in_a_derivation_step():
    # ABOP: a rule producing % cuts the branch in the same step.
    g = grammar(axiom="F[A F F]F", rules=["A -> %"], iterations=1)
    assert derive(g).to_text() == "F[]F"
    assert len(draw(g).skeleton) == 2


@settings(max_examples=80, deadline=None)
@given(st.lists(st.sampled_from(["A", "B", "%", "[", "]"]), max_size=40))
def test_cut_matches_a_stack_walk(symbols):
    text, depth = [], 0
    for s in symbols:                       # keep the brackets balanced
        if s == "]" and depth == 0:
            continue
        depth += s == "["
        depth -= s == "]"
        text.append(s)
    text = "".join(text) + "]" * depth + "A"
    g = grammar(axiom=text)
    assert derive(g).to_text() == _reference_cut(text)
    ms = derive(g)
    assert cut_branches(ms).to_text() == ms.to_text()          # nothing left to cut


# ------------------------------------------------------------------ interpretation rules
LEAFY = dict(axiom="A", iterations=4, seed=5, materials=["bark", "leaf"],
             rules=["A -> F[+L]B A", {"rule": "B -> F", "p": 0.5}, {"rule": "B -> FF", "p": 0.5}])


def test_interpretation_rules_never_change_the_derived_string():
    plain = grammar(**LEAFY)
    leafy = grammar(**LEAFY, interpretation=["L -> '{.+G.-G.-G.}", {"rule": "F -> F(0.5)F(0.5)", "p": 0.5},
                                             {"rule": "F -> F", "p": 0.5}], interpretation_depth=2)
    for seed in range(5):
        ms = derive(leafy, seed=seed)
        before = (ms.sym.copy(), ms.nparam.copy(), ms.params.copy())
        assert ms.to_text() == derive(plain, seed=seed).to_text()
        drawn = apply_interpretation(leafy, ms, seed)
        assert all(np.array_equal(a, b) for a, b in zip(before, (ms.sym, ms.nparam, ms.params), strict=True))
        assert "{" in drawn.to_text() and "{" not in ms.to_text()
        d = interpret_plant(drawn, leafy.turtle, leafy.materials)
        assert len(d.polygons) == ms.to_text().count("L")
        assert set(d.polygons.material.tolist()) == {1}


def test_interpretation_is_applied_a_bounded_number_of_times():
    def passes(depth):
        g = grammar(axiom="A", interpretation=["A -> AA"], interpretation_depth=depth)
        return apply_interpretation(g, derive(g)).to_text()

    assert passes(1) == "AA"
    assert passes(3) == "A" * 8
    with pytest.raises(GrammarError, match="interpretation_depth"):
        grammar(axiom="A", interpretation=["A -> AA"], interpretation_depth=9)


def test_interpretation_rule_errors_name_the_section():
    with pytest.raises(GrammarError, match="interpretation rule 1"):
        grammar(axiom="A", interpretation=["A -> F(x)"])


# ------------------------------------------------------------------ warnings
def test_unsupported_abop_symbol_warns_naming_it():
    d = draw(grammar(axiom="F@(1)F@(2)#.", rules=[]))
    assert any("'@'" in w and "2 module" in w for w in d.warnings)
    assert any("'#'" in w and "1 module" in w for w in d.warnings)
    assert any("'.'" in w for w in d.warnings)              # a dot outside any polygon
    assert len(d.skeleton) == 2
    assert draw(grammar(axiom="F[+F]F")).warnings == ()


@pytest.mark.parametrize("command", [("grow", "-o", "g.npz"), ("grow", "-o", "g.npz", "--quiet"),
                                     ("export", "-o", "g.obj"), ("export", "-o", "g.swc", "--quiet"),
                                     ("render", "-o", "g.png", "--size", "64x48")])
def test_cli_prints_the_warning_on_stderr(tmp_path, command):
    src = tmp_path / "g.yaml"
    src.write_text('axiom: "F @(1) F"\n')
    verb, flag, out, *extra = command
    code, _, err = run_cli(verb, src, flag, tmp_path / out, *extra)
    assert code == 0, err
    assert (tmp_path / out).is_file()
    lines = [line for line in err.splitlines() if "'@'" in line]
    assert len(lines) == 1 and "warning" in lines[0]


# ------------------------------------------------------------------ shipped grammars
@pytest.mark.parametrize(("name", "segments"), [("abop_ternary", 1457), ("aloe", 229), ("saguaro", 30),
                                                ("elm", 1830)])
def test_shipped_grammars_draw_what_they_drew_before(name, segments):
    # Segment counts on main before this change (commit 33c28b2); none uses the new symbols
    # (the aloe's paper variant: its blades, since, are leaf polygons).
    result = grow_file(grammars_dir() / f"{name}.yaml", defines={"blades": 0} if name == "aloe" else None)
    assert len(result.skeleton) == segments
    assert len(result.polygons) == 0 and result.warnings == ()


def test_abop_figure_1_25_bush_grows_its_leaves():
    # ABOP figure 1.25 with its leaves: the branches are unchanged (3,891 segments), every
    # '{' of the derived string is one leaf, and each leaf, a rigid motion of the same
    # outline, has the area of that outline drawn alone.
    bush = grammar(axiom="A", iterations=7, turtle={"angle": 22.5},
                   materials=["bark", "l1", "l2", "l3", "l4", "l5"],
                   rules=["A -> [&FL!A]/////'[&FL!A]///////'[&FL!A]", "F -> S/////F", "S -> FL",
                          "L -> ['''^^{-f+f+f-|-f+f+f}]"])
    d = draw(bush)
    assert len(d.skeleton) == 3891
    assert len(d.polygons) == derive(bush).to_text(10**6).count("{") > 1000
    leaf = draw(grammar(axiom="{-f+f+f-|-f+f+f}", turtle={"angle": 22.5}))
    areas = np.bincount(d.polygons.polygon, d.polygons.triangle_areas())
    assert np.allclose(areas, total_area(leaf), rtol=1e-9)
    assert set(d.polygons.material.tolist()) == set(range(6))
