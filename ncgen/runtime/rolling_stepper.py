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
(``rtol``), no feedback or compiled controller (refused by name); step halving
(``max_halvings``) and ``kernels`` do not apply and are ignored.

What the run says of its accuracy is the compiled stepper's
(:mod:`ncgen.runtime.stepper_checks`, from per-row statistics in its columns):
``info["error_estimate"]`` a global estimate (``estimate=True``, the default) by Richardson
against a shadow run with steps of 2h (``substeps`` even: half the work again) or of h/2
(odd: twice the work), order 2; ``info["energy"]`` the drift of a conservative run or the
energy balance with the work of inputs, drives and moving planes
(:func:`ncgen.assembly.nonholonomic.power_function` by the trapezoidal rule over each step,
each end with its own multipliers); and ``check=True`` (default) raises
:class:`~ncgen.errors.SimulationError` from the first output row where the estimate passes
1 % of the model's size or the energy error 1 % of its scale (Newton iterations are counted
on the Python-driven steps only).  Inputs
are held as the run's samples say (``"zoh"``: the sample of the step's interval; ``"linear"``:
interpolated at the step's start and end).  ``info["stats"]`` counts steps and Newton
iterations of the Python-driven steps; ``lam`` holds the multipliers of the last step's end kick (per output time; at
``t0`` the KKT multipliers), named by ``constraint_names``.
"""
from __future__ import annotations

import time

import numpy as np

from ncgen.assembly.nonholonomic import power_function, rolling_system
from ncgen.assembly.rolling_dae import rolling_kkt
from ncgen.assembly.rolling_rattle import rattle_functions, step_function
from ncgen.codegen.stepper_package import STATS
from ncgen.errors import CompilerNotFound, NcgenError, SimulationError
from ncgen.runtime.energy_balance import balance_report, stepper_works
from ncgen.runtime.integrator import Run
from ncgen.runtime.stepper_options import StepperOptions
from ncgen.runtime.rolling_integrator import COMPILE_PAYS, PACE_AFTER, conservative_run, project
from ncgen.runtime.stepper_checks import check_fixed, energy_report, error_estimate
from ncgen.runtime.trajectory import Trajectory


def check_rolling_stepper(model, opts: StepperOptions) -> None:
    """Refuse, by name, the stepper's options this path does not take (module docstring)."""
    if opts.scheme not in ("auto", "rattle"):
        raise NcgenError(f"method='stepper': model {model.name!r} has rolling elements: scheme={opts.scheme!r} is "
                         "not taken (RATTLE with velocity constraints, order 2, only); give scheme='rattle'")
    if opts.estimate == "local":
        raise NcgenError(f"method='stepper': model {model.name!r} has rolling elements: estimate='local' is not "
                         "taken (its estimate is the shadow run's); give estimate=True or False")
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
    q_next, v_next, nu_, res = step(q, v, (t,), (h,), u0, u1, p)      # sized arguments: the direct call's fast copy
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


def _inputs(U, t, k: int, ta: float, h: float, linear: bool):
    """The inputs of the step ``[ta, ta + h]`` in output interval ``k``: ``(u0, u1)``."""
    if not linear:
        return U[k], U[k]
    return tuple(U[k] + (s - t[k]) / (t[k + 1] - t[k]) * (U[k + 1] - U[k]) for s in (ta, ta + h))


class _Steps:
    """The steps of one run: compiled (``step``) or Python-driven, ``backend="auto"``'s choice
    made once by the pace of the Python steps (module docstring)."""

    def __init__(self, system, opts: StepperOptions, total: int):
        self.system, self.opts, self.total, self.steps = system, opts, total, 0
        key = _step_key(opts.newton_tol, opts.max_newton)
        self.step = system.compiled_steps.get(key) if opts.backend == "auto" else None
        if opts.backend == "compiled":
            try:
                self.step = compiled_step(system, opts.newton_tol, opts.max_newton)
            except CompilerNotFound as e:
                raise CompilerNotFound(f"{e}: backend='compiled' compiles the rolling RATTLE step; install gcc, or "
                                       "give backend='auto' or 'vm' (the same steps in Python)") from None
        self.decided = opts.backend != "auto" or self.step is not None
        self.start = time.perf_counter()

    def __call__(self, ta, q, v, h, u0, u1, p):
        """One step: ``(q⁺, v⁺, ν, Newton iterations)`` (0 iterations counted when compiled)."""
        if self.step is not None:
            return (*compiled_rattle_step(self.step, ta, q, v, h, u0, u1, p, self.opts.newton_tol), 0)
        out = rattle_step(self.system, ta, q, v, h, u0, u1, p, self.opts.newton_tol, self.opts.max_newton)
        self.steps += 1
        elapsed = time.perf_counter() - self.start
        if not self.decided and elapsed > PACE_AFTER and elapsed * self.total / self.steps > COMPILE_PAYS:
            self.decided = True                          # asked once per run
            try:
                self.step = compiled_step(self.system, self.opts.newton_tol, self.opts.max_newton)
            except CompilerNotFound:
                pass
        return out


