"""Radau IIA collocation in joint space, for trees (``form="joint"``; the default for models
that allow it, :func:`joint_space_reason`).

States are the joint coordinates ``q_j`` and rates ``v_j = q̇_j`` of every joint
(:mod:`ncgen.assembly.joint_space`); the natural coordinates are functions of them,
``q = q(q_j)`` by forward kinematics through the joints (exact for a tree, so ``Φ(q) = 0``
holds identically and no multiplier, invariant or projection enters the NLP), and
``q̇ = J v_j``, ``q̈ = J a_j + J̇ v_j`` with ``J = ∂q/∂q_j`` (nq × n_j).  The dynamics are
the equations of motion projected on the joints (d'Alembert: ``J`` spans the tangent space,
``A J = 0``, so ``Aᵀλ`` drops out):

    r = Jᵀ (M (J a_j + J̇ v_j) − F(t, q, q̇, u, p)) = 0        (n_j rows per point; N·m or N)

in implicit form (no mass-matrix solve, so the rows stay sparse and cheap), each row divided
by the joint's inertia ``(Jᵀ M J)_ii`` at the initial configuration so that it reads as an
acceleration (rad/s², m/s²) like an explicit ODE's (:func:`joint_inertias`; measured on the
benchmark acrobot: 137 → 61 iterations at N = 30, the cart-pole and 3D arm unchanged).  As in the
``index3`` form of :mod:`ncgen.optim.radau` only the joint coordinates at the collocation
points are unknowns: the rates are the derivative of their polynomial, the accelerations
the derivative of the rates' polynomial — Radau IIA on ``(q_j, v_j)`` with the stage
rates eliminated.  Those rates and accelerations are unknowns as well, tied to the
positions by linear rows (:data:`POINT_RATES`): each point's residual then depends on its own
unknowns only, so the exact Hessian is built per point, not through the chain of intervals
(Panda, N = 20: 9.6 M → 6.2 M instructions, construction 15 → 6 s); ``3 n_j`` unknowns per
point (6 on the benchmark 3D arm against 68 for the GGL form).  Costs, targets and path constraints are written on the natural
quantities ``q(q_j)``, ``q̇`` (member poses, markers) exactly as in the natural form.

Joints whose rates are not the derivatives of their coordinates (Spherical and Free:
quaternions) are not handled; such models use the natural-coordinate GGL form.
"""
from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from ncgen.assembly.tree_dynamics import recursive_inverse_dynamics_function
from ncgen.errors import ModelError
from ncgen.model.data import model_data
from ncgen.optim.radau import radau_coefficients
from ncgen.optim.transcription import Discretisation, Horizon, Transcription, guess_times, node_times

#: Joint kinds whose rates are not the time derivatives of their coordinates.
QUATERNION_JOINTS = ("Spherical", "Free")


#: Joint rates and accelerations at the collocation points as NLP unknowns (linked to the
#: coordinates by linear rows), so each point's residual depends on its own unknowns only.
POINT_RATES = True


def joint_space_reason(model) -> str | None:
    """Why ``model`` cannot be transcribed in joint space (None if it can): it must be a
    tree of joints with coordinates (every member reached from the ground through them),
    with rates that are the derivatives of the coordinates, no other constraints and no
    drives (``Φ(q(q_j)) = 0`` for every ``q_j`` and ``t``), and as many joint rates as
    degrees of freedom.  Cached per model."""
    data = model_data(model)
    if data.joint_space_reason is None:
        data.joint_space_reason = (_reason(model),)
    return data.joint_space_reason[0]


def _reason(model) -> str | None:
    js = getattr(model, "joint_space", None)
    if js is None or not js.joint_names:
        return "the model has no joints with joint coordinates"
    quat = [n for n in js.joint_names if js.joints[n].kind in QUATERNION_JOINTS]
    if quat:
        return f"joints {', '.join(quat)} use quaternions (rates are not their derivatives)"
    try:
        tree = js.tree_function(model.layout)
    except ModelError as exc:
        return str(exc).split("; use from_joint_space")[0]
    if js.nv != model.dof:
        return f"{js.nv} joint rates for {model.dof} degrees of freedom"
    rng = np.random.default_rng(0)
    for t in (model.t0, model.t0 + 0.731):
        qj = rng.uniform(-1.0, 1.0, js.nq)
        q, _ = tree(qj, np.zeros(js.nv))
        phi = np.abs(np.array(model.functions["phi"](t, q, model.p0))).max(initial=0.0)
        if not phi <= 1e-9 * max(1.0, float(np.max(np.abs(np.array(q))))) ** 2:
            return "the joints do not satisfy every constraint (a closed loop, or a drive)"
    return None


