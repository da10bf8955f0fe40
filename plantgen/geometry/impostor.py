"""Moved to :mod:`plantgen.geometry.meshes.impostor`; this old path stays importable as that module."""

import sys

from .meshes import impostor

sys.modules[__name__] = impostor
