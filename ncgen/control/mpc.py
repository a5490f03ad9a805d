"""``nc.MPC(ocp)``: a receding-horizon controller for an ``OptimalControl`` problem, in
generated C.

Each control step runs a fixed number of sequential-quadratic-programming iterations
(``iterations=1``: the real-time iteration of Diehl et al., 2005) on the problem of
:mod:`ncgen.control.mpc_problem`, from the previous step's inputs shifted by one interval
(warm start).  The iterates are single-shooting ones: the states are always the rollout of
the inputs from the measured state ``x`` (so every iterate is on the constraint manifold and
dynamically feasible; a guess that does not roll out is an error, never an answer).  One
iteration from the inputs ``Ū`` (``N`` intervals) and their rollout ``X̄`` (``N + 1`` nodes):

1. the step and its exact Jacobians at every node, ``A_k, B_k``
   (:mod:`ncgen.control.discrete`, implicit function theorem);
2. the QP in ``(δX, δU)``: minimise ``½ δᵀ H δ + gᵀ δ`` (``g``, ``H``: gradient and Hessian of
   the cost at the guess — a Gauss–Newton Hessian: the dynamics' curvature is left out),
   subject to ``δx_0 = 0``, ``δx_{k+1} = A_k δx_k + B_k δu_k`` and the OCP's bounds moved by
   the guess — condensed onto the inputs (``vec δX = S δU``, :func:`condense`: ``N·nu``
   variables, the bounded state components as general rows) and solved by CasADi's
   active-set ``qrqp``;
3. a backtracking line search (:data:`ALPHAS`) on the ℓ1 merit function
   ``φ = J + ρ V`` (``J`` the cost of the rollout, ``V`` its violation of the state bounds,
   ``ρ = 1 + 2 max |λ|`` over the QP's multipliers of those bounds) along
   ``U(α) = clip(Ū + α δU)`` into the input bounds, each trial a rollout from ``x``: the first
   ``α`` with ``φ(α) ≤ φ(0) + c α D`` (``D = gᵀδU − ρ V``, ``c`` = :data:`ARMIJO`) is taken.
   A trial whose steps do not converge or that is not finite is rejected; when no ``α`` is
   accepted (or the QP's solution is not finite, or not a descent direction) the iterate is
   kept (``mpc.step_lengths``: 0).  So every input returned is inside its bounds and every
   iterate kept as a warm start is a converged, finite rollout.

An iteration is three generated functions (:func:`mpc_functions`): the QP's data, ``qrqp``
and the merit of trial inputs (:func:`merit_function`).  ``mpc(x, t)`` calls them through
:class:`ncgen.codegen.direct.DirectFunction`; :func:`ncgen.control.export.export_mpc` writes
the same functions and the same loop in C, so Python and C compute the same numbers.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.control.discrete import step_jacobian_function
from ncgen.control.mpc_problem import mpc_problem
from ncgen.errors import OptimizationError

SOLVERS = ("sqp",)
#: Added to the diagonal of the QP Hessian (keeps it positive definite on the inputs).
REGULARIZATION = 1e-8
#: Step lengths tried by the line search, longest first, and its Armijo fraction.
ALPHAS = tuple(0.5 ** i for i in range(11))
ARMIJO = 1e-4


def mpc_functions(model, problem, *, regularization: float = REGULARIZATION,
                  qp_max_iter: int = 100) -> list[ca.Function]:
    """The three CasADi functions of one SQP iteration (see the module docstring):

    * ``mpc_qp_data: (x, t, X̄, Ū) -> (H, g, A, lba, uba, lbx, ubx)``: the condensed QP in
      ``δU`` at the guess (``X̄``: the rollout of ``Ū`` from ``x``);
    * ``mpc_qp``: CasADi's ``qrqp`` on it (returns its last iterate also when it reports a
      failure: the caller checks it);
    * ``mpc_merit`` (:func:`merit_function`): the rollout of trial inputs, its cost and its
      violation of the state bounds, for the line search.
    """
    h, N, p = problem.h, problem.N, problem.p
    nx, nu = 2 * model.nq, model.nu
    jac = step_jacobian_function(model, h).map(N)

    # cost, its gradient and (Gauss–Newton) Hessian in y = [vec X; vec U] (SX)
    Xs, Us = ca.SX.sym("X", nx, N + 1), ca.SX.sym("U", nu, N)
    J = sum(problem.stage(Xs[:, k], Us[:, k]) for k in range(N)) + problem.terminal(Xs[:, N])
    y = ca.vertcat(ca.vec(Xs), ca.vec(Us))
    H_sx, g_sx = ca.hessian(J, y)
    H_sx = H_sx + regularization * ca.SX.eye(y.numel())
    cost = ca.Function("mpc_cost", [Xs, Us], [H_sx, g_sx])
    nX, nU = nx * (N + 1), nu * N
    # the condensed QP's general rows: the bounded state components at nodes 1..N
    lo_x, hi_x = problem.x_bounds
    bounded = np.flatnonzero(np.isfinite(lo_x) | np.isfinite(hi_x))
    rows = [nx * k + i for k in range(1, N + 1) for i in bounded]
    qp = ca.conic("mpc_qp", "qrqp", {"h": ca.Sparsity.dense(nU, nU), "a": ca.Sparsity.dense(len(rows), nU)},
                  {"print_iter": False, "print_header": False, "print_info": False, "max_iter": qp_max_iter,
                   "error_on_fail": False})

    x, t = ca.MX.sym("x", nx), ca.MX.sym("t")
    X, U = ca.MX.sym("X", nx, N + 1), ca.MX.sym("U", nu, N)
    lo_u, hi_u = (ca.DM(b) for b in problem.u_bounds)
    times = t + h * ca.DM(np.arange(N)).T
    x1, A, B, _, _ = jac(X[:, :N], U, ca.repmat(ca.DM(p), 1, N), times)
    H, g = cost(X, U)
    S, s = condense(A, B, x - X[:, 0], x1 - X[:, 1:], N)
    H_XX, H_XU, H_UU = H[:nX, :nX], H[:nX, nX:], H[nX:, nX:]
    Hc = ca.mtimes(S.T, ca.mtimes(H_XX, S) + H_XU) + ca.mtimes(H_XU.T, S) + H_UU
    gc = ca.mtimes(S.T, ca.mtimes(H_XX, s) + g[:nX]) + ca.mtimes(H_XU.T, s) + g[nX:]
    Xn = ca.vec(X) + s
    data = ca.Function(
        "mpc_qp_data", [x, t, X, U],
        [ca.densify(e) for e in (0.5 * (Hc + Hc.T), gc, S[rows, :], ca.DM(np.tile(lo_x[bounded], N)) - Xn[rows],
                                 ca.DM(np.tile(hi_x[bounded], N)) - Xn[rows], ca.vec(ca.repmat(lo_u, 1, N) - U),
                                 ca.vec(ca.repmat(hi_u, 1, N) - U))],
        ["x", "t", "X_guess", "U_guess"], ["H", "g", "A", "lba", "uba", "lbx", "ubx"])
    return [data, qp, merit_function(model, problem)]


def merit_function(model, problem) -> ca.Function:
    """``mpc_merit: (x, t, U) -> (X, J, V, res)``: the rollout of the inputs ``U`` (nu × N)
    from the measured state ``x`` (``X``: nx × (N + 1), node 0 is ``x``), its cost ``J``, the
    violation ``V = Σ_{k≥1} Σ_i max(0, lo_i − x_k,i) + max(0, x_k,i − hi_i)`` of the state
    bounds and the largest residual ``res`` of the steps' Newton iterations."""
    from ncgen.control.discrete import step_functions
    h, N, p = problem.h, problem.N, problem.p
    nx, nu = 2 * model.nq, model.nu
    step = step_functions(model, h)["step"]
    x, t, U = ca.MX.sym("x", nx), ca.MX.sym("t"), ca.MX.sym("U", nu, N)
    times = t + h * ca.DM(np.arange(N)).T
    Xn, res = step.mapaccum("mpc_rollout", N, [0], [0])(x, U, ca.repmat(ca.DM(p), 1, N), times)
    X = ca.horzcat(x, Xn)
    Xs, Us = ca.SX.sym("X", nx, N + 1), ca.SX.sym("U", nu, N)
    cost = ca.Function("mpc_total_cost", [Xs, Us], [sum(problem.stage(Xs[:, k], Us[:, k]) for k in range(N))
                                                    + problem.terminal(Xs[:, N])])
    lo_x, hi_x = problem.x_bounds
    bounded = np.flatnonzero(np.isfinite(lo_x) | np.isfinite(hi_x))
    V = ca.MX(0)
    for i in bounded:
        row = Xn[int(i), :]
        if np.isfinite(lo_x[i]):
            V += ca.sum2(ca.fmax(0, float(lo_x[i]) - row))
        if np.isfinite(hi_x[i]):
            V += ca.sum2(ca.fmax(0, row - float(hi_x[i])))
    return ca.Function("mpc_merit", [x, t, U], [X, cost(X, U), V, ca.mmax(res)], ["x", "t", "U"],
                       ["X", "J", "V", "res"])


