"""MJCF geoms as contact shapes (``System.from_mjcf(path, contacts=True)``).

The pairs are MuJoCo's (``mj_collision``'s filter), between the import's rigid groups (a
MuJoCo weld group: a body with joints and the bodies without joints under it, or the world
and the bodies fixed to it):

* not two geoms of one group;
* not a group and its parent group (``filterparent``), unless one geom is in ``<worldbody>``
  itself;
* ``contype``/``conaffinity`` compatible: ``(contype₁ & conaffinity₂) | (contype₂ &
  conaffinity₁) ≠ 0``;
* not two bodies of a ``<contact><exclude body1 body2>``.

Each pair becomes the element of :data:`~ncgen.model.contact_pairs.PAIRS` for its shapes
(sphere, box, capsule, cylinder; a plane only in the world), placed at the geoms' poses in
their members' frames, named ``<geom1>__<geom2>`` (a geom without a name: ``<body>_geom<k>``).
Friction ``mu`` is the larger of the two geoms' sliding friction (MuJoCo's default mixing);
``contacts`` may be a dict of contact keywords (``mu``, ``stiffness``, ``damping``,
``restitution``, ``exponent``, ``slip_velocity``) that apply to every pair.  Pairs of shapes
ncgen has no element for (a cylinder against a box, a capsule or a cylinder; ellipsoids,
meshes, height fields; a sphere fixed in the world against a moving sphere, capsule or cylinder, a
capsule fixed in the world against a moving box) and ``<contact><pair>`` are named in the
import's warning.
"""
from __future__ import annotations

import itertools

from ncgen.errors import ModelError
from ncgen.model.mjcf_inertia import geom_frame
from ncgen.model.mjcf_xml import number, numbers, where
from ncgen.model.urdf import identifier

#: The contact keywords ``contacts=`` may give.
MATERIAL_KEYS = ("mu", "stiffness", "damping", "restitution", "exponent", "slip_velocity")
#: MJCF geom types that can be contact shapes.
SHAPES = ("plane", "sphere", "box", "capsule", "cylinder")


class Geom:
    """One MJCF geom: element, attributes, kind, sizes, world pose (file configuration), its
    group (rigid body of the import), its MJCF body element (None: ``<worldbody>``)."""

    def __init__(self, el, attrs, T, group, body, name):
        self.el, self.attrs, self.group, self.body, self.name = el, attrs, group, body, name
        self.kind = attrs.get("type", "sphere")
        self.T, self.size = T, None

    def placed(self, compiler) -> "Geom":
        Tg, self.size = geom_frame(self.el, self.attrs, compiler)
        self.T = self.T @ Tg
        return self

    def bits(self, key: str) -> int:
        return int(number(self.el, self.attrs, key, 1))


def material_of(contacts) -> dict:
    """The contact keywords of ``contacts`` (True or a dict)."""
    if contacts is True:
        return {}
    if not isinstance(contacts, dict):
        raise ModelError(f"from_mjcf: contacts: expected True, False or a dict of contact keywords "
                         f"({', '.join(MATERIAL_KEYS)}), got {contacts!r}")
    unknown = [k for k in contacts if k not in MATERIAL_KEYS]
    if unknown:
        raise ModelError(f"from_mjcf: contacts: unknown key(s) {', '.join(map(repr, unknown))}; expected "
                         f"{', '.join(MATERIAL_KEYS)}")
    return dict(contacts)


def excluded_bodies(root) -> set:
    """``{frozenset((body1, body2))}`` of ``<contact><exclude>``."""
    out = set()
    for section in root.findall("contact"):
        for el in section.findall("exclude"):
            if "body1" not in el.attrib or "body2" not in el.attrib:
                raise ModelError(f"MJCF {where(el)}: <exclude> needs body1 and body2")
            out.add(frozenset((el.get("body1"), el.get("body2"))))
    return out


def pairs(geoms: list[Geom], parent_of: dict, excluded: set) -> list[tuple[Geom, Geom]]:
    """The geom pairs MuJoCo's filter lets through (module docstring); ``parent_of``: ``{id(group):
    parent group}``."""
    out = []
    for a, b in itertools.combinations(geoms, 2):
        if a.group is b.group:
            continue
        if a.body is not None and b.body is not None and (
                parent_of.get(id(a.group)) is b.group or parent_of.get(id(b.group)) is a.group):
            continue
        if not (a.bits("contype") & b.bits("conaffinity") or b.bits("contype") & a.bits("conaffinity")):
            continue
        names = (a.body.get("name") if a.body is not None else "world",
                 b.body.get("name") if b.body is not None else "world")
        if frozenset(names) in excluded:
            continue
        out.append((a, b))
    return out


