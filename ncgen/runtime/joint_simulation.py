"""Simulation of trees in joint space: ``x = [q_j; v_j]`` integrated by a compiled C loop
around the joint-space forward dynamics (``simulate(method="joint")``, chosen by
``method="auto"`` for every model it applies to, :func:`joint_space_applies`).

* Equations: :mod:`ncgen.assembly.joint_ode` (``q̇_j = Q(q_j) v_j``, ``v̇_j = a_j`` from the
  recursive kernel of :mod:`ncgen.runtime.tree_kernel`, a compiled controller and the joint
  dynamics law inlined); loop: ``templates/c/runtime/ncgen_joint_loop.h`` with the glue
  ``templates/c/joint_loop.c.j2``, generated and compiled once
  per model, controller and options (:mod:`ncgen.codegen.joint_loop`, cached by content).
* Integrators (``integrator=``): ``"dopri5"`` (default) — Dormand–Prince 5(4), error
  controlled by ``rtol``/``atol`` on ``q_j`` and ``v_j`` (Hairer's step control), outputs by
  its 4th-order dense output when the inputs do not jump, else restarted at every output
  time; ``"rk4"`` — classical RK4, ``substeps`` equal steps per output interval.
* Rotations: a spherical or free joint's unit quaternion is integrated by its rate
  ``½ q ⊗ [ω; 0]`` (the dynamics see ``q / |q|``) and renormalised after every step (and
  at every dense output), so it stays on the unit sphere to round-off.
* Inputs: held samples ``w`` (``hold`` zoh/linear, the integrator restarts at each output
  time), a Python callable called once per output interval at its start (state feedback,
  held over the interval), or a compiled controller (``u=nc.PD(...)``, no Python per step).
* Outputs: the trajectory's natural coordinates, markers, energies and multipliers (the KKT
  system at each output time) are derived from the joint states; ``traj.qj``/``traj.vj``
  are the integrated joint states (angles not wrapped).
"""
from __future__ import annotations

import ctypes
import math
import time

import casadi as ca
import numpy as np

from ncgen.codegen.c_binding import address
from ncgen.codegen.compiler import compiler_present, find_compiler
from ncgen.codegen.tree_check import PIVOT_TOL
from ncgen.codegen.tree_kernels import JOINT_KINDS
from ncgen.codegen.tree_tables import UnsupportedTree, tree_tables
from ncgen.codegen.joint_loop import INTERRUPTED, JointOptions, integrator_name, joint_options, run_options
from ncgen.environment import getenv_key
from ncgen.errors import CompilerNotFound, ModelError, NcgenError, SimulationError, SimulationInterrupted, option
from ncgen.runtime.feedback import FeedbackFailed, call_feedback, with_partial
from ncgen.runtime.integrator import Run
from ncgen.runtime.joint_loop_options import JointLoopOptions
from ncgen.interrupts import call_interruptibly
from ncgen.model.data import model_data
from ncgen.runtime.backend_policy import Choice, choose_joint_kernels
from ncgen.progress import enabled as progress_enabled
from ncgen.runtime.simulation_progress import Progress
from ncgen.runtime.trajectory import Derived, Trajectory, output_names
from ncgen.runtime.tree_library import TableJointLoop, input_efforts

#: The run is cut into at most this many calls of the C loop when a progress bar may be drawn
#: (its updates; else one call).
CHUNKS = 20
_STATUS = {1: "the joint-space mass matrix is singular or the accelerations are not finite",
           2: "the integrator needed more than max_steps steps for one output interval (a stiff motion: "
              "a stiff joint limit or friction law; raise max_steps, loosen rtol, or use method='idas')",
           3: "the step size fell to round-off (a discontinuity or a stiff law)"}


