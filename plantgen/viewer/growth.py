"""A grammar's growth step by step: N and Shift+N ask for one derivation step more or
less, G plays the steps; each step is grown on the reload thread with the same seed
(functions over a :class:`~plantgen.viewer.state.ViewerState`)."""

from __future__ import annotations

from .keys import GROW_STEP_S
from .state import ViewerState

__all__ = ["ask_step", "grow_step", "toggle_growth", "advance"]


def _steps_allowed(state: ViewerState) -> bool:
    """Whether the model grows step by step (a grammar); else says so (on stdout once)."""
    if state.step is not None:
        return True
    state.status = f"growth steps need a grammar (this is a {state.model.grown.kind})"
    if not state.steps_need_said:
        state.say(state.status)
        state.steps_need_said = True
    return False


def ask_step(state: ViewerState, step: int) -> None:
    """Grow the grammar ``step`` derivation steps deep with the same seed (on the reload
    thread; a newer step asked meanwhile supersedes it)."""
    state.step_target = step
    state.reloader.start(state.t, None, step)
    state.status = f"growing step {step} ..."


def grow_step(state: ViewerState, delta: int) -> None:
    """N, Shift+N: the growth one derivation step forward or back (from the step last
    asked for), between the axiom (0) and the grammar's iterations; stops playing."""
    if not _steps_allowed(state):
        return
    state.growing = False
    current = state.step if state.step_target is None else state.step_target
    step = min(max(current + delta, 0), state.steps_end)
    if step == current:
        state.step_target = current
        state.status = (f"step {step} is the grammar's last (its iterations)" if delta > 0
                        else "step 0 is the axiom")
        return
    ask_step(state, step)


def toggle_growth(state: ViewerState) -> None:
    """G: play the growth, a step each :data:`GROW_STEP_S` seconds (or as fast as a
    step grows), up to the grammar's iterations; from the axiom when there already;
    G again stops it."""
    if not _steps_allowed(state):
        return
    if state.growing:
        state.growing = False
        state.status = f"growth stopped at step {state.step}"
        return
    state.growing, state.grow_clock = True, 0.0
    current = state.step if state.step_target is None else state.step_target
    if current >= state.steps_end:
        ask_step(state, 0)
    else:
        state.step_target = current
        state.status = "growing ..."


def advance(state: ViewerState, dt: float) -> None:
    """A playing growth's clock by ``dt`` seconds: the next step asked for each
    :data:`~plantgen.viewer.keys.GROW_STEP_S` once the last one is in, up to the grammar's
    iterations (then it stops)."""
    if state.growing:
        state.grow_clock += dt
        if state.grow_clock >= GROW_STEP_S and not state.reloader.busy:
            if state.step_target >= state.steps_end:
                state.growing = False
                state.status = f"grown: step {state.step} of {state.steps_end}"
            else:
                ask_step(state, state.step_target + 1)
