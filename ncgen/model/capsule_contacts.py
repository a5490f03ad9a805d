"""Capsules against spheres, capsules and boxes, as point contacts.

A capsule is the set of points within ``radius`` r (m) of a segment of ``length`` L (m)
along the local z of its axes ``rotation`` (columns, in its member's frame), centred at
``at`` of its member (a rigid body, or the ground for a fixed one).

* :class:`CapsuleSphere`: a sphere against the capsule, one point (exact: the distance from
  the sphere's centre to the segment less both radii);
* :class:`CapsuleCapsule`: each end sphere of one against the other capsule
  (``<name>.a_end0``, ``a_end1``, ``b_end0``, ``b_end1``) and the two segments where they
  cross (``<name>.segments``, an :class:`~ncgen.model.contacts.EdgeContact`): parallel,
  crossed or end on side;
* :class:`CylinderSphere`: a sphere against a solid cylinder, one point (the signed
  distance);
* :class:`CapsuleBox`: the capsule's end spheres against the box (``<name>.end0``,
  ``end1``, :class:`~ncgen.model.contacts.SphereBox` points), the box's corners against
  the capsule (``<name>.corner0 …``) and the segment against the box's edges where they
  cross (``<name>.edge2j0r``, :class:`~ncgen.model.contacts.EdgeContact`).

Gaps and normals: :mod:`ncgen.assembly.contact_kinematics`.  Sign conventions as in
:mod:`ncgen.model.contacts`: the normal points from the capsule (or ``a``'s segment)
towards the other element, whose forces are reported.
"""
from __future__ import annotations

import numpy as np

from ncgen.errors import ModelError
from ncgen.model.contacts import Contact, EdgeContact, SphereBox, _box_frame, edge_contacts
from ncgen.validation import as_vector, rotation as as_rotation


def _capsule(contact, member, radius, length, at, rotation, what: str):
    """Check a capsule (or a cylinder: ``what``) carried by ``member`` (the ground or a
    body): returns ``(radius, length, at, rotation)`` as numbers and arrays."""
    shape = "cylinder" if what == "cylinder" else "capsule"
    if not member.is_ground and member.kind != "body":
        raise ModelError(f"{contact.label}: {what}: a {shape} needs the ground or a rigid body to carry it, got the "
                         f"{member.kind} {member.name!r}")
    if member.dim != 3:
        raise ModelError(f"{contact.label}: a {shape} needs a 3D system, got a planar one")
    radius = contact._length(radius, f"{what} radius")
    length = contact._length(length, f"{what} length", positive=False)
    at = as_vector(np.zeros(3) if at is None else at, 3, f"{contact.label}: {what} at")
    rotation = np.eye(3) if rotation is None else as_rotation(rotation, 3, f"{contact.label}: {what} rotation")
    return radius, length, at, rotation


def _material(element) -> dict:
    return dict(mu=element.mu, restitution=element.restitution, stiffness=element.stiffness,
                damping=element.damping, exponent=element.exponent, slip_velocity=element.slip_velocity)


class CapsuleSphere(Contact):
    """A sphere of ``sphere_radius`` (m, ≥ 0) centred at ``sphere_at`` of ``sphere`` against
    the capsule ``(radius, length, at, rotation)`` of ``capsule`` (the ground by default, or
    a body).  The gap is ``|x − p| − r_s − r``, ``p`` the point of the segment nearest to the
    sphere's centre ``x``; the normal points from p to x; forces are those on the sphere."""

    kind = "CapsuleSphere"
    ground_default = "capsule"

    def __init__(self, sphere, sphere_at=None, sphere_radius=0.0, *, capsule=None, radius=None, length=None,
                 at=None, rotation=None, **material):
        super().__init__(**material)
        self.sphere, self.sphere_at, self.sphere_radius = sphere, sphere_at, sphere_radius
        self.capsule, self.radius, self.length, self.at, self.rotation = capsule, radius, length, at, rotation

    def members(self):
        return [self.sphere] + ([] if self.capsule is None else [self.capsule])

    def check(self, system):
        if self.capsule is self.sphere:
            raise ModelError(f"{self.label}: the sphere and the capsule are on the same member {self.sphere.name!r}")
        self.radius, self.length, self.at, self.rotation = _capsule(self, self.capsule, self.radius, self.length,
                                                                    self.at, self.rotation, "capsule")
        self._check_sphere(system.dim)

    def _check_sphere(self, dim: int):
        self.sphere_at, self.sphere_radius = self._sphere(
            self.sphere, np.zeros(dim) if self.sphere_at is None else self.sphere_at, self.sphere_radius, "sphere")

    @property
    def total_radius(self) -> float:
        """Both radii (m): the gap is the centre's distance to the segment less this."""
        return self.sphere_radius + self.radius

    def spec(self):
        return {**super().spec(), "sphere": self.sphere.name, "sphere_at": np.asarray(self.sphere_at).tolist(),
                "sphere_radius": self.sphere_radius, "capsule": self.capsule.name, "radius": self.radius,
                "length": self.length, "at": np.asarray(self.at).tolist(), "rotation": self.rotation.tolist()}


