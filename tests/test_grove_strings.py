"""The shipped ``grove`` (25 plants grown together, each asking for light through the CPU
tracer every step) derives, string for string, the plants it derived before issue 44's
speed work: a digest of every plant's derived string (symbols, parameter counts and
parameters, bit for bit) against the one today's code gave before that work began
(computed by this very digest at commit 9d1941a, not by hand)."""

from __future__ import annotations

import hashlib

import numpy as np

import plantgen.pipeline.growing as growing
from plantgen.lsystem.strings import ModuleString

#: sha256 over the 25 strings' digests (:func:`string_digest`), from commit 9d1941a.
GROVE_DIGEST = "4eeea0e5319e4082b008df5b6ce7be0ba91d518f23cc72e07198715cf61a482e"


def string_digest(s) -> str:
    """sha256 of a derived ModuleString: its symbols, modules, parameter counts and the
    parameters it uses (unused columns as 0), float64 bits."""
    h = hashlib.sha256("\x00".join(s.symbols).encode())
    h.update(np.ascontiguousarray(s.sym, np.int32).tobytes())
    h.update(np.ascontiguousarray(s.nparam, np.int8).tobytes())
    used = np.arange(s.params.shape[1])[None, :] < s.nparam[:, None]
    h.update(np.where(used, s.params, 0.0).astype(np.float64).tobytes())
    return h.hexdigest()


def test_the_grove_derives_the_same_strings(monkeypatch):
    seen = []
    grow_together = growing.grow_together

    def spy(*args, **kwargs):
        out = grow_together(*args, **kwargs)
        seen.extend(out)
        return out

    monkeypatch.setattr(growing, "grow_together", spy)
    growing.grow_file("grove")
    assert len(seen) == 25 and all(len(s) > 2000 for s in seen)     # the 25 plants grew, in light
    assert hashlib.sha256("".join(string_digest(s) for s in seen).encode()).hexdigest() == GROVE_DIGEST


def test_the_digest_sees_one_ulp_of_a_parameter_and_ignores_unused_columns():
    """The digest would pass vacuously if it ignored the parameters the light writes."""
    params = np.array([[0.25, 7.0], [0.5, 0.0]])
    s = ModuleString(np.array([0, 1], np.int32), np.array([1, 0], np.int8), params, ("A", "B"))
    before = string_digest(s)
    params[1, 1] = 3.0                                   # a column the module does not use
    assert string_digest(s) == before
    params[0, 0] = np.nextafter(0.25, 1.0)
    assert string_digest(s) != before
