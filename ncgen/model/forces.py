"""Force elements: generalised forces ``Q(t, q, v, u, p)`` and their potential energies.

Gravity is built in (``System(gravity=...)``).  Values that may vary (a force vector, a
stiffness) are numbers, CasADi expressions of the system's inputs and parameters, or
callables ``f(t)`` returning such expressions.  Points on members are given in the
member's local frame (``(0.5, 0, 0)`` is the free end of a unit bar).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.model.members import Ground, Member, ModelError
from ncgen.validation import as_vector


class Force:
    """Base class of force elements."""

    kind = "Force"

    def __init__(self, name: str | None = None):
        self.name = name
        self.system = None

    @property
    def label(self) -> str:
        return f"force {self.name!r} ({self.kind})"

    def attach(self, system, index: int):
        if self.system is not None:
            raise ModelError(f"{self.label}: already added to system {self.system.name!r}")
        self.name = self.name or f"{self.kind.lower()}_{index}"
        if any(f.name == self.name for f in system.forces):
            raise ModelError(f"{self.label}: the name is already used by another force")
        for m in self.members():
            if isinstance(m, Ground):
                continue
            if not isinstance(m, Member) or system.members.get(m.name) is not m:
                what = m.name if isinstance(m, Member) else repr(m)
                raise ModelError(f"{self.label}: {what} is not a member of system {system.name!r}")
        self.system = system
        self.check(system)

    def members(self) -> list:
        return []

    def check(self, system):
        """Validate arguments (subclasses)."""

    def generalized(self, ctx) -> ca.SX:
        """``Q`` as an nq-vector expression."""
        raise NotImplementedError

    def potential(self, ctx) -> ca.SX:
        """Potential energy (J) of a conservative part, 0 otherwise."""
        return ca.SX(0)

    def _value(self, ctx, value, shape: int, what: str) -> ca.SX:
        v = value(ctx.t) if callable(value) else value
        try:
            v = ca.SX(v) if not isinstance(v, (ca.SX, ca.MX)) else v
        except (NotImplementedError, TypeError, RuntimeError):
            raise ModelError(f"{self.label}: {what}: expected numbers, a CasADi expression or a "
                             f"callable f(t), got {value!r}") from None
        if isinstance(v, ca.MX):
            raise ModelError(f"{self.label}: {what}: MX expressions are not supported; use SX symbols")
        v = ca.reshape(v, v.numel(), 1) if v.numel() == shape else v
        if v.shape != (shape, 1):
            raise ModelError(f"{self.label}: {what}: expected {shape} component(s), got shape {v.shape}")
        return v

    def __repr__(self) -> str:
        return f"<{self.label}>"


class PointForce(Force):
    """A force (world axes, N) at a body-fixed point ``at`` (local coordinates)."""

    kind = "PointForce"

    def __init__(self, member, at, force, name: str | None = None):
        super().__init__(name)
        self.member, self.at, self.force = member, at, force

    def members(self):
        return [self.member]

    def check(self, system):
        if self.member.is_ground:
            raise ModelError(f"{self.label}: a force on the ground does nothing")
        at = as_vector(self.at, system.dim, f"{self.label}: at")
        self.member.local.affine(at)

    def generalized(self, ctx):
        f = self._value(ctx, self.force, ctx.dim, "force")
        C = ca.DM(self.member.local.C(self.member.local.affine(np.asarray(self.at, float))))
        return ctx.scatter(self.member, ca.mtimes(C.T, f))


class Torque(Force):
    """A pure couple (world axes, N·m; a scalar in planar systems) on a body or bar; on a
    bar only its part normal to the axis acts."""

    kind = "Torque"

    def __init__(self, member, torque, name: str | None = None):
        super().__init__(name)
        self.member, self.torque = member, torque

    def members(self):
        return [self.member]

    def check(self, system):
        if self.member.is_ground or self.member.kind == "point":
            raise ModelError(f"{self.label}: a torque needs a body or a bar, got {self.member!r}")

    def generalized(self, ctx):
        n = 3 if ctx.dim == 3 else 1
        tau = self._value(ctx, self.torque, n, "torque")
        W = ctx.instantiate(self.member, self.member.ctype.derivation.W)
        return ctx.scatter(self.member, ca.mtimes(W.T, tau))


class Spring(Force):
    """Linear spring-damper between point ``at_a`` of ``a`` and ``at_b`` of ``b`` (local
    coordinates; the ground's are world coordinates).  Tension ``k (l − l₀) + c l̇`` (N)
    along the line; ``cable=True`` keeps only positive tension (slack in compression)."""

    kind = "Spring"

    def __init__(self, a, at_a, b, at_b, *, k, rest_length=0.0, damping=0.0, cable=False,
                 name: str | None = None):
        super().__init__(name)
        self.a, self.at_a, self.b, self.at_b = a, at_a, b, at_b
        self.k, self.rest_length, self.damping, self.cable = k, rest_length, damping, bool(cable)

    def members(self):
        return [self.a, self.b]

    def check(self, system):
        for m, at, w in ((self.a, self.at_a, "at_a"), (self.b, self.at_b, "at_b")):
            x = as_vector(at, system.dim, f"{self.label}: {w}")
            if not m.is_ground:
                m.local.affine(x)
        if self.a is self.b:
            raise ModelError(f"{self.label}: both ends on the same member exert no force")

    def _end(self, ctx, m, at):
        at = np.asarray(at, float)
        if m.is_ground:
            return ca.DM(at), ca.DM.zeros(ctx.dim)
        return ctx.local_point(m, at)

    def _geometry(self, ctx):
        ra, va = self._end(ctx, self.a, self.at_a)
        rb, vb = self._end(ctx, self.b, self.at_b)
        d = rb - ra
        length = ca.sqrt(ca.sumsqr(d))
        rate = ca.dot(d, vb - va) / length
        return ra, rb, d, length, rate

    def tension(self, ctx) -> ca.SX:
        _, _, _, length, rate = self._geometry(ctx)
        k = self._value(ctx, self.k, 1, "k")
        l0 = self._value(ctx, self.rest_length, 1, "rest_length")
        c = self._value(ctx, self.damping, 1, "damping")
        T = k * (length - l0) + c * rate
        return ca.fmax(T, 0) if self.cable else T

    def generalized(self, ctx):
        _, _, d, length, _ = self._geometry(ctx)
        f_b = -self.tension(ctx) * d / length        # force on b, pulling it towards a
        Q = ca.SX.zeros(ctx.layout.nq)
        for m, at, f in ((self.a, self.at_a, -f_b), (self.b, self.at_b, f_b)):
            if not m.is_ground:
                C = ca.DM(m.local.C(m.local.affine(np.asarray(at, float))))
                Q += ctx.scatter(m, ca.mtimes(C.T, f))
        return Q

    def potential(self, ctx):
        _, _, _, length, _ = self._geometry(ctx)
        k = self._value(ctx, self.k, 1, "k")
        l0 = self._value(ctx, self.rest_length, 1, "rest_length")
        stretch = length - l0
        V = 0.5 * k * stretch**2
        return ca.if_else(stretch > 0, V, 0) if self.cable else V
