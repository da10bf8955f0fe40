"""The bench's outputs: the Markdown tables, the CSV rows, the JSON results."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np

from .configs import MATCHED_AGAINST, RELIEF_SWEEPS, TABLE_METHODS
from .curves import FAMILIES, family_front, family_points
from .paper import PAPER_MEMORY_RATIO, PAPER_TABLE1, PaperRow
from .plots import plot_curves
from .summary import rcr_over_gsr, summarise, summary_lines

__all__ = ["markdown_table", "match_notes", "table_rows", "curve_rows", "pareto_summary",
           "winners", "write_outputs", "rcr_over_gsr", "TABLE_FIELDS", "CURVE_FIELDS",
           "QUALITY_LEVELS", "UNMATCHED"]

TABLE_FIELDS = ["model", "segments", "rc_fps", "rc_ms", "rc_error", "rcr_fps", "rcr_ms", "rcr_error",
                "rcr_config", "rcr_config_rule",
                "gs_fps", "gs_ms", "gs_level", "gs_matched", "gs_match", "gs_error", "gsr_fps", "gsr_ms",
                "gsr_level", "gsr_matched", "gsr_match", "gsr_error", "rcr_over_gsr", "rcr_over_gsr_matched",
                "paper_segments",
                "paper_rc_fps", "paper_rcr_fps", "paper_gs_fps", "paper_gs_sub", "paper_gsr_fps",
                "paper_gsr_sub", "paper_rcr_over_gsr", "rc_bytes", "rcr_bytes", "gs_bytes",
                "gsr_bytes", "shadows", "animated", "gl_renderer"]
CURVE_FIELDS = ["model", "method", "knob", "value", "ms", "fps", "error", "dssim", "silhouette",
                "overdraw", "samples_per_pixel", "triangles", "gpu_bytes", "pareto", "skipped"]
#: Error levels at which :func:`winners` names the fastest configuration.
QUALITY_LEVELS = (0.3, 0.1, 0.03, 0.01, 0.003)
#: What a table cell shows for a value not measured.
MISSING = "–"
#: The mark of a level (and of the ratio built on it) that did not reach matched quality.
UNMATCHED = "✗"


# ---------------------------------------------------------------------------- cells
def _cell(value, spec: str = "", suffix: str = "") -> str:
    """``value`` formatted with ``spec`` plus ``suffix``, or :data:`MISSING` for None."""
    return MISSING if value is None else format(value, spec) + suffix


def _entry_cell(entry: dict | None, field: str, spec: str) -> str:
    """A field of a Table 1 method's entry (None when the method did not run)."""
    return _cell(None if entry is None else entry[field], spec)


def _level_cell(model: dict, short: str) -> str:
    """The level of a polygonal method: ``m`` when matched, ``m✗`` when no level within the
    budget matched (the best measured is shown), or –."""
    level, matched = model.get(f"{short}_level"), model.get(f"{short}_matched")
    return MISSING if level is None else (str(level) if matched else f"{level}{UNMATCHED}")


def _ratio_cell(model: dict) -> str:
    """RC+R/GS+R, marked :data:`UNMATCHED` where GS+R is not at matched quality."""
    ratio = rcr_over_gsr(model)
    return _cell(ratio, ".2f") + ("" if ratio is None or model.get("gsr_matched") else UNMATCHED)


def _config_cell(model: dict) -> str:
    """RC+R's Table 1 configuration, e.g. ``linear=8`` (``(best)`` when none reached the
    error bound and the most accurate one is timed)."""
    choice = model.get("rcr_choice")
    if not choice:
        return MISSING
    name = choice["key"].split(":", 1)[1] if ":" in choice["key"] else choice["key"]
    return name + ("" if choice["within"] else " (best)")


