"""Point clouds to files (plantgen.scanfiles): LAS 1.4 and LAZ read back by laspy, PLY by
trimesh and by a few lines of numpy here; labels, quantisation, up axis, atomic writes,
one-line refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _scan_helpers import labelled_residuals

from plantgen.geometry.rays.scan import LABELS, ScanSettings, scan_plant
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.pipeline import grow_file, skin_model
from plantgen.scanfiles import (
    FILE_LABELS,
    PointFileError,
    check_point_output,
    las_scale,
    read_points,
    write_points,
)

laspy = pytest.importorskip("laspy", reason="laspy (plantgen[scan]) is not installed")

Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@pytest.fixture(scope="module")
def bush_scan():
    grown = grow_file("abop_bush")
    return scan_plant(grown.skeleton, grown.polygons, ScanSettings(angular_step=0.4, scanners=3, range_noise=1e-3),
                      seed=5, frusta=skin_model(grown))


def test_las_reads_back_with_laspy_labels_and_quantisation(tmp_path, bush_scan):
    cloud = bush_scan
    path = write_points(cloud, tmp_path / "bush.las")
    las = laspy.read(path)
    assert str(las.header.version) == "1.4" and las.header.point_format.id == 6
    assert list(las.point_format.extra_dimension_names) == [FILE_LABELS[k][0] for k in LABELS]
    for name, values in cloud.labels().items():
        assert np.array_equal(np.asarray(las[FILE_LABELS[name][0]]), values), name
    assert np.array_equal(np.asarray(las.point_source_id), cloud.scanner)
    assert np.all(np.asarray(las.return_number) == 1) and np.all(np.asarray(las.number_of_returns) == 1)
    scale = las.header.scales[0]
    extent = float(np.ptp(cloud.xyz, axis=0).max())
    assert scale == 10.0 ** (np.floor(np.log10(extent)) - 6)
    xyz = np.stack([las.x, las.y, las.z], axis=1)
    assert np.abs(xyz - cloud.xyz @ Z_UP.T).max() <= scale / 2 * (1 + 1e-6)       # z-up, within the quantisation
    meta = json.loads(next(v for v in las.vlrs if v.user_id == "plantgen").record_data)
    assert meta["seed"] == 5 and meta["up"] == "z" and meta["parts"] == ["stem", "branch", "leaf"]
    assert np.allclose(meta["scanners"], cloud.scanners @ Z_UP.T)
    assert not list(tmp_path.glob(".*"))                     # no temporary file left


def test_laz_round_trips(tmp_path, bush_scan):
    if not laspy.LazBackend.detect_available():
        pytest.skip("no LAZ backend for laspy")
    path = write_points(bush_scan, tmp_path / "bush.laz")
    las = laspy.read(path)
    back = read_points(path)
    assert np.abs(back.xyz - bush_scan.xyz).max() <= las.header.scales[0]
    assert all(np.array_equal(a, b) for a, b in zip(back.labels().values(), bush_scan.labels().values(),
                                                       strict=True))
    plain = write_points(bush_scan, tmp_path / "bush.las")
    assert path.stat().st_size < plain.stat().st_size / 2                   # compressed


def parse_ply(path) -> tuple[list[str], np.ndarray]:
    """A binary little-endian PLY's header lines and its vertex table, read here."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode().splitlines()
    types = {"double": "<f8", "int": "<i4", "uchar": "u1", "short": "<i2", "ushort": "<u2"}
    fields = [(w[2], types[w[1]]) for w in (line.split() for line in header) if w[0] == "property"]
    count = next(int(line.split()[2]) for line in header if line.startswith("element vertex"))
    return header, np.frombuffer(data[end:], dtype=np.dtype(fields), count=count)


def test_ply_reads_back_with_trimesh_and_by_hand(tmp_path, bush_scan):
    import trimesh

    path = write_points(bush_scan, tmp_path / "bush.ply")
    header, table = parse_ply(path)
    assert header[1] == "format binary_little_endian 1.0" and "comment up z" in header
    assert list(table.dtype.names) == ["x", "y", "z", *(FILE_LABELS[k][0] for k in LABELS)]
    xyz = np.stack([table["x"], table["y"], table["z"]], axis=1)
    assert np.array_equal(xyz, bush_scan.xyz @ Z_UP.T)                        # doubles: no quantisation
    for name, values in bush_scan.labels().items():
        assert np.array_equal(table[FILE_LABELS[name][0]], values)
    loaded = trimesh.load(path)
    assert np.allclose(loaded.vertices, xyz)
    raw = loaded.metadata["_ply_raw"]["vertex"]["data"]
    assert np.array_equal(raw["segment"], bush_scan.segment) and np.array_equal(raw["part"], bush_scan.part)
    back = read_points(path)
    assert np.allclose(back.xyz, bush_scan.xyz, rtol=0, atol=1e-12) and back.metadata["seed"] == 5