def joint_space_applies(model) -> str | None:
    """Why ``model`` cannot be simulated in joint space, or None when it can: a tree of joints
    with coordinates and no other constraints (:func:`~ncgen.runtime.tree_kernel.check_tree`),
    no contacts, and a C compiler."""
    data = model_data(model)
    if data.joint_simulation_reason is not None:
        return data.joint_simulation_reason[0]
    from ncgen.runtime.tree_kernel import check_tree

    reason = ""
    if getattr(model, "nk", 0):
        reason = "the model has contacts"
    else:
        try:
            check_tree(model)
        except ModelError as e:
            reason = str(e)
        if not reason:
            try:
                find_compiler()
            except CompilerNotFound as e:
                reason = "" if _table_loop(model) is not None else str(e)
    data.joint_simulation_reason = (reason or None,)
    return reason or None


def _table_loop(model):
    """The joint-space loop of ``model`` on the tree tables
    (:class:`~ncgen.runtime.tree_library.TableJointLoop`, built once per model), or None when
    the tables do not cover it or there is no tree library and no compiler."""
    loops = model_data(model).joint_loops
    if "tables" not in loops:
        try:
            loops["tables"] = TableJointLoop(model)
        except (UnsupportedTree, CompilerNotFound):
            loops["tables"] = None
    return loops["tables"]


class JointLoop:
    """The compiled loop of one model, controller and joint-dynamics choice."""

    kernels = "flat"

    def __init__(self, model, library, ode: ca.Function, name: str):
        from ncgen.assembly.joint_ode import quaternion_offsets
        from ncgen.codegen.c_binding import ThreadWork, bind, open_library
        from ncgen.codegen.joint_loop import JOINT_RUN, JOINT_WORK_SIZE, JointOptions
        from ncgen.codegen.tree_check import tree_function

        self.model, self.ode, self.library = model, ode, library
        self._lib = open_library(library)
        self._fn = bind(self._lib, f"{name}_joint_run", JOINT_RUN, structs={"ncgen_joint_options": JointOptions},
                        addresses=True)
        #: The calling thread's work array and its address (the library's ``joint_work_size`` doubles).
        self.work = ThreadWork(bind(self._lib, f"{name}_joint_work_size", JOINT_WORK_SIZE)())
        self.quat = np.array(quaternion_offsets(model.joint_space), dtype=np.int32)
        self._quat = address(self.quat)                 # taken once
        self.tree = tree_function(model)
        self._maps: dict = {}

    def mapped(self, what: str, n: int) -> ca.Function:
        """``what`` (``"tree"``, ``"ode"``, ``"accel"``) evaluated at ``n`` points in one call."""
        key = (what, n)
        if key not in self._maps:
            f = {"tree": self.tree, "ode": self.ode, "accel": self.model.functions["accel"]}[what]
            self._maps[key] = f.map(n)
        return self._maps[key]

    def run(self, options: JointOptions, t: np.ndarray, X: np.ndarray, W: np.ndarray, S, p: np.ndarray,
            stats: np.ndarray) -> tuple[int, int]:
        """Integrate over the grid ``t`` (``X[0]`` given, the rest written) with the options
        ``options`` (:class:`~ncgen.codegen.joint_loop.JointOptions`, passed to C whole);
        ``(status, k_done)``, status :data:`INTERRUPTED` after Ctrl-C (its stop flag set,
        :func:`~ncgen.interrupts.call_interruptibly`)."""
        done = ctypes.c_int(0)
        status, interrupted = call_interruptibly(
            self._fn, ctypes.addressof(options), len(t) - 1, address(t), address(X), address(W),
            None if S is None else address(S), address(p), len(self.quat), self._quat, address(stats),
            ctypes.addressof(done), self.work.address, stop=options.stop.contents)
        return INTERRUPTED if interrupted else int(status), int(done.value)


def dynamics_function(model) -> ca.Function:
    """The kernel's SX function ``(t, qj, vj, u, p) -> (aj, check)``: recursive in 3D (rigid
    bodies), else the projected form (as :func:`~ncgen.runtime.tree_kernel.joint_forward_dynamics_kernel`
    with ``method="auto"``)."""
    from ncgen.assembly.tree_dynamics import recursive_dynamics_function, tree_dynamics_function

    if model.joint_space.dim == 3:
        try:
            return recursive_dynamics_function(model)
        except ModelError:
            pass
    return tree_dynamics_function(model)


