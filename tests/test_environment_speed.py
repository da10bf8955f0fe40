"""The environment's speed benchmark (``python -m plantgen.benchmarks.environment_speed``):
what it counts, on a short growth (no timings are asserted)."""

from __future__ import annotations

import pytest

from plantgen.benchmarks import environment_speed
from plantgen.environment.light import Light


def test_it_counts_the_light_rays_of_a_growth_and_leaves_the_light_as_it_was():
    answer = Light.answer
    row = environment_speed.measure("self_organizing", iterations=10)
    assert Light.answer is answer                                   # the counter is gone
    assert row["segments"] > 0 and row["steps"] == 10
    assert row["rays"] > 0 and row["rays"] % 49 == 0                # 48 sky directions and the sun a bud
    assert row["light_s"] <= row["wall"] and row["rays_per_s"] > 0


def test_an_unknown_model_is_one_line(capsys):
    with pytest.raises(SystemExit) as stop:
        environment_speed.main(["--only", "pine"])
    assert stop.value.code == 2
    assert "unknown model 'pine'" in capsys.readouterr().err