def joint_dynamics_residual(model) -> ca.Function:
    """``(t, q_j, v_j, a_j, u, p) -> (r, q, v)``: the joint-space residual
    ``r = Jᵀ (M (J a_j + J̇ v_j) − F)`` and the natural coordinates and rates (module
    docstring).  In 3D ``r`` is computed by recursive Newton–Euler
    (:func:`~ncgen.assembly.tree_dynamics.recursive_inverse_dynamics_function`, the same
    quantity): on the Panda 3.5 k SX instructions instead of 10.7 k with ``J`` formed, and an
    exact Hessian of ``λᵀ r`` per point of 0.10 M instead of 0.22 M."""
    js = model.joint_space
    tree = js.tree_function(model.layout)
    t, u, p = ca.SX.sym("t"), ca.SX.sym("u", model.nu), ca.SX.sym("p", model.np)
    qj, vj, aj = ca.SX.sym("qj", js.nq), ca.SX.sym("vj", js.nv), ca.SX.sym("aj", js.nv)
    q, v = tree(qj, vj)
    if js.dim == 3:
        r = recursive_inverse_dynamics_function(model)(t, qj, vj, aj, u, p)
    else:
        J = ca.jacobian(q, qj)
        a = ca.jtimes(v, ca.vertcat(qj, vj), ca.vertcat(vj, aj))      # J a_j + J̇ v_j
        r = ca.mtimes(J.T, ca.mtimes(ca.DM(model.M), a) - model.functions["F"](t, q, v, u, p))
    return ca.Function("joint_dynamics_residual", [t, qj, vj, aj, u, p], [r, q, v],
                       ["t", "qj", "vj", "aj", "u", "p"], ["r", "q", "v"])


def joint_inertias(model, qj) -> np.ndarray:
    """The diagonal of the joint-space mass matrix ``Jᵀ M J`` at joint coordinates ``qj``
    (kg·m² for a rotation, kg for a translation; 1 where it vanishes): the row scales that
    make the residuals accelerations (rad/s², m/s²), as in an explicit ODE."""
    js = model.joint_space
    x = ca.SX.sym("qj", js.nq)
    q = js.tree_function(model.layout)(x, ca.DM.zeros(js.nv))[0]
    J = np.array(ca.Function("J", [x], [ca.jacobian(q, x)])(qj))
    m = np.einsum("ij,ik,kj->j", J, np.asarray(model.M), J)
    return np.where(m > 1e-12 * max(float(np.max(m, initial=0.0)), 1e-300), m, 1.0)