def choose_kernels(model, outputs: int, controller=None, joint_dynamics: bool = False, kernels: str = "auto"):
    """The :class:`~ncgen.runtime.backend_policy.Choice` of the joint loop's kernels for a run
    over ``outputs`` output intervals: ``"tables"`` — the tree library's loop on the model's
    tables (:class:`~ncgen.runtime.tree_library.TableJointLoop`: no controller, no joint
    dynamics, a tree the tables cover; nothing compiled for the model), ``"flat"`` — the
    model's own ODE compiled with the loop; ``kernels="auto"`` as
    :func:`~ncgen.runtime.backend_policy.choose_joint_kernels` rules (the tables where no C
    compiler is present), else the user's choice."""

    if kernels not in ("auto", "tables", "flat"):
        raise NcgenError(f"kernels: expected one of 'auto', 'tables', 'flat', got {kernels!r}")
    if kernels != "auto":
        return Choice(kernels, "chosen")
    if controller is not None or joint_dynamics:
        return Choice("flat", "the tables' loop takes no compiled controller and no joint dynamics")
    if model.np:
        return Choice("flat", "the tables' loop takes no parameters")
    if not compiler_present():
        return Choice("tables", "no C compiler") if _table_loop(model) is not None else \
            Choice("flat", "the tree tables do not cover the model")
    ready = _flat_ready(model)
    kinds = _table_kinds(model)
    if ready is None and kinds is None:
        return Choice("flat", "the tree tables do not cover the model")
    return choose_joint_kernels(model.joint_space.nv, outputs, ready, _missing_units(model, kinds))


def _table_kinds(model) -> tuple[str, ...] | None:
    """The joint kinds of ``model``'s tree tables when the tables' loop covers it (its tables
    and constant input efforts; nothing loaded or compiled), else None; found once per model."""
    data = model_data(model)
    if data.table_kinds is None:
        try:
            kinds = tree_tables(model).arrays["kind"]
            input_efforts(model)
            data.table_kinds = (tuple(sorted({JOINT_KINDS[int(k)].name for k in kinds})),)
        except UnsupportedTree:
            data.table_kinds = (None,)
    return data.table_kinds[0]


def _missing_units(model, kinds) -> tuple[str, ...]:
    """The tree library's units the tables' loop of ``model`` (joint kinds ``kinds``, or None)
    needs that are not compiled yet: none once that loop is loaded in this process."""
    if kinds is None or model_data(model).joint_loops.get("tables") is not None:
        return ()
    from ncgen.runtime import tree_library          # (its attribute: tests replace it)

    return tuple(tree_library.missing_units(kinds, "forward"))


def _flat_ready(model) -> str | None:
    """Why the model's own loop (no controller, no joint dynamics) is ready without a compile
    — loaded in this process, or its ODE stored beside the model and its library in the
    compile cache (looked up once per model and process) — or None."""
    data = model_data(model)
    if (id(None), False, None) in data.joint_loops:
        return "loaded in this process"
    if data.flat_loop_stored is None:
        from ncgen.codegen.joint_loop import cached_joint_loop
        from ncgen.codegen.model_cache import stored_function

        ode = stored_function(model, "joint-ode")
        data.flat_loop_stored = ("compiled earlier, in the compile cache" if ode is not None and cached_joint_loop(
            f"{model.name}_jsim", ode, PIVOT_TOL) is not None else None,)
    return data.flat_loop_stored[0]


