"""Options the commands share, declared once (as rasterio's ``rio`` declares its options):
an option that several commands take has one name, type and help text everywhere.

Each name here is a click decorator (``@seed_opt``) or, where a command must say what
its file or size is, a function that makes one (``@output_opt("...")``).
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import fields, is_dataclass
from pathlib import Path

import click

from ..errors import PlantgenError
from ..fields import show
from ..geometry.rays.camera import Orbit
from ..knobs import Knob
from ..limits import MAX_IMAGE_SIDE, Limits
from ..limits import limits as default_limits
from ..settings import build_settings, option_names
from .sections import LIMITS, MODEL, OTHER, OUTPUT, SectionedOption, section_of

__all__ = ["GLOSSARY", "MAX_SIDE", "allow_path_opt", "debug_opt", "debug_requested", "define_values", "finite",
           "input_arg", "iterations_opt", "jobs_opt", "knob_option", "knob_options", "limit_opt", "limits_from",
           "orbit_from", "output_opt", "parse_size", "quiet_opt", "seed_opt", "size_opt", "smooth_bends_opt",
           "take_settings", "verbose_opt"]

#: The largest image side ``WIDTHxHEIGHT`` accepts, in pixels.
MAX_SIDE = MAX_IMAGE_SIDE

_SIZE = re.compile(r"\s*(\d{1,18})\s*[xX]\s*(\d{1,18})\s*")   # bounded digits: int() never sees 5,000


def parse_size(ctx, param, value):
    """click callback for a ``WIDTHxHEIGHT`` option: (width, height) ints, or None when
    the option is not given."""
    if value is None:
        return None
    m = _SIZE.fullmatch(value)
    if not m or not (0 < int(m.group(1)) <= MAX_SIDE and 0 < int(m.group(2)) <= MAX_SIDE):
        raise click.BadParameter(f"{show(value)} is not WIDTHxHEIGHT with sides 1..{MAX_SIDE}, e.g. 1024x768")
    return int(m.group(1)), int(m.group(2))


def define_values(items) -> dict[str, float]:
    """``--define NAME=VALUE`` options as {name: finite float}."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not sep or not name.strip() or not math.isfinite(number):
            raise click.BadParameter(f"{item!r} is not NAME=VALUE with a finite number", param_hint="--define")
        out[name.strip()] = number
    return out


def finite(ctx, param, value):
    """click callback for a float option: refuse ``nan`` and ``inf`` (click's float reads them)."""
    if value is not None and not math.isfinite(value):
        raise click.BadParameter(f"{value!r} is not a finite number")
    return value


#: INPUT: a grammar or scene .yaml, a shipped model's name, or a skeleton .npz.
input_arg = click.argument("input", type=click.Path(dir_okay=False, path_type=Path))

seed_opt = click.option("--seed", type=click.IntRange(min=0), cls=SectionedOption, section=MODEL,
                        help="Override the seed of the grammar or scene file.")

iterations_opt = click.option("--iterations", type=click.IntRange(min=0), cls=SectionedOption, section=MODEL,
                              help="Override the grammar's iteration count.")

quiet_opt = click.option("-q", "--quiet", is_flag=True, help="Print nothing but errors.", cls=SectionedOption,
                         section=OTHER)

smooth_bends_opt = click.option(
    "--smooth-bends", "smooth_bends", type=click.FloatRange(0, 180, max_open=True), default=None,
    cls=SectionedOption, section=MODEL,
    callback=finite, metavar="ANGLE",
    help="Round every joint where a branch bends by more than ANGLE degrees into an arc of short "
         "pieces (at most 10° each), so bent branches read as smooth tubes rather than polylines; "
         "radii and texture stay continuous. Default: the grammar's `turtle: smooth_bends` setting "
         "(the saguaro's: 20), else off (straight pieces meet at the joints).")

#: Where the glossary of the paper's terms is, as ``--help`` and the reports point to it.
GLOSSARY = "docs: reference/glossary.md"

