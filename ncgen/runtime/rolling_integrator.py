"""Simulation of a model with nonholonomic elements
(:class:`ncgen.assembly.nonholonomic.RollingSystem`): explicit Runge–Kutta steps of
``q̇ = v``, ``v̇ = a(q, v)`` (the KKT accelerations, exact on the constraints) each followed
by a projection onto both constraint levels, ``Φ̂(q) = 0`` (Newton, least-norm corrections)
and ``Â(q) v = ĉ(q, t)`` (orthogonal projection; ``ĉ`` is zero but for elements on a moving
plane).

Methods: ``"rk4"`` — the classical fourth-order scheme at the fixed step ``h``;
``"dopri5"`` — Dormand–Prince 5(4) with error control (``rtol``, ``atol`` on ``[q; v]``),
fifth order.  A projection after a step keeps the order of the step (its correction is of
the size of the step's local error).  Outputs on the grid ``0, dt, 2 dt, …, t_end`` (s).

:class:`RollingIntegrator` is ``nc.simulate(model, ..., method="rolling")`` (the choice of
``method="auto"`` for a model with rolling elements, ``model.rolling``) behind the seam of
:mod:`ncgen.runtime.integrator`: ``integrator`` ``"dopri5"`` (default, ``rtol``/``atol``,
defaults 1e-8 and 1e-10) or ``"rk4"`` (``substeps`` steps per output interval); ``backend``
``"compiled"`` (each step one call of compiled C, :mod:`ncgen.assembly.rolling_step`),
``"vm"`` (Python-driven CasADi calls) or ``"auto"`` (compiled when it pays, see
:func:`integrate`).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ncgen.assembly.manifold import newton, system_size
from ncgen.assembly.nonholonomic import rolling_system
from ncgen.assembly.rolling_step import DOPRI5, step_function
from ncgen.errors import CompilerNotFound, NcgenError
from ncgen.runtime.integrator import Run
from ncgen.runtime.options import SimulationOptions
from ncgen.runtime.rolling_options import RollingOptions
from ncgen.runtime.stepper_checks import energy_report, is_conservative
from ncgen.runtime.trajectory import Trajectory

METHODS = ("rk4", "dopri5")
_A, _B5, _E = DOPRI5
#: Projected wall time (s) of a run's Python-driven steps beyond which ``compiled=None``
#: compiles the step (a first compile takes 20–45 s on a loaded 2-core machine; a cached one ~1 s).
COMPILE_PAYS = 30.0
#: Wall time (s) of Python-driven steps before their pace is trusted for that projection.
PACE_AFTER = 0.5



@dataclass(frozen=True)
class RollingTrajectory:
    """``t`` (s), ``q``, ``v`` (one row per output), ``energy`` (J, kinetic + potential),
    ``residual`` (``max(|Φ̂|∞, |Â v|∞)`` per output), ``steps`` taken, ``rejected`` steps,
    ``compiled``: whether the run ended on the compiled step."""
    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    energy: np.ndarray
    residual: np.ndarray
    steps: int
    rejected: int
    method: str
    compiled: bool = False


def conservative_run(system, U) -> bool:
    """Whether a run of a model with rolling elements keeps its energy: its planes at rest, no
    drives, and its forces conservative with the run's inputs ``U`` (samples; all zero: as
    without inputs), :func:`~ncgen.runtime.stepper_checks.is_conservative`."""
    return (not system.rheonomic and not system.driven
            and is_conservative(system.model, inputs=bool(np.any(np.asarray(U) != 0))))


def project(system, q, v, tol: float = 1e-14, max_iter: int = 20,
            t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """``(q, v)`` moved to ``Φ̂(q) = 0`` by least-norm Newton steps, then ``v`` to
    ``Â(q) v = ĉ(q, t)`` orthogonally (``t``: the time, s)."""
    q = np.array(q, float)
    nh = system.n_holonomic
    bound = tol * system_size(q)
    q, _, res = newton(lambda x: np.asarray(system.phi_at(x, t), float).ravel(),
                       lambda x: np.asarray(system.A_at(x, t), float)[:nh], q, np.arange(q.size),
                       tol=bound, max_iter=max_iter)
    if not res <= bound:
        raise NcgenError(f"project: Newton's method did not bring |Φ| below {tol:g} in {max_iter} "
                         f"iterations (|Φ| = {res:.3g}); the state is far from the constraints")
    A = np.asarray(system.A_at(q, t))
    v = np.asarray(v, float)
    v = v - np.linalg.lstsq(A, A @ v - np.asarray(system.rate(q, t)).ravel(), rcond=None)[0]
    return q, v


def simulate_rolling(system, t_end: float, dt: float, q0=None, v0=None, *, method: str = "dopri5",
                     h: float | None = None, rtol: float = 1e-8, atol: float = 1e-10,
                     compiled: bool | None = None) -> RollingTrajectory:
    """Integrate ``system`` from ``(q0, v0)`` (default: the model's initial state, projected)
    to ``t_end`` (s), outputs every ``dt`` (s).  ``method``: ``"rk4"`` with step ``h`` (s,
    default ``dt``; ``dt`` must be a whole number of steps) or ``"dopri5"`` with
    ``rtol``/``atol``; ``compiled``: see :func:`integrate`."""
    if method not in METHODS:
        raise NcgenError(f"simulate_rolling: method: expected one of {METHODS}, found {method!r}")
    if not (t_end > 0 and dt > 0):
        raise NcgenError(f"simulate_rolling: t_end and dt: expected positive times, found {t_end!r}, {dt!r}")
    per = 1
    if method == "rk4":
        h = dt if h is None else h
        per = int(round(dt / h))
        if per < 1 or abs(per * h - dt) > 1e-12 * dt:
            raise NcgenError(f"simulate_rolling: h: expected dt / h to be a whole number, found dt = {dt}, h = {h}")
    model = system.model
    grid = dt * np.arange(int(round(t_end / dt)) + 1)
    return integrate(system, grid, model.q0 if q0 is None else q0, model.v0 if v0 is None else v0,
                     method=method, substeps=per, rtol=rtol, atol=atol, compiled=compiled)


def compiled_step(system, method: str):
    """The step of ``method`` for ``system`` (:func:`ncgen.assembly.rolling_step.step_function`)
    as compiled C (:func:`ncgen.codegen.direct.compile_direct`, cached by content), kept
    in ``system.compiled_steps``; raises :class:`~ncgen.errors.CompilerNotFound`."""
    from ncgen.codegen.direct import compile_direct
    if method not in system.compiled_steps:
        system.compiled_steps[method] = compile_direct(f"rolling_{method}_step", step_function(system, method))
    return system.compiled_steps[method]


def integrate(system, grid, q0, v0, *, method: str = "dopri5", substeps: int = 1, rtol: float = 1e-8,
              atol: float = 1e-10, compiled: bool | None = None, force=None) -> RollingTrajectory:
    """Integrate ``system`` from ``(q0, v0)`` (projected onto both constraint levels) over the
    output times ``grid`` (s, increasing): ``"rk4"`` takes ``substeps`` equal steps per output
    interval, ``"dopri5"`` controls its steps by ``rtol``/``atol``; steps end on the outputs.
    ``force``: None, or ``force(t, q, v, t_step) -> f``, an extra generalised force (the
    ``f`` of ``system.accel``) at the stage time ``t`` of a step that began at ``t_step`` (s);
    without it the motion does not depend on time.  ``compiled``: whether each step
    (its stages and projection) is one call of compiled C (:func:`compiled_step`) instead of
    Python-driven CasADi calls (the same steps to round-off, 10–20 times faster): ``True``
    from the start (an error without a C compiler), ``False`` never, ``None`` (default)
    when compiled in this process already, else once the Python steps' pace says the run
    would take longer than :data:`COMPILE_PAYS` (then compiled, or read from the compile
    cache, and continued; without a compiler, continued in Python).  The compiled step has
    no extra force and no moving plane: with ``force`` or ``system.rheonomic``,
    ``compiled=True`` is refused and ``None`` runs in Python."""
    if force is not None or system.rheonomic:
        if compiled:
            raise NcgenError("simulate_rolling: compiled=True: the compiled step takes no extra force "
                             "(inputs, parameters or time-dependent forces) and no moving plane (plane_velocity); "
                             "give compiled=None or False")
        compiled = False
    grid = np.asarray(grid, float)
    q, v = project(system, q0, v0, t=float(grid[0]))
    step = _Step(system, method, compiled, force, grid)
    energy = system.model.functions["energy"]
    rows = []

    def record(y, t):
        q, v = np.split(y, 2)
        T, V = energy(0.0, q, v, system.model.p0)
        rows.append((q, v, float(T) + float(V), max(system.residuals(q, v, t))))

    record(np.concatenate([q, v]), grid[0])
    if method == "rk4":
        steps, rejected = _fixed_steps(step, grid, np.concatenate([q, v]), substeps, record), 0
    else:
        steps, rejected = _controlled_steps(step, grid, np.concatenate([q, v]), rtol, atol, record)
    q_out, v_out, e_out, r_out = (np.array(x) for x in zip(*rows))
    return RollingTrajectory(t=grid, q=q_out, v=v_out, energy=e_out, residual=r_out, steps=steps,
                             rejected=rejected, method=method, compiled=step.compiled_step is not None)


class _Step:
    """One step of ``method`` (``(y⁺ projected, error estimate or None)`` from ``y = [q; v]``):
    the compiled step when there is one, else Python-driven CasADi calls with the extra
    ``force`` (:func:`integrate`); :meth:`switch` compiles it once the Python pace projects
    the run over ``grid`` beyond :data:`COMPILE_PAYS`."""

    def __init__(self, system, method: str, compiled, force, grid):
        self.system, self.method, self.compiled, self.force = system, method, compiled, force
        self.compiled_step = system.compiled_steps.get(method) if compiled is None else \
            compiled_step(system, method) if compiled else None
        self.started, self.start, self.span = time.perf_counter(), float(grid[0]), float(grid[-1] - grid[0])
        self.zero = np.zeros(system.nq)

    def switch(self, t_now: float) -> None:
        """Compile the step when the Python pace projects the run beyond COMPILE_PAYS."""
        elapsed = time.perf_counter() - self.started
        if self.compiled is None and self.compiled_step is None and elapsed > PACE_AFTER and \
                t_now > self.start and elapsed * self.span / (t_now - self.start) > COMPILE_PAYS:
            self.compiled = False                     # decided: asked once per run
            try:
                self.compiled_step = compiled_step(self.system, self.method)
            except CompilerNotFound:
                pass

    def rhs(self, y, t=0.0, t_step=0.0):
        """``[v; a]`` at ``y`` and stage time ``t`` of a step that began at ``t_step``."""
        system = self.system
        q_, v_ = y[:system.nq], y[system.nq:]
        f = self.zero if self.force is None else self.force(t, q_, v_, t_step)
        return np.concatenate([v_, np.asarray(system.accel_t(q_, v_, f, t)[0]).ravel()])

    def __call__(self, y, h, t=0.0):
        """``(y⁺ projected, error estimate)`` of one step of ``method`` from time ``t``."""
        if self.compiled_step is not None:
            y_next, err = self.compiled_step(y, (h,))        # a sized step: the direct call's fast copy
            return y_next.copy(), err.copy()
        rhs, system = self.rhs, self.system
        if self.method == "rk4":
            k1 = rhs(y, t, t)
            k2 = rhs(y + h / 2 * k1, t + h / 2, t)
            k3 = rhs(y + h / 2 * k2, t + h / 2, t)
            k4 = rhs(y + h * k3, t + h, t)
            return np.concatenate(project(system, *np.split(y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4), 2),
                                          t=t + h)), None
        k = [rhs(y, t, t)]
        for i in range(1, 7):
            k.append(rhs(y + h * sum(c * kj for c, kj in zip(_A[i], k)), t + h * sum(_A[i]), t))
        y5 = y + h * sum(b * kj for b, kj in zip(_B5, k))
        return np.concatenate(project(system, *np.split(y5, 2), t=t + h)), h * sum(e * kj for e, kj in zip(_E, k))


def _fixed_steps(step: _Step, grid, y, substeps: int, record) -> int:
    """``substeps`` equal steps per output interval from ``y``, ``record(y, t)`` at each
    output; the number of steps."""
    steps = 0
    for t_a, t_b in zip(grid[:-1], grid[1:]):
        h = (t_b - t_a) / substeps
        for j in range(substeps):
            y = step(y, h, t_a + j * h)[0]
            steps += 1
        record(y, t_b)
        step.switch(t_b)
    return steps


def _controlled_steps(step: _Step, grid, y, rtol: float, atol: float, record) -> tuple[int, int]:
    """Steps controlled by the error estimate (``rtol``, ``atol`` on ``[q; v]``), ending on
    the outputs, from ``y``, ``record(y, t)`` at each output; ``(steps, rejected)``."""
    steps = rejected = 0
    t, h = grid[0], min(grid[1] - grid[0], 1e-3) if len(grid) > 1 else 1e-3
    for target in grid[1:]:
        while t < target - 1e-14 * max(1.0, abs(target)):
            h_now = min(h, target - t)
            y_next, err = step(y, h_now, t)
            # the unprojected step's error estimate against the start and the (projected) end
            scale = atol + rtol * np.maximum(np.abs(y), np.abs(y_next))
            ratio = float(np.sqrt(np.mean((err / scale) ** 2)))
            if ratio <= 1.0:
                y = y_next
                t += h_now
                steps += 1
                step.switch(t)
            else:
                rejected += 1
            proposed = h_now * min(5.0, max(0.2, 0.9 * ratio ** -0.2 if ratio > 0 else 5.0))
            # a step cut short to land on an output does not shrink the next one
            h = max(h, proposed) if ratio <= 1.0 and h_now < h else proposed
            if h < 1e-12 * max(1.0, abs(target)):
                raise NcgenError(f"simulate_rolling: the step fell below {h:.3g} s at t = {t:.6g} s")
        record(y, target)
    return steps, rejected


class RollingIntegrator:
    """``method="rolling"``: a model with nonholonomic elements (``model.rolling``), its
    holonomic and velocity constraints kept by projection after every step (module
    docstring).  The trajectory's ``constraint_residual`` is ``|Φ̂(q)|∞`` (the model's
    constraints and the elements' heights), its ``velocity_residual`` ``|Â(q) v|∞`` (both
    levels, the rolling rows included); ``lam`` holds every multiplier, named by
    ``constraint_names`` (the model's, then the elements' rows,
    :attr:`~ncgen.assembly.nonholonomic.RollingSystem.row_names`: the normal force at a
    contact is ``−λ`` of its ``.height`` row, the friction force ``−λ`` of its ``.x``/``.y``
    rows, N), ``info["rolling_names"]`` the elements.  Open-loop inputs (held as ``hold``
    says), parameters other than the model's in the forces and forces that depend on time
    enter as an extra generalised force, integrated in Python (the compiled step is built
    without them)."""

    METHOD = "rolling"
    Options = RollingOptions

    def __init__(self, model, opts: SimulationOptions):
        if opts.joint_dynamics:
            raise NcgenError("method='rolling' does not take joint_dynamics=True (the joints' damping, friction "
                             "and limits are not in the rolling equations)")
        self.model, self.opts = model, RollingOptions.of(opts)
        self.system = rolling_system(model)
        if self.system.driven:
            raise NcgenError(f"method='rolling': model {model.name!r} has drives (time-dependent constraints), "
                             "which the rolling integrator does not take; use method='idas' or 'stepper'")

    def applied_force(self, run: Run):
        """``force(t, q, v, t_step)`` for :func:`integrate`: the model's applied forces at the
        run's inputs (sample of ``t_step``'s interval for ``"zoh"``, interpolated at ``t`` for
        ``"linear"``) and parameters, less those the rolling equations hold
        (``t = 0``, ``u = 0``, ``model.p0``); None when they are the same."""
        model, system = self.model, self.system
        F = model.functions["F"]
        if system.parametric_constraints and not np.array_equal(run.p, model.p0):
            raise NcgenError(f"method='rolling': model {model.name!r}: its constraints depend on the parameters, "
                             "and the rolling equations are built with model.p0; give p=None")
        if not (system.timed_forces or np.any(run.U != 0) or not np.array_equal(run.p, model.p0)):
            return None
        t_grid, U, p = run.t, np.asarray(run.U, float), np.asarray(run.p, float)
        linear = self.opts.hold == "linear"

        def u_at(t, t_step):
            if linear:
                return np.array([np.interp(t, t_grid, U[:, j]) for j in range(U.shape[1])])
            k = int(np.clip(np.searchsorted(t_grid, t_step, side="right") - 1, 0, len(t_grid) - 1))
            return U[k]

        def force(t, q, v, t_step):
            return np.asarray(F(t, q, v, u_at(t, t_step), p)).ravel() - np.asarray(system.F(q, v)).ravel()
        return force

    def run(self, run: Run) -> Trajectory:
        model, o = self.model, self.opts
        if run.controller is not None or run.feedback is not None:
            raise NcgenError(f"method='rolling': model {model.name!r}: feedback and controllers are not taken "
                             "(open-loop inputs are); give u as samples or a function of t")
        force = self.applied_force(run)
        method = o.integrator or "dopri5"
        rtol = 1e-8 if o.rtol is None else o.rtol
        atol = 1e-10 if o.atol is None else o.atol
        start = time.perf_counter()
        compiled = {"vm": False, "compiled": True}.get(o.backend)
        if (force is not None or self.system.rheonomic) and compiled:
            raise NcgenError(f"method='rolling': model {model.name!r}: backend='compiled': the compiled step is "
                             "built without inputs, other parameters, time-dependent forces or moving planes; "
                             "give backend='vm' or 'auto'")
        tr = integrate(self.system, run.t, run.q, run.v, method=method, substeps=o.substeps, rtol=rtol, atol=atol,
                       compiled=compiled, force=force)
        system = self.system
        zero = np.zeros(system.nq)
        lam = np.array([np.asarray(system.accel_t(q, v, zero if force is None else force(t, q, v, t), t)[1]).ravel()
                        for t, q, v in zip(tr.t, tr.q, tr.v)])
        levels = np.array([system.residuals(q, v, t) for t, q, v in zip(tr.t, tr.q, tr.v)])
        info = {"method": self.METHOD, "integrator": method, "steps": tr.steps, "rejected": tr.rejected,
                "backend": "compiled" if tr.compiled else "vm",
                "rolling_names": [e.name for e in model.rolling], "wall_time": time.perf_counter() - start,
                **({"rtol": rtol, "atol": atol} if method == "dopri5" else {"substeps": o.substeps})}
        traj = Trajectory.from_states(model, tr.t, tr.q, tr.v, lam.reshape(len(tr.t), len(system.row_names)),
                                      run.U, run.p, info)
        traj.constraint_names = list(system.row_names)
        traj.constraint_residual, traj.velocity_residual = levels[:, 0], levels[:, 1]
        if force is None and conservative_run(system, run.U):      # else: no work tracked, no report
            traj.info["energy"] = energy_report(traj, np.zeros(len(traj)), True)
        return traj
