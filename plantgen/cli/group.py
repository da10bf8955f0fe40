"""The ``plantgen`` command group and the console entry point :func:`main`.

The commands live in their own modules and know nothing of the group; they are added to
it here, in one place. No traceback reaches the user: errors a user can cause
(``PlantgenError``, usage errors) print one line and exit 2; an unexpected failure prints
one line and exits 1, with the traceback behind ``--debug``. Numpy's floating-point
warnings and Python warnings never reach the terminal (the stages check finiteness
themselves, and say so in one line).
"""

from __future__ import annotations

import importlib
import sys
import traceback
import warnings

import click
import numpy as np

from .._resources import short_names
from ..errors import PlantgenError
from .options import debug_opt, debug_requested

__all__ = ["COMMANDS", "LazyGroup", "cli", "main"]


#: Each command: the module of this package that holds it and its function's name. A
#: command's module is imported when the command is asked for (:class:`LazyGroup`), so
#: ``plantgen grow`` does not import the renderer, the exporters or the batch engine.
COMMANDS = {"list": ("listing", "list_models"), "grow": ("grow", "grow"), "export": ("export", "export"),
            "render": ("render", "render"), "scan": ("scan", "scan"), "view": ("view", "view"),
            "bench": ("bench", "bench"), "batch": ("batch", "batch"), "convert": ("convert", "convert")}


class LazyGroup(click.Group):
    """A click group whose commands (:data:`COMMANDS`) are imported on first use, each
    given the ``--debug`` option once."""

    def list_commands(self, ctx) -> list[str]:
        return sorted({*COMMANDS, *self.commands})

    def get_command(self, ctx, cmd_name):
        if cmd_name not in self.commands and cmd_name in COMMANDS:
            module, name = COMMANDS[cmd_name]
            command = getattr(importlib.import_module(f"{__package__}.{module}"), name)
            self.add_command(debug_opt(command), cmd_name)
        return self.commands.get(cmd_name)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="plantgen")
@debug_opt
def cli() -> None:
    """plantgen: plants grown from L-system grammars, drawn as tapered tubes with bark relief.

    Grammars and scenes are YAML files; every command also takes a shipped one by
    name, from any folder (`plantgen list` names them all). Run `plantgen COMMAND
    --help` for each command's options. The paper's terms that --verbose reports use
    (RC, RT, GS, frusta, rows) are explained in the glossary (docs: reference/glossary.md).

    \b
    Examples:
      plantgen list
      plantgen render pine                  # writes pine.png
      plantgen export pine                  # writes pine.glb
    """




def main(argv: list[str] | None = None) -> None:
    """Console entry point: user errors become one line on stderr and exit status 2, an
    unexpected failure one line and exit status 1 (the traceback with ``--debug``)."""
    debug_requested(reset=True)
    try:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            if not debug_requested():
                warnings.simplefilter("ignore")
            cli.main(args=argv, prog_name="plantgen", standalone_mode=False)
    except PlantgenError as exc:
        click.echo(f"plantgen: error: {_one_line(exc)}", err=True)
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
    except MemoryError:
        click.echo("plantgen: error: out of memory (lower the input's size or the budgets: --limit)", err=True)
        sys.exit(1)
    except Exception as exc:   # a bug: one line, the traceback only on request
        if debug_requested():
            traceback.print_exc()
        click.echo(f"plantgen: error: unexpected failure: {exc.__class__.__name__}: {_one_line(exc)} "
                   "(run with --debug for the traceback)", err=True)
        sys.exit(1)


def _one_line(exc: BaseException) -> str:
    """An exception's message on one line (a multi-line message keeps its first line)."""
    lines = str(exc).strip().splitlines()
    return short_names(lines[0])[:500] if lines else exc.__class__.__name__
