"""``nc.JointMPC``: a tracking MPC of a tree robot in joint space (e.g. the 7-DOF Panda).

The natural-coordinate :class:`~ncgen.control.mpc.MPC` steps the constrained natural
coordinates; a serial arm's joint space is smaller and its step cheaper.  This controller
works on :class:`~ncgen.control.joint_step.JointStep` (semi-implicit Euler on ABA, exact
Jacobians from ABA's derivatives, compiled C) by single shooting: at each control step, with
the previous inputs shifted by one interval as the guess ``Ū`` (``N`` intervals of ``h``):

1. roll the step out from the measured state ``x``: ``x̄_{k+1} = f(x̄_k, ū_k)``, ``A_k``, ``B_k``;
2. linearise: ``δx_{k+1} = A_k δx_k + B_k δu_k``, ``δx_0 = 0`` gives ``vec δX = S δU``
   (kept in its stages, :class:`~ncgen.control.stagewise_hessian.StagewiseHessian`: no
   ``S`` nor dense Hessian is formed for the default QP solver);
3. the Gauss–Newton QP of the tracking cost
   ``J = ½ Σ_{k=1..N} w_k ‖x_k − x_r(t_k)‖²_W + ½ Σ_{k=0..N−1} ‖u_k − τ_r(t_k)‖²_R``
   (``w_N = terminal_weight``, else 1; ``τ_r = RNEA(q_r, v_r, 0)``: the reference's holding
   torque) in ``δU``, with the torque bounds ``lb − Ū ≤ δU ≤ ub − Ū``, solved by projected
   Newton (:mod:`ncgen.control.box_qp`, its Newton steps by a Riccati recursion on the free
   inputs; or CasADi's ``qpOASES``, ``qrqp`` on the condensed dense Hessian);
4. a backtracking (Armijo) line search on the true cost along ``Ū + α δU``; an answer that is
   not finite, or no decrease, keeps ``Ū`` (``mpc.step_length`` 0).

``iterations`` such SQP iterations run per control step (1: the real-time iteration).  The
first input is returned, checked finite and inside its bounds.
"""
from __future__ import annotations

import numpy as np

from ncgen.blas_threads import one_blas_thread
from ncgen.control.box_qp import box_qp
from ncgen.control.joint_step import JointStep
from ncgen.control.mpc_qp import InProcessQP, check_qp_solver, qp_function
from ncgen.control.stagewise_hessian import StagewiseHessian
from ncgen.errors import NcgenError, OptimizationError
from ncgen.runtime.tree_algorithm_kernels import rnea
from ncgen.validation import as_scalar, as_vector

#: Step lengths of the line search, longest first, and its Armijo fraction.
ALPHAS = tuple(0.5 ** i for i in range(8))
ARMIJO = 1e-4
#: Added to the diagonal of the QP's Hessian.
REGULARIZATION = 1e-9


