"""The nonsmooth contact stepper's step with a fixed active set, as one smooth residual
(CasADi; used by :mod:`ncgen.control.contact_step`).

The compiled stepper's contact step (``contact_step`` in templates/c/runtime/ncgen_contact.h,
docs/contact.md), from ``x = [q; v]`` with step ``h`` (s) and inputs ``u`` held over it:

1. a free RATTLE step ``z_f = [w_f; ν_f; v_f; μ'_f]`` (no impulse), ending at
   ``q_f = q + h w_f``;
2. impulses ``P`` (N·s; per contact its normal row, then its tangent rows) such that the
   end-of-step contact velocities ``U`` satisfy Newton's impact law and Coulomb's law, with
   ``U = W_f (v_f + y_v)``, ``K_f y = [W_fᵀ P; 0]`` (the response linearised at the free step's
   end: ``K_f = [M A_fᵀ; A_f 0]``, ``W_f = W(q_f)``) — or, after an impact (the impulses
   change a contact velocity by more than :data:`IMPACT_STEPS` steps of gravity), the
   velocities the step really ends with, ``U = W(q⁺) v⁺`` (the stepper refines to that);
3. the RATTLE step ``z = [w; ν; v⁺; μ']`` again with the generalised impulse ``W(q)ᵀ P`` in its
   first half and ``W_fᵀ P`` in its second; ``x⁺ = [q + h w; v⁺]``.

With the mode of every contact fixed, the contact laws are smooth equalities (``U_N``:
normal velocity, ``V_T = U_T + e U⁻_T`` the slip, ``U⁻ = W(q) v`` at the start):

* separated: ``P = 0``;
* closed (``P_N > 0``): ``U_N + b = 0``, with ``b = e min(U⁻_N, 0)`` when the contact is
  closed at the free step's end (``g(q_f) ≤ 0``), else (a contact about to close, ``e = 0``)
  ``b = max(0, 2 g(q_f)/h − U_f,N)``;
* sticking (closed, ``|P_T| < μ P_N``): ``V_T = 0``;
* sliding (closed, ``|P_T| = μ P_N``): ``P_T + μ P_N V_T/|V_T| = 0`` — the solver's own cone
  (circular in 3-D, a segment in 2-D), not a polyhedron.

4. the push-out (``push_out`` in ncgen_contact.h), where a contact ends the step inside
   (gap below ``−PENETRATION_TOL``): the displacement ``Δ = y₂_q``, ``K(q⁺) y₂ = [W_N(q⁺)ᵀ π; 0]``,
   with ``π ≥ 0`` the smallest push making the linearised gaps ``g(q⁺) + W_N Δ`` of the pushed
   contacts 0; then back onto ``Φ = 0`` (``M (q_p − q⁺ − Δ) + A(q_p)ᵀ α = 0``, ``Φ(q_p) = 0``:
   the stepper's Newton iterations' limit to second order in their corrections, exact without
   constraints) and the velocities projected, ``[M A_pᵀ; A_p 0] [v_p; μ] = [M v⁺; −Φ_t]``;
   ``x⁺ = [q_p; v_p]``.

The residual takes the modes as numbers ``0``/``1`` (``sel``: per contact closed, closed at
the free step's end, sticking, sliding, pushed out; then impact, any push-out), so one
function serves every active set.  Unknowns ``Z = [z_f; y; P; z; π; y₂; q_p; α; v_p; μ]``.
"""
from __future__ import annotations

import casadi as ca

from ncgen.assembly.mass import sparse_dm
from ncgen.assembly.stepper_equations import contact_function, stepper_functions

#: An impulse changing a contact velocity by more than this many steps of gravity is an
#: impact (the compiled stepper's ``CONTACT_IMPACT_STEPS``).
IMPACT_STEPS = 10
#: Selector columns per contact: closed, closed at the free step's end, sticking, sliding,
#: pushed out (then two for the step: impact, push-out).
NSEL = 5
NGLOBAL = 2


