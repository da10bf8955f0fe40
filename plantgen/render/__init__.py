"""GL rendering: the one EGL context factory, the GLSL loader and the frusta ray caster.

``gl_context()`` (context.py) is the only place a GL context is made; ``build_program``
(shaders.py) assembles ``shaders/*.glsl`` with includes and defines; ``Raycaster``
(raycast.py) ray casts Frusta (RC, RC+R). Nothing here imports click; geometry never
imports this package.
"""

from .context import GLContextError, gl_context, release_framebuffer, renderer_name
from .shaders import ShaderError, build_program, shader_source

__all__ = ["GLContextError", "gl_context", "release_framebuffer", "renderer_name",
           "ShaderError", "build_program", "shader_source"]