def joint_loop(model, controller=None, joint_dynamics: bool = False, cflags=None, kernels: str = "auto"):
    """The compiled loop (built on first use per model, controller object and option) with the
    kernels ``kernels`` (``"tables"``, ``"flat"``, or ``"auto"``: :func:`choose_kernels` for a
    short run)."""
    if kernels == "auto":
        kernels = choose_kernels(model, 1, controller, joint_dynamics).backend
    if kernels not in ("tables", "flat"):
        raise NcgenError(f"kernels: expected one of 'auto', 'tables', 'flat', got {kernels!r}")
    if kernels == "tables":
        return _loop_on_tables(model, controller, joint_dynamics)
    from ncgen.codegen.joint_loop import build_joint_loop

    loops = model_data(model).joint_loops
    key = (id(controller), bool(joint_dynamics), cflags)
    hit = loops.get(key)
    if hit is not None and hit[0] is controller:
        return hit[1]
    why = joint_space_applies(model)
    if why is not None:
        raise ModelError(f"simulate(method='joint'): model {model.name!r} cannot be simulated in joint space: {why}")
    from ncgen.codegen.model_cache import derived_function

    # without a controller the ODE is the model's alone: stored beside a stored model
    ode = _joint_ode(model, controller, joint_dynamics) if controller is not None else \
        derived_function(model, "joint-ode-armature" if joint_dynamics else "joint-ode",
                         lambda: _joint_ode(model, controller, joint_dynamics))
    name = f"{model.name}_jsim"
    loop = JointLoop(model, build_joint_loop(name, ode, PIVOT_TOL, cflags), ode, name)
    loops[key] = (controller, loop)
    return loop


def _loop_on_tables(model, controller, joint_dynamics: bool):
    """``kernels="tables"``: the element tables' loop where the model has one, else the tree
    tables' (neither takes a compiled controller or the joint dynamics)."""
    if controller is None and not joint_dynamics:
        table = _table_loop(model)
        if table is not None:
            return table
    if controller is not None or joint_dynamics:
        raise NcgenError("kernels='tables': the joint-space loop on the tree tables takes no compiled "
                         "controller and no joint dynamics (use kernels='flat' or 'auto')")
    tree_tables(model)                  # raises UnsupportedTree naming what is not covered
    return TableJointLoop(model)        # or the reason it cannot be built


def _joint_ode(model, controller, joint_dynamics: bool):
    """The joint-space ODE of the loop: the model's dynamics (with the joints' armature where
    ``joint_dynamics`` gives one; the recursive inverse dynamics for it and for a
    computed-torque ``controller``) closed by the controller and the joint dynamics."""
    from ncgen.assembly.joint_ode import armature_dynamics_function, armature_vector, joint_ode_function
    from ncgen.model.controllers import ComputedTorque

    arm = armature_vector(model) if joint_dynamics else np.zeros(0)
    inverse = None
    if isinstance(controller, ComputedTorque) or np.any(arm):
        from ncgen.assembly.tree_dynamics import recursive_inverse_dynamics_function
        inverse = recursive_inverse_dynamics_function(model)
    dynamics = armature_dynamics_function(model, inverse, arm) if np.any(arm) else dynamics_function(model)
    return joint_ode_function(model, dynamics, inverse, controller=controller, joint_dynamics=joint_dynamics)


def _run_info(prepared, run: Run, options: JointOptions, stats) -> dict:
    """The run's ``info``: the prepared run's template, then this run's RK4 step ``h`` (s), controller,
    feedback kind and the integrator's counts ``stats``."""
    info = dict(prepared.info)
    if prepared.integrator == "rk4":
        info["h"] = float(run.t[1] - run.t[0]) / options.substeps
    if run.controller is not None:
        info["controller"] = run.controller.describe()
    if run.feedback is not None:
        info["feedback"] = run.feedback[0]
    info["stats"] = {"nsteps": int(stats[0]), "rejected_steps": int(stats[1]), "evaluations": int(stats[2])}
    return info


