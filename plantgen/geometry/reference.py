"""Moved to :mod:`plantgen.geometry.rays.reference`; this old path stays importable as that module."""

import sys

from .rays import reference

sys.modules[__name__] = reference
