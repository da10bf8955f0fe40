"""``plantgen batch`` on a real Dask LocalCluster (2 worker processes): complete manifests,
outputs identical to a 1-worker run, a worker killed mid-batch, a re-run after an
interrupt, a failed sweep value, and seeds that do not depend on scheduling."""

from __future__ import annotations

import json
import os
import signal
import threading
from pathlib import Path

import numpy as np
import pytest
import yaml
from _cli import run_cli
from PIL import Image

pytest.importorskip("dask.distributed", reason="plantgen[batch] (dask.distributed) is not installed")
pytest.importorskip("pyarrow", reason="plantgen[batch] (pyarrow) is not installed")

from dask.distributed import Client, LocalCluster  # noqa: E402

from plantgen.batch import parse_spec, plant_seed, run_batch  # noqa: E402
from plantgen.batch.manifest import read_manifest  # noqa: E402
from plantgen.geometry.skeletons.skeleton import Skeleton  # noqa: E402

TWIG = """\
name: twig
seed: 1
iterations: 3
defines: {a: 28, l: 0.5, w: 0.03}
axiom: "!(w) F(1) A"
rules:
  - "A -> !(w*0.7) [ &(a) F(l) A ] /(137.5) [ &(a) F(l) A ]"
  - {rule: "F(x) -> F(x*1.1)", p: 1.0}
materials: [bark]
"""


def write_spec(folder: Path, *, seeds="0:10", sweep=None, outputs=None) -> Path:
    (folder / "twig.yaml").write_text(TWIG)
    outputs = outputs or {"npz": True, "swc": True, "glb": {"level": 0},
                          "png": {"size": "48x36", "azimuths": [0, 90]}, "depth": True, "mask": "order"}
    spec = {"seed": 5, "plants": [{"grammar": "twig.yaml", "seeds": seeds, **({"sweep": sweep} if sweep else {})}],
            "outputs": outputs}
    path = folder / "spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path




def rows_of(folder: Path) -> dict:
    """The manifest's rows of a batch folder, by plant id."""
    return {r["id"]: r for r in read_manifest(folder).to_pylist()}


def dataset(folder: Path) -> dict:
    """Every file of a batch folder by relative path: arrays, pixels or bytes."""
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = str(p.relative_to(folder))
        if p.is_dir() or rel.startswith("manifest.parquet"):
            continue
        if p.suffix == ".npz":
            with np.load(p) as z:
                out[rel] = {k: z[k].tolist() for k in z.files}
        elif p.suffix == ".npy":
            out[rel] = np.load(p).tolist()
        elif p.suffix == ".png":
            out[rel] = np.asarray(Image.open(p)).tolist()
        else:
            out[rel] = p.read_bytes()
    return out


def test_a_batch_is_complete_and_the_same_on_one_or_two_workers(tmp_path, client):
    spec = parse_spec(write_spec(tmp_path))
    two = run_batch(spec, tmp_path / "two", client=client)
    assert (two.done, two.failed, two.skipped) == (10, 0, 0)
    rows = rows_of(tmp_path / "two")
    assert sorted(rows) == sorted(t.id for t in spec.tasks())
    for task in spec.tasks():
        row = rows[task.id]
        assert row["status"] == "ok" and row["seed"] == plant_seed(5, "twig.yaml", task.index)
        files = row["files"]
        assert all(files[k] for k in ("npz", "swc", "glb", "png", "depth", "mask"))
        skeleton = Skeleton.load(tmp_path / "two" / files["npz"])
        assert row["segments"] == len(skeleton) > 3
        with np.load(tmp_path / "two" / files["npz"]) as z:
            assert z["branch_order"].shape == z["branch_id"].shape == (len(skeleton),)
            assert z["branch_order"][0] == 0 and z["branch_order"].max() >= 1
        mask = np.asarray(Image.open(tmp_path / "two" / files["mask"][0]))
        depth = np.load(tmp_path / "two" / files["depth"][0])
        assert np.array_equal(mask > 0, np.isfinite(depth))       # the mask covers what the view sees
        assert set(np.unique(mask)) >= {0, 1, 2}                    # background, trunk, order-1 branches
        assert row["volume"] > 0 and row["height"] > 0
    cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=50)
    with Client(cluster) as one_client:
        one = run_batch(spec, tmp_path / "one", client=one_client)
    cluster.close()
    assert one.done == 10
    assert dataset(tmp_path / "one") == dataset(tmp_path / "two")


