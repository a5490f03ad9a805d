"""Keeping an IDAS run on the constraint manifold, robustly where ``A`` loses rank.

IDAS integrates the index-1 DAE (Baumgarte-stabilised acceleration constraints), so the
positions drift off ``Φ = 0`` by the integration error; where the constraint Jacobian
loses rank (a parallelogram passing its flat position, where the crossed branch meets the
physical one) that drift is enough to leave the physical branch.  The runner
(:func:`ncgen.runtime.simulation.simulate`, ``project``) therefore watches how close ``A``
is to losing rank (:meth:`ManifoldProjector.near_singular`), hands the intervals next to a
singular configuration to RATTLE (:mod:`ncgen.runtime.rattle_bridge`), and projects the
state back before them (and, with ``project=True``, after every output interval), in the
mass metric:

    positions:  q ← q − M⁻¹Aᵀ (A M⁻¹ Aᵀ)⁺ Φ        (Gauss–Newton, a few iterations)
    velocities: v ← v − M⁻¹Aᵀ (A M⁻¹ Aᵀ)⁺ (A v + Φ_t)

with the pseudo-inverse truncated at :data:`RCOND` × the largest singular value: a
direction in which the constraints are (nearly) dependent takes no step, so the projection
never jumps to another branch.  With a singular ``M`` (a flat body), ``M⁻¹`` is the inverse
of the augmented ``M̄ = M + κAᵀA`` at the ``A`` of the step (the same projection, see
:mod:`ncgen.assembly.mass`).  :func:`robust_algebraic` solves the KKT system for
``z = [a; λ]`` the same way when CasADi's sparse QR fails on a singular configuration.
"""
from __future__ import annotations

import numpy as np

#: Singular values of ``A M⁻¹ Aᵀ`` below this fraction of the largest are treated as zero.
RCOND = 1e-10
#: ``σ_min/σ_max`` of ``A`` below which a configuration counts as near-singular (IDAS is
#: replaced there, see :func:`ncgen.runtime.simulation.simulate`), for a model that starts
#: well-conditioned; scaled by the starting ratio over :data:`WELL_CONDITIONED` where that is
#: smaller (a long chain of parallelograms is less well conditioned everywhere: the N
#: four-bar of IFToMM A02 starts at 0.38 for N = 1, 0.093 for N = 10, 0.025 for N = 40, and
#: its ratio is about proportional to the sine of the crank angle; the scaled limit is
#: reached 5–6° from its flat positions for every N).
NEAR_SINGULAR = 0.05
#: Starting ``σ_min/σ_max`` of ``A`` from which the limits are not scaled down.
WELL_CONDITIONED = 0.4
#: Gauss–Newton iterations of the position projection at most.
MAX_ITER = 8