class JointMPC:
    """Tracking MPC of ``model`` in joint space (module docstring).

    * ``h`` (s), ``N``: the step and the number of intervals of the horizon;
    * ``reference(t)``: the joint positions ``q_r`` (rad, m) to track at time ``t``, or a
      pair ``(q_r, v_r)`` (rates, default zero);
    * ``state_weight``: ``W``'s diagonal, ``2 n`` values (positions then rates) or a pair of
      scalars ``(w_q, w_v)``; ``input_weight``: ``R``'s diagonal (``n`` values or a scalar);
      ``terminal_weight``: the factor of the last node's state cost;
    * ``bounds``: ``(lb, ub)`` on the efforts (N·m, N), default ``±effort`` of the model's
      joint limits (a URDF's ``<limit effort>``); a joint without one is unbounded;
    * ``qp_solver``: ``"box"`` (default: :func:`~ncgen.control.box_qp.box_qp`), or CasADi's
      ``"qpoases"`` or ``"qrqp"``; ``p``: parameter values.

    ``mpc(x, t)`` returns the efforts to apply over ``[t, t + h)`` from the state
    ``x = [q_j; v_j]``; ``mpc.reset()`` forgets the guess."""

    def __init__(self, model, h: float, N: int, reference, *, state_weight=(1e3, 1.0), input_weight=1e-3,
                 terminal_weight: float = 10.0, bounds=None, iterations: int = 1, qp_solver: str = "box",
                 qp_max_iter: int = 200, p=None):
        self.model, self.p = model, p
        self.step = JointStep(model, h, p=p)
        self.h, n = self.step.h, self.step.n
        self.N, self.iterations = _count(N, "N (intervals of the horizon)"), _count(iterations, "iterations")
        if not callable(reference):
            raise NcgenError(f"JointMPC: reference: expected a callable t -> q_r or (q_r, v_r), got {reference!r}")
        self.reference = reference
        self.W = _weights(state_weight, 2 * n, "state_weight")
        self.R = _weights(input_weight, n, "input_weight")
        self.terminal_weight = as_scalar(terminal_weight, "terminal_weight")
        self.lb, self.ub = self._bounds(bounds)
        self.qp_max_iter = _count(qp_max_iter, "qp_max_iter")
        self.qp = None if qp_solver == "box" else \
            InProcessQP(qp_function(check_qp_solver(qp_solver, "JointMPC"), N * n, 0, qp_max_iter))
        self.node_weights = np.ones(self.N)
        self.node_weights[-1] = self.terminal_weight
        self.U: np.ndarray | None = None
        self.step_length, self.cost, self.qp_solved = 0.0, np.nan, False

    def _bounds(self, bounds):
        n = self.step.n
        if bounds is None:
            effort = np.array([self.model.joint_limits.get(j, {}).get("effort", np.inf)
                               for j in self.model.joint_names], float)
            return -effort, effort
        if len(bounds) != 2:
            raise NcgenError(f"JointMPC: bounds: expected a pair (lb, ub) of {n} efforts each, got {bounds!r}")
        lb = np.broadcast_to(np.asarray(bounds[0], float), (n,)).copy()
        ub = np.broadcast_to(np.asarray(bounds[1], float), (n,)).copy()
        if np.any(np.isnan(lb)) or np.any(np.isnan(ub)) or np.any(lb > ub):
            raise NcgenError(f"JointMPC: bounds: expected lb ≤ ub, got lb = {lb}, ub = {ub}")
        return lb, ub

    def __repr__(self) -> str:
        return f"JointMPC({self.model.name!r}, h={self.h:g}, N={self.N}, iterations={self.iterations})"

    def reset(self) -> None:
        """Forget the guess: the next call starts from the reference's holding torques."""
        self.U = None

    def targets(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """``(X_r, U_r)``: the reference states at the nodes ``t + k h``, k = 1..N, and the
        holding torques at k = 0..N−1 (clipped into the bounds)."""
        n, N = self.step.n, self.N
        Xr = np.empty((N + 1, 2 * n))
        for k in range(N + 1):
            r = self.reference(t + k * self.h)
            q_r, v_r = (r if isinstance(r, tuple) else (r, np.zeros(n)))
            Xr[k, :n] = as_vector(q_r, n, "reference(t): q_r (joint positions)")
            Xr[k, n:] = as_vector(v_r, n, "reference(t): v_r (joint rates)")
        Ur = rnea(self.model, Xr[:N, :n], Xr[:N, n:], np.zeros((N, n)), p=self.p)
        return Xr[1:], np.clip(Ur, self.lb, self.ub)

    def total_cost(self, x: np.ndarray, U: np.ndarray, Xr: np.ndarray, Ur: np.ndarray) -> float:
        """``J`` of the inputs ``U`` from ``x`` (forward rollout); inf when it is not finite."""
        J = 0.0
        for k in range(self.N):
            x = self.step.unchecked(x, U[k])
            e, du = x - Xr[k], U[k] - Ur[k]
            J += 0.5 * (self.node_weights[k] * e @ (self.W * e) + du @ (self.R * du))
        return J if np.isfinite(J) else np.inf

    def _iteration(self, x: np.ndarray, U: np.ndarray, Xr: np.ndarray, Ur: np.ndarray) -> np.ndarray:
        N, nx, nu = self.N, self.step.nx, self.step.nu
        A, B, X = np.empty((N, nx, nx)), np.empty((N, nx, nu)), np.empty((N, nx))
        xk = x
        for k in range(N):
            xk, A[k], B[k] = self.step.unchecked_jacobians(xk, U[k])
            X[k] = xk
        ex, eu = X - Xr, (U - Ur).reshape(-1)
        w = self.node_weights[:, None] * self.W[None, :]
        r = np.tile(self.R, N)
        J0 = 0.5 * (np.sum(w * ex * ex) + eu @ (r * eu))
        if not np.isfinite(J0):
            raise OptimizationError(f"JointMPC: the rollout of the guess from x = {x} is not finite")
        H = StagewiseHessian(A, B, w, self.R + REGULARIZATION)
        g = H.adjoint(ex) + r * eu
        u = U.reshape(-1)
        lb, ub = np.tile(self.lb, N) - u, np.tile(self.ub, N) - u
        if self.qp is None:
            dU, solved, _ = box_qp(H, g, lb, ub, max_iter=self.qp_max_iter)
        else:
            solved = self.qp.status_call(H.dense(), g, [], [], [], lb, ub) == 0
            dU = self.qp.outputs[0]
        self.step_length, self.cost, self.qp_solved = 0.0, J0, solved
        if not np.all(np.isfinite(dU)):
            return U
        decrease = g @ dU + 0.5 * dU @ (H @ dU) if solved else g @ dU
        for alpha in ALPHAS:
            trial = np.clip(u + alpha * dU, np.tile(self.lb, N), np.tile(self.ub, N)).reshape(N, nu)
            J = self.total_cost(x, trial, Xr, Ur)
            if J <= J0 + ARMIJO * alpha * min(decrease, 0.0):
                self.step_length, self.cost = alpha, J
                return trial
        return U

    @one_blas_thread
    def __call__(self, x, t: float = 0.0) -> np.ndarray:
        x = as_vector(x, self.step.nx, "x (joint positions and rates [q_j; v_j])")
        t = as_scalar(t, "t")
        Xr, Ur = self.targets(t)
        if self.U is None:
            U = Ur.copy()
        else:
            U = np.vstack([self.U[1:], self.U[-1:]])
        for _ in range(self.iterations):
            U = self._iteration(x, U, Xr, Ur)
        self.U = U
        u = U[0].copy()
        if not (np.all(np.isfinite(u)) and np.all(u >= self.lb) and np.all(u <= self.ub)):
            raise OptimizationError(f"JointMPC: input {u} at t = {t:g} s is not finite or outside its bounds "
                                    f"[{self.lb}, {self.ub}]")
        return u


def _count(n, what: str) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise NcgenError(f"JointMPC: {what}: expected a positive integer, got {n!r}")
    return int(n)


def _weights(w, n: int, what: str) -> np.ndarray:
    if isinstance(w, tuple) and len(w) == 2 and n % 2 == 0 and np.ndim(w[0]) == 0:
        w = np.repeat(np.asarray(w, float), n // 2)
    w = np.broadcast_to(np.asarray(w, float), (n,)).copy() if np.ndim(w) == 0 else as_vector(w, n, what)
    if np.any(w < 0) or not np.all(np.isfinite(w)):
        raise NcgenError(f"JointMPC: {what}: expected nonnegative finite weights, got {w}")
    return w
