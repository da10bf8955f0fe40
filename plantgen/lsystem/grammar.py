"""Grammar files (YAML) to a validated :class:`Grammar`. Parsing only: no derivation here.

The format is documented in the docs' grammar reference (docs/reference/grammar.md). In short::

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

from .. import fields
from ..errors import PlantgenError
from ..geometry.meshes.surfaces import SURFACES
from ..geometry.skeletons.materials import MAX_MATERIALS
from ..limits import Limits, hint
from ..limits import limits as default_limits
from ..tolerances import tol
from .expr import FUNCTIONS, MAX_GLOBALS, Expr, ExprError, compile_expr, evaluate
from .symbols import ARITY, QUERY_PREFIX, SYMBOLS, Action, by_action

__all__ = ["MAX_INTERPRETATION_DEPTH", "TURTLE_ARITY", "Grammar", "GrammarError", "ModuleTemplate", "Pattern", "Rule",
           "TurtleSettings", "load_grammar", "parse_grammar", "parse_modules"]

#: The parameter counts each turtle symbol accepts (declared in :mod:`plantgen.lsystem.symbols`).
TURTLE_ARITY: dict[str, tuple[int, ...]] = ARITY
#: The symbol that places a predefined surface, whose first argument is the surface's name.
SURFACE_SYMBOL = by_action(Action.SURFACE)
#: The query and communication symbols (``?P``, ``?E``): two characters each.
QUERY_SYMBOLS = frozenset(s.char for s in SYMBOLS if len(s.char) == 2)
#: Most passes of the ``decomposition:`` rules after a derivation step (``decomposition_depth``).
MAX_DECOMPOSITION_DEPTH = 10_000
#: Most times the ``interpretation:`` rules may be applied (``interpretation_depth``).
MAX_INTERPRETATION_DEPTH = 8

GRAMMAR_KEYS = {"name", "description", "seed", "iterations", "defines", "axiom", "rules",
                "ignore", "turtle", "materials", "max_modules", "interpretation",
                "interpretation_depth", "environment", "decomposition", "decomposition_depth", "globals", "hooks"}
TURTLE_KEYS = {"step", "angle", "radius", "width_factor", "tropism", "smooth_bends"}
RULE_KEYS = {"rule", "p", "set"}
#: When a grammar's ``hooks`` run: once before the first step, before and after each
#: step, once after the last (L-Py's ``Start``, ``StartEach``, ``EndEach``, ``End``).
HOOKS = ("start", "start_each", "end_each", "end")

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
    section: str = "rule"           # "rule", or "interpretation rule" (drawing only)
    more: tuple[Pattern, ...] = ()  # the modules after ``pred`` in a predecessor of several
    new_left: tuple[Pattern, ...] = ()   # the new left context (``<<``), matched in the string
                                         # being written (a sequential, left-to-right step)
    effects: tuple[tuple[str, Expr], ...] = ()   # the globals the rule sets where it applies

    @property
    def group_key(self) -> tuple:
        cond = self.condition.source if self.condition else ""
        return (self.pred, self.more, self.left, self.new_left, self.right, cond)

    @property
    def patterns(self) -> tuple[Pattern, ...]:
        """Every module the rule's left-hand side names, contexts included, in string order."""
        return (*self.left, *self.new_left, self.pred, *self.more, *self.right)

    @property
    def predecessor(self) -> tuple[Pattern, ...]:
        """The strict predecessor: the modules the successor replaces."""
        return (self.pred, *self.more)

    def where(self) -> str:
        return f"{self.section} {self.index + 1} ({self.source.strip()!r})"


