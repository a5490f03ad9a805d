"""The compiled stepper behind the integrator seam (:mod:`ncgen.runtime.integrator`):
:func:`ncgen.runtime.stepper.simulate_stepper` over the whole grid, or one output interval at
a time when a Python feedback sets the inputs."""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from ncgen.errors import CompilerNotFound, NcgenError, SimulationError, option
from ncgen.runtime.feedback import FeedbackFailed, with_partial
from ncgen.runtime.integrator import Run, refuse_integrator
from ncgen.runtime.run_start import failed_at_start
from ncgen.runtime.options import SimulationOptions
from ncgen.runtime.stepper import simulate_stepper
from ncgen.runtime.stepper_library import load_stepper
from ncgen.runtime.trajectory import Trajectory

NO_CONTROLLER = ("method='stepper' does not take a compiled controller or joint_dynamics=True; use method='joint' "
                 "(trees) or 'idas', or give u as a Python callable u(t, q, v)")


class StepperIntegrator:
    """``method="stepper"``: the model's compiled RATTLE stepper (fixed steps or error
    control), compiled when prepared."""

    METHOD = "stepper"
    OPTIONS = ("rtol", "atol", "hold", "max_steps", "substeps", "newton_tol", "max_newton", "max_halvings",
               "order", "scheme", "check", "estimate")

    def __init__(self, model, opts: SimulationOptions):
        refuse_integrator(opts, self.METHOD)
        if opts.joint_dynamics:
            raise NcgenError(NO_CONTROLLER)
        self.model, self.opts = model, opts

    def _load(self) -> None:
        try:
            load_stepper(self.model)
        except CompilerNotFound as e:
            stepper, idas = option("method='stepper'", "--method stepper"), option("method='idas'", "--method idas")
            raise CompilerNotFound(f"{e}: the stepper ({stepper}) is generated C and needs one; install gcc, "
                                   f"or use IDAS ({idas}), which runs on CasADi's virtual machine") from None

    def run(self, run: Run) -> Trajectory:
        if run.controller is not None:
            raise NcgenError(NO_CONTROLLER)
        if run.feedback is not None:
            return _stepwise(self.model, run, self.opts)
        lam = run.multipliers(float(run.t[0]), run.q, run.v, run.U[0])
        self._load()
        return simulate_stepper(self.model, run.t, run.U, run.p, run.q, run.v, lam, self.opts)


def _stepwise(model, run: Run, opts: SimulationOptions) -> Trajectory:
    """The compiled stepper one output interval at a time, the feedback evaluated at the
    start of each (checks and the shadow error estimate off: they need the whole run)."""
    if opts.hold != "zoh":
        raise NcgenError("hold='linear' with a feedback u(t, q, v): the feedback is held over each output "
                         "interval (zoh); use hold='zoh'")
    t, p, feedback = run.t, run.p, run.feedback
    step_opts = dataclasses.replace(opts, method="stepper", check=False, estimate=False)
    Q, V, LAM, UU = [run.q], [run.v], [], []
    start = time.perf_counter()
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
            info = {"method": "stepper", "feedback": feedback[0]}
            raise with_partial(e, Trajectory.from_states(model, t[:k + 1], np.array(Q), np.array(V), np.array(LAM),
                                                          np.array(UU), p, info)) from e.__cause__
        lam = run.multipliers(float(t[k]), Q[-1], V[-1], uk)
        LAM.append(lam)
        UU.append(uk)
        try:
            part = simulate_stepper(model, t[k:k + 2], np.vstack([uk, uk]), p, Q[-1], V[-1], lam, step_opts)
        except SimulationError as e:
            info = {"method": "stepper", "feedback": feedback[0], "complete": False, "message": str(e)}
            traj = Trajectory.from_states(model, t[:k + 1], np.array(Q), np.array(V), np.array(LAM),
                                          np.array(UU), p, info)
            raise SimulationError(str(e), time=float(t[k]), trajectory=traj) from None
        Q.append(part.q[-1])
        V.append(part.v[-1])
    LAM.append(part.lam[-1])
    UU.append(UU[-1])
    info = {"method": "stepper", "backend": "compiled", "feedback": feedback[0], "hold": "zoh",
            "wall_time": time.perf_counter() - start, "complete": True, "substeps": opts.substeps,
            **({"rtol": opts.rtol, "atol": opts.rtol if opts.atol is None else opts.atol} if opts.rtol else {})}
    return Trajectory.from_states(model, t, np.array(Q), np.array(V), np.array(LAM), np.array(UU), p, info)
