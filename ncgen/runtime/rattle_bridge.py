"""RATTLE across an output interval next to a singular configuration: IDAS's stand-in there.

Where the constraint Jacobian ``A`` loses rank, the KKT matrix of IDAS's index-1 DAE is
singular: its Newton iteration fails when a step lands close to the singular configuration,
and where it does not, the Baumgarte-stabilised acceleration constraints let IDAS drift onto
the other branch that meets the physical one there.  RATTLE keeps ``Φ = 0`` and
``A v + Φ_t = 0`` at every step and continues the velocity smoothly, so it stays on the
branch.  Two forms:

* :func:`compiled_interval`: the model's compiled error-controlled stepper
  (``<model>_simulate_adaptive``, Richardson-extrapolated RATTLE of order 4, projected; see
  :mod:`ncgen.runtime.stepper`) over one interval at a tenth of IDAS's ``rtol``/``atol``
  (:data:`ncgen.runtime.idas_integrator.BRIDGE_TIGHTER`): accurate and cheap (generated C).
  Used whenever a C compiler is available.
* :func:`rattle_interval` (the fallback without a compiler): ``n`` NumPy RATTLE steps of
  ``h`` (second order), each solved with the truncated pseudo-inverse of ``A M⁻¹ Aᵀ``
(:data:`ncgen.assembly.manifold.RANK_TOL`), so a (nearly) dependent constraint direction takes
no step and the motion stays on its branch:

    q₊ = q + h v + h²/2 M⁻¹ (F − A(q)ᵀ λ),      Φ(t₊, q₊) = 0            (λ by Gauss–Newton)
    v½ = v + h/2 M⁻¹ (F − A(q)ᵀ λ)
    v₊ = v½ + h/2 M⁻¹ (F₊ − A(q₊)ᵀ μ),         A(q₊) v₊ + Φ_t = 0     (μ linear)

With a singular ``M`` (a flat body) each ``M⁻¹`` is that of the augmented ``M̄ = M + κAᵀA``
with the ``A`` of its half-step (:mod:`ncgen.assembly.mass`): ``M̄ δ = r − Aᵀλ̃`` is
``M δ = r − Aᵀ(λ̃ + κ A δ)``, the same step with a shifted multiplier, and ``v½ = v + δ/h``.

``F`` is evaluated at the start of the step and ``F₊`` at ``(q₊, v½)``: exact for forces that
do not depend on the velocity, first order in the velocity-dependent part otherwise.
"""
from __future__ import annotations

import numpy as np

from ncgen.codegen.stepper_abi import RunOptions
from ncgen.codegen.stepper_package import MAX_ITER as STEPPER_MAX_ITER, STATUS, STEP_INTERRUPTED
from ncgen.assembly.manifold import RANK_TOL
from ncgen.runtime.stepper import MAX_STEPS, newton_tolerance
from ncgen.runtime.stepper_library import step_options

#: Gauss–Newton iterations per step at most.
MAX_ITER = 20


class RattleFailure(Exception):
    """The position equations of a step did not converge (or became non-finite)."""


def compiled_interval(stepper, x: np.ndarray, lam: np.ndarray, t0: float, dt: float, U: np.ndarray | None,
                      hold_linear: bool, p, rtol: float, atol: float, h0: float = 0.0) -> tuple[np.ndarray, float]:
    """``(x1, h_next)``: the state ``[q; v]`` at ``t0 + dt`` from ``x`` (multipliers ``lam``)
    at ``t0`` by the compiled error-controlled stepper ``stepper``
    (:class:`~ncgen.runtime.stepper_library.CompiledStepper`) with tolerances ``rtol``,
    ``atol``; ``U``: the inputs at ``t0`` and ``t0 + dt`` (rows), held or interpolated
    (``hold_linear``); ``h0``: first step to try (0: the stepper's choice), ``h_next`` the
    step it would take next.  Raises :class:`RattleFailure`, or KeyboardInterrupt on Ctrl-C."""
    nq = len(x) // 2
    tol = newton_tolerance(rtol, atol)
    run = RunOptions(rtol=rtol, atol=atol, h0=h0, extrapolate=1, max_steps=MAX_STEPS, hold_linear=int(hold_linear),
                     track_work=0)
    Q, V, _, _, status, rows, h_next = stepper.simulate_adaptive(x[:nq], x[nq:], lam, t0, dt, 1, U, p, run,
                                                                 step_options(tol, STEPPER_MAX_ITER, 0))
    if status == STEP_INTERRUPTED:
        raise KeyboardInterrupt
    if status != 0 or rows != 1:
        raise RattleFailure(f"the compiled stepper failed on [{t0:.6g}, {t0 + dt:.6g}] s: "
                            f"{STATUS.get(status, f'status {status}')}")
    return np.concatenate([Q[0], V[0]]), h_next