def test_a_worker_killed_mid_batch_loses_nothing(tmp_path, client):
    spec = parse_spec(write_spec(tmp_path, seeds="0:16", outputs={"npz": True, "png": {"size": "64x48"}}))
    killed = threading.Event()

    def progress(result):
        if result.done >= 2 and not killed.is_set():
            killed.set()
            pids = client.run(os.getpid)                     # {worker address: pid}
            os.kill(pids[sorted(pids)[0]], signal.SIGKILL)

    result = run_batch(spec, tmp_path / "out", client=client, progress=progress)
    assert killed.is_set()
    rows = rows_of(tmp_path / "out")
    assert result.failed == 0 and len(rows) == 16
    assert all(r["status"] == "ok" for r in rows.values())
    client.wait_for_workers(2, timeout=60)        # the nanny restarts the worker


def test_a_rerun_after_an_interrupt_makes_only_the_rest(tmp_path, client):
    spec = parse_spec(write_spec(tmp_path, seeds="0:12", outputs={"npz": True}))

    def interrupt(result):
        if result.done >= 4:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_batch(spec, tmp_path / "out", client=client, progress=interrupt)
    kept = rows_of(tmp_path / "out")            # a valid manifest after the interrupt
    assert 4 <= len(kept) < 12
    again = run_batch(spec, tmp_path / "out", client=client)
    assert (again.listed, again.skipped, again.done) == (len(kept), len(kept), 12 - len(kept))
    assert len(rows_of(tmp_path / "out")) == 12
    assert not list((tmp_path / "out").rglob(".*"))   # no temporary file left behind


def test_a_bad_sweep_value_is_one_failed_row(tmp_path, client):
    sweep = {"grid": {"l": [0.5, 1.0e300]}}            # 1e300 m internodes: over the coordinate limit
    spec = parse_spec(write_spec(tmp_path, seeds="0:2", sweep=sweep, outputs={"npz": True}))
    result = run_batch(spec, tmp_path / "out", client=client)
    rows = rows_of(tmp_path / "out")
    failed = [r for r in rows.values() if r["status"] == "failed"]
    assert result.failed == len(failed) == 2 and result.done == 2
    assert all(r["defines"] == [("l", 1e300)] for r in failed)
    assert all(r["error"] and "\n" not in r["error"] for r in failed)


def test_the_command_line(tmp_path):
    (tmp_path / "twig.yaml").write_text(TWIG)
    code, out, err = run_cli("batch", tmp_path / "twig.yaml", "--seeds", "0:3", "--outputs", "npz,swc",
                             "--out", tmp_path / "out", "--workers", "1")
    assert code == 0, err
    assert "3 plants: 3 made, 0 failed" in out
    rows = rows_of(tmp_path / "out")
    row = rows["twig-000001"]
    # any plant can be grown again alone from its manifest row
    code, _, err = run_cli("grow", tmp_path / "twig.yaml", "--seed", row["seed"], "-o", tmp_path / "a.npz")
    assert code == 0, err
    with np.load(tmp_path / "a.npz") as a, np.load(tmp_path / "out" / "npz" / "twig-000001.npz") as b:
        assert np.array_equal(a["end"], b["end"])
    code, _, err = run_cli("batch", tmp_path / "twig.yaml", "--out", tmp_path / "x")
    assert code == 2 and len(err.strip().splitlines()) == 1


