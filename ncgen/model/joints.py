"""Joints: constraint equations between two members (or a member and the ground).

A joint is given in world coordinates in the initial configuration (``at=`` a point,
``axis=`` a direction) and turned, at build time, into body-fixed points and directions
of each member (:class:`ncgen.assembly.context.Context`).  Its equations are joint
primitives (:mod:`ncgen.symbolic.joints`), so they are at most quadratic in q.

An optional ``drive`` prescribes the joint's relative motion as a function of time
(rheonomic constraint): a number, a CasADi expression of the system's symbols, or a
callable ``f(t)`` built from arithmetic and ``casadi`` functions.  For a revolute joint
it is the rotation angle (rad) about ``axis`` since the initial configuration.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.assembly.context import perpendicular_basis
from ncgen.model.members import Ground, Member, ModelError
from ncgen.validation import as_vector


class Joint:
    """Base class: two members, a name, world ``at``/``axis`` and an optional ``drive``."""

    kind = "Joint"

    def __init__(self, A, B, *, at=None, axis=None, name: str | None = None, drive=None):
        self.A, self.B = A, B
        self._at, self._axis = at, axis
        self.name = name
        self.drive = drive
        self.system = None

    # -------------------------------------------------------------- checks
    @property
    def label(self) -> str:
        return f"joint {self.name!r} ({self.kind} {_mname(self.A)}–{_mname(self.B)})"

    def attach(self, system, index: int):
        if self.system is not None:
            raise ModelError(f"{self.label}: already added to system {self.system.name!r}")
        self.name = self.name or f"{self.kind.lower()}_{index}"
        if not isinstance(self.name, str) or not self.name.isidentifier():
            raise ModelError(f"joint name: expected an identifier, got {self.name!r}")
        if any(j.name == self.name for j in system.joints):
            raise ModelError(f"{self.label}: the name is already used by another joint")
        for role, m in (("first", self.A), ("second", self.B)):
            if isinstance(m, Ground):
                continue
            if not isinstance(m, Member) or system.members.get(m.name) is not m:
                what = m.name if isinstance(m, Member) else repr(m)
                raise ModelError(f"{self.kind} joint {self.name!r}: the {role} member {what} is not a "
                                 f"member of system {system.name!r}")
        if self.A is self.B:
            raise ModelError(f"{self.label}: joins a member to itself")
        if self.A.is_ground and self.B.is_ground:
            raise ModelError(f"{self.label}: joins the ground to itself")
        self.system = system
        self.check(system)

    def check(self, system):
        """Validate the joint's own arguments (subclasses)."""

    def at(self) -> np.ndarray:
        if self._at is None:
            raise ModelError(f"{self.label}: at: expected a point, got nothing")
        return as_vector(self._at, self.system.dim, f"{self.label}: at")

    def axis(self) -> np.ndarray:
        if self._axis is None:
            raise ModelError(f"{self.label}: axis: expected a direction, got nothing")
        a = as_vector(self._axis, self.system.dim, f"{self.label}: axis")
        n = np.linalg.norm(a)
        if n < 1e-12:
            raise ModelError(f"{self.label}: axis: expected a non-zero direction, got {a.tolist()}")
        return a / n

    def drive_expr(self, ctx):
        """The drive as a CasADi expression of (t, p)."""
        d = self.drive
        if callable(d):
            d = d(ctx.t)
        try:
            return ca.SX(d)
        except (NotImplementedError, TypeError, RuntimeError):
            raise ModelError(f"{self.label}: drive: expected a number, a CasADi expression or a "
                             f"callable f(t), got {self.drive!r}") from None

    def equations(self, ctx) -> list[tuple[str, ca.SX]]:
        """``[(label, expression)]``; each expression vanishes when the joint is satisfied."""
        raise NotImplementedError

    def _coincidence(self, ctx, point):
        rA, _ = ctx.point(self.A, point, self.label)
        rB, _ = ctx.point(self.B, point, self.label)
        e = ctx.apply("coincidence", rA, rB)
        return [(f"{self.name}.coincide.{'xyz'[k]}", e[k]) for k in range(ctx.dim)]

    def __repr__(self) -> str:
        return f"<{self.label}>"


def _mname(m) -> str:
    return "ground" if m.is_ground else m.name


class Spherical(Joint):
    """Ball joint: the point ``at`` of both members coincides (3 equations).  Sharing a
    basic point between members (``ends=[other.end(1), ...]``) is the same joint with
    fewer coordinates."""

    kind = "Spherical"

    def __init__(self, A, B, *, at, name=None):
        super().__init__(A, B, at=at, name=name)

    def check(self, system):
        if system.dim != 3:
            raise ModelError(f"{self.label}: a planar system has no spherical joint; use Revolute")
        self.at()

    def equations(self, ctx):
        return self._coincidence(ctx, self.at())


