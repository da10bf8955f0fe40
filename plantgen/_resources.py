"""Locate the data that ships with plantgen: grammars, scenes and shaders.

In a wheel they sit inside the package (``plantgen/grammars``, ``plantgen/shaders``);
in a source checkout or an editable install they sit at the repository's top level.
"""

from __future__ import annotations

import difflib
import os
import re
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


def shipped_names() -> list[str]:
    """The names of the shipped grammars and scenes (``pine``, ``forest``, ...), sorted."""
    return sorted(p.stem for p in grammars_dir().glob("*.yaml"))


def shipped_grammar(name: str) -> Path:
    """Path of a shipped grammar or scene by stem, e.g. ``shipped_grammar("pine")``."""
    path = grammars_dir() / f"{name}.yaml"
    if not path.is_file():
        raise FileNotFoundError(f"no shipped grammar or scene named {name!r}{missing_hint(name)}")
    return path


#: What a hint adds when no name comes close.
LIST_HINT = "'plantgen list' names the shipped grammars and scenes"


def closest(name: str, known) -> str | None:
    """The one of ``known`` closest to ``name`` (a mistyped name), or None if none is close."""
    match = difflib.get_close_matches(name, list(known), n=1, cutoff=0.6)
    return match[0] if match else None


def missing_hint(name: str | os.PathLike, folder: Path | None = None) -> str:
    """What to add to "NAME: no such file": `` (did you mean 'pine'?)`` for a mistyped
    shipped name, a path whose stem is a shipped name (``grammars/pine.yaml`` run outside
    the checkout) or a file beside it with a close name; else a pointer to ``plantgen list``.

    ``folder``: where a relative name is looked for besides the shipped ones (a scene's
    folder); default: the name's own folder."""
    text = str(name)
    path = Path(text)
    if path.name == text and not path.suffix:            # a plain name: a shipped one mistyped
        match = closest(text, shipped_names())
        if match is None and folder is not None:
            match = _sibling(folder / text)
        return f" (did you mean '{match}'? {LIST_HINT})" if match else f" ({LIST_HINT})"
    sibling = _sibling(folder / path if folder is not None else path)
    if sibling is not None:
        return f" (did you mean '{path.with_name(sibling)}'?)"
    match = closest(path.name.split(".")[0], shipped_names())
    if match is not None:
        return f" (did you mean the shipped name '{match}'? {LIST_HINT})"
    return ""


def _sibling(path: Path) -> str | None:
    """The name of a file beside ``path`` (with its suffix) close to its name, or None."""
    try:
        names = [p.name for p in path.parent.iterdir() if p.suffix.lower() == path.suffix.lower()]
    except OSError:
        return None
    return closest(path.name, names[:10_000])


def short_names(text: str) -> str:
    """``text`` with every path of a shipped grammar or scene (a long site-packages path in
    an installed wheel) replaced by its name, as commands take it: ``pine``."""
    try:
        root = str(grammars_dir())
    except FileNotFoundError:
        return text
    return re.sub(re.escape(root + os.sep) + r"([\w.-]+?)\.yaml\b", r"\1", text)
