"""Derivation: rewrite the module string ``iterations`` times. Never builds geometry.

The module string is held as arrays, and each rewriting step is vectorised per rule: all
modules a rule matches are rewritten at once, their parameter expressions evaluated over
numpy arrays. Random draws come from one seeded generator in a fixed order (rules in file
order, modules in string order), so a grammar and seed always give the same string.

The derivation's budgets are those of :class:`plantgen.limits.Limits`: a step whose
result would exceed ``max_modules`` modules or ``max_derive_bytes`` bytes stops with
:class:`DerivationLimit` before anything of that size is allocated, and every step spends
``max_derive_work`` (its modules, ``CONTEXT_WORK`` times for a context-sensitive grammar,
plus ``STEP_WORK`` per rule group), so a derivation that does not grow still ends. A
grammar's ``max_modules`` may lower the limit, never raise it.

A grammar's ``globals`` are variables its expressions read and its rules and ``hooks``
set (L-Py's module globals). The ``start`` hook runs once before the first step (after
the axiom is read), ``start_each`` and ``end_each`` before and after each step (the
decomposition included), ``end`` once after the last. A rule's ``set`` runs where it
applies, module after module in string order: a step that holds such a rule is cut at
each module that sets a global (after the whole run of a predecessor of several
modules), so the modules after it see the new values (L-Py's sequential semantics); each
cut re-matches the rest of the string, spending its modules again from the work budget.
A step with a new left context (``<<``) is sequential already: each ``set`` runs right
after its module is rewritten. Interpretation rules read the values the derivation ended with.

A derivation whose state (the string, the globals and the random generator's state) comes back stops
early: a fixed point (``F -> F``) at once, a cycle (``A -> B``, ``B -> A``) after one
period, the remaining steps skipped by their count modulo the period.

``%`` cuts a branch, as ABOP defines it: after the axiom is read and after every step,
each ``%`` is removed with everything after it up to the ``]`` that closes its branch
(to the end of the string on the main axis); the ``]`` stays.

:attr:`Grammar.decomposition` rules (L-Py's ``decomposition:``) rewrite the string after each
derivation step, pass after pass (up to ``decomposition_depth``) until none applies.

:func:`apply_interpretation` applies a grammar's ``interpretation:`` rules (ABOP's
homomorphism, L-Py's ``interpretation:``) to a derived string ``interpretation_depth``
times, for drawing only: it returns a new string and the derived one is never changed.
"""

from __future__ import annotations

import hashlib
from dataclasses import replace

import numpy as np

from ..errors import PlantgenError
from ..limits import CONTEXT_WORK, SEQUENTIAL_WORK, SETTLE_STEPS, STEP_WORK, LimitError, Limits, Meter, hint
from ..limits import limits as default_limits
from .expr import EvalContext, ExprError
from .grammar import Grammar, ModuleTemplate, Pattern, Rule
from .queries import Queries, uses_queries
from .strings import ModuleString, module_bytes
from .symbols import Action, by_action

__all__ = ["DEFAULT_MAX_MODULES", "Derivation", "DerivationLimit", "ModuleString", "apply_interpretation",
           "context_neighbours", "cut_branches", "derive", "module_bytes", "steps_floor"]

DEFAULT_MAX_MODULES = default_limits.max_modules

#: Strings up to this many modules are fingerprinted after each step to find a fixed point
#: or a cycle (hashing costs about as much as copying the string; longer strings that stop
#: growing are bounded by the work budget instead).
CYCLE_WINDOW = 65_536
#: The work a cut of a step at a module that sets globals costs per rule group, besides
#: the modules after it (the rules match the rest of the string again: Python per group).
SETTER_WORK = 2_000
#: The symbol that cuts a branch (``%``).
CUT_SYMBOL = by_action(Action.CUT)


class DerivationLimit(LimitError):
    """The module string would grow past a budget of the limits in force."""


def _width(grammar: Grammar) -> int:
    n = [len(m.args) for m in grammar.axiom]
    for r in (*grammar.rules, *grammar.interpretation, *grammar.decomposition):
        n += [len(m.args) for m in r.successor]
    return max([1, *n])


def _instantiate(templates: tuple[ModuleTemplate, ...], env: dict, rng, n: int, codes: dict,
                 width: int):
    """Evaluate templates for ``n`` matched modules: (len(templates), n) sym/nparam/params."""
    L = len(templates)
    sym = np.empty(L, dtype=np.int32)
    nparam = np.empty(L, dtype=np.int8)
    params = np.zeros((L, n, width))
    ctx = EvalContext(env, rng, n)
    for j, t in enumerate(templates):
        sym[j] = codes[t.symbol]
        nparam[j] = len(t.args)
        for a, expr in enumerate(t.args):
            params[j, :, a] = expr(ctx)
    return sym, nparam, params


