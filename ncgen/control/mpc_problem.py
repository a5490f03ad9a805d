"""The receding-horizon problem of an ``OptimalControl`` (:mod:`ncgen.optim.problem`) on the
discrete RATTLE step: what :class:`ncgen.control.mpc.MPC` solves at every control step.

From the OCP: the horizon (``N`` steps of ``h = t_final / N``, fixed final time), the
parameters, the costs and the bounds::

    min  Σ_{k<N} ℓ(x_k, u_k) + ℓ_N(x_N)   s.t.  x_0 = x (measured),  x_{k+1} = step(x_k, u_k),
         u_lo ≤ u_k ≤ u_hi,  q_lo ≤ q_k ≤ q_hi,  v_lo ≤ v_k ≤ v_hi  (k ≥ 1)

    ℓ(x, u)  = h [uᵀ R u + Σ_markers w |r(q) − r_ref|²]          (effort, track_marker)
    ℓ_N(x)   = Σ terminal costs (minimize_terminal)
               + W (|q − q_f|² + |v − v_f|²)                     (final(q=…, v=…), soft)

Integrals become sums over the ``N`` intervals' first nodes (rectangle rule, as the inputs
are held).  With a time-varying ``reference`` (a plan to track, :mod:`ncgen.control.mpc_reference`)
the stage and terminal costs measure the distance to it at the nodes' times ``t_k``::

    ℓ(x, u, t) = h [(u − u_ref)ᵀ (R + diag r) (u − u_ref) + (x − x_ref)ᵀ diag Q (x − x_ref) + markers]
    ℓ_N(x, t)  = Σ terminal costs + W |x − x_ref(t)|²       (in place of the final conditions)

(``x_ref``, ``u_ref`` at ``t``; ``Q``: ``state_weight``, ``r``: ``input_weight``).  With
``min_tension`` (``T_min``, N) the cables (``Spring(cable=True)``, ``ClusteredCable``) are kept
taut where the step evaluates their forces, at both ends of every interval::

    P_i(q_k, w_k, u_k) ≥ T_min,  P_i(q_{k+1}, w_k, u_k) ≥ T_min,  w_k = (q_{k+1} − q_k) / h
                                                              (k < N, every cable i)

on the pull ``P = k (l − l₀) + c l̇`` (N; :mod:`ncgen.optim.taut_cables`), smooth where the
tension ``max(P, 0)`` has its kink: RATTLE evaluates the forces at ``(q_k, w_k)`` and
``(q_{k+1}, w_k)`` with the half-step velocity ``w_k`` (:mod:`ncgen.assembly.stepper_equations`;
``q_{k+1} = q_k + h w_k``), so a step whose cables stay taut there is a smooth function of
``(x_k, u_k)``, which the SQP's linearisation needs (the pulls at the nodes' own velocities
``v_k`` may be taut while the step's are slack: the damper's ``c (l̇(w) − l̇(v))``).  The final
conditions of the OCP are *soft* in MPC (weight ``W``,
``terminal_weight``): a hard terminal equality can be infeasible from a disturbed state,
and a controller must always return an input.  Not supported in MPC (a clear error):
free final time, free parameters, periodic conditions, marker and joint path constraints,
final poses/joints/markers, time-varying marker references.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ncgen.assembly.stepper_equations import nonsmooth

from ncgen.errors import OptimizationError
from ncgen.validation import as_numbers, as_scalar


@dataclass
class MPCProblem:
    """``stage(x, u, t)`` and ``terminal(x, t)`` (SX callables; ``t``, the node's time, is used
    only with a reference and may be left out without one), bounds as ``(lower, upper)``
    arrays (``u``: nu, ``x``: nx = 2 nq), ``h`` (s), ``N``, ``p``, the final target and
    ``x_start``: the OCP's initial state (``initial(q=…, v=…)``, the model's where it gives
    none), the exported demo's default start."""

    h: float
    N: int
    p: np.ndarray
    stage: object
    terminal: object
    u_bounds: np.ndarray
    x_bounds: np.ndarray
    x_final: np.ndarray | None
    x_start: np.ndarray | None = None
    #: ``mpc_reference: t -> (x_ref, u_ref)`` (:mod:`ncgen.control.mpc_reference`), or None.
    reference: ca.Function | None = None
    #: ``T_min`` (N) of the cables' path constraint, or None.
    min_tension: float | None = None
    #: ``cable_pull: (x_k, x_{k+1}, u_k, t_k) -> P`` (SX, N: the cables' pulls at the interval's
    #: start, then at its end, both with ``w_k``), with ``min_tension``; else None.
    cable_pull: ca.Function | None = None


