"""URDF import: a robot description as a :class:`~ncgen.model.system.System`.

Parsing is the standard library's (:mod:`ncgen.model.urdf_reader`; meshes are not loaded);
this module maps the parsed tree:

* Links joined by ``fixed`` joints are merged into one member; their masses, centres of mass
  and inertia tensors are lumped exactly (parallel-axis theorem).  Everything fixed to the
  root link is the ground (or, with ``floating_base=True``, the root body).
* Each merged group with mass becomes a body (``ruvw``) whose frame has the axes of the
  group's first link and its origin at the group's centre of mass; ``<inertial>`` origins
  and off-diagonal inertia are honoured.  A moving group without mass is refused, naming
  its links (its natural coordinates would have no inertia).
* ``revolute``/``continuous`` become :class:`~ncgen.model.joints.Revolute`, ``prismatic``
  :class:`~ncgen.model.joints.Prismatic`, at the child link's origin along its axis (world,
  zero configuration = the initial one, so joint coordinates match the URDF's).
  ``<mimic>`` adds a :class:`~ncgen.model.joints.Mimic` equation (the follower is not
  actuated).  ``floating``/``planar`` joints inside the tree are refused.
* Every other movable joint is actuated by one component of the input ``tau`` (N·m or N),
  in ``model.joint_names`` order; limits (``lower``, ``upper``, ``velocity``, ``effort``)
  are kept as data (``model.joint_limits``), ``<dynamics damping friction>`` too
  (``joint.dynamics``); both act in simulation with ``simulate(joint_dynamics=True)``
  (:mod:`ncgen.model.joint_dynamics`).
* ``floating_base=True``: the root is a body with a :class:`~ncgen.model.joints.Free`
  joint named ``root`` (Pinocchio's free flyer at the root link's frame).
* Link frames (``model.frames``, ``model.frame_pose``) and visual geometry
  (``system.visuals``: boxes, cylinders, spheres; meshes by file name) are kept as data.
* ``collisions=True`` (or a dict): each moving link's ``<collision>`` box, cylinder and
  sphere becomes a contact against the ground plane z = 0 (:class:`~ncgen.model.contacts.BoxPlane`,
  ``CylinderPlane``, ``SpherePlane``) named ``<link>_collision<i>`` (``i`` counts the link's
  collision elements); meshes, and the geometry of links fixed to the ground, are skipped
  (``system.skipped_collisions`` names them).  The dict holds contact keywords for every
  contact (``mu``, ``restitution``, ``stiffness``, ``damping``, ``exponent``,
  ``slip_velocity``) and ``ground`` (default True: the contacts with the ground plane),
  ``self`` (default False: contacts between links) and ``exclude`` (pairs of link names).
  With ``self=True`` every two shapes of different rigid bodies (links welded by fixed joints
  are one body; the ground's links included) are paired by the element of
  :data:`~ncgen.model.contact_pairs.PAIRS`, named ``<shape a>__<shape b>``, except a body
  and its parent body (the two sides of a movable joint) and the bodies of each ``exclude``
  pair.  Pairs without an element (a cylinder against a box or a cylinder) are named in one
  :class:`UrdfCollisionWarning` and in ``system.skipped_collisions``.

Names: link and joint names become identifiers (characters other than letters, digits and
``_`` replaced by ``_``).
"""
from __future__ import annotations

import itertools
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ncgen.errors import ModelError
from ncgen.model.urdf_checks import check_urdf_document
from ncgen.model.urdf_reader import read_urdf
from ncgen.validation import as_system_name

MOVABLE = ("revolute", "continuous", "prismatic")
#: Keys of ``collisions`` that choose the contacts, and the contact keywords it may give.
COLLISION_KEYS = ("ground", "self", "exclude")
CONTACT_KEYS = ("mu", "restitution", "stiffness", "damping", "exponent", "slip_velocity")


class UrdfCollisionWarning(UserWarning):
    """Pairs of links' collision shapes that no contact element joins (``collisions`` with ``self``)."""

#: Relative tolerance under which a principal moment sum ``I_a + I_b − I_c`` counts as zero
#: (a thin disc or plate, whose natural-coordinate mass matrix is singular).
FLAT_TOL = 1e-9


