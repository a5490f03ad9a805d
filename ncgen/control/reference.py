"""The discrete optimal-control problem of :func:`ncgen.control.ilqr.ilqr` solved by IPOPT:
an independent reference for iLQR (a different algorithm on the same equations).

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


def solve_discrete(st, x0, U0, costs, *, p=None, t0=None, tol: float = 1e-10, max_iter: int = 3000,
                   verbose: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
    """``(X, U, cost)``: IPOPT on the discrete problem, started from the rollout of ``U0``."""
    model, h = st.model, st.h
    stage_d, terminal_d = cost_functions(costs, st.nx, st.nu)
    U0 = st._inputs(U0)
    N, nq, nc = U0.shape[0], model.nq, model.nc
    x0, _, p, t0 = st._args(x0, U0[0], p, t0)
    G = step_residual(model, h)
    X_guess = np.vstack([x0, st.rollout(x0, U0, p, t0)])
    opti = ca.Opti()
    X = ca.horzcat(ca.DM(x0), opti.variable(st.nx, N))
    Z = opti.variable(2 * (nq + nc), N)
    U = opti.variable(st.nu, N)
    times = t0 + h * np.arange(N)
    for k in range(N):
        opti.subject_to(G(Z[:, k], X[:, k], U[:, k], p, times[k]) == 0)
        opti.subject_to(X[:, k + 1] == ca.vertcat(X[:nq, k] + h * Z[:nq, k], Z[nq + nc:2 * nq + nc, k]))
    J = ca.sum2(stage_d.map(N)(X[:, :N], U)[0]) + terminal_d(X[:, N])[0]
    opti.minimize(J)
    opti.set_initial(X[:, 1:], X_guess[1:].T)
    w = (X_guess[1:, :nq] - X_guess[:-1, :nq]) / h
    opti.set_initial(Z, np.hstack([w, np.zeros((N, nc)), X_guess[1:, nq:], np.zeros((N, nc))]).T)
    opti.set_initial(U, U0.T)
    opti.solver("ipopt", {"expand": True, "print_time": verbose},
                {"tol": tol, "max_iter": max_iter, "print_level": 5 if verbose else 0, "sb": "yes"})
    try:
        sol = opti.solve()
    except RuntimeError as exc:
        raise OptimizationError(f"IPOPT on the discrete problem failed: {opti.stats()['return_status']} "
                                f"({exc})") from None
    Xs = np.array(sol.value(X)).T
    Us = np.array(sol.value(U)).reshape(st.nu, N).T
    return Xs, Us, float(sol.value(J))