verbose_opt = click.option(
    "-v", "--verbose", is_flag=True, cls=SectionedOption, section=OTHER,
    help=f"Print the detail in the renderer's own terms (RC+R, frusta, rows; {GLOSSARY}).")


def output_opt(what: str, *, required: bool = True):
    """``-o/--output FILE``; ``what`` says what is written and how the suffix is read."""
    return click.option("-o", "--output", type=click.Path(path_type=Path),   # checked by plantgen.files.check_output
                        required=required, help=f"File to write: {what}", cls=SectionedOption, section=OUTPUT)


def size_opt(*param_decls: str, what: str = "Image size", default: str):
    """A ``WIDTHxHEIGHT`` option (``--size`` unless named otherwise), parsed to
    (width, height) by :func:`parse_size`."""
    return click.option(*(param_decls or ("--size",)), callback=parse_size, metavar="WxH",
                        help=f"{what} (WIDTHxHEIGHT pixels; default: {default}).")


# ---------------------------------------------------------------------------- settings
def _click_type(k: Knob):
    """The click type of a knob: its range or choices, as the settings declare them."""
    if k.kind == "int":
        return click.IntRange(None if k.lo is None else int(k.lo), None if k.hi is None else int(k.hi))
    if k.kind == "float":
        if k.lo is None and k.hi is None:
            return float
        return click.FloatRange(k.lo, k.hi, min_open=k.lo_open, max_open=k.hi_open)
    if k.kind == "choice":
        return click.Choice(list(k.choices))
    return str


def knob_option(k: Knob, default, *, help: str | None = None, section: str | None = None):
    """The click option of one knob: name, type, range, default and help from the settings;
    ``section``: its heading in a sectioned ``--help`` (:mod:`plantgen.cli.sections`)."""
    if k.kind == "bool":
        flag = k.flag or f"--{k.name.replace('_', '-')}/--no-{k.name.replace('_', '-')}"
        return click.option(flag, k.name, default=default, show_default=default is not None, help=help or k.help,
                            cls=SectionedOption, section=section)
    extra = {}
    if k.kind == "size":
        extra["callback"] = parse_size
    elif k.kind == "float":
        extra["callback"] = finite
    shown = default is not None and k.kind != "size"
    return click.option(k.option, k.name, type=_click_type(k), default=default, show_default=shown,
                        metavar=k.metavar, help=help or k.help, cls=SectionedOption, section=section, **extra)


def owned_knobs(cls):
    """(settings class, knob, default) of every knob of ``cls``, nested settings included, in
    declaration order: the class says the knob's ``--help`` section."""
    for f in fields(cls):
        k = f.metadata.get("knob")
        if k is not None:
            yield cls, k, f.default
        elif is_dataclass(f.default):
            yield from owned_knobs(type(f.default))


def knob_options(*classes, skip=(), helps=None):
    """Every knob of the settings ``classes`` (nested settings included) as click
    options, in declaration order; ``skip`` names knobs a command does not take, ``helps``
    replaces a knob's help text by name (a command that says it otherwise). Each option's
    ``--help`` section is its settings class's (:func:`plantgen.cli.sections.section_of`)."""
    helps = helps or {}
    decorators = []
    for cls in classes:
        for owner, k, default in owned_knobs(cls):
            if k.name not in skip:
                decorators.append(knob_option(k, default, help=helps.get(k.name), section=section_of(owner)))

    def apply(command):
        for decorator in reversed(decorators):
            command = decorator(command)
        return command
    return apply


def take_settings(cls, params: dict):
    """Build ``cls`` from the command's parameters, removing the ones it used (one line for
    a value the settings refuse)."""
    names = set(option_names(cls))
    mine = {k: params.pop(k) for k in list(params) if k in names}
    try:
        return build_settings(cls, mine)
    except PlantgenError as exc:
        raise click.UsageError(str(exc)) from None


