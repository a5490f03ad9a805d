"""Second derivatives of one RATTLE step (:mod:`ncgen.control.discrete`) contracted with a
costate: what DDP adds to iLQR's backward pass.

With ``y = [x; u]``, the step's unknowns ``z(y)`` defined by ``G(z; y) = 0`` and
``x⁺ = [q + h w; v⁺]`` (linear in ``x`` and ``z``: ``x⁺ = P x + E z``), the curvature of
``λᵀ x⁺`` is, by the implicit function theorem (second order),

    ∂²(λᵀ x⁺)/∂y² = Wᵀ ∇²_(z,y) (νᵀ G) W,   W = [∂z/∂y; I],   ∂z/∂y = −G_z⁻¹ G_y,
    G_zᵀ ν = −Eᵀ λ,

at the converged ``z``: the Hessian of the Lagrangian ``λᵀ E z + νᵀ G`` whose multiplier
``ν`` makes it stationary in ``z``.  ``G``'s derivatives are SX (exact, by AD); the two
solves are dense NumPy (``z`` has ``2 (nq + nc)`` components).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.control.discrete import step_residual


class StepCurvature:
    """``(H_xx, H_uu, H_ux) = curvature(z, x, u, p, t, lam)``: the blocks of
    ``∂²(λᵀ x⁺)/∂[x; u]²`` at the converged step unknowns ``z`` (see the module docstring)."""

    def __init__(self, model, h: float):
        G = step_residual(model, h)
        z, x, u, p, t = (G.sx_in(i) for i in range(5))
        nu_ = ca.SX.sym("nu", z.numel())
        Gs = G(z, x, u, p, t)
        y = ca.vertcat(x, u)
        self._sens = ca.Function("step_sensitivities", [z, x, u, p, t],
                                 [ca.densify(ca.jacobian(Gs, z)), ca.densify(ca.jacobian(Gs, y))])
        self._hess = ca.Function("step_lagrangian_hessian", [z, x, u, p, t, nu_],
                                 [ca.densify(ca.hessian(ca.dot(nu_, Gs), ca.vertcat(z, y))[0])])
        self.nq, self.nc, self.h = model.nq, model.nc, h
        self.nx, self.nu = 2 * model.nq, model.nu

    def __call__(self, z, x, u, p, t, lam):
        nq, nc, nx = self.nq, self.nc, self.nx
        G_z, G_y = (np.array(a) for a in self._sens(z, x, u, p, t))
        z_bar = np.concatenate([self.h * lam[:nq], np.zeros(nc), lam[nq:], np.zeros(nc)])     # Eᵀ λ
        nu_ = -np.linalg.solve(G_z.T, z_bar)
        W = np.vstack([-np.linalg.solve(G_z, G_y), np.eye(G_y.shape[1])])
        H = W.T @ np.array(self._hess(z, x, u, p, t, nu_)) @ W
        H = 0.5 * (H + H.T)
        return H[:nx, :nx], H[nx:, nx:], H[nx:, :nx]