class CapsulePoint(CapsuleSphere):
    """One point contact of a capsule element (built by it, never attached): a sphere (an end
    of another capsule, or a box corner of radius 0, possibly on the ground) against the
    capsule; the element has checked both."""

    def __init__(self, element, suffix: str, sphere, sphere_at, sphere_radius, capsule, radius, length, at,
                 rotation):
        super().__init__(sphere, np.asarray(sphere_at, float), float(sphere_radius), capsule=capsule, radius=radius,
                         length=length, at=at, rotation=rotation, name=f"{element.name}.{suffix}", **_material(element))
        self.kind, self.element = element.kind, element.name

    def check(self, system):
        """Checked by the element."""

    def spec(self):
        return {**super().spec(), "element": self.element}


def _end(at, rotation, length, sign) -> np.ndarray:
    return np.asarray(at) + sign * length / 2 * np.asarray(rotation)[:, 2]


class CapsuleCapsule(Contact):
    """Two capsules: ``(radius_a, length_a, at_a, rotation_a)`` on ``a`` and likewise on ``b``
    (a body, or the ground for a fixed one).  Five point contacts: the end spheres of ``a``
    against capsule ``b`` (``<name>.a_end0``, ``a_end1``, forces on ``a``), those of ``b``
    against ``a`` (``b_end0``, ``b_end1``, forces on ``b``), and the segments where their
    closest points are inside both (``<name>.segments``, forces on ``b``).  Exact: two
    capsules are nearest at an end of one of their segments or where the segments cross."""

    kind = "CapsuleCapsule"

    def __init__(self, a, radius_a=None, length_a=None, b=None, radius_b=None, length_b=None, *, at_a=None,
                 rotation_a=None, at_b=None, rotation_b=None, **material):
        super().__init__(**material)
        self.a, self.radius_a, self.length_a, self.at_a, self.rotation_a = a, radius_a, length_a, at_a, rotation_a
        self.b, self.radius_b, self.length_b, self.at_b, self.rotation_b = b, radius_b, length_b, at_b, rotation_b
        self._points: list = []

    def members(self):
        return [self.a, self.b]

    def check(self, system):
        if self.a is self.b:
            raise ModelError(f"{self.label}: both capsules are on the same member {self.a.name!r}")
        caps = {}
        for w in "ab":
            r, L, at, rot = _capsule(self, getattr(self, w), getattr(self, f"radius_{w}"), getattr(self, f"length_{w}"),
                                     getattr(self, f"at_{w}"), getattr(self, f"rotation_{w}"), w)
            setattr(self, f"radius_{w}", r), setattr(self, f"length_{w}", L)
            setattr(self, f"at_{w}", at), setattr(self, f"rotation_{w}", rot)
            caps[w] = (getattr(self, w), r, L, at, rot)
        points = []
        for mine, other in (("a", "b"), ("b", "a")):
            m, r, L, at, rot = caps[mine]
            for i, sign in enumerate((-1, 1)):
                points.append(CapsulePoint(self, f"{mine}_end{i}", m, _end(at, rot, L, sign), r, *caps[other]))
        sides = [(m, (0.0, 0.0, L), at, rot, [2], r) for m, r, L, at, rot in (caps["a"], caps["b"])]
        seg = edge_contacts(self, *sides, 1, 1)[0]
        seg.name = f"{self.name}.segments"
        self._points = points + [seg]
        for p in self._points:
            p.system = system

    def point_contacts(self):
        return list(self._points)

    def spec(self):
        return {**super().spec(), "a": self.a.name, "radius_a": self.radius_a, "length_a": self.length_a,
                "at_a": self.at_a.tolist(), "rotation_a": self.rotation_a.tolist(), "b": self.b.name,
                "radius_b": self.radius_b, "length_b": self.length_b, "at_b": self.at_b.tolist(),
                "rotation_b": self.rotation_b.tolist()}


