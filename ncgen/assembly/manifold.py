"""The constraint manifold ``Φ(t, q) = 0``, ``A(q) v + Φ_t = 0``: its numerics in one place.

* **Rank and null space**: :data:`RANK_TOL` is the one tolerance: a singular value of ``A``
  (or of ``A M⁻¹ Aᵀ``) below ``RANK_TOL`` × the largest counts as zero, in the rank
  :func:`numerical_rank` (``Model.rank``, ``dof_report``, the tree check, the check of
  redundant constraints), in the null-space basis :func:`null_basis` (and
  :func:`coordinate_basis`, :func:`tangent_basis`), so that a rank and a null space at one
  position never disagree, in the truncated pseudo-inverse of the mass-metric projections
  (:func:`mass_step`, :class:`ManifoldProjector`, the RATTLE bridge) and in
  :func:`check_tangent_inertia`.
* **Positions**: :func:`newton`, minimum-norm Newton steps onto ``Φ = 0`` on chosen
  coordinates (assembly, the continuation of drives, initial states, joint space,
  optimal-control conditions).
* **Projections in the mass metric**: :func:`mass_step` ``δ = M⁻¹Aᵀ (A M⁻¹ Aᵀ)⁺ r``, the
  smallest step in kinetic energy with ``A δ = r``; :func:`consistent_velocity`,
  :class:`ManifoldProjector` (positions by Gauss–Newton, then velocities) and
  :func:`project` (with coordinates held fixed, by the sparse KKT system).
* **KKT solves**: :func:`project`'s ``[[M, Aᵀ], [A, 0]]`` step by sparse QR,
  :func:`kkt_least_squares` (:func:`robust_algebraic`, the initial multipliers) for
  ``z = [a; λ]`` where ``A`` loses rank, :func:`kkt_solve` (LU, else least squares; the
  interpolation of optimal-control guesses) and :func:`solve_linear` (sparse QR, checked;
  the joint-space maps and the NumPy forward dynamics).
* **Charts**: :func:`manifold_point` and :func:`tangent_velocity` (independent coordinates
  ``z = G (q − q*)`` and rates ``w = G v``).

Conventions: ``N`` (nq × dof) is an orthonormal basis of ``null A(q)`` (``A N = 0``,
``Nᵀ N = I``) from the SVD of ``A``, each column's largest entry made positive so that the
basis is reproducible; the independent coordinates are ``z = Nᵀ (q − q*)`` unless the user
gives other ones (``G``, dof × nq, with ``G N`` invertible: then ``N ← N (G N)⁻¹``).  With a
singular ``M`` (a flat body), ``M⁻¹`` is the inverse of the augmented ``M̄ = M + κAᵀA`` at the
``A`` of the step: the same projection (:mod:`ncgen.assembly.mass`).

Keeping an IDAS run on the manifold (:class:`ManifoldProjector`): IDAS integrates the index-1
DAE (Baumgarte-stabilised acceleration constraints), so the positions drift off ``Φ = 0`` by
the integration error; where ``A`` loses rank (a parallelogram passing its flat position,
where the crossed branch meets the physical one) that drift is enough to leave the physical
branch.  The runner (:func:`ncgen.runtime.simulation.simulate`, ``project``) therefore
watches how close ``A`` is to losing rank (:meth:`ManifoldProjector.near_singular`), hands
the intervals next to a singular configuration to RATTLE (:mod:`ncgen.runtime.rattle_bridge`),
and projects the state back before them (and, with ``project=True``, after every output
interval):

    positions:  q ← q − M⁻¹Aᵀ (A M⁻¹ Aᵀ)⁺ Φ        (Gauss–Newton, a few iterations)
    velocities: v ← v − M⁻¹Aᵀ (A M⁻¹ Aᵀ)⁺ (A v + Φ_t)

A direction in which the constraints are (nearly) dependent takes no step, so the
projection never jumps to another branch.
"""
from __future__ import annotations

from typing import Callable

import casadi as ca
import numpy as np

from ncgen.assembly.mass import augmented_mass, is_regular, jacobi_scale, sparse_dm
from ncgen.errors import ModelError, NcgenError
from ncgen.model.layout import Layout

