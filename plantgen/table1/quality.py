"""Image error against the float64 reference, the quality criterion and the Pareto front:
pure numpy, no GL.

Error metric (documented criterion)
-----------------------------------
Each image is reduced to what the knobs change, its geometry: from the per-pixel distance
along the ray (every renderer writes it; the reference gives it in float64) the surface
point is rebuilt, its normal taken from the neighbouring pixels, and the image shaded as
``0.15 + 0.85·max(0, n·l)`` (0 where the ray misses). The same operator is applied to the
reference and to every method, so colours and texturing cancel out and relief bumps,
polygon facets and silhouettes remain. The error of a method is

    error = (1 - SSIM) + silhouette mismatch

SSIM (scikit-image's ``structural_similarity``: 11x11 Gaussian window, sigma 1.5,
population covariances, as Wang et al. 2004) on that shading, silhouette mismatch the
pixels covered by exactly one of method and reference over the pixels the reference
covers. Both parts are reported.

Quality criterion: a GS level qualifies when its error is at most the ray caster's error
times ``1 + rel_tol`` plus ``abs_tol`` (:func:`quality_bound`; defaults 10 % and 0.01: an
SSIM difference of 0.01 is hard to see); GS is matched against RC (no relief, non-relief
reference), GS+R against RC+R at its Table 1 configuration (relief reference). The levels
are walked up from m = 0 until one qualifies or the next one is over the triangle budget
(:mod:`plantgen.table1.matching`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import PlantgenError, missing_extra

__all__ = ["ssim", "require_skimage", "silhouette_mismatch", "depth_shading", "ImageError", "image_error",
           "matched_level", "quality_bound", "pareto_front", "MATCH_REL_TOL", "MATCH_ABS_TOL",
           "PARETO_MIN_GAIN"]

#: SSIM (Wang et al. 2004) as scikit-image computes it: Gaussian window of sigma 1.5
#: (11 taps), population (co)variances. With these settings skimage's mean SSIM equals the
#: hand-written one this module had before (to 1e-15 on images of 11 pixels and more).
SSIM_WINDOW = 11
SSIM_SIGMA = 1.5
#: What to install where scikit-image is missing.
SKIMAGE_HINT = missing_extra("the bench's error metric (SSIM, scikit-image)", "bench")
#: Depth shading: ambient + diffuse·max(0, n·l) on hits.
SHADING_AMBIENT = 0.15
SHADING_DIFFUSE = 0.85
#: The quality criterion's default tolerance: error <= target·(1 + rel) + abs.
MATCH_REL_TOL = 0.10
MATCH_ABS_TOL = 0.01
#: Error gain below which a slower point does not join the Pareto front (metric noise).
PARETO_MIN_GAIN = 1e-4


# ---------------------------------------------------------------------------- SSIM
def require_skimage():
    """scikit-image's ``structural_similarity``; PlantgenError (one line naming the extra
    to install) where scikit-image is missing."""
    try:
        from skimage.metrics import structural_similarity
    except ImportError:
        raise PlantgenError(SKIMAGE_HINT) from None
    return structural_similarity


def ssim(a: np.ndarray, b: np.ndarray, data_range: float = 1.0) -> float:
    """Mean structural similarity (Wang et al. 2004) of two images; 1 for identical ones.

    Parameters
    ----------
    a, b : (H, W) float images with values in [0, data_range]
    data_range : the value span, scales the stabilising constants (K1 = 0.01, K2 = 0.03)

    ``skimage.metrics.structural_similarity`` with ``gaussian_weights=True``, ``sigma=1.5``
    (an 11x11 window) and ``use_sample_covariance=False``, as Wang et al.; the mean runs over
    the pixels whose window lies inside the image. An image under 11 pixels on a side gets
    the largest odd window that fits, sigma shrunk in proportion.
    """
    structural_similarity = require_skimage()
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 2:
        raise ValueError(f"ssim needs two equal (H, W) images, got {a.shape} and {b.shape}")
    side = min(SSIM_WINDOW, *a.shape)
    window = side if side % 2 else side - 1
    return float(structural_similarity(a, b, data_range=data_range, gaussian_weights=True,
                                       sigma=SSIM_SIGMA * window / SSIM_WINDOW, win_size=window,
                                       use_sample_covariance=False))


def silhouette_mismatch(covered: np.ndarray, reference_covered: np.ndarray) -> float:
    """Pixels covered by exactly one of the two masks, over the pixels the reference
    covers (0: the same silhouette).

    covered, reference_covered : (H, W) bool
    """
    covered = np.asarray(covered, dtype=bool)
    reference_covered = np.asarray(reference_covered, dtype=bool)
    return float((covered ^ reference_covered).sum() / max(int(reference_covered.sum()), 1))


# ---------------------------------------------------------------------------- depth shading
def _neighbour_difference(points: np.ndarray, hit: np.ndarray, axis: int) -> np.ndarray:
    """(H, W, 3) point difference to the next pixel along ``axis`` (0: down, 1: right) where
    both hit, else to the previous one where both hit, else 0.

    points : (H, W, 3) surface points; hit : (H, W) bool
    """
    diff = np.diff(points, axis=axis)
    both = np.logical_and(np.take(hit, range(hit.shape[axis] - 1), axis=axis),
                          np.take(hit, range(1, hit.shape[axis]), axis=axis))
    diff = np.where(both[..., None], diff, 0.0)
    pad_after = [(0, 0)] * 3
    pad_before = [(0, 0)] * 3
    pad_after[axis] = (0, 1)
    pad_before[axis] = (1, 0)
    forward = np.pad(diff, pad_after)
    backward = np.pad(diff, pad_before)
    has_forward = np.pad(both, pad_after[:2])
    return np.where(has_forward[..., None], forward, backward)


def depth_shading(distance: np.ndarray, camera, light_dir) -> np.ndarray:
    """(H, W) float64 shading in [0, 1] of the surface rebuilt from per-pixel distances.

    Parameters
    ----------
    distance : (H, W) distance from the eye along each pixel's unit ray (world units),
        inf (or nan) where the ray misses; row 0 the top row
    camera : the Camera that made the rays
    light_dir : (3,) direction towards the light (normalised here)

    The normal comes from the cross product of the point differences to the right and
    downward neighbours (backward differences at the last row/column, and wherever the
    forward neighbour misses); shading 0.15 + 0.85·max(0, n·l) on hits, 0 on misses.
    """
    _, dirs = camera.rays()
    dist = np.asarray(distance, dtype=np.float64)
    hit = np.isfinite(dist)
    points = dirs * np.where(hit, dist, 0.0)[..., None]   # relative to the eye
    dx = _neighbour_difference(points, hit, axis=1)
    dy = _neighbour_difference(points, hit, axis=0)
    normal = np.cross(dy, dx)
    length = np.linalg.norm(normal, axis=-1, keepdims=True)
    normal = np.where(length > 0, normal / np.where(length > 0, length, 1.0), 0.0)
    facing = np.einsum("hwc,hwc->hw", normal, dirs)
    normal = np.where((facing > 0)[..., None], -normal, normal)   # towards the eye
    light = np.asarray(light_dir, dtype=np.float64)
    light = light / np.linalg.norm(light)
    lambert = np.clip(normal @ light, 0.0, 1.0)
    return np.where(hit, SHADING_AMBIENT + SHADING_DIFFUSE * lambert, 0.0)


# ---------------------------------------------------------------------------- error
@dataclass
class ImageError:
    """Error of one image against the reference: ``dssim`` = 1 - SSIM of the depth
    shading, ``silhouette`` the coverage mismatch, ``total`` their sum."""

    dssim: float
    silhouette: float

    @property
    def total(self) -> float:
        return self.dssim + self.silhouette

    def as_dict(self) -> dict:
        """{"error": total, "dssim", "silhouette"}: the error fields of a results row."""
        return {"error": self.total, "dssim": self.dssim, "silhouette": self.silhouette}


#: The keys :meth:`ImageError.as_dict` writes into a results row.
ERROR_FIELDS = ("error", "dssim", "silhouette")


def image_error(distance, reference_distance, camera, light_dir) -> ImageError:
    """:class:`ImageError` of a distance image against the reference's.

    distance, reference_distance : (H, W) distances along ``camera``'s rays, inf on a miss
    light_dir : (3,) direction towards the light of the depth shading
    """
    shade = depth_shading(distance, camera, light_dir)
    ref_shade = depth_shading(reference_distance, camera, light_dir)
    return ImageError(1.0 - ssim(shade, ref_shade),
                      silhouette_mismatch(np.isfinite(distance), np.isfinite(reference_distance)))


# ---------------------------------------------------------------------------- criterion
def quality_bound(target_error: float, rel_tol: float = MATCH_REL_TOL, abs_tol: float = MATCH_ABS_TOL) -> float:
    """The error a level must not exceed to match ``target_error``:
    ``target_error·(1 + rel_tol) + abs_tol``."""
    return target_error * (1 + rel_tol) + abs_tol


def matched_level(level_errors: dict, target_error: float, rel_tol: float = MATCH_REL_TOL,
                  abs_tol: float = MATCH_ABS_TOL):
    """The smallest level whose error is at most ``target_error·(1 + rel_tol) + abs_tol``.

    level_errors : {m: error} of the levels measured
    Returns (level, matched): the level and True, or the level of least error and False
    ((None, False) when nothing was measured).
    """
    if not level_errors:
        return None, False
    bound = quality_bound(target_error, rel_tol, abs_tol)
    for m in sorted(level_errors):
        if level_errors[m] <= bound:
            return m, True
    return min(level_errors, key=lambda m: (level_errors[m], m)), False


def pareto_front(ms, errors, min_gain: float = PARETO_MIN_GAIN) -> np.ndarray:
    """(k,) indices of the points no other point beats in both time and error (ascending ms).

    ms, errors : (n,) frame times and errors of the points
    A slower point joins the front only if it lowers the error by more than ``min_gain``
    (below that, errors are rounding noise of the metric, not a quality gain).
    """
    ms = np.asarray(ms, dtype=np.float64)
    errors = np.asarray(errors, dtype=np.float64)
    order = np.lexsort((errors, ms))
    front, best = [], np.inf
    for i in order:
        if errors[i] < best - (min_gain if front else 0.0):
            front.append(int(i))
            best = errors[i]
    return np.asarray(front, dtype=np.int64)