def _march(steps: _Steps, t, U, p, q, v, nu_, substeps: int, linear: bool, power=None):
    """Fixed steps over the grid ``t`` from ``(q, v)`` (multipliers ``nu_``), ``substeps`` per
    output interval: ``(Q, V, LAM, iterations, work, failure)`` per output row after the first
    (``work``: rows of the work of :func:`~ncgen.assembly.nonholonomic.power_function`'s five
    parts over each interval, by the trapezoidal rule on the steps' ends with each end's own
    multipliers, when ``power`` is given); on a failed step the rows before it and the
    :class:`~ncgen.errors.SimulationError` (else None)."""
    n = len(t) - 1
    Q, V = np.empty((n, len(q))), np.empty((n, len(q)))
    LAM, iterations, work = np.empty((n, len(nu_))), np.zeros(n, int), np.zeros((n, 5))
    sizes = (1, len(q), len(q), len(nu_), U.shape[1])          # t, q, v, ν, u of the steps' ends
    for k in range(n):
        h = (t[k + 1] - t[k]) / substeps
        ends = [(t[k], q, v, nu_, _inputs(U, t, k, t[k], h, linear)[0])]
        for j in range(substeps):
            ta = t[k] + j * h
            u0, u1 = _inputs(U, t, k, ta, h, linear)
            try:
                q, v, nu_, it = steps(ta, q, v, h, u0, u1, p)
            except SimulationError as e:
                return Q[:k], V[:k], LAM[:k], iterations[:k], work[:k], e
            iterations[k] += it
            ends.append((ta + h, q, v, nu_, u1))
        Q[k], V[k], LAM[k] = q, v, nu_
        if power is not None:
            columns = [np.array(c, float).reshape(len(ends), n_c).T for c, n_c in zip(zip(*ends), sizes)]
            P = np.asarray(power.map(len(ends))(*columns, p))
            work[k] = h * (P[:, 1:-1].sum(axis=1) + 0.5 * (P[:, 0] + P[:, -1]))
    return Q, V, LAM, iterations, work, None


def _shadow_estimates(steps: _Steps, run: Run, p, q0, v0, lam0, Q, V, substeps: int, linear: bool):
    """Global error estimates in q (m) and v (m/s) per output row of the run ``(Q, V)``
    (Richardson, RATTLE's order 2): against a shadow run with steps of 2h,
    ``|y_h − y_2h| / 3`` (``substeps`` even: half the work again), else with steps of h/2,
    ``4 |y_h − y_h/2| / 3`` (twice the work); ``-2`` from where the shadow run failed; and
    how they were obtained."""
    even = substeps % 2 == 0
    shadow = substeps // 2 if even else 2 * substeps
    Qs, Vs, _, _, _, _ = _march(steps, run.t, np.asarray(run.U, float), p, q0, v0, lam0, shadow, linear)
    factor = 1.0 / 3.0 if even else 4.0 / 3.0
    eq, ev = np.full(len(Q), -2.0), np.full(len(Q), -2.0)
    m = min(len(Qs), len(Q))
    eq[:m] = factor * np.max(np.abs(Q[:m] - Qs[:m]), axis=1)
    ev[:m] = factor * np.max(np.abs(V[:m] - Vs[:m]), axis=1)
    how = ("Richardson: |y_h - y_2h| / 3 against a shadow run with steps of 2h (RATTLE with velocity "
           "constraints, order 2)" if even else
           "Richardson: 4 |y_h - y_h/2| / 3 against a shadow run with steps of h/2 (RATTLE with velocity "
           "constraints, order 2; substeps odd)")
    return eq, ev, how


