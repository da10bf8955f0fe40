"""Effects decide programs and passes (issue 6): for every combination of effects, the
programs a frame compiles and the passes it runs are exactly those the effects ask for,
and the command line's overrides and errors."""

from __future__ import annotations

import itertools

import pytest
from _cli import run_cli

from plantgen.errors import PlantgenError
from plantgen.gl.shaders import build_program
from plantgen.pipeline import render_file
from plantgen.settings import resolve_effects

SCENE = """
name: two_posts
effects: []
ground: {size: 8, height: 0, material: sand}
camera: {eye: [4, 3, 5], target: [0, 1, 0], up: [0, 1, 0], fov_y: 40}
light: {direction: [-0.5, -1, -0.3]}
instances:
  - skeleton:
      materials: [bark]
      segments:
        - {start: [0, 0, 0], end: [0, 1, 0], r_start: 0.3, r_end: 0.25}
        - {start: [0, 1, 0], end: [0, 2, 0], r_start: 0.25, r_end: 0.1, parent: 0, continues: true}
    motion: {sway: {amplitude: 20, frequency: 1}}
  - skeleton:
      materials: [bark]
      segments:
        - {start: [0, 0, 0], end: [0, 1.5, 0], r_start: 0.2, r_end: 0.15}
    position: [1.5, 0, 0]
"""


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("scene") / "two_posts.yaml"
    path.write_text(SCENE)
    return path


COMBINATIONS = [c for n in range(4) for c in itertools.combinations(("relief", "shadows", "animation"), n)]


@pytest.mark.parametrize("effects", COMBINATIONS, ids=lambda c: "+".join(c) or "none")
def test_each_combination_compiles_and_runs_only_what_it_asks_for(gl_ctx, scene_file, tmp_path, effects):
    report = render_file(scene_file, tmp_path / "x.png", size=(40, 30), effects=list(effects),
                         shadow_res=64, timed_frames=0, time=0.3)
    stats = report.result.stats
    relief, shadows, animation = ("relief" in effects, "shadows" in effects, "animation" in effects)
    assert report.effects == effects
    # passes: a shadow pass only with shadows
    assert stats.passes == (["shadow"] if shadows else []) + ["sky", "ground", "frusta"]
    programs = set(stats.programs)
    expected = {("sky.glsl", ()), ("ground.glsl", ("SHADOWS",) if shadows else ()),
                ("raycast.glsl", tuple(sorted((["RELIEF"] if relief else []) + (["SHADOWS"] if shadows else []))))}
    if shadows:
        expected |= {("ground.glsl", ("SHADOW_PASS",)),
                     ("raycast.glsl", ("RELIEF", "SHADOW_PASS") if relief else ("SHADOW_PASS",))}
    assert programs == expected
    # the compiled programs: no shadow map is sampled, no relief march is compiled in,
    # unless asked (the GLSL compiler keeps only the uniforms code uses)
    for name, flags in programs:
        program = build_program(gl_ctx, name, dict.fromkeys(flags, True))
        assert ("shadow_map" in program) == ("SHADOWS" in flags)
        if name == "raycast.glsl":
            assert ("linear_steps" in program) == ("RELIEF" in flags)
    # skinning: a static scene (or animation off) is skinned once; with animation the
    # static post is skinned once and the moving one once for the frame at t
    assert report.skin_calls == (2 if animation else 1)


def test_overrides_add_and_remove_effects():
    assert resolve_effects(("relief", "shadows"), remove=("shadows",)) == ("relief",)
    assert resolve_effects((), add=("shadows",)) == ("shadows",)
    assert resolve_effects(("relief",), replace=("shadows", "animation")) == ("shadows", "animation")
    with pytest.raises(PlantgenError, match="unknown effect 'fog'.*known: relief, shadows"):
        resolve_effects((), add=("fog",))


def test_cli_flags_override_the_scene(gl_ctx, scene_file, tmp_path):
    out = tmp_path / "a.png"
    code, stdout, stderr = run_cli("render", scene_file, "-o", out, "--size", "40x30",
                                   "--effects", "relief,shadows", "--no-relief", "--shadow-res", "64")
    assert code == 0, stderr
    assert "effects: shadows (shadow map 64²)" in stdout and out.is_file()
    code, stdout, stderr = run_cli("render", scene_file, "-o", out, "--size", "40x30", "--shadows",
                                   "--shadow-res", "32")
    # the scene lists none: the cheap looks are on by default (settings.DEFAULT_EFFECTS)
    assert code == 0 and "effects: shadows, tone, translucency (shadow map 32²)" in stdout


def test_unknown_effect_is_a_one_line_error(scene_file, tmp_path):
    code, stdout, stderr = run_cli("render", scene_file, "-o", tmp_path / "a.png", "--effects", "relief,fog")
    assert code == 2
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "unknown effect 'fog'" in lines[0]
    assert not (tmp_path / "a.png").exists()
