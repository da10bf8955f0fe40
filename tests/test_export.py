"""Mesh export (issue 5): glTF / OBJ / PLY / STL load back whole; GLB passes the Khronos validator."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import trimesh
from test_mesh import BENT, chain_frusta, concat_frusta

from plantgen.export import ExportError, export_mesh
from plantgen.geometry.mesh import tessellate

REPO = Path(__file__).resolve().parents[1]


def two_material_model(m=2):
    trunk = chain_frusta(BENT, [0.3, 0.25, 0.25, 0.2, 0.15], shell=0.03)
    leaf = chain_frusta([[0, 1, 0], [0.8, 1.6, 0], [1.4, 2.4, 0.3]], [0.1, 0.08, 0.0], material=[1, 1])
    frusta = concat_frusta(trunk, leaf)
    frusta = dataclasses.replace(frusta, material_names=("bark", "leaf"))
    return tessellate(frusta, m)


def load_back(path) -> trimesh.Trimesh:
    loaded = trimesh.load(path)
    if isinstance(loaded, trimesh.Scene):
        loaded = loaded.to_geometry()
    return loaded


@pytest.mark.parametrize("suffix", [".glb", ".obj", ".ply", ".stl"])
def test_every_format_loads_back_with_the_exact_triangle_count(tmp_path, suffix):
    mesh = two_material_model()
    path = export_mesh(mesh, tmp_path / f"plant{suffix}")
    assert path.is_file() and not list(tmp_path.glob("*.part"))
    back = load_back(path)
    assert len(back.faces) == len(mesh.faces)
    # Same surface: same bounds, and the trunk chain is still closed once welded.
    assert np.allclose(back.bounds, mesh.to_trimesh().bounds, atol=1e-5)


def test_a_continuing_chain_loads_back_watertight(tmp_path):
    mesh = tessellate(chain_frusta(BENT, [0.3, 0.25, 0.25, 0.2, 0.15]), 2)
    for suffix in (".stl", ".glb"):
        back = load_back(export_mesh(mesh, tmp_path / f"chain{suffix}"))
        back.merge_vertices(merge_tex=True, merge_norm=True)
        assert back.is_watertight and back.volume > 0


def test_gltf_keeps_material_colours_uv_and_normals(tmp_path):
    mesh = two_material_model()
    colours = {"bark": (0.3, 0.2, 0.1), "leaf": (0.1, 0.6, 0.2)}
    scene = trimesh.load(export_mesh(mesh, tmp_path / "plant.glb", colours=colours))
    assert set(scene.geometry) == {"bark", "leaf"}
    for name, geom in scene.geometry.items():
        base = np.asarray(geom.visual.material.baseColorFactor, dtype=float)
        assert np.allclose(base[:3] / (255 if base.max() > 1 else 1), colours[name], atol=1 / 255)
        faces_of = mesh.face_material == mesh.material_names.index(name)
        assert len(geom.faces) == faces_of.sum()
        used = np.unique(mesh.faces[faces_of])
        assert geom.visual.uv.shape == (len(used), 2)
        assert np.allclose(np.sort(geom.visual.uv[:, 0]), np.sort(mesh.uv[used, 0]), atol=1e-6)
        assert np.allclose(np.linalg.norm(geom.vertex_normals, axis=1), 1, atol=1e-5)


def test_bad_targets_are_user_errors_and_leave_nothing(tmp_path):
    mesh = two_material_model(0)
    with pytest.raises(ExportError, match="unknown export format"):
        export_mesh(mesh, tmp_path / "plant.fbx")
    with pytest.raises(ExportError, match="does not exist"):
        export_mesh(mesh, tmp_path / "missing" / "plant.glb")
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------- Khronos validator
VALIDATE_JS = r"""
const validator = require('gltf-validator');
const fs = require('fs');
const data = new Uint8Array(fs.readFileSync(process.argv[1]));
validator.validateBytes(data, {maxIssues: 1000})
  .then(report => console.log(JSON.stringify(report.issues)))
  .catch(err => { console.error(String(err)); process.exit(3); });