#: The one rank tolerance of the manifold's numerics (module docstring): singular values of
#: ``A`` or ``A M⁻¹ Aᵀ`` below this fraction of the largest count as zero.
RANK_TOL = 1e-10
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
#: States per call of ``A`` mapped over a block (:meth:`ManifoldProjector.ratio_rates`).
RATE_BLOCK = 64


#: Newton onto ``Φ = 0`` (:func:`newton`) stops when max |Φ| ≤ NEWTON_TOL · (size of the
#: system)² (Φ is in m²), after NEWTON_ITER iterations at most.
NEWTON_TOL = 1e-13
NEWTON_ITER = 50


# ------------------------------------------------------------ positions: Newton onto Φ = 0
def newton(phi, jac, q, free, *, tol: float, max_iter: int = NEWTON_ITER):
    """Minimum-norm Newton on the ``free`` entries of ``q``; returns ``(q, iterations,
    max |Φ|)`` (the residual is above ``tol`` when it did not converge)."""
    q = np.array(q, dtype=float)
    free = np.asarray(free, dtype=int)
    r = phi(q)
    for it in range(max_iter + 1):
        res = float(np.max(np.abs(r))) if r.size else 0.0
        if res <= tol or it == max_iter or not np.all(np.isfinite(r)):
            return q, it, res
        step = np.linalg.lstsq(jac(q)[:, free], r, rcond=None)[0]
        q[free] -= step
        r = phi(q)
    return q, max_iter, res


def system_size(q: np.ndarray) -> float:
    """Length scale of a configuration (m): the largest |coordinate|, at least 1."""
    return max(1.0, float(np.max(np.abs(q))) if q.size else 1.0)


# ------------------------------------------------------------ rank, null space and charts
def _rank_of(s: np.ndarray, tol: float) -> int:
    """How many of the singular values ``s`` exceed ``tol`` × the largest."""
    return int(np.sum(s > tol * max(float(s.max()), 1e-300))) if s.size else 0


def numerical_rank(A: np.ndarray, tol: float = RANK_TOL) -> int:
    """Rank of ``A``: its singular values above ``tol`` × the largest (0 for an empty
    ``A``); the rank :func:`null_basis` uses, so ``nq − numerical_rank(A)`` is its width."""
    A = np.atleast_2d(np.asarray(A, float))
    if A.size == 0:
        return 0
    return _rank_of(np.linalg.svd(A, compute_uv=False), tol)


def null_basis(A: np.ndarray, nq: int, tol: float = RANK_TOL) -> np.ndarray:
    """Orthonormal basis of ``null A`` (nq × (nq − :func:`numerical_rank`)), columns signed
    reproducibly; singular values below ``tol`` × the largest count as zero."""
    A = np.asarray(A, float).reshape(-1, nq)
    if A.shape[0] == 0:
        return np.eye(nq)
    _, s, Vt = np.linalg.svd(A)
    N = Vt[_rank_of(s, tol):].T.copy()
    for j in range(N.shape[1]):
        i = int(np.argmax(np.abs(N[:, j])))
        if N[i, j] < 0:
            N[:, j] = -N[:, j]
    return N


def tangent_basis(model, q, t=None, p=None) -> np.ndarray:
    """Orthonormal basis (nq × dof) of the null space of ``A(q)`` (:func:`null_basis`)."""
    return null_basis(model.A(q, t=t, p=p), model.nq)


def coordinate_basis(A: np.ndarray, nq: int, G=None) -> tuple[np.ndarray, np.ndarray]:
    """``(N, G)``: a tangent basis and the independent coordinates' functional, ``A N = 0``,
    ``G N = I``.  ``G=None``: ``N`` orthonormal, ``G = Nᵀ``."""
    N = null_basis(A, nq)
    if G is None:
        return N, N.T.copy()
    G = np.asarray(G, float)
    if G.shape != (N.shape[1], nq):
        raise NcgenError(f"coordinates: expected a {N.shape[1]} × {nq} matrix (one row per degree of "
                         f"freedom, one column per natural coordinate), got shape {G.shape}")
    GN = G @ N
    if numerical_rank(GN) < N.shape[1]:
        raise NcgenError("coordinates: the rows of G do not determine the configuration "
                         "(G N is singular: some motion allowed by the constraints leaves them unchanged)")
    return N @ np.linalg.inv(GN), G


