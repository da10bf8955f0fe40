"""Options the commands share, declared once (as rasterio's ``rio`` declares its options):
an option that several commands take has one name, type and help text everywhere.

Each name here is a click decorator (``@seed_opt``) or, where a command must say what
its file or size is, a function that makes one (``@output_opt("...")``).
"""

from __future__ import annotations

import re
from pathlib import Path

import click

__all__ = ["MAX_SIDE", "input_arg", "iterations_opt", "output_opt", "parse_size", "quiet_opt",
           "seed_opt", "size_opt"]

#: The largest image side ``WIDTHxHEIGHT`` accepts, in pixels.
MAX_SIDE = 16384

_SIZE = re.compile(r"\s*(\d+)\s*[xX]\s*(\d+)\s*")


def parse_size(ctx, param, value):
    """click callback for a ``WIDTHxHEIGHT`` option: (width, height) ints, or None when
    the option is not given."""
    if value is None:
        return None
    m = _SIZE.fullmatch(value)
    if not m or not (0 < int(m.group(1)) <= MAX_SIDE and 0 < int(m.group(2)) <= MAX_SIDE):
        raise click.BadParameter(f"{value!r} is not WIDTHxHEIGHT with sides 1..{MAX_SIDE}, e.g. 1024x768")
    return int(m.group(1)), int(m.group(2))


#: INPUT: a grammar or scene .yaml, a shipped model's name, or a skeleton .npz.
input_arg = click.argument("input", type=click.Path(dir_okay=False, path_type=Path))

seed_opt = click.option("--seed", type=click.IntRange(min=0),
                        help="Override the seed of the grammar or scene file.")

iterations_opt = click.option("--iterations", type=click.IntRange(min=0),
                              help="Override the grammar's iteration count.")

quiet_opt = click.option("-q", "--quiet", is_flag=True, help="Print nothing but errors.")


def output_opt(what: str, *, required: bool = True):
    """``-o/--output FILE``; ``what`` says what is written and how the suffix is read."""
    return click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
                        required=required, help=f"File to write: {what}")


def size_opt(*param_decls: str, what: str = "Image size", default: str):
    """A ``WIDTHxHEIGHT`` option (``--size`` unless named otherwise), parsed to
    (width, height) by :func:`parse_size`."""
    return click.option(*(param_decls or ("--size",)), callback=parse_size, metavar="WxH",
                        help=f"{what} (WIDTHxHEIGHT pixels; default: {default}).")
