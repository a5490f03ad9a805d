"""MJCF import: a MuJoCo model file as a :class:`~ncgen.model.system.System`.

The file is read by :mod:`ncgen.model.mjcf_xml` (line numbers, ``<include>``, ``<default>``
classes and ``childclass``), frames by :mod:`ncgen.model.mjcf_frames` and mass properties
by :mod:`ncgen.model.mjcf_inertia`; the ncgen model comes from the XML alone.

* Bodies without joints are merged into their parent (into the ground under
  ``<worldbody>``); masses, centres of mass and inertia tensors are lumped exactly.  Each
  merged group that moves becomes a body (``ruvw``) with the axes of its first MJCF body and
  its origin at its centre of mass.  Mass comes from ``<inertial>`` (``diaginertia`` or
  ``fullinertia``) or from the geoms (``<compiler inertiafromgeom>``, ``auto`` by default;
  spheres, capsules, cylinders, boxes, ellipsoids of ``density`` or ``mass``).  A moving
  group without mass is refused.
* Joints (the file's configuration is ncgen's initial one, where MuJoCo's ``qpos`` is the
  joint's ``ref``: a hinge's or slide's coordinate is ``qpos − ref``, ``joint.mjcf_ref``):
  ``hinge`` → :class:`~ncgen.model.joints.Revolute`, ``slide`` →
  :class:`~ncgen.model.joints.Prismatic`, ``ball`` → :class:`~ncgen.model.joints.Spherical`,
  ``free``/``<freejoint>`` → :class:`~ncgen.model.joints.Free` (at the body's frame).  Several
  hinges or slides in one body (humanoid hips, ankles on skew axes, planar roots ``slide,
  slide, hinge``, ``slide, slide`` of a point mass) → one
  :class:`~ncgen.model.joints.JointSequence`, applied in the file's order as MuJoCo does,
  whose coordinates are MuJoCo's joints (named ``<sequence>.<MJCF joint>``, the sequence
  named by its joints' names joined by ``_``); the members carry its equations, so no
  massless intermediate body makes the mass matrix singular.  Sequences it does not take (a
  ball with other joints, hinges on parallel axes, three hinges not at one point with
  perpendicular axes, mixed orders) are refused, naming the body.
* Every hinge and slide (sequences' too) is actuated by one component of the input ``tau``
  (N·m or N, in ``model.joint_names`` order).  ``damping``, ``armature``, ``frictionloss``
  (as ``friction``) and ``range`` (when limited; less ``ref``) are the joint's (or the
  sequence coordinate's, ``joint.laws[k]``) dynamics (``simulate(joint_dynamics=True)``,
  :mod:`ncgen.model.joint_dynamics`); a hinge's ``stiffness`` is a
  :class:`~ncgen.model.forces.TorsionalSpring` towards ``springref``.
* Fixed tendons without a force of their own (stiffness, damping, friction loss, range) are
  ``system.tendons`` (``{name: {joint coordinate: coef}}``): transmissions of actuators and
  of equalities.  Actuators (:mod:`ncgen.model.mjcf_actuators`): ``motor``, ``position``,
  ``velocity``, ``damper`` and ``general`` (fixed or affine gain, none or affine bias, no
  activation dynamics) on a hinge, slide or such a tendon, with MuJoCo's ``ctrlrange``,
  ``forcerange`` and the joint's ``actuatorfrcrange`` clamps, as ``system.actuation``
  (``actuation.tau(model, qj, vj, ctrl)``, ``actuation.controller(ctrl)``: a compiled
  controller whose output is ``tau``), their moment arms ``system.actuator_gear`` (``tau =
  actuator_gear @ f``; a tendon's column holds ``gear × coef``) and ``system.actuators``
  (name, kind, joint or tendon, gear, gain, bias, ranges).
* Sites are markers of their member (``<body>_<site>`` frames for those on the ground);
  every body and site is a named frame (``system.frames``).  A spatial tendon through sites
  with a ``stiffness`` or ``damping`` is a :class:`~ncgen.model.cables.ClusteredCable`
  (:func:`_spatial_tendons`).
* ``<equality><connect body1 body2 anchor>`` closes a loop exactly: a
  :class:`~ncgen.model.joints.Spherical` joint at the anchor (body1's frame), the two
  bodies sharing the point (MuJoCo's constraint is soft; ncgen's holds to round-off);
  ``<weld body1 body2>`` (without ``relpose``) is a :class:`~ncgen.model.joints.Fixed` joint;
  ``<joint joint1 joint2 polycoef="0 c1 0 0 0">`` a :class:`~ncgen.model.joints.Mimic`, and
  so is ``<tendon tendon1>`` on a fixed tendon of two hinges or slides (``c_1 x_1 + c_2 x_2 = 0``).
* ``<option gravity>`` (and ``<flag gravity="disable"/>``) sets gravity.

Contacts (geom collisions, ``<contact>``) only with ``contacts=True``
(:mod:`ncgen.model.mjcf_contacts`).  Not part of the imported model, by design: sensors,
cameras, lights, visual and asset data, keyframes (``system.mjcf_ignored`` lists what the
file had).  Everything else the import cannot represent — other equality
constraints, spatial tendons over geoms or with a range, fixed tendons' forces, actuators
with activation dynamics or on sites, bodies and spatial tendons, fluid forces, a slide's
``stiffness``, dynamics on ball and free joints, ... — is named, element and line, in ONE :class:`MjcfWarning`, and
listed in ``system.mjcf_unsupported``.
"""
from __future__ import annotations

