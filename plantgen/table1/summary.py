"""The summary under Table 1: how often RC+R beats GS+R, and what relief costs the ray
caster, over the models of a run, ours beside the paper's."""

from __future__ import annotations

import math

from .paper import PAPER_TABLE1

__all__ = ["rcr_over", "rcr_over_gsr", "relief_overhead", "geometric_mean", "summarise",
           "summary_lines"]


def rcr_over(m: dict, short: str):
    """RC+R fps over the fps of method ``short`` (``gsr``, ``gsn``, ``gspom``) of a model's
    Table 1 run, None if either did not run."""
    if m.get("rcr") and m.get(short):
        return m["rcr"]["fps"] / m[short]["fps"]
    return None


def rcr_over_gsr(m: dict):
    """RC+R fps over GS+R fps of a model's Table 1 run (the ratio column), None if either
    is missing."""
    return rcr_over(m, "gsr")


def relief_overhead(m: dict):
    """RC+R ms over RC ms of a model's Table 1 run, None if either is missing."""
    if m.get("rcr") and m.get("rc"):
        return m["rcr"]["ms"] / m["rc"]["ms"]
    return None


def geometric_mean(values) -> float | None:
    """Geometric mean of positive numbers, None for none."""
    values = list(values)
    return math.exp(sum(math.log(v) for v in values) / len(values)) if values else None


def _ratio_summary(per_model: dict, matched: list | None = None) -> dict:
    """{"per_model", "models", "at_least_one", "geomean"} (+ "matched", "geomean_matched"
    when ``matched`` names the models at matched quality)."""
    out = {"per_model": per_model, "models": len(per_model),
           "at_least_one": sum(1 for v in per_model.values() if v >= 1.0),
           "geomean": geometric_mean(per_model.values())}
    if matched is not None:
        out["matched"] = len(matched)
        out["matched_models"] = matched
        out["geomean_matched"] = geometric_mean(per_model[k] for k in matched)
    return out


def summarise(models: list[dict]) -> dict:
    """The summary of a run's model records (JSON-ready)."""
    ratios = {m["model"]: r for m in models if (r := rcr_over_gsr(m)) is not None}
    matched = [m["model"] for m in models if m["model"] in ratios and m.get("gsr_matched")]
    overhead = {m["model"]: r for m in models if (r := relief_overhead(m)) is not None}
    paper_rows = {m["model"]: PAPER_TABLE1[m["model"]] for m in models if m["model"] in PAPER_TABLE1}
    paper_ratio = {k: p.rcr_over_gsr for k, p in paper_rows.items() if k in ratios}
    paper_overhead = {k: p.rc_fps / p.rcr_fps for k, p in paper_rows.items() if k in overhead}
    return {"rcr_over_gsr": _ratio_summary(ratios, matched),
            "relief_overhead": _ratio_summary(overhead),
            "paper": {"rcr_over_gsr": _ratio_summary(paper_ratio),
                      "relief_overhead": _ratio_summary(paper_overhead)}}


def _per_model(per_model: dict) -> str:
    return ", ".join(f"{k} {v:.2f}" for k, v in per_model.items())


def _ratio_line(s: dict, who: str) -> str:
    line = (f"{who}RC+R ÷ GS+R ≥ 1 on {s['at_least_one']} of {s['models']} models, "
            f"geometric mean {s['geomean']:.2f}")
    if "matched" in s:
        line += f" (at matched quality on {s['matched']} of {s['models']}"
        if 0 < s["matched"] < s["models"]:
            line += f"; geometric mean over those {s['geomean_matched']:.2f}"
        line += ")"
    return line


def _overhead_line(s: dict, who: str) -> str:
    return (f"{who}relief overhead RC+R ms ÷ RC ms: geometric mean {s['geomean']:.2f} "
            f"(per model: {_per_model(s['per_model'])})")


def summary_lines(summary: dict) -> list[str]:
    """The summary as Markdown list items (ours, then the paper's for the same models)."""
    lines = []
    for s, who in ((summary, ""), (summary["paper"], "paper (8800 GTX): ")):
        if s["rcr_over_gsr"]["models"]:
            lines.append(_ratio_line(s["rcr_over_gsr"], who))
        if s["relief_overhead"]["models"]:
            lines.append(_overhead_line(s["relief_overhead"], who))
    return [f"- {line}" for line in lines]
