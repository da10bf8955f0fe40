"""Query and communication modules: the derivation's pass that tells a string where it is.

As in *Synthetic topiary* (Prusinkiewicz, James and Měch 1994) and L-Py, after the axiom is
read and after every derivation step the turtle interprets the string (its ``%`` already
cut; the ``interpretation:`` rules, which are for the final drawing, not applied), and
each query module receives the turtle's state at its place in the string: ``?P(x, y, z)``
the position, ``?H`` the heading, ``?U`` the up axis, ``?L`` the left axis.
The next step's rules read those values like any other parameters
(``?P(x, y, z) : x*x + z*z > r*r -> %``). Communication modules ``?E(...)`` (Měch and
Prusinkiewicz 1996) are answered in the same pass by an *environment*: any object with a
``width`` (the parameters each ``?E`` receives) and ``answer(state) -> (k, width)``
(:class:`QueryState`: the positions and frames of the string's ``?E`` and what the whole
string draws). The built-in environments live in :mod:`plantgen.environment`.

Only a grammar that uses these modules pays for the pass (one turtle walk per step); the
derivation of any other grammar is the same as without them. The modules answered are
counted against ``max_queries`` of the limits in force, over all steps of a derivation.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ..errors import PlantgenError
from ..limits import QUERY_WORK, Limits, Meter
from .grammar import Grammar
from .strings import ModuleString
from .symbols import SYMBOLS, Action
from .turtle import Drawing, interpret_plant

__all__ = ["COMMUNICATION_SYMBOL", "QUERY_SYMBOLS", "Environment", "Queries", "QueryState", "communication_arity",
           "uses_queries"]

#: The query modules and which of the turtle's recorded vectors each receives (position, H, L, U).
QUERY_SYMBOLS: dict[str, int] = {s.char: {Action.QUERY_POSITION: 0, Action.QUERY_HEADING: 1, Action.QUERY_LEFT: 2,
                                          Action.QUERY_UP: 3}[s.action]
                                 for s in SYMBOLS if s.action in (Action.QUERY_POSITION, Action.QUERY_HEADING,
                                                                  Action.QUERY_LEFT, Action.QUERY_UP)}
#: The communication module, answered by the environment.
COMMUNICATION_SYMBOL: str = next(s.char for s in SYMBOLS if s.action is Action.COMMUNICATE)


@dataclass(frozen=True, eq=False)
class QueryState:
    """What the environment sees after one step: the ``k`` communication modules
    (``position``, ``heading``, ``left``, ``up``: (k, 3) world vectors, the turtle's at each
    module, in string order; ``rows``: their indices in ``string``; ``segment``, ``side``:
    the segment each hangs from and whether it starts a side branch) and what the whole
    string draws (``drawing``: the plant grown so far, its leaves included)."""

    step: int
    rows: np.ndarray
    position: np.ndarray
    heading: np.ndarray
    left: np.ndarray
    up: np.ndarray
    drawing: Drawing
    string: ModuleString
    segment: np.ndarray | None = None     # (k,) the segment each hangs from (-1: none)
    side: np.ndarray | None = None        # (k,) bool: it starts a side branch

    def __len__(self) -> int:
        return len(self.rows)

    def local(self, vectors: np.ndarray) -> np.ndarray:
        """World vectors (k, 3), one per module, in each module's frame: (H, L, U) components."""
        return np.stack([np.einsum("ij,ij->i", vectors, axis) for axis in (self.heading, self.left, self.up)],
                        axis=1)


class Environment(Protocol):
    """What answers a grammar's ``?E`` modules (see the module's notes)."""

    width: int

    def answer(self, state: QueryState) -> np.ndarray:
        """(len(state), width) float64: the parameters of each ``?E`` of ``state``."""


def uses_queries(grammar: Grammar) -> bool:
    """Whether ``grammar`` writes a query or communication module (and so needs the pass)."""
    return any(s in QUERY_SYMBOLS or s == COMMUNICATION_SYMBOL for s in grammar.symbols)


