"""The Gauss–Newton Hessian of a single-shooting tracking cost, kept in its stages.

With the linearised dynamics ``δx_{k+1} = A_k δx_k + B_k δu_k`` (``δx_0 = 0``, k = 0..N−1)
and the cost ``½ Σ_k ‖δx_{k+1}‖²_{W_k} + ½ Σ_k ‖δu_k‖²_R`` (``W_k``, ``R`` diagonal), the
condensed Hessian in ``δU = (δu_0, …, δu_{N−1})`` is ``H = Sᵀ W S + R`` (``S``: the
sensitivities ``∂δX/∂δU``).  :class:`StagewiseHessian` never forms ``S`` nor ``H``: products
``H δU`` are a forward rollout and a backward adjoint sweep, and Newton steps on a subset of
the inputs (the others held at zero) are a Riccati recursion — only ``n_x × n_x`` and
``n_x × n_u`` products, ``O(N)`` work, and no BLAS call large enough to start its threads.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dposv


class StagewiseHessian:
    """``H = Sᵀ W S + R`` (module docstring) of ``A`` ``(N, n_x, n_x)``, ``B`` ``(N, n_x, n_u)``,
    the state weights ``w`` ``(N, n_x)`` (row k weighs ``δx_{k+1}``) and the input weights
    ``r`` ``(n_u,)``.  Vectors in ``δU`` are flat, ``N n_u`` long, stage by stage."""

    def __init__(self, A: np.ndarray, B: np.ndarray, w: np.ndarray, r: np.ndarray):
        self.A, self.B, self.w, self.r = A, B, w, r
        self.N, self.nx, self.nu = B.shape
        self.r_all = np.tile(r, self.N)
        self.BA_T = list(np.concatenate([B, A], axis=2).transpose(0, 2, 1).copy())   # [B_kᵀ; A_kᵀ]
        self.A_list = list(A)

    def rollout(self, dU: np.ndarray) -> np.ndarray:
        """``S δU`` as ``(N, n_x)``: row k is ``δx_{k+1}``."""
        X = np.matmul(self.B, dU.reshape(self.N, self.nu, 1))[:, :, 0]
        for k in range(1, self.N):
            X[k] += self.A_list[k] @ X[k - 1]
        return X

    def adjoint(self, Y: np.ndarray) -> np.ndarray:
        """``Sᵀ (w ⊙ Y)`` (flat) of ``Y`` ``(N, n_x)``: the gradient of ``½ Σ_k ‖y_k‖²_{W_k}``
        through the dynamics, by the backward sweep ``μ_k = A_kᵀ μ_{k+1} + W_{k−1} y_{k−1}``."""
        nu = self.nu
        wY = self.w * Y
        out = np.empty((self.N, nu))
        mu = wY[-1]
        for k in range(self.N - 1, 0, -1):
            z = self.BA_T[k] @ mu
            out[k] = z[:nu]
            mu = z[nu:] + wY[k - 1]
        out[0] = self.BA_T[0][:nu] @ mu
        return out.reshape(-1)

    def __matmul__(self, dU: np.ndarray) -> np.ndarray:
        return self.adjoint(self.rollout(dU)) + self.r_all * dU

    def newton(self, free: np.ndarray, grad: np.ndarray) -> np.ndarray | None:
        """``d`` with ``H_ff d_f = −grad_f`` on the ``free`` components and ``d = 0`` on the
        others (the minimiser of ``½ dᵀ H d + gradᵀ d`` with those held), by a Riccati
        recursion on each stage's free inputs ``f``: with ``P``, ``p`` the cost-to-go's Hessian
        and gradient in ``δx_{k+1}``, ``Q_uu = B_fᵀ P B_f + R_f``, ``Q_ux = B_fᵀ P A_k``,
        ``q_u = B_fᵀ p + grad_{k,f}``, the gains ``[K_k, κ_k] = −Q_uu⁻¹ [Q_ux, q_u]``, then
        ``P ← A_kᵀ P A_k + Q_uxᵀ K_k + W_{k−1}``, ``p ← A_kᵀ p + Q_uxᵀ κ_k``; None when a ``Q_uu``
        is not positive definite (``H_ff`` then is not)."""
        N, nx = self.N, self.nx
        free, grad = free.reshape(N, self.nu), grad.reshape(N, self.nu)
        gains = [None] * N
        P, p = np.diag(self.w[-1]), np.zeros(nx)
        for k in range(N - 1, -1, -1):
            f = free[k]
            all_free = f.all()
            A, Bf = self.A_list[k], (self.B[k] if all_free else self.B[k][:, f])
            PB = P @ Bf
            Quu = Bf.T @ PB
            Quu.flat[::Quu.shape[0] + 1] += self.r if all_free else self.r[f]
            Qux_qu = np.column_stack([PB.T @ A, Bf.T @ p + (grad[k] if all_free else grad[k, f])])
            if Quu.size:
                _, Kk, info = dposv(Quu, Qux_qu)
                if info != 0:
                    return None
                Kk = gains[k] = -Kk
            else:
                Kk = gains[k] = Qux_qu
            if k > 0:
                M = Qux_qu[:, :nx].T @ Kk
                AP = A.T @ np.column_stack([P @ A, p])
                P = AP[:, :nx] + M[:, :nx]
                P = 0.5 * (P + P.T)
                P.flat[::nx + 1] += self.w[k - 1]
                p = AP[:, nx] + M[:, nx]
        d = np.zeros((N, self.nu))
        dx = np.zeros(nx)
        for k in range(N):
            d[k, free[k]] = gains[k][:, :nx] @ dx + gains[k][:, nx]
            dx = self.A_list[k] @ dx + self.B[k] @ d[k]
        return d.reshape(-1)

    def dense(self) -> np.ndarray:
        """The matrix ``H = Sᵀ W S + R``, with ``S`` formed block by block (``S_{jk} =
        A_j ⋯ A_{k+1} B_k``): for dense QP solvers."""
        N, nx, nu = self.N, self.nx, self.nu
        S = np.zeros((N * nx, N * nu))
        P = np.zeros((nx, N * nu))
        for k in range(N):
            P[:, :k * nu] = self.A[k] @ P[:, :k * nu]
            P[:, k * nu:(k + 1) * nu] = self.B[k]
            S[k * nx:(k + 1) * nx] = P
        H = S.T @ (self.w.reshape(-1)[:, None] * S)
        H[np.diag_indices_from(H)] += np.tile(self.r, N)
        return H
