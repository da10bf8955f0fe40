"""plantgen works from a plain (non-editable) install: data ships inside the package."""

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import plantgen
from plantgen._resources import grammars_dir, shaders_dir, shipped_grammar

REPO = Path(__file__).resolve().parent.parent


def test_shipped_data_is_found_from_the_installed_package():
    assert any(grammars_dir().glob("*.yaml"))
    assert shaders_dir().is_dir()
    with pytest.raises(FileNotFoundError, match="no-such-plant.*plantgen list"):    # names the way to the names
        shipped_grammar("no-such-plant")


def test_cli_runs_from_another_directory_on_a_shipped_grammar_name(tmp_path):
    name = sorted(p.stem for p in grammars_dir().glob("*.yaml") if "abop" not in p.stem)[0]
    proc = subprocess.run([sys.executable, "-c", "from plantgen.cli import main; main()", "grow", name,
                           "-o", str(tmp_path / "x.npz"), "-q"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "x.npz").is_file()


@pytest.mark.skipif(not (REPO / "pyproject.toml").is_file(),
                    reason="needs the source tree (pyproject.toml) to build a wheel from")
def test_wheel_contains_grammars_and_shaders(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path),
                           str(REPO)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    wheel = next(tmp_path.glob("plantgen-*.whl"))
    names = zipfile.ZipFile(wheel).namelist()
    repo_yaml = {p.name for p in (REPO / "grammars").glob("*.yaml")}
    assert repo_yaml and repo_yaml <= {Path(n).name for n in names if n.startswith("plantgen/grammars/")}
    repo_glsl = {p.name for p in (REPO / "shaders").glob("*.glsl")}
    assert repo_glsl <= {Path(n).name for n in names if n.startswith("plantgen/shaders/")}
    assert "plantgen/cli/__init__.py" in names
    if not plantgen.__file__.startswith(str(REPO)):
        # a non-editable install (CI's) reads its data from inside the package
        assert str(grammars_dir()).startswith(str(Path(plantgen.__file__).parent))
