"""L-Py files (.lpy): read by translation into plantgen's grammar, never run.

Each .lpy file of tests/data/lpy (written for these tests from L-Py's documented syntax)
has a YAML twin of the same name, the grammar a plantgen user writes for the same model;
the ABOP ones are the shipped grammars. Each grows to the same skeleton as its twin, array
for array; ``plantgen convert`` writes YAML that grows the same again; what plantgen
cannot translate is refused in one line naming the construct and its line, fast and in
bounded memory (the hostile runner's subprocess).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import yaml
from _cli import run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_hostile import assert_refused, run_cases

from plantgen.errors import PlantgenError
from plantgen.lsystem.derive import apply_interpretation, derive
from plantgen.lsystem.expr import EvalContext, compile_expr
from plantgen.lsystem.grammar import load_grammar, parse_grammar
from plantgen.lsystem.lpy import MAX_LOOP_ITERATIONS, LpyError, parse_lpy, read_lpy
from plantgen.pipeline import grow, grow_file

DATA = Path(__file__).with_name("data") / "lpy"
GRAMMARS = Path(__file__).resolve().parents[1] / "grammars"
ARRAYS = ("start", "end", "r_start", "r_end", "parent", "continues", "material")
CONSTRUCTS = sorted(p.stem for p in DATA.glob("*.lpy") if not p.stem.startswith("abop_"))
ABOP = sorted(p.stem for p in DATA.glob("abop_*.lpy"))


def twin(stem: str) -> Path:
    return GRAMMARS / f"{stem}.yaml" if stem.startswith("abop_") else DATA / f"{stem}.yaml"


def assert_same_skeleton(a, b) -> None:
    assert len(a.start) > 0
    for name in ARRAYS:
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


def test_every_construct_and_abop_grammar_has_a_twin():
    assert set(ABOP) == {"abop_bush", "abop_monopodial", "abop_sympodial", "abop_ternary"}
    assert len(CONSTRUCTS) >= 10
    for stem in CONSTRUCTS + ABOP:
        assert twin(stem).is_file(), stem


@pytest.mark.parametrize("stem", ABOP + CONSTRUCTS)
def test_an_lpy_model_grows_the_skeleton_of_its_yaml_twin(stem):
    assert_same_skeleton(grow(DATA / f"{stem}.lpy"), grow(twin(stem)))


@pytest.mark.parametrize("stem", ["abop_bush", "stochastic", "queries", "turtle_names", "decomposition",
                                  "branch_context", "new_context", "several_modules", "globals"])
def test_convert_round_trip_grows_the_same_skeleton(tmp_path, stem):
    out = tmp_path / f"{stem}.yaml"
    code, stdout, err = run_cli("convert", DATA / f"{stem}.lpy", "-o", out)
    assert code == 0, err
    assert out.is_file() and "rules" in stdout
    assert_same_skeleton(grow(out), grow(DATA / f"{stem}.lpy"))
    assert parse_grammar(yaml.safe_load(out.read_text()), str(out)).rules


def test_convert_names_renamed_modules_and_refuses_what_it_cannot_express(tmp_path):
    code, stdout, _ = run_cli("convert", DATA / "turtle_names.lpy", "-o", tmp_path / "t.yaml")
    assert code == 0 and "Apex -> " in stdout
    assert "#   Apex -> " in (tmp_path / "t.yaml").read_text()
    bad = tmp_path / "bad.lpy"
    bad.write_text("Axiom: A\nproduction:\nA >> B --> F F\n")
    code, _, err = run_cli("convert", bad, "-o", tmp_path / "bad.yaml")
    assert code == 2 and err.count("\n") == 1 and "line 3" in err and "'>>'" in err
    assert not (tmp_path / "bad.yaml").exists()
    code, _, err = run_cli("convert", GRAMMARS / "abop_bush.yaml", "-o", tmp_path / "x.yaml")
    assert code == 2 and ".lpy" in err


def test_lpy_is_an_input_of_grow_export_load_grammar_and_scenes(tmp_path):
    assert grow_file(DATA / "queries.lpy").sources == (DATA / "queries.lpy",)   # what `view` watches
    code, out, err = run_cli("grow", DATA / "turtle_names.lpy", "-o", tmp_path / "t.npz")
    assert code == 0 and (tmp_path / "t.npz").is_file()
    assert err.count("'@O' (sphere) is not drawn") == 1          # the dropped module, warned of once
    code, _, err = run_cli("export", DATA / "abop_sympodial.lpy", "-o", tmp_path / "t.ply")
    assert code == 0, err
    assert load_grammar(DATA / "abop_ternary.lpy").turtle.tropism_strength == pytest.approx(0.22)
    (tmp_path / "m.lpy").write_text((DATA / "abop_monopodial.lpy").read_text())
    (tmp_path / "scene.yaml").write_text("name: s\ninstances:\n  - {grammar: m.lpy, position: [0, 0, 0]}\n"
                                         "  - {grammar: m.lpy, position: [5, 0, 0]}\n")
    scene = grow_file(tmp_path / "scene.yaml")
    assert len(scene.scene.skeleton().start) == 2 * len(grow(tmp_path / "m.lpy").start)


def test_an_lpy_model_renders(tmp_path):
    from PIL import Image

    out = tmp_path / "t.png"
    code, _, err = run_cli("render", DATA / "abop_ternary.lpy", "-o", out, "--size", "64x64")
    assert code == 0, err
    pixels = np.asarray(Image.open(out).convert("L"), dtype=float)
    assert pixels.std() > 5            # the tree, not an empty frame


@pytest.mark.parametrize("method", ["rc", "rt"])
def test_a_model_of_polygons_alone_grows_renders_and_is_refused_by_export_in_one_line(tmp_path, method):
    """A turtle drawing that fills a square and draws no segment: grow writes its (empty)
    skeleton and says the polygons are not in it, render draws the square, export (a mesh
    of the skin) says in one line why it has nothing to write."""
    from PIL import Image

    path = tmp_path / "square.lpy"
    path.write_text("Axiom: {.f(1)+(90).f(1)+(90).f(1)+(90).f(1).}\nderivation length: 0\nproduction:\nendlsystem\n")
    code, out, err = run_cli("grow", path, "-o", tmp_path / "square.npz")
    assert code == 0, err
    assert "0 segments" in out and "1 leaf polygons" in out and "not written" in err
    png = tmp_path / "square.png"
    code, _, err = run_cli("render", path, "-o", png, "--size", "64x64", "--method", method)
    assert code == 0, err
    pixels = np.asarray(Image.open(png).convert("L"), dtype=float)
    assert pixels.std() > 5            # the square, not an empty frame
    code, _, err = run_cli("export", path, "-o", tmp_path / "square.glb")
    assert code == 2 and "polygons alone" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "square.glb").exists()


def test_select_and_choose_evaluate_only_the_chosen_value():
    ctx = EvalContext({"x": np.array([-1.0, 4.0])}, np.random.default_rng(0), 2)
    assert compile_expr("select(x > 0, sqrt(x), 0)", {"x"})(ctx).tolist() == [0.0, 2.0]
    assert compile_expr("choose(x, 10, 20, 30)", {"x"})(ctx).tolist() == [10.0, 30.0]   # clamped
    assert compile_expr("trunc(-1.5) + round(2.5)")(ctx) == 1.0


def test_the_viewer_grows_an_lpy_model_and_watches_its_file(tmp_path):
    from plantgen.viewer.session import ViewOptions
    from plantgen.viewer.watch import FileWatcher

    path = tmp_path / "m.lpy"
    path.write_text((DATA / "block_if.lpy").read_text())
    model = ViewOptions(input=path, size=(32, 32), watch=True, shots=tmp_path).prepare()
    assert model.grown.sources == (path,) and len(model.grown.skeleton.start) == 21
    watcher = FileWatcher(model.grown.sources, settle_s=0.0)
    assert watcher.poll(0.0) is None
    path.write_text(path.read_text().replace("derivation length: 6", "derivation length: 3"))
    stat = path.stat()
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 10**9))
    assert watcher.poll(1.0) is not None or watcher.poll(2.0) is not None
    assert len(ViewOptions(input=path, size=(32, 32), shots=tmp_path).prepare().grown.skeleton.start) < 21


def test_initialisation_scalars_become_defines_and_groups_are_warned_of():
    model = read_lpy(DATA / "groups_init.lpy")
    assert model.data["defines"] == {"len": 0.6, "turn": 35}
    assert any("INITIALISATION" in w for w in model.warnings)
    assert any("group 1" in w for w in model.warnings)


def test_query_coordinates_are_l_pys_with_z_up():
    """?P(x, y, z) in L-Py has z up: its z is plantgen's y, so the apex stops once its
    internodes reach a height of 3 (plantgen's z stays 0 in this model: read as z, it
    would never stop)."""
    skel = grow(DATA / "queries.lpy")
    long = np.isclose(np.linalg.norm(skel.end - skel.start, axis=1), 1.0)
    assert 3 <= long.sum() < 10
    assert skel.end[long, 1].max() >= 3 > skel.start[long, 1].max()


def test_a_random_test_with_else_is_one_draw_per_module():
    """``if random() < 0.4: ... else: ...`` becomes a conditional rule and an unconditional
    one after it: the else branch draws nothing, so about 40 % of the modules fork."""
    text = ("Axiom: " + " ".join(["A"] * 4000) + "\nderivation length: 1\nproduction:\nA :\n"
            "    if random() < 0.4:\n        produce B\n    else:\n        produce C\nendlsystem\n")
    data = parse_lpy(text, "p.lpy").data
    assert data["rules"] == ["A : random() < 0.4 -> B", "A -> C"]
    ms = derive(parse_grammar(data, "p.lpy"))
    counts = {s: int(np.sum(ms.sym == i)) for i, s in enumerate(ms.symbols)}
    assert counts.get("A", 0) == 0 and counts["B"] + counts["C"] == 4000
    assert abs(counts["B"] / 4000 - 0.4) < 0.04          # 5 standard deviations


def test_a_loop_over_a_module_parameter_is_unrolled_per_count():
    text = ("Axiom: A(0) A(3) A(20)\nproduction:\nA(n) :\n    for i in range(n):\n        nproduce F(1)\n"
            "    produce B\nendlsystem\n")
    model = parse_lpy(text, "r.lpy")
    ms = derive(parse_grammar(model.data, "r.lpy"))
    assert ms.to_text() == "BF(1)F(1)F(1)BA(20)"          # counts over 16 leave the module as it is
    assert any("range(n)" in w for w in model.warnings)


def test_a_turtle_module_carrying_more_parameters_turns_as_its_first_says(tmp_path):
    """L-Py lets ``-(a, t)`` carry an age t; plantgen's ``-`` takes one angle, so it becomes a
    module of its own, drawn as ``-(a)`` by an interpretation rule."""
    path = tmp_path / "c.lpy"
    path.write_text("Axiom: -(30, 0) F(1) -(10) F(1)\nderivation length: 2\nproduction:\n"
                    "-(a, t) --> -(a + 10, t + 1)\nendlsystem\n")
    data = read_lpy(path).data
    assert data["interpretation"][-1].endswith("-> -(p0)")
    skel = grow(path)
    heading = (skel.end - skel.start) / np.linalg.norm(skel.end - skel.start, axis=1)[:, None]
    angles = np.degrees(np.arccos(np.clip(heading[:, 1], -1, 1)))
    assert angles == pytest.approx([50.0, 60.0])


def test_an_n_step_path_draws_its_whole_length_and_grows_as_a_module(tmp_path):
    """``nF(length, dx)`` draws a straight path of ``length`` (one segment: its steps differ
    from it only under a guide); a rule may rewrite it like any module."""
    path = tmp_path / "n.lpy"
    path.write_text("Axiom: nF(3, 0.5) +(90) nF(2, 0.25)\nderivation length: 1\nproduction:\n"
                    "nF(l, d) : if l < 2.5: produce nF(l * 2, d)\nendlsystem\n")
    skel = grow(path)
    length = np.linalg.norm(skel.end - skel.start, axis=1)
    assert length == pytest.approx([3.0, 4.0], abs=1e-12)
    assert np.dot(skel.end[0] - skel.start[0], skel.end[1] - skel.start[1]) == pytest.approx(0.0, abs=1e-9)
    assert np.allclose(skel.start[1], skel.end[0], atol=1e-12)
    assert not any("nF" in w for w in read_lpy(path).warnings)


def _rotated(v, axis, degrees):
    """``v`` turned right-handedly about the unit ``axis`` (Rodrigues)."""
    a = np.radians(degrees)
    return v * np.cos(a) + np.cross(axis, v) * np.sin(a) + axis * np.dot(axis, v) * (1 - np.cos(a))


def test_a_frame_draws_the_turtles_three_axes_and_leaves_it_unchanged(tmp_path):
    """``Frame(size)`` draws H, L and U from the turtle, each one segment of ``size``
    (``Frame`` alone: size 1); the turtle goes on as before it."""
    H, L, U = np.array([0.0, 1.0, 0.0]), np.array([-1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
    H, L = _rotated(H, U, 30), _rotated(L, U, 30)          # + turns H towards L about U
    H, U = _rotated(H, L, 20), _rotated(U, L, 20)          # & pitches H down about L
    L, U = _rotated(L, H, 15), _rotated(U, H, 15)          # L-Py's / rolls L towards U about H
    for size, text in ((2.0, "Frame(2)"), (1.0, "Frame")):
        path = tmp_path / "frame.lpy"
        path.write_text(f"Axiom: F(1) +(30) &(20) /(15) {text} F(1)\nderivation length: 0\nendlsystem\n")
        skel = grow(path)
        assert len(skel.start) == 5
        assert np.allclose(skel.start[1:4], [0.0, 1.0, 0.0], atol=1e-12)
        for i, axis in zip((1, 2, 3), (H, L, U), strict=True):
            assert np.allclose(skel.end[i] - skel.start[i], size * axis, atol=1e-9)
        assert skel.r_start[1:4] == pytest.approx([size / 20] * 3)
        assert np.allclose(skel.start[4], skel.end[0], atol=1e-12)
        assert np.allclose(skel.end[4] - skel.start[4], H, atol=1e-9)
        assert skel.r_start[4] == pytest.approx(skel.r_end[0])
        assert not any("Frame" in w for w in read_lpy(path).warnings)


def test_a_sphere_is_a_chain_of_frusta_on_it_and_leaves_the_turtle_unchanged(tmp_path):
    """``@O(r)`` draws a chain of frusta along H about the turtle, 2r long, its rims on the
    sphere (radius 0 at both poles); the turtle goes on from the centre."""
    r = 0.5
    path = tmp_path / "sphere.lpy"
    path.write_text(f"Axiom: F(1) +(40) @O({r}) F(1)\nderivation length: 0\nendlsystem\n")
    skel = grow(path)
    centre, H = np.array([0.0, 1.0, 0.0]), np.array([-np.sin(np.radians(40)), np.cos(np.radians(40)), 0.0])
    chain = slice(1, len(skel.start) - 1)
    start, end = skel.start[chain], skel.end[chain]
    assert len(start) >= 4
    assert np.allclose(start[0], centre - r * H, atol=1e-12) and np.allclose(end[-1], centre + r * H, atol=1e-12)
    assert np.allclose(start[1:], end[:-1], atol=1e-12)
    for points, radii in ((start, skel.r_start[chain]), (end, skel.r_end[chain])):
        z = (points - centre) @ H
        assert np.all(np.linalg.norm(points - centre, axis=1) <= r + 1e-9)
        assert np.allclose(z ** 2 + radii ** 2, r ** 2, atol=1e-9)      # each rim lies on the sphere
    assert skel.r_start[chain][0] == 0.0 and skel.r_end[chain][-1] == pytest.approx(0.0, abs=1e-12)
    assert skel.r_end[chain].max() == pytest.approx(r, rel=0.03)
    assert np.allclose(skel.start[-1], centre, atol=1e-12) and np.allclose(skel.end[-1] - centre, H, atol=1e-9)
    assert not any("@O" in w for w in read_lpy(path).warnings)


def test_a_frame_and_a_sphere_produced_by_an_interpretation_rule_are_drawn(tmp_path):
    """An interpretation rule producing ``Frame`` and ``@O`` draws them too: the reader's own
    rules for them run one pass after the file's."""
    path = tmp_path / "interp.lpy"
    path.write_text("module A\nAxiom: F(1) A\nderivation length: 1\nproduction:\ninterpretation:\n"
                    "A --> Frame(2) @O(0.5)\nendlsystem\n")
    skel = grow(path)
    assert len(skel.start) > 1 + 3 + 3
    assert np.linalg.norm(skel.end - skel.start, axis=1)[1:4] == pytest.approx([2.0] * 3)
    assert skel.r_end.max() == pytest.approx(0.5)


