"""The joint-space ODE of a tree, ``ẋ = f(t, x, w, p)`` with ``x = [q_j; v_j]``, as one SX
function for the compiled integration loop (:mod:`ncgen.runtime.joint_simulation`).

    q̇_j = Q(q_j) v_j        (quaternion rates ½ q ⊗ [ω; 0], a free joint's translation R v)
    v̇_j = a_j(t, q_j, v_j, u, p),   u = w + κ(t, q_j, v_j, p) + E⁺ τ_jd(q_j, v_j)

``a_j`` is the model's joint-space forward dynamics (the compiled kernel's SX function,
:func:`ncgen.assembly.tree_dynamics.recursive_dynamics_function`, inlined), ``w`` the open-loop
inputs (held samples or a Python controller's output), ``κ`` a compiled controller
(:mod:`ncgen.model.controllers`) and ``τ_jd`` the joint dynamics efforts
(:mod:`ncgen.model.joint_dynamics`), which reach the dynamics through each joint's own
input: ``E⁺`` scatters joint efforts onto the input components that are exactly those
efforts (a URDF robot's ``tau``).  Quaternions enter the dynamics normalised (``q / |q|``),
so the function is exact on the unit sphere and smooth around it; the integrator
renormalises them after each step.

Outputs: ``xdot``, ``check = [smallest relative Cholesky pivot, Σ a_j]`` of the kernel, and
the inputs ``u`` the dynamics received (for the trajectory's record).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.assembly.tree_dynamics import cholesky_solve
from ncgen.errors import ModelError
from ncgen.model.joint_dynamics import armature, coordinate_laws, has_dynamics, joint_effort


def quaternion_offsets(js) -> list[int]:
    """Start of each unit quaternion ``[qx, qy, qz, qw]`` in ``q_j`` (spherical and free joints, 3D)."""
    if js.dim != 3:
        return []
    return [s.stop - 4 for n, s in js.slices().items() if js.nq_joint[n] in (4, 7)]


def effort_inputs(model) -> dict[int, int]:
    """``{joint rate index: input index}`` for the actuated joint rates whose effort is one
    input component exactly (``∂τ/∂u`` a constant selection); other actuated rates are left out."""
    js = model.joint_space
    t, q, u, p = ca.SX.sym("t"), ca.SX.sym("q", model.nq), ca.SX.sym("u", model.nu), ca.SX.sym("p", model.np)
    tau = js.actuation(t, q, u, p)[1]
    if tau.numel() == 0 or model.nu == 0:
        return {}
    E = ca.jacobian(tau, u)
    if ca.depends_on(E, ca.vertcat(t, q, u, p)):
        return {}
    E = np.array(ca.DM(E))
    rows = [i for n in js.actuated for i in range(js.slices(rates=True)[n].start, js.slices(rates=True)[n].stop)]
    out = {}
    for r, row in zip(rows, E):
        nz = np.flatnonzero(row)
        if len(nz) == 1 and row[nz[0]] == 1.0 and np.count_nonzero(E[:, nz[0]]) == 1:
            out[r] = int(nz[0])
    return out


def efforts_to_inputs(model):
    """``τ ↦ u``: efforts of the actuated joint rates (``model.actuated_joints`` order) to an
    input vector (SX), through :func:`effort_inputs`; a joint without its own input is refused."""
    js = model.joint_space
    sv = js.slices(rates=True)
    rows = [i for n in js.actuated for i in range(sv[n].start, sv[n].stop)]
    mapping = effort_inputs(model)

    def apply(tau: ca.SX) -> ca.SX:
        u = ca.SX.zeros(model.nu)
        for k, r in enumerate(rows):
            if r not in mapping:
                name = next(n for n in js.actuated if sv[n].start <= r < sv[n].stop)
                raise ModelError(f"joint {name!r}: its effort is not one input component of its own "
                                 "(effort=u[k]), so a joint-space controller cannot drive it; write the law as "
                                 "nc.Controller(lambda t, qj, vj, p: u)")
            u[mapping[r]] = u[mapping[r]] + tau[k]
        return u
    return apply


def joint_dynamics_inputs(model, qj: ca.SX, vj: ca.SX) -> ca.SX | None:
    """``E⁺ τ_jd``: the joint dynamics efforts as inputs (None when no joint has any)."""
    js = model.joint_space
    sq, sv = js.slices(), js.slices(rates=True)
    laws = [(n, k, law) for n in js.joint_names for k, law in enumerate(coordinate_laws(js.joints[n]))
            if has_dynamics(law)]
    if not laws:
        return None
    mapping = effort_inputs(model)
    u = ca.SX.zeros(model.nu)
    for n, k, law in laws:
        tau = joint_effort(law, qj[sq[n].start + k], vj[sv[n].start + k])
        r = sv[n].start + k
        if r not in mapping:
            raise ModelError(f"joint {n!r}: has damping, friction or limits but its effort is not one input "
                             "component of its own (effort=u[k], as URDF joints have), so they cannot act in "
                             "simulation; give the joint an input, or drop its dynamics")
        u[mapping[r]] = u[mapping[r]] + tau
    return u


def joint_ode_function(model, dynamics: ca.Function, inverse_dynamics: ca.Function | None = None, *,
                       controller=None, joint_dynamics: bool = False) -> ca.Function:
    """``(t, x, w, p) -> (xdot, check, u)`` (module docstring).  ``dynamics``: the kernel's
    ``(t, qj, vj, u, p) -> (aj, check)``; ``inverse_dynamics`` ``(t, qj, vj, aj, u, p) -> r``
    (for :class:`~ncgen.model.controllers.ComputedTorque`)."""
    js = model.joint_space
    t, p = ca.SX.sym("t"), ca.SX.sym("p", model.np)
    x, w = ca.SX.sym("x", js.nq + js.nv), ca.SX.sym("w", model.nu)
    vj = x[js.nq:]
    parts = []
    k = 0
    quats = set(quaternion_offsets(js))
    while k < js.nq:
        if k in quats:
            qk = x[k:k + 4]
            parts.append(qk / ca.norm_2(qk))
            k += 4
        else:
            parts.append(x[k])
            k += 1
    qn = ca.vertcat(*parts) if parts else ca.SX(0, 1)
    sq, sv = js.slices(), js.slices(rates=True)
    qdot = [js.position_rates(n, qn[sq[n]], vj[sv[n]]) for n in js.joint_names]
    u = w
    if controller is not None:
        def rnea(aj):
            if inverse_dynamics is None:
                raise ModelError(f"{controller.name}: computed torque needs the model's inverse dynamics")
            return inverse_dynamics(t, qn, vj, aj, ca.SX.zeros(model.nu), p)
        u = u + controller.inputs(model, t, qn, vj, p, efforts_to_inputs=efforts_to_inputs(model),
                                  inverse_dynamics=rnea)
    if joint_dynamics:
        extra = joint_dynamics_inputs(model, qn, vj)
        if extra is not None:
            u = u + extra
    aj, check = dynamics(t, qn, vj, u, p)
    xdot = ca.vertcat(*qdot, aj) if qdot else aj
    return ca.Function("joint_ode", [t, x, w, p], [xdot, check, u], ["t", "x", "w", "p"], ["xdot", "check", "u"])


def natural_inputs_function(model, inverse_dynamics: ca.Function | None = None, *, controller=None,
                            joint_dynamics: bool = False) -> ca.Function | None:
    """``(t, q, v, p) -> u_extra``: the compiled controller's inputs and the joint dynamics
    efforts (as inputs) at a natural-coordinate state, through ``q_j(q)``, ``v_j(q, v)``: what
    the natural-coordinate integrators add to the inputs (IDAS); None when there is nothing."""
    js = model.joint_space
    t, p = ca.SX.sym("t"), ca.SX.sym("p", model.np)
    q, v = ca.SX.sym("q", model.nq), ca.SX.sym("v", model.nq)
    qj, vj = js.positions(q), js.rates(q, v)
    u = ca.SX.zeros(model.nu)
    used = False
    if controller is not None:
        def rnea(aj):
            if inverse_dynamics is None:
                raise ModelError(f"{controller.name}: computed torque needs the model's inverse dynamics (a tree)")
            return inverse_dynamics(t, qj, vj, aj, ca.SX.zeros(model.nu), p)
        u = u + controller.inputs(model, t, qj, vj, p, efforts_to_inputs=efforts_to_inputs(model),
                                  inverse_dynamics=rnea)
        used = True
    if joint_dynamics:
        extra = joint_dynamics_inputs(model, qj, vj)
        if extra is not None:
            u, used = u + extra, True
    if not used:
        return None
    return ca.Function("natural_inputs", [t, q, v, p], [u], ["t", "q", "v", "p"], ["u"])


def armature_vector(model) -> np.ndarray:
    """Armature per joint rate (``joint.dynamics["armature"]``; Revolute and Prismatic joints,
    and each coordinate of a joint sequence)."""
    js = model.joint_space
    out = np.zeros(js.nv)
    for n, s in js.slices(rates=True).items():
        laws = coordinate_laws(js.joints[n])
        a = np.array([armature(law) for law in laws])
        if np.any(a) and js.nv_joint[n] != len(laws):
            raise ModelError(f"joint {n!r}: armature applies to one-coordinate joints (Revolute, Prismatic) "
                             "and joint sequences")
        out[s] = a if len(laws) == js.nv_joint[n] else a[0]
    return out


def armature_dynamics_function(model, inverse_dynamics: ca.Function, arm: np.ndarray) -> ca.Function:
    """``(t, qj, vj, u, p) -> (aj, check)`` with armature: ``(M_j + diag(arm)) a_j = τ − C``,
    from the inverse dynamics residual ``r = M_j a_j + C − τ`` (linear in ``a_j``:
    ``M_j = ∂r/∂a_j``, ``τ − C = −r(0)``), solved by the written-out Cholesky.  With mimic
    joints (``a_j = G a_i``, :class:`~ncgen.assembly.tree_dynamics.MimicMap`; ``r`` has a row
    per independent rate) the system is in the independent rates,
    ``(Gᵀ M_j G + Gᵀ diag(arm) G) a_i = Gᵀ (τ − C)``: each follower's armature reflected
    through its ratio."""
    from ncgen.assembly.tree_dynamics import MimicMap
    js = model.joint_space
    t, u, p = ca.SX.sym("t"), ca.SX.sym("u", model.nu), ca.SX.sym("p", model.np)
    qj, vj = ca.SX.sym("qj", js.nq), ca.SX.sym("vj", js.nv)
    G = MimicMap(model).G
    mimic = G.shape[1] < js.nv
    ai = ca.SX.sym("aj", G.shape[1])
    Gs = ca.sparsify(ca.DM(G))
    r = inverse_dynamics(t, qj, vj, ca.mtimes(Gs, ai) if mimic else ai, u, p)
    reflected = ca.sparsify(ca.DM(G.T @ np.diag(arm) @ G)) if mimic else ca.diag(ca.DM(arm))
    M = ca.jacobian(r, ai) + reflected
    b = -ca.substitute(r, ai, ca.SX.zeros(ai.numel()))
    x, pivot = cholesky_solve(M, b)
    x = ca.mtimes(Gs, x) if mimic else x
    return ca.Function("joint_forward_dynamics_armature", [t, qj, vj, u, p], [x, ca.vertcat(pivot, ca.sum1(x))],
                       ["t", "qj", "vj", "u", "p"], ["aj", "check"])


def dae_with_inputs(model, dae: ca.Function, extra: ca.Function) -> ca.Function:
    """IDAS's ``dae`` ``(t, x, z, u, p)`` with ``u + extra(t, q, v, p)`` in place of ``u``
    (:func:`natural_inputs_function`: a compiled controller, the joint dynamics)."""
    t, x, z = ca.MX.sym("t"), ca.MX.sym("x", dae.size1_in(1)), ca.MX.sym("z", dae.size1_in(2))
    u, p = ca.MX.sym("u", dae.size1_in(3)), ca.MX.sym("p", dae.size1_in(4))
    nq = model.nq
    out = dae(t, x, z, u + extra(t, x[:nq], x[nq:], p), p)
    return ca.Function(f"{dae.name()}_inputs", [t, x, z, u, p], list(out),
                       [dae.name_in(i) for i in range(5)], [dae.name_out(i) for i in range(dae.n_out())])
