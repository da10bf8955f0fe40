"""Live reload: watch the input files by polling their stamps, and grow a new model in a
background thread while the window keeps drawing the last good one.

Polling ``os.stat`` a few times a second costs microseconds a file and works the same on
every platform and file system, for editors that write in place and for those that
write a new file and rename it over the old one (the stamp holds the inode), so no
file-notification dependency is needed.
"""

from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path

__all__ = ["FileWatcher", "Change", "BackgroundJob"]


def _stamp(path: Path):
    """(mtime ns, size, inode) of ``path``, or None while it does not exist."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_mtime_ns, st.st_size, st.st_ino


@dataclass(frozen=True)
class Change:
    """Files whose stamp changed and then held still for one poll; ``saved_ns`` is the
    latest modification time among them (``time.time_ns`` clock)."""

    paths: tuple
    saved_ns: int


class FileWatcher:
    """Polls the stamps of a set of files; :meth:`poll` reports a change once the changed
    files have held still for ``settle_s`` (an editor's save is complete). A file that
    disappears is waited for: the change is reported when it is back."""

    def __init__(self, paths=(), settle_s: float = 0.05):
        self.settle_s = float(settle_s)
        self._stamps: dict[Path, tuple | None] = {}
        self._moving: dict[Path, tuple] = {}       # path -> (new stamp, first seen at)
        self.watch(paths)

    @property
    def paths(self) -> tuple:
        return tuple(self._stamps)

    def watch(self, paths) -> None:
        """Watch ``paths`` from now on (with their current stamps), and only them."""
        paths = [Path(p).resolve() for p in paths]
        self._stamps = {p: self._stamps.get(p) or _stamp(p) for p in paths}
        self._moving = {p: v for p, v in self._moving.items() if p in self._stamps}

    def poll(self, now: float | None = None) -> Change | None:
        """Compare every stamp with the last one seen; None when nothing has changed and
        settled since the last report."""
        now = time.monotonic() if now is None else now
        for path, old in self._stamps.items():
            new = _stamp(path)
            if new is None or new == old:
                self._moving.pop(path, None)
                continue
            seen = self._moving.get(path)
            if seen is None or seen[0] != new:
                self._moving[path] = (new, now)
        settled = [p for p, (stamp, since) in self._moving.items() if now - since >= self.settle_s
                   and _stamp(p) == stamp]
        if not settled or len(settled) < len(self._moving):
            return None
        for p in settled:
            self._stamps[p] = self._moving.pop(p)[0]
        return Change(tuple(settled), max(self._stamps[p][0] for p in settled))


class BackgroundJob:
    """One job at a time on a daemon thread (a long derivation never holds up the window
    or the exit). :meth:`start` while a job runs queues one more run with the newest
    arguments; :meth:`result` hands back (arguments, value, exception) once, when done."""

    def __init__(self, work):
        self._work = work
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._queued = None
        self._done = None

    @property
    def busy(self) -> bool:
        with self._lock:
            return self._thread is not None or self._queued is not None

    def start(self, *args) -> None:
        with self._lock:
            if self._thread is not None:
                self._queued = args
                return
            self._launch(args)

    def _launch(self, args) -> None:
        self._thread = threading.Thread(target=self._run, args=(args,), daemon=True, name="plantgen-reload")
        self._thread.start()

    def _run(self, args) -> None:
        try:
            outcome = (args, self._work(*args), None)
        except Exception as exc:   # handed to the caller, who shows it in one line
            outcome = (args, None, exc)
        with self._lock:
            self._done = outcome
            self._thread = None
            if self._queued is not None:
                queued, self._queued = self._queued, None
                self._done = None          # superseded by a newer save
                self._launch(queued)

    def result(self):
        with self._lock:
            done, self._done = self._done, None
        return done
