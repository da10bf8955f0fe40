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
each module that sets a globals, so the modules after it see the new values (L-Py's
sequential semantics); each cut re-matches the rest of the string, spending its modules
again from the work budget. Interpretation rules read the values the derivation ended with.

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
from ..limits import CONTEXT_WORK, STEP_WORK, LimitError, Limits, Meter, hint
from ..limits import limits as default_limits
from .expr import EvalContext, ExprError
from .grammar import Grammar, ModuleTemplate, Pattern, Rule
from .queries import Queries, uses_queries
from .strings import ModuleString, module_bytes
from .symbols import Action, by_action

__all__ = ["DEFAULT_MAX_MODULES", "Derivation", "DerivationLimit", "ModuleString", "apply_interpretation",
           "cut_branches", "derive", "module_bytes"]

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


def _context_neighbours(ms_sym: np.ndarray, symbols: tuple[str, ...], ignore: frozenset[str]):
    """For each module, the index of its left and right context neighbour (or -1).

    ABOP semantics: ignored symbols are skipped; looking left, a whole bracketed branch
    ``[...]`` is skipped and an opening ``[`` is stepped over to the module the branch
    grows from; looking right, a branch ``[...]`` is skipped and a ``]`` ends the context.
    """
    n = len(ms_sym)
    seq = [symbols[s] for s in ms_sym.tolist()]
    left = np.full(n, -1, dtype=np.int64)
    right = np.full(n, -1, dtype=np.int64)
    # Left: walk forward keeping, per bracket depth, the last visible module.
    stack = [-1]
    for i, ch in enumerate(seq):
        if ch == "[":
            stack.append(stack[-1])
        elif ch == "]":
            if len(stack) > 1:
                stack.pop()
        else:
            left[i] = stack[-1]
            if ch not in ignore:
                stack[-1] = i
    # Right: walk backward keeping, per depth, the next visible module of the same branch.
    stack = [-1]
    for i in range(n - 1, -1, -1):
        ch = seq[i]
        if ch == "]":
            stack.append(-1)
        elif ch == "[":
            if len(stack) > 1:
                stack.pop()
        else:
            right[i] = stack[-1]
            if ch not in ignore:
                stack[-1] = i
    return left, right


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
        self.queries = Queries(grammar, environment, limits) if uses_queries(grammar) else None
        self.groups = _rule_groups(grammar.rules)
        self.needs_context = any(r.left or r.right for r in grammar.rules)
        self.together = together
        self.seen: dict[bytes, int] | None = None if together else {}   # state fingerprint -> its step
        self.step, self.total = 0, len(self.string[0])
        self.before = self.fixed_point = None     # the string, generator state and globals before the last step
        self.ended = False
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
        neighbours = _context_neighbours(string[0], g.symbols, g.ignore) if self.needs_context else None
        what = f"derivation step {self.step + 1}"
        if _sets_globals(g.rules):
            self.work.spend(len(string[0]) * (CONTEXT_WORK if self.needs_context else 1)
                            + STEP_WORK * (len(self.groups) + 1), f"{g.path}: {what}")
            new, total, self.state, _ = _stateful_step(
                g, self.groups, string, neighbours, self.rng, self.codes, self.width, self.state,
                lambda t: _check_step(g, self.limits, self.step, t, self.width), self.work, what)
        else:
            matched, out_len, applied = _select_rewrites(g, self.groups, string, neighbours, self.rng, self.codes,
                                                         self.state)
            total = int(out_len.sum())
            _check_step(g, self.limits, self.step, total, self.width)
            self.work.spend(total * (CONTEXT_WORK if self.needs_context else 1) + STEP_WORK * (len(self.groups) + 1),
                            f"{g.path}: {what}")
            new = _rewrite(g, string, matched, out_len, applied, self.rng, self.codes, self.width)
        self.string = _cut(new, self.codes)
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
        if self.seen is None or self.total > CYCLE_WINDOW:
            return
        key = _fingerprint(self.string, self.rng, self.state)
        if key in self.seen:                  # the state of step seen[key] again: skip whole periods
            period = self.step - self.seen[key]
            self.iterations = self.step + (self.iterations - self.step) % period
            self.seen = None
        else:
            self.seen[key] = self.step

    def result(self) -> ModuleString:
        return ModuleString(*self.string, self.grammar.symbols, fixed_point=self.fixed_point,
                            globals=dict(self.state) if self.state else None)


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
    needs_context = any(r.left or r.right for r in view.rules)
    for step in range(depth):
        neighbours = (_context_neighbours(string[0], view.symbols, view.ignore) if needs_context else None)
        if _sets_globals(rules):
            work.spend(len(string[0]) * (CONTEXT_WORK if needs_context else 1) + STEP_WORK * (len(groups) + 1),
                       f"{grammar.path}: {what} {step + 1}")
            new, _, state, any_matched = _stateful_step(
                view, groups, string, neighbours, rng, codes, width, state,
                lambda t, step=step: _check_step(view, limits, step, t, width, what), work, f"{what} {step + 1}")
            if not any_matched:
                break
            string = _cut(new, codes)
            continue
        matched, out_len, applied = _select_rewrites(view, groups, string, neighbours, rng, codes, state)
        if not matched.any():
            break
        total = int(out_len.sum())
        _check_step(view, limits, step, total, width, what)
        work.spend(total * (CONTEXT_WORK if needs_context else 1) + STEP_WORK * (len(groups) + 1),
                   f"{grammar.path}: {what} {step + 1}")
        string = _cut(_rewrite(view, string, matched, out_len, applied, rng, codes, width), codes)
    return string, state


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
    opens = (sym == codes["["]).astype(np.int64) if "[" in codes else np.zeros(n, np.int64)
    closes = (sym == codes["]"]).astype(np.int64) if "]" in codes else np.zeros(n, np.int64)
    depth_before = np.cumsum(opens - closes) - opens + closes     # depth before each module
    close_at = np.flatnonzero(closes)
    keys = np.sort(depth_before[close_at] * (n + 1) + close_at)   # (depth, position) pairs
    keys = np.append(keys, np.iinfo(np.int64).max)                # sentinel: no ] left
    hit = keys[np.searchsorted(keys, depth_before[at] * (n + 1) + at)]
    same_depth = hit // (n + 1) == depth_before[at]
    end = np.where(same_depth, hit % (n + 1), n)
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
    """Which rule rewrites which module in this step (the first matching group wins).

    Returns
    -------
    matched : (n,) bool, modules some rule rewrites
    out_len : (n,) int64, length of each module's replacement (1 when untouched)
    applied : list of (modules (k,) int, rule, env): each rule with the modules it rewrites
        and its parameter values there

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
        idx, env = found
        matched[idx] = True
        for sub, rule, sub_env in _choose_alternatives(alts, idx, env, rng):
            out_len[sub] = len(rule.successor)
            applied.append((sub, rule, sub_env))
    return matched, out_len, applied


def _match_group(grammar: Grammar, rule: Rule, string, matched: np.ndarray, neighbours, rng,
                 codes: dict, state: dict):
    """The modules not yet matched that ``rule``'s predecessor, context and condition match,
    with the environment its expressions see there: ((k,) int, env), or None for none."""
    sym, nparam, params = string
    code = codes[rule.pred.symbol]
    idx = np.flatnonzero((sym == code) & (nparam == len(rule.pred.params)) & ~matched)
    if idx.size == 0:
        return None
    env = {**grammar.defines, **state}
    if rule.left or rule.right:
        left_nb, right_nb = neighbours
        keep_l, left_ctx = _match_context(idx, rule.left, left_nb, reversed, sym, nparam, codes)
        keep_r, right_ctx = _match_context(idx, rule.right, right_nb, iter, sym, nparam, codes)
        keep = keep_l & keep_r
        idx = idx[keep]
        if idx.size == 0:
            return None
        for ctx_pats, ctx_map in ((rule.left, left_ctx), (rule.right, right_ctx)):
            for k, pat in enumerate(ctx_pats):
                rows = ctx_map[k][keep]
                for c, name in enumerate(pat.params):
                    env[name] = params[rows, c]
    for c, name in enumerate(rule.pred.params):
        env[name] = params[idx, c]
    if rule.condition is not None:
        try:
            ok = np.broadcast_to(rule.condition(EvalContext(env, rng, idx.size)), idx.shape) != 0
        except ExprError as exc:
            raise PlantgenError(f"{grammar.path}: {rule.where()}: {exc}") from None
        idx = idx[ok]
        env = _rows(env, ok)
        if idx.size == 0:
            return None
    return idx, env


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
        pos = offsets[sub][None, :] + np.arange(len(s))[:, None]  # (L, k)
        new_sym[pos] = s[:, None]
        new_np[pos] = k[:, None]
        new_par[pos] = p
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
                   check, work: Meter, what: str):
    """One parallel step whose rules set globals, cut at each module that sets some: the
    modules up to it are rewritten with the globals as they are, then its rule's ``set``
    runs and the rest is matched again. Returns (the new string, its length, the globals,
    whether any module was rewritten)."""
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
        stop = min(setters) if setters else n - 1
        keep_applied = []
        for sub, rule, env in applied:
            sel = sub <= stop
            if sel.any():
                keep_applied.append((sub[sel], rule, _rows(env, sel)))
        new = matched & ~done
        new[stop + 1:] = False
        matched_all |= new
        out_len[new] = lens[new]
        check(int(out_len[:stop + 1].sum()) + (n - stop - 1))
        pieces += _successors(grammar, keep_applied, rng, codes, width)
        if setters:
            sub, rule, env = next(a for a in keep_applied if a[1].effects and a[0][0] == stop)
            row = _rows(env, sub == stop)
            state = {**state, **_setting(grammar, rule.effects, row, rng, rule.where())}
            work.spend(n - stop - 1 + SETTER_WORK * (len(groups) + 1),
                       f"{grammar.path}: {what}: a rule setting globals (each such module matches the rest again)")
        pos = stop + 1
    total = int(out_len.sum())
    return _assemble(string, matched_all, out_len, pieces, width), total, state, bool(matched_all.any())
