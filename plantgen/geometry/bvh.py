"""Moved to :mod:`plantgen.geometry.rays.bvh`; this old path stays importable as that module."""

import sys

from .rays import bvh

sys.modules[__name__] = bvh
