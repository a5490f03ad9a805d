"""The joint library.

Every joint is given in world coordinates in the initial configuration (``at``: a point;
``axis``/``normal``: a direction) between two members ``A`` and ``B`` (either may be
``system.ground``).  Number of equations (3D; planar in brackets), for two members that
carry every direction (the ground, bodies; planar bars too):

=============  ====  ====================================================================
Spherical        3   the points at ``at`` coincide  [none in 2D: use Revolute]
Revolute         5   coincide + common ``axis``  [2: coincide]
Prismatic        5   no relative rotation + B's point stays on A's line along ``axis``  [2]
Cylindrical      4   common ``axis`` + point on line
Universal        4   coincide + ``axis_a`` (on A) stays ⟂ ``axis_b`` (on B)
Planar           3   common ``normal`` + B's point stays on A's plane
Fixed            6   coincide + no relative rotation  [3]
Distance         1   the two points ``at = (p_A, p_B)`` keep their distance  [1]
PointOnLine      2   B's point at ``at`` stays on A's line through ``at`` along ``axis``  [1]
PointOnPlane     1   B's point at ``at`` stays on A's plane through ``at`` with ``normal``
JointSequence  3–4   hinges or slides applied in order (MuJoCo's joints of one body), see the class;
                     made by the MJCF import (TOML: ``steps = [{kind, at, axis}, ...]``)
=============  ====  ====================================================================

With a bar the count drops by the bar's missing spin: e.g. a bar sliding along its own
axis through a body (Prismatic) has 4 equations, a bar in a Revolute across the axis 4,
Fixed to a bar 5.  What cannot be expressed is refused with a message saying why (a point
off a bar's axis, a revolute about a bar's own axis, a direction a bar does not carry,
orientation of a point member).  :mod:`ncgen.model.joint_equations` has the formulas.

Actuators (``effort=`` on Revolute, Prismatic, Cylindrical, Universal, Planar, Spherical,
Free; a number, text expression, input or callable of t, one value per joint rate): the
joint's torque (N·m) or force (N) conjugate to its rates
(:mod:`ncgen.assembly.joint_coordinates`), acting as ``J(q)ᵀ τ``.

Drives (``drive=``; a number, a text expression such as ``"0.5*sin(2*t)"``, a CasADi
expression of the parameters or a callable ``f(t)``) prescribe, as a function of time:
Revolute — the rotation angle of B relative to A about ``axis`` since the initial
configuration (rad); Prismatic — the displacement of B relative to A along ``axis`` since
the initial configuration (m); Distance — the distance itself (m).  :class:`CoordinateDriver`
prescribes one natural coordinate.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.model.joint_base import Joint
from ncgen.model.joint_equations import (
    align_axis, angle_gauge, coincidence, distance, is_along, is_full, kind_of, lock_orientation,
    point_on_line, point_on_plane, require_orientation,
)
from ncgen.errors import ModelError
from ncgen.reproducible import dot, norm
from ncgen.validation import as_vector, rotation

#: |cos| below which two directions count as perpendicular (Universal).
PERPENDICULAR_TOL = 1e-9


class Spherical(Joint):
    """Ball joint: the points of A and B at ``at`` coincide (3 equations, 3D only).
    Sharing a basic point between members (``ends=[other.end(1), ...]``) is the same joint
    with fewer coordinates."""

    kind = "Spherical"

    def __init__(self, A, B, *, at, name=None, effort=None):
        super().__init__(A, B, name=name, at=at, effort=effort)

    def geometry(self, ctx):
        self.require_dim(3, "use Revolute")
        return coincidence(ctx, self.A, self.B, self.at(), self.label, f"{self.name}.coincide")


class Revolute(Joint):
    """Hinge about ``axis`` (3D) through ``at``: coincidence (3) and a common axis (2 for
    bodies and the ground; 1 with a bar across the axis, which keeps its angle to it).  A
    bar cannot turn about its own axis, two bars share no axis.  Planar: coincidence (2),
    no ``axis``.  ``drive``: rotation angle of B relative to A (rad, right-handed about
    ``axis``; counter-clockwise in 2D) since the initial configuration."""

    kind = "Revolute"
    drive_meaning = "rotation angle of B relative to A since the initial configuration, rad"

    def __init__(self, A, B, *, at, axis=None, name=None, drive=None, effort=None):
        super().__init__(A, B, name=name, at=at, axis=axis, drive=drive, effort=effort)

    def geometry(self, ctx):
        eqs = coincidence(ctx, self.A, self.B, self.at(), self.label, f"{self.name}.coincide")
        if ctx.dim == 3:
            a = self.axis()
            for m in (self.A, self.B):
                if is_along(m, a):
                    raise ModelError(f"{self.label}: the axis lies along bar {m.name}; a bar cannot "
                                     "rotate about its own axis (that rotation is not a coordinate)")
            eqs += align_axis(ctx, self.A, self.B, a, self.label, f"{self.name}.align")
        elif self.options.get("axis") is not None:
            raise ModelError(f"{self.label}: axis: a planar revolute turns about the normal of the "
                             "plane; leave axis out")
        if self.drive is not None:
            self.gauge(ctx)
        return eqs

    def gauge(self, ctx):
        """The :class:`~ncgen.model.joint_equations.AngleGauge` of this hinge."""
        return angle_gauge(ctx, self.A, self.B, self.axis() if ctx.dim == 3 else None, self.label)

    def drive_equations(self, ctx):
        return [(f"{self.name}.drive", self.gauge(ctx).equation(ctx, self.drive_expr(ctx)))]

    def coordinate(self, ctx) -> ca.SX:
        """The joint angle θ (rad): ``atan2`` of the gauge, zero initially."""
        x, y = self.gauge(ctx).terms(ctx)
        return ca.atan2(y, x)


class Prismatic(Joint):
    """Slider along ``axis``: no relative rotation (3 for bodies and the ground, 2 with a
    bar, 1 in 2D) and B's point stays on A's line through ``at`` along ``axis`` (2; 1 in
    2D).  A bar may slide in any direction, including its own axis; two bars cannot (3D).
    ``drive``: displacement of B relative to A along ``axis`` (m) since the initial
    configuration."""

    kind = "Prismatic"
    drive_meaning = "displacement of B relative to A along axis since the initial configuration, m"

    def __init__(self, A, B, *, at, axis, name=None, drive=None, effort=None):
        super().__init__(A, B, name=name, at=at, axis=axis, drive=drive, effort=effort)

    def _sides(self):
        """(carrier of the line, other member, sign of B's displacement seen from it)."""
        if is_full(self.A):
            return self.A, self.B, 1.0
        return self.B, self.A, -1.0

    def geometry(self, ctx):
        at, a = self.at(), self.axis()
        eqs = lock_orientation(ctx, self.A, self.B, self.label, f"{self.name}.lock")
        C, O, _ = self._sides()
        return eqs + point_on_line(ctx, C, O, ctx.nearest_point(C, at), ctx.nearest_point(O, at), a,
                                   self.label, f"{self.name}.line")

    def drive_equations(self, ctx):
        at, a = self.at(), self.axis()
        C, O, sign = self._sides()
        pC, pO = ctx.nearest_point(C, at), ctx.nearest_point(O, at)
        rC, _ = ctx.point(C, pC, self.label)
        rO, _ = ctx.point(O, pO, self.label)
        aC, _ = ctx.direction(C, a, self.label)
        s = dot(a, pO - pC) + sign * self.drive_expr(ctx)
        return [(f"{self.name}.drive", ctx.apply("offset_dot", rC, rO, aC, s)[0])]

    def offset(self, ctx) -> tuple:
        """``(r_C, r_O, a_C, sign, d0)``: the displacement is ``sign ((r_O − r_C)ᵀa_C − d0)``
        (the line's point and direction on its carrier C, the other side's point O)."""
        at, a = self.at(), self.axis()
        C, O, sign = self._sides()
        pC, pO = ctx.nearest_point(C, at), ctx.nearest_point(O, at)
        rC, _ = ctx.point(C, pC, self.label)
        rO, _ = ctx.point(O, pO, self.label)
        aC, _ = ctx.direction(C, a, self.label)
        return rC, rO, aC, sign, dot(a, pO - pC)

    def coordinate(self, ctx) -> ca.SX:
        """The displacement s (m) of B relative to A along ``axis``, zero initially."""
        rC, rO, aC, sign, d0 = self.offset(ctx)
        return sign * (ca.dot(rO - rC, aC) - d0)


class Cylindrical(Joint):
    """Common ``axis`` (2 for bodies and the ground; 1 with a bar across it) and the point
    at ``at`` of the second side on the first side's line (2): B slides along and turns
    about the axis (3D only).  The line is carried by the ground or a body."""

    kind = "Cylindrical"

    def __init__(self, A, B, *, at, axis, name=None, effort=None):
        super().__init__(A, B, name=name, at=at, axis=axis, effort=effort)

    def geometry(self, ctx):
        self.require_dim(3, "use Prismatic or Revolute")
        at, a = self.at(), self.axis()
        eqs = align_axis(ctx, self.A, self.B, a, self.label, f"{self.name}.align")
        C, O = (self.A, self.B) if is_full(self.A) else (self.B, self.A)
        return eqs + point_on_line(ctx, C, O, at, at, a, self.label, f"{self.name}.line")


class Universal(Joint):
    """Hooke joint: the points at ``at`` coincide (3) and ``axis_a``, carried by A, stays ⟂
    ``axis_b``, carried by B (1); the two axes are ⟂ initially.  A bar carries only its own
    axis (3D only)."""

    kind = "Universal"

    def __init__(self, A, B, *, at, axis_a, axis_b, name=None, effort=None):
        super().__init__(A, B, name=name, at=at, axis_a=axis_a, axis_b=axis_b, effort=effort)

    def geometry(self, ctx):
        self.require_dim(3, "use Revolute")
        require_orientation(self.label, self.A, self.B)
        a, b = self.direction("axis_a"), self.direction("axis_b")
        if abs(a @ b) > PERPENDICULAR_TOL:
            raise ModelError(f"{self.label}: axis_a and axis_b: expected perpendicular directions, "
                             f"got an angle of {np.degrees(np.arccos(np.clip(a @ b, -1, 1))):.6g}°")
        for m, d, key in ((self.A, a, "axis_a"), (self.B, b, "axis_b")):
            if not ctx.carries_direction(m, d):
                raise ModelError(f"{self.label}: {key} {np.round(d, 12).tolist()} is not along bar "
                                 f"{m.name}, which carries only its own axis")
        eqs = coincidence(ctx, self.A, self.B, self.at(), self.label, f"{self.name}.coincide")
        aA, _ = ctx.direction(self.A, a, self.label)
        bB, _ = ctx.direction(self.B, b, self.label)
        return eqs + [(f"{self.name}.cross", ctx.apply("dot", aA, bB, 0.0)[0])]


class Planar(Joint):
    """B moves parallel to a plane of A: common ``normal`` (2 for bodies and the ground; 1
    with a bar across it) and B's point at ``at`` stays on A's plane through ``at`` (1)
    (3D only)."""

    kind = "Planar"

    def __init__(self, A, B, *, at, normal, name=None, effort=None):
        super().__init__(A, B, name=name, at=at, normal=normal, effort=effort)

    def geometry(self, ctx):
        self.require_dim(3, "a planar system is already planar")
        at, n = self.at(), self.direction("normal")
        eqs = align_axis(ctx, self.A, self.B, n, self.label, f"{self.name}.align")
        C = next((m for m in (self.A, self.B) if is_full(m)), None) or \
            next(m for m in (self.A, self.B) if is_along(m, n))
        O = self.B if C is self.A else self.A
        return eqs + point_on_plane(ctx, C, O, ctx.nearest_point(C, at), ctx.nearest_point(O, at), n,
                                    self.label, f"{self.name}.plane")


class Fixed(Joint):
    """Weld: the points at ``at`` coincide and there is no relative rotation (6 for
    bodies and the ground, 5 with a bar, 3 in 2D).  With a point member only the
    coincidence remains (it has no orientation).  Two bars cannot be welded (3D)."""

    kind = "Fixed"

    def __init__(self, A, B, *, at, name=None):
        super().__init__(A, B, name=name, at=at)

    def geometry(self, ctx):
        eqs = coincidence(ctx, self.A, self.B, self.at(), self.label, f"{self.name}.coincide")
        if "point" in (kind_of(self.A), kind_of(self.B)):
            return eqs
        return eqs + lock_orientation(ctx, self.A, self.B, self.label, f"{self.name}.lock")


class Distance(Joint):
    """The point of A at ``at[0]`` and the point of B at ``at[1]`` keep their initial
    distance (1 equation).  ``drive``: the distance itself as a function of time (m)."""

    kind = "Distance"
    drive_meaning = "distance between the two points, m"

    def __init__(self, A, B, *, at, name=None, drive=None):
        super().__init__(A, B, name=name, at=at, drive=drive)

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        at = self.options.get("at")
        d = self.system.dim
        if at is None or np.ndim(at) != 2 or np.shape(at)[0] != 2:
            raise ModelError(f"{self.label}: at: expected two points (one on each member), "
                             f"got {at!r}")
        pA = as_vector(at[0], d, f"{self.label}: at[0]")
        pB = as_vector(at[1], d, f"{self.label}: at[1]")
        if np.linalg.norm(pB - pA) < 1e-12 * max(1.0, np.linalg.norm(pA)):
            raise ModelError(f"{self.label}: the two points coincide at {pA.tolist()}; a zero distance "
                             f"is a coincidence: use {'Spherical' if d == 3 else 'Revolute'}")
        return pA, pB

    def geometry(self, ctx):
        pA, pB = self.points()
        eqs = distance(ctx, self.A, pA, self.B, pB, norm(pB - pA), self.label,
                       f"{self.name}.distance")
        return [] if self.drive is not None else eqs

    def drive_equations(self, ctx):
        pA, pB = self.points()
        return distance(ctx, self.A, pA, self.B, pB, self.drive_expr(ctx), self.label, f"{self.name}.drive")


class PointOnLine(Joint):
    """B's point at ``at`` stays on the line of A through ``at`` along ``axis`` (2
    equations; 1 in 2D).  A carries the line: the ground or a body (or a bar in 2D)."""

    kind = "PointOnLine"

    def __init__(self, A, B, *, at, axis, name=None):
        super().__init__(A, B, name=name, at=at, axis=axis)

    def geometry(self, ctx):
        at = self.at()
        return point_on_line(ctx, self.A, self.B, at, at, self.axis(), self.label, f"{self.name}.line")


class PointOnPlane(Joint):
    """B's point at ``at`` stays on the plane of A through ``at`` with ``normal`` (1
    equation, 3D only).  A carries the normal: the ground, a body, or a bar along it."""

    kind = "PointOnPlane"

    def __init__(self, A, B, *, at, normal, name=None):
        super().__init__(A, B, name=name, at=at, normal=normal)

    def geometry(self, ctx):
        self.require_dim(3, "use PointOnLine")
        at = self.at()
        return point_on_plane(ctx, self.A, self.B, ctx.nearest_point(self.A, at), at,
                              self.direction("normal"), self.label, f"{self.name}.plane")


class Free(Joint):
    """No constraint: B moves freely relative to A (the floating base of a robot is a
    ``Free`` joint named ``root`` from the ground).  Its joint frame on B has its origin at
    ``at`` and the axes of ``rotation`` (world, initial configuration; default the world
    axes); on A it is A's frame (the world frame for the ground).  Joint coordinates follow
    Pinocchio's free flyer: ``[x, y, z, qx, qy, qz, qw]`` of B's joint frame in A's, rates
    ``[v, ω]`` of that frame in its own axes (planar: ``[x, y, θ]`` and ``[v_x, v_y, ω]``)."""

    kind = "Free"

    def __init__(self, A, B, *, at=None, rotation=None, name=None, effort=None):
        super().__init__(A, B, name=name, at=at, rotation=rotation, effort=effort)

    def geometry(self, ctx):
        require_orientation(self.label, self.A, self.B)
        if self.options.get("at") is not None:
            self.at()
        self.frame_rotation()
        return []

    def frame_rotation(self) -> np.ndarray:
        """B's joint frame axes in the world, initial configuration."""
        R = self.options.get("rotation")
        d = self.system.dim
        return np.eye(d) if R is None else rotation(R, d, f"{self.label}: rotation")

    def frame_origin(self) -> np.ndarray:
        at = self.options.get("at")
        return np.zeros(self.system.dim) if at is None else self.at()


class CoordinateLaw:
    """The joint dynamics of one coordinate of a :class:`JointSequence` (``dynamics``,
    ``limits``, :meth:`set_dynamics`: as a Revolute's or Prismatic's, :mod:`ncgen.model.joint_dynamics`)."""

    def __init__(self, joint, name: str, kind: str):
        self.joint, self.name, self.kind = joint, name, kind
        self.limits: dict[str, float] = {}
        self.dynamics: dict[str, float] = {}

    @property
    def label(self) -> str:
        return f"{self.joint.label} coordinate {self.name!r}"

    def set_dynamics(self, **values) -> "CoordinateLaw":
        from ncgen.model.joint_dynamics import set_joint_dynamics
        set_joint_dynamics(self, values)
        return self


class JointSequence(Joint):
    """Hinges and slides applied in order, as MuJoCo composes the joints of one body: B's
    motion relative to A is ``H = H_1(x_1) H_2(x_2) ⋯ H_n(x_n)`` (product of exponentials),
    each ``H_k`` a rotation by ``x_k`` (rad, right-handed) about the line through ``at_k``
    along ``axis_k`` or a translation by ``x_k`` (m) along ``axis_k``, lines and axes given in
    the world in the initial configuration (where every ``x_k`` is 0).  ``steps``: a sequence
    of ``(kind, at, axis)`` with kind ``"hinge"`` or ``"slide"``; ``names``: one per step
    (default ``x1, x2, ...``).  Coordinates ``[x_1, ..., x_n]``, rates their derivatives,
    ``effort``: n values (N·m or N); each coordinate has its own joint dynamics
    (``joint.laws[k].set_dynamics``).

    The members carry the equations (no intermediate member, so no massless body):

    * 2 or 3 slides (independent axes): no relative rotation (3) and, for 2, B's point stays
      on A's plane spanned by the axes (1);
    * slide, slide, hinge along the slides' normal (MuJoCo's planar roots): a common normal (2)
      and the hinge's point stays on A's plane (1);
    * 2 hinges through one point (non-parallel axes): the points coincide (3) and
      ``a_A · b_B = a · b`` (1): a Universal joint with any angle between the axes;
    * 2 hinges on skew lines (non-parallel): with ``c_1, c_2`` the lines' closest points,
      ``(r_B(c_2) − r_A(c_1)) · a_A``, ``(r_A(c_1) − r_B(c_2)) · b_B``, ``|r_B(c_2) − r_A(c_1)|``
      and ``a_A · b_B`` keep their initial values (4);
    * 3 hinges through one point with mutually perpendicular axes: the points coincide (3);
      coordinates are the angles of ``R = Rot(a_1, x_1) Rot(a_2, x_2) Rot(a_3, x_3)``, defined
      while ``|x_2| < π/2`` (gimbal lock at ``±π/2``, as for any such angles).

    Other sequences are refused by name (3D only; A and B the ground or bodies)."""

    kind = "JointSequence"

    def __init__(self, A, B, *, steps, names=None, name=None, effort=None):
        super().__init__(A, B, name=name, steps=steps, names=names, effort=effort)
        n = len(steps) if isinstance(steps, (list, tuple)) else 0
        given = list(names) if names is not None else [f"x{k + 1}" for k in range(n)]
        self.laws = [CoordinateLaw(self, given[k] if k < len(given) else f"x{k + 1}",
                                   "Revolute" if _step_kind(steps[k]) == "hinge" else "Prismatic")
                     for k in range(n)]

    # ------------------------------------------------------------ arguments
    def steps(self) -> list[tuple[str, np.ndarray, np.ndarray]]:
        """``[(kind, at, unit axis)]``, checked."""
        steps, names = self.options.get("steps"), self.options.get("names")
        if not isinstance(steps, (list, tuple)) or len(steps) < 2:
            raise ModelError(f"{self.label}: steps: expected at least two (kind, at, axis) steps, got {steps!r}")
        if names is not None and (len(names) != len(steps) or len(set(names)) != len(names)):
            raise ModelError(f"{self.label}: names: expected {len(steps)} distinct names, got {names!r}")
        out = []
        for k, step in enumerate(steps):
            kind = _step_kind(step)
            if kind not in ("hinge", "slide") or len(step) != 3:
                raise ModelError(f"{self.label}: steps[{k}]: expected (\"hinge\" or \"slide\", at, axis), got {step!r}")
            at = as_vector(step[1], 3, f"{self.label}: steps[{k}] at")
            a = as_vector(step[2], 3, f"{self.label}: steps[{k}] axis")
            if norm(a) < 1e-12:
                raise ModelError(f"{self.label}: steps[{k}] axis: expected a non-zero direction, got {a.tolist()}")
            out.append((kind, at, a / norm(a)))
        return out

    def shape(self) -> str:
        """``"slides"``, ``"planar"``, ``"hinges2"`` (one point), ``"skew2"`` or ``"hinges3"``; raises
        :class:`ModelError` for a sequence the joint does not take."""
        steps = self.steps()
        kinds = [k for k, _, _ in steps]
        axes = np.array([a for _, _, a in steps])
        if all(k == "slide" for k in kinds):
            if len(steps) > 3 or np.linalg.svd(axes, compute_uv=False).min() < 1e-9:     # unit axes: dependent
                raise ModelError(f"{self.label}: slides along dependent axes {np.round(axes, 12).tolist()}")
            return "slides"
        if kinds == ["slide", "slide", "hinge"]:
            n = np.cross(axes[0], axes[1])
            if norm(n) < 1e-9 or norm(np.cross(n / norm(n), axes[2])) > PERPENDICULAR_TOL:
                raise ModelError(f"{self.label}: slide, slide, hinge is taken as planar motion: independent "
                                 f"slides and the hinge along their normal; got axes {np.round(axes, 12).tolist()}")
            return "planar"
        if not all(k == "hinge" for k in kinds):
            raise ModelError(f"{self.label}: a sequence of {', '.join(kinds)}: only hinges, only slides, or "
                             "slide, slide, hinge (planar motion) are taken")
        if len(steps) == 2:
            if norm(np.cross(axes[0], axes[1])) < 1e-9:
                raise ModelError(f"{self.label}: two hinges about parallel axes: the body between them would "
                                 "need its own mass (make it a member)")
            c1, c2 = self.closest_points()
            return "hinges2" if norm(c2 - c1) <= 1e-12 * max(1.0, norm(c1)) else "skew2"
        if len(steps) == 3:
            gram = axes @ axes.T - np.eye(3)
            off = max(norm(step[1] - steps[0][1]) for step in steps)
            if np.abs(gram).max() > PERPENDICULAR_TOL or off > 1e-12 * max(1.0, norm(steps[0][1])):
                raise ModelError(f"{self.label}: three hinges are taken through one point with mutually "
                                 "perpendicular axes (a ball joint in angles); got axes "
                                 f"{np.round(axes, 12).tolist()} at {[np.round(s[1], 12).tolist() for s in steps]}")
            return "hinges3"
        raise ModelError(f"{self.label}: {len(steps)} hinges: at most three are taken")

    def closest_points(self) -> tuple[np.ndarray, np.ndarray]:
        """The points of the first two steps' lines nearest each other (world, initial)."""
        (_, p1, a), (_, p2, b) = self.steps()[:2]
        w, ab = p1 - p2, a @ b
        den = 1.0 - ab * ab
        s = (ab * (b @ w) - (a @ w)) / den
        t = ((b @ w) - ab * (a @ w)) / den
        return p1 + s * a, p2 + t * b

    def at(self) -> np.ndarray:
        """The origin of the joint frames: the first hinge's closest point (the common point of
        concurrent hinges), the hinge's point of planar motion, or the first slide's point."""
        shape = self.shape()
        if shape in ("slides", "planar"):
            return self.steps()[-1 if shape == "planar" else 0][1]
        return self.closest_points()[0]

    # ------------------------------------------------------------ equations
    def geometry(self, ctx):
        self.require_dim(3, "use Planar or Revolute")
        require_orientation(self.label, self.A, self.B)
        for m in (self.A, self.B):
            if not is_full(m):
                raise ModelError(f"{self.label}: {m.name} is a {kind_of(m)}; a joint sequence joins the ground "
                                 "or bodies")
        shape, steps, at = self.shape(), self.steps(), self.at()
        if shape == "slides":
            eqs = lock_orientation(ctx, self.A, self.B, self.label, f"{self.name}.lock")
            if len(steps) == 2:
                n = np.cross(steps[0][2], steps[1][2])
                eqs += point_on_plane(ctx, self.A, self.B, at, at, n / norm(n), self.label, f"{self.name}.plane")
            return eqs
        if shape == "planar":
            n = steps[2][2]
            return (align_axis(ctx, self.A, self.B, n, self.label, f"{self.name}.align")
                    + point_on_plane(ctx, self.A, self.B, at, at, n, self.label, f"{self.name}.plane"))
        if shape == "hinges3":
            return coincidence(ctx, self.A, self.B, at, self.label, f"{self.name}.coincide")
        a, b = steps[0][2], steps[1][2]
        aA, _ = ctx.direction(self.A, a, self.label)
        bB, _ = ctx.direction(self.B, b, self.label)
        cross = [(f"{self.name}.angle", ctx.apply("dot", aA, bB, float(a @ b))[0])]
        if shape == "hinges2":
            return coincidence(ctx, self.A, self.B, at, self.label, f"{self.name}.coincide") + cross
        c1, c2 = self.closest_points()
        r1, _ = ctx.point(self.A, c1, self.label)
        r2, _ = ctx.point(self.B, c2, self.label)
        return [(f"{self.name}.along_a", ctx.apply("offset_dot", r1, r2, aA, float(a @ (c2 - c1)))[0]),
                (f"{self.name}.along_b", ctx.apply("offset_dot", r2, r1, bB, float(b @ (c1 - c2)))[0]),
                (f"{self.name}.offset", ctx.apply("distance", r1, r2, norm(c2 - c1))[0])] + cross

    # ------------------------------------------------------------ coordinates
    def terms(self, ctx) -> list:
        """Per step: ``(x, y)`` with the hinge angle ``atan2(y, x)``, or the slide's
        displacement (SX)."""
        shape, steps = self.shape(), self.steps()
        A, B, lab = self.A, self.B, self.label
        if shape in ("slides", "planar"):           # B's point at `at` moves by the slides only
            at = self.at()
            d = ctx.point(B, at, lab)[0] - ctx.point(A, at, lab)[0]
            axes = np.array([a for kind, _, a in steps if kind == "slide"])
            proj = ca.vertcat(*[ca.dot(d, ctx.direction(A, a, lab)[0]) for a in axes])
            s = ca.mtimes(ca.DM(np.linalg.inv(axes @ axes.T)), proj)
            out = [s[k] for k in range(len(axes))]
            return out if shape == "slides" else out + [angle_gauge(ctx, A, B, steps[2][2], lab).terms(ctx)]
        if shape == "hinges3":           # R_ij = e_iᵀ R e_j = Rx(x_1) Ry(x_2) Rz(σ x_3), e = (a_1, a_2, a_1 × a_2)
            e = [steps[0][2], steps[1][2], np.cross(steps[0][2], steps[1][2])]
            sigma = float(np.sign(steps[2][2] @ e[2]))
            eA = [ctx.direction(A, v, lab)[0] for v in e]
            eB = [ctx.direction(B, v, lab)[0] for v in e]
            R = [[ca.dot(eA[i], eB[j]) for j in range(3)] for i in range(3)]
            return [(R[2][2], -R[1][2]), (ca.sqrt(R[0][0] ** 2 + R[0][1] ** 2), R[0][2]),
                    (R[0][0], -sigma * R[0][1])]
        a, b = steps[0][2], steps[1][2]           # b = Rot(a, x_1) b₀ seen from A, a = Rot(b, −x_2) a₀ from B
        c2 = float(a @ b) ** 2
        (aA, bA, abA), (aB, bB, baB) = ([ctx.direction(m, v, lab)[0] for v in vs] for m, vs in
                                        ((A, (a, b, np.cross(a, b))), (B, (a, b, np.cross(b, a)))))
        return [(ca.dot(bB, bA) - c2, ca.dot(bB, abA)), (ca.dot(aA, aB) - c2, -ca.dot(aA, baB))]

    def coordinates(self, ctx) -> ca.SX:
        """``[x_1, ..., x_n]`` (rad or m), zero initially."""
        return ca.vertcat(*[t if not isinstance(t, tuple) else ca.atan2(t[1], t[0]) for t in self.terms(ctx)])


def _step_kind(step):
    return step[0] if isinstance(step, (list, tuple)) and step else None


class Mimic(Joint):
    """URDF ``<mimic>``: the coordinate of the ``follower`` joint (Revolute or Prismatic)
    equals ``multiplier`` × the ``leader``'s + ``offset`` (rad or m; 1 equation).  Both
    coordinates are zero in the initial configuration, so a non-zero ``offset`` needs
    ``build(assemble=True)``."""

    kind = "Mimic"

    def __init__(self, leader, follower, *, multiplier=1.0, offset=0.0, name=None):
        super().__init__(follower.A, follower.B, name=name, leader=leader, follower=follower,
                         multiplier=float(multiplier), offset=float(offset))

    def geometry(self, ctx):
        for role in ("leader", "follower"):
            j = self.options[role]
            if not isinstance(j, (Revolute, Prismatic)) or j.system is not self.system:
                raise ModelError(f"{self.label}: {role}: expected a Revolute or Prismatic joint of "
                                 f"system {self.system.name!r}, got {j!r}")
        return []

    def equations(self, ctx):
        """Of two Prismatic joints, the ``slider_ratio`` primitive (quadratic in q); else
        the coordinates' relation (a Revolute's is an atan2)."""
        self.geometry(ctx)
        o = self.options
        f, lead, m = o["follower"], o["leader"], o["multiplier"]
        if isinstance(f, Prismatic) and isinstance(lead, Prismatic):
            rA, rB, a, s1, d1 = f.offset(ctx)
            rC, rD, b, s2, d2 = lead.offset(ctx)
            d = s1 * d1 - m * s2 * d2 + o["offset"]
            return [(f"{self.name}.mimic", ctx.apply("slider_ratio", rA, rB, a, rC, rD, b, s1, m * s2, d)[0])]
        e = f.coordinate(ctx) - m * lead.coordinate(ctx) - o["offset"]
        return [(f"{self.name}.mimic", e)]


class CoordinateDriver(Joint):
    """Prescribes one natural coordinate of ``member``: component ``axis`` (``"x"``, ``"y"``,
    ``"z"`` or 0, 1, 2) of its slot ``slot`` (``"r_i"``, ``"r_j"``, ``"u"``, ... or the
    index), equal to ``value`` (m; a number, text expression, CasADi expression or callable
    of t).  Without ``value`` the coordinate keeps its initial value.  1 equation."""

    kind = "CoordinateDriver"

    def __init__(self, member, slot, axis, value=None, *, name=None):
        super().__init__(member, None, name=name, slot=slot, axis=axis, value=value)

    def members(self):
        return [self.A]

    def index(self) -> int:
        """Index of the prescribed coordinate in the member's local coordinates."""
        m = self.A
        if m.is_ground:
            raise ModelError(f"{self.label}: the ground has no coordinates")
        ct, d = m.ctype, m.dim
        slot, axis = self.options["slot"], self.options["axis"]
        if isinstance(slot, str):
            if slot not in ct.slots:
                raise ModelError(f"{self.label}: slot: {m.name} ({ct.name}) has slots "
                                 f"{', '.join(ct.slots)}, got {slot!r}")
            slot = ct.slots.index(slot)
        if not isinstance(slot, (int, np.integer)) or not 0 <= slot < len(ct.slots):
            raise ModelError(f"{self.label}: slot: expected a slot name ({', '.join(ct.slots)}) or an "
                             f"index below {len(ct.slots)}, got {slot!r}")
        names = "xyz"[:d]
        if isinstance(axis, str) and len(axis) == 1 and axis in names:
            axis = names.index(axis)
        if not isinstance(axis, (int, np.integer)) or isinstance(axis, bool) or not 0 <= axis < d:
            raise ModelError(f"{self.label}: axis: expected one of {', '.join(names)} or an index below "
                             f"{d}, got {axis!r}")
        return int(slot) * d + int(axis)

    def geometry(self, ctx):
        k = self.index()
        if ctx.layout.member_indices(self.A.name)[k] is None:
            raise ModelError(f"{self.label}: {self.A.name}.{self.A.ctype.slots[k // ctx.dim]} is a ground "
                             "point, not a coordinate")
        return []

    def equations(self, ctx):
        self.geometry(ctx)
        k = self.index()
        value = self.options.get("value")
        target = float(self.A.q0[k]) if value is None else ctx.expression(
            value, 1, f"{self.label}: value (prescribed coordinate, m)", inputs=False)
        return [(f"{self.name}.coordinate", ctx.q_of(self.A)[k] - target)]


JOINT_TYPES: dict[str, type[Joint]] = {cls.kind: cls for cls in (
    Spherical, Revolute, Prismatic, Cylindrical, Universal, Planar, Fixed, Distance, PointOnLine,
    PointOnPlane, Free, Mimic, CoordinateDriver, JointSequence)}

__all__ = ["JOINT_TYPES", "Joint", *JOINT_TYPES]
