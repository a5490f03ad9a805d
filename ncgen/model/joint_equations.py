"""The geometric building blocks joints are made of, written with the joint primitives.

Every function returns ``[(label, expression)]`` with expressions that vanish when the
condition holds.  Geometry is given in world coordinates in the initial configuration and
turned into body-fixed points and directions by the :class:`~ncgen.model.context.Context`
(linear in q), so each equation is at most quadratic in q.

What a member can carry (3D): the ground and a body carry every point and direction; a bar
carries the points of its axis and the direction of its axis only (its spin is not a
coordinate); a point member carries its own position.  In planar systems a bar carries every
direction as well.  A member that carries every direction is called *full* below.

Conventions: ``label`` names the joint in error messages; ``prefix`` starts each equation's
name (``"hinge.align"`` gives ``hinge.align.1``, ...).
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ncgen.errors import ModelError
from ncgen.reproducible import dot, norm, perpendicular_basis

#: |cos| above which a bar counts as lying along a direction.
ALONG_TOL = 1e-9

Equations = list[tuple[str, ca.SX]]


# --------------------------------------------------------------------- members
def kind_of(m) -> str:
    """``"ground"``, ``"body"``, ``"bar"`` or ``"point"``."""
    return "ground" if m.is_ground else m.kind


def name_of(m) -> str:
    return "ground" if m.is_ground else m.name


def is_full(m) -> bool:
    """Whether ``m`` carries every direction (ground, body, planar bar)."""
    k = kind_of(m)
    return k in ("ground", "body") or (k == "bar" and m.dim == 2)


def bar_axis(m) -> np.ndarray:
    """Unit axis of bar ``m`` in the initial configuration (first end to second)."""
    return m.R0[:, 0].copy()


def is_along(m, direction) -> bool:
    """Whether ``m`` is a bar lying along ``direction`` (a unit vector)."""
    return kind_of(m) == "bar" and abs(abs(dot(bar_axis(m), direction)) - 1.0) < ALONG_TOL


def require_orientation(label: str, *members) -> None:
    for m in members:
        if kind_of(m) == "point":
            raise ModelError(f"{label}: {m.name} is a point member and has no orientation; "
                             "use a joint that only constrains points (Spherical, Distance, "
                             "PointOnLine, PointOnPlane), or make it a body")


def _bar_u(ctx, m, label):
    """The bar's axis vector ``u`` (its full length) and its initial value."""
    u0 = bar_axis(m) * m.rigid.Xbar[0, 0]
    return ctx.direction(m, u0, label)[0], u0


def _dot(ctx, a, b, value: float):
    return ctx.apply("dot", a, b, float(value))[0]


def _names(prefix: str, eqs: list) -> Equations:
    if len(eqs) == 1:
        return [(prefix, eqs[0])]
    return [(f"{prefix}.{k + 1}", e) for k, e in enumerate(eqs)]


# ----------------------------------------------------------------- conditions
def coincidence(ctx, A, B, at, label: str, prefix: str) -> Equations:
    """The points of ``A`` and ``B`` at ``at`` coincide (dim equations)."""
    rA, _ = ctx.point(A, at, label)
    rB, _ = ctx.point(B, at, label)
    e = ctx.apply("coincidence", rA, rB)
    return [(f"{prefix}.{'xyz'[k]}", e[k]) for k in range(ctx.dim)]


def distance(ctx, A, at_a, B, at_b, length, label: str, prefix: str) -> Equations:
    """``|r_B − r_A| = length`` (1 equation); ``length`` may be an expression."""
    rA, _ = ctx.point(A, at_a, label)
    rB, _ = ctx.point(B, at_b, label)
    return [(prefix, ctx.apply("distance", rA, rB, length)[0])]


