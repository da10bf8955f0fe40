"""numba where it imports, for the compiled kernels (the CPU tracer, the stand's leaf
cull, the glTF tangents): ``njit`` and ``prange``, and ``NUMBA_ERROR``, why it does not
import (None where it does). Without numba, ``njit`` leaves a kernel plain Python, which
its module never calls: each module checks ``NUMBA_ERROR`` and computes with numpy instead.
"""

from __future__ import annotations

__all__ = ["NUMBA_ERROR", "njit", "numba", "prange"]

try:                                          # an optional accelerator: numpy computes without it
    import numba
    from numba import njit, prange
    NUMBA_ERROR = None
except Exception as error:                    # noqa: BLE001 - any failure means "no compiler"
    numba, prange, NUMBA_ERROR = None, range, error

    def njit(*args, **kwargs):                # the kernels stay plain Python, never called
        return (lambda f: f) if not args or not callable(args[0]) else args[0]
