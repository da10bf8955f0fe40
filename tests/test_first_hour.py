"""What a newcomer meets in the first hour: shipped names that can be found (``plantgen
list``, a did-you-mean wherever a name is taken, names that work from any folder),
default outputs, progress on a terminal only, a fixed point said once, and one-line
errors that name the option. Each test asserts the exit status and the line."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from _cli import run_cli, run_cli_on_terminal
from PIL import Image

import plantgen
from plantgen._resources import grammars_dir, missing_hint, shipped_names, short_names
from plantgen.errors import PlantgenError
from plantgen.lsystem.derive import derive
from plantgen.lsystem.grammar import parse_grammar

PACKAGE = Path(plantgen.__file__).parent


@pytest.fixture(autouse=True)
def _own_cache(tmp_path, monkeypatch):
    """Every test keeps `plantgen list`'s cache in its own folder, and runs in its own
    folder (outside the checkout: repository paths such as grammars/pine.yaml do not exist)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    return work


def one_line(stderr: str) -> str:
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    return lines[0]


# ---------------------------------------------------------------------- 1. names
def test_list_names_every_shipped_grammar_and_scene_without_growing_any(monkeypatch):
    """The listing reads the files' descriptions: nothing is grown, cold or warm (issue 45)."""
    import plantgen.cli.listing as listing

    def no_growing(*args, **kwargs):
        raise AssertionError("plantgen list grew a model")

    monkeypatch.setattr(listing, "grow_file", no_growing)
    code, stdout, stderr = run_cli("list", "--json")
    assert code == 0 and stderr == "", stderr
    rows = json.loads(stdout)
    assert [r["name"] for r in rows] == shipped_names()
    by_name = {r["name"]: r for r in rows}
    assert {"pine", "forest", "abop_monopodial", "abop_sympodial", "ocotillo"} <= set(by_name)
    assert all(r["description"] and "segments" not in r for r in rows)
    assert by_name["forest"]["kind"] == "scene" and by_name["pine"]["kind"] == "grammar"
    code, stdout, stderr = run_cli("list")
    assert code == 0 and stderr == "", stderr
    header, *lines = stdout.strip().splitlines()
    assert header.split() == ["NAME", "KIND", "DESCRIPTION"]
    assert [line.split()[0] for line in lines] == shipped_names()


def test_list_segments_are_what_grow_makes_and_come_from_the_cache_after(monkeypatch):
    """``--segments`` grows each model once at its own seed; a second listing reads the
    counts from the cache (two models, a grammar and a scene, to keep the test short)."""
    import plantgen.cli.listing as listing

    monkeypatch.setattr(listing, "shipped_names", lambda: ["saguaro", "well"])
    code, stdout, stderr = run_cli("list", "--segments", "--json")
    assert code == 0 and stderr == "", stderr
    by_name = {r["name"]: r for r in json.loads(stdout)}
    assert by_name["saguaro"]["segments"] == len(plantgen.grow("saguaro"))
    assert by_name["well"]["segments"] == len(plantgen.grow("well"))

    def no_growing(*args, **kwargs):
        raise AssertionError("grown again despite the cache")

    monkeypatch.setattr(listing, "grow_file", no_growing)
    code, stdout, stderr = run_cli("list", "--segments")
    assert code == 0 and stderr == "", stderr
    header, *lines = stdout.strip().splitlines()
    assert header.split()[:3] == ["NAME", "KIND", "SEGMENTS"]
    well = next(line for line in lines if line.startswith("well "))
    assert f"{by_name['well']['segments']:,}" in well


def test_list_grows_a_shipped_file_again_once_it_changes(tmp_path, monkeypatch):
    """The cache is keyed on the files' bytes: a stale entry is never shown."""
    import plantgen.cli.listing as listing

    monkeypatch.setattr(listing, "shipped_names", lambda: ["saguaro"])
    cache = tmp_path / "cache" / "plantgen" / "list.json"
    assert run_cli("list", "--segments")[0] == 0 and cache.is_file()
    data = json.loads(cache.read_text())
    data["saguaro"]["segments"] = 999_999
    data["saguaro"]["digest"] = "not the file's"
    cache.write_text(json.dumps(data))
    code, stdout, _ = run_cli("list", "--segments", "--json")
    assert code == 0
    assert next(r for r in json.loads(stdout) if r["name"] == "saguaro")["segments"] == 30


