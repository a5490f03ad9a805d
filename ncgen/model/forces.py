"""Force elements: generalised forces ``Q(t, q, v, u, p)`` and their potential energies.

Gravity is built in (``System(gravity=...)``).  Values that may vary (a force vector, a
stiffness) are numbers, text expressions such as ``"k*sin(t)"``, CasADi expressions of the
system's inputs and parameters, or callables ``f(t)`` returning such values
(:mod:`ncgen.model.expressions`).  Points on members are given in the member's local frame
(``(0.5, 0, 0)`` is the free end of a unit bar); the ground's in the world frame.
Units: N, N·m, N/m, N·s/m, N·m/rad, N·m·s/rad.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.errors import BasisError
from ncgen.errors import ModelError
from ncgen.model.expressions import ExpressionError
from ncgen.model.joint_base import attach_element, check_members
from ncgen.model.members import model_name
from ncgen.validation import as_scalar, as_vector


def spring_tension(length, rate, k, rest_length, damping):
    """Tension ``T = k (l − l₀) + c l̇`` (N) of a linear spring-damper of length ``l`` (m)
    stretching at ``l̇`` (m/s): the one formula of :class:`Spring` (and of the spring kernel
    of the element tables, :mod:`ncgen.codegen.element_kernels`)."""
    return k * (length - rest_length) + damping * rate


def spring_energy(stretch, k):
    """Potential energy ``½ k s²`` (J) of a linear spring stretched by ``s = l − l₀`` (m)."""
    return 0.5 * k * stretch**2


def cable_tension(length, rate, k, rest_length, damping):
    """Tension (N) of a cable (a :class:`Spring` with ``cable=True``): the spring-damper's
    :func:`spring_tension`, kept ≥ 0 (slack in compression)."""
    return ca.fmax(spring_tension(length, rate, k, rest_length, damping), 0)


def cable_energy(stretch, k):
    """Potential energy (J) of a cable stretched by ``s = l − l₀`` (m): ``½ k s²`` while taut
    (``s > 0``), 0 while slack."""
    return ca.if_else(stretch > 0, spring_energy(stretch, k), 0)


def torsion_deflection(x, y, rest_angle):
    """``δ = atan2(y, x) − rest_angle`` wrapped to (−π, π] (rad), of an angle given by the
    terms ``(x, y)`` of its gauge (:class:`TorsionalSpring`)."""
    c, s = ca.cos(rest_angle), ca.sin(rest_angle)
    return ca.atan2(y * c - x * s, x * c + y * s)


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
        """Called by ``System.add_force``: name, membership and argument checks."""
        def validate():
            check_members(self.members(), system, self.label)
            self.system = system
            self.check(system)
            self._check_nonnegative()

        attach_element(self, system, index, system.forces, "force", lambda n: model_name(n, "force name"), validate)

    def members(self) -> list:
        return []

    def check(self, system):
        """Validate arguments (subclasses)."""

    def nonnegative(self) -> dict:
        """Values that must be >= 0 (name -> value): numbers are checked when the force is
        added, expressions of parameters when the model is built (:mod:`ncgen.assembly.limits`)."""
        return {}

    def _check_nonnegative(self) -> None:
        for key, value in self.nonnegative().items():
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
                continue
            v = as_scalar(value, f"{self.label}: {key}")
            if v < 0:
                raise ModelError(f"{self.label}: {key}: expected a number >= 0, got {v:g}")

    def generalized(self, ctx) -> ca.SX:
        """``Q`` as an nq-vector expression."""
        raise NotImplementedError

    def potential(self, ctx) -> ca.SX:
        """Potential energy (J) of a conservative part, 0 otherwise."""
        return ca.SX(0)

    def _value(self, ctx, value, shape: int, what: str, *, inputs: bool = True) -> ca.SX:
        """A value of this force (:mod:`ncgen.model.expressions`) as an SX column."""
        return ctx.expression(value, shape, f"{self.label}: {what}", inputs=inputs)

    def _local_point(self, member, at, what: str) -> np.ndarray:
        """Check that ``member`` carries the local point ``at`` (``what`` names the argument)."""
        x = as_vector(at, member.dim, f"{self.label}: {what}")
        if not member.is_ground:
            try:
                member.rigid.affine(x)
            except BasisError as e:
                raise ModelError(f"{self.label}: {what} on {member.name} ({member.ctype.name} "
                                 f"{member.kind}): {e}") from None
        return x

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
        self._local_point(self.member, self.at, "at")

    def generalized(self, ctx):
        f = self._value(ctx, self.force, ctx.dim, "force")
        C = ca.DM(self.member.rigid.C(self.member.rigid.affine(np.asarray(self.at, float))))
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
        W = ctx.instantiate(self.member, "W")
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
            self._local_point(m, at, w)
        if self.a is self.b:
            raise ModelError(f"{self.label}: both ends on the same member exert no force")

    def nonnegative(self) -> dict:
        return {"k": self.k, "damping": self.damping, "rest_length": self.rest_length}

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
        return (cable_tension if self.cable else spring_tension)(length, rate, k, l0, c)

    def generalized(self, ctx):
        _, _, d, length, _ = self._geometry(ctx)
        f_b = -self.tension(ctx) * d / length        # force on b, pulling it towards a
        Q = ca.SX.zeros(ctx.layout.nq)
        for m, at, f in ((self.a, self.at_a, -f_b), (self.b, self.at_b, f_b)):
            if not m.is_ground:
                C = ca.DM(m.rigid.C(m.rigid.affine(np.asarray(at, float))))
                Q += ctx.scatter(m, ca.mtimes(C.T, f))
        return Q

    def potential(self, ctx):
        """``½ k (l − l₀)²`` (a cable's while taut); 0 when ``k`` or ``l₀`` depend on inputs
        (an actuated spring or cable does work on the system: not a conservative force)."""
        _, _, _, length, _ = self._geometry(ctx)
        try:
            k = self._value(ctx, self.k, 1, "k (in the potential energy)", inputs=False)
            l0 = self._value(ctx, self.rest_length, 1, "rest_length (in the potential energy)", inputs=False)
        except ExpressionError:          # tension() has accepted them with the inputs
            return ca.SX(0)
        return (cable_energy if self.cable else spring_energy)(length - l0, k)


class TorsionalSpring(Force):
    """Torsional spring-damper on a :class:`~ncgen.model.joints.Revolute` joint: the torque
    ``τ = −k δ − c θ̇`` (N·m) about the hinge axis on B and ``−τ`` on A, where θ is the
    rotation of B relative to A since the initial configuration and
    ``δ = θ − rest_angle`` wrapped to (−π, π].

    The angle is measured from body-fixed directions, ``θ = atan2(y, x)``
    (:class:`~ncgen.model.joint_equations.AngleGauge`), and the generalised force is the
    virtual work of the torque pair, ``Q = −(k δ + c θ̇) ∂θ/∂q`` with ``θ̇ = (∂θ/∂q) v``:
    exact for bars across the axis too, and internal (no net torque on the system).
    ``coordinate``: on a :class:`~ncgen.model.joints.JointSequence`, the index of the hinge
    whose angle θ is (its ``atan2`` terms, :meth:`~ncgen.model.joints.JointSequence.terms`)."""

    kind = "TorsionalSpring"

    def __init__(self, joint, *, k, damping=0.0, rest_angle=0.0, coordinate=None, name: str | None = None):
        super().__init__(name)
        self.joint, self.k, self.damping, self.rest_angle = joint, k, damping, rest_angle
        self.coordinate = coordinate

    def members(self):
        from ncgen.model.joints import JointSequence, Revolute
        if self.coordinate is None and not isinstance(self.joint, Revolute):
            raise ModelError(f"{self.label}: joint: expected a Revolute joint (or a JointSequence with "
                             f"coordinate=), got {self.joint!r}")
        if self.coordinate is not None:
            laws = getattr(self.joint, "laws", [])
            k = self.coordinate
            if not isinstance(self.joint, JointSequence) or not isinstance(k, int) or not 0 <= k < len(laws) \
                    or laws[k].kind != "Revolute":
                raise ModelError(f"{self.label}: coordinate={k!r}: expected the index of a hinge of a "
                                 f"JointSequence, got joint {self.joint!r}")
        return self.joint.members()

    def check(self, system):
        if self.joint.system is not system:
            raise ModelError(f"{self.label}: {self.joint.label} is not a joint of system {system.name!r}; "
                             "add it with add_joint first")
        from ncgen.model.context import Context
        self._terms(Context.of_members(system, self.joint.members()))

    def nonnegative(self) -> dict:
        return {"k": self.k, "damping": self.damping}

    def _terms(self, ctx):
        """``(x, y)`` with ``θ = atan2(y, x)``."""
        if self.coordinate is None:
            return self.joint.gauge(ctx).terms(ctx)
        return self.joint.terms(ctx)[self.coordinate]

    def deflection(self, ctx) -> ca.SX:
        """``δ = θ − rest_angle`` in (−π, π] (rad)."""
        x, y = self._terms(ctx)
        return torsion_deflection(x, y, self._value(ctx, self.rest_angle, 1, "rest_angle", inputs=False))

    def generalized(self, ctx):
        delta = self.deflection(ctx)
        k = self._value(ctx, self.k, 1, "k")
        c = self._value(ctx, self.damping, 1, "damping")
        rate = ca.jtimes(delta, ctx.q, ctx.v)
        return -(k * delta + c * rate) * ca.gradient(delta, ctx.q)

    def potential(self, ctx):
        k = self._value(ctx, self.k, 1, "k (in the potential energy)", inputs=False)
        return 0.5 * k * self.deflection(ctx) ** 2


class GeneralizedForce(Force):
    """A generalised force ``Q`` given directly (nq components, in the system's coordinate
    order, ``model.coordinate_names``): a sequence of nq values (numbers or text over ``t``,
    ``q``, ``v``, the inputs and parameters), a CasADi SX column of the inputs and
    parameters, or a callable ``f(t, q, v, u, p)`` returning an nq-vector SX expression."""

    kind = "GeneralizedForce"

    def __init__(self, value, *, name: str | None = None):
        super().__init__(name)
        self.value = value

    def generalized(self, ctx):
        return ctx.expression(self.value, ctx.layout.nq, f"{self.label}: value", state=True,
                              call=lambda f: f(ctx.t, ctx.q, ctx.v, ctx.u, ctx.p))


FORCE_TYPES: dict[str, type[Force]] = {cls.kind: cls for cls in (
    PointForce, Torque, Spring, TorsionalSpring, GeneralizedForce)}
