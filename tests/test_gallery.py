"""``python -m plantgen.benchmarks.gallery`` (issue 13): one command rebuilds every image of
``gallery/``, and an entry's image is its command's output."""

from __future__ import annotations

import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from _cli import run_cli
from PIL import Image

from plantgen.benchmarks.gallery import command_line, entries

REPO = Path(__file__).resolve().parent.parent


@pytest.mark.skipif(not (REPO / "gallery").is_dir(), reason="needs the source tree's gallery/ folder")
def test_every_gallery_image_has_an_entry():
    images = {str(p.relative_to(REPO / "gallery")) for p in (REPO / "gallery").rglob("*")
              if p.suffix.lower() in (".png", ".gif")}
    made = {out for e in entries() for out in e.outputs}
    assert images == made


def test_an_entry_drawn_small_is_its_commands_output(gl_ctx, tmp_path):
    gallery, alone = tmp_path / "gallery", tmp_path / "alone"
    proc = subprocess.run([sys.executable, "-m", "plantgen.benchmarks.gallery", "--only", "pine", "--size", "160x120",
                           "--out", str(gallery)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "[1/1] pine: plantgen render pine -o" in proc.stdout and "ok" in proc.stdout
    pine = next(e for e in entries() if e.name == "pine")
    args = command_line(pine, alone, (160, 120))
    assert args[:2] == ["plantgen", "render"] and "--relief" in args
    listed = subprocess.run([sys.executable, "-m", "plantgen.benchmarks.gallery", "--only", "pine", "--size", "160x120",
                             "--out", str(alone), "--list"], capture_output=True, text=True, timeout=120)
    assert listed.stdout.strip() == f"pine: {shlex.join(args)}"
    alone.mkdir()
    code, _, err = run_cli(*args[1:])
    assert code == 0, err
    made, expected = Image.open(gallery / "pine.png"), Image.open(alone / "pine.png")
    assert made.size == (160, 120)
    assert np.array_equal(np.asarray(made), np.asarray(expected))
