"""Issue 45: every stage scales. Work counters (rows sampled, generator steps, bytes
estimated), not CPU seconds."""

from __future__ import annotations

import numpy as np
import pytest
from _geometry_helpers import random_tree

from plantgen.geometry.rays import camera as camera_module
from plantgen.geometry.rays.camera import auto_camera
from plantgen.geometry.skeletons.skin import skin_skeleton


def _sampled_rows(monkeypatch) -> list:
    """Patch camera.section_points to count the rows it samples; returns the counts."""
    counts = []
    real = camera_module.section_points

    def counting(frusta, *args, **kwargs):
        counts.append(len(frusta.base))
        return real(frusta, *args, **kwargs)
    monkeypatch.setattr(camera_module, "section_points", counting)
    return counts


@pytest.mark.parametrize("direction", [(0.35, 0.25, 1.0), (0.0, 1.0, 1e-3), (1.0, -0.3, 0.0)])
def test_framing_samples_few_rows_and_gives_the_camera_of_every_row(monkeypatch, direction):
    f = skin_skeleton(random_tree(3000, seed=4))
    points = np.array([[0.3, 2.0, -0.1], [-0.5, 0.2, 0.4]])
    counts = _sampled_rows(monkeypatch)
    stats = {}
    pruned = auto_camera(f, 160, 90, direction=direction, points=points, stats=stats)
    assert stats["passes"] == 5 and stats["sampled"] == sum(counts)
    assert sum(counts) < 0.25 * 5 * len(f)          # most rows are never sampled
    monkeypatch.setattr(camera_module, "FRAME_PROBE", 10 ** 9)   # every row sampled: the old framing
    counts.clear()
    full = auto_camera(f, 160, 90, direction=direction, points=points)
    assert sum(counts) == 5 * len(f)
    np.testing.assert_allclose(pruned.eye, full.eye, rtol=0, atol=1e-12)
    np.testing.assert_allclose(pruned.target, full.target, rtol=0, atol=1e-12)


def test_framing_sampling_does_not_grow_with_the_rows(monkeypatch):
    """The rows sampled stay about the same as the plant grows tenfold (its outline does)."""
    counts = _sampled_rows(monkeypatch)
    sampled = []
    for n in (1000, 10000):
        counts.clear()
        auto_camera(skin_skeleton(random_tree(n, seed=2)), 64, 48)
        sampled.append(sum(counts))
    assert sampled[1] < 3 * sampled[0]
