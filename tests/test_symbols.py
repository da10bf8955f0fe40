"""One symbol table (plantgen/lsystem/symbols.py): the grammar reference's table of turtle
symbols is the one it renders (generated when the documentation is built) and agrees with
what the parser accepts, and every symbol it declares is acted on (drawn by the turtle, cut
by the derivation, or skipped with a warning)."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest
from _docs import page, table_after

from plantgen.errors import PlantgenError
from plantgen.lsystem import derive, parse_grammar
from plantgen.lsystem.grammar import TURTLE_ARITY, GrammarError
from plantgen.lsystem.symbols import (
    DERIVATION_ACTIONS,
    SYMBOLS,
    UNSUPPORTED,
    Action,
    markdown_table,
    unsupported_warning,
)
from plantgen.lsystem.turtle import HANDLERS, interpret_plant

DRAWN = [s for s in SYMBOLS if s.action in HANDLERS]


def reference_table() -> list[str]:
    """The lines of the table of turtle symbols in the grammar reference
    (docs/reference/grammar.md, section "Turtle symbols"), as the built page shows it."""
    text = page("reference/grammar.md")
    return table_after(text[text.index("## Turtle symbols"):], "| module | meaning |")


def reference_arities() -> dict[str, tuple[int, ...] | None]:
    """Each symbol of the reference's table with the parameter counts its forms show (``F``,
    ``F(l)``, ``F(l, w)``: 0, 1, 2); None for "any parameters"."""
    out: dict[str, tuple[int, ...] | None] = {}
    for line in reference_table()[2:]:
        cells = [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", line)[1:-1]]
        forms = re.findall(r"`([^`]+)`", cells[0])
        chars = {re.match(r"\?\w|.", form).group() for form in forms}
        assert len(chars) == 1, f"one symbol per row: {line}"
        char = chars.pop()
        counts = []
        for form in forms:
            rest = form[len(char):]
            if rest.endswith(", ...)"):       # as many as the environment answers
                counts = None
                continue
            assert rest == "" or re.fullmatch(r"\(\w+(, \w+)*\)", rest), form
            counts.append(len(rest[1:-1].split(",")) if rest else 0)
        assert char not in out, f"{char!r} has two rows"
        out[char] = None if "any parameters" in cells[0] or counts is None else tuple(counts)
    return out


def test_the_reference_table_is_the_one_symbols_py_renders():
    assert "\n".join(reference_table()) == markdown_table()


def test_the_reference_table_and_the_parser_agree():
    table = reference_arities()
    assert {c: a for c, a in table.items() if a is not None} == TURTLE_ARITY
    assert {c for c, a in table.items() if a is None} == set(UNSUPPORTED) | {"?E"}
    assert len(table) == len(SYMBOLS) > 20


def _parse(axiom: str):
    return parse_grammar({"name": "t", "axiom": axiom, "iterations": 0}, "t.yaml")


@pytest.mark.parametrize("char", sorted(TURTLE_ARITY))
def test_the_parser_takes_the_parameter_counts_the_reference_shows(char):
    counts = reference_arities()[char]
    for n in range(max(counts) + 2):
        args = ["leaf" if char == "~" and k == 0 else "1" for k in range(n)]
        module = char + (f"({', '.join(args)})" if n else "")
        axiom = {"[": f"{module}]", "]": f"[{module}"}.get(char, module)
        if n in counts:
            _parse(axiom)
        else:
            with pytest.raises(GrammarError, match="wrong parameter count"):
                _parse(axiom)


@pytest.mark.parametrize("char", sorted(UNSUPPORTED))
def test_an_unsupported_symbol_takes_any_count_once_per_grammar(char):
    _parse(f"F {char}(1, 2, 3) F {char}(4, 5, 6)")
    with pytest.raises(GrammarError, match="wrong parameter count"):
        _parse(f"{char} {char}(1)")


def test_every_action_has_its_symbols_and_every_symbol_an_action():
    """Nothing declared but not drawn (bar the unsupported symbols, which warn, and the
    cut and the query and communication modules, which the derivation runs), and no
    handler that no symbol reaches."""
    for s in SYMBOLS:
        if s.unsupported:
            assert s.action is Action.NONE
        else:
            assert s.action in HANDLERS or s.action in DERIVATION_ACTIONS, s
    assert set(HANDLERS) == {s.action for s in DRAWN}
    assert set(Action) == {*HANDLERS, Action.NONE, *DERIVATION_ACTIONS}
    assert len({s.char for s in SYMBOLS}) == len(SYMBOLS)


#: A string with every drawn symbol, each where leaving it out shows.
EVERY_SYMBOL = ("F &(30) F /(20) +(50) F $ +(50) F \\ +(50) F ^ F - F + F | F ! F F(1, 0.05) ;(1) F ; F ' F "
                "[ - F ] F f F G F { . F . +(90) F . } { f +(90) f +(90) f } ~(leaf) ~(needles, 0.5) F")
MATERIALS = ["bark", "leaf", "needle"]


def _every_symbol():
    g = parse_grammar({"name": "t", "axiom": EVERY_SYMBOL, "iterations": 0, "materials": MATERIALS}, "t.yaml")
    return g, derive(g)


def _arrays(drawing) -> list[np.ndarray]:
    s, p = drawing.skeleton, drawing.polygons
    return [s.start, s.end, s.r_start, s.r_end, s.parent, s.continues, s.material,
            p.vertices, p.triangles, p.material, p.segment]


def _same(a, b) -> bool:
    return all(x.shape == y.shape and np.array_equal(x, y) for x, y in zip(_arrays(a), _arrays(b), strict=True))


def _renamed(ms, char: str, to: str = "Z"):
    """``ms`` with each module ``char`` made a symbol of no turtle meaning."""
    return dataclasses.replace(ms, symbols=tuple(to if s == char else s for s in ms.symbols))


def test_the_test_string_holds_every_drawn_symbol():
    _, ms = _every_symbol()
    assert {s.char for s in DRAWN} <= set(ms.symbols)


@pytest.mark.parametrize("char", [s.char for s in DRAWN])
def test_every_drawn_symbol_changes_the_drawing(char):
    g, ms = _every_symbol()
    full = interpret_plant(ms, g.turtle, g.materials)
    assert len(full.skeleton.start) > 10 and len(full.polygons) > 3 and full.warnings == ()
    try:
        without = interpret_plant(_renamed(ms, char), g.turtle, g.materials)
    except PlantgenError:
        return                          # a bracket or brace left unpaired: it was acted on
    assert not _same(full, without), f"{char!r} drew nothing"


@pytest.mark.parametrize("char", sorted(UNSUPPORTED))
def test_an_unsupported_symbol_is_skipped_with_its_warning(char):
    g, ms = _every_symbol()
    full = interpret_plant(ms, g.turtle, g.materials, "t.yaml")
    g2 = parse_grammar({"name": "t", "axiom": f"{char}(1) {EVERY_SYMBOL} {char}(2)", "iterations": 0,
                        "materials": MATERIALS}, "t.yaml")
    with_it = interpret_plant(derive(g2), g2.turtle, g2.materials, "t.yaml")
    assert _same(full, with_it)
    assert with_it.warnings == (unsupported_warning("t.yaml", char, 2),)
    assert UNSUPPORTED[char] in with_it.warnings[0] and "2 module(s)" in with_it.warnings[0]


def test_the_cut_symbol_is_run_by_the_derivation():
    cut = next(s.char for s in SYMBOLS if s.action is Action.CUT)
    g = parse_grammar({"name": "t", "axiom": f"F [ + F {cut} F F ] F {cut} F", "iterations": 0}, "t.yaml")
    assert derive(g).to_text() == "F[+F]F"
