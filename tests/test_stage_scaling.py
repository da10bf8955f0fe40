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
    assert sum(counts) < 0.05 * 5 * len(f)          # most rows are never sampled
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


def test_a_render_s_cpu_stages_are_the_same_bytes_on_one_thread_or_two(tmp_path, monkeypatch):
    """Reading an .npz, skinning, framing and packing the records run their blocks (or the
    archive's members) on a thread per core: the skeleton, the rows,
    the box, the camera and the records are the same bytes as on one thread."""
    from plantgen.benchmarks.pipeline import synthetic_skeleton
    from plantgen.geometry import vec
    from plantgen.geometry.skeletons.frusta import ROW_FIELDS, frusta_bounds
    from plantgen.geometry.skeletons.skeleton import Skeleton
    from plantgen.gl.records import PACK_BLOCK, pack_records
    path = tmp_path / "plant.npz"
    synthetic_skeleton(PACK_BLOCK + 5 * vec.ROW_BLOCK + 20, seed=3).save(path)
    runs = []
    for workers in (1, 2):
        monkeypatch.setattr(vec, "row_workers", lambda w=workers: w)
        skeleton = Skeleton.load(path)
        frusta = skin_skeleton(skeleton)
        camera = auto_camera(frusta, 64, 48)
        arrays = [getattr(skeleton, k) for k in ("start", "end", "r_start", "r_end", "parent", "continues")]
        arrays += [getattr(frusta, k) for k in ROW_FIELDS]
        arrays += [frusta_bounds(frusta), np.array(camera.eye), pack_records(frusta, np.array(camera.eye))]
        runs.append([np.ascontiguousarray(a).tobytes() for a in arrays])
    assert len(frusta.base) > PACK_BLOCK
    assert runs[0] == runs[1]


# ----------------------------------------------------------------------------- scenes
def _grid_scene(n: int, seeds: int | None = None) -> dict:
    grid = {"count": [n, 1], "spacing": [2, 2]}
    if seeds is not None:
        grid["seeds"] = seeds
    return {"instances": [{"grammar": "saguaro", "seed": 1, "grid": grid}]}


class _Grower:
    """A stand-in for the pipeline's grower: a fixed small plant a call, spending
    ``work`` of the meter; counts its calls and the lengths taken of its skeletons."""

    def __init__(self, meter=None, work: int = 0):
        self.calls, self.lens, self.meter, self.work = 0, [0], meter, work
        from plantgen.geometry.skeletons.skeleton import Skeleton
        lens = self.lens

        class Counted(Skeleton):
            def __len__(self):
                lens[0] += 1
                return super().__len__()
        self.plant = Counted(**{k: getattr(random_tree(12, seed=1), k) for k in
                                ("start", "end", "r_start", "r_end", "parent", "continues", "material",
                                 "material_names")})

    def __call__(self, gpath, seed, iterations):
        self.calls += 1
        if self.meter is not None:
            self.meter.spend(self.work, "derive")
        return self.plant


def test_growing_copies_takes_work_linear_in_the_copies():
    from plantgen.scene import parse_scene
    lens = []
    for n in (300, 600):
        grower = _Grower()
        scene = parse_scene(_grid_scene(n), "grid.yaml", grow_grammar=grower)
        assert grower.calls == n and len(scene.instances) == n
        lens.append(grower.lens[0])
    assert lens[1] < 2.5 * lens[0]          # the old running sum re-done per plant was quadratic


def test_a_scene_over_the_derive_work_is_refused_before_its_copies_grow():
    from plantgen.limits import LimitError, limits
    from plantgen.scene import parse_scene
    meter = limits.meter("derive_work")
    grower = _Grower(meter, work=13_000)
    with pytest.raises(LimitError, match="derive_work of about 130,000,000 estimated"):
        parse_scene({"instances": [{"grammar": "saguaro", "seed": 1, "grid": {"count": [100, 100]}}]},
                    "grid.yaml", grow_grammar=grower, work=meter)
    assert grower.calls <= 3                # the probes, not the copies


def test_a_scene_over_the_segments_is_refused_before_its_copies_grow():
    from plantgen.limits import LimitError, Limits
    from plantgen.scene import parse_scene
    grower = _Grower()
    with pytest.raises(LimitError, match="segments of about 1,200 estimated"):
        parse_scene(_grid_scene(100), "grid.yaml", grow_grammar=grower, limits=Limits(max_segments=1000))
    assert grower.calls <= 3
    grower = _Grower()                      # one seed: grown once, placed 100 times
    assert len(parse_scene(_grid_scene(100, seeds=1), "grid.yaml", grow_grammar=grower,
                           limits=Limits(max_segments=1000)).instances) == 100
    assert grower.calls == 1


