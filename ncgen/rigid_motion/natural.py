"""Natural coordinates ↔ rigid motion: a member's pose, body twist, spatial mass matrix and
the generalised force of a wrench.

A 3D member (:class:`ncgen.symbolic.member.RigidMember`) defines a frame b: origin at its
centre of mass, axes ``R`` (local → world, from :meth:`RigidMember.pose`).  Here, with g the
world frame:

- ``H_gb = [[R, p], [0, 1]]`` from ``(R, p) = member.pose(q)``;
- ``T_b = [Rᵀ ω; Rᵀ v]``, the body twist of b (in b), from ``(ω, v) = member.twist(q, q̇)``
  (ω in world axes, v the velocity of the centre of mass);
- ``M_b = diag(I_c, m 1)`` with ``I_c = tr(J̄) 1 − J̄`` (``J̄ = ∫ρ r̄ r̄ᵀ``, local axes);
- the generalised force of a wrench ``W_b = [τ; f]`` (in b, moment about the centre of mass)
  is ``member.force_at(0, R f) + member.torque(q, R τ)``.

A point member has no rotation: its frame is the translated world frame (``R = 1``).  A bar's
frame completes its axis; its angular velocity about the axis is not represented.
Planar members are not rigid motions in 3D and are refused.
"""
from __future__ import annotations

import numpy as np

from ncgen.errors import CoordinateTypeError
from ncgen.rigid_motion import numeric as rm
from ncgen.symbolic.member import RigidMember


def _check_3d(member: RigidMember) -> None:
    if member.ctype.dim != 3:
        raise CoordinateTypeError(f"member: expected a 3D member for a rigid motion, "
                                  f"found a planar {member.ctype.name} member")


def _rotation(R) -> np.ndarray:
    """A member's rotation; the identity for a point member (``R`` is ``None``)."""
    return np.eye(3) if R is None else R


def member_pose(member: RigidMember, q) -> np.ndarray:
    """``H_gb``: pose of the member frame b (origin at the centre of mass) in the world g."""
    _check_3d(member)
    R, p = member.pose(q)
    return rm.homogeneous(_rotation(R), p)


def member_twist(member: RigidMember, q, qd) -> np.ndarray:
    """``T_b = [Rᵀ ω; Rᵀ v]``: body twist of the member frame, in the member frame."""
    _check_3d(member)
    R = _rotation(member.pose(q)[0])
    omega, v = member.twist(q, qd)
    return np.concatenate([R.T @ (np.zeros(3) if omega is None else omega), R.T @ v])


def member_state(member: RigidMember, H_gb, T_b) -> tuple[np.ndarray, np.ndarray]:
    """``(q, q̇)`` of the member at pose ``H_gb`` moving with body twist ``T_b`` (inverse of
    :func:`member_pose` and :func:`member_twist`; a bar ignores ω along its axis)."""
    _check_3d(member)
    H_gb = rm.check_homogeneous(H_gb, "H_gb")
    R, p = H_gb[:3, :3], H_gb[:3, 3]
    T_g = rm.transport_twist(rm.homogeneous(R, np.zeros(3)), rm.check_vector(T_b, "T_b", 6))
    q = member.q_from_pose(R, p)
    qd = member.qd_from_twist(R, p, T_g[:3], T_g[3:])
    return q, qd


def member_mass_matrix(member: RigidMember) -> np.ndarray:
    """``M_b = diag(I_c, m 1)``: spatial mass matrix at the member frame (centre of mass)."""
    _check_3d(member)
    I_c = rm.inertia_from_second_moment(member.Jbar)
    return np.block([[I_c, np.zeros((3, 3))], [np.zeros((3, 3)), member.mass * np.eye(3)]])


def member_wrench_force(member: RigidMember, q, W_b) -> np.ndarray:
    """Generalised force ``Q`` of the wrench ``W_b = [τ; f]`` (member frame, moment about the
    centre of mass): ``Q = C(0)ᵀ R f + Wᵀ R τ``, so that ``Qᵀ q̇ = W_bᵀ T_b``.  A point member
    takes no moment (a nonzero τ raises :class:`~ncgen.errors.BasisError`)."""
    _check_3d(member)
    R = _rotation(member.pose(q)[0])
    W_g = rm.transport_wrench(rm.homogeneous(R.T, np.zeros(3)), rm.check_vector(W_b, "W_b", 6))
    Q = member.force_at(np.zeros(3), W_g[3:])
    if member.ctype.kind != "point" or np.any(W_g[:3] != 0):
        Q = Q + member.torque(q, W_g[:3])
    return Q
