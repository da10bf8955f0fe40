"""Hostile input (issue 14): no grammar, scene or skeleton file can hang plantgen, exhaust
its memory, read outside its folder or write non-finite geometry.

One test per class of the issue (the README's error section lists them). Each runs its
cases in a subprocess (``hostile_runner.py``) under a 1 GiB address-space limit and a
wall-clock timeout, and asserts for every case: exit status 2, exactly one line on stderr,
no output file left (nor a temporary one), the case's time under ``CASE_SECONDS``, and for
paths that nothing outside the scene's folder was opened. A bounded hypothesis test then
mutates grammars and scenes: every outcome is success or one line with exit status 2.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
import yaml
from _cli import run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.swc import write_swc
from plantgen.limits import SETTLE_STEPS
from plantgen.lsystem.grammar import parse_grammar
from plantgen.pipeline import grow, grow_file

RUNNER = Path(__file__).with_name("hostile_runner.py")
MEMORY = 1 << 30            # the bound: 1 GB of address space
#: The CPU time a hostile input's refusal may take: 5x the 1 s the issue sets (issue 45: a
#: bound that stays keeps a 5x margin on a busy 2-core machine). The cases also assert the
#: work counters the refusals name, which do not depend on the machine.
CASE_SECONDS = 5.0
PROCESS_SECONDS = 120       # the subprocess, start-up and every case together

GRAMMAR = "name: g\naxiom: F\n"
BOMB = "".join(f"{a}: &{a} [{', '.join(['*' + p] * 9 if p else ['lol'] * 9)}]\n"
               for p, a in zip([None, "a", "b", "c", "d", "e", "f", "g"], "abcdefgh", strict=True))


def run_cases(tmp_path: Path, cases: list[list], memory: int = MEMORY) -> list[dict]:
    """Run each argv of ``cases`` through plantgen in one subprocess under ``memory`` bytes."""
    spec = tmp_path / "cases.json"
    spec.write_text(json.dumps([{"argv": [str(a) for a in argv]} for argv in cases]))
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=os.pathsep.join(
        [str(Path(__file__).resolve().parents[1]), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, str(RUNNER), "--memory", str(memory), str(spec)],
                          capture_output=True, text=True, timeout=PROCESS_SECONDS, env=env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stderr == "", proc.stderr[-3000:]    # nothing reached the terminal past sys.stderr
    return json.loads(proc.stdout)


def assert_refused(result: dict, match: str | tuple[str, ...], *, outputs=(), seconds: float = CASE_SECONDS) -> None:
    """Exit 2, one error line on stderr holding ``match`` (or each of a tuple of words), the
    last, after nothing but progress lines (indented: long work shows them at most once a
    second, so a slow machine may show one before a refusal), no output (nor temporary)
    file left, and fast: ``seconds`` of the case's own CPU time (on a shared machine the
    wall time is the neighbours' as much as ours)."""
    where = f"{result['argv']}: {result['stderr']!r}"
    assert result["code"] == 2, where
    *progress, last = [line for line in result["stderr"].splitlines() if line.strip()] or [""]
    assert all(line.startswith("  ") for line in progress), where
    lines = [last]
    assert lines[0].startswith("plantgen: error: "), where
    assert all(word in lines[0] for word in ((match,) if isinstance(match, str) else match)), where
    assert "Traceback" not in result["stderr"] and "allow_pickle" not in result["stderr"], where
    assert result["cpu_seconds"] < seconds, f"{where}: {result['cpu_seconds']:.1f} s of CPU"
    for out in outputs:
        out = Path(out)
        assert not out.exists(), where
        assert not list(out.parent.glob(f".{out.name}.part*")), where


def write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


