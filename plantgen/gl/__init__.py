"""GL rendering: everything that touches OpenGL, and nothing else.

``gl_context()`` (context.py) is the only place a GL context is made; ``build_program``
(shaders.py) assembles ``shaders/*.glsl`` with includes and the shared defines, and
``set_uniforms`` sets them; records.py packs the frusta into 96-byte records (and streams
an animation's); frame.py is the offscreen frame every renderer draws into (sky, ground,
shadow map, read-back); ``Raycaster`` (raycast.py) ray casts Frusta (RC, RC+R) and
``RasterRenderer`` (raster.py) draws tessellated meshes (GS, GS+R); both return a
``RenderResult`` with typed stats (result.py).

This package imports only ``plantgen.geometry`` and the bottom layer (errors, tolerances,
resources): it knows no scene file, no pipeline, no bench and no command line
(``pyproject.toml``'s import-linter contracts check it).
"""

from .context import GLContextError, gl_context, release_framebuffer, renderer_name
from .shaders import ShaderError, build_program, shader_source

__all__ = ["GLContextError", "gl_context", "release_framebuffer", "renderer_name",
           "ShaderError", "build_program", "shader_source"]
