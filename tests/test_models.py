"""The shipped models of the paper's Table 1 (issue 2) and the classic ABOP trees.

Every shipped grammar and scene grows into a valid skeleton with sane geometry (finite,
radii >= 0, no degenerate segments, side branches no thicker than what they grow from,
plausible sizes in metres, y up); each Table 1 model's segment count (its paper variant,
as the bench grows it: ``plantgen.table1.models.PAPER_VARIANTS``) is within 10 % of the
paper's; growth is deterministic for a seed and, where the model is stochastic, differs
for another seed; scenes ask for the effects the paper rendered them with. Each model is
grown once per process (module cache) to keep the file fast.
"""

from __future__ import annotations

import dataclasses
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from plantgen._resources import grammars_dir
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.lsystem.derive import derive
from plantgen.lsystem.grammar import load_grammar
from plantgen.lsystem.turtle import interpret
from plantgen.pipeline import GrowResult, grow_file
from plantgen.table1.models import PAPER_VARIANTS

# Bhagvat et al. 2009, Table 1: segments per model
TABLE1 = {
    "coconut": 3713, "pine": 16997, "elm": 1833, "aloe": 229, "saguaro": 30,
    "well": 8, "desert": 799, "oasis": 18557, "dancing_cacti": 2158,
}
SCENES = {"well", "desert", "oasis", "dancing_cacti"}
EXTRAS = {"abop_monopodial", "abop_sympodial", "abop_ternary", "cactus", "ocotillo",
          "abop_bush", "broadleaf", "pine_needles", "pine_sprays"}   # the last four with leaves
DETERMINISTIC = {"well", "abop_monopodial", "abop_sympodial", "abop_ternary", "abop_bush"}
ALL_MODELS = sorted(set(TABLE1) | EXTRAS)
#: Grown in an environment (?E): checked here as skeletons, and by what they mean in
#: tests/test_environment.py and tests/test_light.py.
ENVIRONMENT = ("topiary", "wall_tree", "wall_garden", "colonised", "self_organizing", "stand")

# plausible overall heights in metres (y extent of the segment axes)
HEIGHTS = {
    "saguaro": (8, 12), "pine": (20, 30), "coconut": (15, 30), "elm": (15, 30),
    "aloe": (0.25, 1.0), "cactus": (1.5, 4), "ocotillo": (2.5, 6), "well": (3, 5),
    "abop_bush": (1, 2.5), "broadleaf": (8, 16), "pine_needles": (20, 30), "pine_sprays": (20, 30),
}


@cache
def grown(name: str, seed: int | None = None) -> GrowResult:
    return grow_file(grammars_dir() / f"{name}.yaml", seed=seed)


@cache
def paper_variant(name: str) -> GrowResult:
    """A Table 1 model as the bench grows it (the pine without foliage, the aloe's round leaves)."""
    return grow_file(grammars_dir() / f"{name}.yaml", defines=PAPER_VARIANTS.get(name))


def _axis_height(skel: Skeleton) -> float:
    ys = np.concatenate([skel.start[:, 1], skel.end[:, 1]])
    return float(ys.max() - ys.min())


def _childless(skel: Skeleton) -> np.ndarray:
    """(n,) bool: segments from which nothing grows (the apices)."""
    has_child = np.zeros(len(skel), dtype=bool)
    has_child[skel.parent[skel.parent >= 0]] = True
    return ~has_child


def test_every_shipped_model_is_covered():
    shipped = {p.stem for p in Path(grammars_dir()).glob("*.yaml")}
    assert set(ALL_MODELS) | set(ENVIRONMENT) <= shipped


