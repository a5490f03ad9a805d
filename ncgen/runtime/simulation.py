"""``simulate``: a model's motion over a time grid, by one of the integrators behind the seam
of :mod:`ncgen.runtime.integrator`: the joint-space loop, IDAS, the compiled stepper or the
rolling integrator."""
from __future__ import annotations

import dataclasses
import inspect

import numpy as np

from ncgen.assembly.nonholonomic import rolling_system
from ncgen.environment import getenv_key
from ncgen.errors import NcgenError
from ncgen.interrupts import raise_if_interrupted, sticky_interrupt
from ncgen.model.controllers import Controller
from ncgen.model.data import model_data
from ncgen.runtime.dae import load_dae
from ncgen.runtime.idas_integrator import IdasIntegrator
from ncgen.runtime.inputs import feedback_kind, hold_columns, input_samples, parameter_values, time_grid
from ncgen.runtime.integrator import Run
from ncgen.runtime.joint_integrator import JointIntegrator
from ncgen.runtime.joint_simulation import joint_space_applies
from ncgen.runtime.options import SimulationOptions
from ncgen.runtime.rolling_integrator import RollingIntegrator
from ncgen.runtime.run_start import initial_multipliers, natural_feedback, point_bytes, start_state
from ncgen.runtime.stepper_integrator import StepperIntegrator
from ncgen.runtime.trajectory import Trajectory
from ncgen.validation import as_scalar


def _show_shortcuts(f):
    """``f`` with a signature that lists the option shortcuts (``help``, editors): each field of
    :class:`~ncgen.runtime.options.SimulationOptions` as a keyword with its default, in place of
    ``**shortcuts``."""
    sig = inspect.signature(f)
    params = [q for q in sig.parameters.values() if q.kind is not inspect.Parameter.VAR_KEYWORD]
    params += [inspect.Parameter(fl.name, inspect.Parameter.KEYWORD_ONLY, default=fl.default, annotation=fl.type)
               for fl in dataclasses.fields(SimulationOptions)]
    f.__signature__ = sig.replace(parameters=params)
    return f


