"""Tree metrics (plantgen.metrics) against independent definitions, worked out here from
the skeleton's arrays alone: wood volume as the sum of frustum volumes, height from the
base to the highest surface point (dense rim samples), DBH 1.3 m along the stem (the
chain walked here from parent/continues), crown projection area and widths (the convex
hull of dense rim samples, scipy's). On shapes with known answers (a cylinder, a cone, a
frustum chain, a hand-built Y tree) and on shipped grammars; the QSM export's cylinders
give the same volume and DBH within the bounds their tolerance implies."""

from __future__ import annotations

import numpy as np
import pytest
from _geometry_helpers import chain_skeleton
from scipy.spatial import ConvexHull

from plantgen.exporters.qsm import cylinder_model
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.metrics import tree_metrics
from plantgen.pipeline import grow_file

RIM = 720          # samples around each end disc


# ---------------------------------------------------------------------------- the definitions, here
def frustum_volume(skel: Skeleton) -> float:
    h = np.sqrt(((skel.end - skel.start) ** 2).sum(axis=1))
    r1, r2 = skel.r_start, skel.r_end
    return float((np.pi * h * (r1 ** 2 + r1 * r2 + r2 ** 2) / 3).sum())


def rim_points(skel: Skeleton, samples: int = RIM) -> np.ndarray:
    """(2n·samples, 3) points around both end discs of every segment."""
    axis = skel.end - skel.start
    axis = axis / np.linalg.norm(axis, axis=1, keepdims=True)
    helper = np.where(np.abs(axis[:, :1]) < 0.9, [[1.0, 0, 0]], [[0.0, 0, 1]])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(axis, u)
    phi = np.linspace(0, 2 * np.pi, samples, endpoint=False)[None, :, None]
    ring = np.cos(phi) * u[:, None] + np.sin(phi) * v[:, None]
    return np.concatenate([(skel.start[:, None] + skel.r_start[:, None, None] * ring).reshape(-1, 3),
                           (skel.end[:, None] + skel.r_end[:, None, None] * ring).reshape(-1, 3)])


def sampled_height(skel: Skeleton) -> tuple[float, float]:
    """(height from the base point to the highest rim sample, how far the samples may fall
    short of the true top: the largest radius times 1 - cos(π/RIM))."""
    top = rim_points(skel)[:, 1].max()
    return float(top - skel.start[0, 1]), float(max(skel.r_start.max(), skel.r_end.max()) * (1 - np.cos(np.pi / RIM)))


def stem(skel: Skeleton) -> list[int]:
    """The stem: segment 0, then each time its first continuing child (in index order)."""
    out = [0]
    while True:
        kids = np.flatnonzero((skel.parent == out[-1]) & skel.continues)
        if not len(kids):
            return out
        out.append(int(kids[0]))


def dbh_along_stem(skel: Skeleton, breast: float = 1.3) -> float | None:
    walked = 0.0
    for s in stem(skel):
        length = float(np.linalg.norm(skel.end[s] - skel.start[s]))
        if walked + length >= breast:
            t = (breast - walked) / length
            return 2 * float(skel.r_start[s] + t * (skel.r_end[s] - skel.r_start[s]))
        walked += length
    return None


def sampled_crown(skel: Skeleton) -> tuple[float, float, float]:
    """(area, largest width, perimeter / π) of the convex hull of the rims' vertical
    projection (x, z)."""
    xz = rim_points(skel)[:, [0, 2]]
    hull = ConvexHull(xz)
    corners = xz[hull.vertices]
    width = np.sqrt(((corners[:, None] - corners[None]) ** 2).sum(axis=-1)).max()
    return float(hull.volume), float(width), float(hull.area / np.pi)      # 2-d: volume is the area


def qsm_dbh(model) -> float | None:
    """TreeQSM's DBHqsm: the diameter of the first trunk cylinder where the trunk's summed
    cylinder lengths reach 1.3 m (tree_data.m); None where they never do."""
    trunk = np.flatnonzero(model.branch == 0)
    trunk = trunk[np.argsort(model.position[trunk])]
    reach = np.cumsum(model.length[trunk])
    if reach[-1] < 1.3:
        return None
    return float(2 * model.radius[trunk[np.searchsorted(reach, 1.3)]])