def mpc_problem(ocp, terminal_weight: float, reference=None, state_weight=None, input_weight=None,
                min_tension=None) -> MPCProblem:
    """The :class:`MPCProblem` of ``ocp`` (see the module docstring); ``reference``: a plan
    ``(t, X, U)`` or an OCP solution (:func:`ncgen.control.mpc_reference.reference_arrays`),
    ``state_weight`` (nx or a scalar; default 1), ``input_weight`` (nu or a scalar; default 0):
    its weights, refused without a reference; ``min_tension``: ``T_min`` (N, finite), refused
    on a model without cables; without it, the OCP's own floor (``ocp.min_tension(T_min)``)."""
    model = ocp.model
    check_supported(ocp)
    W = float(terminal_weight)
    if not np.isfinite(W) or W < 0:
        raise OptimizationError(f"MPC: terminal_weight: expected a non-negative number, got {terminal_weight!r}")
    h, N, p = ocp.t_final / ocp.N, ocp.N, ocp.p_values.copy()
    nq = model.nq
    plan, Q, R = tracking(ocp, reference, state_weight, input_weight)
    markers = model.functions["markers"] if model.marker_names else None

    def marker(q, name):
        return markers(q, ca.SX.zeros(nq))[0][:, ocp.marker_index(name)]

    def stage(x, u, t=None):
        if plan is None:
            out = ca.mtimes([u.T, ca.DM(R), u])
        else:
            x_ref, u_ref = plan(t)
            out = ca.mtimes([(u - u_ref).T, ca.DM(R), u - u_ref]) + ca.sum1(ca.DM(Q) * (x - x_ref) ** 2)
        for name, ref, w in ocp.tracking:
            out += w * ca.sumsqr(marker(x[:nq], name) - ca.DM(ref))
        return h * out

    q_f, v_f = final_target(ocp, p)

    def terminal(x, t=None):
        q, v = x[:nq], x[nq:]
        out = ca.SX(0)
        for _, spec in ocp.terminal:
            if spec[0] == "fn":
                out += spec[2] * spec[1](q, v, ca.DM(p))
            else:
                _, name, target, w = spec
                given = ~np.isnan(target)
                out += w * ca.sumsqr((marker(q, name) - ca.DM(np.nan_to_num(target)))[np.flatnonzero(given).tolist()])
        if plan is not None:
            return out + W * ca.sumsqr(x - plan(t)[0])
        if q_f is not None:
            out += W * ca.sumsqr(q - q_f)
        if v_f is not None:
            out += W * ca.sumsqr(v - v_f)
        return out

    x_bounds = np.hstack([ocp.q_bounds, ocp.v_bounds])
    x_final = None if q_f is None else np.concatenate([q_f, np.zeros(nq) if v_f is None else v_f])
    T_min, pull = cable_constraint(model, h, p, ocp.cable_min_tension if min_tension is None
                                   else min_tension)
    return MPCProblem(h, N, p, stage, terminal, ocp.u_bounds.copy(), x_bounds, x_final, initial_state(ocp, p), plan,
                      T_min, pull)


def check_supported(ocp) -> None:
    """Refuse, naming them, the parts of ``ocp`` MPC does not take (module docstring)."""
    model = ocp.model
    if nonsmooth(model):
        names = ", ".join(repr(c["name"]) for c in model.contacts)
        raise OptimizationError(f"MPC of {model.name!r}: the model has nonsmooth contacts ({names}); the "
                                "receding-horizon controller's step has no contacts (they would be ignored), so it "
                                "is not supported: use nc.ilqr on nc.step_function(model, h), whose Jacobians "
                                "go through the contacts, or build the model with contacts='smooth'")
    unsupported = [what for what, bad in (
        ("a free final time", ocp.t_final_bounds is not None),
        ("free parameters", bool(ocp.p_free)),
        ("periodic conditions", any(ocp.periodic_spec.values())),
        ("marker path constraints (bound_marker)", bool(ocp.marker_bounds)),
        ("joint path constraints (bound_joint, joint_limits)", bool(ocp.joint_bounds)),
        ("bounds on coordinates as written that coordinate sharing re-based (not a box on the state)",
         bool(ocp.row_bounds)),
        ("final markers, poses or joints", bool(ocp.final_spec["markers"] or ocp.final_spec.get("pose")
                                                 or ocp.final_spec.get("joints"))),
        ("minimize_time", ocp.time_weight > 0),
        ("a time-varying track_marker reference", any(callable(ref) for _, ref, _ in ocp.tracking)),
    ) if bad]
    if unsupported:
        raise OptimizationError(f"MPC of {model.name!r}: the problem has {', '.join(unsupported)}, which the "
                                "receding-horizon controller does not support; see ncgen.control.mpc_problem")


