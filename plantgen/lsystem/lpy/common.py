"""What every part of the L-Py reader shares: its error (:class:`LpyError`), its budgets, the
values it passes around (a translated expression :class:`Val`, a module :class:`Mod`, a way
through a rule's block :class:`Way`, the result :class:`LpyModel`) and the small text and
:mod:`ast` helpers (names made safe for plantgen's expressions, brackets, messages)."""

from __future__ import annotations

import ast
import re
import warnings
from dataclasses import dataclass, field

from ...errors import PlantgenError
from ..expr import CONSTANTS, FUNCTIONS

#: Loop iterations (``for ... in range``) one file's rules and functions may unroll, in all.
MAX_LOOP_ITERATIONS = 10_000
#: The largest count a loop over a module parameter (``range(n)``) is unrolled for.
MAX_DYNAMIC_COUNT = 16
#: How deep inlined function calls may nest (a recursive function goes no deeper).
MAX_CALL_DEPTH = 32
#: The most numbers a module-level list may hold to be indexed in an expression.
MAX_TABLE = 64
#: Modules one produced L-string may hold after unrolling.
MAX_SUCCESSOR = 10_000


class LpyError(PlantgenError):
    """An ``.lpy`` file plantgen cannot read; the message names the construct and its line."""


HOOKS = {"Start", "End", "StartEach", "EndEach", "StartInterpretation", "EndInterpretation", "PostDraw"}
SEED_CALLS = {"seed", "random.seed"}


@dataclass
class LpyModel:
    """What an ``.lpy`` file reads to: ``data``, the grammar mapping (as a YAML grammar
    file holds it); ``warnings``, one line each; ``names``, each L-Py module renamed to a
    plantgen symbol (its name in L-Py -> its symbol)."""

    data: dict
    warnings: tuple[str, ...] = ()
    names: dict = field(default_factory=dict)


@dataclass
class Val:
    """A translated expression: plantgen text, whether it draws random numbers, and (a
    local variable's) whether it was read already."""

    text: str
    rand: bool = False
    used: bool = False
    span: tuple | None = None      # a local holding random(): the interval its tests leave it in
    error: str | None = None       # a global's new value plantgen cannot translate: why (refused if read)


@dataclass
class Mod:
    """A module as L-Py writes it: its name and its arguments (translated texts or, in a
    pattern, names)."""

    name: str
    args: list
    line: int


@dataclass
class Way:
    """One way through a rule's block: the tests passed ((if id, holds, text, random)) and
    what it produces (None: the rule does not apply on this path)."""

    conds: list
    modules: list | None
    line: int
    effects: tuple = ()            # ((global, Val)): what the way through sets


def one_line(text: str) -> str:
    return " ".join(str(text).split())


# ------------------------------------------------------------------ helpers
IDENT = re.compile(r"[A-Za-z_][A-Za-z_0-9]*\Z")
ATOM = re.compile(r"[A-Za-z_][A-Za-z_0-9]*|\d+\.?\d*(?:e[-+]?\d+)?")
_RESERVED = set(FUNCTIONS) | set(CONSTANTS) | {"and", "or", "not"}


def safe(name: str) -> str:
    """A name plantgen's expressions can hold: one that is a function or constant there
    gets a trailing underscore."""
    return name + "_" if name in _RESERVED else name


def _atomic(text: str) -> bool:
    """Whether ``text`` needs no parentheses as an operand: a name, a number, a call or
    a parenthesised whole."""
    if ATOM.fullmatch(text):
        return True
    m = re.match(r"[A-Za-z_][A-Za-z_0-9]*\(|\(", text)
    return bool(m) and closing(text, m.end() - 1) == len(text) - 1


def wrap(text: str) -> str:
    return text if _atomic(text) else f"({text})"


def env_effects(env: dict) -> tuple:
    """The globals a block has set so far: ((plantgen name, Val))."""
    return tuple((k[4:], v) for k, v in env.items() if k.startswith("set "))


