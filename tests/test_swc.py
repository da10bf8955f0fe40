"""SWC both ways (issue 16): `-o x.swc` alone, npz -> SWC -> npz keeps every segment,
several roots as the standard allows, and MorphIO (the reader behind NeuroM) measures the
skeleton's total length."""

from __future__ import annotations

import numpy as np
import pytest
from _cli import run_cli

from plantgen.geometry.skeletons.skeleton import Skeleton, SkeletonError
from plantgen.geometry.skeletons.swc import read_swc, swc_lines, write_swc
from plantgen.metrics import segment_lengths
from plantgen.pipeline import grow_file

FIELDS = ("start", "end", "r_start", "r_end", "parent", "continues", "material")


def assert_same(a: Skeleton, b: Skeleton) -> None:
    assert len(a) == len(b) and a.material_names == b.material_names
    for name in FIELDS:
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


def awkward() -> Skeleton:
    """Every case the node rules alone cannot tell apart: a radius step on a continuing
    segment (1), a side branch (2), a second continuing child (3), a cone closing to a
    point (4), a segment of zero length (5), a material change in mid-axis (6), a side
    branch starting 1e-12 off its parent's end, within the joint tolerance (7), a second
    root (8)."""
    start = [[0, 0, 0], [0, 1, 0], [0, 1, 0], [0, 1, 0], [0, 2, 0], [0.1, 1.5, 0], [0.1, 1.5, 0],
             [0, 2, 1e-12], [3, 0, 0]]
    end = [[0, 1, 0], [0, 2, 0], [0.5, 1.5, 0], [0.1, 1.5, 0], [0, 3, 0], [0.1, 1.5, 0], [0.4, 2.5, 0],
           [0, 2.5, 0.5], [3, 1, 0]]
    return Skeleton(start, end, [0.3, 0.35, 0.1, 0.3, 0.3, 0.2, 0.2, 0.05, 0.5],
                    [0.3, 0.3, 0.05, 0.2, 0.0, 0.2, 0.1, 0.05, 0.4], [-1, 0, 0, 0, 1, 3, 5, 1, -1],
                    [False, True, False, True, True, True, True, False, False], [0, 0, 1, 0, 0, 0, 1, 1, 0],
                    ("bark", "leaf"))


@pytest.mark.parametrize("up", ["y", "z"])
def test_the_round_trip_keeps_every_segment_exactly(tmp_path, up):
    skel = awkward()
    skel.validate()
    write_swc(skel, tmp_path / "a.swc", up=up)
    assert_same(read_swc(tmp_path / "a.swc"), skel)


@pytest.mark.parametrize("name", ["saguaro", "coconut", "well", "desert"])
def test_shipped_models_round_trip_npz_swc_npz(tmp_path, name):
    """Through the commands: grow -> .npz, grow .npz -> .swc alone, grow .swc -> .npz."""
    npz, swc, back = tmp_path / "a.npz", tmp_path / "a.swc", tmp_path / "b.npz"
    for args in (("grow", name, "-o", npz), ("grow", npz, "-o", swc), ("grow", swc, "-o", back)):
        code, _, stderr = run_cli(*args, "-q")
        assert code == 0, stderr
    assert_same(Skeleton.load(back), Skeleton.load(npz))


def test_one_soma_marker_and_one_stem_per_root():
    """Several roots as the standardised SWC allows them: one root node (type 1, the soma),
    every plant root a stem starting at a child of it."""
    skel = grow_file("desert").skeleton
    rows = [line.split() for line in swc_lines(skel) if not line.startswith("#")]
    parents = [int(r[6]) for r in rows]
    assert parents.count(-1) == 1 and rows[0][1] == "1" and parents[0] == -1
    assert sum(p == 1 for p in parents) == int((skel.parent < 0).sum())
    assert all(int(r[1]) != 1 for r in rows[1:])
    assert all(0 < p < int(r[0]) for p, r in zip(parents[1:], rows[1:], strict=True))


def test_type_codes_and_units_are_in_the_header():
    lines = swc_lines(grow_file("coconut").skeleton)
    header = [line for line in lines if line.startswith("#")]
    assert "# material 3: bark" in header and "# material 5: leaf" in header
    assert "# up: y" in header and any("units: model units" in line for line in header)
    codes = {line.split()[1] for line in lines if not line.startswith("#")}
    assert codes == {"1", "3", "5"}


def test_sixteen_materials_fit_the_type_codes_and_more_do_not():
    base = Skeleton([[0, 0, 0]], [[0, 1, 0]], [0.1], [0.1], [-1], [False], [0], tuple(f"m{i}" for i in range(16)))
    assert swc_lines(base)[-1].split()[1] == "3"
    with pytest.raises(SkeletonError, match="16 materials"):
        swc_lines(Skeleton([[0, 0, 0]], [[0, 1, 0]], [0.1], [0.1], [-1], [False], [0],
                           tuple(f"m{i}" for i in range(17))))


