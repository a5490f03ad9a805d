"""Derivatives of a converged step by the implicit function theorem, solved numerically.

At the unknowns ``z`` of a converged step, ``G(z; y) = 0`` with ``y = [x; u; p]``
(:mod:`ncgen.control.discrete`), so ``∂z/∂y = −G_z⁻¹ G_y`` and, with
``x⁺ = [q + h w; v⁺] = [I_q 0] y + E z``::

    ∂x⁺/∂y = [I_q 0] + E ∂z/∂y                                   (forward: one LU, ny solves)
    ȳ = (∂x⁺/∂y)ᵀ x̄⁺ = [x̄⁺_q; 0] − G_yᵀ G_z⁻ᵀ Eᵀ x̄⁺               (adjoint: one transposed solve)

``G_z`` and ``G_y`` come sparse from the compiled ``step_sensitivities``; ``G_z`` is
factorised by LAPACK's dense LU up to :data:`DENSE_MAX` rows, by SuperLU beyond.  Nothing is
differentiated through the Newton iterations and no factorisation is unrolled into C.
"""
from __future__ import annotations

import warnings

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ncgen.errors import NcgenError

#: Largest ``G_z`` (rows) factorised densely; SuperLU beyond (measured crossover on the
#: z1 / Panda sizes, 166–184 rows: both take 0.2–0.4 ms there).
DENSE_MAX = 200


class StepSensitivities:
    """IFT Jacobians and adjoints of one step from its compiled ``step_sensitivities``
    (a :class:`~ncgen.codegen.direct.DirectFunction` ``(z, x, u, p, t) -> (G_z, G_y)``);
    ``nq``, ``nc``: the model's sizes, ``h``: the step (s)."""

    def __init__(self, kernel, nq: int, nc: int, h: float):
        self._kernel, self.nq, self.nc, self.h = kernel, nq, nc, h
        f = kernel.function
        self._patterns = [(f.sparsity_out(i).get_ccs(), f.size_out(i)) for i in range(2)]
        self.nz, self.ny = f.size1_out(0), f.size2_out(1)

    def _matrices(self, z, x, u, p, t):
        """``(solve, G_y)``: ``solve(b, transposed)`` with the factorised ``G_z`` at the step."""
        Gz, Gy = ((sp.csc_matrix((data.copy(), row, colind), shape=shape))
                  for data, ((colind, row), shape) in zip(self._kernel(z, x, u, p, t), self._patterns))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sla.LinAlgWarning)
            if self.nz <= DENSE_MAX:
                lu = sla.lu_factor(Gz.toarray(), check_finite=False)

                def solve(b, transposed):
                    return sla.lu_solve(lu, b, trans=int(transposed), check_finite=False)
            else:
                try:
                    lu = spla.splu(Gz)
                except RuntimeError as exc:      # SuperLU: "Factor is exactly singular"
                    raise NcgenError(f"step derivatives: the Newton matrix G_z is singular ({exc}); "
                                     "redundant constraints or a singular configuration") from None

                def solve(b, transposed):
                    return lu.solve(b, trans="T" if transposed else "N")
        return solve, Gy

    def _finite(self, a: np.ndarray) -> np.ndarray:
        if not np.all(np.isfinite(a)):
            raise NcgenError("step derivatives: the solve with the Newton matrix G_z gave NaN or inf (G_z "
                             "singular: redundant constraints or a singular configuration)")
        return a

    def jacobian(self, z, x, u, p, t) -> np.ndarray:
        """``∂x⁺/∂[x; u; p]`` (nx × ny, dense)."""
        nq, nc = self.nq, self.nc
        solve, Gy = self._matrices(z, x, u, p, t)
        Zy = -self._finite(solve(Gy.toarray(), False))
        J = np.vstack([self.h * Zy[:nq], Zy[nq + nc:2 * nq + nc]])
        J[np.arange(nq), np.arange(nq)] += 1.0
        return J

    def adjoint(self, z, x, u, p, t, x1_bar) -> np.ndarray:
        """``ȳ = (∂x⁺/∂[x; u; p])ᵀ x̄⁺`` (ny values)."""
        nq, nc = self.nq, self.nc
        solve, Gy = self._matrices(z, x, u, p, t)
        z_bar = np.zeros(self.nz)
        z_bar[:nq] = self.h * x1_bar[:nq]
        z_bar[nq + nc:2 * nq + nc] = x1_bar[nq:]
        y_bar = -(Gy.T @ self._finite(solve(z_bar, True)))
        y_bar[:nq] += x1_bar[:nq]
        return y_bar
