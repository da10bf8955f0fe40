"""Simulated laser scans (plantgen.geometry.rays.scan) and their files (plantgen.scanfiles):
points on the exact surfaces (distances computed here from the frusta's definition, not
by the ray caster), labels that match what was hit, leaves on their planes, determinism,
misses, grazing rays, scanners inside the plant's box, divergence, airborne passes, and
LAS / LAZ / PLY read back by laspy and trimesh."""

from __future__ import annotations

import numpy as np
import pytest
from _scan_helpers import labelled_residuals

from plantgen.geometry.rays.reference import intersect_frusta
from plantgen.geometry.rays.scan import (
    PART_NAMES,
    ScanError,
    ScanSettings,
    TerrestrialBeams,
    beam_grids,
    beam_returns,
    cast_first_returns,
    scan_plant,
    scan_points,
    scan_target,
    scanner_positions,
)
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.geometry.skeletons.topology import branches
from plantgen.limits import LimitError, Limits
from plantgen.pipeline import grow_file, skin_model

laspy = pytest.importorskip("laspy", reason="laspy (plantgen[scan]) is not installed")


def column(x=0.0, z=0.0, h=3.0, r1=0.3, r2=0.2) -> Skeleton:
    return Skeleton([[x, 0, z]], [[x, h, z]], [r1], [r2], [-1], [False], [0])


def two_columns(x, z, r=0.25, h=2.0) -> Skeleton:
    return Skeleton.concatenate([column(x[0], z[0], h, r, r), column(x[1], z[1], h, r, r)])


# ---------------------------------------------------------------------------- known shapes
def test_a_frustum_is_scanned_on_its_surface_from_every_side():
    skel = column()
    cloud = scan_plant(skel, None, ScanSettings(angular_step=0.5, scanners=3), seed=0)
    assert len(cloud) > 1000 and set(np.unique(cloud.scanner)) == {0, 1, 2}
    rel = cloud.xyz
    rho, y = np.hypot(rel[:, 0], rel[:, 2]), rel[:, 1]
    k = -0.1 / 3
    lateral = np.abs(rho - (0.3 + k * y)) / np.sqrt(1 + k * k)
    assert np.all((y >= -1e-12) & (y <= 3 + 1e-12))
    assert lateral.max() <= 1e-9 * 3
    assert np.all(cloud.part == 0) and np.all(cloud.order == 0) and np.all(cloud.segment == 0)
    assert np.all(cloud.leaf == -1) and np.all(cloud.plant == 0)
    # every side is seen: the points' azimuths around the axis cover the circle
    azimuth = np.degrees(np.arctan2(rel[:, 2], rel[:, 0])) % 360
    assert np.histogram(azimuth, bins=36, range=(0, 360))[0].min() > 0


def test_the_scanners_stand_on_a_circle_at_their_height_looking_at_the_plant():
    skel = column(x=2.0, z=-1.0, h=4.0)
    settings = ScanSettings(scanners=5, distance=7.0, scanner_height=1.2, azimuth=30.0)
    pos = scanner_positions(scan_target(skel), settings)
    assert pos.shape == (5, 3) and np.allclose(pos[:, 1], 1.2)
    assert np.allclose(np.hypot(pos[:, 0] - 2.0, pos[:, 2] + 1.0), 7.0)
    assert np.allclose(np.degrees(np.arctan2(pos[0, 2] + 1, pos[0, 0] - 2)), 30.0)
    explicit = ScanSettings(positions="1,2,3; 4,5,6")
    assert explicit.positions == ((1.0, 2.0, 3.0), (4.0, 5.0, 6.0))
    assert np.array_equal(scanner_positions(scan_target(skel), explicit), [[1, 2, 3], [4, 5, 6]])