@dataclass(frozen=True)
class TurtleSettings:
    step: float = 1.0
    angle: float = 30.0             # degrees
    radius: float = 0.1
    width_factor: float = 0.7
    tropism_direction: tuple[float, float, float] = (0.0, -1.0, 0.0)
    tropism_strength: float = 0.0
    smooth_bends: float | None = None   # degrees: skinning smooths bends past it into arcs


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
    interpretation: tuple[Rule, ...] = ()          # rules applied only for drawing
    interpretation_depth: int = 1                  # how many times they are applied
    environment: object = None                     # the ``environment:`` entry as written (see
                                                   # plantgen.environment), None without one
    decomposition: tuple[Rule, ...] = ()           # rules applied after each derivation step ...
    decomposition_depth: int = 1                   # ... up to this many passes
    globals: dict[str, float] = field(default_factory=dict)   # global variables: their first values
    hooks: dict[str, tuple[tuple[str, Expr], ...]] = field(default_factory=dict)   # HOOKS: what they set


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
        if ch == QUERY_PREFIX and j < n and text[j].isalpha():    # a query module: ?P, ?E
            ch, j = text[i:j + 1], j + 1
            if ch not in QUERY_SYMBOLS:
                raise GrammarError(f"{where}: unknown query module {ch!r} at column {i + 1} (known: "
                                   f"{', '.join(sorted(QUERY_SYMBOLS))})")
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
            i = j if len(ch) == 2 else i + 1
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


def _check_params(mods: list, where: str, max_params: int | None) -> None:
    for sym, args in mods:
        if max_params is not None and args is not None and len(args) > max_params:
            raise GrammarError(f"{where}: module {sym!r} has {len(args):,} parameters, over the limit "
                               f"of {max_params} ({hint('params')})")


def parse_modules(text: str, names, where: str, max_params: int | None = None) -> tuple[ModuleTemplate, ...]:
    """Parse an axiom or successor like ``F(l*2)[+A(l,w)]`` into module templates (each
    with at most ``max_params`` parameters, if given). An argument written several times
    is compiled once (an expression holds no state: its random draws happen per call)."""
    mods = _scan_modules(text, where)
    _check_params(mods, where, max_params)
    _check_brackets(mods, where)
    compiled: dict[str, Expr] = {}
    out = []
    for sym, args in mods:
        exprs = ()
        if args is not None:
            head = (_surface_name(args[0], where),) if sym == SURFACE_SYMBOL and args else ()
            try:
                for a in args[len(head):]:
                    if a not in compiled:
                        compiled[a] = compile_expr(a, names)
                exprs = head + tuple(compiled[a] for a in args[len(head):])
            except ExprError as exc:
                raise GrammarError(f"{where}: {exc}") from None
        out.append(ModuleTemplate(sym, exprs))
    return tuple(out)


def _surface_name(text: str, where: str) -> Expr:
    """``~``'s first argument: the name of a built-in surface (``~(leaf, 0.5)``), written
    out, never an expression. It becomes the surface's index, a constant, so the derived
    string stays numbers and expressions never see a name that is not a number."""
    name = text.strip()
    if name not in SURFACES:
        raise GrammarError(f"{where}: {SURFACE_SYMBOL!r} takes the name of a surface first, one of "
                           f"{', '.join(SURFACES)}; got {name[:40]!r}")
    return compile_expr(str(SURFACES.index(name)))


def _parse_patterns(text: str, where: str, max_params: int | None = None) -> tuple[Pattern, ...]:
    mods = _scan_modules(text, where)
    _check_params(mods, where, max_params)
    pats = []
    for sym, args in mods:
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
def _cut_context(text: str, sep: str, where: str, what: str, after: bool = False) -> tuple[str, str]:
    """``text`` split at its first ``sep`` into (context, the rest): the context before it
    (after it with ``after``); ("", text) without one."""
    if sep not in text:
        return "", text
    head, tail = text.split(sep, 1)
    context, rest = (tail, head) if after else (head, tail)
    if not context.strip():
        raise GrammarError(f"{where}: empty {what} {'after' if after else 'before'} {sep!r}")
    return context, rest


