"""Contact kernels per element and the data of the broad phase (issue 34, deliverable 4).

The nonsmooth stepper's contact rows (gaps ``g``, Jacobian rows ``W``; see
:mod:`ncgen.assembly.stepper_equations`) come from one small kernel per contact *element*
(a sphere pair, a box pair with its corners and edges, a shape against a plane, …), called
by a C loop over the element table (``templates/c/runtime/ncgen_contact_pairs.h``) instead
of one flat function of every contact.  The formulas are those of
:mod:`ncgen.assembly.contact_kinematics` (one source): an element's rows are built there over the whole
system's symbols (the expressions of the model's ``gap`` and ``contact_jacobian``) and made a function of its members' local coordinates ``q_a``, ``q_b``
(the coordinates each member uses are index tables in the C).  Elements whose kernels are
equal (the same kinds, shapes, coordinate types and numbers: equal spheres of a heap, equal
boxes of a stack) share one kernel.  An element whose point contacts all have a pair kind
(:mod:`ncgen.assembly.pair_kinds`; :data:`KIND_CALLS`) is an MX function calling one C
function per kind with its numbers as constant arrays, so the C grows with the kinds of
elements, not with their sizes or number; the others (a plane carried by a member) are the
flat rows with the numbers built in.  Kernels (``k``: the kernel's number):

* ``step_pair<k>_gap``: q_a, q_b, p -> g (m gaps of the element's point contacts)
* ``step_pair<k>_rows``: q_a, q_b, p -> g, W (m dim × (n_a + n_b), dense: per point contact
  its normal row, then its tangent rows, zero for a frictionless contact; columns: the
  coordinates of q_a then q_b)

Broad phase: per element and side a bounding sphere from q.  A side's features (sphere
centres with their radii, box corners, capsule ends with the radius) have affine coordinates
``c`` in the member's frame (``x(c) = C(c) q_I = x₀ + Σ_j (c − c₀)_j X_j``); with ``c₀`` the
centre and ``e`` the half extents of their box in ``c``, every feature point is within
``R = r + Σ_j e_j |X_j|`` of ``x₀ = C(c₀) q_I`` (``X_j = (C(c₀ + ê_j) − C(c₀)) q_I``,
exact for any q, on the constraint manifold or not).  A ground side is a constant sphere, a
ground plane a half-space; a plane carried by a member is not bounded (its element is always
evaluated).  With ``D`` the distance of the two bounding volumes, every gap the element's
kernel returns is at least

    κ D − s   where D ≥ d_min,   and at least ``cap``,

``κ = 1`` and ``d_min = 0`` for spheres, planes, capsules and cylinders (the gap is the
distance while positive), ``κ = 1/√3`` and ``d_min = √3 ε`` for box corners (``ε`` the
corner's edge tolerance: a corner farther than that from the box is over at most one face,
whose plane distance is ≥ dist/√3, or over none, where the largest face-plane distance is),
``d_min`` = the margin for edge crossings (a crossing that is no contact reports its gap
plus ``band``: ``cap = band − 1.01 (h_a + h_b) − r_a − r_b`` with ``h`` the boxes' half
diagonals), and ``s = 10⁻⁶ (R_a + R_b)`` against round-off and the constraint residual.
Velocity bound: the normal (or tangent) velocity ``W_r v`` of any contact row of the
element is at most ``S(v) = Σ_sides |ẋ₀| + Σ_j e_j |Ẋ_j| + |ω| ℓ`` with
``|ω| ≤ ‖Ḡ‖₂ |Ẋ|_F |X|_F`` (``ω̂ = Ẋ Ḡ Xᵀ``, ``Ḡ = (X̄ᵀX̄)⁻¹``; a bar's ``1/|ū|²``) and the
lever ``ℓ = D + 3 (R_a + R_b)`` (``2 R`` against a half-space): the contact point lies within
the bounding volumes and the reference points of the material velocities within their own.
Edge crossings that are no contact compute their rows at points off the edges, so the
bound holds there only for crossings (``rate_bounded`` is false).  The C uses these to skip
an element exactly where the flat kernel's gaps would not change a decision of the step
(``ncgen_contact_pairs.h``).

Sweep (``pairs_sweep`` there): the bounds are taken once per distinct member side, and the
element bounds only for the pairs of sides whose intervals on one axis overlap (sorted by
their lower ends from the last sweep's order); every other element gets the level
``L = max(limit, 0) + R_max + 10⁻⁶ m`` as its bound, which is exact by construction.  Side
``i`` (centre ``x_i``, radius ``R_i``, speed terms ``lin_i``, ``rot_i``) spans
``x_i ∓ (R_i + a_i)`` with ``a_i = (2/κ_min)(L/2 + s R_i + h_s lin_i + 3 ρ_i (R_i + R_max)) +
d_max/2``, ``ρ_i = h_s rot_i ≤ κ_min/4`` (else the whole axis).  Disjoint intervals give
``|x_j − x_i| > R_i + R_j + a_i + a_j``, so ``D > a_i + a_j ≥ d_max``, and with
``(ρ_i + ρ_j)(R_i + R_j) ≤ Σ ρ_i (R_i + R_max)``:

    κ D − s (R_i + R_j) − L − h_s S ≥ (κ_min − ρ_i − ρ_j) D − [L + s (R_i + R_j) + h_s (lin_i + lin_j)
        + 3 (ρ_i + ρ_j)(R_i + R_j)] ≥ κ_min/2 (D − a_i − a_j) > 0,

so the element's own bound exceeds ``L + h_s S ≥ L > limit``: no element within the level is
missed, and the step's decisions are those of every bound taken one by one (a later limit at
or above ``L`` takes them one by one).  Elements with a side that is not a member, a cap, or
unbounded rates are always bounded one by one.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ncgen.assembly.contact_kinematics import EDGE_TOL
from ncgen.assembly.pair_kinds import point_call
from ncgen.model.capsule_contacts import CapsuleSphere
from ncgen.model.contacts import BoxCorner, EdgeContact, SphereBox, SpherePlane, SphereSphere

#: Relative slack of the lower bounds (see the module docstring).
BOUND_SLACK = 1e-6
#: Whether an element whose point contacts all have a pair kind calls the kinds' kernels
#: (:mod:`ncgen.assembly.pair_kinds`: one C function per kind, the numbers constants of the
#: calls) instead of the flat rows with the numbers built in.
KIND_CALLS = True


@dataclass
class Side:
    """One side of an element's bounding volume: ``kind`` ``"member"`` (a sphere moving with
    the coordinates ``idx`` of q, -1 where fixed), ``"fixed"`` (a constant sphere),
    ``"halfspace"`` (a ground plane: ``normal``, ``point``) or ``"unbounded"``."""

    kind: str
    idx: list = field(default_factory=list)
    centre: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))   # dim × n: x₀ = centre q_I (+ fixed)
    axes: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 0)))  # k × dim × n: X_j = axes[j] q_I
    extents: np.ndarray = field(default_factory=lambda: np.zeros(0))       # e_j
    radius: float = 0.0
    gnorm: float = 0.0
    fixed: np.ndarray = field(default_factory=lambda: np.zeros(0))         # x₀ of a fixed sphere, or the plane's point
    normal: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass
class Element:
    """A contact element of the table: its point contacts ``first .. first + count − 1``,
    its kernel number, the coordinates of its two sides (``idx_a``, ``idx_b``, -1 where
    fixed, with ``const_a``, ``const_b``), its sides' bounding volumes and the constants of
    its lower bound (module docstring)."""

    name: str
    first: int
    count: int
    kernel: int
    idx_a: list
    idx_b: list
    const_a: np.ndarray
    const_b: np.ndarray
    sides: tuple
    kappa: float
    dmin: float
    cap: float
    rate_bounded: bool
    friction: list


@dataclass
class PairKernels:
    """The kernels (``functions``: gap then rows per kernel number) and the element table."""

    functions: list
    elements: list


def _box_corners(size, at, rotation) -> list:
    d = len(size)
    size, at, rotation = np.asarray(size, float), np.asarray(at, float), np.asarray(rotation, float)
    return [at + rotation @ (np.array([1.0 if i >> j & 1 else -1.0 for j in range(d)]) * size / 2)
            for i in range(2 ** d)]


def _features(pc) -> tuple[list, dict | None, tuple]:
    """``(features, plane, bound)`` of point contact ``pc``: features ``(member, point in its
    frame, radius)``, the plane ``{"member", "normal", "point"}`` of a sphere–plane contact,
    and ``(κ, d_min, cap, rate_bounded)``; ``features = None`` for a kind without a bound."""
    if isinstance(pc, SpherePlane):
        r = pc.radius + getattr(pc, "rim_radius", 0.0)
        return [(pc.sphere, pc.at, r)], {"member": pc.plane, "normal": pc.normal, "point": pc.point}, \
            (1.0, 0.0, math.inf, True)
    if isinstance(pc, SphereSphere):
        return [(pc.a, pc.at_a, pc.radius_a), (pc.b, pc.at_b, pc.radius_b)], None, (1.0, 0.0, math.inf, True)
    if isinstance(pc, SphereBox):
        feats = [(pc.sphere, pc.at, pc.radius)] + [(pc.box, x, 0.0) for x in
                                                   _box_corners(pc.size, pc.box_at, pc.box_rotation)]
        if isinstance(pc, BoxCorner):
            eps = EDGE_TOL * min(float(np.min(pc.size)), float(np.min(pc.corner_size)))
            return feats, None, (1 / math.sqrt(3), math.sqrt(3) * eps, math.inf, True)
        return feats, None, (1.0, 0.0, math.inf, True)
    if isinstance(pc, EdgeContact):
        feats, half = [], 0.0
        for member, side in ((pc.a, pc.edge_a), (pc.b, pc.edge_b)):
            feats += [(member, x, side["radius"]) for x in _box_corners(side["size"], side["at"], side["rotation"])]
            half += float(np.linalg.norm(side["size"])) / 2
        return feats, None, (1.0, pc.margin, pc.band - 1.01 * half - pc.radius, False)
    if isinstance(pc, CapsuleSphere):
        axis = np.asarray(pc.rotation, float)[:, -1] * pc.length / 2
        feats = [(pc.sphere, pc.sphere_at, pc.sphere_radius),
                 (pc.capsule, np.asarray(pc.at) - axis, pc.radius), (pc.capsule, np.asarray(pc.at) + axis, pc.radius)]
        return feats, None, (1.0, 0.0, math.inf, True)
    return None, None, (1.0, 0.0, math.inf, True)


def _side(member, layout, feats, dim) -> Side:
    """The bounding volume of ``feats`` (``(point, radius)`` in ``member``'s frame) on
    ``member``, a member as the model was built, whose coordinate type the layout indexes
    (coordinate sharing re-bases a body on its joints' points and axes: same frame, other
    local coordinates; :func:`pair_contacts`)."""
    radius = max((r for _, r in feats), default=0.0)
    if member.is_ground:
        pts = np.array([np.asarray(x, float) for x, _ in feats])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        return Side("fixed", fixed=(lo + hi) / 2, radius=float(np.linalg.norm(hi - lo) / 2 + radius))
    rigid = member.rigid
    cs = np.array([rigid.affine(np.asarray(x, float)) for x, _ in feats]).reshape(len(feats), -1)
    k = cs.shape[1]
    lo, hi = cs.min(axis=0), cs.max(axis=0)
    c0, e = (lo + hi) / 2, (hi - lo) / 2
    C0 = np.asarray(rigid.C(c0), float)
    axes = np.array([np.asarray(rigid.C(c0 + np.eye(k)[j]), float) - C0 for j in range(k)]).reshape(k, dim, C0.shape[1])
    if k == 0:
        gnorm = 0.0
    else:
        Xbar = np.asarray(rigid.Xbar, float).reshape(dim, k)
        gnorm = float(np.linalg.norm(np.linalg.inv(Xbar.T @ Xbar), 2))
    idx = [-1 if i is None else int(i) for i in layout.member_indices(member.name)]
    return Side("member", idx=idx, centre=C0, axes=axes, extents=e, radius=float(radius), gnorm=gnorm)


def _element_sides(element, pcs, layout, dim):
    """The two :class:`Side` s of ``element`` and its bound constants."""
    members = element.members()
    feats: dict[int, list] = {id(m): [] for m in members}
    planes, bounds, known = [], [], True
    for pc in pcs:
        f, plane, bound = _features(pc)
        bounds.append(bound)
        if f is None:
            known = False
            continue
        for m, x, r in f:
            feats.setdefault(id(m), []).append((x, r))
        if plane is not None:
            planes.append(plane)
    kappa = min(b[0] for b in bounds)
    dmin = max(b[1] for b in bounds)
    cap = min(b[2] for b in bounds)
    rate_bounded = all(b[3] for b in bounds)
    sides = []
    for m in members:
        plane = next((pl for pl in planes if pl["member"] is m), None)
        if not known or (plane is not None and not m.is_ground):
            sides.append(Side("unbounded"))
        elif plane is not None:
            sides.append(Side("halfspace", fixed=np.asarray(plane["point"], float),
                              normal=np.asarray(plane["normal"], float)))
        else:
            sides.append(_side(m, layout, feats[id(m)], dim))
    return sides, kappa, dmin, cap, rate_bounded


def _local(member, layout):
    """``(idx, const)`` of ``member``'s local coordinates (empty for the ground)."""
    if member.is_ground:
        return [], np.zeros(0)
    idx = [-1 if i is None else int(i) for i in layout.member_indices(member.name)]
    return idx, np.asarray(layout.member_constant(member.name), float)


def pair_contacts(model) -> tuple | None:
    """The contact elements of ``model`` as built (``model.contact_elements``: their members
    are ``model.members``, re-based by coordinate sharing as the layout indexes them), or
    None when it has none (the flat kernels are used)."""
    return tuple(model.contact_elements) or None


def _flat(model, memo: dict) -> tuple:
    """``(q, p, WN, WT, g)``: the flat rows' expressions (not derived again), made once."""
    if not memo:
        jac = model.functions["contact_jacobian"]
        q, p = jac.sx_in(0), jac.sx_in(1)
        memo["flat"] = (q, p, *jac(q, p), model.functions["gap"](q, p))
    return memo["flat"]


def _flat_rows(model, element, first, qa, qb, p, memo: dict):
    """``(g, W)`` of ``element`` (its point contacts from ``first``) in its local coordinates
    ``qa``, ``qb``: the rows of the model's flat ``gap`` and ``contact_jacobian`` (numbers
    built in)."""
    dim, layout = model.dim, model.layout
    q, pf, WN, WT, gaps = _flat(model, memo)
    nt = dim - 1
    (idx_a, _), (idx_b, _) = (_local(m, layout) for m in element.members())
    qfull = ca.SX.zeros(model.nq)
    for sym, idx in ((qa, idx_a), (qb, idx_b)):
        for k, i in enumerate(idx):
            if i >= 0:
                qfull[i] = sym[k]
    pcs = element.point_contacts()
    rows = []
    for k, pc in enumerate(pcs, start=first):
        rows += [WN[k, :], WT[k * nt:(k + 1) * nt, :] if pc.mu > 0 else ca.SX(nt, model.nq)]
    W = ca.vertcat(*rows)
    Wloc = ca.horzcat(*[W[:, i] if i >= 0 else ca.SX(W.shape[0], 1) for i in idx_a + idx_b])
    full = ca.Function("pair", [q, pf], [gaps[first:first + len(pcs)], Wloc])
    # common subexpressions merged: the kernel is then the same expression whether the
    # model's functions were made in this process (g and W sharing nodes) or read back
    # from the store of built models (two separate graphs), so the C is too
    g_loc, W_loc = ca.cse([*full(qfull, p)])
    return ca.densify(g_loc), ca.densify(W_loc)


def _kind_rows(model, element, n_a: int, n_b: int) -> tuple | None:
    """``(gap, rows)``: ``element``'s kernels as MX functions of ``(q_a, q_b, p)`` that call
    its point contacts' pair kinds (:mod:`ncgen.assembly.pair_kinds`: one C function per kind,
    its numbers a constant array of the call), or None when a point contact has no kind."""
    calls = [point_call(pc, model.dim) for pc in element.point_contacts()]
    if not KIND_CALLS or any(c is None for c in calls):
        return None
    dim = model.dim
    qa, qb, p = ca.MX.sym("q_a", n_a), ca.MX.sym("q_b", n_b), ca.MX.sym("p", model.np)
    names = [m.name for m in element.members()]
    local = {names[0]: (qa, 0), names[1]: (qb, n_a)}
    g, g_only, blocks = [], [], []
    for pc, call in zip(element.point_contacts(), calls):
        sides = [local[m.name] for m in call.members if not m.is_ground]
        args = [ca.vertcat(*(s for s, _ in sides)), ca.DM(call.numbers)]
        gk, Wk = call.kind.function(*args)
        g.append(gk)
        g_only.append(call.kind.gap(*args))
        cols, at = [ca.MX(dim, n_a), ca.MX(dim, n_b)], 0
        for s, off in sides:
            cols[0 if off == 0 else 1] = Wk[:, at:at + s.numel()]
            at += s.numel()
        block = ca.horzcat(*cols)
        blocks.append(block if pc.mu > 0 else ca.vertcat(block[0, :], ca.MX(dim - 1, n_a + n_b)))
    names_in = ["q_a", "q_b", "p"]
    gap = ca.Function("gap", [qa, qb, p], [ca.vertcat(*g_only)], names_in, ["g"])
    rows = ca.Function("rows", [qa, qb, p], [ca.vertcat(*g), ca.densify(ca.vertcat(*blocks))], names_in, ["g", "W"])
    return gap, rows


def _renamed(f: ca.Function, name: str) -> ca.Function:
    args = f.mx_in() if f.is_a("MXFunction") else f.sx_in()
    return ca.Function(name, args, f.call(args), f.name_in(), f.name_out())


def pair_kernels(model) -> PairKernels:
    """The element kernels and table of ``model`` (nonsmooth contacts; module docstring);
    ``model`` must have :func:`pair_contacts`."""
    p = ca.SX.sym("p", model.np)
    kernels: dict[str, int] = {}
    functions, memo = [], {}

    def kernel(element, first, n_a, n_b) -> int:
        kind = _kind_rows(model, element, n_a, n_b)
        if kind is None:
            qa, qb = ca.SX.sym("q_a", n_a), ca.SX.sym("q_b", n_b)
            g_loc, W_loc = _flat_rows(model, element, first, qa, qb, p, memo)
            gap = ca.Function("gap", [qa, qb, p], [g_loc], ["q_a", "q_b", "p"], ["g"])
            kind = gap, ca.Function("rows", [qa, qb, p], [g_loc, W_loc], ["q_a", "q_b", "p"], ["g", "W"])
        key = hashlib.sha256(kind[1].serialize().encode()).hexdigest()
        if key not in kernels:
            kernels[key] = len(kernels)
            k = kernels[key]
            functions.extend([_renamed(kind[0], f"step_pair{k}_gap"), _renamed(kind[1], f"step_pair{k}_rows")])
        return kernels[key]

    return PairKernels(functions, pair_elements(model, kernel))


def pair_elements(model, kernel=None) -> list:
    """The :class:`Element` table of ``model`` (:func:`pair_contacts`), each element's kernel
    number ``kernel(element, first point contact, n_a, n_b)`` (None: −1, no kernel)."""
    layout, dim = model.layout, model.dim
    elements, first = [], 0
    for element in pair_contacts(model):
        pcs = element.point_contacts()
        (idx_a, const_a), (idx_b, const_b) = (_local(m, layout) for m in element.members())
        number = kernel(element, first, len(idx_a), len(idx_b)) if kernel is not None else -1
        sides, kappa, dmin, cap, rate_bounded = _element_sides(element, pcs, layout, dim)
        elements.append(Element(element.name, first, len(pcs), number, idx_a, idx_b, const_a, const_b,
                                tuple(sides), kappa, dmin, cap, rate_bounded, [pc.mu > 0 for pc in pcs]))
        first += len(pcs)
    return elements


def _side_numbers(side: Side, ql, vl):
    """``(x₀, R, speed terms lin, rot)`` of ``side`` at local coordinates ``ql`` (rates ``vl``)."""
    if side.kind == "fixed":
        return side.fixed, side.radius, 0.0, 0.0
    x0, X = side.centre @ ql, [a @ ql for a in side.axes]
    V = [a @ vl for a in side.axes] if vl is not None else [np.zeros_like(x0) for _ in side.axes]
    R = side.radius + sum(e * np.linalg.norm(x) for e, x in zip(side.extents, X))
    if vl is None:
        return x0, R, 0.0, 0.0
    lin = np.linalg.norm(side.centre @ vl) + sum(e * np.linalg.norm(v) for e, v in zip(side.extents, V))
    rot = side.gnorm * math.sqrt(sum(float(v @ v) for v in V)) * math.sqrt(sum(float(x @ x) for x in X))
    return x0, R, lin, rot


def element_bounds(element: Element, q, v=None) -> tuple[float, float]:
    """``(b, S)``: the lower bound of ``element``'s gaps at ``q`` (−inf where none) and the
    bound of its rows' velocities ``|W_r v|`` (module docstring); the formulas of
    ``pair_member_bound`` and ``pair_lower`` in ``templates/c/runtime/ncgen_contact_pairs.h``, for tests."""
    def local(idx, const, x, rates):
        return np.array([x[i] if i >= 0 else (0.0 if rates else c) for i, c in zip(idx, const)])
    q = np.asarray(q, float)
    parts = []
    for side, idx, const in zip(element.sides, (element.idx_a, element.idx_b), (element.const_a, element.const_b)):
        if side.kind == "unbounded":
            return -math.inf, 0.0
        ql = local(idx, const, q, False)
        vl = local(idx, const, np.asarray(v, float), True) if v is not None else None
        parts.append((side, ql, vl))
    half = [k for k, (side, _, _) in enumerate(parts) if side.kind == "halfspace"]
    if half:
        side, _, _ = parts[half[0]]
        x0, R, lin, rot = _side_numbers(*parts[1 - half[0]])
        D = float(side.normal @ (x0 - side.fixed)) - R
        lb, speed = D - BOUND_SLACK * R, lin + 2 * R * rot
    else:
        (xa, Ra, la, ra), (xb, Rb, lb_, rb) = (_side_numbers(*p) for p in parts)
        D = float(np.linalg.norm(xb - xa)) - Ra - Rb
        lb = element.kappa * D - BOUND_SLACK * (Ra + Rb)
        speed = la + lb_ + (ra + rb) * (D + 3 * (Ra + Rb))
    if not D >= element.dmin:
        return -math.inf, speed
    return min(lb, element.cap), speed