def tracking(ocp, reference, state_weight, input_weight):
    """``(plan, Q, R)`` of the stage cost: the reference ``plan: t -> (x_ref, u_ref)``
    (:mod:`ncgen.control.mpc_reference`) and the state weights ``Q`` (nx), or ``(None, None,
    R)`` without a reference; ``R`` (nu × nu): the OCP's effort weight, plus ``diag r`` with a
    reference.  The weights are refused without a reference."""
    model = ocp.model
    R = np.zeros((model.nu, model.nu)) if ocp.effort_R is None else ocp.effort_R
    for what, w in (("state_weight", state_weight), ("input_weight", input_weight)):
        if reference is None and w is not None:
            raise OptimizationError(f"MPC: {what}: a weight of the tracking cost, given without a reference "
                                    "(reference=plan)")
    if reference is None:
        return None, None, R
    from ncgen.control.mpc_reference import reference_arrays, reference_function
    plan = reference_function(*reference_arrays(reference, 2 * model.nq, model.nu))
    Q = weights(1.0 if state_weight is None else state_weight, 2 * model.nq, "state_weight")
    return plan, Q, R + np.diag(weights(0.0 if input_weight is None else input_weight, model.nu, "input_weight"))


def final_target(ocp, p) -> tuple[np.ndarray | None, np.ndarray | None]:
    """``(q_f, v_f)`` of the OCP's ``final(q=…, v=…)`` (each None where not given), resolved at
    the final time: the soft terminal cost's target."""
    model, t_end = ocp.model, ocp.t0 + ocp.t_final
    q_f = v_f = None
    if ocp.final_spec["q"] is not None:
        from ncgen.optim.conditions import resolve_configuration
        q_f = resolve_configuration(model, ocp.final_spec["q"], model.q0, t=t_end, p=p, what="final q")
    if ocp.final_spec["v"] is not None:
        from ncgen.optim.conditions import resolve_velocity
        v_f = resolve_velocity(model, ocp.final_spec["v"], model.q0 if q_f is None else q_f, t=t_end, p=p)
    return q_f, v_f


def cable_constraint(model, h: float, p, min_tension) -> tuple[float | None, ca.Function | None]:
    """``(T_min, cable_pull)`` of the ``min_tension`` option (see the module docstring; the pull
    of :mod:`ncgen.optim.taut_cables` at the step's two force evaluations); ``(None, None)`` without it."""
    if min_tension is None:
        return None, None
    from ncgen.optim.taut_cables import cable_pull_function, tension_floor
    T_min = tension_floor(min_tension, "MPC: min_tension")
    pull = cable_pull_function(model, "MPC: min_tension")
    nq = model.nq
    x, x1, u, t = ca.SX.sym("x", 2 * nq), ca.SX.sym("x_next", 2 * nq), ca.SX.sym("u", model.nu), ca.SX.sym("t")
    w = (x1[:nq] - x[:nq]) / h
    P = ca.vertcat(pull(t, x[:nq], w, u, ca.DM(p)), pull(t + h, x1[:nq], w, u, ca.DM(p)))
    return T_min, ca.Function("cable_pull", [x, x1, u, t], [P], ["x", "x_next", "u", "t"], ["P"])


def weights(w, n: int, what: str) -> np.ndarray:
    """``w`` (a scalar or ``n`` numbers, each finite and ≥ 0) as ``n`` weights."""
    a = as_numbers(w, f"MPC: {what}") if np.ndim(w) else np.full(n, as_scalar(w, f"MPC: {what}"))
    if a.shape != (n,) or not np.all(np.isfinite(a)) or np.any(a < 0):
        raise OptimizationError(f"MPC: {what}: expected a number or {n} numbers, finite and >= 0, got "
                                f"{np.asarray(w).tolist() if np.size(w) <= 12 else np.shape(w)}")
    return a


def initial_state(ocp, p) -> np.ndarray:
    """``[q; v]`` of the OCP's ``initial(q=…, v=…)`` (coordinates given by name assembled
    with the others, velocities made consistent); the model's initial state where a part is
    the model's or left free."""
    from ncgen.optim.conditions import resolve_configuration, resolve_velocity
    from ncgen.optim.transcription import MODEL_STATE
    model, spec = ocp.model, ocp.initial_spec
    q = spec["q"]
    q = model.q0 if q is MODEL_STATE or q is None else resolve_configuration(model, q, model.q0, t=ocp.t0, p=p,
                                                                              what="initial q")
    v = spec["v"]
    v = model.v0 if v is MODEL_STATE or v is None else resolve_velocity(model, v, q, t=ocp.t0, p=p)
    return np.concatenate([q, v])


def bounded_states(problem) -> np.ndarray:
    """The state components with a finite bound: the QP's first rows, at nodes ``1..N``."""
    lo_x, hi_x = problem.x_bounds
    return np.flatnonzero(np.isfinite(lo_x) | np.isfinite(hi_x))


def qp_rows(problem, nx: int) -> int:
    """The condensed QP's general rows: the bounded state components at nodes ``1..N``, then,
    with ``min_tension``, the cables' pulls at both ends of every interval."""
    n_taut = 0 if problem.min_tension is None else problem.N * problem.cable_pull.numel_out(0)
    return problem.N * len(bounded_states(problem)) + n_taut
