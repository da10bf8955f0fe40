"""Progress bars on stderr for long work: ``progress(stage, done, total)`` callbacks
become click progress bars, one per stage, once the command has run for ``after``
seconds (quick runs print nothing extra)."""

from __future__ import annotations

import time

import click

__all__ = ["PROGRESS_AFTER_S", "StageBars"]

#: Seconds a command runs before its progress bars appear.
PROGRESS_AFTER_S = 1.0

#: What each stage's bar says.
LABELS = {"tessellate": "tessellating plants", "write": "writing", "scan": "scanning beams"}


class StageBars:
    """A ``progress(stage, done, total)`` callable drawing a bar per stage on stderr.

    Bars start only after ``after`` seconds (default :data:`PROGRESS_AFTER_S`) of the
    command (a bar that has started keeps going); ``enabled=False`` (``--quiet``) draws
    nothing. Use as a context manager, or call :meth:`close`, so the last bar ends its line."""

    def __init__(self, *, after: float | None = None, enabled: bool = True) -> None:
        self.after = PROGRESS_AFTER_S if after is None else float(after)
        self.enabled = enabled
        self.start = time.perf_counter()
        self.stage: str | None = None
        self.bar = None
        self.shown = 0

    def __call__(self, stage: str, done: int, total: int) -> None:
        if not self.enabled:
            return
        if stage != self.stage:
            if time.perf_counter() - self.start < self.after:
                return
            self.close()
            self.stage, self.shown = stage, 0
            self.bar = click.progressbar(length=max(int(total), 1), label=LABELS.get(stage, stage), show_pos=True,
                                         file=click.get_text_stream("stderr"))
            self.bar.__enter__()
        self.bar.update(int(done) - self.shown)
        self.shown = int(done)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.__exit__(None, None, None)
        self.bar, self.stage = None, None

    def __enter__(self) -> StageBars:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