def _parse_rule(index: int, entry, defines: dict, path: str, max_params: int | None = None,
                section: str = "rule", globals_: dict | None = None) -> Rule:
    where = f"{path}: {section} {index + 1}"
    p, sets = None, None
    if isinstance(entry, dict):
        fields.keys(entry, RULE_KEYS, where, GrammarError)
        if "rule" not in entry:
            raise GrammarError(f"{where}: a rule mapping needs a 'rule' string")
        if "p" in entry:
            p = fields.number(entry["p"], "probability p", where, GrammarError, hi=1.0, positive=True)
        sets = entry.get("set")
        entry = entry["rule"]
    if not isinstance(entry, str):
        raise GrammarError(f"{where}: a rule must be a string like 'A -> F[+A]A', got {fields.show(entry)}")
    source = entry
    where = f"{path}: {section} {index + 1} ({source.strip()!r})"
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
    if ">>" in lhs:
        raise GrammarError(f"{where}: the new right context '>>' (a right-to-left step) is not supported")
    new_left_src, lhs = _cut_context(lhs, "<<", where, "new left context")
    if new_left_src:                                      # left < new_left << pred
        left_src, new_left_src = _cut_context(new_left_src, "<", where, "left context")
        if not new_left_src.strip():
            raise GrammarError(f"{where}: empty new left context before '<<'")
    else:
        left_src, lhs = _cut_context(lhs, "<", where, "left context")
    right_src, lhs = _cut_context(lhs, ">", where, "right context", after=True)
    if "<" in lhs or ">" in lhs or ">" in right_src:
        raise GrammarError(f"{where}: at most one '<' and one '>' in a predecessor")
    preds = _parse_patterns(lhs, where, max_params)
    if not preds:
        raise GrammarError(f"{where}: no predecessor module")
    if any(pat.symbol in "[]" for pat in preds):
        raise GrammarError(f"{where}: brackets cannot be rewritten")
    pred, more = preds[0], preds[1:]
    left = _parse_patterns(left_src, where, max_params)
    new_left = _parse_patterns(new_left_src, where, max_params)
    right = _parse_patterns(right_src, where, max_params)
    if any(pat.symbol in "[]" for pat in (*left, *new_left)):
        raise GrammarError(f"{where}: brackets are supported in a right context only")
    if any(pat.symbol in "[]" and pat.params for pat in right):
        raise GrammarError(f"{where}: a bracket takes no parameters")
    formals = [n for pat in (*left, *new_left, *preds, *right) for n in pat.params]
    dup = {n for n in formals if formals.count(n) > 1}
    if dup:
        raise GrammarError(f"{where}: formal parameter(s) {sorted(dup)} used twice")
    names = set(defines) | set(globals_ or {}) | set(formals)
    condition = None
    if cond_src is not None:
        try:
            condition = compile_expr(cond_src, names)
        except ExprError as exc:
            raise GrammarError(f"{where}: {exc}") from None
    successor = parse_modules(rhs, names, where, max_params)
    effects = ()
    if sets is not None:
        if section == "interpretation rule":
            raise GrammarError(f"{where}: an interpretation rule cannot set globals (it only draws)")
        effects = _assignments(sets, globals_ or {}, names, f"{where}: set")
    return Rule(index, source, pred, left, right, condition, successor, p, section, more, new_left, effects)


def _assignments(raw, globals_: dict, names, where: str) -> tuple[tuple[str, Expr], ...]:
    """A ``set`` or hook mapping, global name -> expression, compiled (each value is
    computed from the values before any is set)."""
    if not isinstance(raw, dict):
        raise GrammarError(f"{where}: expected a mapping of global names to expressions, like {{n: n + 1}}")
    out = []
    for name, value in raw.items():
        if name not in globals_:
            raise GrammarError(f"{where}: {fields.show(name)} is not one of the grammar's globals")
        if isinstance(value, bool) or not isinstance(value, (str, int, float)):
            raise GrammarError(f"{where}: {name}: expected a number or an expression, got {fields.show(value)}")
        try:
            out.append((name, compile_expr(str(value), names)))
        except ExprError as exc:
            raise GrammarError(f"{where}: {name}: {exc}") from None
    return tuple(out)


