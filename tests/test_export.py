"""Mesh export (issues 5 and 16): every format is read back whole by an independent reader
(trimesh, meshio, the Khronos validator), OBJ with its MTL, glTF as .glb and .gltf + .bin,
each format in its up-axis convention and turned on request."""

from __future__ import annotations

import dataclasses
import inspect
import json
import os
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest
import trimesh
from _cli import run_cli, run_cli_on_terminal
from _node import assert_khronos_valid, needs_node
from test_mesh import BENT, chain_frusta, concat_frusta

import plantgen
from plantgen.exporters import EXPORT_FORMATS, ExportError, Format, Plant, export_mesh, write_plants, write_skeleton
from plantgen.exporters.formats import FORMAT_KINDS
from plantgen.exporters.plants import MeshWriter, SkeletonWriter
from plantgen.geometry.meshes.mesh import tessellate
from plantgen.geometry.skeletons.frames import up_rotation
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.pipeline import export_model, grow_file

MESH_SUFFIXES = [".glb", ".gltf", ".obj", ".ply", ".stl"]
CONVENTION = {".glb": "y", ".gltf": "y", ".obj": "y", ".ply": "z", ".stl": "z"}


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


def turned_bounds(mesh, up: str) -> np.ndarray:
    points = mesh.vertices @ up_rotation(up).T
    return np.stack([points.min(axis=0), points.max(axis=0)])


@pytest.mark.parametrize("suffix", MESH_SUFFIXES)
def test_every_format_loads_back_with_the_exact_triangle_count(tmp_path, suffix):
    mesh = two_material_model()
    path = export_mesh(mesh, tmp_path / f"plant{suffix}")
    assert path.is_file() and not list(tmp_path.glob(".*part*"))
    back = load_back(path)
    assert len(back.faces) == len(mesh.faces)
    # Same surface, in the format's up-axis convention.
    assert np.allclose(back.bounds, turned_bounds(mesh, CONVENTION[suffix]), atol=1e-5)


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".stl"])
def test_meshio_reads_the_same_triangles(tmp_path, suffix):
    mesh = two_material_model(1)
    path = export_mesh(mesh, tmp_path / f"plant{suffix}")
    back = meshio.read(path)
    triangles = sum(len(block.data) for block in back.cells if block.type == "triangle")
    assert triangles == len(mesh.faces)
    points = np.asarray(back.points, dtype=np.float64)
    assert np.allclose([points.min(axis=0), points.max(axis=0)], turned_bounds(mesh, CONVENTION[suffix]), atol=1e-5)


@pytest.mark.parametrize("suffix", MESH_SUFFIXES)
@pytest.mark.parametrize("up", ["y", "z"])
def test_up_turns_the_model_and_keeps_its_volume(tmp_path, suffix, up):
    """--up: y keeps plantgen's frame, z turns it +90° about x; both keep the solid (a
    mirrored model would have negative volume)."""
    mesh = tessellate(chain_frusta(BENT, [0.3, 0.25, 0.25, 0.2, 0.15]), 2)
    back = load_back(export_mesh(mesh, tmp_path / f"chain{suffix}", up=up))
    assert np.allclose(back.bounds, turned_bounds(mesh, up), atol=1e-5)
    back.merge_vertices(merge_tex=True, merge_norm=True)
    assert back.is_watertight and back.volume > 0
    assert back.volume == pytest.approx(mesh.to_trimesh(merge=True).volume, rel=1e-5)


def test_the_up_conventions_are_the_documented_ones():
    """PLY and STL open upright in z-up tools (Blender, slicers); glTF is y-up by its
    specification; OBJ, USD and SWC keep y; TreeQSM's cylinder models are z-up."""
    up = {suffix: fmt.up for suffix, fmt in EXPORT_FORMATS.items()}
    assert up == {".glb": "y", ".gltf": "y", ".obj": "y", ".ply": "z", ".stl": "z", ".usda": "y", ".usdc": "y",
                  ".usd": "y", ".swc": "y", ".qsm.csv": "z", ".qsm.mat": "z"}
    guide = (Path(__file__).resolve().parents[1] / "docs" / "how-to" / "export.md")
    if not guide.is_file():
        pytest.skip("needs the source tree's docs/how-to/export.md")
    rows = {cells[1].strip(): cells[3].strip() for line in guide.read_text(encoding="utf-8").splitlines()
            if line.startswith("| `.") and len(cells := line.split("|")) > 4}
    assert {suffix: rows.get(f"`{suffix}`") for suffix in up} == up


