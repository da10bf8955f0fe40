"""The GLSL loader and the EGL context factory (plantgen.gl.shaders / .context)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from plantgen._resources import shaders_dir
from plantgen.gl import context as context_module
from plantgen.gl.shaders import ShaderError, build_program, program_stages, shader_source


def write(tmp_path, **files):
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    return tmp_path


def test_stage_guard_defines_and_include_assemble_in_order(tmp_path):
    d = write(tmp_path,
              **{"prog.glsl": '#include "lib.glsl"\n#if defined VERTEX_SHADER\nvoid main(){}\n#endif\n',
                 "lib.glsl": "float lib_value() { return 1.0; }\n"})
    src = shader_source("prog.glsl", "VERTEX_SHADER", {"RELIEF": True, "STEPS": 8, "OFF": False},
                        directory=d)
    lines = src.splitlines()
    assert lines[0] == "#version 430 core"          # the one version line comes first
    assert "#define VERTEX_SHADER" in lines
    assert "#define RELIEF" in lines and "#define STEPS 8" in lines
    assert not any("OFF" in line for line in lines)  # False leaves the macro undefined
    assert lines.index("float lib_value() { return 1.0; }") < lines.index("void main(){}")
    assert not any(line.lstrip().startswith("#include") for line in lines)
    # After the include, #line puts the compiler back on prog.glsl's line 2 (file 0).
    assert lines[lines.index("float lib_value() { return 1.0; }") + 1] == "#line 2 0"


def test_each_file_is_included_once_and_cycles_are_errors(tmp_path):
    d = write(tmp_path, **{"a.glsl": '#include "c.glsl"\n#include "c.glsl"\n', "c.glsl": "int c;\n",
                           "x.glsl": '#include "y.glsl"\n', "y.glsl": '#include "x.glsl"\n'})
    assert shader_source("a.glsl", "FRAGMENT_SHADER", directory=d).count("int c;") == 1
    with pytest.raises(ShaderError, match="cycle: x.glsl -> y.glsl -> x.glsl"):
        shader_source("x.glsl", "FRAGMENT_SHADER", directory=d)
    with pytest.raises(ShaderError, match="missing.glsl"):
        shader_source("missing.glsl", "VERTEX_SHADER", directory=d)
    with pytest.raises(ShaderError, match="bad shader define"):
        shader_source("a.glsl", "VERTEX_SHADER", {"not a name": 1}, directory=d)


def test_shipped_programs_guard_their_stages():
    assert program_stages("raycast.glsl") == ("VERTEX_SHADER", "FRAGMENT_SHADER")
    assert program_stages("sky.glsl") == ("VERTEX_SHADER", "FRAGMENT_SHADER")
    # the cone math lives in one include, shared by every stage that needs it
    for stage in ("VERTEX_SHADER", "FRAGMENT_SHADER"):
        assert shader_source("raycast.glsl", stage).count("bool frustum_interval(") == 1
    assert (shaders_dir() / "cone.glsl").read_text().count("bool frustum_interval(") == 1


@pytest.mark.parametrize("relief, v_exact", list(itertools.product([False, True], repeat=2)))
def test_every_raycast_variant_compiles_and_is_cached(gl_ctx, relief, v_exact):
    defines = {"RELIEF": relief, "V_EXACT": v_exact}
    program = build_program(gl_ctx, "raycast.glsl", defines)
    assert build_program(gl_ctx, "raycast.glsl", dict(defines)) is program
    # the relief knobs exist only in the variant that marches
    assert ("linear_steps" in program) == relief


def test_compile_error_names_the_file(gl_ctx, tmp_path):
    d = write(tmp_path, **{"bad.glsl": '#include "lib.glsl"\n#if defined VERTEX_SHADER\n'
                                       "void main() { gl_Position = vec4(0.0); }\n"
                                       "#elif defined FRAGMENT_SHADER\nout vec4 c;\n"
                                       "void main() { c = undefined_thing; }\n#endif\n",
                           "lib.glsl": "float f() { return 1.0; }\n"})
    with pytest.raises(ShaderError) as info:
        build_program(gl_ctx, "bad.glsl", directory=d)
    assert "undefined_thing" in str(info.value) and "0=bad.glsl, 1=lib.glsl" in str(info.value)


def test_context_is_shared_and_names_its_renderer(gl_ctx):
    assert context_module.gl_context() is gl_ctx
    name = context_module.renderer_name()
    assert name and name == gl_ctx.info["GL_RENDERER"]
    assert gl_ctx.version_code >= context_module.REQUIRED_GL_VERSION


def test_no_context_is_a_one_line_error(monkeypatch):
    import moderngl

    def fail(**kwargs):
        raise Exception("eglGetDisplay failed\n(no EGL)")

    monkeypatch.setattr(context_module, "_context", None)
    monkeypatch.setattr(moderngl, "create_context", fail)
    with pytest.raises(context_module.GLContextError) as info:
        context_module.gl_context()
    message = str(info.value)
    assert "\n" not in message and "EGL" in message and "eglGetDisplay failed" in message


def test_a_draw_through_the_loader_reads_back(gl_ctx, tmp_path):
    # A full-screen triangle whose colour comes from an included function and a define.
    d = write(tmp_path, **{"fill.glsl": '#include "lib.glsl"\n#if defined VERTEX_SHADER\n'
                                        "void main() { vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);"
                                        " gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0); }\n"
                                        "#elif defined FRAGMENT_SHADER\nout vec4 c;\n"
                                        "void main() { c = vec4(half_value() * SCALE, 0.0, 0.0, 1.0); }\n#endif\n",
                           "lib.glsl": "float half_value() { return 0.5; }\n"})
    program = build_program(gl_ctx, "fill.glsl", {"SCALE": 2.0}, directory=d)
    fbo = gl_ctx.framebuffer(color_attachments=[gl_ctx.renderbuffer((4, 4), 4)])
    try:
        fbo.use()
        vao = gl_ctx.vertex_array(program, [])
        vao.render(vertices=3)
        pixels = np.frombuffer(fbo.read(components=4), np.uint8).reshape(4, 4, 4)
        vao.release()
    finally:
        context_module.release_framebuffer(fbo)
    assert np.all(pixels[..., 0] == 255) and np.all(pixels[..., 1] == 0)


def test_a_misspelt_uniform_fails_loudly_and_an_inactive_one_is_passed_over(gl_ctx):
    """set_uniforms checks names against what the program's stages declare: a typo is a
    bug (ShaderError naming it); a declared uniform this variant does not use is fine."""
    from plantgen.gl.shaders import set_uniforms

    sky = build_program(gl_ctx, "sky.glsl")
    set_uniforms(sky, viewport=(64.0, 48.0), material_gloss=np.zeros((16, 2), np.float32))
    assert "material_gloss" not in sky          # declared by shading.glsl, unused by the sky
    assert sky["viewport"].value == (64.0, 48.0)
    with pytest.raises(ShaderError, match="viewprt"):
        set_uniforms(sky, viewprt=(64.0, 48.0))


def test_every_program_gets_the_shared_defines():
    """MAX_MATERIALS and the tolerances reach GLSL from their one Python home."""
    from plantgen.geometry.skeletons.materials import MAX_MATERIALS
    from plantgen.gl.shaders import shared_defines

    src = shader_source("raycast.glsl", "FRAGMENT_SHADER")
    assert f"#define MAX_MATERIALS {MAX_MATERIALS}" in src.splitlines()
    for name in shared_defines():
        assert f"#define {name} " in src
    assert not any(line.strip().startswith("#define MAX_MATERIALS")
                   for path in shaders_dir().glob("*.glsl") for line in path.read_text().splitlines())
    with pytest.raises(ShaderError, match="MAX_MATERIALS"):
        shader_source("sky.glsl", "VERTEX_SHADER", {"MAX_MATERIALS": 4})