def _parse_globals(data: dict, defines: dict, path: str) -> tuple[dict, dict]:
    """``globals`` (name -> first value) and ``hooks`` (HOOKS -> {global: expression})."""
    raw = data.get("globals") or {}
    if not isinstance(raw, dict):
        raise GrammarError(f"{path}: globals must be a mapping of names to numbers")
    if len(raw) > MAX_GLOBALS:
        raise GrammarError(f"{path}: globals: {len(raw)} names, over the limit of {MAX_GLOBALS}")
    values: dict[str, float] = {}
    for key, value in raw.items():
        name = fields.text(key, "a global's name", f"{path}: globals", GrammarError, max_len=100)
        if not _IDENT.match(name) or name in FUNCTIONS or name in defines:
            raise GrammarError(f"{path}: globals: {name!r} is not a usable name (or is a define too)")
        values[name] = fields.number(value, "value", f"{path}: globals: {name}", GrammarError)
    hooks_raw = data.get("hooks") or {}
    if not isinstance(hooks_raw, dict):
        raise GrammarError(f"{path}: hooks must be a mapping of {', '.join(HOOKS)} to assignments")
    fields.keys(hooks_raw, set(HOOKS), f"{path}: hooks", GrammarError)
    names = set(defines) | set(values)
    hooks = {key: _assignments(hooks_raw[key], values, names, f"{path}: hooks: {key}")
             for key in HOOKS if hooks_raw.get(key)}
    return values, hooks


# ---------------------------------------------------------------------------- file
def _parse_turtle(d, path: str) -> TurtleSettings:
    where = f"{path}: turtle"
    if d is None:
        return TurtleSettings()
    fields.keys(d, TURTLE_KEYS, where, GrammarError)
    kw = {}
    for key in ("step", "radius"):   # lengths: within the coordinates a skeleton may hold
        if key in d:
            kw[key] = fields.number(d[key], key, where, GrammarError, lo=0.0, max_abs=tol.max_coordinate)
    if "width_factor" in d:
        kw["width_factor"] = fields.number(d["width_factor"], "width_factor", where, GrammarError, lo=0.0)
    if "angle" in d:
        kw["angle"] = fields.number(d["angle"], "angle", where, GrammarError)
    if "tropism" in d:
        t = d["tropism"]
        fields.keys(t, {"direction", "strength"}, f"{where}: tropism", GrammarError)
        kw["tropism_direction"] = fields.unit_vector(t.get("direction", [0, -1, 0]), "tropism direction",
                                                     where, GrammarError)
        kw["tropism_strength"] = fields.number(t.get("strength", 0.0), "tropism strength", where, GrammarError)
    if d.get("smooth_bends") is not None:
        kw["smooth_bends"] = fields.number(d["smooth_bends"], "smooth_bends (degrees)", where, GrammarError,
                                           lo=0.0, hi=179.0)
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
        for pat in r.patterns:
            if pat.symbol not in "[]":
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


def _parse_defines(raw, path: str) -> dict[str, float]:
    """The grammar's named constants, in file order; a value is a number or an expression
    over the constants before it."""
    defines: dict[str, float] = {}
    if raw is None:
        return defines
    if not isinstance(raw, dict):
        raise GrammarError(f"{path}: defines must be a mapping of names to numbers or expressions")
    for key, value in raw.items():
        name = fields.text(key, "a define's name", f"{path}: defines", GrammarError, max_len=100)
        if not _IDENT.match(name) or name in FUNCTIONS:
            raise GrammarError(f"{path}: defines: {name!r} is not a usable name")
        where = f"{path}: defines: {name}"
        if isinstance(value, str):
            try:
                defines[name] = evaluate(value, defines)
            except ExprError as exc:
                raise GrammarError(f"{where}: {exc}") from None
        else:
            defines[name] = fields.number(value, "value", where, GrammarError)
    return defines


def _parse_header(data, path: str, limits: Limits) -> dict:
    """name, description, seed, iterations and max_modules: typed and ranged."""
    iterations = fields.integer(data.get("iterations", 0), "iterations", path, GrammarError, hi=None)
    limits.check("iterations", iterations, f"{path}: iterations")
    max_modules = data.get("max_modules")
    if max_modules is not None:   # a file may lower the limit, never raise it
        max_modules = fields.integer(max_modules, "max_modules", path, GrammarError, lo=1)
    return {
        "name": fields.text(data.get("name", Path(path).stem), "name", path, GrammarError, max_len=200),
        "description": fields.text(data.get("description", ""), "description", path, GrammarError,
                                   max_len=10_000),
        "seed": fields.integer(data.get("seed", 0), "seed", path, GrammarError),
        "iterations": iterations,
        "max_modules": max_modules,
    }