def simulate_joint(model, run: Run, opts: JointLoopOptions, options: JointOptions) -> Trajectory:
    """Integrate in joint space on the grid ``run.t`` from the natural state ``(run.q,
    run.v)`` (module docstring) with the group ``opts`` and the loop's options ``options``
    (checked by :func:`~ncgen.codegen.joint_loop.joint_options`; ``stop_at_outputs`` is set
    here, where the inputs vary).  ``run.U``: input samples on the grid (the open-loop part);
    ``run.feedback``: ``(kind, u)`` with ``kind`` ``"natural"`` (``u(t, q, v)``) or ``"joint"``
    (``u(t, qj, vj)``), called at the start of every output interval."""
    t, p, hold, feedback, controller = run.t, run.p, opts.hold, run.feedback, run.controller
    if hold == "linear" and feedback is not None:
        raise NcgenError("hold='linear' with a feedback u(t, q, v): the feedback is held over each output "
                         "interval (zoh); use hold='zoh'")
    build_start = time.perf_counter()
    prepared = prepared_run(model, controller, opts, options, len(t) - 1)
    loop, build_time = prepared.loop, time.perf_counter() - build_start
    (nqj, nvj, nu), n = prepared.sizes, len(t)
    X = np.zeros((n, nqj + nvj))
    np.concatenate(run.joint_state or model.joint_space.state(model, run.q, run.v), out=X[0])  # consistent: start_state
    U = np.ascontiguousarray(run.U, dtype=float)
    W, S = U.copy(), _input_slopes(U, t) if hold == "linear" and nu else None
    varying = nu > 0 and (feedback is not None or U[1:].tobytes() != U[:1].tobytes() * (n - 1))  # bit-equal rows
    options = run_options(options, varying)
    integrator = prepared.integrator
    start = time.perf_counter()
    status, k, failed, stats = _integrate(model, loop, options, run, X, W, S, opts.progress)
    info = _run_info(prepared, run, options, stats)
    info["build_time"], info["wall_time"], info["complete"] = build_time, time.perf_counter() - start, status == 0
    trusted, why = k + 1, ""
    if integrator == "rk4" and (failed is not None or status not in (0, INTERRUPTED)):
        trusted, why = _trusted_rk4_rows(model, loop, t[:k + 1], X[:k + 1], W, S, p, options)
        info["complete"] = False
    traj = _trajectory(model, loop, *((t, X, W) if trusted == n else (t[:trusted], X[:trusted], W[:trusted])), p, info,
                       prepared.names)
    if failed is not None:
        cause = failed.__cause__
        if why:
            failed = FeedbackFailed(f"{str(failed).rstrip('.')}.{why}", time=failed.time)
        raise with_partial(failed, traj) from cause
    if status == INTERRUPTED:
        message = f"joint-space simulation of {model.name!r} interrupted (Ctrl-C) at t = {t[k]:.6g} s"
        traj.info["message"] = message
        raise SimulationInterrupted(message, time=float(t[k]), trajectory=traj)
    if status:
        what = _STATUS.get(status, f"status {status}")
        if status == 1 and controller is not None:
            times = (float(t[k]), float(stats[4])) + ((float(t[k + 1]),) if k + 1 < n else ())
            what = _controller_cause(model, loop, times, X[k], p) or what
        message = (f"joint-space simulation of {model.name!r} failed between t = {t[k]:.6g} s and the next output "
                   f"time (at t = {stats[4]:.6g} s): {what}.{why} The trajectory up to t = {traj.t[-1]:.6g} s is "
                   "attached to this error as .trajectory.")
        traj.info["message"] = message
        raise SimulationError(message, time=float(traj.t[-1]), trajectory=traj)
    return traj


def _controller_cause(model, loop: JointLoop, times: tuple, x: np.ndarray, p) -> str | None:
    """Why the accelerations are not finite when the compiled controller is: its inputs at
    the last state reached ``x`` (joint space), at that state's time, the failure's or the
    end of the failed output interval (``times``), if they are not finite there, else None."""
    for t in times:
        applied = np.array(loop.mapped("ode", 1)(t, x, np.zeros(model.nu), np.asarray(p, float))[2]).reshape(-1)
        if not np.all(np.isfinite(applied)):
            return (f"the compiled controller's inputs are not finite: at the state reached at t = {times[0]:.6g} s, "
                    f"taken at t = {t:.6g} s, its law gives {applied.tolist()}")
    return None


#: Prepared runs kept per model (:func:`prepared_run`; then forgotten all at once).
KEPT_RUNS = 16


