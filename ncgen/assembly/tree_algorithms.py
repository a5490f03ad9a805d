"""Rigid-body algorithms of a tree in joint space, as CasADi SX functions for compiled kernels:
inverse dynamics (RNEA), the joint-space mass matrix (CRBA), forward dynamics from joint
efforts (ABA's input and output) and the derivatives of both.

Outputs are dense (a compiled kernel's buffers are the whole vectors and column-major
matrices), common subexpressions merged.  Everything comes from the one Newton–Euler recursion of :mod:`ncgen.assembly.tree_dynamics`
(arboris notation, mimic joints through :class:`~ncgen.assembly.tree_dynamics.MimicMap`).
Joint vectors are ``model.joint_names`` order: ``qj`` (nq), ``vj``, ``aj`` (nv) in and out,
a follower's entries set from its leader's; efforts ``τ`` and every derivative are per
*independent* rate (``nv_i`` of them: the rates that are not mimic followers), as Pinocchio's
models with mimic joints have them.  Passive forces (gravity, springs, dampers) act at the
inputs ``u = 0``; ``τ`` is what the joints add.

- :func:`rnea_function`: ``(t, qj, vj, aj, p) -> τ = Gᵀ S_gᵀ W_g`` (N·m or N);
- :func:`crba_function`: ``(t, qj, p) -> M_i = Gᵀ M_j G`` (symmetric, both triangles);
- :func:`aba_function`: ``(t, qj, vj, τ, p) -> (aj, check)``: ``a_i = M_i⁻¹ (τ − τ_rnea(a=0))``,
  ``aj = G a_i`` (``check`` as in :func:`~ncgen.assembly.tree_dynamics.recursive_dynamics_function`);
- :func:`rnea_derivatives_function`: ``(t, qj, vj, aj, p) -> (τ, ∂τ/∂q, ∂τ/∂v, ∂τ/∂a = M_i)``;
- :func:`efforts_function`: ``(t, q, u, p) -> (τ_i, ∂τ_i/∂u)``, the efforts of the inputs;
- :func:`aba_derivatives_function`: ``(t, qj, vj, τ, p) -> (aj, ∂a/∂q, ∂a/∂v, ∂a/∂τ = M_i⁻¹, check)``
  by ``∂a/∂x = −M_i⁻¹ ∂τ_rnea/∂x`` at ``a = a(q, v, τ)`` (the identity ``τ_rnea(q, v, a(q, v, τ)) = τ``
  differentiated), ``∂τ_rnea/∂x`` by CasADi's AD of the recursion — no finite differences.

Derivatives with respect to positions are in the tangent space, as Pinocchio's: the
perturbation of ``q_j`` along ``δ`` (nv_i) is ``q_j ⊕ Gδ``, to first order ``q_j + q̇_j(q_j, Gδ)``
(angles and lengths add; a spherical or free joint's quaternion turns by ``δω`` in its own
axes and a free joint's position moves by ``R δv``).  Derivatives are ``∂a_i`` (rows per
independent rate), so ``∂a/∂q`` is nv_i × nv_i.
"""
from __future__ import annotations

import casadi as ca

from ncgen.assembly.tree_dynamics import MimicMap, _Recursion, composite_mass_matrix, independent_solve, joint_efforts
from ncgen.errors import ModelError


def _function(name, inputs, outputs, input_names, output_names) -> ca.Function:
    """The SX function with dense outputs and common subexpressions merged (``casadi.cse``:
    the same operations, 10–20 % fewer of them in the derivatives)."""
    return ca.Function(name, inputs, ca.cse([ca.densify(x) for x in outputs]), input_names, output_names)


class TreeAlgorithms:
    """The symbols and SX expressions shared by the functions of this module for one model."""

    def __init__(self, model):
        self.model = model
        self.aj = ca.SX.sym("aj", model.joint_space.nv)
        rec = self.rec = _Recursion(model, self.aj)
        self.G = ca.DM(rec.mimic.G)
        self.nv_i = self.G.size2()
        zero_u = ca.DM.zeros(model.nu)
        tau_full = ca.mtimes(self.G.T, rec.projected_forces())
        self.tau = ca.substitute(tau_full, rec.u, zero_u) if model.nu else tau_full
        M = composite_mass_matrix(rec)
        self.M_i = ca.mtimes([self.G.T, ca.substitute(M, rec.u, zero_u) if model.nu else M, self.G])
        self.bias = ca.substitute(self.tau, self.aj, ca.DM.zeros(self.aj.numel()))

    def tangent(self, expr: ca.SX) -> tuple[ca.SX, ca.SX]:
        """``(∂expr/∂q, ∂expr/∂v)`` with ``q`` perturbed in the tangent space (module docstring)
        and ``v`` along the independent rates."""
        js, rec = self.model.joint_space, self.rec
        delta = ca.SX.sym("delta", self.nv_i)
        w = ca.mtimes(self.G, delta)
        sq, sv = js.slices(), js.slices(rates=True)
        rates = [js.position_rates(n, rec.qj[sq[n]], w[sv[n]]) for n in js.joint_names]
        moved = rec.qj + ca.vertcat(*rates) if rates else rec.qj
        d_q = ca.substitute(ca.jacobian(ca.substitute(expr, rec.qj, moved), delta), delta, ca.DM.zeros(self.nv_i))
        d_v = ca.mtimes(ca.jacobian(expr, rec.vj), self.G)
        return d_q, d_v


