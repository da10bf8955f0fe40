"""Issue 17: the skeleton drawings (``python -m plantgen.benchmarks.draw_skeletons``) show
a model's leaf polygons, filled in their material's colour where they project, painted
with the segments from far to near; a leafless model has no leaf pixels."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from plantgen.benchmarks.draw_skeletons import (
    BACKGROUND,
    LEAF_GREEN,
    MATERIAL_COLOURS,
    draw_skeleton,
    main,
    panel_projection,
)
from plantgen.geometry.meshes.polygons import Polygons, triangulate
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.pipeline import grow_file

TWIG = Path(__file__).parent / "data" / "leafy_twig.yaml"
PANEL = 300
BARK = MATERIAL_COLOURS["bark"]
LEAF_RIM = tuple(int(c * 0.6) for c in LEAF_GREEN)     # the outline's darker shade


def colour_mask(image: np.ndarray, *colours) -> np.ndarray:
    return np.any([np.all(image == c, axis=-1) for c in colours], axis=0)


def projected_triangles(corners_px: np.ndarray, shape, reach: float = 0.0) -> np.ndarray:
    """(h, w) bool: pixel centres (integer coordinates) inside any of the (t, 3, 2)
    triangles, or within ``reach`` pixels of one (a leaf seen edge-on covers no centre)."""
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]]
    p = np.stack([cols, rows], axis=-1).astype(float)
    out = np.zeros(shape, dtype=bool)
    for a, b, c in corners_px:
        d = [(q[0] - o[0]) * (p[..., 1] - o[1]) - (q[1] - o[1]) * (p[..., 0] - o[0])
             for o, q in ((a, b), (b, c), (c, a))]
        out |= (np.all([x >= 0 for x in d], axis=0) | np.all([x <= 0 for x in d], axis=0))
        for o, q in ((a, b), (b, c), (c, a)):           # distance to each edge
            e = q - o
            s = np.clip(((p - o) @ e) / max(float(e @ e), 1e-12), 0.0, 1.0)
            out |= np.linalg.norm(p - (o + s[..., None] * e), axis=-1) <= reach
    return out


@pytest.fixture(scope="module")
def twig():
    return grow_file(TWIG)


@pytest.fixture(scope="module")
def bare_twig(tmp_path_factory):
    path = tmp_path_factory.mktemp("bare") / "bare_twig.yaml"
    path.write_text(TWIG.read_text().replace("{.+G.-G.-G.+|+G.-G.-G.}", ""))
    grown = grow_file(path)
    assert len(grown.polygons) == 0
    return grown


def test_a_leafy_twig_shows_its_leaves_where_they_project(twig):
    image = np.asarray(draw_skeleton(twig.skeleton, "twig", PANEL, polygons=twig.polygons))
    points = np.concatenate([twig.skeleton.start, twig.skeleton.end, twig.polygons.vertices])
    corners = twig.polygons.vertices[twig.polygons.triangles]
    projected = [panel_projection(points, PANEL, k)[0](corners) for k in range(3)]
    near = np.any([projected_triangles(px, image.shape[:2], reach=2.0) for px in projected], axis=0)
    # leaf colours only where a leaf projects in one of the views (within two pixels:
    # Pillow draws the outline between whole pixels) ...
    assert not np.any(colour_mask(image, LEAF_GREEN, LEAF_RIM) & ~near)
    for where in (projected_triangles(px, image.shape[:2]) for px in projected):
        assert where.sum() > 500                        # the leaves cover a good part of each view
        # ... and inside a leaf, leaf (or the stem, where it passes in front), nothing else
        inside = ndimage.binary_erosion(where, iterations=2)
        assert np.all(colour_mask(image, LEAF_GREEN, LEAF_RIM, BARK)[inside])
        assert np.all(image[inside] == LEAF_GREEN, axis=-1).mean() > 0.8


def test_a_leafless_twig_has_no_leaf_pixels(twig, bare_twig):
    assert np.array_equal(bare_twig.skeleton.start, twig.skeleton.start)     # the same stem
    image = np.asarray(draw_skeleton(bare_twig.skeleton, "bare", PANEL, polygons=bare_twig.polygons))
    assert not colour_mask(image, LEAF_GREEN, LEAF_RIM).any()
    assert colour_mask(image, BARK).sum() > 100
    # no leaves: the drawing is the skeleton's alone
    alone = np.asarray(draw_skeleton(bare_twig.skeleton, "bare", PANEL))
    assert np.array_equal(image, alone)


@pytest.mark.parametrize("leaf_z, seen", [(1.0, LEAF_GREEN), (-1.0, BARK)])
def test_a_leaf_in_front_of_a_branch_hides_it_and_behind_it_is_hidden(leaf_z, seen):
    # a thick upright post at z = 0, a square leaf across it at z = leaf_z (the front view
    # looks from +z; the side view from -x sees both edge-on)
    skel = Skeleton(np.array([[0.0, 0, 0]]), np.array([[0.0, 2, 0]]), np.array([0.2]), np.array([0.2]),
                    np.array([-1]), np.array([False]), np.array([0]), ("bark", "leaf"))
    verts, tris, normal = triangulate([[-0.5, 0.5, leaf_z], [0.5, 0.5, leaf_z], [0.5, 1.0, leaf_z],
                                       [-0.5, 1.0, leaf_z]])
    leaf = Polygons(verts, tris, np.zeros(len(tris), np.int64), np.array([1], np.int32), normal[None])
    image = np.asarray(draw_skeleton(skel, "", PANEL, polygons=leaf))
    points = np.concatenate([skel.start, skel.end, leaf.vertices])
    front, _ = panel_projection(points, PANEL, 0)
    col, row = np.round(front(np.array([0.0, 0.75, 0.0]))).astype(int)
    assert tuple(image[row, col]) == seen
    # beside the post, the leaf shows either way; above it, the post
    col, row = np.round(front(np.array([0.4, 0.75, 0.0]))).astype(int)
    assert tuple(image[row, col]) == LEAF_GREEN
    col, row = np.round(front(np.array([0.0, 1.5, 0.0]))).astype(int)
    assert tuple(image[row, col]) == BARK
    assert tuple(image[2, 2]) == BACKGROUND


def test_leaves_take_their_materials_colour():
    skel = Skeleton(np.array([[0.0, 0, 0]]), np.array([[0.0, 1, 0]]), np.array([0.05]), np.array([0.05]),
                    np.array([-1]), np.array([False]), np.array([0]), ("bark", "stone", "petal"))
    verts, tris, normal = triangulate([[0.2, 0.2, 0], [1.0, 0.2, 0], [1.0, 0.8, 0], [0.2, 0.8, 0]])
    polygons = [Polygons(verts, tris, np.zeros(len(tris), np.int64), np.array([m], np.int32), normal[None])
                for m in (1, 2)]
    points = np.concatenate([skel.start, skel.end, verts])
    front, _ = panel_projection(points, PANEL, 0)
    col, row = np.round(front(np.array([0.6, 0.5, 0.0]))).astype(int)
    stone = np.asarray(draw_skeleton(skel, "", PANEL, polygons=polygons[0]))
    petal = np.asarray(draw_skeleton(skel, "", PANEL, polygons=polygons[1]))
    assert tuple(stone[row, col]) == MATERIAL_COLOURS["stone"]
    assert tuple(petal[row, col]) == LEAF_GREEN           # a name the drawing has no colour for


def test_the_command_draws_a_shipped_model(tmp_path, capsys):
    assert main([str(tmp_path), "saguaro", "--panel", "120"]) == 0
    assert (tmp_path / "saguaro.png").is_file()
    assert "30 segments" in capsys.readouterr().out