@dataclass
class Group:
    """Links merged by fixed joints: the first link, every link's zero-configuration pose,
    and the lumped mass properties (world axes, about the centre of mass)."""

    root: str
    links: list[str] = field(default_factory=list)
    mass: float = 0.0
    com: np.ndarray = field(default_factory=lambda: np.zeros(3))
    inertia: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))


def identifier(name: str) -> str:
    s = re.sub(r"\W", "_", name)
    return s if s and not s[0].isdigit() else f"_{s}"


def load_urdf(source):
    """``(robot, where)``: the records of a URDF file or text (:mod:`ncgen.model.urdf_reader`;
    meshes are not loaded) and the name of its source for messages."""
    text = str(source)
    if "<" in text:
        where = "URDF text"
    else:
        path = Path(source)
        if not path.is_file():
            raise ModelError(f"URDF: no file {str(path)!r} (expected a path to a .urdf file or URDF text)")
        where = str(path)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as e:
            raise ModelError(f"URDF {where}: cannot read it: {e}") from None
    check_urdf_document(text, where)
    try:
        return read_urdf(text), where
    except ValueError as e:         # a number the checks do not cover (a <limit>, a shape's size)
        raise ModelError(f"URDF {where}: cannot parse it: {e}") from None


def _origin(T) -> np.ndarray:
    return np.eye(4) if T is None else np.asarray(T, float)


def system_from_urdf(source, system_class, *, floating_base: bool = False, gravity=(0.0, 0.0, -9.81), name=None,
                     collisions=False):
    """A system (an instance of ``system_class``, :class:`~ncgen.model.system.System`) from a
    URDF file or text; see the module docstring."""
    from ncgen.model.joints import Free

    robot, where = load_urdf(source)
    links = {ln.name: ln for ln in robot.links}
    joints = list(robot.joints)
    parent_of = {j.child: j for j in joints}
    root = _check_tree(links, joints, parent_of, where)
    pose, order, group_of = _zero_poses(root, joints)
    order_index = {ln: k for k, ln in enumerate(order)}
    movable = sorted((j for j in joints if j.type != "fixed"), key=lambda j: order_index[j.child])

    groups: dict[str, Group] = {}
    for ln in order:
        g = groups.setdefault(group_of[ln], Group(group_of[ln]))
        g.links.append(ln)
    for g in groups.values():
        _lump(g, links, pose)

    s = system_class(name if name is not None else as_system_name(robot.name or "", "robot"), gravity=gravity)
    member_of = _add_bodies(s, groups, root if not floating_base else None, parent_of, pose, where)

    tau = s.add_input("tau", len([j for j in movable if j.mimic is None])) if movable else None
    s.frames = {}
    s.visuals = []
    for ln in order:
        m = member_of[group_of[ln]]
        s.frames[identifier(ln)] = (m.name if not m.is_ground else "ground",
                                    *_local(m, pose[ln]))
        for vis in links[ln].visuals or []:
            s.visuals.append(_visual(ln, m, pose[ln] @ _origin(vis.origin), vis))

    if floating_base:
        s.add_joint(Free(s.ground, member_of[root], at=pose[root][:3, 3], rotation=pose[root][:3, :3],
                         name="root"))
    _add_joints(s, movable, [member_of[group_of[j.parent]] for j in movable],
                [member_of[group_of[j.child]] for j in movable], pose, tau, where)
    s.skipped_collisions = []
    if collisions is not False and collisions is not None:
        _add_collisions(s, collisions, order, links, member_of, group_of, pose, where, parent_of)
    return s


def _check_tree(links: dict, joints: list, parent_of: dict, where: str) -> str:
    """The root link of the robot's tree, after checking that every joint joins defined links
    and is of a supported type, and that one link has no parent."""
    for j in joints:
        for role, ln in (("parent", j.parent), ("child", j.child)):
            if ln not in links:
                raise ModelError(f"URDF {where}: joint {j.name!r}: {role} link {ln!r} is not defined")
        if j.type not in MOVABLE + ("fixed",):
            raise ModelError(f"URDF {where}: joint {j.name!r}: type {j.type!r} is not supported "
                             f"(supported: {', '.join(MOVABLE)}, fixed)")
    roots = [ln for ln in links if ln not in parent_of]
    if len(roots) != 1:
        raise ModelError(f"URDF {where}: expected one root link (a tree), found {roots}")
    return roots[0]