import warnings

import numpy as np

from ncgen.errors import ModelError
from ncgen.model.mjcf_frames import direction, pose, read_compiler
from ncgen.model.mjcf_inertia import SOLIDS, geom_part, inertial_part, lump
from ncgen.model.mjcf_xml import Defaults, choice, number, numbers, read_document, where
from ncgen.model.urdf import FLAT_TOL, identifier

#: Sections that carry no dynamics of the imported model (listed, never warned about).
IGNORED = ("visual", "asset", "statistic", "sensor", "keyframe", "custom", "contact", "size", "extension")
#: Body children the import reads.
BODY_TAGS = ("body", "joint", "freejoint", "geom", "site", "inertial", "camera", "light", "frame", "plugin")


class MjcfWarning(UserWarning):
    """Parts of an MJCF file that the imported model does not represent."""


class _Unsupported(list):
    def add(self, el, what: str) -> None:
        self.append(f"{where(el)} <{el.tag}>: {what}")


class _Group:
    """MJCF bodies merged by missing joints: the first body, its joints, the parts."""

    def __init__(self, body, T, joints, parent):
        self.body, self.T, self.joints, self.parent = body, T, joints, parent
        self.bodies, self.parts, self.geoms = [], [], []


def system_from_mjcf(source, system_class, *, name=None, contacts=False):
    """A system (an instance of ``system_class``) from an MJCF file or text; see the module
    docstring; ``contacts`` (True or a dict of contact keywords): the geoms as contact shapes
    (:mod:`ncgen.model.mjcf_contacts`)."""
    root, _, fname = read_document(source)
    compiler, bound = read_compiler(root)
    defaults = Defaults(root)
    unsupported = _Unsupported()
    for el, key in bound:
        unsupported.add(el, f"{key} (mass and inertia bounds are not applied)")
    gravity = _option(root, unsupported)
    s = system_class(identifier(name or root.get("model") or "mjcf"), gravity=gravity)
    worldbody = root.findall("worldbody")
    groups: list[_Group] = []
    ground = _Group(None, np.eye(4), [], None)
    sites: list = []
    for wb in worldbody:
        for child, T, cls in _flatten(wb, np.eye(4), None, compiler):
            if child.tag == "site":
                sites.append((child, T, ground, cls))
            if child.tag == "geom":
                ground.geoms.append(_geom(child, T, cls, ground, None, defaults))
            _walk(child, T, ground, cls, groups, sites, compiler, defaults, unsupported)
    if compiler.totalmass > 0:
        _scale_mass(compiler.totalmass, [ground] + groups)
    s.mjcf_ignored = sorted({el.tag for el in root if el.tag in IGNORED and not (contacts and el.tag == "contact")})
    member_of, joints, driven = _members(s, ground, groups, compiler, defaults, unsupported)
    spatial: list = []
    tendons = _tendons(s, root, joints, driven, defaults, compiler, unsupported, spatial)
    _actuators(s, root, joints, driven, tendons, defaults, unsupported)
    _frames(s, ground, groups, member_of, sites, defaults, compiler)
    _spatial_tendons(s, spatial, unsupported)
    if contacts is not False and contacts is not None:
        from ncgen.model.mjcf_contacts import add_contacts
        add_contacts(s, [g for group in [ground] + groups for g in group.geoms], {id(g): g.parent for g in groups},
                     member_of, _local, root, contacts, compiler, unsupported)
    for el in root:
        if el.tag == "equality":
            _equality(s, el, ground, groups, member_of, joints, tendons, defaults, unsupported)
    s.mjcf_unsupported = list(unsupported)
    if unsupported:
        warnings.warn(f"MJCF {fname}: {len(unsupported)} element(s) not imported (the model differs from "
                      "MuJoCo's there): " + "; ".join(unsupported), MjcfWarning, stacklevel=3)
    return s


