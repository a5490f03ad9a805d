"""The CasADi function of the minimal-state linearisation, built from a model's system
functions (so that it can also be generated as a C kernel for LQR/MPC code).

Independent coordinates about a consistent state ``(q*, v*)`` (``Φ = 0``, ``A v* + Φ_t = 0``):
``z = G (q − q*)`` and ``w = ż = G v``, where ``G`` (dof × nq) and the tangent basis ``N``
(nq × dof) satisfy ``A N = 0`` and ``G N = I`` (:mod:`ncgen.assembly.manifold`).  Near ``q*``
the configuration with coordinates ``z`` is ``q(z) = q* + N z + O(z²)``, and the rates with
``G v = w`` on the velocity constraint are ``v(z, w) = v* + V_z z + N w + O(2)`` with

    A V_z = −∂(A v* + Φ_t)/∂q · N,   G V_z = 0,

the term that makes the linearisation valid away from equilibria (``V_z = 0`` when
``v* = 0`` and no drive moves).  With the accelerations ``a(q, v, u)`` of the KKT system
``[[M, Aᵀ], [A, 0]] [a; λ] = [F; γ]`` (no Baumgarte terms: they vanish on the manifold to
first order), the minimal state ``x = [z; w]`` obeys ``ż = w``, ``ẇ = G a(q(z), v(z, w), u)``,
hence

    A_lin = [[0, I], [G (a_q N + a_v V_z), G a_v N]],   B_lin = [[0], [G a_u]],
    C_lin = [[N, 0], [V_z, N]]  (y = [δq; δv]),   D_lin = 0,

and ``xdot = [w*; G a*]`` (zero at an equilibrium).  Time dependence (drives,
time-varying loads) enters only through the point ``t`` of evaluation.

``linearize: t, q, v, u, p, N, G -> A_lin, B_lin, C_lin, xdot``.
"""
from __future__ import annotations

import casadi as ca

#: Documentation of the ``linearize`` function for the generated C header.
DOC = {
    "purpose": ("minimal-state linearisation dx/dt = A_lin x + B_lin du, y = C_lin x about a consistent "
                "state (q, v, u), in the independent coordinates z = G (q - q*), w = G v "
                "(A N = 0, G N = I; see docs/statics-and-modes.md)"),
    "inputs": {"t": ("time", "s"), "q": ("natural coordinates q* (on the constraints)", "m"),
               "v": ("coordinate rates v* (on the velocity constraints)", "m/s"),
               "u": ("inputs, in the order of input_names", "SI units of each input"),
               "p": ("parameters, in the order of parameter_names", "SI units of each parameter"),
               "N": ("tangent basis, nq x dof, A N = 0", "1"),
               "G": ("independent-coordinate functional, dof x nq, G N = I", "1")},
    "outputs": {"A_lin": ("state matrix, 2dof x 2dof, x = [z; w]", "1/s, 1/s^2"),
                "B_lin": ("input matrix, 2dof x nu", "state units per s per input unit"),
                "C_lin": ("output matrix to [dq; dv], 2nq x 2dof", "1"),
                "xdot": ("state derivative at the point, [w*; G a*]", "m/s, m/s^2")},
}


def linearization_function(f: dict, M, dof: int) -> ca.Function:
    """``linearize`` (see the module docstring) from the system functions ``f`` and the
    constant mass matrix ``M`` (sparse DM), for ``dof`` degrees of freedom."""
    nq, nc = f["A"].size2_out(0), f["A"].size1_out(0)
    nu, npar = f["F"].numel_in(3), f["F"].numel_in(4)
    t, q, v = ca.MX.sym("t"), ca.MX.sym("q", nq), ca.MX.sym("v", nq)
    u, p = ca.MX.sym("u", nu), ca.MX.sym("p", npar)
    N, G = ca.MX.sym("N", nq, dof), ca.MX.sym("G", dof, nq)
    z, w = ca.MX.sym("z", dof), ca.MX.sym("w", dof)

    rate = ca.mtimes(f["A"](t, q, p), v) + f["phi_t"](t, q, p)      # A v + Φ_t
    A = f["A"](t, q, p)
    Vz = -ca.solve(ca.vertcat(A, G), ca.vertcat(ca.mtimes(ca.jacobian(rate, q), N), ca.MX(dof, dof)), "qr")

    qz = q + ca.mtimes(N, z)
    vz = v + ca.mtimes(Vz, z) + ca.mtimes(N, w)
    Az = f["A"](t, qz, p)
    K = ca.blockcat([[ca.MX(M), Az.T], [Az, ca.MX(nc, nc)]])
    sol = ca.solve(K, ca.vertcat(f["F"](t, qz, vz, u, p), f["gamma"](t, qz, vz, p)), "qr")
    wdot = ca.mtimes(G, sol[:nq])
    x = ca.vertcat(z, w)
    inner = ca.Function("linearize_inner", [t, q, v, u, p, N, G, z, w],
                        [ca.jacobian(wdot, x), ca.jacobian(wdot, u), wdot])
    Jx, Ju, acc = inner(t, q, v, u, p, N, G, ca.MX(dof, 1), ca.MX(dof, 1))
    I, O = ca.MX.eye(dof), ca.MX(dof, dof)
    A_lin = ca.vertcat(ca.horzcat(O, I), Jx)
    B_lin = ca.vertcat(ca.MX(dof, nu), Ju)
    C_lin = ca.blockcat([[N, ca.MX(nq, dof)], [Vz, N]])
    xdot = ca.vertcat(ca.mtimes(G, v), acc)
    return ca.Function("linearize", [t, q, v, u, p, N, G], [A_lin, B_lin, C_lin, xdot],
                       ["t", "q", "v", "u", "p", "N", "G"], ["A_lin", "B_lin", "C_lin", "xdot"])
