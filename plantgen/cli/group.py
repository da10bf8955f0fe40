"""The ``plantgen`` command group and the console entry point :func:`main`.

The commands live in their own modules and know nothing of the group; they are added to
it here, in one place. Errors a user can cause (``PlantgenError``, usage errors) print one
line and exit 2.
"""

from __future__ import annotations

import sys

import click

from ..errors import PlantgenError
from .bench import bench
from .export import export
from .grow import grow
from .render import render

__all__ = ["cli", "main"]


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="plantgen")
def cli() -> None:
    """plantgen: L-system plants skinned with relief-mapped conical frusta.

    Grammars and scenes are YAML files (the shipped ones are in grammars/). Run
    `plantgen COMMAND --help` for each command's options.
    """


for _command in (grow, export, render, bench):
    cli.add_command(_command)


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
