"""``nc.simulate(model, ..., method="stepper")`` for a model with nonholonomic elements: fixed
RATTLE steps with velocity constraints (:mod:`ncgen.assembly.rolling_rattle`: positions by
the holonomic RATTLE, the step's end on both constraint levels, ``B(q⁺) v⁺ = c(q⁺, t⁺)``
included; order 2): each step is two Newton solves (``newton_tol`` on the residuals'
max-norm, then one more Newton correction, at most ``max_newton`` iterations each), either
one call of compiled C (:func:`ncgen.assembly.rolling_rattle.step_function`, compiled through
the content-keyed cache, :func:`compiled_step`) or Python-driven CasADi calls
(:func:`rattle_step`; the same iterates).  ``backend``: ``"compiled"`` (an error without a C
compiler), ``"vm"`` (Python) or ``"auto"`` (compiled when compiled in this process already, or
once the Python steps' pace says the run would take longer than
:data:`~ncgen.runtime.rolling_integrator.COMPILE_PAYS` s; without a compiler it goes on in
Python); ``info["backend"]`` says which ran last.

``substeps`` steps of ``dt / substeps`` per output interval; ``scheme`` ``"auto"`` or
``"rattle"`` (the fourth-order composition is not built on this step); no error control
(``rtol``), no feedback or compiled controller (refused by name); the
compiled stepper's shadow-run error estimate and checks (``estimate``, ``check``), step
halving (``max_halvings``) and ``kernels`` do not apply and are ignored.  Inputs
are held as the run's samples say (``"zoh"``: the sample of the step's interval; ``"linear"``:
interpolated at the step's start and end).  ``info["stats"]`` counts steps and Newton
iterations of the Python-driven steps; ``lam`` holds the multipliers of the last step's end kick (per output time; at
``t0`` the KKT multipliers), named by ``constraint_names``.
"""
from __future__ import annotations

import time

import numpy as np

from ncgen.assembly.nonholonomic import rolling_system
from ncgen.assembly.rolling_dae import rolling_kkt
from ncgen.assembly.rolling_rattle import rattle_functions, step_function
from ncgen.errors import CompilerNotFound, NcgenError, SimulationError
from ncgen.runtime.integrator import Run
from ncgen.runtime.stepper_options import StepperOptions
from ncgen.runtime.rolling_integrator import COMPILE_PAYS, PACE_AFTER, project
from ncgen.runtime.trajectory import Trajectory


def check_rolling_stepper(model, opts: StepperOptions) -> None:
    """Refuse, by name, the stepper's options this path does not take (module docstring)."""
    if opts.scheme not in ("auto", "rattle"):
        raise NcgenError(f"method='stepper': model {model.name!r} has rolling elements: scheme={opts.scheme!r} is "
                         "not taken (RATTLE with velocity constraints, order 2, only); give scheme='rattle'")
    if opts.rtol is not None or opts.atol is not None:
        raise NcgenError(f"method='stepper': model {model.name!r} has rolling elements: rtol/atol (error control) "
                         "are not taken by its fixed RATTLE steps; give substeps, or use method='rolling' or 'idas'")


def _functions(system):
    """``(drift, kick, kkt)`` of ``system``, made once (kept in ``system.compiled_steps``)."""
    if "rattle" not in system.compiled_steps:
        f = rattle_functions(system)
        system.compiled_steps["rattle"] = f["drift"], f["kick"], rolling_kkt(system)
    return system.compiled_steps["rattle"]


def compiled_step(system, tol: float, max_iter: int):
    """The step of :func:`ncgen.assembly.rolling_rattle.step_function` (Newton tolerance
    ``tol``, at most ``max_iter`` iterations) as compiled C
    (:func:`ncgen.codegen.direct.compile_direct`, cached by content), kept in
    ``system.compiled_steps``; raises :class:`~ncgen.errors.CompilerNotFound`."""
    from ncgen.codegen.direct import compile_direct
    key = _step_key(tol, max_iter)
    if key not in system.compiled_steps:
        system.compiled_steps[key] = compile_direct("rolling_rattle_step", step_function(system, tol, max_iter))
    return system.compiled_steps[key]


def _step_key(tol: float, max_iter: int) -> tuple:
    """The compiled step's key in ``system.compiled_steps``."""
    return "rattle", float(tol), int(max_iter)


def compiled_rattle_step(step, t: float, q, v, h: float, u0, u1, p, tol: float):
    """One step by the compiled ``step`` (:func:`compiled_step`): ``(q⁺, v⁺, ν)``; raises
    :class:`~ncgen.errors.SimulationError` when a Newton solve did not reach ``tol``."""
    q_next, v_next, nu_, res = step(q, v, t, h, u0, u1, p)
    if not float(res[0]) <= tol:
        raise SimulationError(f"RATTLE step with velocity constraints from t = {t:.6g} s (compiled): Newton's method "
                              f"did not bring the residual below {tol:g} (residual {float(res[0]):.3g}); take "
                              "smaller steps (substeps)", time=t, trajectory=None)
    return q_next.copy(), v_next.copy(), nu_.copy()


