"""Supersampling (``ssaa``): a frame drawn at N times the pixels per side, each N x N block
averaged into one pixel.

The sub-pixel centres of the large frame are the rays of an N x N grid inside each pixel
(:meth:`plantgen.geometry.rays.camera.Camera.scaled`), so the average is a box filter over the
pixel: thin twigs that a single ray per pixel hits in some pixels and misses in the next
("dots") cover each pixel in proportion. Colours are averaged in linear light (the
shaders' display encoding, ``to_display`` in ``shaders/shading.glsl``, is undone first and
applied again after), so an edge keeps its brightness; with a transparent background the
colours are averaged weighted by their alpha (coverage).
"""

from __future__ import annotations

import numpy as np

from ..settings import MAX_SSAA  # the largest supersampling factor: its home is the settings

__all__ = ["DISPLAY_GAMMA", "MAX_SSAA", "resolve_supersamples"]

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