def layout(model) -> dict[str, slice]:
    """Where the blocks of ``Z`` sit."""
    n1 = model.nq + model.nc
    nd = model.nk * model.dim
    nq, nk = model.nq, model.nk
    o = 5 * n1 + nd
    return {"zf": slice(0, 2 * n1), "y": slice(2 * n1, 3 * n1), "P": slice(3 * n1, 3 * n1 + nd),
            "z": slice(3 * n1 + nd, o), "pi": slice(o, o + nk), "y2": slice(o + nk, o + nk + n1),
            "qa": slice(o + nk + n1, o + nk + 2 * n1), "vm": slice(o + nk + 2 * n1, o + nk + 3 * n1),
            "x1": (slice(o + nk + n1, o + nk + n1 + nq), slice(o + nk + 2 * n1, o + nk + 2 * n1 + nq))}


def rattle_residual(newton, velocity, nq, nc, h, t, q, v, u, p, zz, j0, j):
    """The RATTLE residual ``G(z)`` of :mod:`ncgen.control.discrete` with the impulse ``j0``
    in the first half-step and ``j`` in the second; also ``K₂`` at its end."""
    w, nu_h, vmu = zz[:nq], zz[nq:nq + nc], zz[nq + nc:]
    r = newton(t, q, v, u, p, h, w, nu_h, j0)[0]
    b, K2 = velocity(t + h, q + h * w, w, u, p, h, j)
    return ca.vertcat(r, ca.mtimes(K2, vmu) - b), K2


def contact_residual(model, h: float) -> ca.Function:
    """``R: (Z, x, u, p, t, sel) -> (R, info)``: the residual of the module docstring and
    ``info = [x⁺; U; U⁻; U_f; g(q_f); g(q⁺ before the push-out); π; the gaps the push-out
    leaves, linearised]`` (``U_f = W_f v_f`` the free step's contact velocities) for
    classifying the modes."""
    newton, velocity = stepper_functions(model)[:2]
    rows = contact_function(model)
    nq, nc, nk, dim = model.nq, model.nc, model.nk, model.dim
    n1 = nq + nc
    L = layout(model)
    Z = ca.SX.sym("Z", L["vm"].stop)
    x, u, p, t = ca.SX.sym("x", 2 * nq), ca.SX.sym("u", model.nu), ca.SX.sym("p", model.np), ca.SX.sym("t")
    sel = ca.SX.sym("sel", NSEL * nk + NGLOBAL)
    q, v = x[:nq], x[nq:]
    zf, y, P, z = Z[L["zf"]], Z[L["y"]], Z[L["P"]], Z[L["z"]]
    zero = ca.SX.zeros(nq)
    G_free, K_f = rattle_residual(newton, velocity, nq, nc, h, t, q, v, u, p, zf, zero, zero)
    q_f, v_f = q + h * zf[:nq], zf[n1:n1 + nq]
    g_f, Wt_f, U_f = rows(q_f, v_f, p)
    _, Wt_0, U_0 = rows(q, v, p)
    j_f, j_0 = ca.mtimes(Wt_f, P), ca.mtimes(Wt_0, P)
    response = ca.mtimes(K_f, y) - ca.vertcat(j_f, ca.SX.zeros(nc))
    G_end, _ = rattle_residual(newton, velocity, nq, nc, h, t, q, v, u, p, z, j_0, j_f)
    q1, v1 = q + h * z[:nq], z[n1:n1 + nq]
    g_1, Wt_1, U_1 = rows(q1, v1, p)
    impact = sel[NSEL * nk]
    U = impact * U_1 + (1 - impact) * (U_f + ca.mtimes(Wt_f.T, y[:nq]))
    laws = []
    for k, spec in enumerate(model.contacts):
        closed, closed_free, stick, slide = (sel[NSEL * k + i] for i in range(4))
        e, mu, n = spec["restitution"], spec["mu"], k * dim
        bias = closed_free * e * ca.fmin(U_0[n], 0) + (1 - closed_free) * ca.fmax(0, 2 * g_f[k] / h - U_f[n])
        laws.append(closed * (U[n] + bias) + (1 - closed) * P[n])
        PT = P[n + 1:n + dim]
        if mu > 0:
            VT = U[n + 1:n + dim] + e * U_0[n + 1:n + dim]
            speed = ca.sqrt(ca.sumsqr(VT) + (1 - slide))
            laws.append(stick * VT + slide * (PT + mu * P[n] * VT / speed) + (1 - stick - slide) * PT)
        else:
            laws.append(PT)
    R = ca.vertcat(G_free, response, *laws, G_end,
                   _push_out(model, h, t, p, q1, v1, g_1, Wt_1, Z, L, sel, velocity))
    x1 = ca.vertcat(Z[L["x1"][0]], Z[L["x1"][1]])
    gaps = g_1 + ca.mtimes(Wt_1[:, [k * dim for k in range(nk)]].T, Z[L["y2"]][:nq])
    info = ca.vertcat(x1, U, U_0, U_f, g_f, g_1, Z[L["pi"]], gaps)
    return ca.Function("contact_step_residual", [Z, x, u, p, t, sel], [ca.densify(R), ca.densify(info)],
                       ["Z", "x", "u", "p", "t", "sel"], ["R", "info"])


