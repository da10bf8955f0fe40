"""TEMPORARY: render/animate.py's skeleton_rows and concatenate_frusta, until the geometry
branch (Skeleton.subset, Frusta.concatenate) merges."""
from __future__ import annotations

import numpy as np

from .frusta import ROW_FIELDS, Frusta
from .skeleton import Skeleton


def skeleton_rows(skeleton: Skeleton, rows) -> Skeleton:
    rows = np.asarray(rows, dtype=np.int64)
    remap = np.full(len(skeleton), -1, dtype=np.int64)
    remap[rows] = np.arange(len(rows))
    parent = skeleton.parent[rows]
    parent = np.where(parent >= 0, remap[np.maximum(parent, 0)], -1)
    return Skeleton(skeleton.start[rows], skeleton.end[rows], skeleton.r_start[rows],
                    skeleton.r_end[rows], parent, skeleton.continues[rows], skeleton.material[rows],
                    skeleton.material_names)


def concatenate_frusta(first: Frusta, second: Frusta) -> Frusta:
    n = len(first)
    parent = np.concatenate([first.parent_row,
                             np.where(second.parent_row >= 0, second.parent_row + n, -1)])
    return Frusta(**{f: np.concatenate([getattr(first, f), getattr(second, f)]) for f in ROW_FIELDS},
                  material_names=first.material_names, parent_row=parent)
