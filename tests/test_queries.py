"""Query modules ?P ?H ?U ?L (Synthetic topiary, L-Py): after each step the turtle walks the
string and writes its own position and frame into them; the next step's rules read them."""

from __future__ import annotations

import numpy as np
import pytest

from plantgen.errors import PlantgenError
from plantgen.lsystem import derive, interpret, parse_grammar
from plantgen.lsystem import queries as queries_module
from plantgen.lsystem.grammar import GrammarError

SPIRAL = {
    "name": "spiral", "iterations": 6, "seed": 3,
    "axiom": "F(1) ?P(0, 0, 0) A(1)",
    # R records what the rule read in ?P: the position after the previous step
    "rules": ["?P(x, y, z) < A(n) -> +(uniform(10, 50)) &(20) F(1) R(x, y, z) ?H(0, 0, 0) ?U(0, 0, 0) "
              "?L(0, 0, 0) ?P(0, 0, 0) A(n + 1)"],
}


def _grammar(**changes):
    return parse_grammar({**SPIRAL, **changes}, "spiral.yaml")


def _modules(ms, name):
    return ms.params[ms.sym == ms.symbols.index(name), :3]


def test_p_holds_the_turtles_own_position_at_the_module():
    g = _grammar()
    ms = derive(g)
    skel = interpret(ms, g.turtle)
    # each ?P follows an F: its position is that segment's end, as the turtle drew it
    np.testing.assert_allclose(_modules(ms, "?P"), skel.end, atol=1e-12)
    heading = skel.end - skel.start
    heading /= np.linalg.norm(heading, axis=1, keepdims=True)
    h, u, left = _modules(ms, "?H"), _modules(ms, "?U"), _modules(ms, "?L")
    np.testing.assert_allclose(h, heading[1:], atol=1e-12)
    frame = np.stack([h, left, u], axis=1)                 # rows H, L, U: orthonormal, right-handed (U = H x L)
    np.testing.assert_allclose(frame @ frame.transpose(0, 2, 1), np.broadcast_to(np.eye(3), frame.shape), atol=1e-12)
    np.testing.assert_allclose(np.cross(h, left), u, atol=1e-12)


def test_rules_read_the_position_of_the_previous_steps_interpretation():
    g = _grammar()
    for k in range(1, g.iterations + 1):
        before, after = derive(g, iterations=k - 1), derive(g, iterations=k)
        last_p = _modules(before, "?P")[-1]                 # the ?P the rule's left context matched
        tip = interpret(before, g.turtle).end[-1]           # where the turtle was there, drawn independently
        np.testing.assert_allclose(_modules(after, "R")[-1], last_p, atol=1e-12)
        np.testing.assert_allclose(last_p, tip, atol=1e-12)


def test_a_rule_can_prune_by_position():
    """?P(x, y, z) : y > 3 -> %: the apex stops once above y = 3 (the segment that crossed it stays)."""
    g = parse_grammar({"name": "t", "iterations": 10, "axiom": "?P(0,0,0) A",
                       "rules": ["?P(x, y, z) : y > 3 -> %", "A -> F(1) ?P(0,0,0) A"]}, "t.yaml")
    skel = interpret(derive(g), g.turtle)
    assert skel.end[:, 1].max() == pytest.approx(4.0)    # grew to y = 4 (the query saw 4 > 3), then was cut


def test_a_grammar_without_query_modules_never_walks_the_turtle(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("the query pass ran for a grammar without query modules")

    monkeypatch.setattr(queries_module, "interpret_plant", refuse)
    g = parse_grammar({"name": "t", "iterations": 4, "axiom": "A", "rules": ["A -> F[+A]A"]}, "t.yaml")
    assert len(derive(g)) > 10


def test_communication_without_an_environment_is_one_line():
    g = parse_grammar({"name": "t", "iterations": 1, "axiom": "F ?E(0)"}, "t.yaml")
    with pytest.raises(PlantgenError, match="need an environment") as info:
        derive(g)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("axiom, match", [("?X(1)", "unknown query module"), ("?P(1, 2)", "wrong parameter count"),
                                          ("?E(1) ?E(1, 2)", "wrong parameter count")])
def test_bad_query_modules_are_refused(axiom, match):
    with pytest.raises(GrammarError, match=match):
        parse_grammar({"name": "t", "axiom": axiom}, "t.yaml")
