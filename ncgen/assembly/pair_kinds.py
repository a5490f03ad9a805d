"""Contact pair kinds: one kernel per *kind* of point contact, the pair's numbers as its
arguments (issue 34, deliverable 1 for contacts).

The per-model contact kernels (:mod:`ncgen.assembly.pair_kernels`) are the rows of a model's
flat ``gap`` and ``contact_jacobian`` with every size, radius and offset built in, so every
model compiles its own.  A *pair kind* is the same formula of
:mod:`ncgen.assembly.contact_kinematics` (one source: its functions are called here with
symbols where the model has numbers) over two *sides* of given coordinate types:

==================  ===============================  ==========================================
kind                point contact                    numbers (``dim``-vectors, ``dim²`` matrices
                                                     column-major, scalars)
==================  ===============================  ==========================================
sphere_plane        :class:`SpherePlane` on the      at, radius, point, normal, tangents
                    ground's plane (shapes' points)
sphere_plane_rim    … a cylinder's rim point         … rim_radius, axis
sphere_sphere       :class:`SphereSphere`            at_a, radius_a, at_b, radius_b
sphere_box          :class:`SphereBox`               at, radius, size, box_at, box_rotation
box_corner          :class:`BoxCorner`               at, size, box_at, box_rotation,
                                                     corner_rotation, corner_signs, corner_size
edge                :class:`EdgeContact`             per side: at, rotation (the edge's axis
                                                     first), size (likewise), choice, radius;
                                                     then margin, band
capsule_sphere      :class:`CapsuleSphere`           sphere_at, sphere_radius, at, rotation,
                                                     length, radius
cylinder_sphere     :class:`CylinderSphere`          as capsule_sphere
==================  ===============================  ==========================================

A side is the ground (no coordinates) or a member of coordinate type ``t``, whose numbers
come first: ``X̄⁺`` (k × dim, column-major) and ``r̄_i`` (a local point ``r̄`` is
``C(c) q_I`` with ``c = X̄⁺ (r̄ − r̄_i)``, ``C`` affine in ``c``), then the constants of
its shipped ``omega`` form (:func:`ncgen.model.context.instance_form`; none for a point).
Kernel ``pk_<kind>_<side a>_<side b>_<dim>d``: inputs ``q = [q_a; q_b]`` (the two sides'
local coordinates, in the point contact's own order: the sphere, corner or first edge
first) and ``c`` (the numbers: side a's, side b's, then the contact's), outputs the gap
``g`` (m) and ``W`` (dim × (n_a + n_b), dense): the normal row, then the tangent rows, in the
columns of ``q``, as ``contact_jacobian`` gives them.  A plane carried by a member has no
kind (:func:`point_kind` returns None).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from ncgen.assembly.contact_kinematics import contact_terms
from ncgen.model.capsule_contacts import CapsuleSphere, CylinderSphere
from ncgen.model.context import instance_form
from ncgen.model.contacts import BoxCorner, EdgeContact, SphereBox, SpherePlane, SphereSphere
from ncgen.reproducible import perpendicular_basis
from ncgen.symbolic.coordinates import coordinate_type
from ncgen.symbolic.numpy_forms import shipped_function

#: Side name of the ground.
GROUND = "ground"

_CAPSULE = (("sphere_at", "v"), ("sphere_radius", "s"), ("at", "v"), ("rotation", "m"), ("length", "s"),
            ("radius", "s"))
_EDGE_SIDE = (("at", "v"), ("rotation", "m"), ("size", "v"), ("choice", "s"), ("radius", "s"))
#: Per kind: the contact's attributes naming its two sides, and its numbers (name, shape:
#: ``v`` a dim-vector, ``m`` a dim × dim matrix, ``s`` a scalar, ``t`` the tangents).
KINDS: dict[str, tuple[tuple[str, str], tuple]] = {
    "sphere_plane": (("sphere", "plane"), (("at", "v"), ("radius", "s"), ("point", "v"), ("normal", "v"),
                                           ("tangents", "t"))),
    "sphere_plane_rim": (("sphere", "plane"), (("at", "v"), ("radius", "s"), ("point", "v"), ("normal", "v"),
                                               ("tangents", "t"), ("rim_radius", "s"), ("axis", "v"))),
    "sphere_sphere": (("a", "b"), (("at_a", "v"), ("radius_a", "s"), ("at_b", "v"), ("radius_b", "s"))),
    "sphere_box": (("sphere", "box"), (("at", "v"), ("radius", "s"), ("size", "v"), ("box_at", "v"),
                                       ("box_rotation", "m"))),
    "box_corner": (("sphere", "box"), (("at", "v"), ("size", "v"), ("box_at", "v"), ("box_rotation", "m"),
                                       ("corner_rotation", "m"), ("corner_signs", "v"), ("corner_size", "v"))),
    "edge": (("a", "b"), tuple((f"{e}.{n}", s) for e in ("edge_a", "edge_b") for n, s in _EDGE_SIDE)
             + (("margin", "s"), ("band", "s"))),
    "capsule_sphere": (("sphere", "capsule"), _CAPSULE),
    "cylinder_sphere": (("sphere", "capsule"), _CAPSULE),
}


def point_kind(pc) -> str | None:
    """The kind of point contact ``pc`` (module docstring), None for a plane carried by a member."""
    for cls, kind in _KIND_OF_CLASS:            # in this order: the first class ``pc`` is an instance of
        if isinstance(pc, cls):
            return kind
    if isinstance(pc, SpherePlane) and pc.plane.is_ground:
        return "sphere_plane_rim" if getattr(pc, "rim_radius", 0.0) > 0 else "sphere_plane"
    return None


#: ``(class, kind)`` of the point contacts whose kind their class alone decides.
_KIND_OF_CLASS = ((EdgeContact, "edge"), (CylinderSphere, "cylinder_sphere"), (CapsuleSphere, "capsule_sphere"),
                  (BoxCorner, "box_corner"), (SphereBox, "sphere_box"), (SphereSphere, "sphere_sphere"))


def side_type(member) -> str:
    """A side's name in a kind: ``ground`` or the member's coordinate type."""
    return GROUND if member.is_ground else member.ctype.name


#: The canonical coordinate type of a side with ``k`` axes, by dimension: a member of any type
#: with ``k`` axes is this type's member with the coordinates ``[x_i; X_1; …; X_k]``
#: (:func:`canonical_map`) and its own numbers: every type with ``k`` axes has the same
#: ``X̄⁺``, ``r̄_i`` and ``omega`` constants (:func:`side_constants`).
CANONICAL = {3: {0: "r", 1: "ru", 3: "ruvw"}, 2: {0: "r", 1: "ru", 2: "ruv"}}


def canonical_type(member, dim: int) -> str | None:
    """The canonical side type of ``member`` (``ground`` for the ground), None for a type of
    another number of axes."""
    return GROUND if member.is_ground else CANONICAL[dim].get(member.ctype.k)


@lru_cache(maxsize=None)
def canonical_map(ctype: str, dim: int) -> np.ndarray:
    """``B`` (dim (k + 1) × nq): a member's canonical coordinates ``[x_i; X_1; …; X_k] = B q_I``,
    ``x_i = C(0) q_I`` and ``X_j = (C(e_j) − C(0)) q_I`` (``C`` affine in ``c``, so that
    ``C(c) q_I = x_i + Σ_j c_j X_j``, the canonical type's ``C``); the identity for a canonical type."""
    ct = coordinate_type(ctype, dim)
    C = shipped_function(ctype, dim, "C")[0]
    C0 = np.asarray(C(np.zeros(ct.k), []), float).reshape(dim, ct.nq)
    rows = [C0] + [np.asarray(C(np.eye(ct.k)[j], []), float).reshape(dim, ct.nq) - C0 for j in range(ct.k)]
    return np.vstack(rows)


#: Which canonical sides each kind takes (``"any"``: any member or the ground, ``"plane"``: the
#: ground's plane, ``"box"``: a body or the ground, ``"axis"``: a bar, a body or the ground).
_SLOTS = {"sphere_plane": ("member", "plane"), "sphere_plane_rim": ("member", "plane"),
          "sphere_sphere": ("member", "member"), "sphere_box": ("any", "box"), "box_corner": ("box", "box"),
          "edge": ("box", "box"), "capsule_sphere": ("any", "axis"), "cylinder_sphere": ("any", "axis")}
#: Kinds of the planar models.
_PLANAR = ("sphere_plane", "sphere_plane_rim", "sphere_sphere", "sphere_box", "box_corner")


def _slot_types(slot: str, dim: int) -> list[str]:
    body = CANONICAL[dim][dim]
    return {"any": [GROUND, "r", "ru", body], "member": ["r", "ru", body], "plane": [GROUND],
            "box": [GROUND, body], "axis": [GROUND, "ru", body]}[slot]


def table_kinds() -> tuple[tuple[str, str, str, int], ...]:
    """The pair kinds of the contact tables' library, in its order: ``(kind, side a, side b,
    dim)`` over the canonical sides each kind takes (:data:`CANONICAL`), not both the ground."""
    out = []
    for dim in (3, 2):
        for kind, (sa, sb) in _SLOTS.items():
            if dim == 2 and kind not in _PLANAR:
                continue
            out += [(kind, a, b, dim) for a in _slot_types(sa, dim) for b in _slot_types(sb, dim)
                    if GROUND not in (a, b) or a != b]
    return tuple(out)


def kind_name(kind: str, type_a: str, type_b: str, dim: int) -> str:
    return f"pk_{kind}_{type_a}_{type_b}_{dim}d"


class _Side:
    """A stand-in member of a kind: its coordinates, rates and numbers as symbols."""

    def __init__(self, name: str, ctype: str, dim: int):
        self.name, self.is_ground = name, ctype == GROUND
        if self.is_ground:
            self.q = self.v = self.numbers = ca.SX(0, 1)
            return
        self.ctype = coordinate_type(ctype, dim)
        self.kind, k, nq = self.ctype.kind, self.ctype.k, self.ctype.nq
        self.q, self.v = ca.SX.sym(f"q_{name}", nq), ca.SX.sym(f"v_{name}", nq)
        self.pinv, self.rbar_i = ca.SX.sym(f"Xbarpinv_{name}", k, dim), ca.SX.sym(f"rbar_i_{name}", dim)
        self.omega = ca.SX.sym(f"omega_c_{name}", len(side_constants(ctype, dim)) if self.kind != "point" else 0)
        self.numbers = ca.vertcat(ca.vec(self.pinv), self.rbar_i, self.omega)
        C = shipped_function(ctype, dim, "C")[0]
        self.C0 = ca.DM(C(np.zeros(k), []))
        self.dC = [ca.DM(C(np.eye(k)[s], [])) - self.C0 for s in range(k)]


@lru_cache(maxsize=None)
def side_constants(ctype: str, dim: int) -> tuple[str, ...]:
    """The names of a member side's ``omega`` constants."""
    return instance_form(ctype, dim, "omega")[0]


class KindContext:
    """The part of :class:`ncgen.model.context.Context` that
    :mod:`ncgen.assembly.contact_kinematics` uses, over two stand-in sides."""

    def __init__(self, dim: int, sides: tuple[_Side, _Side], tangents: list):
        self.dim, self.sides, self.tangents = dim, sides, tangents
        self.v = ca.vertcat(*(s.v for s in sides))

    def local_point(self, side: _Side, rbar):
        """``C(c) q_I`` and ``C(c) q̇_I`` with ``c = X̄⁺ (r̄ − r̄_i)`` (``C`` affine in ``c``)."""
        c = ca.mtimes(side.pinv, rbar - side.rbar_i) if side.dC else []
        C = side.C0 + sum((c[s] * dC for s, dC in enumerate(side.dC)), ca.SX.zeros(side.C0.shape))
        return ca.mtimes(C, side.q), ca.mtimes(C, side.v)

    def instantiate(self, side: _Side, formula: str):
        return instance_form(side.ctype.name, self.dim, formula)[1](side.q, side.v, side.omega)

    def plane_tangents(self, normal) -> list:
        return self.tangents


def _shape(shape: str, dim: int) -> tuple[int, ...]:
    return {"v": (dim,), "m": (dim, dim), "s": (), "t": (dim - 1, dim)}[shape]


def _get(pc, name: str):
    if "." in name:
        edge, key = name.split(".")
        return getattr(pc, edge)[key]
    if name == "tangents":
        return perpendicular_basis(pc.normal)
    return getattr(pc, name)


def _set(pc, name: str, value) -> None:
    if "." in name:
        edge, key = name.split(".")
        getattr(pc, edge)[key] = value
    else:
        setattr(pc, name, value)


def _edge_sides(pc) -> None:
    """``pc``'s edges with their box's axes reordered, the edge's axis first (the others in
    their order): one kernel for every pair of axes, the same formula."""
    for edge in ("edge_a", "edge_b"):
        side = dict(getattr(pc, edge))
        i = side["axis"]
        order = [i] + [k for k in range(3) if k != i]
        side["rotation"] = np.asarray(side["rotation"], float)[:, order]
        side["size"] = np.asarray(side["size"], float)[order]
        side["axis"] = 0
        setattr(pc, edge, side)


def _normalised(pc):
    """A copy of point contact ``pc`` in its kind's normal form (an edge's axis first)."""
    out = copy.copy(pc)
    if isinstance(pc, EdgeContact):
        _edge_sides(out)
    return out


@dataclass(frozen=True)
class PairKind:
    """A pair kind's kernel and sizes: ``n_a``, ``n_b`` the sides' coordinates, ``n_c`` its numbers."""

    name: str
    kind: str
    n_a: int
    n_b: int
    n_c: int
    function: ca.Function
    #: The gap alone: ``pk_..._gap: q, c -> g``.
    gap: ca.Function
    #: ``function`` as a function of its own (no call options): the contact library's kernel.
    plain: ca.Function


#: The contact class of each kind (:func:`point_kind`).
_CLASSES = {"sphere_plane": SpherePlane, "sphere_plane_rim": SpherePlane, "sphere_sphere": SphereSphere,
            "sphere_box": SphereBox, "box_corner": BoxCorner, "edge": EdgeContact,
            "capsule_sphere": CapsuleSphere, "cylinder_sphere": CylinderSphere}


def _template(kind: str):
    """A bare point contact of ``kind`` to fill with symbols: what the formulas read besides
    the numbers (a corner's radius 0, an edge's axis first)."""
    pc = object.__new__(_CLASSES[kind])
    pc.name = pc.kind = kind
    if kind == "box_corner":
        pc.radius = 0.0
    if kind == "edge":
        pc.edge_a, pc.edge_b = {"axis": 0}, {"axis": 0}
    return pc


@lru_cache(maxsize=None)
def pair_kind(kind: str, type_a: str, type_b: str, dim: int) -> PairKind:
    """The kernel of ``kind`` between sides of types ``type_a`` and ``type_b`` (module
    docstring): :func:`ncgen.assembly.contact_kinematics.contact_terms` on a point contact
    whose numbers and members are symbols."""
    (first, second), numbers = KINDS[kind]
    sides = (_Side("a", type_a, dim), _Side("b", type_b, dim))
    pc = _template(kind)
    symbols = []
    for name, shape in numbers:
        size = _shape(shape, dim)
        x = ca.SX.sym(name.replace(".", "_"), int(np.prod(size)) if size else 1)
        symbols.append(x)
        if shape == "m":
            x = ca.reshape(x, dim, dim)
        elif shape == "t":
            x = [x[k * dim:(k + 1) * dim] for k in range(dim - 1)]
        _set(pc, name, x)
    if kind == "edge":
        pc.radius = pc.edge_a["radius"] + pc.edge_b["radius"]
    setattr(pc, first, sides[0])
    setattr(pc, second, sides[1])
    term = contact_terms(KindContext(dim, sides, getattr(pc, "tangents", None)), [pc])[0]
    q = ca.vertcat(sides[0].q, sides[1].q)
    c = ca.vertcat(sides[0].numbers, sides[1].numbers, *symbols)
    g, W = ca.cse([ca.densify(term.g), ca.densify(ca.vertcat(term.WN, term.WT))])
    name = kind_name(kind, type_a, type_b, dim)
    called = {"never_inline": True}       # a call in the expressions that use it, one C function
    fn = ca.Function(name, [q, c], [g, W], ["q", "c"], ["g", "W"], called)
    gap = ca.Function(f"{name}_gap", [q, c], [ca.cse(ca.densify(term.g))], ["q", "c"], ["g"], called)
    plain = ca.Function(name, [q, c], [g, W], ["q", "c"], ["g", "W"])
    return PairKind(name, kind, int(sides[0].q.numel()), int(sides[1].q.numel()), int(c.numel()), fn, gap, plain)


def side_numbers(member, dim: int) -> np.ndarray:
    """A side's numbers (module docstring): ``X̄⁺`` (column-major), ``r̄_i`` and the
    constants of ``omega``; none for the ground."""
    if member.is_ground:
        return np.zeros(0)
    rigid = member.rigid
    omega = [] if member.ctype.kind == "point" else \
        [rigid.constant_values[n] for n in side_constants(member.ctype.name, dim)]
    return np.concatenate([np.asarray(rigid.Xbar_pinv, float).reshape(-1, dim).ravel(order="F")
                           if member.ctype.k else np.zeros(0), rigid.rbar_i, omega]).astype(float)


@dataclass(frozen=True)
class PointCall:
    """One point contact as a call of its kind: the kind's kernel, the two side members (in
    the kind's order) and the numbers ``c``."""

    kind: PairKind
    members: tuple
    numbers: np.ndarray


def point_call(pc, dim: int, canonical: bool = False) -> PointCall | None:
    """Point contact ``pc`` as a call of its kind (None: no kind, :func:`point_kind`), between
    its sides' own coordinate types or (``canonical``) their canonical types
    (:func:`canonical_type`; None where a side has none or the kind is not one of
    :func:`table_kinds`)."""
    kind = point_kind(pc)
    if kind is None:
        return None
    (first, second), numbers = KINDS[kind]
    a, b = getattr(pc, first), getattr(pc, second)
    types = (side_type(a), side_type(b)) if not canonical else (canonical_type(a, dim), canonical_type(b, dim))
    if canonical and (kind, *types, dim) not in _table_kind_set():
        return None
    norm = _normalised(pc)
    own = [np.asarray(_get(norm, name), float).ravel(order="C" if shape == "t" else "F") for name, shape in numbers]
    c = np.concatenate([side_numbers(a, dim), side_numbers(b, dim), *own])
    return PointCall(pair_kind(kind, *types, dim), (a, b), c)


@lru_cache(maxsize=None)
def _table_kind_set() -> frozenset:
    return frozenset(table_kinds())
