"""Skeleton builders shared by geometry tests (importable: ``from _geometry_helpers import ...``)."""

from __future__ import annotations

import numpy as np

from plantgen.geometry.skeletons.skeleton import Skeleton


def chain_skeleton(bends_deg=(), lengths=1.0, radii=0.1, *, start=(0.0, 0.0, 0.0),
                   plane_turn_deg=0.0, material_names=("bark",)) -> Skeleton:
    """One continuing chain going up +y, bending by ``bends_deg[i]`` at joint i.

    ``lengths`` (scalar or (len(bends)+1,)), ``radii`` (scalar or (len(bends)+2,) joint
    radii, root first). Each bend turns in a plane rotated ``plane_turn_deg`` about the
    current axis from the previous one (0: a planar chain bending towards +x).
    """
    bends = np.radians(np.asarray(bends_deg, dtype=float))
    n = len(bends) + 1
    lengths = np.broadcast_to(np.asarray(lengths, dtype=float), (n,))
    radii = np.broadcast_to(np.asarray(radii, dtype=float), (n + 1,))
    d = np.array([0.0, 1.0, 0.0])
    side = np.array([1.0, 0.0, 0.0])
    pts = [np.asarray(start, dtype=float)]
    turn = np.radians(plane_turn_deg)
    for i in range(n):
        pts.append(pts[-1] + lengths[i] * d)
        if i < len(bends):
            side = side * np.cos(turn) + np.cross(d, side) * np.sin(turn)
            d, side = (d * np.cos(bends[i]) + side * np.sin(bends[i]),
                       side * np.cos(bends[i]) - d * np.sin(bends[i]))
    pts = np.array(pts)
    parent = np.arange(-1, n - 1)
    return Skeleton(pts[:-1], pts[1:], radii[:-1], radii[1:], parent, parent >= 0,
                    np.zeros(n, int), material_names)


def y_junction(angle_deg=40.0, *, trunk_radius=0.2, branch_radius=0.12, length=1.0,
               side_branch=True) -> Skeleton:
    """A trunk segment, a continuing segment bending -angle/2 and a branch at +angle."""
    a = np.radians(angle_deg)
    p0 = np.zeros(3)
    p1 = np.array([0.0, length, 0.0])
    cont_dir = np.array([-np.sin(a / 2), np.cos(a / 2), 0.0])
    br_dir = np.array([np.sin(a), np.cos(a), 0.0])
    start = np.array([p0, p1, p1])
    end = np.array([p1, p1 + length * cont_dir, p1 + length * br_dir])
    r_s = np.array([trunk_radius, trunk_radius * 0.9, branch_radius])
    r_e = np.array([trunk_radius * 0.9, trunk_radius * 0.7, branch_radius * 0.6])
    parent = np.array([-1, 0, 0])
    continues = np.array([False, True, not side_branch])
    return Skeleton(start, end, r_s, r_e, parent, continues, np.zeros(3, int))


def random_tree(n: int, seed: int = 0, *, branch_prob=0.15, max_bend_deg=35.0) -> Skeleton:
    """A random tree of ``n`` segments: chains that bend up to ``max_bend_deg`` and side
    branches with probability ``branch_prob``; radii taper towards the tips."""
    rng = np.random.default_rng(seed)
    start = np.zeros((n, 3))
    end = np.zeros((n, 3))
    r_s = np.zeros(n)
    r_e = np.zeros(n)
    parent = np.full(n, -1)
    cont = np.zeros(n, bool)
    has_cont = np.zeros(n, bool)
    dirs = np.zeros((n, 3))
    for i in range(n):
        if i == 0:
            d = np.array([0.0, 1.0, 0.0])
            s = np.zeros(3)
            r0 = 0.3
        else:
            p = int(rng.integers(max(0, i - 8), i))
            side = rng.random() < branch_prob or has_cont[p]
            axis = rng.normal(size=3)
            axis -= axis @ dirs[p] * dirs[p]
            axis /= np.linalg.norm(axis)
            ang = np.radians(rng.uniform(20, 60) if side else rng.uniform(0, max_bend_deg))
            d = dirs[p] * np.cos(ang) + axis * np.sin(ang)
            s = end[p]
            r0 = r_e[p] * (0.6 if side else 1.0)
            parent[i] = p
            cont[i] = not side
            has_cont[p] |= not side
        dirs[i] = d
        length = rng.uniform(0.3, 1.0)
        start[i], end[i] = s, s + length * d
        r_s[i] = r0
        r_s[i] = max(r_s[i], 0.01)
        r_e[i] = max(r_s[i] * rng.uniform(0.9, 1.0), 0.01)
    return Skeleton(start, end, r_s, r_e, parent, cont, np.zeros(n, int))
