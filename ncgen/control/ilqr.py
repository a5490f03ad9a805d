"""iLQR/DDP on a compiled step (:class:`ncgen.control.step.StepFunction`).

Problem: minimise ``J = Σ_{k<N} ℓ(x_k, u_k) + ℓ_N(x_N)`` subject to ``x_{k+1} = st(x_k, u_k)``
from a given ``x_0`` (costs: :mod:`ncgen.control.costs`).  Each iteration: the step's exact
Jacobians ``A_k, B_k`` and the costs' derivatives along the current trajectory; the exact
gradient ``∂J/∂U`` (adjoint recursion, :func:`gradient`), whose ∞-norm is the stopping test
(``tol``); a backward Riccati pass giving feed-forward ``k_k`` and feedback ``K_k``; a
forward pass through the nonlinear step, ``u_k = ū_k + α k_k + K_k (x_k − x̄_k)``, with a
backtracking line search on ``α`` (Armijo on the true cost, :data:`ARMIJO`).
Levenberg–Marquardt regularisation ``Q_uu + μ I`` (μ raised tenfold on a failed pass or a
non-positive ``Q_uu``, lowered tenfold after a success; Tassa, Erez & Todorov 2012).  After an
iteration whose full step (``α = 1``) was accepted, the backward pass is DDP's: it adds the
step's second derivatives contracted with ``V_x`` (:mod:`ncgen.control.step_curvature`),
which makes the final convergence quadratic; after a shortened step it is Gauss–Newton
(iLQR) again, which is more robust far from the optimum (``second_order=False``: always).
On a model with nonsmooth contacts (:mod:`ncgen.control.contact_step`) the step's Jacobians
are those of the active set of each step's contact solve (one-sided at switching points) and
it is Gauss–Newton throughout (no second derivatives of a contact step).

The constraint manifold.  The iterations run in natural coordinates ``x = [q; v]``: every
trajectory is a rollout of the step, so it satisfies both constraint levels exactly, and
``A_k`` maps every perturbation into the tangent space at ``x_{k+1}``.  The value
function's Hessian ``V_xx`` is therefore only ever applied to tangent directions, and the
feedback ``K_k (x − x̄_k)`` is evaluated on differences of states of the manifold (tangent to
first order); directions normal to the manifold carry no cost curvature and no dynamics, so
nothing needs regularising there beyond ``Q_uu``.  (:meth:`StepFunction.reduced_jacobians`
gives the same recursion in a minimal tangent basis.)  Inputs are unconstrained.
The joint-space step of a tree (:class:`~ncgen.control.joint_step.JointStep`, ``x = [q_j; v_j]``)
is taken too, with its own checks of ``x0`` (``st.ilqr_start``), Gauss–Newton throughout.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import numpy as np

from ncgen.blas_threads import one_blas_thread
from ncgen.control.costs import cost_functions
from ncgen.control.initial import check_consistent
from ncgen.control.step_curvature import StepCurvature
from ncgen.errors import NcgenError, OptimizationError
from ncgen.validation import nonnegative

MU_MIN, MU_MAX, MU_FACTOR = 1e-9, 1e10, 10.0
ALPHAS = tuple(0.5 ** i for i in range(16))
#: Armijo fraction: a trial step is accepted when the cost falls by at least this fraction of
#: the decrease the quadratic model predicts for it.
ARMIJO = 1e-4


@dataclass
class ILQRResult:
    """``X`` (N+1, nx) states from ``x0``; ``U`` (N, nu) inputs; ``K`` (N, nu, nx) feedback
    gains of the last backward pass (``u = U_k + K_k (x − X_k)``); ``cost``; ``iterations``;
    ``gradient_norm``: ``‖∂J/∂U‖∞`` of the discrete problem at ``U`` (the exact gradient through
    the rollout, by the adjoint recursion); ``converged``: ``gradient_norm ≤ tol``, a
    stationary point of the discrete problem; ``history`` of costs, ``gradient_history`` of
    gradient norms (one per accepted iterate, the guess first)."""

    X: np.ndarray
    U: np.ndarray
    K: np.ndarray
    cost: float
    iterations: int
    converged: bool
    gradient_norm: float = np.nan
    history: list = field(default_factory=list)
    gradient_history: list = field(default_factory=list)
    message: str = ""


@one_blas_thread
def ilqr(st, x0, U0, costs, *, p=None, t0=None, max_iter: int = 200, tol: float = 1e-8,
         mu: float = 1e-6, second_order: bool = True, verbose: bool = False) -> ILQRResult:
    """iLQR from the initial guess ``U0`` (N × nu); ``costs = (stage, terminal)`` as in
    :mod:`ncgen.control.costs`.  Stops, converged, at the first iterate whose exact gradient
    ``‖∂J/∂U‖∞`` is at most ``tol`` (the cost's units per input unit); otherwise after
    ``max_iter`` iterations or when no step decreases the cost with ``μ`` at its limit
    (not converged; the message says which).
    ``x0`` must satisfy the constraints by ``nc.simulate``'s rule (:mod:`ncgen.control.initial`);
    a cost that is NaN at the initial guess is an :class:`OptimizationError`, at trial steps it
    is said in the result's message.  ``verbose`` prints cost, gradient norm, step and ``μ``
    of every iteration."""
    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise NcgenError(f"ilqr: max_iter: expected a positive integer, got {max_iter!r}")
    tol, mu = nonnegative(tol, "ilqr: tol"), nonnegative(mu, "ilqr: mu")
    stage_d, terminal_d = cost_functions(costs, st.nx, st.nu)
    x0, U, pv, t0 = _start(st, x0, U0, p, t0)
    N = U.shape[0]
    stage_map = stage_d.map(N)

    def total(X, U):
        return float(np.sum(np.array(stage_map(X[:-1].T, U.T)[0]))) + float(terminal_d(X[-1])[0])

    X = np.vstack([x0, st.rollout(x0, U, p, t0)])
    J = total(X, U)
    if not np.isfinite(J):
        raise OptimizationError(f"ilqr: the cost of the initial guess is {J} (states finite): the stage or "
                                "terminal cost is not defined along it (e.g. a square root or logarithm of a "
                                "negative number, or a division by zero)")
    history, gradients, converged, message = [J], [], False, f"stopped after {max_iter} iterations"
    K = np.zeros((N, st.nu, st.nx))
    it = 0
    # a step with nonsmooth contacts has no second derivatives (ncgen.control.contact_step): Gauss-Newton
    curvature = StepCurvature(st.model, st.h) if second_order and getattr(st, "second_derivatives", True) else None
    full_step, alpha = False, np.nan
    while True:
        A, B = _linearisation(st, X, U, p, t0)
        second = _second_derivatives(curvature, st, x0, X, U, pv, t0) if curvature is not None and full_step else None
        _, lx, lu, lxx, luu, lux = (np.array(a) for a in stage_map(X[:-1].T, U.T))
        _, Vx_N, Vxx_N = (np.array(a) for a in terminal_d(X[-1]))
        gnorm = float(np.max(np.abs(gradient(A, B, lx, lu, Vx_N.ravel()))))
        gradients.append(gnorm)
        if verbose:
            print(f"iLQR {it:3d}: cost {J:.12g}, |dJ/dU| {gnorm:.3e}, alpha {alpha:.3g}, mu {mu:.1e}, "
                  f"{'DDP' if second else 'Gauss-Newton'}")
        if gnorm <= tol:
            converged, message = True, f"converged: |dJ/dU|_inf = {gnorm:.2e} <= tol = {tol:g}"
            break
        if it == max_iter:
            message = f"stopped after {max_iter} iterations with |dJ/dU|_inf = {gnorm:.2e} > tol = {tol:g}"
            break
        it += 1
        search = partial(_line_search, st, x0, X, U, J=J, total=total, p=p, t0=t0)    # search(kff, K, dV)
        step, K, mu, ok, undefined = _descent(search, A, B, (lx, lu, lxx, luu, lux, Vx_N.ravel(), Vxx_N), mu, second)
        if step is None:
            message = _no_descent(gnorm, tol, ok, undefined)
            break
        X, U, J, alpha = step
        full_step = alpha == 1.0
        history.append(J)
        mu = max(mu / MU_FACTOR, MU_MIN)
    return ILQRResult(X, U, K, J, it, converged, gnorm, history, gradients, message)


def _second_derivatives(curvature, st, x0, X, U, pv, t0):
    """DDP's term of the backward pass along ``(X, U)``: ``(k, λ) ↦`` the step's second
    derivatives at node ``k`` contracted with ``λ`` (:class:`StepCurvature`, at the step's
    own unknowns ``Z`` of the rollout)."""
    Z = st._rollout(x0, U, pv, t0)[1]
    return lambda k, lam: curvature(Z[k], X[k], U[k], pv, t0 + k * st.h, lam)


def _descent(search, A, B, quadratic, mu: float, second):
    """Levenberg–Marquardt: the backward pass (on the costs' ``quadratic`` model
    ``(lx, lu, lxx, luu, lux, Vx_N, Vxx_N)``) and the line search ``search(kff, K, dV)``, with
    ``μ`` raised tenfold until a step is found or ``μ`` passes :data:`MU_MAX`:
    ``(step, K, μ, ok, undefined)``; ``step``: ``(X, U, J, α)`` or None; ``ok``: the last
    ``Q_uu + μ I`` was positive definite; ``undefined``: the largest ``α`` whose cost was NaN."""
    step, undefined = None, None
    while step is None:
        ok, kff, K, dV = _backward(A, B, *quadratic, mu, second)
        if ok:
            step = search(kff, K, dV)
            if step[0] is None:
                undefined, step = step[1], None
        if step is None:
            mu = max(mu * MU_FACTOR, MU_MIN)
            if mu > MU_MAX:
                break
    return step, K, mu, ok, undefined


def _no_descent(gnorm: float, tol: float, ok: bool, undefined) -> str:
    """The message of a run stopped with no step found (:func:`_descent`)."""
    if not ok:
        return f"Q_uu stayed indefinite (mu above its limit); |dJ/dU|_inf = {gnorm:.2e}"
    message = f"no descent: the line search failed with mu at its limit; |dJ/dU|_inf = {gnorm:.2e} > tol = {tol:g}"
    if undefined is not None:
        message += (f"; the cost was NaN at trial steps (alpha = {undefined:g}): the stage or terminal "
                    "cost is not defined there")
    return message


def _start(st, x0, U0, p, t0):
    """``(x0, U, p, t0)`` checked: the step's own rule (``st.ilqr_start``, e.g. the joint-space
    step :class:`~ncgen.control.joint_step.JointStep`) or a natural-coordinate step's (``x0``
    consistent by ``nc.simulate``'s rule)."""
    if hasattr(st, "ilqr_start"):
        return st.ilqr_start(x0, U0, p, t0)
    U = st._inputs(U0).copy()
    x0, _, pv, t0 = st._args(x0, U[0], p, t0)
    check_consistent(st.model, x0, pv, t0, "ilqr: x0")
    return x0, U, pv, t0