def _pinv_solve(K: np.ndarray, r: np.ndarray) -> np.ndarray:
    try:
        return np.linalg.lstsq(K, r, rcond=RANK_TOL)[0]
    except np.linalg.LinAlgError as e:
        raise RattleFailure(f"the least-squares solve failed ({e})") from None


def rattle_interval(model, t0: float, x: np.ndarray, u, p, h_end: float, n: int, tol: float) -> np.ndarray:
    """The state ``[q; v]`` at ``t0 + h_end`` after ``n`` steps from ``x`` at ``t0`` with input
    ``u`` (held); ``tol``: ``max |Φ|`` accepted (m²).  Raises :class:`RattleFailure`."""
    f, nq = model.functions, model.nq
    factor = model.mass_factor
    Minv = factor.solve_numeric(np.eye(nq)) if factor.regular else None

    def inverse(A):                   # M⁻¹, or M̄⁻¹ for the A of the half-step (singular M)
        return Minv if Minv is not None else factor.solve_with(A, np.eye(nq))
    h = h_end / n
    q, v = x[:nq].copy(), x[nq:].copy()

    def F(t, q, v):
        return np.array(f["F"](t, q, v, u, p), dtype=float).reshape(-1)

    def A(t, q):
        return np.array(f["A"](t, q, p), dtype=float)

    def phi(t, q):
        return np.array(f["phi"](t, q, p), dtype=float).reshape(-1)

    t = t0
    for _ in range(n):
        A0, F0 = A(t, q), F(t, q, v)
        Mi0 = inverse(A0)
        MiAT0 = Mi0 @ A0.T
        free = q + h * v + 0.5 * h * h * (Mi0 @ F0)
        lam = np.zeros(A0.shape[0])
        t1 = t + h
        for _ in range(MAX_ITER):
            q1 = free - 0.5 * h * h * (MiAT0 @ lam)
            r = phi(t1, q1)
            if not np.all(np.isfinite(r)):
                raise RattleFailure(f"non-finite constraints at t = {t1:.6g} s")
            if np.max(np.abs(r), initial=0.0) <= tol:
                break
            J = -0.5 * h * h * (A(t1, q1) @ MiAT0)
            lam -= _pinv_solve(J, r)
        else:
            raise RattleFailure(f"the position constraints did not converge at t = {t1:.6g} s "
                                f"(max |Φ| = {np.max(np.abs(r)):.3g})")
        v_half = (q1 - q) / h              # = v + h/2 M⁻¹ (F − Aᵀλ)
        A1 = A(t1, q1)
        F1 = F(t1, q1, v_half)
        Mi1 = inverse(A1)
        pred = v_half + 0.5 * h * (Mi1 @ F1)
        MiAT1 = Mi1 @ A1.T
        rv = A1 @ pred + np.array(f["phi_t"](t1, q1, p), dtype=float).reshape(-1)
        mu = _pinv_solve(0.5 * h * (A1 @ MiAT1), rv)
        q, v, t = q1, pred - 0.5 * h * (MiAT1 @ mu), t1
        if not np.all(np.isfinite(v)):
            raise RattleFailure(f"non-finite velocities at t = {t1:.6g} s")
    return np.concatenate([q, v])
