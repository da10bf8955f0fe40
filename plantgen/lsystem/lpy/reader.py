"""The reader of one ``.lpy`` file: :class:`Reader` holds what the translation accumulates
(defines, functions, tables, globals, hooks, rules, warnings, the work budget spent) and
takes its methods from the parts, one module each: :class:`~.sections.SectionReader`
(sections), :class:`~.translate.StatementTranslator` and
:class:`~.translate.ExpressionTranslator` (statements and expressions),
:class:`~.inline.Inliner` and :class:`~.inline.Unroller` (inlining and unrolling),
:class:`~.rules.GlobalsReader` and :class:`~.rules.RuleBuilder` (globals, hooks, rules and
the grammar mapping), :class:`~.drawn.DrawnAs` (modules written as plantgen text). The
parts share no state but this object's attributes, set here, and call one another through
``self``; ``refuse`` and ``spend`` (errors and the budget) are every part's."""

from __future__ import annotations

import ast
import re

from ...limits import LimitError, Limits, hint
from .common import LpyError, one_line
from .drawn import DrawnAs
from .inline import Inliner, Unroller
from .rules import GlobalsReader, RuleBuilder
from .sections import SectionReader
from .translate import ExpressionTranslator, StatementTranslator


class Reader(SectionReader, StatementTranslator, ExpressionTranslator, Inliner, Unroller, GlobalsReader,
             RuleBuilder, DrawnAs):
    """One file's translation (see the package's notes): the state every part reads and
    fills, the parts' methods inherited from each."""

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