@pytest.mark.parametrize("command", [["render", "pien"], ["export", "pien"], ["scan", "pien"],
                                     ["grow", "pien"], ["view", "pien"]])
def test_a_mistyped_name_gets_the_closest_shipped_one(command):
    code, stdout, stderr = run_cli(*command)
    assert code == 2 and stdout == ""
    assert one_line(stderr) == ("plantgen: error: pien: no such file (did you mean 'pine'? 'plantgen list' "
                                "names the shipped grammars and scenes)")
    assert list(Path().iterdir()) == []          # nothing written


def test_a_name_close_to_nothing_points_to_plantgen_list():
    code, _, stderr = run_cli("render", "zzzzqq")
    assert code == 2
    assert one_line(stderr) == ("plantgen: error: zzzzqq: no such file ('plantgen list' names the shipped "
                                "grammars and scenes)")


def test_a_repository_path_outside_the_checkout_names_the_shipped_model():
    code, _, stderr = run_cli("render", "grammars/pine.yaml")
    assert code == 2
    assert one_line(stderr).startswith("plantgen: error: grammars/pine.yaml: no such file (did you mean the "
                                       "shipped name 'pine'?")


def test_a_mistyped_file_name_gets_the_file_beside_it(_own_cache):
    (_own_cache / "my_tree.yaml").write_text('axiom: F\niterations: 1\n')
    code, _, stderr = run_cli("grow", "my_tre.yaml")
    assert code == 2
    assert one_line(stderr) == "plantgen: error: my_tre.yaml: no such file (did you mean 'my_tree.yaml'?)"


def test_the_api_says_the_same():
    with pytest.raises(PlantgenError, match=r"^pien: no such file \(did you mean 'pine'\?"):
        plantgen.grow("pien")
    with pytest.raises(PlantgenError, match="did you mean 'pine'"):
        plantgen.render("pien", size=(32, 24))
    with pytest.raises(PlantgenError, match="did you mean the shipped name 'pine'"):
        plantgen.grow("grammars/pine.yaml")


def test_the_api_snippet_works_from_any_folder():
    """The package docstring's first line, run outside the checkout."""
    snippet = re.search(r'skel = (plantgen\.grow\("[a-z_]+", seed=3\))', plantgen.__doc__)
    assert snippet, plantgen.__doc__
    skel = eval(snippet.group(1))          # the documented call, as written
    assert isinstance(skel, plantgen.Skeleton) and len(skel) > 0


def test_a_scene_naming_a_mistyped_grammar_gets_the_closest(_own_cache):
    scene = _own_cache / "garden.yaml"
    scene.write_text("name: garden\ninstances:\n  - grammar: saguaor\n    position: [0, 0, 0]\n")
    code, _, stderr = run_cli("grow", scene)
    assert code == 2
    line = one_line(stderr)
    assert "grammar 'saguaor' not found" in line and "did you mean 'saguaro'?" in line


def test_a_batch_naming_a_mistyped_grammar_gets_the_closest(_own_cache):
    code, _, stderr = run_cli("batch", "pien", "--seeds", "0:1", "--out", _own_cache / "out")
    assert code == 2
    assert "did you mean 'pine'?" in one_line(stderr)
    spec = _own_cache / "spec.yaml"
    spec.write_text("plants:\n  - grammar: saguaor\n    seeds: \"0:1\"\noutputs: {npz: true}\n")
    code, _, stderr = run_cli("batch", spec, "--out", _own_cache / "out")
    assert code == 2
    assert "did you mean 'saguaro'?" in one_line(stderr)
    assert not (_own_cache / "out").exists()


def test_bench_models_get_the_closest_name():
    code, _, stderr = run_cli("bench", "--models", "saguaro,pien", "--out", "b")
    assert code == 2 and "no such model: pien (did you mean 'pine'?)" in one_line(stderr)


