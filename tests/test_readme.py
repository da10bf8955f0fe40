"""The README as a newcomer uses it: every command in its shell blocks runs (from an empty
folder, as the shipped names allow; the first tutorials' commands too), its Python block
runs, it stays short, and its links lead to files that exist.

``pip install`` is left out here (CI's fresh environment runs the set-up commands from the
built wheel, outside the checkout: see .ci/run), and so is ``pytest -q``, which is this
suite. A command that needs an extra that is not installed skips, naming it."""

from __future__ import annotations

import importlib.util
import os
import re
import shlex
import subprocess
import sys

import pytest
from _docs import DOCS, README, REPO

#: Commands that need an extra, by the subcommand or the output's suffix: (test, the
#: module it needs, the extra that installs it).
NEEDS = (
    (lambda args: args[:1] == ["view"], "moderngl_window", "view"),
    (lambda args: args[:1] == ["batch"], "distributed", "batch"),
    (lambda args: args[:1] == ["bench"], "skimage", "bench"),
    (lambda args: any(a.endswith((".usda", ".usdc", ".usd")) for a in args), "pxr", "usd"),
    (lambda args: any(a.endswith((".las", ".laz")) for a in args), "laspy", "scan"),
)


#: Tutorials whose commands are cheap enough to run here too (the others grow a hundred
#: pines or scan at full density).
TUTORIALS = ("first-plant.md", "blender.md")


def _text(path=README) -> str:
    if not path.is_file():
        pytest.skip(f"needs the source tree's {path.name}")
    return path.read_text(encoding="utf-8")


def _blocks(language: str, path=README) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)^```", _text(path), re.M | re.S)


def readme_commands(path=README) -> list[str]:
    """Each command of a page's ``sh`` blocks, comments dropped, ``a && b`` split."""
    if not path.is_file():
        return []
    out = []
    for block in _blocks("sh", path):
        for line in block.splitlines():
            line = line.split("  #")[0].strip()
            out += [part.strip() for part in line.split("&&") if part.strip()]
    return out


def test_the_readme_is_short_and_has_its_sections():
    text = _text()
    assert len(text.splitlines()) <= 250
    for heading in ("## Set-up", "## Five first commands", "## Three ideas", "## Documentation"):
        assert heading in text
    assert [len(re.findall(r"^plantgen ", b, re.M)) for b in _blocks("sh")].count(5) == 1   # five first commands
    assert len(re.findall(r"!\[[^\]]*\]\(", text)) == 1          # one picture


def test_the_readme_spells_extras_one_way():
    text = _text()
    assert not re.search(r"plantgen\[\w+\]", text)
    assert re.findall(r"pip install '\.\[(\w+)\]'", text)


def test_the_readme_test_command_is_what_ci_runs():
    assert {"pip install '.[test]'", "pytest -q"} <= set(readme_commands())
    ci = (REPO / ".ci" / "run").read_text(encoding="utf-8")
    assert "'.[test]'" in ci and re.search(r"^pytest -q$", ci, re.M)


def test_the_readme_links_lead_to_files():
    for target in re.findall(r"\]\(([^)#\s]+)", _text()):
        if "://" not in target:
            assert (REPO / target).exists(), target


def _plantgen_commands() -> list:
    pages = [README, *(DOCS / "tutorials" / name for name in TUTORIALS)]
    return [pytest.param(c, id=f"{page.name}: {c}") for page in pages for c in readme_commands(page)
            if c.startswith("plantgen ")]


@pytest.mark.parametrize("command", _plantgen_commands())
def test_every_readme_command_runs(command, tmp_path):
    """The README's commands, and those of the tutorials that are cheap to run."""
    args = shlex.split(command)[1:]
    for needs, module, extra in NEEDS:
        if needs(args) and importlib.util.find_spec(module) is None:
            pytest.skip(f"needs the {extra} extra (pip install '.[{extra}]')")
    if args[:1] == ["view"]:
        pytest.skip("opens a window: the viewer's own tests run it under Xvfb")
    proc = subprocess.run([sys.executable, "-m", "plantgen", *args], cwd=tmp_path, capture_output=True, text=True,
                          timeout=600, env=_env())
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "error" not in proc.stderr.lower()
    if "-o" in args:
        assert (tmp_path / args[args.index("-o") + 1]).stat().st_size > 0
    elif args[0] in ("grow", "render", "export", "scan"):
        assert any(tmp_path.iterdir()), f"{command} wrote nothing"


def test_the_readme_python_block_runs(tmp_path):
    blocks = _blocks("python")
    assert blocks
    for block in blocks:
        proc = subprocess.run([sys.executable, "-c", block], cwd=tmp_path, capture_output=True, text=True,
                              timeout=600, env=_env())
        assert proc.returncode == 0, proc.stderr[-2000:]


def _env() -> dict:
    """This checkout's plantgen first, as the ``plantgen`` command the README runs."""
    return dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
