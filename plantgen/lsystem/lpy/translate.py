"""Translating L-Py's Python into plantgen's expression language, never running it.

:class:`StatementTranslator` reads the module-level code (constants become defines,
functions are kept to inline, ``import``/``seed``/``context()`` calls checked, anything else
refused naming the construct); :class:`ExpressionTranslator` turns a Python expression into
plantgen text (names, ``math`` and ``random`` calls, indexing a module-level table, inlined
function calls) and an L-string (``produce``'s text, an axiom, a pattern) into modules."""

from __future__ import annotations

import ast
import re

import numpy as np

from ..expr import MAX_EXPR_LENGTH, ExprError, evaluate
from .common import (
    HOOKS,
    IDENT,
    MAX_SUCCESSOR,
    SEED_CALLS,
    LpyError,
    Mod,
    Val,
    ast_parse,
    call_name,
    closing,
    construct,
    reason,
    safe,
    split_top,
    wrap,
)
from .drawn import DEFAULT_ARGS, DRAWN_AS, NAMED, REFUSED_MODULES, SILENT, SPECIAL, TROPISM, UNDRAWN

_MATH_ATTRS = {"pi": "pi", "e": "e"}
_MATH_FUNCS = {"sin": "sin", "cos": "cos", "tan": "tan", "asin": "asin", "acos": "acos", "atan": "atan",
               "atan2": "atan2", "sqrt": "sqrt", "exp": "exp", "log": "log", "fabs": "abs", "abs": "abs",
               "floor": "floor", "ceil": "ceil", "pow": "pow", "radians": "rad", "degrees": "deg",
               "min": "min", "max": "max", "round": "round", "trunc": "trunc", "int": "trunc"}