def _equality(s, section, ground, groups, member_of, joints, tendons, defaults, unsupported) -> None:
    """``<connect body1 body2 anchor>`` as an exact :class:`~ncgen.model.joints.Spherical`
    joint (the bodies share the anchor point), ``<weld body1 body2>`` (the file's relative
    pose) as a :class:`~ncgen.model.joints.Fixed` one; other equality constraints are
    unsupported."""
    from ncgen.model.joints import Fixed, Spherical
    where_body = {b.get("name"): (g, T) for g in [ground] + groups for b, T in g.bodies if b.get("name")}
    for k, el in enumerate(section):
        a = defaults.attributes(el, None)
        name = a.get("name")
        if el.tag == "joint" and a.get("active", "true") != "false" and _joint_coupling(s, el, a, joints, k):
            continue
        if el.tag == "tendon" and a.get("active", "true") != "false" and _tendon_coupling(s, el, a, joints,
                                                                                          tendons, k):
            continue
        if el.tag not in ("connect", "weld") or "body1" not in a:
            unsupported.add(el, f"equality {el.tag} {name!r} is not imported".replace(" None", ""))
            continue
        if a.get("active", "true") == "false":
            unsupported.add(el, f"inactive {el.tag} {name!r} is not imported".replace(" None", ""))
            continue
        relpose = numbers(el, a, "relpose", 7, default=(0, 1, 0, 0, 0, 0, 0))
        if el.tag == "weld" and np.any(relpose[3:] != 0):
            unsupported.add(el, f"weld {name!r} with a relpose (only the file's relative pose is held)"
                            .replace(" None", ""))
            continue
        ends = []
        for key, default in (("body1", None), ("body2", "world")):
            body = a.get(key, default)
            if body == "world":
                ends.append((ground, np.eye(4)))
            elif body in where_body:
                ends.append(where_body[body])
            else:
                raise ModelError(f"MJCF {where(el)}: <connect {key}={body!r}>: no body of that name")
        (g1, T1), (g2, _) = ends
        if g1 is g2:
            raise ModelError(f"MJCF {where(el)}: <{el.tag}>: body1 and body2 move together (one rigid group); "
                             "the constraint would join a body to itself")
        cls = Spherical if el.tag == "connect" else Fixed
        anchor = T1[:3, :3] @ numbers(el, a, "anchor", 3, default=(0, 0, 0)) + T1[:3, 3]
        s.add_joint(cls(member_of[id(g1)], member_of[id(g2)], at=anchor, name=identifier(name or f"{el.tag}{k}")))


def _joint_coupling(s, el, a, joints, k) -> bool:
    """``<joint joint1 joint2 polycoef="c0 c1 0 0 0">``, ``x1 = c0 + c1 x2`` between two
    hinges or slides, as a :class:`~ncgen.model.joints.Mimic` (exact); False when it is not
    of that form (then unsupported): a polynomial of higher degree, one joint only, or an
    offset the file's configuration does not satisfy."""
    from ncgen.model.joints import Mimic
    c = numbers(el, a, "polycoef", 5, default=(0, 1, 0, 0, 0))
    found = [joints.get(a.get(key)) for key in ("joint1", "joint2")]
    if a.get("joint1") not in joints:
        raise ModelError(f"MJCF {where(el)}: <joint joint1={a.get('joint1')!r}>: no joint of that name")
    if a.get("joint2") is not None and found[1] is None:
        raise ModelError(f"MJCF {where(el)}: <joint joint2={a.get('joint2')!r}>: no joint of that name")
    if found[1] is None or np.any(c[2:] != 0) or any(kind not in ("hinge", "slide") for _, kind in found):
        return False
    (j1, _), (j2, _) = found
    offset = c[0] + c[1] * getattr(j2, "mjcf_ref", 0.0) - getattr(j1, "mjcf_ref", 0.0)
    if offset != 0:
        return False
    s.add_joint(Mimic(j2, j1, multiplier=c[1], name=identifier(a.get("name") or f"joint{k}")))
    return True


def _tendon_coupling(s, el, a, joints, tendons, k) -> bool:
    """``<tendon tendon1>`` (no ``tendon2``) on a fixed tendon of two hinges or slides with
    ``polycoef[0] = 0``: ``c_1 x_1 + c_2 x_2 = 0`` held exactly as a
    :class:`~ncgen.model.joints.Mimic` (``x_1 = −(c_2/c_1) x_2``); False otherwise (then
    unsupported)."""
    from ncgen.model.joints import Mimic
    name = a.get("tendon1")
    if name not in tendons:
        raise ModelError(f"MJCF {where(el)}: <tendon tendon1={name!r}>: no tendon of that name")
    c = numbers(el, a, "polycoef", 5, default=(0, 1, 0, 0, 0))
    pairs = [(j, coef) for j, coef in tendons[name] or [] if coef != 0]
    if "tendon2" in a or c[0] != 0 or len(pairs) != 2 or any(joints[j][1] not in ("hinge", "slide") for j, _ in pairs):
        return False
    (follower, c1), (leader, c2) = pairs
    s.add_joint(Mimic(joints[leader][0], joints[follower][0], multiplier=-c2 / c1,
                      name=identifier(a.get("name") or f"tendon{k}")))
    return True


def _option(root, unsupported) -> tuple:
    gravity = np.array([0.0, 0.0, -9.81])
    for el in root.findall("option"):
        g = numbers(el, el.attrib, "gravity", 3)
        if g is not None:
            gravity = g
        for key in ("density", "viscosity"):
            if number(el, el.attrib, key, 0.0) != 0:
                unsupported.add(el, f"{key} (fluid forces are not modelled)")
        if np.any(numbers(el, el.attrib, "wind", 3, default=(0, 0, 0)) != 0):
            unsupported.add(el, "wind (fluid forces are not modelled)")
        for flag in el.findall("flag"):
            if flag.get("gravity") == "disable":
                gravity = np.zeros(3)
            for key in ("passive", "spring", "damper", "actuation"):
                if flag.get(key) == "disable":
                    unsupported.add(flag, f"{key}=\"disable\" (the imported forces act)")
    return tuple(float(x) for x in gravity)