def merge(test: str, env: dict, yes: dict, no: dict) -> dict:
    """The env after ``if test`` whose branches left ``yes`` and ``no``: each global set
    in either a ``select`` between the two (a local set in one branch only is dropped)."""
    out = dict(env)
    for key in dict.fromkeys([*yes, *no]):
        if key.startswith("global "):
            out[key] = Val("")
            continue
        before = env.get(key)
        if key.startswith("set "):
            before = before or Val(key[4:])
        a, b = yes.get(key, before), no.get(key, before)
        if a is None or b is None:
            out.pop(key, None)
            continue
        out[key] = a if a.text == b.text else Val(f"select({test}, {a.text}, {b.text})", a.rand or b.rand,
                                                  a.used or b.used)
    return out


def copy_env(env: dict) -> dict:
    return {k: Val(v.text, v.rand, v.used, v.span, v.error) for k, v in env.items()}


def call_name(call: ast.Call) -> str | None:
    f = call.func
    if isinstance(f, ast.Name):
        return f.id
    if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name):
        return f"{f.value.id}.{f.attr}"
    return None


def construct(node) -> str:
    """How a message names a Python construct."""
    names = {ast.While: "a while loop", ast.With: "a with statement", ast.Try: "a try statement",
             ast.ClassDef: "a class", ast.Global: "a global statement", ast.Lambda: "a lambda",
             ast.List: "a list", ast.Tuple: "a tuple", ast.Dict: "a dict", ast.Set: "a set",
             ast.Subscript: "indexing", ast.ListComp: "a comprehension", ast.GeneratorExp: "a generator",
             ast.DictComp: "a comprehension", ast.SetComp: "a comprehension", ast.JoinedStr: "an f-string",
             ast.Yield: "yield", ast.Await: "await", ast.Starred: "a starred expression",
             ast.NamedExpr: "the := operator", ast.Delete: "del", ast.Raise: "raise", ast.Assert: "assert",
             ast.For: "a for loop", ast.If: "an if statement", ast.FunctionDef: "a function definition",
             ast.Return: "return", ast.Import: "import", ast.ImportFrom: "import", ast.Nonlocal: "nonlocal",
             ast.AsyncFunctionDef: "an async function", ast.Match: "a match statement"}
    if isinstance(node, ast.Expr) and isinstance(node.value, ast.Call):
        return f"a call of {call_name(node.value) or 'a function'}()"
    if isinstance(node, (ast.Assign, ast.AugAssign, ast.AnnAssign)):
        return "an assignment"
    return names.get(type(node), type(node).__name__)


def _scan_depth(text: str, start: int = 0):
    """(index, character, bracket depth after it, whether it lies in a quote) for each
    character of ``text`` from ``start``."""
    depth, quote = 0, None
    for j in range(start, len(text)):
        ch = text[j]
        quoted = quote is not None
        if quote:
            if ch == quote:
                quote = None
        elif ch in "'\"":
            quote = ch
        elif ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
        yield j, ch, depth, quoted or quote is not None


def closing(text: str, k: int) -> int:
    """The index of the bracket closing the one at ``k`` (-1: none)."""
    return next((j for j, ch, depth, quoted in _scan_depth(text, k) if ch in ")]}" and not quoted and depth == 0), -1)


def split_top(text: str, sep: str) -> list[str]:
    """``text`` split at each ``sep`` outside brackets and quotes."""
    out, last = [], 0
    for j, ch, depth, quoted in _scan_depth(text):
        if ch == sep and depth == 0 and not quoted:
            out.append(text[last:j])
            last = j + 1
    out.append(text[last:])
    return out


def ast_parse(source: str, mode: str = "exec") -> ast.Module | ast.Expression:
    """``ast.parse`` without the warnings Python's compiler prints for odd literals."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return ast.parse(source, mode=mode)


def reason(exc: BaseException) -> str:
    return one_line(getattr(exc, "msg", None) or str(exc) or exc.__class__.__name__)[:100]
