"""Consistent initial state and constraint redundancy.

* positions: Gauss–Newton with minimum-norm steps ``Δq = −A⁺ Φ`` onto ``Φ(t0, q) = 0``;
* velocities: the M-orthogonal projection onto ``A v + Φ_t = 0`` (the velocities that drives
  prescribe, rows with ``Φ_t ≠ 0``, are imposed without counting as an inconsistency),
  ``v ← v − M⁻¹Aᵀ (A M⁻¹ Aᵀ)⁺ (A v + Φ_t)``
  (both from :mod:`ncgen.assembly.kinematics`, optionally keeping some coordinates fixed);
* multipliers and accelerations from the KKT system.
A correction larger than ``tolerance`` × the system's size is an error that names the
constraints that were violated and the coordinate that had to move most, unless the
configuration is being assembled (``build(assemble=True)``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ncgen.assembly.manifold import NEWTON_TOL as TOL, kkt_least_squares, newton, project, system_size
from ncgen.assembly.mass import dense_dm
from ncgen.errors import ModelError

@dataclass
class State:
    q0: np.ndarray
    v0: np.ndarray
    lam0: np.ndarray
    a0: np.ndarray
    dq: float      # largest position correction applied (m)
    dv: float      # largest velocity correction applied (m/s)
    phi_given: float = 0.0        # max |Φ(t0, q)| of the state as given (m²)
    velocity_given: float = 0.0   # max |A v + Φ_t| of the state as given (m²/s)


def consistent_state(f, layout, labels, q, v, p, t0, tolerance, M, *, fixed=(), assemble=False,
                     max_iter: int = 50) -> State:
    """Project ``(q, v)`` onto the constraints; see the module docstring.  ``fixed``: indices
    of coordinates (and their rates) kept as given.  ``assemble``: no limit on the
    corrections (the given configuration is only a guess)."""

    def phi(x):
        return np.array(f["phi"](t0, x, p)).reshape(-1)

    def A(x):
        return dense_dm(f["A"](t0, x, p))

    def phi_t(x):
        return np.array(f["phi_t"](t0, x, p)).reshape(-1)

    fixed = set(fixed)
    free = [i for i in range(layout.nq) if i not in fixed]
    size = system_size(q)
    q_init, v_init = q.copy(), v.copy()
    res0 = phi(q)
    vel0 = A(q) @ v + phi_t(q) if res0.size else res0
    q, _, res = newton(phi, A, q, free, tol=TOL * size**2, max_iter=max_iter)
    if res > TOL * size**2 or not np.isfinite(res):
        r = phi(q)
        worst = int(np.nanargmax(np.abs(r)))
        raise ModelError(f"the constraints cannot be satisfied near the initial configuration: "
                         f"{labels[worst]} keeps a residual of {abs(r[worst]):.3g}"
                         + (f" with {len(fixed)} coordinate(s) fixed" if fixed else ""))
    dq = np.abs(q - q_init)
    if not assemble and dq.size and dq.max() > tolerance * size:
        k = int(np.argmax(dq))
        worst = np.argsort(-np.abs(res0))[:3]
        viol = ", ".join(f"{labels[i]} = {res0[i]:.3g}" for i in worst if abs(res0[i]) > TOL * size**2)
        raise ModelError(
            f"inconsistent initial configuration: the constraints are violated ({viol}); making them "
            f"hold moves {layout.coordinate_names[k]} by {dq[k]:.3g} m, more than the tolerance "
            f"{tolerance:g} × {size:.3g} m. Fix the initial positions, or build(assemble=True) to "
            "assemble them (or build(tolerance=...))")
    A0, rate = A(q), phi_t(q)
    v = project(A0, -rate, v, M, free)
    dv = np.abs(v - v_init)
    # drives set their own velocities: only the constraints without one (Φ_t = 0) judge the given state
    steady = rate == 0
    check = np.abs(project(A0[steady], np.zeros(int(steady.sum())), v_init, M, free) - v_init)
    vscale = max(np.max(np.abs(v_init)) if v_init.size else 0.0, size)
    if not assemble and check.size and check.max() > tolerance * vscale:
        k = int(np.argmax(check))
        raise ModelError(
            f"inconsistent initial velocities: making them satisfy the constraints changes "
            f"{layout.coordinate_names[k]} by {check[k]:.3g} m/s, more than the tolerance {tolerance:g} × "
            f"{vscale:.3g} m/s. Check the members' velocity and angular_velocity")
    a, lam = _multipliers(f, M, q, v, p, t0)
    return State(q, v, lam, a,
                 float(dq.max()) if dq.size else 0.0, float(dv.max()) if dv.size else 0.0,
                 float(np.max(np.abs(res0))) if res0.size else 0.0,
                 float(np.max(np.abs(vel0))) if res0.size else 0.0)


def _multipliers(f, M, q, v, p, t0):
    """``(a, λ)`` from the KKT system at a consistent state; with redundant constraints kept
    (singular KKT matrix) the minimum-norm least-squares solution."""
    nu = f["F"].size1_in(3)
    u = np.zeros(nu)
    try:
        a, lam = (np.array(x, dtype=float).reshape(-1) for x in f["accel"](t0, q, v, u, p))
        if np.all(np.isfinite(a)) and np.all(np.isfinite(lam)):
            return a, lam
    except RuntimeError:
        pass
    A = dense_dm(f["A"](t0, q, p))
    rhs = np.concatenate([np.array(f["F"](t0, q, v, u, p), dtype=float).reshape(-1),
                          np.array(f["gamma"](t0, q, v, p), dtype=float).reshape(-1)])
    sol = kkt_least_squares(M, A, rhs)
    if not np.all(np.isfinite(sol)):
        raise ModelError(f"the accelerations and multipliers at the initial state (t0 = {t0:g} s) are not "
                         "finite: a force or a constraint is not finite there (e.g. a spring of zero length)")
    return sol[:M.shape[0]], sol[M.shape[0]:]
