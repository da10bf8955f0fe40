"""Every setting has one home (plantgen.settings): the commands' options take their
defaults, ranges and choices from it, the API and the viewer take the same names, and a
setting written back as command-line words reads back as the same value."""

from __future__ import annotations

import math

import click
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plantgen.cli.batch import batch
from plantgen.cli.bench import bench
from plantgen.cli.export import export
from plantgen.cli.options import take_settings
from plantgen.cli.render import render
from plantgen.cli.view import view
from plantgen.errors import PlantgenError
from plantgen.knobs import Knob, knob_args, knob_of
from plantgen.settings import (
    MAX_SUBDIV,
    EffectSettings,
    ImageSettings,
    KeyframeSettings,
    MeshSettings,
    MotionSettings,
    ParallaxSettings,
    RaycastSettings,
    RenderSettings,
    ShadowSettings,
    build_settings,
    option_names,
    settings_knobs,
)

COMMANDS = {"render": render, "view": view, "export": export, "batch": batch, "bench": bench}
KNOBS = {k.name: (k, default) for k, default in
         settings_knobs(RenderSettings) + settings_knobs(MeshSettings) + settings_knobs(KeyframeSettings)
         + settings_knobs(ParallaxSettings)}


def params_of(command: click.Command) -> dict[str, click.Parameter]:
    return {p.name: p for p in command.params}


def declared_range(param: click.Parameter):
    """(lo, hi, lo_open, hi_open) of a click number type, or the choices, as click has them."""
    t = param.type
    if isinstance(t, click.Choice):
        return tuple(t.choices)
    if isinstance(t, click.IntRange | click.FloatRange):
        return (t.min, t.max, t.min_open, t.max_open)
    return None


def knob_range(k: Knob):
    if k.kind == "choice":
        return tuple(k.choices)
    if k.kind in ("int", "float") and (k.lo is not None or k.hi is not None):
        return (k.lo, k.hi, k.lo_open, k.hi_open)
    return None


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_commands_knob_options_have_the_settings_default_range_and_help(name):
    """Read from the settings, never restated: an option named as a knob has the knob's
    default, range or choices and option string."""
    checked = 0
    for pname, param in params_of(COMMANDS[name]).items():
        if pname not in KNOBS or not isinstance(param, click.Option):
            continue
        k, default = KNOBS[pname]
        if name == "batch" and pname != "subdiv":
            continue        # batch's --relief and --size say what its views are (a spec's own defaults)
        if name == "bench" and not pname.startswith("pom_"):
            continue        # bench's --size and --frames are its timed frames' (defaults by --quick)
        if name == "export" and pname == "relief":
            assert param.default == MeshSettings().relief      # the mesh's relief, GS+R
            continue
        checked += 1
        assert param.default == default, (name, pname)
        got, want = declared_range(param), knob_range(k)
        if want is not None:
            assert got == want, (name, pname)
        if k.kind != "bool":
            assert k.option in param.opts, (name, pname)
    assert checked >= {"render": 20, "view": 17, "export": 3, "batch": 1, "bench": 3}[name]


def test_render_and_view_declare_their_shared_options_once():
    """The options both commands take are the same declarations: same type, range, default."""
    r, v = params_of(render), params_of(view)
    shared = set(r) & set(v) & set(KNOBS)
    assert {"effects", "relief", "shadows", "shadow_res", "ssaa", "background", "time", "linear_steps",
            "binary_steps", "march", "march_density", "v_exact", "shadow_caster", "camera", "azimuth"} <= shared
    for name in shared:
        assert declared_range(r[name]) == declared_range(v[name]), name
        assert r[name].default == v[name].default, name
        assert r[name].opts == v[name].opts, name


def test_the_subdivision_level_has_one_range_everywhere():
    level = KNOBS["subdiv"][0]
    assert level.hi == MAX_SUBDIV
    for command in (export, view, batch):
        p = params_of(command)["subdiv"]
        assert (p.type.min, p.type.max) == (0, MAX_SUBDIV)
        assert p.default == MeshSettings().level


