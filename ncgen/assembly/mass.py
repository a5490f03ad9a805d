"""The constant system mass matrix and the application of its inverse.

``M = Σ_I S_Iᵀ M_I S_I`` (members' constant mass matrices scattered onto their free
coordinates).  Shared points couple members, so ``M`` is sparse but not block diagonal and
``M⁻¹`` would be dense; instead ``M = L Lᵀ`` is factorised once (numerically, it is
constant) and ``M⁻¹ b`` is the pair of sparse triangular solves ``L⁻ᵀ (L⁻¹ b)``, whose
CasADi expression costs O(nnz(L)).  The factorisation is sparse too (CasADi's LDLᵀ in the
natural order, ``L = (I + L̃) D^½``): a dense one costs O(nq³), seconds for a 1000-bar chain.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.errors import ModelError
from ncgen.model.layout import Layout


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
    so they are gathered in that order (``np.nonzero(M)`` lists them row by row)."""
    cols, rows = np.nonzero(np.asarray(M).T)
    return ca.DM(ca.Sparsity.triplet(M.shape[0], M.shape[1], rows.tolist(), cols.tolist()), M[rows, cols])


class CholeskyFactor:
    """``M = L Lᵀ`` with ``L`` stored row-wise sparse."""

    def __init__(self, M: np.ndarray, names: list[str]):
        self.n = n = M.shape[0]
        D, LT, _ = ca.ldl(sparse_dm(M), False) if n else (ca.DM(0, 1), ca.DM(0, 0), [])
        d = np.array(D).reshape(-1)
        if not np.all(d > 0):
            diag = np.diag(M)
            bad = [names[i] for i in np.flatnonzero(diag <= 0)]
            raise ModelError("the mass matrix is not positive definite"
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

    def solve_numeric(self, b: np.ndarray) -> np.ndarray:
        L = self.dense()
        return np.linalg.solve(L.T, np.linalg.solve(L, b))

    def dense(self) -> np.ndarray:
        return np.array(ca.densify(self.lower())) if self.n else np.zeros((0, 0))