def _flatten(el, T, cls, compiler):
    """``(child, pose in el's frame, class)`` of ``el``'s children, ``<frame>``s opened."""
    for child in el:
        if child.tag == "frame":
            yield from _flatten(child, T @ pose(child, child.attrib, compiler), child.get("childclass") or cls,
                                compiler)
        else:
            yield child, T, cls


def _walk(el, T_parent, group, childclass, groups, sites, compiler, defaults, unsupported) -> None:
    """Collect the body ``el`` (at ``T_parent`` @ its pose) and the bodies under it into groups."""
    tag = el.tag
    if tag in ("geom", "site", "camera", "light"):
        return                                       # read with their body (or the world)
    if tag == "plugin":
        unsupported.add(el, "plugins are not imported")
        return
    if tag in ("replicate", "composite", "flexcomp", "attach"):
        raise ModelError(f"MJCF {where(el)}: <{tag}> makes bodies that the import cannot read; expand it "
                         "first (e.g. save the model from MuJoCo: mujoco.mj_saveLastXML)")
    if tag != "body":
        raise ModelError(f"MJCF {where(el)}: <{tag}> cannot be here (expected one of {', '.join(BODY_TAGS)}; "
                         "joints and inertials directly in a body)")
    cls = el.get("childclass") or childclass
    T = T_parent @ pose(el, el.attrib, compiler)
    joints = [(j, _joint_attrs(j, defaults, cls)) for j in el if j.tag in ("joint", "freejoint")]
    if el.get("mocap") == "true":
        unsupported.add(el, "mocap body (held fixed)")
    if number(el, el.attrib, "gravcomp", 0.0) != 0:
        unsupported.add(el, "gravcomp (gravity compensation is not modelled)")
    if joints:
        group = _Group(el, T, joints, group)
        groups.append(group)
    group.bodies.append((el, T))
    contents = []
    for c, Tc, ccls in _flatten(el, np.eye(4), cls, compiler):
        if c.tag in ("joint", "freejoint", "inertial"):
            if not any(c is d for d in el):
                raise ModelError(f"MJCF {where(c)}: <{c.tag}> inside a <frame>: the import reads joints and "
                                 "inertials given directly in their body")
            continue
        contents.append((c, Tc, ccls))
    group.parts += _parts(el, [(c, Tc, ccls) for c, Tc, ccls in contents if c.tag == "geom"], T, cls, compiler,
                          defaults, unsupported)
    for child, Tc, ccls in contents:
        if child.tag == "site":
            sites.append((child, T @ Tc, group, ccls))
        if child.tag == "geom":
            group.geoms.append(_geom(child, T @ Tc, ccls, group, el, defaults))
    for child, Tc, ccls in contents:
        _walk(child, T @ Tc, group, ccls, groups, sites, compiler, defaults, unsupported)


def _geom(el, T, cls, group, body, defaults):
    """A :class:`~ncgen.model.mjcf_contacts.Geom` of ``group`` (``body``: its MJCF body, None
    in ``<worldbody>``), at ``T`` (its container's world pose)."""
    from ncgen.model.mjcf_contacts import Geom
    owner = "world" if body is None else body.get("name") or "body"
    name = el.get("name") or f"{owner}_geom{len(group.geoms)}"
    return Geom(el, defaults.attributes(el, cls), T, group, body, name)


def _scale_mass(total: float, groups) -> None:
    """``<compiler settotalmass>``: every mass and inertia scaled so that the bodies' masses
    add up to ``total`` (kg), as MuJoCo does."""
    now = sum(m for g in groups for m, _, _ in g.parts)
    if now > 0:
        f = total / now
        for g in groups:
            g.parts = [(f * m, c, f * I) for m, c, I in g.parts]


def _joint_attrs(j, defaults, cls) -> dict:
    attrs = defaults.attributes(j, cls)
    if j.tag == "freejoint":
        attrs = dict(j.attrib, type="free")
    return attrs