def test_exactly_the_beams_that_meet_the_cylinder_give_points():
    """A vertical cylinder seen from mid-height: a beam hits iff its line passes within r of
    the axis and enters the side between the ends (worked out here in the plane); the
    scan gives one point for each of those beams and none for the others."""
    r, h = 0.4, 2.0
    skel = column(h=h, r1=r, r2=r)
    settings = ScanSettings(angular_step=0.4, positions="3,1,0.5")
    cloud = scan_plant(skel, None, settings, seed=0)
    target = scan_target(skel)
    lo, hi = target.box()
    grid = TerrestrialBeams(np.array([3.0, 1.0, 0.5]), lo, hi, np.radians(0.4))
    a, b = np.divmod(np.arange(grid.count), grid.nb)
    origin, d = grid.rays(grid.a0 + a, grid.b0 + b)
    o2, d2 = origin[:, [0, 2]], d[:, [0, 2]]
    qa, qb, qc = (d2 ** 2).sum(1), (o2 * d2).sum(1), (o2 ** 2).sum(1) - r * r
    disc = qb * qb - qa * qc
    t = (-qb - np.sqrt(np.maximum(disc, 0))) / np.where(qa > 0, qa, 1)
    y = origin[:, 1] + t * d[:, 1]
    hits = (disc > 0) & (t > 0) & (y > 0) & (y < h)
    assert 0 < hits.sum() < grid.count
    assert len(cloud) == hits.sum()
    expected = origin[hits] + t[hits, None] * d[hits]
    assert np.allclose(np.sort(cloud.xyz, axis=0), np.sort(expected, axis=0), atol=1e-9)


def test_a_ray_that_meets_nothing_gives_no_point_and_a_grazing_ray_stays_finite():
    r = 0.5
    target = scan_target(column(h=2.0, r1=r, r2=r))
    origins = np.array([[3.0, 1.0, 0.0], [3.0, 1.0, 0.0], [r, 1.0, 5.0], [r * (1 - 1e-15), 1.0, 5.0]])
    dirs = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])
    t, prim = cast_first_returns(target, origins, dirs)
    assert t[0] == np.inf and prim[0] == -1                  # pointing away
    assert t[1] == pytest.approx(3.0 - r) and prim[1] == 0
    assert not np.isnan(t).any()
    for k in (2, 3):                                            # tangent, and a hair inside
        if np.isfinite(t[k]):
            p = origins[k] + t[k] * dirs[k]
            assert abs(np.hypot(p[0], p[2]) - r) <= 1e-7 and t[k] == pytest.approx(5.0, abs=1e-6)


def test_a_grid_beam_grazing_two_columns_is_handled():
    """Two columns touching at x = 0, seen along x = 0 by the central beam of the grid
    (a direction whose x is a rounding error): every point is on a column's surface."""
    r = 0.25
    skel = two_columns([-r, r], [r, r], r=r)
    cloud = scan_plant(skel, None, ScanSettings(angular_step=0.25, positions=f"0,1,{6 * r}"), seed=0)
    frusta = skin_skeleton(skel)
    assert len(cloud) and np.isfinite(cloud.xyz).all()
    assert labelled_residuals(frusta, cloud, 1e-9).max() <= 1e-9
    assert set(np.unique(cloud.segment)) == {0, 1}


def test_a_scanner_inside_the_plants_box_sees_all_around():
    skel = two_columns([-3.0, 3.0], [0.0, 0.5])
    cloud = scan_plant(skel, None, ScanSettings(angular_step=0.3, positions="0,1,0.2"), seed=0)
    frusta = skin_skeleton(skel)
    assert set(np.unique(cloud.segment)) == {0, 1}              # in front and behind
    assert labelled_residuals(frusta, cloud, 1e-9).max() <= 1e-9
    # and under a crown: a horizontal branch right above the scanner
    arm = Skeleton([[0, 0, 0], [0, 2, 0]], [[0, 2, 0], [3, 2, 0]], [0.2, 0.1], [0.15, 0.1], [-1, 0],
                   [False, False], [0, 0])
    cloud = scan_plant(arm, None, ScanSettings(angular_step=0.3, positions="1.5,1,0.3"), seed=0)
    assert labelled_residuals(skin_skeleton(arm), cloud, 1e-9).max() <= 1e-9
    assert (cloud.segment == 1).sum() > 100 and np.all(cloud.part[cloud.segment == 1] == 1)


def test_range_noise_stays_within_its_sigma_and_is_applied():
    sigma = 2e-3
    skel = column()
    cloud = scan_plant(skel, None, ScanSettings(angular_step=0.5, range_noise=sigma), seed=4)
    frusta = skin_skeleton(skel)
    res = labelled_residuals(frusta, cloud, 6 * sigma)
    assert res.max() <= 6 * sigma                    # a 6-sigma bound: about 2e-9 of a miss per point
    assert np.median(res) > 0.2 * sigma              # noise there is, of the right size
    assert 0.3 * sigma < np.std(res) < sigma


