"""Progress on stderr for long work, on a terminal only.

The library reports progress as ``progress(stage, done, total)`` calls (``total`` None
where the count is not known in advance, ``done`` 0 as a stage begins);
:class:`StageBars` draws them with rich: one live line per command that names the stage,
a bar and its count where there is one, and the time elapsed, which keeps running
during a long step that reports nothing (skinning 300,000 segments, the first draw).
The line is transient: it is erased when the work ends, so a quick run leaves nothing
behind and the command's report stands alone. Where stderr is not a terminal (a log, a
pipe, a CI job) or with ``--quiet``, nothing at all is drawn.
"""

from __future__ import annotations

import sys

__all__ = ["LABELS", "StageBars"]

#: What each stage says.
LABELS = {"derive": "deriving", "interpret": "drawing the turtle", "grow": "growing the scene's plants",
          "skin": "skinning", "place": "placing the scene", "render": "rendering", "frames": "rendering frames",
          "tessellate": "tessellating plants", "write": "writing", "scan": "scanning", "plants": "plants",
          "bench": "bench"}


class StageBars:
    """A ``progress(stage, done, total)`` callable drawing one transient line on stderr
    while a terminal shows it (``enabled=False``, ``--quiet``: nothing). Use it as a
    context manager, so the line is erased when the work ends or fails. rich is imported
    only where a terminal shows the line (logs and pipes do without its import time)."""

    def __init__(self, *, enabled: bool = True) -> None:
        isatty = getattr(sys.stderr, "isatty", None)
        self.enabled = bool(enabled and isatty is not None and isatty())
        self.stage: str | None = None
        self.task = None
        self.bars = None

    def __call__(self, stage: str, done: int, total: int | None = None, detail: str | None = None) -> None:
        """Stage ``stage`` has done ``done`` of ``total`` steps (None: not known);
        ``detail`` (optional) says what it is on now."""
        if self.bars is None:
            return
        total = None if total is None else max(int(total), 1)
        if stage != self.stage:
            if self.task is not None:
                self.bars.remove_task(self.task)
            self.stage = stage
            self.task = self.bars.add_task(LABELS.get(stage, stage), total=total, count="")
        count = f"{int(done):,}/{total:,}" if total is not None else (f"{int(done):,}" if done else "")
        label = LABELS.get(stage, stage) + (f": {detail}" if detail else "")
        self.bars.update(self.task, completed=int(done), total=total, count=count, description=label)

    def __enter__(self) -> StageBars:
        if self.enabled:
            from rich.console import Console
            from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

            console = Console(stderr=True)
            if not console.is_terminal:       # rich knows better (e.g. TTY_COMPATIBLE=0)
                self.enabled = False
                return self
            self.bars = Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.fields[count]}"),
                                 TimeElapsedColumn(), console=console, transient=True,
                                 redirect_stdout=False)   # stdout stays the report's; stderr lines print above
            self.bars.start()
        return self

    def __exit__(self, *exc) -> None:
        if self.bars is not None:
            self.bars.stop()
        self.bars, self.task, self.stage = None, None, None
