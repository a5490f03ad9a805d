"""The start of a run, shared by the integrators: the consistent initial state and
multipliers, a Python feedback's inputs at a natural state, and the memory per output time."""
from __future__ import annotations

import numpy as np

from ncgen.assembly.initial_state import consistent_state
from ncgen.errors import ModelError, SimulationError
from ncgen.runtime.diagnose import explain
from ncgen.runtime.feedback import FeedbackFailed, call_feedback, with_partial
from ncgen.runtime.tree_library import loaded_tree_start
from ncgen.validation import as_vector


def natural_feedback(model, feedback, t: float, q, v, p) -> np.ndarray:
    """The feedback's inputs at the natural state ``(q, v)`` at ``t``."""
    kind, u = feedback
    if kind == "joint":
        qj, vj = model.to_joint_space(q, v)
        return call_feedback(u, t, qj, vj, nu=model.nu, what="joint")
    return call_feedback(u, t, np.array(q, float), np.array(v, float), nu=model.nu, what="natural")


def failed_at_start(model, error: FeedbackFailed, t0: float, q, v, p, lam, info: dict) -> FeedbackFailed:
    """``error`` (the feedback failed at its first call) with the initial state attached as
    a one-row trajectory: input zero, ``lam`` the multipliers with that input."""
    from ncgen.runtime.trajectory import Trajectory

    row = Trajectory.from_states(model, np.array([t0]), np.array(q, float)[None], np.array(v, float)[None],
                                 np.asarray(lam, float)[None], np.zeros((1, model.nu)), p, info)
    return with_partial(error, row)


def point_bytes(model) -> float:
    """Bytes a trajectory holds per output time, counting the integrator's work arrays:
    ``t``, q, v, a, λ, u, markers and their rates, energies, residuals, twice over."""
    per = 1 + 3 * model.nq + 2 * model.nc + model.nu + 2 * model.dim * len(model.marker_names) + 4
    return 2 * 8.0 * per


def initial_state(model, q0, v0, t0: float, p: np.ndarray, tolerance: float | None):
    """Consistent ``(q, v)`` at ``t0`` (see :func:`~ncgen.runtime.simulation.simulate`)."""
    return start_state(model, q0, v0, t0, p, tolerance)[:2]


def start_state(model, q0, v0, t0: float, p: np.ndarray, tolerance: float | None, joint: bool = False):
    """``(q, v, joint state)``: :func:`initial_state` and, when ``joint`` and the given state
    holds as it is (one C call checks it and maps it), its ``(q_j, v_j)`` (then ``q``, ``v``
    are the arrays given, not copies), else None."""
    js, shape = model.joint_space, model.q0.shape
    at_model = t0 == model.t0 and (model.p0.size == 0 or np.array_equal(p, model.p0))
    if q0 is None and v0 is None and at_model:
        return model.q0.copy(), model.v0.copy(), None
    if at_model and (q0 is None or type(q0) is _ARRAY and q0.dtype == _FLOAT64 and q0.shape == shape) and \
            (v0 is None or type(v0) is _ARRAY and v0.dtype == _FLOAT64 and v0.shape == shape):
        # (None or float64 arrays of nq values, which _holds checks; anything else goes through as_vector,
        # whose messages name the argument)
        q, v = (model.q0 if q0 is None else q0), (model.v0 if v0 is None else v0)
        if joint:                           # finite, in range, consistent, and its joint state: one C call
            state = js._checked_state(model, q, v, t0, p, loaded_tree_start(model))
            if state is not None:           # (q, v not copied: the joint run reads its joint state only)
                return q, v, state
        elif js._holds(model, q, v, t0, p):  # finite, in range, consistent: one C call
            return q.copy(), v.copy(), None
    q = model.q0 if q0 is None else as_vector(q0, model.nq, "q0")
    v = model.v0 if v0 is None else as_vector(v0, model.nq, "v0")
    if at_model and js._holds(model, q, v, t0, p):
        return q.copy(), v.copy(), None    # consistent to round-off already (e.g. from from_joint_space)
    try:
        state = consistent_state(model.functions, model.layout, model.constraint_names, q.copy(), v.copy(),
                                 p, t0, 1.0 if tolerance is None else tolerance, model.M,
                                 assemble=tolerance is None)
    except ModelError as e:
        raise ModelError(f"simulate: initial state of {model.name!r} at t0 = {t0:g} s: {e}. In simulate: give "
                         f"q0/v0 consistent at t0, or ic_tolerance=None to accept any correction") from None
    return state.q0, state.v0, None


_ARRAY, _FLOAT64 = np.ndarray, np.float64


def initial_multipliers(model, t0: float, q, v, u, p, dae) -> np.ndarray:
    """``λ0`` from the KKT system at the initial state; a singular system is a
    :class:`~ncgen.errors.SimulationError` at ``t0`` (no trajectory)."""
    try:
        lam = np.array(model.functions["accel"](t0, q, v, u, p)[1]).reshape(-1)
    except RuntimeError:
        lam = np.full(model.nc, np.nan)
    if np.all(np.isfinite(lam)):
        return lam
    cause = explain(model, "", t0, q, v, np.zeros(model.nc), u, p, dae)
    raise SimulationError(f"simulation of {model.name!r} cannot start: the KKT system [[M, A^T], [A, 0]] "
                          f"is singular at t0 = {t0:g} s, so the multipliers are undefined: {cause}",
                          time=t0, trajectory=None)