"""


def validator_modules() -> Path:
    """node_modules holding gltf-validator: $PLANTGEN_GLTF_VALIDATOR, .ci/node, or a user cache.

    CI installs it with ``npm install --prefix .ci/node gltf-validator``; where none is
    installed the test installs it into the user cache (needs the npm registry).
    """
    candidates = [os.environ.get("PLANTGEN_GLTF_VALIDATOR"), REPO / ".ci" / "node",
                  Path.home() / ".cache" / "plantgen" / "gltf-validator"]
    for prefix in filter(None, candidates):
        modules = Path(prefix) / "node_modules"
        if (modules / "gltf-validator").is_dir():
            return modules
    cache = Path(candidates[-1])
    cache.mkdir(parents=True, exist_ok=True)
    npm = shutil.which("npm")
    assert npm, "node is installed but npm is not: install gltf-validator with npm to run this test"
    done = subprocess.run([npm, "install", "--prefix", str(cache), "gltf-validator"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"cannot install gltf-validator: {done.stderr[-500:]}"
    return cache / "node_modules"


@pytest.mark.skipif(shutil.which("node") is None, reason="Node.js is not installed: the Khronos "
                    "glTF validator is a Node package")
@pytest.mark.parametrize("relief", [False, True])
def test_plantgen_glb_passes_the_khronos_gltf_validator(tmp_path, relief):
    if relief:
        # A skinned chain with a knuckle (degenerate hinge triangles) and bark relief.
        from _geometry_helpers import chain_skeleton

        from plantgen.geometry.skin import skin_skeleton

        frusta = skin_skeleton(chain_skeleton((30, 150), radii=(0.2, 0.15, 0.12, 0.1)))
        mesh = tessellate(frusta, 2, relief=True)
    else:
        mesh = two_material_model()
    path = export_mesh(mesh, tmp_path / "plant.glb")
    env = dict(os.environ, NODE_PATH=str(validator_modules()))
    done = subprocess.run(["node", "-e", VALIDATE_JS, str(path)], capture_output=True, text=True,
                          env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    issues = json.loads(done.stdout)
    errors = [msg for msg in issues["messages"] if msg["severity"] == 0]
    assert issues["numErrors"] == 0, errors
    assert issues["numWarnings"] == 0, issues["messages"]


# ---------------------------------------------------------------------------- the command
def y_skeleton():
    from plantgen.geometry.skeleton import Skeleton

    start = np.array([[0, 0, 0], [0, 1, 0], [0, 2, 0], [0, 1, 0]], float)
    end = np.array([[0, 1, 0], [0, 2, 0], [0.2, 3, 0], [0.8, 1.6, 0]], float)
    return Skeleton(start, end, [0.3, 0.25, 0.2, 0.1], [0.25, 0.2, 0.12, 0.05], [-1, 0, 1, 0],
                    [False, True, True, False], [0, 0, 0, 1], ("bark", "leaf"))


@pytest.mark.parametrize("suffix", [".glb", ".stl"])
def test_the_export_command_writes_the_counted_triangles(tmp_path, suffix):
    from _cli import run_cli

    skel_path = tmp_path / "y.npz"
    y_skeleton().save(skel_path)
    out = tmp_path / f"y{suffix}"
    code, stdout, stderr = run_cli("export", skel_path, "-o", out, "--subdiv", "2")
    assert code == 0, stderr
    from plantgen.geometry.skin import skin_skeleton

    frusta = skin_skeleton(y_skeleton())
    expected = len(tessellate(frusta, 2).faces)
    assert len(load_back(out).faces) == expected
    assert f"{expected:,} triangles" in stdout


def test_the_export_command_reports_bad_input_in_one_line(tmp_path):
    from _cli import run_cli

    skel_path = tmp_path / "y.npz"
    y_skeleton().save(skel_path)
    code, _, stderr = run_cli("export", skel_path, "-o", tmp_path / "y.fbx")
    assert code == 2 and "unknown export format" in stderr and len(stderr.strip().splitlines()) == 1
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    code, _, stderr = run_cli("export", tmp_path / "junk.npz", "-o", tmp_path / "y.glb")
    assert code == 2 and stderr.startswith("plantgen: error:")
    assert not (tmp_path / "y.glb").exists()


def test_default_gltf_colours_are_the_renderers_palette(tmp_path):
    from plantgen.geometry.materials import material_palette

    mesh = two_material_model(0)
    scene = trimesh.load(export_mesh(mesh, tmp_path / "plant.glb"))
    palette = material_palette(mesh.material_names)
    for i, name in enumerate(mesh.material_names):
        base = np.asarray(scene.geometry[name].visual.material.baseColorFactor, dtype=float)[:3]
        base = base / 255 if base.max() > 1 else base
        assert np.allclose(base, (palette["dark"][i] + palette["light"][i]) / 2, atol=1 / 255)


def test_an_export_too_large_to_hold_is_refused_before_tessellating(tmp_path):
    from _cli import run_cli

    skel_path = tmp_path / "y.npz"
    y_skeleton().save(skel_path)
    code, _, stderr = run_cli("export", skel_path, "-o", tmp_path / "y.glb", "--subdiv", "1",
                              "--limit", "export_triangles=100")
    assert code == 2 and "over the export limit" in stderr and "--limit export_triangles=N" in stderr
    assert not (tmp_path / "y.glb").exists()
    code, _, stderr = run_cli("export", skel_path, "-o", tmp_path / "y.glb", "--subdiv", "1",
                              "--limit", "export_bytes=1000")
    assert code == 2 and "--limit export_bytes=N" in stderr and len(stderr.strip().splitlines()) == 1
    assert not (tmp_path / "y.glb").exists()
