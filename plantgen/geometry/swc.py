"""Reading SWC skeletons (the writer is :meth:`Skeleton.save_swc`), as untrusted input.

An SWC file lists nodes, one a line: ``id type x y z radius parent`` (``parent`` -1 for a
root, else the id of a node listed before it); ``#`` starts a comment. Every edge from a
node to its parent becomes a segment from the parent's point to the node's, with the two
radii. A node that lies where its parent lies (the start node plantgen writes for a root
or a side branch) carries the branch's start radius; the segments that leave it are side
branches of the segment ending at its parent. Of the segments that leave a segment's end
node, the first carries on its axis (``continues``) and the others are side branches.

Every failure is one line naming the file and, where there is one, the line: not a
regular file or over ``max_skeleton_bytes``, a malformed or non-finite value, an id used
twice, a parent not listed before its child, over ``max_segments`` segments; the result
is checked by :meth:`Skeleton.validate`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..files import read_input
from ..limits import Limits
from ..limits import limits as default_limits
from ..tolerances import tol
from .skeleton import Skeleton, SkeletonError

__all__ = ["read_swc"]


def read_swc(path: str | Path, limits: Limits | None = None) -> Skeleton:
    """The skeleton an SWC file describes (see the module docstring)."""
    limits = limits or default_limits
    data = read_input(path, SkeletonError, max_bytes=limits.max_skeleton_bytes, limit="skeleton_bytes",
                      what="SWC")
    try:
        text = data.decode("ascii")
    except UnicodeDecodeError as exc:
        raise SkeletonError(f"{path}: not an SWC file (a non-ASCII byte at offset {exc.start})") from None
    nodes = _parse_nodes(text, path, limits)
    if not nodes:
        raise SkeletonError(f"{path}: an SWC file without nodes")
    skel = _segments(nodes)
    try:
        skel.validate()
    except SkeletonError as exc:
        raise SkeletonError(f"{path}: {exc}") from None
    return skel


def _parse_nodes(text: str, path, limits: Limits) -> list[tuple]:
    """[(x, y, z, radius, parent row or -1)] in file order, ids checked."""
    rows: dict[int, int] = {}     # id -> row
    nodes = []
    for number, line in enumerate(text.splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        where = f"{path}: line {number}"
        parts = line.split()
        if len(parts) != 7:
            raise SkeletonError(f"{where}: an SWC node needs 7 values (id type x y z radius parent), "
                                f"got {len(parts)}")
        try:
            node_id, _, parent = int(parts[0]), int(parts[1]), int(parts[6])
            x, y, z, r = (float(v) for v in parts[2:6])
        except ValueError:
            raise SkeletonError(f"{where}: not an SWC node (id, type and parent are integers, "
                                "x y z radius numbers)") from None
        if not all(abs(v) <= tol.max_coordinate for v in (x, y, z, r)) or r < 0:
            raise SkeletonError(f"{where}: a coordinate or radius that is not finite, negative or "
                                f"beyond {tol.max_coordinate:g}")
        if node_id < 1 or node_id in rows:
            raise SkeletonError(f"{where}: node id {node_id} is not positive or is used twice")
        if parent != -1 and parent not in rows:
            raise SkeletonError(f"{where}: parent {parent} is not a node listed before this one")
        rows[node_id] = len(nodes)
        nodes.append((x, y, z, r, rows[parent] if parent != -1 else -1))
        limits.check("segments", len(nodes) - 1, f"{path}: SWC segments")
    return nodes


def _segments(nodes: list[tuple]) -> Skeleton:
    """One segment per edge from a node to its parent, but for the edges to start nodes
    (see the module docstring)."""
    points = np.array([n[:3] for n in nodes], dtype=np.float64)
    radius = np.array([n[3] for n in nodes], dtype=np.float64)
    parent_node = [n[4] for n in nodes]
    starts_branch = [False] * len(nodes)   # a root node, or the start node of a side branch
    ends_segment: dict[int, int] = {}      # node row -> the segment ending there
    carried_on: set[int] = set()           # segments a child already continues
    cols = {k: [] for k in ("start", "end", "r_start", "r_end", "parent", "continues")}
    for row, p in enumerate(parent_node):
        if p < 0 or (not starts_branch[p] and np.array_equal(points[row], points[p])):
            starts_branch[row] = True
            continue
        if starts_branch[p]:     # the first segment of a root or a side branch
            seg_parent = ends_segment.get(parent_node[p], -1)
            continues = False
        else:
            seg_parent = ends_segment[p]
            continues = seg_parent not in carried_on
            carried_on.add(seg_parent)
        ends_segment[row] = len(cols["end"])
        for key, value in (("start", points[p]), ("end", points[row]), ("r_start", radius[p]),
                           ("r_end", radius[row]), ("parent", seg_parent), ("continues", continues)):
            cols[key].append(value)
    n = len(cols["end"])
    return Skeleton(np.reshape(cols["start"], (n, 3)), np.reshape(cols["end"], (n, 3)),
                    np.array(cols["r_start"]), np.array(cols["r_end"]), np.array(cols["parent"], dtype=np.int64),
                    np.array(cols["continues"], dtype=bool), np.zeros(n, dtype=np.int32), ("bark",))
