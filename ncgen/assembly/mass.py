"""The constant system mass matrix and the application of its inverse.

``M = Σ_I S_Iᵀ M_I S_I`` (members' constant mass matrices scattered onto their free
coordinates).  Shared points couple members, so ``M`` is sparse but not block diagonal and
``M⁻¹`` would be dense; instead ``M = L Lᵀ`` is factorised once (numerically, it is
constant) and ``M⁻¹ b`` is the pair of sparse triangular solves ``L⁻ᵀ (L⁻¹ b)``, whose
CasADi expression costs O(nnz(L)).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.assembly.layout import Layout
from ncgen.model.members import ModelError


def assemble_mass(layout: Layout, members) -> np.ndarray:
    M = np.zeros((layout.nq, layout.nq))
    for m in members:
        idx = layout.member_indices(m.name)
        keep = [k for k, i in enumerate(idx) if i is not None]
        rows = [idx[k] for k in keep]
        M[np.ix_(rows, rows)] += m.local.M[np.ix_(keep, keep)]
    return M


class CholeskyFactor:
    """``M = L Lᵀ`` with ``L`` stored row-wise sparse."""

    def __init__(self, M: np.ndarray, names: list[str]):
        try:
            L = np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            d = np.diag(M)
            bad = [names[i] for i in np.flatnonzero(d <= 0)]
            raise ModelError("the mass matrix is not positive definite"
                             + (f"; coordinates without mass: {', '.join(bad)}" if bad else "")) from None
        self.n = M.shape[0]
        self.rows = [(np.flatnonzero(L[i, :i]), L[i, np.flatnonzero(L[i, :i])]) for i in range(self.n)]
        self.diag = np.diag(L).copy()
        self.cols = [(np.flatnonzero(L[i + 1:, i]) + i + 1, L[i + 1:, i][np.flatnonzero(L[i + 1:, i])])
                     for i in range(self.n)]
        self.nnz = int(np.count_nonzero(L))

    def solve(self, b):
        """``M⁻¹ b`` for a CasADi column ``b`` (SX or MX), by two sparse triangular solves."""
        n = self.n
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

    def solve_numeric(self, b: np.ndarray) -> np.ndarray:
        L = self.dense()
        return np.linalg.solve(L.T, np.linalg.solve(L, b))

    def dense(self) -> np.ndarray:
        L = np.zeros((self.n, self.n))
        for i, (idx, vals) in enumerate(self.rows):
            L[i, idx] = vals
            L[i, i] = self.diag[i]
        return L
