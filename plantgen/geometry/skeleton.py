"""Moved to :mod:`plantgen.geometry.skeletons.skeleton`; this old path stays importable as that module."""

import sys

from .skeletons import skeleton

sys.modules[__name__] = skeleton