def test_errors_and_notes_of_shipped_grammars_name_them_short():
    code, _, stderr = run_cli("grow", "pine", "--define", "nosuch=1")
    assert code == 2
    line = one_line(stderr)
    assert line.startswith("plantgen: error: pine: the grammar has no define nosuch"), line
    assert str(grammars_dir()) not in line
    full = f"{grammars_dir() / 'elm.yaml'}: line 3: YAML error"
    assert short_names(full) == "elm: line 3: YAML error"
    assert short_names("/elsewhere/elm.yaml: x") == "/elsewhere/elm.yaml: x"


def test_help_examples_use_shipped_names_not_repository_paths():
    """Every example's INPUT is a shipped name (so it runs from any folder) or a file the
    example says is the user's own."""
    own = {"my_tree.yaml", "my_dataset.yaml"}
    inputs = []
    for command in ([], ["grow"], ["render"], ["export"], ["scan"], ["list"], ["batch"], ["view"], ["bench"]):
        code, stdout, _ = run_cli(*command, "--help")
        assert code == 0
        assert "grammars/" not in stdout, (command, stdout)
        # the examples stand above the options' help, whose first heading starts a line
        examples = re.split(r"\n[A-Z][A-Za-z ]*:\n", stdout)[0]
        for line in examples.splitlines():
            words = line.split()
            if words[:1] == ["plantgen"] and len(words) > 2 and not words[2].startswith("-"):
                inputs.append(words[2])
    assert len(inputs) > 15
    assert set(inputs) - own <= set(shipped_names()), inputs
    assert "grammars/" not in plantgen.__doc__


def test_missing_hint_without_a_close_name_or_folder():
    assert missing_hint("no/such/dir/qqq.npz") == ""
    assert "did you mean 'elm'?" in missing_hint("ekm")


# ---------------------------------------------------------------------- 2. default outputs
def test_render_export_and_scan_write_beside_the_user_by_default(_own_cache, gl_ctx):
    code, stdout, stderr = run_cli("render", "saguaro", "--size", "64x48")
    assert code == 0, stderr
    assert stdout.strip().splitlines()[-1] == "wrote saguaro.png"
    with Image.open(_own_cache / "saguaro.png") as image:
        assert image.size == (64, 48)
    code, stdout, stderr = run_cli("render", "saguaro", "--size", "32x24", "--frames", "2")
    assert code == 0, stderr
    assert stdout.strip().splitlines()[-1] == "wrote saguaro.gif"
    code, stdout, stderr = run_cli("export", "saguaro", "--subdiv", "0", "--no-textures")
    assert code == 0, stderr
    assert stdout.strip().splitlines()[-1] == "wrote saguaro.glb"
    assert (_own_cache / "saguaro.glb").read_bytes()[:4] == b"glTF"
    code, stdout, stderr = run_cli("scan", "saguaro", "--angular-step", "2")
    assert code == 0, stderr
    assert stdout.strip().splitlines()[-1] == "wrote saguaro.ply"
    assert (_own_cache / "saguaro.ply").read_bytes().startswith(b"ply")
    code, stdout, stderr = run_cli("grow", "saguaro")
    assert code == 0 and stdout.strip().splitlines()[-1] == "wrote saguaro.npz"
    assert sorted(p.name for p in _own_cache.iterdir()) == ["saguaro.gif", "saguaro.glb", "saguaro.npz",
                                                          "saguaro.ply", "saguaro.png"]


# ---------------------------------------------------------------------- 3. progress
def test_progress_shows_on_a_terminal_only_and_never_with_quiet(gl_ctx):
    code, stdout, stderr = run_cli_on_terminal("grow", "abop_ternary", "--iterations", "6")
    assert code == 0, stderr
    assert "deriving" in stderr and "drawing the turtle" in stderr
    assert "deriving" not in stdout
    code, stdout, stderr = run_cli_on_terminal("render", "saguaro", "--size", "32x24")
    assert code == 0 and "skinning" in stderr and "rendering" in stderr
    code, stdout, stderr = run_cli_on_terminal("scan", "saguaro", "--angular-step", "2")
    assert code == 0 and "scanning" in stderr
    # a log or a pipe: not a line of progress, only the report on stdout
    for command in (["grow", "abop_ternary", "--iterations", "6"], ["render", "saguaro", "--size", "32x24"],
                    ["scan", "saguaro", "--angular-step", "2"], ["export", "saguaro", "--subdiv", "0"]):
        code, stdout, stderr = run_cli(*command)
        assert code == 0 and stderr == "" and stdout.strip().splitlines()[-1].startswith("wrote "), (command, stderr)
        code, stdout, stderr = run_cli_on_terminal(*command, "-q")
        assert code == 0 and stdout == "" and stderr == "", (command, stderr)


