"""The documentation: its reference tables are generated from the code that holds each
fact, every page's generated tables expand, and the site builds with warnings as errors
(a broken link, anchor or API reference fails)."""

from __future__ import annotations

import importlib
import importlib.util
import os
import re
import subprocess
import sys
from dataclasses import MISSING, fields, is_dataclass

import pytest
from _docs import DOCS, README, REPO, hooks, page, table_after

from plantgen.knobs import knob_fields
from plantgen.settings import RenderSettings

GENERATED_ON = {
    "reference/grammar.md": ["symbols"],
    "reference/settings.md": ["settings_summary", "settings"],
    "reference/limits.md": ["limits"],
    "reference/formats.md": ["export_formats", "manifest"],
    "reference/models.md": ["shipped"],
    "how-to/view.md": ["viewer_keys"],
}


def _pages() -> list[str]:
    if not DOCS.is_dir():
        pytest.skip("needs the source tree's docs/")
    return sorted(str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md") if "gallery" not in p.parts)


@pytest.mark.parametrize(("name", "tables"), sorted(GENERATED_ON.items()))
def test_reference_pages_take_their_tables_from_the_code(name, tables):
    raw = (DOCS / name).read_text(encoding="utf-8") if (DOCS / name).is_file() else pytest.skip(f"no docs/{name}")
    assert re.findall(r"^<!-- generated: ([a-z_]+) -->$", raw, re.M) == tables
    text = page(name)
    assert "<!-- generated:" not in text
    for table in tables:
        assert hooks().TABLES[table]() in text


def test_every_marker_names_a_table_and_every_page_expands():
    for name in _pages():
        text = page(name)          # an unknown marker raises
        assert "<!-- generated:" not in text, name


def test_an_unknown_marker_fails_the_build():
    with pytest.raises(KeyError, match="unknown generated table 'nope'"):
        hooks().expand("<!-- generated: nope -->")


def _settings_values(cls) -> set[type]:
    """The settings dataclasses ``cls`` holds, nested ones included."""
    out = {cls}
    for f in fields(cls):
        default = f.default
        if default is MISSING and f.default_factory is not MISSING:
            default = f.default_factory()
        if is_dataclass(default) and not isinstance(default, type):
            out |= _settings_values(type(default))
    return out


def test_the_settings_reference_lists_every_knob_render_takes():
    text = page("reference/settings.md")
    for cls in _settings_values(RenderSettings):
        for _, knob, _default in knob_fields(cls):
            assert f"`{knob.flag or knob.option}` | `{knob.name}` |" in text, (cls.__name__, knob.option)


def test_the_limits_reference_explains_every_limit():
    from plantgen.limits import Limits

    rows = table_after(page("reference/limits.md"), "| limit | default | bounds |")[2:]
    assert [row.split("|")[1].strip().strip("`") for row in rows] == list(Limits.names())
    assert all(row.split("|")[3].strip() for row in rows), "a limit without its meaning in Limits' docstring"


def test_the_api_reference_names_existing_objects():
    for target in re.findall(r"^::: ([\w.]+)$", page("reference/api.md"), re.M):
        module, _, name = target.rpartition(".")
        try:
            obj = getattr(importlib.import_module(module), name)
        except ModuleNotFoundError:
            obj = importlib.import_module(target)
        assert obj.__doc__, target


DOCS_EXTRA = ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python", "mkdocs_click")


def _has_docs_extra() -> bool:
    try:
        return all(importlib.util.find_spec(name) is not None for name in DOCS_EXTRA)
    except ModuleNotFoundError:
        return False


@pytest.mark.skipif(not _has_docs_extra(), reason="the docs extra is not installed (pip install '.[docs]')")
def test_the_site_builds_strictly(tmp_path):
    # no --quiet: MkDocs drops warnings below ERROR before its strict count sees them
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(tmp_path / "site")],
                          cwd=REPO, capture_output=True, text=True, timeout=300, env=_env())
    assert proc.returncode == 0, proc.stderr[-3000:]
    html = (tmp_path / "site" / "reference" / "grammar" / "index.html").read_text(encoding="utf-8")
    assert "<table>" in html and "turn left by a degrees" in html
    cli = (tmp_path / "site" / "reference" / "cli" / "index.html").read_text(encoding="utf-8")
    assert "--linear-steps" in cli and "plantgen render" in cli


def _env() -> dict:
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH", "")]))
    return env