# ---------------------------------------------------------------------- 1. YAML expansion
def test_yaml_alias_bombs_and_deep_nests_are_refused_before_they_are_built(tmp_path):
    """An alias bomb anywhere a value is read (header fields, a define, turtle.step, a
    rule's p, a scene's name, an instance's position), a recursive alias, a deep nest."""
    grammar_fields = {
        "name": "name: *h\n", "description": "description: *h\n", "seed": "seed: *h\n",
        "iterations": "iterations: *h\n", "define": "defines: {k: *h}\n", "step": "turtle: {step: *h}\n",
        "p": 'rules: [{rule: "F -> F", p: *h}]\n',
    }
    cases = []
    for key, text in grammar_fields.items():
        cases.append(["grow", write(tmp_path, f"{key}.yaml", BOMB + GRAMMAR + text), "-o", tmp_path / f"{key}.npz"])
    scene_bombs = {"scene_name": "name: *h\ninstances: [{grammar: g}]\n",
                   "position": "instances: [{grammar: g, position: *h}]\n"}
    write(tmp_path, "g.yaml", GRAMMAR)
    for key, text in scene_bombs.items():
        cases.append(["grow", write(tmp_path, f"{key}.yaml", BOMB + text), "-o", tmp_path / f"{key}.npz"])
    cases.append(["grow", write(tmp_path, "deep.yaml", GRAMMAR + "x: " + "[" * 500 + "]" * 500 + "\n"),
                  "-o", tmp_path / "deep.npz"])
    cases.append(["grow", write(tmp_path, "very_deep.yaml", "x: " + "[" * 100_000 + "]" * 100_000 + "\n"),
                  "-o", tmp_path / "very_deep.npz"])
    cases.append(["grow", write(tmp_path, "recursive.yaml", GRAMMAR + "description: &r [*r]\n"),
                  "-o", tmp_path / "recursive.npz"])
    results = run_cases(tmp_path, cases)
    for result, case in zip(results[:9], cases, strict=False):
        assert_refused(result, "aliases are expanded", outputs=[case[-1]])
        assert "line " in result["stderr"] and Path(case[1]).name in result["stderr"]
    for result, case in zip(results[9:11], cases[9:11], strict=True):
        # The behaviour, whichever layer refuses first: plantgen's depth count on the
        # parser's events, or the YAML library's own nesting limit (PyYAML 6.0.4's C
        # loader stops 100,000 nested ``[`` itself, in its own words). One line naming the
        # file, exit 2, fast, under the memory limit of the subprocess.
        assert_refused(result, Path(case[1]).name, outputs=[case[-1]])
    assert "nested deeper than" in results[9]["stderr"]     # 500 levels: plantgen's limit (64) refuses
    assert_refused(results[11], "alias *r inside the node it names", outputs=[cases[11][-1]])


def test_the_entry_point_itself_prints_one_line_under_the_memory_limit(tmp_path):
    """``python -m plantgen`` as a user runs it: the whole stderr is one line."""
    bomb = write(tmp_path, "bomb.yaml", BOMB + GRAMMAR + "name: *h\n")
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=os.pathsep.join(
        [str(Path(__file__).resolve().parents[1]), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-m", "plantgen", "grow", str(bomb), "-o", str(tmp_path / "b.npz")],
                          capture_output=True, text=True, timeout=60, env=env,
                          preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_AS, (MEMORY, MEMORY)))
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and "aliases are expanded" in proc.stderr
    assert not (tmp_path / "b.npz").exists()


# ---------------------------------------------------------------------- 2. numbers
def test_numbers_are_typed_finite_and_in_range(tmp_path):
    write(tmp_path, "g.yaml", GRAMMAR)
    grammars = {
        "seed: .inf": "seed must be an integer", "iterations: .nan": "iterations must be an integer",
        "seed: 99999999999999999999": "seed must be an integer 0..", "seed: -1": "seed must be an integer 0..",
        "iterations: 2.5": "iterations must be an integer", "seed: 1" + "0" * 5000: "YAML error",
        "turtle: {angle: .inf}": "angle must be a finite number", "defines: {k: [1]}": "must be a number",
    }
    scenes = {"seed: abc": "seed must be an integer", "seed: [1]": "seed must be an integer",
              "seed: 1.5": "seed must be an integer"}
    cases, matches = [], []
    for i, (text, match) in enumerate(grammars.items()):
        cases.append(["grow", write(tmp_path, f"g{i}.yaml", GRAMMAR + text + "\n"), "-o", tmp_path / f"g{i}.npz"])
        matches.append(match)
    for i, (text, match) in enumerate(scenes.items()):
        scene = write(tmp_path, f"s{i}.yaml", f"{text}\ninstances: [{{grammar: g}}]\n")
        cases.append(["grow", scene, "-o", tmp_path / f"s{i}.npz"])
        matches.append(match)
    params = ",".join(["1"] * 128)
    cases.append(["grow", write(tmp_path, "params.yaml", f"axiom: A({params}) F\n"), "-o", tmp_path / "p.npz"])
    matches.append("128 parameters, over the limit of 32")
    for result, case, match in zip(run_cases(tmp_path, cases), cases, matches, strict=True):
        assert_refused(result, match, outputs=[case[-1]])