def test_the_same_seed_gives_the_same_cloud_however_it_is_chunked():
    skel = grow_file("saguaro").skeleton
    frusta = skin_skeleton(skel)
    settings = ScanSettings(angular_step=0.4, range_noise=0.01, divergence=3.0, beam_samples=4)
    a = scan_plant(skel, None, settings, seed=11, frusta=frusta)
    b = scan_plant(skel, None, settings, seed=11, frusta=frusta, max_pairs=1 << 12)
    c = scan_plant(skel, None, settings, seed=12, frusta=frusta)
    assert len(a) > 1000 and np.array_equal(a.xyz, b.xyz)
    assert all(np.array_equal(x, y) for x, y in zip(a.labels().values(), b.labels().values(), strict=True))
    assert a.metadata == b.metadata and a.metadata["seed"] == 11
    assert not np.array_equal(a.xyz[: min(len(a), len(c))], c.xyz[: min(len(a), len(c))])


def test_a_diverging_beam_returns_its_first_hit_within_its_footprint():
    skel = grow_file("saguaro").skeleton
    frusta = skin_skeleton(skel)
    ideal = scan_plant(skel, None, ScanSettings(angular_step=0.4), seed=1, frusta=frusta)
    gamma = 5.0                                                            # mrad, a wide beam
    wide = scan_plant(skel, None, ScanSettings(angular_step=0.4, divergence=gamma), seed=1, frusta=frusta)
    assert len(wide) > len(ideal)                                          # edges caught by part of the beam
    ranges = np.linalg.norm(wide.xyz - wide.scanners[wide.scanner], axis=1)
    res = labelled_residuals(frusta, wide, ranges.max() * gamma / 2000)
    assert np.all(res <= ranges * gamma / 2000 + 1e-9)
    mean = scan_plant(skel, None, ScanSettings(angular_step=0.4, divergence=gamma, beam_return="mean"), seed=1,
                      frusta=frusta)
    assert len(mean) == len(wide) and np.isfinite(mean.xyz).all()
    # the mean of a beam's ranges is never nearer than its first return
    assert np.all(np.linalg.norm(mean.xyz - mean.scanners[mean.scanner], axis=1) >= ranges - 1e-9)


# ---------------------------------------------------------------------------- grown plants
@pytest.fixture(scope="module")
def elm_scan():
    grown = grow_file("elm")
    frusta = skin_model(grown)
    cloud = scan_plant(grown.skeleton, None, ScanSettings(angular_step=0.25), seed=0, frusta=frusta)
    return grown.skeleton, frusta, cloud


def test_a_grown_tree_is_scanned_on_its_labelled_segments(elm_scan):
    skel, frusta, cloud = elm_scan
    size = float(np.ptp(np.concatenate([frusta.base, frusta.top]), axis=0).max())
    assert len(cloud) > 5000
    assert labelled_residuals(frusta, cloud, 1e-9 * size).max() <= 1e-9 * size
    order = branches(skel).segment_order
    assert np.array_equal(cloud.order, order[cloud.segment])
    assert np.array_equal(cloud.part == 0, cloud.order == 0) and set(np.unique(cloud.part)) == {0, 1}


def test_recast_rays_hit_the_labelled_segment(elm_scan):
    """A sample of points: the ray from its scanner through it, cast again by the brute
    force reference (every row tested), meets the labelled segment at that point."""
    _, frusta, cloud = elm_scan
    pick = np.random.default_rng(3).choice(len(cloud), 60, replace=False)
    origin = cloud.scanners[cloud.scanner[pick]]
    d = cloud.xyz[pick] - origin
    hits = intersect_frusta(frusta, origin, d / np.linalg.norm(d, axis=1, keepdims=True))
    assert hits.hit.all()
    assert np.array_equal(hits.segment, cloud.segment[pick])
    assert np.allclose(hits.point, cloud.xyz[pick], atol=1e-9)


