"""L-Py files (``.lpy``) read into plantgen's grammar mapping, never run.

An L-Py file is Python with L-system sections (``Axiom:``, ``derivation length:``,
``production:``, ``interpretation:``/``homomorphism:``, ``endlsystem`` ...). This module
splits the sections line by line, parses each piece of Python with :mod:`ast` and
*translates* it: module-level constants become the grammar's ``defines``, functions are
inlined into the expressions that call them, and a rule's Python block is walked
symbolically, each path that ends in ``produce`` becoming one plantgen rule whose
condition is the path's tests (``if``/``elif``/``else``; ``for ... in range(...)`` with a
constant count is unrolled; local assignments are substituted). Every expression ends up
as text in plantgen's whitelist expression language (:mod:`plantgen.lsystem.expr`), which
is what evaluates it: nothing here calls ``exec`` or ``eval``. The result is the same
mapping a YAML grammar file gives (:func:`plantgen.lsystem.grammar.parse_grammar` takes
it; ``plantgen convert`` writes it).

``Start``/``StartEach``/``EndEach``/``End`` and ``global`` assignments in rules become
the grammar's ``globals``, ``hooks`` and a rule's ``set`` (a global nothing drawn reads is
dropped with what sets it); a module-level function whose body produces is run in place
where a rule calls it as a statement.

What cannot be translated is refused in one line naming the construct and its line
(:class:`LpyError`): imports other than ``random`` and ``math`` (``time`` is ignored,
``numpy`` only gives a tropism vector), PlantGL, hooks that produce or read the L-string,
file access, a random draw that would be tested twice. Drawing modules plantgen
has no meaning for are dropped with one warning each; the ``INITIALISATION`` section is
read only for its scalar parameters (defines), the rest ignored with a warning.

Budgets: the file's size (``max_input_bytes``), the work of the translation (AST nodes
visited, inlined calls and unrolled loop bodies included, against ``max_yaml_nodes``),
the nesting of inlined calls (:data:`MAX_CALL_DEPTH`), :data:`MAX_LOOP_ITERATIONS` unrolled
loop iterations and :data:`~plantgen.lsystem.expr.MAX_EXPR_LENGTH` characters per
translated expression; then the grammar's own budgets when it is derived.
"""

from __future__ import annotations

import ast
import re
import textwrap
from pathlib import Path

import numpy as np
import yaml

from ...errors import PlantgenError
from ...files import read_text, read_yaml
from ...limits import LimitError, Limits, hint
from ...limits import limits as default_limits
from ..expr import ExprError, evaluate
from .common import (
    ATOM,
    IDENT,
    MAX_CALL_DEPTH,
    MAX_DYNAMIC_COUNT,
    MAX_LOOP_ITERATIONS,
    MAX_SUCCESSOR,
    MAX_TABLE,
    SEED_CALLS,
    LpyError,
    LpyModel,
    Mod,
    Val,
    Way,
    ast_parse,
    call_name,
    construct,
    copy_env,
    env_effects,
    merge,
    one_line,
    safe,
    split_top,
    wrap,
)
from .drawn import CANDIDATES, DRAWN_AS, PLANTGEN_CHARS, TURTLE, UNDRAWN, DrawnAs, turtle_params
from .sections import PRODUCE, SectionReader, strip_comment
from .translate import ExpressionTranslator, StatementTranslator

__all__ = ["LPY_SUFFIX", "MAX_CALL_DEPTH", "MAX_LOOP_ITERATIONS", "TURTLE", "LpyError", "LpyModel", "parse_lpy",
           "read_grammar_data", "read_lpy", "to_yaml"]

LPY_SUFFIX = ".lpy"


#: The hooks that may set globals: plantgen's grammar hook each becomes.
_STATE_HOOKS = {"Start": "start", "StartEach": "start_each", "EndEach": "end_each", "End": "end"}


