"""Run the ``plantgen`` command in-process, the way a user's shell would see it."""

from __future__ import annotations

import contextlib
import io

from plantgen.cli import main


def run_cli(*args: str, stderr: io.StringIO | None = None) -> tuple[int, str, str]:
    """Return (exit status, stdout, stderr) of ``plantgen ARGS`` (``stderr``: the stream
    it writes to, a fresh one by default)."""
    out, err = io.StringIO(), stderr if stderr is not None else io.StringIO()
    code = 0
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main([str(a) for a in args])
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    return code, out.getvalue(), err.getvalue()


class _Terminal(io.StringIO):
    """A stream that says it is a terminal (what a command's stderr is in a shell)."""

    def isatty(self) -> bool:
        return True


def run_cli_on_terminal(*args: str) -> tuple[int, str, str]:
    """:func:`run_cli` with stderr a terminal: what progress a user watching sees."""
    return run_cli(*args, stderr=_Terminal())
