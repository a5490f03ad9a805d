"""Simulation with the compiled fixed-step stepper (``nc.simulate(..., method="stepper")``).

The scheme (RATTLE for constant mass matrices, see :mod:`ncgen.runtime.stepper_kernels`)
runs entirely in generated C: ``<model>_simulate`` of the stepper library
(:mod:`ncgen.runtime.stepper_package`) advances all steps in one call, Python only prepares
the inputs and wraps the result in a :class:`~ncgen.runtime.trajectory.Trajectory`.

Steps: ``substeps`` fixed steps of ``h = dt / substeps`` per output interval ``dt`` (s); a
step whose Newton iteration fails is split into halves (at most ``max_halvings`` times,
recursively), so the output grid stays fixed.
Inputs are constant over each step: with ``hold="zoh"`` the sample of its output interval,
with ``hold="linear"`` the interpolated input at the step's midpoint (second order for
smooth inputs).  Multipliers in the trajectory are those of the last half-step (first-order
accurate in h); at ``t0`` they solve the KKT system.
"""
from __future__ import annotations

import math
import time

import numpy as np

from ncgen.errors import NcgenError, SimulationError
from ncgen.runtime.inputs import HOLDS
from ncgen.runtime.stepper_package import HALVINGS_LIMIT, MAX_HALVINGS, MAX_ITER, STATUS, TOL, load_stepper
from ncgen.runtime.trajectory import Trajectory



def simulate_stepper(model, t: np.ndarray, U: np.ndarray, p: np.ndarray, q0: np.ndarray, v0: np.ndarray,
                     lam0: np.ndarray, *, hold: str = "zoh", substeps: int = 1, tol: float = TOL,
                     max_iter: int = MAX_ITER, max_halvings: int = MAX_HALVINGS, cflags=None) -> Trajectory:
    """Integrate ``model`` over the uniform grid ``t`` (s) from the consistent state
    ``(q0, v0)`` with multipliers ``lam0`` at ``t[0]``; ``U`` holds the input samples on the
    grid, shape ``(len(t), nu)``, ``p`` the parameter values.  Raises
    :class:`~ncgen.errors.SimulationError` naming the time of the step that failed, with the
    trajectory up to the last output time before it."""
    substeps, max_iter, max_halvings = int(substeps), int(max_iter), int(max_halvings)
    if substeps < 1:
        raise NcgenError(f"substeps: expected a positive number of steps per output interval, got {substeps}")
    if not (math.isfinite(tol) and tol > 0):
        raise NcgenError(f"tol: expected a positive Newton tolerance, got {tol!r}")
    if max_iter < 1:
        raise NcgenError(f"max_iter: expected at least one Newton iteration, got {max_iter}")
    if not 0 <= max_halvings <= HALVINGS_LIMIT:
        raise NcgenError(f"max_halvings: expected 0 to {HALVINGS_LIMIT} step halvings, got {max_halvings}")
    if hold not in HOLDS:
        raise NcgenError(f"hold: expected one of {', '.join(HOLDS)}, got {hold!r}")
    n_out = len(t) - 1
    h = float(t[1] - t[0]) / substeps
    stepper = load_stepper(model, cflags)
    IMP = np.zeros((n_out, stepper.nd)) if stepper.nd else None      # contact impulses per output interval
    start = time.perf_counter()
    Q, V, LAM, ITER, status, done, splits = stepper.simulate(q0, v0, float(t[0]), h, n_out * substeps, substeps,
                                                             step_inputs(U, t, hold, substeps), p, tol, max_iter,
                                                             max_halvings, impulse_out=IMP)
    wall = time.perf_counter() - start
    rows = done // substeps
    scheme = "RATTLE, nonsmooth contacts" if IMP is not None else "RATTLE"
    info = {"method": "stepper", "backend": "compiled", "scheme": scheme, "h": h, "substeps": substeps,
            "hold": hold, "tol": tol, "max_iter": max_iter, "max_halvings": max_halvings, "wall_time": wall,
            "complete": status == 0,
            "stats": {"nsteps": done, "newton_iterations": int(ITER[:rows].sum()), "step_splits": splits}}
    if status != 0:
        t_fail = float(t[0]) + done * h
        info["message"] = (f"simulation of {model.name!r} with the stepper failed in the step from "
                           f"t = {t_fail:.6g} s to {t_fail + h:.6g} s (h = {h:.3g} s, halved up to "
                           f"{max_halvings} times): "
                           f"{STATUS.get(status, f'status {status}')}. The trajectory up to "
                           f"t = {t[rows]:.6g} s is attached to this error as .trajectory.")
    traj = Trajectory.from_states(model, t[:rows + 1], np.vstack([q0, Q[:rows]]), np.vstack([v0, V[:rows]]),
                                  np.vstack([lam0, LAM[:rows]]), U[:rows + 1], p, info,
                                  impulses=None if IMP is None else IMP[:rows])
    if status != 0:
        raise SimulationError(info["message"], time=float(t[rows]), trajectory=traj)
    return traj


def step_inputs(U: np.ndarray, t: np.ndarray, hold: str, substeps: int) -> np.ndarray | None:
    """Inputs of every step, shape ``(n_steps, nu)`` (see the module docstring), or None
    without inputs."""
    if U.shape[1] == 0:
        return None
    if hold == "zoh":
        return np.repeat(U[:-1], substeps, axis=0)
    frac = (np.arange(substeps) + 0.5) / substeps
    return (U[:-1, None, :] + frac[None, :, None] * (U[1:] - U[:-1])[:, None, :]).reshape(-1, U.shape[1])