def _zero_poses(root: str, joints: list) -> tuple[dict, list, dict]:
    """``(pose, order, group_of)``: every link's world pose (4×4) at the zero configuration, the
    links depth first in file order, and the link each is welded to by fixed joints (its group)."""
    children: dict[str, list] = {}
    for j in joints:
        children.setdefault(j.parent, []).append(j)
    pose = {root: np.eye(4)}
    order = []
    group_of = {root: root}
    stack = [root]
    while stack:
        here = stack.pop()
        order.append(here)
        for j in reversed(children.get(here, [])):
            pose[j.child] = pose[here] @ _origin(j.origin)
            group_of[j.child] = group_of[here] if j.type == "fixed" else j.child
            stack.append(j.child)
    return pose, order, group_of


def _add_bodies(s, groups: dict, grounded: str | None, parent_of: dict, pose: dict, where: str) -> dict:
    """``{group: member}``: one body per group of welded links (its lumped mass and inertia),
    the group ``grounded`` (the root of a fixed-base robot) the ground."""
    member_of: dict[str, object] = {}
    for gname, g in groups.items():
        if gname == grounded:
            member_of[gname] = s.ground
            continue
        moved_by = f"joint {parent_of[gname].name!r}" if gname in parent_of else "the floating base"
        if g.mass <= 0:
            raise ModelError(f"URDF {where}: link(s) {', '.join(g.links)} (moved by {moved_by}) have no mass "
                             "(no <inertial>); ncgen needs mass on every moving body: add an <inertial>, "
                             "or make the joint fixed so the link is merged into its parent")
        R = pose[gname][:3, :3]
        I_body = R.T @ g.inertia @ R
        _check_inertia(I_body, g, where, moved_by)
        member_of[gname] = s.add_body(identifier(gname), mass=g.mass, inertia=I_body, position=g.com,
                                      rotation=R)
    return member_of


def _add_joints(s, movable: list, parents: list, children: list, pose: dict, tau, where: str) -> None:
    """The movable joints (revolute, continuous, prismatic) between the members ``parents[i]``
    and ``children[i]`` at their zero-configuration poses, with their limits, damping and
    friction, each driven by its component of the input ``tau`` unless it mimics another
    (those as :class:`~ncgen.model.joints.Mimic` constraints, added last)."""
    from ncgen.model.joints import Mimic, Prismatic, Revolute

    made = {}
    k = 0
    for j, A, B in zip(movable, parents, children):
        T = pose[j.child]
        axis = T[:3, :3] @ (np.asarray(j.axis, float) if j.axis is not None else np.array([1.0, 0, 0]))
        effort = None
        if j.mimic is None:
            effort, k = tau[k], k + 1
        cls = Prismatic if j.type == "prismatic" else Revolute
        joint = s.add_joint(cls(A, B, at=T[:3, 3], axis=axis, name=identifier(j.name), effort=effort))
        lim = j.limit
        joint.limits = {} if lim is None else {
            key: float(getattr(lim, key)) for key in ("lower", "upper", "velocity", "effort")
            if getattr(lim, key) is not None and not (j.type == "continuous" and key in ("lower", "upper"))}
        dyn = j.dynamics
        if dyn is not None:
            joint.set_dynamics(**{k: getattr(dyn, k) for k in ("damping", "friction") if getattr(dyn, k)})
        made[j.name] = joint
    for j in movable:
        if j.mimic is not None:
            leader = made.get(j.mimic.joint)
            if leader is None:
                raise ModelError(f"URDF {where}: joint {j.name!r}: mimics {j.mimic.joint!r}, which is not a "
                                 "movable joint of this robot")
            s.add_joint(Mimic(leader, made[j.name], multiplier=j.mimic.multiplier or 1.0,
                              offset=j.mimic.offset or 0.0, name=identifier(f"{j.name}_mimic")))