class PreparedRun:
    """What a joint-space run derives from its options, output count, controller and
    compiler but not from its start: the loop (:func:`joint_loop`) on the kernels
    :func:`choose_kernels` chose, the integrator's name, the sizes ``(nq_j, nv_j, nu)``, the
    trajectory's names and the run's ``info`` without its per-run entries (the RK4 step ``h``, the controller's and
    feedback's descriptions, the counts and times: set by the run)."""

    __slots__ = ("controller", "opts", "options", "loop", "integrator", "info", "sizes", "names")

    def __init__(self, model, controller, opts: JointLoopOptions, options: JointOptions, n_out: int):
        choice = choose_kernels(model, n_out, controller, opts.joint_dynamics, opts.kernels)
        self.controller, self.opts, self.options = controller, opts, options
        self.loop = joint_loop(model, controller, opts.joint_dynamics, kernels=choice.backend)
        self.integrator = integrator = integrator_name(options)
        self.sizes, self.names = (model.joint_space.nq, model.joint_space.nv, model.nu), output_names(model)
        steps = {"rtol": options.rtol, "atol": options.atol} if integrator == "dopri5" else \
            {"h": None, "substeps": options.substeps}
        self.info = {"method": "joint", "integrator": integrator, **steps, "hold": opts.hold,
                     "controller": None, "feedback": None,
                     "joint_dynamics": bool(opts.joint_dynamics), "kernels": self.loop.kernels,
                     "kernels_reason": choice.reason, "stats": None, "build_time": None, "wall_time": None,
                     "complete": None}


def prepared_run(model, controller, opts: JointLoopOptions, options: JointOptions, n_out: int) -> PreparedRun:
    """The :class:`PreparedRun` of a run of ``n_out`` output intervals, made once per
    options, output count, controller and C compiler (``$CC``, ``$PATH``) as long as the
    kernel choice cannot change: once the loop chosen, and for ``kernels="auto"`` without a
    controller every loop the choice weighs, is loaded (else made on every call, as
    :func:`choose_kernels` weighs what is compiled)."""
    data = model_data(model)
    loops = data.joint_loops
    key = (id(opts), id(options), n_out, id(controller), getenv_key("CC"), getenv_key("PATH"), _OWN_LOOP in loops,
           loops.get("tables") is not None)                        # (_loaded, inline)
    hit = data.prepared_runs.get(key)
    if hit is not None and hit.controller is controller and hit.opts is opts and hit.options is options:
        return hit
    prepared = PreparedRun(model, controller, opts, options, n_out)
    if _choice_settled(model, controller, opts, data.joint_loops):
        if len(data.prepared_runs) >= KEPT_RUNS:
            data.prepared_runs.clear()
        data.prepared_runs[key[:-2] + _loaded(data.joint_loops)] = prepared    # (as loaded now)
    return prepared


#: The key of the model's own loop (no controller, no joint dynamics) in ``joint_loops``.
_OWN_LOOP = (id(None), False, None)


def _loaded(loops: dict) -> tuple[bool, bool]:
    """Whether the model's own loop (no controller) and the tables' loop are loaded."""
    return _OWN_LOOP in loops, loops.get("tables") is not None


def _choice_settled(model, controller, opts: JointLoopOptions, loops: dict) -> bool:
    """Whether :func:`choose_kernels` gives the same for the same arguments, compiler and
    loaded loops: it weighs no tree-library units still to compile (:func:`_missing_units`)."""
    return (opts.kernels != "auto" or controller is not None or bool(opts.joint_dynamics) or bool(model.np)
            or (id(None), False, None) in loops or loops.get("tables") is not None
            or model_data(model).table_kinds == (None,))


