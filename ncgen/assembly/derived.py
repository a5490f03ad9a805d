"""Whole-system CasADi functions built on demand from a model's function set
(``model.functions``), outside the model's C package.

* :func:`kkt_function` — forward dynamics ``(t, q, v, u, p) -> (a, λ)`` by the Schur
  complement of the constant mass matrix (compiled alone by
  :func:`ncgen.runtime.dynamics_at_state.forward_dynamics_kernel`);
* :func:`kkt_qr_function` — the same from the KKT system by sparse QR: the model's
  ``accel`` with the Baumgarte terms at zero (the path of a singular ``M``);
* :func:`joint_kkt_function` — joint space in and out for a tree;
* :func:`constraint_residuals_function` — ``Φ``, ``A v + Φ_t`` of a state, and
  :func:`residual_function` — their drift ``|Φ|∞``, ``|A v + Φ_t|∞``;
* :func:`slip_function` — the contacts' tangential velocities ``W_T v``;
* :func:`potential_force_residual_function` — ``F + ∇V``, zero for conservative forces
  (with :func:`depends_on_time`: the stepper's energy check).

No stabilisation terms: on the constraint manifold the accelerations are exact.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.assembly.functions import _accel
from ncgen.assembly.mass import mass_is_regular, sparse_dm
from ncgen.assembly.stepper_equations import power_function
from ncgen.model.data import model_data


def _symbols(model):
    t, q, v = ca.MX.sym("t"), ca.MX.sym("q", model.nq), ca.MX.sym("v", model.nq)
    return t, q, v, ca.MX.sym("u", model.nu), ca.MX.sym("p", model.np)


def kkt_function(model) -> ca.Function:
    """``fd: (t, q, v, u, p) -> (a, lam)`` by the Schur complement of the constant mass
    matrix: ``(A M⁻¹ Aᵀ) λ = A M⁻¹ F − γ`` (sparse LDLᵀ; M⁻¹ is block-diagonal per member),
    ``a = M⁻¹ (F − Aᵀ λ)``, then one step of iterative refinement on the KKT residual (forming
    ``S`` squares the conditioning of ``M``: a 15 g finger of the Panda leaves ``cond S ≈ 1e14``
    and 1e-8 relative errors in ``a_j``; the step brings them to ~1e-13); no stabilisation
    terms.  Needs a non-singular M and independent constraints (as the model's other paths
    do); a singular M (a flat body, :func:`~ncgen.assembly.mass.mass_is_regular` false) takes
    :func:`kkt_qr_function`."""
    if not mass_is_regular(model):
        return kkt_qr_function(model)
    f = model.functions
    t, q, v, u, p = _symbols(model)
    A = f["A"](t, q, p)
    Minv = model.Minv
    Minv[np.abs(Minv) < 1e-300] = 0.0
    Mi = ca.MX(sparse_dm(Minv))
    F = f["F"](t, q, v, u, p)
    gamma = f["gamma"](t, q, v, p)
    M = ca.MX(sparse_dm(model.M))
    S = ca.mtimes(ca.mtimes(A, Mi), A.T)
    a, lam = ca.MX.zeros(model.nq), ca.MX.zeros(model.nc)
    for _ in range(2):
        r_F = F - ca.mtimes(M, a) - ca.mtimes(A.T, lam)
        Mi_r = ca.mtimes(Mi, r_F)
        d_lam = ca.solve(S, ca.mtimes(A, Mi_r) - (gamma - ca.mtimes(A, a)), "ldl")
        a, lam = a + Mi_r - ca.mtimes(Mi, ca.mtimes(A.T, d_lam)), lam + d_lam
    return ca.Function("forward_dynamics", [t, q, v, u, p], [a, lam], ["t", "q", "v", "u", "p"], ["a", "lam"])


def kkt_qr_function(model) -> ca.Function:
    """``fd: (t, q, v, u, p) -> (a, lam)`` from the KKT system ``[[M, Aᵀ], [A, 0]] [a; λ] =
    [F; γ]`` by CasADi's sparse QR: the model's ``accel`` with ``α = β = 0``; needs no
    ``M⁻¹``, only ``M`` positive definite on ``null(A)`` (the path of a singular M)."""
    return _accel(model.functions, sparse_dm(model.M), model.nc, 0.0, 0.0, model.nq, model.nu, model.np,
                  name="forward_dynamics")


def joint_kkt_function(model) -> ca.Function:
    """``fd_j: (t, qj, vj, u, p) -> (aj, a, lam)``: joint space in and out for a tree
    (:meth:`~ncgen.assembly.joint_space.JointSpace.tree_function`, then :func:`kkt_function`,
    then ``a_j = J q̈ + J̇ q̇``)."""
    js = model.joint_space
    tree = js.tree_function(model.layout)
    t, qj, vj = ca.MX.sym("t"), ca.MX.sym("qj", js.nq), ca.MX.sym("vj", js.nv)
    u, p = ca.MX.sym("u", model.nu), ca.MX.sym("p", model.np)
    q, v = tree(qj, vj)
    a, lam = kkt_function(model)(t, q, v, u, p)
    aj = js.accelerations(q, v, a)
    return ca.Function("joint_forward_dynamics", [t, qj, vj, u, p], [aj, a, lam],
                       ["t", "qj", "vj", "u", "p"], ["aj", "a", "lam"])


def constraint_residuals_function(model) -> ca.Function:
    """``(t, q, v, p) -> (Φ, A v + Φ_t)``: both constraint levels' residuals of a state,
    composed of ``model.functions`` ``phi``, ``A`` and ``phi_t`` (SX when they are)."""
    f = model.functions
    sym = ca.SX if all(f[k].is_a("SXFunction") for k in ("phi", "A", "phi_t")) else ca.MX
    t, q, v, p = sym.sym("t"), sym.sym("q", model.nq), sym.sym("v", model.nq), sym.sym("p", model.np)
    return ca.Function("constraint_residuals", [t, q, v, p], [f["phi"](t, q, p), ca.mtimes(f["A"](t, q, p), v) +
                       f["phi_t"](t, q, p)], ["t", "q", "v", "p"], ["phi", "phi_dot"])


def state_check_function(model) -> ca.Function:
    """``(t, q, v, p) -> [|Φ|∞, |A v + Φ_t|∞, |q|∞, |v|∞, s]`` (one vector): what deciding that
    a state holds both constraint levels needs, in one call; ``s`` is the sum of every entry of
    ``q``, ``v`` and both residuals, finite only if they all are (CasADi's ``norm_inf`` skips NaN)."""
    t, q, v = ca.SX.sym("t"), ca.SX.sym("q", model.nq), ca.SX.sym("v", model.nq)
    p = ca.SX.sym("p", model.np)
    phi, phidot = constraint_residuals_function(model)(t, q, v, p)
    probe = ca.sum1(q) + ca.sum1(v) + ca.sum1(phi) + ca.sum1(phidot)
    return ca.Function("state_check", [t, q, v, p], [ca.vertcat(ca.norm_inf(phi), ca.norm_inf(phidot), ca.norm_inf(q),
                                                                ca.norm_inf(v), probe)], ["t", "q", "v", "p"], ["check"])


def residual_function(model) -> ca.Function:
    """``(t, q, v, p) -> (|Φ|∞, |A v + Φ_t|∞)``: position and velocity constraint drift."""
    t, q, v = ca.SX.sym("t"), ca.SX.sym("q", model.nq), ca.SX.sym("v", model.nq)
    p = ca.SX.sym("p", model.np)
    phi, phidot = constraint_residuals_function(model)(t, q, v, p)
    return ca.Function("residuals", [t, q, v, p], [ca.norm_inf(phi), ca.norm_inf(phidot)])


def slip_function(model) -> ca.Function:
    """``(q, v, p) -> W_T v``: the contacts' tangential velocities (m/s), ``(nk·(dim − 1))``
    stacked per contact (:mod:`ncgen.assembly.contact_kinematics`)."""
    qs, vs, ps = ca.SX.sym("q", model.nq), ca.SX.sym("v", model.nq), ca.SX.sym("p", model.np)
    return ca.Function("slip", [qs, vs, ps], [ca.mtimes(model.functions["contact_jacobian"](qs, ps)[1], vs)])


def depends_on_time(model) -> bool:
    """Whether ``Φ_t`` depends on ``t`` or ``q``, or the potential energy ``V`` on ``t``
    (structurally: from the expressions, not from values)."""
    f = model.functions
    t, q, p = ca.SX.sym("t"), ca.SX.sym("q", model.nq), ca.SX.sym("p", model.np)
    V = ca.sum1(model.potential_terms(t, q, p))
    return bool(ca.depends_on(ca.densify(f["phi_t"](t, q, p)), ca.vertcat(t, q)) or ca.depends_on(V, t))


def potential_force_residual_function(model) -> ca.Function:
    """``F_nc: (t, q, v, u, p) -> (F + ∇_q V, F)``: the applied force minus the negative
    gradient of the potential energy (N; zero for conservative forces), and ``F``."""
    f = model.functions
    t, q, v = ca.SX.sym("t"), ca.SX.sym("q", model.nq), ca.SX.sym("v", model.nq)
    u, p = ca.SX.sym("u", model.nu), ca.SX.sym("p", model.np)
    V = ca.sum1(model.potential_terms(t, q, p))
    F = f["F"](t, q, v, u, p)
    return ca.Function("F_nc", [t, q, v, u, p], [F + ca.gradient(V, q), F])


def power_parts_function(model) -> ca.Function:
    """``(t, q, v, lam, u, p) -> [P, P_contacts, P_friction, P_inputs, P_drives]`` (W): the
    power of all forces and its parts for the energy balance
    (:mod:`ncgen.runtime.energy_balance`; the stepper's ``step_power``,
    :func:`~ncgen.assembly.stepper_equations.power_function`), kept in the model's data."""
    data = model_data(model)
    if "power_parts" not in data.functions:
        data.functions["power_parts"] = power_function(model)
    return data.functions["power_parts"]