class CapsuleBox(Contact):
    """A capsule ``(radius, length, at, rotation)`` on ``capsule`` (a rigid body) against a
    box of full edge lengths ``size`` centred at ``box_at`` with axes ``box_rotation`` on
    ``box`` (the ground by default, or a body).  Point contacts: the capsule's end spheres
    against the box (``<name>.end0``, ``end1``: the exact signed distance,
    :class:`~ncgen.model.contacts.SphereBox`, forces on the capsule), the box's corners
    against the capsule (``<name>.corner0 …``, numbered as ``BoxPlane``'s, forces on the
    box) and the segment against the box's edges where they cross (``<name>.edge2j0r``, j
    the box's axis, forces on the box).  A capsule meets a box at an end sphere, at a box
    corner, or where its segment crosses an edge: lying on a face (its ends), across a
    face narrower than it (the crossings of that face's edges), over an edge or a corner."""

    kind = "CapsuleBox"
    ground_default = "box"

    def __init__(self, capsule, radius=None, length=None, *, at=None, rotation=None, box=None, size=None, box_at=None,
                 box_rotation=None, **material):
        super().__init__(**material)
        self.capsule, self.radius, self.length, self.at, self.rotation = capsule, radius, length, at, rotation
        self.box, self.size, self.box_at, self.box_rotation = box, size, box_at, box_rotation
        self._points: list = []

    def members(self):
        return [self.capsule] + ([] if self.box is None else [self.box])

    def check(self, system):
        if self.box is self.capsule:
            raise ModelError(f"{self.label}: the capsule and the box are on the same member {self.box.name!r}")
        if self.capsule.is_ground:
            raise ModelError(f"{self.label}: capsule: a CapsuleBox needs a moving capsule (a rigid body), got the "
                             "ground; give the fixed shape as the box, or use a CapsuleCapsule")
        self.radius, self.length, self.at, self.rotation = _capsule(self, self.capsule, self.radius, self.length,
                                                                    self.at, self.rotation, "capsule")
        self.size, self.box_at, self.box_rotation = _box_frame(self, self.box, self.size, self.box_at,
                                                               self.box_rotation, "box", system.dim)
        cap = (self.capsule, self.radius, self.length, self.at, self.rotation)
        points = []
        for i, sign in enumerate((-1, 1)):
            end = SphereBox(self.capsule, _end(self.at, self.rotation, self.length, sign), self.radius,
                            box=self.box, size=self.size, box_at=self.box_at, box_rotation=self.box_rotation,
                            name=f"{self.name}.end{i}", **_material(self))
            end.kind, end.element = self.kind, self.name
            end.check(system)
            points.append(end)
        for i in range(8):
            corner = self.box_at + self.box_rotation @ (
                np.array([1.0 if i >> j & 1 else -1.0 for j in range(3)]) * self.size / 2)
            points.append(CapsulePoint(self, f"corner{i}", self.box, corner, 0.0, *cap))
        points += edge_contacts(self, (self.capsule, (0.0, 0.0, self.length), self.at, self.rotation, [2], self.radius),
                                (self.box, self.size, self.box_at, self.box_rotation, range(3), 0.0), 1, 2)
        self._points = points
        for p in self._points:
            p.system = system

    def point_contacts(self):
        return list(self._points)

    def spec(self):
        return {**super().spec(), "capsule": self.capsule.name, "radius": self.radius, "length": self.length,
                "at": self.at.tolist(), "rotation": self.rotation.tolist(), "box": self.box.name,
                "size": self.size.tolist(), "box_at": self.box_at.tolist(), "box_rotation": self.box_rotation.tolist()}


class CylinderSphere(CapsuleSphere):
    """A sphere of ``sphere_radius`` (m, ≥ 0) centred at ``sphere_at`` of ``sphere`` against
    the solid cylinder of ``radius`` and ``length`` (m) along the local z of ``rotation``,
    centred at ``at`` of ``cylinder`` (the ground by default, or a body).  One point: the
    signed distance from the sphere's centre to the cylinder less ``sphere_radius`` —
    outside, the distance to its nearest point (side, end face or rim); inside, the largest
    of the side's and the end planes' distances (:mod:`ncgen.assembly.contact_kinematics`).  The
    normal points from the cylinder towards the sphere; forces are those on the sphere."""

    kind = "CylinderSphere"
    ground_default = "cylinder"

    def __init__(self, sphere, sphere_at=None, sphere_radius=0.0, *, cylinder=None, radius=None, length=None,
                 at=None, rotation=None, **material):
        super().__init__(sphere, sphere_at, sphere_radius, capsule=cylinder, radius=radius, length=length, at=at,
                         rotation=rotation, **material)

    @property
    def cylinder(self):
        return self.capsule

    @cylinder.setter
    def cylinder(self, member):
        self.capsule = member

    def check(self, system):
        if self.capsule is self.sphere:
            raise ModelError(f"{self.label}: the sphere and the cylinder are on the same member {self.sphere.name!r}")
        self.radius, self.length, self.at, self.rotation = _capsule(self, self.capsule, self.radius, self.length,
                                                                    self.at, self.rotation, "cylinder")
        self.length = self._length(self.length, "cylinder length")
        self._check_sphere(system.dim)

    @property
    def total_radius(self) -> float:
        return self.sphere_radius

    def spec(self):
        out = super().spec()
        out["cylinder"] = out.pop("capsule")
        return out
