"""Branches of a skeleton: which segments form one axis, their order and their place.

A *branch* is a maximal chain of segments joined by ``continues``: it starts at a root or
at a side branch (``continues`` False) and carries on through each segment's continuing
child. Branches are numbered in the order of their first segment, so branch 0 is the
chain of segment 0 (a plant's trunk, its main axis); as parents precede children, a
branch's parent branch always has a smaller number.

- **branch order**: 0 for a branch that starts at a root (the trunk, and every further
  root of a scene or of a grammar's ``f`` moves), one more than its parent branch's for a
  side branch (the convention of TreeQSM, rTwig and SimpleForest: the trunk is order 0,
  the branches on it order 1, ...);
- **position in branch**: the segment's place along its branch, 0 for its first segment.

A segment continued by more than one segment (the format allows it, plantgen's turtle
never makes it) has its first continuing child (in index order) on its branch; the others
start branches of their own, one order higher, like side branches.

Pure numpy (tree walks by pointer jumping, :mod:`plantgen.geometry.vec`); no GL, no click.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..vec import ancestor_count, tree_roots
from .skeleton import Skeleton

__all__ = ["Branches", "branches", "carried_on"]


def carried_on(parent: np.ndarray, continues: np.ndarray) -> np.ndarray:
    """(n,) bool: the segment carries on its parent's branch: it continues its parent and
    is the first segment (in index order) to do so."""
    parent = np.asarray(parent, dtype=np.int64)
    cont = np.flatnonzero(np.asarray(continues, dtype=bool) & (parent >= 0))
    first = np.zeros(len(parent), dtype=bool)
    # np.unique returns the first index of each parent among the continuing segments.
    _, at = np.unique(parent[cont], return_index=True)
    first[cont[at]] = True
    return first


@dataclass(frozen=True, eq=False)
class Branches:
    """The branch structure of a skeleton of ``n`` segments in ``b`` branches.

    ==================  ============  ====================================================
    ``branch``          (n,) i8       branch of each segment, 0..b-1
    ``position``        (n,) i8       place of the segment along its branch, from 0
    ``order``           (b,) i8       branch order (0: starts at a root)
    ``parent``          (b,) i8       parent branch, -1 for a branch starting at a root
    ``first``           (b,) i8       first segment of each branch
    ``next``            (n,) i8       the segment that carries the branch on, -1 at its tip
    ==================  ============  ====================================================
    """

    branch: np.ndarray
    position: np.ndarray
    order: np.ndarray
    parent: np.ndarray
    first: np.ndarray
    next: np.ndarray

    def __len__(self) -> int:
        return len(self.order)

    @property
    def segment_order(self) -> np.ndarray:
        """(n,) branch order of each segment."""
        return self.order[self.branch]

    def chains(self) -> list[np.ndarray]:
        """The segments of each branch, base to tip: one (k,) int array per branch."""
        sort = np.lexsort((self.position, self.branch))
        counts = np.bincount(self.branch, minlength=len(self))
        return np.split(sort, np.cumsum(counts)[:-1])


def branches(skeleton: Skeleton) -> Branches:
    """The :class:`Branches` of ``skeleton`` (see the module docstring)."""
    n = len(skeleton)
    parent = skeleton.parent
    on_branch = carried_on(parent, skeleton.continues)
    chain_parent = np.where(on_branch, parent, -1)
    position = ancestor_count(chain_parent)
    first_segment = tree_roots(chain_parent)
    first = np.flatnonzero(chain_parent < 0)                 # increasing: branch numbering
    number = np.full(n, -1, dtype=np.int64)
    number[first] = np.arange(len(first))
    branch = number[first_segment] if n else np.zeros(0, dtype=np.int64)
    base_parent = parent[first]
    branch_parent = np.where(base_parent >= 0, branch[np.maximum(base_parent, 0)], -1) if n else first
    order = ancestor_count(branch_parent)
    following = np.full(n, -1, dtype=np.int64)
    carried = np.flatnonzero(on_branch)
    following[parent[carried]] = carried
    return Branches(branch, position, order, branch_parent.astype(np.int64), first.astype(np.int64),
                    following)
