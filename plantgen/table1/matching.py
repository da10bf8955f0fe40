"""Which configurations Table 1 times: the RC+R configuration picked from the curves, and
the GS / GS+R level matched to the ray caster's quality. Pure Python, no GL.

RC+R (:func:`choose_relief_config`): the fastest measured RC+R configuration whose error
is at most ``relief_error`` (0.01 by default), else the most accurate one.

GS and GS+R (:func:`walk_levels`): m = 0, 1, 2, ... are built and measured in turn until a
level's error is within the quality criterion's bound (:func:`~plantgen.table1.quality.quality_bound`
of the target's error): matched at that m, no finer level built. Before building a level
its triangle count is checked against the budget (``max_triangles``); the first level over
it stops the walk unmatched, and Table 1 then times the level of least error measured.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from .quality import MATCH_ABS_TOL, MATCH_REL_TOL, quality_bound

__all__ = ["LevelMatch", "walk_levels", "choose_relief_config", "match_text"]


@dataclass
class LevelMatch:
    """How a polygonal method's walk up the levels ended.

    method : GS or GS+R
    target_key, target_error : the configuration matched against and its error
    bound : the error a level had to reach
    budget : the triangle budget
    errors : {m: error} of the levels built and measured, in the order walked
    over_budget : (m, triangles) of the level that was over the budget (not built), or
        None when the walk ended on a match
    """

    method: str
    target_key: str
    target_error: float
    bound: float
    budget: int
    errors: dict = field(default_factory=dict)
    over_budget: tuple | None = None

    @property
    def matched(self) -> bool:
        """The last level built qualified."""
        return bool(self.errors) and self.errors[max(self.errors)] <= self.bound

    @property
    def best_level(self) -> int | None:
        """The level of least error measured (the lower on a tie), None if none was built."""
        return min(self.errors, key=lambda m: (self.errors[m], m)) if self.errors else None

    @property
    def level(self) -> int | None:
        """The level Table 1 times: the matched one, else the one of least error."""
        return max(self.errors) if self.matched else self.best_level

    def as_dict(self) -> dict:
        """The JSON-ready record (with its one-line ``text``)."""
        over_level, over_triangles = self.over_budget if self.over_budget else (None, None)
        level = self.level
        out = {"method": self.method, "matched": self.matched, "level": level,
               "error": None if level is None else self.errors[level],
               "target_key": self.target_key, "target_error": self.target_error, "bound": self.bound,
               "levels_measured": sorted(self.errors), "budget": self.budget,
               "stopped_by": "match" if self.matched else "budget",
               "over_budget_level": over_level, "over_budget_triangles": over_triangles}
        out["text"] = match_text(out)
        return out


def match_text(match: dict) -> str:
    """``matched at m=3`` or ``not matched: m=6 over the triangle budget (7,864,320
    triangles), best measured error 0.0412 at m=5`` of a :meth:`LevelMatch.as_dict`."""
    if match["matched"]:
        return f"matched at m={match['level']}"
    over = (f"m={match['over_budget_level']} over the triangle budget "
            f"({match['over_budget_triangles']:,} triangles)")
    if match["level"] is None:
        return f"not matched: {over}, no level built"
    return f"not matched: {over}, best measured error {match['error']:.4f} at m={match['level']}"


def walk_levels(method: str, target_key: str, target_error: float, measure: Callable[[int], float],
                triangles: Callable[[int], int], budget: int, rel_tol: float = MATCH_REL_TOL,
                abs_tol: float = MATCH_ABS_TOL) -> LevelMatch:
    """Walk m = 0, 1, ... until a level qualifies or the next is over ``budget``.

    measure : m -> the error of the level (builds and measures it)
    triangles : m -> its triangle count (checked before ``measure`` is called)
    """
    match = LevelMatch(method, target_key, target_error, quality_bound(target_error, rel_tol, abs_tol),
                       budget)
    m = 0
    while True:
        count = triangles(m)
        if count > budget:
            match.over_budget = (m, count)
            return match
        match.errors[m] = measure(m)
        if match.matched:
            return match
        m += 1


def choose_relief_config(rows: list[dict], max_error: float) -> dict:
    """The RC+R configuration Table 1 times, from its measured curve ``rows`` (dicts with
    ``key``, ``ms``, ``error``): the fastest with ``error <= max_error``, else the most
    accurate (the faster on a tie).

    Returns {"key", "ms", "error", "settings", "within": bool, "max_error", "rule": text}.
    """
    if not rows:
        raise ValueError("no RC+R configuration was measured")
    within = [r for r in rows if r["error"] <= max_error]
    if within:
        row = min(within, key=lambda r: (r["ms"], r["error"]))
        rule = f"fastest RC+R configuration of the curves with err ≤ {max_error:g}"
    else:
        row = min(rows, key=lambda r: (r["error"], r["ms"]))
        rule = f"no RC+R configuration reached err ≤ {max_error:g}: the most accurate one"
    return {"key": row["key"], "ms": row["ms"], "error": row["error"], "settings": row.get("settings"),
            "within": bool(within), "max_error": max_error, "rule": rule}
