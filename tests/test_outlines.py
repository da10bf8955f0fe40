"""Leaf outlines triangulated all at once (issue 44): :func:`triangulate_outlines` gives,
outline for outline and bit for bit, what :func:`triangulate` of each gives (vertices,
triangles in order, normal, or nothing), and :class:`PolygonBuilder` builds the same
polygons as triangulating each outline as it is added did."""

from __future__ import annotations

import numpy as np
import pytest

from plantgen.geometry.meshes import outlines as outlines_module
from plantgen.geometry.meshes.outlines import triangulate, triangulate_outlines
from plantgen.geometry.meshes.polygons import PolygonBuilder, Polygons


def _rotation(rng) -> np.ndarray:
    return np.linalg.qr(rng.normal(size=(3, 3)))[0]


def _hand_built() -> list[np.ndarray]:
    """Outlines of every kind the ear clipping meets: convex and concave, either winding,
    collinear corners, repeated points (the closing one too), no area, a figure eight (no
    Newell normal: the least-squares plane's), too few points, points not finite."""
    a = np.array
    return [a([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float),                               # a triangle
            a([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]], float),  # an L (concave)
            a([[0, 0, 0], [0, 2, 0], [1, 2, 0], [1, 1, 0], [2, 1, 0], [2, 0, 0]], float),  # the L clockwise
            a([[0, 0, 0], [1, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], float),            # a collinear corner
            a([[0, 0, 0], [0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 0]], float),  # repeated, closing
            a([[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3]], float),                       # no area
            a([[0, 0, 0], [1, 0, 0], [1, 1e-11, 0], [1, 1, 0], [0, 1, 0], [1e-11, 0, 0]]),   # near repeats
            a([[0, 0, 0], [1, 0, 0], [1, 1.5e-9, 0], [1, 1, 0], [0, 1, 0], [1e-8, 0, 0]]),   # kept apart
            a([[0, 0, 0], [1, 1, 0], [1, 0, 0], [0, 1, 0]], float),                       # a figure eight
            a([[0, 0, 0], [1, 0, 0], [1, 0, 0]], float),                                  # two distinct points
            a([[0, 0, 0], [2, 0, 0], [1, 0.5, 0], [2, 1, 0], [0, 1, 0], [1, 0.5, 0]], float),  # a bow tie
            a([[0, 0, 0], [1, 0, 0]], float), np.zeros((0, 3)),                           # under three points
            a([[0, 0, 0], [np.nan, 1, 0], [1, 0, 0]]), a([[0, 0, 0], [np.inf, 1, 0], [1, 0, 0], [2, 2, 2]])]


def _random(rng, count: int) -> list[np.ndarray]:
    """Stars (concave, either winding, turned anywhere, bent out of their plane a little),
    clouds of points (self-intersecting), grid points (collinear and repeated corners)."""
    out = []
    for _ in range(count):
        k = int(rng.integers(3, 10))
        ang, r = np.sort(rng.uniform(0, 2 * np.pi, k)), rng.uniform(0.2, 1.0, k)
        star = np.c_[r * np.cos(ang), r * np.sin(ang), rng.normal(0, 0.02, k)]
        out.append((star if rng.random() < 0.5 else star[::-1]) @ _rotation(rng) * 10.0 ** rng.uniform(-3, 3))
        out.append(rng.normal(size=(k, 3)))
        out.append(np.c_[np.round(rng.uniform(0, 3, (k, 2))), np.zeros(k)] @ _rotation(rng))
    return out


def _each(got, i: int):
    """Outline ``i`` of a Triangulated as triangulate gives one (None where dropped)."""
    if got.triangle_count[i] == 0:
        assert got.vertex_count[i] == 0 and not got.normal[i].any()
        return None
    v0, t0 = (int(np.sum(c[:i])) for c in (got.vertex_count, got.triangle_count))
    return (got.vertices[v0:v0 + got.vertex_count[i]], got.triangles[t0:t0 + got.triangle_count[i]], got.normal[i])


def _same(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return (a[0].shape == b[0].shape and a[0].tobytes() == b[0].tobytes() and a[1].shape == b[1].shape
            and np.array_equal(a[1], b[1]) and np.asarray(a[2], np.float64).tobytes() == b[2].tobytes())


def _large(rng) -> list[np.ndarray]:
    """Outlines of more points than a batch takes (BATCH_POINTS): a wavy ring, a star."""
    k = outlines_module.BATCH_POINTS + 9
    ang = np.linspace(0, 2 * np.pi, k, endpoint=False)
    r = 1 + 0.3 * np.sin(5 * ang) * rng.uniform(0.5, 1.0, k)
    return [np.c_[r * np.cos(ang), r * np.sin(ang), np.zeros(k)] @ _rotation(rng),
            np.c_[np.cos(ang) * (1 + (np.arange(k) % 2)), np.sin(ang) * (1 + (np.arange(k) % 2)), np.zeros(k)]]


@pytest.mark.parametrize("pairs", [None, 40])
def test_all_at_once_is_one_by_one_bit_for_bit(pairs, monkeypatch):
    """As triangulate of each, whole groups at once and (``pairs`` 40) a few outlines a call."""
    if pairs is not None:
        monkeypatch.setattr(outlines_module, "BATCH_PAIRS", pairs)
    rng = np.random.default_rng(44)
    outlines = _hand_built() + _random(rng, 400) + _large(rng)
    got = triangulate_outlines(outlines)
    expected = [triangulate(o) if len(o) >= 3 else None for o in outlines]
    wrong = [i for i, e in enumerate(expected) if not _same(e, _each(got, i))]
    assert not wrong, f"outlines {wrong[:10]} differ from triangulate's"
    # the cases are all there: dropped ones, concave ones clipped to k - 2 triangles, fans
    dropped = sum(e is None for e in expected)
    assert len(expected[6][0]) == 4 and len(expected[7][0]) == 6         # the near repeats merged, not the others
    assert 10 < dropped < len(outlines) // 2
    assert expected[1][1].tolist() != [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]]   # the L is not a fan
    assert len(got.vertices) == got.vertex_count.sum() and len(got.triangles) == got.triangle_count.sum()
    assert got.triangle_count[-2:].tolist() == [len(o) - 2 for o in outlines[-2:]]     # the large ones, whole


def test_an_outline_alone_and_among_others_is_the_same():
    """Grouping by point count does not change an outline: each of the hand-built ones
    triangulated alone, and all in reverse order, match."""
    outlines = _hand_built()
    together = triangulate_outlines(outlines)
    backwards = triangulate_outlines(outlines[::-1])
    for i, o in enumerate(outlines):
        alone = _each(triangulate_outlines([o]), 0)
        assert _same(alone, _each(together, i)) and _same(alone, _each(backwards, len(outlines) - 1 - i))


def test_nothing_to_triangulate():
    got = triangulate_outlines([])
    assert got.vertices.shape == (0, 3) and got.triangles.shape == (0, 3) and got.normal.shape == (0, 3)


def _one_by_one(entries) -> Polygons:
    """The polygons as the builder built them when each outline was triangulated as added."""
    parts, dropped = [], 0
    for kind, value, material, segment in entries:
        if kind == "outline":
            got = triangulate(value) if len(value) >= 3 else None
            if got is None:
                dropped += 1
                continue
            verts, tris, normal = got
            parts.append(Polygons(verts, tris, np.zeros(len(tris), np.int64), np.array([material], np.int32),
                                  normal[None], np.array([segment], np.int64)))
        else:
            parts.append(value)
    return Polygons.concatenate(parts), dropped


@pytest.mark.parametrize("seed", [0, 1])
def test_the_builder_keeps_the_order_of_outlines_and_placed_polygons(seed):
    """Outlines added around polygons already triangulated (extend) come out where they
    were added, their triangles, materials, normals and segments as before."""
    rng = np.random.default_rng(seed)
    outlines = _hand_built() + _random(rng, 30)
    rng.shuffle(outlines)
    placed = triangulate_outlines([np.array([[0, 0, 5], [1, 0, 5], [1, 1, 5], [0, 1, 5]], float)])
    surface = Polygons(placed.vertices, placed.triangles, np.zeros(2, np.int64), np.array([7], np.int32),
                       placed.normal, np.array([3], np.int64))
    entries = [("outline", o, int(rng.integers(0, 3)), int(rng.integers(-1, 9))) for o in outlines]
    entries[5:5] = [("placed", surface, 0, 0)]
    entries.append(("placed", surface, 0, 0))
    builder = PolygonBuilder()
    for kind, value, material, segment in entries:
        builder.add(value, material, segment) if kind == "outline" else builder.extend(value)
    got = builder.build()
    expected, dropped = _one_by_one(entries)
    assert builder.degenerate == dropped > 0
    for name in ("vertices", "triangles", "polygon", "material", "normal", "segment"):
        a, b = getattr(got, name), getattr(expected, name)
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), name


def test_a_builder_given_nothing_builds_nothing():
    builder = PolygonBuilder()
    builder.add(np.zeros((2, 3)), 0)
    assert len(builder.build()) == 0 and builder.degenerate == 1
