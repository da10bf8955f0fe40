"""The one place that creates an OpenGL context: headless, through EGL.

On a machine without a display this gives Mesa's llvmpipe (software) or the NVIDIA
driver's EGL where a GPU exists. Every renderer (the ray caster, the raster renderer,
tests) asks :func:`gl_context` for the shared, cached context.
"""

from __future__ import annotations

import threading

import moderngl

from ..errors import PlantgenError

__all__ = ["GLContextError", "gl_context", "hardware_gl", "renderer_name", "release_framebuffer", "REQUIRED_GL_VERSION"]

#: OpenGL core version the shaders are written for (``#version 430``).
REQUIRED_GL_VERSION = 430

_lock = threading.Lock()
_context = None


class GLContextError(PlantgenError, RuntimeError):
    """No usable headless OpenGL context could be made."""


def gl_context():
    """The shared headless moderngl context (created on first use, then cached).

    Raises
    ------
    GLContextError
        One line saying what is missing: an EGL library or an OpenGL 4.3 core driver.
    """
    global _context
    with _lock:
        if _context is not None:
            return _context
        try:
            ctx = moderngl.create_context(standalone=True, backend="egl",
                                          require=REQUIRED_GL_VERSION)
        except Exception as exc:  # moderngl/glcontext raise plain Exception subclasses
            detail = " ".join(str(exc).split()) or type(exc).__name__
            raise GLContextError(
                "cannot create a headless OpenGL 4.3 context through EGL "
                f"(install libEGL and Mesa's llvmpipe, or a GPU driver with EGL): {detail}"
            ) from None
        _context = ctx
        return ctx


def renderer_name() -> str:
    """The GL_RENDERER string of the shared context, e.g. ``llvmpipe (LLVM 15.0.6, 256 bits)``."""
    return str(gl_context().info["GL_RENDERER"])


#: GL_RENDERER words of a software rasteriser (Mesa's): no GPU behind the context.
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "lavapipe")


def hardware_gl() -> bool:
    """Whether a GL context exists here and a GPU draws it (not a software rasteriser,
    :data:`SOFTWARE_RENDERERS`): where it does not, the compiled CPU traversal is the
    faster tracer (``plantgen.trace(device="auto")``, ``plantgen scan``)."""
    try:
        name = renderer_name().lower()
    except GLContextError:
        return False
    return not any(word in name for word in SOFTWARE_RENDERERS)


_parking = {}


def release_framebuffer(fbo) -> None:
    """Release ``fbo`` (and its attachments) without leaving a deleted framebuffer bound.

    moderngl restores the current framebuffer after creating one; if the current one had
    been released, that restore raises GL_INVALID_OPERATION. So a bound framebuffer is
    first swapped for a 1x1 parking framebuffer owned by this module.
    """
    ctx = fbo.ctx
    if ctx.fbo is fbo:
        park = _parking.get(id(ctx))
        if park is None or park.ctx is not ctx:
            park = ctx.framebuffer(color_attachments=[ctx.renderbuffer((1, 1), 4)])
            _parking[id(ctx)] = park
        park.use()
    attachments = [*fbo.color_attachments, fbo.depth_attachment]
    fbo.release()
    for att in attachments:
        if att is not None:
            att.release()
