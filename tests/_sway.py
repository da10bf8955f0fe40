"""plantgen's own pose of a swaying plant copy, tessellated as the export tessellates the
plant: the reference the exported animations (glTF skins in three.js, UsdSkel in
usd-core) are compared with.

The pose is :func:`plantgen.geometry.skeletons.motion.pose` of the copy (its sway in the plant's
own frame: the scene's axis turned back by the copy's rotation), skinned again (the
joints' cutting planes and seam radii of the new pose) and tessellated at the export's
level. One thing is carried over from the rest instead of being worked out again: each
row's texture frame (``ref_dir``, ``u_offset``), turned with its segment. Re-skinning
transports the frames along the posed chains, which turns them about the axes by up to
a few degrees (the dancing cacti: 3° in the arms): the same surface, its vertices slid
around it. A skin carries the frames rigidly, so the vertex-by-vertex comparison is
made with the frames carried rigidly too (:func:`texture_swim` measures the slide).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from plantgen.geometry.meshes.mesh import TessellatedMesh, tessellate
from plantgen.geometry.meshes.polygons import Polygons
from plantgen.geometry.skeletons.motion import pose, sway_rig, turn_at, turn_coefficients
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.geometry.vec import rotate


def local_rig(skeleton: Skeleton, sway, matrix=None, groups=None):
    """The sway rig of one copy in the plant's own frame (``matrix`` places the copy):
    ``sway`` a :class:`Sway` (or None), or with ``groups`` (each segment's) one per group
    (a scene written in place: one per instance)."""
    if groups is None:
        groups, sway = np.zeros(len(skeleton), np.int64), [sway]
    rig = sway_rig(skeleton, groups, list(sway))
    if matrix is None:
        return rig
    turn = np.asarray(matrix, dtype=np.float64)[:3, :3]
    turn = turn / np.cbrt(np.linalg.det(turn))
    return dataclasses.replace(rig, axis=rig.axis @ turn)


def posed(skeleton: Skeleton, sway, t: float, level: int, matrix=None, leaves: Polygons | None = None,
          carried: bool = True, groups=None) -> tuple[TessellatedMesh, np.ndarray | None]:
    """(mesh, leaf vertices) of the copy posed at ``t`` in the plant's own frame: the
    re-skinned pose tessellated at ``level`` (``carried``: with the rest's texture frames
    turned with their segments, see the module docstring) and the leaves turned with the
    segments they hang from, as :meth:`plantgen.animation.AnimatedScene.leaves_at` turns
    them. ``sway`` and ``groups``: see :func:`local_rig`."""
    rig = local_rig(skeleton, sway, matrix, groups)
    turns = turn_at(rig, turn_coefficients(skeleton, rig), t)
    moved = pose(skeleton, rig, t)
    frusta = skin_skeleton(moved)
    if carried:
        rest = skin_skeleton(skeleton)
        assert len(rest) == len(frusta), "the pose changed the rows (a knuckle came or went)"
        ref = rotate(rest.ref_dir, rig.axis[rest.segment], turns[rest.segment])
        ref = ref - frusta.axis * np.einsum("ij,ij->i", ref, frusta.axis)[:, None]
        ref /= np.linalg.norm(ref, axis=1, keepdims=True)
        frusta = dataclasses.replace(frusta, ref_dir=ref, u_offset=rest.u_offset)
    mesh = tessellate(frusta, level)
    if leaves is None or not len(leaves.triangles):
        return mesh, None
    seg = leaves.segment[leaves.vertex_polygon]
    hung = seg >= 0
    out = leaves.vertices.copy()
    s = seg[hung]
    out[hung] = moved.start[s] + rotate(leaves.vertices[hung] - skeleton.start[s], rig.axis[s], turns[s])
    return mesh, out


def placed(points: np.ndarray, matrix) -> np.ndarray:
    """(v, 3) ``points`` placed by ``matrix`` (4, 4; None: where they are)."""
    if matrix is None:
        return points
    m = np.asarray(matrix, dtype=np.float64)
    return points @ m[:3, :3].T + m[:3, 3]


def copy_height(skeleton: Skeleton, matrix=None) -> float:
    """The height of the copy: its skeleton's, scaled by its placement."""
    scale = 1.0 if matrix is None else float(np.cbrt(np.linalg.det(np.asarray(matrix)[:3, :3])))
    return float(skeleton.height) * scale


def texture_swim(skeleton: Skeleton, sway, times, level: int) -> float:
    """The largest distance between a vertex of the re-skinned pose with the frames
    re-transported (plantgen's animation) and with them carried rigidly: how far the
    texture slides around the axes."""
    worst = 0.0
    for t in times:
        a, _ = posed(skeleton, sway, t, level, carried=False)
        b, _ = posed(skeleton, sway, t, level, carried=True)
        worst = max(worst, float(np.linalg.norm(a.vertices - b.vertices, axis=1).max()))
    return worst
