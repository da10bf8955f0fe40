"""Live reload: the work of the reload thread (:func:`grow_model`)."""

from __future__ import annotations

import time

from .options import ViewOptions

__all__ = ["grow_model"]


def grow_model(options: ViewOptions, t: float, saved_ns: int | None, step: int | None = None):
    """The reload's work (background thread): grow (a grammar ``step`` derivation steps
    deep when given), skin at ``t``; returns (model, frusta, seconds of each stage).
    ``saved_ns`` is the save's time for a reload, None for a growth step."""
    t0 = time.perf_counter()
    model = options.prepare(step)
    frusta = model.frusta_at(t)
    total = time.perf_counter() - t0
    grow = sum(model.grown.timings.values())      # read, parse, derive, interpret (place)
    return model, frusta, {"grow": grow, "skin": max(total - grow, 0.0)}