def orbit_from(azimuth, elevation, distance, zoom, fov) -> Orbit:
    """The :class:`~plantgen.geometry.rays.camera.Orbit` the camera options give (one line for a
    value out of range)."""
    try:
        return Orbit(azimuth=azimuth, elevation=elevation, distance=distance, zoom=zoom, fov_y=fov)
    except PlantgenError as exc:
        raise click.BadParameter(str(exc)) from None


# ---------------------------------------------------------------------------- budgets, paths
def _parse_limits(ctx, param, values) -> dict:
    """click callback for ``--limit NAME=N`` (repeatable): {name: int}."""
    out = {}
    for value in values:
        name, _, number = value.partition("=")
        name = name.strip().removeprefix("max_").replace("-", "_")
        if name not in Limits.names():
            raise click.BadParameter(f"{value!r}: unknown limit {name!r} (known: {', '.join(Limits.names())})")
        try:
            n = float(number.replace("_", "").replace(",", ""))
            if not n.is_integer() or n < 1:
                raise ValueError
        except ValueError:
            raise click.BadParameter(f"{value!r} is not NAME=N with N a positive integer, e.g. "
                                     "derive_work=200000000") from None
        out[name] = int(n)
    return out


def _limit_defaults() -> str:
    return ", ".join(f"{f.name[4:]} {getattr(default_limits, f.name):,}" for f in fields(Limits))


#: ``--limit NAME=N``: set a budget of plantgen.limits.Limits for this run.
limit_opt = click.option(
    "--limit", "limit_values", metavar="NAME=N", multiple=True, callback=_parse_limits, cls=SectionedOption,
    section=LIMITS,
    help="Set a budget for this run, higher or lower (repeatable); a file may lower a budget, "
         f"never raise it. Names and defaults: {_limit_defaults()} (docs: how-to/untrusted-input.md).")


def limits_from(values: dict) -> Limits:
    """The limits a command runs under: the defaults with ``--limit`` values in place."""
    return default_limits.raised(**values)


#: ``--jobs N``: the processes a scene's distinct plants may grow in.
jobs_opt = click.option(
    "--jobs", type=click.IntRange(min=1), default=None, cls=SectionedOption, section=MODEL,
    help="Processes a scene's distinct plants grow in (default: the cores this process may use; 1: one by "
         "one). A scene whose plants are forecast to take under about a tenth of a second grows them one by "
         "one anyway; the plants are the same either way.")


#: ``--allow-path DIR``: a folder a scene or a batch spec may read grammars from besides its own.
allow_path_opt = click.option(
    "--allow-path", "allow_paths", metavar="DIR", multiple=True,
    type=click.Path(exists=True, file_okay=False, path_type=Path), cls=SectionedOption, section=LIMITS,
    help="A folder a scene (or a batch spec) may read grammars from besides its own folder and "
         "the shipped grammars (repeatable). Without it, a grammar path that leaves its folder "
         "(../x.yaml, /abs/path, a link pointing out) is refused before it is opened.")

_DEBUG = {"on": False}


def _set_debug(ctx, param, value):
    if value:
        _DEBUG["on"] = True


#: ``--debug``: an unexpected failure prints its Python traceback.
debug_opt = click.option("--debug", is_flag=True, expose_value=False, is_eager=True, callback=_set_debug,
                         cls=SectionedOption, section=OTHER,
                         help="On an unexpected failure (a bug, exit status 1), print the Python "
                              "traceback too; also PLANTGEN_DEBUG=1. Bad input stays one line.")


def debug_requested(reset: bool = False) -> bool:
    """Whether ``--debug`` (or ``PLANTGEN_DEBUG=1``) asks for tracebacks; ``reset`` starts
    a new run with the environment's answer."""
    if reset:
        _DEBUG["on"] = os.environ.get("PLANTGEN_DEBUG", "") not in ("", "0")
    return _DEBUG["on"]