def test_the_glb_labels_every_vertex_with_its_branch_order(tmp_path):
    """The batch's glTF carries branch order as the vertex attribute _BRANCH_ORDER: read back
    from the file, it spans the skeleton's orders, and the Khronos validator passes it."""
    import shutil

    from _node import assert_khronos_valid

    from plantgen.batch.plant import make_plant
    from plantgen.batch.spec import simple_spec
    from plantgen.geometry.skeletons.topology import branches

    (tmp_path / "twig.yaml").write_text(TWIG)
    (tmp_path / "glb").mkdir()
    (tmp_path / "npz").mkdir()
    spec = simple_spec(str(tmp_path / "twig.yaml"), "0:1", ["glb", "npz"], glb_level=0)
    row = make_plant(next(spec.tasks()), spec.outputs, str(tmp_path))
    assert row["status"] == "ok", row["error"]
    path = tmp_path / row["files"]["glb"]
    data = path.read_bytes()
    length = int.from_bytes(data[12:16], "little")
    doc = json.loads(data[20:20 + length])
    binary = data[20 + length + 8:]
    orders = set()
    for prim in doc["meshes"][0]["primitives"]:
        acc = doc["accessors"][prim["attributes"]["_BRANCH_ORDER"]]
        view = doc["bufferViews"][acc["bufferView"]]
        values = np.frombuffer(binary, np.float32, acc["count"], view["byteOffset"])
        orders |= set(np.unique(values).astype(int).tolist())
    skeleton = Skeleton.load(tmp_path / row["files"]["npz"])
    assert orders == set(np.unique(branches(skeleton).segment_order).tolist())
    if shutil.which("node") is None:
        pytest.skip("Node.js is not installed: the Khronos validator needs it (the rest of this test ran)")
    assert_khronos_valid(path)


@pytest.mark.parametrize("mask", ["order", "material"])
def test_a_leafy_plants_views_masks_and_glb_carry_its_leaves(tmp_path, mask):
    """A grammar with leaves: the mask labels every pixel the colour view sees (frusta and
    leaves, the same hits), leaves with their class (order mask: LEAF_ORDER_LABEL; material
    mask: the leaf material + 1), and the glb holds the leaf triangles."""
    import trimesh
    from PIL import Image

    from plantgen.batch.plant import LEAF_ORDER_LABEL, make_plant
    from plantgen.batch.spec import simple_spec
    from plantgen.pipeline import grow_file

    leafy = TWIG.replace("materials: [bark]", "materials: [bark, leaf]").replace(
        '"A -> !(w*0.7) [ &(a) F(l) A ] /(137.5) [ &(a) F(l) A ]"',
        '"A -> !(w*0.7) [ &(a) F(l) A ] /(137.5) [ &(a) F(l) A ] [ ;(1) {.+(30)G(0.3).-(30)G(0.3).-(30)G(0.3).} ]"')
    (tmp_path / "leafy.yaml").write_text(leafy)
    for kind in ("png", "depth", "mask", "glb"):
        (tmp_path / kind).mkdir()
    spec = simple_spec(str(tmp_path / "leafy.yaml"), "0:1", ["png", "depth", "mask", "glb"], size="96x72",
                       glb_level=0, mask=mask)
    row = make_plant(next(spec.tasks()), spec.outputs, str(tmp_path))
    assert row["status"] == "ok", row["error"]
    files = row["files"]
    labels = np.asarray(Image.open(tmp_path / files["mask"][0]))
    depth = np.load(tmp_path / files["depth"][0])
    assert np.array_equal(labels > 0, np.isfinite(depth))
    leaf_label = LEAF_ORDER_LABEL if mask == "order" else 2
    assert (labels == leaf_label).sum() > 20 and (labels == 1).sum() > 5
    polygons = grow_file(tmp_path / "leafy.yaml", seed=next(spec.tasks()).seed).polygons
    data = (tmp_path / files["glb"]).read_bytes()
    doc = json.loads(data[20:20 + int.from_bytes(data[12:16], "little")])
    leaf_faces = sum(doc["accessors"][p["indices"]]["count"] // 3 for p in doc["meshes"][0]["primitives"]
                     if doc["materials"][p["material"]]["name"].endswith("(leaf)"))
    assert len(polygons) > 3 and leaf_faces == len(polygons.triangles)
    assert len(trimesh.load(tmp_path / files["glb"]).geometry) >= 2     # trimesh reads frusta and leaves


