"""Moved to :mod:`plantgen.geometry.meshes.leaf_cards`; this old path stays importable as that module."""

import sys

from .meshes import leaf_cards

sys.modules[__name__] = leaf_cards
