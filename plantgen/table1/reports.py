"""The bench's outputs: the Markdown tables, the CSV rows, the JSON results."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .configs import MAPPED_METHODS, MATCHED_AGAINST, RELIEF_SWEEPS, TABLE_METHODS, Method
from .curves import FAMILIES, family_front, family_points
from .paper import PAPER_MEMORY_RATIO, PAPER_TABLE1, PaperRow
from .plots import plot_curves
from .summary import rcr_over, rcr_over_gsr, summarise, summary_lines

__all__ = ["markdown_table", "match_notes", "table_rows", "curve_rows", "pareto_summary",
           "winners", "write_outputs", "rcr_over_gsr", "Column", "TABLE1_COLUMNS", "WORK_COLUMNS",
           "MEMORY_COLUMNS", "csv_fields", "markdown_head", "markdown_row", "TABLE_FIELDS", "CURVE_FIELDS",
           "QUALITY_LEVELS", "UNMATCHED"]

CURVE_FIELDS = ["model", "method", "knob", "value", "ms", "fps", "error", "dssim", "silhouette",
                "overdraw", "samples_per_pixel", "triangles", "gpu_bytes", "texture_bytes", "pareto", "skipped"]
#: Error levels at which :func:`winners` names the fastest configuration.
QUALITY_LEVELS = (0.3, 0.1, 0.03, 0.01, 0.003)
#: What a table cell shows for a value not measured.
MISSING = "–"
#: The mark of a level (and of the ratio built on it) that did not reach matched quality.
UNMATCHED = "✗"


# ---------------------------------------------------------------------------- columns
#: ``value(model, results)``: a column's value for one model of a run's results (None: not measured).
Value = Callable[[dict, dict], object]


@dataclass(frozen=True)
class Column:
    """One column of a bench table, declared once: its CSV field, its Markdown header and
    how its value is found and shown.

    Parameters
    ----------
    name : the CSV field (``table1.csv``); None: Markdown only
    header : the Markdown header; None: CSV only
    value : ``value(model, results)``, the CSV value (None: an empty field) and the value a
        Markdown cell shows
    spec, suffix : the Markdown cell is ``format(value, spec) + suffix``, or :data:`MISSING`
        for None
    cell : ``cell(model)``, the Markdown cell where it is more than the value (paper values
        beside ours, levels, marks)
    """

    name: str | None
    header: str | None = None
    value: Value | None = None
    spec: str = ""
    suffix: str = ""
    cell: Callable[[dict], str] | None = None

    def __post_init__(self) -> None:
        if self.name is None and self.header is None:
            raise ValueError("a column needs a CSV name, a Markdown header or both")
        if self.value is None and (self.name is not None or self.cell is None):
            raise ValueError(f"column {self.name or self.header!r} needs a value (a CSV field or a cell shows it)")

    def text(self, model: dict, results: dict) -> str:
        """The Markdown cell of ``model``."""
        if self.cell is not None:
            return self.cell(model)
        return _cell(self.value(model, results), self.spec, self.suffix)


def csv_fields(columns) -> list[str]:
    """The CSV fields of ``columns``, in order."""
    return [c.name for c in columns if c.name is not None]


def markdown_head(columns) -> list[str]:
    """The Markdown header line of ``columns`` (those with a header) and its rule."""
    headers = [c.header for c in columns if c.header is not None]
    return ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]


def markdown_row(columns, model: dict, results: dict) -> str:
    """The Markdown row of ``model`` under :func:`markdown_head`."""
    return "| " + " | ".join(c.text(model, results) for c in columns if c.header is not None) + " |"


def _key(key: str) -> Value:
    return lambda m, results: m[key]


def _key_or_none(key: str) -> Value:
    """A model's field that results from before it was added lack (None there)."""
    return lambda m, results: m.get(key)


def _entry(method: str, field: str) -> Value:
    """A field of a Table 1 method's entry (None when the method did not run)."""
    return lambda m, results: m[method][field] if m.get(method) else None


def _choice(field: str) -> Value:
    """A field of RC+R's Table 1 configuration (None without one)."""
    return lambda m, results: m["rcr_choice"][field] if m.get("rcr_choice") else None


def _match_text(method: str) -> Value:
    """How a polygonal method's level walk ended (None without one)."""
    return lambda m, results: m[f"{method}_match"]["text"] if m.get(f"{method}_match") else None


