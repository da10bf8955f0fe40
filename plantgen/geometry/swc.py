"""Moved to :mod:`plantgen.geometry.skeletons.swc`; this old path stays importable as that module."""

import sys

from .skeletons import swc

sys.modules[__name__] = swc
