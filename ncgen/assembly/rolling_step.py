"""One projected Runge–Kutta step of a model with nonholonomic elements, as one CasADi
function (compiled by :mod:`ncgen.runtime.rolling_integrator`, which controls the steps).

For a :class:`~ncgen.assembly.nonholonomic.RollingSystem` with constant mass matrix ``M``:

* accelerations by the Schur complement of the KKT system:
  ``(Â M⁻¹ Âᵀ) λ = Â M⁻¹ F − γ̂``, ``a = M⁻¹ (F − Âᵀ λ)``;
* an explicit step of the tableau ``(A, b, e)`` (:data:`TABLEAUS`) of ``ẏ = [v; a(q, v)]``,
  ``y = [q; v]``: ``y⁺ = y + h Σ b_i k_i`` and the error estimate ``h Σ e_i k_i``;
* the projection of :func:`ncgen.runtime.rolling_integrator.project`, with a fixed number of
  least-norm Newton steps ``q ← q − Â_hᵀ (Â_h Â_hᵀ)⁻¹ Φ̂(q)`` (quadratic convergence from a
  step's local error: three reach round-off) and then ``v ← v − Âᵀ (Â Âᵀ)⁻¹ Â v``.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

#: Dormand–Prince 5(4): stage coefficients, fifth-order weights, error weights (5th − 4th).
DOPRI5 = ([[], [1 / 5], [3 / 40, 9 / 40], [44 / 45, -56 / 15, 32 / 9],
           [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729],
           [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656],
           [35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84]],
          np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0]),
          np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0])
          - np.array([5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40]))
#: The classical fourth-order Runge–Kutta scheme (no error estimate).
RK4 = ([[], [1 / 2], [0.0, 1 / 2], [0.0, 0.0, 1.0]], np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6]), np.zeros(4))
TABLEAUS = {"dopri5": DOPRI5, "rk4": RK4}
#: Newton steps of the compiled projection onto ``Φ̂(q) = 0``.
NEWTON_STEPS = 3


def accel_function(system) -> ca.Function:
    """``(q, v) -> a``: the accelerations of ``system`` by the Schur complement (SX)."""
    nq = system.nq
    q, v = ca.SX.sym("q", nq), ca.SX.sym("v", nq)
    A = system.A(q)
    Minv = ca.DM(np.linalg.inv(system.model.M))
    F = system.F(q, v)
    lam = ca.solve(ca.mtimes([A, Minv, A.T]), ca.mtimes([A, Minv, F]) - system.gamma(q, v))
    return ca.Function("rolling_accel", [q, v], [ca.mtimes(Minv, F - ca.mtimes(A.T, lam))], ["q", "v"], ["a"])


def projection_function(system, newton_steps: int = NEWTON_STEPS) -> ca.Function:
    """``(q, v) -> (q, v)`` moved onto both constraint levels (module docstring; SX)."""
    nq, nh = system.nq, system.n_holonomic
    q0, v0 = ca.SX.sym("q", nq), ca.SX.sym("v", nq)
    q = q0
    for _ in range(newton_steps):
        Ah = system.A(q)[:nh, :]
        q = q - ca.mtimes(Ah.T, ca.solve(ca.mtimes(Ah, Ah.T), system.phi(q)))
    A = system.A(q)
    v = v0 - ca.mtimes(A.T, ca.solve(ca.mtimes(A, A.T), ca.mtimes(A, v0)))
    return ca.Function("rolling_project", [q0, v0], [q, v], ["q", "v"], ["q_p", "v_p"])


def step_function(system, method: str) -> ca.Function:
    """``(y, h) -> (y⁺, err)``: one step of ``method`` (``"rk4"``, ``"dopri5"``) from
    ``y = [q; v]`` over ``h`` (s), projected; ``err``: the unprojected step's error estimate
    (zeros for RK4)."""
    A_tab, b, e = TABLEAUS[method]
    nq = system.nq
    accel, project = accel_function(system), projection_function(system)
    y, h = ca.MX.sym("y", 2 * nq), ca.MX.sym("h")

    def rhs(x):
        return ca.vertcat(x[nq:], accel(x[:nq], x[nq:]))

    k = [rhs(y)]
    for row in A_tab[1:]:
        k.append(rhs(y + h * sum(c * kj for c, kj in zip(row, k) if c != 0.0)))
    y_new = y + h * sum(bi * ki for bi, ki in zip(b, k) if bi != 0.0)
    err = h * sum(ei * ki for ei, ki in zip(e, k) if ei != 0.0) if np.any(e) else ca.MX.zeros(2 * nq)
    q_p, v_p = project(y_new[:nq], y_new[nq:])
    return ca.Function(f"rolling_{method}_step", [y, h], [ca.vertcat(q_p, v_p), err], ["y", "h"], ["y_next", "err"])