@pytest.mark.parametrize("name", [*ALL_MODELS, *ENVIRONMENT])
def test_model_grows_into_a_sane_skeleton(name):
    res = grown(name)
    skel = res.skeleton
    assert len(skel) > 0
    skel.validate(tol=1e-6)
    for arr in (skel.start, skel.end, skel.r_start, skel.r_end):
        assert np.all(np.isfinite(arr))
    assert skel.r_start.min() >= 0 and skel.r_end.min() >= 0
    length = np.linalg.norm(skel.end - skel.start, axis=1)
    assert length.min() > 1e-3, "zero-length or degenerate segment"
    assert length.max() < 10.0, "absurdly long segment"
    assert skel.r_start.max() < 2.0 and skel.r_end.max() < 2.0
    # everything stands on the ground (y = 0), nothing sinks below it
    assert skel.start[:, 1].min() >= -1e-9 and skel.end[:, 1].min() >= -1e-9
    assert set(skel.material_names) <= {"bark", "leaf", "cactus", "aloe", "stone", "stem", "needle"}


@pytest.mark.parametrize("name", sorted(TABLE1))
def test_table1_segment_count_within_ten_percent(name):
    n = len(paper_variant(name).skeleton)
    paper = TABLE1[name]
    assert abs(n - paper) <= 0.10 * paper, f"{name}: {n} segments, paper {paper}"


@pytest.mark.parametrize("name", sorted(HEIGHTS))
def test_model_has_a_realistic_height(name):
    lo, hi = HEIGHTS[name]
    assert lo <= _axis_height(grown(name).skeleton) <= hi


@pytest.mark.parametrize("name", [*ALL_MODELS, *ENVIRONMENT])
def test_side_branches_are_no_thicker_than_their_parent(name):
    skel = grown(name).skeleton
    side = np.flatnonzero((skel.parent >= 0) & ~skel.continues)
    parent_r = np.maximum(skel.r_start[skel.parent[side]], skel.r_end[skel.parent[side]])
    assert np.all(skel.r_start[side] <= parent_r * (1 + 1e-9))


@pytest.mark.parametrize("name", ["coconut", "pine", "elm", "aloe", "saguaro", "cactus"])
def test_axes_taper_from_base_to_tip(name):
    """Along each continuing chain the radius never grows (a plant thins towards its tips)."""
    skel = grown(name).skeleton
    cont = np.flatnonzero(skel.continues)
    assert np.all(skel.r_end[cont] <= skel.r_start[cont] * (1 + 1e-9))
    apex = _childless(skel)
    assert skel.r_end[apex].max() < skel.r_start[skel.parent < 0].max()


def _count_F(ms) -> int:
    return int(np.count_nonzero(ms.sym == ms.symbols.index("F")))


@pytest.mark.parametrize("name", sorted(set(ALL_MODELS) - SCENES - {"abop_monopodial", "abop_sympodial",
                                                                     "abop_ternary", "abop_bush"}))
def test_default_iterations_finish_growth(name):
    """More derivation steps add nothing: the count is the grown plant's, not a cut-off.

    (The ABOP trees grow for ever; the book stops them after n steps.)
    """
    grammar = load_grammar(grammars_dir() / f"{name}.yaml")
    assert _count_F(derive(grammar, iterations=grammar.iterations + 3)) == _count_F(derive(grammar))


@pytest.mark.parametrize("name", ALL_MODELS)
def test_same_seed_gives_the_same_model(name):
    a = grown(name).skeleton
    b = grow_file(grammars_dir() / f"{name}.yaml").skeleton
    for field in ("start", "end", "r_start", "r_end", "parent", "continues", "material"):
        assert np.array_equal(getattr(a, field), getattr(b, field)), field


@pytest.mark.parametrize("name", sorted(set(ALL_MODELS) - DETERMINISTIC))
def test_another_seed_gives_another_plant(name):
    a, b = grown(name).skeleton, grown(name, seed=12345).skeleton
    assert len(a) != len(b) or not np.allclose(a.end, b.end)