def _parts(body, geoms, T, cls, compiler, defaults, unsupported) -> list:
    """The body's mass parts in world axes (zero configuration); ``geoms``: its geoms with
    their poses in the body's frame and classes."""
    parts = []
    inertial = body.find("inertial")
    use_geoms = compiler.inertiafromgeom == "true" or (compiler.inertiafromgeom == "auto" and inertial is None)
    if inertial is not None and compiler.inertiafromgeom != "true":
        parts.append(inertial_part(inertial, inertial.attrib, compiler))
    lo, hi = compiler.group_range
    for g, Tg, gcls in geoms if use_geoms else []:
        attrs = defaults.attributes(g, gcls)
        kind = choice(g, attrs, "type", ("plane", "hfield", "sphere", "capsule", "ellipsoid", "cylinder",
                                         "box", "mesh", "sdf"), "sphere")
        if not lo <= int(number(g, attrs, "group", 0)) <= hi:
            continue
        if kind not in SOLIDS:
            if kind == "plane" or ("mass" in attrs and number(g, attrs, "mass", 0.0) == 0):
                continue
            raise ModelError(f"MJCF {where(g)}: <geom type={kind!r}> gives its body's mass, which the import "
                             "cannot compute; give the body an <inertial> (or the geom mass=\"0\")")
        if attrs.get("shellinertia") == "true":
            unsupported.add(g, "shellinertia (computed as a solid)")
        part = geom_part(g, attrs, compiler)
        if part is not None:
            m, c, I = part
            parts.append((m, Tg[:3, :3] @ c + Tg[:3, 3], Tg[:3, :3] @ I @ Tg[:3, :3].T))
    R, p = T[:3, :3], T[:3, 3]
    return [(m, R @ c + p, R @ I @ R.T) for m, c, I in parts]


def _bodies(s, ground, groups) -> dict:
    """``{id(group): member}``: one body per group of welded MJCF bodies (their lumped mass and
    inertia), the world the ground."""
    member_of = {id(ground): s.ground}
    for g in groups:
        mass, com, inertia = lump(g.parts)
        bname = identifier(g.body.get("name") or f"body{len(member_of)}")
        if mass <= 0:
            names = ", ".join(repr(b.get("name", "?")) for b, _ in g.bodies)
            raise ModelError(f"MJCF {where(g.body)}: body {names} moves (joints) but has no mass; ncgen needs mass "
                             "on every moving body: give it an <inertial> or a geom with mass")
        R = g.T[:3, :3]
        I_body = R.T @ inertia @ R
        _check_inertia(I_body, g.body)
        member_of[id(g)] = s.add_body(bname, mass=mass, inertia=I_body, position=com, rotation=R)
    return member_of


def _members(s, ground, groups, compiler, defaults, unsupported):
    """Bodies and joints of the groups; returns ``(member of group, {MJCF joint name: (joint,
    kind)}, the joints driven by tau in its order)``."""
    from ncgen.model.forces import TorsionalSpring
    from ncgen.model.joints import Free, Prismatic, Revolute, Spherical

    member_of = _bodies(s, ground, groups)
    actuated = [j for g in groups for j, a in g.joints if a.get("type", "hinge") in ("hinge", "slide")]
    tau = s.add_input("tau", len(actuated)) if actuated else None
    effort = {id(j): k for k, j in enumerate(actuated)}
    joints, driven = {}, []
    for g in groups:
        A, B = member_of[id(g.parent)], member_of[id(g)]
        kinds = [a.get("type", "hinge") for _, a in g.joints]
        R, p = g.T[:3, :3], g.T[:3, 3]
        if len(kinds) > 1:
            _sequence(s, g, A, B, tau, effort, joints, driven, compiler, unsupported, TorsionalSpring)
            continue
        j, a = g.joints[0]
        kind = kinds[0]
        jname = identifier(j.get("name") or f"{B.name}_{kind}")
        at = R @ numbers(j, a, "pos", 3, default=(0, 0, 0)) + p
        if kind == "free":
            if not A.is_ground:
                raise ModelError(f"MJCF {where(j)}: a free joint must be in a body that is a child of the world")
            joint = s.add_joint(Free(A, B, at=p, rotation=R, name=jname))
            _passive_unsupported(j, a, unsupported, "a free joint")
        elif kind == "ball":
            joint = s.add_joint(Spherical(A, B, at=at, name=jname))
            _passive_unsupported(j, a, unsupported, "a ball joint")
        elif kind in ("hinge", "slide"):
            axis = R @ direction(j, a, "axis", (0, 0, 1))
            cls = Revolute if kind == "hinge" else Prismatic
            joint = s.add_joint(cls(A, B, at=at, axis=axis, name=jname, effort=tau[effort[id(j)]]))
            driven.append(joint.name)
            _joint_dynamics(joint, j, a, kind, compiler, unsupported,
                            lambda k, rest, joint=joint: s.add_force(TorsionalSpring(
                                joint, k=k, rest_angle=rest, name=f"{joint.name}_spring")))
        else:
            choice(j, a, "type", ("free", "ball", "slide", "hinge"), "hinge")
        if j.get("name"):
            joints[j.get("name")] = (joint, kind)
    return member_of, joints, driven


