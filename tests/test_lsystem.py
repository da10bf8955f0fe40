"""Rule kinds, the classic ABOP trees, turtle semantics, determinism and the size limit."""

import tracemalloc

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plantgen.lsystem import DEFAULT_MAX_MODULES, DerivationLimit, derive, interpret, parse_grammar
from plantgen.lsystem.derive import context_neighbours
from plantgen.lsystem.grammar import GrammarError


def grammar(**kw):
    kw.setdefault("iterations", 1)
    return parse_grammar(kw, "test.yaml")


def text(g, **kw):
    return derive(g, **kw).to_text()


def grow(g, **kw):
    ms = derive(g, **kw)
    skel = interpret(ms, g.turtle, g.materials)
    skel.validate()
    return skel


# ---------------------------------------------------------------- rule kinds
def test_plain_rule_and_both_arrows():
    g = grammar(axiom="A", rules=["A -> AB", "B → A"], iterations=4)
    assert text(g) == "ABAABABA"          # the Fibonacci word of ABOP section 1.2


def test_parametric_rules_and_conditions():
    g = grammar(axiom="A(0)", rules=["A(x) : x < 3 -> F(x) A(x + 1)", "A(x) : x >= 3 -> B(x * 10)"],
                iterations=5)
    assert text(g) == "F(0)F(1)F(2)B(30)"


def test_first_matching_rule_wins_and_unmatched_modules_stay():
    g = grammar(axiom="A(1)A(5)C", rules=["A(x) : x > 2 -> B", "A(x) -> D(x)"])
    assert text(g) == "D(1)BC"


def test_constants_are_visible_and_may_use_each_other():
    g = grammar(axiom="A(1)", defines={"k": 2, "k2": "k * 3"}, rules=["A(x) -> A(x * k2)"], iterations=2)
    assert text(g) == "A(36)"


def test_stochastic_frequencies_follow_probabilities():
    g = grammar(axiom="S(12)", iterations=14, seed=3,
                rules=["S(n) : n > 0 -> S(n - 1) S(n - 1)", "S(n) : n == 0 -> T",
                       {"rule": "T -> B", "p": 0.3}, {"rule": "T -> C", "p": 0.7}])
    s = text(g)
    n_b, n_c = s.count("B"), s.count("C")
    assert n_b + n_c == 4096
    sigma = np.sqrt(0.3 * 0.7 / 4096)
    assert abs(n_b / 4096 - 0.3) < 5 * sigma


def test_stochastic_inline_probability_form():
    g = grammar(axiom="TTTTTTTTTTTTTTTTTTTT", rules=["T ->(0.5) B", "T -> (0.5) C"], seed=1)
    s = text(g)
    assert set(s) == {"B", "C"} and len(s) == 20


def test_seed_determines_the_string():
    g = grammar(axiom="TTTTTTTTTTTTTTTTTTTTTTTTTTTTTT", rules=[{"rule": "T -> B", "p": 0.5},
                                                              {"rule": "T -> C", "p": 0.5}])
    assert text(g, seed=1) == text(g, seed=1)
    assert text(g, seed=1) != text(g, seed=2)


def test_left_context_propagates_a_signal():
    g = grammar(axiom="baaaa", rules=["b < a -> b", "b -> a"])
    assert [text(g, iterations=k) for k in range(1, 5)] == ["abaaa", "aabaa", "aaaba", "aaaab"]


def test_right_context():
    g = grammar(axiom="aaaab", rules=["a > b -> b", "b -> a"], iterations=2)
    assert text(g) == "aabaa"


def test_context_ignore_list_and_brackets():
    # '+' is ignored, so b is the left context of a across it; inside a branch the left
    # context is the module the branch grows from; after a branch it is skipped.
    g = grammar(axiom="b[a]+a", ignore="+", rules=["b < a -> c"])
    assert text(g) == "b[c]+c"
    g = grammar(axiom="b+a[a]a", ignore="+", rules=["b < a -> c"])
    assert text(g) == "b+c[a]a"                       # the branch grows from a, not b
    g = grammar(axiom="b+a", rules=["b < a -> c"])     # '+' not ignored: no match
    assert text(g) == "b+a"
    g = grammar(axiom="a[b]c", rules=["a > c -> x"])   # right context skips the branch
    assert text(g) == "x[b]c"
    g = grammar(axiom="a[b]c", rules=["b > c -> x"])   # ']' ends the right context
    assert text(g) == "a[b]c"


