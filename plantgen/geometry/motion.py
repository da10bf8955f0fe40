"""Moved to :mod:`plantgen.geometry.skeletons.motion`; this old path stays importable as that module."""

import sys

from .skeletons import motion

sys.modules[__name__] = motion
