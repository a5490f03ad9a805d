"""Joint reactions and actuator efforts in SI units, from the Lagrange multipliers.

The equations of motion ``M q̈ + Aᵀλ = F`` make ``−A_Jᵀ λ_J`` the generalised force of
joint J's equations (its rows of ``A`` and ``λ``).  On member B (the joint's second member;
the first with the sign flipped when B is the ground) that generalised force ``Q_B`` is
turned into the equivalent wrench by virtual power: for every rigid motion of B with
centre-of-mass velocity ``v`` and angular velocity ``ω``, ``Q_Bᵀ q̇_B(v, ω) = fᵀ v + τ_Gᵀ ω``
(``q̇_B`` linear in the twist, from the member's derivation).  Reported:

* ``force`` ``f`` (N) and ``moment`` about the joint point (N·m; a scalar in 2D) exerted
  **on B by A** through the joint, in **world axes**; the joint point is the point of B at
  ``at`` in the initial configuration (``at[1]`` for Distance), at its current position
  ``point`` (m).  Components a joint leaves free vanish (the moment about a hinge's axis,
  unless it is driven).  A bar takes no moment about its own axis.
* ``effort``: a driven joint's actuator torque (N·m, Revolute, about its axis) or force (N,
  Prismatic along its axis; Distance along the line B − A, positive pushing the points
  apart), from the drive's own multiplier; a joint with ``effort=`` reports the value of
  its effort.  None otherwise.

Joints that coordinate sharing eliminated (``model.sharing``: a shared point or axis, a
weld merged) have no multipliers of their own.  Their reactions come from the same system
built with ``share=False`` (:class:`ncgen.assembly.unshared.UnsharedForm`, built on first
use): its coordinates are ``q_u = S q + c``, ``v_u = S v``, ``a_u = S a`` with
``a = M⁻¹(F − Aᵀλ)`` from the given multipliers, and its multipliers solve its own equations
of motion ``A_uᵀ λ_u = F_u − M_u a_u`` (least squares; the residual is checked).  Its rows of
the eliminated joints then give the reactions as above, in the same frames and units, equal
to what ``build(share=False)`` reports.  A weld (``Fixed``) reports the wrench transmitted
through it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ncgen.blas_threads import one_blas_thread
from ncgen.errors import ModelError
from ncgen.validation import as_vector


@dataclass
class JointReaction:
    """Wrench exerted on ``member`` by the other member through joint ``joint`` (world axes,
    moment about ``point``), and the actuator ``effort`` when driven or actuated."""

    joint: str
    member: str
    point: np.ndarray
    force: np.ndarray
    moment: np.ndarray | float
    effort: float | np.ndarray | None = None
    frame: str = "world axes; moment about the joint point; acting on the joint's second member"


def _rows(model, name: str) -> tuple[list[int], list[int]]:
    """Rows of joint ``name`` in Φ: all of them, and the drive's."""
    rows, drive = [], []
    for i, label in enumerate(model.constraint_names):
        parts = label.split(".")
        if parts[0] == name and (len(parts) < 2 or parts[1] != "rigid"):
            rows.append(i)
            if len(parts) > 1 and parts[1] == "drive":
                drive.append(i)
    return rows, drive


def _wrench(model, member, Q_full: np.ndarray, q: np.ndarray, point_local):
    """``(point, f, moment)`` equivalent to the generalised force ``Q_full`` on ``member``."""
    idx = model.layout.member_indices(member.name)
    Q = np.array([Q_full[i] if i is not None else 0.0 for i in idx])
    qm = np.array([q[i] if i is not None else c for i, c in zip(idx, model.layout.member_constant(member.name))])
    loc = member.rigid
    d = model.dim
    R, pc = loc.pose(qm)
    R = np.eye(d) if R is None else R
    nw = 3 if d == 3 else 1
    cols_v = [loc.qd_from_twist(R, pc, np.zeros(nw) if d == 3 else 0.0, e) for e in np.eye(d)]
    f = np.array([c @ Q for c in cols_v])
    if member.kind == "point":
        tau_g = np.zeros(nw)
    else:
        tau_g = np.array([loc.qd_from_twist(R, pc, e if d == 3 else float(e[0]), np.zeros(d)) @ Q
                          for e in np.eye(nw)])
    P = loc.position(qm, point_local)
    r = pc - P
    if d == 3:
        return P, f, tau_g + np.cross(r, f)
    return P, f, float(tau_g[0] + r[0] * f[1] - r[1] * f[0])