def test_undeclared_letters_before_a_rule_heads_parameters_are_modules_of_one_letter(tmp_path):
    """L-Py reads undeclared names at their minimal length: ``IB(x)``, where ``B(x)`` heads a
    rule and ``IB`` none, is the internode I then B(x); a declared name stays whole."""
    path = tmp_path / "ib.lpy"
    path.write_text("Axiom: B(2)\nderivation length: 2\nproduction:\nB(x) --> IB(x - 1)\n"
                    "homomorphism:\nI --> F(1)\nendlsystem\n")
    assert len(grow(path).start) == 2                   # two steps: two internodes drawn
    declared = tmp_path / "declared.lpy"
    declared.write_text("module IB\nAxiom: B(2)\nderivation length: 2\nproduction:\nB(x) --> IB(x - 1)\n"
                        "homomorphism:\nI --> F(1)\nIB(x) --> F(3)\nendlsystem\n")
    skel = grow(declared)
    assert np.linalg.norm(skel.end - skel.start, axis=1) == pytest.approx([3.0])


def test_randint_and_choice_in_a_rule_are_stochastic_alternatives():
    """``n = randint(2, 4)`` read twice (the loop's count and an angle) is one draw per
    module: the rule becomes three alternatives of probability 1/3, each with n fixed."""
    text = ("from random import randint, choice\nAxiom: " + " ".join(["A"] * 3000) + "\nderivation length: 1\n"
            "production:\nA :\n    n = randint(2, 4)\n    for i in range(n):\n        nproduce [ +(360 / n) B ]\n"
            "    produce C(choice([1, 2]))\nendlsystem\n")
    data = parse_lpy(text, "s.lpy").data
    assert [r["p"] for r in data["rules"]] == pytest.approx([1 / 3] * 3)
    ms = derive(parse_grammar(data, "s.lpy"))
    b = int(np.sum(ms.sym == ms.symbols.index("B")))
    assert b / 3000 == pytest.approx(3.0, abs=0.1)            # the mean of 2, 3 and 4
    plus = ms.params[ms.sym == ms.symbols.index("+"), 0]
    assert set(np.round(plus, 6)) == {180.0, 120.0, 90.0}       # each branch turns by 360 / its own n