def _convention(protocol) -> list[tuple[str, object]]:
    """(name, kind) of the parameters of a writer convention's ``__call__``, self left out."""
    params = list(inspect.signature(protocol.__call__).parameters.values())[1:]
    return [(q.name, q.kind) for q in params]


def test_every_format_row_names_a_writer_of_its_kinds_convention():
    """Each row carries its writer ("module:function", imported on first use), under
    plantgen.export, taking what its kind's convention passes (MeshWriter, SkeletonWriter)."""
    conventions = {"mesh": _convention(MeshWriter), "skeleton": _convention(SkeletonWriter)}
    assert set(conventions) == set(FORMAT_KINDS)
    for suffix, fmt in EXPORT_FORMATS.items():
        writer = fmt.load_writer()
        assert writer.__module__.startswith("plantgen.exporters."), (suffix, writer.__module__)
        params = [(q.name, q.kind) for q in inspect.signature(writer).parameters.values()]
        expected = conventions[fmt.kind]
        # the first two may be named after what the writer takes; the keywords are the convention's
        assert [k for _, k in params] == [k for _, k in expected], (suffix, params)
        assert params[2:] == expected[2:], (suffix, params)


def test_the_writers_of_optional_extras_are_imported_on_first_use_only():
    """Importing plantgen's pipeline imports neither the writers that need an optional
    package (usd-core, scipy) nor those packages, nor trimesh."""
    lazy = sorted({fmt.writer.split(":")[0] for fmt in EXPORT_FORMATS.values() if fmt.module})
    assert lazy == ["plantgen.exporters.qsm", "plantgen.exporters.usd"]
    code = "import json, sys, plantgen.pipeline; print(json.dumps(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": str(Path(plantgen.__file__).parents[1])}).stdout
    loaded = json.loads(out)
    assert "plantgen.exporters.formats" in loaded
    assert not [m for m in loaded if m in lazy or m.split(".")[0] in ("pxr", "scipy", "trimesh")]


def test_a_row_must_name_a_kind_and_a_writer():
    with pytest.raises(ValueError, match="kind must be one of mesh, skeleton"):
        Format("x", ".x", "cloud", "y", False, 0, "plantgen.exporters.gltf:write_gltf")
    with pytest.raises(ValueError, match="module:function"):
        Format("x", ".x", "mesh", "y", False, 0, "plantgen.exporters.gltf.write_gltf")


def test_a_new_format_is_one_row_and_its_writer(tmp_path, monkeypatch):
    """Nothing dispatches by format name: a row with its writer is enough for export_mesh,
    write_skeleton and the export command's pipeline, which call it with the convention's
    arguments and the row's up axis."""
    calls = []

    def write_points(plants, path, *, up, colours, instancing, unit, name, progress, animation, extras,
                     textures):
        calls.append(("mesh", path.name, up, instancing, len(plants)))
        path.write_text("points")
        return [path]

    def write_bones(skeleton, path, *, up, unit, tolerance, name):
        calls.append(("skeleton", path.name, up, unit, name))
        path.write_text("bones")
        return {"paths": [path], "bones": len(skeleton)}

    monkeypatch.setitem(EXPORT_FORMATS, ".pts", Format("pts", ".pts", "mesh", "z", True, 100, write_points))
    monkeypatch.setitem(EXPORT_FORMATS, ".bones", Format("bones", ".bones", "skeleton", "z", False, 0, write_bones))
    assert export_mesh(two_material_model(0), tmp_path / "plant.pts") == tmp_path / "plant.pts"
    grown = grow_file("saguaro")
    info = write_skeleton(grown.skeleton, tmp_path / "plant.bones", unit=0.5, name="cactus")
    assert info == {"paths": [tmp_path / "plant.bones"], "bones": len(grown.skeleton)}
    summary = export_model("saguaro", tmp_path / "model.bones")
    assert summary["format"] == "bones" and summary["path"] == tmp_path / "model.bones"
    assert calls == [("mesh", "plant.pts", "z", "nodes", 1), ("skeleton", "plant.bones", "z", 0.5, "cactus"),
                     ("skeleton", "model.bones", "z", 1.0, "saguaro")]
    with pytest.raises(ExportError, match="holds a mesh, not a skeleton"):
        write_skeleton(grown.skeleton, tmp_path / "plant.glb")


