"""Nearest site within a radius, for many points: a uniform grid of cells a radius wide.

Each point looks at the sites of its own cell and its 26 neighbours, so the work is the
pairs closer than about two radii, not points x sites. Ties go to the lowest site index,
and points are handled ``batch`` at a time: the answer does not depend on the batch.
"""

from __future__ import annotations

import numpy as np

__all__ = ["nearest_within"]

#: Cells per axis at most (a key is three 21-bit cell coordinates).
_CELLS = 1 << 20
_OFFSETS = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)], dtype=np.int64)


def nearest_within(points: np.ndarray, sites: np.ndarray, radius: float, batch: int = 65_536):
    """For each of the (n, 3) ``points``, the index of the nearest of the (m, 3) ``sites``
    within ``radius`` (-1 for none) and its distance (inf for none)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    sites = np.asarray(sites, dtype=np.float64).reshape(-1, 3)
    index = np.full(len(points), -1, dtype=np.int64)
    dist = np.full(len(points), np.inf)
    if not len(points) or not len(sites):
        return index, dist
    origin = np.minimum(points.min(axis=0), sites.min(axis=0))
    extent = float((np.maximum(points.max(axis=0), sites.max(axis=0)) - origin).max())
    cell = max(float(radius), extent / (_CELLS - 4), 1e-300)

    def key(c):
        return (c[:, 0] << 42) | (c[:, 1] << 21) | c[:, 2]

    site_cells = np.floor((sites - origin) / cell).astype(np.int64) + 1
    site_keys = key(site_cells)
    order = np.argsort(site_keys, kind="stable")
    sorted_keys = site_keys[order]
    r2 = float(radius) ** 2
    for lo in range(0, len(points), max(1, int(batch))):
        p = points[lo:lo + batch]
        cells = np.floor((p - origin) / cell).astype(np.int64) + 1
        pi_all, sj_all = [], []
        for off in _OFFSETS:
            k = key(cells + off)
            a = np.searchsorted(sorted_keys, k, "left")
            b = np.searchsorted(sorted_keys, k, "right")
            count = b - a
            if not count.any():
                continue
            pi = np.repeat(np.arange(len(p)), count)
            start = np.repeat(a - np.cumsum(count) + count, count)
            sj_all.append(order[start + np.arange(len(pi))])
            pi_all.append(pi)
        if not pi_all:
            continue
        pi, sj = np.concatenate(pi_all), np.concatenate(sj_all)
        d2 = np.sum((p[pi] - sites[sj]) ** 2, axis=1)
        near = d2 <= r2
        pi, sj, d2 = pi[near], sj[near], d2[near]
        if not len(pi):
            continue
        best = np.lexsort((sj, d2, pi))                # per point: nearest, then lowest index
        first = np.ones(len(best), dtype=bool)
        first[1:] = pi[best][1:] != pi[best][:-1]
        chosen = best[first]
        index[lo + pi[chosen]] = sj[chosen]
        dist[lo + pi[chosen]] = np.sqrt(d2[chosen])
    return index, dist
