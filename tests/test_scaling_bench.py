"""The scaling bench (plantgen.benchmarks.scaling) on a tiny forest: the tiles hold the
copies asked for, of the same distinct plants, and the table's rows are whole: times
positive, copies and segments counted right, GPU memory growing by a bounded amount a copy."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from plantgen.benchmarks.scaling import BUDGET_DATA, markdown, measure, tile_placed
from plantgen.geometry.rays.instances import PlacedPlants
from plantgen.gl.records import RECORD_BYTES
from plantgen.gl.rt import RayTracer
from plantgen.pipeline import prepare_model

SCENE = """\
name: tiny
seed: 1
effects: [lod]
ground: {size: 40, height: 0, material: grass}
camera: {eye: [0, 4, 40], target: [0, 3, 0], up: [0, 1, 0], fov_y: 50}
light: {direction: [-0.75, -0.6, 0.3]}
instances:
  - {grammar: abop_ternary, seed: 1, position: [0, 0, 0],
     grid: {count: [2, 2], spacing: [8, 8], jitter: 0.3, seeds: 1, scale_jitter: 0.2}}
  - {grammar: aloe, seed: 1, position: [0, 0, 12],
     grid: {count: [3, 2], spacing: [5, 5], jitter: 0.3, seeds: 1}}
"""


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    path = tmp_path_factory.mktemp("scaling") / "tiny.yaml"
    path.write_text(SCENE)
    return path


def test_tiles_keep_the_plants_and_step_away_from_the_camera(scene):
    base = prepare_model(scene).placed
    big = tile_placed(base, 100)
    assert [p.frusta for p in big.plants] == [p.frusta for p in base.plants]      # the same objects
    assert big.copies == 100                                                      # 10 copies x 10 = 100
    first = np.concatenate([p.matrices[: len(q.matrices)] for p, q in zip(big.plants, base.plants, strict=True)])
    np.testing.assert_array_equal(first, np.concatenate([p.matrices for p in base.plants]))   # nearest tile first
    z = np.concatenate([p.matrices[:, 2, 3] for p in big.plants])
    assert z.max() == max(p.matrices[:, 2, 3].max() for p in base.plants)         # nothing nearer the eye
    assert z.min() < base.box[0][2] - 1.0                                         # tiles beyond the forest
    assert tile_placed(base, 5).copies == 5                                       # half of each grid
    assert tile_placed(base, 1).copies == len(base.plants)                        # each plant at least once


def test_table_rows_are_whole(scene, tmp_path, gl_ctx):
    result = measure(str(scene), (10, 100), size=(64, 48), frames=1, rc_max=10, say=lambda _: None,
                     images=tmp_path)
    rows = result["rows"]
    assert [r["copies"] for r in rows] == [10, 100]
    for r in rows:
        assert r["rt_ms"] > 0 and r["scene_s"] > 0 and r["top_s"] > 0
        assert 16 <= r["copy_bytes"] <= 256                    # a map, an index, a share of the top level
        assert r["of_budget"] == r["gpu_bytes"] / (1.2 * result["data_bytes"] + 64 * r["copies"])
        assert r["gpu_bytes"] > result["base_bytes"]
    assert rows[0]["rc_ms"] > 0 and np.isnan(rows[1]["rc_ms"])                 # RC stops at rc_max
    assert rows[1]["segments"] == 10 * rows[0]["segments"]                     # ten whole tiles
    assert rows[1]["gpu_bytes"] - rows[0]["gpu_bytes"] <= 256 * 90
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rc_10_scene.png", "rt_100_scene.png", "rt_10_scene.png"]
    # the distinct plants' GPU data is what their upload's buffers hold: their row records as
    # RC's, and within the memory goal's 1.2 times them with the BVH's nodes beside
    parts = result["base_parts"]
    base = prepare_model(scene).placed
    once = PlacedPlants(tuple(replace(p, matrices=p.matrices[:1]) for p in base.plants), base.material_names)
    gpu = RayTracer(gl_ctx).gpu_bvh(once, None, np.zeros(3))
    assert [b.size for b in gpu.buffers] == [max(n, 16) for n in parts.values()]   # an empty buffer holds 16 B
    assert result["base_bytes"] == sum(parts.values()) == gpu.nbytes
    assert parts["row records"] == result["data_bytes"] == base.unique_rows * RECORD_BYTES
    assert parts["primitive ids"] == 0                       # rows only: records in the GPU's order
    assert result["base_bytes"] <= BUDGET_DATA * result["data_bytes"]
    text = markdown(result)
    assert f"{result['base_bytes'] / result['data_bytes']:.2f}x the records" in text
    assert result["renderer"] in text and "the scene's camera" in text
    assert text.count("\n| 10 |") == 1 and "| 100 |" in text and "not run" in text
