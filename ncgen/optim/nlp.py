"""From an :class:`~ncgen.optim.problem.OptimalControl` to a solved ``casadi.Opti`` NLP.

Constraint handling (why the equality-constraint Jacobian has full row rank):

* the transcription's rows are square and nonsingular in each interval's own unknowns
  (:mod:`ncgen.optim.radau`: the GGL form imposes ``Φ = 0`` and ``A v + Φ_t = 0`` at the
  collocation points, never at the initial node; the index-1 form and shooting keep them
  as invariants);
* at the initial node the invariants ``Φ(q) = 0`` and ``A v + Φ_t = 0`` are imposed once,
  and only where the initial state is a decision variable (a fixed initial state is
  projected onto the constraints and enters as a constant);
* partial targets (a member's pose) impose only their independent rows
  (:mod:`ncgen.optim.targets`);
* full-state final and periodic conditions impose their ``dof`` tangent components
  ``Nᵀ (x_N − x*)`` (:mod:`ncgen.optim.conditions`), never the ``nc`` components the
  dynamics already keep; a box around the target (inequalities, inactive at the
  solution) selects the branch;
* bounds on inputs, states, parameters and the final time are simple variable bounds
  (``detect_simple_bounds``), so they never enter the constraint Jacobian.

Every constraint group is recorded with a label so that a failure can name it
(:mod:`ncgen.optim.diagnostics`).
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ncgen.progress import bar, enabled
from ncgen.errors import OptimizationError
from ncgen.interrupts import deferred_interrupt
from ncgen.model.model import component_names
from ncgen.optim.diagnostics import DIAGNOSIS_BUDGET, RELAXABLE, SUCCESS, diagnose, violation_of
from ncgen.optim.guess import guess_duration, make_guess
from ncgen.assembly.manifold import tangent_basis
from ncgen.optim.conditions import (BRANCH_RADIUS, consistent_configuration, length_scale, resolve_configuration,
                                    resolve_velocity)
from ncgen.optim.result import OptimalTrajectory, SolverStats
from ncgen.optim.targets import joint_target, pose_target
from ncgen.optim.transcription import MODEL_STATE, Horizon


#: IPOPT options ncgen sets (``tol`` and ``max_iter`` come from ``solve``); everything else
#: is IPOPT's default, measured on benchmarks/optimal_control.py (benchmarks/README.md).
#: A former hard-coded ``mumps_pivtol = 1e-4`` cost 10× the iterations on the double
#: pendulum swing-up (425 vs 43) and is gone; ``ipopt={...}`` passes any option through.
IPOPT_DEFAULTS = {"sb": "yes"}

#: Drift ``max |Φ|`` on the nodes, relative to the shortest member's length², above which
#: the solution is reported as under-resolved (the transcription's error shows there).
DRIFT_WARNING = 1e-3


@dataclass
class Group:
    """A labelled block of constraints ``lb ≤ expr ≤ ub`` (``kind``: dynamics, invariant,
    initial, final, periodic, path, bound)."""

    label: str
    kind: str
    expr: object
    lb: np.ndarray
    ub: np.ndarray


class NLP:
    """The built problem: ``opti``, the constraint ``groups``, the discretisation ``disc``,
    the final time ``T`` and parameter vector ``p`` (MX or numbers)."""

    def __init__(self, ocp, elastic: bool = False):
        self.ocp = ocp
        self.model = ocp.model
        self.opti = ca.Opti()
        self.groups: list[Group] = []
        self.x_opt: np.ndarray | None = None
        self.elastic = elastic
        self.slacks: dict[str, object] = {}

    # ------------------------------------------------------------ constraints
    def constrain(self, label: str, kind: str, expr, lb=0.0, ub=0.0):
        expr = ca.vec(expr)
        n = expr.shape[0]
        if n == 0:
            return
        lb = np.broadcast_to(np.asarray(lb, dtype=float), (n,)).copy()
        ub = np.broadcast_to(np.asarray(ub, dtype=float), (n,)).copy()
        keep = np.isfinite(lb) | np.isfinite(ub)
        if not keep.all():
            idx = [int(i) for i in np.flatnonzero(keep)]
            if not idx:
                return
            expr, lb, ub = expr[idx], lb[idx], ub[idx]
        if self.elastic and kind in RELAXABLE:
            self._relaxed(label, expr, lb, ub)
        elif np.array_equal(lb, ub):
            self.opti.subject_to(expr == ca.DM(lb))
        else:
            self.opti.subject_to(self.opti.bounded(ca.DM(lb), expr, ca.DM(ub)))
        self.groups.append(Group(label, kind, expr, lb, ub))

    def _relaxed(self, label: str, expr, lb: np.ndarray, ub: np.ndarray):
        """``lb − s ≤ expr ≤ ub + s`` with a slack ``s ≥ 0`` per row (elastic mode)."""
        s = self.opti.variable(expr.shape[0])
        self.opti.subject_to(s >= 0)
        lo, hi = [int(i) for i in np.flatnonzero(np.isfinite(lb))], [int(i) for i in np.flatnonzero(np.isfinite(ub))]
        if lo:
            self.opti.subject_to(expr[lo] - ca.DM(lb[lo]) >= -s[lo])
        if hi:
            self.opti.subject_to(expr[hi] - ca.DM(ub[hi]) <= s[hi])
        self.slacks[label] = s

    # ------------------------------------------------------------------ build
    def build(self, warm_start):
        ocp, opti = self.ocp, self.opti
        p_num = self._time_and_parameters()
        q_init, v_init = self._initial_state(p_num)
        tN = ocp.t0 + guess_duration(ocp, warm_start)
        q_start = self.model.q0 if q_init is None else q_init
        self._final_targets(q_start, tN, p_num)
        guess, p_guess = make_guess(ocp, warm_start, q_start,
                                    np.zeros(self.model.nq) if v_init is None else v_init, self.q_final, p_num)
        self.guess = guess
        joint = getattr(ocp.transcription, "joint_space", False)
        hz = self._initial_node(joint, q_init, v_init, q_start, p_num)
        self.disc = disc = ocp.transcription.build(opti, self.model, hz)
        for label, e in disc.defects:
            self.constrain(label, "dynamics", e)
        if not joint:
            self._initial_invariants(q_init, v_init)
        self._markers_at("initial", 0, ocp.initial_spec["markers"])
        self._final_conditions(guess, q_init, p_num)
        self._bounds(q_init, v_init)
        self._path()
        if self.elastic:
            opti.minimize(sum(ca.sum1(v) for v in self.slacks.values()) if self.slacks else ca.MX(0))
        else:
            opti.minimize(self._objective())
        self._initial_values(joint, q_init, v_init, p_guess)

    def _time_and_parameters(self) -> np.ndarray:
        """The final time ``T`` and parameters ``p`` (variables where free, with their bounds);
        returns the parameters' values (the free ones at their given values)."""
        ocp, model, opti = self.ocp, self.model, self.opti
        if ocp.t_final_bounds is None:
            self.T = ocp.t_final
        else:
            self.T = opti.variable()
            self.constrain("bound on the final time", "bound", self.T, *ocp.t_final_bounds)
        p_num = ocp.p_values.copy()
        if ocp.p_free:
            free = sorted(ocp.p_free)
            self.p_var = opti.variable(len(free))
            entries = [self.p_var[free.index(i)] if i in ocp.p_free else ca.MX(p_num[i])
                       for i in range(model.np)]
            self.p = ca.vertcat(*entries)
            lo = [ocp.p_free[i][0] for i in free]
            hi = [ocp.p_free[i][1] for i in free]
            self.constrain("bounds on the free parameters", "bound", self.p_var, lo, hi)
        else:
            self.p_var = None
            self.p = ca.DM(p_num)
        return p_num

    def _final_targets(self, q_start, tN: float, p_num) -> None:
        """``q_final`` (a configuration, or the reference of a pose or joint target),
        ``pose_target`` and ``joint_target`` of the final conditions, resolved at ``tN`` from
        ``q_start``."""
        ocp, model = self.ocp, self.model
        self.q_final = None if ocp.final_spec["q"] is None else resolve_configuration(
            model, ocp.final_spec["q"], q_start, t=tN, p=p_num, what="final q")
        self.pose_target = self.joint_target = None
        if ocp.final_spec.get("pose"):
            self.pose_target = pose_target(model, ocp.final_spec["pose"], q_start, t=tN, p=p_num)
            self.q_final = self.pose_target.q_ref
        if ocp.final_spec.get("joints"):
            self.joint_target = joint_target(model, ocp.final_spec["joints"], q_start, t=tN, p=p_num)
            self.q_final = self.joint_target.q_ref

    def _initial_node(self, joint: bool, q_init, v_init, q_start, p_num) -> Horizon:
        """The initial node (``x0, w0`` in joint coordinates, or ``q0, v0``: variables where
        free) and the :class:`Horizon` the transcription builds on."""
        ocp, model, opti = self.ocp, self.model, self.opti
        if not joint:
            self.q0 = opti.variable(model.nq) if q_init is None else ca.DM(q_init)
            self.v0 = opti.variable(model.nq) if v_init is None else ca.DM(v_init)
            return Horizon(t0=ocp.t0, T=self.T, p=self.p, q0=self.q0, v0=self.v0, N=ocp.N)
        js = model.joint_space        # the initial node in joint coordinates; q₀ = q(q_j0) holds Φ = 0
        self._check_joint_space(q_start, p_num)
        self.x0 = opti.variable(js.nq) if q_init is None else ca.DM(js.positions(q_init))
        if v_init is None:
            self.w0 = opti.variable(js.nv)
        elif q_init is not None or not np.any(v_init):
            self.w0 = ca.DM(js.rates(q_start, v_init))
        else:
            raise OptimizationError("initial v: a nonzero velocity with a free initial q cannot be given in the "
                                    "joint-space form; fix the initial q, or use form='ggl'")
        self.q0, self.v0 = js.tree_function(model.layout)(self.x0, self.w0)
        return Horizon(t0=ocp.t0, T=self.T, p=self.p, q0=self.x0, v0=self.w0, N=ocp.N)

    def _initial_invariants(self, q_init, v_init) -> None:
        """``Φ(q₀) = 0`` where the initial q is free, ``A(q₀) v₀ + Φ_t = 0`` where either is."""
        f, t0 = self.model.functions, self.ocp.t0
        if q_init is None:
            self.constrain("initial position invariant Φ(q₀) = 0", "invariant", f["phi"](t0, self.q0, self.p))
        if q_init is None or v_init is None:
            vel = ca.mtimes(f["A"](t0, self.q0, self.p), self.v0) + f["phi_t"](t0, self.q0, self.p)
            if ca.symvar(vel):
                self.constrain("initial velocity invariant A(q₀) v₀ + Φ_t = 0", "invariant", vel)

    def _initial_values(self, joint: bool, q_init, v_init, p_guess) -> None:
        """IPOPT's starting point: the transcription's from the guess, then the free initial
        node, final time and parameters."""
        ocp, opti, guess = self.ocp, self.opti, self.guess
        start = self.disc.set_guess(opti, guess)
        g0 = np.array([ocp.t0])
        x0, w0 = (self.x0, self.w0) if joint else (self.q0, self.v0)
        if q_init is None:
            opti.set_initial(x0, start[0] if joint else guess.q(g0)[0])
        if v_init is None:
            opti.set_initial(w0, start[1] if joint else guess.v(g0)[0])
        if ocp.t_final_bounds is not None:
            opti.set_initial(self.T, guess.T)
        if self.p_var is not None:
            opti.set_initial(self.p_var, [p_guess[i] for i in sorted(ocp.p_free)])

    def _check_joint_space(self, q_start, p_num):
        """The joint-space form's forward kinematics uses the model's geometry: refuse it
        where parameters change the constraints (a free parameter in Φ, or fixed values that
        move the start off q(q_j))."""
        model, ocp = self.model, self.ocp
        js = model.joint_space
        if self.p_var is not None:
            dep = ca.jacobian(model.functions["phi"](ocp.t0, ca.DM(q_start), self.p), self.p_var)
            if dep.nnz():
                raise OptimizationError("a free parameter enters the constraints Φ, which the joint-space form "
                                        "cannot follow: use form='ggl'")
        q = np.array(js.tree_function(model.layout)(js.positions(q_start), np.zeros(js.nv))[0]).reshape(-1)
        phi = np.max(np.abs(np.array(model.functions["phi"](ocp.t0, q, p_num))), initial=0.0)
        if not phi <= 1e-9 * max(1.0, float(np.max(np.abs(q)))) ** 2:
            raise OptimizationError(f"the joints' forward kinematics misses the constraints by {phi:.3g} with these "
                                    "parameter values (a parameter changes the geometry): use form='ggl'")

    def _initial_state(self, p_num):
        ocp, model = self.ocp, self.model
        spec = ocp.initial_spec
        q, v = spec["q"], spec["v"]
        if q is MODEL_STATE:
            q = model.q0
        elif q is not None:
            q = resolve_configuration(model, q, model.q0, t=ocp.t0, p=p_num, what="initial q")
        if v is MODEL_STATE:
            v = model.v0
        elif isinstance(v, dict) and q is None:
            raise OptimizationError("initial v given by coordinate names needs a fixed initial q")
        if v is not None and q is not None:
            vp = resolve_velocity(model, v, q, t=ocp.t0, p=p_num)
            if not isinstance(v, dict) and np.max(np.abs(vp - v), initial=0.0) > 1e-6 * max(1.0, float(np.max(np.abs(v)))):
                k = int(np.argmax(np.abs(vp - v)))
                raise OptimizationError(f"initial v is not tangent to the constraints at the initial q: "
                                        f"{model.coordinate_names[k]} would change by {vp[k] - v[k]:.3g} m/s")
            v = vp
        if q is not None and self.p_var is not None:
            dep = ca.jacobian(model.functions["phi"](ocp.t0, ca.DM(q), self.p), self.p_var)
            if dep.nnz():
                raise OptimizationError("a free parameter enters the constraints Φ, so a fixed initial q "
                                        "cannot be consistent for every value: leave the initial q free")
        return q, v

    def _markers_at(self, when: str, node: int, markers):
        if not markers:
            return
        disc = self.disc
        r, _ = self.model.functions["markers"](disc.q[:, node], disc.v[:, node])
        for name, target in markers:
            j = self.model.marker_names.index(name)
            comp = [int(i) for i in np.flatnonzero(~np.isnan(target))]
            self.constrain(f"{when} marker {name!r}", when, r[comp, j] - ca.DM(target[comp]))

    def _final_conditions(self, guess, q_init, p_num):
        ocp, model, disc = self.ocp, self.model, self.disc
        spec, per = ocp.final_spec, ocp.periodic_spec
        tN = ocp.t0 + guess.T
        qN, vN = disc.q[:, -1], disc.v[:, -1]
        radius = BRANCH_RADIUS * length_scale(model)
        q_ref = None
        if self.pose_target is not None:
            target = self.pose_target
            q_ref = target.q_ref
            W = target.rows(model, t=tN, p=p_num)
            self.constrain(f"{target.label} (independent components)", "final", ca.mtimes(ca.DM(W), qN - ca.DM(q_ref)))
            Sq = ca.mtimes(ca.DM(target.S), qN)
            Sr = target.S @ q_ref
            self.constrain(f"{target.label} (branch box)", "final", Sq, Sr - radius, Sr + radius)
        elif self.joint_target is not None:
            target = self.joint_target
            q_ref = target.q_ref
            qj = disc.qj[:, -1] if disc.qj is not None else model.joint_space.positions(qN)
            eq, branch = target.residuals(qj)
            self.constrain(target.label, "final", eq)
            self.constrain(f"{target.label} (branch)", "final", branch, 0.0, np.inf)
        elif self.q_final is not None:
            q_ref = self.q_final
            N = tangent_basis(model, q_ref, t=tN, p=p_num)
            self.constrain("final q (tangent components)", "final", ca.mtimes(N.T, qN - ca.DM(q_ref)))
            self.constrain("final q (branch box)", "final", qN, q_ref - radius, q_ref + radius)
        if spec["v"] is not None:
            if q_ref is None:
                q_ref = consistent_configuration(model, guess.q(np.array([tN]))[0], t=tN, p=p_num,
                                                 what="final configuration of the initial guess", tolerance=1.0)
            v_ref = resolve_velocity(model, spec["v"], q_ref, t=tN, p=p_num)
            N = tangent_basis(model, q_ref, t=tN, p=p_num)
            self.constrain("final v (tangent components)", "final", ca.mtimes(N.T, vN - ca.DM(v_ref)))
        self._markers_at("final", -1, spec["markers"])
        if per["q"] or per["v"]:
            q_ref = q_init if q_init is not None else consistent_configuration(
                model, guess.q(np.array([ocp.t0]))[0], t=ocp.t0, p=p_num,
                what="initial configuration of the initial guess", tolerance=1.0)
            N = ca.DM(tangent_basis(model, q_ref, t=ocp.t0, p=p_num))
            if per["q"]:
                self.constrain("periodic q (tangent components)", "periodic", ca.mtimes(N.T, qN - disc.q[:, 0]))
                self.constrain("periodic q (branch box)", "periodic", qN - disc.q[:, 0], -radius, radius)
            if per["v"]:
                self.constrain("periodic v (tangent components)", "periodic", ca.mtimes(N.T, vN - disc.v[:, 0]))

    def _bounds(self, q_init, v_init):
        ocp, model, disc = self.ocp, self.model, self.disc
        for i, name in enumerate(component_names(model.input_names, model.input_sizes)):
            lo, hi = ocp.u_bounds[:, i]
            self.constrain(f"bound on input {name}", "bound", disc.U[i, :], lo, hi)
        for x, x0, fixed, bounds, what in ((disc.path_q, self.q0, q_init, ocp.q_bounds, "coordinate"),
                                           (disc.path_v, self.v0, v_init, ocp.v_bounds, "velocity of")):
            for i, name in enumerate(model.coordinate_names):
                lo, hi = bounds[:, i]
                if not (np.isfinite(lo) or np.isfinite(hi)):
                    continue
                self.constrain(f"bound on {what} {name}", "bound", x[i, :], lo, hi)
                if fixed is None:
                    self.constrain(f"bound on {what} {name} (initial node)", "bound", x0[i], lo, hi)
                elif not lo - 1e-12 <= fixed[i] <= hi + 1e-12:
                    raise OptimizationError(f"the initial state violates the bound on {what} {name}: "
                                            f"{fixed[i]:.6g} is outside [{lo:.6g}, {hi:.6g}]")
        for what, name, s, c, lo, hi in ocp.row_bounds:      # coordinates as written: s · x + c
            x, x0, fixed = (disc.path_q, self.q0, q_init) if what == "coordinate" else (disc.path_v, self.v0, v_init)
            row = ca.DM(s).T
            self.constrain(f"bound on {what} {name}", "bound", ca.mtimes(row, x) + c, lo, hi)
            if fixed is None:
                self.constrain(f"bound on {what} {name} (initial node)", "bound", ca.mtimes(row, x0) + c, lo, hi)
            elif not lo - 1e-12 <= s @ fixed + c <= hi + 1e-12:
                raise OptimizationError(f"the initial state violates the bound on {what} {name}: "
                                        f"{s @ fixed + c:.6g} is outside [{lo:.6g}, {hi:.6g}]")

    def _path(self):
        ocp, model, disc = self.ocp, self.model, self.disc
        if ocp.joint_bounds:
            js = model.joint_space
            npts = disc.path_q.shape[1]
            if disc.path_qj is not None:
                qj, vj = disc.path_qj, disc.path_vj
            else:
                qj = js.positions.map(npts)(disc.path_q)
                vj = js.rates.map(npts)(disc.path_q, disc.path_v)
            rows = {"position": js.slices(), "rate": js.slices(rates=True)}
            for name, kind, lo, hi in ocp.joint_bounds:
                i = rows[kind][name].start
                x = (qj if kind == "position" else vj)[i, :]
                if kind == "position" and disc.path_qj is None and js.angles[i]:
                    x = continuous_angle(x, lo, hi)
                self.constrain(f"path constraint on joint {name!r} ({kind})", "path", x, lo, hi)
        if ocp.cable_min_tension is not None:
            self._taut_cables()
        if not ocp.marker_bounds:
            return
        nm = len(model.marker_names)
        npts = disc.path_q.shape[1]
        r, _ = model.functions["markers"].map(npts)(disc.path_q, disc.path_v)
        for name, lo, hi in ocp.marker_bounds:
            j = model.marker_names.index(name)
            cols = list(range(j, nm * npts, nm))
            for c in range(model.dim):
                if np.isfinite(lo[c]) or np.isfinite(hi[c]):
                    self.constrain(f"path constraint on marker {name!r} ({'xyz'[c]})", "path",
                                   r[c, cols], lo[c], hi[c])

    def _taut_cables(self):
        """``P(t, q, v, u) ≥ T_min`` (:meth:`~ncgen.optim.problem.OptimalControl.min_tension`) at
        both ends of every interval and at its path points, each with the interval's input (the
        input jumps at the nodes, so node ``k`` is taken with ``u_{k−1}`` and with ``u_k``; the
        path points come interval by interval, the same number in each, the interval's end last)."""
        from ncgen.optim.taut_cables import cable_pull_function
        ocp, model, disc = self.ocp, self.model, self.disc
        pull = cable_pull_function(model, "min_tension")
        npts, N = disc.path_q.shape[1], ocp.N
        if npts % N:
            raise OptimizationError(f"min_tension: the transcription's {npts} path points are not the same number "
                                    f"in each of its {N} intervals")
        m, nu = npts // N, model.nu
        U = disc.U if nu else ca.DM(0, N)
        U_path = ca.reshape(ca.repmat(U, m, 1), nu, npts)      # column k m + j: U[:, k]
        t_start = ocp.t0 + self.T * ca.DM(np.arange(N)).T / N if disc.t_nodes is None else disc.t_nodes[:, :N]
        starts = pull.map(N)(t_start, disc.q[:, :N], disc.v[:, :N], U, self.p)
        P = pull.map(npts)(disc.path_t, disc.path_q, disc.path_v, U_path, self.p)
        T_min = ocp.cable_min_tension
        self.constrain("path constraint min_tension (cable pulls at the intervals' starts)", "path", ca.vec(starts),
                       T_min, np.inf)
        self.constrain("path constraint min_tension (cable pulls)", "path", ca.vec(P), T_min, np.inf)

    def _objective(self):
        ocp, model, disc = self.ocp, self.model, self.disc
        J = ca.MX(0)
        h = self.T / ocp.N
        if ocp.effort_R is not None and model.nu:
            w = h if disc.interval_w is None else disc.interval_w
            J += ca.sum2(w * ca.sum1(disc.U * ca.mtimes(ca.DM(ocp.effort_R), disc.U)))
        if disc.extra_cost is not None:
            J += disc.extra_cost
        if ocp.tracking:
            nm = len(model.marker_names)
            npts = disc.quad_q.shape[1]
            r, _ = model.functions["markers"].map(npts)(disc.quad_q, disc.quad_v)
            ref_t = disc.quad_t
            for name, ref, w in ocp.tracking:
                j = model.marker_names.index(name)
                R = _reference(ref, ref_t, model.dim, name)
                err = r[:, list(range(j, nm * npts, nm))] - R
                J += w * ca.sum2(disc.quad_w * ca.sum1(err * err))
        for label, term in ocp.terminal:
            qN, vN = disc.q[:, -1], disc.v[:, -1]
            if term[0] == "marker":
                _, name, target, w = term
                j = model.marker_names.index(name)
                r, _ = model.functions["markers"](qN, vN)
                comp = [int(i) for i in np.flatnonzero(~np.isnan(target))]
                J += w * ca.sumsqr(r[comp, j] - ca.DM(target[comp]))
            else:
                _, fn, w = term
                val = fn(qN, vN, self.p)
                if not isinstance(val, (ca.MX, ca.DM, float, int)) or ca.MX(val).numel() != 1:
                    raise OptimizationError(f"{label}: fn(q, v, p) must return a scalar CasADi expression")
                J += w * val
        if ocp.time_weight:
            J += ocp.time_weight * self.T
        return J

    # ------------------------------------------------------------------ solve
    def solve(self, *, max_iter: int, tol: float, verbose: bool, ipopt: dict, linear_solver: str = "mumps",
              max_wall_time: float | None = None):
        ocp, opti = self.ocp, self.opti
        options = {**IPOPT_DEFAULTS, "tol": tol, "constr_viol_tol": tol, "max_iter": max_iter,
                   "print_level": 5 if verbose else 0, "hessian_approximation": ocp.transcription.hessian,
                   "linear_solver": linear_solver, **ocp.transcription.ipopt_options, **ipopt}
        if max_wall_time is not None:
            options["max_wall_time"] = float(max_wall_time)
        solver_options = {"expand": self.disc.expandable, "detect_simple_bounds": True, "print_time": False,
                          "ipopt": options}
        if solver_options != getattr(self, "_solver_options", None):  # same options: IPOPT as built last time
            opti.solver("ipopt", solver_options)
            self._solver_options = solver_options
        start = time.perf_counter()
        shown = enabled(None) and not verbose          # IPOPT's own log replaces the bar
        with deferred_interrupt() as interrupt, \
                bar(max_iter, "IPOPT", unit="iter", mode=None if shown else False) as progress:
            def each_iteration(i):                       # Ctrl-C stops IPOPT at its next iteration
                interrupt.check(i)
                progress.update(1)
            opti.callback(each_iteration)
            try:
                self.value = opti.solve_limited().value
            except RuntimeError:               # IPOPT failed (infeasible, NaN, ...): the last iterate
                self.value = opti.debug.value
        status = opti.stats().get("return_status", "")
        if status in ("Invalid_Option", "Invalid_Problem_Definition"):
            raise OptimizationError(f"IPOPT refused its options ({status}): check ipopt={ipopt!r} and "
                                    f"linear_solver={options['linear_solver']!r} (MUMPS and SPRAL ship with "
                                    "CasADi; ma27, ma57, ... need the HSL library)")
        self.solve_time = time.perf_counter() - start
        self.x_opt = np.array(self.value(opti.x)).reshape(-1)
        return self.value


