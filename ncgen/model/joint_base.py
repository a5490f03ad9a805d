"""The :class:`Joint` base class: membership and name checks, geometry arguments, drives.

A joint is given in world coordinates in the initial configuration (``at=`` a point,
``axis=`` a direction) and turned, at build time, into body-fixed points and directions of
each member through the :class:`~ncgen.model.context.Context`.  Its equations come from
:mod:`ncgen.model.joint_equations`, so they are at most quadratic in q.

Adding a joint to a system checks it at once: the members belong to the system, the
arguments have the right shapes, and its geometry can be expressed with the members'
coordinates (a bar carries points on its axis and its own direction only, a point member
has no orientation).  Drives (prescribed relative motion, :attr:`Joint.drive`) are
evaluated at build time, when every parameter is known.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.errors import ModelError
from ncgen.model.joint_equations import name_of
from ncgen.model.members import Ground, Member, model_name
from ncgen.reproducible import norm
from ncgen.validation import as_vector


class Joint:
    """Base class: members, a name, world geometry ``options`` and an optional ``drive``.

    Subclasses set :attr:`kind`, store their constructor keywords in ``options`` (the TOML
    writer reads them back) and implement :meth:`geometry` (and :meth:`drive_equations`
    when they can be driven)."""

    kind = "Joint"
    #: What a drive prescribes (drivable joints only), for messages.
    drive_meaning: str | None = None

    def __init__(self, A, B, *, name: str | None = None, **options):
        self.A, self.B = A, B
        self.name = name
        self.options = options
        self.system = None
        #: Limits (``lower``, ``upper``, ``velocity``, ``effort``; SI units), e.g. from a URDF
        #: ``<limit>``: bounds in optimal control; ``lower``/``upper`` act in simulation when
        #: asked (``simulate(joint_dynamics=True)``, :mod:`ncgen.model.joint_dynamics`).
        self.limits: dict[str, float] = {}
        #: Joint dynamics (``damping``, ``friction``, ``armature``, limit law ``limit_stiffness``,
        #: ``limit_damping``, ``friction_velocity``), e.g. from a URDF ``<dynamics>``; set with
        #: :meth:`set_dynamics` (checked), see :mod:`ncgen.model.joint_dynamics`.
        self.dynamics: dict[str, float] = {}

    def set_dynamics(self, **values) -> "Joint":
        """Set joint dynamics and limits: ``damping`` (N·m·s/rad or N·s/m), ``friction``
        (N·m or N), ``armature`` (kg·m² or kg), ``lower``/``upper`` (rad or m), ``limit_stiffness``, ``limit_damping``,
        ``friction_velocity`` (see :mod:`ncgen.model.joint_dynamics`).  Returns the joint."""
        from ncgen.model.joint_dynamics import set_joint_dynamics
        set_joint_dynamics(self, values)
        return self

    # -------------------------------------------------------------- identity
    def members(self) -> list:
        return [self.A, self.B]

    @property
    def label(self) -> str:
        who = "–".join(name_of(m) if isinstance(m, (Member, Ground)) else repr(m) for m in self.members())
        return f"joint {self.name!r} ({self.kind} {who})"

    @property
    def drive(self):
        return self.options.get("drive")

    def attach(self, system, index: int):
        """Called by ``System.add_joint``: name, membership and geometry checks."""
        def validate():
            check_members(self.members(), system, f"{self.kind} joint {self.name!r}")
            ms = self.members()
            if len(ms) == 2 and ms[0] is ms[1]:
                raise ModelError(f"{self.label}: joins {'the ground' if ms[0].is_ground else 'a member'} "
                                 "to itself")
            self.system = system
            self.check(system)

        attach_element(self, system, index, system.joints, "joint", lambda n: model_name(n, "joint name"), validate)

    def check(self, system):
        """Validate the arguments and the geometry by writing the equations once, in a
        context of the joint's members (:meth:`~ncgen.model.context.Context.of_members`)."""
        from ncgen.model.context import Context
        self.geometry(Context.of_members(system, self.members()))

    # ------------------------------------------------------------- equations
    def equations(self, ctx) -> list[tuple[str, ca.SX]]:
        """``[(label, expression)]``; each expression vanishes when the joint holds."""
        eqs = self.geometry(ctx)
        if self.drive is not None:
            eqs = eqs + self.drive_equations(ctx)
        return eqs

    def geometry(self, ctx) -> list[tuple[str, ca.SX]]:
        raise NotImplementedError

    def drive_equations(self, ctx) -> list[tuple[str, ca.SX]]:
        raise NotImplementedError

    def drive_expr(self, ctx) -> ca.SX:
        """The drive as a scalar CasADi expression of t and the parameters (passed through
        ``ctx.drive_blend[name]`` where the assembly continues it from the measured value)."""
        expr = ctx.expression(self.drive, 1, f"{self.label}: drive ({self.drive_meaning})", inputs=False)
        blend = ctx.drive_blend.get(self.name)
        return expr if blend is None else blend(expr)

    # ------------------------------------------------------------- arguments
    def vector(self, key: str) -> np.ndarray:
        value = self.options.get(key)
        if value is None:
            raise ModelError(f"{self.label}: {key}: expected a point, got nothing")
        return as_vector(value, self.system.dim, f"{self.label}: {key}")

    def direction(self, key: str) -> np.ndarray:
        """The unit vector of option ``key`` (refuses a zero vector)."""
        value = self.options.get(key)
        if value is None:
            raise ModelError(f"{self.label}: {key}: expected a direction, got nothing")
        a = as_vector(value, self.system.dim, f"{self.label}: {key}")
        n = norm(a)
        if n < 1e-12:
            raise ModelError(f"{self.label}: {key}: expected a non-zero direction, got {a.tolist()}")
        return a / n

    def at(self) -> np.ndarray:
        return self.vector("at")

    def axis(self) -> np.ndarray:
        return self.direction("axis")

    def require_dim(self, dim: int, hint: str):
        if self.system.dim != dim:
            where = "a planar" if self.system.dim == 2 else "a 3D"
            raise ModelError(f"{self.label}: {where} system has no {self.kind} joint; {hint}")

    def __repr__(self) -> str:
        return f"<{self.label}>"