def test_leaf_points_lie_on_their_leaves():
    grown = grow_file("abop_bush")
    leaves = grown.polygons
    cloud = scan_plant(grown.skeleton, leaves, ScanSettings(angular_step=0.3, scanners=2), seed=0,
                       frusta=skin_model(grown))
    leaf = np.flatnonzero(cloud.part == 2)
    assert len(leaf) > 1000 and np.all(cloud.leaf[leaf] >= 0) and np.all(cloud.leaf[cloud.part != 2] == -1)
    assert np.array_equal(cloud.segment[leaf], leaves.segment[cloud.leaf[leaf]])
    tri = leaves.vertices[leaves.triangles]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    for i in np.random.default_rng(0).choice(leaf, 300, replace=False):
        own = np.flatnonzero(leaves.polygon == cloud.leaf[i])
        dist = np.abs(np.einsum("ij,ij->i", cloud.xyz[i] - tri[own, 0], n[own]))
        assert dist.min() <= 1e-9
    assert PART_NAMES[2] == "leaf"


def test_plant_labels_follow_the_segments_given():
    skel = two_columns([-2.0, 2.0], [0.0, 0.0])
    cloud = scan_plant(skel, None, ScanSettings(angular_step=0.5), seed=0, plant=np.array([7, 9]))
    assert set(np.unique(cloud.plant)) == {7, 9}
    assert np.array_equal(cloud.plant == 7, cloud.segment == 0)


# ---------------------------------------------------------------------------- airborne
def test_nadir_lines_see_the_top_of_a_column():
    r = 0.5
    skel = column(h=2.0, r1=r, r2=r)
    settings = ScanSettings(mode="airborne", scan_angle=0.0, pulse_spacing=0.05, line_spacing=0.05,
                            flight_height=10.0)
    cloud = scan_plant(skel, None, settings, seed=0)
    assert np.allclose(cloud.xyz[:, 1], 2.0) and np.all(np.hypot(cloud.xyz[:, 0], cloud.xyz[:, 2]) <= r + 1e-12)
    assert len(cloud) == pytest.approx(np.pi * r * r / 0.05 ** 2, rel=0.1)
    assert len(np.unique(cloud.scanner)) == pytest.approx(2 * r / 0.05, abs=2)


def test_a_mirror_sweep_scans_sides_and_top_on_the_surface():
    skel = grow_file("saguaro").skeleton
    frusta = skin_skeleton(skel)
    cloud = scan_plant(skel, None, ScanSettings(mode="airborne", angular_step=0.2, scan_angle=40.0), seed=0,
                       frusta=frusta)
    assert len(cloud) > 500 and set(np.unique(cloud.scanner)) <= set(range(len(cloud.scanners)))
    assert labelled_residuals(frusta, cloud, 1e-8).max() <= 1e-8
    assert np.all(cloud.scanners[:, 1] > frusta.top[:, 1].max())


# ---------------------------------------------------------------------------- settings, limits
def test_bad_settings_are_one_line_naming_the_option():
    with pytest.raises(ScanError, match="--angular-step"):
        ScanSettings(angular_step=0)
    with pytest.raises(ScanError, match="--scan-mode"):
        ScanSettings(mode="satellite")
    with pytest.raises(ScanError, match="--scanner-positions"):
        ScanSettings(positions="1,2")
    with pytest.raises(ScanError, match="--range-noise"):
        ScanSettings(range_noise=-1)


def test_a_scan_over_its_ray_budget_is_refused_before_casting():
    with pytest.raises(LimitError, match="scan_rays"):
        scan_plant(column(), None, ScanSettings(angular_step=0.01), limits=Limits(max_scan_rays=1000))


def test_an_empty_plant_gives_an_empty_cloud():
    cloud = scan_plant(Skeleton.empty(), None, ScanSettings())
    assert len(cloud) == 0 and cloud.xyz.shape == (0, 3)


@pytest.mark.parametrize("settings", [ScanSettings(mode="airborne", angular_step=0.3, scan_angle=40.0),
                                      ScanSettings(angular_step=0.3, positions="0.3,1.5,0.2; 6,1,-4")],
                         ids=["airborne", "inside and outside"])