def add_contacts(s, geoms, parent_of, member_of, local, root, contacts, compiler, unsupported) -> None:
    """The contact elements of the pairs (module docstring) added to ``s``; ``local(member, T)``:
    a world pose as ``(R, p)`` in the member's frame."""
    from ncgen.model.contact_pairs import PAIRS
    material = material_of(contacts)
    for section in root.findall("contact"):
        for el in section.findall("pair"):
            unsupported.add(el, "explicit contact pair (only the geoms' own filtering is imported)")
    placed = [g.placed(compiler) for g in geoms]
    for a, b in pairs(placed, parent_of, excluded_bodies(root)):
        if a.kind not in SHAPES or b.kind not in SHAPES or not (
                (a.kind, b.kind) in PAIRS or (b.kind, a.kind) in PAIRS or "plane" in (a.kind, b.kind)):
            unsupported.add(a.el, f"contact of geom {a.name!r} ({a.kind}) with {b.name!r} ({b.kind}) at "
                            f"{where(b.el)} (no contact element for that pair)")
            continue
        if (b.kind, a.kind) in PAIRS and (a.kind, b.kind) not in PAIRS:
            a, b = b, a
        if b.kind == "plane" and a.kind == "plane":
            continue
        if a.kind == b.kind and a.group.body is None:
            a, b = b, a                              # the moving shape first (SphereSphere's a, BoxBox's a)
        mu = max(numbers(g.el, g.attrs, "friction", (1, 2, 3), default=(1.0,))[0] for g in (a, b))
        kw = {"mu": mu, **material, "name": identifier(f"{a.name}__{b.name}")}
        try:
            s.add_contact(_element(a, b, member_of, local, kw))
        except ModelError as e:                      # e.g. a fixed sphere against a moving capsule
            unsupported.add(a.el, f"contact of geom {a.name!r} ({a.kind}) with {b.name!r} ({b.kind}) at "
                            f"{where(b.el)} ({e})")


def _element(a: Geom, b: Geom, member_of, local, kw):
    """The element of :data:`~ncgen.model.contact_pairs.PAIRS` for geoms ``a``, ``b`` (in the
    table's order)."""
    from ncgen.model.capsule_contacts import CapsuleBox, CapsuleCapsule, CapsuleSphere, CylinderSphere
    from ncgen.model.contacts import (BoxBox, BoxPlane, CapsulePlane, CylinderPlane, SphereBox, SpherePlane,
                                      SphereSphere)
    ma, mb = member_of[id(a.group)], member_of[id(b.group)]
    (Ra, pa), (Rb, pb) = local(ma, a.T), local(mb, b.T)
    ra, rb = a.size[0], b.size[0]
    if b.kind == "plane":
        if not mb.is_ground:
            raise ModelError(f"MJCF {where(b.el)}: a plane geom in a moving body; contacts take planes in the world")
        plane = dict(plane=mb, point=b.T[:3, 3], normal=b.T[:3, 2])
        if a.kind == "sphere":
            return SpherePlane(ma, pa, ra, **plane, **kw)
        shape = {"box": dict(size=2 * a.size)}.get(a.kind, dict(radius=ra, length=2 * a.size[1]))
        cls = {"box": BoxPlane, "capsule": CapsulePlane, "cylinder": CylinderPlane}[a.kind]
        return cls(ma, at=pa, rotation=Ra, **shape, **plane, **kw)
    pair = (a.kind, b.kind)
    if pair == ("sphere", "sphere"):
        return SphereSphere(ma, pa, ra, mb, pb, rb, **kw)
    if pair == ("sphere", "box"):
        return SphereBox(ma, pa, ra, box=mb, size=2 * b.size, box_at=pb, box_rotation=Rb, **kw)
    if pair == ("box", "box"):
        return BoxBox(ma, 2 * a.size, mb, 2 * b.size, at_a=pa, rotation_a=Ra, at_b=pb, rotation_b=Rb, **kw)
    axial = dict(radius=ra, length=2 * a.size[1], at=pa, rotation=Ra)
    if pair == ("capsule", "sphere"):
        return CapsuleSphere(mb, pb, rb, capsule=ma, **axial, **kw)
    if pair == ("cylinder", "sphere"):
        return CylinderSphere(mb, pb, rb, cylinder=ma, **axial, **kw)
    if pair == ("capsule", "capsule"):
        return CapsuleCapsule(ma, ra, 2 * a.size[1], mb, rb, 2 * b.size[1], at_a=pa, rotation_a=Ra, at_b=pb,
                              rotation_b=Rb, **kw)
    return CapsuleBox(ma, **axial, box=mb, size=2 * b.size, box_at=pb, box_rotation=Rb, **kw)