# ---------------------------------------------------------------------- 4. a fixed point
def test_a_fixed_point_is_said_once():
    # the paper's pine (--define foliage=0): the leafy one notes its leaves left out of the .npz too
    code, stdout, stderr = run_cli("grow", "pine", "--define", "foliage=0", "--iterations", "200")
    assert code == 0
    assert one_line(stderr) == ("pine: note: the derivation reached a fixed point at step 38 (steps past it "
                                "change nothing: --iterations 200 draws the plant of --iterations 38)")
    code, _, stderr = run_cli("grow", "pine", "--define", "foliage=0", "--iterations", "38", "-o", "p38.npz")
    assert code == 0 and stderr == ""            # no step past the fixed point: nothing to say
    a, b = plantgen.Skeleton.load("pine.npz"), plantgen.Skeleton.load("p38.npz")
    assert len(a) == len(b) and np.array_equal(a.end, b.end)


def test_derive_stops_at_a_fixed_point_of_any_size():
    """A string past the cycle check's window (70,000 modules) that stops changing."""
    growing = parse_grammar({"axiom": "F A", "rules": ["A -> F A"], "iterations": 1}, "growing.yaml")
    assert derive(growing, iterations=50).fixed_point is None
    grammar = parse_grammar({"axiom": "F A", "rules": ["A -> F F F F F F F F F F"], "iterations": 1}, "f.yaml")
    ms = derive(grammar, iterations=100)
    assert ms.fixed_point == 1 and len(ms) == 11
    wide = parse_grammar({"axiom": "A", "rules": ["A -> " + "F " * 70_000]}, "wide.yaml")
    ms = derive(wide, iterations=1000)
    assert ms.fixed_point == 1 and len(ms) == 70_000


# ---------------------------------------------------------------------- 5. smaller things
def test_a_bad_background_names_the_option_before_any_work():
    code, _, stderr = run_cli("render", "forest", "--background", "blu")
    assert code == 2
    line = one_line(stderr)
    assert line.startswith("plantgen: error: Invalid value for '--background': 'blu' is not a colour"), line
    assert list(Path().iterdir()) == []


def test_a_huge_size_is_one_sensible_line():
    code, _, stderr = run_cli("render", "saguaro", "--size", "16000x16000")
    assert code == 2
    line = one_line(stderr)
    assert "a render of 16000x16000 pixels needs about" in line and "--limit render_bytes=N" in line
    assert "0 segments" not in line and "frame(s)" not in line
    assert list(Path().iterdir()) == []


def test_extras_are_spelled_one_way_in_messages():
    """Every install command plantgen prints is the README's, pip install '.[EXTRA]' in the
    clone (``plantgen[EXTRA]`` would ask an index for a package of that name), worded once
    by plantgen.errors.missing_extra."""
    from plantgen.errors import missing_extra

    pattern = re.compile(r"pip install (\S+)")
    found = [(path.name, spelled) for path in PACKAGE.rglob("*.py") for spelled in pattern.findall(path.read_text())]
    assert found
    odd = [(name, s) for name, s in found if not re.match(r"'\.\[([a-z]+|\{extra\})\]'", s)]
    assert not odd, odd
    assert missing_extra("plantgen view", "view") == ("plantgen view needs the view extra: "
                                                      "pip install '.[view]' (in plantgen's folder)")


# ---------------------------------------------------------------------- every shipped name renders
@pytest.mark.parametrize("name", shipped_names())
def test_every_listed_name_renders(name, gl_ctx):
    code, stdout, stderr = run_cli("render", name, "--size", "64x48")
    assert code == 0, stderr
    assert stdout.strip().splitlines()[-1] == f"wrote {name}.png"
    with Image.open(f"{name}.png") as image:
        pixels = np.asarray(image.convert("RGB"))
    assert image.size == (64, 48)
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 8     # a picture, not a blank frame