def _sequence(s, g, A, B, tau, effort, joints, driven, compiler, unsupported, TorsionalSpring) -> None:
    """Several hinges or slides in one body as one :class:`~ncgen.model.joints.JointSequence`
    (applied in the file's order, as MuJoCo does), each coordinate with its own dynamics and
    spring."""
    from ncgen.model.joints import JointSequence
    R, p = g.T[:3, :3], g.T[:3, 3]
    steps, names = [], []
    for k, (j, a) in enumerate(g.joints):
        kind = a.get("type", "hinge")
        if kind not in ("hinge", "slide"):
            raise ModelError(f"MJCF {where(j)}: a {kind} joint in body {B.name!r} with other joints; "
                             "several joints in one body are taken as hinges or slides applied in order")
        steps.append((kind, R @ numbers(j, a, "pos", 3, default=(0, 0, 0)) + p,
                       R @ direction(j, a, "axis", (0, 0, 1))))
        names.append(identifier(j.get("name") or f"{kind}{k}"))
    name = identifier("_".join(names))
    k0 = effort[id(g.joints[0][0])]
    try:
        joint = s.add_joint(JointSequence(A, B, steps=steps, names=names, name=name,
                                          effort=tau[k0:k0 + len(steps)]))
    except ModelError as e:
        raise ModelError(f"MJCF {where(g.body)}: body {B.name!r}, joints "
                         f"{', '.join(names)}: {e}") from None
    for k, ((j, a), law) in enumerate(zip(g.joints, joint.laws)):
        kind = a.get("type", "hinge")
        driven.append(f"{joint.name}.{law.name}")
        if j.get("name"):
            joints[j.get("name")] = (joint, "sequence")
        _joint_dynamics(law, j, a, kind, compiler, unsupported,
                        lambda stiff, rest, k=k, law=law: s.add_force(TorsionalSpring(
                            joint, k=stiff, rest_angle=rest, coordinate=k, name=f"{joint.name}_{law.name}_spring")))


def _passive_unsupported(j, a, unsupported, what: str) -> None:
    for key in ("damping", "armature", "stiffness", "frictionloss"):
        if number(j, a, key, 0.0) != 0:
            unsupported.add(j, f"{key} on {what}")
    if _limited(j, a):
        unsupported.add(j, f"range on {what}")


def _limited(j, a, autolimits: bool = True) -> bool:
    """Whether the joint's ``range`` applies (``limited``, or ``auto`` with
    ``<compiler autolimits>`` and a range given)."""
    lim = a.get("limited", "auto")
    return lim == "true" or (lim == "auto" and autolimits and "range" in a)


def _joint_dynamics(joint, j, a, kind, compiler, unsupported, spring) -> None:
    """``joint``'s (or a sequence coordinate's law's) ``mjcf_ref``, dynamics and limits from
    the MJCF joint ``j``; a hinge's ``stiffness`` through ``spring(k, rest angle)``."""
    angle = compiler.angle if kind == "hinge" else float
    ref = angle(number(j, a, "ref", 0.0))
    joint.mjcf_ref = ref
    dyn = {}
    for key, ours in (("damping", "damping"), ("armature", "armature"), ("frictionloss", "friction")):
        value = number(j, a, key, 0.0)
        if value < 0:
            raise ModelError(f"MJCF {where(j)}: <joint {key}={a[key]!r}>: expected a number ≥ 0")
        if value:
            dyn[ours] = value
    if _limited(j, a, compiler.autolimits):
        lo, hi = numbers(j, a, "range", 2, default=(0, 0))
        if lo > hi:
            raise ModelError(f"MJCF {where(j)}: <joint range={a.get('range')!r}>: the lower bound is above the upper")
        dyn.update(lower=angle(lo) - ref, upper=angle(hi) - ref)
    joint.set_dynamics(**dyn)
    joint.mjcf_actuatorfrcrange = None
    if a.get("actuatorfrclimited") == "true" or (a.get("actuatorfrclimited", "auto") == "auto"
                                                  and "actuatorfrcrange" in a):
        lo, hi = numbers(j, a, "actuatorfrcrange", 2, default=(0, 0))
        if lo > hi:
            raise ModelError(f"MJCF {where(j)}: <joint actuatorfrcrange={a.get('actuatorfrcrange')!r}>: the lower "
                             "bound is above the upper")
        joint.mjcf_actuatorfrcrange = (float(lo), float(hi))
    k = number(j, a, "stiffness", 0.0)
    if "springdamper" in a:
        unsupported.add(j, "springdamper")
    if k:
        if kind == "slide":
            unsupported.add(j, "stiffness on a slide joint")
        else:
            spring(k, angle(number(j, a, "springref", 0.0)) - ref)


def _rate_index(joints, driven) -> dict:
    """``{MJCF joint name: its component of tau}`` for the hinges and slides."""
    return {n: driven.index(j.name if kind in ("hinge", "slide") else f"{j.name}.{identifier(n)}")
            for n, (j, kind) in joints.items() if kind in ("hinge", "slide", "sequence")}


#: Attributes of a tendon that make it act (the import takes fixed tendons without them).
TENDON_FORCES = ("stiffness", "damping", "frictionloss", "armature")