class _Reader(DrawnAs, SectionReader, StatementTranslator, ExpressionTranslator):
    """One file's translation (see the module's notes)."""

    def __init__(self, text: str, path: str, limits: Limits):
        self.path, self.limits = path, limits
        self.lines = text.splitlines()
        self.warnings: list[str] = []
        self.defines: dict[str, float] = {}
        self.define_text: dict[str, object] = {}    # for the YAML: the value as a number
        self.functions: dict[str, ast.AST] = {}
        self.lazy: dict[str, str] = {}              # name -> why it cannot be used
        self.tables: dict[str, list[str]] = {}      # a module-level list of numbers -> their texts
        self.declared: set[str] = set()
        # names that start a line as a rule's head would (name then '(', '-->' or ':'): an
        # undeclared word before '(' whose last letter is one of them and that is not one
        # itself is read as letters, L-Py's modules of minimal length ('IB(x)': I, B(x))
        self.heads = {m.group(1) for m in re.finditer(r"^[ \t]*([A-Za-z_]\w*)[ \t]*(?:\(|-->|:)", text, re.M)}
        self.seed = 0
        self.iterations = 1
        self.work = 0
        self.depth = 0
        self.calls = 0
        self.angle = 60.0
        self.carried: dict[str, int] = {}       # turtle modules written with extra parameters: how many
        self.aliases = {"random": "random", "math": "math"}
        self.loops = 0
        self.if_ids = 0
        self.tropism: dict[str, object] = {}
        self.dropped: dict[str, int] = {}
        self.used_colour = False
        self.rules: dict[str, list] = {"production": [], "interpretation": [], "decomposition": []}
        self.mutable: set[str] = set()              # globals a hook or a rule sets
        self.globals: dict[str, float] = {}         # those, by plantgen name: their first values
        self.hooks: dict[str, dict] = {}            # Start ... -> {global: Val}
        self.hook_defs: list[ast.FunctionDef] = []
        self.vectors: dict[str, list] = {}          # numpy.array constants: only a tropism's direction
        self.later: list[tuple[str, str]] = []      # the rules after the one translated: (section, header)
        self.producers: dict[str, tuple] = {}       # functions that produce: (def line, their lines)
        self.producer_code: dict[str, tuple] = {}
        self.lstrings: list[tuple[str, int]] = []   # produce's L-strings, by placeholder
        self.axiom_effects: tuple = ()
        self.max_depth = {"interpretation": 1, "decomposition": 1}

    # ------------------------------------------------------------ errors and budgets
    def refuse(self, line, what: str) -> LpyError:
        where = f"{self.path}: line {line}" if line else self.path
        return LpyError(f"{where}: {one_line(what)}")

    def spend(self, line) -> None:
        self.work += 1
        if self.work > self.limits.max_yaml_nodes:
            raise LimitError(f"{self.path}: line {line}: translating the file takes over "
                             f"{self.limits.max_yaml_nodes:,} steps ({hint('yaml_nodes')})")

    def _producer(self, name: str, args: list, state, paths: list) -> list:
        """A function that produces modules, called as a statement in a rule: its body
        run in place (its parameters bound to the arguments), as if written in the rule;
        its ``produce`` ends the rule, as in L-Py. The states still running come back."""
        env, conds, pending = state
        line, text = self.producers[name]
        if name not in self.producer_code:
            tree = self._parse_block(strip_comment(text[0]).rstrip() + " pass", line, f"function {name}")
            fn = tree[0]
            body = self._placeholders([(line + k + 1, t) for k, t in enumerate(text[1:])], f"function {name}")
            if body and isinstance(body[-1], ast.Return) and body[-1].value is None:
                body = body[:-1]
            if any(isinstance(n, ast.Return) for b in body for n in ast.walk(b)):
                raise self.refuse(line, f"function {name}() returns from inside a block; plantgen inlines a "
                                        "function that produces modules only where it ends at its last line")
            self.producer_code[name] = (fn, body)
        fn, body = self.producer_code[name]
        params = fn.args
        if params.vararg or params.kwarg or params.kwonlyargs or params.posonlyargs or params.defaults \
                or len(params.args) != len(args):
            raise self.refuse(line, f"function {name}() takes {len(params.args)} plain parameters; the rule passes "
                                    f"{len(args)}")
        local = {a.arg: Val(v.text, v.rand) for a, v in zip(params.args, [self.expr(x, env, line) for x in args],
                                                                strict=True)}
        self.calls += 1
        if self.calls > MAX_CALL_DEPTH:
            raise self.refuse(line, f"function calls nested deeper than {MAX_CALL_DEPTH}: a recursive function "
                                    f"such as {name}() cannot be translated")
        try:
            out = self._run(body, [(local, conds, pending)], paths)
        finally:
            self.calls -= 1
        back = []
        for fenv, c, p in out:               # the globals it set, seen by the rest of the rule
            sets = {k: v for k, v in fenv.items() if k.startswith("set ")}
            back.append(({**env, **sets, **{k[4:]: fenv[k[4:]] for k in sets if k[4:] in fenv}}, c, p))
        return back

    def _assign_global(self, target, value, line: int) -> None:
        if isinstance(target, ast.Tuple) and isinstance(value, ast.Tuple) and len(target.elts) == len(value.elts):
            for t, v in zip(target.elts, value.elts, strict=True):
                self._assign_global(t, v, line)
            return
        if not isinstance(target, ast.Name):
            raise self.refuse(line, f"assignment to {construct(target)} is not supported")
        name = target.id
        if isinstance(value, ast.Lambda):
            self._forget(name)
            self.functions[name] = value
            return
        vector = self._vector(value)
        if vector is not None:
            self._forget(name)
            self.vectors[name] = vector
            self.lazy[name] = (f"{name} (line {line}) is a vector (numpy.array): plantgen reads one only as "
                               "@Tp's direction")
            return
        if isinstance(value, (ast.List, ast.Tuple)) and 1 <= len(value.elts) <= MAX_TABLE:
            try:
                texts = [self.expr(v, {}, line) for v in value.elts]
                numbers = [evaluate(t.text, self.defines) for t in texts if not t.rand]
            except (LpyError, ExprError):
                numbers = []
            self._forget(name)
            if len(numbers) == len(value.elts):
                self.tables[name] = [repr(float(v)) for v in numbers]
                self.lazy[name] = f"{name} (line {line}) is a list: plantgen reads it only indexed ({name}[i])"
            else:
                self.lazy[name] = f"{name} (line {line}) is a list plantgen can index only when it holds numbers"
            return
        try:
            val = self.expr(value, {}, line)
            if val.rand:
                raise self.refuse(line, f"{name} draws a random number at module level")
            number = evaluate(val.text, self.defines)
            self._forget(name)
        except LpyError as exc:
            self._forget(name)
            self.lazy[name] = f"{name} (line {line}) is not a number plantgen can use: " + \
                str(exc).split(": ", 2)[-1]
            return
        except ExprError as exc:
            self._forget(name)
            self.lazy[name] = f"{name} (line {line}): {exc}"
            return
        self.defines[safe(name)] = number

    def _vector(self, value) -> list | None:
        """``numpy.array([x, y, z])`` of constants: its numbers (None for anything else)."""
        name = call_name(value) if isinstance(value, ast.Call) else None
        base, _, attr = (name or "").rpartition(".")
        if self.aliases.get(base) != "numpy" or attr != "array" or len(value.args) != 1 or value.keywords \
                or not isinstance(value.args[0], (ast.List, ast.Tuple)) or len(value.args[0].elts) != 3:
            return None
        try:
            return [self._constant(ast.unparse(e), value.lineno, "a vector's coordinate") for e in value.args[0].elts]
        except LpyError:
            return None

    def _forget(self, name: str) -> None:
        self.vectors.pop(name, None)
        self.functions.pop(name, None)
        self.tables.pop(name, None)
        self.lazy.pop(name, None)
        self.defines.pop(safe(name), None)

    def _hook(self, fn: ast.FunctionDef) -> None:
        if fn.name in _STATE_HOOKS:
            self._state_hook(fn)
            return
        env = self._hook_run(fn.body, {}, fn.name)
        if env_effects(env):
            raise self.refuse(fn.lineno, f"{fn.name}() sets globals: only Start, StartEach, EndEach and End may")

    def _state_hook(self, fn: ast.FunctionDef) -> None:
        """``Start``/``StartEach``/``EndEach``/``End``: the globals they set (each as an
        expression over the globals before the hook ran), seeds, and nothing else."""
        a = fn.args
        if a.vararg or a.kwarg or a.kwonlyargs or a.posonlyargs or fn.decorator_list:
            raise self.refuse(fn.lineno, f"{fn.name}() with starred parameters or decorators is not supported")
        unread = [p.arg for p in a.args]         # the L-string (and scene) L-Py passes: never read here
        for stmt in ast.walk(fn):
            if isinstance(stmt, ast.Name) and stmt.id in unread and isinstance(stmt.ctx, ast.Load) and not any(
                    isinstance(c, ast.Call) and call_name(c) == "print" and stmt in ast.walk(c)
                    for c in ast.walk(fn)):
                raise self.refuse(stmt.lineno, f"{fn.name}() reads the L-string ({stmt.id}): not supported")
        env = self._hook_run(fn.body, {}, fn.name)
        sets = dict(env_effects(env))
        if sets:
            self.hooks[_STATE_HOOKS[fn.name]] = sets

    def _hook_run(self, stmts: list, env: dict, name: str) -> dict:
        for stmt in stmts:
            self.spend(stmt.lineno)
            line = stmt.lineno
            if isinstance(stmt, (ast.Pass, ast.Assert)) or (isinstance(stmt, ast.Expr)
                                                           and isinstance(stmt.value, ast.Constant)):
                continue
            call = stmt.value if isinstance(stmt, ast.Expr) and isinstance(stmt.value, ast.Call) else None
            if call is not None and call_name(call) in SEED_CALLS:
                self.seed = self._seed(call, line)
                continue
            if call is not None and (call_name(call) == "print" or self._context_call(call, line)):
                continue
            if isinstance(stmt, ast.Return) and stmt.value is None and stmt is stmts[-1]:
                continue
            if isinstance(stmt, ast.If):
                c = self.expr(stmt.test, env, line)
                if c.rand:
                    raise self.refuse(line, f"a random test in {name}() is not supported")
                yes = self._hook_run(stmt.body, copy_env(env), name)
                no = self._hook_run(stmt.orelse, copy_env(env), name)
                env = merge(c.text, env, yes, no)
                continue
            state = self._assign(stmt, env)
            if state is None:
                raise self.refuse(line, f"{name}() does more than set globals and seed the random generator "
                                        f"({construct(stmt)}): not supported")
            env = state
        return env

    def _assign(self, stmt, env: dict) -> dict | None:
        """``global``, or an assignment to a local or a declared global: the new env
        (a global's new value is kept under ``set NAME`` too); None for another statement."""
        if isinstance(stmt, ast.Global):
            names = [n for n in stmt.names if n in self.mutable]     # the others are only read
            for n in names:
                if safe(n) not in self.globals:
                    raise self.refuse(stmt.lineno, f"global {n} is set, but " + self.lazy.get(
                        n, f"{n} is a function") + ": plantgen's globals are numbers")
            return {**env, **{f"global {n}": Val("") for n in names}}
        if isinstance(stmt, ast.AugAssign) and isinstance(stmt.target, ast.Name):
            value, name = ast.BinOp(ast.Name(stmt.target.id, ast.Load()), stmt.op, stmt.value), stmt.target.id
        elif isinstance(stmt, ast.Assign) and len(stmt.targets) == 1 and isinstance(stmt.targets[0], ast.Name):
            value, name = stmt.value, stmt.targets[0].id
        else:
            return None
        if f"global {name}" not in env:
            v = self.expr(value, env, stmt.lineno)
            return {**env, name: Val(v.text, v.rand)}
        probe = {k: (Val(v.text, v.rand, v.used, v.span, v.error) if v.rand or k == name else v)
                 for k, v in env.items()}     # what it reads of a random local is not spent (it may be dropped)
        own = probe.get(name)
        if own is not None:
            own.used = False     # its value so far: the new one replaces it
        try:
            v = self.expr(value, probe, stmt.lineno)
        except LpyError as exc:
            why = str(exc).split(": ", 1)[-1]
            return {**env, name: Val("", error=why), f"set {safe(name)}": Val("", error=why)}
        shared = any(probe[k].used and not env[k].used for k in env if env[k].rand and k != name)
        if own is not None and probe[name].used:
            shared = shared or env.get(f"set {safe(name)}", own).used
        return {**env, name: Val(v.text, v.rand, used=v.rand), f"set {safe(name)}": Val(v.text, v.rand, shared)}

    def _seed(self, call: ast.Call, line: int) -> int:
        if len(call.args) != 1 or call.keywords:
            raise self.refuse(line, "random.seed takes one number here")
        val = self._constant(ast.unparse(call.args[0]), line, "random.seed's argument")
        if val != int(val) or not 0 <= val < 2 ** 63:
            raise self.refuse(line, f"random.seed's argument must be a whole number from 0, got {val:g}")
        return int(val)

    def _initialisation(self, tail: list[str], first: int) -> None:
        """``endlsystem``'s tail: the scalars of the INITIALISATION section become
        defines (where the rules have not defined the name); the rest is ignored."""
        text = "\n".join(tail)
        if not text.strip():
            return
        try:
            tree = ast_parse(text)
        except (SyntaxError, ValueError, RecursionError, MemoryError, OverflowError):
            self.warnings.append(f"{self.path}: warning: line {first}: the code after endlsystem is not read")
            return
        ignored = 0
        for node in ast.walk(tree):
            self.spend(first)
            if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "scalars"
                                                    for t in node.targets):
                self._scalars(node.value, first + node.lineno - 1)
            elif isinstance(node, ast.stmt) and not isinstance(node, (ast.FunctionDef, ast.If)):
                ignored += 1
        if ignored:
            self.warnings.append(f"{self.path}: warning: the INITIALISATION section (line {first}) is read only "
                                 "for its scalar parameters; materials, curves, functions and options are ignored")

    def _scalars(self, node, line: int) -> None:
        if not isinstance(node, (ast.List, ast.Tuple)):
            return
        for item in node.elts:
            if (isinstance(item, ast.Tuple) and len(item.elts) >= 3 and isinstance(item.elts[0], ast.Constant)
                    and isinstance(item.elts[0].value, str) and isinstance(item.elts[2], ast.Constant)
                    and isinstance(item.elts[2].value, (int, float))):
                name = item.elts[0].value
                if IDENT.match(name) and safe(name) not in self.defines and name not in self.functions:
                    value = float(item.elts[2].value)
                    if np.isfinite(value):
                        self.defines[safe(name)] = value
                        self.lazy.pop(name, None)

    def _inline(self, name: str, args: list, env: dict, line: int) -> Val:
        fn = self.functions[name]
        params = fn.args
        if params.vararg or params.kwarg or params.kwonlyargs or params.posonlyargs:
            raise self.refuse(line, f"function {name}: only plain parameters are supported")
        formals = [a.arg for a in params.args]
        defaults = params.defaults
        if not len(formals) - len(defaults) <= len(args) <= len(formals):
            raise self.refuse(line, f"{name}() takes {len(formals)} argument(s), got {len(args)}")
        values = [self.expr(a, env, line) for a in args]
        values += [self.expr(d, {}, line) for d in defaults[len(defaults) - (len(formals) - len(args)):]]
        local = {f: Val(v.text, v.rand) for f, v in zip(formals, values, strict=True)}
        self.calls += 1
        if self.calls > MAX_CALL_DEPTH:
            raise self.refuse(line, f"function calls nested deeper than {MAX_CALL_DEPTH}: a recursive function "
                                    f"such as {name}() cannot be translated")
        try:
            if isinstance(fn, ast.Lambda):
                return self.expr(fn.body, local, line)
            return self._body_value(fn.body, local, name)
        finally:
            self.calls -= 1

    def _body_value(self, stmts: list, env: dict, name: str) -> Val:
        """The value a function body returns: assignments substituted, each ``if``
        a ``select`` between the values its branches (and what follows them) return."""
        for i, stmt in enumerate(stmts):
            self.spend(stmt.lineno)
            if isinstance(stmt, ast.Return):
                if stmt.value is None:
                    raise self.refuse(stmt.lineno, f"function {name}() returns no value")
                return self.expr(stmt.value, env, stmt.lineno)
            if isinstance(stmt, ast.Global):
                env = {**env, **{f"global {n}": Val("") for n in stmt.names}}
                continue
            targets = stmt.targets if isinstance(stmt, ast.Assign) else [getattr(stmt, "target", None)]
            if any(isinstance(t, ast.Name) and f"global {t.id}" in env for t in targets):
                raise self.refuse(stmt.lineno, f"function {name}() sets a global: plantgen inlines functions "
                                               "into expressions, which cannot set anything")
            if isinstance(stmt, ast.Assign) and len(stmt.targets) == 1 and isinstance(stmt.targets[0], ast.Name):
                v = self.expr(stmt.value, env, stmt.lineno)
                env = {**env, stmt.targets[0].id: Val(v.text, v.rand)}
                continue
            if isinstance(stmt, ast.AugAssign) and isinstance(stmt.target, ast.Name):
                v = self.expr(ast.BinOp(ast.Name(stmt.target.id, ast.Load()), stmt.op, stmt.value), env, stmt.lineno)
                env = {**env, stmt.target.id: Val(v.text, v.rand)}
                continue
            if isinstance(stmt, ast.If):
                c = self.expr(stmt.test, env, stmt.lineno)
                rest = stmts[i + 1:]
                a = self._body_value(stmt.body + rest, copy_env(env), name)
                b = self._body_value(stmt.orelse + rest, copy_env(env), name)
                return Val(f"select({c.text}, {a.text}, {b.text})", c.rand or a.rand or b.rand)
            if isinstance(stmt, ast.Pass) or (isinstance(stmt, ast.Expr) and isinstance(stmt.value, ast.Constant)):
                continue
            raise self.refuse(stmt.lineno, f"{construct(stmt)} in function {name}() is not supported "
                                           "(only assignments, if and return)")
        raise self.refuse(stmts[-1].lineno if stmts else 0, f"function {name}() may end without returning a value")

    # ------------------------------------------------------------ rules
    def _rule(self, section: str, lines: list) -> None:
        no, header = lines[0]
        if "-->" in header:
            lhs, rhs = header.split("-->", 1)
            if any(t.strip() for _, t in lines[1:]):
                raise self.refuse(lines[1][0], "an indented block after a '-->' rule")
            body = None
        elif len(split_top(header, ":")) > 1:
            parts = split_top(header, ":")
            lhs, rest, rhs = parts[0], ":".join(parts[1:]), None
            body = ([(no, "    " + rest.strip())] if rest.strip() else []) + lines[1:]
        else:
            raise self.refuse(no, f"not a rule (expected 'predecessor --> successor' or 'predecessor :' and a "
                                  f"block): {header.strip()[:60]!r}")
        self.pattern_conds: list[str] = []
        left, pred, right = self._predecessor(lhs, no)
        env = {p: Val(p) for m in (*left[0], *left[1], *pred, *right) for p in m.args}
        self.if_ids += 1
        fixed = [(self.if_ids, True, c, False, no) for c in self.pattern_conds]
        if body is None:
            succ = self._successor(rhs, no, env)
            self._emit(section, left, pred, right, [Way(fixed, succ, no)], no)
            return
        paths = self._block(body, env)
        for path in paths:
            path.conds = fixed + path.conds
        self._emit(section, left, pred, right, paths, no)

    def _predecessor(self, text: str, line: int):
        """The left context (old and new, ``<`` and ``<<``, each a list of modules), the
        strict predecessor's modules and the right context of a rule's left-hand side."""
        if ">>" in text:
            raise self.refuse(line, "the new right context '>>' (a right-to-left step) is not supported")
        left_src, new_src, right_src = "", "", ""
        if "<<" in text:
            new_src, text = text.split("<<", 1)
            if "<" in new_src:
                left_src, new_src = new_src.split("<", 1)
        elif "<" in text:
            left_src, text = text.split("<", 1)
        if ">" in text:
            text, right_src = text.split(">", 1)
        pred = self._lstring(text, line, {}, pattern=True)
        if not pred:
            raise self.refuse(line, "a rule without a predecessor module")
        left, new_left, right = (self._lstring(src, line, {}, pattern=True) for src in (left_src, new_src, right_src))
        if any(m.name in "[]" for m in (*left, *new_left, *pred)):
            raise self.refuse(line, "brackets in a predecessor or a left context are not supported")
        return (left, new_left), pred, right

    def _successor(self, text: str, line: int, env: dict) -> list[Mod]:
        text = text.strip()
        if text in ("*", ""):
            return []
        return self._lstring(text, line, env, pattern=False)

    def _placeholders(self, body: list, what: str) -> list:
        """A block's lines parsed, each ``produce L-string`` a placeholder call."""
        first = body[0][0] if body else 0
        texts = [t for _, t in body]
        source = textwrap.dedent("\n".join(t.expandtabs(4) for t in texts))
        out_lines = []
        for k, text in enumerate(source.split("\n")):
            m = PRODUCE.search(text)
            if m:
                self.lstrings.append((strip_comment(m.group(3)), first + k))
                fn = "__nproduce__" if m.group(2) == "nproduce" else "__produce__"
                text = text[:m.start()] + f"{m.group(1)}{fn}({len(self.lstrings) - 1})"
            out_lines.append(text)
        return self._parse_block("\n".join(out_lines), first, what)

    def _block(self, body: list, env: dict) -> list[Way]:
        first = body[0][0] if body else 0
        stmts = self._placeholders(body, "rule block")
        paths: list[Way] = []
        live = self._run(stmts, [(env, [], [])], paths)
        for env_, conds, pending in live:   # the block's end: what nproduce gave, if anything
            paths.append(Way(conds, pending if pending else None, stmts[-1].lineno if stmts else first,
                               env_effects(env_)))
        return paths

    def _run(self, stmts: list, states: list, paths: list) -> list:
        """Run ``stmts`` symbolically from each state (env, conds, pending modules):
        paths ending in produce go to ``paths``; the states still running come back."""
        for stmt in stmts:
            if not states:
                break
            self.spend(stmt.lineno)
            line = stmt.lineno
            nxt = []
            if isinstance(stmt, ast.If):
                for env, conds, pending in states:
                    self.if_ids += 1                    # one test per state: a way through the rule
                    ident = self.if_ids
                    split = self._uniform_test(stmt.test, env)
                    if split is not None:
                        nxt += self._split(stmt, split, (env, conds, pending), paths)
                        continue
                    c = self.expr(stmt.test, env, line)
                    yes = self._run(stmt.body, [(copy_env(env), [*conds, (ident, True, c.text, c.rand, line)],
                                                 list(pending))], paths)
                    no = self._run(stmt.orelse, [(copy_env(env), [*conds, (ident, False, c.text, c.rand, line)],
                                                  list(pending))], paths)
                    nxt += yes + no
            elif isinstance(stmt, ast.For):
                nxt = self._for(stmt, states, paths)
            elif (isinstance(stmt, ast.Assign) and len(stmt.targets) == 1 and isinstance(stmt.targets[0], ast.Name)
                  and isinstance(stmt.value, (ast.Call, ast.IfExp))):
                name = stmt.targets[0].id
                for env, conds, pending in states:
                    alts = None if f"global {name}" in env else self._alternatives(stmt.value, env, line)
                    if alts is None or all(w == 1.0 for _, _, w in alts):
                        state = self._simple(stmt, env, conds, pending, paths)
                        nxt += [state] if state is not None else []
                        continue
                    self.if_ids += 1
                    for extra, text, w in alts:        # one stochastic alternative per value
                        nxt.append(({**copy_env(env), name: Val(text)}, [*conds, *extra, (self.if_ids, True, None, w,
                                                                                           line)], list(pending)))
            elif (isinstance(stmt, ast.Expr) and isinstance(stmt.value, ast.Call)
                  and call_name(stmt.value) in self.producers):
                call = stmt.value
                if call.keywords or any(isinstance(a, ast.Starred) for a in call.args):
                    raise self.refuse(line, f"keyword or starred arguments in a call to {call_name(call)}")
                for state in states:
                    nxt += self._producer(call_name(call), call.args, state, paths)
            else:
                for env, conds, pending in states:
                    state = self._simple(stmt, env, conds, pending, paths)
                    if state is not None:
                        nxt.append(state)
            states = nxt
        return states

    def _uniform_test(self, test, env: dict):
        """``r < c`` (or ``<=``, ``>``, ``>=``, either side) with ``r`` a local holding
        ``random()`` and ``c`` a constant: (r, the interval where the test holds)."""
        if not (isinstance(test, ast.Compare) and len(test.ops) == 1):
            return None
        left, right, op = test.left, test.comparators[0], type(test.ops[0])
        if isinstance(right, ast.Name) and right.id in env and env[right.id].span is not None:
            left, right = right, left
            op = {ast.Lt: ast.Gt, ast.LtE: ast.GtE, ast.Gt: ast.Lt, ast.GtE: ast.LtE}.get(op)
        if not (isinstance(left, ast.Name) and left.id in env and env[left.id].span is not None) or op not in (
                ast.Lt, ast.LtE, ast.Gt, ast.GtE):
            return None
        try:
            c = evaluate(self.expr(right, {}, test.lineno).text, self.defines)
        except (LpyError, ExprError):
            return None
        lo, hi = env[left.id].span
        t = min(max(c, lo), hi)
        below, above = (lo, t), (t, hi)
        return left.id, (below, above) if op in (ast.Lt, ast.LtE) else (above, below)

    def _split(self, stmt: ast.If, split, state, paths: list) -> list:
        """An ``if`` on a uniform draw: its branches become stochastic alternatives, each
        as likely as the part of the draw's interval it keeps."""
        name, (yes, no) = split
        env, conds, pending = state
        lo, hi = env[name].span
        out = []
        for body, (a, b) in ((stmt.body, yes), (stmt.orelse, no)):
            weight = (b - a) / (hi - lo) if hi > lo else 0.0
            if weight <= 0:
                continue
            self.if_ids += 1
            branch_env = copy_env(env)
            branch_env[name].span = (a, b)
            out += self._run(body, [(branch_env, [*conds, (self.if_ids, True, None, weight, stmt.lineno)],
                                     list(pending))], paths)
        return out

    def _alternatives(self, node, env: dict, line: int) -> list | None:
        """The values ``node`` may take, for a rule to fork on: ``randint(a, b)`` (bounds
        that differ by a constant, at most 32 values) or ``choice([...])``, each value as
        likely; a conditional expression over them (its test, not random, a condition of
        each alternative); a lambda returning one. [(tests, value text, probability)], or
        None when ``node`` draws no such choice (or plantgen cannot enumerate it)."""
        try:
            return self._enumerate(node, env, line)
        except (LpyError, ExprError):
            return None

    def _enumerate(self, node, env: dict, line: int) -> list | None:
        if isinstance(node, ast.IfExp):
            c = self.expr(node.test, env, line)
            yes, no = self._enumerate(node.body, env, line), self._enumerate(node.orelse, env, line)
            if c.rand or yes is None or no is None:
                return None
            self.if_ids += 1
            return ([([(self.if_ids, True, c.text, False, line), *t], v, w) for t, v, w in yes]
                    + [([(self.if_ids, False, c.text, False, line), *t], v, w) for t, v, w in no])
        name = call_name(node) if isinstance(node, ast.Call) else None
        fn = self.functions.get(name or "")
        if isinstance(fn, ast.Lambda) and not node.keywords and len(node.args) == len(fn.args.args) and not (
                fn.args.vararg or fn.args.kwarg or fn.args.kwonlyargs or fn.args.posonlyargs):
            values = [self.expr(a, env, line) for a in node.args]
            if any(v.rand for v in values):
                return None
            self.calls += 1
            try:
                if self.calls > MAX_CALL_DEPTH:
                    return None
                return self._enumerate(fn.body, {p.arg: v for p, v in zip(fn.args.args, values, strict=True)}, line)
            finally:
                self.calls -= 1
        base, _, attr = (name or "").rpartition(".")
        if name is None or name in self.functions or self.aliases.get(base, base) not in ("", "random") \
                or attr not in ("randint", "choice") or node.keywords:
            v = self.expr(node, env, line)           # a plain value: one alternative, certain
            return None if v.rand else [([], v.text, 1.0)]
        if attr == "randint" and len(node.args) == 2:
            width = self._width(*node.args, env, line)
            lo = self.expr(node.args[0], env, line)
            if width is None or not 0 <= width <= 31 or lo.rand:
                return None
            try:
                first = evaluate(lo.text, self.defines)
            except ExprError:                         # a lower bound that changes: one test per value
                return self._enumerate_bound(lo.text, width, line)
            if first != int(first):
                return None
            return [([], str(int(first) + k), 1.0 / (width + 1)) for k in range(width + 1)]
        seq = node.args[0] if len(node.args) == 1 else None
        if attr != "choice" or not isinstance(seq, (ast.List, ast.Tuple)) or not 1 <= len(seq.elts) <= 32:
            return None
        vals = [self.expr(e, env, line) for e in seq.elts]
        return None if any(v.rand for v in vals) else [([], v.text, 1.0 / len(vals)) for v in vals]

    def _enumerate_bound(self, lo: str, width: int, line: int) -> list:
        """``randint(lo, lo + width)`` with ``lo`` a module's value: for each whole ``lo``
        from 0 to :data:`MAX_DYNAMIC_COUNT`, the test ``lo == m`` and the values ``m`` to
        ``m + width``, each as likely (so a loop over the draw unrolls); a module whose
        ``lo`` is another value is left unchanged, with a warning."""
        self.if_ids += 1
        ident = self.if_ids
        self.warnings.append(f"{self.path}: warning: line {line}: randint({lo[:40]}, ...) is enumerated for a lower "
                             f"bound from 0 to {MAX_DYNAMIC_COUNT}; a module asking another is left unchanged")
        return [([(ident * 1000 + m, True, f"{wrap(lo)} == {m}", False, line)], str(m + k), 1.0 / (width + 1))
                for m in range(MAX_DYNAMIC_COUNT + 1) for k in range(width + 1)]

    def _width(self, lo, hi, env: dict, line: int) -> int | None:
        """``hi - lo`` where it is a whole constant: computed, or read from the two
        expressions' shapes (``5 - x`` and ``4 - x`` differ by 1 whatever ``x``)."""
        try:
            a, b = (evaluate(self.expr(n, env, line).text, self.defines) for n in (lo, hi))
            return int(b - a) if b - a == int(b - a) else None
        except (LpyError, ExprError):
            pass
        if ast.dump(lo) == ast.dump(hi):
            return 0
        if isinstance(lo, ast.BinOp) and isinstance(hi, ast.BinOp) and type(lo.op) is type(hi.op) and isinstance(
                lo.op, (ast.Add, ast.Sub)):
            if ast.dump(lo.right) == ast.dump(hi.right):
                return self._width(lo.left, hi.left, env, line)
            if ast.dump(lo.left) == ast.dump(hi.left):
                inner = self._width(lo.right, hi.right, env, line)
                return None if inner is None else (inner if isinstance(lo.op, ast.Add) else -inner)
        return None

    def _choice_values(self, call: ast.Call) -> list[str] | None:
        name = call_name(call) or ""
        fn = self.functions.get(name)
        if isinstance(fn, ast.Lambda) and isinstance(fn.body, ast.Call):   # nb = lambda o: randint(3, 5)
            return self._choice_values(fn.body)
        base, _, attr = name.rpartition(".")
        if self.aliases.get(base, base) not in ("", "random") or attr not in ("randint", "choice") or name in \
                self.functions or len(call.args) != (2 if attr == "randint" else 1) or call.keywords:
            return None
        try:
            if attr == "randint":
                lo, hi = (evaluate(self.expr(a, {}, call.lineno).text, self.defines) for a in call.args)
                if lo != int(lo) or hi != int(hi) or not 1 <= hi - lo + 1 <= 32:
                    return None
                return [str(k) for k in range(int(lo), int(hi) + 1)]
            seq = call.args[0]
            if not isinstance(seq, (ast.List, ast.Tuple)) or not 1 <= len(seq.elts) <= 32:
                return None
            vals = [self.expr(e, {}, call.lineno) for e in seq.elts]
            return None if any(v.rand for v in vals) else [v.text for v in vals]
        except (LpyError, ExprError):
            return None

    def _simple(self, stmt, env, conds, pending, paths):
        line = stmt.lineno
        if isinstance(stmt, ast.Expr) and isinstance(stmt.value, ast.Call) and call_name(stmt.value) in (
                "__produce__", "__nproduce__"):
            text, at = self.lstrings[stmt.value.args[0].value]
            mods = pending + self._successor(text, at, env)
            if len(mods) > MAX_SUCCESSOR:
                raise self.refuse(line, f"a rule produces more than {MAX_SUCCESSOR:,} modules")
            if call_name(stmt.value) == "__produce__":
                paths.append(Way(conds, mods, line, env_effects(env)))
                return None
            return env, conds, mods
        if isinstance(stmt, ast.Global) or (isinstance(stmt, (ast.Assign, ast.AugAssign)) and any(
                isinstance(t, ast.Name) and f"global {t.id}" in env
                for t in (stmt.targets if isinstance(stmt, ast.Assign) else [stmt.target]))):
            return self._assign(stmt, env), conds, pending
        if isinstance(stmt, ast.Assign) and len(stmt.targets) == 1 and isinstance(stmt.targets[0], ast.Name):
            v = self.expr(stmt.value, env, line)
            uniform = v.text == "random()"           # a draw its tests split into alternatives
            return {**env, stmt.targets[0].id: Val(v.text, v.rand, span=(0.0, 1.0) if uniform else None)}, \
                conds, pending
        if isinstance(stmt, ast.AugAssign) and isinstance(stmt.target, ast.Name):
            v = self.expr(ast.BinOp(ast.Name(stmt.target.id, ast.Load()), stmt.op, stmt.value), env, line)
            return {**env, stmt.target.id: Val(v.text, v.rand)}, conds, pending
        if isinstance(stmt, ast.Return):
            if stmt.value is not None:
                raise self.refuse(line, "return with a value in a rule (use produce)")
            paths.append(Way(conds, pending or None, line, env_effects(env)))    # what nproduce gave, as L-Py does
            return None
        if isinstance(stmt, ast.Pass) or (isinstance(stmt, ast.Expr) and isinstance(stmt.value, ast.Constant)):
            return env, conds, pending
        if isinstance(stmt, ast.Expr) and isinstance(stmt.value, ast.Call) and call_name(stmt.value) == "print":
            return env, conds, pending
        if isinstance(stmt, ast.Expr) and isinstance(stmt.value, ast.Call):
            name = call_name(stmt.value) or ast.unparse(stmt.value.func)[:40]
            raise self.refuse(line, f"call of {name}() as a statement in a rule is not supported (only a "
                                    "module-level function that produces modules is inlined there)")
        raise self.refuse(line, f"{construct(stmt)} in a rule is not supported")

    def _for(self, stmt: ast.For, states: list, paths: list) -> list:
        line = stmt.lineno
        it = stmt.iter
        if (stmt.orelse or not isinstance(stmt.target, ast.Name) or not isinstance(it, ast.Call)
                or call_name(it) != "range" or not 1 <= len(it.args) <= 3):
            raise self.refuse(line, "a for loop other than 'for NAME in range(...)' is not supported")
        if any(isinstance(n, (ast.Break, ast.Continue)) for n in ast.walk(stmt)):
            raise self.refuse(line, "break and continue are not supported")
        out = []
        counts = self._choice_values(it.args[0]) if len(it.args) == 1 and isinstance(it.args[0], ast.Call) else None
        if counts is not None:                 # range(randint(a, b)): one alternative per count
            self.if_ids += 1
            choice = (self.if_ids, True, None, 1.0 / len(counts), line)
            for env, conds, pending in states:
                for k in counts:
                    n = int(float(k))
                    out += self._unroll(stmt, max(n, 0), range(n), (copy_env(env), [*conds, choice], list(pending)),
                                        paths)
            return out
        for env, conds, pending in states:
            bounds = []
            for a in it.args:
                v = self.expr(a, env, line)
                try:
                    x = evaluate(v.text, self.defines) if not v.rand else None
                except ExprError:
                    x = None
                if x is None and len(it.args) == 1 and not v.rand:
                    out += self._dynamic_for(stmt, v.text, (env, conds, pending), paths)
                    break
                if x is None or x != int(x):
                    raise self.refuse(line, "range() of a random draw or of a value that is not whole: plantgen "
                                            "unrolls loops of a known count only")
                bounds.append(int(x))
            else:
                count = len(range(*bounds)) if bounds[-1] != 0 or len(bounds) < 3 else 0
                out += self._unroll(stmt, count, range(*bounds) if count else (), (env, conds, pending), paths)
        return out

    def _unroll(self, stmt: ast.For, count: int, values, state, paths: list) -> list:
        self._count_loops(count, stmt.lineno)
        cur = [state]
        for i in values:
            cur = [({**e, stmt.target.id: Val(str(i))}, c, p) for e, c, p in cur]
            cur = self._run(stmt.body, cur, paths)
        return cur

    def _count_loops(self, count: int, line: int) -> None:
        self.loops += count
        if self.loops > MAX_LOOP_ITERATIONS:
            raise LimitError(f"{self.path}: line {line}: loops unroll to over {MAX_LOOP_ITERATIONS:,} "
                             "iterations in all")

    def _dynamic_for(self, stmt: ast.For, count: str, state, paths: list) -> list:
        """``for i in range(n)`` with ``n`` a module parameter: one way through the rule
        per count from 0 to :data:`MAX_DYNAMIC_COUNT`, each under the test that ``n``
        gives that count; a larger count leaves the module unchanged, with a warning."""
        env, conds, pending = state
        self.if_ids += 1
        ident = self.if_ids
        times = f"max(0, ceil({count}))"
        out = []
        for k in range(MAX_DYNAMIC_COUNT + 1):
            cond = (ident * 1000 + k, True, f"{times} == {k}", False, stmt.lineno)
            out += self._unroll(stmt, k, range(k), (copy_env(env), [*conds, cond], list(pending)), paths)
        paths.append(Way([*conds, (ident * 1000 + MAX_DYNAMIC_COUNT + 1, True, f"{times} > {MAX_DYNAMIC_COUNT}",
                                     False, stmt.lineno)], None, stmt.lineno))
        self.warnings.append(f"{self.path}: warning: line {stmt.lineno}: range({count[:40]}) is unrolled for counts "
                             f"up to {MAX_DYNAMIC_COUNT}; a module asking more is left unchanged")
        return out

    def _taken_later(self, section: str, name: str) -> bool:
        """Whether a later rule of ``section`` may rewrite a module ``name`` (its name is
        written before its ``-->`` or ``:``)."""
        word = re.compile(rf"(?<![\w@~?]){re.escape(name)}(?!\w)")
        return any(s == section and word.search(re.split(r"-->|:", h, maxsplit=1)[0]) for s, h in self.later)

    def _emit(self, section, left, pred, right, paths: list[Way], line: int) -> None:
        """Plantgen rules from a block's paths, in order: a test whose other branch always
        produces is left out of the later paths (the earlier rule took those modules)."""
        if any(p.modules is None and any(c[2] is None for c in p.conds) for p in paths) and not any(
                self._taken_later(section, m.name) for m in pred):
            for p in paths:      # a random alternative that leaves the modules unchanged: no later rule
                if p.modules is None and any(c[2] is None for c in p.conds) and not p.effects:
                    p.modules = [Mod(m.name, [Val(a) for a in m.args], p.line) for m in pred]   # to themselves
        leaky = {(c[0], c[1]) for p in paths if p.modules is None for c in p.conds}
        emitted = []
        for p in paths:
            if p.modules is None:
                if p.effects:
                    raise self.refuse(p.line, "a way through the rule that sets a global but produces nothing "
                                              "(the module left unchanged): not supported")
                continue
            conds = []
            for ident, holds, text, rand, at in p.conds:
                if not holds and (ident, True) not in leaky:
                    continue           # the modules where it holds were all rewritten already
                conds.append((ident, holds, text, rand, at))
            emitted.append((conds, p))
        seen: dict = {}
        for conds, _ in emitted:
            for ident, _holds, text, rand, at in conds:
                if rand and text is not None:
                    seen[ident] = seen.get(ident, 0) + 1
                    if seen[ident] > 1:
                        raise self.refuse(at, "a random test on which more than one way through the rule "
                                              "depends: plantgen would draw it anew for each")
        rules, weights = [], {}
        for conds, p in emitted:
            tests = [c for c in conds if c[2] is not None]
            text = " && ".join(wrap(t) if h else f"!{wrap(t)}" for _, h, t, _, _ in tests)
            if len(tests) == 1 and tests[0][1]:
                text = tests[0][2]
            weight = float(np.prod([c[3] for c in conds if c[2] is None]))
            weights[text] = weights.get(text, 0.0) + weight
            rules.append((left, pred, right, [text] if text else [], p.modules, p.line,
                          weight if len(conds) > len(tests) else None, p.effects))
        for r in rules:
            if r[6] is not None and abs(weights[r[3][0] if r[3] else ""] - 1) > 1e-9:
                raise self.refuse(r[5], "a random choice (randint, choice) in a branch that may leave the module "
                                        "unchanged: plantgen's stochastic rules always rewrite it")
        self.rules[section] += rules

    # ------------------------------------------------------------ output
    def _prune_globals(self) -> None:
        """Keep the globals something drawn reads (a condition, a module's argument, a
        kept global's new value); the others, and what sets them, are dropped (a label's
        text, a counter printed). Refuse what a kept one needs that plantgen lacks."""
        if not self.globals:
            return
        def names(text: str) -> set:
            return set(ATOM.findall(text)) & set(self.globals)
        read: set = set()
        for m in self.axiom:
            read |= {n for a in m.args for n in names(a.text)}
        sets = [(k, v, 0, key) for key, hook in self.hooks.items() for k, v in hook.items()]
        for sec, rules in self.rules.items():
            for _left, _pred, _right, cond, succ, line, _p, effects in rules:
                read |= {n for c in cond for n in names(c)}
                read |= {n for m in succ for a in m.args for n in names(a.text)}
                sets += [(k, v, line, sec) for k, v in effects]
        sets += [(k, v, line, "axiom") for k, v, line in self.axiom_effects]
        live, grown = set(read), True
        while grown:
            new = {n for k, v, _, _ in sets if k in live for n in names(v.text)}
            grown = not new <= live
            live |= new
        for k, v, line, where in sets:
            if k not in live:
                continue
            if v.error:
                raise self.refuse(0, v.error)           # the message names its line
            if where == "axiom":
                raise self.refuse(line, f"the axiom's block sets the global {k}, which the rules read: not supported")
            if where == "interpretation":
                raise self.refuse(line, f"an interpretation rule sets the global {k}: not supported")
            if v.used:
                raise self.refuse(line, f"the global {k} is set from a random draw held in a local variable"
                                        + ("" if line else f" (in {where})") + ": not supported")
        self.globals = {k: v for k, v in self.globals.items() if k in live}
        self.hooks = {key: kept for key, hook in self.hooks.items()
                      if (kept := {k: v for k, v in hook.items() if k in live})}

    def build(self, stem: str) -> LpyModel:
        self._prune_globals()
        names: dict[str, str] = {}
        everything = list(self.axiom)
        for sec in self.rules.values():
            for (left, new_left), pred, right, _, succ, *_ in sec:
                everything += [*left, *new_left, *pred, *right, *succ]
        self.carried = {m.name: max(len(m.args), self.carried.get(m.name, 0)) for m in everything
                        if m.name in TURTLE and len(m.args) > turtle_params(TURTLE[m.name])}
        user = [m.name for m in everything if m.name not in TURTLE or m.name in self.carried]
        singles = {n for n in user if len(n) == 1}
        free = (c for c in CANDIDATES if c not in singles and c not in PLANTGEN_CHARS)
        for n in user:
            if n in names:
                continue
            if len(n) == 1 and n.isalpha() and n not in PLANTGEN_CHARS:
                names[n] = n
            else:
                names[n] = next(free, None)
                if names[n] is None:
                    raise self.refuse(0, "more distinct modules than plantgen has symbols for")
        self.names = names
        data: dict = {"name": stem, "description": f"read from the L-Py file {Path(self.path).name}",
                      "seed": self.seed, "iterations": self.iterations}
        if self.defines:
            data["defines"] = {k: (int(v) if float(v).is_integer() and abs(v) < 2 ** 53 else v)
                               for k, v in self.defines.items()}
        if self.globals:
            data["globals"] = {k: (int(v) if float(v).is_integer() and abs(v) < 2 ** 53 else v)
                               for k, v in self.globals.items()}
        if self.hooks:
            data["hooks"] = {key: {k: v.text for k, v in hook.items()} for key, hook in self.hooks.items()}
        axiom = self._text(self.axiom)
        data["axiom"] = axiom if axiom.strip() else "[]"
        data["rules"] = [self._rule_text(r) for r in self.rules["production"]]
        for key in ("decomposition", "interpretation"):
            if self.rules[key]:
                data[key] = [self._rule_text(r) for r in self.rules[key]]
                data[f"{key}_depth"] = self.max_depth[key]
        for name, n in self.carried.items():   # a turtle module carrying more parameters: drawn as itself
            sym, keep = TURTLE[name], turtle_params(TURTLE[name])
            params = [f"p{i}" for i in range(n)]
            drawn = (["leaf"] if sym == "~" else []) + params[:keep]
            data.setdefault("interpretation", []).append(
                f"{names[name]}({', '.join(params)}) -> {sym}" + (f"({', '.join(drawn)})" if drawn else ""))
        drawn_as = {}
        for m in everything:
            if m.name in DRAWN_AS:
                drawn_as.setdefault(m.name, set()).add(len(m.args))
        if drawn_as and "interpretation_depth" in data:    # the file's interpretation rules may produce one
            data["interpretation_depth"] += 1
        for name, counts in drawn_as.items():   # an L-Py drawing module plantgen draws its own way
            for n in sorted(counts):
                params = ", ".join(f"p{i}" for i in range(n))
                data.setdefault("interpretation", []).append(
                    f"{names[name]}({params}) -> {DRAWN_AS[name][1]}")
        ignore = self._ignore()
        if ignore:
            data["ignore"] = ignore
        turtle = {"angle": self.angle}
        if self.tropism:
            turtle["tropism"] = {"direction": self.tropism.get("direction", [0.0, -1.0, 0.0]),
                                 "strength": self.tropism.get("strength", 0.0)}
        data["turtle"] = turtle
        if self.used_colour:
            data["materials"] = ["bark", "leaf", *(f"colour{i}" for i in range(2, 16))]
        for name, count in self.dropped.items():
            what = UNDRAWN.get(name, "surface")
            self.warnings.append(f"{self.path}: warning: {name!r} ({what}) is not drawn by plantgen; "
                                 f"{count:,} place(s) in the file dropped")
        return LpyModel(data, tuple(self.warnings), {k: v for k, v in names.items() if k != v})