# ---------------------------------------------------------------------------- Markdown
def _header_lines(results: dict) -> list[str]:
    info = results["machine"]
    o = results["options"]
    relief_error = o.get("relief_error", 0.01)
    return [f"# plantgen bench: Table 1 on {info['gl_renderer']}", "",
            f"{info['date_utc']} · GL {info['gl_version']} · {info['cpu']} ({info['cpus']} CPUs) · "
            f"{o['size'][0]}x{o['size'][1]} · median of {o['frames']} frames after a warm-up "
            f"(curves: {o['curve_frames']}) · "
            f"run took {results['wall_s']:.0f} s" + (" · QUICK run" if o.get("quick") else ""), "",
            "fps = 1000 / median frame time (draw to glFinish). err = (1 - SSIM, scikit-image) + "
            "silhouette mismatch against the float64 reference in a "
            f"{o['eval_size'][0]}x{o['eval_size'][1]} window at full angular resolution. "
            f"RC+R config: the fastest RC+R configuration of the curves with err ≤ {relief_error:g} "
            "('(best)': none reached it, the most accurate is timed). Level m: GS and GS+R go up "
            f"from m = 0 until err <= target err·(1 + {o['rel_tol']}) + {o['abs_tol']} (GS vs RC, "
            "GS+R vs RC+R at its config) or the next level is over the triangle budget "
            f"({o['max_triangles']:,}, --max-triangles); 'm{UNMATCHED}': not matched, the best "
            f"measured level is shown and timed, and the ratio beside it is not at matched quality "
            "(see the notes). RC+R/GS+R: fps ratio of the Table 1 run, where all four methods run "
            "the scene's passes (shadow map and ground where it lists shadows; pose and re-skin, "
            "and re-tessellation for GS, in every frame of an animated scene; a leafy model's leaves, "
            "rasterised the same way by all four; the errors are of the frusta alone, as the float64 "
            "reference casts no leaves). Paper: 8800 GTX, 2009.", ""]


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
        cells.append(fps + paper[short])
        if short == "rcr":
            cells.append(_config_cell(m))
        cells.append(_entry_cell(m[short], "error", ".3f"))
    cells += [_ratio_cell(m), _cell(None if p is None else p.rcr_over_gsr, ".2f")]
    return "| " + " | ".join(cells) + " |"


def _memory_row(m: dict) -> str:
    mem = m["memory"]
    cells = [m["model"], _cell(mem["rc_bytes"], ","), _cell(mem["relief_map_bytes"], ","),
             f"{_cell(mem['gs_bytes'], ',')} ({_level_cell(m, 'gs')})", _cell(mem["gs_over_rc"], ".1f", "x"),
             f"{_cell(mem['gsr_bytes'], ',')} ({_level_cell(m, 'gsr')})",
             _cell(mem["gsr_over_rcr"], ".1f", "x"), f"{PAPER_MEMORY_RATIO:.0f}x"]
    return "| " + " | ".join(cells) + " |"


def _work_cell(entry: dict | None, relief: bool) -> str:
    """'ms · overdraw (· samples per pixel)' of a Table 1 entry."""
    if not entry or entry.get("overdraw") is None:
        return MISSING
    text = f"{entry['ms']:.1f} · {entry['overdraw']:.2f}"
    return text + (f" · {entry['samples_per_pixel']:.1f}" if relief else "")


def _work_row(m: dict) -> str:
    cells = [m["model"]] + [_work_cell(m[short], short == "rcr") for short in ("rc", "rcr", "gs", "gsr")]
    return "| " + " | ".join(cells) + " |"


def _settings_text(settings: dict | None) -> str:
    """The ray caster's settings of a configuration that the RC+R sweeps vary
    (:data:`RELIEF_SWEEPS`; the rest is at the ray caster's default)."""
    swept = {f for sweep in RELIEF_SWEEPS for f in (sweep.field, *dict(sweep.base))}
    return ", ".join(f"{k}={v}" for k, v in (settings or {}).items() if k in swept)