def point_on_line(ctx, C, O, at_c, at_o, axis, label: str, prefix: str) -> Equations:
    """The point of ``O`` at ``at_o`` keeps its offset from the line of ``C`` through
    ``at_c`` along ``axis``, measured ⟂ to the line (dim − 1 equations; zero offset when the
    point starts on the line).  ``C`` must be full: it carries the perpendiculars."""
    if not is_full(C):
        raise ModelError(f"{label}: the line must be carried by the ground or a body"
                         f"{' (or a bar in a planar system)' if ctx.dim == 3 else ''}; "
                         f"{name_of(C)} is a {kind_of(C)}, whose directions ⟂ to its axis are not "
                         "coordinates")
    rC, _ = ctx.point(C, at_c, label)
    rO, _ = ctx.point(O, at_o, label)
    gap = np.asarray(at_o, float) - np.asarray(at_c, float)
    eqs = []
    for n in perpendicular_basis(axis):
        nC, _ = ctx.direction(C, n, label)
        eqs.append(ctx.apply("offset_dot", rC, rO, nC, dot(n, gap))[0])
    return _names(prefix, eqs)


def point_on_plane(ctx, C, O, at_c, at_o, normal, label: str, prefix: str) -> Equations:
    """The point of ``O`` at ``at_o`` keeps its offset along ``normal`` from the plane of
    ``C`` through ``at_c`` (1 equation).  ``C`` carries the normal: full, or a bar along it."""
    if not ctx.carries_direction(C, normal):
        raise ModelError(f"{label}: the plane normal {np.round(normal, 12).tolist()} must be carried "
                         f"by the ground, a body or a bar along it; {name_of(C)} is a {kind_of(C)}"
                         + (" not along it" if kind_of(C) == "bar" else ""))
    rC, _ = ctx.point(C, at_c, label)
    rO, _ = ctx.point(O, at_o, label)
    nC, _ = ctx.direction(C, normal, label)
    gap = np.asarray(at_o, float) - np.asarray(at_c, float)
    return [(prefix, ctx.apply("offset_dot", rC, rO, nC, dot(normal, gap))[0])]


def align_axis(ctx, A, B, axis, label: str, prefix: str) -> Equations:
    """3D: ``A`` and ``B`` keep a common axis direction but may rotate about it.

    Both full: ``a_A · n_B,k = 0`` for B's two directions ⟂ axis (2).  A full member F and a
    bar Y along the axis: ``n_F,k · u_Y = 0`` (2).  F and a bar Y across the axis:
    ``a_F · u_Y`` constant (1).  A bar X along the axis and a bar Y across it:
    ``u_X · u_Y`` constant (1)."""
    require_orientation(label, A, B)
    if is_full(A) and is_full(B):
        aA, _ = ctx.direction(A, axis, label)
        return _names(prefix, [_dot(ctx, aA, n, 0.0) for n in ctx.perpendiculars(B, axis, label)])
    if is_full(A) or is_full(B):
        F, Y = (A, B) if is_full(A) else (B, A)
        uY, u0 = _bar_u(ctx, Y, label)
        if is_along(Y, axis):
            return _names(prefix, [_dot(ctx, n, uY, 0.0) for n in ctx.perpendiculars(F, axis, label)])
        aF, _ = ctx.direction(F, axis, label)
        return _names(prefix, [_dot(ctx, aF, uY, dot(axis, u0))])
    along = [m for m in (A, B) if is_along(m, axis)]
    if len(along) != 1:
        why = "both lie along it" if along else "neither lies along it"
        raise ModelError(f"{label}: two bars cannot share the axis {np.round(axis, 12).tolist()} ({why}; "
                         "a bar carries only its own axis direction); make one of them a body")
    X = along[0]
    Y = B if X is A else A
    uX, uX0 = _bar_u(ctx, X, label)
    uY, uY0 = _bar_u(ctx, Y, label)
    return _names(prefix, [_dot(ctx, uX, uY, dot(uX0, uY0))])


