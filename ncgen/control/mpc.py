"""``nc.MPC(ocp)``: a receding-horizon controller for an ``OptimalControl`` problem, in
generated C.

Each control step runs a fixed number of sequential-quadratic-programming iterations
(``iterations=1``: the real-time iteration of Diehl et al., 2005) on the problem of
:mod:`ncgen.control.mpc_problem`, from the previous step's solution shifted by one interval
(warm start).  One iteration, with the guess ``(X̄, Ū)`` (states at the ``N + 1`` nodes,
inputs on the ``N`` intervals):

1. the step and its exact Jacobians at every node, ``x̄⁺_k, A_k, B_k``
   (:mod:`ncgen.control.discrete`, implicit function theorem);
2. the QP in ``(δX, δU)``: minimise ``½ δᵀ H δ + gᵀ δ`` (``g``, ``H``: gradient and Hessian of
   the cost at the guess — a Gauss–Newton Hessian: the dynamics' curvature is left out, which
   is exact for the quadratic costs of ``OptimalControl``), subject to
   ``δx_0 = x − x̄_0``, ``δx_{k+1} = A_k δx_k + B_k δu_k + x̄⁺_k − x̄_{k+1}`` and the OCP's bounds
   moved by the guess — condensed onto the inputs (``vec δX = S δU + s``, :func:`condense`:
   ``N·nu`` variables, the bounded state components as general rows) and solved by CasADi's
   active-set ``qrqp``;
3. ``X̄ ← X̄ + δX``, ``Ū ← Ū + δU``.

The states are natural coordinates: each ``A_k`` has rank ``2 dof`` (it maps onto the
tangent space at ``x̄⁺_k``); the dynamics fix every ``δx_k`` from ``δx_0`` and the inputs, so
the condensed QP needs no minimal parametrisation.

An iteration is three generated functions (:func:`mpc_functions`): the QP's data, ``qrqp``
and the update.  They are separate so that the caller sees ``qrqp``'s status: it can stall on
a degenerate QP whose solution is its starting point (at convergence, gradients of 1e-12)
and then reports a failure although its last iterate is the solution; that iterate is used.
``mpc(x, t)`` calls the three through :class:`ncgen.codegen.direct.DirectFunction`;
:func:`ncgen.control.export.export_mpc` writes the same functions and the same loop in C, so
Python and C compute the same numbers.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.control.discrete import step_jacobian_function
from ncgen.control.mpc_problem import mpc_problem
from ncgen.errors import OptimizationError
from ncgen.validation import as_scalar

SOLVERS = ("sqp",)
#: Added to the diagonal of the QP Hessian (keeps it positive definite on the inputs).
REGULARIZATION = 1e-8


def mpc_functions(model, problem, *, regularization: float = REGULARIZATION,
                  qp_max_iter: int = 100) -> list[ca.Function]:
    """The three CasADi functions of one SQP iteration (see the module docstring):

    * ``mpc_qp_data: (x, t, X̄, Ū) -> (H, g, A, lba, uba, lbx, ubx, Xs, S)``: the condensed QP
      in ``δU`` (``vec δX = S δU + (Xs − vec X̄)``);
    * ``mpc_qp``: CasADi's ``qrqp`` on it (returns its last iterate also when it reports a
      failure: the caller decides);
    * ``mpc_update: (Xs, S, Ū, δU) -> (X, U)``: the new iterate.
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
                                 ca.vec(ca.repmat(hi_u, 1, N) - U), Xn, S)],
        ["x", "t", "X_guess", "U_guess"], ["H", "g", "A", "lba", "uba", "lbx", "ubx", "Xs", "S"])
    Xs_, S_, U_, dU = ca.MX.sym("Xs", nX), ca.MX.sym("S", nX, nU), ca.MX.sym("U", nu, N), ca.MX.sym("dU", nU)
    update = ca.Function("mpc_update", [Xs_, S_, U_, dU],
                         [ca.densify(ca.reshape(Xs_ + ca.mtimes(S_, dU), nx, N + 1)),
                          ca.densify(U_ + ca.reshape(dU, nu, N))],
                         ["Xs", "S", "U_guess", "dU"], ["X_sol", "U_sol"])
    return [data, qp, update]


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

    ``solver``: ``"sqp"`` (Gauss–Newton SQP with CasADi's ``qrqp``, generated C);
    ``iterations``: SQP iterations per control step (1: real-time iteration);
    ``terminal_weight``: weight ``W`` of the OCP's final conditions, soft in MPC
    (:mod:`ncgen.control.mpc_problem`).  The horizon is the OCP's: ``N`` intervals of
    ``h = t_final / N`` seconds, and ``mpc`` is meant to be called every ``h`` seconds.
    ``mpc.reset(x, iterations=...)`` (also done by the first call) sets the guess to ``x``
    held with zero inputs (clipped into their bounds) and iterates on it."""

    def __init__(self, ocp, solver: str = "sqp", *, iterations: int = 1, terminal_weight: float = 1e3,
                 regularization: float = REGULARIZATION, qp_max_iter: int = 100):
        if solver not in SOLVERS:
            hint = (" (Fatrop: not wired up yet; see docs/control.md)" if solver == "fatrop" else "")
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
        self._data, self._qp, self._update = (lib[f.name()] for f in self.functions)
        #: qrqp's status of each QP of the last control step (0: converged).
        self.qp_status: list[int] = []
        self.u_rest = np.clip(np.zeros(self.nu), *self.problem.u_bounds)
        self.X = self.U = self.solution = None

    def __repr__(self) -> str:
        return (f"<MPC of {self.model.name!r}: N={self.N}, h={self.h} s, {self.iterations} SQP "
                f"iteration(s) per step, qrqp>")

    def _solve(self, x, t: float, X: np.ndarray, U: np.ndarray):
        """``iterations`` SQP iterations from the guess ``(X, U)``: ``(X, U)`` after them.  A QP
        that qrqp reports as failed (it stalls on degenerate QPs whose solution is the
        starting point, at convergence) still gives its last iterate, as in the C package."""
        self.qp_status = []
        for _ in range(self.iterations):
            H, g, A, lba, uba, lbx, ubx, Xs, S = (o.copy() for o in self._data(x, t, X.ravel(), U.ravel()))
            self.qp_status.append(self._qp.status_call(H, g, A, lba, uba, lbx, ubx, 0.0, 0.0, 0.0))
            dU = self._qp.outputs[0].copy()
            Xn, Un = self._update(Xs, S, U.ravel(), dU)
            X, U = Xn.reshape(self.N + 1, self.nx).copy(), Un.reshape(self.N, self.nu).copy()
        return X, U

    def initial_guess(self, x) -> tuple[np.ndarray, np.ndarray]:
        """``(X, U)``: ``x`` at every node, inputs zero clipped into their bounds."""
        return np.tile(x, (self.N + 1, 1)), np.tile(self.u_rest, (self.N, 1))

    def reset(self, x, t: float | None = None, iterations: int = 0) -> None:
        """Start again from the guess of :meth:`initial_guess`, then run ``iterations``
        solves at ``x`` without shifting (to converge the first solution)."""
        from ncgen.control.step import _vector
        x = _vector(x, self.nx, "x", "the state [q; v]")
        t = self.model.t0 if t is None else as_scalar(t, "MPC.reset: t")
        if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) or iterations < 0:
            raise OptimizationError(f"MPC.reset: iterations: expected an integer >= 0, got {iterations!r}")
        self.X, self.U = self.initial_guess(x)
        for _ in range(iterations):
            self.X, self.U = self._solve(x, t, self.X, self.U)

    def __call__(self, x, t: float | None = None) -> np.ndarray:
        """The input to apply now, from the measured state ``x`` at time ``t``; the solution
        (``mpc.solution``: states and inputs along the horizon), shifted by one interval,
        is the next call's guess."""
        from ncgen.control.step import _vector
        x = _vector(x, self.nx, "x", "the state [q; v]")
        t = self.model.t0 if t is None else as_scalar(t, "MPC: t")
        if self.X is None:
            self.reset(x)
        X, U = self._solve(x, t, self.X, self.U)
        u = U[0].copy()
        if not np.all(np.isfinite(u)):
            raise OptimizationError(f"MPC of {self.model.name!r}: the control step returned {u.tolist()} "
                                    "(a step of the model failed along the horizon); reset() the guess")
        self.solution = (X, U)
        self.X = np.vstack([X[1:], X[-1:]])
        self.U = np.vstack([U[1:], U[-1:]])
        return u.copy()