def glb_triangles(path: Path) -> int:
    """Triangles in a .glb: every primitive's indices over 3."""
    data = path.read_bytes()
    doc = json.loads(data[20:20 + int.from_bytes(data[12:16], "little")])
    return sum(doc["accessors"][p["indices"]]["count"] // 3 for m in doc["meshes"] for p in m["primitives"])


def test_a_batch_plant_is_what_render_and_export_make(tmp_path, client):
    """A grammar's ``turtle: smooth_bends`` reaches the batch: its view is, pixel for pixel,
    the PNG ``plantgen render`` draws from the same camera, and its glb holds the triangles
    of ``plantgen export`` at the same level; the grammar without smooth bends gives
    another skin, another picture and another triangle count."""
    from plantgen.batch.plant import view_camera
    from plantgen.geometry.skeletons.skin import skin_skeleton
    from plantgen.pipeline import grow_file, model_leaves, resolve_input, skin_model

    data = yaml.safe_load(resolve_input("saguaro").read_text())
    assert data.pop("turtle") == {"smooth_bends": 20}       # the shipped saguaro's; the plain copy has none
    (tmp_path / "plain.yaml").write_text(yaml.safe_dump(data))
    (tmp_path / "smooth.yaml").write_text(yaml.safe_dump({**data, "turtle": {"smooth_bends": 30}}))
    spec = {"seed": 5, "plants": [{"grammar": "smooth.yaml", "seeds": "0:1"}],
            "outputs": {"npz": True, "glb": {"level": 0}, "png": {"size": "64x48", "azimuths": [30]}}}
    (tmp_path / "spec.yaml").write_text(yaml.safe_dump(spec))
    result = run_batch(parse_spec(tmp_path / "spec.yaml"), tmp_path / "out", client=client)
    assert (result.done, result.failed) == (1, 0)
    (row,) = rows_of(tmp_path / "out").values()
    files, seed = row["files"], row["seed"]

    grown = grow_file(tmp_path / "smooth.yaml", seed=seed)
    assert np.array_equal(Skeleton.load(tmp_path / "out" / files["npz"]).end, grown.skeleton.end)
    frusta = skin_model(grown)
    assert len(frusta) > len(skin_skeleton(grown.skeleton))          # the bends became arcs
    view_camera(frusta, (64, 48), 30, model_leaves(grown)).save(tmp_path / "cam.json")
    images = {}
    for name in ("smooth", "plain"):
        # a batch draws the plant alone, as before the render's default ground: --ground none
        code, _, err = run_cli("render", tmp_path / f"{name}.yaml", "--seed", seed, "--camera", tmp_path / "cam.json",
                               "--no-relief", "--ground", "none", "-o", tmp_path / f"{name}.png")
        assert code == 0, err
        images[name] = np.asarray(Image.open(tmp_path / f"{name}.png"))
    batch_png = np.asarray(Image.open(tmp_path / "out" / files["png"][0]))
    assert batch_png.shape == (48, 64, 3)
    assert np.array_equal(batch_png, images["smooth"])
    assert not np.array_equal(batch_png, images["plain"])

    triangles = {}
    for name in ("smooth", "plain"):
        code, _, err = run_cli("export", tmp_path / f"{name}.yaml", "--seed", seed, "--subdiv", "0", "-q",
                               "-o", tmp_path / f"{name}.glb")
        assert code == 0, err
        triangles[name] = glb_triangles(tmp_path / f"{name}.glb")
    assert glb_triangles(tmp_path / "out" / files["glb"]) == triangles["smooth"] != triangles["plain"]


def test_a_glb_over_the_export_limit_is_a_failed_row(tmp_path):
    """The batch's glb is held to ``plantgen export``'s limits: over them, the row fails
    with export's one line and no glb is written."""
    from plantgen.batch.plant import make_plant
    from plantgen.batch.spec import simple_spec
    from plantgen.limits import Limits

    (tmp_path / "twig.yaml").write_text(TWIG)
    (tmp_path / "glb").mkdir()
    spec = simple_spec(str(tmp_path / "twig.yaml"), "0:1", ["glb"], glb_level=0)
    row = make_plant(next(spec.tasks()), spec.outputs, str(tmp_path), Limits(max_export_triangles=50))
    assert row["status"] == "failed" and "over the export limit of 50" in row["error"]
    assert not list((tmp_path / "glb").iterdir())
    assert make_plant(next(spec.tasks()), spec.outputs, str(tmp_path))["status"] == "ok"
