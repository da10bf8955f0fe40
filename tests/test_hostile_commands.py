"""Hostile input for every command (grow, render, export, scan, batch, view, convert) and every
input kind (grammars, scenes, .npz and .swc skeletons, options at their extremes): one
test per class of failure, each on inputs designed here.

As ``test_hostile.py``: the cases run in a subprocess (``hostile_runner.py``) under a
1 GiB address-space limit, and each refusal must be exit 2, one line, nothing left behind
(nor a temporary file) and under 2 s of the case's own CPU time. The accepted cases that
need a GL context or write files run in-process (``run_cli``).
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import numpy as np
import pytest
from _cli import run_cli
from test_hostile import assert_refused, run_cases, write

from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.swc import read_swc

# A small grammar: a chain of 2,048 segments (11 doublings), cheap to grow.
CHAIN = "name: chain\naxiom: F\niterations: 11\nrules: ['F -> FF']\n"
# A bush: branches in every direction around its middle, about 800 segments.
BUSH = ("name: bush\naxiom: F\niterations: 4\nturtle: {angle: 60, step: 1, radius: 0.3}\n"
        "rules: ['F -> F[+F][-F][&F][^F]F']\n")


LPY = Path(__file__).with_name("data") / "lpy" / "abop_bush.lpy"


def _fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


def _is_fifo(path: Path) -> bool:
    return stat.S_ISFIFO(os.lstat(path).st_mode)


def _leftovers(folder: Path, keep) -> list[str]:
    """Files in ``folder`` other than ``keep`` (names): what a refusal left behind."""
    return sorted(p.name for p in folder.iterdir() if p.name not in set(keep))


# ---------------------------------------------------------------------- 1. outputs that are not ours
def test_no_command_replaces_or_writes_through_a_device_a_fifo_or_a_folder(tmp_path):
    """A FIFO, a link to a FIFO, a folder (and a character device, as root) named as any
    output of any command: one line, 'cannot write', before any work; the node is left
    as it was, never renamed over."""
    chain = write(tmp_path, "chain.yaml", CHAIN)
    fifo = _fifo(tmp_path / "pipe.npz")
    png_fifo = _fifo(tmp_path / "pipe.png")
    (tmp_path / "link.ply").symlink_to(_fifo(tmp_path / "pipe2.ply"))
    folder = tmp_path / "folder.glb"
    folder.mkdir()
    (tmp_path / "x.swc").mkdir()
    cases = [
        ["grow", chain, "-o", fifo],
        ["grow", chain, "-o", tmp_path / "x.npz", "--format", "swc"],    # x.swc is a folder
        ["render", chain, "-o", png_fifo, "--size", "16x16"],
        ["render", chain, "-o", tmp_path / "r.png", "--size", "16x16", "--camera-out", png_fifo.with_suffix(".json")],
        ["export", chain, "-o", folder],
        ["export", chain, "-o", tmp_path / "e.obj", "--subdiv", "0"],     # its .mtl: below, a FIFO
        ["scan", chain, "-o", tmp_path / "link.ply"],
        ["view", chain, "--snapshot", png_fifo],
        ["convert", LPY, "-o", _fifo(tmp_path / "pipe.yaml")],
    ]
    _fifo(tmp_path / "e.mtl")
    _fifo(png_fifo.with_suffix(".json"))
    devices = []
    if os.geteuid() == 0:        # only root makes a device node: a copy of /dev/null
        os.mknod(tmp_path / "null.npz", 0o666 | stat.S_IFCHR, os.makedev(1, 3))
        cases.append(["grow", chain, "-o", tmp_path / "null.npz"])
        devices.append(tmp_path / "null.npz")
    before = sorted(p.name for p in tmp_path.iterdir())
    results = run_cases(tmp_path, cases)
    for result in results:
        assert_refused(result, "cannot write (")
        assert "regular file" in result["stderr"] or "is a folder" in result["stderr"], result["stderr"]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([*before, "cases.json"])
    for node in (fifo, png_fifo, tmp_path / "pipe2.ply", tmp_path / "e.mtl", tmp_path / "pipe.yaml"):
        assert _is_fifo(node)
    for node in devices:
        assert stat.S_ISCHR(os.lstat(node).st_mode)


def test_one_wording_for_a_missing_or_unwritable_folder_in_every_command(tmp_path):
    chain = write(tmp_path, "chain.yaml", CHAIN)
    (tmp_path / "file").write_text("not a folder")
    missing = tmp_path / "no" / "such"
    cases = [["grow", chain, "-o", missing / "x.npz"],
             ["render", chain, "-o", missing / "x.png", "--size", "16x16"],
             ["render", chain, "--frames", "2", "-o", missing / "x.gif", "--size", "16x16"],
             ["export", chain, "-o", missing / "x.glb"],
             ["scan", chain, "-o", missing / "x.ply"],
             ["view", chain, "--snapshot", missing / "x.png"],
             ["convert", LPY, "-o", missing / "x.yaml"],
             ["view", chain, "--shots", missing],
             ["grow", chain, "-o", tmp_path / "file" / "x.npz"],
             ["export", chain, "-o", tmp_path / "file" / "x.stl"],
             ["view", chain, "--shots", tmp_path / "file"]]
    results = run_cases(tmp_path, cases)
    for result in results[:8]:
        assert_refused(result, ("cannot write (no such folder", str(tmp_path / "no" / "such")))
    for result in results[8:]:
        assert_refused(result, ("cannot write (", "is not a folder"))


def test_a_stale_temporary_link_is_not_written_through(tmp_path):
    """A link left at an output's temporary name, pointing elsewhere: the write replaces
    the link, never the file it points to."""
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    (tmp_path / ".out.npz.part.npz").symlink_to(victim)
    code, _, err = run_cli("grow", write(tmp_path, "chain.yaml", CHAIN), "-o", tmp_path / "out.npz", "-q")
    assert code == 0, err
    assert victim.read_text() == "keep me"
    assert len(Skeleton.load(tmp_path / "out.npz")) == 2048
    assert not os.path.lexists(tmp_path / ".out.npz.part.npz")


def test_an_api_render_checks_its_output_before_the_work(tmp_path):
    import plantgen
    from plantgen.errors import PlantgenError

    with pytest.raises(PlantgenError, match="cannot write .no such folder"):
        plantgen.render(write(tmp_path, "chain.yaml", CHAIN), tmp_path / "no" / "x.png", size=(16, 16))
    with pytest.raises(PlantgenError, match="cannot write .it is not a regular file"):
        plantgen.export(write(tmp_path, "chain.yaml", CHAIN), _fifo(tmp_path / "x.glb"))


# ---------------------------------------------------------------------- 2. budgets count what is built
def test_budgets_count_every_placed_copy_before_any_is_skinned(tmp_path):
    """9,000 copies of a 2,048-segment plant (18.4 M placed segments, under drawn_segments)
    in a three-line scene: render, export (instanced or not, with or without lod) and scan
    refuse before skinning, in bounded memory and time, or (a glTF export, instanced)
    write the plant once and a node per copy, its camera framed per copy (issue 45); the
    scan, which skins the plant once, finishes in bounded memory or is refused by its
    budgets."""
    write(tmp_path, "chain.yaml", CHAIN)
    grid = "  - grammar: chain.yaml\n    grid: {count: [90, 100], spacing: [1, 1], seeds: 1}\n"
    scene = write(tmp_path, "many.yaml", "name: many\ninstances:\n" + grid)
    lod = write(tmp_path, "lod.yaml", "name: lod\neffects: [lod]\ninstances:\n" + grid)
    cases = [["render", scene, "-o", tmp_path / "a.png"],
             ["export", scene, "-o", tmp_path / "a.glb"],
             ["export", lod, "-o", tmp_path / "b.glb"],
             ["export", scene, "-o", tmp_path / "a.ply", "--subdiv", "0"],
             ["scan", scene, "-o", tmp_path / "s.ply"]]
    # the scan too under the 1 GiB of address space: on a machine without a GPU device node
    # it no longer opens llvmpipe's GL context (to learn it is software) before the
    # compiled CPU walk (it needed 2 GiB with that context)
    results = run_cases(tmp_path, cases)
    assert_refused(results[0], ("18,432,000 segments", "render_bytes"), outputs=[tmp_path / "a.png"])
    for result, glb in ((results[1], "a.glb"), (results[2], "b.glb")):
        assert result["code"] == 0, result
        blob = (tmp_path / glb).read_bytes()
        doc = json.loads(blob[20:20 + int.from_bytes(blob[12:16], "little")])
        assert sum(1 for node in doc["nodes"] if "mesh" in node) == 9000
    assert_refused(results[3], ("294,912,000 triangles", "export limit"), outputs=[tmp_path / "a.ply"])
    # The scan skins the plant once and traces its copies through two levels: done under
    # the subprocess's 1 GiB of address space, or refused by a scan budget in one line.
    scanned = results[4]
    if scanned["code"] == 0:
        assert (tmp_path / "s.ply").stat().st_size > 0
    else:
        assert_refused(scanned, "limit scan_", outputs=[tmp_path / "s.ply"])


def test_instances_of_all_grids_are_counted_before_any_plant_grows(tmp_path):
    """Two grids of 8,000 copies each of a grammar that takes long to grow (every copy its
    own seed): refused by the count, before the first copy is grown."""
    write(tmp_path, "slow.yaml", "name: slow\naxiom: F\niterations: 14\nrules: ['F -> F[+F]F']\n")
    grid = "  - grammar: slow.yaml\n    grid: {count: [80, 100], spacing: [1, 1]}\n"
    scene = write(tmp_path, "grids.yaml", "name: grids\ninstances:\n" + grid + grid)
    results = run_cases(tmp_path, [[cmd, scene, "-o", tmp_path / f"x.{ext}"]
                                   for cmd, ext in (("grow", "npz"), ("render", "png"), ("export", "glb"),
                                                    ("scan", "ply"))])
    for result in results:
        assert_refused(result, ("instances placed", "16,000", "limit instances"))


def test_airborne_scans_count_their_flight_lines_before_making_them(tmp_path):
    chain = write(tmp_path, "chain.yaml", CHAIN)
    air = ["scan", chain, "-o", tmp_path / "a.ply", "--scan-mode", "airborne"]
    spec = write(tmp_path, "spec.yaml", "plants: [{grammar: chain.yaml, seeds: 2}]\n"
                 "outputs: {points: {format: ply, mode: airborne, line_spacing: 5.0e-324}}\n")
    results = run_cases(tmp_path, [[*air, "--line-spacing", "1e-8"], [*air, "--flight-height", "1e-6"],
                                   [*air, "--pulse-spacing", "1e-9"], [*air, "--line-spacing", "5e-324"],
                                   [*air, "--pulse-spacing", "4e-320"],
                                   ["batch", spec, "--out", tmp_path / "out"]])
    for result in results[:3]:
        assert_refused(result, ("an airborne scan", "rays", "limit scan_rays"), outputs=[tmp_path / "a.ply"])
    for result in results[3:5]:
        assert_refused(result, "is not in the range")     # a denormal spacing: one line, exit 2
    assert_refused(results[5], "line-spacing")
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------------- 3. hangs
def _many_types_swc(path: Path, n: int) -> Path:
    lines = ["1 1 0 0 0 1 -1"] + [f"{i} {i} 0 {i} 0 0.5 {i - 1}" for i in range(2, n + 1)]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_what_would_hang_is_bounded(tmp_path):
    """100,000 node types (materials) in an SWC, an aspect step a hair above 1, a million
    workers, a scanner a hair from the centre, a scanner inside a bush."""
    types = _many_types_swc(tmp_path / "types.swc", 100_000)
    bush = write(tmp_path, "bush.yaml", BUSH)
    radii = 0.01 * 1.05 ** np.arange(120)
    n = len(radii)
    skel = Skeleton(np.c_[np.zeros(n), np.arange(n), np.zeros(n)].astype(float),
                    np.c_[np.zeros(n), np.arange(1, n + 1), np.zeros(n)].astype(float), radii, radii,
                    np.arange(-1, n - 1), np.arange(n) > 0, np.zeros(n, int), ("bark",))
    skel.save(tmp_path / "taper.npz")
    cases = [["grow", types, "-o", tmp_path / "t.npz"], ["render", types, "-o", tmp_path / "t.png"],
             ["export", types, "-o", tmp_path / "t.glb"],
             ["export", tmp_path / "taper.npz", "-o", tmp_path / "taper.glb", "--aspect-step", "1.000001"],
             ["batch", bush, "--seeds", "0:1", "--workers", "1000000", "--out", tmp_path / "out"],
             ["scan", bush, "-o", tmp_path / "s.ply", "--scan-distance", "1e-300"],
             ["scan", bush, "-o", tmp_path / "s.ply", "--scanner-positions", "0,2,0", "--angular-step", "0.02"]]
    results = run_cases(tmp_path, cases)
    for result in results[:3]:
        assert_refused(result, ("node types", "256"), outputs=[tmp_path / "t.npz"])
    assert_refused(results[3], ("--aspect-step", "normal maps"), outputs=[tmp_path / "taper.glb"])
    assert_refused(results[4], ("--workers", "1<=x<=256"))
    assert not (tmp_path / "out").exists()
    assert_refused(results[5], ("--scan-distance", "not in the range"))
    assert_refused(results[6], ("would return about", "limit scan_bytes"), outputs=[tmp_path / "s.ply"])


# ---------------------------------------------------------------------- 4. one line, exit 2
def test_extreme_numbers_and_link_loops_are_one_line_with_exit_2(tmp_path):
    """5,000-digit integers wherever an integer is parsed, a grammar linked to itself (as
    a scene's grammar, a batch spec's), tiny frame rates, huge units and noise."""
    chain = write(tmp_path, "chain.yaml", CHAIN)
    big = "9" * 5000
    (tmp_path / "loop.yaml").symlink_to("loop.yaml")
    loop_scene = write(tmp_path, "loop_scene.yaml", "instances: [{grammar: loop.yaml}]\n")
    loop_spec = write(tmp_path, "loop_spec.yaml", "plants: [{grammar: loop.yaml, seeds: 1}]\noutputs: [npz]\n")
    spec = write(tmp_path, "spec.yaml", "plants: [{grammar: chain.yaml, seeds: 1}]\n"
                 f"outputs: {{png: {{size: '{big}x10'}}}}\n")
    seeds_spec = write(tmp_path, "seeds.yaml", f"plants: [{{grammar: chain.yaml, seeds: '0:{big}'}}]\noutputs: [npz]\n")
    swc = tmp_path / "bigid.swc"
    swc.write_text(f"1 1 0 0 0 1 -1\n{big} 3 0 1 0 1 1\n")
    cases = [["render", chain, "-o", tmp_path / "a.png", "--size", f"{big}x10"],
             ["batch", chain, "--seeds", f"0:{big}", "--out", tmp_path / "b"],
             ["batch", chain, "--seeds", "0:1", "--size", f"10x{big}", "--outputs", "png", "--out", tmp_path / "b"],
             ["batch", spec, "--out", tmp_path / "b"],
             ["batch", seeds_spec, "--out", tmp_path / "b"],
             ["grow", swc, "-o", tmp_path / "s.npz"],
             ["grow", loop_scene, "-o", tmp_path / "l.npz"],
             ["batch", loop_spec, "--out", tmp_path / "b"],
             ["render", chain, "--frames", "2", "--fps", "1e-300", "-o", tmp_path / "a.gif"],
             ["export", chain, "-o", tmp_path / "a.qsm.csv", "--unit", "1e308"],
             ["scan", chain, "-o", tmp_path / "a.ply", "--range-noise", "1e308"],
             ["scan", chain, "-o", tmp_path / "a.las", "--range-noise", "1e308"]]
    results = run_cases(tmp_path, cases)
    for result, case in zip(results, cases, strict=True):
        assert_refused(result, "", outputs=[Path(case[-1])] if case[-2] == "-o" else ())
        assert len(result["stderr"]) < 600, result["stderr"][:200]       # a 5,000-digit value is not echoed whole
        assert "unexpected failure" not in result["stderr"]
    assert "loop.yaml" in results[6]["stderr"] and "symbolic links" in results[6]["stderr"]
    assert not (tmp_path / "b").exists()


# ---------------------------------------------------------------------- 5. writers escape, stay finite
def test_writers_escape_what_their_format_cannot_hold(tmp_path):
    """A material name with a line break and an SWC node line in it, and one with ESC and
    BEL: the SWC reads back as written (no line injected), OBJ and MTL hold no control
    character."""
    names = ("bark\n2 3 9 9 9 1 1", "leaf\x1b[31m\x07 é")
    skel = Skeleton(np.array([[0, 0, 0], [0, 1, 0.0]]), np.array([[0, 1, 0], [0, 2, 0.0]]), np.full(2, 0.1),
                    np.full(2, 0.1), np.array([-1, 0]), np.array([False, True]), np.array([0, 1]), names)
    skel.save(tmp_path / "m.npz")
    code, _, err = run_cli("grow", tmp_path / "m.npz", "-o", tmp_path / "m.swc", "-q")
    assert code == 0, err
    text = (tmp_path / "m.swc").read_bytes()
    assert all(32 <= b < 127 or b == 10 for b in text)
    back = read_swc(tmp_path / "m.swc")
    assert back.material_names == names and len(back) == 2
    code, _, err = run_cli("export", tmp_path / "m.npz", "-o", tmp_path / "m.obj", "--subdiv", "0", "-q")
    assert code == 0, err
    for out in ("m.obj", "m.mtl"):
        data = (tmp_path / out).read_text(encoding="utf-8")
        assert not any(not c.isprintable() for line in data.splitlines() for c in line), out


def test_no_writer_writes_a_number_that_is_not_finite(tmp_path):
    from plantgen.geometry.rays.scan import PointCloud
    from plantgen.scanfiles import PointFileError, write_points

    cloud = PointCloud(np.array([[0.0, 1.0, np.inf]]), plant=np.zeros(1, int), part=np.zeros(1, int),
                       order=np.zeros(1, int), segment=np.zeros(1, int), leaf=np.full(1, -1),
                       scanner=np.zeros(1, int), scanners=np.zeros((1, 3)))
    for suffix in (".ply", ".las"):
        with pytest.raises(PointFileError, match="not finite"):
            write_points(cloud, tmp_path / f"p{suffix}")
    assert _leftovers(tmp_path, ()) == []


# ---------------------------------------------------------------------- 6. all outputs or none
def test_a_command_leaves_no_output_when_another_of_its_outputs_cannot_be_written(tmp_path):
    chain = write(tmp_path, "chain.yaml", CHAIN)
    (tmp_path / "x.swc").mkdir()
    (tmp_path / "m.bin").mkdir()
    cases = [["render", chain, "-o", tmp_path / "r.png", "--size", "16x16", "--camera-out",
              tmp_path / "no" / "c.json"],
             ["render", chain, "-o", tmp_path / "r.png", "--size", "16x16", "--depth-out", tmp_path / "no" / "d.npy"],
             ["grow", chain, "-o", tmp_path / "x.npz", "--format", "swc"],
             ["export", chain, "-o", tmp_path / "m.gltf", "--subdiv", "0"]]
    results = run_cases(tmp_path, cases)
    for result in results:
        assert_refused(result, "cannot write (")
    assert _leftovers(tmp_path, ("chain.yaml", "x.swc", "m.bin", "cases.json")) == []


def test_the_outputs_of_a_render_are_committed_together(tmp_path):
    """The image, the camera and the depth all appear, and no temporary file stays."""
    chain = write(tmp_path, "chain.yaml", CHAIN)
    code, out, err = run_cli("render", chain, "-o", tmp_path / "r.png", "--size", "16x12",
                             "--camera-out", tmp_path / "c.json", "--depth-out", tmp_path / "d.npy")
    assert code == 0, err
    assert _leftovers(tmp_path, ()) == ["c.json", "chain.yaml", "d.npy", "r.png"]
    assert np.load(tmp_path / "d.npy").shape == (12, 16)


# ---------------------------------------------------------------------- 7. refusals come before the work
def test_skeleton_limits_are_checked_before_the_file_is_parsed(tmp_path):
    """1,000,002 SWC nodes (one over the segments limit), 300,000 comment lines, and a
    .npz of 100,000 material names: refused in under 2 s of CPU."""
    nodes = tmp_path / "nodes.swc"
    nodes.write_text("1 1 0 0 0 1 -1\n" + "".join(f"{i} 3 0 {i} 0 1 {i - 1}\n" for i in range(2, 1_000_003)))
    comments = tmp_path / "comments.swc"
    comments.write_text("# c\n" * 300_000 + "1 1 0 0 0 1 -1\n2 3 0 1 0 1 1\n")
    n = 2
    Skeleton(np.zeros((n, 3)), np.ones((n, 3)), np.ones(n), np.ones(n), np.array([-1, -1]), np.zeros(n, bool),
             np.zeros(n, int), tuple(f"m{k}" for k in range(100_000))).save(tmp_path / "names.npz")
    cases = [[cmd, path, "-o", tmp_path / f"out.{ext}"] for path in (nodes, comments, tmp_path / "names.npz")
             for cmd, ext in (("grow", "npz"), ("render", "png"), ("export", "glb"), ("scan", "ply"))]
    results = run_cases(tmp_path, cases)
    for result in results[:4]:
        assert_refused(result, ("nodes.swc", "limit segments"))
    for result in results[4:8]:
        assert_refused(result, ("comments.swc", "comment marks"))
    for result in results[8:]:
        assert_refused(result, ("names.npz", "material names"))
