"""The ``plantgen`` command line: a thin click layer over the library.

Each command lives in its own module of this package, converts its options and calls one
library function. Errors a user can cause (``PlantgenError``) print one line and exit 2.
"""

from __future__ import annotations

import re
import sys

import click

from ..errors import PlantgenError


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="plantgen")
def cli() -> None:
    """plantgen: L-system plants skinned with relief-mapped conical frusta.

    Grammars and scenes are YAML files (the shipped ones are in grammars/). Run `plantgen COMMAND --help` for each command's options.
    """


def parse_size(ctx, param, value):
    """click callback for a ``WIDTHxHEIGHT`` option (shared by the commands that render):
    (width, height) ints, None when the option is not given."""
    if value is None:
        return None
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", value)
    if not m or not (0 < int(m.group(1)) <= 16384 and 0 < int(m.group(2)) <= 16384):
        raise click.BadParameter(f"{value!r} is not WIDTHxHEIGHT with sides 1..16384, e.g. 1024x768")
    return int(m.group(1)), int(m.group(2))


def main(argv: list[str] | None = None) -> None:
    """Console entry point: user errors become one line on stderr and exit status 2."""
    try:
        cli.main(args=argv, prog_name="plantgen", standalone_mode=False)
    except PlantgenError as exc:
        click.echo(f"plantgen: error: {exc}", err=True)
        sys.exit(2)
    except click.exceptions.Abort:
        click.echo("plantgen: aborted", err=True)
        sys.exit(130)
    except click.ClickException as exc:
        # Usage errors too are one line; the command's --help has the details.
        hint = ""
        if isinstance(exc, click.UsageError) and exc.ctx is not None:
            hint = f" (see '{exc.ctx.command_path} --help')"
        click.echo(f"plantgen: error: {exc.format_message()}{hint}", err=True)
        sys.exit(exc.exit_code if exc.exit_code else 2)
    except click.exceptions.Exit as exc:
        sys.exit(exc.exit_code)


# Commands register themselves on `cli` when their module is imported.
from . import grow as _grow  # noqa: E402,F401
from . import export as _export  # noqa: E402,F401
from . import render as _render  # noqa: E402,F401
from . import bench as _bench  # noqa: E402,F401
