"""A time-varying reference for :class:`ncgen.control.mpc.MPC`: a planned trajectory (an
optimal-control solution, say) that the controller tracks.

Given at ``M`` increasing times ``t_j`` (s): states ``X_j = [q_j; v_j]`` and inputs ``U_j``.
Between the times the state is interpolated linearly, the input held (``U_j`` on
``[t_j, t_{j+1})``, as an OCP's piecewise-constant inputs); before ``t_0`` and after
``t_{M−1}`` both are held at their first and last values (so ``U_{M−1}`` is the input that holds
the final state, e.g. an equilibrium's)::

    x_ref(t) = Σ_j φ_j(τ) X_j,   u_ref(t) = Σ_j χ_j(τ) U_j,   τ = min(max(t, t_0), t_{M−1})

with ``φ_j`` the hat functions of the grid (1 at ``t_j``, 0 at its neighbours) and ``χ_j`` the
indicator of ``[t_j, t_{j+1})`` (``χ_{M−1}``: ``τ = t_{M−1}``).  Written with ``fmin``/``fmax``
and comparisons, so the same expression is SX inside the MPC's generated cost and a number
for its guess.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.errors import OptimizationError
from ncgen.validation import as_numbers


def reference_arrays(reference, nx: int, nu: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t, X, U)`` of ``reference``: a tuple ``(t, X, U)`` (``M``, ``M × nx``, ``M × nu``) or an
    object with ``t``, ``q``, ``v``, ``u`` (an :class:`~ncgen.optim.result.Solution`: its ``u``
    may have ``M − 1`` rows, the last then repeated)."""
    what = "MPC: reference"
    if all(hasattr(reference, a) for a in ("t", "q", "v", "u")):
        t, X, U = reference.t, np.hstack([np.asarray(reference.q, float), np.asarray(reference.v, float)]), \
            reference.u
    else:
        try:
            t, X, U = reference
        except (TypeError, ValueError):
            raise OptimizationError(f"{what}: expected (t, X, U) or a solution with t, q, v, u, got "
                                    f"{type(reference).__name__}") from None
    t = as_numbers(t, f"{what}: t").reshape(-1)
    X, U = as_numbers(X, f"{what}: X"), as_numbers(U, f"{what}: U")
    M = t.size
    if U.ndim == 2 and U.shape[0] == M - 1:
        U = np.vstack([U, U[-1:]])
    for name, a, n in (("X", X, nx), ("U", U, nu)):
        if a.shape != (M, n):
            raise OptimizationError(f"{what}: {name}: expected shape ({M}, {n}) (one row per time), got {a.shape}")
    if M < 2 or not np.all(np.diff(t) > 0):
        raise OptimizationError(f"{what}: t: expected at least 2 increasing times, got {t.tolist()}")
    for name, a in (("t", t), ("X", X), ("U", U)):
        if not np.all(np.isfinite(a)):
            raise OptimizationError(f"{what}: {name}: expected finite numbers, got {int(np.sum(~np.isfinite(a)))} "
                                    "non-finite values")
    return t, X, U


def reference_function(t: np.ndarray, X: np.ndarray, U: np.ndarray) -> ca.Function:
    """``mpc_reference: t -> (x_ref, u_ref)`` (SX; see the module docstring)."""
    s = ca.SX.sym("t")
    tau = ca.fmin(ca.fmax(s, float(t[0])), float(t[-1]))
    M = t.size
    phi, chi = [], []
    for j in range(M):
        rise = 1.0 if j == 0 else (tau - t[j - 1]) / (t[j] - t[j - 1])
        fall = 1.0 if j == M - 1 else (t[j + 1] - tau) / (t[j + 1] - t[j])
        phi.append(ca.fmax(0, ca.fmin(rise, fall)))
        chi.append((tau >= t[j]) * (tau < t[j + 1]) if j < M - 1 else (tau >= t[j]))
    phi, chi = ca.vertcat(*phi), ca.vertcat(*chi)
    return ca.Function("mpc_reference", [s], [ca.mtimes(ca.DM(X).T, phi), ca.mtimes(ca.DM(U).T, chi)],
                       ["t"], ["x_ref", "u_ref"])