def contact_system(R: ca.Function) -> ca.Function:
    """``(Z, x, u, p, t, sel) -> (R, info, R_Z, R_y)`` (``R_Z``, ``R_y`` sparse), ``y = [x; u; p]``:
    what each Newton iteration and the implicit function theorem need, in one evaluation."""
    Z, x, u, p, t, sel = (R.sx_in(i) for i in range(6))
    r, info = R(Z, x, u, p, t, sel)
    return ca.Function("contact_step_system", [Z, x, u, p, t, sel],
                       [r, info, ca.jacobian(r, Z), ca.jacobian(r, ca.vertcat(x, u, p))],
                       ["Z", "x", "u", "p", "t", "sel"], ["R", "info", "R_Z", "R_y"])


def _push_out(model, h, t, p, q1, v1, g_1, Wt_1, Z, L, sel, velocity):
    """The push-out's rows (step 4 of the module docstring); with no contact pushed
    (``sel`` push 0) ``π = 0``, ``x⁺`` the step's end."""
    nq, nc, nk, dim = model.nq, model.nc, model.nk, model.dim
    f = model.functions
    push = sel[NSEL * nk + 1]
    pi, y2, qa, vm = Z[L["pi"]], Z[L["y2"]], Z[L["qa"]], Z[L["vm"]]
    q_p, alpha = qa[:nq], qa[nq:]
    WN = Wt_1[:, [k * dim for k in range(nk)]]
    _, K1 = velocity(t + h, q1, v1, ca.SX.zeros(model.nu), p, 0, ca.SX.zeros(nq))
    rows = [ca.mtimes(K1, y2) - ca.vertcat(ca.mtimes(WN, pi), ca.SX.zeros(nc))]
    gaps = g_1 + ca.mtimes(WN.T, y2[:nq])
    rows += [sel[NSEL * k + 4] * gaps[k] + (1 - sel[NSEL * k + 4]) * pi[k] for k in range(nk)]
    M = sparse_dm(model.M)
    back = ca.mtimes(M, q_p - q1 - y2[:nq]) + ca.mtimes(f["A"](t + h, q_p, p).T, alpha)
    rows += [push * back + (1 - push) * (q_p - q1), push * f["phi"](t + h, q_p, p) + (1 - push) * alpha]
    b, K2 = velocity(t + h, q_p, v1, ca.SX.zeros(model.nu), p, 0, ca.SX.zeros(nq))
    rows += [push * (ca.mtimes(K2, vm) - b) + (1 - push) * (vm - ca.vertcat(v1, ca.SX.zeros(nc)))]
    return ca.vertcat(*rows)
