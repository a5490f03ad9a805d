"""The MPC's horizon problem (:mod:`ncgen.control.mpc_problem`) posed stage-wise for Fatrop
(Vanroye et al., 2023: an interior-point method exploiting the optimal-control structure),
CasADi's ``nlpsol("fatrop")`` with ``structure_detection="auto"``.

Stage ``k < N`` has the state ``x_k`` (nx) and the controls ``[u_k; z_k]`` (nu inputs, then the
RATTLE step's unknowns ``z = [w; ν; v⁺; μ']`` of :mod:`ncgen.control.discrete`), stage ``N``
the state only.  Decision variables in stage order ``x_0, u_0, z_0, x_1, …, x_N``; constraints
in stage order, all equalities:

* the gap ``x_{k+1} − [q_k + h w_k; v⁺_k] = 0`` (Fatrop's dynamics: explicit in the stage's
  state and controls),
* at stage 0 ``x_0 − x = 0`` (``x``: the measured state, a parameter with the time ``t``),
* the step residual ``G(z_k; x_k, u_k, p, t + k h) = 0`` (a path constraint of stage ``k``);

the bounds on inputs (``u_k``) and states (``x_k``, ``k ≥ 1``) are bounds on the variables.
Cost ``Σ ℓ(x_k, u_k) + ℓ_N(x_N)`` as the SQP's.  Exact Hessians (SX, expanded), no
condensing: Fatrop's Riccati recursion sees the stage structure.  The solution satisfies the
same discrete problem as the SQP's converged iterate, so both answer the same input.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ncgen.control.discrete import _step_state, step_residual
from ncgen.errors import OptimizationError

#: Fatrop's options for an MPC solve: quiet, a small initial barrier parameter (the guess is
#: the previous solution shifted, near the optimum: on the cart-pole's swing-up 1e-6 took 25 %
#: fewer iterations than 1e-3, the same closed loop to 2e-9), its convergence tolerance.
FATROP_OPTIONS = {"print_level": 0, "mu_init": 1e-6, "tolerance": 1e-8}


@dataclass
class FatropProblem:
    """The solver and the layout of its variables: ``solver(x0, p, lbx, ubx, lbg, ubg)``;
    ``state[k]``, ``input[k]``, ``unknowns[k]``: index arrays of ``x_k``, ``u_k``, ``z_k`` in
    the variable vector; ``lbx``, ``ubx``: the variables' bounds; ``ng``: number of
    constraints."""

    solver: ca.Function
    state: list
    input: list
    unknowns: list
    lbx: np.ndarray
    ubx: np.ndarray
    ng: int


def fatrop_problem(model, problem, *, options: dict | None = None) -> FatropProblem:
    """The stage-wise NLP of ``problem`` (an :class:`~ncgen.control.mpc_problem.MPCProblem`)
    and its Fatrop solver (see the module docstring); ``options``: Fatrop's own, over
    :data:`FATROP_OPTIONS`."""
    h, N, p = problem.h, problem.N, ca.DM(problem.p)
    nq, nc, nu = model.nq, model.nc, model.nu
    nx, nz = 2 * nq, 2 * (nq + nc)
    G = step_residual(model, h)
    x_meas, t = ca.SX.sym("x", nx), ca.SX.sym("t")
    X = [ca.SX.sym(f"x_{k}", nx) for k in range(N + 1)]
    U = [ca.SX.sym(f"u_{k}", nu) for k in range(N)]
    Z = [ca.SX.sym(f"z_{k}", nz) for k in range(N)]
    w, g, equality = [], [], []
    state, inputs, unknowns = [], [], []
    lo_u, hi_u = problem.u_bounds
    lo_x, hi_x = problem.x_bounds
    lbx, ubx = [], []
    J = problem.terminal(X[N], t + N * h)
    for k in range(N + 1):
        state.append(np.arange(len(lbx), len(lbx) + nx))
        w.append(X[k])
        lbx += [-np.inf] * nx if k == 0 else list(lo_x)
        ubx += [np.inf] * nx if k == 0 else list(hi_x)
        if k == N:
            break
        inputs.append(np.arange(len(lbx), len(lbx) + nu))
        unknowns.append(np.arange(len(lbx) + nu, len(lbx) + nu + nz))
        w += [U[k], Z[k]]
        lbx += list(lo_u) + [-np.inf] * nz
        ubx += list(hi_u) + [np.inf] * nz
        g.append(X[k + 1] - _step_state(X[k], Z[k], nq, nc, h))
        if k == 0:
            g.append(X[0] - x_meas)
        g.append(G(Z[k], X[k], U[k], p, t + k * h))
        J += problem.stage(X[k], U[k], t + k * h)
    g = ca.vertcat(*g)
    nlp = {"x": ca.vertcat(*w), "f": J, "g": g, "p": ca.vertcat(x_meas, t)}
    opts = {"structure_detection": "auto", "equality": [True] * g.numel(), "print_time": False,
            "fatrop": {**FATROP_OPTIONS, **(options or {})}}
    solver = ca.nlpsol("mpc_fatrop", "fatrop", nlp, opts)
    return FatropProblem(solver, state, inputs, unknowns, np.array(lbx, dtype=float), np.array(ubx, dtype=float),
                         g.numel())


def pack(fp: FatropProblem, X: np.ndarray, U: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """The variable vector of states ``X`` ((N + 1) × nx), inputs ``U`` (N × nu) and step
    unknowns ``Z`` (N × nz)."""
    out = np.empty(fp.lbx.size)
    for k, idx in enumerate(fp.state):
        out[idx] = X[k]
    for k, (iu, iz) in enumerate(zip(fp.input, fp.unknowns)):
        out[iu], out[iz] = U[k], Z[k]
    return out


def unpack(fp: FatropProblem, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(X, U, Z)`` of the variable vector ``w`` (the inverse of :func:`pack`)."""
    return (np.array([w[i] for i in fp.state]), np.array([w[i] for i in fp.input]).reshape(len(fp.input), -1),
            np.array([w[i] for i in fp.unknowns]))