def build_and_solve(ocp, warm_start, *, max_iter: int, tol: float, verbose: bool, ipopt: dict,
                    linear_solver: str = "mumps", diagnose_budget: float = DIAGNOSIS_BUDGET):
    start = time.perf_counter()
    nlp = NLP(ocp)
    nlp.build(warm_start)
    build_time = time.perf_counter() - start
    value = ocp.transcription.solve(nlp, lambda **extra: nlp.solve(max_iter=max_iter, tol=tol, verbose=verbose,
                                                                   ipopt={**extra, **ipopt},
                                                                   linear_solver=linear_solver), tol)
    result = extract(nlp, value, build_time)
    ocp.transcription.finish(value, result)
    if not result.stats.success:
        message = diagnose(nlp, value, result, tol=tol, ipopt=ipopt, budget=diagnose_budget,
                           linear_solver=linear_solver)
        raise OptimizationError(message, result=result, status=result.stats.status)
    if result.stats.status != "Solve_Succeeded":
        warnings.warn(f"IPOPT: {result.stats.status} (objective {result.stats.objective:.6g}, max defect "
                      f"{result.stats.max_defect:.2e})", stacklevel=3)
    scale = length_scale(ocp.model) ** 2
    drift = float(np.max(result.constraint_residual, initial=0.0))
    if drift > DRIFT_WARNING * scale:
        warnings.warn(f"the constraints drift by up to |Φ| = {drift:.3g} m² on the nodes ({drift / scale:.2g} of the "
                      f"shortest member's length²): the mesh is too coarse for this motion, and the optimum may "
                      f"exploit the discretisation error; increase N (now {ocp.N})", stacklevel=3)
    return result


