"""Rules and globals: what the translation gathers, made into the grammar mapping.

:class:`GlobalsReader` reads what sets globals: module-level assignments (defines, tables,
vectors), ``seed``, the ``Start``/``StartEach``/``EndEach``/``End`` hooks (the grammar's
``globals`` and ``hooks``), a rule's ``global`` assignments, the ``INITIALISATION``
section's scalars; a global nothing drawn reads is dropped with what sets it.
:class:`RuleBuilder` reads a rule's head (predecessor, context), turns each way through its
block into a plantgen rule and builds the :class:`~.common.LpyModel`."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np

from ..expr import ExprError, evaluate
from .common import (
    ATOM,
    IDENT,
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
    safe,
    split_top,
    wrap,
)
from .drawn import CANDIDATES, DRAWN_AS, PLANTGEN_CHARS, TURTLE, UNDRAWN, turtle_params

#: The hooks that may set globals: plantgen's grammar hook each becomes.
_STATE_HOOKS = {"Start": "start", "StartEach": "start_each", "EndEach": "end_each", "End": "end"}


class GlobalsReader:
    """The reader's part that reads globals, hooks and module-level values."""

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


class RuleBuilder:
    """The reader's part that builds the rules and the grammar mapping."""

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
