"""Supersampling (``ssaa``): a frame drawn at N times the pixels per side, each N x N block
averaged into one pixel.

The sub-pixel centres of the large frame are the rays of an N x N grid inside each pixel
(:meth:`plantgen.geometry.camera.Camera.scaled`), so the average is a box filter over the
pixel: thin twigs that a single ray per pixel hits in some pixels and misses in the next
("dots") cover each pixel in proportion. Colours are averaged in linear light (the
shaders' display encoding, ``to_display`` in ``shaders/shading.glsl``, is undone first and
applied again after), so an edge keeps its brightness; with a transparent background the
colours are averaged weighted by their alpha (coverage).
"""

from __future__ import annotations

import numpy as np

__all__ = ["DISPLAY_GAMMA", "MAX_SSAA", "resolve_supersamples"]

#: The exponent of the shaders' display encoding: ``to_display(c) = c^(1/2.2)``.
DISPLAY_GAMMA = 2.2

#: The largest supersampling factor (N x N samples a pixel).
MAX_SSAA = 8

_TO_LINEAR = ((np.arange(256, dtype=np.float64) / 255.0) ** DISPLAY_GAMMA).astype(np.float32)


def _blocks(image: np.ndarray, n: int) -> np.ndarray:
    """(h*n, w*n, ...) -> (h, n, w, n, ...) view of each pixel's n x n block."""
    hn, wn = image.shape[:2]
    return image.reshape(hn // n, n, wn // n, n, *image.shape[2:])


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
    linear = _blocks(_TO_LINEAR[color[..., :3]], n)                     # (h, n, w, n, 3)
    if color.shape[-1] == 4:
        alpha = _blocks(color[..., 3].astype(np.float32) / 255.0, n)[..., None]
        weight = alpha.sum(axis=(1, 3))
        mean = (linear * alpha).sum(axis=(1, 3)) / np.maximum(weight, 1e-12)
        coverage = weight[..., 0] / (n * n)
    else:
        mean = linear.mean(axis=(1, 3))
        coverage = None
    rgb = np.round(255.0 * np.clip(mean, 0.0, 1.0) ** (1.0 / DISPLAY_GAMMA)).astype(np.uint8)
    if coverage is not None:
        rgb = np.concatenate([rgb, np.round(255.0 * coverage)[..., None].astype(np.uint8)], axis=-1)
    centre = _blocks(distance, n)[:, n // 2, :, n // 2]
    return rgb, np.ascontiguousarray(centre)
