"""MkDocs hook: the reference tables are generated from the code that holds each fact.

A page asks for a table with a marker on a line of its own, ``<!-- generated: NAME -->``;
:func:`on_page_markdown` replaces it with ``TABLES[NAME]()``. Nothing here is copied by
hand: the turtle symbols come from ``plantgen.lsystem.symbols``, the settings from their
knobs (``plantgen.knobs``), the budgets from ``plantgen.limits.Limits``, the export formats
from ``plantgen.exporters.formats``, the batch manifest's columns from
``plantgen.batch.schema``, the viewer's keys from ``plantgen.viewer.keys`` and the shipped
models from the files' own descriptions. The tests
(``tests/test_docs.py``) render the pages through :func:`expand` too.
"""

from __future__ import annotations

import re
from dataclasses import MISSING, fields, is_dataclass

MARKER = re.compile(r"^<!-- generated: ([a-z_]+) -->$", re.MULTILINE)


def _cell(text) -> str:
    """One table cell: reStructuredText's ``code`` as Markdown's, on one line."""
    return " ".join(str(text).replace("``", "`").replace("|", "\\|").split())


def _table(header: tuple[str, ...], rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def symbols_table() -> str:
    from plantgen.lsystem.symbols import markdown_table

    return markdown_table()


def _default_text(value) -> str:
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "on" if value else "off"
    if isinstance(value, tuple):
        return ", ".join(map(str, value)) if value else "—"
    return f"`{value}`"


def _knob_rows(cls):
    """(option, keyword, default, accepts, help) of every knob of ``cls``, nested
    settings values included."""
    from plantgen.knobs import knob_fields

    for _, k, default in knob_fields(cls):
        option = k.flag or k.option
        accepts = {"choice": " \\| ".join(map(str, k.choices)), "size": "WIDTHxHEIGHT",
                   "list": "comma-separated names", "bool": "on / off"}.get(k.kind, k.kind)
        if k.range_text():
            accepts = f"{accepts}, {k.range_text()}"
        yield (f"`{option}`", f"`{k.name}`", _default_text(default), accepts, k.help)
    for f in fields(cls):
        default = f.default if f.default is not MISSING else None
        if f.default_factory is not MISSING:
            default = f.default_factory()
        if is_dataclass(default) and not isinstance(default, type) and "knob" not in f.metadata:
            yield from _knob_rows(type(default))


def _settings_classes():
    from plantgen import settings
    from plantgen.geometry.rays.scan_settings import ScanSettings

    return [
        (settings.EffectSettings, "render, view"), (settings.RaycastSettings, "render, view, bench"),
        (settings.ShadowSettings, "render, view"), (settings.DetailSettings, "render, view, export"),
        (settings.ImageSettings, "render, view"), (settings.MotionSettings, "render, view"),
        (settings.ViewSettings, "render, view"),
        (settings.MeshSettings, "export, view, batch"), (settings.ParallaxSettings, "bench"),
        (settings.LevelSettings, "export"), (settings.KeyframeSettings, "export"), (ScanSettings, "scan, batch"),
    ]


def settings_tables() -> str:
    """One section per settings value: its knobs with option, API keyword, default, range
    and help, as the command line's ``--help`` shows them."""
    out = []
    for cls, commands in _settings_classes():
        rows = list(_knob_rows(cls))
        if not rows:
            continue
        doc = _cell((cls.__doc__ or "").strip().split("\n\n")[0])
        out.append(f"### `{cls.__name__}`\n\n`{cls.__module__}.{cls.__name__}` ({commands}). {doc}\n")
        out.append(_table(("option", "keyword", "default", "accepts", "what it does"), rows) + "\n")
    return "\n".join(out).rstrip()


def settings_summary() -> str:
    """Which value holds which options."""
    rows = []
    for cls, commands in _settings_classes():
        options = [f"`{row[0].strip('`')}`" for row in _knob_rows(cls)]
        if options:
            rows.append((f"[`{cls.__name__}`](#{cls.__name__.lower()})", commands, ", ".join(options)))
    return _table(("value", "commands", "options"), rows)


def limits_table() -> str:
    """The budgets of one input, with their defaults and meanings (``Limits``' docstring)."""
    from plantgen.limits import Limits

    doc = Limits.__doc__ or ""
    meaning = {}
    for m in re.finditer(r"^    (max_\w+) : (.*?)(?=^    max_|\Z)", doc, re.MULTILINE | re.DOTALL):
        meaning[m.group(1)] = " ".join(m.group(2).split())
    rows = []
    for f in fields(Limits):
        value = f.default
        size = next((f"{value >> s:,} {unit}" for s, unit in ((30, "GiB"), (20, "MiB"), (10, "KiB"))
                     if "bytes" in f.name and value >= 1 << s and value % (1 << s) == 0), f"{value:,}")
        rows.append((f"`{f.name[4:]}`", size, meaning.get(f.name, "")))
    return _table(("limit", "default", "bounds"), rows)


def export_formats_table() -> str:
    """The export formats: suffix, kind, up axis and what each holds."""
    from plantgen.exporters.formats import EXPORT_FORMATS

    rows = []
    for suffix, fmt in EXPORT_FORMATS.items():
        rows.append((f"`{suffix}`", fmt.kind, fmt.up, "once, instanced" if fmt.instancing else "every copy",
                     "yes" if fmt.animation else "— (at rest)", "yes" if fmt.scene else "—",
                     "yes" if fmt.textures else "—", f"the `{fmt.extra}` extra" if fmt.extra else "—"))
    return _table(("suffix", "holds", "up", "a scene's repeated plants", "a scene's sway", "camera, light, ground",
                   "relief maps", "needs"), rows)


def manifest_table() -> str:
    """The batch manifest's columns (``plantgen.batch.schema.COLUMNS``)."""
    from plantgen.batch.schema import COLUMNS

    return _table(("column", "type", "unit", "meaning"),
                  ((f"`{name}`", f"`{kind}`", unit, meaning) for name, kind, unit, meaning in COLUMNS))


def viewer_keys_table() -> str:
    """The viewer's keys and mouse (``plantgen.viewer.keys.help_lines``)."""
    from plantgen.viewer.keys import help_lines

    return _table(("keys and mouse", "what they do"), help_lines())


def shipped_table() -> str:
    """The shipped grammars and scenes: name, kind and the file's own description."""
    import yaml

    from plantgen._resources import grammars_dir

    rows = []
    for path in sorted(grammars_dir().glob("*.yaml")):
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
        kind = "scene" if "instances" in data else "grammar"
        rows.append((f"`{path.stem}`", kind, data.get("description", "")))
    return _table(("name", "kind", "description"), rows)


TABLES = {
    "shipped": shipped_table,
    "symbols": symbols_table,
    "settings": settings_tables,
    "settings_summary": settings_summary,
    "limits": limits_table,
    "export_formats": export_formats_table,
    "manifest": manifest_table,
    "viewer_keys": viewer_keys_table,
}


def expand(markdown: str) -> str:
    """``markdown`` with every ``<!-- generated: NAME -->`` marker replaced by its table;
    an unknown name is an error (the build fails rather than print a stale page)."""

    def table(m: re.Match) -> str:
        name = m.group(1)
        if name not in TABLES:
            raise KeyError(f"unknown generated table {name!r} (known: {', '.join(TABLES)})")
        return TABLES[name]()

    return MARKER.sub(table, markdown)


def on_page_markdown(markdown: str, page, config, files) -> str:   # noqa: ARG001 (MkDocs' hook signature)
    return expand(markdown)
