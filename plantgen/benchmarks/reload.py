"""Live reload of ``plantgen view``: the time from saving a grammar to the new plant's frame.

Run as ``python -m plantgen.benchmarks.reload [MODEL] [--edits 9] [--size 1024x768]``
(default model: pine). The model's grammar is copied to a temporary folder and opened in
a :class:`~plantgen.viewer.session.ViewerSession` on the headless context (the window's
session, without the window: what differs is only the final swap to the screen); then it
is saved ``--edits`` times, each time with another value of its first ``defines`` entry,
and the session's clock is ticked every 10 ms as the window's loop does. Prints each
reload's stages (detect: the poll and the thread; grow: parse, derive, interpret; skin;
draw) and their medians, with the GL renderer.
"""

from __future__ import annotations

import argparse
import re
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

from ..gl.context import gl_context, renderer_name
from ..pipeline import prepare_model, resolve_input
from ..settings import DEFAULT_SIZE
from ..viewer.session import ViewerSession, ViewOptions
from .arguments import image_size

__all__ = ["main", "time_reloads"]

_FIRST_DEFINE = re.compile(r"(defines:\s*\{\s*\w+:\s*)([-\d.]+)")


def time_reloads(grammar: Path, edits: int, size: tuple) -> list[dict]:
    """Open ``grammar`` in a session, save it ``edits`` times and return each reload's
    timings (seconds: total, detect, grow, skin, draw)."""
    text = grammar.read_text()
    m = _FIRST_DEFINE.search(text)
    if m is None:
        raise SystemExit(f"{grammar}: needs a 'defines: {{name: value, ...}}' line to edit")
    base = float(m.group(2))
    options = ViewOptions(input=grammar, size=size)
    session = ViewerSession(gl_context(), options, prepare_model(grammar), say=lambda line: None,
                            warn=lambda line: print(line, file=sys.stderr))
    session.draw(*size)
    results = []
    try:
        for i in range(edits):
            value = base * (1.0 + 0.02 * ((i % 2) * 2 - 1) * (1 + i // 2))
            grammar.write_text(_FIRST_DEFINE.sub(lambda mm, v=value: f"{mm.group(1)}{v:.6g}", text, count=1))
            deadline = time.monotonic() + 60
            report = None
            while report is None and time.monotonic() < deadline:
                if session.tick(0.01):
                    session.draw(*size)
                    report = session.presented()
                time.sleep(0.01)
            if report is None:
                raise SystemExit(f"{grammar}: no reload within 60 s ({session.error})")
            results.append(report)
            time.sleep(0.2)
    finally:
        session.release()
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", nargs="?", default="pine", help="a shipped grammar name or a grammar path")
    parser.add_argument("--edits", type=int, default=9)
    parser.add_argument("--size", type=image_size, default=DEFAULT_SIZE)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        grammar = Path(tmp) / resolve_input(args.model).name
        shutil.copy(resolve_input(args.model), grammar)
        results = time_reloads(grammar, args.edits, args.size)
    keys = list(results[0])
    print(f"reload of {args.model} at {args.size[0]}x{args.size[1]}, {len(results)} saves; GL renderer: "
          f"{renderer_name()}")
    print("  ".join(f"{k:>7}" for k in keys) + "   (seconds)")
    for r in results:
        print("  ".join(f"{r[k]:7.3f}" for k in keys))
    print("  ".join(f"{statistics.median(r[k] for r in results):7.3f}" for k in keys) + "   median")
    return 0


if __name__ == "__main__":
    sys.exit(main())
