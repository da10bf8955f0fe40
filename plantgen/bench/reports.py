"""The bench's outputs: the Markdown tables, the CSV rows, the JSON results."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np

from .configs import MATCHED_AGAINST, TABLE_METHODS
from .curves import FAMILIES, family_front, family_points
from .paper import PAPER_MEMORY_RATIO, PAPER_TABLE1, PaperRow
from .plots import plot_curves

__all__ = ["markdown_table", "budget_notes", "table_rows", "curve_rows", "pareto_summary",
           "winners", "write_outputs", "rcr_over_gsr", "TABLE_FIELDS", "CURVE_FIELDS",
           "QUALITY_LEVELS"]

TABLE_FIELDS = ["model", "segments", "rc_fps", "rc_ms", "rc_error", "rcr_fps", "rcr_ms", "rcr_error",
                "gs_fps", "gs_ms", "gs_level", "gs_matched", "gs_error", "gsr_fps", "gsr_ms",
                "gsr_level", "gsr_matched", "gsr_error", "rcr_over_gsr",
                "paper_segments",
                "paper_rc_fps", "paper_rcr_fps", "paper_gs_fps", "paper_gs_sub", "paper_gsr_fps",
                "paper_gsr_sub", "paper_rcr_over_gsr", "rc_bytes", "rcr_bytes", "gs_bytes",
                "gsr_bytes", "shadows", "animated", "gl_renderer"]
CURVE_FIELDS = ["model", "method", "knob", "value", "ms", "fps", "error", "dssim", "silhouette",
                "triangles", "gpu_bytes", "pareto", "skipped"]
#: Error levels at which :func:`winners` names the fastest configuration.
QUALITY_LEVELS = (0.3, 0.1, 0.03, 0.01, 0.003)
#: What a table cell shows for a value not measured.
MISSING = "–"


# ---------------------------------------------------------------------------- cells
def _cell(value, spec: str = "", suffix: str = "") -> str:
    """``value`` formatted with ``spec`` plus ``suffix``, or :data:`MISSING` for None."""
    return MISSING if value is None else format(value, spec) + suffix


def _entry_cell(entry: dict | None, field: str, spec: str) -> str:
    """A field of a Table 1 method's entry (None when the method did not run)."""
    return _cell(None if entry is None else entry[field], spec)


def _level_cell(model: dict, short: str) -> str:
    """The matched level of a polygonal method: ``m``, ``>m`` when none matched, or –."""
    level, matched = model[f"{short}_level"], model[f"{short}_matched"]
    return MISSING if level is None else (str(level) if matched else f">{level}")


def rcr_over_gsr(m: dict):
    """RC+R fps over GS+R fps (the ratio column), None if either is missing."""
    if m.get("rcr") and m.get("gsr"):
        return m["rcr"]["fps"] / m["gsr"]["fps"]
    return None


# ---------------------------------------------------------------------------- Markdown
def _header_lines(results: dict) -> list[str]:
    info = results["machine"]
    o = results["options"]
    return [f"# plantgen bench: Table 1 on {info['gl_renderer']}", "",
            f"{info['date_utc']} · GL {info['gl_version']} · {info['cpu']} ({info['cpus']} CPUs) · "
            f"{o['size'][0]}x{o['size'][1]} · median of {o['frames']} frames after a warm-up "
            f"(curves: {o['curve_frames']}) · "
            f"run took {results['wall_s']:.0f} s" + (" · QUICK run" if o.get("quick") else ""), "",
            "fps = 1000 / median frame time (draw to glFinish). err = (1 - SSIM) + silhouette "
            f"mismatch against the float64 reference in a {o['eval_size'][0]}x{o['eval_size'][1]} "
            "window at full angular resolution. Level m: smallest m with err <= "
            f"RC err·(1 + {o['rel_tol']}) + {o['abs_tol']} (GS vs RC, GS+R vs RC+R); '>m': "
            "none qualified, best measured shown. RC+R/GS+R: fps ratio of the Table 1 run, where "
            "all four methods run the scene's passes (shadow map and ground where it lists "
            "shadows; pose and re-skin, and re-tessellation for GS, in every frame of an "
            "animated scene). Paper: 8800 GTX, 2009.", ""]


