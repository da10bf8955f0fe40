"""The evaluation window: where in the timing image the float64 reference is rendered.

The reference is too slow for a full 1024x768 frame on a CPU, and a down-scaled view would
hide exactly the facets and relief that the knobs trade away, so the error is measured in a
crop at full angular resolution: a small camera with the timing camera's eye and angle per
pixel, aimed at the part of the image with the most surface and silhouette.
"""

from __future__ import annotations

import math

import numpy as np

from ..geometry.rays.camera import Camera

__all__ = ["eval_camera", "SILHOUETTE_WEIGHT"]

#: Weight of a silhouette pixel against a covered pixel when choosing the window.
SILHOUETTE_WEIGHT = 4.0


def _window_scores(covered: np.ndarray, width: int, height: int) -> np.ndarray:
    """(H - height + 1, W - width + 1) score of each ``width`` x ``height`` window, by its
    top-left pixel: covered pixels plus :data:`SILHOUETTE_WEIGHT` times silhouette pixels.

    covered : (H, W) bool
    """
    edge = np.zeros_like(covered)
    edge[:, 1:] |= covered[:, 1:] ^ covered[:, :-1]
    edge[1:] |= covered[1:] ^ covered[:-1]
    score = covered.astype(np.float64) + SILHOUETTE_WEIGHT * edge
    integral = np.zeros((covered.shape[0] + 1, covered.shape[1] + 1))
    integral[1:, 1:] = score.cumsum(0).cumsum(1)
    return (integral[height:, width:] - integral[:-height, width:] - integral[height:, :-width]
            + integral[:-height, :-width])


def eval_camera(camera: Camera, covered: np.ndarray, eval_size) -> Camera:
    """The evaluation window's camera.

    Parameters
    ----------
    camera : the timing camera
    covered : (camera.height, camera.width) bool, the timing image's hits
    eval_size : (width, height) of the window in pixels (clamped to the camera's)

    Returns an ``eval_size`` camera with ``camera``'s eye, up and angle per pixel, aimed at
    the centre of the window with the most surface plus (4x weighted) silhouette pixels.
    """
    width, height = camera.width, camera.height
    ew, eh = min(int(eval_size[0]), width), min(int(eval_size[1]), height)
    sums = _window_scores(np.asarray(covered, dtype=bool), ew, eh)
    y0, x0 = np.unravel_index(int(np.argmax(sums)), sums.shape)
    cx, cy = x0 + ew / 2, y0 + eh / 2          # window centre, pixel units
    right, up, fwd = camera.basis()
    tan_y = math.tan(math.radians(camera.fov_y) / 2)
    tan_x = tan_y * camera.aspect
    direction = fwd + (cx / width * 2 - 1) * tan_x * right + (1 - cy / height * 2) * tan_y * up
    direction /= np.linalg.norm(direction)
    eye = np.asarray(camera.eye, dtype=np.float64)
    # same angle per pixel at the window's centre: scale the field of view with the height
    fov = math.degrees(2 * math.atan(tan_y * eh / height))
    return Camera(tuple(eye.tolist()), tuple((eye + direction).tolist()), tuple(up.tolist()),
                  fov, ew, eh)