@_show_shortcuts
def simulate(model, t_end: float, dt: float, *, u=None, p=None, q0=None, v0=None, t0: float | None = None,
             options: SimulationOptions | None = None, **shortcuts) -> Trajectory:
    """Integrate ``model`` from ``t0`` (default ``model.t0``) to ``t_end`` and return the
    :class:`~ncgen.runtime.trajectory.Trajectory` on the grid ``t0, t0 + dt, ..., t_end``
    (``dt`` shortened if needed so that ``t_end`` is on the grid).  Times in s.

    Equations: the semi-explicit index-1 DAE ``q̇ = v``, ``v̇ = M⁻¹ (F − Aᵀ λ)``,
    ``0 = A v̇ − γ + 2α Φ̇ + β² Φ`` with the model's Baumgarte coefficients
    ``model.baumgarte = (α, β)`` (default 5 s⁻¹ each, set by ``System.build(baumgarte=...)``:
    constraint drift decays like a critically damped oscillator with time constant 0.2 s;
    IDAS keeps the drift small anyway, the terms stop it from growing over long runs).

    How to integrate is ``options`` (:class:`~ncgen.runtime.options.SimulationOptions`,
    ``nc.SimulationOptions``: defaults, validated once); every field of it can also be given
    as a keyword argument (``method=``, ``rtol=``, ``substeps=``, ...), which overrides
    ``options`` for this call.  The run's data and the options:

    * ``method``: ``"auto"`` (default): ``"joint"`` for a tree without contacts when a C
      compiler is available (:func:`~ncgen.runtime.joint_simulation.joint_space_applies`)
      and ``backend`` is not ``"vm"``, else ``"idas"``; ``info["method"]`` says which ran (``info["auto"]`` why not joint).
      ``"joint"``: the joint coordinates ``q_j``, ``v_j`` integrated by a compiled C loop
      around the joint-space forward dynamics (:mod:`ncgen.runtime.joint_simulation`):
      ``integrator="dopri5"`` (default; Dormand–Prince 5(4), error control ``rtol``/``atol``
      on q_j and v_j, defaults 1e-8 and 1e-10) or ``"rk4"`` (``substeps`` RK4 steps per
      output interval); quaternions renormalised after each step; the natural coordinates,
      markers, energies and multipliers are derived from the joint states.
      ``"idas"``: SUNDIALS IDAS through CasADi, variable-order BDF with error
      control ``rtol`` (relative, default 1e-8) and ``atol`` (absolute, in the units of q and
      v, default 1e-10) on q and v).  For both methods ``rtol``/``atol`` bound the **local**
      error, the error each step makes; the global error at the end is a small multiple of
      the tolerance on regular motions and grows without such a bound on chaotic ones
      (``docs/python-guide.md``, "What rtol means").
    * ``u``: inputs (``model.nu`` values): ``None`` (zeros), a constant vector (a scalar when
      ``nu = 1``), a callable ``u(t)``, or samples on
      the grid, shape ``(len(t), nu)`` or ``(len(t) − 1, nu)``; held between grid times by
      ``hold`` = ``"zoh"`` (sample k on ``[t_k, t_k+1)``) or ``"linear"`` (interpolated).
      Feedback: a callable ``u(t, q, v)`` (natural coordinates) or ``u(t, qj, vj)`` (joint
      space: its 2nd and 3rd parameters named ``qj``, ``vj``; see
      :func:`~ncgen.runtime.inputs.feedback_kind`), called once per output interval at its
      start and held over it (every method).  A compiled controller
      (:class:`~ncgen.model.controllers.PD`, ``ComputedTorque``, ``Controller``): generated
      into the C loop with ``method="joint"`` (no Python per step), into IDAS's DAE with
      ``"idas"``; the stepper does not take it.
    * ``joint_dynamics``: honour the joints' damping, friction and position limits
      (``joint.dynamics``, ``joint.limits``; from a URDF ``<dynamics>`` and ``<limit>``) by
      the stiff law of :mod:`ncgen.model.joint_dynamics` (joint and IDAS methods; the stepper
      refuses it).
    * ``p``: parameter values: ``None`` (the model's), an array, or a dict by name.
    * ``q0``, ``v0``: initial coordinates and rates (default the model's, consistent at
      ``model.t0``).  Whenever they are given, or ``p`` or ``t0`` differ from the model's,
      they are projected onto the constraints (``Φ = 0`` by Gauss–Newton, then ``A v + Φ_t = 0``
      in the mass metric); corrections larger than ``ic_tolerance`` × the system's size are
      an error (``ic_tolerance=None``: no limit, the given state is only a guess, e.g. when
      starting a driven mechanism at another ``t0``).  ``λ0`` then solves the KKT system
      with ``u(t0)``.
    * ``backend``: ``"vm"`` (CasADi's virtual machine), ``"compiled"`` (the DAE and its
      Jacobian as generated C, compiled once and cached) or ``"auto"`` (default: start on the
      VM, compile only when the run is long enough to pay for it; the rule is
      :func:`ncgen.runtime.backend_policy.choose_backend`, the same as the CLI's;
      ``info["backend_reason"]`` says why).
    * ``progress``: a progress bar on stderr: ``True``, ``False``, or ``None`` = when stderr is a
      terminal and the run takes more than a second.
    * ``max_steps``: IDAS steps allowed per output interval (per interval of the watched grid
      below when watching); ``linear_solver``: CasADi's
      sparse solver for the Newton systems (``"csparse"``, ``"qr"``, ...).
    * ``project`` (IDAS), for linkages that pass singular positions (where ``A`` loses rank
      and another branch of ``Φ = 0`` meets the physical one, e.g. a parallelogram passing
      flat; there the KKT matrix of the index-1 DAE is singular and IDAS either fails or
      drifts onto the other branch).  ``"auto"`` (default): the run watches ``σ_min/σ_max``
      of ``A`` and its rate (an SVD each; only models with ``nq · nc ≤``
      :data:`~ncgen.runtime.idas_integrator.AUTO_MAX_SIZE`) on a grid of its own, each output interval split into parts of
      at most :data:`~ncgen.runtime.idas_integrator.WATCHED_SAMPLE` (0.01 s), so that where the singular positions are
      looked for does not depend on the output grid; IDAS runs in chunks of that grid that
      end where the ratio's trend says it reaches the limit (few calls: IDAS restarts at
      order 1 with each, its first step ``min(√rtol, 10⁻³)`` times the grid's interval, see
      :class:`~ncgen.runtime.idas.ChunkedIDAS`); every grid interval that starts or ends
      near-singular (ratio below :data:`~ncgen.assembly.manifold.NEAR_SINGULAR`, scaled by
      the starting ratio, see :mod:`ncgen.assembly.manifold`), across which the ratio could
      dip below that limit unseen (its rate at the two ends), or that IDAS fails on close
      to one, is crossed instead by the model's compiled error-controlled RATTLE stepper
      (order 4, tolerances a hundredth of ``rtol`` and ``atol``, at least 1e-12, from the
      state projected onto both constraint levels, multipliers recomputed at both ends;
      compiled on first use; :mod:`ncgen.runtime.rattle_bridge`), which stays on the branch.
      Each bridged interval is then checked to end on the branch it started on (the chord
      between its ends tangent to the constraints, :data:`~ncgen.runtime.idas_integrator.BRANCH_DEPARTURE`); one that does
      not is a :class:`~ncgen.errors.BranchWarning` naming its times
      (``info["branch_changes"]``).  ``info["projected_from"]`` is the first bridged time,
      ``info["watched_interval"]`` the grid's interval, ``info["stats"]["rattle_intervals"]``
      the number of bridged intervals and ``info["stats"]["branch_departure"]`` the largest
      departure of the branch test.  The N four-bar of the IFToMM benchmark A02 over 20 s
      (sixteen flat positions) at ``rtol = atol = 1e-10`` then stays within 5e-7 m of the
      exact motion for N = 1, 10, 40, planar and 3D, for every output interval from 1 ms to
      0.5 s and both backends (``tests/test_singular_output_grid.py``).  ``True``: the same,
      with one IDAS call per grid interval and the state projected after each.  ``False``:
      IDAS alone.
    * ``method="rolling"``: the method of a model with rolling elements (``model.rolling``:
      ``System.add_rolling``, TOML ``[[rolling]]``), chosen by ``"auto"`` (``"idas"`` for a
      model with drives as well, which ``"rolling"`` refuses; ``"idas"``:
      :mod:`ncgen.runtime.rolling_idas`, and ``"stepper"``: RATTLE with velocity
      constraints, :mod:`ncgen.runtime.rolling_stepper`, take it too): explicit Runge–Kutta
      steps (``integrator="dopri5"``, default, with
      ``rtol``/``atol``, or ``"rk4"`` with ``substeps``) each projected onto the holonomic
      and the velocity constraints (:mod:`ncgen.runtime.rolling_integrator`, docs/rolling.md);
      no feedback or controllers.
    * ``method="stepper"``: the compiled fixed-step stepper (generated C, Newton loop
      included; :mod:`ncgen.runtime.stepper`): ``scheme="auto"`` (default) Suzuki's
      fourth-order composition of five RATTLE steps per step (``"rattle4"``), RATTLE alone
      (``"rattle"``, second order) for models with contacts,
      ``substeps`` steps of ``dt / substeps`` per
      output interval, Newton tolerance ``newton_tol`` (both constraint levels hold to it at
      every step) and at most ``max_newton`` iterations per RATTLE step; a step whose Newton fails is
      split in halves, at most ``max_halvings`` times (counted in ``info["stats"]``).  The
      run estimates its error (a shadow run with steps of 2h, ``info["error_estimate"]``;
      ``estimate="local"``: sampled local errors, a fifth of the work)
      and is checked: split steps, exploding Newton iterations, an energy change
      (conservative models) or energy balance error (others) above 1 % or an estimated error
      above 1 % of the model's size raise :class:`~ncgen.errors.SimulationError` naming the
      step to use (``check=False``: no checks; ``estimate=False``: no shadow run, a third
      less work, no error check; see :mod:`ncgen.runtime.stepper_checks`).  With ``rtol``
      (``atol`` default ``rtol``) the stepper chooses its steps instead (Richardson error
      estimate; ``order=4``: extrapolated and projected, ``order=2``: plain RATTLE steps),
      at most ``max_steps`` step attempts per output interval; a shadow run at 10× looser
      tolerances estimates the global error (``estimate=False`` skips it), and the run warns
      (:class:`~ncgen.errors.AccuracyWarning`) where that estimate ends above 100× the
      tolerance and raises where it passes 1 % of the model's size (``check=False``: neither).
      ``backend``, ``linear_solver`` and ``progress`` are
      IDAS's only.

    Raises :class:`~ncgen.errors.SimulationError` if IDAS fails; it names the time reached
    and the likely cause, and carries the trajectory up to that time (``.trajectory``).
    """
    plan = _kept_plan(model, t_end, dt, options, shortcuts) if u is None and p is None and t0 is None else None
    if plan is None:
        plan = Plan(model, t_end, dt, t0, options, shortcuts)
    opts, t0, t = plan.opts, plan.t0, plan.t.copy()
    pv = model.p0.copy() if p is None else parameter_values(p, model)
    if u is None:
        controller = feedback = None
    else:
        controller = u if isinstance(u, Controller) else None
        kind = feedback_kind(u) if controller is None else None
        feedback = (kind, u) if kind in ("natural", "joint") else None
    if u is None and plan.U is not None:
        U, columns = plan.U, plan.columns
    else:
        U = input_samples(None if controller is not None else u, model, t)
        columns = hold_columns(U, t, opts.hold)
    q, v, joint = start_state(model, q0, v0, t0, pv, opts.ic_tolerance, joint=plan.method == "joint")
    run = Run(t, U, columns, pv, q, v, controller, feedback, plan.why_not,
              lambda tk, qk, vk, uk: initial_multipliers(model, tk, qk, vk, uk, pv, load_dae(model, "vm")[0]),
              lambda tk, qk, vk: natural_feedback(model, feedback, tk, qk, vk, pv), joint)
    with sticky_interrupt():               # a Ctrl-C that CasADi swallows is raised again between chunks
        raise_if_interrupted()
        return plan.integrator.run(run)


