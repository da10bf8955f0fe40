"""The skeleton contract: file round trip, invariant checks, transforms, joining."""

import numpy as np
import pytest

from plantgen.geometry.skeletons.skeleton import Skeleton, SkeletonError
from plantgen.scene import rotation_matrix


def y_tree():
    return Skeleton(
        start=[[0, 0, 0], [0, 1, 0], [0, 1, 0]],
        end=[[0, 1, 0], [0, 2, 0], [1, 2, 0]],
        r_start=[0.2, 0.15, 0.05], r_end=[0.15, 0.1, 0.02],
        parent=[-1, 0, 0], continues=[False, True, False], material=[0, 0, 1],
        material_names=("bark", "leaf"))


def test_round_trip_keeps_every_array(tmp_path):
    s = y_tree()
    s.save(tmp_path / "s.npz")
    t = Skeleton.load(tmp_path / "s.npz")
    for name in ("start", "end", "r_start", "r_end", "parent", "continues", "material"):
        np.testing.assert_array_equal(getattr(s, name), getattr(t, name))
        assert getattr(t, name).dtype == getattr(s, name).dtype
    assert t.material_names == ("bark", "leaf")
    assert not list(tmp_path.glob("*.part"))


def test_tips_bounds_height():
    s = y_tree()
    assert list(s.tips) == [1, 2]
    assert s.height == pytest.approx(2.0 + 0.1 + 0.2)


@pytest.mark.parametrize("change, message", [
    (dict(r_end=[0.15, -0.1, 0.02]), "negative radius"),
    (dict(start=[[0, 0, 0], [0, 1.5, 0], [0, 1, 0]]), "does not start where its parent ends"),
    (dict(parent=[-1, 2, 0]), "parent index"),
    (dict(continues=[True, True, False]), "root segment cannot continue"),
    (dict(material=[0, 0, 2]), "material index"),
    (dict(end=[[0, np.nan, 0], [0, 2, 0], [1, 2, 0]]), "NaN"),
])
def test_validate_catches_broken_invariants(change, message):
    s = y_tree()
    fields = {k: getattr(s, k) for k in ("start", "end", "r_start", "r_end", "parent", "continues",
                                          "material")}
    fields.update(change)
    with pytest.raises(SkeletonError, match=message):
        Skeleton(**fields, material_names=s.material_names).validate()


def test_load_rejects_other_files(tmp_path):
    np.savez(tmp_path / "x.npz", a=np.zeros(3))
    with pytest.raises(SkeletonError, match="missing array"):
        Skeleton.load(tmp_path / "x.npz")
    (tmp_path / "y.npz").write_text("not a zip")
    with pytest.raises(SkeletonError, match="not a plantgen skeleton"):
        Skeleton.load(tmp_path / "y.npz")


def test_similarity_transform_scales_radii_and_keeps_joints():
    s = y_tree()
    m = np.eye(4)
    m[:3, :3] = 2.5 * rotation_matrix([10, 70, -30])
    m[:3, 3] = [5, 0, -3]
    t = s.transformed(m)
    t.validate()
    np.testing.assert_allclose(t.r_start, 2.5 * s.r_start)
    np.testing.assert_allclose(np.linalg.norm(t.end - t.start, axis=1),
                               2.5 * np.linalg.norm(s.end - s.start, axis=1))


def test_concatenate_reindexes_parents_and_merges_materials():
    a = y_tree()
    b = Skeleton([[0, 0, 0]], [[0, 1, 0]], [1], [1], [-1], [False], [0], ("stone",))
    c = Skeleton.concatenate([a, b, a])
    c.validate()
    assert c.material_names == ("bark", "leaf", "stone")
    assert list(c.parent) == [-1, 0, 0, -1, -1, 4, 4]
    assert list(c.material) == [0, 0, 1, 2, 0, 0, 1]


def test_subset_keeps_the_segments_and_reindexes_parents():
    s = y_tree()
    t = s.subset([0, 2])
    assert t.parent.tolist() == [-1, 0] and t.continues.tolist() == [False, False]
    np.testing.assert_array_equal(t.end, s.end[[0, 2]])
    assert t.material.tolist() == [0, 1] and t.material_names == s.material_names
    t.validate()
    assert s.subset([1]).parent.tolist() == [-1]      # a dropped parent: the row becomes a root
