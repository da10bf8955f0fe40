"""A whitelist expression language for grammar parameters and conditions.

Grammars are untrusted input, so expressions are tokenised and parsed here (a small Pratt
parser) and compiled to closures over numpy arrays. Nothing reaches Python's ``eval``,
attributes, imports, files or builtins: the only names an expression can see are the
module's formal parameters, the grammar's constants and the functions in ``FUNCTIONS``.
All arithmetic is float64, so no expression can hang the process (``10^10^10`` is ``inf``,
which is reported as an error, not computed as a huge integer).

Grammar (lowest precedence first)::

    expr   := or
    or     := and (("||" | "or") and)*
    and    := not (("&&" | "and") not)*
    not    := ("!" | "not") not | cmp
    cmp    := sum (("<" | "<=" | ">" | ">=" | "==" | "!=") sum)?
    sum    := prod (("+" | "-") prod)*
    prod   := unary (("*" | "/" | "%") unary)*
    unary  := ("-" | "+") unary | power
    power  := atom (("^" | "**") unary)?          (right-associative)
    atom   := number | name | name "(" [expr ("," expr)*] ")" | "(" expr ")"

Booleans are 1.0 and 0.0. ``select(c, a, b)`` is ``a`` where ``c`` is true, else ``b``
(both are evaluated, and only the chosen one must be finite); ``choose(i, a, b, ...)`` is
the option at index ``floor(i)`` (clamped to the options). Trigonometric functions take
radians; ``rad(x)`` and ``deg(x)``
convert. Random draws (``random()``, ``uniform(a, b)``, ``normal(mean, sd)``) come from the
seeded generator of the derivation, one draw per module, in a fixed order.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from ..errors import PlantgenError

__all__ = ["FUNCTIONS", "MAX_DEPTH", "MAX_EXPR_LENGTH", "MAX_GLOBALS", "Expr", "ExprError", "compile_expr"]

MAX_EXPR_LENGTH = 2000
MAX_DEPTH = 64
#: The most global variables (a grammar's ``globals``) expressions may read besides the defines.
MAX_GLOBALS = 64


class ExprError(PlantgenError):
    """An expression that does not parse, names something unknown, or overflows."""


def _det(fn):
    return lambda ctx, *args: fn(*args)


def _random(ctx):
    return ctx.rng.random(ctx.n)


def _uniform(ctx, a, b):
    return a + (b - a) * ctx.rng.random(ctx.n)


def _normal(ctx, mean, sd):
    return mean + sd * ctx.rng.standard_normal(ctx.n)


def _select(ctx, cond, a, b):
    return np.where(np.asarray(cond) != 0, a, b)


def _choose(ctx, index, *options):
    """The option at ``index`` (0-based, clamped to the options), module by module."""
    at = np.clip(np.asarray(index, dtype=float), 0, len(options) - 1).astype(np.int64)
    return np.choose(at, np.broadcast_arrays(*options, at)[:-1]) if np.ndim(at) else options[int(at)]


# name -> (function(ctx, *args), allowed argument counts)
FUNCTIONS: dict[str, tuple[Callable, tuple[int, ...]]] = {
    "sin": (_det(np.sin), (1,)),
    "cos": (_det(np.cos), (1,)),
    "tan": (_det(np.tan), (1,)),
    "asin": (_det(np.arcsin), (1,)),
    "acos": (_det(np.arccos), (1,)),
    "atan": (_det(np.arctan), (1,)),
    "atan2": (_det(np.arctan2), (2,)),
    "sqrt": (_det(np.sqrt), (1,)),
    "exp": (_det(np.exp), (1,)),
    "log": (_det(np.log), (1,)),
    "abs": (_det(np.abs), (1,)),
    "floor": (_det(np.floor), (1,)),
    "ceil": (_det(np.ceil), (1,)),
    "min": (_det(np.minimum), (2,)),
    "max": (_det(np.maximum), (2,)),
    "pow": (_det(np.power), (2,)),
    "clamp": (_det(lambda x, lo, hi: np.minimum(np.maximum(x, lo), hi)), (3,)),
    "rad": (_det(np.radians), (1,)),
    "deg": (_det(np.degrees), (1,)),
    "select": (_select, (3,)),
    "choose": (_choose, tuple(range(2, 33))),
    "trunc": (_det(np.trunc), (1,)),
    "round": (_det(np.round), (1,)),
    "random": (_random, (0,)),
    "uniform": (_uniform, (2,)),
    "normal": (_normal, (2,)),
}
CONSTANTS = {"pi": np.pi, "e": np.e, "true": 1.0, "false": 0.0}

_TOKEN = re.compile(
    r"\s*(?:(?P<num>(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)|(?P<name>[A-Za-z_][A-Za-z_0-9]*)"
    r"|(?P<op>\*\*|<=|>=|==|!=|&&|\|\||[-+*/%^<>!(),]))"
)


@dataclass
class EvalContext:
    """What an expression sees while it runs: variables, the generator, the batch size."""

    env: dict
    rng: np.random.Generator
    n: int


class Expr:
    """A compiled expression. ``expr(ctx)`` gives a float64 array of length ``ctx.n``
    (or a scalar broadcastable to it)."""

    __slots__ = ("_fn", "is_const", "names", "source")

    def __init__(self, source: str, fn: Callable, names: frozenset[str], is_const: bool):
        self.source = source
        self._fn = fn
        self.names = names
        self.is_const = is_const

    def __call__(self, ctx: EvalContext):
        with np.errstate(all="ignore"):
            out = self._fn(ctx)
        if not np.all(np.isfinite(out)):
            raise ExprError(f"expression {self.source!r} gave a non-finite value "
                            "(overflow, division by zero or a domain error)")
        return out

    def __repr__(self) -> str:
        return f"Expr({self.source!r})"


def _tokenise(src: str) -> list[tuple[str, str]]:
    if len(src) > MAX_EXPR_LENGTH:
        raise ExprError(f"expression longer than {MAX_EXPR_LENGTH} characters")
    tokens = []
    pos = 0
    src = src.rstrip()
    while pos < len(src):
        m = _TOKEN.match(src, pos)
        if not m or m.end() == pos:
            bad = src[pos:].lstrip()[:1]
            raise ExprError(f"unexpected character {bad!r} in expression {src!r}")
        kind = m.lastgroup
        tokens.append((kind, m.group(kind)))
        pos = m.end()
    tokens.append(("end", ""))
    return tokens


_BINARY = {
    "+": np.add, "-": np.subtract, "*": np.multiply, "/": np.true_divide, "%": np.mod,
    "^": np.power, "**": np.power,
    "<": np.less, "<=": np.less_equal, ">": np.greater, ">=": np.greater_equal,
    "==": np.equal, "!=": np.not_equal,
}
_ALIASES = {"and": "&&", "or": "||", "not": "!"}


class _Parser:
    def __init__(self, src: str, known: frozenset[str]):
        self.src = src
        self.toks = _tokenise(src)
        self.i = 0
        self.known = known
        self.used: set[str] = set()
        self.depth = 0
        self.pure = True  # no variables and no random draws

    # token helpers
    def peek(self) -> tuple[str, str]:
        kind, val = self.toks[self.i]
        if kind == "name" and val in _ALIASES:
            return "op", _ALIASES[val]
        return kind, val

    def take(self) -> tuple[str, str]:
        t = self.peek()
        self.i += 1
        return t

    def expect(self, op: str) -> None:
        kind, val = self.take()
        if (kind, val) != ("op", op):
            raise ExprError(f"expected {op!r} in expression {self.src!r}, found {val or 'the end'!r}")

    def error(self, what: str) -> ExprError:
        return ExprError(f"{what} in expression {self.src!r}")

    # grammar
    def parse(self):
        fn = self.expr()
        kind, val = self.peek()
        if kind != "end":
            raise self.error(f"unexpected {val!r}")
        return fn

    def expr(self):
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise self.error("expression nested too deeply")
        fn = self.or_()
        self.depth -= 1
        return fn

    def _left_assoc(self, sub, ops, combine):
        fn = sub()
        while self.peek()[0] == "op" and self.peek()[1] in ops:
            op = self.take()[1]
            rhs = sub()
            fn = combine(op, fn, rhs)
        return fn

    def or_(self):
        return self._left_assoc(self.and_, {"||"},
                                lambda op, a, b: lambda c: np.logical_or(a(c), b(c)).astype(float))

    def and_(self):
        return self._left_assoc(self.not_, {"&&"},
                                lambda op, a, b: lambda c: np.logical_and(a(c), b(c)).astype(float))

    def not_(self):
        if self.peek() == ("op", "!"):
            self.take()
            self.depth += 1
            if self.depth > MAX_DEPTH:
                raise self.error("expression nested too deeply")
            a = self.not_()
            self.depth -= 1
            return lambda c: np.logical_not(a(c)).astype(float)
        return self.cmp()

    def cmp(self):
        a = self.sum()
        kind, val = self.peek()
        if kind == "op" and val in ("<", "<=", ">", ">=", "==", "!="):
            self.take()
            b = self.sum()
            f = _BINARY[val]
            return lambda c: f(a(c), b(c)).astype(float)
        return a

    def _binary(self, op, a, b):
        f = _BINARY[op]
        return lambda c: f(a(c), b(c))

    def sum(self):
        return self._left_assoc(self.prod, {"+", "-"}, self._binary)

    def prod(self):
        return self._left_assoc(self.unary, {"*", "/", "%"}, self._binary)

    def unary(self):
        kind, val = self.peek()
        if kind == "op" and val in ("-", "+"):
            self.take()
            self.depth += 1
            if self.depth > MAX_DEPTH:
                raise self.error("expression nested too deeply")
            a = self.unary()
            self.depth -= 1
            return (lambda c: np.negative(a(c))) if val == "-" else a
        return self.power()

    def power(self):
        base = self.atom()
        kind, val = self.peek()
        if kind == "op" and val in ("^", "**"):
            self.take()
            self.depth += 1
            if self.depth > MAX_DEPTH:
                raise self.error("expression nested too deeply")
            exp = self.unary()
            self.depth -= 1
            src = self.src

            def power(c):
                out = np.power(np.asarray(base(c), dtype=float), exp(c))
                if not np.all(np.isfinite(out)):
                    raise ExprError(f"power overflows or is undefined in expression {src!r}")
                return out

            return power
        return base

    def atom(self):
        kind, val = self.take()
        if kind == "num":
            x = float(val)
            return lambda c: x
        if kind == "op" and val == "(":
            fn = self.expr()
            self.expect(")")
            return fn
        if kind == "name":
            if self.peek() == ("op", "("):
                return self.call(val)
            if val in FUNCTIONS:
                raise self.error(f"function {val!r} used without arguments")
            if val in CONSTANTS:
                x = CONSTANTS[val]
                return lambda c: x
            if val not in self.known:
                raise self.error(f"undefined name {val!r}")
            self.used.add(val)
            self.pure = False
            return lambda c: c.env[val]
        raise self.error(f"unexpected {val or 'end'!r}")

    def call(self, name: str):
        if name not in FUNCTIONS:
            raise self.error(f"unknown function {name!r}")
        fn, arities = FUNCTIONS[name]
        self.expect("(")
        args = []
        if self.peek() != ("op", ")"):
            args.append(self.expr())
            while self.peek() == ("op", ","):
                self.take()
                args.append(self.expr())
        self.expect(")")
        if len(args) not in arities:
            raise self.error(f"{name}() takes {' or '.join(map(str, arities))} arguments, got {len(args)}")
        if name in ("random", "uniform", "normal"):
            self.pure = False
        return lambda c: fn(c, *(a(c) for a in args))


def compile_expr(source: str, names: Iterable[str] = ()) -> Expr:
    """Compile ``source`` to an :class:`Expr` that may read the variables ``names``.

    Raises :class:`ExprError` for syntax errors, unknown names or functions, wrong argument
    counts, and over-long or over-deep expressions.
    """
    if not isinstance(source, str):
        source = str(source)
    if not source.strip():
        raise ExprError("empty expression")
    p = _Parser(source, frozenset(names))
    fn = p.parse()
    return Expr(source.strip(), fn, frozenset(p.used), p.pure)


def evaluate(source: str, env: dict | None = None, rng: np.random.Generator | None = None) -> float:
    """Evaluate a scalar expression once (constants, scene values)."""
    env = env or {}
    e = compile_expr(source, env.keys())
    out = e(EvalContext(env, rng or np.random.default_rng(0), 1))
    return float(np.asarray(out).reshape(-1)[0])
