"""The collision-pair table: which contact element joins two shapes, as MuJoCo's table of
collision functions.

:data:`PAIRS` maps a pair of shape kinds (:mod:`ncgen.model.shapes`; ``"plane"`` for the
ground) to the element whose gap and normal :mod:`ncgen.assembly.contact_kinematics` computes, one
function per pair:

=================  =========================================================================
pair               element (point contacts)
=================  =========================================================================
sphere–plane       :class:`~ncgen.model.contacts.SpherePlane`
box–plane          :class:`~ncgen.model.contacts.BoxPlane` (corners)
capsule–plane      :class:`~ncgen.model.contacts.CapsulePlane` (end spheres)
cylinder–plane     :class:`~ncgen.model.contacts.CylinderPlane` (rim points, face points)
sphere–sphere      :class:`~ncgen.model.contacts.SphereSphere`
sphere–box         :class:`~ncgen.model.contacts.SphereBox`
box–box            :class:`~ncgen.model.contacts.BoxBox` (corners, edge crossings)
capsule–sphere     :class:`~ncgen.model.capsule_contacts.CapsuleSphere`
capsule–capsule    :class:`~ncgen.model.capsule_contacts.CapsuleCapsule` (ends, segments)
capsule–box        :class:`~ncgen.model.capsule_contacts.CapsuleBox` (ends, corners, edges)
cylinder–sphere    :class:`~ncgen.model.capsule_contacts.CylinderSphere`
mesh–plane         :class:`~ncgen.model.contacts.MeshPlane` (its convex hull's vertices)
=================  =========================================================================

Any other pair (a cylinder against a box, a capsule or a cylinder; a mesh against
anything but a plane; an ellipsoid against anything) is refused by :func:`contact_between` with a message naming
both shapes.  :data:`CONTACT_TYPES` lists every element by its TOML ``type``.
"""
from __future__ import annotations

from ncgen.errors import ModelError
from ncgen.model.capsule_contacts import CapsuleBox, CapsuleCapsule, CapsuleSphere, CylinderSphere
from ncgen.model.contacts import (BoxBox, BoxPlane, CapsulePlane, Contact, CylinderPlane, MeshPlane, SphereBox,
                                  SpherePlane, SphereSphere)

#: Shape kinds (sorted as in the table) -> contact element.
PAIRS: dict[tuple[str, str], type[Contact]] = {
    ("sphere", "plane"): SpherePlane, ("box", "plane"): BoxPlane, ("capsule", "plane"): CapsulePlane,
    ("cylinder", "plane"): CylinderPlane, ("sphere", "sphere"): SphereSphere, ("sphere", "box"): SphereBox,
    ("box", "box"): BoxBox, ("capsule", "sphere"): CapsuleSphere, ("capsule", "capsule"): CapsuleCapsule,
    ("capsule", "box"): CapsuleBox, ("cylinder", "sphere"): CylinderSphere, ("mesh", "plane"): MeshPlane,
}

#: Every contact element by its ``kind`` (TOML ``type``).
CONTACT_TYPES: dict[str, type[Contact]] = {cls.kind: cls for cls in (
    SpherePlane, SphereSphere, BoxPlane, CapsulePlane, CylinderPlane, SphereBox, BoxBox, CapsuleSphere,
    CapsuleCapsule, CapsuleBox, CylinderSphere, MeshPlane)}


def pair_element(kind_a: str, kind_b: str) -> tuple[type[Contact], bool]:
    """The element joining shapes of kinds ``kind_a`` and ``kind_b`` and whether it takes
    them in the other order; a :class:`ModelError` naming both for a pair not in :data:`PAIRS`."""
    if (kind_a, kind_b) in PAIRS:
        return PAIRS[kind_a, kind_b], False
    if (kind_b, kind_a) in PAIRS:
        return PAIRS[kind_b, kind_a], True
    def article(kind):
        return "an" if kind[0] in "aeiou" else "a"
    raise ModelError(f"no contact between {article(kind_a)} {kind_a} and {article(kind_b)} {kind_b}: that pair is not "
                     f"in the collision-pair table (supported: {', '.join(f'{a}–{b}' for a, b in PAIRS)})")