def manifold_point(phi: Callable, jac: Callable, q_ref: np.ndarray, N: np.ndarray, G: np.ndarray,
                   z: np.ndarray, *, tol: float = 1e-13, max_iter: int = 30) -> np.ndarray:
    """The configuration ``q`` with ``Φ(q) = 0`` and ``G (q − q_ref) = z`` (Newton from
    ``q_ref + N z``): the point of independent coordinates ``z`` in the chart at ``q_ref``."""
    q = q_ref + N @ z
    size = max(1.0, float(np.abs(q_ref).max()) if q_ref.size else 1.0)
    for _ in range(max_iter):
        r = np.concatenate([phi(q), G @ (q - q_ref) - z])
        if np.abs(r).max() <= tol * size**2:
            return q
        J = np.vstack([jac(q), G])
        q = q - np.linalg.lstsq(J, r, rcond=None)[0]
    raise NcgenError(f"no configuration with independent coordinates z = {np.round(z, 6)} near the "
                     "reference: the perturbation is too large for the chart")


def tangent_velocity(A: np.ndarray, G: np.ndarray, w: np.ndarray, phi_t=None) -> np.ndarray:
    """The rates ``v`` with ``A v + Φ_t = 0`` and ``G v = w``."""
    nc = A.shape[0]
    rhs = np.concatenate([np.zeros(nc) if phi_t is None else -np.asarray(phi_t, float), w])
    return np.linalg.lstsq(np.vstack([A, G]), rhs, rcond=None)[0]


# ------------------------------------------------------------ mass-metric projections
def mass_step(factor, A: np.ndarray, r: np.ndarray, Minv: np.ndarray | None = None) -> np.ndarray:
    """``δ = M⁻¹Aᵀ (A M⁻¹ Aᵀ)⁺ r``: the step of least kinetic energy ``½ δᵀMδ`` with
    ``A δ = r``, the pseudo-inverse truncated at :data:`RANK_TOL` (``factor``: the model's
    ``mass_factor``; ``Minv``: a dense ``M⁻¹`` to use instead, for repeated calls)."""
    MiAT = Minv @ A.T if Minv is not None else factor.solve_with(A, A.T)
    return MiAT @ np.linalg.lstsq(A @ MiAT, r, rcond=RANK_TOL)[0]


def consistent_velocity(model, q, v, *, t=None, p=None) -> np.ndarray:
    """The M-orthogonal projection of ``v`` onto ``A(q) v + Φ_t = 0``."""
    A = np.atleast_2d(model.A(q, t=t, p=p))
    v = np.asarray(v, dtype=float)
    if A.shape[0] == 0:
        return v.copy()
    phi_t = np.array(model.functions["phi_t"](model.t0 if t is None else t, q,
                                              model.p0 if p is None else p)).reshape(-1)
    return v - mass_step(model.mass_factor, A, A @ v + phi_t)


def project(A: np.ndarray, b: np.ndarray, v: np.ndarray, M: np.ndarray, free) -> np.ndarray:
    """The ``w`` closest to ``v`` in the metric ``M`` with ``A w = b`` and ``w = v`` outside
    ``free`` (least squares when that is impossible).  The step ``δ = M⁻¹Aᵀμ`` with
    ``A δ = b − A v`` comes from the sparse KKT system (O(n) for chain-like systems); only
    rank-deficient constraints take the dense least-squares route."""
    w = np.array(v, dtype=float)
    if A.shape[0] == 0:
        return w
    free = np.asarray(free, dtype=int)
    every = free.size == w.size and np.array_equal(free, np.arange(w.size))     # no copies of A and M then
    Af, Mf = (A, M) if every else (A[:, free], M[np.ix_(free, free)])
    r = b - A @ w
    step = _kkt_step(Mf, Af, r)
    if step is None:
        MiAT = np.linalg.solve(augmented_mass(Mf, Af) if not is_regular(Mf) else Mf, Af.T)
        step = MiAT @ np.linalg.lstsq(Af @ MiAT, r, rcond=RANK_TOL)[0]
    w[free] += step
    return w