def test_a_random_test_after_a_random_choice_is_drawn_once_per_module():
    text = ("Axiom: " + " ".join(["A"] * 4000) + "\nderivation length: 1\nproduction:\nA :\n    n = randint(1, 2)\n"
            "    if random() < 0.25:\n        produce B(n)\n    else:\n        produce C(n)\nendlsystem\n")
    ms = derive(parse_grammar(parse_lpy(text, "t.lpy").data, "t.lpy"))
    b = ms.sym == ms.symbols.index("B")
    assert abs(b.mean() - 0.25) < 0.04 and len(ms) == 4000
    assert abs(np.mean(ms.params[b, 0] == 1) - 0.5) < 0.08


def test_a_random_count_from_a_conditional_lambda_forks_per_value():
    """``nb = lambda o: randint(2, 4) if o > 2 else randint(4 - o, 5 - o)`` then
    ``for i in range(nb(o))``: the test picks the draw; a draw whose bounds change with
    ``o`` (a width of 1 whatever ``o``) is enumerated per lower bound. Each module gets
    one of its own counts, each about as often."""
    text = ("import random as rd\nnb = lambda o: rd.randint(2, 4) if o > 2 else rd.randint(4 - o, 5 - o)\n"
            "Axiom: " + " ".join(["A(3)", "A(1)"] * 1500) + "\nderivation length: 1\nproduction:\nA(o) :\n"
            "    n = nb(o)\n    for i in range(n):\n        nproduce B(o)\n    produce C\nendlsystem\n")
    model = parse_lpy(text, "n.lpy")
    ms = derive(parse_grammar(model.data, "n.lpy"))
    counts = {3: [], 1: []}
    run, last = 0, None
    for s, row in zip(ms.sym.tolist(), ms.params.tolist(), strict=True):
        if ms.symbols[s] == "B":
            run, last = run + 1, row[0]
        else:
            counts[int(last)].append(run)
            run = 0
    assert len(counts[3]) == len(counts[1]) == 1500
    for o, values in ((3, [2, 3, 4]), (1, [3, 4])):
        share = [counts[o].count(v) / 1500 for v in values]
        assert sum(share) == 1.0 and share == pytest.approx([1 / len(values)] * len(values), abs=0.05)