def _paper_suffixes(p: PaperRow | None) -> dict:
    """The paper's value of each Table 1 column, as `` (value)``; empty off the paper."""
    if p is None:
        return dict.fromkeys(("segments", *TABLE_METHODS), "")
    return {"segments": f" ({p.segments})", "rc": f" ({p.rc_fps})", "rcr": f" ({p.rcr_fps})",
            "gs": f" ({p.gs.fps} / {p.gs.sub})", "gsr": f" ({p.gsr.fps} / {p.gsr.sub})"}


def _table1_row(m: dict) -> str:
    p = PAPER_TABLE1.get(m["model"])
    paper = _paper_suffixes(p)
    cells = [m["model"], f"{m['segments']:,}{paper['segments']}"]
    for short in TABLE_METHODS:
        fps = _entry_cell(m[short], "fps", ".1f")
        if short in MATCHED_AGAINST:
            fps += f" / {_level_cell(m, short)}"
        cells += [fps + paper[short], _entry_cell(m[short], "error", ".3f")]
    cells += [_cell(rcr_over_gsr(m), ".2f"), _cell(None if p is None else p.rcr_over_gsr, ".2f")]
    return "| " + " | ".join(cells) + " |"


def _memory_row(m: dict) -> str:
    mem = m["memory"]
    cells = [m["model"], _cell(mem["rc_bytes"], ","), _cell(mem["relief_map_bytes"], ","),
             f"{_cell(mem['gs_bytes'], ',')} ({_level_cell(m, 'gs')})", _cell(mem["gs_over_rc"], ".1f", "x"),
             f"{_cell(mem['gsr_bytes'], ',')} ({_level_cell(m, 'gsr')})",
             _cell(mem["gsr_over_rcr"], ".1f", "x"), f"{PAPER_MEMORY_RATIO:.0f}x"]
    return "| " + " | ".join(cells) + " |"