def _kkt_step(M: np.ndarray, A: np.ndarray, r: np.ndarray) -> np.ndarray | None:
    """``δ`` of ``[[M, Aᵀ], [A, 0]] [δ; −μ] = [0; r]`` by sparse QR, or None if the system is
    singular (dependent constraints)."""
    n, m = M.shape[0], A.shape[0]
    Ms, As = sparse_dm(M), sparse_dm(A)
    K = ca.blockcat([[Ms, As.T], [As, ca.DM(m, m)]])
    rhs = np.concatenate([np.zeros(n), r])
    try:
        x = np.array(ca.solve(K, ca.DM(rhs), "qr")).reshape(-1)
    except RuntimeError:                       # CasADi's QR refuses a structurally singular K
        return None
    # checked against the dense inputs, not against K: a fault in building K shows up here
    delta, mu = x[:n], -x[n:]
    Md = M @ delta
    scale = 1.0 + float(np.max(np.abs(np.concatenate([r, Md])), initial=0.0))
    residual = max(np.max(np.abs(A @ delta - r), initial=0.0), np.max(np.abs(Md - A.T @ mu), initial=0.0))
    if not np.all(np.isfinite(x)) or residual > 1e-9 * scale:
        return None
    return delta


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

    def ratio_rate(self, t: float, x: np.ndarray) -> tuple[float, float]:
        """``(r, ṙ)``: ``r = σ_min/σ_max`` of ``A`` at ``x = [q; v]`` and its rate along the
        motion (1/s), ``ṙ = (σ̇_min σ_max − σ_min σ̇_max)/σ_max²`` with ``σ̇_k = u_kᵀ Ȧ w_k``
        (singular vectors ``u_k``, ``w_k``) and ``Ȧ = dA/dt + ∂A/∂q v`` by a central difference
        along ``(1, v)`` (exact where ``A`` is affine in ``(t, q)``, as for quadratic
        constraints).  ``(1, 0)`` where ``A`` is empty or not finite."""
        if not self.active:
            return 1.0, 0.0
        q, v = x[:self.nq], x[self.nq:]
        A = self._A(t, q)
        eps = 1e-6 / max(1.0, float(np.max(np.abs(v), initial=0.0)))
        A_dot = (self._A(t + eps, q + eps * v) - self._A(t - eps, q - eps * v)) / (2.0 * eps)
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(A_dot))):
            return 1.0, 0.0
        try:
            U, s, Wt = np.linalg.svd(A, full_matrices=False)
        except np.linalg.LinAlgError:
            return 1.0, 0.0
        if not s[0] > 0:
            return 1.0, 0.0
        rate_min, rate_max = U[:, -1] @ A_dot @ Wt[-1], U[:, 0] @ A_dot @ Wt[0]
        return float(s[-1] / s[0]), float((rate_min * s[0] - s[-1] * rate_max) / s[0] ** 2)

    def ratio_rates(self, t: np.ndarray, X: np.ndarray) -> np.ndarray:
        """:meth:`ratio_rate` at the times ``t`` (n) and states ``X`` (n × 2nq) at once, as rows
        ``(r, ṙ)`` of an n × 2 array: ``A`` through CasADi's ``map`` over blocks of
        :data:`RATE_BLOCK` states and one stacked SVD, about twenty times cheaper than n calls."""
        t, X = np.asarray(t, dtype=float), np.asarray(X, dtype=float)
        out = np.tile([1.0, 0.0], (len(t), 1))
        if not self.active or len(t) == 0:
            return out
        Q, V = X[:, :self.nq], X[:, self.nq:]
        eps = 1e-6 / np.maximum(1.0, np.max(np.abs(V), axis=1, initial=0.0))
        A = self._A_many(t, Q)
        A_dot = (self._A_many(t + eps, Q + eps[:, None] * V) - self._A_many(t - eps, Q - eps[:, None] * V)) \
            / (2.0 * eps[:, None, None])
        ok = np.all(np.isfinite(A), axis=(1, 2)) & np.all(np.isfinite(A_dot), axis=(1, 2))
        if not np.any(ok):
            return out
        try:
            U, s, Wt = np.linalg.svd(A[ok], full_matrices=False)
        except np.linalg.LinAlgError:
            out[ok] = [self.ratio_rate(ti, xi) for ti, xi in zip(t[ok], X[ok])]
            return out
        Ad = A_dot[ok]
        rate_min = np.einsum("bi,bij,bj->b", U[:, :, -1], Ad, Wt[:, -1, :])
        rate_max = np.einsum("bi,bij,bj->b", U[:, :, 0], Ad, Wt[:, 0, :])
        s_max, s_min = s[:, 0], s[:, -1]
        good = s_max > 0
        safe = np.where(good, s_max, 1.0)
        r = np.where(good, s_min / safe, 1.0)
        r_dot = np.where(good, (rate_min * s_max - s_min * rate_max) / safe ** 2, 0.0)
        out[ok] = np.column_stack([r, r_dot])
        return out

    def _A_many(self, t: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """``A`` at each row of ``(t, Q)``: an n × nc × nq array."""
        if getattr(self, "_A_map", None) is None:
            self._A_map = self.f["A"].map(RATE_BLOCK)
        n, B = len(t), RATE_BLOCK
        rows, cols = self.f["A"].size_out(0)
        out = np.empty((n, rows, cols))
        for s in range(0, n, B):
            m = min(B, n - s)
            tb = np.concatenate([t[s:s + m], np.full(B - m, t[s + m - 1])])
            Qb = np.vstack([Q[s:s + m], np.repeat(Q[s + m - 1:s + m], B - m, axis=0)])
            A = np.array(self._A_map(tb[None, :], Qb.T, self.p), dtype=float)
            out[s:s + m] = A.reshape(rows, B, cols).transpose(1, 0, 2)[:m]
        return out

    def departure(self, t_a: float, x_a: np.ndarray, t_b: float, x_b: np.ndarray) -> float:
        """How far the chord from ``(t_a, q_a)`` to ``(t_b, q_b)`` leaves the motions tangent to
        ``Φ(t, q) = 0`` at its two ends, relative to its length: the largest over both ends of
        ``|J⁺ r| / |d|`` with ``d = q_b − q_a``, ``Δt = t_b − t_a``, ``r = A d + Φ_t Δt`` and
        ``J = [A, Φ_t / c]`` acting on ``(δq, c δt)``, ``c = |d| / Δt`` (time measured as the
        chord's own speed, so that a driven motion may also shift in time; ``J⁺`` truncated at
        :data:`RANK_TOL`).  For a constraint without time, ``|A⁺ A d| / |d|``, the part of ``d``
        normal to the tangent space.  On one smooth branch of ``Φ = 0`` this is about half the
        angle the tangent turns along the chord; a chord that leaves one branch at a singular
        configuration for another makes it of the order of the sine of the angle between
        their tangents."""
        nq = self.nq
        d = x_b[:nq] - x_a[:nq]
        size = float(np.linalg.norm(d))
        if not self.active or not size > 0 or not t_b > t_a:
            return 0.0
        c = size / (t_b - t_a)
        worst = 0.0
        for t, q in ((t_a, x_a[:nq]), (t_b, x_b[:nq])):
            A = self._A(t, q)
            phi_t = np.array(self.f["phi_t"](t, q, self.p), dtype=float).reshape(-1)
            J = np.column_stack([A, phi_t / c])
            r = A @ d + phi_t * (t_b - t_a)
            worst = max(worst, float(np.linalg.norm(np.linalg.lstsq(J, r, rcond=RANK_TOL)[0])) / size)
        return worst

    def start(self, t: float, x: np.ndarray):
        """Scale the near-singular limits by this starting configuration's ``σ_min/σ_max``
        over :data:`WELL_CONDITIONED`, where below 1."""
        self.scale = min(1.0, self.ratio(t, x) / WELL_CONDITIONED)

    def _phi(self, t, q):
        return np.array(self.f["phi"](t, q, self.p), dtype=float).reshape(-1)

    def _A(self, t, q):
        return np.array(self.f["A"](t, q, self.p), dtype=float)

    def _step(self, A, r):
        return mass_step(self.factor, A, r, self.Minv)

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
    return kkt_least_squares(model.M, A, rhs)


def solve_linear(K: np.ndarray, b: np.ndarray, tol: float = 1e-8) -> np.ndarray | None:
    """``x`` with ``K x = b``: CasADi's sparse QR for a square ``K`` (dense LAPACK is slow
    and thread-hungry at these sizes), least squares otherwise; None when no ``x`` fits to
    ``tol`` relative to ``|b|`` (a singular or inconsistent system)."""
    K, b = np.asarray(K, float), np.asarray(b, float)
    if K.shape[0] == K.shape[1]:
        try:
            x = np.array(ca.solve(sparse_dm(K), ca.DM(b), "qr")).reshape(-1)
        except RuntimeError:
            return None
    else:
        x = np.linalg.lstsq(K, b, rcond=None)[0]
    if not np.all(np.isfinite(x)):
        return None
    err = np.max(np.abs(K @ x - b), initial=0.0)
    return x if err <= tol * max(1.0, np.max(np.abs(b), initial=0.0)) else None


def kkt_solve(M: np.ndarray, A: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """``z`` of ``[[M, Aᵀ], [A, 0]] z = rhs`` by LU (regular where ``A`` has full rank and
    ``M`` is positive definite on its null space), else :func:`kkt_least_squares`."""
    nc = A.shape[0]
    K = np.block([[M, A.T], [A, np.zeros((nc, nc))]])
    try:
        z = np.linalg.solve(K, rhs)
        if np.all(np.isfinite(z)):
            return z
    except np.linalg.LinAlgError:
        pass
    return kkt_least_squares(M, A, rhs)


def kkt_least_squares(M: np.ndarray, A: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """``z`` of ``[[M, Aᵀ], [A, 0]] z = rhs``, the minimum-norm least-squares solution (so a
    rank-deficient ``A`` is fine); NaN where the system is not finite or the solve fails."""
    nc = A.shape[0]
    K = np.block([[M, A.T], [A, np.zeros((nc, nc))]])
    if not np.all(np.isfinite(K)) or not np.all(np.isfinite(rhs)):
        return np.full(K.shape[0], np.nan)
    try:
        return np.linalg.lstsq(K, rhs, rcond=None)[0]
    except np.linalg.LinAlgError:
        return np.full(K.shape[0], np.nan)


# ------------------------------------------------------------ inertia on the tangent space
#: ``M`` counts as positive definite on ``null(A)`` when the smallest eigenvalue of the
#: Jacobi-scaled reduced mass matrix ``Nᵀ M N`` exceeds this.
TANGENT_INERTIA_TOL = 1e-9


def check_tangent_inertia(M: np.ndarray, A: np.ndarray, layout: Layout, members, where: str) -> None:
    """Raise :class:`ModelError` unless ``M`` is positive definite on ``null(A)`` (``A`` at
    the initial configuration): otherwise a motion allowed by the constraints has no inertia
    (a line-like body free to spin about its line, a point-like body free to turn), and the
    equations of motion do not determine it.  Names the members that move in that motion."""
    n = M.shape[0]
    if n == 0:
        return
    d = jacobi_scale(M)
    Ms = M / d[:, None] / d[None, :]
    As = A / d[None, :] if A.size else np.zeros((0, n))
    N = null_basis(As, n)
    if N.shape[1] == 0:
        return
    w, Y = np.linalg.eigh(N.T @ Ms @ N)
    if w[0] > TANGENT_INERTIA_TOL:
        return
    z = (N @ Y[:, 0]) / d
    z = z / np.max(np.abs(z))
    moving = []
    for m in members:
        idx = [i for i in layout.member_indices(m.name) if i is not None]
        if idx and np.max(np.abs(z[idx])) > 1e-6:
            moving.append(m.name)
    raise ModelError(
        f"{where}: a motion allowed by the constraints has no inertia (the mass matrix is singular on "
        f"the constraint tangent space at the initial configuration), so the equations of motion do "
        f"not determine it; it moves member(s) {', '.join(moving)}: a point mass, a line-like body "
        f"free to spin about its line or a flat body free to turn its normal needs inertia for that "
        f"motion (give the body thickness or a non-zero moment) or a joint that stops it")
