"""Tree-level figures (plantgen.metrics) and branch structure (plantgen.geometry.skeletons.topology)
on shapes with known answers: cylinders, cones, leaning trunks, crowns of known area."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.topology import branches
from plantgen.metrics import CROWN_DIRECTIONS, crown_projection, geometry_bounds, segment_volumes, tree_metrics
from plantgen.pipeline import grow_file
from plantgen.tolerances import tol


def chain(points, radii, material=0) -> Skeleton:
    """One continuing chain through ``points`` with radii at the points."""
    points = np.asarray(points, dtype=float)
    n = len(points) - 1
    return Skeleton(points[:-1], points[1:], radii[:-1], radii[1:], np.arange(n) - 1, np.arange(n) > 0,
                    np.full(n, material), ("bark",))


def split(start, end, r1, r2, pieces) -> Skeleton:
    """A straight frustum cut into ``pieces`` continuing segments."""
    t = np.linspace(0, 1, pieces + 1)[:, None]
    return chain(np.asarray(start) + t * (np.asarray(end) - np.asarray(start)), r1 + (r2 - r1) * t[:, 0])


# ---------------------------------------------------------------------------- topology
def y_tree() -> Skeleton:
    """Trunk 0 -> 1 -> 2, a side branch 3 -> 4 from the top of segment 0, a branch 5 on it,
    and a second root 6 -> 7."""
    start = [[0, 0, 0], [0, 1, 0], [0, 2, 0], [0, 1, 0], [0.5, 1.5, 0], [1, 2, 0], [5, 0, 0], [5, 1, 0]]
    end = [[0, 1, 0], [0, 2, 0], [0, 3, 0], [0.5, 1.5, 0], [1, 2, 0], [1, 3, 0], [5, 1, 0], [5, 2, 0]]
    return Skeleton(start, end, np.full(8, 0.1), np.full(8, 0.1), [-1, 0, 1, 0, 3, 4, -1, 6],
                    [False, True, True, False, True, False, False, True], np.zeros(8), ("bark",))


def test_branches_orders_and_positions_of_a_known_tree():
    topo = branches(y_tree())
    assert topo.branch.tolist() == [0, 0, 0, 1, 1, 2, 3, 3]
    assert topo.position.tolist() == [0, 1, 2, 0, 1, 0, 0, 1]
    assert topo.order.tolist() == [0, 1, 2, 0]          # the second root is a trunk too
    assert topo.parent.tolist() == [-1, 0, 1, -1]
    assert topo.first.tolist() == [0, 3, 5, 6]
    assert topo.next.tolist() == [1, 2, -1, 4, -1, -1, 7, -1]
    assert [c.tolist() for c in topo.chains()] == [[0, 1, 2], [3, 4], [5], [6, 7]]


def test_a_second_continuing_child_starts_a_branch_of_its_own():
    skel = Skeleton([[0, 0, 0], [0, 1, 0], [0, 1, 0]], [[0, 1, 0], [0, 2, 0], [1, 2, 0]], [.1] * 3, [.1] * 3,
                    [-1, 0, 0], [False, True, True], [0] * 3)
    topo = branches(skel)
    assert topo.branch.tolist() == [0, 0, 1] and topo.order.tolist() == [0, 1]


def test_shipped_models_have_consistent_branches():
    for name in ("pine", "desert"):
        skel = grow_file(name).skeleton
        topo = branches(skel)
        chains = topo.chains()
        assert sum(len(c) for c in chains) == len(skel)
        for c in chains:                 # each chain is a path of continuing segments
            assert np.all(skel.parent[c[1:]] == c[:-1]) and np.all(skel.continues[c[1:]])
        roots = np.flatnonzero(skel.parent < 0)
        assert np.all(topo.order[topo.branch[roots]] == 0)
        side = topo.first[topo.parent >= 0]
        assert np.all(topo.order[topo.branch[side]] == topo.order[topo.branch[skel.parent[side]]] + 1)


# ---------------------------------------------------------------------------- bounds, volume, DBH
def test_the_well_is_as_tall_as_its_geometry():
    """Issue 16: grow said height 4.85 and min y -0.9 for a well spanning y 0..3.55."""
    skel = grow_file("well").skeleton
    box = geometry_bounds(skel)
    assert box[0, 1] == 0 and box[1, 1] == pytest.approx(3.55)
    assert np.allclose(box[:, [0, 2]], [[-1.35, -1.35], [1.35, 1.35]])
    assert tree_metrics(skel).height == pytest.approx(3.55)


@given(st.lists(st.floats(-3, 3), min_size=6, max_size=6), st.floats(0.05, 1), st.floats(0.0, 1))
@settings(max_examples=60, deadline=None)
def test_bounds_are_the_box_of_points_on_the_discs(ends, r1, r2):
    """The box touches the frustum: every sampled rim point lies inside it, and each face
    of the box is reached by a rim point (to the sampling's precision)."""
    start, end = np.array(ends[:3]), np.array(ends[3:])
    if np.linalg.norm(end - start) < 1e-3:
        return
    skel = Skeleton([start], [end], [r1], [r2], [-1], [False], [0])
    box = geometry_bounds(skel)
    axis = (end - start) / np.linalg.norm(end - start)
    u = np.cross(axis, [1, 0, 0] if abs(axis[0]) < 0.9 else [0, 1, 0])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    phi = np.linspace(0, 2 * np.pi, 20001)[:, None]
    rims = np.concatenate([start + r1 * (np.cos(phi) * u + np.sin(phi) * v),
                           end + r2 * (np.cos(phi) * u + np.sin(phi) * v)])
    assert np.all(rims >= box[0] - 1e-12 * (1 + np.abs(rims))) and np.all(rims <= box[1] + 1e-12 * (1 + np.abs(rims)))
    assert np.allclose(rims.min(axis=0), box[0], atol=1e-6) and np.allclose(rims.max(axis=0), box[1], atol=1e-6)


def test_a_cylinder_has_its_volume_and_its_diameter_at_breast_height():
    r, h = 0.25, 10.0
    for pieces in (1, 7):
        m = tree_metrics(split([0, 0, 0], [0, h, 0], r, r, pieces))
        assert m.volume == pytest.approx(np.pi * r * r * h)
        assert m.dbh == pytest.approx(2 * r) and m.height == pytest.approx(h)
        assert m.trunk_volume == pytest.approx(m.volume) and m.branch_volume == 0
        assert m.surface_area == pytest.approx(2 * np.pi * r * h)


def test_a_cone_has_a_third_of_its_cylinder_and_tapers_linearly():
    r, h = 0.4, 6.0
    for pieces in (1, 5):
        m = tree_metrics(split([0, 0, 0], [0, h, 0], r, 0.0, pieces))
        assert m.volume == pytest.approx(np.pi * r * r * h / 3)
        assert m.dbh == pytest.approx(2 * r * (1 - 1.3 / h))


def test_dbh_is_taken_along_a_leaning_trunk_and_follows_the_unit():
    lean = np.array([np.sin(0.5), np.cos(0.5), 0.0])
    skel = split([0, 0, 0], 4 * lean, 0.3, 0.1, 3)
    assert tree_metrics(skel).dbh == pytest.approx(2 * (0.3 + (0.1 - 0.3) * 1.3 / 4))
    # In centimetres (a unit is 0.01 m), breast height is 130 units: this trunk is shorter.
    assert tree_metrics(skel, unit=0.01).dbh is None
    assert tree_metrics(skel, unit=0.5).dbh == pytest.approx(2 * (0.3 - 0.2 * 2.6 / 4))


def test_a_trunk_shorter_than_breast_height_has_no_dbh():
    assert tree_metrics(grow_file("well").skeleton).dbh is None


def test_branch_and_trunk_volumes_add_up_on_a_shipped_tree():
    skel = grow_file("elm").skeleton
    m = tree_metrics(skel)
    assert m.trunk_volume + m.branch_volume == pytest.approx(m.volume)
    assert m.volume == pytest.approx(segment_volumes(skel).sum())
    assert m.trunk_length + m.branch_length == pytest.approx(m.length)
    assert m.branches == len(branches(skel)) - 1 and m.max_branch_order >= 2


# ---------------------------------------------------------------------------- crown
def test_the_crown_of_a_vertical_cylinder_is_its_disc():
    r = 1.5
    crown = crown_projection(split([1, 0, 2], [1, 5, 2], r, r, 1))
    assert crown.area == pytest.approx(np.pi * r * r, rel=2e-5)
    assert crown.max_width == pytest.approx(2 * r) and crown.mean_width == pytest.approx(2 * r, rel=2e-5)
    assert np.allclose(crown.polygon.mean(axis=0), [1, 2], atol=1e-6)


def test_the_crown_of_a_horizontal_cylinder_is_a_rectangle():
    length, r = 4.0, 0.5
    crown = crown_projection(split([0, 1, 0], [length, 1, 0], r, r, 2))
    assert crown.area == pytest.approx(2 * r * length, rel=1e-9)
    assert crown.max_width == pytest.approx(np.hypot(length, 2 * r), rel=1e-5)
    assert crown.mean_width == pytest.approx((2 * length + 4 * r) / np.pi, rel=1e-9)


def test_the_crown_of_two_trees_is_their_stadium():
    """Two vertical trunks of radius r, d apart: a stadium of area πr² + 2rd."""
    r, d = 0.5, 3.0
    a, b = split([0, 0, 0], [0, 2, 0], r, r, 1), split([d, 0, 0], [d, 3, 0], r, r, 1)
    crown = crown_projection(Skeleton.concatenate([a, b]))
    assert crown.area == pytest.approx(np.pi * r * r + 2 * r * d, rel=2e-5)
    assert crown.max_width == pytest.approx(d + 2 * r)


@given(st.lists(st.tuples(st.floats(-5, 5), st.floats(0, 5), st.floats(-5, 5), st.floats(-5, 5), st.floats(0, 5),
                          st.floats(-5, 5), st.floats(0.01, 1)), min_size=1, max_size=6))
@example([(1.2705465286743225e-155, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)])     # a unit axis 7e-15 too long
@example([(0.0, 0.0, 0.0, 0.0, 0.0, 6.098323116560077e-171, 1.0)])     # squares that underflow to 0
@example([(0.0, 0.0, 0.0, 0.0, 6.098323116560077e-171, 6.098323116560077e-171, 1.0)])
@example([(0.0, 0.0, 0.0, 0.0, 0.03125, 1.0, 1.0)])                    # a flat ellipse's narrow end
@settings(max_examples=40, deadline=None)
def test_the_crown_hull_holds_every_rim_point(segments):
    """Every point of every end disc projects inside the hull (up to its polygon's
    chordal slack), and the hull's area lies between the largest disc's and the box's."""
    start = np.array([s[:3] for s in segments])
    end = np.array([s[3:6] for s in segments])
    radius = np.array([s[6] for s in segments])
    skel = Skeleton(start, end, radius, radius, np.full(len(segments), -1), np.zeros(len(segments), bool),
                    np.zeros(len(segments)), ("bark",))
    crown = crown_projection(skel)
    poly = crown.polygon
    edges = np.roll(poly, -1, axis=0) - poly
    poly, edges = poly[np.linalg.norm(edges, axis=1) > 1e-12], edges[np.linalg.norm(edges, axis=1) > 1e-12]
    sense = np.sign(np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1]))
    box = geometry_bounds(skel)
    slack = 2e-4 * max(1.0, float(np.abs(box).max()))     # chords between support points
    # and the arc between two support points whose normals differ by 2π / CROWN_DIRECTIONS
    # lies within (L / 2)·tan(π / CROWN_DIRECTIONS) of their chord of length L (a flat
    # ellipse's narrow end: its support point runs fast between two sampled directions)
    length = np.linalg.norm(edges, axis=1)
    sagitta = 0.5 * length * np.tan(np.pi / CROWN_DIRECTIONS)
    for s, e, r in zip(start, end, radius, strict=True):
        axis = _direction(e - s)
        axis = np.array([0.0, 1.0, 0.0]) if axis is None else axis
        u = np.cross(axis, [1, 0, 0] if abs(axis[0]) < 0.9 else [0, 1, 0])
        u /= np.linalg.norm(u)
        v = np.cross(axis, u)
        phi = np.linspace(0, 2 * np.pi, 64)[:, None]
        for c in (s, e):
            rim = (c + r * (np.cos(phi) * u + np.sin(phi) * v))[:, [0, 2]]
            cross = sense * (edges[None, :, 0] * (rim[:, None, 1] - poly[None, :, 1])
                             - edges[None, :, 1] * (rim[:, None, 0] - poly[None, :, 0]))
            assert np.all(cross >= -(slack + sagitta) * length[None, :])
    span = box[1] - box[0]
    assert crown.area <= span[0] * span[2] + 1e-9
    # Each end disc projects to an ellipse of area πr²·|a_y| (a its unit normal).
    a_y = np.array([1.0 if (a := _direction(e - s)) is None else abs(a[1]) for s, e in zip(start, end, strict=True)])
    assert crown.area >= (np.pi * radius ** 2 * a_y).max() * (1 - 1e-4)


