"""L-systems: the turtle symbols (symbols.py), parse (grammar.py), derive (derive.py), interpret (turtle.py).
No GL, no click."""

from .derive import DEFAULT_MAX_MODULES, DerivationLimit, ModuleString, derive
from .expr import ExprError, compile_expr
from .grammar import Grammar, GrammarError, load_grammar, parse_grammar
from .turtle import interpret

__all__ = ["DEFAULT_MAX_MODULES", "DerivationLimit", "ExprError", "Grammar", "GrammarError",
           "ModuleString", "compile_expr", "derive", "interpret", "load_grammar", "parse_grammar"]
