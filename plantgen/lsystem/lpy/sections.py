"""Reading an ``.lpy`` file's sections: its lines split into the module-level Python, the
axiom, ``derivation length``, ``production:``/``interpretation:``/``decomposition:``
rules (by group), ``ignore``/``consider``, ``module`` declarations and the tail after
``endlsystem``; module-level functions that produce set aside; ``global`` declarations
found; then each gathered piece handed to its translation (:class:`SectionReader`)."""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from ..expr import MAX_GLOBALS, ExprError, evaluate
from .common import HOOKS, safe

_GLOBAL_DECL = re.compile(r"^\s+global\s+([A-Za-z_]\w*(?:\s*,\s*[A-Za-z_]\w*)*)")
_KEYWORD = re.compile(
    r"^(?:(?P<axiom>Axiom)\s*:(?P<axiom_text>.*)|derivation\s+length\s*:(?P<length>.*)"
    r"|(?P<section>production|homomorphism|interpretation|decomposition)\s*:\s*$"
    r"|maximum\s+depth\s*:(?P<depth>.*)|group\s+(?P<group>\w+)\s*:\s*$|(?P<endgroup>endgroup)\s*$"
    r"|(?P<end>endlsystem)\s*$|(?P<decl>ignore|consider)\s*:(?P<decl_text>.*)|module\s+(?P<module>.*)"
    r"|initial_view\s*[=:](?P<view>.*))")
PRODUCE = re.compile(r"(?:^|(?<=:))(\s*)(nproduce|produce)\b(.*)$")


# ------------------------------------------------------------------ file splitting
def strip_comment(line: str) -> str:
    depth, quote = 0, None
    for i, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "'\"":
            quote = ch
        elif ch == "(":
            depth += 1
        elif ch == ")":
            depth -= 1
        elif ch == "#" and depth <= 0:
            return line[:i]
    return line


@dataclass
class _Sections:
    """What splitting a file's lines gathers: the module-level Python (one entry per line,
    L-Py lines blanked), the tail after ``endlsystem``, the axiom, the rules' lines."""

    python: list = field(default_factory=list)
    tail: list = field(default_factory=list)
    mode: str = "python"                 # python, axiom (its block), rules, tail
    section: str | None = None
    group: str = "0"
    rule_lines: list = field(default_factory=list)     # the current rule: (line number, text)
    rules: list = field(default_factory=list)          # (section, group, lines)
    axiom: tuple | None = None
    axiom_block: list | None = None
    length: tuple | None = None
    depths: list = field(default_factory=list)
    decls: list = field(default_factory=list)
    in_def: bool = False                 # in a function defined between the rules

    def close_rule(self) -> None:
        if self.rule_lines:
            self.rules.append((self.section, self.group, self.rule_lines))
            self.rule_lines = []


_ASSIGNMENT = re.compile(r"[A-Za-z_][A-Za-z_0-9]*\s*(?:[-+*/]?=)(?!=)")