def _add_collisions(s, collisions, order, links, member_of, group_of, pose, where, parent_of) -> None:
    """The contacts of the links' collision geometry: against the ground plane, and between
    links with ``self`` (see the module docstring)."""
    from ncgen.model.contact_pairs import shape_contact
    material, ground, self_contact, excluded = _collision_options(collisions, links, group_of, where)
    shapes = []                                      # (group, member, name, shape) in link order
    for ln in order:
        m = member_of[group_of[ln]]
        for i, col in enumerate(links[ln].collisions or []):
            name = identifier(f"{ln}_collision{i}")
            try:
                shape = _collision_shape(col.geometry, *_local(m, pose[ln] @ _origin(col.origin)))
            except ModelError as e:
                raise ModelError(f"URDF {where}: link {ln!r}: <collision> {i}: {e}") from None
            if shape is None or (m.is_ground and not self_contact):
                s.skipped_collisions.append(name)
                continue
            if ground and not m.is_ground:
                s.add_contact(shape_contact(m, shape, s.ground, None, name=name, **material))
            shapes.append((group_of[ln], m, name, shape))
    if not self_contact:
        return
    parent_group = {g: group_of[parent_of[g].parent] for g in set(group_of.values()) if g in parent_of}
    refused = []
    for (ga, ma, na, sa), (gb, mb, nb, sb) in itertools.combinations(shapes, 2):
        if ga == gb or parent_group.get(ga) == gb or parent_group.get(gb) == ga or frozenset((ga, gb)) in excluded:
            continue
        name = f"{na}__{nb}"
        reason = _pair_refusal(s, (ma, sa, mb, sb), name, material)
        if reason:
            s.skipped_collisions.append(name)
            refused.append(f"{name} ({sa.kind}–{sb.kind}: {reason})")
    if refused:
        warnings.warn(f"URDF {where}: collisions: {len(refused)} pair(s) of links' shapes have no contact element "
                      f"and are not modelled (system.skipped_collisions): " + "; ".join(refused),
                      UrdfCollisionWarning, stacklevel=4)


def _pair_refusal(s, shapes, name, material) -> str | None:
    """Add the contact between two placed shapes ``(ma, sa, mb, sb)``; None, or why not."""
    from ncgen.model.contact_pairs import pair_element, shape_contact
    try:
        pair_element(shapes[1].kind, shapes[3].kind)
    except ModelError:
        return "no contact element for that pair"
    try:
        s.add_contact(shape_contact(*shapes, name=name, **material))
    except ModelError as e:                          # e.g. an element that takes no shape on the ground
        return str(e)
    return None


def _collision_options(collisions, links, group_of, where) -> tuple[dict, bool, bool, set]:
    """``(material, ground, self, excluded)`` of ``collisions`` (True or a dict); ``excluded``:
    ``{frozenset((group, group))}`` of the ``exclude`` pairs of links."""
    if collisions is True:
        return {}, True, False, set()
    if not isinstance(collisions, dict):
        raise ModelError(f"URDF {where}: collisions: expected True, False or a dict of contact keywords "
                         f"(mu, restitution, ...) and of ground, self, exclude, got {collisions!r}")
    unknown = [k for k in collisions if k not in CONTACT_KEYS + COLLISION_KEYS]
    if unknown:
        raise ModelError(f"URDF {where}: collisions: unknown key(s) {', '.join(map(repr, unknown))}; expected "
                         f"{', '.join(COLLISION_KEYS + CONTACT_KEYS)}")
    flags = {}
    for key, default in (("ground", True), ("self", False)):
        flags[key] = collisions.get(key, default)
        if not isinstance(flags[key], bool):
            raise ModelError(f"URDF {where}: collisions: {key}: expected True or False, got {flags[key]!r}")
    pairs = collisions.get("exclude", [])
    if pairs and not flags["self"]:
        raise ModelError(f"URDF {where}: collisions: exclude: filters the pairs of links, which only self=True makes")
    if not isinstance(pairs, (list, tuple)):
        raise ModelError(f"URDF {where}: collisions: exclude: expected a list of pairs of link names, got {pairs!r}")
    excluded = set()
    for k, pair in enumerate(pairs):
        if not (isinstance(pair, (list, tuple)) and len(pair) == 2 and all(isinstance(x, str) for x in pair)):
            raise ModelError(f"URDF {where}: collisions: exclude[{k}]: expected a pair of link names, got {pair!r}")
        for ln in pair:
            if ln not in links:
                raise ModelError(f"URDF {where}: collisions: exclude[{k}]: {ln!r} is not a link of this robot "
                                 f"(links: {', '.join(links)})")
        excluded.add(frozenset(group_of[ln] for ln in pair))
    material = {k: v for k, v in collisions.items() if k in CONTACT_KEYS}
    return material, flags["ground"], flags["self"], excluded


