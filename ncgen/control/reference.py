"""The discrete optimal-control problem of :func:`ncgen.control.ilqr.ilqr` solved by IPOPT:
an independent reference for iLQR (a different algorithm on the same equations); and that of
the joint-space step of a tree (:func:`solve_joint_discrete`).

Decision variables: the states ``x_1 … x_N``, the step unknowns ``z_k = [w; ν; v⁺; μ']`` and
the inputs ``u_k``; constraints: the step residual ``G(z_k; x_k, u_k, p, t_k) = 0`` and
``x_{k+1} = [q_k + h w_k; v⁺_k]`` (:mod:`ncgen.control.discrete`), all SX, so IPOPT gets
exact sparse Hessians.  Minimises the same ``Σ ℓ(x_k, u_k) + ℓ_N(x_N)``.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.control.costs import cost_functions
from ncgen.control.discrete import step_residual
from ncgen.errors import OptimizationError


class DiscreteOCP:
    """The discrete problem over ``N`` steps, built once (the initial state a parameter):
    :meth:`solve` re-solves it from another state and guess."""

    def __init__(self, st, N: int, costs, *, p=None, t0=None, tol: float = 1e-10, max_iter: int = 3000,
                 verbose: bool = False):
        model, h = st.model, st.h
        self.st, self.N = st, N
        stage_d, terminal_d = cost_functions(costs, st.nx, st.nu)
        nq, nc = model.nq, model.nc
        _, _, self.p, self.t0 = st._args(np.zeros(st.nx), np.zeros(st.nu), p, t0)
        G = step_residual(model, h)
        opti = ca.Opti()
        self.x0 = opti.parameter(st.nx)
        self.X = ca.horzcat(self.x0, opti.variable(st.nx, N))
        self.Z = opti.variable(2 * (nq + nc), N)
        self.U = opti.variable(st.nu, N)
        X, Z, U = self.X, self.Z, self.U
        times = self.t0 + h * np.arange(N)
        for k in range(N):
            opti.subject_to(G(Z[:, k], X[:, k], U[:, k], self.p, times[k]) == 0)
            opti.subject_to(X[:, k + 1] == ca.vertcat(X[:nq, k] + h * Z[:nq, k], Z[nq + nc:2 * nq + nc, k]))
        self.J = ca.sum2(stage_d.map(N)(X[:, :N], U)[0]) + terminal_d(X[:, N])[0]
        opti.minimize(self.J)
        opti.solver("ipopt", {"expand": True, "print_time": verbose},
                    {"tol": tol, "max_iter": max_iter, "print_level": 5 if verbose else 0, "sb": "yes"})
        self.opti = opti

    def solve(self, x0, U0) -> tuple[np.ndarray, np.ndarray, float]:
        """``(X, U, cost)`` from ``x0``, started from the rollout of ``U0``."""
        st, N, opti = self.st, self.N, self.opti
        nq, nc = st.model.nq, st.model.nc
        U0 = st._inputs(U0)
        x0 = st._args(x0, U0[0], self.p, self.t0)[0]
        X_guess = np.vstack([x0, st.rollout(x0, U0, self.p, self.t0)])
        opti.set_value(self.x0, x0)
        opti.set_initial(self.X[:, 1:], X_guess[1:].T)
        w = (X_guess[1:, :nq] - X_guess[:-1, :nq]) / st.h
        opti.set_initial(self.Z, np.hstack([w, np.zeros((N, nc)), X_guess[1:, nq:], np.zeros((N, nc))]).T)
        opti.set_initial(self.U, U0.T)
        try:
            sol = opti.solve()
        except RuntimeError as exc:
            raise OptimizationError(f"IPOPT on the discrete problem failed: {opti.stats()['return_status']} "
                                    f"({exc})") from None
        Xs = np.array(sol.value(self.X)).T
        Us = np.array(sol.value(self.U)).reshape(st.nu, N).T
        return Xs, Us, float(sol.value(self.J))


def solve_discrete(st, x0, U0, costs, *, p=None, t0=None, tol: float = 1e-10, max_iter: int = 3000,
                   verbose: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
    """``(X, U, cost)``: IPOPT on the discrete problem, started from the rollout of ``U0``."""
    U0 = st._inputs(U0)
    return DiscreteOCP(st, U0.shape[0], costs, p=p, t0=t0, tol=tol, max_iter=max_iter,
                       verbose=verbose).solve(x0, U0)


def solve_joint_discrete(step, x0, U0, costs, *, tol: float = 1e-10, max_iter: int = 3000,
                         verbose: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
    """``(X, U, cost)``: IPOPT on the discrete problem of the joint-space step ``step``
    (:class:`~ncgen.control.joint_step.JointStep`), started from the rollout of ``U0``.  The
    step is written through the inverse dynamics (RNEA, SX), not ABA:
    ``τ_k = RNEA(q_k, v_k, (v_{k+1} − v_k)/h)``, ``q_{k+1} = q_k + h v_{k+1}``; an independent
    check of iLQR on that step (another algorithm for the same dynamics, another solver)."""
    from ncgen.assembly.tree_algorithms import rnea_function

    model, h, n = step.model, step.h, step.n
    stage_d, terminal_d = cost_functions(costs, step.nx, step.nu)
    U0 = step._inputs(U0)
    N = U0.shape[0]
    X_guess = np.vstack([step.ilqr_start(x0, U0, None, None)[0], step.rollout(x0, U0)])
    rnea = rnea_function(model)
    p = model.p0 if step.p is None else step.p
    opti = ca.Opti()
    X1 = opti.variable(step.nx, N)
    X = ca.horzcat(X_guess[0], X1)
    U = opti.variable(step.nu, N)
    for k in range(N):
        q, v, v1 = X[:n, k], X[n:, k], X[n:, k + 1]
        opti.subject_to(rnea(0.0, q, v, (v1 - v) / h, p) == U[:, k])
        opti.subject_to(X[:n, k + 1] == q + h * v1)
    J = ca.sum2(stage_d.map(N)(X[:, :N], U)[0]) + terminal_d(X[:, N])[0]
    opti.minimize(J)
    opti.solver("ipopt", {"expand": True, "print_time": verbose},
                {"tol": tol, "max_iter": max_iter, "print_level": 5 if verbose else 0, "sb": "yes"})
    opti.set_initial(X1, X_guess[1:].T)
    opti.set_initial(U, U0.T)
    try:
        sol = opti.solve()
    except RuntimeError as exc:
        raise OptimizationError(f"IPOPT on the joint-space discrete problem failed: "
                                f"{opti.stats()['return_status']} ({exc})") from None
    Xs = np.vstack([X_guess[0], np.array(sol.value(X1)).reshape(step.nx, N).T])
    return Xs, np.array(sol.value(U)).reshape(step.nu, N).T, float(sol.value(J))
