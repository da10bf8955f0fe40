"""Issue 45: a scene's distinct plants grown once each (a cache by grammar, seed and
iterations) and, where the forecast says it pays, in a pool of processes; the plants are
the same array for array, the progress lines the same, the refusals still before the work."""

from __future__ import annotations

import multiprocessing
from pathlib import Path

import numpy as np
import pytest
import yaml
from _cli import run_cli

from plantgen.pipeline import growing
from plantgen.pipeline.growing import grow_file

ARRAYS = ("start", "end", "r_start", "r_end", "parent", "continues", "material")


def _scene(tmp_path, copies: int, seeds: int | None = None, name: str = "grid.yaml") -> str:
    grid = {"count": [copies, 1], "spacing": [4, 4], "jitter": 0.3}
    if seeds is not None:
        grid["seeds"] = seeds
    path = tmp_path / name
    path.write_text(yaml.safe_dump({"name": "grid", "instances": [{"grammar": "saguaro", "seed": 1, "grid": grid}]}))
    return str(path)


def _pools(monkeypatch) -> list:
    """Count the pools a scene grows in: each call's (plants, processes)."""
    calls = []
    real = growing._grow_in_pool

    def counted(requests, jobs, *args):
        calls.append((len(requests), jobs))
        return real(requests, jobs, *args)
    monkeypatch.setattr(growing, "_grow_in_pool", counted)
    return calls


def _same_scene(a, b) -> None:
    assert len(a.instances) == len(b.instances)
    for x, y in zip(a.instances, b.instances, strict=True):
        assert (x.source, x.seed) == (y.source, y.seed)
        np.testing.assert_array_equal(x.matrix, y.matrix)
        for name in ARRAYS:
            np.testing.assert_array_equal(getattr(x.skeleton, name), getattr(y.skeleton, name))
        assert x.skeleton.material_names == y.skeleton.material_names
        assert (x.polygons is None) == (y.polygons is None)
        if x.polygons is not None:
            np.testing.assert_array_equal(x.polygons.vertices, y.polygons.vertices)


def test_serial_and_parallel_growth_give_identical_plants(tmp_path, monkeypatch):
    monkeypatch.setattr(growing, "PARALLEL_WORK", 0)       # a small scene, grown in the pool all the same
    pools = _pools(monkeypatch)
    path = _scene(tmp_path, 12)
    serial = grow_file(path, jobs=1)
    assert pools == []
    said = []
    parallel = grow_file(path, jobs=2, progress=lambda stage, done, total: said.append((stage, done)))
    assert pools == [(11, 2)]                 # the probe plant grew in the parent, the other 11 in the pool
    _same_scene(serial.scene, parallel.scene)
    assert parallel.modules == serial.modules
    assert [d for s, d in said if s == "grow"] == list(range(1, 13))    # a progress line a plant, in order
    assert serial.warnings == parallel.warnings


def test_a_small_scene_grows_one_by_one_from_its_forecast(tmp_path, monkeypatch):
    """The pool starts only where the probe plant's derive work times the plants to grow
    passes PARALLEL_WORK: decided from counts before any copy grows."""
    pools = _pools(monkeypatch)
    grow_file(_scene(tmp_path, 4), jobs=2)
    assert pools == []
    from plantgen.limits import limits
    from plantgen.scene import parse_scene
    asked, meter = [], limits.meter("derive_work")
    parse_scene(yaml.safe_load(Path(_scene(tmp_path, 40)).read_text()), str(tmp_path / "grid.yaml"),
                grow_grammar=_grower(meter, 1000), work=meter,
                grow_many=lambda requests, estimate: asked.append((len(requests), estimate)))
    assert asked == [(39, 40 * 1000)]         # the probe's work times the 40 distinct seeds


def test_copies_of_one_seed_are_grown_once_and_no_pool_starts(tmp_path, monkeypatch):
    monkeypatch.setattr(growing, "PARALLEL_WORK", 0)
    pools = _pools(monkeypatch)
    said = []
    grown = grow_file(_scene(tmp_path, 30, seeds=3), jobs=2,
                      progress=lambda stage, done, total: said.append(stage))
    assert said.count("grow") == 3 and len(grown.scene.instances) == 30
    assert pools == [(2, 2)]                  # the cache: three plants, one the probe
    assert len(grown.scene.plants()) == 3


def test_a_scene_refused_by_its_forecast_starts_no_pool(tmp_path, monkeypatch):
    from plantgen.limits import LimitError
    pools = _pools(monkeypatch)
    with pytest.raises(LimitError, match="derive_work of about"):
        grow_file(_scene(tmp_path, 400), jobs=2, limits=growing.Limits(max_derive_work=1_000_000))
    assert pools == []