# ---------------------------------------------------------------------- 3. work that does not grow
def test_derivations_that_do_not_grow_end_quickly_with_few_progress_lines(tmp_path):
    fixed = write(tmp_path, "fixed.yaml", 'axiom: F\nrules: ["F -> F"]\niterations: 1000000\n')
    cycle = write(tmp_path, "cycle.yaml", 'axiom: F A\nrules: ["A -> B", "B -> A"]\niterations: 999999\n')
    huge = write(tmp_path, "huge.yaml", 'axiom: F A\nrules: ["A -> B", "B -> A"]\niterations: 1.0e+18\n')
    count = write(tmp_path, "count.yaml", 'axiom: F A(0)\nrules: ["A(x) -> A(x+1)"]\niterations: 1000000\n')
    cases = [["grow", fixed, "-o", tmp_path / "fixed.npz"], ["grow", cycle, "-o", tmp_path / "cycle.npz"],
             ["grow", huge, "-o", tmp_path / "huge.npz"], ["grow", count, "-o", tmp_path / "count.npz"]]
    fixed_r, cycle_r, huge_r, count_r = run_cases(tmp_path, cases)
    for result in (fixed_r, cycle_r):   # a fixed point or a cycle: the remaining steps are skipped
        assert result["code"] == 0 and result["cpu_seconds"] < CASE_SECONDS, result
        assert len(result["stderr"].splitlines()) <= 2
    assert (tmp_path / "fixed.npz").exists() and (tmp_path / "cycle.npz").exists()
    assert_refused(huge_r, "over the limit of 1,000,000 (limit iterations", outputs=[cases[2][-1]])
    # no fixed point: the work budget (modules x steps) ends it, its progress at most a line
    # a second before the one error line
    # no fixed point: its steps alone would spend past the work budget (modules x steps), so
    # it is refused once it has not settled in SETTLE_STEPS steps, the estimate in the line
    *progress, error = count_r["stderr"].rstrip("\n").splitlines()
    assert all(line.startswith("  derivation step ") for line in progress)
    assert len(progress) <= count_r["seconds"] + 1
    assert_refused({**count_r, "stderr": error}, ("derive_work", "400,", f"first {SETTLE_STEPS:,} steps"),
                   outputs=[cases[3][-1]])


# ---------------------------------------------------------------------- 4. limits the file may raise
def test_a_file_can_lower_limits_but_never_raise_them(tmp_path):
    doubling = write(tmp_path, "doubling.yaml",
                     'axiom: A\nrules: ["A -> AA"]\niterations: 40\nmax_modules: 1000000000000\n')
    params = ",".join(f"x{i}" for i in range(32))
    wide = write(tmp_path, "wide.yaml", f'axiom: A({",".join(["1"] * 32)})\n'
                                        f'rules: ["A({params}) -> A({params}) A({params})"]\niterations: 22\n')
    write(tmp_path, "g.yaml", GRAMMAR)
    grid = write(tmp_path, "grid.yaml", "instances: [{grammar: g, grid: {count: [100000, 100000]}}]\n")
    lowered = write(tmp_path, "lowered.yaml", 'axiom: A\nrules: ["A -> AA"]\niterations: 12\nmax_modules: 1000\n')
    cases = [["grow", doubling, "-o", tmp_path / "d.npz"], ["grow", wide, "-o", tmp_path / "w.npz"],
             ["grow", grid, "-o", tmp_path / "grid.npz"],
             ["grow", lowered, "-o", tmp_path / "l.npz", "--max-modules", "100000"]]
    doubling_r, wide_r, grid_r, lowered_r = run_cases(tmp_path, cases)
    assert_refused(doubling_r, "over the limit of 5,000,000", outputs=[cases[0][-1]])
    assert_refused(wide_r, "derive_bytes", outputs=[cases[1][-1]])   # few modules, many bytes
    assert_refused(grid_r, "10,000,000,000 over the limit of 10,000 (limit instances", outputs=[cases[2][-1]])
    assert_refused(lowered_r, "over the limit of 1,000", outputs=[cases[3][-3]])


# ---------------------------------------------------------------------- 5. files that are not files
def test_only_regular_files_are_read(tmp_path):
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    cases = [["grow", "/dev/zero", "-o", tmp_path / "z.npz"], ["grow", fifo, "-o", tmp_path / "f.npz"],
             ["render", "/dev/zero", "-o", tmp_path / "z.png"], ["export", "/dev/zero", "-o", tmp_path / "z.glb"],
             ["grow", tmp_path, "-o", tmp_path / "d.npz"]]
    results = run_cases(tmp_path, cases)
    for result, case in zip(results[:4], cases, strict=False):
        assert_refused(result, "not a regular file", outputs=[case[-1]])
    assert_refused(results[4], "is a directory", outputs=[cases[4][-1]])