@pytest.mark.parametrize("axiom, rule, ignore, expected", [
    ("a[b]c", "a > [b]c -> x", "", "x[b]c"),
    ("a[b][c]d", "a > [b][c]d -> x", "", "x[b][c]d"),
    ("a[be]c", "a > [b]c -> x", "", "x[be]c"),             # ']' skips the rest of the branch
    ("a[b[e]f]c", "a > [b]c -> x", "", "x[b[e]f]c"),       # ... nested branches included
    ("a[be]c", "a > [b -> x", "", "x[be]c"),               # a branch that begins with b
    ("a[+b]+c", "a > [b]c -> x", "+", "x[+b]+c"),          # ignored modules are skipped
    ("a[+b]c", "a > [b]c -> x", "", "a[+b]c"),             # ... only those
    ("a[e][b]c", "a > [b]c -> x", "", "a[e][b]c"),         # '[' meets the first branch only
    ("a[b]e[c]d", "a > [b]e d -> x", "", "x[b]e[c]d"),     # an unnamed branch is skipped
    ("a[b]", "a > [b]c -> x", "", "a[b]"),
    ("[a]b", "a > ]b -> x", "", "[x]b"),                   # ']' steps out of the branch
    ("[ae]b", "a > ]b -> x", "", "[xe]b"),
])
def test_brackets_in_a_right_context(axiom, rule, ignore, expected):
    # hand-derived from L-Py's matching of a right context along the branching structure
    assert text(grammar(axiom=axiom, rules=[rule], ignore=ignore)) == expected


def test_bracketed_right_context_binds_parameters():
    g = grammar(axiom="I(1)[I(2)]I(3)", rules=["I(p) > [I(k)] I(q) -> I(p + k * 10 + q * 100)"])
    assert text(g) == "I(321)[I(2)]I(3)"


@pytest.mark.parametrize("axiom, rules, expected", [
    ("F(1)+F(2)F(3)+F(4)", ["F(x) + F(y) -> G(x + y)"], "G(3)G(7)"),
    ("aaa", ["a a -> b"], "ba"),                              # matches taken from the left
    ("aaaa", ["a a -> b"], "bb"),
    ("ab", ["b -> c", "a b -> d"], "ac"),                     # an earlier rule took b
    ("ab", ["a b -> d", "b -> c"], "d"),
    ("xaby", ["x < a b > y -> c"], "xcy"),                    # contexts around the whole run
    ("a[e]b", ["a b -> c"], "c"),                             # a branch inside the run goes too
    ("a+b", ["a b -> c"], "a+b"),
    ("F(1)F(5)", ["F(x) F(y) : y > x -> F(y) F(x)"], "F(5)F(1)"),
])
def test_predecessor_of_several_modules(axiom, rules, expected):
    assert text(grammar(axiom=axiom, rules=rules)) == expected


def test_predecessor_of_several_modules_skips_ignored_ones():
    assert text(grammar(axiom="a+b", rules=["a b -> c"], ignore="+")) == "c"


def test_new_left_context_reads_the_string_being_written():
    # a sequential step: each K sees the two K written just before it (Fibonacci in one step)
    g = grammar(axiom="K(1)K(1)K(1)K(1)K(1)K(1)", rules=["K(x) K(y) << K(z) : z == 1 -> K(x + y)"])
    assert text(g) == "K(1)K(1)K(2)K(3)K(5)K(8)"
    # against the old string (parallel), every K sees K(1)K(1)
    g = grammar(axiom="K(1)K(1)K(1)K(1)", rules=["K(x) K(y) < K(z) : z == 1 -> K(x + y)"])
    assert text(g) == "K(1)K(1)K(2)K(2)"