def _parse_materials(materials, path: str) -> tuple[str, ...]:
    if (not isinstance(materials, list) or not materials
            or not all(isinstance(m, str) and m for m in materials)):
        raise GrammarError(f"{path}: materials must be a non-empty list of names")
    if len(materials) > MAX_MATERIALS:
        raise GrammarError(f"{path}: {len(materials)} materials, more than the {MAX_MATERIALS} a model may use")
    return tuple(fields.text(m, "material", path, GrammarError, max_len=100) for m in materials)


def parse_grammar(data, path: str = "<grammar>", limits: Limits | None = None) -> Grammar:
    """Validate a parsed YAML mapping and build a :class:`Grammar`: every field typed and
    ranged (``limits``: the iterations and the parameters a module may have)."""
    limits = limits or default_limits
    if not isinstance(data, dict):
        raise GrammarError(f"{path}: not a grammar (expected a YAML mapping with 'axiom' and 'rules')")
    fields.keys(data, GRAMMAR_KEYS, path, GrammarError)
    if "axiom" not in data:
        raise GrammarError(f"{path}: not a grammar (no 'axiom')")
    header = _parse_header(data, path, limits)
    defines = _parse_defines(data.get("defines"), path)
    globals_, hooks = _parse_globals(data, defines, path)

    axiom_src = data["axiom"]
    if not isinstance(axiom_src, str) or not axiom_src.strip():
        raise GrammarError(f"{path}: axiom must be a non-empty string")
    axiom = parse_modules(axiom_src, set(defines) | set(globals_), f"{path}: axiom", limits.max_params)

    raw_rules = data.get("rules") or []
    if not isinstance(raw_rules, list):
        raise GrammarError(f"{path}: rules must be a list")
    rules = tuple(_parse_rule(i, r, defines, path, limits.max_params, globals_=globals_)
                  for i, r in enumerate(raw_rules))
    _check_groups(rules, path)
    interpretation, depth = _parse_passes(data, "interpretation", defines, path, limits, MAX_INTERPRETATION_DEPTH,
                                          globals_)
    decomposition, dec_depth = _parse_passes(data, "decomposition", defines, path, limits, MAX_DECOMPOSITION_DEPTH,
                                             globals_)
    symbols = _check_arities(axiom, rules + interpretation + decomposition, path)

    ignore = data.get("ignore", "")
    if not isinstance(ignore, str):
        raise GrammarError(f"{path}: ignore must be a string of symbols, e.g. '+-F'")
    ignore = frozenset(ch for ch in ignore if not ch.isspace())

    return Grammar(header["name"], header["description"], header["seed"], header["iterations"], defines,
                   axiom, rules, ignore, _parse_turtle(data.get("turtle"), path),
                   _parse_materials(data.get("materials", ["bark"]), path), header["max_modules"],
                   path, tuple(symbols), interpretation, depth, data.get("environment"), decomposition, dec_depth,
                   globals_, hooks)


def _parse_passes(data: dict, key: str, defines: dict, path: str, limits: Limits,
                  max_depth: int, globals_: dict) -> tuple[tuple[Rule, ...], int]:
    """The ``interpretation:`` or ``decomposition:`` rules (``key``; the notation of
    ``rules``) and ``KEY_depth``, the most passes of them (1 to ``max_depth``)."""
    raw = data.get(key) or []
    if not isinstance(raw, list):
        raise GrammarError(f"{path}: {key} must be a list of rules like 'L -> {{.-f.+f.}}'")
    rules = tuple(_parse_rule(i, r, defines, path, limits.max_params, f"{key} rule", globals_)
                  for i, r in enumerate(raw))
    _check_groups(rules, path)
    depth = fields.integer(data.get(f"{key}_depth", 1), f"{key}_depth", path, GrammarError, lo=1, hi=max_depth)
    return rules, depth


def load_grammar(path: str | Path, limits: Limits | None = None) -> Grammar:
    """Read and validate a grammar file: YAML, or an L-Py file (``.lpy``, translated by
    :mod:`plantgen.lsystem.lpy`)."""
    from .lpy import read_grammar_data  # lpy builds on this module

    return parse_grammar(read_grammar_data(path, GrammarError, limits)[0], str(path), limits)
