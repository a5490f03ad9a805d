"""Poses through the tree of joints: the relative pose of each joint's frames for given joint
coordinates, and the pose of the member across a joint, numerically (NumPy) or symbolically
(CasADi SX, ``sym=True``) — used by :mod:`ncgen.assembly.joint_space` to go from joint space
to natural coordinates.

Conventions: an :class:`Edge` holds a joint's frames on A and B (world axes and origin in the
initial configuration) and its axes; ``relative_pose`` gives ``(R, p)`` of B's joint frame in
A's; quaternions are ``[qx, qy, qz, qw]`` (Hamilton).
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ncgen.errors import ModelError
from ncgen.model.joint_equations import bar_axis, is_along, is_full
from ncgen.reproducible import perpendicular_basis
from ncgen.rigid_motion import casadi_forms as crm


@dataclass
class Edge:
    """A joint of the spanning tree: member names, joint kind, frames and axes (world,
    initial configuration) — plain data for :func:`relative_pose`."""

    name: str
    kind: str
    A: str
    B: str
    frame_a: tuple[np.ndarray, np.ndarray]
    frame_b: tuple[np.ndarray, np.ndarray]
    axes: tuple
    #: a joint to a 3D bar (A: the full member, B: the bar): its coordinates give the bar's
    #: pose from the other's, never the other way (the bar's spin is not in them)
    one_way: bool = False


def edge_of(j) -> Edge:
    """The :class:`Edge` of joint ``j`` (joint frames: world axes at ``at`` on both sides; a
    Free joint: A's frame and B's given frame)."""
    d = j.system.dim
    eye = np.eye(d)
    A, B = ("ground" if m.is_ground else m.name for m in (j.A, j.B))
    if j.kind == "Free":
        fa = (eye, np.zeros(d)) if j.A.is_ground else (j.A.R0, j.A.p0)
        return Edge(j.name, j.kind, A, B, fa, (j.frame_rotation(), j.frame_origin()), ())
    at = j.at()
    if j.kind in ("Spherical", "Universal", "Planar") and not (is_full(j.A) and is_full(j.B)):
        return _bar_edge(j, at)
    axes = ()
    if j.kind == "JointSequence":                    # (kind, point − at, axis) per step
        axes = tuple((k, p - at, a) for k, p, a in j.steps())
    if j.kind in ("Revolute",) and d == 3:
        axes = (j.axis(),)
    elif j.kind in ("Prismatic", "Cylindrical"):
        axes = (j.axis(),)
    elif j.kind == "Universal":
        axes = (j.direction("axis_a"), j.direction("axis_b"))
    elif j.kind == "Planar":
        n = j.direction("normal")
        axes = (n, *perpendicular_basis(n))
    return Edge(j.name, j.kind, A, B, (eye, at), (eye, at), axes)


def _bar_edge(j, at) -> Edge:
    """The one-way :class:`Edge` of a Spherical, Universal or Planar joint between a full member
    C and a 3D bar O (:mod:`ncgen.assembly.joint_coordinates`): from C's frame at ``at`` to the
    bar's frame at its point nearest ``at``."""
    C, O = (j.A, j.B) if is_full(j.A) else (j.B, j.A)
    names = ["ground" if m.is_ground else m.name for m in (C, O)]
    near = O.p0 + np.dot(at - O.p0, bar_axis(O)) * bar_axis(O)
    eye = np.eye(3)
    if j.kind == "Spherical":
        kind, axes = "Swing", tuple(perpendicular_basis(bar_axis(O)))
    elif j.kind == "Universal":                      # θ_a about a (B the bar), or θ_b about b, of B in A
        kind, axes = "Revolute", ((j.direction("axis_a"),) if O is j.B else (-j.direction("axis_b"),))
    else:
        n = j.direction("normal")
        kind, axes = "PlanarBar", (n, *perpendicular_basis(n), near - at, not is_along(O, n))
    return Edge(j.name, kind, *names, (eye, at), (eye, near), axes, one_way=True)


def _numeric(x) -> np.ndarray:
    return np.array(ca.DM(x), float)


def rotation_about(axis, angle, sym: bool = False):
    """Rotation by ``angle`` (rad) about the unit ``axis`` (SX when ``sym``;
    :func:`ncgen.symbolic.rigid_motion.rotation_about`)."""
    R = crm.rotation_about(_const(axis, True), angle)
    return R if sym else _numeric(R)


def rotation_vector(phi, sym: bool = False):
    """``exp(φ̂)``: rotation by ``|φ|`` about ``φ`` (SX when ``sym``;
    :func:`ncgen.symbolic.rigid_motion.exp_so3`)."""
    if sym:
        return crm.exp_so3(phi)
    return _numeric(crm.exp_so3(np.asarray(phi, float).reshape(3, 1)))


def rotation_2d(angle, sym: bool = False):
    if sym:
        c, s = ca.cos(angle), ca.sin(angle)
        return ca.vertcat(ca.horzcat(c, -s), ca.horzcat(s, c))
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


def quaternion_matrix(quat, sym: bool = False):
    """Rotation matrix of the unit quaternion ``[qx, qy, qz, qw]`` (normalised first; SX when
    ``sym``; :func:`ncgen.symbolic.rigid_motion.quaternion_matrix`)."""
    if sym:
        return crm.quaternion_matrix(quat)
    return _numeric(crm.quaternion_matrix(np.asarray(quat, float).reshape(4, 1)))


def quaternion_rate(quat, omega):
    """``q̇ = ½ q ⊗ [ω; 0]`` for ω in the rotated frame's axes ([qx, qy, qz, qw] order;
    :func:`ncgen.symbolic.rigid_motion.quaternion_rate`)."""
    return crm.quaternion_rate(quat, omega)