def _bush(tmp_path) -> tuple[str, dict, dict]:
    """A grammar whose plants differ by seed (each step doubles or stays): its path, and
    each seed's derive work and segments, grown here as a pool process grows them."""
    from plantgen.limits import Limits
    gpath = tmp_path / "bush.yaml"
    gpath.write_text(yaml.safe_dump({"axiom": "A", "iterations": 10, "rules": ["A ->(0.5) F[+A]A", "A ->(0.5) FA"]}))
    gpath = str(gpath.resolve())
    growing._start_worker({gpath: yaml.safe_load(Path(gpath).read_text())}, Limits())   # this process as a worker
    grown = {s: growing._grow_in_worker((gpath, s, None, 0)) for s in range(1, 25)}
    return gpath, {s: g[2] for s, g in grown.items()}, {s: len(g[0].skeleton) for s, g in grown.items()}


def _first_light_seed(figures: dict) -> int:
    """A seed whose plant is lighter than the mean of it and the seven after it: a scene
    of those eight seeds passes its forecast (the first seed's figure times eight)."""
    return next(b for b in range(1, 17) if figures[b] * 8 < sum(figures[b + k] for k in range(8)))


def _bush_scene(tmp_path, base: int) -> Path:
    path = tmp_path / "grid.yaml"
    path.write_text(yaml.safe_dump({"instances": [{"grammar": "bush.yaml", "seed": base, "grid": {"count": [8, 1]}}]}))
    return path


def test_the_pool_charges_each_plants_work_to_the_scene(tmp_path, monkeypatch):
    """The forecast is the first seed's work times the seeds: a scene whose other plants
    cost more passes it, and is refused as its plants come back from the pool, the
    scene's meter charged with each plant's work."""
    from plantgen.errors import PlantgenError
    from plantgen.limits import Limits
    _, work, _ = _bush(tmp_path)
    base = _first_light_seed(work)
    monkeypatch.setattr(growing, "PARALLEL_WORK", 0)
    pools = _pools(monkeypatch)
    path = _bush_scene(tmp_path, base)
    for jobs in (2, 1):                     # the pool, then one by one: both refuse
        with pytest.raises(PlantgenError, match="instance 1: .*derive_work reaches") as refused:
            grow_file(path, jobs=jobs, limits=Limits(max_derive_work=work[base] * 8))
        assert "derive_work of about" not in str(refused.value)     # not the forecast: the plants
        assert multiprocessing.active_children() == []             # the pool stopped, none left growing
    assert pools == [(7, 2)]
    assert len(grow_file(path, jobs=2, limits=Limits(max_derive_work=sum(work[base + k] for k in range(8)))
                         ).scene.instances) == 8


def test_the_pool_counts_each_plants_segments_as_it_comes(tmp_path, monkeypatch):
    from plantgen.limits import LimitError, Limits
    _, _, segments = _bush(tmp_path)
    base = _first_light_seed(segments)
    monkeypatch.setattr(growing, "PARALLEL_WORK", 0)
    path = _bush_scene(tmp_path, base)
    said = {}
    for jobs in (2, 1):
        with pytest.raises(LimitError, match="grid.yaml: instance 1: segments grown for the scene: ") as refused:
            grow_file(path, jobs=jobs, limits=Limits(max_segments=segments[base] * 8))
        said[jobs] = str(refused.value)
    assert said[1] == said[2]               # the same plant, the same line


def test_jobs_must_be_a_positive_integer(tmp_path):
    from plantgen.errors import PlantgenError
    with pytest.raises(PlantgenError, match="jobs must be a positive integer"):
        grow_file(_scene(tmp_path, 2), jobs=0)


def test_grow_takes_jobs_and_writes_the_same_skeleton(tmp_path, monkeypatch):
    monkeypatch.setattr(growing, "PARALLEL_WORK", 0)
    path = _scene(tmp_path, 6)
    outs = []
    for jobs in ("1", "2"):
        out = tmp_path / f"grid{jobs}.npz"
        code, _, err = run_cli("grow", path, "-o", out, "-q", "--jobs", jobs)
        assert code == 0, err
        outs.append(np.load(out))
    for name in ARRAYS:
        np.testing.assert_array_equal(outs[0][name], outs[1][name])
    code, _, err = run_cli("grow", path, "-o", tmp_path / "x.npz", "--jobs", "0")
    assert code == 2 and "--jobs" in err


# ----------------------------------------------------------------------------- helpers
def _grower(meter, work: int):
    """A stand-in for the pipeline's grower: a fixed small plant a call, spending ``work``."""
    from _geometry_helpers import random_tree
    plant = random_tree(12, seed=1)

    def grow(gpath, seed, iterations):
        meter.spend(work, "derive")
        return plant
    return grow
