"""Leaves hang from segments and sway with them (issue 17).

The turtle records, for each polygon and placed surface, the last segment drawn on its
path (``Polygons.segment``); scenes renumber them as they join skeletons; a swaying
animation turns each leaf rigidly with that segment (about the segment's start, by the
segment's total turn), so the leaf keeps its distances to both ends of the segment.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from plantgen.animation import AnimatedScene
from plantgen.geometry.skeletons.motion import pose, sway_rig
from plantgen.lsystem.turtle import interpret_plant
from plantgen.pipeline import grow_file, prepare_model

TWIG = Path(__file__).parent / "data" / "leafy_twig.yaml"

SWAYING = """\
name: windy
seed: 3
effects: [animation]
instances:
  - grammar: leafy_twig.yaml
    position: [0, 0, 0]
    motion: {sway: {amplitude: 20, frequency: 0.7}}
  - grammar: leafy_twig.yaml
    position: [3, 0, 0]
  - grammar: leafy_twig.yaml
    position: [-3, 0, 1]
    motion: {sway: {amplitude: 12, frequency: 1.3, phase: 2.0}}
"""


def first_vertices(polygons) -> np.ndarray:
    """(p, 3) the first vertex of each polygon (the outline's start: where '{' was)."""
    first = np.full(len(polygons), -1)
    for tri, poly in zip(polygons.triangles, polygons.polygon, strict=True):
        first[poly] = tri.min() if first[poly] < 0 else min(first[poly], tri.min())
    return polygons.vertices[first]


def test_each_polygon_hangs_from_the_last_segment_on_its_path(tmp_path):
    # segments: 0 F, 1 F inside the branch, 2 F after it; a polygon in the branch hangs
    # from 1, one after a G move still from 2 (a move draws nothing), a surface from 2,
    # and one before any F from none
    from plantgen.lsystem.derive import derive
    from plantgen.lsystem.grammar import parse_grammar

    g = parse_grammar({"name": "t", "axiom": "{.G.+G.}F[+F{.G.+G.}]FG{.G.+G.}~(leaf, 0.5)", "rules": [],
                       "materials": ["bark"], "turtle": {"angle": 90}})
    d = interpret_plant(derive(g), g.turtle, g.materials)
    assert len(d.skeleton) == 3
    assert d.polygons.segment[:3].tolist() == [-1, 1, 2]
    assert set(d.polygons.segment[3:].tolist()) == {2}


def test_a_scenes_polygons_hang_from_its_joined_segments(tmp_path):
    shutil.copy(TWIG, tmp_path / "leafy_twig.yaml")
    (tmp_path / "windy.yaml").write_text(SWAYING)
    grown = grow_file(tmp_path / "windy.yaml")
    leaves, skeleton = grown.polygons, grown.skeleton
    assert len(leaves) == 3 * len(grow_file(TWIG).polygons) and np.all(leaves.segment >= 0)
    # the twig's leaves start where their segment ends ('[' right after 'F')
    assert np.allclose(first_vertices(leaves), skeleton.end[leaves.segment], atol=1e-12)


@pytest.mark.parametrize("t", [0.0, 0.4, 1.37])
def test_swaying_leaves_keep_their_place_on_their_segment(tmp_path, t):
    shutil.copy(TWIG, tmp_path / "leafy_twig.yaml")
    (tmp_path / "windy.yaml").write_text(SWAYING)
    model = prepare_model(tmp_path / "windy.yaml")
    rest, scene = model.grown.polygons, model.grown.scene
    model.anim.frusta_at(t)
    moved = model.anim.leaves_at(t)
    # the whole scene posed at t independently (still instances have no sway: unchanged)
    skeleton = scene.skeleton()
    posed = pose(skeleton, sway_rig(skeleton, scene.segment_instance(), [i.motion for i in scene.instances]), t)
    seg = rest.segment[rest.vertex_polygon]
    for ends_rest, ends_posed in ((skeleton.start, posed.start), (skeleton.end, posed.end)):
        before = np.linalg.norm(rest.vertices - ends_rest[seg], axis=1)
        after = np.linalg.norm(moved.vertices - ends_posed[seg], axis=1)
        assert np.allclose(before, after, rtol=0, atol=1e-12)
    still_instance = scene.segment_instance()[seg] == 1             # the copy without motion
    assert still_instance.any() and np.array_equal(moved.vertices[still_instance], rest.vertices[still_instance])
    if t > 0:
        assert np.abs(moved.vertices - rest.vertices).max() > 1e-3       # something moved
    # still attached where they grew, and each normal turned with its triangles
    assert np.allclose(first_vertices(moved), posed.end[moved.segment], atol=1e-12)
    a, b, c = (moved.vertices[moved.triangles[:, k]] for k in range(3))
    facing = np.einsum("ij,ij->i", np.cross(b - a, c - a), moved.normal[moved.polygon])
    assert np.all(facing > 0) and np.allclose(np.linalg.norm(moved.normal, axis=1), 1.0)


def test_a_still_model_keeps_its_leaves_as_grown():
    grown = grow_file(TWIG)
    anim = AnimatedScene.still(grown.skeleton, leaves=grown.polygons)
    assert anim.leaves_at(2.5) is grown.polygons
