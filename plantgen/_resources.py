"""Locate the data that ships with plantgen: grammars, scenes and shaders.

In a wheel they sit inside the package (``plantgen/grammars``, ``plantgen/shaders``);
in a source checkout or an editable install they sit at the repository's top level.
"""

from __future__ import annotations

from pathlib import Path

_PKG = Path(__file__).resolve().parent


def _data_dir(name: str) -> Path:
    for candidate in (_PKG / name, _PKG.parent / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"plantgen's {name}/ directory is missing from this install")


def grammars_dir() -> Path:
    """Directory of the shipped grammars and scenes (``*.yaml``)."""
    return _data_dir("grammars")


def shaders_dir() -> Path:
    """Directory of the shipped GLSL sources."""
    return _data_dir("shaders")


def shipped_grammar(name: str) -> Path:
    """Path of a shipped grammar or scene by stem, e.g. ``shipped_grammar("pine")``."""
    path = grammars_dir() / f"{name}.yaml"
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in grammars_dir().glob("*.yaml")))
        raise FileNotFoundError(f"no shipped grammar named {name!r} (known: {known})")
    return path
