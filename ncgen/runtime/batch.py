"""``simulate_batch``: many runs of one model through its compiled stepper in one call.

Each run is what ``nc.simulate(model, t_end, dt, method="stepper", ...)`` computes with the
same initial state, parameters and inputs, bit for bit (the same consistent initial state,
multipliers and compiled loop, ``<model>_simulate_stats``), and is checked as a single run
is (``check=True``: split steps, Newton iterations, energy, the shadow run's error estimate).
Runs are spread over ``workers`` threads; per run, a thread makes compiled calls only (the
loop, the multipliers and the outputs of its samples), each releasing the GIL, with a few
tens of µs of Python around them, so that the threads integrate in parallel however busy
the interpreter is.  The checks of all runs are then screened at once, in NumPy over the
batch's arrays (:meth:`_Runs.screen`): only a run the screen flags, or one that failed, is
checked on its own as a single run is, which names its reason.

A run that fails (Newton fails on a step even when halved, an initial state that cannot be
made consistent, parameters out of their limits) or fails its checks does not stop the
batch: ``status[i]`` is nonzero, ``message[i]`` says why, and its rows after the failure are
NaN.
"""
from __future__ import annotations

import ctypes
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

from ncgen.codegen.c_binding import open_library
from ncgen.codegen.stepper_abi import bind_stepper
from ncgen.codegen.stepper_package import MAX_HALVINGS, MAX_ITER, STATS, STATUS, TOL, n_stats
from ncgen.errors import NcgenError
from ncgen.model.rolling import refuse_rolling
from ncgen.runtime.dae import load_dae
from ncgen.runtime.energy_balance import nonsmooth_contacts
from ncgen.runtime.inputs import input_samples, parameter_values, time_grid
from ncgen.runtime.library import compiled_functions
from ncgen.runtime.run_start import initial_multipliers, initial_state, point_bytes
from ncgen.runtime.options import SimulationOptions
from ncgen.runtime.stepper import (COMPOSITION_STAGES, ESTIMATE_MODES, ESTIMATE_NAMES, StepperRows, StepperStart,
                                   _trajectory, fine_estimates, fixed_scheme, step_inputs)
from ncgen.runtime.stepper_checks import is_conservative, row_flags, untrusted_row
from ncgen.codegen.stepper_abi import RunOptions
from ncgen.runtime.stepper_library import step_options
from ncgen.runtime.table_stepper import load_any_stepper
from ncgen.validation import as_numbers, as_scalar

#: ``status`` of a run that could not start (its initial state, parameters or inputs).
STATUS_SETUP = -1
#: ``status`` of a run that completed but failed its checks (``check=True``).
STATUS_UNTRUSTED = -2
#: Runs handed to a thread at a time.
CHUNK = 8


@dataclass
class BatchResult:
    """Runs of :func:`simulate_batch`; arrays are shaped ``(batch, time, ...)``.

    ``t`` (s, shared by all runs); ``q``, ``v`` (batch, time, nq); ``lam`` (batch, time, nc);
    ``p`` (batch, np) the parameters of each run; ``status`` (0: complete; ``STATUS_SETUP``:
    not started; else the stepper's code, :data:`ncgen.codegen.stepper_package.STATUS`);
    ``message`` (empty for a complete run); ``newton_iterations`` per run; ``kinetic``,
    ``potential`` (J), ``constraint_residual`` (max |Φ|, m²) (batch, time), ``markers``
    (batch, time, n_markers, dim, m) when computed (``outputs=True``).  Rows of a failed
    run after its last completed output time are NaN."""

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    lam: np.ndarray
    p: np.ndarray
    status: np.ndarray
    message: list
    newton_iterations: np.ndarray
    kinetic: np.ndarray | None = None
    potential: np.ndarray | None = None
    constraint_residual: np.ndarray | None = None
    markers: np.ndarray | None = None
    info: dict = field(default_factory=dict)

    @property
    def ok(self) -> np.ndarray:
        """Which runs completed (``status == 0``)."""
        return self.status == 0

    def __len__(self) -> int:
        return len(self.status)

    def __repr__(self) -> str:
        return (f"<BatchResult: {len(self)} runs of {self.info.get('model')!r}, {len(self.t)} times, "
                f"{int(np.sum(~self.ok))} failed, {self.info.get('wall_time', 0):.3g} s>")