def _tendons(s, root, joints, driven, defaults, compiler, unsupported, spatial) -> dict:
    """Fixed tendons as ``s.tendons`` (``{name: {joint coordinate: coef}}``, the length
    ``L = Σ coef x_k`` of hinge and slide coordinates): they carry an actuator's transmission
    (a motor's force ``f`` acts as ``coef_k f`` on joint k) or an equality.  A tendon with a
    force of its own (stiffness, damping, friction loss, armature, a range), on a ball or free
    joint, or spatial, is unsupported.  Returns ``{name: [(MJCF joint, coef)]}`` (None for
    the unsupported ones)."""
    index = _rate_index(joints, driven)
    s.tendons, out = {}, {}
    for section in root.findall("tendon"):
        for k, el in enumerate(section):
            a = {**defaults.classes.get(el.get("class") or "main", {}).get("tendon", {}),
                 **defaults.attributes(el, None)}
            name = a.get("name") or f"tendon{k}"
            out[name] = None
            if el.tag == "spatial":
                spatial.append((el, a, name))
                continue
            if el.tag != "fixed":
                unsupported.add(el, f"tendon {el.tag} {name!r} is not imported")
                continue
            acting = [key for key in TENDON_FORCES if number(el, a, key, 0.0) != 0]
            if _limited(el, a, compiler.autolimits):
                acting.append("range")
            coefs, pairs = {}, []
            for item in el:
                target = item.get("joint")
                if item.tag != "joint" or target not in joints:
                    raise ModelError(f"MJCF {where(item)}: <{item.tag} joint={target!r}> in tendon {name!r}: "
                                     "expected <joint joint=...> naming a joint")
                if target not in index:
                    acting.append(f"ball or free joint {target!r}")
                    continue
                c = number(item, item.attrib, "coef", 1.0)
                coefs[driven[index[target]]] = coefs.get(driven[index[target]], 0.0) + c
                pairs.append((target, c))
            if acting:
                unsupported.add(el, f"tendon fixed {name!r} ({', '.join(acting)} not modelled)")
                continue
            s.tendons[name], out[name] = coefs, pairs
    return out


def _spatial_tendons(s, spatial, unsupported) -> None:
    """Spatial tendons through sites only, with a ``stiffness`` or ``damping`` and no other
    force (friction loss, armature, range), as
    :class:`~ncgen.model.cables.ClusteredCable` forces named as the tendon: the length ``L =
    Σ |s_{i+1} − s_i|`` between the sites, the tension ``k (L − springlength) + c L̇``
    (``springlength`` −1: the file's length), kept ≥ 0 (MuJoCo's tendon spring also pushes
    below ``springlength``; a cable goes slack).  Others are unsupported."""
    from ncgen.model.cables import ClusteredCable
    for el, a, name in spatial:
        k, c = number(el, a, "stiffness", 0.0), number(el, a, "damping", 0.0)
        others = [key for key in ("frictionloss", "armature") if number(el, a, key, 0.0) != 0]
        if _limited(el, a):
            others.append("range")
        items = [item.tag if item.tag != "site" else None for item in el]
        rest = numbers(el, a, "springlength", (1, 2), default=(-1.0,))
        if others or any(items) or len(items) < 2 or rest[0] != rest[-1] or k < 0 or c < 0 or not (k or c):
            why = (f"{', '.join(others)} not modelled" if others else
                   f"<{next(t for t in items if t)}> in its path (only sites are taken)" if any(items) else
                   "a dead band (two springlength values)" if rest[0] != rest[-1] else
                   "no stiffness or damping: nothing acts" if not (k or c) else "fewer than two sites")
            unsupported.add(el, f"tendon spatial {name!r} ({why})")
            continue
        path = []
        for item in el:
            site = identifier(item.get("site", ""))
            if site not in s.frames:
                raise ModelError(f"MJCF {where(item)}: <site site={item.get('site')!r}> in tendon {name!r}: "
                                 "no site of that name")
            member, _, p = s.frames[site]
            path.append((s.ground if member == "ground" else s.member(member), p))
        if rest[0] < 0:
            ends = [s.frames[identifier(item.get("site"))] for item in el]
            world = [p if m == "ground" else s.member(m).R0 @ p + s.member(m).p0 for m, _, p in ends]
            rest = [sum(float(np.linalg.norm(b - q)) for q, b in zip(world, world[1:]))]
        s.add_force(ClusteredCable(path, k=k, rest_length=float(rest[0]), damping=c, name=identifier(name)))