class Revolute(Joint):
    """Hinge about ``axis`` through ``at``.  3D: coincidence (3) and axis alignment (2 for
    two bodies; 1 for a bar, which must not lie along the axis).  2D: coincidence (2).
    ``drive``: the rotation angle (rad) about ``axis`` since the initial configuration."""

    kind = "Revolute"

    def __init__(self, A, B, *, at, axis=None, name=None, drive=None):
        super().__init__(A, B, at=at, axis=axis, name=name, drive=drive)

    def check(self, system):
        self.at()
        if system.dim == 3:
            a = self.axis()
            for m in (self.A, self.B):
                if not m.is_ground and m.kind == "point":
                    raise ModelError(f"{self.label}: {m.name} is a point and has no orientation; use Spherical")
                if not m.is_ground and m.kind == "bar":
                    u = m.R0[:, 0]
                    if abs(abs(u @ a) - 1) < 1e-9:
                        raise ModelError(f"{self.label}: the axis lies along bar {m.name}; a bar cannot "
                                         "rotate about its own axis (that rotation is not a coordinate)")
            if all((not m.is_ground) and m.kind == "bar" for m in (self.A, self.B)):
                raise ModelError(f"{self.label}: neither bar carries the hinge axis; make one of them a "
                                 "body, or use Spherical joints (bars do not spin about their axis)")
        elif self._axis is not None and np.size(self._axis) not in (0, 3):
            raise ModelError(f"{self.label}: a planar revolute has no axis (it is ⟂ to the plane)")
        if self.drive is not None and system.dim == 3:
            if all((not m.is_ground) and m.kind != "body" for m in (self.A, self.B)):
                raise ModelError(f"{self.label}: a driven revolute needs a body or the ground on one side")

    def equations(self, ctx):
        eqs = self._coincidence(ctx, self.at())
        if ctx.dim == 3:
            eqs += self._alignment(ctx)
        if self.drive is not None:
            eqs.append((f"{self.name}.drive", self._drive(ctx)))
        return eqs

    def _alignment(self, ctx):
        a = self.axis()
        A, B = self.A, self.B
        if ctx.carries_direction(A, a) and not _is_bar(A):
            X, Y = A, B
        else:
            X, Y = B, A
        if _is_bar(Y):   # Y's axis keeps its angle to the hinge axis carried by X
            u0 = Y.R0[:, 0] * Y.local.Xbar[0, 0]
            aX, _ = ctx.direction(X, a, self.label)
            uY, _ = ctx.direction(Y, u0, self.label)
            return [(f"{self.name}.align", ctx.apply("dot", aX, uY, float(u0 @ a)))]
        aX, _ = ctx.direction(X, a, self.label)
        return [(f"{self.name}.align.{k + 1}", ctx.apply("dot", aX, n, 0.0)[0])
                for k, n in enumerate(ctx.perpendiculars(Y, a, self.label))]

    def _drive(self, ctx):
        theta = self.drive_expr(ctx)
        A, B = self.A, self.B
        if ctx.dim == 2:
            wA = _reference_direction(A)
            wB = _reference_direction(B) if _is_bar(B) else wA
            a, _ = ctx.direction(A, wA, self.label)
            m1, _ = ctx.direction(B, wB, self.label)
            theta0 = float(np.arctan2(wA[0] * wB[1] - wA[1] * wB[0], wA @ wB))
            return ctx.apply("angle", a, m1, theta + theta0)[0]
        axis = self.axis()
        sign = 1.0
        if _is_bar(B) or (B.kind == "point" if not B.is_ground else False):
            A, B, sign = B, A, -1.0
        wA = A.R0[:, 0] if _is_bar(A) else perpendicular_basis(axis)[0]
        wA = wA - (wA @ axis) * axis
        wA /= np.linalg.norm(wA)
        a, _ = ctx.direction(A, wA * (A.local.Xbar[0, 0] if _is_bar(A) else 1.0), self.label)
        m1, _ = ctx.direction(B, wA, self.label)
        m2, _ = ctx.direction(B, np.cross(axis, wA), self.label)
        return ctx.apply("angle", a, m1, m2, sign * theta)[0]


def _is_bar(m) -> bool:
    return (not m.is_ground) and m.kind == "bar"


def _reference_direction(m) -> np.ndarray:
    """A direction the member carries: a bar's axis, else the world x axis."""
    if _is_bar(m):
        return m.R0[:, 0] * m.local.Xbar[0, 0]
    return np.eye(m.dim if not m.is_ground else 2)[0]