def _paper(field: str, level: str | None = None) -> Value:
    """A figure of the paper's Table 1 (of one of its polygonal methods, ``level``), None
    off the paper."""
    def value(m, results):
        p = PAPER_TABLE1.get(m["model"])
        return None if p is None else getattr(p if level is None else getattr(p, level), field)
    return value


def _memory(field: str) -> Value:
    return lambda m, results: m["memory"].get(field)


def _ratio_matched(m: dict, results: dict):
    """Whether RC+R/GS+R is at matched quality (None without the ratio)."""
    return bool(m["gsr_matched"]) if rcr_over_gsr(m) is not None else None


# ---------------------------------------------------------------------------- cells
def _cell(value, spec: str = "", suffix: str = "") -> str:
    """``value`` formatted with ``spec`` plus ``suffix``, or :data:`MISSING` for None."""
    return MISSING if value is None else format(value, spec) + suffix


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


def _paper_suffixes(p: PaperRow | None) -> dict:
    """The paper's value of each Table 1 column, as `` (value)``; empty off the paper."""
    if p is None:
        return dict.fromkeys(("segments", *TABLE_METHODS), "")
    return {"segments": f" ({p.segments})", "rc": f" ({p.rc_fps})", "rcr": f" ({p.rcr_fps})",
            "gs": f" ({p.gs.fps} / {p.gs.sub})", "gsr": f" ({p.gsr.fps} / {p.gsr.sub})",
            **dict.fromkeys((m.short for m in MAPPED_METHODS), "")}


def _segments_cell(model: dict) -> str:
    """Segments, the paper's in parentheses."""
    return f"{model['segments']:,}" + _paper_suffixes(PAPER_TABLE1.get(model["model"]))["segments"]


def _fps_cell(short: str) -> Callable[[dict], str]:
    """A Table 1 method's fps, its level (polygonal methods, :func:`_level_cell`), the
    paper's in parentheses."""
    def cell(model: dict) -> str:
        entry = model.get(short)
        text = _cell(None if entry is None else entry["fps"], ".1f")
        if short in MATCHED_AGAINST:
            text += f" / {_level_cell(model, short)}"
        return text + _paper_suffixes(PAPER_TABLE1.get(model["model"]))[short]
    return cell


def _work_cell(short: str, samples: bool = False) -> Callable[[dict], str]:
    """'ms · overdraw (· relief samples per pixel)' of a Table 1 entry."""
    def cell(model: dict) -> str:
        entry = model.get(short)
        if not entry or entry.get("overdraw") is None:
            return MISSING
        text = f"{entry['ms']:.1f} · {entry['overdraw']:.2f}"
        return text + (f" · {entry['samples_per_pixel']:.1f}" if samples else "")
    return cell


def _bytes_cell(short: str) -> Callable[[dict], str]:
    """A polygonal method's bytes on the GPU and its level."""
    return lambda m: f"{_cell(m['memory'].get(f'{short}_bytes'), ',')} ({_level_cell(m, short)})"


# ---------------------------------------------------------------------------- tables
def _mapped_columns(method: Method) -> tuple:
    """Table 1's columns of a method drawn with baked maps (not in the paper): fps / m,
    ms, its level walk, error."""
    short = method.short
    return (Column(f"{short}_fps", f"{method.name} fps / m", _entry(short, "fps"), cell=_fps_cell(short)),
            Column(f"{short}_ms", None, _entry(short, "ms")),
            Column(f"{short}_level", None, _key_or_none(f"{short}_level")),
            Column(f"{short}_matched", None, _key_or_none(f"{short}_matched")),
            Column(f"{short}_match", None, _match_text(short)),
            Column(f"{short}_error", f"{method.name} err", _entry(short, "error"), ".3f"))


def _rcr_over(short: str) -> Value:
    return lambda m, results: rcr_over(m, short)


