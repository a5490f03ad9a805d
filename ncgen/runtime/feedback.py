"""A Python feedback ``u(t, q, v)`` (or ``u(t, qj, vj)``) called during a run.

:func:`call_feedback` returns its ``nu`` finite inputs or raises :class:`FeedbackFailed`
naming the call: the time (s), the arguments' names, and what the function raised or
returned against what was expected.  Every path that calls a feedback (joint loop, IDAS, the
stepper one interval at a time) catches it, attaches the trajectory up to the last state
reached (:func:`with_partial`) and re-raises it, so a failing law loses no finished work.
"""
from __future__ import annotations

import numpy as np

from ncgen.errors import SimulationError


class FeedbackFailed(SimulationError):
    """The feedback failed at ``time`` (s); ``trajectory`` is attached by the run."""

    def __init__(self, message: str, *, time: float):
        super().__init__(message, time=time, trajectory=None)


def call_feedback(u, t: float, a, b, *, nu: int, what: str) -> np.ndarray:
    """``u(t, a, b)`` as ``nu`` finite floats; ``what``: ``"joint"`` (``a, b = qj, vj``) or
    ``"natural"`` (``q, v``)."""
    call = f"the feedback u(t, {'qj, vj' if what == 'joint' else 'q, v'}) called at t = {t:.6g} s"
    try:
        value = u(t, a, b)
    except Exception as e:         # noqa: BLE001 - the user's law: whatever it raises, named
        raise FeedbackFailed(f"{call} raised {type(e).__name__}: {e}", time=t) from e
    try:
        val = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        shown = repr(value) if len(repr(value)) <= 80 else repr(value)[:77] + "..."
        raise FeedbackFailed(f"{call} returned {shown}: expected {nu} finite number(s), the inputs", time=t) from None
    if val.size != nu or val.ndim > 1 and max(val.shape) != val.size:
        raise FeedbackFailed(f"{call} returned an array of shape {val.shape}: expected {nu} input value(s)",
                             time=t)
    val = val.reshape(-1)
    if not np.all(np.isfinite(val)):
        raise FeedbackFailed(f"{call} returned {val.tolist()}: expected {nu} finite input value(s)", time=t)
    return val


def with_partial(error: FeedbackFailed, trajectory) -> FeedbackFailed:
    """``error`` with ``trajectory`` (the run up to the last state reached) attached and
    marked incomplete; its message says so.  A feedback that fails at its first call leaves
    the initial state alone, one row whose input is zero (none was given)."""
    if len(trajectory.t) == 1:
        kept = (f"The initial state (t = {trajectory.t[0]:.6g} s; no input was applied, its u is zero) is "
                "attached to this error as .trajectory.")
    else:
        kept = f"The trajectory up to t = {trajectory.t[-1]:.6g} s is attached to this error as .trajectory."
    message = f"{str(error).rstrip('.')}. {kept}"
    trajectory.info.update(complete=False, message=message)
    out = FeedbackFailed(message, time=float(trajectory.t[-1]))
    out.trajectory = trajectory
    return out
