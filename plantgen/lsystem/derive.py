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

A derivation whose state (the string and the random generator's state) comes back stops
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

__all__ = ["DEFAULT_MAX_MODULES", "DerivationLimit", "ModuleString", "apply_interpretation", "cut_branches",
           "derive", "module_bytes"]

DEFAULT_MAX_MODULES = default_limits.max_modules

#: Strings up to this many modules are fingerprinted after each step to find a fixed point
#: or a cycle (hashing costs about as much as copying the string; longer strings that stop
#: growing are bounded by the work budget instead).
CYCLE_WINDOW = 65_536
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
    limits = (limits or default_limits).raised(modules=max_modules).lowered(modules=grammar.max_modules)
    iterations = grammar.iterations if iterations is None else int(iterations)
    limits.check("iterations", iterations, f"{grammar.path}: iterations")
    seed = grammar.seed if seed is None else int(seed)
    work = work or limits.meter("derive_work")
    rng = np.random.default_rng(seed)
    codes = {s: i for i, s in enumerate(grammar.symbols)}
    width = _width(grammar)

    string = _cut(_axiom_string(grammar, rng, codes, width), codes)
    if len(string[0]) > limits.max_modules:
        raise DerivationLimit(f"{grammar.path}: the axiom alone exceeds the limit of {limits.max_modules} modules")
    queries = Queries(grammar, environment, limits) if uses_queries(grammar) else None
    if queries is not None:
        queries.update(string, 0)
    groups = _rule_groups(grammar.rules)
    needs_context = any(r.left or r.right for r in grammar.rules)
    seen: dict[bytes, int] | None = {}    # fingerprint of a state -> the step it was reached
    if len(string[0]) <= CYCLE_WINDOW:
        seen[_fingerprint(string, rng)] = 0

    step, fixed_point = 0, None
    while step < iterations:
        before, state = string, rng.bit_generator.state
        neighbours = (_context_neighbours(string[0], grammar.symbols, grammar.ignore)
                      if needs_context else None)
        matched, out_len, applied = _select_rewrites(grammar, groups, string, neighbours, rng, codes)
        total = int(out_len.sum())
        _check_step(grammar, limits, step, total, width)
        work.spend(total * (CONTEXT_WORK if needs_context else 1) + STEP_WORK * (len(groups) + 1),
                   f"{grammar.path}: derivation step {step + 1}")
        string = _cut(_rewrite(grammar, string, matched, out_len, applied, rng, codes, width), codes)
        if grammar.decomposition:
            string = _passes(grammar, grammar.decomposition, grammar.decomposition_depth, string, rng, codes,
                             width, limits, work, f"decomposition after step {step + 1}, pass")
        step += 1
        if queries is not None:
            queries.update(string, step)
        if progress is not None:
            progress(step, total)
        if _unchanged(before, string) and rng.bit_generator.state == state:   # a fixed point: done
            fixed_point = step - 1
            break
        if seen is not None and total <= CYCLE_WINDOW:
            key = _fingerprint(string, rng)
            if key in seen:           # the state of step seen[key] again: skip whole periods
                period = step - seen[key]
                iterations = step + (iterations - step) % period
                seen = None
            else:
                seen[key] = step

    return ModuleString(*string, grammar.symbols, fixed_point=fixed_point)


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
    string = _passes(grammar, grammar.interpretation, grammar.interpretation_depth, string, rng, codes, width,
                     limits, work, "interpretation pass")
    return ModuleString(*string, grammar.symbols)


def _passes(grammar: Grammar, rules: tuple[Rule, ...], depth: int, string, rng, codes: dict, width: int,
            limits: Limits, work: Meter, what: str):
    """``string`` rewritten by ``rules`` up to ``depth`` times, each pass one parallel
    step (stopping at the first pass that rewrites nothing): the interpretation passes,
    and the decomposition after each derivation step."""
    view = replace(grammar, rules=rules)
    groups = _rule_groups(view.rules)
    needs_context = any(r.left or r.right for r in view.rules)
    for step in range(depth):
        neighbours = (_context_neighbours(string[0], view.symbols, view.ignore) if needs_context else None)
        matched, out_len, applied = _select_rewrites(view, groups, string, neighbours, rng, codes)
        if not matched.any():
            break
        total = int(out_len.sum())
        _check_step(view, limits, step, total, width, what)
        work.spend(total * (CONTEXT_WORK if needs_context else 1) + STEP_WORK * (len(groups) + 1),
                   f"{grammar.path}: {what} {step + 1}")
        string = _cut(_rewrite(view, string, matched, out_len, applied, rng, codes, width), codes)
    return string


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


def _fingerprint(string, rng) -> bytes:
    """A digest of the derivation's state: the module string and the generator's state
    (a step is a function of these two alone)."""
    h = hashlib.blake2b(digest_size=16)
    for array in string:
        h.update(np.ascontiguousarray(array).tobytes())
    h.update(repr(rng.bit_generator.state).encode())
    return h.digest()


def _axiom_string(grammar: Grammar, rng, codes: dict, width: int):
    """The axiom as a module string: (sym (n,) int32, nparam (n,) int8, params (n, width))."""
    try:
        sym, nparam, params = _instantiate(grammar.axiom, dict(grammar.defines), rng, 1, codes, width)
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
                     codes: dict):
    """Which rule rewrites which module in this step (the first matching group wins).

    Returns
    -------
    matched : (n,) bool, modules some rule rewrites
    out_len : (n,) int64, length of each module's replacement (1 when untouched)
    applied : list of (modules (k,) int, rule, env): each rule with the modules it rewrites
        and its parameter values there
    """
    sym = string[0]
    n = len(sym)
    matched = np.zeros(n, dtype=bool)
    out_len = np.ones(n, dtype=np.int64)
    applied: list[tuple[np.ndarray, Rule, dict]] = []
    for alts in groups:
        found = _match_group(grammar, alts[0], string, matched, neighbours, rng, codes)
        if found is None:
            continue
        idx, env = found
        matched[idx] = True
        for sub, rule, sub_env in _choose_alternatives(alts, idx, env, rng):
            out_len[sub] = len(rule.successor)
            applied.append((sub, rule, sub_env))
    return matched, out_len, applied


def _match_group(grammar: Grammar, rule: Rule, string, matched: np.ndarray, neighbours, rng,
                 codes: dict):
    """The modules not yet matched that ``rule``'s predecessor, context and condition match,
    with the environment its expressions see there: ((k,) int, env), or None for none."""
    sym, nparam, params = string
    code = codes[rule.pred.symbol]
    idx = np.flatnonzero((sym == code) & (nparam == len(rule.pred.params)) & ~matched)
    if idx.size == 0:
        return None
    env = dict(grammar.defines)
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
    for sub, rule, sub_env in applied:
        if not rule.successor:
            continue
        try:
            s, k, p = _instantiate(rule.successor, sub_env, rng, sub.size, codes, width)
        except ExprError as exc:
            raise PlantgenError(f"{grammar.path}: {rule.where()}: {exc}") from None
        pos = offsets[sub][None, :] + np.arange(len(rule.successor))[:, None]  # (L, k)
        new_sym[pos] = s[:, None]
        new_np[pos] = k[:, None]
        new_par[pos] = p
    return new_sym, new_np, new_par