def _linearisation(st, X, U, p, t0):
    """The step's exact Jacobians ``A_k, B_k`` along ``(X, U)``."""
    N = U.shape[0]
    A, B = np.empty((N, st.nx, st.nx)), np.empty((N, st.nx, st.nu))
    for k in range(N):
        _, A[k], B[k] = st.jacobians(X[k], U[k], p, t0 + k * st.h)
    return A, B


def gradient(A, B, lx, lu, Vx_N):
    """``∂J/∂U`` (N × nu) of ``J = Σ ℓ(x_k, u_k) + ℓ_N(x_N)`` through ``x_{k+1} = st(x_k, u_k)``
    by the adjoint recursion ``λ_N = ∂ℓ_N/∂x``, ``∂J/∂u_k = ℓ_u + B_kᵀ λ_{k+1}``,
    ``λ_k = ℓ_x + A_kᵀ λ_{k+1}`` (``lx``, ``lu``: gradients as columns, one per stage)."""
    lam, g = Vx_N, np.empty((B.shape[0], B.shape[2]))
    for k in range(B.shape[0] - 1, -1, -1):
        g[k] = lu[:, k] + B[k].T @ lam
        lam = lx[:, k] + A[k].T @ lam
    return g


def _line_search(st, x0, X, U, kff, K, dV, J, total, p, t0):
    """Backtracking on the true cost along the closed-loop forward pass: ``(X, U, J)`` of the
    first ``α`` of :data:`ALPHAS` (and ``α``) whose cost falls by at least :data:`ARMIJO` times the
    predicted decrease, or ``(None, α)`` (``α``: the largest step whose cost was NaN, or
    None) when none does."""
    undefined = None
    for alpha in ALPHAS:
        Xn, Un = _forward(st, x0, X, U, kff, K, alpha, p, t0)
        if Xn is None:
            continue
        Jn = total(Xn, Un)
        if np.isnan(Jn):
            undefined = alpha if undefined is None else undefined
            continue
        expected = -(alpha * dV[0] + alpha ** 2 * dV[1])
        if Jn < J and J - Jn >= ARMIJO * expected:
            return Xn, Un, Jn, alpha
    return None, undefined