def extract(nlp: NLP, val, build_time: float) -> OptimalTrajectory:
    """The solution (or last iterate; ``val`` evaluates expressions there) as an
    :class:`OptimalTrajectory`."""
    ocp, model, disc = nlp.ocp, nlp.model, nlp.disc
    T = float(val(nlp.T)) if isinstance(nlp.T, ca.MX) else float(nlp.T)
    p = np.array(val(nlp.p)).reshape(-1) if isinstance(nlp.p, ca.MX) else np.array(nlp.p).reshape(-1)
    t = ocp.t0 + T * np.arange(ocp.N + 1) / ocp.N if disc.t_nodes is None else np.array(val(disc.t_nodes)).reshape(-1)
    q = np.array(val(disc.q)).reshape(model.nq, -1).T
    v = np.array(val(disc.v)).reshape(model.nq, -1).T
    u = np.array(val(disc.U)).reshape(model.nu, -1).T if model.nu else np.zeros((ocp.N, 0))
    lam = np.zeros((ocp.N + 1, model.nc))
    nodes = range(ocp.N + 1) if disc.lam is None else [0]      # the rest from the transcription's unknowns
    for k in nodes:
        _, lam_k = model.accel(q[k], v[k], t=t[k], u=u[min(k, ocp.N - 1)] if model.nu else None, p=p)
        lam[k] = np.atleast_1d(lam_k).reshape(model.nc)
    if disc.lam is not None and model.nc:
        lam[1:] = np.array(val(disc.lam)).reshape(model.nc, -1).T
    st = nlp.opti.stats()
    defect = max((float(np.max(np.abs(np.array(val(e))), initial=0.0)) for _, e in disc.defects), default=0.0)
    violation = max((violation_of(val, g) for g in nlp.groups), default=0.0)
    status = st.get("return_status", "unknown")
    stats = SolverStats(status=status, success=bool(st.get("success", False)) or status in SUCCESS,
                        iterations=int(st.get("iter_count", -1)), objective=float(val(nlp.opti.f)),
                        solve_time=nlp.solve_time, build_time=build_time, max_defect=defect,
                        max_violation=violation, n_variables=int(nlp.opti.nx), n_constraints=int(nlp.opti.ng),
                        method=ocp.transcription.describe())
    return OptimalTrajectory.from_solution(model, t=t, q=q, v=v, lam=lam, u=u, p=p, stats=stats, nlp=nlp)