def _choice_lines(results: dict) -> list[str]:
    """Per model with relief: RC+R's Table 1 configuration and why it was chosen."""
    lines = []
    for m in results["models"]:
        c = m.get("rcr_choice")
        if c:
            lines.append(f"- **{m['model']}**: {c['key']} ({_settings_text(c.get('settings'))}; "
                         f"err {c['error']:.4f}, {c['ms']:.1f} ms in the curves): {c['rule']}")
    return lines


def markdown_table(results: dict) -> str:
    """Table 1 beside the paper's, with errors, the ratio column, the summary, the RC+R
    configurations, the memory table and the notes (matches, budgets, conditions)."""
    lines = _header_lines(results)
    lines += ["| model | segments (paper) | RC fps (paper) | RC err | RC+R fps (paper) | RC+R config | "
              "RC+R err | GS fps / m (paper) | GS err | GS+R fps / m (paper) | GS+R err | RC+R/GS+R ours | "
              "paper |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    lines += [_table1_row(m) for m in results["models"]]
    summary = results.get("summary") or summarise(results["models"])
    lines += ["", *summary_lines(summary)]
    choices = _choice_lines(results)
    if choices:
        lines += ["", "RC+R's Table 1 configuration (GS+R is matched against its error):", "", *choices]
    lines += ["", "## Why: work per pixel (Table 1 configurations)", "",
              "ms of the Table 1 run · shaded fragments per covered pixel (overdraw) · for RC+R, mean "
              "relief height samples per covered pixel; counted in one render of the bare model at the "
              "timed size (fragments the shader ran for, misses included, with depth tested after "
              "the shader).", "",
              "| model | RC ms · overdraw | RC+R ms · overdraw · samples/px | GS ms · overdraw | "
              "GS+R ms · overdraw |",
              "|---|---|---|---|---|"]
    lines += [_work_row(m) for m in results["models"]]
    lines += ["", "## Memory on the GPU (§4: relief-mapped frusta vs polygons)", "",
              "| model | RC records B | relief maps B | GS B (m) | GS/RC | GS+R B (m) | GS+R / RC+R | "
              "paper |",
              "|---|---|---|---|---|---|---|---|"]
    lines += [_memory_row(m) for m in results["models"]]
    notes = sorted({f"{m['model']}: {n}" for m in results["models"] for n in m["notes"] + match_notes(m)})
    if notes:
        lines += ["", "Notes:", *[f"- {n}" for n in notes]]
    return "\n".join(lines) + "\n"


def _speed_text(ratio: float) -> str:
    return f"{ratio:.2f}× faster" if ratio >= 1 else f"{1 / ratio:.2f}× slower"


def match_notes(model: dict) -> list[str]:
    """A note for each polygonal method that matched no level within the triangle budget:
    why the walk stopped, the best level measured, and how the ray caster it was matched
    against compares with that level in accuracy and in the Table 1 run's speed."""
    notes = []
    for short, against in MATCHED_AGAINST.items():
        match = model.get(f"{short}_match")
        if not match or match["matched"]:
            continue
        method, ray = TABLE_METHODS[short], TABLE_METHODS[against]
        note = f"{method} {match['text']} (--max-triangles)"
        mesh, caster = model.get(short), model.get(against)
        if mesh and caster:
            better = "more" if caster["error"] < mesh["error"] else "not more"
            note += (f"; {ray} ({match['target_key']}) is {better} accurate (err {caster['error']:.4f} vs "
                     f"{mesh['error']:.4f}) and {_speed_text(caster['fps'] / mesh['fps'])} than the best "
                     f"{method} mesh within the budget (m={match['level']})")
        notes.append(note)
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
               "rcr_over_gsr": rcr_over_gsr(m),
               "rcr_over_gsr_matched": bool(m["gsr_matched"]) if rcr_over_gsr(m) is not None else None}
        for short in MATCHED_AGAINST:
            match = m.get(f"{short}_match")
            row[f"{short}_match"] = match["text"] if match else None
        choice = m.get("rcr_choice")
        if choice:
            row.update(rcr_config=choice["key"], rcr_config_rule=choice["rule"])
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