def test_new_left_context_follows_the_branching_structure():
    # a branch sees the module it grows from in the new string; an ignored module is skipped
    g = grammar(axiom="A[B]+B", ignore="+", rules=["A -> C", "C << B -> D"])
    assert text(g) == "C[D]+D"
    g = grammar(axiom="A[B]B", rules=["A -> C", "B << B -> D"])
    assert text(g) == "C[B]B"
    g = grammar(axiom="BBB", rules=["B << B -> D(1)", "D(x) << B -> D(x + 1)"], iterations=1)
    assert text(g) == "BD(1)D(2)"
    # '<' still reads the string before the step, '<<' the one being written (L-Py's order)
    assert text(grammar(axiom="XBC", rules=["B -> A", "B < A << C -> D"])) == "XAD"
    assert text(grammar(axiom="XBC", rules=["B -> A", "A < A << C -> D"])) == "XAC"


def test_globals_set_in_a_sequential_step_are_read_by_the_modules_after():
    # a '<<' step is sequential already: each rule's set runs right after its module is
    # rewritten, so the next module reads the new value as well as the new string
    g = grammar(axiom="AAA", globals={"n": 0}, rules=[
        {"rule": "B(x) << A -> B(x + n)", "set": {"n": "n + 1"}},
        {"rule": "A -> B(n)", "set": {"n": "n + 10"}}])
    ms = derive(g)
    assert ms.to_text() == "B(0)B(10)B(21)" and ms.globals == {"n": 12.0}
    # the same rules without '<<' (a step cut at each setter) give the same values
    g = grammar(axiom="AAA", globals={"n": 0}, rules=[{"rule": "A -> B(n)", "set": {"n": "n + 1"}}])
    assert text(g) == "B(0)B(1)B(2)"


def test_a_predecessor_of_several_modules_that_sets_globals():
    # the whole run is rewritten before its set runs; the modules after it read the new value
    g = grammar(axiom="ABABC", globals={"n": 0}, rules=[
        {"rule": "A B -> F(n)", "set": {"n": "n + 1"}}, "C -> F(n * 10)"])
    ms = derive(g)
    assert ms.to_text() == "F(0)F(1)F(20)" and ms.globals == {"n": 2.0}
    # an erased module after a setter's run is matched again with the new value
    g = grammar(axiom="ABAA", globals={"n": 0}, rules=[
        {"rule": "A B -> F(n)", "set": {"n": "n + 1"}}, "A : n > 0 ->"])
    assert text(g) == "F(0)"


def _left_by_walking(seq: str, i: int, ignore: str) -> int:
    """ABOP's left context neighbour of seq[i], by walking back: ignored modules and whole
    branches are skipped, an opening bracket is stepped over to the module it grows from."""
    p = i - 1
    while p >= 0:
        if seq[p] == "]":
            depth = 1
            while depth:
                p -= 1
                depth += (seq[p] == "]") - (seq[p] == "[")
        elif seq[p] != "[" and seq[p] not in ignore:
            return p
        p -= 1
    return -1


@settings(max_examples=300, deadline=None)
@given(st.lists(st.sampled_from("AB+[]"), max_size=40), st.sampled_from(["", "+", "+B"]))
def test_left_context_neighbours_follow_the_branching_structure(chars, ignore):
    seq, depth = [], 0
    for c in chars:
        if c != "]" or depth:
            depth += (c == "[") - (c == "]")
            seq.append(c)
    seq = "".join(seq) + "]" * depth
    symbols = ("A", "B", "+", "[", "]")
    left, _ = context_neighbours(np.array([symbols.index(c) for c in seq], dtype=np.int32), symbols,
                                  frozenset(ignore))
    assert list(left) == [-1 if c in "[]" else _left_by_walking(seq, i, ignore) for i, c in enumerate(seq)]


def test_context_parameters_are_visible():
    g = grammar(axiom="A(2)B(3)C(5)", rules=["A(x) < B(y) > C(z) -> B(x * 100 + y * 10 + z)"])
    assert text(g) == "A(2)B(235)C(5)"


def test_predefined_symbols_can_be_rewritten():
    g = grammar(axiom="!(1)F(1)", rules=["F(l) -> F(l * 2)", "!(w) -> !(w * 0.5)"], iterations=3,
                turtle={"step": 1})
    skel = grow(g)
    assert np.linalg.norm(skel.end - skel.start, axis=1) == pytest.approx([8.0])
    assert skel.r_end == pytest.approx([0.125])