def relative_pose(e: Edge, x, dim: int, sym: bool = False):
    """``(R, p)`` of B's joint frame in A's for joint coordinates ``x`` (SX when ``sym``)."""
    if sym:
        rot = (lambda ax, th: rotation_about(ax, th, True)) if dim == 3 else (lambda ax, th: rotation_2d(th, True))
        eye, zero = ca.DM.eye(dim), ca.DM.zeros(dim, 1)
    else:
        rot = (lambda ax, th: rotation_about(ax, th)) if dim == 3 else (lambda ax, th: rotation_2d(th))
        eye, zero = np.eye(dim), np.zeros(dim)
    qm = (lambda x_: quaternion_matrix(x_, True)) if sym else quaternion_matrix
    k = e.kind
    if k == "Fixed":
        return eye, zero
    if k == "Revolute":
        return rot(e.axes[0] if e.axes else None, x[0]), zero
    if k == "Prismatic":
        return eye, x[0] * _const(e.axes[0], sym)
    if k == "Cylindrical":
        return rot(e.axes[0], x[1]), x[0] * _const(e.axes[0], sym)
    if k == "Universal":
        Ra, Rb = rotation_about(e.axes[0], x[0], sym), rotation_about(e.axes[1], x[1], sym)
        return (ca.mtimes(Ra, Rb) if sym else Ra @ Rb), zero
    if k == "Planar":
        n, e1, e2 = e.axes
        return rotation_about(n, x[2], sym), x[0] * _const(e1, sym) + x[1] * _const(e2, sym)
    if k == "Spherical":
        return qm(x), zero
    if k == "Swing":                                 # rotation vector x₁ e₁ + x₂ e₂
        return rotation_vector(x[0] * _const(e.axes[0], sym) + x[1] * _const(e.axes[1], sym), sym), zero
    if k == "PlanarBar":
        n, e1, e2, p0, turns = e.axes
        p = _const(p0, sym) + x[0] * _const(e1, sym) + x[1] * _const(e2, sym)
        return (rotation_about(n, x[2], sym) if turns else eye), p
    if k == "JointSequence":
        return _sequence_pose(e, x, sym)
    if k == "Free":
        if dim == 2:
            return rotation_2d(x[2], sym), x[:2]
        return qm(x[3:]), x[:3]
    raise ModelError(f"joint {e.name!r}: no relative pose for a {k} joint")


def _sequence_pose(e: Edge, x, sym: bool):
    """``H_1(x_1) ⋯ H_n(x_n)``: each step a rotation by ``x_k`` about the line through its
    point along its axis, or a translation by ``x_k`` along its axis."""
    mul = ca.mtimes if sym else np.matmul
    R, p = (ca.DM.eye(3), ca.DM.zeros(3, 1)) if sym else (np.eye(3), np.zeros(3))
    for k, (kind, c, a) in enumerate(e.axes):
        if kind == "hinge":
            Rk = rotation_about(a, x[k], sym)
            pk = _const(c, sym) - mul(Rk, _const(c, sym))
        else:
            Rk, pk = (ca.DM.eye(3) if sym else np.eye(3)), x[k] * _const(a, sym)
        R, p = mul(R, Rk), mul(R, pk) + p
    return R, p


def _const(x, sym: bool):
    """``x`` as CasADi when ``sym`` (a symbolic axis or point, SX, passes as it is)."""
    if isinstance(x, ca.SX):
        return x
    return ca.DM(np.asarray(x, float)) if sym else x


def carry(pose, e: Edge, T, forward: bool, members, sym: bool = False):
    """Pose of the member across joint ``e`` from the pose of the one on this side.

    World pose of a frame fixed to member m that was ``H0`` initially: ``H_m H_m0⁻¹ H0``.
    Forward (A → B): ``H_JB = H_JA T``, backward: ``H_JA = H_JB T⁻¹``."""
    mul = ca.mtimes if sym else np.matmul
    R, p = pose
    Rt, pt = T if forward else (T[0].T, -mul(T[0].T, T[1]))
    a1, b1, a2, b2 = edge_placements(e, forward, members, R.shape[0])
    if sym:
        a1, b1, a2, b2 = (ca.DM(x) for x in (a1, b1, a2, b2))
    RJ = mul(R, a1)
    oJ = mul(R, b1) + p
    RJ2, oJ2 = mul(RJ, Rt), mul(RJ, pt) + oJ
    return mul(RJ2, a2), mul(RJ2, b2) + oJ2


def edge_placements(e: Edge, forward: bool, members, dim: int):
    """``(a1, b1, a2, b2)``: the constant poses of the joint frame on this side in this
    member's frame (``H = [[a1, b1], [0, 1]]``) and of the member beyond in the joint frame on
    that side (``[[a2, b2], [0, 1]]``), so that ``H_here,there = [a1, b1] T [a2, b2]`` for
    the joint's relative pose ``T`` (:func:`carry`)."""
    here, there = (e.A, e.B) if forward else (e.B, e.A)
    f_here, f_there = (e.frame_a, e.frame_b) if forward else (e.frame_b, e.frame_a)
    R0h, p0h = initial_pose(members, here, dim)
    R0t, p0t = initial_pose(members, there, dim)
    return (R0h.T @ f_here[0], R0h.T @ (f_here[1] - p0h), f_there[0].T @ R0t, f_there[0].T @ (p0t - f_there[1]))


def initial_pose(members, name: str, dim: int):
    """``(R0, p0)`` of a member's frame in the initial configuration (the ground: identity)."""
    if name == "ground":
        return np.eye(dim), np.zeros(dim)
    m = members[name]
    return (np.eye(dim) if m.R0 is None else m.R0), m.p0
