"""Budgets: how much work and memory one input may cost, in one place.

A grammar or scene is untrusted input: people share them, and ``plantgen batch`` runs
thousands. Every budget such a file could exhaust is a field of :class:`Limits`, with its
default; the code reads the one in force (``limits`` by default, or the object a caller
passes down) and a budget overrun is a :class:`LimitError`, one line that names the limit
and how to raise it.

A file may lower a limit, never raise it (:meth:`Limits.lowered`: a grammar's
``max_modules``); the command line may raise it (``--limit NAME=N``, ``--max-modules``:
:meth:`Limits.raised`). The defaults keep one input under about 1 GB and a few tens of
seconds on a small machine, and far above what the shipped models need (the largest,
the oasis scene, derives 114,217 modules into 18,578 segments).
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

from .errors import PlantgenError

__all__ = ["CONTEXT_WORK", "GAME_LEVEL_TRIANGLES", "LimitError", "Limits", "MAX_IMAGE_SIDE", "Meter", "QUERY_WORK",
           "SEQUENTIAL_WORK", "STEP_WORK", "hint", "limits"]

#: The largest image side (pixels) plantgen renders: the GL texture size every OpenGL 4.3
#: driver plantgen has met supports. A hard bound, not a budget: no option raises it.
MAX_IMAGE_SIDE = 16384
#: ``--asset game``'s triangle budget per level of detail of one plant (level 0 first; the
#: impostor's card is two): a warning names a level over it.
GAME_LEVEL_TRIANGLES = (80_000, 40_000, 20_000, 10_000)

#: The fixed cost of one derivation step, counted in modules (per rule group, plus one):
#: a step over a tiny string costs about as much as rewriting this many modules, so a
#: derivation that does not grow still spends its ``derive_work`` budget.
STEP_WORK = 200

#: A derivation whose steps alone would spend more than its ``derive_work`` budget (its
#: iterations times ``STEP_WORK`` per rule group, the least a step costs, known before the
#: first step) can end within the budget only by settling: reaching a fixed point or a
#: cycle, whose remaining steps are skipped. It is given this many steps to settle, then
#: refused with the estimate (a tenth of a second or so: a step of a short string costs
#: about 100 µs), instead of spending the whole budget first (16 s for a counter
#: ``A(x) -> A(x+1)`` asked for a million iterations).
SETTLE_STEPS = 2_000

#: How much more than rewriting a step of a context-sensitive grammar costs per module:
#: finding each module's context neighbours sorts and searches the string's bracket
#: depths, a few times the rewriting's cost, so such a step counts its modules four times.
CONTEXT_WORK = 4

#: How much the query pass of a grammar with query or communication modules (``?P``,
#: ``?E``) costs per module of the string, counted against ``derive_work`` before each
#: step's turtle walk: the walk interprets every module in Python, about 40 times what
#: rewriting one costs (a drawing module; a few times for the others). Without it a
#: string of half a million modules walked a hundred times spent 65 s of CPU before its
#: rewriting alone reached the budget.
QUERY_WORK = 40

#: How much a step of a grammar with a new left context (``<<``) costs per module, and
#: again per rule group tried on it: such a step is sequential, a module at a time in
#: Python, and one rule group tried on one module (its match, condition and successor
#: evaluated for that module alone) costs about what vectorised rewriting spends on
#: hundreds of modules.
SEQUENTIAL_WORK = 400


class LimitError(PlantgenError):
    """An input that would exceed a budget of :class:`Limits`; the message names it."""


@dataclass(frozen=True)
class Limits:
    """The budgets of one input (a grammar, a scene, a skeleton file). Every field is a
    count or a size in bytes; ``--limit NAME=N`` sets ``max_NAME``.

    max_input_bytes : size of a YAML or camera JSON input file (the largest shipped one
        has 3 KiB; a grammar's parse and first step cost about 10 µs a byte at worst)
    max_skeleton_bytes : size of a skeleton input file (.npz, .swc) and of the arrays an
        .npz unpacks to
    max_yaml_nodes : nodes of a YAML document after its aliases are expanded, each scalar
        counting one more per character (an alias "bomb" is refused before it is built)
    max_yaml_depth : nesting depth of a YAML document (aliases expanded)
    max_params : parameters of one module in a grammar (at most 127)
    max_iterations : derivation steps a grammar or the command line may ask for
    max_modules : modules a derivation may reach (a grammar's ``max_modules`` lowers it)
    max_derive_bytes : bytes of a derived module string (modules × (5 + 8 × parameters))
    max_derive_work : modules rewritten over all steps of all derivations of one input;
        each step also counts ``STEP_WORK`` per rule group (a derivation that does not
        grow still ends), a context-sensitive one counts its modules ``CONTEXT_WORK``
        times, and the query pass of one with query modules each module it walks
        ``QUERY_WORK`` times
    max_segments : segments of one input's skeleton; for a scene, the segments grown (each
        distinct plant once, an explicit skeleton per copy)
    max_drawn_segments : segments a scene places (every copy's: what a merged skeleton, a
        ``plantgen grow`` output or a full-detail render holds)
    max_instances : placed plants of a scene (grid copies included)
    max_polygon_vertices : polygon vertices of one plant: its ``.`` and the vertices of
        the surfaces its ``~`` place (each leaf 26, each needle tuft 56), counted before
        the turtle walks
    max_export_triangles : triangles ``plantgen export`` builds at most
    max_export_bytes : memory an export may take while tessellating and writing
        (estimated from the triangle count before anything is built)
    max_render_bytes : memory a render may take (images, frames, depth, shadow map and
        skinned frusta, estimated before anything is allocated)
    max_scan_rays : rays a simulated laser scan may fire (every scanner's beams, times the
        sub-rays of a diverging beam), counted before any is cast
    max_scan_bytes : memory a laser scan may take: the skin of the segments it skins
        (estimated before anything is skinned), and the points it returns (estimated
        from a sample of its beams before any is traced, then counted as they are kept)
    max_queries : query and communication modules (``?P``, ``?E``) one derivation answers,
        summed over its steps (each step that has any walks the turtle over the string)
    max_markers : attraction points of a grammar's ``markers`` environment
    max_light_rays : rays the ``light`` environment traces in one derivation step
    """

    max_input_bytes: int = 256 << 10
    max_skeleton_bytes: int = 256 << 20
    max_yaml_nodes: int = 2_000_000
    max_yaml_depth: int = 64
    max_params: int = 32
    max_iterations: int = 1_000_000
    max_modules: int = 5_000_000
    max_derive_bytes: int = 128 << 20
    max_derive_work: int = 50_000_000
    max_segments: int = 1_000_000
    max_drawn_segments: int = 20_000_000
    max_instances: int = 10_000
    max_polygon_vertices: int = 4_000_000
    max_export_triangles: int = 100_000_000
    max_export_bytes: int = 2 << 30
    max_render_bytes: int = 2 << 30
    max_scan_rays: int = 200_000_000
    max_scan_bytes: int = 2 << 30
    max_queries: int = 20_000_000
    max_markers: int = 1_000_000
    max_light_rays: int = 50_000_000

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise LimitError(f"limit {f.name[4:]} must be a positive integer, got {value!r}")
        if self.max_params > 127:
            raise LimitError(f"limit params must be at most 127, got {self.max_params}")

    @staticmethod
    def names() -> tuple[str, ...]:
        """The names ``--limit NAME=N`` takes: the fields without ``max_``."""
        return tuple(f.name[4:] for f in fields(Limits))

    def raised(self, **values) -> Limits:
        """These limits with ``values`` (name without ``max_`` -> int; None: unchanged) in
        place, higher or lower: what the command line may do."""
        unknown = set(values) - set(self.names())
        if unknown:
            raise LimitError(f"unknown limit(s) {sorted(unknown)} (known: {', '.join(self.names())})")
        return replace(self, **{f"max_{k}": v for k, v in values.items() if v is not None})

    def lowered(self, **values) -> Limits:
        """These limits lowered to ``values`` where they are lower: what a file may do
        (a value above the limit in force leaves it as it is)."""
        current = {k: getattr(self, f"max_{k}") for k in values}
        return self.raised(**{k: min(v, current[k]) for k, v in values.items() if v is not None})

    def check(self, name: str, value: int, what: str) -> int:
        """``value`` if it is within the limit ``name``; else a :class:`LimitError`
        ``"WHAT: VALUE over the limit NAME = LIMIT (raise it with --limit NAME=N)"``."""
        limit = getattr(self, f"max_{name}")
        if value > limit:
            raise LimitError(f"{what}: {value:,} over the limit of {limit:,} ({hint(name)})")
        return value

    def meter(self, name: str) -> Meter:
        """A running total against the limit ``name`` (:class:`Meter`)."""
        return Meter(name, getattr(self, f"max_{name}"))


def hint(name: str) -> str:
    """How a message says which option raises the limit ``name``."""
    return f"limit {name}; raise it with --limit {name}=N"


class Meter:
    """A budget spent in steps: :meth:`spend` adds to the total and raises
    :class:`LimitError` when it passes the limit. One meter can be shared by every
    derivation of a scene."""

    def __init__(self, name: str, limit: int) -> None:
        self.name, self.limit, self.spent = name, int(limit), 0

    def spend(self, amount: int, what: str) -> None:
        self.spent += int(amount)
        if self.spent > self.limit:
            raise LimitError(f"{what}: {self.name} reaches {self.spent:,}, over the limit of "
                             f"{self.limit:,} ({hint(self.name)})")


#: The limits in force when a caller passes none.
limits = Limits()