def markdown_table(results: dict) -> str:
    """Table 1 beside the paper's, with errors, the ratio column and the memory table."""
    lines = _header_lines(results)
    lines += ["| model | segments (paper) | RC fps (paper) | RC err | RC+R fps (paper) | RC+R err | "
              "GS fps / m (paper) | GS err | GS+R fps / m (paper) | GS+R err | RC+R/GS+R ours | "
              "paper |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    lines += [_table1_row(m) for m in results["models"]]
    lines += ["", "## Memory on the GPU (§4: relief-mapped frusta vs polygons)", "",
              "| model | RC records B | relief maps B | GS B (m) | GS/RC | GS+R B (m) | GS+R / RC+R | "
              "paper |",
              "|---|---|---|---|---|---|---|---|"]
    lines += [_memory_row(m) for m in results["models"]]
    notes = sorted({f"{m['model']}: {n}" for m in results["models"] for n in m["notes"] + budget_notes(m)})
    if notes:
        lines += ["", "Notes:", *[f"- {n}" for n in notes]]
    return "\n".join(lines) + "\n"


def budget_notes(model: dict) -> list[str]:
    """Notes for methods left unmatched (``>m``) whose finer levels were not built because
    they exceeded the triangle budget: the criterion did not fail there, the budget did."""
    notes = []
    for method, matched in (("GS", model.get("gs_matched")), ("GS+R", model.get("gsr_matched"))):
        skipped = [c for c in model["curve"] if c["method"] == method and "skipped" in c]
        if skipped and not matched:
            levels = ", ".join(str(c["value"]) for c in skipped)
            notes.append(f"{method} m = {levels} not built: {skipped[0]['skipped']} (--max-triangles)")
    return notes


# ---------------------------------------------------------------------------- CSV rows
def table_rows(results: dict) -> list[dict]:
    """One row per model: the :data:`TABLE_FIELDS` of ``table1.csv``."""
    rows = []
    for m in results["models"]:
        row = {"model": m["model"], "segments": m["segments"], "shadows": m["shadows"],
               "animated": m["animated"], "gl_renderer": results["machine"]["gl_renderer"],
               "gs_level": m["gs_level"], "gs_matched": m["gs_matched"],
               "gsr_level": m["gsr_level"], "gsr_matched": m["gsr_matched"],
               "rcr_over_gsr": rcr_over_gsr(m)}
        for k in TABLE_METHODS:
            e = m[k]
            for field in ("fps", "ms", "error"):
                row[f"{k}_{field}"] = e[field] if e else None
            row[f"{k}_bytes"] = m["memory"][f"{k}_bytes"]
        p = PAPER_TABLE1.get(m["model"])
        if p:
            row.update(paper_segments=p.segments, paper_rc_fps=p.rc_fps, paper_rcr_fps=p.rcr_fps,
                       paper_gs_fps=p.gs.fps, paper_gs_sub=p.gs.sub, paper_gsr_fps=p.gsr.fps,
                       paper_gsr_sub=p.gsr.sub, paper_rcr_over_gsr=p.rcr_over_gsr)
        rows.append(row)
    return rows


def curve_rows(results: dict) -> list[dict]:
    """Every measured configuration, with ``pareto`` True on its family's front."""
    rows = []
    for m in results["models"]:
        on_front = set()
        for family in FAMILIES:
            pts = family_points(m, family)
            if pts:
                on_front |= {id(pts[i]) for i in family_front(pts)}
        for c in m["curve"]:
            row = {k: c.get(k) for k in CURVE_FIELDS if k in c}
            row.update(model=m["model"], pareto=(id(c) in on_front) if "error" in c else None)
            rows.append(row)
    return rows


def pareto_summary(results: dict) -> list[str]:
    """Per model and family: the Pareto front from fastest to most accurate."""
    lines = []
    for m in results["models"]:
        for family in FAMILIES:
            pts = family_points(m, family)
            if not pts:
                continue
            steps = [f"{pts[i]['key']} ({pts[i]['ms']:.1f} ms, err {pts[i]['error']:.4f})"
                     for i in family_front(pts)]
            lines.append(f"- **{m['model']}** ({family}): " + " → ".join(steps))
    return lines


def winners(results: dict) -> list[str]:
    """Markdown rows: per model and family, the fastest configuration whose error is at
    most each of :data:`QUALITY_LEVELS`."""
    head = "| model | family | " + " | ".join(f"err ≤ {q}" for q in QUALITY_LEVELS) + " |"
    lines = [head, "|" + "---|" * (2 + len(QUALITY_LEVELS))]
    for m in results["models"]:
        for family in FAMILIES:
            pts = family_points(m, family)
            if not pts:
                continue
            cells = []
            for q in QUALITY_LEVELS:
                ok = [c for c in pts if c["error"] <= q]
                best = min(ok, key=lambda c: c["ms"]) if ok else None
                cells.append(MISSING if best is None else f"{best['key']} {best['ms']:.1f} ms")
            lines.append(f"| {m['model']} | {family} | " + " | ".join(cells) + " |")
    return lines


# ---------------------------------------------------------------------------- files
def _write_csv(path: Path, fields, rows) -> None:
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
        writer.writeheader()
        for r in rows:
            writer.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in fields})


def _json_default(obj):
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating,)):
        return float(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, io.IOBase):
        return None
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def _full_markdown(results: dict) -> str:
    """:func:`markdown_table`, then who wins at each quality and the Pareto fronts."""
    md = markdown_table(results)
    summary = pareto_summary(results)
    if summary:
        md += ("\n## Who wins at which quality (fastest configuration under each error; "
               "curves, no shadows)\n\n" + "\n".join(winners(results)) + "\n"
               "\n## Pareto front per model (fastest → most accurate)\n\n"
               + "\n".join(summary) + "\n")
    return md


def write_outputs(results: dict, out_dir: str | Path) -> dict:
    """Write ``table.md``, ``table1.csv``, ``curves.csv``, ``results.json`` and the curve
    plots into ``out_dir``; returns {"markdown": text, "files": [...], "plots": message}."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    md = _full_markdown(results)
    (out / "table.md").write_text(md)
    _write_csv(out / "table1.csv", TABLE_FIELDS, table_rows(results))
    _write_csv(out / "curves.csv", CURVE_FIELDS, curve_rows(results))
    with open(out / "results.json", "w") as fh:
        json.dump(results, fh, indent=1, default=_json_default)
    files = [out / "table.md", out / "table1.csv", out / "curves.csv", out / "results.json"]
    plots = plot_curves(results, out)
    if isinstance(plots, str):
        return {"markdown": md, "files": files, "plots": plots}
    return {"markdown": md, "files": files + plots, "plots": None}
