"""Budgets: how much work and memory one input may cost, in one place.

A file may lower a limit, never raise it; the command line may raise it. (The grammar's
``max_modules`` and ``--max-modules`` work this way for the derivation.)
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Limits", "limits"]


@dataclass(frozen=True)
class Limits:
    """max_modules : modules a derivation may reach before it stops with an error
    max_export_triangles : triangles ``plantgen export`` builds at most (about 60 bytes a
        triangle in memory while writing)
    """

    max_modules: int = 5_000_000
    max_export_triangles: int = 100_000_000


#: The limits in force.
limits = Limits()
