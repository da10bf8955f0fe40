"""A small GLSL loader: one file per program, stage guards, ``#include`` and defines.

A program file holds every stage, each behind a guard::

    #if defined VERTEX_SHADER
    ...
    #elif defined FRAGMENT_SHADER
    ...
    #endif

:func:`shader_source` assembles the text for one stage: the ``#version`` line, the stage
macro, the tolerances (``plantgen.tolerances.tol.glsl_defines()``: ``TOL_*`` macros), the
caller's ``defines`` (variants such as ``RELIEF``, ``V_EXACT``, ``SHADOWS``),
then the file with every ``#include "other.glsl"`` replaced by that file's text (looked up
in :func:`plantgen._resources.shaders_dir`, each file included at most once per stage).
``#line`` directives keep compiler messages pointing at the right file and line; the
file numbers are listed in the error text. Every program also gets the defines of
:func:`shared_defines`: the material slot count and the named tolerances of
:mod:`plantgen.tolerances`, so GLSL and numpy read each constant from one home.

Uniforms are set through :func:`set_uniforms`, which fails loudly on a name no stage of
the program declares (a misspelt uniform), and passes over a declared uniform that the
compiler optimised out of this variant.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from .._resources import shaders_dir
from ..geometry.skeletons.materials import MAX_MATERIALS
from ..tolerances import tol

__all__ = ["ShaderError", "shader_source", "build_program", "build_compute", "program_stages", "GLSL_VERSION",
           "shared_defines", "set_uniforms", "mat4"]

GLSL_VERSION = "#version 430 core"
STAGES = ("VERTEX_SHADER", "GEOMETRY_SHADER", "FRAGMENT_SHADER", "COMPUTE_SHADER")
_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"\s*$')
_DEFINE_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_UNIFORM = re.compile(r"^\s*uniform\s+\w+\s+(\w+)", re.MULTILINE)


def shared_defines() -> dict[str, object]:
    """Defines every program gets: ``MAX_MATERIALS`` and the GLSL-side tolerances."""
    return {"MAX_MATERIALS": MAX_MATERIALS, **tol.glsl_defines()}


class ShaderError(RuntimeError):
    """A shader file is missing, includes itself, or does not compile (a bug, not user input)."""


def _read(name: str, directory: Path) -> str:
    path = directory / name
    if not path.is_file():
        raise ShaderError(f"shader file {name!r} not found in {directory}")
    return path.read_text()


def _define_lines(defines: Mapping[str, object] | None) -> list[str]:
    lines = []
    for key, value in sorted((defines or {}).items()):
        if not _DEFINE_NAME.match(key) or key in STAGES:
            raise ShaderError(f"bad shader define name {key!r}")
        if value is None or value is False:
            continue
        if value is True:
            lines.append(f"#define {key}")
        elif isinstance(value, float):
            lines.append(f"#define {key} {value!r}")
        else:
            lines.append(f"#define {key} {value}")
    return lines


def shader_source(name: str, stage: str, defines: Mapping[str, object] | None = None,
                  directory: Path | None = None) -> str:
    """The complete GLSL text of one stage of program file ``name``.

    Parameters
    ----------
    name : file name in the shaders directory, e.g. ``"raycast.glsl"``
    stage : one of ``"VERTEX_SHADER"``, ``"GEOMETRY_SHADER"``, ``"FRAGMENT_SHADER"``,
        ``"COMPUTE_SHADER"``
    defines : macro name -> value; ``True`` defines a flag, ``False``/``None`` leaves it out
    directory : where to look for files (default: the shipped ``shaders/``)
    """
    if stage not in STAGES:
        raise ShaderError(f"unknown shader stage {stage!r}")
    directory = Path(directory) if directory is not None else shaders_dir()
    files: list[str] = []
    shared = shared_defines()
    clash = sorted(set(shared) & set(defines or {}))
    if clash:
        raise ShaderError(f"defines {clash} are set by plantgen for every program")
    out = [GLSL_VERSION, f"#define {stage}", *_define_lines(shared), *_define_lines(defines)]

    def expand(fname: str, chain: tuple[str, ...]) -> None:
        if fname in chain:
            raise ShaderError(f"shader include cycle: {' -> '.join(chain + (fname,))}")
        if fname in files:  # included once per stage, like #pragma once
            return
        files.append(fname)
        number = len(files) - 1
        out.append(f"#line 1 {number}")
        for lineno, line in enumerate(_read(fname, directory).splitlines(), start=1):
            m = _INCLUDE.match(line)
            if m:
                expand(m.group(1), chain + (fname,))
                out.append(f"#line {lineno + 1} {number}")
            elif line.lstrip().startswith("#version"):
                out.append("")  # the loader writes the one #version line
            else:
                out.append(line)

    expand(name, ())
    out.insert(1, "// files: " + ", ".join(f"{i}={f}" for i, f in enumerate(files)))
    return "\n".join(out) + "\n"


def program_stages(name: str, directory: Path | None = None) -> tuple[str, ...]:
    """The stages program file ``name`` guards with ``#if defined STAGE`` (not its includes)."""
    directory = Path(directory) if directory is not None else shaders_dir()
    text = _read(name, directory)
    return tuple(s for s in STAGES if re.search(rf"defined\s*\(?\s*{s}\b", text))


