"""`plantgen grow` through the command line: output, summary, and every bad-input class."""

import numpy as np
import pytest
from _cli import run_cli

from plantgen import Skeleton, grow

GOOD = """\
name: bush
description: a small stochastic bush
seed: 4
iterations: 5
defines: {lr: 0.8}
axiom: "!(0.1) A(1)"
rules:
  - {rule: "A(l) -> F(l) [+ A(l*lr)] [- A(l*lr)] A(l*lr)", p: 0.7}
  - {rule: "A(l) -> F(l) /(90) A(l*lr)", p: 0.3}
turtle: {angle: 25}
"""


@pytest.fixture
def good(tmp_path):
    p = tmp_path / "bush.yaml"
    p.write_text(GOOD)
    return p


def test_grow_writes_the_skeleton_and_a_summary(good, tmp_path):
    out = tmp_path / "bush.npz"
    code, stdout, stderr = run_cli("grow", good, "-o", out, "--format", "swc")
    assert code == 0, stderr
    skel = Skeleton.load(out)
    skel.validate()
    assert "segments" in stdout and "branch tips" in stdout and "height" in stdout
    assert f"{len(skel):,} segments" in stdout
    for stage in ("parse", "derive", "interpret"):
        assert stage in stdout
    # SWC: one line per node, every parent id refers to an earlier node
    rows = [line.split() for line in (tmp_path / "bush.swc").read_text().splitlines()
            if not line.startswith("#")]
    ids = [int(r[0]) for r in rows]
    assert ids == list(range(1, len(rows) + 1))
    assert all(int(r[6]) == -1 or 0 < int(r[6]) < int(r[0]) for r in rows)
    assert len(rows) >= len(skel)


def test_seed_and_iterations_override_the_file(good, tmp_path):
    a, b, c = tmp_path / "a.npz", tmp_path / "b.npz", tmp_path / "c.npz"
    assert run_cli("grow", good, "-o", a, "--seed", "1")[0] == 0
    assert run_cli("grow", good, "-o", b, "--seed", "1")[0] == 0
    assert run_cli("grow", good, "-o", c, "--seed", "2", "--iterations", "3")[0] == 0
    sa, sb, sc = (Skeleton.load(p) for p in (a, b, c))
    np.testing.assert_array_equal(sa.end, sb.end)
    assert len(sc) < len(sa)
    # the API mirrors the CLI
    np.testing.assert_array_equal(grow(good, seed=1).end, sa.end)


BAD = {
    "yaml error": ("axiom: [unclosed\n", "YAML error"),
    "unknown key": (GOOD + "colour: red\n", "unknown key"),
    "unbalanced brackets": (GOOD.replace("[- A(l*lr)]", "[- A(l*lr)"), "rule 1.*unbalanced"),
    "undefined name": (GOOD.replace("A(l*lr)] A", "A(l*q)] A"), "rule 1.*undefined name 'q'"),
    "parameter count": (GOOD.replace("/(90) A(l*lr)", "/(90) A(l, 2)"), "rule 2.*wrong parameter count"),
    "probabilities": (GOOD.replace("p: 0.3", "p: 0.2"), "add up to 0.9"),
    "not a grammar": ("just: a mapping\n", "not a grammar"),
    "not a mapping": ("- a\n- list\n", "not a grammar"),
    "empty file": ("", "empty file"),
    "bad expression": (GOOD.replace("A(l*lr)] A", "A(l.x)] A"), "rule 1.*unexpected character"),
    "size limit": (GOOD.replace("iterations: 5", "iterations: 60"), "over the limit"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_is_one_line_and_exit_2(case, tmp_path):
    text, pattern = BAD[case]
    src = tmp_path / "bad.yaml"
    src.write_text(text)
    out = tmp_path / "out.npz"
    code, stdout, stderr = run_cli("grow", src, "-o", out, "--max-modules", "100000")
    assert code == 2
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert "Traceback" not in stderr
    assert "bad.yaml" in lines[0]
    import re
    assert re.search(pattern, lines[0]), lines[0]
    assert not out.exists() and not list(tmp_path.glob("*.part"))   # nothing half-written


def test_missing_file_and_directory(tmp_path):
    code, _, stderr = run_cli("grow", tmp_path / "nope.yaml")
    assert code == 2 and "nope.yaml: no such file" in stderr
    code, _, stderr = run_cli("grow", tmp_path)
    assert code == 2 and len(stderr.strip().splitlines()) == 1


def test_bad_options_exit_2(good):
    code, _, stderr = run_cli("grow", good, "--seed", "-3")
    assert code == 2 and "Traceback" not in stderr
    code, _, stderr = run_cli("grow", good, "--format", "obj")
    assert code == 2


def test_help_explains():
    code, stdout, _ = run_cli("grow", "--help")
    assert code == 0
    for word in ("--seed", "--iterations", "--format", "--max-modules", "Example"):
        assert word in stdout
    code, stdout, _ = run_cli("--help")
    assert code == 0 and "grow" in stdout


def test_grow_prints_the_true_height_and_bounds(tmp_path):
    """Issue 16: the well spans y 0..3.55; grow said height 4.85, min y -0.9 (each end point
    padded by its radius every way)."""
    code, stdout, stderr = run_cli("grow", "well", "-o", tmp_path / "w.npz")
    assert code == 0, stderr
    assert "height 3.55;" in stdout and "min [-1.35  0.   -1.35]" in stdout and "max [1.35 3.55 1.35]" in stdout


def test_grow_counts_the_leaves_and_says_the_skeleton_file_holds_none(tmp_path):
    from plantgen.pipeline import grow_file

    polygons = grow_file("abop_bush").polygons
    code, out, err = run_cli("grow", "abop_bush", "-o", str(tmp_path / "bush.npz"))
    assert code == 0, err
    assert f"{len(polygons):,} leaf polygons ({len(polygons.triangles):,} triangles)" in out.splitlines()[0]
    [line] = [w for w in err.splitlines() if "leaf polygons not written" in w]
    assert line.startswith("warning: .npz carries the skeleton only")
    code, out, err = run_cli("grow", "saguaro", "-o", str(tmp_path / "saguaro.npz"))
    assert code == 0 and "leaf" not in out + err