def communication_arity(grammar: Grammar) -> int | None:
    """The parameter count of ``grammar``'s ``?E`` modules (one per grammar), None without any."""
    for templates in (grammar.axiom, *(r.successor for r in (*grammar.rules, *grammar.interpretation))):
        for m in templates:
            if m.symbol == COMMUNICATION_SYMBOL:
                return len(m.args)
    for r in grammar.rules:
        for pat in (*r.left, r.pred, *r.right):
            if pat.symbol == COMMUNICATION_SYMBOL:
                return len(pat.params)
    return None


class Queries:
    """The query pass of one derivation: :meth:`update` writes the answers into a string."""

    def __init__(self, grammar: Grammar, environment: Environment | None, limits: Limits,
                 work: Meter | None = None):
        self.grammar, self.environment, self.work = grammar, environment, work
        self.meter = limits.meter("queries")
        self.limits = limits
        self.pending = None          # (string, step, rows, drawing) walked by interpret, not yet written
        codes = {s: i for i, s in enumerate(grammar.symbols)}
        self.query_codes = {codes[s]: k for s, k in QUERY_SYMBOLS.items() if s in codes}
        self.communication = codes.get(COMMUNICATION_SYMBOL)
        self.all_codes = np.array([*self.query_codes, *([self.communication] if self.communication is not None
                                                        else [])], dtype=np.int32)
        if self.communication is not None:
            arity = communication_arity(grammar)
            if environment is None:
                raise PlantgenError(f"{grammar.path}: {COMMUNICATION_SYMBOL!r} modules need an environment to "
                                    "answer them: declare one under 'environment:'")
            if arity != environment.width:
                raise PlantgenError(f"{grammar.path}: {COMMUNICATION_SYMBOL!r} has {arity} parameter(s) but "
                                    f"the environment answers {environment.width}")

    def interpret(self, string: tuple, step: int) -> Drawing | None:
        """Walk the turtle over ``string`` (sym, nparam, params) and keep what it drew and
        its state at each query module (:attr:`drawing`), for :meth:`update` to write."""
        sym = string[0]
        rows = np.flatnonzero(np.isin(sym, self.all_codes))
        self.pending = (string, step, rows, None)
        if not len(rows):
            return None
        self.meter.spend(len(rows), f"{self.grammar.path}: query modules after step {step}")
        if self.work is not None:        # the walk over the whole string, charged before it is taken
            self.work.spend(len(sym) * QUERY_WORK, f"{self.grammar.path}: the query pass after step {step}")
        ms = ModuleString(*string, self.grammar.symbols)
        drawing = interpret_plant(ms, self.grammar.turtle, self.grammar.materials, self.grammar.path, self.limits,
                                  queries=True)
        self.pending = (string, step, rows, drawing)
        return drawing

    def update(self, string: tuple, step: int) -> None:
        """Write, in place, each query module's turtle vector and each ``?E``'s answer into
        its parameters (walking the turtle over ``string`` first, unless :meth:`interpret`
        just did)."""
        if self.pending is None or self.pending[0] is not string or self.pending[1] != step:
            self.interpret(string, step)
        string, step, rows, drawing = self.pending
        self.pending = None
        if drawing is None:
            return
        sym, _, params = string
        ms = ModuleString(*string, self.grammar.symbols)
        states = drawing.queries
        kinds = sym[rows]
        for code, k in self.query_codes.items():
            at = kinds == code
            params[rows[at], :3] = states[at, k]
        if self.communication is not None:
            at = kinds == self.communication
            if at.any():
                s = states[at]
                links = drawing.query_links[at]
                state = QueryState(step, rows[at], s[:, 0], s[:, 1], s[:, 2], s[:, 3], drawing, ms, links[:, 0],
                                   links[:, 1] != 0)
                answers = np.asarray(self.environment.answer(state), dtype=np.float64)
                if answers.shape != (len(state), self.environment.width) or not np.isfinite(answers).all():
                    raise PlantgenError(f"{self.grammar.path}: the environment's answer after step {step} is not "
                                        f"{len(state)} finite rows of {self.environment.width}")
                if self.environment.width:
                    params[rows[at], :self.environment.width] = answers