def check_against_definitions(skel: Skeleton, *, crown_rel=2e-5):
    m = tree_metrics(skel)
    assert m.volume == pytest.approx(frustum_volume(skel), rel=1e-12)
    height, slack = sampled_height(skel)
    assert height <= m.height + 1e-12 and m.height <= height + slack + 1e-12
    want = dbh_along_stem(skel)
    assert (m.dbh is None) == (want is None)
    if want is not None:
        assert m.dbh == pytest.approx(want, rel=1e-12)
    area, width, mean_width = sampled_crown(skel)
    assert m.crown.area == pytest.approx(area, rel=crown_rel)
    assert m.crown.max_width == pytest.approx(width, rel=crown_rel)
    assert m.crown.mean_width == pytest.approx(mean_width, rel=crown_rel)
    return m


# ---------------------------------------------------------------------------- known shapes
def test_a_cylinder():
    r, h = 0.2, 5.0
    m = check_against_definitions(chain_skeleton((), lengths=h, radii=r))
    assert m.volume == pytest.approx(np.pi * r * r * h) and m.height == pytest.approx(h)
    assert m.dbh == pytest.approx(2 * r) and m.crown.area == pytest.approx(np.pi * r * r, rel=2e-5)
    assert m.crown.max_width == pytest.approx(2 * r)


def test_a_cone():
    r, h = 0.5, 4.0
    m = check_against_definitions(chain_skeleton((), lengths=h, radii=[r, 0.0]))
    assert m.volume == pytest.approx(np.pi * r * r * h / 3)
    assert m.dbh == pytest.approx(2 * r * (1 - 1.3 / h))


def test_a_bent_tapering_frustum_chain():
    skel = chain_skeleton((25, 40, 30), lengths=[0.8, 0.7, 1.2, 0.9], radii=[0.3, 0.27, 0.2, 0.12, 0.05],
                          plane_turn_deg=70)
    m = check_against_definitions(skel)
    # 1.3 along the stem falls in the second segment, 0.5 into it
    assert m.dbh == pytest.approx(2 * (0.27 + 0.5 / 0.7 * (0.2 - 0.27)))
    # the chain bends away from the vertical: its top is lower than its length
    assert m.height < 3.6


def y_tree() -> Skeleton:
    """A two-segment trunk, a side branch from its top joint with a branch of its own, and a
    continuing top: built by hand."""
    start = [[0, 0, 0], [0, 1.0, 0], [0, 2.0, 0], [0, 2.0, 0], [0.8, 2.6, 0.1], [0.8, 2.6, 0.1]]
    end = [[0, 1.0, 0], [0, 2.0, 0], [0.1, 3.2, 0], [0.8, 2.6, 0.1], [1.5, 3.4, 0.4], [0.9, 2.7, 1.0]]
    r_s = [0.25, 0.22, 0.18, 0.1, 0.08, 0.05]
    r_e = [0.22, 0.18, 0.06, 0.08, 0.03, 0.02]
    return Skeleton(start, end, r_s, r_e, [-1, 0, 1, 1, 3, 3], [False, True, True, False, True, False],
                    [0] * 6)


def test_a_y_tree_built_by_hand():
    skel = y_tree()
    m = check_against_definitions(skel)
    trunk = [0, 1, 2]
    h = np.linalg.norm(skel.end - skel.start, axis=1)
    r1, r2 = skel.r_start, skel.r_end
    per = np.pi * h * (r1 ** 2 + r1 * r2 + r2 ** 2) / 3
    assert m.trunk_volume == pytest.approx(per[trunk].sum()) and m.branch_volume == pytest.approx(per[3:].sum())
    assert m.dbh == pytest.approx(2 * (0.22 + 0.3 * (0.18 - 0.22)))
    assert m.branches == 2 and m.max_branch_order == 2