def test_a_format_without_instancing_refuses_a_scene_in_one_line(tmp_path):
    """OBJ, PLY and STL hold one mesh in place: their writers refuse placed copies or several
    plants, naming the format's suffix, and write nothing."""
    mesh = two_material_model(0)
    plant = Plant("p", Skeleton.empty(mesh.material_names), mesh)
    placed = dataclasses.replace(plant, matrices=np.stack([np.eye(4)] * 2))
    for suffix, fmt in EXPORT_FORMATS.items():
        if fmt.kind == "mesh" and not fmt.instancing:
            for plants in ([placed], [plant, plant]):
                with pytest.raises(ExportError, match=rf"\{suffix} holds one mesh in place; flatten the scene first"):
                    write_plants(plants, tmp_path / f"scene{suffix.upper()}")
    assert list(tmp_path.iterdir()) == []


def test_a_continuing_chain_loads_back_watertight(tmp_path):
    mesh = tessellate(chain_frusta(BENT, [0.3, 0.25, 0.25, 0.2, 0.15]), 2)
    for suffix in (".stl", ".glb", ".obj"):
        back = load_back(export_mesh(mesh, tmp_path / f"chain{suffix}"))
        back.merge_vertices(merge_tex=True, merge_norm=True)
        assert back.is_watertight and back.volume > 0


def test_gltf_keeps_material_colours_uv_and_normals(tmp_path):
    mesh = two_material_model()
    colours = {"bark": (0.3, 0.2, 0.1), "leaf": (0.1, 0.6, 0.2)}
    for suffix in (".glb", ".gltf"):
        scene = trimesh.load(export_mesh(mesh, tmp_path / f"plant{suffix}", colours=colours))
        by_material = {geom.visual.material.name: geom for geom in scene.geometry.values()}
        assert set(by_material) == {"bark", "leaf"}
        for name, geom in by_material.items():
            base = np.asarray(geom.visual.material.baseColorFactor, dtype=float)
            assert np.allclose(base[:3] / (255 if base.max() > 1 else 1), colours[name], atol=1 / 255)
            faces_of = mesh.face_material == mesh.material_names.index(name)
            assert len(geom.faces) == faces_of.sum()
            used = np.unique(mesh.faces[faces_of])
            assert geom.visual.uv.shape == (len(used), 2)
            assert np.allclose(np.sort(geom.visual.uv[:, 0]), np.sort(mesh.uv[used, 0]), atol=1e-6)
            assert np.allclose(np.linalg.norm(geom.vertex_normals, axis=1), 1, atol=1e-5)


def test_gltf_json_names_its_bin_and_both_are_written(tmp_path):
    mesh = two_material_model(1)
    path = export_mesh(mesh, tmp_path / "my plant.gltf")
    doc = json.loads(path.read_text())
    assert doc["buffers"][0]["uri"] == "my%20plant.bin"
    assert (tmp_path / "my plant.bin").stat().st_size == doc["buffers"][0]["byteLength"]
    assert doc["asset"]["version"] == "2.0"


def test_obj_comes_with_its_mtl_one_material_per_plantgen_material(tmp_path):
    """The defect of issue 16: OBJ named a material.mtl that was never written, and every
    material collapsed into one."""
    mesh = two_material_model()
    colours = {"bark": (0.3, 0.2, 0.1), "leaf": (0.1, 0.6, 0.2)}
    path = export_mesh(mesh, tmp_path / "plant.obj", colours=colours)
    text = path.read_text()
    assert "mtllib plant.mtl" in text
    mtl = (tmp_path / "plant.mtl").read_text()
    declared = [line.split()[1] for line in mtl.splitlines() if line.startswith("newmtl ")]
    used = [line.split()[1] for line in text.splitlines() if line.startswith("usemtl ")]
    assert declared == ["bark", "leaf"] and set(used) == set(declared)
    # trimesh follows mtllib and keeps one material (with its Kd) per group of faces.
    scene = trimesh.load(path, group_material=True, process=False, split_object=True)
    geoms = list(scene.geometry.values()) if isinstance(scene, trimesh.Scene) else [scene]
    by_material = {g.visual.material.name: g for g in geoms}
    assert set(by_material) == {"bark", "leaf"}
    for name, geom in by_material.items():
        assert len(geom.faces) == int((mesh.face_material == mesh.material_names.index(name)).sum())
        diffuse = np.asarray(geom.visual.material.diffuse, dtype=float)[:3] / 255
        assert np.allclose(diffuse, colours[name], atol=1 / 255)