def _input_slopes(U: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The slopes (per s) of the inputs ``U`` held linearly between the output times ``t``, one
    row per interval (the last row, after the end, zero)."""
    S = np.zeros_like(U)
    S[:-1] = np.diff(U, axis=0) / np.diff(t)[:, None]
    return S


def _integrate(model, loop, options: JointOptions, run: Run, X: np.ndarray, W: np.ndarray, S, progress):
    """``(status, k, failed, stats)``: the loop run over the grid in one call, or in chunks (one
    output interval each under a feedback, which sets that interval's inputs ``W[k]``; at most
    :data:`CHUNKS` under a progress bar) until the end or a
    failure, the states into ``X``; ``k``: the last output reached; ``failed``: the
    :class:`~ncgen.runtime.feedback.FeedbackFailed` of a feedback or None; ``stats``: the loop's
    counts (steps, rejected steps, evaluations, …, the time reached)."""
    t, p, feedback, n = run.t, run.p, run.feedback, len(run.t)
    stats = np.zeros(5)
    shown = progress_enabled(progress)
    bar = Progress(float(t[0]), float(t[-1]), progress, label=f"simulating {model.name} (joint space): ") \
        if shown else None
    status, k, failed = 0, 0, None
    chunk = 1 if feedback is not None else max(1, math.ceil((n - 1) / CHUNKS)) if shown else n - 1
    try:
        if feedback is None and chunk == n - 1:     # one call over the whole grid (W, S: made contiguous)
            status, k = loop.run(options, np.ascontiguousarray(t), X, W, S, p, stats)
        while k < n - 1 and status == 0:
            m = min(chunk, n - 1 - k)
            if feedback is not None:
                try:
                    W[k] = _feedback(model, feedback, float(t[k]), X[k], p)
                except FeedbackFailed as e:
                    failed, W[k] = e, W[k - 1] if k else W[k]
                    break
            sl = slice(k, k + m + 1)
            Xs = X[sl]
            status, done = loop.run(options, np.ascontiguousarray(t[sl]), Xs, np.ascontiguousarray(W[k:k + m]),
                                    None if S is None else np.ascontiguousarray(S[k:k + m]), p, stats)
            k += done
            if bar is not None:
                bar.update(float(t[k]))
    except KeyboardInterrupt:             # between chunks (in a feedback u(t, q, v))
        status = INTERRUPTED
    finally:
        if bar is not None:
            bar.close()
    return status, k, failed, stats


def _trusted_rk4_rows(model, loop: JointLoop, t, X, W, S, p, options: JointOptions) -> tuple[int, str]:
    """How many rows of a failed fixed-step RK4 run ``X`` (on the grid ``t``, with the
    inputs ``W`` it applied and the options ``options``) to keep, and why (``""``: all of them).  RK4 past its stability
    limit grows until the accelerations overflow; the rows kept are those before the first
    where its natural coordinates depart from an error-controlled run with the same inputs
    (Dormand–Prince, rtol 1e-8, atol 1e-10) by more than
    :data:`~ncgen.runtime.stepper_checks.ERROR_FRACTION` of the model's size ``max |q0|``
    (the stepper's rule), and not past where that reference run stops."""
    from ncgen.runtime.stepper_checks import ERROR_FRACTION

    n = len(t)
    R = np.zeros_like(X)
    R[0] = X[0]
    reference = joint_options("dopri5", 1e-8, 1e-10, 1, options.max_steps, bool(options.stop_at_outputs))
    status, done = loop.run(reference, np.ascontiguousarray(t), R, np.ascontiguousarray(W[:n - 1]),
                            None if S is None else np.ascontiguousarray(S[:n - 1]), p, np.zeros(5))
    m = (n - 1 if status == 0 else done) + 1
    tree = loop.mapped("tree", m)
    nqj = model.joint_space.nq
    q_rk4 = np.array(tree(X[:m, :nqj].T, X[:m, nqj:].T)[0]).T
    q_ref = np.array(tree(R[:m, :nqj].T, R[:m, nqj:].T)[0]).T
    size = max(float(np.max(np.abs(model.q0), initial=0.0)), 1e-9)
    gap = np.max(np.abs(q_rk4 - q_ref), axis=1)
    bad = ~(gap <= ERROR_FRACTION * size)                       # NaN counts as bad
    first = int(np.argmax(bad)) if bad.any() else m
    if first == n:
        return n, ""
    if first < m:
        return first, (f" Before that, the RK4 run departed from an error-controlled run (Dormand-Prince, rtol 1e-8) "
                       f"by {gap[first]:.3g} m at t = {t[first]:.6g} s, more than {ERROR_FRACTION:g} of the model's "
                       f"size {size:.3g} m (RK4's step is past its stability limit: use more substeps, or "
                       f"{option('integrator=', '--integrator ')}dopri5), so only the rows before it are kept.")
    return m, (f" The error-controlled run that checks the RK4 run stopped at t = {t[m - 1]:.6g} s, so only the rows "
               f"up to there are kept.")


def _feedback(model, feedback, t: float, x: np.ndarray, p) -> np.ndarray:
    kind, u = feedback
    js = model.joint_space
    qj, vj = x[:js.nq].copy(), x[js.nq:].copy()
    if kind == "joint":
        args = (qj, vj)
    else:
        args = model.from_joint_space(qj, vj, t=t, p=p)
    return call_feedback(u, t, *args, nu=model.nu, what=kind)


def _trajectory(model, loop: JointLoop, t, X, W, p, info, names) -> Trajectory:
    """The natural-coordinate trajectory of the joint states ``X`` (module docstring); ``X``
    and ``W`` are the run's own arrays, which the lazy outputs keep (``traj.qj``, ``traj.vj``
    too: copies made when first read, so editing them changes nothing else); ``names``: the
    model's :func:`~ncgen.runtime.trajectory.output_names`."""
    outputs = _JointOutputs(model, loop, t, X, W if len(W) == len(t) else W[:len(t)], p)
    derived = Derived(model, t, outputs.q, outputs.v, p)
    arrays = {"t": t, "lam": outputs.lam, "u": outputs.applied, "p": np.asarray(p, float), "qj": outputs.qj,
              "vj": outputs.vj}
    return Trajectory.of_run(model, derived, arrays, info, names)


class _JointOutputs:
    """The outputs of a joint run derived from its joint states ``X`` (rows at the times ``t``)
    and applied samples ``W``, each evaluated when first asked for: the natural state (the
    tree function, mapped), the applied inputs (the ODE's third output), the multipliers
    (``accel`` at the natural state) and the joint states (copies)."""

    __slots__ = ("model", "loop", "t", "X", "W", "p", "_natural", "_applied", "_P")

    def __init__(self, model, loop, t, X, W, p):
        self.model, self.loop, self.t, self.X, self.W, self.p = model, loop, t, X, W, p
        self._natural = self._applied = self._P = None

    def P(self) -> np.ndarray:
        if self._P is None:
            self._P = np.repeat(np.asarray(self.p, float)[:, None], len(self.t), axis=1)
        return self._P

    def natural(self) -> list:
        if self._natural is None:
            X, nqj = self.X, self.model.joint_space.nq
            self._natural = [np.array(y).T for y in self.loop.mapped("tree", len(self.t))(X[:, :nqj].T, X[:, nqj:].T)]
        return self._natural

    def q(self) -> np.ndarray:
        return self.natural()[0]

    def v(self) -> np.ndarray:
        return self.natural()[1]

    def applied(self) -> np.ndarray:
        if self._applied is None:
            m, n, t = self.model, len(self.t), self.t
            self._applied = np.array(self.loop.mapped("ode", n)(t[None, :], self.X.T, self.W.T if m.nu else
                                                                np.zeros((0, n)), self.P())[2]).T.reshape(n, m.nu)
        return self._applied

    def lam(self) -> np.ndarray:
        m, n, (q, v) = self.model, len(self.t), self.natural()
        return np.array(self.loop.mapped("accel", n)(self.t[None, :], q.T, v.T, self.applied().T,
                                                     self.P())[1]).T.reshape(n, m.nc)

    def qj(self) -> np.ndarray:
        return self.X[:, :self.model.joint_space.nq].copy()

    def vj(self) -> np.ndarray:
        return self.X[:, self.model.joint_space.nq:].copy()