@one_blas_thread
def joint_reactions(model, q, lam, *, v=None, t=None, u=None, p=None, joints=None) -> dict[str, JointReaction]:
    """Reactions of ``joints`` (default: every joint with equations, those that coordinate
    sharing eliminated included) at the state ``q`` with multipliers ``lam`` (from
    :func:`~ncgen.runtime.dynamics_at_state.forward_dynamics`, or a trajectory's ``lam``);
    ``u``, ``t``, ``p`` for the efforts of actuated joints and the applied forces; ``v`` is
    needed for the reactions of eliminated joints when a force depends on velocities."""
    q = as_vector(q, model.nq, "q")
    lam = as_vector(lam, model.nc, "lam (one multiplier per constraint)")
    t = model.t0 if t is None else float(t)
    p = model.p0 if p is None else as_vector(p, model.np, "p")
    u = np.zeros(model.nu) if u is None else as_vector(u, model.nu, "u")
    A = np.array(model.functions["A"](t, q, p))
    js = model.joint_space
    B, tau = (np.array(x) for x in js.actuation(t, q, u, p))
    tau = tau.reshape(-1)
    offsets = np.cumsum([0] + [js.nv_joint[n] for n in js.actuated])
    efforts = {n: tau[offsets[k]:offsets[k + 1]] for k, n in enumerate(js.actuated)}
    by_name = js.joints
    names = list(by_name) if joints is None else list(joints)
    out, eliminated = {}, []
    for name in names:
        j = by_name.get(name)
        if j is None:
            raise ModelError(f"joint_reactions: no joint named {name!r}; joints: {', '.join(by_name)}")
        if j.kind in ("CoordinateDriver", "Mimic"):
            continue
        if model.sharing is not None and (name in model.sharing.eliminated or name in model.sharing.partial):
            eliminated.append(name)
            out[name] = None
            continue
        rows, drive = _rows(model, name)
        if not rows and name not in efforts:
            continue
        side, sign = (j.B, 1.0) if not j.B.is_ground else (j.A, -1.0)
        at = j.options.get("at")
        world = np.asarray(at[1] if j.kind == "Distance" else at, float) if at is not None else side.p0
        local = side.to_local(world)
        if side.kind == "bar":
            local = side.to_local(_nearest(side, world))
        Q = -A[rows].T @ lam[rows] if rows else np.zeros(model.nq)
        P, f, m = _wrench(model, side, Q, q, local)
        effort = None
        if drive:
            _, fd, md = _wrench(model, side, -A[drive].T @ lam[drive], q, local)
            effort = sign * _along(j, side, model, q, fd, md)
        elif name in efforts:
            e = efforts[name]
            effort = float(e[0]) if e.size == 1 else e
        out[name] = JointReaction(name, "ground" if j.B.is_ground else j.B.name, P, sign * f, sign * m, effort)
    if eliminated:
        out.update(_eliminated(model, q, lam, A, v, t, u, p, eliminated))
    return {k: r for k, r in out.items() if r is not None}


#: Largest residual of the unshared equations of motion, relative to their terms, accepted when
#: recovering the multipliers of eliminated joints.  Any ``lam`` balances them at a state on the
#: constraints (``a`` follows from it), so this guards the map between the two forms and states
#: far off the constraints.
BALANCE_TOL = 1e-6


def _eliminated(model, q, lam, A, v, t, u, p, names) -> dict[str, JointReaction]:
    """Reactions of the joints ``names`` that coordinate sharing eliminated, through the
    model's unshared form (module docstring)."""
    um, q_u, v_u, lam_u = unshared_state(model, q, lam, A, v, t, u, p, names)
    return joint_reactions(um, q_u, lam_u, v=v_u, t=t, u=u, p=p, joints=names)