def _backward(A, B, lx, lu, lxx, luu, lux, Vx, Vxx, mu, curvature=None):
    """Riccati sweep: ``(ok, k, K, (Σ kᵀQ_u, ½ Σ kᵀQ_uu k))``; ``ok`` false when a regularised
    ``Q_uu + μ I`` is not positive definite.  ``curvature(k, λ)``: the step's second
    derivatives contracted with ``λ = V_x`` of the next node (DDP), or None (iLQR)."""
    N, nx, nu = B.shape[0], A.shape[1], B.shape[2]
    kff, K = np.zeros((N, nu)), np.zeros((N, nu, nx))
    d1 = d2 = 0.0
    for k in range(N - 1, -1, -1):
        Ak, Bk = A[k], B[k]
        Qx = lx[:, k] + Ak.T @ Vx
        Qu = lu[:, k] + Bk.T @ Vx
        VA, VB = Vxx @ Ak, Vxx @ Bk
        Qxx = lxx[:, k * nx:(k + 1) * nx] + Ak.T @ VA
        Quu = luu[:, k * nu:(k + 1) * nu] + Bk.T @ VB
        Qux = lux[:, k * nx:(k + 1) * nx] + Bk.T @ VA
        if curvature is not None:
            Hxx, Huu, Hux = curvature(k, Vx)
            Qxx, Quu, Qux = Qxx + Hxx, Quu + Huu, Qux + Hux
        try:
            L = np.linalg.cholesky(0.5 * (Quu + Quu.T) + mu * np.eye(nu))
        except np.linalg.LinAlgError:
            return False, kff, K, (0.0, 0.0)
        sol = np.linalg.solve(L.T, np.linalg.solve(L, np.column_stack([Qu, Qux])))
        kff[k], K[k] = -sol[:, 0], -sol[:, 1:]
        Vx = Qx + K[k].T @ Quu @ kff[k] + K[k].T @ Qu + Qux.T @ kff[k]
        Vxx = Qxx + K[k].T @ Quu @ K[k] + K[k].T @ Qux + Qux.T @ K[k]
        Vxx = 0.5 * (Vxx + Vxx.T)
        d1 += kff[k] @ Qu
        d2 += 0.5 * kff[k] @ Quu @ kff[k]
    return True, kff, K, (d1, d2)


def _forward(st, x0, X, U, kff, K, alpha, p, t0):
    """Closed-loop rollout through the nonlinear step; ``(None, None)`` if a step fails."""
    from ncgen.control.step_support import StepDidNotConverge
    N = U.shape[0]
    Xn, Un = np.empty_like(X), np.empty_like(U)
    Xn[0] = x0
    try:
        for k in range(N):
            Un[k] = U[k] + alpha * kff[k] + K[k] @ (Xn[k] - X[k])
            Xn[k + 1] = st(Xn[k], Un[k], p, t0 + k * st.h)
    except (StepDidNotConverge, NcgenError):
        return None, None
    if not np.all(np.isfinite(Xn)):
        return None, None
    return Xn, Un