_cache: dict = {}


def build_program(ctx, name: str, defines: Mapping[str, object] | None = None,
                  directory: Path | None = None):
    """Compile and link program file ``name`` with ``defines``; cached per context and variant.

    Returns a ``moderngl.Program``. Raises :class:`ShaderError` with the compiler log,
    prefixed by the file numbering, if a stage does not compile.
    """
    key = (id(ctx), name, tuple(sorted((k, repr(v)) for k, v in (defines or {}).items())),
           str(directory))
    program = _cache.get(key)
    if program is not None and program.ctx is ctx:
        return program
    stages = program_stages(name, directory)
    if "VERTEX_SHADER" not in stages:
        raise ShaderError(f"{name}: no '#if defined VERTEX_SHADER' section")
    sources = {s: shader_source(name, s, defines, directory) for s in stages}
    try:
        program = ctx.program(
            vertex_shader=sources["VERTEX_SHADER"],
            geometry_shader=sources.get("GEOMETRY_SHADER"),
            fragment_shader=sources.get("FRAGMENT_SHADER"),
        )
    except Exception as exc:  # moderngl.Error
        files = sources["VERTEX_SHADER"].splitlines()[1]
        raise ShaderError(f"{name} {dict(defines or {})}: {exc}\n{files}") from None
    declared = {m.group(1) for text in sources.values() for m in _UNIFORM.finditer(text)}
    program.extra = {"name": name, "defines": dict(defines or {}), "uniforms": declared}
    _cache[key] = program
    return program


def build_compute(ctx, name: str, defines: Mapping[str, object] | None = None,
                  directory: Path | None = None):
    """Compile the ``COMPUTE_SHADER`` stage of program file ``name`` with ``defines``
    (cached per context and variant, as :func:`build_program`); returns a
    ``moderngl.ComputeShader`` that :func:`set_uniforms` can set."""
    key = (id(ctx), name, "compute", tuple(sorted((k, repr(v)) for k, v in (defines or {}).items())),
           str(directory))
    program = _cache.get(key)
    if program is not None and program.ctx is ctx:
        return program
    if "COMPUTE_SHADER" not in program_stages(name, directory):
        raise ShaderError(f"{name}: no '#if defined COMPUTE_SHADER' section")
    source = shader_source(name, "COMPUTE_SHADER", defines, directory)
    try:
        program = ctx.compute_shader(source)
    except Exception as exc:  # moderngl.Error
        raise ShaderError(f"{name} {dict(defines or {})}: {exc}\n{source.splitlines()[1]}") from None
    program.extra = {"name": name, "defines": dict(defines or {}),
                     "uniforms": {m.group(1) for m in _UNIFORM.finditer(source)}}
    _cache[key] = program
    return program


def set_uniforms(program, **values) -> None:
    """Set uniforms of a program made by :func:`build_program`.

    A numpy array is written as float32 bytes (uniform arrays such as the palette); any
    other value is assigned as is (numbers and tuples; see :func:`mat4` for matrices). A
    name that no stage of the program declares raises :class:`ShaderError` (a misspelt
    uniform is a bug); a declared uniform the compiler removed from this variant is
    passed over.
    """
    info = program.extra
    for name, value in values.items():
        if name not in info["uniforms"]:
            raise ShaderError(f"{info['name']} {info['defines']}: no uniform named {name!r}")
        member = program.get(name, None)
        if member is None:
            continue
        if isinstance(value, np.ndarray):
            member.write(np.ascontiguousarray(value, dtype=np.float32).tobytes())
        else:
            member.value = value


def mat4(matrix: np.ndarray) -> tuple:
    """A (4, 4) float64 matrix as a GLSL ``mat4`` uniform value (column-major float32)."""
    return tuple(np.asarray(matrix).T.astype(np.float32).ravel())