# ---------------------------------------------------------------------- 6. paths
def test_scene_references_stay_inside_the_scene_folder(tmp_path):
    scenes = tmp_path / "scenes"
    elsewhere = write(tmp_path, "elsewhere/tree.yaml", GRAMMAR)
    (scenes / "link.yaml").parent.mkdir(parents=True)
    (scenes / "link.yaml").symlink_to(elsewhere)
    refs = ["/etc/passwd", "../../../../etc/passwd", "../elsewhere/tree.yaml", "link.yaml", str(elsewhere)]
    cases = []
    for i, ref in enumerate(refs):
        scene = write(scenes, f"s{i}.yaml", yaml.safe_dump({"instances": [{"grammar": ref}]}))
        cases.append(["grow", scene, "-o", scenes / f"s{i}.npz"])
    allowed = write(scenes, "allowed.yaml", yaml.safe_dump({"instances": [{"grammar": "../elsewhere/tree.yaml"}]}))
    cases.append(["grow", allowed, "-o", scenes / "allowed.npz", "--allow-path", elsewhere.parent])
    results = run_cases(tmp_path, cases)
    for result, case in zip(results[:-1], cases, strict=False):
        assert_refused(result, "outside the scene's folder", outputs=[case[3]])
        assert "--allow-path" in result["stderr"]
        outside = [p for p in result["opened"] if not p.startswith(str(scenes))]
        assert outside == [], outside       # /etc/passwd, the grammar elsewhere: never opened
    assert results[-1]["code"] == 0, results[-1]["stderr"]
    assert str(elsewhere) in results[-1]["opened"]


# ---------------------------------------------------------------------- 7. non-finite results
def test_non_finite_geometry_is_refused_naming_where_it_came_from(tmp_path):
    grammars = {"long.yaml": ("axiom: F(1e308) F(1e308)\n", "segment 0 (module 1"),
                "step.yaml": ("axiom: F\nturtle: {step: 1.0e+308}\n", "turtle: step"),
                "wide.yaml": ("axiom: '!(1e308) F'\n", "segment 0 (module 2 of the derived string, F) has a radius")}
    cases, matches = [], []
    for name, (text, match) in grammars.items():
        cases.append(["grow", write(tmp_path, name, text), "-o", tmp_path / f"{name}.npz"])
        matches.append(match)
    write(tmp_path, "g.yaml", GRAMMAR)
    scenes = {"position": ("position: [1.0e+308, 0, 0]", "instance 1: position 1e+308 is beyond"),
              "scale": ("scale: 1.0e+308", "instance 1: scale 1e+308 is beyond"),
              "grid": ("position: [1.0e+8, 0, 0], grid: {count: [3, 1], spacing: [9.0e+8, 1]}",
                       "instance 1: placed, the plant reaches coordinates")}
    for name, (text, match) in scenes.items():
        scene = write(tmp_path, f"{name}.yaml", f"instances: [{{grammar: g, {text}}}]\n")
        cases.append(["grow", scene, "-o", tmp_path / f"{name}.npz"])
        matches.append(match)
    camera = write(tmp_path, "camera.yaml", "camera: {eye: [.nan, 0, 0], target: [0, 0, 0]}\n"
                                            "instances: [{grammar: g}]\n")
    cases.append(["render", camera, "-o", tmp_path / "camera.png"])
    matches.append("camera: eye must be a finite number")
    nan = tmp_path / "nan.npz"
    skel = grow(tmp_path / "g.yaml")
    np.savez(nan, **{k: getattr(skel, k) for k in ("start", "r_start", "r_end", "parent", "continues", "material")},
             end=np.full((1, 3), np.nan))
    for command, suffix in (("grow", ".npz"), ("render", ".png"), ("export", ".glb")):
        cases.append([command, nan, "-o", tmp_path / f"nan_out{suffix}"])
        matches.append("nan.npz: end holds NaN or inf (segment 0)")
    for option in ("--time", "--fps"):
        cases.append(["render", "dancing_cacti", "-o", tmp_path / "t.gif", "--frames", "2", option, "nan"])
        matches.append((option, "nan is not a finite number"))     # the option named, not click's wording
    for result, case, match in zip(run_cases(tmp_path, cases), cases, matches, strict=True):
        assert_refused(result, match, outputs=[case[3]])