@pytest.mark.parametrize("name", sorted(DETERMINISTIC - SCENES))
def test_deterministic_grammars_ignore_the_seed(name):
    """The ABOP trees have no random draws: every seed gives the same tree."""
    assert np.array_equal(grown(name).skeleton.end, grown(name, seed=12345).skeleton.end)


@pytest.mark.parametrize("name", sorted(SCENES))
def test_scenes_ask_for_the_papers_effects(name):
    scene = grown(name).scene
    assert scene is not None
    assert "shadows" in scene.effects and "relief" in scene.effects
    assert ("animation" in scene.effects) == (name == "dancing_cacti")
    assert scene.ground is not None and scene.ground.material in {"sand", "grass"}
    # the ground holds every instance's footprint
    world = scene.skeleton()
    half = scene.ground.size / 2
    assert np.abs(world.start[:, [0, 2]]).max() < half


def test_dancing_cacti_are_a_hundred_different_swaying_cacti():
    scene = grown("dancing_cacti").scene
    assert len(scene.instances) == 100
    assert all(i.source == "cactus" for i in scene.instances)
    counts = np.array([len(i.skeleton) for i in scene.instances])
    assert counts.min() >= 20 and counts.max() <= 24 and len(set(counts.tolist())) > 1
    assert abs(counts.mean() - 21.58) < 1.0
    phases = [i.motion.phase for i in scene.instances]
    assert all(i.motion.amplitude > 0 for i in scene.instances)
    assert len(set(phases)) == 100, "every cactus sways on its own phase"
    heights = {round(_axis_height(i.skeleton), 6) for i in scene.instances}
    assert len(heights) > 50, "cacti should differ in shape"


def test_oasis_is_mostly_leaves():
    skel = grown("oasis").skeleton
    leaf = skel.material_names.index("leaf")
    assert np.mean(skel.material == leaf) > 0.5


def test_coconut_fronds_carry_thin_leaflets():
    skel = grown("coconut").skeleton
    leaf = np.asarray(skel.material) == skel.material_names.index("leaf")
    bark = ~leaf
    assert leaf.sum() > 0.5 * len(skel)
    assert skel.r_start[leaf].max() < 0.1 * skel.r_start[bark].max()
    # leaflets hang from the crown: all of them above two thirds of the palm's height
    assert skel.end[leaf, 1].min() > 0.6 * _axis_height(skel)


def test_pine_tropism_makes_branches_sag():
    """The same derived string drawn without tropism puts the branch tips higher up."""
    grammar = load_grammar(grammars_dir() / "pine.yaml")
    assert grammar.turtle.tropism_strength > 0 and grammar.turtle.tropism_direction[1] < 0
    ms = derive(grammar)
    with_tropism = interpret(ms, grammar.turtle, grammar.materials)
    straight = interpret(ms, dataclasses.replace(grammar.turtle, tropism_strength=0.0),
                         grammar.materials)
    tips = with_tropism.tips
    assert np.array_equal(tips, straight.tips)
    drop = straight.end[tips, 1] - with_tropism.end[tips, 1]
    assert drop.mean() > 0.2            # metres: tips hang lower on average
    # the trunk is vertical, so tropism does not bend it
    assert np.allclose(with_tropism.end[0], straight.end[0])


def test_abop_ternary_tree_matches_the_books_structure():
    """ABOP fig. 2.8: after n steps, 3^n apices, and F(l) and !(w) grow each step."""
    grammar = load_grammar(grammars_dir() / "abop_ternary.yaml")
    skel = grown("abop_ternary").skeleton
    n = grammar.iterations
    assert np.count_nonzero(_childless(skel)) == 3 ** n                # apices
    length = np.linalg.norm(skel.end - skel.start, axis=1)
    lr, vr = grammar.defines["lr"], grammar.defines["vr"]
    assert np.isclose(length[0], 2.0 * lr ** n)                       # the trunk F(200)
    assert np.isclose(skel.r_end[0], grammar.defines["w0"] * vr ** n)
