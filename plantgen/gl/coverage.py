"""Coverage anti-aliasing's passes of thin pieces (``--aa coverage``): the ray caster's rows
thinner than the floor radius (``raycast.glsl``'s THIN_COVERAGE) and the leaves narrower
than the floor width (``leaf.glsl``'s THIN_LEAVES) are left out of the opaque draw
(``coverage_pass`` 0) and drawn after everything opaque by passes of their own (the thin
leaves by the first alone: they leave no distance, :mod:`plantgen.gl.leaf_layer`):

- ``coverage_pass`` 1, widened to the floor, blended by their alpha (their share of the
  pixel) over what is there, writing neither depth nor distance: a thin piece hides nothing;
- then, after every such blend, ``coverage_pass`` 2, at their true size, writing the depth
  and the distance (no colour) where they are the nearest surface on a pixel centre's ray,
  so the frame's distances are those of one ray a pixel.
"""

from __future__ import annotations

from .shaders import set_uniforms

__all__ = ["coverage_passes"]


def coverage_passes(ctx, program, render) -> tuple:
    """The two draws (blend, distance) of ``program``'s thin pieces; ``render()`` draws the
    program's geometry. Each leaves ``coverage_pass`` at 0 and the state as it was. The
    frame draws every blend before any distance (``Surroundings.thin``, ``thin_distance``):
    a distance pass writes depth."""

    def pass_(number: int, blend: bool):
        def draw():
            set_uniforms(program, coverage_pass=number)
            fbo = ctx.fbo
            masks = fbo.color_mask
            if blend:
                ctx.enable(ctx.BLEND)
                ctx.blend_func = (ctx.SRC_ALPHA, ctx.ONE_MINUS_SRC_ALPHA, ctx.ONE, ctx.ONE_MINUS_SRC_ALPHA)
            ctx.disable(ctx.CULL_FACE)
            fbo.depth_mask = not blend
            # the colour (blend) or the distances (the other attachments) alone
            fbo.color_mask = tuple(((i == 0) == blend,) * 4 for i in range(len(masks)))
            try:
                render()
            finally:
                fbo.color_mask = masks
                fbo.depth_mask = True
                ctx.disable(ctx.BLEND)
                ctx.blend_func = ctx.DEFAULT_BLENDING
                set_uniforms(program, coverage_pass=0)
        return draw

    return pass_(1, True), pass_(2, False)