def _least_squares(B: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``x`` minimising ``|B x − b|``: by QR when ``B`` has full column rank (the usual case,
    ~10× cheaper than an SVD), else the minimum-norm SVD solution."""
    if B.shape[1] == 0:
        return np.zeros(0)
    Q, R = np.linalg.qr(B)
    d = np.abs(np.diag(R))
    if d.min() > 1e-10 * d.max():
        return scipy.linalg.solve_triangular(R, Q.T @ b)
    return np.linalg.lstsq(B, b, rcond=None)[0]


def unshared_state(model, q, lam, A, v, t, u, p, names):
    """``(unshared model, q_u, v_u, λ_u)``: the state of the ``share=False`` form of ``model``
    and its multipliers, from the state and multipliers ``lam`` of ``model`` (``A`` its
    constraint Jacobian at ``q``; ``names``: the eliminated joints asked for, for messages)."""
    form = model.unshared
    if form is None:
        raise ModelError(f"joint_reactions: model {model.name!r} has no unshared form for the eliminated "
                         f"joints {', '.join(names)}")
    um = form.model(model)
    S, c = form.coordinate_map(model)
    if v is None:
        if any(m.functions["F"].which_depends("v", ["F"], 1, True)[0] for m in (model, um)):
            raise ModelError(f"joint_reactions: the reactions of {', '.join(names)} (eliminated by coordinate "
                             f"sharing) need the velocities v: model {model.name!r} has velocity-dependent "
                             f"forces")
        v = np.zeros(model.nq)
    v = as_vector(v, model.nq, "v")
    a = model.mass_factor.solve_numeric(model.F(q, v, t=t, u=u, p=p) - A.T @ lam)
    q_u, v_u = S @ q + c, S @ v
    F_u, Ma_u = um.F(q_u, v_u, t=t, u=u, p=p), np.asarray(um.M) @ (S @ a)
    A_u = np.asarray(um.A(q_u, t=t, p=p)).reshape(um.nc, um.nq)
    rhs = F_u - Ma_u
    lam_u = _least_squares(A_u.T, rhs)
    residual = float(np.linalg.norm(A_u.T @ lam_u - rhs))
    scale = float(np.linalg.norm(F_u) + np.linalg.norm(Ma_u) + np.linalg.norm(A_u.T @ lam_u))
    if residual > BALANCE_TOL * max(scale, 1e-300):
        raise ModelError(
            f"joint_reactions: the reactions of {', '.join(names)} (eliminated by coordinate sharing) could "
            f"not be recovered: the equations of motion of the model's share=False form leave a residual "
            f"of {residual:.3g} N (terms of {scale:.3g} N) at this state; is q on the constraints? Pass a "
            f"consistent state with its multipliers (nc.forward_dynamics, or a trajectory's q, v, lam)")
    return um, q_u, v_u, lam_u


def _nearest(bar, world):
    e = bar.R0[:, 0]
    return bar.p0 + np.dot(world - bar.p0, e) * e


def _along(j, side, model, q, f, m) -> float:
    """The component of a drive's wrench along the joint's free direction, current axes."""
    d = model.dim
    if j.kind == "Revolute":
        if d == 2:
            return float(m)
        return float(np.dot(m, _current(model, side, q, j.axis())))
    if j.kind == "Prismatic":
        return float(np.dot(f, _current(model, side, q, j.axis())))
    if j.kind == "Distance":
        pA, pB = j.points()
        rA = _world_point(model, j.A, q, pA)
        rB = _world_point(model, j.B, q, pB)
        e = (rB - rA) / np.linalg.norm(rB - rA)
        return float(np.dot(f, e)) * (1.0 if side is j.B else -1.0)
    raise ModelError(f"{j.label}: no effort for a driven {j.kind} joint")


def _member_q(model, m, q):
    idx = model.layout.member_indices(m.name)
    return np.array([q[i] if i is not None else c for i, c in zip(idx, model.layout.member_constant(m.name))])


def _current(model, m, q, world_dir):
    """A direction fixed to ``m`` (world ``world_dir`` initially), now."""
    if m.is_ground:
        return np.asarray(world_dir, float)
    R, _ = m.rigid.pose(_member_q(model, m, q))
    return R @ (m.R0.T @ np.asarray(world_dir, float))


def _world_point(model, m, q, world0):
    if m.is_ground:
        return np.asarray(world0, float)
    return m.rigid.position(_member_q(model, m, q), m.to_local(world0))