def condense(A, B, d0, defects, N: int):
    """``(S, s)`` with ``vec δX = S vec δU + s`` from ``δx_0 = d0`` and
    ``δx_{k+1} = A_k δx_k + B_k δu_k + defects_k`` (``A``: nx × nx·N, ``B``: nx × nu·N)."""
    nx, nu = A.size1(), B.size2() // N
    S_rows, s_rows = [ca.MX(nx, nu * N)], [d0]
    for k in range(N):
        A_k, B_k = A[:, nx * k:nx * (k + 1)], B[:, nu * k:nu * (k + 1)]
        pad = [ca.MX(nx, nu * k), B_k, ca.MX(nx, nu * (N - k - 1))]
        S_rows.append(ca.mtimes(A_k, S_rows[-1]) + ca.horzcat(*pad))
        s_rows.append(ca.mtimes(A_k, s_rows[-1]) + defects[:, k])
    return ca.vertcat(*S_rows), ca.vertcat(*s_rows)


class MPC:
    """A receding-horizon controller for ``ocp`` (an :class:`~ncgen.optim.problem.OptimalControl`):
    ``u = mpc(x, t)``.

    ``solver``: ``"sqp"`` (Gauss–Newton SQP with CasADi's ``qrqp`` and a line search on an
    ℓ1 merit function, generated C; see the module docstring);
    ``iterations``: SQP iterations per control step (1: real-time iteration);
    ``terminal_weight``: weight ``W`` of the OCP's final conditions, soft in MPC
    (:mod:`ncgen.control.mpc_problem`).  The horizon is the OCP's: ``N`` intervals of
    ``h = t_final / N`` seconds, and ``mpc`` is meant to be called every ``h`` seconds.
    ``mpc.reset(x, iterations=...)`` (also done by the first call) sets the guess to the
    rollout of zero inputs (clipped into their bounds) from ``x`` and iterates on it.
    ``mpc.qp_status`` and ``mpc.step_lengths`` report each iteration of the last call."""

    def __init__(self, ocp, solver: str = "sqp", *, iterations: int = 1, terminal_weight: float = 1e3,
                 regularization: float = REGULARIZATION, qp_max_iter: int = 100):
        if solver not in SOLVERS:
            hint = (" (Fatrop is not wired into ncgen's MPC: CasADi's wheel ships libfatrop, its conic and "
                    "nlpsol plugins and headers, but the MPC does not yet pose its QP in Fatrop's stage-wise form "
                    "nor link the exported C package against libfatrop (C++); see docs/control.md)"
                    if solver == "fatrop" else "")
            raise OptimizationError(f"MPC: solver: expected one of {', '.join(SOLVERS)}, got {solver!r}{hint}")
        if not isinstance(iterations, int) or iterations < 1:
            raise OptimizationError(f"MPC: iterations: expected a positive integer, got {iterations!r}")
        self.ocp, self.model = ocp, ocp.model
        self.problem = mpc_problem(ocp, terminal_weight)
        self.h, self.N = self.problem.h, self.problem.N
        self.nx, self.nu = 2 * self.model.nq, self.model.nu
        self.iterations = iterations
        self.functions = mpc_functions(self.model, self.problem, regularization=regularization,
                                       qp_max_iter=qp_max_iter)
        from ncgen.control.step import _compile
        lib = _compile(f"{self.model.name}_mpc", self.functions)
        self._data, self._qp, self._merit = (lib[f.name()] for f in self.functions)
        self._residual_tol = residual_tolerance(self.model)
        #: qrqp's status of each QP of the last control step (0: converged).
        self.qp_status: list[int] = []
        #: the step length α taken by each SQP iteration of the last control step (0: the line
        #: search found no decrease of the merit function, the iterate was kept).
        self.step_lengths: list[float] = []
        self.u_bounds = self.problem.u_bounds
        self.u_rest = np.clip(np.zeros(self.nu), *self.u_bounds)
        self.X = self.U = self.solution = None

    def __repr__(self) -> str:
        return (f"<MPC of {self.model.name!r}: N={self.N}, h={self.h} s, {self.iterations} SQP "
                f"iteration(s) per step, qrqp>")

    def _rollout(self, x, t: float, U: np.ndarray):
        """``(X, φ-parts)``: the rollout of ``U`` from ``x`` and ``(J, V)``, or ``None`` when a
        step did not converge or anything is not finite (a diverging trial)."""
        X, J, V, res = (o.copy() for o in self._merit(x, t, U.ravel()))
        if not (float(res[0]) <= self._residual_tol and np.all(np.isfinite(X)) and np.isfinite(J[0])
                and np.isfinite(V[0])):
            return None
        return X.reshape(self.N + 1, self.nx), float(J[0]), float(V[0])

    def _solve(self, x, t: float, U: np.ndarray):
        """``iterations`` globalised SQP iterations from the inputs ``U``: ``(X, U)``, ``X`` the
        rollout of ``U`` from ``x`` (see :func:`sqp_iteration`)."""
        self.qp_status, self.step_lengths = [], []
        start = self._rollout(x, t, U)
        if start is None:
            raise OptimizationError(f"MPC of {self.model.name!r}: the guess does not roll out from the state "
                                    f"{np.asarray(x).tolist()} at t = {t:g} s (a step of the model did not "
                                    "converge along the horizon); reset() the guess")
        X, J, V = start
        for _ in range(self.iterations):
            X, U, J, V = self._iteration(x, t, X, U, J, V)
        return X, U

    def _iteration(self, x, t, X, U, J, V):
        """One SQP iteration: the QP at the rollout ``(X, U)``, then the backtracking line search
        on the ℓ1 merit ``φ = J + ρ V`` (``ρ = 1 + 2 max |λ|`` of the QP's state-bound rows)
        along ``U(α) = clip(U + α δU)`` (each trial a rollout from ``x``), accepted at
        ``φ(α) ≤ φ(0) + c α D`` (``D = gᵀδU − ρ V``, its predicted derivative, ``c`` =
        :data:`ARMIJO`); no accepted ``α`` of :data:`ALPHAS`, a non-finite or out-of-bounds
        QP solution: the iterate is kept (α = 0)."""
        H, g, A, lba, uba, lbx, ubx = (o.copy() for o in self._data(x, t, X.ravel(), U.ravel()))
        self.qp_status.append(self._qp.status_call(H, g, A, lba, uba, lbx, ubx, 0.0, 0.0, 0.0))
        dU, lam_a = self._qp.outputs[0].copy(), self._qp.outputs[2].copy()
        if not (np.all(np.isfinite(dU)) and np.all(np.isfinite(lam_a))):
            self.step_lengths.append(0.0)
            return X, U, J, V
        rho = 1.0 + 2.0 * _max_abs(lam_a)
        phi0, D = J + rho * V, _dot(g, dU) - rho * V
        lo, hi = (np.tile(b, self.N) for b in self.u_bounds)
        if D < 0:
            for alpha in ALPHAS:
                Un = np.minimum(np.maximum(U.ravel() + alpha * dU, lo), hi)
                trial = self._rollout(x, t, Un)
                if trial is not None and trial[1] + rho * trial[2] <= phi0 + ARMIJO * alpha * D:
                    self.step_lengths.append(alpha)
                    return trial[0], Un.reshape(self.N, self.nu), trial[1], trial[2]
        self.step_lengths.append(0.0)
        return X, U, J, V

    def initial_guess(self, x) -> tuple[np.ndarray, np.ndarray]:
        """``(X, U)``: ``x`` at every node, inputs zero clipped into their bounds."""
        return np.tile(x, (self.N + 1, 1)), np.tile(self.u_rest, (self.N, 1))

    def reset(self, x, t: float | None = None, iterations: int = 0) -> None:
        """Start again from the inputs of :meth:`initial_guess` (their rollout from ``x``),
        then run ``iterations`` solves at ``x`` without shifting (to converge the first
        solution)."""
        from ncgen.control.step import _vector
        x = _vector(x, self.nx, "x", "the state [q; v]")
        t = self.model.t0 if t is None else float(t)
        _, U = self.initial_guess(x)
        start = self._rollout(x, t, U)
        if start is None:
            raise OptimizationError(f"MPC of {self.model.name!r}: the inputs at rest do not roll out from the "
                                    f"state {np.asarray(x).tolist()} (a step of the model did not converge "
                                    "along the horizon)")
        X = start[0]
        for _ in range(iterations):
            X, U = self._solve(x, t, U)
        self.X, self.U = X, U

    def __call__(self, x, t: float | None = None) -> np.ndarray:
        """The input to apply now, from the measured state ``x`` at time ``t``; the solution
        (``mpc.solution``: states and inputs along the horizon), shifted by one interval,
        is the next call's guess.  The input is inside its bounds (checked)."""
        from ncgen.control.step import _vector
        x = _vector(x, self.nx, "x", "the state [q; v]")
        if self.X is None:
            self.reset(x)
        t = self.model.t0 if t is None else float(t)
        X, U = self._solve(x, t, self.U)
        u = U[0].copy()
        lo, hi = self.u_bounds
        if not (np.all(np.isfinite(u)) and np.all(lo <= u) and np.all(u <= hi)):
            raise OptimizationError(f"MPC of {self.model.name!r}: the control step returned {u.tolist()}, "
                                    f"outside the bounds [{lo.tolist()}, {hi.tolist()}]")
        self.solution = (X, U)
        self.X = np.vstack([X[1:], X[-1:]])
        self.U = np.vstack([U[1:], U[-1:]])
        return u


def residual_tolerance(model) -> float:
    """The Newton residual above which a step is refused (as :class:`ncgen.control.step.StepFunction`)."""
    from ncgen.control.step import RESIDUAL_TOL
    return RESIDUAL_TOL * (1.0 + float(np.max(np.abs(model.M))) if model.nq else 1.0)


def _max_abs(a: np.ndarray) -> float:
    """``max |a_i|`` (0 for an empty array)."""
    return float(np.max(np.abs(a))) if a.size else 0.0


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """``aᵀb`` summed left to right, as the generated package's C does (same rounding)."""
    out = 0.0
    for ai, bi in zip(a.tolist(), b.tolist()):
        out += ai * bi
    return out