def test_foreign_swc_files_read_as_trees(tmp_path):
    """A neuron-style file from another tool: a three-point soma, two dendrites leaving it,
    no plantgen header: the soma is no wood, each stem is a root, types name materials."""
    (tmp_path / "n.swc").write_text(
        "# from another tool\n"
        "1 1 0 0 0 1 -1\n2 1 0 -1 0 1 1\n3 1 0 1 0 1 1\n"
        "4 3 0 2 0 0.5 3\n5 3 0 4 0 0.4 4\n6 3 1 5 0 0.3 5\n7 3 -1 5 0 0.3 5\n"
        "8 2 0 -2 0 0.2 2\n9 2 0 -5 0 0.1 8\n")
    skel = read_swc(tmp_path / "n.swc")
    # 3 -> 4 is a soma edge (no wood); 4 -> 5 a root; 5 -> 6 carries it on; 5 -> 7 a side
    # branch; 2 -> 8 a soma edge, 8 -> 9 a second root (an axon: a second material).
    assert skel.parent.tolist() == [-1, 0, 0, -1] and skel.continues.tolist() == [False, True, False, False]
    assert skel.material.tolist() == [0, 0, 0, 1] and skel.material_names == ("bark", "swc2")
    assert np.allclose(segment_lengths(skel), [2, np.sqrt(2), np.sqrt(2), 3])
    assert skel.r_start.tolist() == [0.5, 0.4, 0.4, 0.2]


def morphio_reads(path):
    """MorphIO with every warning an error, but for zero diameters: a cone closing to a
    point (the well's roof, every branch tip of a tapering tree) ends at radius 0, which
    MorphIO merely flags."""
    morphio = pytest.importorskip("morphio", reason="MorphIO is in the test extra; install '.[test]'")
    morphio.set_raise_warnings(True)
    morphio.set_ignored_warning(morphio.Warning.zero_diameter, True)
    try:
        return morphio.Morphology(str(path))
    finally:
        morphio.set_raise_warnings(False)
        morphio.set_ignored_warning(morphio.Warning.zero_diameter, False)


@pytest.mark.parametrize("name", ["saguaro", "well", "desert", "coconut"])
def test_morphio_measures_the_skeletons_total_length(tmp_path, name):
    """The issue: NeuroM's total length of the saguaro was 21.39 against 22.40 (the root
    segment taken for the soma); several roots read as disconnected neurites."""
    skel = grow_file(name).skeleton
    write_swc(skel, tmp_path / "p.swc")
    morph = morphio_reads(tmp_path / "p.swc")
    total = sum(float(np.linalg.norm(np.diff(s.points.astype(np.float64), axis=0), axis=1).sum())
                for s in morph.iter())
    assert total == pytest.approx(segment_lengths(skel).sum(), rel=1e-6)
    assert len(morph.root_sections) == int((skel.parent < 0).sum())
    assert str(morph.soma.type).endswith("SOMA_SINGLE_POINT")


def test_export_and_render_read_swc(tmp_path):
    skel = grow_file("saguaro").skeleton
    write_swc(skel, tmp_path / "s.swc", up="z")
    code, stdout, stderr = run_cli("export", tmp_path / "s.swc", "-o", tmp_path / "s.glb", "--subdiv", "0")
    assert code == 0, stderr
    assert f"{len(skel)} branch segments" in stdout
    code, stdout, stderr = run_cli("export", "saguaro", "-o", tmp_path / "e.swc")
    assert code == 0, stderr
    assert_same(read_swc(tmp_path / "e.swc"), skel)


def test_render_reads_swc(gl_ctx, tmp_path):
    """`plantgen render x.swc` (the issue: 'not a grammar or scene')."""
    write_swc(grow_file("saguaro").skeleton, tmp_path / "s.swc")
    code, stdout, stderr = run_cli("render", tmp_path / "s.swc", "-o", tmp_path / "s.png", "--size", "64x48")
    assert code == 0, stderr
    assert (tmp_path / "s.png").stat().st_size > 0


def test_grow_writes_swc_alone_and_refuses_up_for_npz(tmp_path):
    code, stdout, stderr = run_cli("grow", "saguaro", "-o", tmp_path / "s.swc", "--up", "z")
    assert code == 0, stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.swc"]
    assert "# up: z" in (tmp_path / "s.swc").read_text()
    code, _, stderr = run_cli("grow", "saguaro", "-o", tmp_path / "s.npz", "--up", "z")
    assert code == 2 and "always y-up" in stderr and not (tmp_path / "s.npz").exists()
    code, _, stderr = run_cli("grow", "saguaro", "-o", tmp_path / "s.obj")
    assert code == 2 and ".npz or .swc" in stderr
