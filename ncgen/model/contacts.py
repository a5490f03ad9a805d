"""Unilateral contact elements: a body-fixed sphere against a plane, two spheres, and
body-fixed shapes against a plane as several contact points (:class:`BoxPlane`,
:class:`CapsulePlane`, :class:`CylinderPlane`); a sphere against a box (:class:`SphereBox`)
and two boxes as the corners of each against the other (:class:`BoxBox`), a box carried by
a body or the ground.

Geometry is given like a joint's: body-fixed points in the member's local frame (``at``,
as for forces), the plane by a world point and a world normal in the initial
configuration (fixed to the ground, or carried by a member).  In planar systems a "plane"
is a line and a "sphere" a disc.

Every contact has, besides its geometry (SI units):

* ``mu``: Coulomb friction coefficient (isotropic, dimensionless, ≥ 0);
* ``restitution``: Newton's normal restitution coefficient ``e`` in [0, 1] (nonsmooth
  stepper: post-impact normal velocity ``= −e ×`` pre-impact);
* the smooth (compliant) law used when the model is built with ``contacts="smooth"``
  (:mod:`ncgen.assembly.contact_kinematics`): ``stiffness`` k (N/m^n), ``damping`` d
  (N·s/m^(n+1)), ``exponent`` n (Hunt–Crossley: ``f_N = max(0, δⁿ (k + d δ̇))`` with the
  penetration ``δ = max(0, −g)``) and ``slip_velocity`` v_s (m/s, friction regularised as
  ``f_T = −μ f_N v_T / sqrt(|v_T|² + v_s²)``).  A contact given ``restitution`` and no
  ``damping`` gets the damping with which the law restores ``e`` at an impact speed of
  :data:`RESTITUTION_SPEED` (:func:`damping_for_restitution`; faster impacts lose more,
  slower ones less, as the law says); given ``damping``, the smooth law uses it and
  ``restitution`` is the nonsmooth stepper's only.

Sign conventions: the gap ``g`` (m) is positive when apart; the normal ``n`` points from the
plane (or sphere ``a``, or the box) towards the sphere (or sphere ``b``, or the box corner);
contact forces are those on the second element (the sphere, ``b``, or the corner's box), and
``−`` that on the first.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ncgen.errors import BasisError
from ncgen.model.joint_base import attach_element, check_members
from ncgen.errors import ModelError
from ncgen.validation import as_vector, rotation as as_rotation

#: Defaults of the smooth law (steel-like ball of a few kg: a 1 kg ball rests ~0.1 mm deep).
STIFFNESS, DAMPING, EXPONENT, SLIP_VELOCITY = 1e6, 1e5, 1.5, 1e-3
#: Impact speed (m/s) at which the smooth law restores a contact's ``restitution``.
RESTITUTION_SPEED = 1.0


#: Smallest restitution the smooth law is fitted to (e → 0 needs infinite damping).
MIN_RESTITUTION = 0.01


def damping_for_restitution(stiffness: float, restitution: float, exponent: float = EXPONENT) -> float:
    """The damping d (N·s/m^(n+1)) with which ``f_N = δⁿ (k + d δ̇)`` returns a normal impact
    at :data:`RESTITUTION_SPEED` with restitution ``e`` (at least :data:`MIN_RESTITUTION`).
    Scaled by ``δ = L y``, ``L^(n+1) = m v²/k``, the impact is ``y'' = −yⁿ (1 + ζ y')`` with
    ``ζ = d v / k`` alone, and ``d = ζ k / v`` with ζ from :func:`restitution_zeta` (the same
    for every exponent n: ``exponent`` is accepted and does not change the result)."""
    return restitution_zeta(max(float(restitution), MIN_RESTITUTION)) * stiffness / RESTITUTION_SPEED


def restitution_zeta(e: float) -> float:
    """The scaled damping ζ of the Hunt–Crossley impact ``y'' = −yⁿ (1 + ζ y')``, ``y(0) = 0``,
    ``y'(0) = 1``, that rebounds with speed ``e`` (0 < e ≤ 1).  With ``y'' = v dv/dy`` the
    equation separates, ``v dv / (1 + ζ v) = −yⁿ dy``; integrated over the whole impact
    (from ``v = 1`` at ``y = 0`` back to ``y = 0`` at ``v = −e``) its right side vanishes, so
    ``∫_{−e}^{1} v / (1 + ζ v) dv = 0``, i.e. ``ln((1 + ζ)/(1 − e ζ)) = (1 + e) ζ``
    whatever n.  ``1 + ζ v`` stays positive (the integral diverges as ``v → −1/ζ``), so the
    force never vanishes before separation; the root in ``(0, 1/e)`` is found by bisection
    (the left side minus the right is negative below it, positive above)."""
    if e >= 1.0:
        return 0.0
    lo, hi = 0.0, 1.0 / e
    while hi - lo > 4.0 * math.ulp(hi):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if math.log1p(mid) - math.log1p(-e * mid) < (1.0 + e) * mid else (lo, mid)
    return 0.5 * (lo + hi)


def _check_name(name) -> None:
    if not isinstance(name, str) or not name.isidentifier():
        raise ModelError(f"contact name: expected an identifier (letters, digits, _), got {name!r}")


class Contact:
    """Base class: name, friction, restitution and the smooth law's parameters."""

    kind = "Contact"

    def __init__(self, *, mu=0.0, restitution=None, stiffness=STIFFNESS, damping=None, exponent=EXPONENT,
                 slip_velocity=SLIP_VELOCITY, name: str | None = None):
        self.name = name
        if damping is None:
            numbers = all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in (stiffness, restitution))
            damping = damping_for_restitution(stiffness, restitution, exponent) \
                if restitution is not None and numbers and isinstance(exponent, (int, float)) else DAMPING
        self.mu, self.restitution = mu, 0.0 if restitution is None else restitution
        self.stiffness, self.damping, self.exponent, self.slip_velocity = stiffness, damping, exponent, slip_velocity
        self.system = None

    @property
    def label(self) -> str:
        return f"contact {self.name!r} ({self.kind})"

    def members(self) -> list:
        raise NotImplementedError

    #: The attribute naming a member that is the ground where it was not given (None: none).
    ground_default: str | None = None

    def attach(self, system, index: int):
        """Called by ``System.add_contact``: name, membership and argument checks (the member
        :attr:`ground_default` is the ground where it was not given, and is given back on a
        failure)."""
        given = getattr(self, self.ground_default) if self.ground_default else None
        if self.ground_default and given is None:
            setattr(self, self.ground_default, system.ground)

        def validate():
            check_members(self.members(), system, self.label)
            self._check_material()
            self.check(system)
            self.system = system

        try:
            attach_element(self, system, index, system.contacts, "contact", _check_name, validate)
        except BaseException:
            if self.ground_default:
                setattr(self, self.ground_default, given)
            raise

    def _check_material(self):
        checks = (("mu", self.mu, 0.0, math.inf), ("restitution", self.restitution, 0.0, 1.0),
                  ("stiffness", self.stiffness, 0.0, math.inf), ("damping", self.damping, 0.0, math.inf),
                  ("exponent", self.exponent, 1.0, math.inf), ("slip_velocity", self.slip_velocity, 0.0, math.inf))
        for what, value, lo, hi in checks:
            try:
                x = float(value)
            except (TypeError, ValueError):
                raise ModelError(f"{self.label}: {what}: expected a number, got {value!r}") from None
            bad = not math.isfinite(x) or x < lo or x > hi or (what in ("stiffness", "slip_velocity") and x == 0)
            if bad:
                rng = f"in [{lo:g}, {hi:g}]" if math.isfinite(hi) else (f"> {lo:g}" if what in (
                    "stiffness", "slip_velocity") else f">= {lo:g}")
                raise ModelError(f"{self.label}: {what}: expected a finite number {rng}, got {value!r}")
            setattr(self, what, x)

    def check(self, system):
        """Geometry checks (subclasses)."""

    def _sphere(self, member, at, radius, what: str):
        """Check a sphere of ``radius`` (m) centred at local point ``at`` of ``member``."""
        if member.is_ground:
            raise ModelError(f"{self.label}: {what}: a sphere needs a moving member, got the ground")
        x = as_vector(at, member.dim, f"{self.label}: {what} at")
        try:
            member.rigid.affine(x)
        except BasisError as e:
            raise ModelError(f"{self.label}: {what} centre on {member.name} ({member.ctype.name} "
                             f"{member.kind}): {e}") from None
        try:
            r = float(radius)
        except (TypeError, ValueError):
            raise ModelError(f"{self.label}: {what} radius: expected a number (m), got {radius!r}") from None
        if not math.isfinite(r) or r < 0:
            raise ModelError(f"{self.label}: {what} radius: expected a finite number >= 0 (m), got {radius!r}")
        return x, r

    def _length(self, value, what: str, positive: bool = True) -> float:
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise ModelError(f"{self.label}: {what}: expected a number (m), got {value!r}") from None
        if not math.isfinite(x) or x < 0 or (positive and x == 0):
            raise ModelError(f"{self.label}: {what}: expected a finite number {'> 0' if positive else '>= 0'} (m), "
                             f"got {value!r}")
        return x

    def point_contacts(self) -> list:
        """The point contacts this element stands for (itself for a sphere pair)."""
        return [self]

    def spec(self) -> dict:
        """Plain data describing the contact (``model.contacts``, TOML)."""
        return {"name": self.name, "type": self.kind, "mu": self.mu, "restitution": self.restitution,
                "stiffness": self.stiffness, "damping": self.damping, "exponent": self.exponent,
                "slip_velocity": self.slip_velocity}

    def __repr__(self) -> str:
        return f"<{self.label}>"


class SpherePlane(Contact):
    """A sphere of ``radius`` (m) centred at the local point ``at`` of ``sphere`` against the
    plane through the world point ``point`` with world normal ``normal`` (initial
    configuration), fixed to ``plane`` (the ground by default, or a body carrying it).
    The plane is one-sided: the sphere is kept on the side ``normal`` points to."""

    kind = "SpherePlane"
    ground_default = "plane"

    def __init__(self, sphere, at=None, radius=0.0, *, plane=None, point=None, normal=None, **material):
        super().__init__(**material)
        self.sphere, self.at, self.radius = sphere, at, radius
        self.plane, self.point, self.normal = plane, point, normal

    def members(self):
        return [self.sphere] + ([] if self.plane is None else [self.plane])

    def check(self, system):
        d = system.dim
        self.at = np.zeros(d) if self.at is None else self.at
        self.at, self.radius = self._sphere(self.sphere, self.at, self.radius, "sphere")
        self.point = as_vector(np.zeros(d) if self.point is None else self.point, d, f"{self.label}: point")
        default_n = np.eye(d)[-1]
        n = as_vector(default_n if self.normal is None else self.normal, d, f"{self.label}: normal")
        if np.linalg.norm(n) == 0:
            raise ModelError(f"{self.label}: normal: expected a non-zero vector, got {n.tolist()}")
        self.normal = n / np.linalg.norm(n)
        if self.plane is self.sphere:
            raise ModelError(f"{self.label}: the sphere and the plane are on the same member {self.sphere.name!r}")
        if not self.plane.is_ground and not (self.plane.kind == "body" or (self.plane.kind == "bar" and d == 2)):
            raise ModelError(f"{self.label}: plane: a plane needs the ground or a body (or a planar bar) to "
                             f"carry it, got the {self.plane.kind} {self.plane.name!r}")

    def spec(self):
        return {**super().spec(), "sphere": self.sphere.name, "at": np.asarray(self.at).tolist(),
                "radius": self.radius, "plane": self.plane.name, "point": self.point.tolist(),
                "normal": self.normal.tolist()}


class SphereSphere(Contact):
    """Two spheres: radius ``radius_a`` (m) at local point ``at_a`` of ``a``, ``radius_b`` at
    ``at_b`` of ``b``.  The normal points from the centre of ``a`` to that of ``b``."""

    kind = "SphereSphere"

    def __init__(self, a, at_a=None, radius_a=0.0, b=None, at_b=None, radius_b=0.0, **material):
        super().__init__(**material)
        self.a, self.at_a, self.radius_a = a, at_a, radius_a
        self.b, self.at_b, self.radius_b = b, at_b, radius_b

    def members(self):
        return [self.a, self.b]

    def check(self, system):
        d = system.dim
        if self.b is None:
            raise ModelError(f"{self.label}: b: expected the second member, got None")
        if self.a is self.b:
            raise ModelError(f"{self.label}: both spheres are on the same member {self.a.name!r}")
        self.at_a, self.radius_a = self._sphere(self.a, np.zeros(d) if self.at_a is None else self.at_a,
                                                self.radius_a, "a")
        self.at_b, self.radius_b = self._sphere(self.b, np.zeros(d) if self.at_b is None else self.at_b,
                                                self.radius_b, "b")
        if self.radius_a + self.radius_b <= 0:
            raise ModelError(f"{self.label}: radius_a + radius_b: expected > 0 (two points never touch)")

    def spec(self):
        return {**super().spec(), "a": self.a.name, "at_a": np.asarray(self.at_a).tolist(), "radius_a": self.radius_a,
                "b": self.b.name, "at_b": np.asarray(self.at_b).tolist(), "radius_b": self.radius_b}


class ShapePoint(SpherePlane):
    """One point contact of a :class:`ShapePlane` ``element`` (built by it, never attached):
    a sphere of ``radius`` at ``offset`` from the shape's centre; with ``rim_radius`` > 0, the
    lowest point of the circle of that radius about the body's z through the point (a
    cylinder's rim)."""

    def __init__(self, element, suffix: str, offset, radius: float, rim_radius: float = 0.0):
        super().__init__(element.body, element.at + element.rotation @ offset, radius, plane=element.plane,
                         point=element.point,
                         normal=element.normal, mu=element.mu, restitution=element.restitution,
                         stiffness=element.stiffness, damping=element.damping, exponent=element.exponent,
                         slip_velocity=element.slip_velocity, name=f"{element.name}.{suffix}")
        self.kind, self.element, self.rim_radius = element.kind, element.name, rim_radius
        self.axis = element.rotation[:, -1]               # the shape's z in the body's frame

    def spec(self):
        return {**super().spec(), "element": self.element, "rim_radius": self.rim_radius, "axis": self.axis.tolist()}


class ShapePlane(Contact):
    """Base of a body-fixed shape against a plane, given as point contacts: spheres of the
    shape's body (radius ≥ 0) against the plane, each a :class:`SpherePlane` named
    ``<name>.<point>`` (``model.contact_names``, trajectories).  The shape is centred at the
    local point ``at`` of ``body`` (default its origin) with its axes along the columns of
    ``rotation`` (in the body's frame; default the body's axes); the plane keywords are those
    of :class:`SpherePlane`."""

    ground_default = "plane"

    def __init__(self, body, *, at=None, rotation=None, plane=None, point=None, normal=None, **material):
        super().__init__(**material)
        self.body, self.at, self.rotation = body, at, rotation
        self.plane, self.point, self.normal = plane, point, normal
        self._points: list = []

    def members(self):
        return [self.body] + ([] if self.plane is None else [self.plane])

    def local_spheres(self) -> list:
        """``[(suffix, local centre offset from at, radius[, rim radius])]`` (subclasses)."""
        raise NotImplementedError

    def check(self, system):
        d = system.dim
        if self.body.is_ground or self.body.kind != "body":
            raise ModelError(f"{self.label}: body: a {self.kind} needs a rigid body, got the "
                             f"{'ground' if self.body.is_ground else self.body.kind} {self.body.name!r}")
        self._check_shape(d)
        self.at = as_vector(np.zeros(d) if self.at is None else self.at, d, f"{self.label}: at")
        self.rotation = np.eye(d) if self.rotation is None else as_rotation(self.rotation, d, f"{self.label}: rotation")
        self._points = []
        for suffix, offset, radius, *rim in self.local_spheres():
            sp = ShapePoint(self, suffix, offset, radius, *rim)
            sp.check(system)
            sp.system = system
            self._points.append(sp)
        self.point, self.normal = self._points[0].point, self._points[0].normal

    def _check_shape(self, dim: int):
        """Argument checks of the shape's dimensions (subclasses)."""

    def _need_3d(self, dim: int):
        if dim != 3:
            raise ModelError(f"{self.label}: a {self.kind} needs a 3D system (its axis is the body's z), "
                             f"got a planar one")

    def point_contacts(self) -> list:
        return list(self._points)

    def spec(self):
        return {**super().spec(), "body": self.body.name, "at": np.asarray(self.at).tolist(),
                "rotation": self.rotation.tolist(), "plane": self.plane.name,
                "point": self.point.tolist(), "normal": self.normal.tolist()}


class BoxPlane(ShapePlane):
    """A box of full edge lengths ``size = (a, b, c)`` (m; ``(a, b)`` in planar systems) along
    the body's axes against a plane: its 8 corners (4 in 2D) as point contacts
    ``<name>.corner0 …``, corner ``i`` at ``at + (±a/2, ±b/2, ±c/2)`` with the signs of the
    bits of ``i`` (bit 0 for x: ``−`` when clear).  Exact for a box meeting the plane with a
    face, an edge or a corner (a face's force is carried by its corners)."""

    kind = "BoxPlane"

    def __init__(self, body, size=None, **kw):
        super().__init__(body, **kw)
        self.size = size

    def _check_shape(self, dim):
        if self.size is None:
            raise ModelError(f"{self.label}: size: expected the box's {dim} full edge lengths (m), got None")
        size = as_vector(self.size, dim, f"{self.label}: size")
        self.size = np.array([self._length(x, f"size[{i}]") for i, x in enumerate(size)])

    def local_spheres(self):
        d = len(self.size)
        return [(f"corner{i}", np.array([(1 if i >> j & 1 else -1) * self.size[j] / 2 for j in range(d)]), 0.0)
                for i in range(2 ** d)]

    def spec(self):
        return {**super().spec(), "size": self.size.tolist()}


class CapsulePlane(ShapePlane):
    """A capsule of ``radius`` r (m) whose hemisphere centres are ``length`` L (m) apart along
    the body's z, centred at ``at``, against a plane: two spheres of radius r at
    ``at ± (0, 0, L/2)`` (points ``<name>.end0``, ``<name>.end1``).  Exact: a capsule meets a
    plane where its lower sphere does (both, lying flat)."""

    kind = "CapsulePlane"

    def __init__(self, body, radius=None, length=None, **kw):
        super().__init__(body, **kw)
        self.radius, self.length = radius, length

    def _check_shape(self, dim):
        self._need_3d(dim)
        self.radius = self._length(self.radius, "radius")
        self.length = self._length(self.length, "length", positive=False)

    def local_spheres(self):
        return [(f"end{i}", np.array([0.0, 0.0, s * self.length / 2]), self.radius) for i, s in enumerate((-1, 1))]

    def spec(self):
        return {**super().spec(), "radius": self.radius, "length": self.length}


class CylinderPlane(ShapePlane):
    """A cylinder of ``radius`` r (m) and ``length`` L (m) along the body's z (as in URDF),
    centred at ``at``, against a plane.  Each end face contributes its exact lowest rim point
    (``<name>.end0``, ``<name>.end1``: the lowest point of the rim circle, smooth except within
    ~1e-4 rad of standing upright, where it moves to the face centre;
    :mod:`ncgen.assembly.contact_kinematics`), so a cylinder rolls, lies and pivots on a rim exactly; and
    ``face_points`` (default 3) fixed points equally spaced on each end face at half the
    radius (``<name>.face0 …``, face 0 at z = −L/2), so it stands on an end.  Inside the rim,
    they never touch while the cylinder lies or rolls (a point on the rim itself would strike
    the plane each time it passed the bottom), and once it tilts the exact rim point is lower.
    """

    kind = "CylinderPlane"

    def __init__(self, body, radius=None, length=None, *, face_points=3, **kw):
        super().__init__(body, **kw)
        self.radius, self.length, self.face_points = radius, length, face_points

    def _check_shape(self, dim):
        self._need_3d(dim)
        self.radius = self._length(self.radius, "radius")
        self.length = self._length(self.length, "length")
        n = self.face_points
        if isinstance(n, float) and n.is_integer():
            n = int(n)
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0 or n in (1, 2):
            raise ModelError(f"{self.label}: face_points: expected 0 or an integer >= 3 (points per end face), "
                             f"got {self.face_points!r}")
        self.face_points = int(n)

    def local_spheres(self):
        out = [(f"end{i}", np.array([0.0, 0.0, s * self.length / 2]), 0.0, self.radius)
               for i, s in enumerate((-1, 1))]
        n = self.face_points
        for i, s in enumerate((-1, 1)):
            for j in range(n):
                phi = 2 * math.pi * j / n
                rho = self.radius / 2
                out.append((f"face{i * n + j}", np.array([rho * math.cos(phi), rho * math.sin(phi), s * self.length / 2]),
                            0.0))
        return out

    def spec(self):
        return {**super().spec(), "radius": self.radius, "length": self.length, "face_points": self.face_points}


class MeshPlane(ShapePlane):
    """A convex mesh against a plane: the vertices of the convex hull of the mesh file
    ``mesh`` (anything ``trimesh`` reads: STL, OBJ, ...; the optional dependency of the
    ``meshes`` extra), scaled by ``scale`` (a number or three) in the shape's axes, as
    point contacts ``<name>.vertex0 …`` (in the hull's vertex order).  Exact for the hull:
    a convex polytope meets a plane at a vertex, an edge or a face, whose force its
    vertices carry; a non-convex mesh touches as its hull does."""

    kind = "MeshPlane"

    def __init__(self, body, mesh=None, scale=1.0, **kw):
        super().__init__(body, **kw)
        self.mesh, self.scale = mesh, scale
        self._vertices = None

    def _check_shape(self, dim):
        self._need_3d(dim)
        if not isinstance(self.mesh, (str, Path)) or not str(self.mesh):
            raise ModelError(f"{self.label}: mesh: expected a mesh file name, got {self.mesh!r}")
        s = np.atleast_1d(np.asarray(self.scale, dtype=float)).reshape(-1)
        if s.size not in (1, 3) or not np.all(np.isfinite(s)) or np.any(s <= 0):
            raise ModelError(f"{self.label}: scale: expected a positive number or three, got {self.scale!r}")
        self.mesh = str(self.mesh)
        self.scale = float(s[0]) if s.size == 1 else s.tolist()
        self._vertices = hull_vertices(self.mesh, np.broadcast_to(s, 3), self.label)

    def local_spheres(self):
        return [(f"vertex{i}", v, 0.0) for i, v in enumerate(self._vertices)]

    def spec(self):
        return {**super().spec(), "mesh": self.mesh, "scale": self.scale}


def hull_vertices(filename: str, scale, what: str) -> np.ndarray:
    """``(n, 3)`` vertices (m) of the convex hull of the mesh in ``filename`` scaled by
    ``scale`` (three factors), by ``trimesh``; errors name ``what`` and the file."""
    try:
        import trimesh
    except ImportError:
        raise ModelError(f"{what}: mesh: reading {filename!r} needs trimesh (pip install ncgen[meshes])") from None
    if not Path(filename).is_file():
        raise ModelError(f"{what}: mesh: no such file {filename!r}")
    try:
        mesh = trimesh.load(filename, force="mesh")
        hull = trimesh.Trimesh(vertices=np.asarray(mesh.vertices, float) * scale).convex_hull
    except Exception as e:                                      # trimesh raises many kinds
        raise ModelError(f"{what}: mesh: could not read a mesh from {filename!r}: {e}") from None
    vertices = np.asarray(hull.vertices, float)
    if len(vertices) < 4:
        raise ModelError(f"{what}: mesh: {filename!r} has no volume (its convex hull has {len(vertices)} vertices)")
    return vertices


def _box_frame(contact, member, size, at, rotation, what: str, dim: int):
    """Check a box carried by ``member`` (the ground or a body): full edge lengths ``size``
    (m), centre ``at`` and axes ``rotation`` (columns) in the member's frame (the world frame
    for the ground).  Returns ``(size, at, rotation)`` as arrays."""
    if not member.is_ground and member.kind != "body":
        raise ModelError(f"{contact.label}: {what}: a box needs the ground or a rigid body to carry it, got the "
                         f"{member.kind} {member.name!r}")
    if size is None:
        raise ModelError(f"{contact.label}: {what} size: expected the box's {dim} full edge lengths (m), got None")
    size = as_vector(size, dim, f"{contact.label}: {what} size")
    size = np.array([contact._length(x, f"{what} size[{i}]") for i, x in enumerate(size)])
    at = as_vector(np.zeros(dim) if at is None else at, dim, f"{contact.label}: {what} at")
    rotation = np.eye(dim) if rotation is None else as_rotation(rotation, dim, f"{contact.label}: {what} rotation")
    return size, at, rotation


class SphereBox(Contact):
    """A sphere of ``radius`` (m, ≥ 0; 0 is a point) centred at the local point ``at`` of
    ``sphere`` against a box of full edge lengths ``size`` (m; a rectangle in planar
    systems) carried by ``box`` (the ground by default, or a body), centred at ``box_at`` with
    its axes along the columns of ``box_rotation``, both in ``box``'s frame (the world frame
    for the ground).  The gap is the signed distance from the sphere to the box
    (:mod:`ncgen.assembly.contact_kinematics`): the distance to the box's nearest point less the
    radius while the centre is outside, and the largest face-plane distance less the radius
    inside.  The normal points from the box towards the sphere; forces are those on the
    sphere."""

    kind = "SphereBox"
    ground_default = "box"

    def __init__(self, sphere, at=None, radius=0.0, *, box=None, size=None, box_at=None, box_rotation=None,
                 **material):
        super().__init__(**material)
        self.sphere, self.at, self.radius = sphere, at, radius
        self.box, self.size, self.box_at, self.box_rotation = box, size, box_at, box_rotation

    def members(self):
        return [self.sphere] + ([] if self.box is None else [self.box])

    def check(self, system):
        d = system.dim
        if self.box is self.sphere:
            raise ModelError(f"{self.label}: the sphere and the box are on the same member {self.sphere.name!r}")
        self._check_point(d)
        self.size, self.box_at, self.box_rotation = _box_frame(self, self.box, self.size, self.box_at,
                                                               self.box_rotation, "box", d)

    def _check_point(self, dim: int):
        self.at, self.radius = self._sphere(self.sphere, np.zeros(dim) if self.at is None else self.at,
                                            self.radius, "sphere")

    def spec(self):
        return {**super().spec(), "sphere": self.sphere.name, "at": np.asarray(self.at).tolist(),
                "radius": self.radius, "box": self.box.name, "size": self.size.tolist(),
                "box_at": self.box_at.tolist(), "box_rotation": self.box_rotation.tolist()}


class BoxCorner(SphereBox):
    """One point contact of a :class:`BoxBox` ``element`` (built by it, never attached):
    corner ``signs`` (±1 per axis) of the box ``(size, at, rotation)`` on ``member`` against
    the other box.  Its gap is the corner's distance to the plane of one face of the other
    box, the face chosen among those the corner is over (``_sphere_box`` in
    :mod:`ncgen.assembly.contact_kinematics`); ``corner_rotation``, ``corner_signs`` and
    ``corner_size`` say which faces of its own box meet at the corner and how large it is
    (they settle near ties between faces)."""

    def __init__(self, element, suffix: str, member, size, at, rotation, signs, box, box_size, box_at,
                 box_rotation):
        super().__init__(member, at + rotation @ (signs * size / 2), 0.0, box=box, size=box_size, box_at=box_at,
                         box_rotation=box_rotation, mu=element.mu, restitution=element.restitution,
                         stiffness=element.stiffness, damping=element.damping, exponent=element.exponent,
                         slip_velocity=element.slip_velocity, name=f"{element.name}.{suffix}")
        self.kind, self.element = element.kind, element.name
        self.corner_rotation, self.corner_signs, self.corner_size = rotation, np.asarray(signs, float), size

    def _check_point(self, dim: int):
        self.at = np.asarray(self.at, float)

    def spec(self):
        return {**super().spec(), "element": self.element, "corner_rotation": self.corner_rotation.tolist(),
                "corner_signs": self.corner_signs.tolist(), "corner_size": self.corner_size.tolist()}


#: Edges whose directions are within this sine of parallel have no edge contact (their
#: common normal is ill-defined); the corners of the boxes carry such contacts.
PARALLEL_SIN = 1e-2
#: Edge contacts and box corners: the margin, relative to the smallest edge of the two
#: shapes, by which a crossing must lie inside both edges (the corners cover the rest, with
#: the same tolerance: ``EDGE_TOL`` of :mod:`ncgen.assembly.contact_kinematics`).
EDGE_MARGIN = 1e-2


class EdgeContact(Contact):
    """One point contact of an element (built by it, never attached): an edge of a box, or a
    capsule's segment, against an edge or a segment of another shape, where the two cross.

    Each side ``(member, size, at, rotation, axis, choice, radius)`` is a box of full edge
    lengths ``size`` centred at ``at`` with axes ``rotation`` (columns) in the member's frame
    (the world frame for the ground): its edges parallel to axis ``axis``, of which the one
    facing the other shape (:mod:`ncgen.assembly.contact_kinematics`, ``choice`` ∈ {0, 1} picking the
    side where the facing direction is ambiguous), swollen by ``radius`` (m).  A capsule's
    segment is the box ``(0, 0, L)`` with ``axis = 2`` and its radius.  The gap is the
    distance between the two edges' lines along their common normal ``n`` (from ``a``'s
    towards ``b``'s, forces on ``b``) less the radii, while their closest points lie inside
    both edges by ``margin`` (m), the edges are not parallel (:data:`PARALLEL_SIN`) and the
    gap is above ``−margin``, and that plus ``band`` (m, larger than any such distance, so
    never a contact) otherwise."""

    def __init__(self, element, suffix: str, side_a: tuple, side_b: tuple, margin: float, band: float):
        super().__init__(mu=element.mu, restitution=element.restitution, stiffness=element.stiffness,
                         damping=element.damping, exponent=element.exponent, slip_velocity=element.slip_velocity,
                         name=f"{element.name}.{suffix}")
        self.kind, self.element = element.kind, element.name
        self.a, self.b = side_a[0], side_b[0]
        self.edge_a, self.edge_b = (self._side(side) for side in (side_a, side_b))
        self.radius = self.edge_a["radius"] + self.edge_b["radius"]
        self.margin, self.band = float(margin), float(band)

    @staticmethod
    def _side(side) -> dict:
        _, size, at, rotation, axis, choice, radius = side
        return {"size": np.asarray(size, float).tolist(), "at": np.asarray(at, float).tolist(),
                "rotation": np.asarray(rotation, float).tolist(), "axis": int(axis), "choice": int(choice),
                "radius": float(radius)}

    def members(self):
        return [self.a, self.b]

    def spec(self):
        return {**super().spec(), "element": self.element, "a": self.a.name, "b": self.b.name,
                "edge_a": self.edge_a, "edge_b": self.edge_b, "margin": self.margin, "band": self.band}


def edge_contacts(element, side_a: tuple, side_b: tuple, choices_a: int, choices_b: int) -> list:
    """The :class:`EdgeContact` s between the edges of two shapes, each side ``(member, size,
    at, rotation, axes, radius)`` with ``axes`` the axes whose edges take part; ``choices``
    is 2 for a box (the facing edge may be either of two), 1 for a segment.  Named
    ``edge<i><j><p><r>``: axis i of ``a``, axis j of ``b``, choices p and r."""
    (ma, size_a, at_a, rot_a, axes_a, r_a), (mb, size_b, at_b, rot_b, axes_b, r_b) = side_a, side_b
    dims = [x for x in (*size_a, *size_b) if x > 0] + [2 * r for r in (r_a, r_b) if r > 0]
    margin = EDGE_MARGIN * min(dims)
    band = 10 * (float(np.sum(size_a) + np.sum(size_b)) + 2 * (r_a + r_b))
    out = []
    for i in axes_a:
        for j in axes_b:
            for p in range(choices_a):
                for r in range(choices_b):
                    out.append(EdgeContact(element, f"edge{i}{j}{p}{r}", (ma, size_a, at_a, rot_a, i, p, r_a),
                                           (mb, size_b, at_b, rot_b, j, r, r_b), margin, band))
    return out


class BoxBox(Contact):
    """Two boxes: full edge lengths ``size_a`` (m) centred at ``at_a`` with axes along the
    columns of ``rotation_a`` in ``a``'s frame, and likewise ``size_b``, ``at_b``,
    ``rotation_b`` on ``b`` (a body, or the ground for a fixed box: a table, a step).  As
    point contacts (:class:`BoxCorner`): each corner of ``a`` against box ``b``
    (``<name>.a_corner0 …``, forces on ``a``) and each corner of ``b`` against box ``a``
    (``<name>.b_corner0 …``, forces on ``b``), corner ``i`` at ``(±x/2, ±y/2, ±z/2)`` with
    the sign of axis j ``+`` when bit j of i is set.  This holds a box resting on a face,
    an edge or a corner of the other wherever a corner of one of them is in contact: a box
    on a larger, a smaller or an equal box, shifted or turned in the plane of contact so
    long as a corner of one lies over the other's face (docs/contact.md gives the method and
    its tolerances).  With ``edges=True`` (3D), edges crossing edges are point contacts too
    (:class:`EdgeContact`, ``<name>.edge<i><j><p><r>``: the edges along axis i of ``a`` and
    axis j of ``b``, 36 in all, forces on ``b``): equal boxes stacked at 45°, or two beams
    crossed edge on edge, rest on the crossings; without them such boxes pass through each
    other.  They are off by default: they nearly double the package of
    ``examples/box_stack.toml`` even with the contact kernels per element (its C from 1.4 to
    2.5 MB; with the flat kernels from 1.6 to 3.3 MB) and its compile time more than that
    (one kernel of the pair then exceeds gcc's -O2 size limit and is compiled at -O1)."""

    kind = "BoxBox"

    def __init__(self, a, size_a=None, b=None, size_b=None, *, at_a=None, rotation_a=None, at_b=None,
                 rotation_b=None, edges=False, **material):
        super().__init__(**material)
        self.a, self.size_a, self.at_a, self.rotation_a = a, size_a, at_a, rotation_a
        self.b, self.size_b, self.at_b, self.rotation_b = b, size_b, at_b, rotation_b
        self.edges = edges
        self._points: list = []

    def members(self):
        return [self.a, self.b]

    def check(self, system):
        d = system.dim
        if self.a is self.b:
            raise ModelError(f"{self.label}: both boxes are on the same member {self.a.name!r}")
        self.size_a, self.at_a, self.rotation_a = _box_frame(self, self.a, self.size_a, self.at_a,
                                                             self.rotation_a, "a", d)
        self.size_b, self.at_b, self.rotation_b = _box_frame(self, self.b, self.size_b, self.at_b,
                                                             self.rotation_b, "b", d)
        boxes = {"a": (self.a, self.size_a, self.at_a, self.rotation_a),
                 "b": (self.b, self.size_b, self.at_b, self.rotation_b)}
        self._points = []
        for mine, other in (("a", "b"), ("b", "a")):
            member, size, at, rot = boxes[mine]
            for i in range(2 ** d):
                signs = np.array([1.0 if i >> j & 1 else -1.0 for j in range(d)])
                bc = BoxCorner(self, f"{mine}_corner{i}", member, size, at, rot, signs, *boxes[other])
                bc.system = system
                self._points.append(bc)
        if not isinstance(self.edges, bool):
            raise ModelError(f"{self.label}: edges: expected true or false, got {self.edges!r}")
        if self.edges and d != 3:
            raise ModelError(f"{self.label}: edges: edge crossings need a 3D system (in a plane the corners "
                             "cover every contact), got a planar one")
        if self.edges:
            for e in edge_contacts(self, (*boxes["a"], range(3), 0.0), (*boxes["b"], range(3), 0.0), 2, 2):
                e.system = system
                self._points.append(e)

    def point_contacts(self) -> list:
        return list(self._points)

    def spec(self):
        return {**super().spec(), "a": self.a.name, "size_a": self.size_a.tolist(), "at_a": self.at_a.tolist(),
                "rotation_a": self.rotation_a.tolist(), "b": self.b.name, "size_b": self.size_b.tolist(),
                "at_b": self.at_b.tolist(), "rotation_b": self.rotation_b.tolist(),
                **({"edges": True} if self.edges else {})}


def point_contacts(contacts) -> list:
    """The point contacts of ``contacts`` (elements expanded), in order."""
    return [p for c in contacts for p in c.point_contacts()]

