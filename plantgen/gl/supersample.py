"""Supersampling (``ssaa``): a frame drawn at N times the pixels per side, each N x N block
averaged into one pixel.

The sub-pixel centres of the large frame are the rays of an N x N grid inside each pixel
(:meth:`plantgen.geometry.rays.camera.Camera.scaled`), so the average is a box filter over the
pixel: thin twigs that a single ray per pixel hits in some pixels and misses in the next
("dots") cover each pixel in proportion. Colours are averaged in linear light (the
shaders' display encoding, ``to_display`` in ``shaders/shading.glsl``, is undone first and
applied again after), so an edge keeps its brightness; with a transparent background the
colours are averaged weighted by their alpha (coverage). The renderers average on the GPU
(:class:`GpuResolve`, ``shaders/resolve.glsl``); :func:`resolve_supersamples` is the same
average on the CPU, the reference the tests hold the GPU's to.
"""

from __future__ import annotations

import numpy as np

from ..settings import MAX_SSAA  # the largest supersampling factor: its home is the settings
from .context import release_framebuffer
from .shaders import build_program, set_uniforms

__all__ = ["DISPLAY_GAMMA", "MAX_SSAA", "resolve_supersamples", "GpuResolve"]

#: The exponent of the shaders' display encoding: ``to_display(c) = c^(1/2.2)``.
DISPLAY_GAMMA = 2.2


_TO_LINEAR = ((np.arange(256, dtype=np.float64) / 255.0) ** DISPLAY_GAMMA).astype(np.float32)


def _block_sums(image: np.ndarray, n: int) -> np.ndarray:
    """(h*n, w*n, c) float32 -> (h, w, c): the sum of each pixel's n x n block (slice adds:
    several times faster than a reduction over two strided axes)."""
    hn, wn, c = image.shape
    cols = image.reshape(hn, wn // n, n, c)
    across = cols[:, :, 0].copy()
    for k in range(1, n):
        across += cols[:, :, k]
    rows = across.reshape(hn // n, n, wn // n, c)
    total = rows[:, 0].copy()
    for k in range(1, n):
        total += rows[:, k]
    return total


def resolve_supersamples(color: np.ndarray, distance: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Average each ``n`` x ``n`` block of a supersampled frame into one pixel.

    Parameters
    ----------
    color : (h*n, w*n, 3 or 4) uint8, display-encoded; a 4th channel is alpha (coverage)
    distance : (h*n, w*n) float32 distances along each sub-pixel's ray (inf for a miss)
    n : samples per pixel side (1 returns the inputs)

    Returns
    -------
    color : (h, w, 3 or 4) uint8, the linear-light mean re-encoded (alpha: the mean
        coverage, colours weighted by it)
    distance : (h, w) float32, the sub-sample nearest each pixel's centre (the centre
        itself for odd ``n``)
    """
    n = int(n)
    if n == 1:
        return color, distance
    linear = _TO_LINEAR[color[..., :3]]                                  # (h*n, w*n, 3)
    if color.shape[-1] == 4:
        alpha = color[..., 3:].astype(np.float32) / 255.0
        weight = _block_sums(alpha, n)
        mean = _block_sums(linear * alpha, n) / np.maximum(weight, 1e-12)
        coverage = weight / (n * n)
    else:
        mean = _block_sums(linear, n) / (n * n)
        coverage = None
    rgb = np.round(255.0 * np.clip(mean, 0.0, 1.0) ** (1.0 / DISPLAY_GAMMA)).astype(np.uint8)
    if coverage is not None:
        rgb = np.concatenate([rgb, np.round(255.0 * coverage).astype(np.uint8)], axis=-1)
    hn, wn = distance.shape
    centre = distance.reshape(hn // n, n, wn // n, n)[:, n // 2, :, n // 2]
    return rgb, np.ascontiguousarray(centre)


class GpuResolve:
    """:func:`resolve_supersamples` as a pass on the GPU (``shaders/resolve.glsl``): the
    large frame's colour and distance textures averaged into a framebuffer of the final
    size, so only the final image is read back (the large one, read back and averaged on
    the CPU, took longer than the frame's own draw). The target is kept for the next
    frame of the same size."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._fbo = None
        self._size = None
        self._vaos: dict = {}

    def _target(self, width: int, height: int):
        if self._size != (width, height):
            if self._fbo is not None:
                release_framebuffer(self._fbo)
            ctx = self.ctx
            self._fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer((width, height), 4),
                                                           ctx.renderbuffer((width, height), 1, dtype="f4")])
            self._size = (width, height)
        return self._fbo

    def resolve(self, color_texture, distance_texture, width: int, height: int, n: int, alpha: bool):
        """The final (height, width, 3 or 4) uint8 colour and (height, width) float32
        distance, row 0 the top row, of a frame drawn at ``n`` samples per side into
        ``color_texture`` (RGBA8) and ``distance_texture`` (R32F)."""
        ctx = self.ctx
        program = build_program(ctx, "resolve.glsl", {"COVERAGE": bool(alpha), "FACTOR": int(n)})
        vao = self._vaos.get((alpha, n))
        if vao is None or vao.program is not program:
            vao = self._vaos[alpha, n] = ctx.vertex_array(program, [])
        fbo = self._target(width, height)
        fbo.use()
        fbo.viewport = (0, 0, width, height)
        color_texture.use(0)
        distance_texture.use(1)
        set_uniforms(program, frame_color=0, frame_distance=1)
        program["to_linear"].value = _TO_LINEAR.tolist()
        ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE | ctx.BLEND)
        vao.render(mode=ctx.TRIANGLES, vertices=3)
        k = 4 if alpha else 3
        color = np.frombuffer(fbo.read(components=k, attachment=0, alignment=1), np.uint8).reshape(height, width, k)
        dist = np.frombuffer(fbo.read(components=1, attachment=1, dtype="f4", alignment=1),
                             np.float32).reshape(height, width)
        return color[::-1].copy(), dist[::-1].copy()

    def release(self) -> None:
        for vao in self._vaos.values():
            vao.release()
        self._vaos = {}
        if self._fbo is not None:
            release_framebuffer(self._fbo)
        self._fbo = self._size = None
