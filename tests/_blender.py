"""Running a script in Blender for the import tests (the ``blender`` fixture finds it)."""

from __future__ import annotations

import subprocess

from plantgen.benchmarks.in_blender import NUMPY_BOOL


def blender_line(blender: str, script_text: str, tmp_path, prefix: str, *args, timeout: int = 600) -> str:
    """Run ``script_text`` (after :data:`NUMPY_BOOL`) in ``blender --background`` with
    ``args`` after ``--``; it must exit 0. The first line it printed that starts with
    ``prefix``, the prefix cut off."""
    script = tmp_path / "blender_script.py"
    script.write_text(NUMPY_BOOL + script_text)
    done = subprocess.run([blender, "--background", "--factory-startup", "--python", str(script), "--", *args],
                          capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, done.stderr[-2000:]
    return next(x for x in done.stdout.splitlines() if x.startswith(prefix))[len(prefix):]
