"""Scanning an instanced scene through two levels (plantgen.geometry.rays.scan.SceneTarget):
the hits, ranges and labels of the merged scene, without placing its copies."""

from __future__ import annotations

import numpy as np
import pytest

from plantgen.geometry.rays.scan import ScanSettings, scan_points, scan_target, scene_target
from plantgen.pipeline import grow_file, model_leaves, skin_model


@pytest.fixture(scope="module", params=["desert", "oasis"])
def scene(request):
    grown = grow_file(request.param)
    merged = scan_target(grown.skeleton, model_leaves(grown), frusta=skin_model(grown),
                         plant=grown.scene.segment_instance(), leaf_plant=grown.scene.polygon_instance())
    return grown, merged, scene_target(grown.scene.plants())


def test_two_levels_hit_what_the_merged_scene_hits(scene):
    grown, merged, two = scene
    assert len(two) == len(merged)
    assert len(two.targets) == len(grown.scene.plants()) and two.bvh.copies == len(grown.scene.instances)
    rng = np.random.default_rng(0)
    lo, hi = merged.box()
    O = lo + (hi - lo) * rng.random((400, 3))
    D = lo + (hi - lo) * rng.random((400, 3)) - O
    t1, p1 = merged.first_hits(O, D)
    t2, p2 = two.first_hits(O, D)
    assert np.isfinite(t1).sum() > 50
    np.testing.assert_array_equal(np.isfinite(t1), np.isfinite(t2))
    hit = np.isfinite(t1)
    a, b = merged.primitive_labels(p1[hit]), two.primitive_labels(p2[hit])
    same = np.ones(hit.sum(), bool)
    for name in ("plant", "segment", "leaf", "part", "order"):
        same &= a[name] == b[name]
    assert same.mean() > 0.99                            # a tie between touching rows may go either way
    np.testing.assert_allclose(t2[hit][same], t1[hit][same], rtol=1e-9)
    assert (b["leaf"] >= 0).any() == (a["leaf"] >= 0).any()


def test_a_scenes_box_is_known_before_its_trees_are_built(scene):
    """A scan sizes its beams from the copies' box before any budget check: the box comes
    from the plants' primitive boxes, without building a tree, and it is the box the
    built two-level tree gives."""
    grown = scene[0]
    fresh = scene_target(grown.scene.plants())
    early = fresh.box()
    assert "bvh" not in fresh.__dict__ and not any("bvh" in t.__dict__ for t in fresh.targets)
    assert fresh.bvh.copies == len(fresh.instance)
    assert np.array_equal(early, fresh.box())
    assert (early[1] > early[0]).all()


def test_scan_of_a_scene_matches_the_merged_scan(scene):
    """The same scanner: points agree in number and labels up to the beam grid's alignment
    (aimed at the copies' box rather than the placed rows' box)."""
    grown, merged, two = scene
    centre = merged.box().mean(axis=0)
    settings = ScanSettings(angular_step=0.4, positions=((centre[0] + 1.0, centre[1], centre[2] - 2.0),))
    a, b = scan_points(merged, settings), scan_points(two, settings)
    assert len(a) > 500
    assert abs(len(a) - len(b)) <= 0.02 * len(a)
    for name in ("plant", "part"):
        ca = np.bincount(getattr(a, name), minlength=8)
        cb = np.bincount(getattr(b, name), minlength=8)
        assert np.abs(ca - cb).sum() <= 0.05 * len(a), name


def test_a_finder_gives_the_primitives_and_float64_the_ranges(scene):
    """precision float32 with a finder (the GPU's search; here a stand-in that gives the
    right primitives with float32 distances): the float64 scan's points exactly."""
    _, merged, two = scene
    centre = merged.box().mean(axis=0)
    positions = ((centre[0] + 1.0, centre[1], centre[2] - 2.0),)
    exact = scan_points(two, ScanSettings(angular_step=0.8, positions=positions))
    calls = []

    def finder(target, origins, dirs):
        calls.append(len(origins))
        t, prim = target.first_hits(origins, dirs)
        return t.astype(np.float32), prim

    got = scan_points(two, ScanSettings(angular_step=0.8, positions=positions, precision="float32"), finder=finder)
    assert calls and len(exact) > 100
    np.testing.assert_array_equal(got.xyz, exact.xyz)
    np.testing.assert_array_equal(got.segment, exact.segment)
    np.testing.assert_array_equal(got.plant, exact.plant)


def test_beams_stream_in_bounded_chunks(monkeypatch):
    """Whatever the beam count, the tracer never gets more than a chunk of rays at once;
    the points do not depend on the chunking."""
    from _geometry_helpers import random_tree

    import plantgen.geometry.rays.scan as scan

    target = scan_target(random_tree(60, seed=5))
    settings = ScanSettings(angular_step=0.5, scanners=2)
    whole = scan_points(target, settings)
    sizes = []
    real = scan.ScanTarget.first_hits

    def spy(self, origins, dirs, **kw):
        sizes.append(len(origins))
        return real(self, origins, dirs, **kw)

    monkeypatch.setattr(scan.ScanTarget, "first_hits", spy)
    small = scan_points(target, settings, max_pairs=1000)
    assert max(sizes) <= 1000 and len(sizes) > 10
    np.testing.assert_array_equal(small.xyz, whole.xyz)
    monkeypatch.setattr(scan, "SCAN_CHUNK_RAYS", 4096)
    sizes.clear()
    scan_points(target, settings)
    assert max(sizes) <= 4096
