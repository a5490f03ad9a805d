"""Joint coordinates and rates as CasADi expressions of the natural coordinates.

Each joint that has coordinates gets its positions ``q_j(q)`` and rates ``v_j(q, q̇)``,
zero in the initial configuration unless its frames say otherwise (the free joint of a
floating base: the pose of the base frame in the world):

==============  =======================================  ======================================
joint           positions                                rates
==============  =======================================  ======================================
Revolute        θ, rad (the drive's angle gauge)         θ̇
Prismatic       s, m (the drive's displacement)          ṡ
Cylindrical     [s, θ] along / about ``axis``            [ṡ, θ̇]
Universal       [θ_a, θ_b]: R = Rot(a, θ_a) Rot(b, θ_b)  [θ̇_a, θ̇_b]
Planar          [x, y, θ]: offsets along the two         [ẋ, ẏ, θ̇]
                directions ⟂ ``normal``, angle about it
Spherical       [qx, qy, qz, qw] of B relative to A      ω of B relative to A, B's axes
Free (3D)       [x, y, z, qx, qy, qz, qw]                [v, ω] of B's frame in its own axes
Free (planar)   [x, y, θ]                                [v_x, v_y, ω] in B's frame axes
JointSequence   [x_1, ..., x_n]: each hinge's angle or   their time derivatives
                slide's displacement, in order
==============  =======================================  ======================================

Joints to a 3D bar (which has no spin about its own axis) have the coordinates of what is
measurable, **of the bar relative to the other member** (a body or the ground, "C"), in C's
joint frame (world axes at ``at`` carried by C):

==============  =======================================  ======================================
Spherical       [swing_1, swing_2], rad: the rotation    their time derivatives
                vector θ k of the smallest rotation
                taking the bar's initial direction u₀
                to its current one (k ⟂ u₀), along
                e₁, e₂ = perpendicular_basis(u₀)
Universal       θ_a (B the bar, along ``axis_b``) or     θ̇
                θ_b (A the bar): the other angle is the
                bar's spin
Planar          [x, y], m, of the bar's point nearest    [ẋ, ẏ(, θ̇)]
                ``at`` in C's plane (e₁, e₂ ⟂ normal);
                a bar across the normal adds θ, its
                angle about the normal
==============  =======================================  ======================================

The swing is defined while the bar is less than π from its initial direction (it is
singular pointing back along −u₀).  Undefined, so those joints have no coordinates (listed
with the reason in ``model.joint_space.skipped``, named by any error that asks for them): a
spin about a bar's own axis; anything of a joint between two 3D bars (only the angle between
their axes is defined, with no smooth rate where they align) or with a point member (no
orientation); a Free joint with a bar or point member.

Angles are right-handed about the joint's axis (counter-clockwise in 2D); quaternions are
unit, ``qw ≥ 0``, in Pinocchio's order.  Spherical and Free joints measure the relative
rotation of the joint frames: the world axes at ``at`` carried by each side (Free: A's
frame and the frame given by ``at``/``rotation`` on B).  The joints' rates are exactly
``J(q) q̇`` with ``J = ∂v_j/∂q̇``, so an effort ``τ`` conjugate to them (torque for
angles, force for lengths, the wrench ``[f, τ]`` in B's frame for a free joint) acts as the
generalised force ``Jᵀ τ``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ncgen.errors import ModelError
from ncgen.model.joint_equations import angle_gauge, bar_axis, is_along, is_full, kind_of, name_of
from ncgen.reproducible import perpendicular_basis
from ncgen.rigid_motion import casadi_forms as crm


@dataclass
class JointCoordinates:
    """Positions and rates of one joint: ``q`` (SX of the context's q), ``v`` (SX of q and
    v), their names and which positions are angles (they wrap by 2π)."""

    joint: object
    q: ca.SX
    v: ca.SX
    position_names: list[str]
    rate_names: list[str]
    angles: list[bool] = field(default_factory=list)

    @property
    def name(self) -> str:
        return self.joint.name

    @property
    def nq(self) -> int:
        return int(self.q.numel())

    @property
    def nv(self) -> int:
        return int(self.v.numel())


def joint_coordinates(ctx, joint) -> JointCoordinates | None:
    """The :class:`JointCoordinates` of ``joint``, or None for a joint without coordinates
    (Fixed, Distance, PointOnLine, PointOnPlane, CoordinateDriver).  Raises
    :class:`ModelError` when the joint's members cannot carry its coordinates (a bar's spin)."""
    make = _BUILDERS.get(joint.kind)
    if make is None:
        return None
    return make(ctx, joint)


# ----------------------------------------------------------------- builders
def _scalar_rates(ctx, q: ca.SX) -> ca.SX:
    return ca.mtimes(ca.jacobian(q, ctx.q), ctx.v)


def _atan2(x, y):
    return ca.atan2(y, x)


def _revolute(ctx, j):
    th = j.coordinate(ctx)
    return JointCoordinates(j, th, _scalar_rates(ctx, th), [j.name], [j.name], [True])


def _prismatic(ctx, j):
    s = j.coordinate(ctx)
    return JointCoordinates(j, s, _scalar_rates(ctx, s), [j.name], [j.name], [False])


def _cylindrical(ctx, j):
    at, a = j.at(), j.axis()
    C, O, sign = (j.A, j.B, 1.0) if is_full(j.A) else (j.B, j.A, -1.0)
    rC, _ = ctx.point(C, at, j.label)
    rO, _ = ctx.point(O, at, j.label)
    aC, _ = ctx.direction(C, a, j.label)
    s = sign * ca.dot(rO - rC, aC)
    x, y = angle_gauge(ctx, j.A, j.B, a, j.label).terms(ctx)
    q = ca.vertcat(s, _atan2(x, y))
    names = [f"{j.name}.s", f"{j.name}.theta"]
    return JointCoordinates(j, q, _scalar_rates(ctx, q), names, names, [False, True])


def _universal(ctx, j):
    C, O = _full_and_bar(j, "a Universal joint")
    a, b = j.direction("axis_a"), j.direction("axis_b")
    c = np.cross(a, b)
    A_dirs = (a,) if O is j.A else (a, b, c)        # a bar carries only its own axis
    B_dirs = (b,) if O is j.B else (a, b, c)
    onA = dict(zip("abc" if len(A_dirs) == 3 else "a", (ctx.direction(j.A, d, j.label)[0] for d in A_dirs)))
    onB = dict(zip("abc" if len(B_dirs) == 3 else "b", (ctx.direction(j.B, d, j.label)[0] for d in B_dirs)))
    q, names = [], []
    if O is not j.A:                                  # θ_a needs A's b, c and B's b
        q.append(_atan2(ca.dot(onA["b"], onB["b"]), ca.dot(onA["c"], onB["b"])))
        names.append(f"{j.name}.theta_a")
    if O is not j.B:                                  # θ_b needs B's a, c and A's a
        q.append(_atan2(ca.dot(onB["a"], onA["a"]), ca.dot(onB["c"], onA["a"])))
        names.append(f"{j.name}.theta_b")
    q = ca.vertcat(*q)
    return JointCoordinates(j, q, _scalar_rates(ctx, q), names, names, [True] * len(names))


def _planar(ctx, j):
    C, O = _full_and_bar(j, "a Planar joint")
    at, n = j.at(), j.direction("normal")
    e1, e2 = perpendicular_basis(n)
    if O is None:
        rA, _ = ctx.point(j.A, at, j.label)
        rB, _ = ctx.point(j.B, at, j.label)
        d = rB - rA
        x = ca.dot(d, ctx.direction(j.A, e1, j.label)[0])
        y = ca.dot(d, ctx.direction(j.A, e2, j.label)[0])
        gx, gy = angle_gauge(ctx, j.A, j.B, n, j.label).terms(ctx)
        q = ca.vertcat(x, y, _atan2(gx, gy))
        names = [f"{j.name}.{k}" for k in ("x", "y", "theta")]
        return JointCoordinates(j, q, _scalar_rates(ctx, q), names, names, [False, False, True])
    R, o = member_frame(ctx, C, np.eye(3), at, j.label)
    near = ctx.nearest_point(O, at)
    d = ca.mtimes(R.T, ctx.point(O, near, j.label)[0] - o) - ca.DM(near - at)
    parts, names, angles = [ca.dot(d, ca.DM(e1)), ca.dot(d, ca.DM(e2))], ["x", "y"], [False, False]
    if not is_along(O, n):                            # a bar across the normal: its angle about it
        u0 = bar_axis(O)
        u = ca.mtimes(R.T, ctx.direction(O, u0, j.label)[0])
        p0 = u0 - (u0 @ n) * n
        up = u - ca.dot(u, ca.DM(n)) * ca.DM(n)
        parts.append(_atan2(ca.dot(ca.DM(p0), up), ca.dot(ca.DM(n), ca.cross(ca.DM(p0), up))))
        names.append("theta")
        angles.append(True)
    q = ca.vertcat(*parts)
    names = [f"{j.name}.{k}" for k in names]
    return JointCoordinates(j, q, _scalar_rates(ctx, q), names, names, angles)


def _spherical(ctx, j):
    C, O = _full_and_bar(j, "a Spherical joint")
    at = j.at()
    if O is None:
        R = _relative(ctx, j, (np.eye(3), at), (np.eye(3), at))[0]
        q = quaternion(R)
        w = _body_rate(ctx, R)
        names = [f"{j.name}.{k}" for k in ("qx", "qy", "qz", "qw")]
        rates = [f"{j.name}.{k}" for k in ("wx", "wy", "wz")]
        return JointCoordinates(j, q, w, names, rates, [False] * 4)
    R, _ = member_frame(ctx, C, np.eye(3), at, j.label)
    u0 = bar_axis(O)
    u = ca.mtimes(R.T, ctx.direction(O, u0, j.label)[0])
    q = swing(u0, u)
    names = [f"{j.name}.swing_1", f"{j.name}.swing_2"]
    return JointCoordinates(j, q, _scalar_rates(ctx, q), names, names, [False, False])


def swing(u0, u) -> ca.SX:
    """``[φ·e₁, φ·e₂]``, ``e₁, e₂ = perpendicular_basis(u0)``, of the rotation vector ``φ`` of
    the smallest rotation taking the unit ``u0`` to ``u``
    (:func:`ncgen.symbolic.rigid_motion.swing`: ``φ = (θ / sin θ)(u0 × u)``, a series near
    θ = 0 so that it and its derivatives stay smooth there)."""
    e1, e2 = perpendicular_basis(u0)
    phi = crm.swing(ca.DM(u0), u)
    return ca.vertcat(ca.dot(phi, ca.DM(e1)), ca.dot(phi, ca.DM(e2)))


def _free(ctx, j):
    _require_full(j, "a relative pose")
    d = ctx.dim
    frame_a = (np.eye(d), np.zeros(d)) if j.A.is_ground else (j.A.R0, j.A.p0)
    R, p = _relative(ctx, j, frame_a, (j.frame_rotation(), j.frame_origin()))
    pdot = ca.jtimes(p, ctx.q, ctx.v)
    v_lin = ca.mtimes(R.T, pdot)
    if d == 2:
        th = ca.atan2(R[1, 0], R[0, 0])
        q = ca.vertcat(p, th)
        v = ca.vertcat(v_lin, _scalar_rates(ctx, th))
        names = [f"{j.name}.{k}" for k in ("x", "y", "theta")]
        rates = [f"{j.name}.{k}" for k in ("vx", "vy", "w")]
        return JointCoordinates(j, q, v, names, rates, [False, False, True])
    q = ca.vertcat(p, quaternion(R))
    v = ca.vertcat(v_lin, _body_rate(ctx, R))
    names = [f"{j.name}.{k}" for k in ("x", "y", "z", "qx", "qy", "qz", "qw")]
    rates = [f"{j.name}.{k}" for k in ("vx", "vy", "vz", "wx", "wy", "wz")]
    return JointCoordinates(j, q, v, names, rates, [False] * 7)


def _sequence(ctx, j):
    q = j.coordinates(ctx)
    names = [f"{j.name}.{law.name}" for law in j.laws]
    return JointCoordinates(j, q, _scalar_rates(ctx, q), names, names, [law.kind == "Revolute" for law in j.laws])


_BUILDERS = {"Revolute": _revolute, "Prismatic": _prismatic, "Cylindrical": _cylindrical, "JointSequence": _sequence,
             "Universal": _universal, "Planar": _planar, "Spherical": _spherical, "Free": _free}


# ------------------------------------------------------------------ frames
def _full_and_bar(j, what: str):
    """``(C, O)``: the joint's full member (ground or body) and its 3D bar, or ``(None, None)``
    when both are full; :class:`ModelError` naming why there are no coordinates otherwise."""
    if is_full(j.A) and is_full(j.B):
        return None, None
    points = [name_of(m) for m in (j.A, j.B) if kind_of(m) == "point"]
    if points:
        raise ModelError(f"{j.label}: {points[0]} is a point member, which has no orientation, so {what} "
                         "with it has no joint coordinates (its point coincides and nothing else is measured)")
    if not is_full(j.A) and not is_full(j.B):
        raise ModelError(f"{j.label}: {what} between two bars has no joint coordinates: a bar has no spin "
                         "about its own axis, so only the angle between their axes is defined (with no "
                         "smooth rate where they align)")
    return (j.A, j.B) if is_full(j.A) else (j.B, j.A)


def _require_full(j, what: str):
    for m in (j.A, j.B):
        if not is_full(m):
            k = kind_of(m)
            raise ModelError(f"{j.label}: {name_of(m)} is a {k}, which does not carry {what} "
                             "(a bar's spin is not a coordinate); the joint has no joint coordinates")


def member_frame(ctx, m, R0, o0, label: str):
    """World rotation and origin (SX) of the frame fixed to ``m`` whose world axes and origin
    are ``R0``, ``o0`` in the initial configuration: ``R = R_m(q) R_m0ᵀ R0``."""
    if m.is_ground:
        return ca.DM(R0), ca.DM(np.asarray(o0, float))
    R = ca.mtimes(ctx.instantiate(m, "R"), ca.DM(m.R0.T @ R0))
    return R, ctx.point(m, o0, label)[0]


def _relative(ctx, j, frame_a, frame_b):
    """``(R, p)``: B's joint frame relative to A's, in A's frame axes."""
    Ra, oa = member_frame(ctx, j.A, *frame_a, j.label)
    Rb, ob = member_frame(ctx, j.B, *frame_b, j.label)
    return ca.mtimes(Ra.T, Rb), ca.mtimes(Ra.T, ob - oa)


def _body_rate(ctx, R) -> ca.SX:
    """ω in the moving frame's axes: the vee of ``Rᵀ Ṙ`` (skew part)."""
    Rdot = ca.reshape(ca.jtimes(ca.vec(R), ctx.q, ctx.v), 3, 3)
    S = ca.mtimes(R.T, Rdot)
    return 0.5 * ca.vertcat(S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1])


def quaternion(R) -> ca.SX:
    """Unit quaternion ``[qx, qy, qz, qw]`` (``qw ≥ 0``) of the rotation matrix ``R``
    (Shepperd's method, :func:`ncgen.symbolic.rigid_motion.quaternion`)."""
    return crm.quaternion(R)