def test_a_random_alternative_that_produces_nothing_keeps_the_module_unless_a_later_rule_may_take_it():
    rule = "A :\n    n = randint(0, 1)\n    for i in range(n):\n        nproduce F\n"
    text = "from random import randint\nAxiom: " + " ".join(["A"] * 4000) + "\nderivation length: 1\nproduction:\n"
    ms = derive(parse_grammar(parse_lpy(text + rule, "k.lpy").data, "k.lpy"))
    kept = np.mean(ms.sym == ms.symbols.index("A"))
    assert len(ms) == 4000 and abs(kept - 0.5) < 0.04          # L-Py leaves the module as it is: no rule applied
    with pytest.raises(LpyError, match="may leave the module unchanged"):
        parse_lpy(text + rule + "A --> B\n", "k.lpy")           # there, the next rule would rewrite it


def test_a_numpy_vector_is_read_only_as_a_tropism_direction():
    text = "import numpy as np\nv = np.array([0, 1, 2])\nAxiom: F @Tp(v) @Ts(0.2) F\n"
    assert parse_lpy(text, "v.lpy").data["turtle"]["tropism"] == {"direction": [1.0, 2.0, 0.0], "strength": 0.2}
    with pytest.raises(LpyError, match="line 5: v .line 2. is a vector"):
        parse_lpy(text + "production:\nF --> F(v)\n", "v.lpy")
    with pytest.raises(LpyError, match="np.zeros"):
        parse_lpy("import numpy as np\nAxiom: F(np.zeros(3))\n", "v.lpy")


