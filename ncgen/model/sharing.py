"""Coordinate sharing: the model-compilation pass that eliminates joints (``build(share=True)``).

De Jalón's natural coordinates express a pin by *sharing* a basic point between the
members it joins, and a hinge by sharing the point and a unit vector along its axis; a weld
makes two members one.  Users write joints (``nc.Spherical``, ``nc.Revolute``, ``nc.Fixed``)
the way other tools ask for; :func:`share_coordinates` rewrites a copy of the system so that:

* a **Spherical** joint (3D) or a planar **Revolute** between two members becomes a shared
  basic point (its 3 or 2 coincidence equations disappear, and so do the coordinates of
  one copy of the point);
* a 3D **Revolute** shares the point and, where both sides can carry it (bodies and the
  ground; a bar carries only its own axis), the unit vector along its axis (its 5 equations
  disappear, or its 3 coincidence equations when one side is a bar);
* a **Fixed** joint between two bodies (or a body and the ground) merges them: every body
  of a welded group gets the same basic points and base vectors (its mass adds on them).

Bodies are re-based for this: each body (welded group) takes as basic points the points of
its joints (``r_i``, ``r_j``, ... up to 4 in 3D, 3 in 2D) and as base vectors the axes of
its hinges, completed by unit vectors of its own frame, the choice de Jalón recommends.  A
body's frame, centre of mass, inertia and markers do not change, so every force, marker and
remaining joint reads the same; only the coordinates differ.  Bars and point members keep
their coordinates: a joint can share only their existing basic points.  A joint that cannot
be expressed by sharing (another joint type, a drive's own equation, a point that no side
can carry) keeps its equations; a driven Revolute shares its geometry and keeps its drive.

Names as written keep working.  A re-based body's coordinates as written (``"upper.r_i.x"``)
are no longer in ``model.coordinate_names``, but each is an affine function ``s · q + c`` of
the shared coordinates (the identity for the kept members, a row of the map
``q_u = S q_s + c`` of :mod:`ncgen.assembly.unshared` for the re-based ones):
``model.coordinate(name)`` returns ``(s, c)``, and every place a coordinate is named goes
through it — ``traj.coordinate(name)`` (results), ``nc.assemble(values=...)`` and
``nc.project_velocity(values=...)`` (extra equations ``s · q + c = value``), optimal-control
bounds (linear path constraints) and targets (:mod:`ncgen.optim.problem`), and the TOML
``initial`` / ``initial_rates`` tables.  Markers and member names never change (a body keeps
its frame).

The joints stay in the system (``TorsionalSpring`` and drives still measure them); the pass
only marks which of their equations are implied by the sharing (:attr:`SharingPlan.dropped`),
and :func:`intrinsic_key` lets the build skip rigidity constraints that two members now
state twice (the ``u·u = 1`` of a shared axis) or that hold by construction (all nodes fixed).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from ncgen.model.members import Member, NodeRef
from ncgen.reproducible import norm
from ncgen.symbolic.coordinates import coordinate_type
from ncgen.symbolic.member import RigidMember

#: Two points (m) or unit vectors closer than this, relative to the system's size, are the same.
SAME = 1e-9
#: Smallest singular value of a body's normalised spans and base vectors accepted when choosing
#: them: a nearly coplanar choice (the SO-101's wrist: its roll and flex axes and the line
#: between its two joint points are coplanar within 2e-6 rad, singular value 1.9e-6) makes the
#: body's rigidity equations numerically dependent at the initial configuration, so below
#: this its own axes complete the basis (the joint keeps its axis equations).
INDEPENDENT = 5e-3


@dataclass
class SharingPlan:
    """What :func:`share_coordinates` did (plain data, kept on the ``Model`` as ``model.sharing``).

    ``eliminated``: joint name → what replaced it ("shared point", "shared point and axis",
    "merged"); ``partial``: joint name → what was shared and which equations remain;
    ``rebased``: body name → "old type -> new type"; ``nq_before``: coordinates without
    sharing (set by the build, which lays the system out); ``dropped``: joint name → label prefixes of the equations implied;
    ``removed``: labels of the equations left out (filled by the build)."""

    eliminated: dict[str, str] = field(default_factory=dict)
    partial: dict[str, str] = field(default_factory=dict)
    rebased: dict[str, str] = field(default_factory=dict)
    nq_before: int = 0
    dropped: dict[str, tuple[str, ...]] = field(default_factory=dict)
    removed: list[str] = field(default_factory=list)
    off: str | None = None       # why the pass did nothing, if it was skipped

    @property
    def nc_removed(self) -> int:
        return len(self.removed)

    def keeps(self, joint_name: str, label: str) -> bool:
        """Whether the joint equation ``label`` stays a constraint."""
        return not any(label == p or label.startswith(p + ".") for p in self.dropped.get(joint_name, ()))


# --------------------------------------------------------------------------- helpers
class _UnionFind:
    """Disjoint sets over hashable keys, each key its own set until merged (path halving);
    :meth:`union` keeps the root of its first argument's set."""

    def __init__(self):
        self.parent: dict = {}

    def _add(self, a):
        self.parent[a] = a

    def find(self, a):
        if a not in self.parent:
            self._add(a)
        while self.parent[a] != a:
            self.parent[a] = self.parent[self.parent[a]]
            a = self.parent[a]
        return a

    def _merge(self, ra, rb):
        self.parent[rb] = ra

    def union(self, a, b) -> bool:
        ra, rb = self.find(a), self.find(b)
        if ra != rb:
            self._merge(ra, rb)
        return True


