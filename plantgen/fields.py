"""Typed, ranged reading of the values an input file gives, in one place for grammars,
scenes and cameras.

A grammar or scene is untrusted input, so every value is checked where it is read: its
type (a number is an int or a float, never a bool or a string), finite, and within its
range; an integer field takes an int or an integral float (``3.0``), never ``1.5``. Each
reader takes the ``error`` class to raise (``GrammarError``, ``SceneError``,
``CameraError``) and ``where`` (the file and the place in it), and quotes the value
through :func:`show`, which stays short whatever the value is (a long list, a deep
mapping, a 10,000-digit number).
"""

from __future__ import annotations

import math
import reprlib

import numpy as np

from .errors import PlantgenError

__all__ = ["MAX_INT", "integer", "keys", "number", "show", "text", "unit_vector", "vector"]

#: The largest integer a file may give anywhere (seeds, counts): int64's.
MAX_INT = 2**63 - 1

_REPR = reprlib.Repr()
_REPR.maxlevel, _REPR.maxstring, _REPR.maxother, _REPR.maxlong = 2, 40, 40, 40
_REPR.maxlist = _REPR.maxtuple = _REPR.maxdict = _REPR.maxset = 4


def show(value) -> str:
    """A short repr of ``value`` for a message (at most a few dozen characters)."""
    try:
        return _REPR.repr(value)
    except Exception:   # a repr that itself fails (an int past Python's digit limit)
        return f"<{type(value).__name__}>"


def _is_number(value) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, float))


def integer(value, what: str, where: str, error: type[PlantgenError], *, lo: int = 0,
            hi: int | None = MAX_INT) -> int:
    """``value`` as an int in ``lo..hi`` (``hi`` None: no upper bound here; the caller
    checks it against a limit)."""
    if isinstance(value, float) and math.isfinite(value) and value == int(value):
        value = int(value)
    if not _is_number(value) or not isinstance(value, int):
        raise error(f"{where}: {what} must be an integer, got {show(value)}")
    if value < lo or (hi is not None and value > hi):
        bounds = f"{lo}..{hi}" if hi is not None else f">= {lo}"
        raise error(f"{where}: {what} must be an integer {bounds}, got {show(value)}")
    return value


def number(value, what: str, where: str, error: type[PlantgenError], *, lo: float | None = None,
           hi: float | None = None, positive: bool = False, max_abs: float | None = None) -> float:
    """``value`` as a finite float, at least ``lo``, at most ``hi``, above 0 if
    ``positive``, at most ``max_abs`` in magnitude."""
    if not _is_number(value):
        raise error(f"{where}: {what} must be a number, got {show(value)}")
    try:
        out = float(value)
    except OverflowError:
        out = math.inf
    if not math.isfinite(out):
        raise error(f"{where}: {what} must be a finite number, got {show(value)}")
    if positive and out <= 0:
        raise error(f"{where}: {what} must be positive, got {out:g}")
    if lo is not None and out < lo:
        raise error(f"{where}: {what} must be at least {lo:g}, got {out:g}")
    if hi is not None and out > hi:
        raise error(f"{where}: {what} must be at most {hi:g}, got {out:g}")
    if max_abs is not None and abs(out) > max_abs:
        raise error(f"{where}: {what} {out:g} is beyond the largest magnitude {max_abs:g}")
    return out


def vector(value, what: str, where: str, error: type[PlantgenError], *, n: int = 3,
           max_abs: float | None = None) -> np.ndarray:
    """``value`` as a (n,) float64 array of finite numbers (each at most ``max_abs``)."""
    if not isinstance(value, (list, tuple)) or len(value) != n or not all(_is_number(x) for x in value):
        count = {2: "two", 3: "three", 4: "four"}.get(n, str(n))
        raise error(f"{where}: {what} must be {count} numbers, got {show(value)}")
    return np.array([number(x, what, where, error, max_abs=max_abs) for x in value], dtype=np.float64)


def unit_vector(value, what: str, where: str, error: type[PlantgenError]) -> tuple[float, ...]:
    """``value`` (three finite numbers, not all zero) scaled to unit length. Huge
    components keep their direction (the vector is scaled down before its norm is taken)."""
    v = vector(value, what, where, error)
    scale = float(np.abs(v).max())
    if scale == 0:
        raise error(f"{where}: {what} must not be zero")
    v = v / scale
    return tuple((v / np.linalg.norm(v)).tolist())


def text(value, what: str, where: str, error: type[PlantgenError], *, max_len: int = 1000) -> str:
    """``value`` as a string of at most ``max_len`` characters (a number is written out)."""
    if _is_number(value):
        value = str(value)
    if not isinstance(value, str):
        raise error(f"{where}: {what} must be a string, got {show(value)}")
    if len(value) > max_len:
        raise error(f"{where}: {what} is {len(value):,} characters long, over {max_len:,}")
    return value


def keys(value, allowed, where: str, error: type[PlantgenError]) -> dict:
    """``value`` if it is a mapping whose keys are all in ``allowed`` (None: any string)."""
    if not isinstance(value, dict):
        raise error(f"{where}: must be a mapping, got {show(value)}")
    if allowed is None:
        bad = [k for k in value if not isinstance(k, str)]
        if bad:
            raise error(f"{where}: keys must be names, got {show(bad)}")
        return value
    unknown = [k for k in value if k not in allowed]
    if unknown:
        raise error(f"{where}: unknown key(s) {show(sorted(map(str, unknown)))} "
                    f"(allowed: {', '.join(sorted(allowed))})")
    return value
