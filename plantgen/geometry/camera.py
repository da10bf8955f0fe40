"""Moved to :mod:`plantgen.geometry.rays.camera`; this old path stays importable as that module."""

import sys

from .rays import camera

sys.modules[__name__] = camera