class ManifoldProjector:
    """Projection of ``x = [q; v]`` onto ``Φ(t, q) = 0``, ``A v + Φ_t = 0`` (see module
    docstring).  ``tol``: residuals ``max |Φ|`` (m²) and ``max |A v + Φ_t|`` (m²/s) below which
    the state is left alone; ``counts`` records how often each level moved."""

    def __init__(self, model, p: np.ndarray, tol: float):
        self.f = model.functions
        self.nq = model.nq
        self.p = p
        self.tol = tol
        self.active = model.nc > 0
        self.factor = model.mass_factor
        self.Minv = self.factor.solve_numeric(np.eye(model.nq)) if self.active and self.factor.regular else None
        self.counts = {"position_projections": 0, "velocity_projections": 0}
        self.scale = 1.0

    def ratio(self, t: float, x: np.ndarray) -> float:
        """``σ_min/σ_max`` of ``A`` at ``x`` (1 where ``A`` is empty or not finite)."""
        if not self.active:
            return 1.0
        A = self._A(t, x[:self.nq])
        if not np.all(np.isfinite(A)):
            return 1.0
        s = np.linalg.svd(A, compute_uv=False)
        return float(s[-1] / s[0]) if np.all(np.isfinite(s)) and s[0] > 0 else 1.0

    def start(self, t: float, x: np.ndarray):
        """Scale the near-singular limits by this starting configuration's ``σ_min/σ_max``
        over :data:`WELL_CONDITIONED`, where below 1."""
        self.scale = min(1.0, self.ratio(t, x) / WELL_CONDITIONED)

    def _phi(self, t, q):
        return np.array(self.f["phi"](t, q, self.p), dtype=float).reshape(-1)

    def _A(self, t, q):
        return np.array(self.f["A"](t, q, self.p), dtype=float)

    def _step(self, A, r):
        """``M⁻¹Aᵀ (A M⁻¹ Aᵀ)⁺ r`` with the truncated pseudo-inverse."""
        MiAT = self.Minv @ A.T if self.Minv is not None else self.factor.solve_with(A, A.T)
        return MiAT @ np.linalg.lstsq(A @ MiAT, r, rcond=RCOND)[0]

    def near_singular(self, t: float, x: np.ndarray, ratio: float | None = None) -> bool:
        """Whether ``A`` at ``x`` is close to losing rank: ``σ_min/σ_max`` below ``ratio``
        (default :data:`NEAR_SINGULAR`) times the scale set by :meth:`start`."""
        limit = NEAR_SINGULAR if ratio is None else ratio
        return self.ratio(t, x) < limit * self.scale

    def __call__(self, t: float, x: np.ndarray) -> np.ndarray:
        """The projected state (``x`` itself where it is not finite or the solve fails: the
        integrator's next call reports that)."""
        if not self.active or not np.all(np.isfinite(x)):
            return x
        try:
            return self._project(t, x)
        except np.linalg.LinAlgError:
            return x

    def _project(self, t: float, x: np.ndarray) -> np.ndarray:
        nq = self.nq
        q, v = x[:nq].copy(), x[nq:].copy()
        r = self._phi(t, q)
        moved = False
        for _ in range(MAX_ITER):
            if not np.all(np.isfinite(r)) or np.max(np.abs(r)) <= self.tol:
                break
            q -= self._step(self._A(t, q), r)
            r = self._phi(t, q)
            moved = True
        self.counts["position_projections"] += moved
        A = self._A(t, q)
        rv = A @ v + np.array(self.f["phi_t"](t, q, self.p), dtype=float).reshape(-1)
        if np.all(np.isfinite(rv)) and np.max(np.abs(rv)) > self.tol:
            v -= self._step(A, rv)
            self.counts["velocity_projections"] += 1
        return np.concatenate([q, v])


def robust_algebraic(model, t: float, q, v, u, p) -> np.ndarray:
    """``z = [a; λ]`` of the KKT system ``[[M, Aᵀ], [A, 0]] z = [F; γ − 2αΦ̇ − β²Φ]`` at
    ``(t, q, v)``: CasADi's sparse QR (``accel``), or, where it fails or returns non-finite
    numbers (rank-deficient ``A``), the minimum-norm least-squares solution.  Returns
    non-finite numbers only if the model's functions do."""
    f = model.functions
    try:
        a, lam = f["accel"](t, q, v, u, p)
        z = np.concatenate([np.array(a, dtype=float).reshape(-1), np.array(lam, dtype=float).reshape(-1)])
        if np.all(np.isfinite(z)):
            return z
    except RuntimeError:
        pass
    alpha, beta = model.baumgarte
    A = np.array(f["A"](t, q, p), dtype=float)
    phi = np.array(f["phi"](t, q, p), dtype=float).reshape(-1)
    phidot = A @ v + np.array(f["phi_t"](t, q, p), dtype=float).reshape(-1)
    rhs = np.concatenate([np.array(f["F"](t, q, v, u, p), dtype=float).reshape(-1),
                          np.array(f["gamma"](t, q, v, p), dtype=float).reshape(-1)
                          - 2 * alpha * phidot - beta**2 * phi])
    nc = A.shape[0]
    K = np.block([[model.M, A.T], [A, np.zeros((nc, nc))]])
    if not np.all(np.isfinite(K)) or not np.all(np.isfinite(rhs)):
        return np.full(model.nq + nc, np.nan)
    try:
        return np.linalg.lstsq(K, rhs, rcond=None)[0]
    except np.linalg.LinAlgError:
        return np.full(model.nq + nc, np.nan)
