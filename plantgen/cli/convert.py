"""``plantgen convert``: an L-Py model (``.lpy``) to plantgen's YAML grammar."""

from __future__ import annotations

from pathlib import Path

import click

from ..errors import PlantgenError
from ..files import check_output, write_atomically
from ..lsystem.grammar import parse_grammar
from ..lsystem.lpy import LPY_SUFFIX, read_lpy, to_yaml
from .options import input_arg, limit_opt, limits_from, output_opt, quiet_opt


@click.command()
@input_arg
@output_opt("the grammar, YAML (.yaml). Default: INPUT's name with .yaml, in the current directory.",
            required=False)
@limit_opt
@quiet_opt
def convert(input: Path, output: Path | None, limit_values, quiet) -> None:
    """Convert INPUT, an L-Py model (.lpy), into plantgen's YAML grammar.

    The L-Py file is translated, never run (see the docs' L-Py page): its constants become
    defines, its functions and local variables are substituted into the expressions, each
    way through a rule's Python block becomes one rule with a condition, and its modules
    are renamed to plantgen's one-character symbols (the YAML's first lines list them).
    What plantgen cannot express is refused in one line naming the construct and its line
    (exit status 2), and nothing is written; drawing modules plantgen does not draw are
    left out with a warning. The grammar written grows as the .lpy file does.

    \b
    Examples:
      plantgen convert model.lpy -o model.yaml
      plantgen grow model.lpy -o model.npz      (an .lpy file grows directly, too)
    """
    if input.suffix.lower() != LPY_SUFFIX:
        raise PlantgenError(f"{input}: convert reads an L-Py model ({LPY_SUFFIX}); a YAML grammar needs no converting")
    output = output or Path(input.stem + ".yaml")
    if output.suffix.lower() not in (".yaml", ".yml"):
        raise PlantgenError(f"{output}: the output is a YAML grammar: give it the suffix .yaml")
    check_output(output)          # before any work, as every command
    limits = limits_from(limit_values)
    model = read_lpy(input, limits)
    grammar = parse_grammar(model.data, str(input), limits)   # the YAML must be a grammar plantgen reads
    text = to_yaml(model)
    write_atomically(output, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))
    for line in model.warnings:
        click.echo(line, err=True)
    if not quiet:
        click.echo(f"{output}: {len(grammar.rules)} rules, {len(grammar.decomposition)} decomposition and "
                   f"{len(grammar.interpretation)} interpretation rules, "
                   f"{grammar.iterations} steps" + (f"; modules renamed: {_renamed(model.names)}"
                                                    if model.names else ""))


def _renamed(names: dict) -> str:
    shown = ", ".join(f"{k} -> {v}" for k, v in list(names.items())[:8])
    return shown + (f" and {len(names) - 8} more" if len(names) > 8 else "")
