"""A dense convex QP with bounds only, ``min ½ xᵀ H x + gᵀ x  s.t.  l ≤ x ≤ u`` (``H``
symmetric positive definite), by projected Newton (Bertsekas, 1982): at each iterate the
components at a bound whose gradient pushes outwards are held, a Newton step (Cholesky of
``H`` on the free components) is taken on the others, projected onto the box and shortened
until the cost decreases by an Armijo fraction of the projected step's first-order change.
Without active bounds it is one Cholesky solve.

Stops when the KKT conditions hold to ``tol`` (relative to ``‖g‖∞ + 1``): free components'
gradient zero, at a lower bound gradient ≥ 0, at an upper ≤ 0.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import cho_factor, cho_solve, LinAlgError

ARMIJO = 1e-4


def kkt_error(H: np.ndarray, g: np.ndarray, l: np.ndarray, u: np.ndarray, x: np.ndarray) -> float:
    """``‖x − clip(x − ∇, l, u)‖∞``: zero exactly at the QP's solution (``∇ = H x + g``)."""
    return float(np.max(np.abs(x - np.clip(x - (H @ x + g), l, u)), initial=0.0))


def box_qp(H: np.ndarray, g: np.ndarray, l: np.ndarray, u: np.ndarray, x0=None, *, tol: float = 1e-10,
           max_iter: int = 100) -> tuple[np.ndarray, bool, int]:
    """``(x, converged, iterations)`` (module docstring); ``x0``: the start (default 0),
    clipped into the box.  ``converged`` is False when ``max_iter`` passes, ``H`` is not
    positive definite on the free components, or a number is not finite."""
    x = np.clip(np.zeros_like(g) if x0 is None else np.asarray(x0, float), l, u)
    scale = tol * (np.max(np.abs(g), initial=0.0) + 1.0)
    f = 0.5 * x @ (H @ x) + g @ x
    for it in range(max_iter):
        grad = H @ x + g
        if kkt_error(H, g, l, u, x) <= scale:
            return x, True, it
        held = ((x <= l) & (grad > 0)) | ((x >= u) & (grad < 0))
        free = ~held
        try:
            c = cho_factor(H[np.ix_(free, free)], check_finite=True)
        except (LinAlgError, ValueError):
            return x, False, it
        dx = np.zeros_like(x)
        dx[free] = -cho_solve(c, grad[free])
        alpha = 1.0
        while alpha > 1e-12:
            trial = np.clip(x + alpha * dx, l, u)
            f_trial = 0.5 * trial @ (H @ trial) + g @ trial
            if f_trial <= f + ARMIJO * grad @ (trial - x):
                break
            alpha *= 0.5
        else:
            return x, False, it
        x, f = trial, f_trial
        if not np.isfinite(f):
            return x, False, it
    return x, kkt_error(H, g, l, u, x) <= scale, max_iter