def _collision_shape(g, R, p):
    """The :mod:`~ncgen.model.shapes` shape of a URDF collision geometry placed at ``(R, p)``
    in its member's frame; None for a mesh or no geometry."""
    from ncgen.model.shapes import Box, Cylinder, Sphere
    place = dict(position=p, rotation=R)
    if g is None:
        return None
    if g.box is not None:
        return Box(*np.asarray(g.box.size, float), **place)
    if g.cylinder is not None:
        return Cylinder(g.cylinder.radius, g.cylinder.length, **place)
    if g.sphere is not None:
        return Sphere(g.sphere.radius, **place)
    return None


def _lump(g: Group, links, pose) -> None:
    """Total mass, centre of mass and inertia about it (world axes) of a group's links."""
    parts = []
    for ln in g.links:
        inert = links[ln].inertial
        if inert is None or not inert.mass:
            continue
        T = pose[ln] @ _origin(inert.origin)
        Rc = T[:3, :3]
        I = np.zeros((3, 3)) if inert.inertia is None else np.asarray(inert.inertia, float)
        parts.append((float(inert.mass), T[:3, 3], Rc @ I @ Rc.T))
    g.mass = sum(m for m, _, _ in parts)
    if g.mass <= 0:
        return
    g.com = sum(m * c for m, c, _ in parts) / g.mass
    g.inertia = np.zeros((3, 3))
    for m, c, I in parts:
        d = c - g.com
        g.inertia += I + m * (d @ d * np.eye(3) - np.outer(d, d))


def _check_inertia(I, g: Group, where: str, moved_by: str) -> None:
    """Refuse an inertia tensor that is not physical.  A flat one (a thin disc or plate,
    I_a + I_b = I_c) is accepted: its singular mass matrix is handled (ncgen.assembly.mass)."""
    I = 0.5 * (I + I.T)
    e = np.linalg.eigvalsh(I)
    slack = [e[1] + e[2] - e[0], e[0] + e[2] - e[1], e[0] + e[1] - e[2]]
    scale = max(float(e.max()), 1e-300)
    what = f"URDF {where}: link(s) {', '.join(g.links)} (moved by {moved_by})"
    if e.min() < -FLAT_TOL * scale or min(slack) < -FLAT_TOL * scale:
        raise ModelError(f"{what}: the inertia tensor is not physical (principal moments {e.tolist()} "
                         "violate I_a + I_b ≥ I_c)")


def _local(m, T) -> tuple[np.ndarray, np.ndarray]:
    """A world pose (zero configuration) in the member's local frame: ``(R, p)``."""
    if m.is_ground:
        return T[:3, :3].copy(), T[:3, 3].copy()
    R0 = m.R0
    return R0.T @ T[:3, :3], R0.T @ (T[:3, 3] - m.p0)


def _visual(link: str, m, T, vis) -> dict:
    g = vis.geometry
    out = {"link": identifier(link), "member": "ground" if m.is_ground else m.name}
    R, p = _local(m, T)
    out["rotation"], out["position"] = R, p
    if g is None:
        out["shape"] = "none"
    elif g.box is not None:
        out.update(shape="box", size=np.asarray(g.box.size, float))
    elif g.cylinder is not None:
        out.update(shape="cylinder", radius=float(g.cylinder.radius), length=float(g.cylinder.length))
    elif g.sphere is not None:
        out.update(shape="sphere", radius=float(g.sphere.radius))
    elif g.mesh is not None:
        out.update(shape="mesh", filename=g.mesh.filename,
                   scale=None if g.mesh.scale is None else np.asarray(g.mesh.scale, float).reshape(-1))
    return out