# ---------------------------------------------------------------------------- the prose check
#: How docs/how-to/render.md read before it was mended (issue 46): a sentence's tail after
#: the camera section, the camera paragraph twice, and sections opening on a stray space.
GARBLED = """## Cameras

The camera file holds `eye`, `target`, `up`, `fov_y` (vertical, degrees), `width` and
`height`; `--camera-out cam.json` writes the one a render used and `--camera cam.json`
reads it back. Rays go through pixel centres. `--depth-out depth.npy` writes float32
distances along each pixel's ray, shape (height, width), row 0 the top row of the PNG,
`inf` for a miss. `--camera auto` (the default) frames the model so it spans most of the
viewport, or takes the scene's camera.

dark and light colour, a fixed function of its index, so neighbours read apart. With
shadows the leaves are drawn into the light's map too, so they cast shadows on the ground,
the branches and each other, and receive them.

The camera file holds `eye`, `target`, `up`, `fov_y` (vertical, degrees), `width` and
`height`; rays go through pixel centres; `--depth-out` writes float32 distances along
each pixel's ray, shape (height, width), row 0 the top row of the PNG, `inf` for a miss.
`auto` frames the model so it spans most of the viewport (or takes the scene's camera).

## The camera without a file

 `--azimuth DEG` (around the vertical axis; 0 looks from +z,
90 from +x), `--elevation DEG` (above the horizontal, within 89) turn the automatic camera.
"""


def test_the_prose_check_finds_each_kind_of_garble():
    problems = hooks().prose_problems(GARBLED)
    kinds = [p.split(": ", 1)[1].split(":")[0] for p in problems]
    assert kinds == ["paragraph starts mid-sentence", "paragraph repeats line 3's",
                     "paragraph starts with a stray space"], problems
    assert problems[0].startswith("line 10:")
    assert hooks().prose_problems("# Title\n\n#  Spaced heading\n\nText.\n")[0].startswith("line 3: heading")


def test_the_prose_check_passes_what_reads_well():
    good = """# Title

One command:

```sh
plantgen grow pine
```

derives the L-system; the text goes on after the command.

plantgen starts many sentences with its own name.

- a list item
  that wraps

  and a second paragraph of the item, indented.

| a | table |
|---|---|

Under one table the bench says 1,234 rays took 5.6 s on the first run of this very long caption.

Under one table the bench says 2,345 rays took 7.8 s on the first run of this very long caption.
"""
    assert hooks().prose_problems(good) == []


def test_every_page_reads_cleanly():
    """The prose check over every page and the README (the strict build runs it as well)."""
    found = {name: hooks().prose_problems((DOCS / name).read_text(encoding="utf-8")) for name in _pages()}
    found["README.md"] = hooks().prose_problems(README.read_text(encoding="utf-8"))
    assert {name: p for name, p in found.items() if p} == {}


@pytest.mark.skipif(not _has_docs_extra(), reason="the docs extra is not installed (pip install '.[docs]')")
def test_a_garbled_page_fails_the_strict_build(tmp_path):
    """The hook's warnings stop MkDocs in strict mode (a small site with the same hook)."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "index.md").write_text("# Garbled\n\n" + GARBLED, encoding="utf-8")
    (tmp_path / "mkdocs.yml").write_text(f"site_name: t\nhooks:\n  - {DOCS / 'hooks.py'}\n", encoding="utf-8")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(tmp_path / "site")],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120, env=_env())
    assert proc.returncode != 0
    assert "paragraph starts mid-sentence" in proc.stderr


# ---------------------------------------------------------------------------- one source for every figure
#: A speed figure: a time in ms, frames a second, rays (beams, primitives, points) a second,
#: or a speed-up ("2.5 to 11 times faster", "1.2x faster"), a range's two ends included.
#: Seconds and bare ratios ("3.5x") are left out: most seconds are settings (a timeout, a
#: sway's duration), and "4x4", "8x the rows" are no speeds.
SPEED = re.compile(
    r"(?<![\w.])(\d[\d,]*(?:\.\d+)?)(?:\s*(?:to|-|–)\s*(\d[\d,]*(?:\.\d+)?))?\s*"
    r"(?:(?:times|x|×)\s+(?:faster|slower)|ms\b|fps\b|"
    r"(?:million\s+)?(?:rays|beams|primitives|points)\s*(?:/\s*s\b|a second|per second))", re.I)
#: The prose pages: they never type a speed figure, they point at the benchmark tables (or
#: include a bench's table by snippet).
PROSE = ("how-to", "tutorials", "explanation")


def _fences_out(text: str) -> str:
    """``text`` without fenced code (commands and sample output, not claims)."""
    return re.sub(r"^\s*(```|~~~).*?^\s*\1", "", text, flags=re.M | re.S)


def speed_figures(text: str) -> list[tuple[str, tuple[str, ...]]]:
    """(the figure as written, its numbers) of every speed figure in ``text``'s prose."""
    return [(m.group(0).replace("\n", " "), tuple(n for n in m.groups() if n))
            for m in SPEED.finditer(_fences_out(text))]