def test_python_between_the_rules_is_module_code():
    text = ("Axiom: A(1)\nderivation length: 3\nproduction:\n\ndef grow(x):\n    return x * 2\n\nk = 3\n"
            "A(x) --> F(grow(x)) A(x + k)\n\nendlsystem\n")
    ms = derive(parse_grammar(parse_lpy(text, "b.lpy").data, "b.lpy"))
    assert ms.to_text() == "F(2)F(8)F(14)A(10)"


def test_one_draw_tested_in_an_elif_chain_is_a_stochastic_rule():
    """``r = random()`` then ``if r < 0.2 ... elif r < 0.7 ... else`` is ABOP's stochastic
    rule: alternatives of probability 0.2, 0.5 and 0.3."""
    text = ("Axiom: " + " ".join(["A"] * 4000) + "\nderivation length: 1\nproduction:\nA :\n    r = random()\n"
            "    if r < 0.2:\n        produce B\n    elif 0.7 > r:\n        produce C\n    else:\n        produce D\n"
            "endlsystem\n")
    data = parse_lpy(text, "r.lpy").data
    assert [r["p"] for r in data["rules"]] == pytest.approx([0.2, 0.5, 0.3])
    ms = derive(parse_grammar(data, "r.lpy"))
    share = [np.mean(ms.sym == ms.symbols.index(c)) for c in "BCD"]
    assert share == pytest.approx([0.2, 0.5, 0.3], abs=0.04)


