"""Morton codes for the BVH's linear build (:func:`~plantgen.geometry.rays.bvh.build_bvh`,
``method="lbvh"``): points quantised to 21 bits an axis over their bounding cube, the bits
interleaved into one 63-bit key, so that sorting the keys lays the points along a
Z-order curve; and the highest set bit of a key, which finds where two keys' prefixes
part (the split between two runs of sorted keys).

Pure numpy, exact in uint64.
"""

from __future__ import annotations

import numpy as np

__all__ = ["highest_bit", "morton_codes", "spread21"]


def spread21(x):
    """uint64 values (an array, or one value) of 21 bits spread out to every third bit;
    plain operators only, so the compiled LBVH build compiles this same function
    (:mod:`plantgen.geometry.rays.native_build`)."""
    x = x & np.uint64(0x1FFFFF)
    x = (x | (x << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
    x = (x | (x << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
    x = (x | (x << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
    x = (x | (x << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
    x = (x | (x << np.uint64(2))) & np.uint64(0x1249249249249249)
    return x


def morton_codes(points: np.ndarray) -> np.ndarray:
    """(n,) uint64 63-bit Morton codes of points (n, 3): 21 bits an axis over the points'
    bounding cube (x in the highest of each three bits)."""
    points = np.asarray(points, dtype=np.float64)
    if not len(points):
        return np.zeros(0, np.uint64)
    lo = points.min(axis=0)
    extent = float((points.max(axis=0) - lo).max())
    q = np.clip((points - lo) / (extent if extent > 0 else np.inf) * (2 ** 21 - 1), 0, 2 ** 21 - 1)
    q = q.astype(np.uint64)
    return (spread21(q[:, 0]) << np.uint64(2)) | (spread21(q[:, 1]) << np.uint64(1)) | spread21(q[:, 2])


def highest_bit(x: np.ndarray) -> np.ndarray:
    """The highest set bit of each uint64 (0 for 0), exactly."""
    for s in (1, 2, 4, 8, 16, 32):
        x = x | (x >> np.uint64(s))
    return x ^ (x >> np.uint64(1))
