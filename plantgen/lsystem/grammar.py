"""Grammar files (YAML) to a validated :class:`Grammar`. Parsing only: no derivation here.

The format is documented in the README, section "Grammar format". In short::

    name: monopodial
    description: ABOP figure 2.6
    seed: 1
    iterations: 10
    defines: {r1: 0.9, r2: 0.6, a0: 45, d: 137.5, wr: 0.707}
    axiom: "A(1, 10)"
    ignore: "+-/"                      # symbols skipped when matching context
    rules:
      - "A(l,w) : l > 0.1 -> !(w) F(l) [&(a0) B(l*r2, w*wr)] /(d) A(l*r1, w*wr)"
      - {rule: "B(l,w) -> F(l) B(l, w)", p: 0.7}   # stochastic: p per alternative
      - {rule: "B(l,w) -> F(l)", p: 0.3}
      - "A < B > C -> D"                 # context-sensitive (ABOP notation)
    turtle: {step: 1, angle: 30, radius: 0.1, width_factor: 0.7,
             tropism: {direction: [0, -1, 0], strength: 0.2}}
    materials: [bark, leaf]
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import PlantgenError
from ..files import read_yaml
from .expr import FUNCTIONS, Expr, ExprError, compile_expr, evaluate

__all__ = ["TURTLE_ARITY", "Grammar", "GrammarError", "ModuleTemplate", "Pattern", "Rule",
           "TurtleSettings", "load_grammar", "parse_grammar", "parse_modules"]

# Turtle symbols (ABOP meanings) and the parameter counts each accepts.
TURTLE_ARITY: dict[str, tuple[int, ...]] = {
    "F": (0, 1, 2), "f": (0, 1),
    "+": (0, 1), "-": (0, 1), "&": (0, 1), "^": (0, 1), "\\": (0, 1), "/": (0, 1),
    "|": (0,), "[": (0,), "]": (0,), "$": (0,),
    "!": (0, 1), ";": (0, 1),
}

GRAMMAR_KEYS = {"name", "description", "seed", "iterations", "defines", "axiom", "rules",
                "ignore", "turtle", "materials", "max_modules"}
TURTLE_KEYS = {"step", "angle", "radius", "width_factor", "tropism"}
RULE_KEYS = {"rule", "p"}
_IDENT = re.compile(r"[A-Za-z_][A-Za-z_0-9]*\Z")
_ARROW = re.compile(r"->|→")
_PROB_PREFIX = re.compile(r"\s*\(\s*([0-9]*\.?[0-9]+(?:[eE][-+]?\d+)?)\s*\)")


class GrammarError(PlantgenError):
    """A grammar file that cannot be used; the message names the file and the place."""


@dataclass(frozen=True)
class ModuleTemplate:
    """A module written in an axiom or successor: a symbol with argument expressions."""

    symbol: str
    args: tuple[Expr, ...] = ()


@dataclass(frozen=True)
class Pattern:
    """A module in a predecessor or context: a symbol with formal parameter names."""

    symbol: str
    params: tuple[str, ...] = ()


@dataclass(frozen=True)
class Rule:
    index: int                      # position in the file's rule list (0-based)
    source: str
    pred: Pattern
    left: tuple[Pattern, ...]       # left context, in string order
    right: tuple[Pattern, ...]      # right context, in string order
    condition: Expr | None
    successor: tuple[ModuleTemplate, ...]
    p: float | None                 # probability within its stochastic group

    @property
    def group_key(self) -> tuple:
        cond = self.condition.source if self.condition else ""
        return (self.pred, self.left, self.right, cond)

    def where(self) -> str:
        return f"rule {self.index + 1} ({self.source.strip()!r})"


@dataclass(frozen=True)
class TurtleSettings:
    step: float = 1.0
    angle: float = 30.0             # degrees
    radius: float = 0.1
    width_factor: float = 0.7
    tropism_direction: tuple[float, float, float] = (0.0, -1.0, 0.0)
    tropism_strength: float = 0.0


@dataclass(frozen=True)
class Grammar:
    name: str
    description: str
    seed: int
    iterations: int
    defines: dict[str, float]
    axiom: tuple[ModuleTemplate, ...]
    rules: tuple[Rule, ...]
    ignore: frozenset[str]
    turtle: TurtleSettings
    materials: tuple[str, ...]
    max_modules: int | None = None
    path: str = "<grammar>"
    symbols: tuple[str, ...] = field(default=())   # every symbol used, in first-seen order


# ---------------------------------------------------------------------------- modules
def _split_args(text: str, where: str) -> list[str]:
    args, depth, cur = [], 0, []
    for ch in text:
        if ch == "(":
            depth += 1
        elif ch == ")":
            depth -= 1
        if ch == "," and depth == 0:
            args.append("".join(cur))
            cur = []
        else:
            cur.append(ch)
    args.append("".join(cur))
    if any(not a.strip() for a in args):
        raise GrammarError(f"{where}: empty argument in ({text})")
    return args


def _scan_modules(text: str, where: str) -> list[tuple[str, list[str] | None]]:
    """Split a module string into (symbol, raw argument strings or None)."""
    out: list[tuple[str, list[str] | None]] = []
    i, n = 0, len(text)
    while i < n:
        ch = text[i]
        if ch.isspace():
            i += 1
            continue
        if ch in "(),":
            raise GrammarError(f"{where}: unexpected {ch!r} at column {i + 1} of {text.strip()!r}")
        j = i + 1
        while j < n and text[j].isspace():
            j += 1
        if j < n and text[j] == "(":
            depth, k = 0, j
            while k < n:
                if text[k] == "(":
                    depth += 1
                elif text[k] == ")":
                    depth -= 1
                    if depth == 0:
                        break
                k += 1
            if depth != 0:
                raise GrammarError(f"{where}: unclosed '(' after {ch!r} in {text.strip()!r}")
            inner = text[j + 1:k]
            out.append((ch, _split_args(inner, where) if inner.strip() else []))
            i = k + 1
        else:
            out.append((ch, None))
            i += 1
    return out


def _check_brackets(mods: list, where: str) -> None:
    depth = 0
    for sym, _ in mods:
        if sym == "[":
            depth += 1
        elif sym == "]":
            depth -= 1
            if depth < 0:
                raise GrammarError(f"{where}: unbalanced brackets (']' without '[')")
    if depth:
        raise GrammarError(f"{where}: unbalanced brackets ({depth} '[' not closed)")


def parse_modules(text: str, names, where: str) -> tuple[ModuleTemplate, ...]:
    """Parse an axiom or successor like ``F(l*2)[+A(l,w)]`` into module templates."""
    mods = _scan_modules(text, where)
    _check_brackets(mods, where)
    out = []
    for sym, args in mods:
        exprs = ()
        if args is not None:
            try:
                exprs = tuple(compile_expr(a, names) for a in args)
            except ExprError as exc:
                raise GrammarError(f"{where}: {exc}") from None
        out.append(ModuleTemplate(sym, exprs))
    return tuple(out)


def _parse_patterns(text: str, where: str) -> tuple[Pattern, ...]:
    pats = []
    for sym, args in _scan_modules(text, where):
        params = ()
        if args is not None:
            params = tuple(a.strip() for a in args)
            for p in params:
                if not _IDENT.match(p):
                    raise GrammarError(f"{where}: formal parameter {p!r} must be a name")
                if p in FUNCTIONS:
                    raise GrammarError(f"{where}: formal parameter {p!r} shadows a function")
        pats.append(Pattern(sym, params))
    return tuple(pats)


# ---------------------------------------------------------------------------- rules
def _parse_rule(index: int, entry, defines: dict, path: str) -> Rule:
    where = f"{path}: rule {index + 1}"
    p = None
    if isinstance(entry, dict):
        unknown = set(entry) - RULE_KEYS
        if unknown:
            raise GrammarError(f"{where}: unknown key(s) {sorted(unknown)} (allowed: rule, p)")
        if "rule" not in entry:
            raise GrammarError(f"{where}: a rule mapping needs a 'rule' string")
        if "p" in entry:
            p = entry["p"]
            if isinstance(p, bool) or not isinstance(p, (int, float)) or not (0 < p <= 1):
                raise GrammarError(f"{where}: probability p must be a number in (0, 1], got {p!r}")
            p = float(p)
        entry = entry["rule"]
    if not isinstance(entry, str):
        raise GrammarError(f"{where}: a rule must be a string like 'A -> F[+A]A'")
    source = entry
    where = f"{path}: rule {index + 1} ({source.strip()!r})"
    parts = _ARROW.split(source)
    if len(parts) != 2:
        raise GrammarError(f"{where}: a rule needs exactly one '->'")
    lhs, rhs = parts
    m = _PROB_PREFIX.match(rhs)
    if m:
        if p is not None:
            raise GrammarError(f"{where}: probability given twice")
        p = float(m.group(1))
        if not (0 < p <= 1):
            raise GrammarError(f"{where}: probability must lie in (0, 1]")
        rhs = rhs[m.end():]
    cond_src = None
    if ":" in lhs:
        lhs, cond_src = lhs.split(":", 1)
        if not cond_src.strip():
            raise GrammarError(f"{where}: empty condition after ':'")
    left_src, right_src = "", ""
    if "<" in lhs:
        left_src, lhs = lhs.split("<", 1)
        if not left_src.strip():
            raise GrammarError(f"{where}: empty left context before '<'")
    if ">" in lhs:
        lhs, right_src = lhs.split(">", 1)
        if not right_src.strip():
            raise GrammarError(f"{where}: empty right context after '>'")
    if "<" in lhs or ">" in lhs:
        raise GrammarError(f"{where}: at most one '<' and one '>' in a predecessor")
    pred = _parse_patterns(lhs, where)
    if len(pred) != 1:
        raise GrammarError(f"{where}: the predecessor must be exactly one module, got {len(pred)}")
    pred = pred[0]
    if pred.symbol in "[]":
        raise GrammarError(f"{where}: brackets cannot be rewritten")
    left = _parse_patterns(left_src, where)
    right = _parse_patterns(right_src, where)
    if any(pat.symbol in "[]" for pat in (*left, *right)):
        raise GrammarError(f"{where}: brackets are not supported in a context")
    formals = [n for pat in (*left, pred, *right) for n in pat.params]
    dup = {n for n in formals if formals.count(n) > 1}
    if dup:
        raise GrammarError(f"{where}: formal parameter(s) {sorted(dup)} used twice")
    names = set(defines) | set(formals)
    condition = None
    if cond_src is not None:
        try:
            condition = compile_expr(cond_src, names)
        except ExprError as exc:
            raise GrammarError(f"{where}: {exc}") from None
    successor = parse_modules(rhs, names, where)
    return Rule(index, source, pred, left, right, condition, successor, p)


# ---------------------------------------------------------------------------- file
def _number(value, what: str, where: str, *, integer=False, positive=False, nonneg=False):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise GrammarError(f"{where}: {what} must be a number, got {value!r}")
    if integer and int(value) != value:
        raise GrammarError(f"{where}: {what} must be an integer, got {value!r}")
    if not np.isfinite(value):
        raise GrammarError(f"{where}: {what} must be finite")
    if positive and value <= 0:
        raise GrammarError(f"{where}: {what} must be positive, got {value!r}")
    if nonneg and value < 0:
        raise GrammarError(f"{where}: {what} must not be negative, got {value!r}")
    return int(value) if integer else float(value)


def _parse_turtle(d, path: str) -> TurtleSettings:
    where = f"{path}: turtle"
    if d is None:
        return TurtleSettings()
    if not isinstance(d, dict):
        raise GrammarError(f"{where}: must be a mapping")
    unknown = set(d) - TURTLE_KEYS
    if unknown:
        raise GrammarError(f"{where}: unknown key(s) {sorted(unknown)} (allowed: {sorted(TURTLE_KEYS)})")
    kw = {}
    for key in ("step", "angle", "radius", "width_factor"):
        if key in d:
            kw[key] = _number(d[key], key, where, nonneg=(key != "angle"))
    if "tropism" in d:
        t = d["tropism"]
        if not isinstance(t, dict) or set(t) - {"direction", "strength"}:
            raise GrammarError(f"{where}: tropism must be a mapping with 'direction' and 'strength'")
        direction = t.get("direction", [0, -1, 0])
        if not isinstance(direction, list) or len(direction) != 3:
            raise GrammarError(f"{where}: tropism direction must be three numbers")
        vec = np.array([_number(x, "tropism direction", where) for x in direction])
        norm = np.linalg.norm(vec)
        if norm == 0:
            raise GrammarError(f"{where}: tropism direction must not be zero")
        kw["tropism_direction"] = tuple((vec / norm).tolist())
        kw["tropism_strength"] = _number(t.get("strength", 0.0), "tropism strength", where)
    return TurtleSettings(**kw)


def _check_arities(axiom, rules, path: str) -> list[str]:
    """Every non-turtle symbol has one parameter count; turtle symbols their allowed ones."""
    seen: dict[str, tuple[int, str]] = {}
    symbols: list[str] = []

    def visit(sym: str, n: int, where: str):
        if sym not in symbols:
            symbols.append(sym)
        if sym in TURTLE_ARITY:
            if n not in TURTLE_ARITY[sym]:
                allowed = " or ".join(map(str, TURTLE_ARITY[sym]))
                raise GrammarError(f"{where}: wrong parameter count for {sym!r}: "
                                   f"takes {allowed}, got {n}")
            return
        if sym in seen and seen[sym][0] != n:
            raise GrammarError(f"{where}: wrong parameter count for {sym!r}: {n} here, "
                               f"{seen[sym][0]} in {seen[sym][1]}")
        seen.setdefault(sym, (n, where.split(": ", 1)[-1]))

    for m in axiom:
        visit(m.symbol, len(m.args), f"{path}: axiom")
    for r in rules:
        where = f"{path}: {r.where()}"
        for pat in (*r.left, r.pred, *r.right):
            visit(pat.symbol, len(pat.params), where)
        for m in r.successor:
            visit(m.symbol, len(m.args), where)
    return symbols


def _check_groups(rules: tuple[Rule, ...], path: str) -> None:
    groups: dict[tuple, list[Rule]] = {}
    for r in rules:
        groups.setdefault(r.group_key, []).append(r)
    for members in groups.values():
        probs = [r.p for r in members]
        first = members[0]
        if all(p is None for p in probs):
            if len(members) > 1:
                raise GrammarError(f"{path}: {members[1].where()} repeats the predecessor of "
                                   f"{first.where()}; give each alternative a probability p")
            continue
        if any(p is None for p in probs):
            raise GrammarError(f"{path}: {first.where()}: every alternative of a stochastic rule "
                               "needs a probability p")
        total = sum(probs)
        if abs(total - 1.0) > 1e-6:
            raise GrammarError(f"{path}: probabilities for {first.pred.symbol!r} in "
                               f"{first.where()} add up to {total:g}, not 1")


def parse_grammar(data, path: str = "<grammar>") -> Grammar:
    """Validate a parsed YAML mapping and build a :class:`Grammar`."""
    if not isinstance(data, dict):
        raise GrammarError(f"{path}: not a grammar (expected a YAML mapping with 'axiom' and 'rules')")
    unknown = set(data) - GRAMMAR_KEYS
    if unknown:
        raise GrammarError(f"{path}: unknown key(s) {sorted(unknown)} (allowed: {sorted(GRAMMAR_KEYS)})")
    if "axiom" not in data:
        raise GrammarError(f"{path}: not a grammar (no 'axiom')")
    name = str(data.get("name", Path(path).stem))
    description = str(data.get("description", ""))
    seed = _number(data.get("seed", 0), "seed", path, integer=True, nonneg=True)
    iterations = _number(data.get("iterations", 0), "iterations", path, integer=True, nonneg=True)
    max_modules = data.get("max_modules")
    if max_modules is not None:
        max_modules = _number(max_modules, "max_modules", path, integer=True, positive=True)

    defines: dict[str, float] = {}
    raw_defines = data.get("defines") or {}
    if not isinstance(raw_defines, dict):
        raise GrammarError(f"{path}: defines must be a mapping of names to numbers or expressions")
    for key, value in raw_defines.items():
        key = str(key)
        if not _IDENT.match(key) or key in FUNCTIONS:
            raise GrammarError(f"{path}: defines: {key!r} is not a usable name")
        try:
            if isinstance(value, bool):
                raise ExprError("booleans are not numbers")
            defines[key] = float(value) if isinstance(value, (int, float)) else evaluate(str(value), defines)
        except ExprError as exc:
            raise GrammarError(f"{path}: defines: {key}: {exc}") from None
        if not np.isfinite(defines[key]):
            raise GrammarError(f"{path}: defines: {key} is not finite")

    axiom_src = data["axiom"]
    if not isinstance(axiom_src, str) or not axiom_src.strip():
        raise GrammarError(f"{path}: axiom must be a non-empty string")
    axiom = parse_modules(axiom_src, defines, f"{path}: axiom")

    raw_rules = data.get("rules") or []
    if not isinstance(raw_rules, list):
        raise GrammarError(f"{path}: rules must be a list")
    rules = tuple(_parse_rule(i, r, defines, path) for i, r in enumerate(raw_rules))
    _check_groups(rules, path)
    symbols = _check_arities(axiom, rules, path)

    ignore = data.get("ignore", "")
    if not isinstance(ignore, str):
        raise GrammarError(f"{path}: ignore must be a string of symbols, e.g. '+-F'")
    ignore = frozenset(ch for ch in ignore if not ch.isspace())

    materials = data.get("materials", ["bark"])
    if (not isinstance(materials, list) or not materials
            or not all(isinstance(m, str) and m for m in materials)):
        raise GrammarError(f"{path}: materials must be a non-empty list of names")

    return Grammar(name, description, seed, iterations, defines, axiom, rules, ignore,
                   _parse_turtle(data.get("turtle"), path), tuple(materials), max_modules,
                   path, tuple(symbols))


def load_grammar(path: str | Path) -> Grammar:
    """Read and validate a grammar file."""
    return parse_grammar(read_yaml(path, GrammarError), str(path))
