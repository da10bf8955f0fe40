"""Running ``plantgen view`` in a real window for the tests: a virtual X server (Xvfb), the
viewer as a subprocess, and xdotool sending it keys and mouse events through the X
server, as a user's would arrive.

Without Xvfb, xdotool or the ``[view]`` extra the viewer's window tests skip with the
reason; CI sets PLANTGEN_REQUIRE_VIEWER=1 (``.ci/run`` installs Xvfb and xdotool), which
turns that into a failure.
"""

from __future__ import annotations

import importlib.util
import os
import queue
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

#: Seconds the tests wait for the viewer to print a line (llvmpipe on 2 shared cores).
WAIT_S = 60.0


def viewer_unavailable() -> str | None:
    """Why the viewer's window tests cannot run here, or None."""
    missing = [name for name, ok in (("Xvfb", shutil.which("Xvfb")), ("xdotool", shutil.which("xdotool")),
                                     ("moderngl-window", importlib.util.find_spec("moderngl_window")),
                                     ("pyglet", importlib.util.find_spec("pyglet"))) if not ok]
    if missing:
        return (f"the viewer's window tests need {', '.join(missing)} (apt-get install xvfb xdotool; "
                "pip install '.[view]')")
    return None


def skip_or_fail(reason: str):
    if os.environ.get("PLANTGEN_REQUIRE_VIEWER") == "1":
        pytest.fail(reason)
    pytest.skip(reason)


class VirtualDisplay:
    """An Xvfb server on a free display number (Xvfb picks it: -displayfd)."""

    def __init__(self, screen: str = "1280x1024x24"):
        read, write = os.pipe()
        self.proc = subprocess.Popen(["Xvfb", "-displayfd", str(write), "-screen", "0", screen, "-nolisten", "tcp"],
                                     pass_fds=(write,), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        os.close(write)
        number = b""
        with os.fdopen(read, "rb") as fh:
            while not number.endswith(b"\n"):
                chunk = fh.read(1)
                if not chunk:
                    break
                number += chunk
        if not number.strip().isdigit():
            self.stop()
            raise RuntimeError(f"Xvfb did not start: {self.proc.stderr.read().decode(errors='replace')[-500:]}")
        self.name = f":{number.decode().strip()}"

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


class Viewer:
    """``plantgen view ARGS`` running on ``display``; its stdout and stderr lines are
    collected by threads, and :meth:`wait_for` waits for one."""

    def __init__(self, display: str, args, cwd: Path, title: str):
        env = {**os.environ, "DISPLAY": display, "PYTHONUNBUFFERED": "1"}
        self.display, self.title = display, title
        # Ctrl-C as a terminal sends it: a suite started in the background by a shell without job
        # control ignores SIGINT, which the viewer would inherit (and Python then keeps ignoring)
        self.proc = subprocess.Popen([sys.executable, "-m", "plantgen", "view", *map(str, args)], cwd=cwd, env=env,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        self.lines: queue.Queue = queue.Queue()
        self.out, self.err = [], []
        for stream, keep, tag in ((self.proc.stdout, self.out, "out"), (self.proc.stderr, self.err, "err")):
            threading.Thread(target=self._read, args=(stream, keep, tag), daemon=True).start()
        self.window = None

    def _read(self, stream, keep, tag) -> None:
        for line in stream:
            keep.append(line.rstrip("\n"))
            self.lines.put((tag, line.rstrip("\n")))
        self.lines.put((tag, None))

    def wait_for(self, pattern: str, stream: str = "out", timeout: float = WAIT_S) -> re.Match:
        """The first new line of ``stream`` matching ``pattern`` (re.search)."""
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise AssertionError(f"no line matching {pattern!r} within {timeout} s\nstdout: {self.out}\n"
                                     f"stderr: {self.err}")
            try:
                tag, line = self.lines.get(timeout=left)
            except queue.Empty:
                continue
            if line is None and tag == stream:
                raise AssertionError(f"the viewer ended before {pattern!r}\nstdout: {self.out}\nstderr: {self.err}")
            if tag == stream and line is not None:
                m = re.search(pattern, line)
                if m:
                    return m

    def xdotool(self, *args) -> None:
        subprocess.run(["xdotool", *map(str, args)], env={**os.environ, "DISPLAY": self.display}, check=True,
                       timeout=30, capture_output=True)

    def find_window(self) -> str:
        out = subprocess.run(["xdotool", "search", "--sync", "--name", f"^{re.escape(self.title)}$"],
                             env={**os.environ, "DISPLAY": self.display}, capture_output=True, text=True,
                             timeout=30, check=True)
        self.window = out.stdout.split()[0]
        self.xdotool("mousemove", "--window", self.window, 10, 10)
        self.xdotool("windowfocus", "--sync", self.window)
        return self.window

    def keys(self, *names: str) -> None:
        """Press and release each key (xdotool names: p, shift+p, 2, bracketright, space)."""
        for name in names:
            self.xdotool("key", name)

    def drag(self, start, end, button: int = 1, steps: int = 5) -> None:
        """Drag with mouse ``button`` from window point ``start`` to ``end`` in ``steps`` moves."""
        self.xdotool("mousemove", "--window", self.window, *start)
        self.xdotool("mousedown", button)
        for i in range(1, steps + 1):
            x = start[0] + (end[0] - start[0]) * i / steps
            y = start[1] + (end[1] - start[1]) * i / steps
            self.xdotool("mousemove", "--window", self.window, int(round(x)), int(round(y)))
        self.xdotool("mouseup", button)

    def scroll(self, notches: int) -> None:
        """Turn the wheel: positive notches away from the user (zoom in)."""
        button = 4 if notches > 0 else 5
        for _ in range(abs(notches)):
            self.xdotool("click", button)

    def interrupt(self) -> None:
        self.proc.send_signal(signal.SIGINT)

    def finish(self, timeout: float = WAIT_S) -> int:
        """Wait for the viewer to exit; returns its status."""
        try:
            return self.proc.wait(timeout=timeout)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