def context_neighbours(ms_sym: np.ndarray, symbols: tuple[str, ...], ignore: frozenset[str]):
    """What context matching needs of a string: each module's left context neighbour (or
    -1), and the jumps :func:`_walk` takes rightwards.

    ABOP semantics: ignored symbols are skipped; looking left, a whole bracketed branch
    ``[...]`` is skipped and an opening ``[`` is stepped over to the module the branch
    grows from. The jumps, arrays of n + 1 (position n: the end of the string): ``vis``,
    the first position from each on that is not an ignored module; ``skip``, the same
    skipping whole branches too; ``outer``, the ``]`` that closes the branch a position is
    in (a ``[`` being outside its own branch; n on the main axis).
    """
    n = len(ms_sym)
    codes = {c: i for i, c in enumerate(symbols)}
    opens, closes, depth = _depths(ms_sym, codes)
    ignored = np.isin(ms_sym, [codes[c] for c in ignore if c in codes]) & ~opens & ~closes
    visible = ~ignored & ~opens & ~closes
    at = np.arange(n)
    # Left: the last visible module before each in its own branch, else that of the [ the
    # branch opens with (pointer jumping up the nesting).
    opener = np.where(depth > 0, _last_before(depth + 1, opens, depth), -1)      # the [ a branch opens with
    target = _last_before(opener + 1, visible, opener + 1)
    ptr = np.where((target < 0) & (opener >= 0), opener, -1)
    while (ptr >= 0).any():
        go = np.flatnonzero(ptr >= 0)
        target[go], ptr[go] = target[ptr[go]], ptr[ptr[go]]
    left = np.where(opens | closes, -1, target)
    # Right: the first position from each on, at its own bracket depth, of a kind.
    vis = np.append(np.minimum.accumulate(np.where(ignored, n, at)[::-1])[::-1], n)
    skip = np.append(_next_at_depth(depth, ~ignored & ~opens), n)
    outer = np.append(_next_at_depth(depth, closes), n)
    return left, (vis, skip, outer)


def _depths(sym: np.ndarray, codes: dict):
    """Where a string has ``[`` and ``]`` (two (n,) bool arrays), and the bracket depth
    before each module (a ``]`` is inside the branch it closes)."""
    opens = sym == codes.get("[", -2)
    closes = sym == codes.get("]", -2)
    return opens, closes, np.cumsum(opens.astype(np.int64) - closes) - opens + closes