def test_functions_are_inlined_into_whitelisted_expressions():
    text = ("from math import *\nk = 2\ndef f(x):\n    y = x * k\n    if y > 3:\n        return sqrt(y)\n"
            "    return -y\ng = lambda a, b=1: a + b if a > 0 else b\nAxiom: F(f(1)) F(f(4)) F(g(2)) F(g(-1))\n")
    axiom = parse_lpy(text, "f.lpy").data["axiom"]
    values = []
    for arg in axiom.split("F(")[1:]:
        expr = compile_expr(arg.rsplit(")", 1)[0], {"k"})
        values.append(float(expr(EvalContext({"k": 2.0}, np.random.default_rng(0), 1))))
    assert values == [-2.0, pytest.approx(np.sqrt(8.0)), 3.0, 1.0]


def test_globals_follow_l_pys_hooks_and_its_module_after_module_rules():
    """globals.lpy by hand: P sets ``turned`` in step 3, so the G after it (to its right)
    turns in that step and the G's before it one step later; StartEach counts the steps
    (``F(step)``), EndEach halves ``length`` from step 3 on, End sets ``size`` from the
    count, and the interpretation draws ``E`` with it."""
    grammar = load_grammar(DATA / "globals.lpy")
    names = {s: read_lpy(DATA / "globals.lpy").names.get(s, s) for s in "EGP"}
    g = names["G"]
    three = derive(grammar, iterations=3)
    assert three.to_text() == f"E{g}F(1)[{g}]F(1)[{g}]+F(3)"
    assert three.globals == {"length": 0.5, "size": 30.0, "step": 3.0, "turned": 1.0}
    five = derive(grammar)
    assert five.to_text() == "E+F(4)F(1)[+F(4)]F(1)[+F(4)]+F(3)"      # the string stops changing; the hooks don't
    assert five.globals["size"] == 50.0 and five.globals["length"] == 0.125
    drawn = apply_interpretation(grammar, five)
    assert drawn.to_text().startswith("F(50)+F(4)")
    assert derive(grammar).to_text() == five.to_text()                # deterministic
    assert "print" not in str(read_lpy(DATA / "globals.lpy").data)    # print() is a no-op


def test_a_global_only_a_dropped_module_reads_is_dropped_with_what_sets_it():
    """A global read only where plantgen draws nothing (a label) and set from a random
    local is dropped: the local's draw is then used once, where the module is produced."""
    text = ("from random import uniform\nimport time\ntotal = 0\nclock = 0\ndef Start():\n    global total, clock\n"
            "    total = 0\n    clock = time.time()\nAxiom: A\nderivation length: 2\nproduction:\nA :\n"
            "    global total\n    x = uniform(1, 2)\n    total += x\n    produce F(x) A\n"
            "interpretation:\nA --> @L(str(total))\nendlsystem\n")
    model = parse_lpy(text, "d.lpy")
    assert "globals" not in model.data and "hooks" not in model.data
    assert any("import of time is ignored" in w for w in model.warnings)
    ms = derive(parse_grammar(model.data, "d.lpy"))
    assert [m[:2] for m in ms.to_text().split(")")[:2]] == ["F(", "F("]


def test_a_function_that_produces_is_run_in_the_rule_that_calls_it():
    ms = derive(load_grammar(DATA / "produce_function.lpy"))
    assert ms.to_text() == "F(1)F(1)[+F(1)]F(2)F(2)[+F(1)]F(3)F(3)B"      # by hand: produce ends the rule


def test_globals_with_a_new_left_context_and_a_predecessor_of_several_modules():
    """L-Py's global in a '<<' rule (a sequential step: each set runs where its module is
    rewritten) and in a rule of several modules (the run rewritten, then its set runs)."""
    source = ("n = 0\nAxiom: A A A\nderivation length: 1\nproduction:\nB(x) << A :\n    global n\n"
              "    n = n + 1\n    produce B(x + n)\nA :\n    global n\n    n = n + 10\n    produce B(n)\n")
    model = parse_lpy(source, "seq.lpy")
    assert [r["rule"] for r in model.data["rules"]] == ["B(x) << A -> B(x + (n + 1))", "A -> B((n + 10))"]
    ms = derive(parse_grammar(model.data, "seq.yaml"))
    assert ms.to_text() == "B(10)B(21)B(33)" and ms.globals == {"n": 12.0}
    source = ("n = 0\nAxiom: A B A B C\nderivation length: 1\nproduction:\nA B :\n    global n\n"
              "    n = n + 1\n    produce F(n)\nC --> F(n * 10)\n")
    ms = derive(parse_grammar(parse_lpy(source, "run.lpy").data, "run.yaml"))
    assert ms.to_text() == "F(1)F(2)F(20)" and ms.globals == {"n": 2.0}


