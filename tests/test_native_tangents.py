"""The compiled glTF tangents (plantgen.geometry.meshes.native_tangents) against the numpy
ones, bit for bit: shipped plants, a synthetic skeleton, hostile faces (degenerate,
untextured, unnormalised normals); the glb written either way is the same file; small
meshes never import numba; without numba the numpy code computes them."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from plantgen.benchmarks.pipeline import synthetic_skeleton
from plantgen.exporters import Plant, gltf, write_plants
from plantgen.exporters.plants import material_parts
from plantgen.exporters.textures import bake_textures
from plantgen.geometry.meshes import textures as tx
from plantgen.geometry.meshes.mesh import tessellate
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.pipeline import grow_file


@pytest.fixture
def numba_runs():
    """Skips where numba does not run; asked at the test, not at collection, so that a run
    of other tests neither imports numba nor compiles the kernels."""
    from plantgen.geometry.meshes import native_tangents
    if native_tangents.tangent_kernels() is None:
        pytest.skip("numba does not run here: numpy computes every tangent")


needs_numba = pytest.mark.usefixtures("numba_runs")


def _both(monkeypatch, vertices, normals, uv, faces):
    """(compiled, numpy) tangents of one mesh."""
    monkeypatch.setattr(tx, "COMPILED_FACES", 0)
    compiled = tx.mesh_tangents(vertices, normals, uv, faces)
    monkeypatch.setattr(tx, "COMPILED_FACES", 1 << 62)
    return compiled, tx.mesh_tangents(vertices, normals, uv, faces)


@needs_numba
@pytest.mark.parametrize("source", ["saguaro", "broadleaf", "well", "synthetic"])
@pytest.mark.parametrize("up", ["y", "z"])
def test_compiled_tangents_are_numpys_bit_for_bit(monkeypatch, source, up):
    skeleton = synthetic_skeleton(2000) if source == "synthetic" else grow_file(source).skeleton
    mesh = tessellate(skin_skeleton(skeleton), 1)
    for part in material_parts(mesh, up):
        compiled, numpy = _both(monkeypatch, part.vertices, part.normals, part.uv, part.faces)
        assert compiled.dtype == np.float32 and compiled.shape == (len(part.vertices), 4)
        assert compiled.tobytes() == numpy.tobytes()
        assert set(np.unique(compiled[:, 3]).tolist()) == {-1.0, 1.0}    # both signs met


@needs_numba
def test_compiled_tangents_of_hostile_faces(monkeypatch):
    rng = np.random.default_rng(45)
    vertices = rng.normal(size=(400, 3)) * rng.choice([1e-6, 1.0, 1e6], size=(400, 1))
    faces = rng.integers(0, 390, size=(900, 3))           # the last 10 vertices: in no face
    faces[:50, 1] = faces[:50, 0]                         # zero area
    uv = rng.random((400, 2)).astype(np.float32)
    uv[faces[50:100, 1]] = uv[faces[50:100, 0]]           # texture coordinates that span nothing
    normals = rng.normal(size=(400, 3)).astype(np.float32) * 3.0   # not unit
    normals[:5] = [1.0, 0.0, 0.0]                         # the helper's other branch
    normals[5] = 0.0                                      # no normal at all
    for uv_type, normal_type in ((np.float32, np.float32), (np.float64, np.float64)):
        compiled, numpy = _both(monkeypatch, vertices, normals.astype(normal_type), uv.astype(uv_type), faces)
        assert compiled.tobytes() == numpy.tobytes()


@needs_numba
def test_the_glb_is_the_same_file_either_way(monkeypatch, tmp_path):
    skeleton = grow_file("saguaro").skeleton
    mesh = tessellate(skin_skeleton(skeleton), 1)
    textures = bake_textures([mesh])
    plants = [Plant("saguaro", skeleton, mesh, None)]
    files = []
    for way, faces in (("compiled", 0), ("numpy", 1 << 62)):      # one name: the scene is named after it
        monkeypatch.setattr(tx, "COMPILED_FACES", faces)
        (tmp_path / way).mkdir()
        files.append(write_plants(plants, tmp_path / way / "saguaro.glb", textures=textures)[0].read_bytes())
    assert files[0] == files[1]


def _run(code: str) -> str:
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    return run.stdout.strip()


MESH = ("from plantgen.geometry.meshes import textures as tx\n"
        "from plantgen.geometry.meshes.mesh import tessellate\n"
        "from plantgen.geometry.skeletons.skin import skin_skeleton\n"
        "from plantgen.benchmarks.pipeline import synthetic_skeleton\n"
        "mesh = tessellate(skin_skeleton(synthetic_skeleton(200)), 0)\n")


def test_a_small_mesh_does_not_import_numba():
    code = MESH + ("import sys\n"
                   "assert len(mesh.faces) < tx.COMPILED_FACES\n"
                   "tx.mesh_tangents(mesh.vertices, mesh.normals, mesh.uv, mesh.faces)\n"
                   "print('numba' in sys.modules)\n")
    assert _run(code) == "False"


def test_without_numba_numpy_computes_them():
    code = ("import sys; sys.modules['numba'] = None\n" + MESH
            + "from plantgen.geometry.meshes import native_tangents\n"
              "numpy = tx.mesh_tangents(mesh.vertices, mesh.normals, mesh.uv, mesh.faces)\n"
              "tx.COMPILED_FACES = 0\n"
              "fallback = tx.mesh_tangents(mesh.vertices, mesh.normals, mesh.uv, mesh.faces)\n"
              "print(native_tangents.tangent_kernels() is None, numpy.tobytes() == fallback.tobytes())\n")
    assert _run(code) == "True True"


def test_an_export_whose_plants_reach_the_threshold_compiles_every_primitive(monkeypatch, tmp_path):
    """numba's load is paid once an export: plants whose faces together reach
    COMPILED_FACES have each primitive's tangents compiled, small ones included."""
    skeleton = grow_file("saguaro").skeleton
    mesh = tessellate(skin_skeleton(skeleton), 1)
    textures = bake_textures([mesh])
    asked = []
    was = tx.mesh_tangents

    def spy(*args, compiled=None):
        asked.append(compiled)
        return was(*args, compiled=compiled)
    monkeypatch.setattr(gltf, "mesh_tangents", spy)
    monkeypatch.setattr(gltf, "COMPILED_FACES", 3 * len(mesh.faces))
    for copies in (2, 3):                 # under and at the threshold: numpy's choice, then compiled
        plants = [Plant(f"saguaro {k}", skeleton, mesh, None) for k in range(copies)]
        write_plants(plants, tmp_path / f"{copies}.glb", textures=textures)
    assert asked == [None] * 2 + [True] * 3


@needs_numba
def test_faces_the_kernels_cannot_index_are_numpys(monkeypatch):
    """The kernels check no index: faces out of range or negative are left to numpy,
    whose errors say so (not a read outside the arrays)."""
    vertices = np.eye(3) * [1.0, 2.0, 3.0]
    uv = np.array([[0, 0], [1, 0], [0, 1]], np.float32)
    normals = np.ones((3, 3), np.float32)
    monkeypatch.setattr(tx, "COMPILED_FACES", 0)
    with pytest.raises(IndexError):
        tx.mesh_tangents(vertices, normals, uv, np.array([[0, 1, 3]]))
    with pytest.raises(ValueError, match="negative"):
        tx.mesh_tangents(vertices, normals, uv, np.array([[0, 1, -1]]))
    assert tx.mesh_tangents(vertices, normals, uv, np.array([[0, 1, 2]])).shape == (3, 4)