class _Classes(_UnionFind):
    """Node classes: a union–find over node keys with the checks that keep a merge
    meaningful: one fixed value per class, and never two slots of the same member."""

    def __init__(self):
        super().__init__()
        self.sets: dict = {}

    def _add(self, a):
        super()._add(a)
        self.sets[a] = {a}

    def _merge(self, ra, rb):
        super()._merge(ra, rb)
        self.sets[ra] |= self.sets.pop(rb)

    def can_union(self, a, b) -> bool:
        ra, rb = self.find(a), self.find(b)
        if ra == rb:
            return True
        both = self.sets[ra] | self.sets[rb]
        fixed = {k[1:] for k in both if k[0] == "ground"}
        owners = [k[0] for k in both if k[0] != "ground"]
        return len(fixed) <= 1 and len(owners) == len(set(owners))

    def union(self, a, b) -> bool:
        return self.can_union(a, b) and super().union(a, b)


def _key(v) -> tuple:
    return tuple(float(x) for x in np.round(np.asarray(v, float), 12))


def _same(a, b, scale) -> bool:
    return norm(np.asarray(a, float) - np.asarray(b, float)) <= SAME * scale


def _candidate(joint, dim: int) -> str | None:
    """"point", "hinge" (point + axis) or "weld" for a joint the pass may eliminate."""
    kind = joint.kind
    if kind == "Spherical" and dim == 3:
        return "point"
    if kind == "Revolute":
        return "point" if dim == 2 else "hinge"
    if kind == "Fixed" and all(m.is_ground or m.kind == "body" for m in joint.members()):
        return "weld"
    return None


# ----------------------------------------------------------------------- the pass
def share_coordinates(system):
    """A copy of ``system`` with joints replaced by shared coordinates, and its
    :class:`SharingPlan` (see the module docstring).  ``system`` is not changed.

    Steps: group the welded bodies (:class:`_Welds`); re-base each group on the points and
    axes its joints ask for (:func:`_rebase_groups`); make node classes from the user's
    shares and the welds (:func:`_share_given`, :func:`_share_welds`) and from the point and
    hinge joints (:func:`_share_joints`); give each member its ``shared`` slots
    (:func:`_apply_classes`)."""
    plan = SharingPlan()
    by_index = [f.name for f in system.forces if f.kind == "GeneralizedForce"]
    if by_index:
        plan.off = (f"the generalised force(s) {', '.join(by_index)} index q and v as written, so the "
                    "coordinates are kept as written")
        return system, plan
    sys_c = copy.deepcopy(system)
    members = list(sys_c.members.values())
    old_shares = {m.name: dict(m.shared) for m in members}      # before re-basing clears them
    scale = max([1.0] + [norm(m.p0) for m in members])
    welds = _Welds(sys_c, members)
    _rebase_groups(sys_c, members, welds, plan, scale)
    keys = _NodeKeys(welds.ground_bodies, scale)
    classes = _Classes()
    for m in members:
        for slot in range(len(m.ctype.slots)):
            classes.find((m.name, slot))
    refused = _share_given(members, old_shares, keys, classes)
    if refused:
        plan.off = refused
        return system, plan
    _share_welds(welds, classes, plan)
    _share_joints(sys_c, welds, keys, classes, plan, scale)
    _apply_classes(sys_c, members, classes)
    return sys_c, plan