def _direction(axis):
    """The unit vector along ``axis``, scaled by its largest component first (a segment
    1e-171 long has squares that underflow to 0), or None where it is no longer than
    ``tol.tiny`` (a segment of no direction: its discs count as balls)."""
    big = float(np.abs(axis).max())
    if big == 0:
        return None
    scaled = axis / big
    length = np.linalg.norm(scaled)
    return None if big * length <= tol.tiny else scaled / length


@pytest.mark.parametrize("name", ["pine", "abop_bush", "oasis"])
def test_the_crown_leaves_out_only_discs_that_cannot_reach_its_hull(name, monkeypatch):
    """The crown's pruning (discs deeper inside the centres' hull than their radius) is
    exact: the same polygon, area and widths as with every disc, and it does leave many out."""
    import plantgen.metrics as metrics

    skeleton = grow_file(name).skeleton
    pruned = metrics.crown_projection(skeleton)
    centres, _, radii = metrics.end_discs(skeleton)
    kept = metrics.may_reach_hull(centres[:, [0, 2]] - centres.mean(axis=0)[[0, 2]], radii)
    assert kept.sum() < 0.5 * len(kept)
    monkeypatch.setattr(metrics, "may_reach_hull", lambda xz, r: np.ones(len(xz), dtype=bool))
    full = metrics.crown_projection(skeleton)
    assert np.array_equal(pruned.polygon, full.polygon)
    assert (pruned.area, pruned.max_width, pruned.mean_width) == (full.area, full.max_width, full.mean_width)
