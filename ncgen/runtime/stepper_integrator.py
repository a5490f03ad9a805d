"""The compiled stepper behind the integrator seam (:mod:`ncgen.runtime.integrator`):
:func:`ncgen.runtime.stepper.simulate_stepper` over the whole grid, or one output interval at
a time when a Python feedback sets the inputs."""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from ncgen.errors import CompilerNotFound, NcgenError, SimulationError, option
from ncgen.model.data import model_data
from ncgen.runtime.feedback import FeedbackFailed, with_partial
from ncgen.runtime.integrator import Run, refuse_integrator
from ncgen.runtime.rolling_stepper import check_rolling_stepper, simulate_rolling_rattle
from ncgen.runtime.run_start import failed_at_start
from ncgen.runtime.options import SimulationOptions
from ncgen.codegen.stepper_package import CONTACT_STATS, STATS, WORK_PARTS
from ncgen.runtime.stepper import simulate_stepper
from ncgen.runtime.stepper_options import StepperOptions
from ncgen.runtime.table_stepper import load_any_stepper, stepper_kernels
from ncgen.runtime.energy_balance import balance_report, stepper_works
from ncgen.runtime.stepper_checks import check_fixed, energy_report, is_conservative, trusted_before_failure
from ncgen.runtime.trajectory import Trajectory

NO_CONTROLLER = ("method='stepper' does not take a compiled controller or joint_dynamics=True; use method='joint' "
                 "(trees) or 'idas', or give u as a Python callable u(t, q, v)")


class StepperIntegrator:
    """``method="stepper"``: the model's compiled RATTLE stepper (fixed steps or error
    control), compiled when prepared."""

    METHOD = "stepper"
    Options = StepperOptions

    def __init__(self, model, opts: SimulationOptions):
        refuse_integrator(opts, self.METHOD)
        if opts.joint_dynamics:
            raise NcgenError(NO_CONTROLLER)
        self.model, self.opts = model, StepperOptions.of(opts)
        self.opts.check_together()
        if model.rolling:
            check_rolling_stepper(model, self.opts)

    def _load(self) -> None:
        try:
            load_any_stepper(self.model, None, self.opts.kernels)
        except CompilerNotFound as e:
            stepper, idas = option("method='stepper'", "--method stepper"), option("method='idas'", "--method idas")
            raise CompilerNotFound(f"{e}: the stepper ({stepper}) is generated C and needs one; install gcc, "
                                   f"or use IDAS ({idas}), which runs on CasADi's virtual machine") from None

    def _table_multipliers(self, run: Run):
        """``λ0`` from the element tables when the run uses them (no flat function on their
        path), else None."""
        try:
            if stepper_kernels(self.model, self.opts.kernels) != "tables":
                return None
        except CompilerNotFound:             # _load says what to do
            return None
        return model_data(self.model).steppers[("tables", None)].multipliers(run.q, run.v, run.U[0])

    def run(self, run: Run) -> Trajectory:
        if run.controller is not None:
            raise NcgenError(NO_CONTROLLER)
        if self.model.rolling:
            return simulate_rolling_rattle(self.model, run, self.opts)
        if run.feedback is not None:
            return _stepwise(self.model, run, self.opts)
        lam = self._table_multipliers(run)
        if lam is None or not np.all(np.isfinite(lam)):      # singular: the flat path explains why
            lam = run.multipliers(float(run.t[0]), run.q, run.v, run.U[0])
        self._load()
        return simulate_stepper(self.model, run.t, run.U, run.p, run.q, run.v, lam, self.opts)


def _stepwise(model, run: Run, opts: StepperOptions) -> Trajectory:
    """The compiled stepper one output interval at a time, the feedback evaluated at the
    start of each (no shadow run: it needs the whole run).  The intervals' statistics (steps,
    Newton iterations, split steps, work of the non-conservative forces, contact solves) are
    checked over the whole run as a fixed-step run's are (:func:`_checked`, unless
    ``check=False``): a run that stops being trustworthy raises, and a failure (of the stepper
    or the feedback) attaches only the rows before that."""
    if opts.hold != "zoh":
        raise NcgenError("hold='linear' with a feedback u(t, q, v): the feedback is held over each output "
                         "interval (zoh); use hold='zoh'")
    t, p, feedback = run.t, run.p, run.feedback
    step_opts = dataclasses.replace(opts, check=False, estimate=False)
    Q, V, LAM, UU, S = [run.q], [run.v], [], [], []
    IMP: list | None = None             # nonsmooth contacts: each interval's impulse sums (N·s)
    info = {"method": "stepper", "backend": "compiled", "feedback": feedback[0], "hold": "zoh",
            "substeps": opts.substeps, "estimate": False,
            **({"rtol": opts.rtol, "atol": opts.rtol if opts.atol is None else opts.atol} if opts.rtol else {})}
    start, cpu_start = time.perf_counter(), time.process_time()
    part = None
    for k in range(len(t) - 1):
        try:
            uk = run.feedback_input(float(t[k]), Q[-1], V[-1])
        except FeedbackFailed as e:
            if not k:
                lam = run.multipliers(float(t[0]), run.q, run.v, np.zeros(model.nu))
                raise failed_at_start(model, e, float(t[0]), run.q, run.v, p, lam,
                                      {"method": "stepper", "feedback": feedback[0], "complete": False}) \
                    from e.__cause__
            LAM.append(run.multipliers(float(t[k]), Q[-1], V[-1], UU[-1]))
            UU.append(UU[-1])
            traj = _checked(model, opts, _states(model, t, Q, V, LAM, UU, p, info, part, IMP), np.array(S),
                            f" Then {str(e).rstrip('.')}.")
            raise with_partial(e, traj) from e.__cause__
        lam = run.multipliers(float(t[k]), Q[-1], V[-1], uk)
        LAM.append(lam)
        UU.append(uk)
        try:
            part = simulate_stepper(model, t[k:k + 2], np.vstack([uk, uk]), p, Q[-1], V[-1], lam, step_opts)
        except SimulationError as e:
            traj = _states(model, t, Q, V, LAM, UU, p, {**info, "complete": False}, part, IMP)
            traj = _checked(model, opts, traj, np.array(S), f" The stepper then failed at t = {t[k]:.6g} s: {e}")
            traj.info["message"] = str(e)
            raise SimulationError(str(e), time=float(t[k]), trajectory=traj) from None
        Q.append(part.q[-1])
        V.append(part.v[-1])
        S.append(_interval_row(part))
        if "contacts" in part.info:
            IMP = [] if IMP is None else IMP
            IMP.append(_interval_impulses(part))
    LAM.append(part.lam[-1])
    UU.append(UU[-1])
    info.update(wall_time=time.perf_counter() - start, cpu_time=time.process_time() - cpu_start, complete=True)
    return _checked(model, opts, _states(model, t, Q, V, LAM, UU, p, info, part, IMP), np.array(S))


