"""The RC+R | Blender gallery image (plantgen.benchmarks.in_blender): Blender renders the
exported glTF with plantgen's camera and sun, where Blender is installed."""

from __future__ import annotations

import numpy as np

from plantgen.benchmarks import in_blender


def test_blender_renders_the_exported_scene_as_plantgen_frames_it(blender, tmp_path):
    """The well's glb rendered by Cycles: the model sits where plantgen draws it (the two
    panels' non-sky masks overlap), its ground is lit green and its stones are grey."""
    out = tmp_path / "well.png"
    assert in_blender.main(["well", str(out), "--size", "96", "72", "--samples", "4"]) == 0
    from PIL import Image

    image = np.asarray(Image.open(out).convert("RGB")).astype(int)
    ours, theirs = image[12:, :96], image[12:, 96:]

    def model_mask(panel):        # not sky: sky is bluer than it is red by a margin
        return (panel[..., 2] - panel[..., 0]) < 40

    a, b = model_mask(ours), model_mask(theirs)
    assert b.mean() > 0.2 and (a & b).sum() > 0.7 * min(a.sum(), b.sum())
    green = theirs[..., 1] > theirs[..., 0] + 20
    assert green.mean() > 0.1


def test_without_blender_one_line_and_exit_2(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(in_blender.shutil, "which", lambda name: None)
    assert in_blender.main(["saguaro", str(tmp_path / "s.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Blender" in err[0] and not (tmp_path / "s.png").exists()