def lock_orientation(ctx, A, B, label: str, prefix: str) -> Equations:
    """No relative rotation.  3D full–full: ``e_i,A · e_j,B = 0`` for (i, j) = (1, 2),
    (1, 3), (2, 3) with the world axes ``e`` of the initial configuration (3).  3D full F and
    a bar Y: ``n_F,k · u_Y = 0`` for two directions ⟂ the bar (2).  Planar:
    ``e_y,A · e_x,B = 0`` (1)."""
    require_orientation(label, A, B)
    E = np.eye(ctx.dim)
    if ctx.dim == 2:
        ey, _ = ctx.direction(A, E[1], label)
        ex, _ = ctx.direction(B, E[0], label)
        return _names(prefix, [_dot(ctx, ey, ex, 0.0)])
    if is_full(A) and is_full(B):
        dA = [ctx.direction(A, e, label)[0] for e in E]
        dB = [ctx.direction(B, e, label)[0] for e in E]
        return _names(prefix, [_dot(ctx, dA[i], dB[j], 0.0) for i, j in ((0, 1), (0, 2), (1, 2))])
    if is_full(A) or is_full(B):
        F, Y = (A, B) if is_full(A) else (B, A)
        uY, u0 = _bar_u(ctx, Y, label)
        return _names(prefix, [_dot(ctx, ctx.direction(F, n, label)[0], uY, 0.0)
                               for n in perpendicular_basis(u0)])
    raise ModelError(f"{label}: the relative orientation of two bars is not a coordinate (a bar "
                     "does not carry directions ⟂ to its axis); make one of them a body, or join "
                     "collinear bars into one")


# ------------------------------------------------------------- relative angle
@dataclass
class AngleGauge:
    """Measures the rotation ``θ`` of ``B`` relative to ``A`` about an axis since the
    initial configuration (rad, right-handed about the axis) from body-fixed directions.

    3D: a full side F carries ``m1`` (⟂ axis) and ``m2 = axis × m1``; the other side carries
    ``b`` (``m1``'s initial direction, or a bar's axis whose projection ⟂ the axis points
    along ``m1``); ``sign`` is +1 when F is A.  Planar: A carries ``a`` and ``a_perp``
    (world x and y initially), B carries ``b`` (world x initially).
    """

    dim: int
    b: ca.SX
    m1: ca.SX
    m2: ca.SX
    sign: float

    def terms(self, ctx):
        """``(x, y)`` with ``θ = atan2(y, x)``; initially ``y = 0 < x``."""
        x = _dot(ctx, self.m1, self.b, 0.0)
        y = _dot(ctx, self.m2, self.b, 0.0)
        return x, self.sign * y

    def equation(self, ctx, theta) -> ca.SX:
        """Vanishes when the relative angle is ``theta`` (the ``angle`` primitive)."""
        if self.dim == 2:
            return ctx.apply("angle", self.m1, self.b, theta)[0]
        return ctx.apply("angle", self.b, self.m1, self.m2, -self.sign * theta)[0]


def angle_gauge(ctx, A, B, axis, label: str) -> AngleGauge:
    """The :class:`AngleGauge` of ``B`` relative to ``A`` (``axis`` ignored in 2D)."""
    require_orientation(label, A, B)
    if ctx.dim == 2:
        E = np.eye(2)
        return AngleGauge(2, ctx.direction(B, E[0], label)[0], ctx.direction(A, E[0], label)[0],
                          ctx.direction(A, E[1], label)[0], 1.0)
    if is_full(A):
        F, O, sign = A, B, 1.0
    elif is_full(B):
        F, O, sign = B, A, -1.0
    else:
        raise ModelError(f"{label}: measuring a rotation about the axis needs the ground or a body "
                         "on one side; bars do not carry directions ⟂ to their axis")
    if is_full(O):
        e1 = perpendicular_basis(axis)[0]
        b, _ = ctx.direction(O, e1, label)
    else:
        b, u0 = _bar_u(ctx, O, label)
        e1 = u0 - dot(u0, axis) * axis
        if norm(e1) < 1e-9 * norm(u0):
            raise ModelError(f"{label}: bar {O.name} lies along the axis; its rotation about it is "
                             "not a coordinate")
        e1 = e1 / norm(e1)
    m1, _ = ctx.direction(F, e1, label)
    m2, _ = ctx.direction(F, np.cross(axis, e1), label)
    return AngleGauge(3, b, m1, m2, sign)
