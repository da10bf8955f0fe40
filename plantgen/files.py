"""Files in and out, in one place: reading YAML input and writing outputs atomically.

Every output plantgen writes goes through :func:`write_atomically`: the bytes go to a
hidden temporary name beside the target, which is renamed onto it only when complete,
so a failure never leaves a half-written file. Every YAML input goes through
:func:`read_yaml`, which turns every failure into one :class:`PlantgenError` line.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import yaml

from .errors import PlantgenError

__all__ = ["read_yaml", "write_atomically", "temporary_name"]


def read_yaml(path: str | Path, error: type[PlantgenError] = PlantgenError):
    """Read a YAML file, turning every failure into one ``error`` line naming the file
    (and the line, for a syntax error)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error(f"{path}: no such file") from None
    except IsADirectoryError:
        raise error(f"{path}: is a directory, not a grammar") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{path}: cannot read ({exc.__class__.__name__})") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f" line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise error(f"{path}:{line}: YAML error: {problem}") from None


def temporary_name(path: str | Path) -> Path:
    """The hidden name ``path`` is written under before the rename: ``.NAME.partSUFFIX``
    (the suffix stays last, so writers that pick a format by suffix still can)."""
    path = Path(path)
    return path.with_name(f".{path.name}.part{path.suffix}")


def write_atomically(path: str | Path, write: Callable[[Path], object],
                     error: type[PlantgenError] = PlantgenError) -> Path:
    """Call ``write(tmp_path)``, then rename the temporary file onto ``path``.

    Nothing half-written survives: on any failure the temporary file is removed; an
    ``OSError`` becomes one ``error`` line naming ``path``. Returns ``path``.
    """
    path = Path(path)
    tmp = temporary_name(path)
    try:
        write(tmp)
        tmp.replace(path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise error(f"{path}: cannot write ({exc.strerror or exc})") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path