def attach_element(element, system, index: int, siblings, what: str, check_name, validate) -> None:
    """Add a joint, force or contact to ``system`` (their ``attach``): name it (the name given,
    else ``<kind>_<index>``), check the name (``check_name(name)``) and that no other
    ``what`` in ``siblings`` has it, then ``validate()``.  On any error the element is left
    as it was: unattached, its name as given."""
    if element.system is not None:
        raise ModelError(f"{element.label}: already added to system {element.system.name!r}")
    given = element.name
    element.name = given or f"{element.kind.lower()}_{index}"
    try:
        check_name(element.name)
        if any(x.name == element.name for x in siblings):
            raise ModelError(f"{element.label}: the name is already used by another {what} "
                             f"of system {system.name!r}")
        validate()
    except BaseException:
        element.system, element.name = None, given
        raise


def check_members(members, system, what: str) -> None:
    """Every member is the system's ground or one of its members."""
    for i, m in enumerate(members):
        role = f"{('first', 'second')[i]} member" if len(members) == 2 else "member"
        if isinstance(m, Ground):
            if m.dim != system.dim:
                raise ModelError(f"{what}: the {role} is the ground of a {m.dim}D system, "
                                 f"but system {system.name!r} is {system.dim}D")
            continue
        if not isinstance(m, Member):
            raise ModelError(f"{what}: the {role}: expected a member of system {system.name!r} "
                             f"(from add_body, add_bar, add_point) or system.ground, got {m!r}")
        if system.members.get(m.name) is not m:
            raise ModelError(f"{what}: the {role} {m.name!r} is not a member of system "
                             f"{system.name!r}")