def test_a_yaml_grammar_with_globals_is_validated_in_one_line(tmp_path):
    base = {"axiom": "A", "rules": ["A -> B"], "globals": {"c": 0}}
    for extra, words in [({"hooks": {"start_each": {"d": 1}}}, "'d' is not one of the grammar's globals"),
                         ({"hooks": {"later": {"c": 1}}}, "later"),
                         ({"rules": [{"rule": "A -> B", "set": {"c": "c +"}}]}, "set: c"),
                         ({"defines": {"c": 1}}, "is a define too"),
                         ({"interpretation": [{"rule": "A -> F", "set": {"c": 1}}]}, "cannot set globals")]:
        with pytest.raises(PlantgenError, match=words):
            parse_grammar({**base, **extra}, "g.yaml")


REFUSALS = [
    ("import os\nAxiom: F\n", ("line 1", "import of os")),
    ("from openalea.plantgl.all import *\nAxiom: F\n", ("line 1", "PlantGL")),
    ("n = 0\ndef StartEach():\n    global n\n    n = open('f')\nAxiom: F(n)\n", ("line 4", "open()", "file access")),
    ("def StartEach():\n    for i in range(3):\n        pass\nAxiom: F\n", ("line 2", "StartEach() does more")),
    ("m = 0\ndef PostDraw():\n    global m\n    m = 1\nAxiom: F(m)\n", ("line 2", "PostDraw() sets globals")),
    ("def End(lstring):\n    print(1)\n    return lstring\nAxiom: F\n", ("line 3", "End() reads the L-string")),
    ("m = 0\nAxiom: A\nproduction:\nA :\n    global m\n    if m < 1:\n        m = 1\n    else:\n        produce F(m)\n",
     ("line 6", "sets a global but produces nothing")),
    ("m = 0\ndef f(x):\n    global m\n    m = x\n    return x\nAxiom: A\nproduction:\nA --> F(f(1))\n",
     ("line 4", "function f() sets a global")),
    ("m = 0\nAxiom: A\nproduction:\nA :\n    global m\n    r = random()\n    m = r\n    produce F(r) B(m)\n",
     ("line", "random draw")),
    ("m = [1]\nAxiom: A\nproduction:\nA :\n    global m\n    m = 2\n    produce F(m)\n",
     ("line 5", "global m is set", "a list")),
    ("Axiom: A\nproduction:\nA :\n    f = open('/etc/passwd')\n    produce F\n", ("line 4", "open()", "file access")),
    ("Axiom: A\nproduction:\nA :\n    while True:\n        nproduce F\n    produce A\n", ("line 4", "while loop")),
    ("Axiom: A\nproduction:\nA --> @g(Cylinder(1))\n", ("line 3", "PlantGL")),
    ("Axiom: A\nproduction:\nA :\n    if getIterationNb() > 2:\n        produce F\n", ("line 4", "getIterationNb")),
    ("def StartEach():\n    useGroup(1)\nAxiom: F\n", ("line 2", "useGroup")),
    ("Axiom: A(1)\nproduction:\nA(x) :\n    r = random()\n    if r < 0.5:\n        produce F(r)\n",
     ("line 6", "'r' holds a random draw")),
    ("Axiom: A(1)\nproduction:\nA(x) :\n    for i in range(randint(1, x)):\n        nproduce F\n    produce A(x)\n",
     ("line 4", "range() of a random draw")),
    ("Axiom: A\nproduction:\nA >> B --> F\n", ("line 3", "'>>'")),
    ("Axiom: A\nproduction:\n[B] < A --> F\n", ("line 3", "brackets in a predecessor or a left context")),
    ("Axiom: A\nproduction:\nA [B] --> F\n", ("line 3", "brackets in a predecessor")),
    ("x = [1, 2]\nAxiom: A\nproduction:\nA --> F(x[random()])\n", ("line 4", "indexed by a random draw")),
    ("x = [1, 2]\nAxiom: F(x)\n", ("line 2", "x (line 1)", "a list")),
    ("def StartInterpretation():\n    nproduce -(90)\nAxiom: F\n", ("line 2", "StartInterpretation() produces")),
    ("def g(x):\n    if x > 1:\n        return\n    produce F\nAxiom: A(1)\nproduction:\nA(x) :\n    g(x)\n",
     ("line 1", "g() returns from inside a block")),
    ("def g(x):\n    nproduce F\nAxiom: A(1)\nproduction:\nA(x) :\n    g(x, 2)\n    produce A\n",
     ("line 1", "g() takes 1 plain parameters")),
    ("produce F\nAxiom: A\n", ("line 1", "produce outside a rule and outside a function")),
    ("production:\nA --> F\n", ("no 'Axiom:'",)),
    ("Axiom: A\nproduction:\nA :\n    if x >\n        produce F\n", ("line 4", "syntax error")),
]