class _Welds:
    """Bodies welded together (``Fixed`` joints between bodies or to the ground), as groups
    named by a root member ("ground" for those welded to it).  Bodies named by a
    ``CoordinateDriver`` are not merged (their slots must keep their meaning)."""

    def __init__(self, system, members: list[Member]):
        d = system.dim
        self.driven = {j.A.name for j in system.joints if j.kind == "CoordinateDriver" and not j.A.is_ground}
        self._uf = _UnionFind()
        self.joints = []
        for j in system.joints:
            if _candidate(j, d) == "weld" and not any(m.name in self.driven for m in j.members() if not m.is_ground):
                a, b = (self._uf.find("ground" if m.is_ground else m.name) for m in j.members())
                if a != b:
                    self._uf.union(*((b, a) if b == "ground" else (a, b)))     # the ground stays a root
                    self.joints.append(j)
        self.groups: dict[str, list[Member]] = {}
        for m in members:
            self.groups.setdefault(self._uf.find(m.name), []).append(m)
        self.frozen = {self._uf.find(n) for n in self.driven}
        self.ground_bodies = {b.name for b in self.groups.get("ground", [])}

    def gid(self, m) -> str:
        return "ground" if m.is_ground else self._uf.find(m.name)

    def rebasable(self, g: str) -> bool:
        """Bodies (welded groups) not named by a CoordinateDriver, whose slots must keep their meaning."""
        return g != "ground" and self.groups[g][0].kind == "body" and g not in self.frozen


def _rebase_groups(system, members: list[Member], welds: _Welds, plan: SharingPlan, scale: float) -> None:
    """Give every re-basable group the world basic points and axes its joints ask for (those
    with something to share), and every body welded to the ground fixed nodes; records
    ``plan.rebased``."""
    d = system.dim
    gid = welds.gid
    # requests of every re-basable group, in joint order: points (world) and axes (world, unit)
    points: dict[str, list[np.ndarray]] = {g: [] for g in welds.groups if welds.rebasable(g)}
    vectors: dict[str, list[np.ndarray]] = {g: [] for g in welds.groups if welds.rebasable(g)}
    for m in members:                                   # basic points already shared stay basic points
        for slot, ref in m.shared.items():
            for who, s in ((m, slot), (ref.member, ref.slot)):
                if not who.is_ground and welds.rebasable(gid(who)):
                    points[gid(who)].append(who.slot_position(s))
    for j in system.joints:
        how = _candidate(j, d)
        if how in ("point", "hinge"):
            ga, gb = (gid(m) for m in j.members())
            if ga == gb:
                continue
            at = j.at()
            for g in (ga, gb):
                if g in points:
                    points[g].append(at)
            if how == "hinge" and all(g == "ground" or g in vectors for g in (ga, gb)):
                a = j.axis()
                for g in (ga, gb):
                    if g in vectors:
                        vectors[g].append(a)
    for g, body_list in welds.groups.items():
        if g == "ground" or not welds.rebasable(g) or not (points[g] or vectors[g] or len(body_list) > 1):
            continue
        pts, vecs = _choose_basis(d, points[g], vectors[g], body_list[0], scale)
        for b in body_list:
            old, q_old = b.ctype.name, b.q0
            _rebase(b, pts, vecs, d)
            if old != b.ctype.name or q_old.shape != b.q0.shape or not np.allclose(q_old, b.q0, rtol=0, atol=1e-12):
                plan.rebased[b.name] = f"{old} -> {b.ctype.name}"
    for b in welds.groups.get("ground", []):          # welded to the ground: every node fixed
        old = b.ctype.name
        pts, vecs = _choose_basis(d, [], [], b, scale)
        _rebase(b, pts, vecs, d)
        plan.rebased[b.name] = f"{old} -> {b.ctype.name}, welded to the ground (no coordinates)"


class _NodeKeys:
    """Node keys: ``(member, slot)`` for a member's slot, ``("ground", "p" or "v", values…)``
    for a fixed point or axis (the ground's, or a body welded to it)."""

    def __init__(self, welded_to_ground: set, scale: float):
        self.welded_to_ground, self.scale = welded_to_ground, scale

    def point(self, m, world):
        """The node key of ``m``'s basic point at ``world``, or None."""
        if m.is_ground or m.name in self.welded_to_ground:
            return ("ground", "p") + _key(world)
        for s in m.ctype.point_slots:
            if _same(m.slot_position(s), world, self.scale):
                return (m.name, s)
        return None

    def vector(self, m, axis):
        """The node key of ``m``'s base vector along ``axis`` (``("flip", …)`` if opposite), or None."""
        if m.is_ground or m.name in self.welded_to_ground:
            return ("ground", "v") + _key(axis)
        if m.kind != "body":
            return None
        n = len(m.ctype.point_slots)
        for s in range(n, len(m.ctype.slots)):
            val = m.slot_position(s)
            if _same(val, axis, 1.0):
                return (m.name, s)
            if _same(val, -axis, 1.0):
                return ("flip", m.name, s)
        return None


