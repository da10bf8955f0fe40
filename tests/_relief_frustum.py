"""One relief frustum seen face-on, shared by the tests of GS+N and GS+POM against RC+R
(importable: ``from _relief_frustum import ...``)."""

from __future__ import annotations

import numpy as np

from plantgen.geometry.rays.camera import Camera
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.skin import skin_skeleton

RADIUS, LENGTH = 0.5, 2.0


def relief_frustum(name):
    """A cylinder of ``RADIUS`` and ``LENGTH`` up +y from the origin, of material ``name``."""
    skeleton = Skeleton(np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, LENGTH, 0.0]]), np.array([RADIUS]),
                        np.array([RADIUS]), np.array([-1]), np.array([False]), np.zeros(1, int), (name,))
    return skin_skeleton(skeleton)


def face_on_camera(width, height):
    """Face-on: the eye on the normal through the frustum's middle, far, a narrow view."""
    return Camera((0.0, LENGTH / 2, 8.0), (0.0, LENGTH / 2, 0.0), (0, 1, 0), 18.0, width, height)


def axis_bands(camera, hit):
    """Each pixel's distance from the frustum's axis on screen, over its half width."""
    columns = np.where(hit.any(axis=0))[0]
    centre, half = columns.mean(), (columns.max() - columns.min()) / 2
    return np.abs(np.arange(camera.width) - centre)[None, :] / half * np.ones((camera.height, 1))
