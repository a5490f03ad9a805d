"""Which constraints depend linearly on the others, by name order."""
from __future__ import annotations

from contextlib import nullcontext

import casadi as ca
import numpy as np

from ncgen.assembly.mass import dense_dm, sparse_dm
from ncgen.blas_threads import blas_limit

#: Relative size of a row's component outside the span of the earlier rows below which it
#: counts as linearly dependent.
DEPENDENT_TOL = 1e-9
#: Constraints from which the Cholesky factor of their Gram matrix runs on one BLAS thread
#: (:func:`ncgen.blas_threads.blas_limit`): OpenBLAS's threads on an O(nc³) factor cost more CPU
#: than they save (a 1000-bar chain: 0.4 s of CPU against 0.03 s); smaller ones do not pay the
#: limit's set-up (≈ 10 ms in a process).
ONE_THREAD_FROM = 200


def dependent_rows(A: np.ndarray, tol: float = DEPENDENT_TOL) -> list[int]:
    """Rows of ``A`` that depend linearly on earlier rows (greedy, in order, so intrinsic
    constraints are kept and the later joint equations are the ones named)."""
    if A.shape[0] == 0:
        return []
    norms = np.linalg.norm(A, axis=1)
    zero = [i for i in range(A.shape[0]) if norms[i] == 0]
    An = A / np.where(norms > 0, norms, 1)[:, None]
    S = sparse_dm(An)                     # the Gram matrix from the nonzeros: O(nnz), not O(nc² nq)
    G = dense_dm(ca.mtimes(S, S.T))
    try:
        with blas_limit() if len(G) >= ONE_THREAD_FROM else nullcontext():
            L = np.linalg.cholesky(G)
        if np.min(np.diag(L)) > np.sqrt(tol) and not zero:
            return []
    except np.linalg.LinAlgError:
        pass
    basis: list[np.ndarray] = []
    dependent = []
    for i in range(A.shape[0]):
        r = An[i].copy()
        for b in basis:
            r -= (b @ r) * b
        for b in basis:
            r -= (b @ r) * b
        n = np.linalg.norm(r)
        if norms[i] == 0 or n < tol ** 0.5:
            dependent.append(i)
        else:
            basis.append(r / n)
    return dependent