def _shape(member):
    """``(kind, shape)`` of ``member``: the ground is a plane; a member without a shape is refused."""
    if member.is_ground:
        return "plane", None
    if member.shape is None:
        raise ModelError(f"contact_between: member {member.name!r} has no shape: give it one "
                         f"(shape=nc.Box(...), nc.Sphere(...), nc.Capsule(...), ...)")
    return member.shape.kind, member.shape


def contact_between(a, b, **material) -> Contact:
    """The contact element between the shapes of members ``a`` and ``b`` (``member.shape``,
    placed by its ``position`` and ``rotation``; the ground is the plane z = 0 with normal +z,
    ``s.ground`` may be either), from :data:`PAIRS`; ``material``:
    ``mu``, ``restitution``, the smooth law's keywords and ``name``.  Add it with
    ``s.add_contact(...)``.  A pair not in the table is refused naming both shapes."""
    (ka, sa), (kb, sb) = _shape(a), _shape(b)
    if ka == kb == "plane":
        raise ModelError("contact_between: both members are the ground")
    try:
        pair_element(ka, kb)
    except ModelError as e:
        raise ModelError(f"contact_between({a.name!r}, {b.name!r}): {e}") from None
    return shape_contact(a, sa, b, sb, **material)


def shape_contact(a, sa, b, sb, **material) -> Contact:
    """The element of :data:`PAIRS` between shape ``sa`` (a :class:`~ncgen.model.shapes.Shape`
    placed in member ``a``'s frame) and ``sb`` on ``b``; a shape None is the ground's plane
    z = 0.  A pair not in the table raises :func:`pair_element`'s error."""
    ka, kb = ("plane" if sh is None else sh.kind for sh in (sa, sb))
    cls, swap = pair_element(ka, kb)
    if swap:
        (a, sa, ka), (b, sb, kb) = (b, sb, kb), (a, sa, ka)
    if kb == "plane":
        place = dict(at=sa.position, rotation=sa.rotation, plane=b)
        if ka == "sphere":
            return SpherePlane(a, sa.position, sa.size[0], plane=b, **material)
        if ka == "box":
            return BoxPlane(a, size=sa.size, **place, **material)
        if ka == "mesh":
            return MeshPlane(a, sa.filename, sa.scale, **place, **material)
        return cls(a, radius=sa.size[0], length=sa.size[1], **place, **material)
    if cls is SphereSphere:
        return SphereSphere(a, sa.position, sa.size[0], b, sb.position, sb.size[0], **material)
    if cls is SphereBox:
        return SphereBox(a, sa.position, sa.size[0], box=b, size=sb.size, box_at=sb.position,
                         box_rotation=sb.rotation, **material)
    if cls is BoxBox:
        return BoxBox(a, sa.size, b, sb.size, at_a=sa.position, rotation_a=sa.rotation, at_b=sb.position,
                      rotation_b=sb.rotation, **material)
    capsule = dict(radius=sa.size[0], length=sa.size[1], at=sa.position, rotation=sa.rotation)
    if cls is CapsuleSphere:
        return CapsuleSphere(b, sb.position, sb.size[0], capsule=a, **capsule, **material)
    if cls is CylinderSphere:
        return CylinderSphere(b, sb.position, sb.size[0], cylinder=a, **capsule, **material)
    if cls is CapsuleCapsule:
        return CapsuleCapsule(a, sa.size[0], sa.size[1], b, sb.size[0], sb.size[1], at_a=sa.position,
                              rotation_a=sa.rotation, at_b=sb.position, rotation_b=sb.rotation, **material)
    return CapsuleBox(a, **capsule, box=b, size=sb.size, box_at=sb.position, box_rotation=sb.rotation, **material)
