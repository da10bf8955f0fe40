"""A derived module string, held as arrays (what the derivation writes and the turtle reads)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ModuleString", "module_bytes"]


@dataclass(frozen=True, eq=False)
class ModuleString:
    """A derived string of ``n`` modules.

    sym : (n,) int32, index into ``symbols``
    nparam : (n,) int8, parameter count of each module
    params : (n, P) float64, parameters (columns past ``nparam`` are unused)
    fixed_point : the step after which the derivation stopped changing the string (the
        next step rewrote it into itself, drawing no random number), when it ran past it;
        else None
    globals : the grammar's global variables as the derivation left them (None: it has none)
    """

    sym: np.ndarray
    nparam: np.ndarray
    params: np.ndarray
    symbols: tuple[str, ...]
    fixed_point: int | None = None
    globals: dict | None = None

    def __len__(self) -> int:
        return len(self.sym)

    def to_text(self, limit: int = 10_000, digits: int = 4) -> str:
        """ABOP text of the first ``limit`` modules, for debugging and tests."""
        out = []
        for s, k, row in zip(self.sym[:limit].tolist(), self.nparam[:limit].tolist(),
                             self.params[:limit].tolist(), strict=True):
            name = self.symbols[s]
            if k:
                out.append(name + "(" + ",".join(f"{x:.{digits}g}" for x in row[:k]) + ")")
            else:
                out.append(name)
        return "".join(out)


def module_bytes(width: int) -> int:
    """Bytes one module of a string takes with ``width`` parameter columns."""
    return 4 + 1 + 8 * width