def _actuators(s, root, joints, driven, tendons, defaults, unsupported) -> None:
    """The actuators on hinges, slides and imported fixed tendons as ``s.actuation``
    (:class:`~ncgen.model.mjcf_actuators.Actuation`: MuJoCo's gain, bias and clamps), their
    moment arms ``s.actuator_gear`` (``tau = actuator_gear @ f``; a tendon's column holds
    ``gear × coef``) and ``s.actuators`` (one dict per actuator, for reports)."""
    from ncgen.model.mjcf_actuators import Actuation, actuator_law, inherited_range
    index = _rate_index(joints, driven)
    coordinate = {d: _coordinate(joints, n, d) for n, d in ((n, driven[k]) for n, k in index.items())}
    s.actuators = []
    columns, laws = [], []
    elements = [el for section in root.findall("actuator") for el in section]
    for k, el in enumerate(elements):
        a = defaults.attributes(el, None)
        target = _transmission(el, a, joints, tendons)
        name = a.get("name") or f"actuator{k}"
        law, why = actuator_law(el, a, name)
        on_tendon = target == "tendon" and tendons[a["tendon"]] is not None
        if law is not None and target == "tendon" and not on_tendon:
            why = f"actuator {name!r} on tendon {a['tendon']!r}, which is not imported"
        elif law is not None and not (on_tendon or (target == "joint" and a["joint"] in index)):
            why = f"actuator {name!r} on a {target} (only hinges, slides and fixed tendons are imported)"
        if why:
            unsupported.add(el, why)
            continue
        if law.inheritrange > 0:
            obj = None if on_tendon else coordinate[driven[index[a["joint"]]]]
            limits = {} if obj is None else obj.limits
            if on_tendon:
                unsupported.add(el, f"actuator {name!r}: inheritrange on a tendon")
                continue
            if "lower" not in limits or "upper" not in limits:
                raise ModelError(f"MJCF {where(el)}: <position inheritrange=...> on joint {a['joint']!r}, which has "
                                 "no range (MuJoCo refuses it too)")
            ref = getattr(obj, "mjcf_ref", 0.0)
            law.ctrlrange = inherited_range(law, (limits["lower"] + ref, limits["upper"] + ref))
        gear = numbers(el, a, "gear", None, default=(1.0,))[0]
        column = np.zeros(len(driven))
        for joint, c in (tendons[a["tendon"]] if on_tendon else [(a["joint"], 1.0)]):
            column[index[joint]] += gear * c
        columns.append(column)
        laws.append(law)
        s.actuators.append({"name": name, "kind": el.tag, ("tendon" if on_tendon else "joint"):
                            a["tendon"] if on_tendon else driven[index[a["joint"]]], "gear": gear,
                            "gain": law.gain, "bias": law.bias, "ctrlrange": law.ctrlrange,
                            "forcerange": law.forcerange})
    s.actuator_gear = np.column_stack(columns) if columns else np.zeros((len(driven), 0))
    ref = np.zeros(len(driven))
    ranges = {}
    for d, obj in coordinate.items():
        ref[driven.index(d)] = getattr(obj, "mjcf_ref", 0.0)
        if getattr(obj, "mjcf_actuatorfrcrange", None) is not None:
            ranges[driven.index(d)] = obj.mjcf_actuatorfrcrange
    s.actuation = Actuation(laws, s.actuator_gear, ref, driven, ranges)


def _transmission(el, a: dict, joints: dict, tendons: dict) -> str:
    """The actuator ``el``'s one transmission (``joint``, ``tendon``, ``site``, ``body`` or
    ``jointinparent``), checked to name a joint or tendon of the model where it is one."""
    target = [key for key in ("joint", "tendon", "site", "body", "jointinparent") if key in a]
    if len(target) != 1:
        raise ModelError(f"MJCF {where(el)}: <{el.tag}> needs exactly one transmission (joint, tendon, site, "
                         f"body), found {target or 'none'}")
    if target[0] in ("joint", "jointinparent") and a[target[0]] not in joints:
        raise ModelError(f"MJCF {where(el)}: <{el.tag} {target[0]}={a[target[0]]!r}>: no joint of that name")
    if target[0] == "tendon" and a["tendon"] not in tendons:
        raise ModelError(f"MJCF {where(el)}: <{el.tag} tendon={a['tendon']!r}>: no tendon of that name")
    return target[0]


def _coordinate(joints, mjcf_name, driven_name):
    """The joint (a hinge or slide) or sequence law whose coordinate is ``driven_name``."""
    joint, kind = joints[mjcf_name]
    if kind != "sequence":
        return joint
    return next(law for law in joint.laws if f"{joint.name}.{law.name}" == driven_name)


def _frames(s, ground, groups, member_of, sites, defaults, compiler) -> None:
    s.frames = {}
    for g in [ground] + groups:
        m = member_of[id(g)]
        for body, T in g.bodies:
            if body.get("name"):
                s.frames[identifier(body.get("name"))] = ("ground" if m.is_ground else m.name, *_local(m, T))
    for el, T_body, g, cls in sites:
        attrs = defaults.attributes(el, cls)
        T = T_body @ pose(el, attrs, compiler)
        m = member_of[id(g)]
        R, p = _local(m, T)
        name = identifier(el.get("name") or f"site{len(s.frames)}")
        s.frames[name] = ("ground" if m.is_ground else m.name, R, p)
        if not m.is_ground and name not in m.markers:
            m.add_marker(name, p)


def _local(m, T) -> tuple[np.ndarray, np.ndarray]:
    if m.is_ground:
        return T[:3, :3].copy(), T[:3, 3].copy()
    return m.R0.T @ T[:3, :3], m.R0.T @ (T[:3, 3] - m.p0)


def _check_inertia(I, body) -> None:
    e = np.linalg.eigvalsh(0.5 * (I + I.T))
    scale = max(float(e.max()), 1e-300)
    if e.min() < -FLAT_TOL * scale or min(e[1] + e[2] - e[0], e[0] + e[2] - e[1], e[0] + e[1] - e[2]) < -FLAT_TOL * scale:
        raise ModelError(f"MJCF {where(body)}: body {body.get('name')!r}: the lumped inertia tensor is not physical "
                         f"(principal moments {e.tolist()})")
