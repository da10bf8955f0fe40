"""What the viewer starts from and counts with: the options of ``plantgen view``
(:class:`ViewOptions`), the methods the keys choose, the viewer's limits, a drawn frame's
times (:class:`FrameStats`), an error as one line, and the reload's work
(:func:`grow_model`); no GL and no state."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from ..errors import PlantgenError
from ..geometry.meshes.mesh import triangle_count
from ..geometry.rays.instances import PlacedPlants
from ..limits import Limits
from ..pipeline import PreparedModel, prepare_model
from ..settings import DEFAULT_SIZE, MeshSettings, RenderSettings

__all__ = ["METHODS", "VIEW_MAX_TRIANGLES", "DRAG_TURN", "HUD_FRAMES", "ViewOptions", "FrameStats", "one_line",
           "stored_triangles", "grow_model"]


def stored_triangles(frusta, level: int) -> int:
    """Triangles the GS mesh of ``frusta`` holds at ``level``: a placed scene's distinct
    plants once each (its copies share them)."""
    parts = [p.frusta for p in frusta.plants] if isinstance(frusta, PlacedPlants) else [frusta]
    return sum(triangle_count(len(f), level, int(f.open_lo.sum() + f.open_hi.sum())) for f in parts)

#: The methods of Table 1, as the keys 1..4 choose them.
METHODS = ("RC", "RC+R", "GS", "GS+R", "RT", "RT+R")

#: The most triangles a GS level may have in the viewer (the level is refused above).
VIEW_MAX_TRIANGLES = 24_000_000

#: Degrees the view turns per pixel of a left drag.
DRAG_TURN = 0.4

#: How many frames the heads-up line's medians look back.
HUD_FRAMES = 30



def one_line(exc: BaseException) -> str:
    """An exception as the viewer shows it: a PlantgenError's message, else its class and
    message, on one line."""
    text = " ".join(str(exc).split()) or exc.__class__.__name__
    if not isinstance(exc, PlantgenError):
        text = f"unexpected failure: {exc.__class__.__name__}: {text}"
    return text[:300]


@dataclass
class ViewOptions:
    """How ``plantgen view`` was asked to start (its options; see ``plantgen view --help``):
    the render settings whole (:class:`~plantgen.settings.RenderSettings`), the window's
    ``size``, and what only the viewer has (the method, the GS level, shots, watching)."""

    input: Path
    settings: RenderSettings = RenderSettings()
    size: tuple = DEFAULT_SIZE
    seed: int | None = None
    iterations: int | None = None
    method: str | None = None
    level: int = MeshSettings().level
    shots: Path = Path(".")
    watch: bool = True
    poll_s: float = 0.025
    snapshot: Path | None = None
    limits: Limits | None = None
    allow_paths: tuple = ()
    smooth_bends: float | None = None

    def prepare(self, iterations: int | None = None) -> PreparedModel:
        """Grow the input with these options (the first model, and each reload); a grammar
        ``iterations`` steps deep when given (a growth step), else as the options say. A
        scene's plants grow in this process (``jobs=1``): a process with a window, its GL
        context and their threads is not forked into a pool."""
        iterations = self.iterations if iterations is None else iterations
        return prepare_model(self.input, effects=self.settings.effects, seed=self.seed, iterations=iterations,
                             limits=self.limits, allow_paths=self.allow_paths, smooth_bends=self.smooth_bends,
                             jobs=1)


@dataclass
class FrameStats:
    """One drawn frame: the renderer's frame ms (draw to finish) and the wall ms of the
    whole frame (skin or pose, draw, read-back), when it was drawn."""

    frame_ms: float
    wall_ms: float
    at: float


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