def simulate_batch(model, t_end: float, dt: float, *, q0=None, v0=None, p=None, u=None, t0: float | None = None,
                   hold: str = "zoh", substeps: int = 1, newton_tol: float = TOL, max_newton: int = MAX_ITER,
                   max_halvings: int = MAX_HALVINGS, ic_tolerance: float | None = 1e-6, project: bool = True,
                   check: bool = True, estimate: bool | str = True, scheme: str = "auto",
                   outputs: bool = True, workers: int | None = None, kernels: str = "auto") -> BatchResult:
    """Integrate ``model`` with its compiled stepper once per run, on ``workers`` threads
    (default: all cores), over the grid ``t0, t0 + dt, ..., t_end`` (s).

    Per run, as in :func:`ncgen.simulate` (``method="stepper"``, fixed steps):

    * ``q0``, ``v0``: ``None`` (the model's), one vector of ``nq`` values for every run, or
      one per run, shape ``(batch, nq)``;
    * ``p``: ``None`` (the model's), one parameter vector, one per run ``(batch, np)``, or a
      dict by name of scalars (all runs) or arrays of ``batch`` values (vector parameters:
      ``(batch, size)``);
    * ``u``: ``None`` (zeros), samples on the grid for every run ``(len(t), nu)`` or one set
      per run ``(batch, len(t), nu)`` (also ``len(t) − 1`` rows), held by ``hold``.

    The batch size is that of the per-run arguments (they must agree).  Where a run's
    ``q0``/``v0`` are given or its ``p`` differs from the model's, its initial state is
    projected onto the constraints as :func:`ncgen.simulate` does (``ic_tolerance``), in
    Python, a few milliseconds per run, chunk by chunk in the calling thread while the
    worker threads integrate the chunks before; ``project=False`` trusts the given states as
    consistent (only the multipliers ``λ0`` are computed, for all runs in one compiled
    call): then preparing a run costs about 20 µs, its KKT solve included.
    ``check`` (default): each run is checked as a single run is (split steps, exploding Newton
    iterations, energy drift, and, with ``estimate``, an estimated error above 1 % of the
    model's size: see :mod:`ncgen.runtime.stepper_checks`); an untrustworthy run gets
    ``STATUS_UNTRUSTED``, its rows from the problem on NaN, and the reason.  ``estimate``: the
    error estimate of the checks, as ``nc.simulate``'s (``True`` or ``"shadow"``: a shadow run
    with steps of 2h, about half the work again, and where Newton fails at 2h a run with steps of
    h/2 for that run; ``"local"``: a fifth, but it misses the growth
    of errors along a chaotic motion: on 48 runs of the 5-bar chain, 20 of them with errors
    above 1 % at h = 1 ms, the shadow run flagged exactly those 20 and the local estimate none;
    at 2 ms and 5 ms the shadow missed 1 of 22 and 0 of 30 bad runs, the local estimate 21 and
    17, benchmarks/batch_estimates.py; ``False``: none, the other checks stay).  ``check=False``: the bare compiled loop (fastest; choose ``dt`` with
    a checked run first).  ``outputs``: also the multipliers of the output states, the
    energies, constraint residuals and markers (compiled calls per run; always with ``check``).
    ``kernels``: the stepper's kernels, as ``SimulationOptions(kernels=...)`` chooses them
    (:func:`ncgen.runtime.table_stepper.stepper_kernels`): a model of the kinds the element
    tables cover runs on the element library (no compile of the model, no flat function for
    the multipliers; ``info["kernels"]``).
    Returns a :class:`BatchResult`; failed runs are reported there, never raised.
    """
    refuse_rolling(model, "simulate_batch", "run nc.simulate once per run (method 'rolling', 'idas' or 'stepper' "
                   "keep them), or nc.sweep(..., method='idas')")
    start = time.perf_counter()
    SimulationOptions(method="stepper", hold=hold, substeps=substeps, newton_tol=newton_tol, max_newton=max_newton,
                      max_halvings=max_halvings, ic_tolerance=ic_tolerance, scheme=scheme, estimate=estimate,
                      kernels=kernels)  # checked as for one run
    t0 = model.t0 if t0 is None else as_scalar(t0, "t0")
    t = time_grid(t0, t_end, dt, bytes_per_point=point_bytes(model))
    n = _batch_size(model, q0, v0, p, u, len(t))
    stepper = load_any_stepper(model, kernels=kernels)
    runs = _Runs(model, stepper, t, n, hold, int(substeps), newton_tol, max_newton, max_halvings, ic_tolerance,
                 outputs or check, check, fixed_scheme(model, scheme), estimate)
    workers = runs.workers = _workers(workers, n)
    pending = runs.prepare(q0, v0, p, u, project)      # projections: chunk by chunk, beside the threads
    chunks = [range(i, min(i + CHUNK, n)) for i in range(0, n, CHUNK)]
    stepping = time.perf_counter()
    if workers == 1:
        for c in chunks:
            if pending:
                pending(c)
            runs.integrate(c)
    else:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            futures = []
            for c in chunks:
                if pending:
                    pending(c)
                futures.append(pool.submit(runs.integrate, c))
            for f in futures:
                f.result()
    checking = time.perf_counter()
    if check:
        runs.check_all()
    end = time.perf_counter()
    result = runs.result()
    result.info.update(model=model.name, method="stepper", kernels=stepper.kernels, h=runs.h, substeps=runs.substeps,
                       hold=hold, check=check, estimate=ESTIMATE_NAMES[runs.mode] if check else False,
                       workers=workers, runs=n, stepping_time=checking - stepping, checking_time=end - checking,
                       checked_alone=runs.checked_alone, wall_time=end - start)
    return result


