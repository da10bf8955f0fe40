"""Surface distances of scan points, computed from the frusta's definition (not by the ray
caster): shared by the scan tests (importable: ``from _scan_helpers import ...``)."""

from __future__ import annotations

import numpy as np

from plantgen.geometry.rays.scan import PointCloud


def row_residuals(frusta, rows, points, slack):
    """Distance of each point (m, 3) to the surface of frustum row rows[i]: the lateral
    cone between its two planes, or the disc capping an open end (the frusta's definition;
    ``slack`` lets a point stray that far past a plane or a rim)."""
    c1, a = frusta.base[rows], frusta.axis[rows]
    k = (frusta.r2[rows] - frusta.r1[rows]) / frusta.length[rows]
    rel = points - c1
    y = np.einsum("ij,ij->i", rel, a)
    rho = np.linalg.norm(rel - y[:, None] * a, axis=1)
    r = frusta.r1[rows] + k * y
    s_lo = np.einsum("ij,ij->i", points, frusta.plane_lo[rows, :3]) - frusta.plane_lo[rows, 3]
    s_hi = np.einsum("ij,ij->i", points, frusta.plane_hi[rows, :3]) - frusta.plane_hi[rows, 3]
    lateral = np.where((s_lo >= -slack) & (s_hi <= slack), np.abs(rho - r) / np.sqrt(1 + k * k), np.inf)
    rim = rho <= r + slack
    cap_lo = np.where(frusta.open_lo[rows] & rim, np.abs(s_lo), np.inf)
    cap_hi = np.where(frusta.open_hi[rows] & rim, np.abs(s_hi), np.inf)
    return np.minimum(lateral, np.minimum(cap_lo, cap_hi))


def labelled_residuals(frusta, cloud: PointCloud, slack) -> np.ndarray:
    """(m,) each wood point's distance to the nearest surface of the rows of its labelled
    segment (inf where none is near)."""
    wood = np.flatnonzero(cloud.part != 2)
    rows_of = {}
    for row, seg in enumerate(frusta.segment):
        rows_of.setdefault(int(seg), []).append(row)
    point = np.concatenate([np.full(len(rows_of[int(s)]), i) for i, s in zip(wood, cloud.segment[wood], strict=True)])
    rows = np.concatenate([rows_of[int(s)] for s in cloud.segment[wood]])
    res = row_residuals(frusta, rows, cloud.xyz[point], slack)
    best = np.full(len(cloud), np.inf)
    np.minimum.at(best, point, res)
    return best[wood]


def nearest_residuals(frusta, points, slack) -> np.ndarray:
    """(m,) each point's distance to the nearest surface of any row."""
    m, n = len(points), len(frusta)
    res = row_residuals(frusta, np.tile(np.arange(n), m), np.repeat(points, n, axis=0), slack)
    return res.reshape(m, n).min(axis=1)