#: An include on a line of its own (``--8<-- "file"`` or ``"file:section"``) and the
#: section markers inside an included file, as pymdownx.snippets reads them.
SNIPPET = re.compile(r'^--8<--\s+"([^":]+)(?::([\w-]+))?"\s*$', re.M)
SECTION_MARK = re.compile(r"^.*--8<-- \[(start|end):([\w-]+)\].*$")


def with_snippets(text: str) -> str:
    """``text`` with its ``--8<--`` includes resolved from mkdocs.yml's snippet base path
    (the bench tables of gallery/bench): a whole file, or the lines between a section's
    start and end markers; the markers themselves left out, as the site drops them. Read
    here, not through pymdownx, so the test extra alone runs these tests."""
    import yaml

    config = yaml.safe_load((REPO / "mkdocs.yml").read_text(encoding="utf-8"))
    options = next(e["pymdownx.snippets"] for e in config["markdown_extensions"]
                   if isinstance(e, dict) and "pymdownx.snippets" in e)
    bases = [REPO / p for p in options["base_path"]]

    def include(m: re.Match) -> str:
        path = next(base / m.group(1) for base in bases if (base / m.group(1)).is_file())
        lines, inside = [], m.group(2) is None
        for line in path.read_text(encoding="utf-8").splitlines():
            mark = SECTION_MARK.match(line)
            if mark:
                if mark.group(2) == m.group(2):
                    inside = mark.group(1) == "start"
                continue
            if inside:
                lines.append(line)
        return "\n".join(lines)

    return SNIPPET.sub(include, text)


def table_numbers(text: str) -> set[str]:
    """Every number in the Markdown tables of ``text``."""
    rows = " ".join(line for line in text.splitlines() if line.lstrip().startswith("|"))
    return set(re.findall(r"\d[\d,]*(?:\.\d+)?", rows))


def _prose_pages() -> list[str]:
    return [name for name in _pages() if name.split("/")[0] in PROSE or name == "index.md"]


def test_the_speed_figure_pattern_finds_each_kind():
    text = ("RC is 2.5 to 11 times faster; 12 against 67 ms; 24 fps; 330,000 beams a second; "
            "1.2–1.4x faster; 1.5 million primitives a second\n```\nframe: 40 ms\n```\n4x4 views, 1024x768, "
            "8x the rows, 256 × 256")
    found = [numbers for _, numbers in speed_figures(text)]
    assert found == [("2.5", "11"), ("67",), ("24",), ("330,000",), ("1.2", "1.4"), ("1.5",)]


def test_the_readme_and_the_guides_type_no_speed_figure():
    """Speed claims in the README, the how-to guides, the tutorials and the explanations
    come from the bench tables (included by snippet) or point at them, never retyped."""
    readme = README.read_text(encoding="utf-8") if README.is_file() else pytest.skip("no README.md")
    found = {"README.md": speed_figures(readme)}
    for name in _prose_pages():
        text = (DOCS / name).read_text(encoding="utf-8")
        found[name] = speed_figures(re.sub(r'^--8<--\s+".*"\s*$', "", text, flags=re.M))   # included: a table's
    typed = {name: [f for f, _ in figures] for name, figures in found.items() if figures}
    assert typed == {}, f"pages that type speed figures instead of pointing at a bench table: {typed}"


def test_the_guides_include_the_bench_summary_they_quote():
    text = with_snippets((DOCS / "how-to" / "render.md").read_text(encoding="utf-8"))
    assert "| inputs | size | faster frame | times faster |" in text and "--8<--" not in text
    assert "| single plants | 1024x768 | RC on 5 of 5 |" in text


@pytest.mark.parametrize("name", sorted(p.name for p in (DOCS / "benchmarks").glob("*.md")))
def test_a_benchmark_page_quotes_only_figures_its_tables_hold(name):
    """A benchmark page's prose may discuss the numbers of its tables and of the bench
    files it includes (a bench's output, tables and notes, is the source); a speed figure
    that neither holds is retyped from elsewhere or derived by hand."""
    text = page(f"benchmarks/{name}")
    snippet = re.compile(r'^--8<--\s+".*"\s*$', re.M)
    included = "\n".join(with_snippets(line) for line in snippet.findall(text))
    assert "--8<--" not in included
    held = table_numbers(text) | set(re.findall(r"\d[\d,]*(?:\.\d+)?", included))
    prose = "\n".join(line for line in snippet.sub("", text).splitlines() if not line.lstrip().startswith("|"))
    loose = [figure for figure, numbers in speed_figures(prose) if not set(numbers) <= held]
    assert loose == [], f"figures no table on the page holds: {loose}"
