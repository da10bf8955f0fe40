"""Coverage anti-aliasing's pass of thin pieces (``--aa coverage``): the ray caster's rows
thinner than the floor radius (``raycast.glsl``'s THIN_COVERAGE) and the leaves narrower
than the floor width (``leaf.glsl``'s THIN_LEAVES) are left out of the opaque draw
(``coverage_pass`` 0) and drawn after everything opaque by a pass of their own
(``coverage_pass`` 1): widened to the floor, blended by their alpha (their share of the
pixel) over what is there, writing neither depth nor distance. A thin piece hides nothing,
and the frame's distances are those of the opaque surfaces alone. (A second pass writing
the thin pieces' own distances was tried: it cost the pine about as much as the blend.)
"""

from __future__ import annotations

from .shaders import set_uniforms

__all__ = ["coverage_pass"]


def coverage_pass(ctx, program, render):
    """The blended draw of ``program``'s thin pieces; ``render()`` draws the program's
    geometry. It leaves ``coverage_pass`` at 0 and the state as it was."""

    def draw():
        set_uniforms(program, coverage_pass=1)
        fbo = ctx.fbo
        masks = fbo.color_mask
        ctx.enable(ctx.BLEND)
        ctx.blend_func = (ctx.SRC_ALPHA, ctx.ONE_MINUS_SRC_ALPHA, ctx.ONE, ctx.ONE_MINUS_SRC_ALPHA)
        ctx.disable(ctx.CULL_FACE)
        fbo.depth_mask = False
        fbo.color_mask = ((True,) * 4,) + ((False,) * 4,) * (len(masks) - 1)    # the colour alone
        try:
            render()
        finally:
            fbo.color_mask = masks
            fbo.depth_mask = True
            ctx.disable(ctx.BLEND)
            ctx.blend_func = ctx.DEFAULT_BLENDING
            set_uniforms(program, coverage_pass=0)
    return draw
