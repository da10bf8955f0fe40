"""The documentation's pages as a reader sees them: each page of ``docs/`` with its
generated tables filled in by the site's own hook (``docs/hooks.py``)."""

from __future__ import annotations

import importlib.util
from functools import cache
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"
README = REPO / "README.md"


@cache
def hooks():
    """The site's hook module (docs/hooks.py), or a skip outside the source tree."""
    path = DOCS / "hooks.py"
    if not path.is_file():
        pytest.skip("needs the source tree's docs/ (docs/hooks.py)")
    spec = importlib.util.spec_from_file_location("plantgen_docs_hooks", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def page(name: str) -> str:
    """The Markdown of ``docs/NAME`` with its generated tables expanded."""
    path = DOCS / name
    if not path.is_file():
        pytest.skip(f"needs the source tree's docs/{name}")
    return hooks().expand(path.read_text(encoding="utf-8"))


def table_after(text: str, header: str) -> list[str]:
    """The lines of the first Markdown table whose header row starts with ``header``."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(header))
    stop = next((i for i in range(start, len(lines)) if not lines[i].startswith("|")), len(lines))
    return lines[start:stop]
