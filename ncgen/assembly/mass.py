"""The constant system mass matrix and the application of its inverse.

``M = Σ_I S_Iᵀ M_I S_I`` (members' constant mass matrices scattered onto their free
coordinates).  Shared points couple members, so ``M`` is sparse but not block diagonal and
``M⁻¹`` would be dense; instead ``M = L Lᵀ`` is factorised once (numerically, it is
constant) and ``M⁻¹ b`` is the pair of sparse triangular solves ``L⁻ᵀ (L⁻¹ b)``, whose
CasADi expression costs O(nnz(L)).  The factorisation is sparse too (CasADi's LDLᵀ in the
natural order, ``L = (I + L̃) D^½``): a dense one costs O(nq³), seconds for a 1000-bar chain.

A flat body (a thin disc or plate: principal moments with I1 + I2 = I3) has a singular
``M``: its mass lies in a plane, so the base vector normal to it carries no inertia.  The
dynamics are still regular when ``M`` is positive definite on the tangent space of the
constraints, ``null(A)`` (:func:`ncgen.assembly.manifold.check_tangent_inertia`).  :func:`mass_factor` then returns
a :class:`SingularMass`; KKT paths are unchanged, and every path that needs ``M⁻¹`` uses
the KKT system instead or the augmented mass matrix (de Jalón & Bayo; docs/architecture.md)

    M̄(q) = M + κ A(q)ᵀ A(q),

which is positive definite exactly when ``M`` is on ``null(A)``.  It is exact wherever ``A x``
is known: in a projection (``min ½ δᵀMδ`` subject to ``A δ = r`` has the same minimiser in
the ``M̄`` metric, since ``δᵀM̄δ = δᵀMδ + κ|r|²`` on the feasible set) and in the equations
of motion (``M a = F − Aᵀλ`` with ``A a = c`` is ``M̄ a = F − Aᵀλ + κ Aᵀc``).  Regular
mass matrices keep the constant factor (:class:`CholeskyFactor`).  ``κ`` (:func:`kappa`)
only scales ``AᵀA`` to ``M``; it does not change any result.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.errors import ModelError
from ncgen.model.layout import Layout

#: A mass matrix counts as singular when a pivot of its LDLᵀ, after scaling ``M`` to a unit
#: diagonal, is below this.
SINGULAR_PIVOT_TOL = 1e-9
#: A body counts as flat (or line- or point-like) when the smallest eigenvalue of its
#: ``J̄ = ∫ρ r̄ r̄ᵀ`` is below this fraction of the largest: a disc thinner than about 3e-4 of
#: its radius.  Its ``M`` is then treated as singular, even if slightly regular: a constant
#: ``M⁻¹`` would amplify rounding by the inverse of that ratio.
FLAT_TOL = 1e-8
#: Diagonal entries of ``M`` below this fraction of the largest are scaled as if they were
#: that size (Jacobi scaling of coordinates without inertia).
SCALE_FLOOR = 1e-12


def assemble_mass(layout: Layout, members) -> np.ndarray:
    M = np.zeros((layout.nq, layout.nq))
    for m in members:
        idx = layout.member_indices(m.name)
        keep = [k for k, i in enumerate(idx) if i is not None]
        rows = [idx[k] for k in keep]
        M[np.ix_(rows, rows)] += m.rigid.M[np.ix_(keep, keep)]
    return M


def sparse_dm(M: np.ndarray) -> ca.DM:
    """``M`` as a sparse CasADi matrix, built from its nonzeros (``ca.DM(M)`` first copies
    every entry of the dense array: O(nq²)).  A DM's nonzeros are stored column by column,
    so the nonzeros, found in memory order (row by row: one pass over ``M``, twice as fast as
    over its transpose), are sorted by column, rows ascending within each."""
    M = np.asarray(M)
    rows, cols = np.divmod(np.flatnonzero(M), M.shape[1])
    order = np.argsort(cols, kind="stable")
    rows, cols = rows[order], cols[order]
    return ca.DM(ca.Sparsity.triplet(M.shape[0], M.shape[1], rows.tolist(), cols.tolist()), M[rows, cols])


def dense_dm(X: ca.DM) -> np.ndarray:
    """``X`` as a dense NumPy array, scattered from its nonzeros (``np.array(X)`` goes through a
    Python list of every entry: O(rows × cols) Python floats, 0.4 s for a 1000-bar chain's ``A``)."""
    out = np.zeros(X.shape)
    rows, cols = X.sparsity().get_triplet()
    out[rows, cols] = X.nonzeros()
    return out


def flat_members(members, layout: Layout) -> list[str]:
    """Names of the 3D bodies whose mass lies (nearly) in a plane, on a line or at a point
    (:data:`FLAT_TOL`) and whose free coordinates (``layout``) include a direction without
    (enough) inertia: a thin disc's normal, unless a joint fixes it."""
    out = []
    for m in members:
        if m.kind != "body" or m.rigid.Jbar.shape[0] != 3:
            continue
        w = np.linalg.eigvalsh(m.rigid.Jbar)
        if w[0] > FLAT_TOL * max(float(w[-1]), 1e-300):
            continue
        free = [k for k, i in enumerate(layout.member_indices(m.name)) if i is not None]
        Mf = m.rigid.M[np.ix_(free, free)]
        if free and np.linalg.eigvalsh(Mf)[0] <= FLAT_TOL * max(float(w[-1]), 1e-300):
            out.append(m.name)
    return out


def flat_support(members, layout: Layout, flat: list[str]) -> np.ndarray:
    """Indices of the coordinates that only ``flat`` members move: ``null(M)`` lies in their
    span (``zᵀMz = Σ_I z_Iᵀ M_I z_I`` vanishes only if every regular member's ``z_I`` does)."""
    own, other = set(), set()
    for m in members:
        idx = {i for i in layout.member_indices(m.name) if i is not None}
        (own if m.name in flat else other).update(idx)
    return np.array(sorted(own - other), dtype=int)


def mass_factor(M: np.ndarray, names: list[str], flat: list[str] = (),
                support: np.ndarray | None = None) -> "CholeskyFactor | SingularMass":
    """The constant factor of a regular ``M``, or a :class:`SingularMass` when ``M`` is
    singular or a member is ``flat`` (see module docstring); ``support``: where ``null(M)``
    lies (:func:`flat_support`; default: anywhere)."""
    if not flat:
        try:
            return CholeskyFactor(M, names)
        except SingularMassError:
            support = None
    return SingularMass(M, names, flat, support)


def jacobi_scale(M: np.ndarray) -> np.ndarray:
    """``d`` with ``M / (d dᵀ)`` of unit diagonal (floored at :data:`SCALE_FLOOR`)."""
    diag = np.diag(M)
    return np.sqrt(np.maximum(diag, SCALE_FLOOR * max(float(np.max(diag, initial=0.0)), 1e-300)))


def scaled_pivots(D, M: np.ndarray) -> np.ndarray:
    """The pivots of the LDLᵀ of the Jacobi-scaled ``M`` from those ``D`` of ``M`` itself
    (scaling by ``S`` keeps the unit triangle: pivot ``k`` becomes ``D_k / d_k²``)."""
    return np.array(D).reshape(-1) / jacobi_scale(M) ** 2


def is_regular(M: np.ndarray) -> bool:
    """Whether ``M`` is numerically positive definite (:data:`SINGULAR_PIVOT_TOL`)."""
    if M.shape[0] == 0:
        return True
    D, _, _ = ca.ldl(sparse_dm(M), False)
    return bool(np.all(scaled_pivots(D, M) > SINGULAR_PIVOT_TOL))


class SingularMassError(ModelError):
    """``M`` is not (numerically) positive definite: no constant Cholesky factor."""


def mass_is_regular(model) -> bool:
    """Whether ``model``'s mass matrix is regular (its constant ``M⁻¹`` exists); False for a
    model with a flat body, whose every ``M⁻¹`` goes through :func:`augmented_mass`."""
    return bool(model.mass_factor.regular)


def kappa(M: np.ndarray, A: np.ndarray) -> float:
    """The scale ``κ`` of ``M̄ = M + κ AᵀA``: ``max diag M / max diag AᵀA`` (kg per unit of A²)."""
    aa = float(np.max(np.sum(A * A, axis=0), initial=0.0))
    return float(np.max(np.diag(M), initial=1.0)) / aa if aa > 0 else 1.0


def augmented_mass(M: np.ndarray, A: np.ndarray) -> np.ndarray:
    """``M̄ = M + κ AᵀA`` (dense; see module docstring)."""
    return M + kappa(M, A) * (A.T @ A)


class SingularMass:
    """A singular constant ``M`` (a flat body): no constant inverse; :meth:`solve_with` applies
    ``M̄(q)⁻¹`` for the constraint Jacobian of the state at hand, :meth:`pseudo_solve` the
    pseudo-inverse ``M⁺ = (M + c P)⁻¹ − P/c`` (``P`` the orthogonal projector onto
    ``null(M)``, ``c = max diag M``), with the sparse factor of ``M + c P``."""

    regular = False

    def __init__(self, M: np.ndarray, names: list[str], flat: list[str] = (), support: np.ndarray | None = None):
        self.n = n = M.shape[0]
        self.M = np.array(M, dtype=float)
        self.flat = list(flat)
        S = np.arange(n) if support is None else np.asarray(support, dtype=int)
        Mss = self.M[np.ix_(S, S)]
        d = jacobi_scale(Mss)
        w, V = np.linalg.eigh(Mss / d[:, None] / d[None, :]) if S.size else (np.zeros(0), np.zeros((0, 0)))
        Z = np.zeros((n, int(np.sum(w <= SINGULAR_PIVOT_TOL))))
        Z[S] = V[:, w <= SINGULAR_PIVOT_TOL] / d[:, None]        # null(M) = D^-½ null(M_s), on S
        Q = np.linalg.qr(Z)[0] if Z.shape[1] else np.zeros((n, 0))
        P = Q @ Q.T
        P[np.abs(P) < 1e-14] = 0.0
        self.c = float(np.max(np.diag(self.M), initial=1.0))
        self.P = P
        try:
            self._regularised = CholeskyFactor(self.M + self.c * P, names)
        except SingularMassError:
            self._regularised = None

    def solve_with(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:
        """``M̄⁻¹ B`` with ``M̄ = M + κ AᵀA``; raises :class:`ModelError` when ``M̄`` is singular
        (a motion without inertia that the constraints ``A`` leave free)."""
        Mbar = augmented_mass(self.M, np.asarray(A, dtype=float).reshape(-1, self.n))
        try:
            L = np.linalg.cholesky(Mbar)
        except np.linalg.LinAlgError:
            raise ModelError("the mass matrix is singular on the constraint tangent space: a motion has no "
                             "inertia (see ncgen.assembly.mass.check_tangent_inertia)") from None
        return np.linalg.solve(L.T, np.linalg.solve(L, B))

    def pseudo_solve(self, b):
        """``M⁺ b`` for a CasADi column ``b`` (what the ``Minv`` function applies)."""
        if self._regularised is None:            # M + cP ill-conditioned: the dense pseudo-inverse
            Mp = np.linalg.pinv(self.M, hermitian=True)
            Mp[np.abs(Mp) < 1e-12 * max(float(np.max(np.abs(Mp), initial=0.0)), 1e-300)] = 0.0
            return ca.mtimes(sparse_dm(Mp), b)
        return self._regularised.solve(b) - ca.mtimes(sparse_dm(self.P), b) / self.c

    def solve(self, b):
        raise ModelError("the mass matrix is singular (a flat body): M⁻¹ does not exist; use the "
                         "augmented mass matrix (ncgen.assembly.mass.augmented_mass)")

    solve_numeric = solve


class CholeskyFactor:
    """``M = L Lᵀ`` with ``L`` stored row-wise sparse."""

    regular = True

    def __init__(self, M: np.ndarray, names: list[str]):
        self.n = n = M.shape[0]
        D, LT, _ = ca.ldl(sparse_dm(M), False) if n else (ca.DM(0, 1), ca.DM(0, 0), [])
        d = np.array(D).reshape(-1)
        if n and not np.all(scaled_pivots(D, M) > SINGULAR_PIVOT_TOL):
            diag = np.diag(M)
            bad = [names[i] for i in np.flatnonzero(diag <= 0)]
            raise SingularMassError("the mass matrix is not positive definite"
                                    + (f"; coordinates without mass: {', '.join(bad)}" if bad else ""))
        self.diag = np.sqrt(d)
        # L = (I + L̃) D^½ with L̃ = LTᵀ strictly lower: entry (i, j), j < i, is LT[j, i] √d_j
        cols_of, rows_of = LT.sparsity().get_triplet()          # LT[r, c]: r < c
        vals = np.array(LT.nonzeros()) * self.diag[cols_of] if LT.nnz() else np.zeros(0)
        lower_i, lower_j = np.asarray(rows_of, dtype=int), np.asarray(cols_of, dtype=int)
        order = np.lexsort((lower_j, lower_i))
        by_row = np.split(order, np.searchsorted(lower_i[order], np.arange(1, n)))
        order = np.lexsort((lower_i, lower_j))
        by_col = np.split(order, np.searchsorted(lower_j[order], np.arange(1, n)))
        self.rows = [(lower_j[k], vals[k]) for k in by_row] if n else []
        self.cols = [(lower_i[k], vals[k]) for k in by_col] if n else []
        self.nnz = int(n + len(vals))

    def solve(self, b):
        """``M⁻¹ b`` for a CasADi column ``b`` by two sparse triangular solves: unrolled into
        O(nnz(L)) operations for SX, two solve nodes with the constant ``L`` for MX (loops
        over its pattern in generated C)."""
        n = self.n
        if isinstance(b, ca.MX) and n:
            L = ca.MX(self.lower())
            return ca.solve(L.T, ca.solve(L, b))
        y = [None] * n
        for i in range(n):
            idx, vals = self.rows[i]
            acc = b[i]
            for j, lij in zip(idx, vals):
                acc = acc - lij * y[j]
            y[i] = acc / self.diag[i]
        x = [None] * n
        for i in reversed(range(n)):
            idx, vals = self.cols[i]
            acc = y[i]
            for j, lji in zip(idx, vals):
                acc = acc - lji * x[j]
            x[i] = acc / self.diag[i]
        return ca.vertcat(*x) if n else b

    def lower(self) -> ca.DM:
        """``L`` as a sparse CasADi matrix."""
        rows = [i for i, (idx, _) in enumerate(self.rows) for _ in idx] + list(range(self.n))
        cols = [int(j) for idx, _ in self.rows for j in idx] + list(range(self.n))
        vals = [float(x) for _, v in self.rows for x in v] + [float(d) for d in self.diag]
        sp, mapping = ca.Sparsity.triplet(self.n, self.n, rows, cols, True)
        nz = np.zeros(sp.nnz())
        nz[np.array(mapping, dtype=np.int64)] = vals
        return ca.DM(sp, nz)

    def solve_with(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:
        """``M⁻¹ B`` (``A`` is ignored: for a regular ``M`` the augmented form is not needed)."""
        return self.solve_numeric(B)

    def solve_numeric(self, b: np.ndarray) -> np.ndarray:
        L = self.dense()
        return np.linalg.solve(L.T, np.linalg.solve(L, b))

    def dense(self) -> np.ndarray:
        return np.array(ca.densify(self.lower())) if self.n else np.zeros((0, 0))