# ---------------------------------------------------------------- classic ABOP trees
MONOPODIAL = dict(  # ABOP figure 2.6 (a)
    defines={"r1": 0.9, "r2": 0.6, "a0": 45, "a2": 45, "d": 137.5, "wr": 0.707},
    axiom="A(1, 10)",
    rules=["A(l,w) -> !(w) F(l) [&(a0) B(l*r2, w*wr)] /(d) A(l*r1, w*wr)",
           "B(l,w) -> !(w) F(l) [-(a2) $ C(l*r2, w*wr)] C(l*r1, w*wr)",
           "C(l,w) -> !(w) F(l) [+(a2) $ B(l*r2, w*wr)] B(l*r1, w*wr)"])
SYMPODIAL = dict(  # ABOP figure 2.7 (a)
    defines={"r1": 0.9, "r2": 0.7, "a1": 10, "a2": 60, "wr": 0.707},
    axiom="A(1, 10)",
    rules=["A(l,w) -> !(w) F(l) [&(a1) B(l*r1, w*wr)] /(180) [&(a2) B(l*r2, w*wr)]",
           "B(l,w) -> !(w) F(l) [+(a1) $ B(l*r1, w*wr)] [-(a2) $ B(l*r2, w*wr)]"])
TERNARY = dict(  # ABOP figure 2.8 (a): y-up, tropism towards -y
    defines={"d1": 94.74, "d2": 132.63, "a": 18.95, "lr": 1.109, "vr": 1.732},
    axiom="!(1) F(200) /(45) A",
    rules=["A -> !(vr) F(50) [&(a) F(50) A] /(d1) [&(a) F(50) A] /(d2) [&(a) F(50) A]",
           "F(l) -> F(l*lr)", "!(w) -> !(w*vr)"],
    turtle={"tropism": {"direction": [0, -1, 0], "strength": 0.22}})


def trunk(skel):
    """Segments of the main axis: from the root, follow the continuing child."""
    chain = [0]
    while True:
        kids = np.flatnonzero((skel.parent == chain[-1]) & skel.continues)
        if kids.size == 0:
            return np.array(chain)
        assert kids.size == 1
        chain.append(int(kids[0]))


@pytest.mark.parametrize("n", [1, 4, 8, 10])
def test_monopodial_counts_and_trunk(n):
    g = grammar(**MONOPODIAL, iterations=n)
    skel = grow(g)
    assert len(skel) == 2 ** n - 1                      # every apex makes one F and two apices
    t = trunk(skel)
    assert len(t) == n
    lengths = np.linalg.norm(skel.end[t] - skel.start[t], axis=1)
    np.testing.assert_allclose(lengths, 0.9 ** np.arange(n))
    # the trunk is straight and vertical: its top is at the geometric sum
    assert skel.end[t[-1]] == pytest.approx([0, (1 - 0.9 ** n) / (1 - 0.9), 0], abs=1e-9)
    # radii taper by wr per internode; a continuing segment starts at its parent's end radius
    np.testing.assert_allclose(skel.r_end[t], 10 * 0.707 ** np.arange(n))
    np.testing.assert_allclose(skel.r_start[t[1:]], skel.r_end[t[:-1]])
    assert len(skel.tips) == 2 ** (n - 1)


@pytest.mark.parametrize("n", [1, 5, 9])
def test_sympodial_counts_and_trunk(n):
    skel = grow(grammar(**SYMPODIAL, iterations=n))
    assert len(skel) == 2 ** n - 1
    assert len(trunk(skel)) == 1                        # the trunk ends in two side branches
    assert skel.end[0] == pytest.approx([0, 1, 0])
    assert not skel.continues.any()                     # every later segment is a side branch


