"""Derivation: rewrite the module string ``iterations`` times. Never builds geometry.

The module string is held as arrays, and each rewriting step is vectorised per rule: all
modules a rule matches are rewritten at once, their parameter expressions evaluated over
numpy arrays. Random draws come from one seeded generator in a fixed order (rules in file
order, modules in string order), so a grammar and seed always give the same string.

A step whose result would exceed ``max_modules`` stops with :class:`DerivationLimit`
before anything of that size is allocated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import PlantgenError
from .expr import EvalContext, ExprError
from .grammar import Grammar, ModuleTemplate, Pattern, Rule

__all__ = ["ModuleString", "DerivationLimit", "derive", "DEFAULT_MAX_MODULES"]

DEFAULT_MAX_MODULES = 5_000_000


class DerivationLimit(PlantgenError):
    """The module string would grow past the configured size limit."""


@dataclass(frozen=True, eq=False)
class ModuleString:
    """A derived string of ``n`` modules.

    sym : (n,) int32, index into ``symbols``
    nparam : (n,) int8, parameter count of each module
    params : (n, P) float64, parameters (columns past ``nparam`` are unused)
    """

    sym: np.ndarray
    nparam: np.ndarray
    params: np.ndarray
    symbols: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.sym)

    def to_text(self, limit: int = 10_000, digits: int = 4) -> str:
        """ABOP text of the first ``limit`` modules, for debugging and tests."""
        out = []
        for s, k, row in zip(self.sym[:limit].tolist(), self.nparam[:limit].tolist(),
                             self.params[:limit].tolist()):
            name = self.symbols[s]
            if k:
                out.append(name + "(" + ",".join(f"{x:.{digits}g}" for x in row[:k]) + ")")
            else:
                out.append(name)
        return "".join(out)


def _width(grammar: Grammar) -> int:
    n = [len(m.args) for m in grammar.axiom]
    for r in grammar.rules:
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
           max_modules: int | None = None, progress=None) -> ModuleString:
    """Rewrite the axiom ``iterations`` times (default: the grammar's).

    Parameters
    ----------
    grammar : Grammar
    iterations, seed : override the grammar's values
    max_modules : the size limit (default: the grammar's, else DEFAULT_MAX_MODULES)
    progress : optional callable(step, n_modules) called after each step
    """
    iterations = grammar.iterations if iterations is None else int(iterations)
    seed = grammar.seed if seed is None else int(seed)
    limit = max_modules or grammar.max_modules or DEFAULT_MAX_MODULES
    rng = np.random.default_rng(seed)
    symbols = grammar.symbols
    codes = {s: i for i, s in enumerate(symbols)}
    width = _width(grammar)
    defines = dict(grammar.defines)

    try:
        a_sym, a_np, a_par = _instantiate(grammar.axiom, defines, rng, 1, codes, width)
    except ExprError as exc:
        raise PlantgenError(f"{grammar.path}: axiom: {exc}") from None
    sym, nparam, params = a_sym, a_np, a_par[:, 0, :]
    if len(sym) > limit:
        raise DerivationLimit(f"{grammar.path}: the axiom alone exceeds the limit of {limit} modules")

    # Rules grouped as in the file: (first rule, alternatives, probabilities)
    groups: list[list[Rule]] = []
    index: dict[tuple, int] = {}
    for r in grammar.rules:
        key = r.group_key
        if key not in index:
            index[key] = len(groups)
            groups.append([])
        groups[index[key]].append(r)
    needs_context = any(r.left or r.right for r in grammar.rules)

    for step in range(iterations):
        n = len(sym)
        matched = np.zeros(n, dtype=bool)
        out_len = np.ones(n, dtype=np.int64)
        applied: list[tuple[np.ndarray, Rule, dict]] = []
        if needs_context:
            left_nb, right_nb = _context_neighbours(sym, symbols, grammar.ignore)
        for alts in groups:
            r0 = alts[0]
            code = codes[r0.pred.symbol]
            idx = np.flatnonzero((sym == code) & (nparam == len(r0.pred.params)) & ~matched)
            if idx.size == 0:
                continue
            env = dict(defines)
            if r0.left or r0.right:
                keep_l, left_ctx = _match_context(idx, r0.left, left_nb, reversed, sym, nparam, codes)
                keep_r, right_ctx = _match_context(idx, r0.right, right_nb, iter, sym, nparam, codes)
                keep = keep_l & keep_r
                idx = idx[keep]
                if idx.size == 0:
                    continue
                for ctx_pats, ctx_map in ((r0.left, left_ctx), (r0.right, right_ctx)):
                    for k, pat in enumerate(ctx_pats):
                        rows = ctx_map[k][keep]
                        for c, name in enumerate(pat.params):
                            env[name] = params[rows, c]
            for c, name in enumerate(r0.pred.params):
                env[name] = params[idx, c]
            try:
                if r0.condition is not None:
                    ok = np.broadcast_to(r0.condition(EvalContext(env, rng, idx.size)), idx.shape) != 0
                    idx = idx[ok]
                    env = {k: (v[ok] if isinstance(v, np.ndarray) else v) for k, v in env.items()}
                    if idx.size == 0:
                        continue
            except ExprError as exc:
                raise PlantgenError(f"{grammar.path}: {r0.where()}: {exc}") from None
            matched[idx] = True
            if len(alts) == 1:
                choice = np.zeros(idx.size, dtype=np.int64)
            else:
                cum = np.cumsum([r.p for r in alts])
                choice = np.minimum(np.searchsorted(cum / cum[-1], rng.random(idx.size), side="right"),
                                    len(alts) - 1)
            for a, rule in enumerate(alts):
                sel = choice == a
                if not sel.any():
                    continue
                sub = idx[sel]
                sub_env = {k: (v[sel] if isinstance(v, np.ndarray) else v) for k, v in env.items()}
                out_len[sub] = len(rule.successor)
                applied.append((sub, rule, sub_env))

        total = int(out_len.sum())
        if total > limit:
            raise DerivationLimit(
                f"{grammar.path}: derivation step {step + 1} would make {total:,} modules, "
                f"over the limit of {limit:,} (lower iterations or raise --max-modules)")
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
        sym, nparam, params = new_sym, new_np, new_par
        if progress is not None:
            progress(step + 1, total)

    return ModuleString(sym, nparam, params, symbols)