def test_the_api_takes_the_commands_names():
    """plantgen.render's keywords are the render command's option names: one vocabulary."""
    names = set(option_names(RenderSettings))
    assert names <= set(params_of(render))
    s = RenderSettings.from_options(linear_steps=16, shadow_res=1024, azimuth=60.0, time=0.5, ssaa=2,
                                    effects="relief,shadows", fov=30.0)
    assert (s.march.linear_steps, s.shadows.resolution, s.view.orbit.azimuth, s.motion.time, s.image.ssaa,
            s.effects.effects, s.view.orbit.fov_y) == (16, 1024, 60.0, 0.5, 2, ("relief", "shadows"), 30.0)
    with pytest.raises(PlantgenError, match="linear_stepz"):
        RenderSettings.from_options(linear_stepz=3)


@pytest.mark.parametrize("cls, field, bad", [
    (RaycastSettings, "linear_steps", 0), (RaycastSettings, "binary_steps", 65), (RaycastSettings, "march", "slow"),
    (RaycastSettings, "march_density", 0.0), (ShadowSettings, "resolution", 8), (ShadowSettings, "caster", "x"),
    (ImageSettings, "ssaa", 9), (MotionSettings, "fps", 0.0), (MotionSettings, "time", math.nan),
    (MotionSettings, "frames", 0), (MeshSettings, "level", MAX_SUBDIV + 1), (KeyframeSettings, "rate", 0.0),
    (KeyframeSettings, "duration", 3601.0)])
def test_a_value_out_of_range_is_one_line_naming_the_option(cls, field, bad):
    with pytest.raises(PlantgenError) as info:
        cls(**{field: bad})
    text = str(info.value)
    assert "\n" not in text and knob_of(cls, field).option in text


def test_effects_resolve_against_the_scenes_list():
    assert EffectSettings().resolve(("shadows", "animation")) == ("shadows", "animation", "tone", "translucency")
    assert EffectSettings(bounce=True).resolve(()) == ("tone", "translucency", "bounce")
    assert EffectSettings(relief=True, shadows=False, tone=False, translucency=False,
                          bounce=False).resolve(("shadows",)) == ("relief",)
    assert EffectSettings(effects=()).resolve(("relief",)) == ()
    assert EffectSettings(effects="relief,animation").effects == ("relief", "animation")
    march, shadows = RenderSettings().frame(("relief",))
    assert march.relief and shadows is None
    march, shadows = RenderSettings().frame(("shadows",))
    assert not march.relief and shadows == ShadowSettings()


knob_values = st.fixed_dictionaries({}, optional={
    "linear_steps": st.integers(1, 4096), "binary_steps": st.integers(0, 64),
    "march": st.sampled_from(["adaptive", "fixed"]), "march_density": st.floats(0.01, 100),
    "v_exact": st.booleans(), "shadow_res": st.integers(16, 16384),
    "shadow_caster": st.sampled_from(["relief", "inner"]),
    "ssaa": st.integers(1, 8), "background": st.sampled_from(["sky", "white", "none", "#20304a"]),
    "time": st.floats(0, 1e4), "frames": st.integers(1, 100), "fps": st.floats(0.1, 120),
    "relief": st.booleans(), "shadows": st.booleans(),
    "effects": st.lists(st.sampled_from(["relief", "shadows", "animation"]), unique=True).map(",".join),
    "azimuth": st.floats(-720, 720), "elevation": st.floats(-89, 89), "zoom": st.floats(0.01, 100),
    "fov": st.floats(1, 179), "size": st.tuples(st.integers(1, 4096), st.integers(1, 4096))})


@settings(max_examples=60, deadline=None)
@given(knob_values)
def test_settings_written_as_words_read_back_the_same(values):
    """knob_args (what the viewer prints as a render command) and the command's own
    parsing are inverse: any settings, written out and read back, are the same value."""
    s = build_settings(RenderSettings, values)
    words = knob_args(s)
    ctx = render.make_context("render", ["x.yaml", "-o", "x.png", *words])
    params = dict(ctx.params)
    assert take_settings(RenderSettings, params) == s