# ----------------------------------------------------------------------------- export
def _write_scene(tmp_path, instances) -> str:
    import yaml
    path = tmp_path / "grid.yaml"
    path.write_text(yaml.safe_dump({"name": "grid", "instances": instances}))
    return str(path)


def _glb_json(path) -> dict:
    import json
    import struct
    blob = path.read_bytes()
    (length,) = struct.unpack("<I", blob[12:16])
    return json.loads(blob[20:20 + length])


def test_an_instanced_scene_is_framed_per_copy_not_per_placed_segment(tmp_path, monkeypatch):
    """900 copies of one plant, camera auto: framing costs the plant's bound times 900
    transforms (no placed segment is sampled); one mesh, 900 copy nodes written."""
    from plantgen.limits import Limits
    from plantgen.pipeline import export_model
    counts = _sampled_rows(monkeypatch)
    scene = _write_scene(tmp_path, [{"grammar": "saguaro", "seed": 1,
                                     "grid": {"count": [30, 30], "spacing": [3, 3], "seeds": 1}}])
    # the placed copies' skin (27,000 segments x 1 KiB) is over this budget, and over the
    # segments of one model; the plant's is not
    info = export_model(scene, tmp_path / "grid.glb", level=0, textures=False,
                        limits=Limits(max_export_bytes=8 << 20, max_segments=10_000))
    assert sum(counts) == 0 and info["plants"] == 1 and info["copies"] == 900
    doc = _glb_json(tmp_path / "grid.glb")
    assert len(doc["meshes"]) == 1
    assert sum(1 for n in doc["nodes"] if n.get("mesh") == 0) == 900
    assert "camera" in info["scene"]


def test_an_export_over_the_default_level_makes_the_finest_that_fits(tmp_path):
    from plantgen.limits import Limits
    from plantgen.pipeline import export_model
    scene = _write_scene(tmp_path, [{"grammar": "saguaro", "seed": 1, "grid": {"count": [2, 1], "seeds": 1}}])
    full = export_model(scene, tmp_path / "a.glb", level=None, textures=False)
    assert full["level"] == 1 and not any("--subdiv" in w for w in full["warnings"])
    low = export_model(scene, tmp_path / "b.glb", level=None, textures=False,
                       limits=Limits(max_export_triangles=full["triangles"] - 1))
    assert low["level"] == 0 and any("exported at --subdiv 0" in w for w in low["warnings"])
    with pytest.raises(Exception, match="m = 1"):     # a level asked for is never lowered
        export_model(scene, tmp_path / "c.glb", level=1, textures=False,
                     limits=Limits(max_export_triangles=full["triangles"] - 1))


def test_the_glb_buffer_is_laid_out_once_and_reads_back(tmp_path):
    import trimesh

    from plantgen.pipeline import export_model
    scene = _write_scene(tmp_path, [{"grammar": "saguaro", "seed": 1, "grid": {"count": [3, 1], "seeds": 1}}])
    export_model(scene, tmp_path / "s.glb", level=1)
    doc = _glb_json(tmp_path / "s.glb")
    size = (tmp_path / "s.glb").stat().st_size
    assert doc["buffers"][0]["byteLength"] <= size
    loaded = trimesh.load(tmp_path / "s.glb", force="scene")
    assert len(loaded.geometry) >= 1 and len(loaded.graph.nodes_geometry) == 3


# ----------------------------------------------------------------------------- the bench
def test_the_pipeline_bench_quick_run_writes_a_table_of_every_stage(tmp_path):
    from plantgen.benchmarks import pipeline as bench
    skel = bench.synthetic_skeleton(400, seed=3)
    skel.validate()
    assert len(skel) == 400 and (skel.parent[1:] < np.arange(1, 400)).all()
    out = tmp_path / "stages.md"
    assert bench.main(["--quick", "--kinds", "npz,scene", "--out", str(out)]) == 0
    text = out.read_text()
    for stage in ("read", "skin", "frame", "check", "upload/BVH", "write", "derive"):
        assert f"| {stage} |" in text
    assert "| **npz** | *size* | 1,000 | 10,000 |" in text and "per 10x" in text
    for stage in ("grow, 1 job", "grow, all cores"):      # the distinct-seed scenes, grown both ways
        assert f"| scene N seeds | {stage} | " in text and f"| scene 1 seed | {stage} |" not in text
    assert "- scene N seeds 100: " in text and " times as fast" in text
