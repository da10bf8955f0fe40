"""L-Py files (``.lpy``) read into plantgen's grammar mapping, never run.

An L-Py file is Python with L-system sections (``Axiom:``, ``derivation length:``,
``production:``, ``interpretation:``/``homomorphism:``, ``endlsystem`` ...). This package
splits the sections line by line, parses each piece of Python with :mod:`ast` and
*translates* it: module-level constants become the grammar's ``defines``, functions are
inlined into the expressions that call them, and a rule's Python block is walked
symbolically, each path that ends in ``produce`` becoming one plantgen rule whose
condition is the path's tests (``if``/``elif``/``else``; ``for ... in range(...)`` with a
constant count is unrolled; local assignments are substituted). Every expression ends up
as text in plantgen's whitelist expression language (:mod:`plantgen.lsystem.expr`), which
is what evaluates it: nothing here calls ``exec`` or ``eval``. The result is the same
mapping a YAML grammar file gives (:func:`plantgen.lsystem.grammar.parse_grammar` takes
it; ``plantgen convert`` writes it).

``Start``/``StartEach``/``EndEach``/``End`` and ``global`` assignments in rules become
the grammar's ``globals``, ``hooks`` and a rule's ``set`` (a global nothing drawn reads is
dropped with what sets it); a module-level function whose body produces is run in place
where a rule calls it as a statement.

What cannot be translated is refused in one line naming the construct and its line
(:class:`LpyError`): imports other than ``random`` and ``math`` (``time`` is ignored,
``numpy`` only gives a tropism vector), PlantGL, hooks that produce or read the L-string,
file access, a random draw that would be tested twice. Drawing modules plantgen
has no meaning for are dropped with one warning each; the ``INITIALISATION`` section is
read only for its scalar parameters (defines), the rest ignored with a warning.

Budgets: the file's size (``max_input_bytes``), the work of the translation (AST nodes
visited, inlined calls and unrolled loop bodies included, against ``max_yaml_nodes``),
the nesting of inlined calls (:data:`MAX_CALL_DEPTH`), :data:`MAX_LOOP_ITERATIONS` unrolled
loop iterations and :data:`~plantgen.lsystem.expr.MAX_EXPR_LENGTH` characters per
translated expression; then the grammar's own budgets when it is derived.

The package, by responsibility: :mod:`.sections` (the file split into its sections),
:mod:`.translate` (statements and expressions translated), :mod:`.inline` (functions
inlined, a rule's block walked, loops unrolled), :mod:`.rules` (globals, hooks, rules and
the grammar mapping), :mod:`.drawn` (the drawn-as table: L-Py's modules as plantgen's),
:mod:`.common` (the error, the budgets, the values and helpers they share) and
:mod:`.reader` (:class:`~.reader.Reader`, one file's translation: the state the parts
share, its methods theirs). This module holds the entry points.
"""

from __future__ import annotations

from pathlib import Path

import yaml

from ...errors import PlantgenError
from ...files import read_text, read_yaml
from ...limits import Limits
from ...limits import limits as default_limits
from .common import MAX_CALL_DEPTH, MAX_DYNAMIC_COUNT, MAX_LOOP_ITERATIONS, MAX_SUCCESSOR, MAX_TABLE, LpyError, LpyModel
from .drawn import DEFAULT_ARGS, DRAWN_AS, REFUSED_MODULES, SILENT, SPHERE_SEGMENTS, TROPISM, TURTLE, UNDRAWN
from .reader import Reader

__all__ = ["LPY_SUFFIX", "MAX_CALL_DEPTH", "MAX_LOOP_ITERATIONS", "TURTLE", "LpyError", "LpyModel", "parse_lpy",
           "read_grammar_data", "read_lpy", "to_yaml",
           # the other public names lpy.py had, importable from here as before the split
           "DEFAULT_ARGS", "DRAWN_AS", "MAX_DYNAMIC_COUNT", "MAX_SUCCESSOR", "MAX_TABLE", "REFUSED_MODULES", "SILENT",
           "SPHERE_SEGMENTS", "TROPISM", "UNDRAWN"]

LPY_SUFFIX = ".lpy"


# ------------------------------------------------------------------ entry points
def parse_lpy(text: str, path: str = "<lpy>", limits: Limits | None = None) -> LpyModel:
    """Translate the text of an ``.lpy`` file (see the package's notes)."""
    limits = limits or default_limits
    reader = Reader(text, path, limits)
    try:
        reader.read()
        return reader.build(Path(path).stem)
    except RecursionError:
        raise LpyError(f"{path}: nested too deeply to translate") from None


def read_lpy(path: str | Path, limits: Limits | None = None) -> LpyModel:
    """Read and translate an ``.lpy`` file (at most ``max_input_bytes``)."""
    limits = limits or default_limits
    return parse_lpy(read_text(path, LpyError, limits, "L-Py"), str(path), limits)


def to_yaml(model: LpyModel) -> str:
    """The grammar mapping as a YAML grammar file, its first lines saying where it came
    from and which modules were renamed."""
    head = [f"# Converted from the L-Py model {Path(model.data.get('name', 'model')).name}.lpy by plantgen convert."]
    if model.names:
        head.append("# Modules renamed to plantgen's one-character symbols:")
        head += [f"#   {k} -> {v}" for k, v in model.names.items()]
    body = yaml.safe_dump(model.data, sort_keys=False, allow_unicode=True, width=10_000, default_flow_style=False)
    return "\n".join(head) + "\n" + body


def read_grammar_data(path: str | Path, error: type[PlantgenError] = PlantgenError,
                      limits: Limits | None = None) -> tuple[object, tuple[str, ...]]:
    """A grammar file's mapping and the warnings its reading gave: an ``.lpy`` file
    translated, any other read as YAML (the one place a grammar path is dispatched)."""
    if Path(path).suffix.lower() == LPY_SUFFIX:
        model = read_lpy(path, limits)
        return model.data, model.warnings
    return read_yaml(path, error, limits), ()