def _workers(workers, n: int) -> int:
    if workers is None:
        workers = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if int(workers) < 1:
        raise NcgenError(f"workers: expected a positive number of threads, got {workers!r}")
    return max(1, min(int(workers), n))


def _batch_size(model, q0, v0, p, u, n_t: int) -> int:
    """The number of runs the per-run arguments say (1 when none is per run)."""
    sizes = {}
    for name, value, single in (("q0", q0, 1), ("v0", v0, 1), ("u", u, 2)):
        if value is not None and not callable(value) and _ndim(value, name) == single + 1:
            sizes[name] = len(value)
    if isinstance(p, dict):
        unknown = [key for key in p if key not in model.parameter_names]
        if unknown:                        # a name is the call's, not one run's: refused at once
            from ncgen.model.expressions import did_you_mean
            raise NcgenError(f"simulate_batch: p: model {model.name!r} has no parameter {unknown[0]!r}"
                             f"{did_you_mean(str(unknown[0]), model.parameter_names)} (parameters: "
                             f"{', '.join(model.parameter_names) or 'none'})")
        for key, value in p.items():
            size = model.parameter_sizes[model.parameter_names.index(key)]
            if _ndim(value, f"p[{key!r}]") >= (1 if size == 1 else 2):
                sizes[f"p[{key!r}]"] = len(value)
    elif p is not None and _ndim(p, "p") == 2:
        sizes["p"] = len(p)
    if len(set(sizes.values())) > 1:
        said = ", ".join(f"{k}: {v}" for k, v in sizes.items())
        raise NcgenError(f"simulate_batch: the per-run arguments disagree on the number of runs ({said})")
    n = next(iter(sizes.values()), 1)
    if n < 1:
        raise NcgenError("simulate_batch: no runs (the per-run arguments are empty)")
    return n


def _ndim(value, what: str) -> int:
    """``np.ndim(value)``, or an error naming ``what`` when its rows differ in length."""
    try:
        return np.ndim(value)
    except ValueError:
        raise NcgenError(f"simulate_batch: {what}: the runs' values are ragged (rows of different lengths); "
                         "expected one row per run, all of one shape") from None


