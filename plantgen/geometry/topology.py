"""Moved to :mod:`plantgen.geometry.skeletons.topology`; this old path stays importable as that module."""

import sys

from .skeletons import topology

sys.modules[__name__] = topology