def _statistics(iterations, substeps: int, eq, ev, work) -> np.ndarray:
    """The run's per-row statistics in the compiled stepper's columns
    (:data:`~ncgen.codegen.stepper_package.STATS`): steps, Newton iterations, no splits, the
    global estimates, and the work since the start, total and by class (the dampers' the rest)."""
    S = np.zeros((len(iterations), len(STATS)))
    S[:, STATS.index("steps")] = substeps
    S[:, STATS.index("newton_iterations")] = iterations
    S[:, STATS.index("error_q")], S[:, STATS.index("error_v")] = eq, ev
    W = np.cumsum(work, axis=0)
    S[:, STATS.index("work")] = W[:, 0]
    for i, part in enumerate(("contacts", "friction", "inputs", "drives"), start=1):
        S[:, STATS.index(f"work_{part}")] = W[:, i]
    S[:, STATS.index("work_dampers")] = W[:, 0] - W[:, 1:].sum(axis=1)
    return S


def simulate_rolling_rattle(model, run: Run, opts: StepperOptions) -> Trajectory:
    """Fixed RATTLE steps over ``run``'s grid (module docstring)."""
    if run.controller is not None or run.feedback is not None:
        raise NcgenError(f"method='stepper': model {model.name!r} has rolling elements: feedback and controllers "
                         "are not taken (open-loop inputs are); give u as samples or a function of t")
    system = rolling_system(model)
    if system.parametric_constraints and not np.array_equal(run.p, model.p0):
        raise NcgenError(f"method='stepper': model {model.name!r}: its constraints depend on the parameters, and "
                         "the rolling equations are built with model.p0; give p=None")
    t, p, nq, substeps = run.t, np.asarray(run.p, float), model.nq, opts.substeps
    U = np.asarray(run.U, float)
    linear = opts.hold == "linear"
    q0, v0 = project(system, run.q, run.v, t=float(t[0]))
    lam0 = np.asarray(_functions(system)[2](t[0], q0, v0, U[0], p)[1]).ravel()
    conservative = conservative_run(system, run.U)
    power = None if conservative else power_function(system)
    steps = _Steps(system, opts, (len(t) - 1) * substeps * (1 if opts.estimate is False else 2))
    Q, V, LAM, iterations, work, failure = _march(steps, t, U, p, q0, v0, lam0, substeps, linear, power)
    rows = len(Q)
    if opts.estimate is False or rows == 0 or failure is not None:
        eq, ev, how = np.full(rows, -1.0), np.full(rows, -1.0), None
    else:
        eq, ev, how = _shadow_estimates(steps, run, p, q0, v0, lam0, Q, V, substeps, linear)
    S = _statistics(iterations, substeps, eq, ev, work)
    info = {"method": "stepper", "scheme": "rattle", "order": 2, "substeps": substeps, "h": float(t[1] - t[0]) /
            substeps, "hold": opts.hold, "estimate": opts.estimate, "stages": 1,
            "backend": "vm" if steps.step is None else "compiled",
            "rolling_names": [e.name for e in model.rolling],
            "stats": {"steps": rows * substeps, "newton": int(iterations.sum())},
            "wall_time": time.perf_counter() - steps.start, "complete": failure is None}
    traj = Trajectory.from_states(model, t[:rows + 1], np.vstack([q0, Q]), np.vstack([v0, V]),
                                  np.vstack([lam0, LAM]), U[:rows + 1], p, info)
    traj.constraint_names = list(system.row_names)
    levels = np.array([system.residuals(a, b, tk) for tk, a, b in zip(traj.t, traj.q, traj.v)])
    traj.constraint_residual, traj.velocity_residual = levels[:, 0], levels[:, 1]
    traj.info["error_estimate"] = error_estimate(S, substeps, opts.estimate, traj.q, traj.v)
    if how is not None and "Richardson" in traj.info["error_estimate"]["how"]:
        traj.info["error_estimate"]["how"] = how
    W = np.concatenate([[0.0], S[:, STATS.index("work")]])
    traj.info["energy"] = energy_report(traj, W, conservative, S)
    if not conservative and rows:
        balance_report(model, traj.info["energy"], stepper_works(S))
    if failure is not None:
        traj.info["complete"] = False
        raise SimulationError(str(failure), time=failure.time, trajectory=traj)
    if opts.check:
        check_fixed(model, traj, S, traj.info["h"], substeps, contacts=False, conservative=conservative)
    return traj