def test_skins_and_meshes_are_checked_finite_before_they_are_drawn_or_written():
    from dataclasses import replace
    from types import SimpleNamespace

    from plantgen.errors import PlantgenError
    from plantgen.geometry.skeletons.skin import skin_skeleton
    from plantgen.pipeline import check_finite_frusta, check_finite_mesh

    frusta = skin_skeleton(grow("saguaro"))
    r1 = frusta.r1.copy()
    r1[3] = np.inf
    with pytest.raises(PlantgenError, match=f"x.yaml: the skin of segment {frusta.segment[3]} is not finite"):
        check_finite_frusta(replace(frusta, r1=r1), "x.yaml")
    base = frusta.base.copy()
    base[7, 1] = np.nan                        # NaN, not the first row's nor the extreme's
    with pytest.raises(PlantgenError, match=f"x.yaml: the skin of segment {frusta.segment[7]} is not finite"):
        check_finite_frusta(replace(frusta, base=base), "x.yaml")
    assert check_finite_frusta(frusta, "x.yaml") is frusta
    vertices = np.zeros((4, 3))
    vertices[2] = np.nan
    mesh = SimpleNamespace(vertices=vertices, normals=np.ones((4, 3)), uv=np.zeros((4, 2)),
                           faces=np.array([[0, 1, 3], [1, 2, 3]]), face_row=np.array([0, 5]))
    with pytest.raises(PlantgenError, match=f"the mesh of segment {frusta.segment[5]} is not finite"):
        check_finite_mesh(mesh, frusta, "x.yaml")


def test_a_huge_tropism_direction_keeps_its_direction():
    g = parse_grammar({"axiom": "F", "turtle": {"tropism": {"direction": [1e308, 1e308, 0], "strength": 0.5}}})
    assert np.allclose(g.turtle.tropism_direction, [2 ** -0.5, 2 ** -0.5, 0])


# ---------------------------------------------------------------------- 8. binary inputs
def _npz_bytes(skel: Skeleton, **replace) -> dict:
    arrays = {k: getattr(skel, k) for k in ("start", "end", "r_start", "r_end", "parent", "continues", "material")}
    return {**arrays, "material_names": np.array(skel.material_names), **replace}


def test_binary_inputs_are_validated(tmp_path):
    skel = grow(write(tmp_path, "g.yaml", 'axiom: F\nrules: ["F -> F[+F]F"]\niterations: 2\n'))
    files = {}
    files["corrupt.npz"] = b"PK\x03\x04" + os.urandom(200)
    good = tmp_path / "good.npz"
    skel.save(good)
    files["truncated.npz"] = good.read_bytes()[:-40]
    for name, replace in {"pickled.npz": {"start": np.array([object()] * len(skel))},
                          "shape.npz": {"start": skel.start[:, :2]},
                          "parents.npz": {"parent": np.arange(len(skel))},
                          "strings.npz": {"r_start": np.array(["a"] * len(skel))}}.items():
        np.savez(tmp_path / name, allow_pickle=True, **_npz_bytes(skel, **replace))
    with zipfile.ZipFile(tmp_path / "zipbomb.npz", "w", zipfile.ZIP_DEFLATED) as z, \
            z.open("start.npy", "w", force_zip64=True) as member:
        for _ in range(300):                              # 300 MiB of zeros: about 300 kB packed
            member.write(bytes(1 << 20))
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    swc = {"short.swc": "1 1 0 0 0 1 -1\n2 3 0 1 0\n", "nan.swc": "1 1 0 0 0 1 -1\n2 3 0 nan 0 1 1\n",
           "parent.swc": "1 1 0 0 0 1 -1\n2 3 0 1 0 1 7\n", "twice.swc": "1 1 0 0 0 1 -1\n1 3 0 1 0 1 1\n"}
    for name, text in swc.items():
        write(tmp_path, name, text)
    expected = {"corrupt.npz": "corrupt .npz", "truncated.npz": "corrupt .npz", "pickled.npz": "pickled",
                "shape.npz": "array 'start'", "parents.npz": "parent index", "strings.npz": "array 'r_start'",
                "zipbomb.npz": "unpacks to", "short.swc": "line 2: an SWC node needs 7 values",
                "nan.swc": "line 2: a coordinate or radius", "parent.swc": "line 2: parent 7",
                "twice.swc": "line 2: node id 1"}
    cases = [[cmd, tmp_path / name, "-o", tmp_path / f"{name}.out{suffix}"]
             for name in expected for cmd, suffix in (("grow", ".npz"), ("export", ".glb"))]
    for result, case in zip(run_cases(tmp_path, cases), cases, strict=True):
        assert_refused(result, expected[Path(case[1]).name], outputs=[case[3]])
        assert Path(case[1]).name in result["stderr"]


