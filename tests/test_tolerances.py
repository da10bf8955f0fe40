"""The tolerance object: named, frozen, and handed to every GLSL program unchanged."""

import dataclasses
import inspect
import re

import numpy as np
import pytest

from plantgen.gl.shaders import shader_source
from plantgen.tolerances import GLSL_FIELDS, Tolerances, tol


def test_tolerances_are_frozen_and_documented():
    with pytest.raises(dataclasses.FrozenInstanceError):
        tol.tiny = 0.0
    text = inspect.getsource(Tolerances)
    for field in dataclasses.fields(Tolerances):
        # every field is followed by its docstring (what it guards, its unit)
        assert re.search(rf"^    {field.name}: float = .*\n    \"\"\"", text, re.M), field.name
        assert getattr(tol, field.name) > 0


def test_every_program_gets_the_glsl_tolerances_with_their_float32_values():
    defines = tol.glsl_defines()
    assert set(defines) == {f"TOL_{name.upper()}" for name in GLSL_FIELDS}
    for stage in ("VERTEX_SHADER", "FRAGMENT_SHADER"):
        lines = shader_source("raycast.glsl", stage, {"RELIEF": True}).splitlines()
        written = {m.group(1): m.group(2) for m in
                   (re.match(r"#define (TOL_\w+) (\S+)$", line) for line in lines) if m}
        assert set(written) == set(defines)
        for name, text in written.items():
            # GLSL reads the written text as a float32: the same one as the field's value
            assert np.float32(float(text)) == np.float32(defines[name]), name
            assert float(text) == defines[name]
        # the tolerances come before the caller's variant defines
        assert lines.index("#define RELIEF") > max(lines.index(f"#define {k} {v}") for k, v in written.items())