def _last_before(group: np.ndarray, kind: np.ndarray, want: np.ndarray) -> np.ndarray:
    """For each position i, the last position p < i where ``kind`` holds and
    ``group[p] == want[i]``; -1 for none (``group`` and ``want`` at least 0)."""
    n = len(group)
    where = np.flatnonzero(kind)
    keys = np.sort(group[where] * (n + 1) + where)
    k = np.searchsorted(keys, want * (n + 1) + np.arange(n)) - 1
    hit = keys[np.maximum(k, 0)] if keys.size else np.zeros(n, dtype=np.int64)
    return np.where((k >= 0) & (hit // (n + 1) == want), hit % (n + 1), -1)


def _next_at_depth(depth: np.ndarray, kind: np.ndarray, at: np.ndarray | None = None) -> np.ndarray:
    """For each position ``at`` (default: all), the first position from it on whose
    bracket depth is its own and where ``kind`` holds; n (the string's length) for none."""
    n = len(depth)
    at = np.arange(n) if at is None else at
    where = np.flatnonzero(kind)
    keys = np.append(np.sort(depth[where] * (n + 1) + where), np.iinfo(np.int64).max)
    hit = keys[np.searchsorted(keys, depth[at] * (n + 1) + at)]
    return np.where(hit // (n + 1) == depth[at], hit % (n + 1), n)


def _left_of(stack: list[int], ch: str, i: int, ignore: frozenset[str]) -> int:
    """The left context neighbour of module ``i`` (symbol ``ch``) of a string read from the
    left, -1 for none or a bracket; ``stack`` holds, per bracket depth, the last visible
    module before it, and is updated past it."""
    if ch == "[":
        stack.append(stack[-1])
    elif ch == "]":
        if len(stack) > 1:
            stack.pop()
    else:
        left = stack[-1]
        if ch not in ignore:
            stack[-1] = i
        return left
    return -1


def _walk(pats: tuple[Pattern, ...], start: np.ndarray, jumps, sym, nparam, codes: dict):
    """Match ``pats`` rightwards from positions ``start``, as L-Py matches a right context
    (vectorised over the starts): ignored modules are skipped; a module pattern skips whole
    branches ``[...]`` and fails at a ``]`` (the end of its branch); a ``[`` must meet a
    ``[``; a ``]`` skips the rest of the branch the walk is in and steps out of it.

    Returns the starts that match, per module pattern the position it matched (by pattern
    index), and the position after the last one matched.
    """
    vis, skip, outer = jumps
    n = len(sym)
    sym = np.append(sym, -1)
    nparam = np.append(nparam, -1)
    ok = np.ones(len(start), dtype=bool)
    rows = {}
    p = np.minimum(start, n)
    for k, pat in enumerate(pats):
        if pat.symbol == "[":
            p = vis[p]
            ok &= sym[p] == codes.get("[", -2)
        elif pat.symbol == "]":
            p = vis[p]
            p = np.where(sym[p] == codes.get("]", -2), p, outer[p])
            ok &= p < n
        else:
            p = skip[p]
            ok &= (sym[p] == codes.get(pat.symbol, -2)) & (nparam[p] == len(pat.params))
            rows[k] = np.where(ok, p, 0)
        p = np.minimum(p + 1, n)
    return ok, rows, p


def _match_context(idx, pats: tuple[Pattern, ...], neighbour, step_order, sym, nparam, codes):
    """Filter ``idx`` to modules whose context chain matches ``pats``.

    Returns the surviving positions in ``idx`` and, per pattern, the context module indices.
    """
    keep = np.ones(len(idx), dtype=bool)
    ctx_idx = {}
    cur = idx
    for k in step_order(range(len(pats))):
        pat = pats[k]
        nb = neighbour[cur]
        ok = nb >= 0
        safe = np.where(ok, nb, 0)
        code = codes.get(pat.symbol, -1)
        ok &= (sym[safe] == code) & (nparam[safe] == len(pat.params))
        keep &= ok
        ctx_idx[k] = safe
        cur = safe
    return keep, ctx_idx


def derive(grammar: Grammar, iterations: int | None = None, seed: int | None = None,
           max_modules: int | None = None, progress=None, *, limits: Limits | None = None,
           work: Meter | None = None, environment=None) -> ModuleString:
    """Rewrite the axiom ``iterations`` times (default: the grammar's).

    Each step has two phases: :func:`_select_rewrites` finds, rule group by rule group in
    file order, the modules each rule rewrites (predecessor, context, condition, then the
    stochastic choice among alternatives); :func:`_rewrite` writes the new string, every
    untouched module copied and every rewritten one replaced by its successor.

    Parameters
    ----------
    grammar : Grammar
    iterations, seed : override the grammar's values
    max_modules : the size limit (default: ``limits.max_modules``; the grammar's
        ``max_modules`` lowers either, never raises it)
    progress : optional callable(step, n_modules) called after each step
    limits : the budgets (default: :data:`plantgen.limits.limits`)
    work : the ``derive_work`` meter to spend (a scene shares one over its derivations);
        default: a fresh one of ``limits``
    environment : what answers the grammar's ``?E`` modules (:mod:`plantgen.lsystem.queries`);
        a grammar with query or communication modules is interpreted after the axiom and
        after each step, and its modules receive the answers before the next step
    """
    run = Derivation(grammar, iterations, seed, max_modules, progress, limits=limits, work=work,
                     environment=environment)
    run.answer()
    while run.rewrite():
        run.answer()
    return run.result()


class Derivation:
    """One derivation, a step at a time (what :func:`derive` runs): :meth:`rewrite` applies
    the rules once, :meth:`answer` then gives the query and communication modules their
    values (and looks for a fixed point or a cycle). Plants that grow together in one
    environment (:mod:`plantgen.environment.together`) rewrite each in turn, then are
    answered each in turn; ``together`` turns off the cycle skip (a plant's future then
    depends on its neighbours too)."""

    def __init__(self, grammar: Grammar, iterations: int | None = None, seed: int | None = None,
                 max_modules: int | None = None, progress=None, *, limits: Limits | None = None,
                 work: Meter | None = None, environment=None, together: bool = False):
        limits = (limits or default_limits).raised(modules=max_modules).lowered(modules=grammar.max_modules)
        self.iterations = grammar.iterations if iterations is None else int(iterations)
        limits.check("iterations", self.iterations, f"{grammar.path}: iterations")
        seed = grammar.seed if seed is None else int(seed)
        self.grammar, self.limits, self.progress = grammar, limits, progress
        self.work = work or limits.meter("derive_work")
        self.rng = np.random.default_rng(seed)
        self.codes = {s: i for i, s in enumerate(grammar.symbols)}
        self.width = _width(grammar)
        self.state = dict(grammar.globals)
        self.string = _cut(_axiom_string(grammar, self.rng, self.codes, self.width, self.state), self.codes)
        if len(self.string[0]) > limits.max_modules:
            raise DerivationLimit(f"{grammar.path}: the axiom alone exceeds the limit of {limits.max_modules} "
                                  "modules")
        self.queries = Queries(grammar, environment, limits, self.work) if uses_queries(grammar) else None
        self.groups = _rule_groups(grammar.rules)
        self.together = together
        self.seen: dict[bytes, int] | None = None if together else {}   # state fingerprint -> its step
        self.step, self.total = 0, len(self.string[0])
        self.before = self.fixed_point = None     # the string, generator state and globals before the last step
        self.ended = False
        self.step_floor = STEP_WORK * (len(self.groups) + 1)     # the least any step spends
        self.state = run_hook(grammar, "start", self.state, self.rng)

    def rewrite(self) -> bool:
        """One derivation step (False, and nothing done, once every step is done)."""
        if self.step >= self.iterations:
            if not self.ended:             # once, after the last step
                self.ended = True
                self.state = run_hook(self.grammar, "end", self.state, self.rng)
            return False
        g, string = self.grammar, self.string
        self.before = (string, self.rng.bit_generator.state, dict(self.state))
        self.state = run_hook(g, "start_each", self.state, self.rng)
        self.string, total, _, self.state = _step(g, self.groups, string, self.rng, self.codes, self.width,
                                                  self.limits, self.work, self.step, "derivation step", self.state)
        if g.decomposition:
            self.string, self.state = _passes(g, g.decomposition, g.decomposition_depth, self.string, self.rng,
                                              self.codes, self.width, self.limits, self.work,
                                              f"decomposition after step {self.step + 1}, pass", self.state)
        self.state = run_hook(g, "end_each", self.state, self.rng)
        self.step, self.total = self.step + 1, total
        return True

    def interpret(self) -> None:
        """Walk the turtle over the string for its query modules (nothing without any)."""
        if self.queries is not None:
            self.queries.interpret(self.string, self.step)

    def answer(self) -> None:
        """Write the query modules' values and the environment's answers (walking the turtle
        first unless :meth:`interpret` did), report the step, stop at a fixed point (the
        step left the string and the generator as they were), and skip whole periods of a
        cycle once the state comes back (neither for plants grown together)."""
        if self.queries is not None:
            self.queries.update(self.string, self.step)
        if self.step and self.progress is not None:
            self.progress(self.step, self.total)
        if (not self.together and self.before is not None and _unchanged(self.before[0], self.string)
                and self.rng.bit_generator.state == self.before[1] and self.state == self.before[2]):   # a fixed point
            self.fixed_point, self.iterations = self.step - 1, self.step
            return
        if self.step == SETTLE_STEPS:
            self._check_floor()
        if self.seen is None or self.total > CYCLE_WINDOW:
            return
        key = _fingerprint(self.string, self.rng, self.state)
        if key in self.seen:                  # the state of step seen[key] again: skip whole periods
            period = self.step - self.seen[key]
            self.iterations = self.step + (self.iterations - self.step) % period
            self.seen = None
        else:
            self.seen[key] = self.step

    def _check_floor(self) -> None:
        """Refuse, with the estimate, a derivation that has not settled by ``SETTLE_STEPS``
        and whose remaining steps alone would spend past its ``derive_work`` budget."""
        floor = (self.iterations - self.step) * self.step_floor
        if self.work.spent + floor > self.work.limit:
            raise LimitError(f"{self.grammar.path}: {self.iterations:,} derivation steps spend at least "
                             f"{self.work.spent + floor:,} of derive_work (each at least {self.step_floor:,}), "
                             f"over the limit of {self.work.limit:,}, and the derivation did not settle into a "
                             f"fixed point or a cycle in its first {SETTLE_STEPS:,} steps ({hint(self.work.name)})")

    def result(self) -> ModuleString:
        return ModuleString(*self.string, self.grammar.symbols, fixed_point=self.fixed_point,
                            globals=dict(self.state) if self.state else None)


def steps_floor(grammar: Grammar, iterations: int | None = None) -> int:
    """The least ``derive_work`` that ``iterations`` steps of ``grammar`` (its own count by
    default) spend when none is skipped: ``STEP_WORK`` a rule group, plus one, a step."""
    steps = grammar.iterations if iterations is None else int(iterations)
    return steps * STEP_WORK * (len(_rule_groups(grammar.rules)) + 1)


def _unchanged(before, after) -> bool:
    """Whether a step left the string as it was (sym, nparam, params all equal)."""
    return len(before[0]) == len(after[0]) and all(np.array_equal(a, b) for a, b in zip(before, after, strict=True))



def apply_interpretation(grammar: Grammar, ms: ModuleString, seed: int | None = None, *,
                         limits: Limits | None = None, work: Meter | None = None) -> ModuleString:
    """The string to draw: ``ms`` rewritten by the grammar's ``interpretation:`` rules
    ``grammar.interpretation_depth`` times (``ms`` itself when there are none). Each pass
    is one parallel rewriting step like a derivation step (context, conditions,
    stochastic choice from its own generator seeded by ``seed``, ``%`` cuts), under the
    same size limits and work meter. ``ms`` is not modified."""
    if not grammar.interpretation:
        return ms
    limits = (limits or default_limits).lowered(modules=grammar.max_modules)
    work = work or limits.meter("derive_work")
    seed = grammar.seed if seed is None else int(seed)
    rng = np.random.default_rng([seed, 1])        # not the derivation's stream
    codes = {s: i for i, s in enumerate(grammar.symbols)}
    width = max(_width(grammar), ms.params.shape[1])
    params = np.zeros((len(ms), width))
    params[:, :ms.params.shape[1]] = ms.params
    string = (ms.sym.copy(), ms.nparam.copy(), params)
    state = ms.globals if ms.globals is not None else dict(grammar.globals)
    string, _ = _passes(grammar, grammar.interpretation, grammar.interpretation_depth, string, rng, codes, width,
                        limits, work, "interpretation pass", state)
    return ModuleString(*string, grammar.symbols)


def _passes(grammar: Grammar, rules: tuple[Rule, ...], depth: int, string, rng, codes: dict, width: int,
            limits: Limits, work: Meter, what: str, state: dict):
    """``string`` rewritten by ``rules`` up to ``depth`` times, each pass one parallel
    step (stopping at the first pass that rewrites nothing): the interpretation passes,
    and the decomposition after each derivation step. Returns it and the globals (which
    rules with ``set`` change)."""
    view = replace(grammar, rules=rules)
    groups = _rule_groups(view.rules)
    for step in range(depth):
        string, _, rewritten, state = _step(view, groups, string, rng, codes, width, limits, work, step, what,
                                            state, idle=False)
        if not rewritten:
            break
    return string, state


def _step(grammar: Grammar, groups: list[list[Rule]], string, rng, codes: dict, width: int, limits: Limits,
          work: Meter, step: int, what: str, state: dict, idle: bool = True):
    """One rewriting step of ``grammar``'s rules (``groups``) with the globals ``state``:
    the new string (``%`` cuts applied), its length before the cuts, whether any rule
    applied (without ``idle``, a step where none applies leaves the string as it was) and
    the globals after it. In parallel, as :func:`_select_rewrites` and :func:`_rewrite` do;
    cut at each module that sets globals when a rule sets some (:func:`_stateful_step`);
    or, for rules with a new left context (``<<``), sequentially from left to right
    (:func:`_sequential`, which runs each ``set`` where it applies)."""
    rules = [r for alts in groups for r in alts]
    contexts = any(r.left or r.right or r.more or r.new_left for r in rules)
    neighbours = context_neighbours(string[0], grammar.symbols, grammar.ignore) if contexts else None
    where = f"{grammar.path}: {what} {step + 1}"

    def check(total: int) -> None:
        _check_step(grammar, limits, step, total, width, what)

    if any(r.new_left for r in rules):
        tries = sum(int(np.count_nonzero(string[0] == codes[alts[0].pred.symbol])) for alts in groups)
        work.spend((len(string[0]) + tries) * SEQUENTIAL_WORK + STEP_WORK * (len(groups) + 1), where)
        new, rewritten, state = _sequential(grammar, groups, string, neighbours, rng, codes, width, check, state)
        total = len(new[0])
    elif _sets_globals(rules):
        work.spend(len(string[0]) * (CONTEXT_WORK if contexts else 1) + STEP_WORK * (len(groups) + 1), where)
        new, total, state, rewritten = _stateful_step(grammar, groups, string, neighbours, rng, codes, width, state,
                                                      check, work, where)
    else:
        matched, out_len, applied = _select_rewrites(grammar, groups, string, neighbours, rng, codes, state)
        total, rewritten = int(out_len.sum()), bool(matched.any())
        if not (rewritten or idle):
            return string, total, False, state
        check(total)
        work.spend(total * (CONTEXT_WORK if contexts else 1) + STEP_WORK * (len(groups) + 1), where)
        new = _rewrite(grammar, string, matched, out_len, applied, rng, codes, width)
    if not (rewritten or idle):
        return string, total, False, state
    return _cut(new, codes), total, rewritten, state


def _sequential(grammar: Grammar, groups: list[list[Rule]], string, neighbours, rng, codes: dict, width: int,
                check, state: dict):
    """A sequential step, as L-Py rewrites with new contexts: module by module from left to
    right, each rewritten by the first rule group that matches it, a new left context
    (``<<``) matched in the string written so far, a rule's ``set`` run where it applies
    (after its successor is written, as in a step cut at each module that sets globals);
    ``check(total)`` refuses a string grown too long before it is written. Returns the new
    string, whether any rule applied and the globals."""
    sym, nparam, params = string
    n = len(sym)
    firsts = {codes[alts[0].pred.symbol] for alts in groups}
    reach = max(len(r.new_left) for alts in groups for r in alts)
    out_sym: list[int] = []
    out_np: list[int] = []
    out_par: list[np.ndarray] = []
    chain: list[int] = []          # each new module's left context neighbour (or -1)
    stack = [-1]                   # per bracket depth, the last visible new module
    symbols, ignore = grammar.symbols, grammar.ignore
    none = np.zeros(n, dtype=bool)
    rewritten = False

    def append(s_: int, k_: int, p_: np.ndarray) -> None:
        chain.append(_left_of(stack, symbols[s_], len(out_sym), ignore))
        out_sym.append(s_)
        out_np.append(k_)
        out_par.append(p_)

    sym_l, nparam_l = sym.tolist(), nparam.tolist()
    i = 0
    while i < n:
        found = None
        if sym_l[i] in firsts:
            found, alts = _first_group(grammar, groups, string, none, neighbours, rng, codes, i,
                                       _new_context(stack[-1], chain, out_sym, out_np, out_par, reach, width),
                                       state)
        if found is None:
            append(sym_l[i], nparam_l[i], params[i])
            i += 1
            continue
        idx, env, end = found
        for _, rule, sub_env in _choose_alternatives(alts, idx, env, rng):
            check(len(out_sym) + len(rule.successor) + n - i)
            try:
                s_, k_, p_ = _instantiate(rule.successor, sub_env, rng, 1, codes, width)
            except ExprError as exc:
                raise PlantgenError(f"{grammar.path}: {rule.where()}: {exc}") from None
            for j, (sj, kj) in enumerate(zip(s_.tolist(), k_.tolist(), strict=True)):
                append(sj, kj, p_[j, 0])
            if rule.effects:              # its set runs here: the modules after it see the new values
                state = {**state, **_setting(grammar, rule.effects, sub_env, rng, rule.where())}
        rewritten = True
        i = int(end[0])
    new_par = np.array(out_par).reshape(-1, width) if out_par else np.zeros((0, width))
    return (np.array(out_sym, dtype=np.int32), np.array(out_np, dtype=np.int8), new_par), rewritten, state


def _first_group(grammar: Grammar, groups: list[list[Rule]], string, none, neighbours, rng, codes: dict, i: int,
                 new, state: dict):
    """The first rule group that matches at position ``i`` of a sequential step, with its
    match (as :func:`_match_group` gives it): (match, group), or (None, None)."""
    at = np.array([i])
    for alts in groups:
        found = _match_group(grammar, alts[0], string, none, neighbours, rng, codes, state, at, new)
        if found is not None:
            return found, alts
    return None, None


def _new_context(top: int, chain: list[int], out_sym: list[int], out_np: list[int], out_par: list, reach: int,
                 width: int):
    """The new string's modules a new left context can reach from the next module (its
    ``reach`` nearest left neighbours, nearest first), as ``_match_group`` takes them: (a
    placeholder of the next module's index, the neighbour chain with the next module's at
    the end, sym, nparam, params)."""
    at = []
    while top >= 0 and len(at) < reach:
        at.append(top)
        top = chain[top]
    k = len(at)
    neighbour = np.array([*range(1, k), -1, 0] if k else [-1], dtype=np.int64)
    sym = np.array([out_sym[p] for p in at] or [-1], dtype=np.int32)
    nparam = np.array([out_np[p] for p in at] or [-1], dtype=np.int8)
    params = np.array([out_par[p] for p in at]).reshape(-1, width) if at else np.zeros((1, width))
    return neighbour[:k], neighbour, sym, nparam, params


def cut_branches(ms: ModuleString) -> ModuleString:
    """``ms`` with each ``%`` and the rest of its branch removed (see the module's notes)."""
    return ModuleString(*_cut((ms.sym, ms.nparam, ms.params), {s: i for i, s in enumerate(ms.symbols)}),
                        ms.symbols)


def _cut(string, codes: dict):
    """Remove each ``%`` and what follows it up to (not including) the ``]`` closing its
    branch, or to the end of the string at depth 0. Vectorised: the closing ``]`` of a
    ``%`` at depth d is the first ``]`` after it whose depth before it is d."""
    sym, nparam, params = string
    cut = codes.get(CUT_SYMBOL)
    if cut is None:
        return string
    at = np.flatnonzero(sym == cut)
    if at.size == 0:
        return string
    n = len(sym)
    _, closes, depth = _depths(sym, codes)
    end = _next_at_depth(depth, closes, at)
    mark = np.zeros(n + 1, dtype=np.int64)
    np.add.at(mark, at, 1)
    np.add.at(mark, end, -1)
    keep = np.cumsum(mark[:n]) == 0
    return sym[keep], nparam[keep], params[keep]


def _check_step(grammar: Grammar, limits: Limits, step: int, total: int, width: int,
                what: str = "derivation step") -> None:
    """Refuse a step whose string would exceed ``max_modules`` or ``max_derive_bytes``."""
    if total > limits.max_modules:
        raise DerivationLimit(
            f"{grammar.path}: {what} {step + 1} would make {total:,} modules, "
            f"over the limit of {limits.max_modules:,} (lower iterations or raise --max-modules)")
    size = total * module_bytes(width)
    if size > limits.max_derive_bytes:
        raise DerivationLimit(
            f"{grammar.path}: {what} {step + 1} would make {total:,} modules of {width} "
            f"parameters, {size:,} bytes, over the limit of {limits.max_derive_bytes:,} "
            f"({hint('derive_bytes')})")


def _fingerprint(string, rng, state: dict) -> bytes:
    """A digest of the derivation's state: the module string, the generator's state and
    the globals (a step is a function of these alone)."""
    h = hashlib.blake2b(digest_size=16)
    for array in string:
        h.update(np.ascontiguousarray(array).tobytes())
    h.update(repr(rng.bit_generator.state).encode())
    h.update(repr(sorted(state.items())).encode())
    return h.digest()


def _axiom_string(grammar: Grammar, rng, codes: dict, width: int, state: dict):
    """The axiom as a module string: (sym (n,) int32, nparam (n,) int8, params (n, width))."""
    try:
        sym, nparam, params = _instantiate(grammar.axiom, {**grammar.defines, **state}, rng, 1, codes, width)
    except ExprError as exc:
        raise PlantgenError(f"{grammar.path}: axiom: {exc}") from None
    return sym, nparam, params[:, 0, :]


def _rule_groups(rules: tuple[Rule, ...]) -> list[list[Rule]]:
    """Rules grouped by predecessor, context and condition, in the order of the file: each
    group is one rule or the stochastic alternatives of one."""
    groups: list[list[Rule]] = []
    index: dict[tuple, int] = {}
    for r in rules:
        key = r.group_key
        if key not in index:
            index[key] = len(groups)
            groups.append([])
        groups[index[key]].append(r)
    return groups


def _select_rewrites(grammar: Grammar, groups: list[list[Rule]], string, neighbours, rng,
                     codes: dict, state: dict | None = None, done: np.ndarray | None = None):
    """Which rule rewrites which module in this step (the first matching group wins; the
    matches of a predecessor of several modules taken from left to right, none overlapping).

    Returns
    -------
    matched : (n,) bool, modules some rule rewrites
    out_len : (n,) int64, length of each module's replacement (1 when untouched, 0 for the
        second and later modules of a predecessor of several)
    applied : list of (modules (k,) int, rule, env): each rule with the modules it rewrites
        (the first of each predecessor) and its parameter values there

    ``state``: the globals' values; ``done``: modules already rewritten (or kept) this step.
    """
    sym = string[0]
    n = len(sym)
    matched = np.zeros(n, dtype=bool) if done is None else done.copy()
    out_len = np.ones(n, dtype=np.int64)
    applied: list[tuple[np.ndarray, Rule, dict]] = []
    for alts in groups:
        found = _match_group(grammar, alts[0], string, matched, neighbours, rng, codes, state or {})
        if found is None:
            continue
        idx, env, end = found
        covered = _ranges(idx, end)
        matched[covered] = True
        out_len[covered] = 0
        for sub, rule, sub_env in _choose_alternatives(alts, idx, env, rng):
            out_len[sub] = len(rule.successor)
            applied.append((sub, rule, sub_env))
    return matched, out_len, applied


def _ranges(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """The positions of the runs ``start[k] <= i < end[k]``, concatenated."""
    lengths = end - start
    if lengths.size and lengths.max() == 1:
        return start
    first = np.cumsum(lengths) - lengths
    return np.repeat(start - first, lengths) + np.arange(int(lengths.sum()))


def _match_group(grammar: Grammar, rule: Rule, string, matched: np.ndarray, neighbours, rng,
                 codes: dict, state: dict, candidates: np.ndarray | None = None, new=None):
    """The modules not yet matched that ``rule``'s predecessor, context and condition match,
    with the environment its expressions see there (the globals' values ``state`` besides
    the defines and the modules' parameters) and where each match ends: ((k,) int,
    env, (k,) int), or None for none. ``candidates`` limits the search to those positions;
    ``new`` is (left neighbours, the next module's, sym, nparam, params) of the string being
    written, for a new left context (``<<``, a sequential step)."""
    sym, nparam, params = string
    code = codes[rule.pred.symbol]
    if candidates is None:
        idx = np.flatnonzero((sym == code) & (nparam == len(rule.pred.params)) & ~matched)
    else:
        idx = candidates[(sym[candidates] == code) & (nparam[candidates] == len(rule.pred.params))]
    if idx.size == 0:
        return None
    end = idx + 1
    bound = [(rule.pred, idx, params)]
    if rule.more or rule.left or rule.right or rule.new_left:
        left_nb, jumps = neighbours
        keep, more_rows, end = _walk(rule.more, idx + 1, jumps, sym, nparam, codes)
        if rule.more:
            taken = np.concatenate([[0], np.cumsum(matched)])
            keep &= taken[end] == taken[idx]          # none of the run rewritten already
        keep_l, left_ctx = _match_context(idx, rule.left, left_nb, reversed, sym, nparam, codes)
        keep_r, right_ctx, _ = _walk(rule.right, end, jumps, sym, nparam, codes)
        keep &= keep_l & keep_r
        new_ctx = {}
        if rule.new_left:                      # one candidate: the module the sequential step is at
            chain, neighbour, new_sym, new_nparam, new_params = new
            keep_n, new_ctx = _match_context(np.array([len(chain)]), rule.new_left, neighbour, reversed,
                                             new_sym, new_nparam, codes)
            keep &= keep_n
        idx, end = idx[keep], end[keep]
        if idx.size == 0:
            return None
        bound = [(rule.pred, idx, params)]
        for pats, rows_of, values in ((rule.more, more_rows, params), (rule.left, left_ctx, params),
                                      (rule.right, right_ctx, params), (rule.new_left, new_ctx, new and new[4])):
            bound += [(pats[k], rows[keep], values) for k, rows in rows_of.items()]
    env = {**grammar.defines, **state}
    for pat, rows, values in bound:
        for c, name in enumerate(pat.params):
            env[name] = values[rows, c]
    if rule.condition is not None:
        try:
            ok = np.broadcast_to(rule.condition(EvalContext(env, rng, idx.size)), idx.shape) != 0
        except ExprError as exc:
            raise PlantgenError(f"{grammar.path}: {rule.where()}: {exc}") from None
        idx, end = idx[ok], end[ok]
        env = _rows(env, ok)
        if idx.size == 0:
            return None
    if rule.more and idx.size > 1 and (end[:-1] > idx[1:]).any():
        ok = _leftmost(idx, end)
        idx, end, env = idx[ok], end[ok], _rows(env, ok)
    return idx, env, end


def _leftmost(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Which of the runs ``[start, end)`` (sorted by start) a left-to-right scan takes: each
    run that begins after the last one taken ends."""
    keep = np.zeros(len(start), dtype=bool)
    free = -1
    for k, (a, b) in enumerate(zip(start.tolist(), end.tolist(), strict=True)):
        if a >= free:
            keep[k], free = True, b
    return keep


def _choose_alternatives(alts: list[Rule], idx: np.ndarray, env: dict, rng):
    """Split the matched modules ``idx`` among a group's alternatives, drawing one random
    number per module for a stochastic group: [(modules, rule, env)] for each chosen rule."""
    if len(alts) == 1:
        choice = np.zeros(idx.size, dtype=np.int64)
    else:
        cum = np.cumsum([r.p for r in alts])
        choice = np.minimum(np.searchsorted(cum / cum[-1], rng.random(idx.size), side="right"),
                            len(alts) - 1)
    chosen = []
    for a, rule in enumerate(alts):
        sel = choice == a
        if sel.any():
            chosen.append((idx[sel], rule, _rows(env, sel)))
    return chosen


def _rows(env: dict, selection: np.ndarray) -> dict:
    """``env`` with every per-module array cut to ``selection``; defines stay scalars."""
    return {k: (v[selection] if isinstance(v, np.ndarray) else v) for k, v in env.items()}


def _rewrite(grammar: Grammar, string, matched: np.ndarray, out_len: np.ndarray, applied, rng,
             codes: dict, width: int):
    """The next module string: untouched modules copied, each rewritten module replaced by
    its rule's successor, evaluated in ``applied`` order (rules in file order)."""
    return _assemble(string, matched, out_len, _successors(grammar, applied, rng, codes, width), width)


def _successors(grammar: Grammar, applied, rng, codes: dict, width: int) -> list:
    """Each applied rule's successor evaluated where it applies: [(modules, sym, nparam, params)]."""
    pieces = []
    for sub, rule, sub_env in applied:
        if not rule.successor:
            continue
        try:
            pieces.append((sub, *_instantiate(rule.successor, sub_env, rng, sub.size, codes, width)))
        except ExprError as exc:
            raise PlantgenError(f"{grammar.path}: {rule.where()}: {exc}") from None
    return pieces


def _assemble(string, matched: np.ndarray, out_len: np.ndarray, pieces: list, width: int):
    """The new string from the old one, the rewritten modules and their successors."""
    sym, nparam, params = string
    total = int(out_len.sum())
    offsets = np.cumsum(out_len) - out_len
    new_sym = np.empty(total, dtype=np.int32)
    new_np = np.empty(total, dtype=np.int8)
    new_par = np.zeros((total, width))
    keep = ~matched
    new_sym[offsets[keep]] = sym[keep]
    new_np[offsets[keep]] = nparam[keep]
    new_par[offsets[keep]] = params[keep]
    for sub, s, k, p in pieces:
        # (k, L): each rewritten module's successor run in place, one after the next, so the
        # writes go through the new string once in order (L passes a successor position at
        # a time strode the whole string, slower per module the more it outgrew the cache)
        pos = offsets[sub][:, None] + np.arange(len(s))[None, :]
        new_sym[pos] = s[None, :]
        new_np[pos] = k[None, :]
        new_par[pos] = p.swapaxes(0, 1)
    return new_sym, new_np, new_par


def _setting(grammar: Grammar, effects, env: dict, rng, what: str) -> dict:
    """The globals ``effects`` set, each computed from ``env`` (one module's, or the
    globals' and defines' for a hook) before any is set."""
    out = {}
    for name, expr in effects:
        try:
            out[name] = float(np.asarray(expr(EvalContext(env, rng, 1))).reshape(-1)[0])
        except ExprError as exc:
            raise PlantgenError(f"{grammar.path}: {what}: setting {name}: {exc}") from None
    return out


def run_hook(grammar: Grammar, key: str, state: dict, rng) -> dict:
    """The globals after the grammar's hook ``key`` (``state`` itself without one)."""
    effects = grammar.hooks.get(key)
    if not effects:
        return state
    return {**state, **_setting(grammar, effects, {**grammar.defines, **state}, rng, f"hooks: {key}")}


def _sets_globals(rules) -> bool:
    return any(r.effects for r in rules)


def _stateful_step(grammar: Grammar, groups, string, neighbours, rng, codes: dict, width: int, state: dict,
                   check, work: Meter, where: str):
    """One parallel step whose rules set globals, cut at each module that sets some: the
    modules up to it (the whole run of a predecessor of several modules that sets them)
    are rewritten with the globals as they are, then its rule's ``set`` runs and the rest
    is matched again. Returns (the new string, its length, the globals, whether any
    module was rewritten); ``where`` names the step in messages."""
    n = len(string[0])
    done = np.zeros(n, dtype=bool)
    matched_all = np.zeros(n, dtype=bool)
    out_len = np.ones(n, dtype=np.int64)
    pieces: list = []
    pos = 0
    while pos < n:
        done[:pos] = True
        matched, lens, applied = _select_rewrites(grammar, groups, string, neighbours, rng, codes, state, done)
        setters = [int(sub.min()) for sub, rule, _ in applied if rule.effects and sub.size]
        upto = n
        if setters:
            stop = min(setters)
            starts = np.zeros(n, dtype=bool)
            for sub, _, _ in applied:
                starts[sub] = True
            follows = matched[stop + 1:] & ~starts[stop + 1:]     # the rest of the setter's run
            upto = stop + 1 + (int(np.argmin(follows)) if not follows.all() else follows.size)
        keep_applied = []
        for sub, rule, env in applied:
            sel = sub < upto
            if sel.any():
                keep_applied.append((sub[sel], rule, _rows(env, sel)))
        new = matched & ~done
        new[upto:] = False
        matched_all |= new
        out_len[new] = lens[new]
        check(int(out_len[:upto].sum()) + (n - upto))
        pieces += _successors(grammar, keep_applied, rng, codes, width)
        if setters:
            sub, rule, env = next(a for a in keep_applied if a[1].effects and a[0][0] == stop)
            row = _rows(env, sub == stop)
            state = {**state, **_setting(grammar, rule.effects, row, rng, rule.where())}
            work.spend(n - upto + SETTER_WORK * (len(groups) + 1),
                       f"{where}: a rule setting globals (each such module matches the rest again)")
        pos = upto
    total = int(out_len.sum())
    return _assemble(string, matched_all, out_len, pieces, width), total, state, bool(matched_all.any())