def test_obj_material_names_with_spaces_stay_distinct(tmp_path):
    mesh = dataclasses.replace(two_material_model(0), material_names=("dark bark", "dark  bark"))
    path = export_mesh(mesh, tmp_path / "plant.obj")
    mtl = (tmp_path / "plant.mtl").read_text()
    assert [line.split(maxsplit=1)[1] for line in mtl.splitlines() if line.startswith("newmtl")] == \
        ["dark_bark", "dark_bark_2"]
    assert len(load_back(path).faces) == len(mesh.faces)


def test_bad_targets_are_user_errors_and_leave_nothing(tmp_path):
    mesh = two_material_model(0)
    with pytest.raises(ExportError, match="unknown export format"):
        export_mesh(mesh, tmp_path / "plant.fbx")
    with pytest.raises(ExportError, match="cannot write .no such folder"):
        export_mesh(mesh, tmp_path / "missing" / "plant.glb")
    with pytest.raises(ExportError, match="holds a skeleton"):
        export_mesh(mesh, tmp_path / "plant.swc")
    assert list(tmp_path.iterdir()) == []


def test_a_failed_pair_leaves_neither_file(tmp_path, monkeypatch):
    """OBJ + MTL and .gltf + .bin are written together: a failure in the second leaves
    neither, and no temporary file."""
    from plantgen.exporters import obj

    mesh = two_material_model(0)

    def broken(*args, **kwargs):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(obj, "_rows", broken)
    with pytest.raises(ExportError, match="No space left"):
        export_mesh(mesh, tmp_path / "plant.obj")
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------- Khronos validator
@needs_node
@pytest.mark.parametrize("case", ["two materials", "relief knuckle", "gltf + bin", "z-up"])
def test_plantgen_gltf_passes_the_khronos_gltf_validator(tmp_path, case):
    if case == "relief knuckle":
        # A skinned chain with a knuckle and bark relief.
        from _geometry_helpers import chain_skeleton

        from plantgen.geometry.skeletons.skin import skin_skeleton

        frusta = skin_skeleton(chain_skeleton((30, 150), radii=(0.2, 0.15, 0.12, 0.1)))
        mesh = tessellate(frusta, 2, relief=True)
    else:
        mesh = two_material_model()
    suffix = ".gltf" if case == "gltf + bin" else ".glb"
    path = export_mesh(mesh, tmp_path / f"plant{suffix}", up="z" if case == "z-up" else None)
    assert_khronos_valid(path)


# ---------------------------------------------------------------------------- the command
def y_skeleton():
    from plantgen.geometry.skeletons.skeleton import Skeleton

    start = np.array([[0, 0, 0], [0, 1, 0], [0, 2, 0], [0, 1, 0]], float)
    end = np.array([[0, 1, 0], [0, 2, 0], [0.2, 3, 0], [0.8, 1.6, 0]], float)
    return Skeleton(start, end, [0.3, 0.25, 0.2, 0.1], [0.25, 0.2, 0.12, 0.05], [-1, 0, 1, 0],
                    [False, True, True, False], [0, 0, 0, 1], ("bark", "leaf"))


@pytest.mark.parametrize("suffix", [".glb", ".stl", ".obj", ".gltf", ".ply"])
def test_the_export_command_writes_the_counted_triangles(tmp_path, suffix):
    skel_path = tmp_path / "y.npz"
    y_skeleton().save(skel_path)
    out = tmp_path / f"y{suffix}"
    code, stdout, stderr = run_cli("export", skel_path, "-o", out, "--subdiv", "2")
    assert code == 0, stderr
    from plantgen.geometry.skeletons.skin import skin_skeleton

    frusta = skin_skeleton(y_skeleton())
    expected = len(tessellate(frusta, 2).faces)
    assert len(load_back(out).faces) == expected
    assert f"{expected:,} triangles" in stdout and f"{CONVENTION[suffix]}-up" in stdout


