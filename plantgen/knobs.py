"""Knobs: a setting's one declaration (its default, range, command-line name and help).

A setting is a field of a frozen dataclass (:mod:`plantgen.settings`, :class:`plantgen.geometry.rays.camera.Orbit`)
declared with :func:`knob`: the field's default is the setting's only default, and its
:class:`Knob` metadata says how the command line spells it, what it accepts and what it
does. The command line builds its options from these (``plantgen.cli.options.knob_options``),
the API and the viewer take the same names, and :func:`check_knobs` refuses a value out of
range in one line naming the option. Nothing here knows click, GL or numpy.
"""

from __future__ import annotations

import math
from dataclasses import MISSING, dataclass, field, fields, is_dataclass

from .errors import PlantgenError

__all__ = ["Knob", "knob", "knob_of", "knob_fields", "check_knobs", "knob_args", "knob_values"]


@dataclass(frozen=True)
class Knob:
    """How a setting is given and checked.

    option : the command line's name (``--linear-steps``); its parameter name (and the
        API's keyword) is the option without dashes (``linear_steps``), or ``param``
    help : one sentence for ``--help``
    kind : ``int``, ``float``, ``bool``, ``str``, ``choice``, ``size`` (WIDTHxHEIGHT) or
        ``list`` (comma-separated names)
    lo, hi : the range of a number (None: unbounded); lo_open, hi_open exclude the bound
    choices : the values of a ``choice``
    flag : a boolean's ``--on/--off`` pair (default ``--name/--no-name``)
    metavar : how ``--help`` shows the value
    param : the parameter name, where it differs from the option's
    """

    option: str
    help: str
    kind: str = "float"
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple = ()
    flag: str | None = None
    metavar: str | None = None
    param: str | None = None

    @property
    def name(self) -> str:
        """The parameter's (and the API keyword's) name."""
        return self.param or self.option.lstrip("-").replace("-", "_")

    def range_text(self) -> str:
        """The range as one phrase (``1..4096``, ``> 0``), or '' when unbounded."""
        lo = None if self.lo is None else f"{self.lo:g}"
        hi = None if self.hi is None else f"{self.hi:g}"
        if lo is not None and hi is not None:
            if not (self.lo_open or self.hi_open):
                return f"{lo}..{hi}"
            return f"{'(' if self.lo_open else '['}{lo}, {hi}{')' if self.hi_open else ']'}"
        if lo is not None:
            return f"{'>' if self.lo_open else '>='} {lo}"
        if hi is not None:
            return f"{'<' if self.hi_open else '<='} {hi}"
        return ""

    def clamp(self, value):
        """``value`` brought into the knob's closed range (a key that steps a knob)."""
        if self.lo is not None and not self.lo_open:
            value = max(value, type(value)(self.lo))
        if self.hi is not None and not self.hi_open:
            value = min(value, type(value)(self.hi))
        return value

    def check(self, value, error=PlantgenError) -> None:
        """One line naming the option for a value outside the knob's range or choices
        (None passes: a knob left unset)."""
        if value is None:
            return
        if self.kind == "choice" and value not in self.choices:
            raise error(f"{self.option} must be one of {', '.join(map(str, self.choices))}, got {value!r}")
        if self.kind == "int" and (isinstance(value, bool) or int(value) != value):
            raise error(f"{self.option} must be an integer, got {value!r}")
        if self.kind in ("int", "float"):
            if not math.isfinite(float(value)):
                raise error(f"{self.option} must be a finite number, got {value!r}")
            low = self.lo is not None and (value <= self.lo if self.lo_open else value < self.lo)
            high = self.hi is not None and (value >= self.hi if self.hi_open else value > self.hi)
            if low or high:
                raise error(f"{self.option} must be {self.range_text()}, got {value!r}")


def knob(default, option: str, help: str, **spec):
    """A dataclass field with ``default`` and its :class:`Knob` (see there for ``spec``)."""
    return field(default=default, metadata={"knob": Knob(option, help, **spec)})


def knob_of(cls, name: str) -> Knob:
    """The knob of the field ``name`` of the dataclass ``cls``."""
    return next(f.metadata["knob"] for f in fields(cls) if f.name == name)


def knob_fields(cls) -> list[tuple[str, Knob, object]]:
    """(field name, knob, default) of every knob field of the dataclass ``cls``."""
    out = []
    for f in fields(cls):
        k = f.metadata.get("knob")
        if k is not None:
            default = f.default if f.default is not MISSING else f.default_factory()    # type: ignore[misc]
            out.append((f.name, k, default))
    return out


def check_knobs(obj, error=PlantgenError) -> None:
    """Check every knob field of the dataclass instance ``obj`` (:meth:`Knob.check`)."""
    for name, k, _ in knob_fields(type(obj)):
        k.check(getattr(obj, name), error)


def knob_values(cls, params: dict) -> dict:
    """{field name: value} of ``cls``'s knobs found in ``params`` (keyed by knob name),
    leaving out the unset (None) ones: the keywords that build ``cls``."""
    out = {}
    for name, k, _ in knob_fields(cls):
        value = params.get(k.name)
        if value is not None:
            out[name] = tuple(value) if isinstance(value, list) else value
    return out


def knob_args(obj) -> list[str]:
    """The command-line words that give ``obj``'s knobs where they differ from their
    defaults (nested settings included): what a printed command needs to say."""
    words: list[str] = []
    for f in fields(obj):
        value = getattr(obj, f.name)
        k = f.metadata.get("knob")
        if k is None:
            if is_dataclass(value) and not isinstance(value, type):
                words += knob_args(value)
            continue
        default = f.default if f.default is not MISSING else f.default_factory()    # type: ignore[misc]
        if value == default or value is None:
            continue
        if k.kind == "bool":
            on, _, off = (k.flag or f"--{k.name.replace('_', '-')}/--no-{k.name.replace('_', '-')}").partition("/")
            words.append(on if value else off)
        elif k.kind == "size":
            words += [k.option, f"{value[0]}x{value[1]}"]
        elif k.kind == "list":
            words += [k.option, ",".join(value) or "none"]
        else:
            words += [k.option, str(value)]
    return words