def rnea_function(model) -> ca.Function:
    """``(t, qj, vj, aj, p) -> tau``: inverse dynamics (module docstring)."""
    ta = TreeAlgorithms(model)
    rec = ta.rec
    return _function("rnea", [rec.t, rec.qj, rec.vj, ta.aj, rec.p], [ta.tau], ["t", "qj", "vj", "aj", "p"], ["tau"])


def crba_function(model) -> ca.Function:
    """``(t, qj, p) -> M``: the joint-space mass matrix ``M_i`` (module docstring)."""
    ta = TreeAlgorithms(model)
    rec = ta.rec
    return _function("crba", [rec.t, rec.qj, rec.p], [ta.M_i], ["t", "qj", "p"], ["M"])


def _forward(ta: TreeAlgorithms, tau: ca.SX) -> tuple[ca.SX, ca.SX]:
    """``(a_i, pivot)``: ``M_i a_i = τ − bias`` by the leaves-first Cholesky."""
    return independent_solve(ta.rec, ta.M_i, tau - ta.bias)


def aba_function(model) -> ca.Function:
    """``(t, qj, vj, tau, p) -> (aj, check)``: forward dynamics from the efforts of the
    independent joint rates (module docstring)."""
    ta = TreeAlgorithms(model)
    rec = ta.rec
    tau = ca.SX.sym("tau", ta.nv_i)
    a_i, pivot = _forward(ta, tau)
    aj = ca.mtimes(ta.G, a_i)
    return _function("aba", [rec.t, rec.qj, rec.vj, tau, rec.p], [aj, ca.vertcat(pivot, ca.sum1(aj))],
                     ["t", "qj", "vj", "tau", "p"], ["aj", "check"])


def rnea_derivatives_function(model) -> ca.Function:
    """``(t, qj, vj, aj, p) -> (tau, dtau_dq, dtau_dv, dtau_da)`` (module docstring)."""
    ta = TreeAlgorithms(model)
    rec = ta.rec
    d_q, d_v = ta.tangent(ta.tau)
    return _function("rnea_derivatives", [rec.t, rec.qj, rec.vj, ta.aj, rec.p], [ta.tau, d_q, d_v, ta.M_i],
                     ["t", "qj", "vj", "aj", "p"], ["tau", "dtau_dq", "dtau_dv", "dtau_da"])


def aba_derivatives_function(model) -> ca.Function:
    """``(t, qj, vj, tau, p) -> (aj, da_dq, da_dv, da_dtau, check)`` (module docstring):
    ``[∂a/∂q, ∂a/∂v, M_i⁻¹] = M_i⁻¹ [−∂τ/∂q, −∂τ/∂v, 1]`` in one multi-column solve."""
    ta = TreeAlgorithms(model)
    rec = ta.rec
    tau = ca.SX.sym("tau", ta.nv_i)
    a_i, _ = _forward(ta, tau)
    aj = ca.mtimes(ta.G, a_i)
    d_q, d_v = ta.tangent(ta.tau)
    n = ta.nv_i
    rhs = ca.horzcat(-d_q, -d_v, ca.SX.eye(n))
    sol, pivot = independent_solve(rec, ta.M_i, ca.substitute(rhs, ta.aj, aj))
    return _function("aba_derivatives", [rec.t, rec.qj, rec.vj, tau, rec.p],
                     [aj, sol[:, :n], sol[:, n:2 * n], sol[:, 2 * n:], ca.vertcat(pivot, ca.sum1(aj))],
                     ["t", "qj", "vj", "tau", "p"], ["aj", "da_dq", "da_dv", "da_dtau", "check"])


def efforts_function(model) -> ca.Function:
    """``(t, q, u, p) -> τ_i``: the efforts of the independent joint rates from the inputs
    (actuated joints' efforts, :func:`~ncgen.assembly.tree_dynamics.joint_efforts`, summed
    onto the leaders of mimic joints), and ``∂τ_i/∂u``."""
    js = model.joint_space
    t, q, u, p = ca.SX.sym("t"), ca.SX.sym("q", model.nq), ca.SX.sym("u", model.nu), ca.SX.sym("p", model.np)
    v = ca.SX.sym("v", model.nq)
    if ca.depends_on(js.passive_force(t, q, v, u, p), u):
        raise ModelError("the model's inputs act on it besides through joint efforts (forces with "
                         "inputs): the joint-space algorithms take passive forces at u = 0")
    tau = ca.mtimes(ca.DM(MimicMap(model).G).T, joint_efforts(js, js.actuation(t, q, u, p)[1]))
    return ca.Function("efforts", [t, q, u, p], [tau, ca.jacobian(tau, u)])