@pytest.mark.parametrize("text, words", REFUSALS)
def test_what_plantgen_cannot_translate_is_refused_in_one_line_naming_it(tmp_path, text, words):
    path = tmp_path / "m.lpy"
    path.write_text(text)
    with pytest.raises(LpyError) as info:
        read_lpy(path)
    assert "\n" not in str(info.value) and str(info.value).startswith(str(path))
    for word in words:
        assert word in str(info.value)
    code, _, err = run_cli("grow", path, "-o", tmp_path / "m.npz")
    assert code == 2 and err.startswith("plantgen: error: ") and err.count("\n") == 1
    assert not (tmp_path / "m.npz").exists()


HOSTILE = {
    "loop.lpy": ("Axiom: A\nproduction:\nA :\n    for i in range(10**9):\n        nproduce F\n    produce A\n",
                 ("line 4", f"{MAX_LOOP_ITERATIONS:,} iterations")),
    "nested.lpy": ("Axiom: A\nproduction:\nA :\n    for i in range(1000):\n        for j in range(1000):\n"
                   "            nproduce F\n    produce A\n", ("line 5", "iterations")),
    "recursion.lpy": ("def f(x):\n    if x <= 0:\n        return 0\n    return f(x - 1) + 1\nAxiom: F(f(10**6))\n",
                      ("recursive function", "f()")),
    "doubling.lpy": ("def d(x):\n    return x + x\nAxiom: A(1)\nproduction:\nA(x) --> F(" + "d(" * 30 + "x" + ")" * 30
                     + ")\n", ("line 2", "2000 characters")),
    "power.lpy": ("x = 10**10**10\nAxiom: F(x)\n", ("line 1", "x")),
    "globals.lpy": ("def Start():\n    global " + ", ".join(f"g{i}" for i in range(15_000)) + "\n"
                    + "".join(f"    g{i} = 1\n" for i in range(3_000)) + "Axiom: F\n",
                    ("3,000 globals", "limit of 64")),
    "producer.lpy": ("def g(x):\n    nproduce F\n    g(x)\nAxiom: A\nproduction:\nA :\n    g(1)\n    produce A\n",
                     ("line 1", "recursive function", "g()")),
    "digits.lpy": ("x = " + "9" * 100_000 + "\nAxiom: F(x)\n", ("line 1",)),
    "sum.lpy": ("x = " + "+".join(["1"] * 60_000) + "\nAxiom: F(x)\n", ("line 1",)),
    "parens.lpy": ("Axiom: F(" + "(" * 5000 + "1" + ")" * 5000 + ")\n", ("line 1",)),
    "modules.lpy": ("Axiom: A\nderivation length: 60\nproduction:\nA --> A A\n", ("modules",)),
    "sequential.lpy": ("Axiom: A\nderivation length: 60\nproduction:\nB(x) B(y) << B(z) :\n    if z > 10:\n"
                       "        produce B(x + y)\nA --> A A B(1)\n", ("derive_work",)),
    "setters.lpy": ("c = 0\nAxiom: " + "A " * 9_000 + "\nderivation length: 5\nproduction:\nA :\n    global c\n"
                    "    c = c + 1\n    produce A\nB --> F(c)\n", ("derive_work", "setting globals")),
}


def test_hostile_lpy_files_are_refused_fast_in_bounded_memory(tmp_path):
    cases = []
    for name, (text, _) in HOSTILE.items():
        (tmp_path / name).write_text(text)
        cases.append(["grow", tmp_path / name, "-o", tmp_path / f"{name}.npz"])
    for result, (name, (_, words)) in zip(run_cases(tmp_path, cases), HOSTILE.items(), strict=True):
        assert_refused(result, words, outputs=[tmp_path / f"{name}.npz"],
                       seconds=15.0 if name in ("modules.lpy", "sequential.lpy") else 2.0)


PIECES = list("()[]{}:<>-*/%+&^|!_;,.~@?$#'\"=\n\t AxFf0123456789") + [
    "-->", "produce ", "nproduce ", "if ", "else:", "for i in range(", "def ", "lambda ", "\n    ", "Axiom:"]
SOURCES = [p.read_text() for p in sorted(DATA.glob("*.lpy"))]


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(source=st.sampled_from(SOURCES), edits=st.lists(
    st.tuples(st.floats(0, 1), st.sampled_from(["delete", "insert"]), st.sampled_from(PIECES)), min_size=1, max_size=6))
def test_mutated_lpy_files_translate_or_are_refused_in_one_line(source, edits):
    text = source
    for where, op, piece in edits:
        i = int(where * len(text))
        text = text[:i] + text[i + 1:] if op == "delete" else text[:i] + piece + text[i:]
    try:
        model = parse_lpy(text, "m.lpy")
        derive(parse_grammar(model.data, "m.lpy"), iterations=3)
    except PlantgenError as exc:
        assert "\n" not in str(exc)