class _Runs:
    """Inputs and result buffers of the runs, and the loop over a chunk of them."""

    def __init__(self, model, stepper, t, n, hold, substeps, tol, max_iter, max_halvings, ic_tolerance, outputs,
                 check, scheme: str = "rattle", estimate: bool | str = True):
        self.model, self.stepper, self.t, self.n, self.check = model, stepper, t, n, check
        self.mode = ESTIMATE_MODES[estimate] if check and estimate and not stepper.nd else 0
        self.checked_alone = 0       # runs checked on their own (failed, or flagged by the screen)
        self.tables = stepper.kernels == "tables"
        self.conservative = is_conservative(model) if check else True
        self.hold, self.substeps, self.ic_tolerance, self.outputs = hold, substeps, ic_tolerance, outputs
        self.h = float(t[1] - t[0]) / substeps
        self.n_out = len(t) - 1
        self.rattle4 = scheme == "rattle4"
        self._options = step_options(tol, max_iter, max_halvings, int(self.rattle4))
        self.options = ctypes.byref(self._options)
        self._run = RunOptions(estimate=self.mode, track_work=int(not self.conservative))
        self.run_options = ctypes.byref(self._run)
        nq, nc, T = model.nq, model.nc, len(t)
        self.Q, self.V = np.full((n, T, nq), np.nan), np.full((n, T, nq), np.nan)
        self.LAM = np.full((n, T, nc), np.nan)
        self.ITER = np.zeros((n, self.n_out), dtype=np.dtype(ctypes.c_long))
        self.STATS = np.zeros((n, self.n_out, n_stats(stepper.nd))) if check else None
        self.rows = np.zeros(n, dtype=int)       # output rows each run completed
        self.P = np.zeros((n, model.np))
        self.U = [None] * n          # inputs on the grid (len(t), nu) per run
        self.US = [None] * n         # inputs per step, or None
        self.status = np.zeros(n, dtype=int)
        self.message = [""] * n
        self.Y = np.full((n, T, stepper.nout), np.nan) if outputs else None

    def prepare(self, q0, v0, p, u, project: bool):
        """Parameters, consistent initial state, multipliers and inputs of the runs (a run
        whose setup fails gets ``STATUS_SETUP`` and the reason).  States as given
        (``project=False``): every run now, their ``λ0`` in one compiled call, and None is
        returned; else a function that prepares the runs of a chunk (Python, milliseconds per
        run), to be called chunk by chunk while the threads integrate the chunks before."""
        model, t, t0 = self.model, self.t, float(self.t[0])
        # the flat DAE names the cause of a singular KKT system (the tables' runs load it only then)
        dae = load_dae(model, "vm")[0] if project and not self.tables else None
        per_run_u = u is not None and not callable(u) and np.ndim(u) == 3
        if not per_run_u:
            U = input_samples(u, model, t)
            shared_u = (U, step_inputs(U, t, self.hold, self.substeps))

        def runs(chunk: range) -> None:
            for i in chunk:
                try:
                    self.P[i] = pv = model.p0 if p is None else parameter_values(_pick_p(p, i, model), model)
                    if project:
                        q, v = initial_state(model, _pick(q0, i, 1), _pick(v0, i, 1), t0, pv, self.ic_tolerance)
                        self.Q[i, 0], self.V[i, 0] = q, v
                    if per_run_u:
                        U = input_samples(u[i], model, t)
                        self.U[i], self.US[i] = U, step_inputs(U, t, self.hold, self.substeps)
                    else:
                        self.U[i], self.US[i] = shared_u
                    if project:
                        self.LAM[i, 0] = self._initial_multipliers(t0, q, v, self.U[i][0], pv, dae)
                except NcgenError as e:
                    self.status[i], self.message[i] = STATUS_SETUP, f"could not start: {e}"
                    self.Q[i, 0] = self.V[i, 0] = np.nan

        if project:
            return runs
        self.Q[:, 0] = _states(q0, model.q0, self.n, model.nq, "q0")     # states as given: checked at once
        self.V[:, 0] = _states(v0, model.v0, self.n, model.nq, "v0")
        runs(range(self.n))
        self._multipliers(t0)
        return None

    def _initial_multipliers(self, t0: float, q, v, u, p, dae) -> np.ndarray:
        """``λ0`` of one run: from the element tables on their path, else (or to name the cause
        of a singular KKT system) from the flat functions."""
        if self.tables:
            lam = self.stepper.multipliers(q, v, u)
            if np.all(np.isfinite(lam)):
                return lam
            dae = load_dae(self.model, "vm")[0]
        return initial_multipliers(self.model, t0, q, v, u, p, dae)

    def _accel(self):
        """The compiled ``accel`` of the flat path; None on the tables' (their multipliers)."""
        return None if self.tables else _compiled_accel(self.model)

    def _multipliers(self, t0: float) -> None:
        """``λ0`` of every run from the KKT system, in one call: the compiled ``accel`` (the same
        operations as the model's CasADi function, so the same bits) mapped over the runs."""
        model, n = self.model, self.n
        if not model.nc:
            return
        U0 = np.array([self.U[i][0] for i in range(n)]).reshape(n, model.nu)
        if self.tables:
            lam = self.stepper.multipliers(self.Q[:, 0], self.V[:, 0], U0)
        else:
            accel = _compiled_accel(model).map(n, "thread", self.workers)
            lam = np.array(accel(t0, self.Q[:, 0].T, self.V[:, 0].T, U0.T, self.P.T)[1]).T
        ok = self.status == 0
        self.LAM[ok, 0] = lam[ok]
        for i in np.flatnonzero(ok & ~np.all(np.isfinite(lam), axis=1)):
            self.status[i] = STATUS_SETUP
            self.message[i] = (f"could not start: the KKT system [[M, A^T], [A, 0]] is singular at "
                               f"t0 = {t0:g} s (a singular configuration, or the state is not consistent: "
                               f"project=True makes it so)")

    def integrate(self, chunk: range) -> None:
        """The compiled loop over the runs of ``chunk``, then their multipliers and outputs
        (:meth:`_derived`): compiled calls, each releasing the GIL."""
        st, raw = self.stepper, _raw_loops(self.model, self.stepper)
        done, splits = ctypes.c_long(0), ctypes.c_long(0)
        n_steps = self.n_out * self.substeps
        extra = [None] if st.nd else []
        Q, V, L = (_Address(a) for a in (self.Q, self.V, self.LAM))
        p_at, iter_at = _Address(self.P), _Address(self.ITER)
        stats_at = _Address(self.STATS) if self.check else None
        started = []
        for i in chunk:
            if self.status[i] != 0:
                continue
            started.append(i)
            US = self.US[i]
            common = (float(self.t[0]), self.h, n_steps, self.substeps, _ptr(US), st.nu if US is not None else 0,
                      p_at(i), Q(i, 1), V(i, 1), L(i, 1))
            if self.check:
                status = raw.simulate_stats(Q(i, 0), V(i, 0), L(i, 0), *common, stats_at(i), self.options,
                                            self.run_options, ctypes.byref(done),
                                            ctypes.byref(splits), *extra)
                self.ITER[i] = self.STATS[i, :, STATS.index("newton_iterations")]
            else:
                status = raw.simulate(Q(i, 0), V(i, 0), *common, iter_at(i), self.options, ctypes.byref(done),
                                      ctypes.byref(splits), *extra)
            self.rows[i] = rows = done.value // self.substeps
            if status != 0:
                self.status[i] = status
                t_fail = float(self.t[0]) + done.value * self.h
                self.message[i] = (f"the stepper failed in the step from t = {t_fail:.6g} s to "
                                   f"{t_fail + self.h:.6g} s: {STATUS.get(status, f'status {status}')}")
                self._blank(i, rows + 1)
        if self.Y is not None:
            self._derived(started)

    def _derived(self, runs: list) -> None:
        """The multipliers of the output states (as a single run's trajectory has them: the
        tables' KKT solve, the compiled ``accel`` mapped over the samples of all ``runs`` in
        one call, or with nonsmooth contacts the stepper's own) and the outputs of the
        compiled ``<model>_outputs``, of the completed rows of ``runs``."""
        model, st, t = self.model, self.stepper, self.t
        k = {i: int(self.rows[i]) + 1 for i in runs}
        U = {i: self.U[i][:k[i]] if model.nu else None for i in runs}
        if self.tables:
            for i in runs:
                if k[i] > 1:
                    self.LAM[i, 1:k[i]] = st.multipliers(self.Q[i, 1:k[i]], self.V[i, 1:k[i]],
                                                         None if U[i] is None else U[i][1:])
        elif not nonsmooth_contacts(model):
            self._flat_multipliers([i for i in runs if k[i] > 1], k)
        for i in runs:
            self.Y[i, :k[i]] = st.outputs(t[:k[i]], self.Q[i, :k[i]], self.V[i, :k[i]], self.LAM[i, :k[i]], U[i],
                                          self.P[i])

    def _flat_multipliers(self, runs: list, k: dict) -> None:
        """``λ`` at the output rows ``1 .. k[i] − 1`` of ``runs`` by the compiled ``accel``
        mapped over all those samples in one call (each sample's evaluation is the one
        :func:`~ncgen.runtime.dynamics_at_state.multipliers_at_samples` makes for a single run)."""
        if not runs or not self.model.nc:
            return
        model, t = self.model, self.t
        rows = [(i, r) for i in runs for r in range(1, k[i])]
        ii, rr = np.array([i for i, _ in rows]), np.array([r for _, r in rows])
        U = np.array([self.U[i][r] for i, r in rows]).reshape(len(rows), model.nu)
        _, lam = _compiled_accel(model).map(len(rows))(t[rr][None, :], self.Q[ii, rr].T, self.V[ii, rr].T, U.T,
                                                       self.P[ii].T)
        self.LAM[ii, rr] = np.array(lam).reshape(model.nc, len(rows)).T

    def check_all(self) -> None:
        """The checks of every started run (``check=True``): :meth:`screen` over the batch,
        then each run it flags, and each run that failed, checked on its own as a single run
        is (:meth:`_checked`, which names the reason)."""
        started = self.status != STATUS_SETUP
        alone = started & ((self.status != 0) | self.screen())
        for i in np.flatnonzero(alone):
            self._checked(i, int(self.rows[i]), self.STATS[i])
        self.checked_alone = int(np.sum(alone))

    def screen(self) -> np.ndarray:
        """Per run: whether the checks of :func:`~ncgen.runtime.stepper_checks.untrusted_row`
        (its :func:`~ncgen.runtime.stepper_checks.row_flags`) may flag it, evaluated over all runs
        at once from their statistics and outputs.  The
        energy error is measured against the energy scale without the round-off floor, which
        only raises the scale, so every run the single-run check flags is flagged here too
        (and a run flagged here only for round-off passes its own check).  Every run with
        nonsmooth contacts is flagged (their checks are the contact stepper's), and every run
        whose shadow run failed (its estimate then comes from a run with steps of h/2)."""
        if self.stepper.nd:
            return np.ones(self.n, dtype=bool)
        S, Y, col = self.STATS, self.Y, STATS.index
        kinetic, potential = Y[:, :, 0], Y[:, :, 1]
        E = kinetic + potential
        work = np.concatenate([np.zeros((self.n, 1)), S[:, :, col("work")]], axis=1)
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            error = np.abs(E - E[:, :1] - (0.0 if self.conservative else work))[:, 1:]
            terms = np.abs(np.stack([E, kinetic, potential - potential[:, :1], work])).max(axis=0)
            scale = np.maximum.accumulate(terms, axis=1)[:, 1:]
            e_rel = error / np.maximum(scale, 1e-300)
        e_rel = np.where(np.isnan(e_rel), np.inf, e_rel)
        size = max(float(np.max(np.abs(self.model.q0), initial=0.0)), 1e-9)
        flags = row_flags(S[:, :, col("splits")], S[:, :, col("newton_iterations")], S[:, :, col("steps")],
                          COMPOSITION_STAGES if self.rattle4 else 1, e_rel, S[:, :, col("error_q")], size,
                          error_q=S[:, :, col("error_q")])
        flags["shadow_failed"] = S[:, :, col("error_q")] == -2   # its estimate from a run at h/2: checked alone
        return np.logical_or.reduce(list(flags.values())).any(axis=1)

    def _checked(self, i: int, rows: int, S: np.ndarray) -> None:
        """Outputs of run ``i`` and the checks of a single run (:func:`untrusted_row`), the
        estimate from a run at h/2 where its shadow run failed (:func:`fine_estimates`)."""
        model, Q, V, LAM = self.model, self.Q[i], self.V[i], self.LAM[i]
        start = StepperStart(self.t, self.U[i], self.P[i], Q[0], V[0], LAM[0])
        if self.mode == ESTIMATE_MODES["shadow"]:
            fine_estimates(self.stepper, start, StepperRows(Q[1:], V[1:], LAM[1:], S, rows), self.hold, self.substeps,
                           self._options, 4 if self.rattle4 else 2)
        info = {"method": "stepper", "h": self.h, "substeps": self.substeps, "stats": {},
                "stages": COMPOSITION_STAGES if self.rattle4 else 1, "order": 4 if self.rattle4 else 2,
                "estimate": ESTIMATE_NAMES[self.mode]}
        traj = _trajectory(model, self.stepper, start, StepperRows(Q[1:], V[1:], LAM[1:], S, rows), info,
                           self.conservative, time.perf_counter(), accel=self._accel())
        LAM[:rows + 1] = traj.lam
        self.Y[i, :rows + 1, 0], self.Y[i, :rows + 1, 1] = traj.kinetic, traj.potential
        self.Y[i, :rows + 1, 2] = traj.constraint_residual
        self.Y[i, :rows + 1, 5:] = traj.markers.reshape(rows + 1, -1)
        bad = untrusted_row(model, traj, S[:rows], self.h, contacts=self.stepper.nd > 0)
        if bad is not None:            # also before a failed step: only trusted rows are kept
            row, reason = bad
            later = f". Later, {self.message[i]}" if self.status[i] != 0 else ""
            self.status[i] = STATUS_UNTRUSTED if self.status[i] == 0 else self.status[i]
            self.message[i] = f"not trustworthy: {reason}{later}"
            self._blank(i, row + 1)

    def _blank(self, i: int, k: int) -> None:
        """Rows ``k`` on of run ``i`` set to NaN (after a failure)."""
        self.Q[i, k:] = self.V[i, k:] = self.LAM[i, k:] = np.nan
        if self.Y is not None:
            self.Y[i, k:] = np.nan

    def result(self) -> BatchResult:
        model, Y = self.model, self.Y
        out = {}
        if Y is not None:
            n_m = len(model.marker_names)
            out = dict(kinetic=Y[:, :, 0], potential=Y[:, :, 1], constraint_residual=Y[:, :, 2],
                       markers=Y[:, :, 5:].reshape(self.n, len(self.t), n_m, model.dim))
        return BatchResult(t=self.t, q=self.Q, v=self.V, lam=self.LAM, p=self.P, status=self.status,
                           message=self.message, newton_iterations=self.ITER.sum(axis=1), **out)