#: Table 1: ``table1.csv``'s fields (``name``) and ``table.md``'s columns (``header``), in order.
TABLE1_COLUMNS = (
    Column("model", "model", _key("model")),
    Column("segments", "segments (paper)", _key("segments"), cell=_segments_cell),
    Column("rc_fps", "RC fps (paper)", _entry("rc", "fps"), cell=_fps_cell("rc")),
    Column("rc_ms", None, _entry("rc", "ms")),
    Column("rc_error", "RC err", _entry("rc", "error"), ".3f"),
    Column("rcr_fps", "RC+R fps (paper)", _entry("rcr", "fps"), cell=_fps_cell("rcr")),
    Column("rcr_ms", None, _entry("rcr", "ms")),
    Column(None, "RC+R config", cell=_config_cell),
    Column("rcr_error", "RC+R err", _entry("rcr", "error"), ".3f"),
    Column("rcr_config", None, _choice("key")),
    Column("rcr_config_rule", None, _choice("rule")),
    Column("gs_fps", "GS fps / m (paper)", _entry("gs", "fps"), cell=_fps_cell("gs")),
    Column("gs_ms", None, _entry("gs", "ms")),
    Column("gs_level", None, _key("gs_level")),
    Column("gs_matched", None, _key("gs_matched")),
    Column("gs_match", None, _match_text("gs")),
    Column("gs_error", "GS err", _entry("gs", "error"), ".3f"),
    Column("gsr_fps", "GS+R fps / m (paper)", _entry("gsr", "fps"), cell=_fps_cell("gsr")),
    Column("gsr_ms", None, _entry("gsr", "ms")),
    Column("gsr_level", None, _key("gsr_level")),
    Column("gsr_matched", None, _key("gsr_matched")),
    Column("gsr_match", None, _match_text("gsr")),
    Column("gsr_error", "GS+R err", _entry("gsr", "error"), ".3f"),
    *(column for method in MAPPED_METHODS for column in _mapped_columns(method)),
    Column("rcr_over_gsr", "RC+R/GS+R ours", lambda m, results: rcr_over_gsr(m), cell=_ratio_cell),
    Column("rcr_over_gsr_matched", None, _ratio_matched),
    *(Column(f"rcr_over_{method.short}", None, _rcr_over(method.short)) for method in MAPPED_METHODS),
    Column("paper_segments", None, _paper("segments")),
    Column("paper_rc_fps", None, _paper("rc_fps")),
    Column("paper_rcr_fps", None, _paper("rcr_fps")),
    Column("paper_gs_fps", None, _paper("fps", "gs")),
    Column("paper_gs_sub", None, _paper("sub", "gs")),
    Column("paper_gsr_fps", None, _paper("fps", "gsr")),
    Column("paper_gsr_sub", None, _paper("sub", "gsr")),
    Column("paper_rcr_over_gsr", "paper", _paper("rcr_over_gsr"), ".2f"),
    Column("rc_bytes", None, _memory("rc_bytes")),
    Column("rcr_bytes", None, _memory("rcr_bytes")),
    Column("gs_bytes", None, _memory("gs_bytes")),
    Column("gsr_bytes", None, _memory("gsr_bytes")),
    *(column for method in MAPPED_METHODS for column in (Column(f"{method.short}_bytes", None,
                                                                _memory(f"{method.short}_bytes")),
                                                         Column(method.texture_field, None,
                                                                _memory(method.texture_field)))),
    Column("shadows", None, _key("shadows")),
    Column("animated", None, _key("animated")),
    Column("gl_renderer", None, lambda m, results: results["machine"]["gl_renderer"]),
)
#: The fields of ``table1.csv`` (:data:`TABLE1_COLUMNS`' names).
TABLE_FIELDS = csv_fields(TABLE1_COLUMNS)
#: ``table.md``'s work per pixel of the Table 1 configurations.
WORK_COLUMNS = (
    Column(None, "model", _key("model")),
    Column(None, "RC ms · overdraw", cell=_work_cell("rc")),
    Column(None, "RC+R ms · overdraw · samples/px", cell=_work_cell("rcr", samples=True)),
    Column(None, "GS ms · overdraw", cell=_work_cell("gs")),
    Column(None, "GS+R ms · overdraw", cell=_work_cell("gsr")),
    *(Column(None, f"{method.name} ms · overdraw", cell=_work_cell(method.short)) for method in MAPPED_METHODS),
)
#: ``table.md``'s memory on the GPU.
MEMORY_COLUMNS = (
    Column(None, "model", _key("model")),
    Column(None, "RC records B", _memory("rc_bytes"), ","),
    Column(None, "relief maps B", _memory("relief_map_bytes"), ","),
    Column(None, "GS B (m)", cell=_bytes_cell("gs")),
    Column(None, "GS/RC", _memory("gs_over_rc"), ".1f", "x"),
    Column(None, "GS+R B (m)", cell=_bytes_cell("gsr")),
    Column(None, "GS+R / RC+R", _memory("gsr_over_rcr"), ".1f", "x"),
    *(column for method in MAPPED_METHODS for column in (
        Column(None, f"{method.name} B (m)", cell=_bytes_cell(method.short)),
        Column(None, f"{method.name} maps B", _memory(method.texture_field), ","),
        Column(None, f"{method.name} / RC+R", _memory(f"{method.short}_over_rcr"), ".1f", "x"))),
    Column(None, "paper", cell=lambda m: f"{PAPER_MEMORY_RATIO:.0f}x"),
)


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
            "('(best)': none reached it, the most accurate is timed). Level m: the meshes go up "
            f"from m = 0 until err <= target err·(1 + {o['rel_tol']}) + {o['abs_tol']} (GS vs RC, "
            f"{_matched_against_rcr()} vs RC+R at its config) or the next level is over the triangle budget "
            f"({o['max_triangles']:,}, --max-triangles); 'm{UNMATCHED}': not matched, the best "
            f"measured level is shown and timed, and the ratio beside it is not at matched quality "
            "(see the notes). RC+R/GS+R: fps ratio of the Table 1 run, where all four methods run "
            "the scene's passes (shadow map and ground where it lists shadows: a still scene's map is "
            "drawn by the warm-up frame and reused by the timed ones, as a viewer's would be, an animated "
            "scene's drawn in every frame; an animated scene posed and skinned on the GPU in every frame: "
            "records by a compute pass for RC, a mesh built once and posed by the vertex shader for GS; "
            "a leafy model's leaves, "
            "rasterised the same way by all four; the errors are of the frusta alone, as the float64 "
            "reference casts no leaves). "
            + " ".join(f"{m.name} (not in the paper, measured against the relief reference): {m.about}."
                       for m in MAPPED_METHODS)
            + " Paper: 8800 GTX, 2009.", ""]


