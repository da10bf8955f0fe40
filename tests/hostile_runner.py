"""Run ``plantgen`` on hostile inputs in one process under a memory limit; report as JSON.

Used by ``test_hostile.py`` as a subprocess::

    python tests/hostile_runner.py CASES.json

``CASES.json`` holds a list of ``{"argv": [...]}``. The process first limits its address
space (``RLIMIT_AS``, default 1 GiB, ``--memory`` bytes), then runs each case in-process
through ``plantgen.cli.main`` with its stdout and stderr captured, timing it (wall and
this process's CPU seconds: on a shared machine the CPU time is what the case cost), and records
every file the case opens (an audit hook on ``open``). It prints one JSON list: per case
the exit status, stdout, stderr, seconds and the files opened outside Python's own
installation, leaving out plantgen's own modules (a command's module is imported when the
command runs).
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import json
import os
import resource
import sys
import time


def _limit_memory(limit: int) -> None:
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))


def main(argv: list[str]) -> int:
    memory = 1 << 30
    if argv[:1] == ["--memory"]:
        memory, argv = int(argv[1]), argv[2:]
    with open(argv[0]) as fh:
        cases = json.load(fh)
    _limit_memory(memory)

    opened: list[str] = []
    recording = [False]
    library = tuple({sys.prefix, sys.base_prefix, sys.exec_prefix, os.path.dirname(os.__file__)})
    package = os.path.dirname(importlib.util.find_spec("plantgen").origin) + os.sep

    def hook(event, args):
        if recording[0] and event == "open" and isinstance(args[0], (str, bytes, os.PathLike)):
            path = os.path.abspath(os.fsdecode(args[0]))
            module = path.startswith(package) and path.endswith((".py", ".pyc"))
            if not path.startswith(library) and not module:
                opened.append(path)

    sys.addaudithook(hook)
    from plantgen.cli import main as plantgen_main  # after the limit: imports count too

    report = []
    for case in cases:
        out, err = io.StringIO(), io.StringIO()
        opened.clear()
        code = 0
        start, cpu_start = time.perf_counter(), time.process_time()
        recording[0] = True
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                plantgen_main([str(a) for a in case["argv"]])
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
            except BaseException as exc:   # anything else is what the test is after
                code = f"escaped: {exc.__class__.__name__}: {exc}"
        recording[0] = False
        report.append({"argv": case["argv"], "code": code, "stdout": out.getvalue(), "stderr": err.getvalue(),
                       "seconds": time.perf_counter() - start,
                       "cpu_seconds": time.process_time() - cpu_start, "opened": sorted(set(opened))})
    sys.stdout.write(json.dumps(report))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