def test_the_export_command_reports_bad_input_in_one_line(tmp_path):
    skel_path = tmp_path / "y.npz"
    y_skeleton().save(skel_path)
    code, _, stderr = run_cli("export", skel_path, "-o", tmp_path / "y.fbx")
    assert code == 2 and "unknown export format" in stderr and len(stderr.strip().splitlines()) == 1
    code, _, stderr = run_cli("export", skel_path, "-o", tmp_path / "y.csv")
    assert code == 2 and ".qsm.csv" in stderr and len(stderr.strip().splitlines()) == 1
    code, _, stderr = run_cli("export", skel_path, "-o", tmp_path / "y.glb", "--up", "x")
    assert code == 2 and "--up" in stderr
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    code, _, stderr = run_cli("export", tmp_path / "junk.npz", "-o", tmp_path / "y.glb")
    assert code == 2 and stderr.startswith("plantgen: error:")
    assert not (tmp_path / "y.glb").exists()


def test_a_missing_extra_is_one_line_naming_the_install_command(tmp_path, monkeypatch):
    """usd-core and scipy are extras: without them the export stops before any work, in one
    line that says what to install (exit status 2)."""
    import importlib.util

    from plantgen.exporters import formats

    real = importlib.util.find_spec
    monkeypatch.setattr(formats.importlib.util, "find_spec",
                        lambda name, *a: None if name in ("pxr", "scipy") else real(name, *a))
    for suffix, extra in ((".usda", "usd"), (".qsm.mat", "qsm")):
        code, _, stderr = run_cli("export", "saguaro", "-o", tmp_path / f"s{suffix}")
        assert code == 2 and f"pip install '.[{extra}]'" in stderr, stderr
        assert len(stderr.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_default_gltf_colours_are_the_renderers_palette(tmp_path):
    from plantgen.geometry.skeletons.materials import material_palette

    mesh = two_material_model(0)
    scene = trimesh.load(export_mesh(mesh, tmp_path / "plant.glb"))
    palette = material_palette(mesh.material_names)
    by_material = {g.visual.material.name: g for g in scene.geometry.values()}
    for i, name in enumerate(mesh.material_names):
        base = np.asarray(by_material[name].visual.material.baseColorFactor, dtype=float)[:3]
        base = base / 255 if base.max() > 1 else base
        assert np.allclose(base, (palette["dark"][i] + palette["light"][i]) / 2, atol=1 / 255)


def test_an_export_too_large_to_hold_is_refused_before_tessellating(tmp_path):
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


def test_exports_show_progress_on_a_terminal_only(tmp_path):
    """On a terminal an export's stages show on stderr, never on stdout; a log (stderr not
    a terminal) gets no progress line; --quiet shows none."""
    code, stdout, stderr = run_cli_on_terminal("export", "saguaro", "-o", tmp_path / "s.obj")
    assert code == 0, stderr
    assert "tessellating plants" in stderr and "writing" in stderr
    assert "tessellating" not in stdout
    code, stdout, stderr = run_cli("export", "saguaro", "-o", tmp_path / "u.obj")
    assert code == 0 and stderr == "" and "wrote" in stdout
    code, stdout, stderr = run_cli_on_terminal("export", "saguaro", "-o", tmp_path / "t.obj", "-q")
    assert code == 0 and stdout == "" and stderr == ""


def test_export_help_documents_formats_and_up_conventions():
    code, stdout, _ = run_cli("export", "--help")
    assert code == 0
    stdout = " ".join(stdout.split())
    for word in (".qsm.csv", ".usda", ".gltf", "--up", "z for PLY, STL and QSM", "--instancing",
                 "EXT_mesh_gpu_instancing", "PointInstancer", "--unit", "--qsm-tolerance", "[default: nodes]",
                 "Blender 3.4", "camera, light and ground"):
        assert word in stdout, word