def _method(model, opts: SimulationOptions) -> tuple[str, str | None]:
    """``(method, why not joint)``: ``opts.method`` with ``"auto"`` resolved (see :func:`simulate`)."""
    method, why_not = opts.method, None
    if model.rolling and method not in ("auto", "rolling", "idas", "stepper"):
        raise NcgenError(f"method={method!r}: model {model.name!r} has rolling elements "
                         f"({', '.join(e.name for e in model.rolling)}), whose velocity constraints only "
                         "method='rolling' (the default for it), 'idas' and 'stepper' keep")
    if model.rolling and method == "auto":
        if rolling_system(model).driven:
            method, why_not = "idas", "the model has rolling elements and drives (method='idas')"
        else:
            method, why_not = "rolling", "the model has rolling elements (method='rolling')"
    elif method == "auto":                 # the joint loop is compiled: backend="vm" asks for no compiling
        why_not = "backend='vm' compiles nothing" if opts.backend == "vm" else joint_space_applies(model)
        method = "joint" if why_not is None else "idas"
    return method, why_not


class Plan:
    """What :func:`simulate` derives from its arguments but not from the start, the inputs or
    the parameters: the options resolved, the method (and why not the joint loop), the
    integrator prepared, ``t0`` and the grid (each run copies it) and, for a plan that is kept,
    the inputs of ``u=None`` (zeros, read only) and their hold columns."""

    __slots__ = ("options", "opts", "method", "why_not", "integrator", "t0", "t", "U", "columns")

    def __init__(self, model, t_end, dt, t0, options, shortcuts: dict):
        self.options = options
        self.opts = opts = SimulationOptions.resolve(options, **shortcuts)
        self.method, self.why_not = _method(model, opts)
        self.integrator = INTEGRATORS[self.method](model, opts)
        self.t0 = model.t0 if t0 is None else as_scalar(t0, "t0")
        self.t = time_grid(self.t0, t_end, dt, bytes_per_point=point_bytes(model))
        self.U = self.columns = None


