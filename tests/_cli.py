"""Run the ``plantgen`` command in-process, the way a user's shell would see it."""

from __future__ import annotations

import contextlib
import io

from plantgen.cli import main


def run_cli(*args: str) -> tuple[int, str, str]:
    """Return (exit status, stdout, stderr) of ``plantgen ARGS``."""
    out, err = io.StringIO(), io.StringIO()
    code = 0
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main([str(a) for a in args])
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    return code, out.getvalue(), err.getvalue()
