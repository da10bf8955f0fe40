"""Scene files: placement, copies, explicit skeletons, effects, and their errors."""

import numpy as np
import pytest
import yaml
from _cli import run_cli

from plantgen.pipeline import grow_file
from plantgen.scene import SceneError

BUSH = """\
name: bush
seed: 1
iterations: 3
axiom: "!(0.1) A"
rules: ["A -> F [+A] [-A] F A"]
materials: [bark]
"""


def write_scene(tmp_path, scene: dict):
    (tmp_path / "bush.yaml").write_text(BUSH)
    p = tmp_path / "scene.yaml"
    p.write_text(yaml.safe_dump(scene))
    return p


def test_instances_are_placed_rotated_and_scaled(tmp_path):
    p = write_scene(tmp_path, {
        "name": "two", "effects": ["shadows"], "ground": {"size": 10},
        "instances": [
            {"grammar": "bush", "position": [0, 0, 0]},
            {"grammar": "bush.yaml", "position": [5, 0, 0], "rotation": [0, 90, 0], "scale": 2},
        ]})
    res = grow_file(p)
    one = grow_file(tmp_path / "bush.yaml").skeleton
    skel = res.skeleton
    skel.validate(tol=1e-9)
    assert len(skel) == 2 * len(one)
    second = slice(len(one), None)
    np.testing.assert_allclose(skel.r_end[second], 2 * one.r_end)
    # a y rotation keeps heights; scale 2 doubles them; the base sits at the position
    np.testing.assert_allclose(skel.end[second, 1], 2 * one.end[:, 1], atol=1e-12)
    np.testing.assert_allclose(skel.start[len(one)], [5, 0, 0], atol=1e-12)
    assert res.scene.effects == ("shadows",) and res.kind == "scene"
    assert list(np.bincount(res.scene.segment_instance())) == [len(one), len(one)]


def test_grid_copies_are_deterministic_and_jittered(tmp_path):
    scene = {"instances": [{"grammar": "bush", "grid": {"count": [3, 2], "spacing": [4, 4], "jitter": 0.2},
                            "motion": {"sway": {"amplitude": 5, "frequency": 1}}}]}
    p = write_scene(tmp_path, scene)
    a, b = grow_file(p), grow_file(p)
    assert len(a.scene.instances) == 6
    np.testing.assert_array_equal(a.skeleton.start, b.skeleton.start)
    roots = a.skeleton.start[a.skeleton.parent < 0]
    assert len(np.unique(np.round(roots, 6), axis=0)) == 6
    phases = [i.motion.phase for i in a.scene.instances]
    assert len(set(phases)) == 6      # each copy sways with its own phase
    c = grow_file(p, seed=9)
    assert not np.array_equal(c.skeleton.start, a.skeleton.start)


def test_explicit_skeleton_instance(tmp_path):
    p = write_scene(tmp_path, {"instances": [{"skeleton": {"materials": ["stone"], "segments": [
        {"start": [0, 0, 0], "end": [0, 1, 0], "r_start": 1, "r_end": 1},
        {"start": [0, 1, 0], "end": [0, 2, 0], "r_start": 1, "r_end": 0.5, "parent": 0, "continues": True},
    ]}}]})
    skel = grow_file(p).skeleton
    assert len(skel) == 2 and skel.material_names == ("stone",)
    assert list(skel.continues) == [False, True]


@pytest.mark.parametrize("scene, message", [
    ({"instances": [{"grammar": "bush"}], "effects": ["fog"]}, "unknown effect"),
    ({"instances": [{"grammar": "nope"}]}, "not found"),
    ({"instances": [{"grammar": "bush", "colour": 1}]}, "unknown key"),
    ({"instances": [{"grammar": "bush", "skeleton": {}}]}, "exactly one"),
    ({"instances": [{"grammar": "bush", "position": [1, 2]}]}, "three numbers"),
    ({"instances": [{"grammar": "bush", "scale": -1}]}, "positive"),
    ({"instances": []}, "non-empty"),
    ({"instances": [{"skeleton": {"segments": [
        {"start": [0, 0, 0], "end": [0, 1, 0], "r_start": 1, "r_end": 1},
        {"start": [0, 3, 0], "end": [0, 4, 0], "r_start": 1, "r_end": 1, "parent": 0}]}}]},
     "does not start where its parent ends"),
    ({"instances": [{"grammar": "bush"}], "camera": {"eye": [0, 0, 0], "target": [0, 0, 0]}}, "coincide"),
])
def test_bad_scenes(tmp_path, scene, message):
    p = write_scene(tmp_path, scene)
    with pytest.raises(SceneError, match=message):
        grow_file(p)
    code, _, stderr = run_cli("grow", p, "-o", tmp_path / "o.npz")
    assert code == 2 and len(stderr.strip().splitlines()) == 1 and "scene.yaml" in stderr


def test_a_broken_grammar_inside_a_scene_names_both(tmp_path):
    p = write_scene(tmp_path, {"instances": [{"grammar": "bush"}]})
    (tmp_path / "bush.yaml").write_text(BUSH.replace("[-A]", "[-A"))
    code, _, stderr = run_cli("grow", p, "-o", tmp_path / "o.npz")
    assert code == 2 and "scene.yaml" in stderr and "bush.yaml" in stderr and "unbalanced" in stderr