#: Plans kept per model (:func:`_kept_plan`; then forgotten all at once).
KEPT_PLANS = 16
_PLAIN = (float, int)


def _kept_plan(model, t_end, dt, options, shortcuts: dict) -> Plan | None:
    """The :class:`Plan` of a call without inputs, parameters or ``t0`` that runs the joint
    loop, kept per model, ``t_end``, ``dt`` (plain numbers), options (the object), option
    keywords (values and types) and ``$NCGEN_MAX_BYTES`` (the grid's limit; the model is constant); None
    for any other call (unhashable keywords, another method), which makes its plan afresh."""
    if type(t_end) not in _PLAIN or type(dt) not in _PLAIN:
        return None
    key = (t_end, type(t_end), dt, type(dt), id(options), getenv_key("NCGEN_MAX_BYTES"),
           *shortcuts.items(), *map(type, shortcuts.values()))
    plans = model_data(model).simulate_plans
    try:
        plan = plans.get(key)
    except TypeError:                      # an unhashable keyword value
        return None
    if plan is not None and plan.options is options:
        return plan
    plan = Plan(model, t_end, dt, None, options, shortcuts)
    if plan.method != "joint":
        return plan
    plan.U = np.zeros((len(plan.t), model.nu))
    plan.columns = hold_columns(plan.U, plan.t, plan.opts.hold)
    plan.U.flags.writeable = plan.columns.flags.writeable = False
    if len(plans) >= KEPT_PLANS:
        plans.clear()
    plans[key] = plan
    return plan


#: The integrators by ``SimulationOptions.method`` (:mod:`ncgen.runtime.integrator`).
INTEGRATORS = {c.METHOD: c for c in (JointIntegrator, IdasIntegrator, StepperIntegrator, RollingIntegrator)}