@pytest.mark.parametrize("n", [1, 3, 6])
def test_ternary_counts_trunk_and_tropism(n):
    skel = grow(grammar(**TERNARY, iterations=n))
    assert len(skel) == 1 + 2 * (3 ** n - 1)            # A makes four F and three A
    # F(l) -> F(l*lr): the first internode has grown n times
    assert np.linalg.norm(skel.end[0] - skel.start[0]) == pytest.approx(200 * 1.109 ** n)
    assert skel.r_end[0] == pytest.approx(1.732 ** n)
    if n < 2:
        return   # tropism acts after each F, so a single step has nothing to bend yet
    # tropism towards -y bends the tips down relative to no tropism
    flat = dict(TERNARY, turtle={})
    free = grow(grammar(**flat, iterations=n))
    assert skel.end[skel.tips, 1].mean() < free.end[free.tips, 1].mean()


# ---------------------------------------------------------------- turtle semantics
def seg_dirs(skel):
    d = skel.end - skel.start
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_turtle_starts_up_and_turns_by_the_angle():
    skel = grow(grammar(axiom="F+F-F&F^F\\(90)+F", iterations=0, turtle={"angle": 90, "step": 2}))
    d = seg_dirs(skel)
    np.testing.assert_allclose(d[0], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(d[1], [-1, 0, 0], atol=1e-12)    # '+' turns left, towards L = -x
    np.testing.assert_allclose(d[2], [0, 1, 0], atol=1e-12)     # '-' turns back
    np.testing.assert_allclose(d[3], [0, 0, -1], atol=1e-12)    # '&' pitches down, away from U = +z
    np.testing.assert_allclose(d[4], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(d[5], [0, 0, 1], atol=1e-12)     # "\\" rolls L towards U = +z
    assert np.linalg.norm(skel.end[0] - skel.start[0]) == pytest.approx(2)


def test_turn_around_move_and_brackets():
    skel = grow(grammar(axiom="F[+F]F|F f F", iterations=0, turtle={"angle": 30}))
    assert len(skel) == 5
    assert list(skel.parent) == [-1, 0, 0, 2, -1]
    assert list(skel.continues) == [False, False, True, True, False]
    np.testing.assert_allclose(seg_dirs(skel)[3], [0, -1, 0], atol=1e-12)   # '|' reverses H
    np.testing.assert_allclose(skel.start[4], skel.end[3] + [0, -1, 0])   # 'f' moved, no segment


def test_width_default_factor_and_material():
    g = grammar(axiom="!(2)F!F;F;(0)F", iterations=0, materials=["bark", "leaf"],
                turtle={"width_factor": 0.5})
    skel = grow(g)
    np.testing.assert_allclose(skel.r_end, [2, 1, 1, 1])
    np.testing.assert_allclose(skel.r_start, [2, 2, 1, 1])     # continuing: parent's end radius
    assert list(skel.material) == [0, 0, 1, 0]
    assert skel.material_names == ("bark", "leaf")


def test_two_argument_F_tapers_roots_and_side_branches():
    skel = grow(grammar(axiom="!(0.3) F(1, 0.2) [+ !(0.1) F(1, 0)] F(1)", iterations=0))
    np.testing.assert_allclose(skel.r_start, [0.3, 0.1, 0.2])
    np.testing.assert_allclose(skel.r_end, [0.2, 0.0, 0.2])


def test_dollar_rolls_left_to_horizontal():
    skel = grow(grammar(axiom="&(30)/(50)$+(90)F", iterations=0))
    # after $, L is horizontal, so a 90° turn about U gives a horizontal heading
    assert abs(seg_dirs(skel)[0, 1]) < 1e-12


def test_tropism_bends_by_e_times_sin():
    e = 0.1
    skel = grow(grammar(axiom="+(90)FF", iterations=0,
                        turtle={"tropism": {"direction": [0, -1, 0], "strength": e}}))
    d = seg_dirs(skel)
    # H ⟂ T, so |H × T| = 1 and the heading turns by e radians towards -y
    assert np.arccos(np.clip(d[0] @ d[1], -1, 1)) == pytest.approx(e)
    assert d[1, 1] < 0


# ---------------------------------------------------------------- invariants and limits
STOCHASTIC_BUSH = dict(
    axiom="A(1)", iterations=6, turtle={"angle": 25, "radius": 0.1},
    rules=[{"rule": "A(l) -> !F(l)[+(uniform(10, 40))A(l*0.8)][-A(l*0.7)]/(137)A(l*0.9)", "p": 0.6},
           {"rule": "A(l) -> F(l)&A(l*0.9)", "p": 0.4}])


@settings(max_examples=25, deadline=None)
@given(st.integers(min_value=0, max_value=2**31 - 1))
def test_skeleton_invariants_hold_for_any_seed(seed):
    skel = grow(grammar(**STOCHASTIC_BUSH), seed=seed)
    has_p = skel.parent >= 0
    np.testing.assert_allclose(skel.start[has_p], skel.end[skel.parent[has_p]], atol=1e-12)
    assert (skel.r_start >= 0).all() and (skel.r_end >= 0).all()
    assert np.isfinite(skel.start).all() and np.isfinite(skel.end).all()


def test_seed_changes_a_stochastic_plant():
    g = grammar(**STOCHASTIC_BUSH)
    a, b = grow(g, seed=1), grow(g, seed=1)
    np.testing.assert_array_equal(a.end, b.end)
    c = grow(g, seed=2)
    assert len(a) != len(c) or not np.array_equal(a.end, c.end)


def test_size_limit_stops_promptly_with_bounded_memory():
    assert DEFAULT_MAX_MODULES >= 1_000_000
    g = grammar(axiom="A", rules=["A -> AAAA"], iterations=40)
    tracemalloc.start()
    with pytest.raises(DerivationLimit, match="limit of 100,000"):
        derive(g, max_modules=100_000)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 20e6   # never allocated the string past the limit


def test_grammar_max_modules_key_is_used():
    g = grammar(axiom="A", rules=["A -> AA"], iterations=12, max_modules=1000)
    with pytest.raises(DerivationLimit):
        derive(g)


@pytest.mark.parametrize("data, message", [
    (dict(axiom="A(1)", rules=["A(x,y) -> B"]), "wrong parameter count"),
    (dict(axiom="F(1,2,3)"), "wrong parameter count"),
    (dict(axiom="A", rules=["A -> [B"]), "unbalanced"),
    (dict(axiom="A]"), "unbalanced"),
    (dict(axiom="A(q)"), "undefined name 'q'"),
    (dict(axiom="A", rules=[{"rule": "A -> B", "p": 0.5}, {"rule": "A -> C", "p": 0.4}]), "add up to 0.9"),
    (dict(axiom="A", rules=["A -> B", "A -> C"]), "repeats the predecessor"),
    (dict(axiom="A", rules=["A >> B -> C"]), "new right context"),
        (dict(axiom="A", rules=["[B] < A -> C"]), "right context only"),
        (dict(axiom="A", rules=["A > [(x) B -> C"]), "takes no parameters"),
        (dict(axiom="A", rules=["A < << B -> C"]), "empty new left context"),
    (dict(axiom="A", colour="red"), "unknown key"),
    (dict(axiom="A", turtle={"size": 1}), "unknown key"),
    (dict(rules=[]), "no 'axiom'"),
    (dict(axiom="A", rules=["A(x) : -> B"]), "empty condition"),
])
def test_bad_grammars_name_the_problem(data, message):
    with pytest.raises(GrammarError, match=message):
        parse_grammar(data, "bad.yaml")


# ---------------------------------------------------------------- fuzzing: errors, never crashes
_ALPHABET = st.sampled_from(list("AFBf+-&^\\/|[]!$;(),:<>0123456789.*lxy ") + ["->", "l*2", "x>1"])


@settings(max_examples=300, deadline=None)
@given(axiom=st.lists(_ALPHABET, max_size=12).map("".join),
       rules=st.lists(st.lists(_ALPHABET, max_size=14).map("".join), max_size=3))
def test_random_grammars_grow_or_fail_with_a_plantgen_error(axiom, rules):
    from plantgen.errors import PlantgenError
    try:
        g = parse_grammar({"axiom": axiom, "rules": rules, "iterations": 3}, "fuzz.yaml")
        ms = derive(g, max_modules=20_000)
        interpret(ms, g.turtle, g.materials, g.path).validate()
    except PlantgenError as exc:
        assert str(exc).startswith("fuzz.yaml") and "\n" not in str(exc)