# ------------------------------------------------------------------ entry points
def parse_lpy(text: str, path: str = "<lpy>", limits: Limits | None = None) -> LpyModel:
    """Translate the text of an ``.lpy`` file (see the module's notes)."""
    limits = limits or default_limits
    reader = _Reader(text, path, limits)
    try:
        reader.read()
        return reader.build(Path(path).stem)
    except RecursionError:
        raise LpyError(f"{path}: nested too deeply to translate") from None


def read_lpy(path: str | Path, limits: Limits | None = None) -> LpyModel:
    """Read and translate an ``.lpy`` file (at most ``max_input_bytes``)."""
    limits = limits or default_limits
    return parse_lpy(read_text(path, LpyError, limits, "L-Py"), str(path), limits)


def to_yaml(model: LpyModel) -> str:
    """The grammar mapping as a YAML grammar file, its first lines saying where it came
    from and which modules were renamed."""
    head = [f"# Converted from the L-Py model {Path(model.data.get('name', 'model')).name}.lpy by plantgen convert."]
    if model.names:
        head.append("# Modules renamed to plantgen's one-character symbols:")
        head += [f"#   {k} -> {v}" for k, v in model.names.items()]
    body = yaml.safe_dump(model.data, sort_keys=False, allow_unicode=True, width=10_000, default_flow_style=False)
    return "\n".join(head) + "\n" + body


def read_grammar_data(path: str | Path, error: type[PlantgenError] = PlantgenError,
                      limits: Limits | None = None) -> tuple[object, tuple[str, ...]]:
    """A grammar file's mapping and the warnings its reading gave: an ``.lpy`` file
    translated, any other read as YAML (the one place a grammar path is dispatched)."""
    if Path(path).suffix.lower() == LPY_SUFFIX:
        model = read_lpy(path, limits)
        return model.data, model.warnings
    return read_yaml(path, error, limits), ()