class JointRadauCollocation(Transcription):
    """Radau IIA collocation of degree ``degree`` in joint space (module docstring).  The
    builder gives the initial node as joint coordinates and rates (``Horizon.q0``,
    ``Horizon.v0``: ``q_j0``, ``v_j0``)."""

    joint_space = True

    def __init__(self, degree: int = 3):
        if not isinstance(degree, int) or not 1 <= degree <= 9:
            raise ValueError(f"collocation degree: expected an integer 1..9, got {degree!r}")
        self.degree = degree
        self.form = "joint"

    def describe(self) -> str:
        return f"Radau IIA collocation, degree {self.degree}, joint-space form"

    def build(self, opti: ca.Opti, model, hz: Horizon) -> Discretisation:
        d, N, nu = self.degree, hz.N, model.nu
        js = model.joint_space
        nj = js.nq
        tau, C, b = radau_coefficients(d)
        h = hz.T / N
        t = node_times(hz, tau[1:])
        Qj = opti.variable(nj, N * d)
        U = opti.variable(nu, N)
        Urep = ca.reshape(ca.repmat(U, d, 1), nu, N * d)
        Vj, Aj = _collocated_rates(hz, Qj, ca.DM(C), h, d)
        rates, points = [], None
        if POINT_RATES:
            points = opti.variable(nj, N * d), opti.variable(nj, N * d)
            rates = [("joint rates at the collocation points", ca.vec(points[0] - Vj)),
                     ("joint accelerations at the collocation points", ca.vec(points[1] - Aj))]
            Vj, Aj = points
        res, Q, V = joint_dynamics_residual(model).map(N * d)(t, Qj, Vj, Aj, Urep, hz.p)
        tree = js.tree_function(model.layout)
        q0, v0 = tree(hz.q0, hz.v0)
        last = list(range(d - 1, N * d, d))
        w = ca.repmat(ca.DM(b).T, 1, N) * h
        q_scale = np.array(hz.q0).reshape(-1) if isinstance(hz.q0, ca.DM) else js.positions(model.q0)
        res = res / ca.DM(joint_inertias(model, q_scale))
        defects = [("dynamics (joint-space equations of motion M_j⁻¹ Jᵀ(M q̈ − F) = 0)", ca.vec(res))] + rates
        return Discretisation(q=ca.horzcat(q0, Q[:, last]), v=ca.horzcat(v0, V[:, last]), lam=None, U=U,
                              path_t=t, path_q=Q, path_v=V, quad_t=t, quad_q=Q, quad_v=V, quad_w=w,
                              defects=defects, expandable=True,
                              set_guess=functools.partial(self._set_guess, model, hz, Qj, U, points),
                              qj=ca.horzcat(hz.q0, Qj[:, last]), vj=ca.horzcat(hz.v0, Vj[:, last]),
                              path_qj=Qj, path_vj=Vj)

    def _set_guess(self, model, hz: Horizon, Qj, U, points, o: ca.Opti, g):
        """Initial values from the guess ``g``: its joint coordinates at the collocation points
        (angles unwound, in the fixed start's winding), with ``points`` (the rates and
        accelerations at the points, or None) their collocation rates; returns the guess's
        initial joint coordinates and rates."""
        d, N, js = self.degree, hz.N, model.joint_space
        tau, C, _ = radau_coefficients(d)
        tg = np.concatenate([[hz.t0], guess_times(hz, g.T, tau[1:])])
        qg, vg = g.q(tg), g.v(tg)
        qjg = np.array(js.positions.map(tg.size)(qg.T)).reshape(js.nq, -1)
        qjg[js.angles] = np.unwrap(qjg[js.angles], axis=1)
        start = hz.q0 if isinstance(hz.q0, ca.DM) else None
        if start is not None and js.nq:            # the winding of the fixed start
            turns = np.round((np.array(start).reshape(-1) - qjg[:, 0]) / (2 * np.pi)) * js.angles
            qjg += 2 * np.pi * turns[:, None]
        o.set_initial(Qj, qjg[:, 1:])
        vj0 = np.array(js.rates(qg[0], vg[0])).reshape(-1)
        if points is not None:
            vs, acc, v_prev = [], [], vj0
            for k in range(N):
                Vk = np.column_stack([qjg[:, k * d], qjg[:, k * d + 1:(k + 1) * d + 1]]) @ C / (g.T / N)
                acc.append(np.column_stack([v_prev, Vk]) @ C / (g.T / N))
                vs.append(Vk)
                v_prev = Vk[:, -1]
            o.set_initial(points[0], np.hstack(vs))
            o.set_initial(points[1], np.hstack(acc))
        if model.nu:
            o.set_initial(U, g.u(guess_times(hz, g.T, [0.0])).T)
        return qjg[:, 0], vj0


def _collocated_rates(hz: Horizon, Qj, Cm, h, d: int):
    """The joint rates and accelerations at the collocation points that the collocated
    joint coordinates ``Qj`` imply: ``V = (1/h) Σ_r C_rj q_{k,r}``, ``A = (1/h) Σ_r C_rj
    v_{k,r}``, each interval from the last point of the one before (the initial node first)."""
    Vj, Aj, q_start, v_start = [], [], hz.q0, hz.v0
    for k in range(hz.N):
        cols = slice(k * d, (k + 1) * d)
        Vk = ca.mtimes(ca.horzcat(q_start, Qj[:, cols]), Cm) / h
        Aj.append(ca.mtimes(ca.horzcat(v_start, Vk), Cm) / h)
        Vj.append(Vk)
        q_start, v_start = Qj[:, k * d + d - 1], Vk[:, d - 1]
    return ca.horzcat(*Vj), ca.horzcat(*Aj)
