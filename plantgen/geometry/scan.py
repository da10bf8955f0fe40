"""Moved to :mod:`plantgen.geometry.rays.scan`; this old path stays importable as that module."""

import sys

from .rays import scan

sys.modules[__name__] = scan
