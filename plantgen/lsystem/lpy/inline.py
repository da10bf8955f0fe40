"""Inlining and unrolling: how a rule's Python block becomes plantgen rules.

:class:`Inliner` inlines a module-level function into the expression that calls it (its
body's value, nested at most :data:`~.common.MAX_CALL_DEPTH` deep) and runs a function
that produces in place where a rule calls it. :class:`Unroller` walks a block
symbolically: each ``if``/``elif``/``else`` splits the way through (a test over a random
draw or a parameter's few values enumerated), ``for ... in range(...)`` is unrolled (at
most :data:`~.common.MAX_LOOP_ITERATIONS` iterations in all), local assignments are
substituted, and each way that ends in ``produce`` is a :class:`~.common.Way`."""

from __future__ import annotations

import ast
import textwrap

from ...limits import LimitError
from ..expr import ExprError, evaluate
from .common import (
    MAX_CALL_DEPTH,
    MAX_DYNAMIC_COUNT,
    MAX_LOOP_ITERATIONS,
    MAX_SUCCESSOR,
    LpyError,
    Val,
    Way,
    call_name,
    construct,
    copy_env,
    env_effects,
    wrap,
)
from .sections import PRODUCE, strip_comment


class Inliner:
    """The reader's part that inlines function calls and functions that produce."""

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


class Unroller:
    """The reader's part that walks a rule's block: its branches, loops and produce."""

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