class SectionReader:
    """The reader's part that splits the file into its sections and hands each on."""

    # ------------------------------------------------------------ sections
    def read(self) -> None:
        st = _Sections()
        for no, raw in enumerate(self.lines, 1):
            if st.mode == "tail":
                st.tail.append(raw)
                st.python.append("")
                continue
            line = raw.rstrip()
            code = strip_comment(line).rstrip()
            starts = code[:1] not in ("", " ", "\t")
            if st.mode == "axiom":
                if not starts:
                    st.axiom_block.append((no, line if code.strip() else ""))
                    st.python.append("")
                    continue
                st.mode = "python"
            m = _KEYWORD.match(code) if starts else None
            if m and not (m.group("module") is not None and "=" in code.split("(")[0]):
                st.python.append("")
                st.close_rule()
                self._keyword(m, no, st)
            elif st.mode == "rules":
                self._rule_line(no, raw, line, code, starts, st)
            else:
                st.python.append(raw)
        st.close_rule()
        self._find_producers(st)
        self._find_globals(st)
        self._translate(st)

    def _find_producers(self, st: _Sections) -> None:
        """Module-level functions whose body produces modules: kept aside (their lines
        blanked from the module code) to be inlined where a rule calls them as a statement.
        ``produce`` anywhere else outside a rule is refused, naming where it is."""
        lines, current = st.python, None          # current: (name, index of its def line, hook?)
        found: list = []
        for i, text in enumerate([*lines, "end"]):
            code = strip_comment(text).rstrip()
            if code[:1] not in ("", " ", "\t"):             # a line at column 0 ends any def
                current = None
                m = re.match(r"def\s+([A-Za-z_]\w*)\s*\(", code)
                if m:
                    current = (m.group(1), i)
            if not PRODUCE.search(code):
                continue
            if current is None:
                raise self.refuse(i + 1, "produce outside a rule and outside a function is not supported")
            if current[0] in HOOKS:
                raise self.refuse(i + 1, f"{current[0]}() produces modules: plantgen's grammar has no place for "
                                         "modules added when a step or the drawing starts or ends")
            if current not in found:
                found.append(current)
        for name, start in found:
            end = start + 1
            while end < len(lines) and strip_comment(lines[end]).rstrip()[:1] in ("", " ", "\t"):
                end += 1
            self.producers[name] = (start + 1, lines[start:end])
            for k in range(start, end):
                lines[k] = ""

    def _find_globals(self, st: _Sections) -> None:
        """The names a ``global`` statement declares in a block (a hook's, a rule's, a
        function's) that an indented line assigns: the model's globals, which change."""
        code = [strip_comment(t) for t in self.lines[:len(self.lines) - len(st.tail)]]
        declared = {n.strip() for t in code for m in [_GLOBAL_DECL.match(t)] if m for n in m.group(1).split(",")}
        assigned = {m.group(1) for t in code for m in [re.match(r"\s+([A-Za-z_]\w*)\s*(?:[-+*/%]|\*\*|//)?=(?!=)", t)]
                    if m}
        self.mutable = declared & assigned
        if len(self.mutable) > MAX_GLOBALS:
            raise self.refuse(0, f"{len(self.mutable):,} globals set by hooks and rules, over the limit of "
                                 f"{MAX_GLOBALS}")

    def _keyword(self, m: re.Match, no: int, st: _Sections) -> None:
        """One L-Py line of the L-system part (``Axiom:``, ``production:`` ...)."""
        if m.group("axiom"):
            st.axiom = (m.group("axiom_text"), no)
            if not st.axiom[0].strip() and st.mode == "python":
                st.axiom_block, st.mode = [], "axiom"      # an axiom written as a block
        elif m.group("length") is not None:
            st.length = (m.group("length"), no)
        elif m.group("section"):
            name = m.group("section")
            st.section = "interpretation" if name == "homomorphism" else name
            st.mode = "rules"
        elif m.group("depth") is not None:
            key = "decomposition" if st.section == "decomposition" else "interpretation"
            st.depths.append((m.group("depth"), no, key))
        elif m.group("group") is not None:
            st.group = m.group("group")
        elif m.group("endgroup"):
            st.group = "0"
        elif m.group("end"):
            st.mode = "tail"
        elif m.group("decl"):
            st.decls.append((m.group("decl"), m.group("decl_text"), no))
        elif m.group("module") is not None:
            self._declare(m.group("module"), no)

    def _rule_line(self, no: int, raw: str, line: str, code: str, starts: bool, st: _Sections) -> None:
        """A line of a rule section: a rule's header, a line of its block, or Python."""
        st.python.append("")
        if st.in_def and (not starts or not code.strip()):
            st.python[-1] = raw                       # the body of a function between the rules
            return
        st.in_def = starts and bool(re.match(r"(def|import|from)\s", code))
        if st.in_def:
            st.python[-1] = raw
            st.close_rule()
        elif not code.strip():
            if st.rule_lines:
                st.rule_lines.append((no, ""))
        elif starts and _ASSIGNMENT.match(code) and "-->" not in code:
            st.python[-1] = raw                       # Python between the rules
            st.close_rule()
        elif starts:
            st.close_rule()
            st.rule_lines = [(no, code)]
        elif st.rule_lines:
            st.rule_lines.append((no, line))
        else:
            raise self.refuse(no, "an indented line outside any rule")

    def _translate(self, st: _Sections) -> None:
        """The sections split: module code first (the names the rules use), then the
        axiom and the rules."""
        self._module_code("\n".join(st.python))
        self._initialisation(st.tail, len(self.lines) - len(st.tail) + 1)
        for name in sorted(self.mutable):
            if safe(name) in self.defines:
                self.globals[safe(name)] = self.defines.pop(safe(name))
            elif name not in self.lazy and name not in self.functions:
                self.globals[safe(name)] = 0.0          # first set by Start: 0 for the axiom
        for fn in self.hook_defs:
            self._hook(fn)
        if st.length is not None:
            self.iterations = self._int(st.length[0], st.length[1], "derivation length", 0, None)
        for text, no, key in st.depths:
            self.max_depth[key] = self._int(text, no, "maximum depth", 1, None)
        if st.axiom is None:
            raise self.refuse(0, "no 'Axiom:' line, not an L-Py model")
        if st.axiom_block is not None and any(t.strip() for _, t in st.axiom_block):
            self.axiom = self._axiom_block(st.axiom_block, st.axiom[1])
        else:
            self.axiom = self._lstring(st.axiom[0], st.axiom[1], {}, pattern=False)
        self.decls = st.decls
        for i, (sec, grp, lines) in enumerate(st.rules):
            self.later = [(s, ls[0][1]) for s, g, ls in st.rules[i + 1:] if g == "0"]
            if grp != "0":
                self.warnings.append(f"{self.path}: warning: line {lines[0][0]}: the rules of group {grp} are "
                                     "ignored (plantgen applies group 0 only: useGroup is not supported)")
                continue
            self._rule(sec, lines)

    def _axiom_block(self, lines: list, line: int) -> list:
        """An axiom written as a Python block (``nproduce`` in loops): the modules of the
        way through it whose tests, constants all, hold."""
        for path in self._block(lines, {}):
            ok = True
            for _ident, holds, text, rand, at in path.conds:
                if rand:
                    raise self.refuse(at, "a random test in the axiom is not supported")
                try:
                    value = evaluate(text, self.defines) != 0
                except ExprError as exc:
                    raise self.refuse(at, f"axiom: {exc}") from None
                ok = ok and value == holds
            if ok:
                self.axiom_effects = tuple((k, v, line) for k, v in path.effects)
                return path.modules or []
        raise self.refuse(line, "the axiom's block produces nothing")
