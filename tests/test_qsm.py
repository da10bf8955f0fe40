"""Forestry cylinder models (issue 16): TreeQSM's fields in .qsm.csv (+ .treedata.csv) and
.qsm.mat (read back with scipy's loadmat), frusta split to a volume tolerance, and the
tree-level figures, on shapes with known answers."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from _cli import run_cli
from scipy.io import loadmat

from plantgen.exporters.qsm import CYLINDER_COLUMNS, cylinder_model, pieces_for, write_qsm
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.metrics import segment_volumes
from plantgen.pipeline import export_model, grow_file


def frustum(r1, r2, h=10.0) -> Skeleton:
    return Skeleton([[0, 0, 0]], [[0, h, 0]], [r1], [r2], [-1], [False], [0])


def y_tree() -> Skeleton:
    """A trunk of two segments, a side branch of two from its top joint, a branch on that."""
    start = [[0, 0, 0], [0, 2, 0], [0, 2, 0], [1, 3, 0], [1, 3, 0]]
    end = [[0, 2, 0], [0, 4, 0], [1, 3, 0], [2, 4, 0], [1, 4, 0]]
    return Skeleton(start, end, [0.3, 0.25, 0.1, 0.08, 0.05], [0.25, 0.2, 0.08, 0.06, 0.04], [-1, 0, 0, 2, 2],
                    [False, True, False, True, False], [0] * 5)


def test_a_cylinder_stays_one_cylinder_with_its_exact_volume():
    model = cylinder_model(frustum(0.5, 0.5))
    assert len(model) == 1 and model.volume[0] == pytest.approx(np.pi * 0.25 * 10)


@pytest.mark.parametrize("tolerance", [1e-2, 1e-3, 1e-4])
def test_a_cone_is_split_until_its_volume_is_within_the_tolerance(tolerance):
    """A cone to a point in k mean-radius cylinders lacks exactly 1/(4k²) of its volume."""
    model = cylinder_model(frustum(0.5, 0.0), tolerance)
    k = len(model)
    assert k == int(np.ceil(1 / (2 * np.sqrt(tolerance))))
    cone = np.pi * 0.25 * 10 / 3
    lost = 1 - model.volume.sum() / cone
    assert lost == pytest.approx(1 / (4 * k * k)) and lost <= tolerance * (1 + 1e-9)
    assert 1 / (4 * (k - 1) ** 2) > tolerance                        # the fewest that do
    assert np.allclose(model.length, 10 / k) and np.allclose(np.diff(model.radius), -0.5 / k)


def test_the_tolerance_bounds_every_frustum_of_a_real_tree():
    skel = grow_file("pine").skeleton
    model = cylinder_model(skel, 1e-3)
    per_segment = np.bincount(model.segment, model.volume, len(skel))
    exact = segment_volumes(skel)
    lost = 1 - per_segment / np.where(exact > 0, exact, 1)
    assert np.all(lost <= 1e-3 + 1e-12) and np.all(lost >= -1e-12)
    assert np.array_equal(pieces_for(skel.r_start, skel.r_end, 1e-3), np.bincount(model.segment, minlength=len(skel)))


def test_structure_parent_extension_branch_order_position():
    model = cylinder_model(y_tree(), tolerance=1.0)            # one cylinder per segment
    assert model.parent.tolist() == [-1, 0, 0, 2, 2]
    assert model.extension.tolist() == [1, -1, 3, -1, -1]
    assert model.branch.tolist() == [0, 0, 1, 1, 2]
    assert model.order.tolist() == [0, 0, 1, 1, 2]
    assert model.position.tolist() == [0, 1, 0, 1, 0]


def test_split_cylinders_chain_through_their_branch():
    model = cylinder_model(y_tree(), tolerance=1e-4)
    for c in range(len(model)):
        if model.extension[c] >= 0:
            e = model.extension[c]
            assert model.parent[e] == c and model.branch[e] == model.branch[c]
            assert model.position[e] == model.position[c] + 1
            assert np.allclose(model.start[c] + model.length[c] * model.axis[c], model.start[e])
    for b in range(3):
        positions = np.sort(model.position[model.branch == b])
        assert positions.tolist() == list(range(len(positions)))


def read_rows(path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def read_csv(path) -> dict:
    rows = read_rows(path)
    return {key: np.array([float(r[key]) for r in rows]) for key in rows[0]}


def test_csv_has_treeqsm_fields_in_metres_z_up(tmp_path):
    """A 20 m vertical trunk, 0.3 m radius: its cylinders stand along z from the origin."""
    skel = Skeleton([[0, 0, 0], [0, 10, 0]], [[0, 10, 0], [0, 20, 0]], [0.3, 0.3], [0.3, 0.3], [-1, 0],
                    [False, True], [0, 0])
    info = write_qsm(skel, tmp_path / "t.qsm.csv")
    assert [p.name for p in info["paths"]] == ["t.treedata.csv", "t.qsm.csv"]
    with open(tmp_path / "t.qsm.csv") as fh:
        assert fh.readline().strip().split(",") == list(CYLINDER_COLUMNS)
    cyl = read_csv(tmp_path / "t.qsm.csv")
    assert np.allclose(cyl["start.z"], [0, 10]) and np.allclose(cyl["axis.z"], 1) and np.allclose(cyl["radius"], 0.3)
    assert cyl["parent"].tolist() == [0, 1] and cyl["extension"].tolist() == [2, 0]
    assert cyl["branch"].tolist() == [1, 1] and cyl["BranchOrder"].tolist() == [0, 0]
    assert cyl["PositionInBranch"].tolist() == [1, 2]
    tree = {r["name"]: (r["value"], r["unit"]) for r in read_rows(tmp_path / "t.treedata.csv")}
    assert float(tree["TotalVolume"][0]) == pytest.approx(1000 * np.pi * 0.09 * 20) and tree["TotalVolume"][1] == "L"
    assert float(tree["DBHqsm"][0]) == pytest.approx(0.6) and float(tree["TreeHeight"][0]) == pytest.approx(20)
    assert float(tree["CrownAreaConv"][0]) == pytest.approx(np.pi * 0.09, rel=1e-4)


def test_units_scale_to_metres(tmp_path):
    """A model in centimetres (unit 0.01): coordinates and DBH come out in metres."""
    skel = frustum(30, 30, 2000)                     # 20 m tall, 0.6 m across, in cm
    write_qsm(skel, tmp_path / "cm.qsm.csv", unit=0.01)
    cyl = read_csv(tmp_path / "cm.qsm.csv")
    assert np.allclose(cyl["radius"], 0.3) and np.allclose(cyl["length"].sum(), 20)
    tree = {r["name"]: float(r["value"]) for r in read_rows(tmp_path / "cm.treedata.csv")}
    assert tree["DBHqsm"] == pytest.approx(0.6) and tree["TotalVolume"] == pytest.approx(1000 * np.pi * 0.09 * 20)


def test_mat_file_reads_back_with_loadmat(tmp_path):
    skel = grow_file("elm").skeleton
    info = write_qsm(skel, tmp_path / "elm.qsm.mat")
    mat = loadmat(tmp_path / "elm.qsm.mat", squeeze_me=True, struct_as_record=False)
    qsm = mat["QSM"]
    assert sorted(qsm._fieldnames) == ["branch", "cylinder", "pmdistance", "rundata", "treedata", "triangulation"]
    cyl = qsm.cylinder
    n = info["cylinders"]
    assert cyl.radius.shape == (n,) and cyl.start.shape == (n, 3) and cyl.axis.shape == (n, 3)
    assert np.allclose(np.linalg.norm(cyl.axis, axis=1), 1)
    assert np.pi * np.sum(cyl.radius ** 2 * cyl.length) == pytest.approx(info["volume"])
    assert 1 - info["volume"] / segment_volumes(skel).sum() <= 1e-3
    assert cyl.branch.min() == 1 and cyl.parent.min() == 0 and cyl.BranchOrder.min() == 0
    tree = qsm.treedata
    assert tree.TotalVolume == pytest.approx(1000 * info["volume"])
    assert tree.TreeHeight == pytest.approx(info["metrics"].height)
    assert tree.DBHqsm == pytest.approx(info["metrics"].dbh)
    assert tree.StemTaper.shape[0] == 2
    branch = qsm.branch
    assert branch.order.shape == (info["metrics"].branches + 1,) and branch.parent[0] == 0
    assert np.sum(branch.volume) == pytest.approx(tree.TotalVolume)


def test_the_command_writes_a_cylinder_model_and_prints_the_figures(tmp_path):
    code, stdout, stderr = run_cli("export", "elm", "-o", tmp_path / "elm.qsm.csv")
    assert code == 0, stderr
    assert "cylinders" in stdout and "DBH" in stdout and "crown" in stdout and "z-up" in stdout
    assert (tmp_path / "elm.treedata.csv").is_file()
    code, stdout, stderr = run_cli("export", "well", "-o", tmp_path / "well.qsm.csv")
    assert code == 0 and "no DBH (the trunk is shorter than 1.3 m)" in stdout
    code, _, stderr = run_cli("export", "elm", "-o", tmp_path / "x.qsm.csv", "--qsm-tolerance", "0")
    assert code == 2 and "--qsm-tolerance" in stderr
    assert not (tmp_path / "x.qsm.csv").exists()


def test_volumes_agree_across_mesh_and_cylinder_model(tmp_path):
    """A straight trunk of one taper (so skinning keeps its radii): the frusta's volume, the
    cylinders' (within the tolerance) and the exported mesh's (an n-gon frustum) agree."""
    import trimesh

    skel = Skeleton([[0, 0, 0], [0, 3, 0]], [[0, 3, 0], [0, 6, 0]], [0.5, 0.4], [0.4, 0.3], [-1, 0],
                    [False, True], [0, 0])
    skel.save(tmp_path / "t.npz")
    exact = segment_volumes(skel).sum()
    info = export_model(tmp_path / "t.npz", tmp_path / "t.qsm.csv")
    assert 0 <= 1 - info["volume"] / exact <= 1e-3
    export_model(tmp_path / "t.npz", tmp_path / "t.stl", level=4)
    mesh = trimesh.load(tmp_path / "t.stl")
    mesh.merge_vertices()
    n = 8 * 2 ** 4                                   # a regular n-gon keeps sin(2π/n)·n/(2π) of a disc
    assert mesh.volume == pytest.approx(exact * np.sin(2 * np.pi / n) * n / (2 * np.pi), rel=1e-6)