def test_height_counts_from_the_base_not_from_what_hangs_below_it():
    """A drooping branch reaching 0.8 below the base: the box is 0.8 deeper, the height is
    still base to top (the fix: the height was the box's extent)."""
    start = [[0, 0, 0], [0, 2, 0]]
    end = [[0, 2, 0], [1.5, -0.8, 0]]
    skel = Skeleton(start, end, [0.2, 0.05], [0.15, 0.05], [-1, 0], [False, False], [0, 0])
    m = check_against_definitions(skel)
    assert m.bounds[0, 1] < -0.8 and m.height == pytest.approx(m.bounds[1, 1], abs=1e-15)
    assert m.height < 2.05 and m.bounds[1, 1] - m.bounds[0, 1] > 2.8       # not the box's extent
    lean = chain_skeleton((), lengths=3.0, radii=0.4)
    tilted = lean.transformed(np.array([[np.cos(0.3), -np.sin(0.3), 0, 0], [np.sin(0.3), np.cos(0.3), 0, 0],
                                        [0, 0, 1, 0], [0, 0, 0, 1.0]]))
    m = check_against_definitions(tilted)          # the base disc dips below the base point
    assert m.bounds[0, 1] < -0.1 and m.height == pytest.approx(m.bounds[1, 1])


def test_metres_convert_by_the_unit():
    skel = chain_skeleton((), lengths=300.0, radii=20.0)        # centimetres: 3 m tall, 0.4 m across
    m = tree_metrics(skel, unit=0.01)
    got = m.as_dict(metres=True)
    assert got["units"] == "m" and got["height"] == pytest.approx(3.0) and got["dbh"] == pytest.approx(0.4)
    assert got["volume"] == pytest.approx(np.pi * 0.2 ** 2 * 3) and got["crown_area"] == pytest.approx(
        np.pi * 0.04, rel=2e-5)
    assert m.as_dict()["units"] == "model" and m.as_dict()["height"] == pytest.approx(300.0)


# ---------------------------------------------------------------------------- grown plants
@pytest.mark.parametrize("name", ["saguaro", "elm", "pine", "broadleaf", "abop_monopodial", "abop_bush"])
def test_shipped_plants_meet_the_definitions(name):
    check_against_definitions(grow_file(name).skeleton, crown_rel=5e-5)


# ---------------------------------------------------------------------------- the cylinder model
@pytest.mark.parametrize("name, tolerance", [("y", 1e-3), ("saguaro", 1e-3), ("pine", 1e-3), ("elm", 1e-4),
                                             ("abop_monopodial", 1e-2)])
def test_the_cylinder_model_gives_the_volume_and_dbh_within_its_tolerance(name, tolerance):
    """The QSM's cylinders lack at most ``tolerance`` of each frustum's volume, so of the
    total; TreeQSM's DBH (the cylinder where 1.3 m is reached) is the frustum's radius at
    that cylinder's middle, off the exact DBH by at most the radius change over the
    cylinder: Δr/k = 2·sqrt(tolerance·(r1² + r1·r2 + r2²)) for its segment."""
    skel = y_tree() if name == "y" else grow_file(name).skeleton
    model = cylinder_model(skel, tolerance)
    exact = frustum_volume(skel)
    assert 0 <= 1 - model.volume.sum() / exact <= tolerance * (1 + 1e-9)
    m = tree_metrics(skel)
    dbh = qsm_dbh(model)
    assert (dbh is None) == (m.dbh is None)
    if dbh is not None:
        trunk = np.flatnonzero(model.branch == 0)
        trunk = trunk[np.argsort(model.position[trunk])]
        seg = model.segment[trunk[np.searchsorted(np.cumsum(model.length[trunk]), 1.3)]]
        r1, r2 = skel.r_start[seg], skel.r_end[seg]
        bound = 2 * np.sqrt(tolerance * (r1 * r1 + r1 * r2 + r2 * r2))
        assert abs(dbh - m.dbh) <= bound * (1 + 1e-9)