_RANDOM_FUNCS = {"random", "uniform", "randint", "choice", "gauss", "normalvariate"}
_PLANTGL = re.compile(r"plantgl|openalea")
_NUMBER = re.compile(r"-?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


class StatementTranslator:
    """The reader's part that reads module-level Python statements and constants."""

    def _int(self, text: str, line: int, what: str, lo: int, hi: int | None) -> int:
        val = self._constant(text, line, what)
        if val != int(val) or val < lo or (hi is not None and val > hi):
            rng = f"{lo} to {hi}" if hi is not None else f"at least {lo}"
            raise self.refuse(line, f"{what} must be a whole number {rng}, got {val:g}")
        if what == "derivation length":
            self.limits.check("iterations", int(val), f"{self.path}: line {line}: derivation length")
        return int(val)

    def _constant(self, text: str, line: int, what: str) -> float:
        node = self._parse_expr(text, line, what)
        val = self.expr(node, {}, line)
        if val.rand:
            raise self.refuse(line, f"{what} draws a random number; it must be a constant")
        try:
            return evaluate(val.text, self.defines)
        except ExprError as exc:
            raise self.refuse(line, f"{what}: {exc}") from None

    def _parse_expr(self, text: str, line: int, what: str) -> ast.expr:
        if len(text) > MAX_EXPR_LENGTH:
            raise self.refuse(line, f"{what} is longer than {MAX_EXPR_LENGTH} characters")
        try:
            node = ast_parse(text.strip(), "eval").body
            for sub in ast.walk(node):
                if hasattr(sub, "lineno"):
                    sub.lineno = line
            return node
        except (SyntaxError, ValueError, RecursionError, MemoryError, OverflowError) as exc:
            raise self.refuse(line, f"{what}: cannot read {text.strip()[:60]!r} ({reason(exc)})") from None

    def _declare(self, text: str, line: int) -> None:
        for part in split_top(text, ","):
            name = re.match(r"\s*([^\s(:]+)", part)
            if not name:
                raise self.refuse(line, f"module declaration {part.strip()[:40]!r} names no module")
            self.declared.add(name.group(1))

    # ------------------------------------------------------------ module-level Python
    def _parse_block(self, source: str, first_line: int, what: str) -> list[ast.stmt]:
        try:
            tree = ast_parse(source)
        except (SyntaxError, ValueError) as exc:
            line = first_line + (getattr(exc, "lineno", None) or 1) - 1
            raise self.refuse(line, f"{what}: Python syntax error ({reason(exc)})") from None
        except (RecursionError, MemoryError, OverflowError) as exc:
            raise self.refuse(first_line, f"{what}: too deeply nested to read ({reason(exc)})") from None
        for node in ast.walk(tree):
            if hasattr(node, "lineno"):
                node.lineno += first_line - 1
        return tree.body

    def _module_code(self, source: str) -> None:
        for no, text in enumerate(source.split("\n"), 1):      # named before any syntax error after them
            m = re.match(r"\s*(?:from\s+([\w.]+)\s+import|import\s+([\w.]+))", text)
            if m and _PLANTGL.search(m.group(1) or m.group(2)):
                raise self.refuse(no, f"import of {m.group(1) or m.group(2)}: PlantGL and OpenAlea are not supported")
        for stmt in self._parse_block(source, 1, "module-level code"):
            self.spend(stmt.lineno)
            self._module_stmt(stmt)

    def _module_stmt(self, stmt: ast.stmt) -> None:
        line = stmt.lineno
        if isinstance(stmt, (ast.Import, ast.ImportFrom)):
            names = [stmt.module or ""] if isinstance(stmt, ast.ImportFrom) else [a.name for a in stmt.names]
            if isinstance(stmt, ast.Import):
                for a in stmt.names:
                    if a.asname and a.name in ("random", "math"):
                        self.aliases[a.asname] = a.name
            if isinstance(stmt, ast.Import) and all(a.name == "numpy" for a in stmt.names):
                self.aliases.update({a.asname or a.name: "numpy" for a in stmt.names})   # for numpy.array only
                return
            if all(n == "time" for n in names) and not (isinstance(stmt, ast.ImportFrom) and stmt.level):
                self.warnings.append(f"{self.path}: warning: line {line}: import of time is ignored (plantgen runs "
                                     "no clock: a model that draws with a time it reads is refused where it does)")
                return
            for name in names:
                if _PLANTGL.search(name):
                    raise self.refuse(line, f"import of {name}: PlantGL and OpenAlea are not supported")
                if name.split(".")[0] not in ("random", "math") or (isinstance(stmt, ast.ImportFrom) and stmt.level):
                    raise self.refuse(line, f"import of {name}: only random and math may be imported")
            return
        if isinstance(stmt, ast.Assign) and len(stmt.targets) == 1:
            self._assign_global(stmt.targets[0], stmt.value, line)
            return
        if isinstance(stmt, ast.AnnAssign) and stmt.value is not None:
            self._assign_global(stmt.target, stmt.value, line)
            return
        if isinstance(stmt, ast.AugAssign) and isinstance(stmt.target, ast.Name):
            self._assign_global(stmt.target, ast.BinOp(ast.Name(stmt.target.id, ast.Load()), stmt.op, stmt.value,
                                                       lineno=line, col_offset=0), line)
            return
        if isinstance(stmt, ast.FunctionDef):
            if stmt.name in HOOKS:
                self.hook_defs.append(stmt)
            elif stmt.decorator_list:
                self.lazy[stmt.name] = f"function {stmt.name} (line {line}) has decorators"
            else:
                self.functions[stmt.name] = stmt
                self.lazy.pop(stmt.name, None)
            return
        if isinstance(stmt, ast.Expr):
            if isinstance(stmt.value, ast.Constant) and isinstance(stmt.value.value, str):
                return                                   # a docstring
            call = stmt.value
            if isinstance(call, ast.Call) and call_name(call) == "extern":
                for kw in call.keywords:
                    if kw.arg:
                        self._assign_global(ast.Name(kw.arg, ast.Store()), kw.value, line)
                return
            if isinstance(call, ast.Call) and call_name(call) in SEED_CALLS:
                self.seed = self._seed(call, line)
                return
            if isinstance(call, ast.Call) and call_name(call) == "print":
                return
            if isinstance(call, ast.Call) and self._context_call(call, line):
                return
        if isinstance(stmt, (ast.Pass, ast.Assert)):
            return
        raise self.refuse(line, f"{construct(stmt)} at module level is not supported "
                                "(only constants, functions, imports of random and math, and random.seed)")

    def _context_call(self, call: ast.Call, line: int) -> bool:
        """``context().turtle.setAngleIncrement(a)`` sets the turtle's angle; another
        call on the L-Py context is ignored with a warning. False for any other call."""
        root = call.func
        while isinstance(root, ast.Attribute):
            root = root.value
        if not (isinstance(root, ast.Call) and isinstance(root.func, ast.Name)
                and root.func.id in ("context", "execContext", "getContext")):
            return False
        method = call.func.attr if isinstance(call.func, ast.Attribute) else ""
        if method == "setAngleIncrement" and len(call.args) == 1:
            self.angle = self._constant(ast.unparse(call.args[0]), line, "the angle increment")
        else:
            self.warnings.append(f"{self.path}: warning: line {line}: {ast.unparse(call.func)[:60]}() is ignored "
                                 "(plantgen reads only the angle increment from the L-Py context)")
        return True


class ExpressionTranslator:
    """The reader's part that translates expressions and L-strings."""

    # ------------------------------------------------------------ expressions
    def expr(self, node, env: dict, line: int) -> Val:
        """``node`` (a Python expression) as plantgen expression text."""
        line = getattr(node, "lineno", line)
        self.spend(line)
        self.depth += 1
        try:
            if self.depth > 200:
                raise self.refuse(line, "expression nested too deeply")
            val = self._expr(node, env, line)
        finally:
            self.depth -= 1
        if len(val.text) > MAX_EXPR_LENGTH:
            raise self.refuse(line, f"an expression grows past {MAX_EXPR_LENGTH} characters once its "
                                    "functions and local variables are substituted")
        return val

    def _expr(self, node, env: dict, line: int) -> Val:
        if isinstance(node, ast.Constant):
            v = node.value
            if isinstance(v, bool):
                return Val("1" if v else "0")
            if isinstance(v, (int, float)):
                if not np.isfinite(float(v)) or abs(v) > 1e300:
                    raise self.refuse(line, "a number literal too large")
                return Val(repr(float(v)) if isinstance(v, float) else str(v))
            raise self.refuse(line, f"a {type(v).__name__} value ({str(v)[:30]!r}) where plantgen needs a number")
        if isinstance(node, ast.Name):
            return self._name(node.id, env, line)
        if isinstance(node, ast.Attribute):
            base = node.value.id if isinstance(node.value, ast.Name) else None
            if self.aliases.get(base) == "math" and node.attr in _MATH_ATTRS:
                return Val(_MATH_ATTRS[node.attr])
            raise self.refuse(line, f"attribute {ast.unparse(node)[:40]!r} is not supported")
        if isinstance(node, ast.UnaryOp):
            a = self.expr(node.operand, env, line)
            op = {ast.USub: "-", ast.UAdd: "+", ast.Not: "!"}.get(type(node.op))
            if op is None:
                raise self.refuse(line, "the operator ~ is not supported")
            return Val(f"{op}{wrap(a.text)}", a.rand)
        if isinstance(node, ast.BinOp):
            a, b = self.expr(node.left, env, line), self.expr(node.right, env, line)
            if isinstance(node.op, ast.FloorDiv):
                return Val(f"floor(({a.text}) / ({b.text}))", a.rand or b.rand)
            op = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Mod: "%",
                  ast.Pow: "^"}.get(type(node.op))
            if op is None:
                raise self.refuse(line, f"the operator {type(node.op).__name__} is not supported")
            return Val(f"{wrap(a.text)} {op} {wrap(b.text)}", a.rand or b.rand)
        if isinstance(node, ast.BoolOp):
            parts = [self.expr(v, env, line) for v in node.values]
            op = " && " if isinstance(node.op, ast.And) else " || "
            return Val(op.join(wrap(p.text) for p in parts), any(p.rand for p in parts))
        if isinstance(node, ast.Compare):
            vals = [self.expr(v, env, line) for v in (node.left, *node.comparators)]
            ops = []
            for op in node.ops:
                sym = {ast.Lt: "<", ast.LtE: "<=", ast.Gt: ">", ast.GtE: ">=", ast.Eq: "==",
                       ast.NotEq: "!="}.get(type(op))
                if sym is None:
                    raise self.refuse(line, f"the comparison {type(op).__name__} is not supported")
                ops.append(sym)
            if len(ops) > 1 and any(v.rand for v in vals[1:-1]):
                raise self.refuse(line, "a chained comparison around a random draw is not supported")
            parts = [f"{wrap(vals[i].text)} {ops[i]} {wrap(vals[i + 1].text)}" for i in range(len(ops))]
            text = parts[0] if len(parts) == 1 else " && ".join(f"({p})" for p in parts)
            return Val(text, any(v.rand for v in vals))
        if isinstance(node, ast.IfExp):
            c, a, b = (self.expr(n, env, line) for n in (node.test, node.body, node.orelse))
            return Val(f"select({c.text}, {a.text}, {b.text})", c.rand or a.rand or b.rand)
        if isinstance(node, ast.Call):
            return self._call(node, env, line)
        if (isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name) and node.value.id not in env
                and node.value.id in self.tables):
            return self._index(self.tables[node.value.id], node.slice, env, line)
        raise self.refuse(line, f"{construct(node)} is not supported in an expression")

    def _index(self, values: list[str], index, env: dict, line: int) -> Val:
        """A module-level list of numbers indexed by an expression: nested ``select`` on the
        index (Python's negative indices too; one past either end reads the last value)."""
        if isinstance(index, ast.Slice):
            raise self.refuse(line, "a slice is not supported in an expression")
        i = self.expr(index, env, line)
        if i.rand:
            raise self.refuse(line, "a list indexed by a random draw is not supported")
        at = wrap(i.text)
        text = values[-1]
        for k in range(len(values) - 2, -1, -1):
            text = f"select({at} == {k} || {at} == {k - len(values)}, {values[k]}, {text})"
        return Val(text)

    def _name(self, name: str, env: dict, line: int) -> Val:
        if name in env:
            local = env[name]
            if local.error:
                raise self.refuse(line, local.error)
            if local.span is not None and local.span != (0.0, 1.0):
                raise self.refuse(line, f"{name!r} holds a random draw that a test has narrowed; reading its "
                                        "value after the test is not supported")
            if local.rand:
                if local.used:
                    raise self.refuse(line, f"{name!r} holds a random draw and is read twice: plantgen would "
                                            "draw it anew each time; write the draw where it is used once")
                local.used = True
            return Val(wrap(local.text), local.rand)
        if safe(name) in self.defines or safe(name) in self.globals:
            return Val(safe(name))
        if name in ("pi", "e"):
            return Val(name)
        if name in ("True", "False"):
            return Val("1" if name == "True" else "0")
        if name in self.lazy:
            raise self.refuse(line, self.lazy[name])
        raise self.refuse(line, f"name {name!r} is not defined (or not a number plantgen can use)")

    def _call(self, node: ast.Call, env: dict, line: int) -> Val:
        name = call_name(node)
        if node.keywords or any(isinstance(a, ast.Starred) for a in node.args):
            raise self.refuse(line, f"keyword or starred arguments in a call to {name or 'a function'}")
        if name is None:
            raise self.refuse(line, f"call of {ast.unparse(node.func)[:40]!r} is not supported")
        if name in self.functions:
            return self._inline(name, node.args, env, line)
        base, _, attr = name.rpartition(".")
        base = self.aliases.get(base, base)
        if base in ("", "random") and attr in _RANDOM_FUNCS:
            return self._random(attr, node.args, env, line)
        if base in ("", "math") and attr in _MATH_FUNCS:
            args = [self.expr(a, env, line) for a in node.args]
            fn = _MATH_FUNCS[attr]
            rand = any(a.rand for a in args)
            if fn in ("min", "max") and len(args) > 2:
                text = args[0].text
                for a in args[1:]:
                    text = f"{fn}({text}, {a.text})"
                return Val(text, rand)
            if fn == "log" and len(args) == 2:
                return Val(f"log({args[0].text}) / log({args[1].text})", rand)
            if fn == "round" and len(args) != 1:
                raise self.refuse(line, "round() with digits is not supported")
            return Val(f"{fn}({', '.join(a.text for a in args)})", rand)
        if name == "sum" and len(node.args) == 1 and isinstance(node.args[0], (ast.List, ast.Tuple, ast.ListComp,
                                                                                  ast.GeneratorExp)):
            terms = self._terms(node.args[0], env, line) or [Val("0")]
            return Val(" + ".join(wrap(t.text) for t in terms), any(t.rand for t in terms))
        if base == "" and attr in ("float", "bool", "abs") and len(node.args) == 1:
            a = self.expr(node.args[0], env, line)
            return Val({"float": f"({a.text})", "bool": f"(({a.text}) != 0)", "abs": f"abs({a.text})"}[attr], a.rand)
        if _PLANTGL.search(name) or name[:1].isupper():
            raise self.refuse(line, f"call of {name}(): PlantGL and L-Py objects are not supported")
        if name in ("open", "exec", "eval", "compile", "__import__", "input", "getattr", "setattr", "globals"):
            raise self.refuse(line, f"call of {name}(): file access and dynamic code are not supported")
        if name in self.lazy:
            raise self.refuse(line, self.lazy[name])
        raise self.refuse(line, f"call of {name}() is not supported")

    def _terms(self, seq, env: dict, line: int) -> list[Val]:
        """The values of a written list, or of ``[e for NAME in range(...)]`` with a
        constant count (unrolled, as a loop)."""
        if isinstance(seq, (ast.List, ast.Tuple)):
            return [self.expr(e, env, line) for e in seq.elts]
        gen = seq.generators[0]
        it = gen.iter
        if (len(seq.generators) != 1 or gen.ifs or not isinstance(gen.target, ast.Name) or not isinstance(it, ast.Call)
                or call_name(it) != "range" or not 1 <= len(it.args) <= 3):
            raise self.refuse(line, "a comprehension other than '[e for NAME in range(...)]' is not supported")
        try:
            bounds = [evaluate(self.expr(a, env, line).text, self.defines) for a in it.args]
        except ExprError:
            bounds = [0.5]
        if any(b != int(b) for b in bounds):
            raise self.refuse(line, "range() in a comprehension must have a constant, whole count")
        values = range(*map(int, bounds)) if bounds[-1] != 0 or len(bounds) < 3 else range(0)
        self._count_loops(len(values), line)
        return [self.expr(seq.elt, {**env, gen.target.id: Val(str(i))}, line) for i in values]

    def _random(self, fn: str, args: list, env: dict, line: int) -> Val:
        vals = [self.expr(a, env, line) for a in args] if fn != "choice" else []
        need = {"random": 0, "uniform": 2, "randint": 2, "gauss": 2, "normalvariate": 2, "choice": 1}[fn]
        if len(args) != need:
            raise self.refuse(line, f"{fn}() takes {need} argument(s) here")
        if fn == "random":
            return Val("random()", True)
        if fn == "uniform":
            return Val(f"uniform({vals[0].text}, {vals[1].text})", True)
        if fn == "randint":
            return Val(f"floor(uniform({vals[0].text}, ({vals[1].text}) + 1))", True)
        if fn in ("gauss", "normalvariate"):
            return Val(f"normal({vals[0].text}, {vals[1].text})", True)
        seq = args[0]
        if not isinstance(seq, (ast.List, ast.Tuple)) or not 1 <= len(seq.elts) <= 31:
            raise self.refuse(line, "choice() takes a written list of 1 to 31 numbers here")
        opts = [self.expr(e, env, line) for e in seq.elts]
        if len(opts) == 1:
            return opts[0]
        return Val(f"choose(floor(random() * {len(opts)}), {', '.join(o.text for o in opts)})", True)

    # ------------------------------------------------------------ L-strings
    def _lstring(self, text: str, line: int, env: dict, pattern: bool) -> list[Mod]:
        """An L-string as modules; arguments translated (or, in a pattern, names)."""
        out = []
        for name, args in self._scan(text, line):
            self.spend(line)
            if name in REFUSED_MODULES:
                raise self.refuse(line, REFUSED_MODULES[name])
            if name in SILENT:
                continue
            if not args and not pattern and name in DEFAULT_ARGS:
                args = DEFAULT_ARGS[name]
            if name in UNDRAWN and not (name in DRAWN_AS and len(args or ()) >= DRAWN_AS[name][0]):
                self.dropped[name] = self.dropped.get(name, 0) + 1
                continue
            if name in TROPISM:
                self._tropism(name, args, line, pattern)
                continue
            if name.startswith("~") and name != "~l":
                self.dropped[name] = self.dropped.get(name, 0) + 1
                continue
            out.append(Mod(name, self._args(name, args, line, env, pattern), line))
            if len(out) > MAX_SUCCESSOR:
                raise self.refuse(line, f"an L-string of more than {MAX_SUCCESSOR:,} modules")
        return out

    def _args(self, name: str, args, line: int, env: dict, pattern: bool):
        if args is None:
            return []
        if pattern:
            names = []
            for a in args:
                a = a.strip()
                if _NUMBER.fullmatch(a) and hasattr(self, "pattern_conds"):
                    names.append(f"k{len(self.pattern_conds)}_")       # a value to match: a condition
                    self.pattern_conds.append(f"{names[-1]} == {float(a)!r}")
                    continue
                if not IDENT.match(a):
                    raise self.refuse(line, f"pattern argument {a[:30]!r} of {name}: only names are supported "
                                            "in a predecessor or context")
                names.append(safe(a))
            return names
        return [self.expr(self._parse_expr(a, line, f"argument of {name}"), env, line) for a in args]

    def _tropism(self, name: str, args, line: int, pattern: bool) -> None:
        key = TROPISM[name]
        if pattern or not args:
            return
        try:
            vals = self.vectors.get(args[0].strip()) if len(args) == 1 else None
            vals = vals or [float(evaluate(self.expr(self._parse_expr(a, line, name), {}, line).text, self.defines))
                            for a in args]
        except (ExprError, LpyError):
            self.warnings.append(f"{self.path}: warning: line {line}: {name} with arguments that change is not "
                                 "drawn (plantgen has one tropism per grammar)")
            return
        value = vals[0] if key == "strength" else vals
        if key == "direction":
            if len(vals) != 3:
                return
            value = [vals[1], vals[2], vals[0]]          # L-Py's z up to plantgen's y up
            if not any(value):
                return
        if key in self.tropism and self.tropism[key] != value:
            self.warnings.append(f"{self.path}: warning: line {line}: {name} set again to another value; plantgen "
                                 "has one tropism per grammar and keeps the first")
            return
        self.tropism[key] = value

    def _scan(self, text: str, line: int):
        """(name, raw argument texts or None) for each module of an L-string."""
        i, n = 0, len(text)
        while i < n:
            ch = text[i]
            if ch.isspace():
                i += 1
                continue
            if ch.isalpha() or ch == "_":
                j = i
                while j < n and (text[j].isalnum() or text[j] == "_"):
                    j += 1
                word = text[i:j]
                k = j
                while k < n and text[k] == " ":
                    k += 1
                letters = (k < n and text[k] == "(" and len(word) > 1 and word not in self.heads
                           and word[-1] in self.heads and word not in self.declared and word not in NAMED)
                if letters:
                    name, i = word[0], i + 1
                elif word in self.declared or word in NAMED or (k < n and text[k] == "(") or len(word) == 1:
                    name, i = word, j
                else:
                    name = next((word[:m] for m in range(len(word), 1, -1)
                                 if word[:m] in self.declared or word[:m] in NAMED), word[0])
                    i += len(name)
            else:
                name = next((s for s in SPECIAL if text.startswith(s, i)), None)
                if name is None and ch in "~" and i + 1 < n and text[i + 1].isalpha():
                    name = text[i:i + 2]
                if name is None:
                    name = ch
                i += len(name)
                if name in "()," and name != ",":
                    raise self.refuse(line, f"unexpected {name!r} in L-string {text.strip()[:60]!r}")
            args = None
            k = i
            while k < n and text[k] == " ":
                k += 1
            if k < n and text[k] == "(":
                end = closing(text, k)
                if end < 0:
                    raise self.refuse(line, f"unclosed '(' after {name!r}")
                inner = text[k + 1:end]
                args = split_top(inner, ",") if inner.strip() else []
                i = end + 1
            yield name, args