def _newton(f, y, args, tol: float, max_iter: int, what: str, t: float) -> tuple[np.ndarray, int]:
    """``y`` with ``max|f(y, *args)[0]| ≤ tol`` by Newton's method, then corrected once more by
    the last Newton step (no further evaluation; the convergence being quadratic, the
    residual is then at round-off); the iterations used."""
    for k in range(max_iter + 1):
        r, J = f(y, *args)
        r = np.asarray(r).ravel()
        y = y - np.linalg.solve(np.asarray(J), r)
        if np.max(np.abs(r)) <= tol:
            return y, k
    raise SimulationError(f"RATTLE step with velocity constraints from t = {t:.6g} s: Newton's method on the {what} "
                          f"did not bring the residual below {tol:g} in {max_iter} iterations "
                          f"(residual {np.max(np.abs(r)):.3g}); take smaller steps (substeps)", time=t,
                          trajectory=None)


def rattle_step(system, t: float, q, v, h: float, u0, u1, p, tol: float = 1e-12, max_iter: int = 20):
    """One step from ``(q, v)`` at ``t`` over ``h`` (s), inputs ``u0`` in the first half kick
    and ``u1`` in the second: ``(q⁺, v⁺, ν, Newton iterations)`` (:mod:`ncgen.assembly.rolling_rattle`)."""
    drift, kick, kkt = _functions(system)
    nq, nh = system.nq, system.n_holonomic
    mu = np.asarray(kkt(t, q, v, u0, p)[1]).ravel()[nh:]
    y, n1 = _newton(drift, np.concatenate([v, np.zeros(nh)]), (q, v, mu, t, h, u0, p), tol, max_iter,
                    "positions (first half kick)", t)
    q_next, v_half = q + h * y[:nq], y[:nq]
    y, n2 = _newton(kick, np.concatenate([v_half, np.zeros(len(system.row_names))]), (q_next, v_half, t, h, u1, p),
                    tol, max_iter, "velocities (second half kick)", t)
    return q_next, y[:nq], y[nq:], n1 + n2


def simulate_rolling_rattle(model, run: Run, opts: StepperOptions) -> Trajectory:
    """Fixed RATTLE steps over ``run``'s grid (module docstring)."""
    if run.controller is not None or run.feedback is not None:
        raise NcgenError(f"method='stepper': model {model.name!r} has rolling elements: feedback and controllers "
                         "are not taken (open-loop inputs are); give u as samples or a function of t")
    system = rolling_system(model)
    if system.parametric_constraints and not np.array_equal(run.p, model.p0):
        raise NcgenError(f"method='stepper': model {model.name!r}: its constraints depend on the parameters, and "
                         "the rolling equations are built with model.p0; give p=None")
    t, p, nq = run.t, np.asarray(run.p, float), model.nq
    U = np.asarray(run.U, float)
    linear = opts.hold == "linear"
    q, v = project(system, run.q, run.v, t=float(t[0]))
    Q, V = np.empty((len(t), nq)), np.empty((len(t), nq))
    lam = np.empty((len(t), len(system.row_names)))
    Q[0], V[0] = q, v
    lam[0] = np.asarray(_functions(system)[2](t[0], q, v, U[0], p)[1]).ravel()
    steps = iterations = 0
    start = time.perf_counter()
    step = system.compiled_steps.get(_step_key(opts.newton_tol, opts.max_newton)) if opts.backend == "auto" else None
    if opts.backend == "compiled":
        try:
            step = compiled_step(system, opts.newton_tol, opts.max_newton)
        except CompilerNotFound as e:
            raise CompilerNotFound(f"{e}: backend='compiled' compiles the rolling RATTLE step; install gcc, or give "
                                   "backend='auto' or 'vm' (the same steps in Python)") from None
    decided = opts.backend != "auto" or step is not None
    total = (len(t) - 1) * opts.substeps
    for k in range(len(t) - 1):
        h = (t[k + 1] - t[k]) / opts.substeps
        for j in range(opts.substeps):
            ta = t[k] + j * h
            if linear:
                u0, u1 = (U[k] + (s - t[k]) / (t[k + 1] - t[k]) * (U[k + 1] - U[k]) for s in (ta, ta + h))
            else:
                u0 = u1 = U[k]
            try:
                if step is not None:
                    q, v, nu_ = compiled_rattle_step(step, ta, q, v, h, u0, u1, p, opts.newton_tol)
                    n = 0
                else:
                    q, v, nu_, n = rattle_step(system, ta, q, v, h, u0, u1, p, opts.newton_tol, opts.max_newton)
            except SimulationError as e:
                raise SimulationError(str(e), time=float(ta), trajectory=Trajectory.from_states(
                    model, t[:k + 1], Q[:k + 1], V[:k + 1], lam[:k + 1], U[:k + 1], p,
                    {"method": "stepper", "complete": False})) from None
            steps, iterations = steps + 1, iterations + n
            elapsed = time.perf_counter() - start
            if not decided and elapsed > PACE_AFTER and elapsed * total / steps > COMPILE_PAYS:
                decided = True                           # asked once per run
                try:
                    step = compiled_step(system, opts.newton_tol, opts.max_newton)
                except CompilerNotFound:
                    pass
        Q[k + 1], V[k + 1], lam[k + 1] = q, v, nu_
    info = {"method": "stepper", "scheme": "rattle", "substeps": opts.substeps, "hold": opts.hold,
            "backend": "vm" if step is None else "compiled",
            "rolling_names": [e.name for e in model.rolling], "stats": {"steps": steps, "newton": iterations},
            "wall_time": time.perf_counter() - start, "complete": True}
    traj = Trajectory.from_states(model, t, Q, V, lam, U, p, info)
    traj.constraint_names = list(system.row_names)
    levels = np.array([system.residuals(a, b, tk) for tk, a, b in zip(t, Q, V)])
    traj.constraint_residual, traj.velocity_residual = levels[:, 0], levels[:, 1]
    return traj