def test_binning_loses_no_beam(settings):
    """Beams sampled from every scanner's grid, cast by the brute-force reference (every
    row's box tested): the binned scan has a return for exactly those that hit, at the
    same range and on the same row."""
    grown = grow_file("saguaro")
    frusta = skin_model(grown)
    target = scan_target(grown.skeleton, frusta=frusta)
    rng = np.random.default_rng(2)
    hits = 0
    for grid, got in zip(beam_grids(target, settings), beam_returns(target, settings), strict=True):
        beams = rng.choice(grid.count, min(4000, grid.count), replace=False)
        origins, dirs = grid.rays(grid.a0 + beams // grid.nb, grid.b0 + beams % grid.nb)
        want = intersect_frusta(frusta, np.broadcast_to(origins, dirs.shape), dirs)
        found = np.isin(beams, got.beam)
        where = np.searchsorted(got.beam, beams)
        assert np.array_equal(found, want.hit)
        assert np.allclose(got.range[where[found]], want.t[want.hit], rtol=0, atol=1e-12)
        assert np.array_equal(got.primitive[where[found]], want.row[want.hit])
        hits += int(want.hit.sum())
    assert hits > 50


def test_plant_labels_of_the_wrong_length_are_one_line():
    with pytest.raises(ScanError, match="one per segment"):
        scan_plant(two_columns([-2.0, 2.0], [0.0, 0.0]), None, ScanSettings(), plant=[1, 2, 3])


# ---------------------------------------------------------------------- the scan's memory
def _crown_scan(step: float):
    """A scanner inside a random tree's crown, at ``step`` degrees."""
    from _geometry_helpers import random_tree

    target = scan_target(random_tree(200, seed=5))
    lo, hi = target.box()
    return target, ScanSettings(angular_step=step, positions=(tuple((np.asarray(lo) + np.asarray(hi)) / 2),))


def test_a_scans_memory_grows_with_the_points_it_keeps_not_its_beams(monkeypatch):
    """Four times the beams: the peak grows by at most POINT_BYTES a point more returned
    (the beams are traced a chunk at a time; what stays is the points)."""
    import tracemalloc

    import plantgen.geometry.rays.scan as scan

    monkeypatch.setattr(scan, "SCAN_CHUNK_RAYS", 1 << 12)
    monkeypatch.setattr(scan, "LABEL_CHUNK", 1 << 10)     # as a real scan's millions of points: chunked
    target, settings = _crown_scan(2.0)
    scan_points(target, settings)                   # the target's BVH built outside the measure
    runs = []
    tracemalloc.start()
    try:
        for step in (0.5, 0.25):
            settings = ScanSettings(angular_step=step, positions=settings.positions)
            tracemalloc.reset_peak()
            base = tracemalloc.get_traced_memory()[0]
            cloud = scan_points(target, settings)
            runs.append((len(cloud), tracemalloc.get_traced_memory()[1] - base))
            del cloud
    finally:
        tracemalloc.stop()
    (few, peak_few), (many, peak_many) = runs
    assert many > 3 * few > 0
    assert peak_many - peak_few <= scan.POINT_BYTES * (many - few)


def test_the_scan_budget_is_estimated_before_and_counted_while_it_runs(monkeypatch):
    import plantgen.geometry.rays.scan as scan

    target, settings = _crown_scan(0.5)
    grids = scan.beam_grids(target, settings)
    beams = sum(g.count for g in grids)
    points = len(scan_points(target, settings))
    expected = scan.expected_points(target, grids)
    share = points / beams
    assert abs(expected - points) <= 4 * np.sqrt(share * (1 - share) / scan.RETURN_SAMPLE) * beams + 1
    # a budget under the estimate: refused before the beams are traced
    traced = []
    real = scan.ScanTarget.first_hits
    monkeypatch.setattr(scan.ScanTarget, "first_hits", lambda self, o, d, **kw: traced.append(len(o)) or
                        real(self, o, d, **kw))
    with pytest.raises(LimitError, match="would return about.*scan_bytes"):
        scan_points(target, settings, limits=Limits(max_scan_bytes=int(0.5 * scan.POINT_BYTES * points)))
    assert sum(traced) <= scan.RETURN_SAMPLE
    # an estimate that misses: the points are counted as they come, and the scan stops
    monkeypatch.setattr(scan, "expected_points", lambda *a, **k: 0.0)
    with pytest.raises(LimitError, match="already returned.*scan_bytes"):
        scan_points(target, settings, limits=Limits(max_scan_bytes=int(0.5 * scan.POINT_BYTES * points)))
    assert len(scan_points(target, settings, limits=Limits(max_scan_bytes=2 * scan.POINT_BYTES * points))) == points