def test_ply_rows_written_a_chunk_at_a_time_are_the_whole_tables(tmp_path, bush_scan, monkeypatch):
    """The vertex rows, made and written PLY_CHUNK points at a time, are the bytes of the
    whole table at once: each coordinate the z-up product's (xyz @ Z_UP.T, BLAS's, -0
    coming out +0), each label as it is, for chunks that do and do not divide the points."""
    import dataclasses

    from plantgen import scanfiles

    xyz = bush_scan.xyz.copy()
    xyz[::7] = -0.0                              # signed zeros: the product writes +0
    xyz[1::7, 1] = 0.0
    cloud = dataclasses.replace(bush_scan, xyz=xyz)
    whole = write_points(cloud, tmp_path / "whole.ply").read_bytes()
    header, table = parse_ply(tmp_path / "whole.ply")
    turned = xyz @ Z_UP.T
    assert np.stack([table["x"], table["y"], table["z"]], axis=1).tobytes() == (turned + 0.0).tobytes()
    assert not np.signbit(table["x"][::7]).any() and np.signbit(xyz[::7]).all()
    assert (turned + 0.0).tobytes() == turned.tobytes()            # what the matrix product gave before
    for chunk in (1000, 7, len(cloud)):
        monkeypatch.setattr(scanfiles, "PLY_CHUNK", chunk)
        assert write_points(cloud, tmp_path / f"{chunk}.ply").read_bytes() == whole
    assert len(cloud) > 1000


def test_up_y_keeps_plantgens_frame(tmp_path, bush_scan):
    _, table = parse_ply(write_points(bush_scan, tmp_path / "y.ply", up="y"))
    assert np.array_equal(np.stack([table["x"], table["y"], table["z"]], axis=1), bush_scan.xyz)


def test_points_from_the_file_lie_on_the_surface_within_noise_and_quantisation(tmp_path):
    sigma = 1e-3
    skel = Skeleton([[0, 0, 0], [0, 2, 0]], [[0, 2, 0], [0.8, 3.2, 0]], [0.3, 0.25], [0.25, 0.1], [-1, 0],
                    [False, True], [0, 0])
    frusta = skin_skeleton(skel)
    cloud = scan_plant(skel, None, ScanSettings(angular_step=0.5, range_noise=sigma), seed=2, frusta=frusta)
    path = write_points(cloud, tmp_path / "t.las")
    back = read_points(path)
    scale = laspy.read(path).header.scales[0]
    res = labelled_residuals(frusta, back, 6 * sigma + scale)
    assert res.max() <= 6 * sigma + np.sqrt(3) * scale / 2


def test_scale_and_offset_for_the_scenes_size():
    scale, offset = las_scale([-10, 0, -10], [15, 25, 10])
    assert scale == 1e-5 and np.allclose(offset, [2.5, 12.5, 0])
    scale, _ = las_scale([1e5, 0, 1e5], [1e5 + 3, 2, 1e5 + 3])
    assert scale == 1e-6
    scale, _ = las_scale([0, 0, 0], [0, 0, 0])
    assert scale > 0


def test_refusals_are_one_line(tmp_path, bush_scan, monkeypatch):
    with pytest.raises(PointFileError, match=r"unknown point cloud format '\.xyz'.*\.las, \.laz, \.ply"):
        write_points(bush_scan, tmp_path / "a.xyz")
    with pytest.raises(PointFileError, match="no such folder"):
        write_points(bush_scan, tmp_path / "nowhere" / "a.ply")
    import plantgen.scanfiles as scanfiles

    real = scanfiles.importlib.util.find_spec
    monkeypatch.setattr(scanfiles.importlib.util, "find_spec", lambda name: None if name == "laspy" else real(name))
    wording = r"LAS and LAZ support needs the scan extra: pip install '\.\[scan\]'.*laspy missing"
    with pytest.raises(PointFileError, match=wording):
        check_point_output(tmp_path / "a.las")
    assert check_point_output(tmp_path / "a.ply") == "ply"          # PLY needs nothing
    assert not list(tmp_path.iterdir())