def _matched_against_rcr() -> str:
    """``GS+R, GS+N and GS+POM``: the methods matched against RC+R."""
    names = [TABLE_METHODS[short] for short, against in MATCHED_AGAINST.items() if against == "rcr"]
    return ", ".join(names[:-1]) + " and " + names[-1] if len(names) > 1 else "".join(names)


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


def _table_lines(columns, results: dict) -> list[str]:
    """A Markdown table of ``columns``: the header, its rule and a row per model."""
    return [*markdown_head(columns), *(markdown_row(columns, m, results) for m in results["models"])]


def markdown_table(results: dict) -> str:
    """Table 1 beside the paper's, with errors, the ratio column, the summary, the RC+R
    configurations, the memory table and the notes (matches, budgets, conditions)."""
    lines = _header_lines(results) + _table_lines(TABLE1_COLUMNS, results)
    summary = results.get("summary") or summarise(results["models"])
    lines += ["", *summary_lines(summary)]
    choices = _choice_lines(results)
    if choices:
        lines += ["", f"RC+R's Table 1 configuration ({_matched_against_rcr()} are matched against its error):",
                  "", *choices]
    lines += ["", "## Why: work per pixel (Table 1 configurations)", "",
              "ms of the Table 1 run · shaded fragments per covered pixel (overdraw) · for RC+R, mean "
              "relief height samples per covered pixel; counted in one render of the bare model at the "
              "timed size (fragments the shader ran for, misses included, with depth tested after "
              "the shader).", "", *_table_lines(WORK_COLUMNS, results)]
    lines += ["", "## Memory on the GPU (§4: relief-mapped frusta vs polygons)", "",
              *_table_lines(MEMORY_COLUMNS, results)]
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
    """One row per model: the values of :data:`TABLE1_COLUMNS` by CSV field (``table1.csv``)."""
    columns = [c for c in TABLE1_COLUMNS if c.name is not None]
    return [{c.name: c.value(m, results) for c in columns} for m in results["models"]]


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
    _write_csv(out / "table1.csv", csv_fields(TABLE1_COLUMNS), table_rows(results))
    _write_csv(out / "curves.csv", CURVE_FIELDS, curve_rows(results))
    with open(out / "results.json", "w") as fh:
        json.dump(results, fh, indent=1, default=_json_default)
    files = [out / "table.md", out / "table1.csv", out / "curves.csv", out / "results.json"]
    plots = plot_curves(results, out)
    if isinstance(plots, str):
        return {"markdown": md, "files": files, "plots": plots}
    return {"markdown": md, "files": files + plots, "plots": None}