def test_swc_is_read_back_as_the_skeleton_it_was_written_from(tmp_path):
    skel = grow("abop_ternary")
    write_swc(skel, tmp_path / "t.swc")
    code, _, stderr = run_cli("grow", tmp_path / "t.swc", "-o", tmp_path / "back.npz", "-q")
    assert code == 0, stderr
    back = Skeleton.load(tmp_path / "back.npz")
    np.testing.assert_allclose(back.end, skel.end, rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(back.r_start, skel.r_start, rtol=1e-8)
    assert np.array_equal(back.parent, skel.parent) and np.array_equal(back.continues, skel.continues)


# ---------------------------------------------------------------------- 9. sizes
def test_sizes_are_estimated_and_refused_before_allocating(tmp_path):
    cam = write(tmp_path, "cam.json", json.dumps({"eye": [0, 1, 5], "target": [0, 1, 0], "width": 100000,
                                                  "height": 100000}))
    deep_json = write(tmp_path, "deep.json", "[" * 100000 + "]" * 100000)
    skel = tmp_path / "s.npz"
    grow_file("pine", defines={"foliage": 0}).skeleton.save(skel)     # the paper's pine: 16,816 segments
    cases = [["render", skel, "-o", tmp_path / "a.png", "--camera", cam],
             ["render", skel, "-o", tmp_path / "b.png", "--camera", deep_json],
             ["render", skel, "-o", tmp_path / "c.gif", "--size", "16384x16384", "--frames", "100000"],
             ["export", skel, "-o", tmp_path / "d.glb", "--subdiv", "8"],
             ["export", skel, "-o", tmp_path / "e.obj", "--subdiv", "3"]]
    a, b, c, d, e = run_cases(tmp_path, cases)
    assert_refused(a, "camera width must be an integer 1..16384", outputs=[cases[0][3]])
    assert_refused(b, "cannot read camera JSON", outputs=[cases[1][3]])
    assert_refused(c, "--limit render_bytes=N", outputs=[cases[2][3]])
    assert_refused(d, "over the export limit", outputs=[cases[3][3]])
    assert_refused(e, "--limit export_bytes=N", outputs=[cases[4][3]])


# ---------------------------------------------------------------------- every outcome: success or one line
def test_an_unexpected_failure_is_one_line_and_exit_1_with_the_traceback_behind_debug(tmp_path, monkeypatch):
    import importlib

    def broken(*args, **kwargs):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(importlib.import_module("plantgen.cli.grow"), "grow_file", broken)
    code, _, stderr = run_cli("grow", "saguaro", "-o", tmp_path / "x.npz")
    assert code == 1 and stderr.strip().splitlines() == [
        "plantgen: error: unexpected failure: ZeroDivisionError: a bug (run with --debug for the traceback)"]
    for argv in (["--debug", "grow", "saguaro"], ["grow", "saguaro", "--debug"]):
        code, _, stderr = run_cli(*argv, "-o", tmp_path / "x.npz")
        assert code == 1 and "Traceback" in stderr and stderr.strip().splitlines()[-1].endswith("traceback)")
    assert not (tmp_path / "x.npz").exists()


_BASE_GRAMMAR = {"name": "fuzz", "seed": 1, "iterations": 3, "defines": {"a": 30, "r": 0.9},
                 "axiom": "!(0.1) A(1)", "rules": ["A(l) -> F(l) [+(a) A(l*r)] [-(a) A(l*r)]"],
                 "turtle": {"step": 1, "angle": 25, "radius": 0.1, "tropism": {"direction": [0, -1, 0],
                                                                                "strength": 0.1}},
                 "materials": ["bark"]}
_BASE_SCENE = {"name": "s", "seed": 2, "effects": ["relief"], "ground": {"size": 10},
               "light": {"direction": [0, -1, 0]},
               "instances": [{"grammar": "fuzz", "position": [0, 0, 0], "scale": 1, "rotation": [0, 10, 0],
                              "grid": {"count": [2, 1], "spacing": [1, 1], "jitter": 0.1}}]}
_HOSTILE = st.sampled_from([None, True, -1, 0, 1.5, 2**70, -(2**70), 1e308, -1e308, float("inf"), float("nan"),
                            "", "abc", "F(1e308)", "../../etc/passwd", "/dev/zero", "A" * 5000, [], [1, 2],
                            [1e308, 1e308, 1e308], {}, {"x": 1}, [[[[[]]]]], 10**6, 3])


def _paths(value, prefix=()):
    """Every (path, value) of a nested mapping/list."""
    yield prefix, value
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _paths(v, (*prefix, i))


def _mutate(doc, data):
    import copy

    doc = copy.deepcopy(doc)
    for _ in range(data.draw(st.integers(1, 3))):
        places = [p for p, _ in _paths(doc) if p]
        if not places:
            break
        path = data.draw(st.sampled_from(places))
        parent = doc
        for key in path[:-1]:
            parent = parent[key]
        if data.draw(st.booleans()) and isinstance(parent, dict):
            del parent[path[-1]]
        else:
            parent[path[-1]] = copy.deepcopy(data.draw(_HOSTILE))   # a drawn list must stay as it is
    return doc


@settings(max_examples=60, deadline=10_000, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_mutated_grammars_and_scenes_grow_or_fail_in_one_line(tmp_path, data):
    folder = Path(tempfile.mkdtemp(dir=tmp_path))
    write(folder, "fuzz.yaml", yaml.safe_dump(_mutate(_BASE_GRAMMAR, data) if data.draw(st.booleans())
                                              else _BASE_GRAMMAR))
    scene = data.draw(st.booleans())
    src = write(folder, "in.yaml", yaml.safe_dump(_mutate(_BASE_SCENE if scene else _BASE_GRAMMAR, data)))
    out = folder / "out.npz"
    code, _, stderr = run_cli("grow", src, "-o", out, "-q", "--limit", "derive_work=2000000",
                              "--limit", "segments=20000", "--limit", "drawn_segments=20000",
                              "--limit", "instances=100")
    assert code in (0, 2), stderr
    if code == 2:
        assert len(stderr.strip().splitlines()) == 1 and stderr.startswith("plantgen: error: "), stderr
        assert not out.exists()
    assert not list(folder.glob(".*.part*"))


# ---------------------------------------------------------------------- 5. refusals before the work (issue 45)
def test_the_slow_refusals_come_before_their_work(tmp_path):
    """Inputs that used to be refused only after seconds of work: each refusal now names the
    count it was estimated from, taken before the work (or, for the scanners, as the grids
    come, O(1) each)."""
    blank = write(tmp_path, "blank.swc", "\n" * 2_000_000)
    digits = write(tmp_path, "digits.swc", f"# material {'9' * 5000}: bark\n1 3 0 0 0 0.1 -1\n2 3 0 1 0 0.1 1\n"
                                           "3 3 0 2 0 0.1 2\n")
    scanners = ";".join(f"{i % 100},1,{i // 100}" for i in range(10_000))
    cases = [["grow", blank, "-o", tmp_path / "b.npz"], ["grow", digits, "-o", tmp_path / "d.npz"],
             ["scan", "saguaro", "--scanner-positions", scanners, "--limit", "scan_rays=20000000",
              "-o", tmp_path / "s.ply"]]
    blank_r, digits_r, scan_r = run_cases(tmp_path, cases)
    assert_refused(blank_r, ("2,000,001 lines", "limit segments"), outputs=[cases[0][-1]])
    assert_refused(digits_r, "a material type code of 5,000 digits", outputs=[cases[1][-1]])
    assert_refused(scan_r, ("a scan of 10000 scanners (the first", "limit scan_rays"), outputs=[cases[2][-1]])
    first = int(scan_r["stderr"].split("(the first ")[1].split()[0])
    assert first < 10_000                     # refused part way through the scanners, not after all


def test_a_counter_that_settles_late_is_still_grown():
    """The settling allowance: a derivation whose steps would overspend the budget is grown
    when it settles within SETTLE_STEPS steps (its fixed point skips the rest)."""
    from plantgen.lsystem.derive import derive

    grammar = parse_grammar({"axiom": "A(0)", "iterations": 1_000_000,
                             "rules": [f"A(x) : x < {SETTLE_STEPS // 2} -> A(x+1)"]})
    ms = derive(grammar)
    assert ms.fixed_point == SETTLE_STEPS // 2 and ms.params[0, 0] == SETTLE_STEPS // 2


def test_the_query_pass_is_charged_to_the_work_before_each_walk(monkeypatch):
    """A string of half a million modules with one ``?P``, walked by the turtle after every
    step: each walk is charged to ``derive_work`` (``QUERY_WORK`` a module) before it is
    taken, so the budget ends it after a few walks, not after a hundred (65 s of CPU when
    only its rewriting was counted)."""
    from plantgen.limits import QUERY_WORK, LimitError, limits
    from plantgen.lsystem import queries
    from plantgen.lsystem.derive import derive

    walks = []
    real = queries.interpret_plant
    monkeypatch.setattr(queries, "interpret_plant", lambda ms, *a, **k: walks.append(len(ms)) or real(ms, *a, **k))
    grammar = parse_grammar({"axiom": "C(0) ?P(0,0,0) X(0)", "iterations": 200,
                             "rules": ["C(x) -> C(x+1)", "X(n) : n < 19 -> X(n+1) X(n+1)", "X(n) : n >= 19 -> F"]})
    with pytest.raises(LimitError, match=r"the query pass after step \d+: derive_work reaches") as refused:
        derive(grammar)
    walked = sum(walks)
    assert walked * QUERY_WORK <= limits.max_derive_work           # every walk taken was paid for first
    assert len(walks) < 30 and walked < 3 * 2 ** 19                # at most a couple of the full-size walks
    assert int(str(refused.value).split("after step ")[1].split(":")[0]) <= 21


def test_a_stand_whose_steps_alone_pass_the_work_is_refused_before_it_derives(tmp_path, monkeypatch):
    """grow: together: 10,000 saguaros take every step they are given (none settles), each
    at least its floor: the sum is known before the first step (it was refused at step 5,
    after 22 s of CPU). The refusal names the floor; no derivation is started."""
    from plantgen._resources import grammars_dir
    from plantgen.environment import together
    from plantgen.errors import PlantgenError
    from plantgen.lsystem.derive import steps_floor

    started = []
    real = together.Derivation
    monkeypatch.setattr(together, "Derivation", lambda *a, **k: started.append(1) or real(*a, **k))
    scene = write(tmp_path, "stand.yaml", "grow: together\ninstances:\n  - {grammar: saguaro, seed: 1, "
                                          "grid: {count: [100, 100], spacing: [4, 4]}}\n")
    floor = steps_floor(parse_grammar(yaml.safe_load((grammars_dir() / "saguaro.yaml").read_text())))
    with pytest.raises(PlantgenError, match=f"10,000 plants grown together take steps that spend at least "
                                            f"{10_000 * floor:,} of derive_work"):
        grow_file(scene)
    assert started == []


def test_each_plant_of_a_stand_is_charged_for_its_drawing(tmp_path):
    """The drawing every plant makes for the others after each step is charged to the work:
    nine saguaros grown together spend more than their rewriting alone."""
    from plantgen._resources import grammars_dir
    from plantgen.environment.together import TogetherPlant, grow_together
    from plantgen.limits import QUERY_WORK, limits
    from plantgen.lsystem.derive import derive

    grammar = parse_grammar(yaml.safe_load((grammars_dir() / "saguaro.yaml").read_text()))
    alone = limits.meter("derive_work")
    strings = [derive(grammar, seed=s, work=alone) for s in range(9)]
    stand = limits.meter("derive_work")
    grow_together([TogetherPlant(grammar, s, None, np.eye(4)) for s in range(9)], limits=limits, work=stand)
    assert stand.spent >= alone.spent + QUERY_WORK * sum(len(ms) for ms in strings)


def test_a_plants_light_among_the_stand_is_charged_for_the_others_it_gathers():
    """A stand's light gathers the other plants for each plant at every step (P squared a
    step): each gathering is charged QUERY_WORK a segment gathered, before it is made, so a
    large stand ends at the budget (196 self_organizing trees ran on for many minutes)."""
    from _geometry_helpers import random_tree

    from plantgen.environment import together
    from plantgen.geometry.meshes.polygons import Polygons
    from plantgen.limits import QUERY_WORK, LimitError, Meter

    grammar = parse_grammar({"axiom": "F", "rules": []})
    plants = [together.TogetherPlant(grammar, s, None, np.eye(4)) for s in range(3)]
    meter = Meter("derive_work", 10 ** 9)
    world = together._World(plants, meter)
    trees = [random_tree(n, seed=n) for n in (10, 20, 40)]
    for i, tree in enumerate(trees):
        world.put(i, tree, Polygons.empty())
    world.put(2, trees[2], Polygons.empty())            # drawn again: counted once
    assert world.segments == 70 and meter.spent == 0
    others = world.others(0)
    assert len(others[0]) == 60 and meter.spent == 60 * QUERY_WORK
    small = together._World(plants, Meter("derive_work", 59 * QUERY_WORK))
    for i, tree in enumerate(trees):
        small.put(i, tree, Polygons.empty())
    with pytest.raises(LimitError, match="the light of plant 1 of the stand, among the others"):
        small.others(0)