def _reference(ref, times, dim: int, name: str):
    """Reference positions at the quadrature times (``dim × n``)."""
    if not callable(ref):
        return ca.repmat(ca.DM(ref), 1, times.shape[1])
    if isinstance(times, ca.DM):
        tt = np.array(times).reshape(-1)
        vals = np.array([np.asarray(ref(float(ti)), dtype=float).reshape(-1) for ti in tt])
        if vals.shape != (tt.size, dim):
            raise OptimizationError(f"track_marker {name!r}: reference(t) must return {dim} numbers")
        return ca.DM(vals.T)
    cols = []
    try:
        for i in range(times.shape[1]):
            val = ref(times[0, i])
            cols.append(ca.vec(val if isinstance(val, ca.MX) else ca.MX(ca.DM(val))))
    except Exception as exc:
        raise OptimizationError(f"track_marker {name!r}: with a free final time the reference is called with "
                                f"CasADi symbols and failed ({exc}); use casadi functions in it") from None
    return ca.horzcat(*cols)


def continuous_angle(theta, lower: float, upper: float):
    """A joint angle ``θ`` (rad, measured by ``atan2`` in (−π, π]) taken to the turn centred on
    the middle ``c`` of its bounds, ``c + atan2(sin(θ − c), cos(θ − c))``: continuous over
    ``[lower, upper]`` when that range is shorter than a turn (the Panda's joint 6 reaches
    3.75 rad, where ``θ`` itself jumps by 2π at π); ``θ`` unchanged otherwise."""
    if not (np.isfinite(lower) and np.isfinite(upper) and upper - lower < 2 * np.pi):
        return theta
    c = (lower + upper) / 2
    return c + ca.atan2(ca.sin(theta - c), ca.cos(theta - c))