def _share_given(members: list[Member], old_shares: dict, keys: _NodeKeys, classes: _Classes) -> str | None:
    """Classes from the shares the user wrote; why the pass must stop, or None."""
    for m in members:
        for slot, ref in old_shares[m.name].items():
            ka = keys.point(m, np.asarray(ref.position))
            kb = keys.point(ref.member, np.asarray(ref.position))
            if ka is None or kb is None or not classes.union(ka, kb):
                return (f"{m.name} shares {ref.label}, which the re-based bodies cannot keep as a basic "
                        "point (too many points on one welded group), so the coordinates are kept as written")
    return None


def _share_welds(welds: _Welds, classes: _Classes, plan: SharingPlan) -> None:
    """Welded bodies: one set of nodes (fixed ones for those welded to the ground); the
    welds are eliminated."""
    for g, body_list in welds.groups.items():
        for b in body_list:
            for s in range(len(b.ctype.slots)):
                if g == "ground":
                    kind = "p" if s in b.ctype.point_slots else "v"
                    classes.union((b.name, s), ("ground", kind) + _key(b.slot_position(s)))
                elif b is not body_list[0]:
                    classes.union((body_list[0].name, s), (b.name, s))
    for j in welds.joints:
        plan.eliminated[j.name] = "merged"
        plan.dropped[j.name] = (f"{j.name}.coincide", f"{j.name}.lock")


def _share_joints(system, welds: _Welds, keys: _NodeKeys, classes: _Classes, plan: SharingPlan,
                  scale: float) -> None:
    """Point joints share their point, hinges their point and axis (or a second point on an
    axis fixed to the ground) where the classes allow it; records what each eliminated."""
    d = system.dim
    for j in system.joints:
        how = _candidate(j, d)
        if how not in ("point", "hinge"):
            continue
        A, B = j.members()
        if welds.gid(A) == welds.gid(B):
            continue
        at = j.at()
        ka, kb = keys.point(A, at), keys.point(B, at)
        already = ka is not None and kb is not None and classes.find(ka) == classes.find(kb)
        if ka is None or kb is None or not classes.union(ka, kb):
            continue
        parts = [f"{j.name}.coincide"]
        what = "implied: the point was already shared" if already else "shared point"
        if how == "hinge":
            axis = j.axis()
            va, vb = keys.vector(A, axis), keys.vector(B, axis)
            if va is not None and vb is not None and va[0] != "flip" and vb[0] != "flip" \
                    and classes.union(va, vb):
                parts.append(f"{j.name}.align")
                what = "shared point and axis"
            elif _second_point_to_ground(A, B, at, axis, keys.point, classes, scale, keys.welded_to_ground):
                parts.append(f"{j.name}.align")
                what = "two shared points on the axis"
            else:
                plan.partial[j.name] = f"shared point; the axis equations remain ({j.name}.align)"
        if j.drive is not None:
            plan.partial[j.name] = f"{what}; the drive equation remains ({j.name}.drive)"
        elif j.name not in plan.partial:
            plan.eliminated[j.name] = what
        plan.dropped[j.name] = tuple(parts)


def _second_point_to_ground(A, B, at, axis, point_key, classes, scale, welded_to_ground) -> bool:
    """A hinge to the ground (or to a body welded to it) whose other side has a second basic
    point on the axis: that point is fixed too, which holds the axis (de Jalón's two points
    on a fixed axis)."""
    sides = [m.is_ground or m.name in welded_to_ground for m in (A, B)]
    if sides[0] == sides[1]:
        return False
    other = B if sides[0] else A
    for s in other.ctype.point_slots:
        p = other.slot_position(s)
        off = p - at
        if norm(off) > SAME * scale and norm(np.cross(off, axis)) <= SAME * scale:
            return classes.union((other.name, s), point_key(A if sides[0] else B, p))
    return False


