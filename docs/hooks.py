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

import logging
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


# ---------------------------------------------------------------------------- the prose check
# The strict build checks links; these check the text a reader meets. A page fails on a
# paragraph that repeats another (the same run of words twice), a paragraph that starts
# mid-sentence (a lower-case word after a blank line: the tail of a sentence whose head
# went missing), and a heading or paragraph that starts with a stray space.

#: How many words in a row count as a repeat; the share of a paragraph's runs that must
#: reappear in one earlier paragraph of the page for it to count as repeated; and the
#: fewest runs a paragraph needs to be judged (a one-line caption may recur by design).
REPEAT_RUN = 6
REPEAT_SHARE = 0.5
REPEAT_MIN_RUNS = 12
#: A paragraph may start in lower case with the product's name, or after a code block
#: whose command it goes on describing ("... one command: ```...``` installs plantgen").
LOWER_CASE_NAMES = ("plantgen",)
FENCE = re.compile(r"^\s*(```|~~~)")
#: Blocks that are not prose: tables, lists, quotes, HTML, admonitions, snippets, markers,
#: images, math, indented code and footnotes.
NOT_PROSE = re.compile(r"^(\||[-*+] |\d+[.)] |>|<|!!!|\?\?\?|--8<--|!\[|\$\$|:::|\[\^|    |\t)")


def _blocks(markdown: str):
    """(line number, first line, text) of each blank-line separated block outside fences;
    a fenced code block yields one block whose first line is its fence."""
    block, start, fenced = [], 0, False
    for number, line in enumerate(markdown.splitlines() + [""], 1):
        if FENCE.match(line):
            if block and not fenced:
                yield start, block[0], " ".join(part.strip() for part in block)
            if not fenced:
                yield number, line.strip(), ""
            fenced, block = not fenced, []
            continue
        if fenced:
            continue
        if line.strip():
            if not block:
                start = number
            block.append(line)
        elif block:
            yield start, block[0], " ".join(part.strip() for part in block)
            block = []


def _numbers(text: str) -> set[str]:
    return set(re.findall(r"\d[\d.,]*", text))


def _runs(text: str) -> set[tuple[str, ...]]:
    words = re.findall(r"[\w`'-]+", text.lower())
    return {tuple(words[i:i + REPEAT_RUN]) for i in range(len(words) - REPEAT_RUN + 1)}


def prose_problems(markdown: str) -> list[str]:
    """What reads wrong in ``markdown``: one line per problem, naming its line number."""
    out, seen, after_list = [], [], False
    for number, first, text in _blocks(markdown):
        if FENCE.match(first):
            after_list = True          # what follows a command may go on its sentence
            continue
        heading = first.lstrip().startswith("#")
        if heading and re.match(r"^#+\s{2,}\S|^\s+#", first):
            out.append(f"line {number}: heading starts with a stray space: {first.strip()[:60]!r}")
        if heading:
            after_list = False
            continue
        indented = re.match(r"^ {1,3}\S", first) and not NOT_PROSE.match(first.lstrip())
        if indented and not after_list:
            out.append(f"line {number}: paragraph starts with a stray space: {first.strip()[:60]!r}")
        prose = not NOT_PROSE.match(first) and not first.startswith(" ")
        if prose and re.match(r"^[a-z]", first) and not after_list and not first.startswith(LOWER_CASE_NAMES):
            out.append(f"line {number}: paragraph starts mid-sentence: {first[:60]!r}")
        after_list = bool(NOT_PROSE.match(first)) and not first.startswith(("|", "<", "!["))
        if not prose:
            continue
        runs, numbers = _runs(text), _numbers(text)
        for other_number, other, other_numbers in seen:
            # a caption that states other figures (a bench's note under each table) is no repeat
            if len(runs) >= REPEAT_MIN_RUNS and len(runs & other) >= REPEAT_SHARE * len(runs) \
                    and numbers == other_numbers:
                out.append(f"line {number}: paragraph repeats line {other_number}'s: {first.strip()[:60]!r}")
                break
        seen.append((number, runs, numbers))
    return out


def on_page_markdown(markdown: str, page, config, files) -> str:   # noqa: ARG001 (MkDocs' hook signature)
    for problem in prose_problems(markdown):
        logging.getLogger("mkdocs.plugins.plantgen.prose").warning("%s: %s", page.file.src_uri, problem)
    return expand(markdown)