def _states(model, t, Q, V, LAM, UU, p, info: dict, part, IMP=None) -> Trajectory:
    """The rows reached so far, as a trajectory (``part``: the last interval's run, for its
    scheme's name and stages; ``IMP``: with nonsmooth contacts, each interval's impulse sums,
    so the contact outputs are the stepper's mean forces as in a run without feedback — the
    states alone put a resting contact a round-off gap apart, with no force)."""
    k = len(Q)
    if part is not None:
        info = {**info, **{key: part.info[key] for key in ("scheme", "order", "stages", "h") if key in part.info}}
    impulses = None if IMP is None else np.array(IMP[:k - 1]).reshape(k - 1, -1)
    return Trajectory.from_states(model, t[:k], np.array(Q), np.array(V), np.array(LAM[:k]), np.array(UU[:k]),
                                  p, dict(info), impulses=impulses)


def _interval_impulses(part: Trajectory) -> np.ndarray:
    """The impulse sums (N·s, ``(nk·dim,)`` in :func:`~ncgen.runtime.contact_outputs.impulse_outputs`'
    layout) of a one-interval nonsmooth run: its mean forces times the interval."""
    dt = float(part.t[-1] - part.t[0])
    return np.concatenate([part.contact_normal[-1][:, None], part.contact_tangent[-1]], axis=1).reshape(-1) * dt


def _interval_row(part: Trajectory) -> list:
    """One output interval's statistics in the columns of the fixed-step run's (``STATS``
    and, with nonsmooth contacts, ``CONTACT_STATS``); no error estimate (-1)."""
    stats, energy = part.info["stats"], part.info["energy"]
    parts = energy.get("parts", {})
    row = [stats["nsteps"], stats["newton_iterations"], stats.get("step_splits", 0), -1.0, -1.0,
           energy.get("work", 0.0)] + [parts.get(k, 0.0) for k in WORK_PARTS]
    if "contacts" in part.info:
        row += [part.info["contacts"][key] for key in CONTACT_STATS]
    return row


def _checked(model, opts: StepperOptions, traj: Trajectory, S: np.ndarray, after: str = "") -> Trajectory:
    """``traj`` with its energy report, checked unless ``check=False`` from the statistics
    ``S`` (one row per interval; ``after``: the failure that ended the run, or ""): fixed
    steps as a fixed-step run (:func:`~ncgen.runtime.stepper_checks.check_fixed`, raising
    where the run stops being trusted); error control, after a failure, as a failed
    error-controlled run (the rows before its energy error passes 1 %,
    :func:`~ncgen.runtime.stepper_checks.trusted_before_failure`)."""
    if not len(S):
        return traj
    conservative = is_conservative(model, inputs=bool(np.any(traj.u != 0)))
    S = S.copy()
    columns = [STATS.index("work")] + [STATS.index(f"work_{k}") for k in WORK_PARTS]
    S[:, columns] = np.cumsum(S[:, columns], axis=0)
    work = np.concatenate([[0.0], S[:, STATS.index("work")]])
    traj.info["energy"] = energy_report(traj, work, conservative, S)
    if not conservative:
        balance_report(model, traj.info["energy"], stepper_works(S))
    if not opts.check:
        return traj
    if opts.rtol is None:
        contacts = S.shape[1] > len(STATS)
        check_fixed(model, traj, S, float(traj.info.get("h", 0.0)), opts.substeps, contacts, conservative, after)
        return traj
    if not after:
        return traj
    kept, why = trusted_before_failure(model, traj, S, None)
    if why:
        message = (f"simulation of {model.name!r} with the error-controlled stepper is not trustworthy:{after}"
                   f"{why} The trajectory up to t = {kept.t[-1]:.6g} s is attached to this error as .trajectory.")
        kept.info.update(complete=False, message=message)
        raise SimulationError(message, time=float(kept.t[-1]), trajectory=kept)
    return traj
