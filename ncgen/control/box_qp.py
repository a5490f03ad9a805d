"""A dense convex QP with bounds only, ``min ½ xᵀ H x + gᵀ x  s.t.  l ≤ x ≤ u`` (``H``
symmetric positive definite), by projected Newton (Bertsekas, 1982): at each iterate the
components at a bound whose gradient pushes outwards are held, a Newton step (Cholesky of
``H`` on the free components) is taken on the others, projected onto the box and shortened
until the cost decreases by an Armijo fraction of the projected step's first-order change.
Without active bounds it is one Cholesky solve.  ``H`` is a dense matrix or an operator with
``H @ x`` and ``H.newton(free, grad)`` (e.g.
:class:`~ncgen.control.stagewise_hessian.StagewiseHessian`, which never forms the matrix).

Stops when the KKT conditions hold to ``tol`` (relative to ``‖g‖∞ + 1``): free components'
gradient zero, at a lower bound gradient ≥ 0, at an upper ≤ 0.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import cho_factor, cho_solve, LinAlgError

ARMIJO = 1e-4


class DenseHessian:
    """A dense symmetric ``H`` as :func:`box_qp`'s operator: products and Cholesky solves."""

    def __init__(self, H: np.ndarray):
        self.H = H

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        return self.H @ x

    def newton(self, free: np.ndarray, grad: np.ndarray) -> np.ndarray | None:
        """``d`` with ``H_ff d_f = −grad_f``, ``d = 0`` elsewhere; None when ``H_ff`` is not
        positive definite."""
        try:
            c = cho_factor(self.H[np.ix_(free, free)], check_finite=True)
        except (LinAlgError, ValueError):
            return None
        d = np.zeros_like(grad)
        d[free] = -cho_solve(c, grad[free])
        return d


def projected_gradient(x: np.ndarray, grad: np.ndarray, l: np.ndarray, u: np.ndarray) -> float:
    """``‖x − clip(x − grad, l, u)‖∞``."""
    return float(np.max(np.abs(x - np.clip(x - grad, l, u)), initial=0.0))


def kkt_error(H, g: np.ndarray, l: np.ndarray, u: np.ndarray, x: np.ndarray) -> float:
    """``‖x − clip(x − ∇, l, u)‖∞``: zero exactly at the QP's solution (``∇ = H x + g``)."""
    return projected_gradient(x, H @ x + g, l, u)


def box_qp(H, g: np.ndarray, l: np.ndarray, u: np.ndarray, x0=None, *, tol: float = 1e-10,
           max_iter: int = 100) -> tuple[np.ndarray, bool, int]:
    """``(x, converged, iterations)`` (module docstring); ``x0``: the start (default 0),
    clipped into the box.  ``converged`` is False when ``max_iter`` passes, ``H`` is not
    positive definite on the free components, or a number is not finite."""
    if isinstance(H, np.ndarray):
        H = DenseHessian(H)
    x = np.clip(np.zeros_like(g) if x0 is None else np.asarray(x0, float), l, u)
    scale = tol * (np.max(np.abs(g), initial=0.0) + 1.0)
    Hx = H @ x if np.any(x) else np.zeros_like(x)
    f = 0.5 * x @ Hx + g @ x
    for it in range(max_iter):
        grad = Hx + g
        if projected_gradient(x, grad, l, u) <= scale:
            return x, True, it
        held = ((x <= l) & (grad > 0)) | ((x >= u) & (grad < 0))
        dx = H.newton(~held, grad)
        if dx is None or not np.all(np.isfinite(dx)):
            return x, False, it
        alpha = 1.0
        while alpha > 1e-12:
            trial = np.clip(x + alpha * dx, l, u)
            H_trial = H @ trial
            f_trial = 0.5 * trial @ H_trial + g @ trial
            if f_trial <= f + ARMIJO * grad @ (trial - x):
                break
            alpha *= 0.5
        else:
            return x, False, it
        x, f, Hx = trial, f_trial, H_trial
        if not np.isfinite(f):
            return x, False, it
    return x, projected_gradient(x, Hx + g, l, u) <= scale, max_iter
