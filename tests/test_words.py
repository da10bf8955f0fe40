"""Plain words first, detail on request (issue 46): ``render --help`` in sections, reports
without the paper's abbreviations unless ``--verbose`` asks, a glossary that defines every
term the detail uses, and the still formats a person expects (.jpg, .webp)."""

from __future__ import annotations

import re

import pytest
from _cli import run_cli
from _docs import DOCS
from PIL import Image

from plantgen.geometry.skeletons.skeleton import Skeleton

#: The headings of ``render --help``, in their order.
RENDER_SECTIONS = ("Output:", "Camera:", "Quality:", "Effects:", "Limits:")
#: The paper's terms a plain report must not use (it says "ray cast", "branch pieces"...).
JARGON = re.compile(r"\b(RC|RT|GS|BVH)(\+\w+)?\b|\bfrust(a|um)\b|\brows?\b|§|\(7\)")
#: The terms the verbose reports and the help use, each a heading of the glossary.
GLOSSARY_TERMS = ("Segment", "Frustum, frusta", "Row", "m (subdivision level)", "RC (ray casting)",
                  "RT (ray tracing)", "BVH", "GS (geometry shading)", "+R (relief)", "GS+N, GS+POM",
                  "Relief mapping", "Shell, relief layer", "Texel", "Adaptive march, fixed march",
                  "Linear steps, binary steps", "v, v of (7)", "§2, §3, (7)", "Shadow map", "Level of detail, lod0",
                  "Instancing, copies", "Supersampling (SSAA)")


@pytest.fixture
def column(tmp_path):
    """A one-segment skeleton file."""
    path = tmp_path / "column.npz"
    Skeleton([[0, 0, 0]], [[0, 2, 0]], [0.5], [0.4], [-1], [False], [0], ("bark",)).save(path)
    return path


def _sections(help_text: str) -> dict[str, list[str]]:
    """{heading: the option lines under it} of a command's ``--help``."""
    out, current = {}, None
    for line in help_text.splitlines():
        if re.match(r"^[A-Z][\w ]*:$", line):
            current = out.setdefault(line, [])
        elif current is not None and re.match(r"^  -", line):
            current.append(line.split()[0].rstrip(","))
    return out


def test_render_help_shows_its_options_in_sections():
    code, stdout, _ = run_cli("render", "--help")
    assert code == 0
    sections = _sections(stdout)
    headings = [h for h in sections if h in RENDER_SECTIONS]
    assert headings == list(RENDER_SECTIONS), list(sections)
    assert "Options:" not in sections                      # no option left in one long list
    assert "--size" in sections["Output:"] and "--azimuth" in sections["Camera:"]
    assert "--linear-steps" in sections["Quality:"] and "--shadows" in sections["Effects:"]
    assert "--limit" in sections["Limits:"]
    # help is "-h" or "--help" first, depending on the context click built its option in first
    unplaced = set(sections.get("Other options:", [])) - {"--time-frames", "-q", "-v", "--debug", "-h", "--help"}
    assert not unplaced, f"options in no section: name their settings class in plantgen.cli.sections: {unplaced}"
    options = [o for lines in sections.values() for o in lines]
    assert len(options) == len(set(options))               # each option once
    assert "§" not in stdout and "v of (7)" not in stdout
    assert "docs: reference/glossary.md" in " ".join(stdout.split())     # the glossary, linked


def test_export_help_is_sectioned_and_links_the_glossary():
    code, stdout, _ = run_cli("export", "--help")
    assert code == 0 and "Output:" in stdout and "Quality:" in stdout and "Options:" not in stdout
    assert "docs: reference/glossary.md" in " ".join(stdout.split())


def test_a_default_render_says_it_in_plain_words_and_verbose_in_the_renderers(gl_ctx, column, tmp_path):
    args = ["render", column, "-o", tmp_path / "c.png", "--size", "64x48", "--relief", "--shadows",
            "--shadow-res", "64"]
    code, plain, stderr = run_cli(*args)
    assert code == 0, stderr
    assert not JARGON.search(plain), JARGON.search(plain)
    assert "model: 1 branch segments" in plain and "ray cast with relief mapping" in plain
    code, verbose, stderr = run_cli(*args, "--verbose")
    assert code == 0, stderr
    assert "segments: 1 -> 1 frusta (96 bytes each" in verbose
    assert "RC+R (adaptive march, 2 samples per texel, at most 32 linear + 12 binary steps, v interpolated)" in verbose


def test_a_shipped_default_render_has_no_unexplained_abbreviation(gl_ctx, tmp_path):
    code, stdout, stderr = run_cli("render", "saguaro", "-o", tmp_path / "s.png", "--size", "64x48")
    assert code == 0, stderr
    assert not JARGON.search(stdout), stdout


def test_the_glossary_defines_every_term_and_is_in_the_site():
    path = DOCS / "reference" / "glossary.md"
    if not DOCS.is_dir():
        pytest.skip("needs the source tree's docs/")
    text = path.read_text(encoding="utf-8")
    headings = set(re.findall(r"^### (.+)$", text, re.M))
    assert set(GLOSSARY_TERMS) <= headings, set(GLOSSARY_TERMS) - headings
    for term in GLOSSARY_TERMS:                              # each with a definition under it
        body = text.split(f"### {term}\n", 1)[1].split("\n#", 1)[0]
        assert len(body.split()) >= 12, term
    assert "reference/glossary.md" in (DOCS.parent / "mkdocs.yml").read_text(encoding="utf-8")


@pytest.mark.parametrize(("suffix", "fmt"), [(".jpg", "JPEG"), (".jpeg", "JPEG"), (".webp", "WEBP")])
def test_render_writes_jpeg_and_webp_stills(gl_ctx, column, tmp_path, suffix, fmt):
    out = tmp_path / f"c{suffix}"
    code, stdout, stderr = run_cli("render", column, "-o", out, "--size", "80x60")
    assert code == 0, stderr
    assert stdout.strip().splitlines()[-1] == f"wrote {out}"
    with Image.open(out) as image:
        assert image.format == fmt and image.size == (80, 60) and image.mode == "RGB"
        pixels = image.convert("RGB").getcolors(1 << 16)
    assert len(pixels) > 4                                   # a picture, not one flat colour


def test_a_transparent_webp_keeps_its_alpha_and_a_jpeg_refuses_it(gl_ctx, column, tmp_path):
    out = tmp_path / "c.webp"
    code, _, stderr = run_cli("render", column, "-o", out, "--size", "40x30", "--background", "none")
    assert code == 0, stderr
    with Image.open(out) as image:
        assert image.mode == "RGBA" and image.size == (40, 30)
        alpha = image.getchannel("A")
        assert alpha.getextrema() == (0, 255)                # the model opaque, the rest clear
    code, _, stderr = run_cli("render", column, "-o", tmp_path / "c.jpg", "--background", "none")
    assert code == 2 and "no transparency" in stderr and not (tmp_path / "c.jpg").exists()
