"""The stand's world (plantgen.environment.together): the other plants' skeletons a
plant's light gathers are the placed skeletons but its own, joined as
Skeleton.concatenate joins them (each array and its dtype, the material names), whether
the plants share their material names (the rows of all joined once, the plant's cut out)
or not (joined part by part), and whichever plants are not drawn yet."""

from __future__ import annotations

import numpy as np
import pytest
from _geometry_helpers import random_tree

from plantgen.environment import together
from plantgen.geometry.meshes.polygons import Polygons
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.lsystem.grammar import parse_grammar

FIELDS = ("start", "end", "r_start", "r_end", "parent", "continues", "material")


def _matrix(angle, x):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0, s, x], [0, 1, 0, 0], [-s, 0, c, 0.3 * x], [0, 0, 0, 1.0]])


@pytest.mark.parametrize("names", ["shared", "different"])
def test_the_others_are_the_placed_skeletons_but_ones_own_joined_in_order(names):
    grammar = parse_grammar({"axiom": "F", "rules": []})
    plants = [together.TogetherPlant(grammar, s, None, _matrix(0.4 * s, 1.5 * s)) for s in range(4)]
    world = together._World(plants)
    trees = [random_tree(n, seed=n) for n in (12, 25, 7, 30)]
    if names == "different":
        trees[1] = Skeleton(trees[1].start, trees[1].end, trees[1].r_start, trees[1].r_end, trees[1].parent,
                            trees[1].continues, np.ones(len(trees[1]), np.int32), ("leafwood", "bark"))
    for i in (0, 1, 3):                                  # plant 2 not drawn yet
        world.put(i, trees[i], Polygons.empty())
    for i in range(4):
        parts = [world.placed[j].skeleton for j in range(4) if j != i and world.placed[j] is not None]
        want = Skeleton.concatenate(parts).transformed(np.linalg.inv(plants[i].matrix))
        got = world.others(i).skeleton
        assert got.material_names == want.material_names
        for name in FIELDS:
            a, b = getattr(got, name), getattr(want, name)
            assert a.dtype == b.dtype and np.array_equal(a, b), name
        assert len(got) == sum(len(p) for p in parts)
    world.put(1, trees[2], Polygons.empty())             # a plant moves: the joined rows follow
    got = world.others(0).skeleton
    assert len(got) == len(trees[2]) + len(trees[3])
