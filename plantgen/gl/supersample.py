"""Supersampling (``ssaa``): a frame drawn at N times the pixels per side, each N x N block
averaged into one pixel.

The sub-pixel centres of the large frame are the rays of an N x N grid inside each pixel
(:meth:`plantgen.geometry.rays.camera.Camera.scaled`), so the average is a box filter over the
pixel: thin twigs that a single ray per pixel hits in some pixels and misses in the next
("dots") cover each pixel in proportion. Colours are averaged in linear light (the
shaders' display encoding, ``to_display`` in ``shaders/shading.glsl``, is undone first and
applied again after), so an edge keeps its brightness; with a transparent background the
colours are averaged weighted by their alpha (coverage). A frame drawn with the ``tone``
effect is sRGB-encoded (after the tone curve): ``srgb`` undoes and applies that instead.
The renderers average on the GPU (:class:`GpuResolve`, ``shaders/resolve.glsl``);
:func:`resolve_supersamples` is the same average on the CPU, the reference the tests hold
the GPU's to.
"""

from __future__ import annotations

import numpy as np

from ..settings import MAX_SSAA, TONE_KNEE  # the largest supersampling factor: its home is the settings
from .context import release_framebuffer
from .shaders import build_program, set_uniforms

__all__ = ["DISPLAY_GAMMA", "MAX_SSAA", "EDGE_THRESHOLD", "EDGE_RELATIVE",
           "resolve_supersamples", "srgb_encode", "srgb_decode", "tone_curve",
           "GpuResolve"]

#: The exponent of the shaders' display encoding: ``to_display(c) = c^(1/2.2)``.
DISPLAY_GAMMA = 2.2


_TO_LINEAR = ((np.arange(256, dtype=np.float64) / 255.0) ** DISPLAY_GAMMA).astype(np.float32)


def srgb_decode(c):
    """Linear values of sRGB-encoded ``c`` in [0, 1] (IEC 61966-2-1)."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def srgb_encode(c):
    """sRGB encoding of linear ``c`` in [0, 1] (shading.glsl's ``srgb_encode``)."""
    c = np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1.0 / 2.4) - 0.055)


def tone_curve(x, exposure: float = 1.0, curve: str = "filmic", knee: float = TONE_KNEE):
    """The ``tone`` effect's curve of linear light, in [0, 1) (shading.glsl's
    ``tone_curve``): ``filmic``, the identity up to ``knee`` then an exponential shoulder;
    ``aces``, the rational fit of ACES's RRT+ODT published by K. Narkowicz (2016)."""
    x = np.maximum(np.asarray(x, dtype=np.float64) * exposure, 0.0)
    if curve == "aces":
        return np.clip(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)
    shoulder = knee + (1.0 - knee) * (1.0 - np.exp(-(x - knee) / (1.0 - knee)))
    return np.where(x < knee, x, shoulder)


#: Coverage anti-aliasing's edge pass (:meth:`GpuResolve.smooth_edges`): a pixel is on an
#: edge where the luma (display-encoded, 0..1) of it and its eight neighbours spans at least
#: this much, and at least :data:`EDGE_RELATIVE` of the brightest of them.
EDGE_THRESHOLD = 0.05
EDGE_RELATIVE = 0.1

_SRGB_TO_LINEAR = srgb_decode(np.arange(256) / 255.0).astype(np.float32)


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


def resolve_supersamples(color: np.ndarray, distance: np.ndarray, n: int, *,
                         srgb: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Average each ``n`` x ``n`` block of a supersampled frame into one pixel.

    Parameters
    ----------
    color : (h*n, w*n, 3 or 4) uint8, display-encoded; a 4th channel is alpha (coverage)
    distance : (h*n, w*n) float32 distances along each sub-pixel's ray (inf for a miss)
    n : samples per pixel side (1 returns the inputs)
    srgb : the frame is sRGB-encoded (the ``tone`` effect), else c^(1/2.2)

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
    linear = (_SRGB_TO_LINEAR if srgb else _TO_LINEAR)[color[..., :3]]   # (h*n, w*n, 3)
    if color.shape[-1] == 4:
        alpha = color[..., 3:].astype(np.float32) / 255.0
        weight = _block_sums(alpha, n)
        mean = _block_sums(linear * alpha, n) / np.maximum(weight, 1e-12)
        coverage = weight / (n * n)
    else:
        mean = _block_sums(linear, n) / (n * n)
        coverage = None
    encoded = srgb_encode(mean) if srgb else np.clip(mean, 0.0, 1.0) ** (1.0 / DISPLAY_GAMMA)
    rgb = np.round(255.0 * encoded).astype(np.uint8)
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

    def resolve(self, color_texture, distance_texture, width: int, height: int, n: int, alpha: bool, *,
                srgb: bool = False):
        """The final (height, width, 3 or 4) uint8 colour and (height, width) float32
        distance, row 0 the top row, of a frame drawn at ``n`` samples per side into
        ``color_texture`` (RGBA8) and ``distance_texture`` (R32F); ``srgb``: the frame is
        sRGB-encoded (the ``tone`` effect), else c^(1/2.2), as :func:`resolve_supersamples`."""
        srgb = bool(srgb)
        program = build_program(self.ctx, "resolve.glsl", {"COVERAGE": bool(alpha), "FACTOR": int(n), "SRGB": srgb})
        set_uniforms(program, frame_color=0, frame_distance=1)
        program["to_linear"].value = (_SRGB_TO_LINEAR if srgb else _TO_LINEAR).tolist()
        return self._run(program, color_texture, distance_texture, width, height, alpha)

    def smooth_edges(self, color_texture, distance_texture, width: int, height: int, alpha: bool):
        """Coverage anti-aliasing's edge pass (``shaders/edges.glsl``) over a frame drawn at
        one ray a pixel: the (height, width, 3 or 4) uint8 colour with its edges smoothed
        along their direction (:data:`EDGE_THRESHOLD`, :data:`EDGE_RELATIVE`) and the
        (height, width) float32 distance as drawn, row 0 the top row."""
        program = build_program(self.ctx, "edges.glsl")
        set_uniforms(program, frame_color=0, frame_distance=1, edge_threshold=EDGE_THRESHOLD,
                     edge_relative=EDGE_RELATIVE)
        color_texture.repeat_x = color_texture.repeat_y = False     # the taps clamp at the border
        return self._run(program, color_texture, distance_texture, width, height, alpha)

    def _run(self, program, color_texture, distance_texture, width: int, height: int, alpha: bool):
        """Draw ``program``'s full-screen triangle into the target of the final size, the
        frame's textures on units 0 and 1, and read the target back."""
        ctx = self.ctx
        vao = self._vaos.get(id(program))
        if vao is None or vao.program is not program:
            vao = self._vaos[id(program)] = ctx.vertex_array(program, [])
        fbo = self._target(width, height)
        fbo.use()
        fbo.viewport = (0, 0, width, height)
        color_texture.use(0)
        distance_texture.use(1)
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