def _choose_basis(d: int, points: list, vectors: list, body: Member, scale: float):
    """World basic points and unit base vectors for a body (group): the requested points
    (those that already are basic points first, in their order, so their names stay) and
    axes while they stay affinely independent (at most d + 1 slots, points first),
    completed by the body's own axes."""
    pts: list[np.ndarray] = []
    existing = [body.slot_position(s) for s in body.ctype.point_slots]
    points = [e for e in existing if any(_same(e, p, scale) for p in points)] + list(points)
    for p in points:
        p = np.asarray(p, float)
        if len(pts) == d + 1 or any(_same(p, q, scale) for q in pts):
            continue
        if not pts or _independent([q - pts[0] for q in pts[1:]] + [p - pts[0]], d):
            pts.append(p)
    if not pts:
        pts = [body.slot_position(0)]
    spans = [q - pts[0] for q in pts[1:]]
    for e in existing:                       # the body's other basic points, while there is room
        if len(spans) + len(vectors) < d and not any(_same(e, q, scale) for q in pts) \
                and _independent(spans + [e - pts[0]], d):
            pts.append(e)
            spans.append(e - pts[0])
    vecs: list[np.ndarray] = []
    for a in vectors:
        a = np.asarray(a, float) / norm(a)
        if any(_same(a, b, 1.0) or _same(a, -b, 1.0) for b in vecs):
            continue
        if len(spans) + len(vecs) < d and _independent(spans + vecs + [a], d):
            vecs.append(a)
    R = np.eye(d) if body.R0 is None else body.R0
    while len(spans) + len(vecs) < d:
        current = spans + vecs
        best, best_n = None, 0.0
        for e in R.T:
            r = e.copy()
            if current:
                Q, _ = np.linalg.qr(np.column_stack(current))
                r = e - Q @ (Q.T @ e)
            if norm(r) > best_n:
                best, best_n = r / norm(r), norm(r)
        vecs.append(best)
    return pts, vecs


def _independent(columns: list, d: int) -> bool:
    if not columns:
        return True
    X = np.column_stack([c / norm(c) for c in columns])
    s = np.linalg.svd(X, compute_uv=False)
    return bool(len(columns) <= d and s[-1] > INDEPENDENT)


def _rebase(body: Member, pts: list, vecs: list, d: int) -> None:
    """Give ``body`` the basic points ``pts`` and base vectors ``vecs`` (world, initial
    configuration), keeping its frame, mass, inertia, markers and motion."""
    name = "r" * len(pts) + ("uvw" if d == 3 else "uv")[len(pts) - 1:]
    ct = coordinate_type(name, d)
    old = body.rigid
    rbar = [body.to_local(p) for p in pts]
    X = [r - rbar[0] for r in rbar[1:]] + [body.direction_to_local(v) for v in vecs]
    local = RigidMember(ct, old.mass, rbar[0], np.column_stack(X), old.Jbar)
    markers, spec = body.markers, body.spec
    Member.__init__(body, body.name, local, body.R0, body.p0, body.omega0, body.v0, {})
    body.markers, body.spec = markers, spec


def _apply_classes(system, members: list[Member], classes: _Classes) -> None:
    """Each member's ``shared`` from the node classes: a slot shares the class's ground node
    if it has one, else the class's earliest slot in member order."""
    order = {m.name: i for i, m in enumerate(members)}
    by_name = {m.name: m for m in members}
    roots: dict = {}
    for key in classes.parent:
        roots.setdefault(classes.find(key), []).append(key)
    for m in members:
        m.shared = {}
    for keys in roots.values():
        fixed = [k for k in keys if k[0] == "ground"]
        slots = sorted((k for k in keys if k[0] != "ground"), key=lambda k: (order[k[0]], k[1]))
        if fixed:
            ref = NodeRef(system.ground, -1, tuple(fixed[0][2:]))
            owners = slots
        else:
            if len(slots) < 2:
                continue
            first = by_name[slots[0][0]]
            ref = NodeRef(first, slots[0][1], tuple(float(x) for x in first.slot_position(slots[0][1])))
            owners = slots[1:]
        for name, s in owners:
            by_name[name].shared[s] = ref


def intrinsic_key(layout, member: Member, pair: tuple[int, int]):
    """A key naming the rigidity constraint ``x_s·x_t`` of ``member`` by the nodes it reads
    (equal keys: the same equation), or None when every node is fixed (nothing to
    constrain).  ``x_s`` is the base vector of slot ``s + 1``."""
    slots = layout.slots[member.name]
    nodes = layout.nodes

    def base(s):
        slot = s + 1
        if member.ctype.name[slot] == "r":
            return ("d", frozenset((slots[slot], slots[0])))
        return ("v", slots[slot])

    parts = [base(s) for s in pair]
    used = {n for kind, x in parts for n in (x if kind == "d" else (x,))}
    if all(nodes[n].fixed is not None for n in used):
        return None
    return tuple(sorted(parts, key=repr))
