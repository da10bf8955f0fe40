"""Time passes in the viewer: an animation plays, the watched files are polled, a
finished reload (or growth step) is taken in, and its time from the save to the frame is
told once the frame is shown (functions over a :class:`~plantgen.viewer.state.ViewerState`;
the reload's own work, on its thread, is :func:`~plantgen.viewer.options.grow_model`)."""

from __future__ import annotations

import time

from . import growth
from .options import one_line
from .state import ViewerState

__all__ = ["tick", "presented"]


def tick(state: ViewerState, dt: float, now: float | None = None) -> bool:
    """Advance the clock by ``dt`` seconds: play an animation, poll the watched files
    and take a finished reload in. Returns True when the frame must be drawn again."""
    if state.playing and state.model.animated:
        state.t += dt
        state.dirty = True
    if state.options.watch:
        change = state.watcher.poll(now)
        if change is not None:
            state.reloader.start(state.t, change.saved_ns, state.step_target)   # at the step shown
            state.status = "reloading ..."
    done = state.reloader.result()
    if done is not None:
        _take_reload(state, *done)
    growth.advance(state, dt)
    return state.dirty


def _take_reload(state: ViewerState, args, value, exc) -> None:
    """A finished reload or growth step (:meth:`BackgroundJob.result
    <plantgen.viewer.watch.BackgroundJob.result>`): its model shown, or its error, the
    last good model kept."""
    t, saved_ns, step = args
    if exc is not None:
        state.error = one_line(exc) if saved_ns is not None else f"step {step}: {one_line(exc)}"
        state.status = ""
        state.warn(f"plantgen view: error: {state.error} (keeping the last good model)")
        if saved_ns is None and not state.growing:     # a step that cannot be drawn: stay at the one shown
            state.step_target = state.step
        return
    model, frusta, timings = value
    state.model, state.error = model, None
    state.frusta_cache, state.frusta_key = frusta, (model, t if model.animated else 0.0)
    state.mesh_key = None
    state.watcher.watch(model.grown.sources)
    state.grow_clock = 0.0
    if model.grown.iterations is None:              # no longer a grammar
        state.step_target, state.steps_end, state.growing = None, None, False
    elif step is None:
        state.steps_end = model.grown.iterations
    if saved_ns is None:
        state.status = f"step {state.step} of {state.steps_end}: {model.grown.segments:,} segments"
        state.say(f"{model.grown.name}: {state.status}")
    else:
        waited = max(0.0, (time.time_ns() - saved_ns) / 1e9 - timings["grow"] - timings["skin"])
        state.reload_timings = {"detect": waited, **timings}
        state.saved_ns = saved_ns
    state.dirty = True


def presented(state: ViewerState) -> dict | None:
    """The window calls this after a frame is on screen: a reload's time from the save
    to this frame is printed here, and returned ({"total": s, "detect": s, "grow": s,
    "skin": s, "draw": s}; None when no reload waited for this frame)."""
    if state.saved_ns is None:
        return None
    total = (time.time_ns() - state.saved_ns) / 1e9
    timings = {**state.reload_timings, "draw": state.frames[-1].wall_ms / 1e3 if state.frames else 0.0}
    parts = ", ".join(f"{k} {v:.2f}" for k, v in timings.items())
    state.say(f"reloaded {state.model.source}: {state.model.grown.segments:,} segments, "
              f"{total:.2f} s from save to frame ({parts} s)")
    state.status = f"reloaded: {total:.2f} s from save to frame"
    state.saved_ns = None
    return {"total": total, **timings}