def unknowns_guess(model, h: float, X: np.ndarray) -> np.ndarray:
    """Step unknowns consistent with the state guess ``X``: ``w_k = (q_{k+1} − q_k)/h``,
    ``v⁺_k = v_{k+1}``, multipliers zero."""
    nq, nc = model.nq, model.nc
    w = (X[1:, :nq] - X[:-1, :nq]) / h
    zeros = np.zeros((X.shape[0] - 1, nc))
    return np.hstack([w, zeros, X[1:, nq:], zeros])


class FatropSolver:
    """Fatrop on the stage-wise problem, one solve per call of :meth:`solve` from the guess
    given (the MPC's previous solution shifted: a primal warm start).  ``status`` and
    ``iteration_counts``: Fatrop's return status and interior-point iterations of each solve
    since :meth:`clear`."""

    def __init__(self, model, problem, options: dict | None = None):
        if options is not None and not (isinstance(options, dict) and all(isinstance(k, str) for k in options)):
            raise OptimizationError(f"MPC: fatrop_options: expected a dict of Fatrop's options by name, got {options!r}")
        self.model, self.problem = model, problem
        try:
            self.nlp = fatrop_problem(model, problem, options=options)
        except RuntimeError as exc:
            raise OptimizationError(f"MPC: Fatrop refused the problem or fatrop_options {options!r}: {exc}") from None
        self.status: list[str] = []
        self.iteration_counts: list[int] = []
        if options:                                # Fatrop reads its options at the first solve only
            self.check_options(options)

    def check_options(self, options: dict) -> None:
        """One solve from the problem's start held, so that an option Fatrop does not know, or
        a value of the wrong type, is refused now and by name."""
        x = self.problem.x_start
        X = np.tile(x, (self.problem.N + 1, 1))
        U = np.tile(np.clip(np.zeros(self.model.nu), *self.problem.u_bounds), (self.problem.N, 1))
        self.solve(x, self.model.t0, X, U, unknowns_guess(self.model, self.problem.h, X))
        status = self.status[-1]
        self.clear()
        if status.startswith("error"):
            raise OptimizationError(f"MPC: fatrop_options {options!r}: Fatrop refused them: "
                                    f"{status.splitlines()[-1]}")

    def clear(self) -> None:
        self.status.clear()
        self.iteration_counts.clear()

    def solve(self, x, t: float, X: np.ndarray, U: np.ndarray, Z: np.ndarray):
        """``(X, U, Z)``: Fatrop's solution from the guess ``(X, U, Z)`` at the measured state
        ``x`` and time ``t``, its inputs clipped into their bounds (Fatrop, as IPOPT, relaxes
        bounds by about 1e-8 relative: a saturated push came back as 20.00000016 N against
        20 N); the guess itself when Fatrop fails or answers anything not finite (its status
        says so)."""
        nlp = self.nlp
        try:
            r = nlp.solver(x0=pack(nlp, X, U, Z), p=np.concatenate([x, [t]]), lbx=nlp.lbx, ubx=nlp.ubx,
                           lbg=0.0, ubg=0.0)
            stats = nlp.solver.stats()
            status, success, count = str(stats.get("return_status")), bool(stats.get("success")), \
                int(stats.get("iter_count", -1))
            w = np.array(r["x"], dtype=float).ravel()
        except RuntimeError as exc:                 # an evaluation error inside Fatrop
            status, success, count, w = f"error: {exc}", False, -1, None
        self.iteration_counts.append(count)
        self.status.append(status if w is None or np.all(np.isfinite(w)) else f"{status}, not finite")
        if not success or not np.all(np.isfinite(w)):
            return X, U, Z
        X, U, Z = unpack(nlp, w)
        return X, np.clip(U, *self.problem.u_bounds), Z