def _pick(value, i: int, single_ndim: int):
    """Run ``i``'s value of a per-run argument (or the shared one)."""
    if value is None or np.ndim(value) == single_ndim:
        return value
    return value[i]


def _pick_p(p, i: int, model):
    if isinstance(p, dict):
        out = {}
        for key, value in p.items():
            size = model.parameter_sizes[model.parameter_names.index(key)] if key in model.parameter_names else 1
            out[key] = value[i] if np.ndim(value) >= (1 if size == 1 else 2) else value
        return out
    return _pick(p, i, 1)


def _states(given, default, n: int, nq: int, name: str) -> np.ndarray:
    """``(n, nq)`` states from ``None`` (``default``), one vector, or one per run."""
    if given is None:
        return np.broadcast_to(default, (n, nq))
    a = as_numbers(given, name, f"{nq} values or an array of shape ({n}, {nq})")
    if a.shape not in ((nq,), (n, nq)):
        raise NcgenError(f"{name}: expected {nq} values or an array of shape ({n}, {nq}), got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a.reshape(-1, nq)))[0]
        raise NcgenError(f"{name}: run {bad[0]} has a non-finite value at coordinate {bad[1]}")
    return np.broadcast_to(a, (n, nq))


def _ptr(a):
    return None if a is None or a.size == 0 else a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


class _Address:
    """``addr(i, k)``: address of ``A[i, k]`` (of ``A[i]`` with one index) as an integer, or
    None for an empty array (the raw loops take addresses: the per-run cost stays at µs)."""

    def __init__(self, A: np.ndarray):
        self.base = A.ctypes.data if A.size else None
        self.strides = A.strides

    def __call__(self, i: int, k: int = 0):
        if self.base is None:
            return None
        return self.base + i * self.strides[0] + (k * self.strides[1] if k else 0)


def _compiled_accel(model):
    """The model's compiled ``accel`` (loaded once per model, kept in its data)."""
    data = model.data
    if data.batch_accel is None:
        data.batch_accel = compiled_functions(model, ["accel"])["accel"]
    return data.batch_accel


def _raw_loops(model, stepper):
    """``<model>_simulate`` and ``_simulate_stats`` of ``stepper``'s library bound with
    address arguments (``c_void_p``: plain integers pass without conversion objects; kept in
    the model's data by library), from the one table of
    :mod:`ncgen.codegen.stepper_abi`."""
    if stepper.kernels == "tables":
        return stepper.raw_loops()
    loops = model.data.batch_loops
    if stepper.library not in loops:
        lib = open_library(stepper.library)
        raw = bind_stepper(lib, stepper.name, bool(stepper.nd), ("simulate", "simulate_stats"), addresses=True)
        loops[stepper.library] = SimpleNamespace(simulate=raw.simulate, simulate_stats=raw.simulate_stats, lib=lib)
    return loops[stepper.library]
