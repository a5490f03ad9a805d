"""Contact kinematics and the smooth (compliant) contact law as CasADi expressions.

For contact k (:mod:`ncgen.model.contacts`) with unit normal ``n`` and tangent basis
``t₁, t₂`` (one tangent in planar systems):

* gap ``g_k(q)`` (m): sphere–plane ``nᵀ (r_s − x_p) − R``, sphere–sphere
  ``|r_b − r_a| − R_a − R_b``; a shape against a plane is several sphere–plane points
  (:func:`ncgen.model.contacts.point_contacts`), a cylinder's rim point of radius ``ρ``
  about the body axis ``a`` through ``r_s`` being the lowest: ``x = r_s − ρ u`` with
  ``w = n − (n·a) a``, ``u = w / sqrt(|w|² + ε²)`` (:data:`RIM_EPS`), so
  ``g = nᵀ (r_s − x_p) − ρ |w|² / sqrt(|w|² + ε²)``.  A body-fixed point is ``r = C(c) q``, so against a
  plane fixed to the ground the gap is linear in q and its Jacobian constant.
* contact Jacobians ``W_N`` (1 × nq) and ``W_T`` ((dim − 1) × nq): the normal and
  tangential components of the relative velocity of the two material points at the contact
  point, ``[n, t₁, t₂]ᵀ (v_second − v_first) = [W_N; W_T] q̇``.  A material point at the world
  point x of member I moves with ``ṙ_ref + ω × (x − r_ref)`` (``ω`` from the member's
  derivation: a 3D bar does not spin about its axis); with the contact point on the sphere's
  surface, ``W_N = ∂g/∂q`` (exactly, except for a plane carried by a member, where it is the
  relative normal velocity at the contact point).
* generalised contact force ``Q = W_Nᵀ f_N + W_Tᵀ f_T`` for normal force ``f_N`` and
  tangential components ``f_T`` (N) on the second element.

Smooth law (``System.build(contacts="smooth")``, documented in docs/contact.md):
Hunt–Crossley ``f_N = max(0, δⁿ (k + d δ̇))`` with ``δ = max(0, −g)``, ``δ̇ = −W_N q̇``, and
regularised Coulomb friction ``f_T = −μ f_N v_T / sqrt(|v_T|² + v_s²)`` with
``v_T = W_T q̇``; the spring's potential ``k δⁿ⁺¹/(n + 1)`` joins the potential energy.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.errors import ModelError
from ncgen.model.context import Context
from ncgen.model.contacts import PARALLEL_SIN, BoxCorner, EdgeContact, SphereBox, SphereSphere, point_contacts
from ncgen.model.capsule_contacts import CapsuleSphere, CylinderSphere
from ncgen.rigid_motion import casadi_forms as crm

#: Regularisation of a cylinder rim's lowest point (dimensionless): within ~ε rad of standing
#: on that end the point slides to the face centre.  The gap exceeds the true one by
#: ``ρ s (1 − s / sqrt(s² + ε²))`` at a tilt s = sin β: at most ~0.3 ρ ε (near s = ε; 2.4e-6 m
#: for ρ = 8 cm), ``ρ ε² / 2`` lying.  A smaller ε makes the rows of a nearly upright rim
#: change faster than a step resolves (the two half-steps' impulses then tilt it).
RIM_EPS = 1e-4
#: Box corners against a box, relative to the smallest edge of the two boxes (see
#: :func:`_sphere_box`).  ``EDGE_TOL``: a corner counts as over a face while it is off the
#: face's edges by at most this: equal boxes stacked flush have every corner on an edge of
#: the other, and a yaw of ψ moves them off by ~ψ × half the diagonal, so a smaller tolerance
#: lets a yaw of 1e-6 rad (a friction solve's drift) drop the upper box through (no corner is
#: then over a face); the price: the support reaches that far past an edge (1 mm for 10 cm
#: boxes).  ``FACE_TIE``:
#: among the faces a corner is over, one lying flatter against the corner's own box wins
#: while its face-plane distance is within this of the largest.  A corner of a box resting on
#: an equal box lies on the lower box's side planes too (distance 0 from them however deep it
#: goes), so the tie must exceed the depth a corner reaches within a step (about v h, 1 mm at
#: 1 m/s and h = 1 ms); where the faces' flatness differs and a corner is within the tie of a
#: side plane, a penetration up to the tie can be attributed to the wrong face.
EDGE_TOL, FACE_TIE = 1e-2, 1e-2


class ContactTerms:
    """Gap, normal/tangential Jacobians (in q only) of one contact, as SX."""

    def __init__(self, contact, g, WN, WT):
        self.contact, self.g, self.WN, self.WT = contact, g, WN, WT


def contact_terms(ctx: Context, contacts) -> list[ContactTerms]:
    """The :class:`ContactTerms` of every point contact of ``contacts``, in order."""
    def terms(c):
        if isinstance(c, SphereSphere):
            return _sphere_sphere(ctx, c)
        if isinstance(c, SphereBox):
            return _sphere_box(ctx, c)
        if isinstance(c, EdgeContact):
            return _edge_edge(ctx, c)
        if isinstance(c, CylinderSphere):
            return _cylinder_sphere(ctx, c)
        if isinstance(c, CapsuleSphere):
            return _capsule_sphere(ctx, c)
        return _sphere_plane(ctx, c)
    return [terms(c) for c in point_contacts(contacts)]


def _omega_cross(ctx: Context, member, d):
    """``ω × d = ω̂ d`` for member ``member`` (zero for points; ``crm.so3_hat`` in 3D); ``ω`` linear in q̇."""
    if member.ctype.kind == "point":
        return ca.SX.zeros(ctx.dim)
    w = ctx.instantiate(member, "omega")
    if ctx.dim == 2:
        return w[0] * ca.vertcat(-d[1], d[0])
    return ca.mtimes(crm.so3_hat(w), d)


def _material_velocity(ctx: Context, member, r_ref, rdot_ref, x):
    """Velocity of the material point of ``member`` at the world point ``x``."""
    if member.is_ground:
        return ca.SX.zeros(ctx.dim)
    return rdot_ref + _omega_cross(ctx, member, x - r_ref)


def _jacobians(ctx: Context, n, tangents, rel):
    rows = [ca.dot(n, rel)] + [ca.dot(t, rel) for t in tangents]
    W = ca.jacobian(ca.vertcat(*rows), ctx.v)
    return W[0, :], W[1:, :]


def _sphere_plane(ctx: Context, c) -> ContactTerms:
    r_s, rd_s = ctx.local_point(c.sphere, c.at)
    P = c.plane
    what = c.label
    if P.is_ground:
        n, x_p = _const(c.normal), _const(c.point)
        tangents = ctx.plane_tangents(c.normal)
        vel_plane = lambda x: ca.SX.zeros(ctx.dim)  # noqa: E731
    else:
        n = ctx.direction(P, c.normal, what)[0]
        x_p, xd_p = ctx.point(P, c.point, what)
        tangents = ctx.perpendiculars(P, c.normal, what)
        vel_plane = lambda x: _material_velocity(ctx, P, x_p, xd_p, x)  # noqa: E731
    rho = getattr(c, "rim_radius", 0.0)
    if isinstance(rho, ca.SX) or rho > 0:
        axis = ctx.local_point(c.sphere, _num(c.at) + _num(c.axis))[0] - r_s
        w = n - ca.dot(n, axis) * axis
        centre = r_s - rho * w / ca.sqrt(ca.sumsqr(w) + RIM_EPS ** 2)
    else:
        centre = r_s
    g = ca.dot(n, centre - x_p) - c.radius
    x = centre - c.radius * n
    rel = _material_velocity(ctx, c.sphere, r_s, rd_s, x) - vel_plane(x)
    WN, WT = _jacobians(ctx, n, tangents, rel)
    return ContactTerms(c, g, WN, WT)


def _sphere_sphere(ctx: Context, c: SphereSphere) -> ContactTerms:
    r_a, rd_a = ctx.local_point(c.a, c.at_a)
    r_b, rd_b = ctx.local_point(c.b, c.at_b)
    d = r_b - r_a
    length = ca.sqrt(ca.sumsqr(d))
    n = d / length
    g = length - c.radius_a - c.radius_b
    rel = (_material_velocity(ctx, c.b, r_b, rd_b, r_b - c.radius_b * n)
           - _material_velocity(ctx, c.a, r_a, rd_a, r_a + c.radius_a * n))
    WN, WT = _jacobians(ctx, n, tangent_basis(n), rel)
    return ContactTerms(c, g, WN, WT)


def _fixed_point(ctx: Context, member, at):
    """World position and velocity of the point at local ``at`` of ``member`` (world for the ground)."""
    if member.is_ground:
        return _const(at), ca.SX.zeros(ctx.dim)
    return ctx.local_point(member, at)


def _axes(ctx: Context, member, at, rotation) -> list:
    """World directions of the columns of ``rotation`` (in ``member``'s frame) at ``at``."""
    if member.is_ground:
        return [_const(_num(rotation)[:, k]) for k in range(ctx.dim)]
    r = ctx.local_point(member, at)[0]
    return [ctx.local_point(member, _num(at) + _num(rotation)[:, k])[0] - r for k in range(ctx.dim)]


def _sphere_box(ctx: Context, c) -> ContactTerms:
    """Sphere (or a :class:`BoxCorner`, radius 0) against a box.  With ``p`` the centre in the
    box's axes ``b_k`` and ``h = size/2``:

    * outside (some ``|p_k| > h_k``; spheres only): ``g = |p − clamp(p, −h, h)| − R``,
      normal along ``p − clamp(p)`` (the nearest face, edge or corner);
    * inside: ``g = max_k (|p_k| − h_k) − R`` over the face planes, normal ``sign(p_k) b_k``
      of the face chosen (the signed distance to the surface).
    * a box corner (R = 0), always: the face-plane distance ``|p_k| − h_k`` of one face k,
      chosen among the faces the corner is over (``|p_l| ≤ h_l + EDGE_TOL·e`` for l ≠ k, e the
      smallest edge of the two boxes; inside the box, all) by the largest
      ``|p_k| − h_k + FACE_TIE·e·f_k``, with ``f_k = max_l −sign(p_k) b_k·σ_l a_l`` how flat
      the face lies against a face of the corner's own box (σ the corner's signs, a its box's
      axes); over no face (off an edge or a corner), the largest face-plane distance.  The
      gap is the signed distance inside and over a face, a lower bound (still > 0) off an
      edge or a corner, so a corner touches exactly when it reaches the surface, and a box
      resting on an equal one (its corners on the lower box's side planes too) presses on
      the top face.

    The gap is piecewise smooth: its derivative (``W_N``) holds within the face or region
    chosen."""
    r_s, rd_s = _fixed_point(ctx, c.sphere, c.at)
    centre_b, rd_b = _fixed_point(ctx, c.box, c.box_at)
    b = _axes(ctx, c.box, c.box_at, c.box_rotation)
    h = c.size / 2
    p = [ca.dot(bk, r_s - centre_b) for bk in b]
    corner = isinstance(c, BoxCorner)
    if corner:
        a = _axes(ctx, c.sphere, c.at, c.corner_rotation)
        scale = _min(_num(c.size), _num(c.corner_size))
        band = 10 * (_sum(_num(c.size)) + _sum(_num(c.corner_size)))    # above any distance
    best_key = best_g = best_n = None
    for k in range(ctx.dim):
        s = ca.if_else(p[k] >= 0, 1, -1)
        gk = s * p[k] - h[k]
        key = gk
        if corner:
            over = _all([ca.fabs(p[l]) <= h[l] + EDGE_TOL * scale for l in range(ctx.dim) if l != k])
            flat = _max([-s * _num(c.corner_signs)[j] * ca.dot(b[k], al) for j, al in enumerate(a)])
            key = ca.if_else(over, gk + FACE_TIE * scale * flat + band, gk)
        nk = s * b[k]
        if best_key is None:
            best_key, best_g, best_n = key, gk, nk
        else:
            better = key > best_key
            best_key, best_g = ca.if_else(better, key, best_key), ca.if_else(better, gk, best_g)
            best_n = ca.if_else(better, nk, best_n)
    g, n = best_g - c.radius, best_n
    if not corner:
        d = [p[k] - ca.fmin(ca.fmax(p[k], -h[k]), h[k]) for k in range(ctx.dim)]
        dist2 = sum(dk * dk for dk in d)
        dist = ca.sqrt(ca.fmax(dist2, 1e-300))
        outside = dist2 > 0
        g = ca.if_else(outside, dist - c.radius, g)
        n = ca.if_else(outside, sum((dk / dist) * bk for dk, bk in zip(d, b)), n)
    x = r_s - c.radius * n
    rel = _material_velocity(ctx, c.sphere, r_s, rd_s, x) - _material_velocity(ctx, c.box, centre_b, rd_b, x)
    WN, WT = _jacobians(ctx, n, tangent_basis(n), rel)
    return ContactTerms(c, g, WN, WT)


def _facing_edge(ctx: Context, member, side: dict, n):
    """Centre (world) of the edge of ``side``'s box (:class:`EdgeContact`) along its axis
    that faces the direction ``n``: ``c + Σ σ_k h_k a_k`` over the other axes k, with
    ``σ_k = sign(n·a_k)`` for the one more aligned with n and ``2·choice − 1`` for the other
    (where n lies along a face normal both edges of the face face it).  Returns the box's
    centre, the edge's centre and its unit direction."""
    rotation = _num(side["rotation"])
    centre = _fixed_point(ctx, member, side["at"])[0]
    axes = _axes(ctx, member, side["at"], rotation)
    i, h = side["axis"], _num(side["size"]) / 2
    k1, k2 = [k for k in range(3) if k != i]
    d1, d2 = ca.dot(n, axes[k1]), ca.dot(n, axes[k2])
    first = ca.fabs(d1) >= ca.fabs(d2)
    free = 2.0 * side["choice"] - 1.0
    s1 = ca.if_else(first, ca.if_else(d1 >= 0, 1, -1), free)
    s2 = ca.if_else(first, free, ca.if_else(d2 >= 0, 1, -1))
    return centre, centre + s1 * h[k1] * axes[k1] + s2 * h[k2] * axes[k2], axes[i]


def _edge_edge(ctx: Context, c: EdgeContact) -> ContactTerms:
    """An edge (or segment) of ``a`` against one of ``b`` (:class:`EdgeContact`).  With
    ``u``, ``w`` the edges' unit directions, ``n = ±(u × w)/|u × w|`` oriented along the
    centres' difference ``d = c_b − c_a``, the edge of each box facing the other (``a``'s
    facing n, ``b``'s −n; :func:`_facing_edge`) centred at ``e_a``, ``e_b``, and
    ``δ = e_b − e_a``, the closest points of the two lines are ``e_a + s u`` and
    ``e_b + t w`` with

        s = (u·δ − β w·δ)/(1 − β²),   t = (β u·δ − w·δ)/(1 − β²),   β = u·w,

    and the gap is ``g = n·δ − r_a − r_b`` (the lines' distance along n, less the radii):
    the separation of the two boxes along n, hence their distance while the closest points
    lie on both edges.  It holds while ``|s|``, ``|t|`` are within the edges' half lengths
    less ``margin``, ``|u × w| > PARALLEL_SIN`` and ``g > −margin`` (only near the edges is a
    negative g a penetration: where the boxes overlap along n, two edges far behind each
    other's faces also cross); elsewhere it is ``g + band`` (> 0: no contact).
    ``W_N = ∂g/∂q`` (n ⊥ u, w and the closest points differ along n)."""
    ea, eb = c.edge_a, c.edge_b
    axis_a = _axes(ctx, c.a, ea["at"], _num(ea["rotation"]))[ea["axis"]]
    axis_b = _axes(ctx, c.b, eb["at"], _num(eb["rotation"]))[eb["axis"]]
    d = _fixed_point(ctx, c.b, eb["at"])[0] - _fixed_point(ctx, c.a, ea["at"])[0]
    n0 = ca.cross(axis_a, axis_b)
    sine = ca.sqrt(ca.sumsqr(n0))
    n0 = ca.if_else(sine > 1e-9, n0 / sine, tangent_basis(axis_a)[0])  # parallel: any normal (no contact)
    n = ca.if_else(ca.dot(n0, d) >= 0, 1, -1) * n0
    ca_, e_a, u = _facing_edge(ctx, c.a, ea, n)
    cb_, e_b, w = _facing_edge(ctx, c.b, eb, -n)
    delta = e_b - e_a
    beta = ca.dot(u, w)
    det = ca.fmax(1 - beta * beta, 1e-24)
    s = (ca.dot(u, delta) - beta * ca.dot(w, delta)) / det
    t = (beta * ca.dot(u, delta) - ca.dot(w, delta)) / det
    g = ca.dot(n, delta) - c.radius
    inside = _all([sine > PARALLEL_SIN, g > -c.margin, ca.fabs(s) <= _num(ea["size"])[ea["axis"]] / 2 - c.margin,
                   ca.fabs(t) <= _num(eb["size"])[eb["axis"]] / 2 - c.margin])
    x = 0.5 * (e_a + s * u + ea["radius"] * n + e_b + t * w - eb["radius"] * n)
    rel = (_material_velocity(ctx, c.b, cb_, _fixed_point(ctx, c.b, eb["at"])[1], x)
           - _material_velocity(ctx, c.a, ca_, _fixed_point(ctx, c.a, ea["at"])[1], x))
    WN, WT = _jacobians(ctx, n, tangent_basis(n), rel)
    return ContactTerms(c, ca.if_else(inside, g, g + c.band), WN, WT)


def _capsule_sphere(ctx: Context, c: CapsuleSphere) -> ContactTerms:
    """A sphere (centre x, radius r_s) against a capsule (centre m, unit axis u, length L,
    radius r): the nearest point of the segment ``p = m + τ u``,
    ``τ = clamp(u·(x − m), −L/2, L/2)``; ``g = |x − p| − r_s − r``, ``n = (x − p)/|x − p|``.
    ``W_N = ∂g/∂q`` (n ⊥ u where τ is inside, τ constant where clamped)."""
    x, xd = _fixed_point(ctx, c.sphere, c.sphere_at)
    m, md = _fixed_point(ctx, c.capsule, c.at)
    u = _axes(ctx, c.capsule, c.at, c.rotation)[2]
    tau = ca.fmin(ca.fmax(ca.dot(u, x - m), -c.length / 2), c.length / 2)
    d = x - (m + tau * u)
    dist = ca.sqrt(ca.fmax(ca.sumsqr(d), 1e-300))
    n = d / dist
    point = x - c.sphere_radius * n
    rel = _material_velocity(ctx, c.sphere, x, xd, point) - _material_velocity(ctx, c.capsule, m, md, point)
    WN, WT = _jacobians(ctx, n, tangent_basis(n), rel)
    return ContactTerms(c, dist - c.total_radius, WN, WT)


def _cylinder_sphere(ctx: Context, c: CylinderSphere) -> ContactTerms:
    """A sphere (centre x, radius r_s) against a solid cylinder (centre m, unit axis u,
    radius R, length L).  With ``z = u·(x − m)``, the radial vector ``ρ = x − m − z u``
    (``ρ̂ = ρ/|ρ|``), ``a = |ρ| − R`` and ``b = |z| − L/2``: outside (a > 0 or b > 0),
    ``g = sqrt(a⁺² + b⁺²) − r_s`` with ``n = (a⁺ ρ̂ + b⁺ sign(z) u)/sqrt(a⁺² + b⁺²)``
    (side, end face or rim); inside, ``g = max(a, b) − r_s`` with ``n = ρ̂`` or
    ``sign(z) u`` (the signed distance).  ``W_N = ∂g/∂q`` within each region."""
    x, xd = _fixed_point(ctx, c.sphere, c.sphere_at)
    m, md = _fixed_point(ctx, c.capsule, c.at)
    u = _axes(ctx, c.capsule, c.at, c.rotation)[2]
    z = ca.dot(u, x - m)
    rho = x - m - z * u
    rlen = ca.sqrt(ca.fmax(ca.sumsqr(rho), 1e-300))
    radial = ca.if_else(rlen > 1e-12, rho / rlen, tangent_basis(u)[0])
    axial = ca.if_else(z >= 0, 1, -1) * u
    a, b = rlen - c.radius, ca.fabs(z) - c.length / 2
    ap, bp = ca.fmax(a, 0), ca.fmax(b, 0)
    dist = ca.sqrt(ca.fmax(ap * ap + bp * bp, 1e-300))
    outside = ca.logic_or(a > 0, b > 0)
    g = ca.if_else(outside, dist, ca.fmax(a, b)) - c.sphere_radius
    n = ca.if_else(outside, (ap * radial + bp * axial) / dist, ca.if_else(a > b, radial, axial))
    point = x - c.sphere_radius * n
    rel = _material_velocity(ctx, c.sphere, x, xd, point) - _material_velocity(ctx, c.capsule, m, md, point)
    WN, WT = _jacobians(ctx, n, tangent_basis(n), rel)
    return ContactTerms(c, g, WN, WT)


def _num(x):
    """A contact's number or array of numbers as a float array; an SX (a pair kind's
    argument, :mod:`ncgen.assembly.pair_kinds`) as it is."""
    return x if isinstance(x, ca.SX) else np.asarray(x, float)


def _const(x):
    """:func:`_num` as a CasADi constant (a DM), an SX as it is."""
    return x if isinstance(x, ca.SX) else ca.DM(np.asarray(x, float))


def _min(*xs):
    """The smallest entry of the arrays ``xs`` (floats, or SX)."""
    if any(isinstance(x, ca.SX) for x in xs):
        return ca.mmin(ca.vertcat(*xs))
    return min(float(np.min(x)) for x in xs)


def _sum(x):
    return ca.sum1(x) if isinstance(x, ca.SX) else float(np.sum(x))


def _all(conditions):
    out = conditions[0]
    for x in conditions[1:]:
        out = ca.logic_and(out, x)
    return out


def _max(xs):
    out = xs[0]
    for x in xs[1:]:
        out = ca.fmax(out, x)
    return out


def tangent_basis(n) -> list:
    """Unit tangents completing the unit normal ``n`` (SX) to a right-handed basis: in 3D
    ``t₁ ∝ n × e`` with ``e`` the axis of ``z``, ``x`` least aligned with ``n``."""
    if n.shape[0] == 2:
        return [ca.vertcat(-n[1], n[0])]
    helper = ca.if_else(ca.fabs(n[2]) < 0.8, ca.DM([0, 0, 1]), ca.DM([1, 0, 0]))
    t1 = ca.cross(n, helper)
    t1 = t1 / ca.sqrt(ca.sumsqr(t1))
    return [t1, ca.cross(n, t1)]


def smooth_forces(ctx: Context, terms: list[ContactTerms]):
    """``(f_N (nk), f_T (nk·(dim−1)), Q (nq), V (nk))``: the smooth law's contact forces (N),
    their generalised force and the contact springs' potential energies (J)."""
    fN, fT, V = [], [], []
    Q = ca.SX.zeros(ctx.layout.nq)
    for k in terms:
        c = k.contact
        delta = ca.fmax(0, -k.g)
        rate = -ca.mtimes(k.WN, ctx.v)
        dn = delta ** c.exponent
        f_n = ca.fmax(0, dn * (c.stiffness + c.damping * rate))
        vT = ca.mtimes(k.WT, ctx.v)
        f_t = -c.mu * f_n * vT / ca.sqrt(ca.sumsqr(vT) + c.slip_velocity ** 2)
        Q += ca.mtimes(k.WN.T, f_n) + ca.mtimes(k.WT.T, f_t)
        fN.append(f_n)
        fT.append(f_t)
        V.append(c.stiffness * delta ** (c.exponent + 1) / (c.exponent + 1))
    return ca.vertcat(*fN), ca.vertcat(*fT), Q, ca.vertcat(*V)


def contact_functions(ctx: Context, terms: list[ContactTerms]) -> dict[str, ca.Function]:
    """``gap: q, p -> g``; ``contact_jacobian: q, p -> WN (nk × nq), WT (nk·(dim−1) × nq)``
    (rows of contact k: ``k`` and ``k·(dim−1) ...``); ``contact_force: t, q, v, p -> fN, fT``
    (the smooth law, N, whether or not the model uses it)."""
    q, v, p, t = ctx.q, ctx.v, ctx.p, ctx.t
    g = ca.vertcat(*[k.g for k in terms])
    WN = ca.vertcat(*[k.WN for k in terms])
    WT = ca.vertcat(*[k.WT for k in terms])
    fN, fT, _, _ = smooth_forces(ctx, terms)
    return {
        "gap": ca.Function("gap", [q, p], [g], ["q", "p"], ["g"]),
        "contact_jacobian": ca.Function("contact_jacobian", [q, p], [WN, WT], ["q", "p"], ["WN", "WT"]),
        "contact_force": ca.Function("contact_force", [t, q, v, p], [fN, fT], ["t", "q", "v", "p"], ["fN", "fT"]),
    }


#: Deepest initial penetration (m) the nonsmooth stepper accepts: deeper overlaps are refused
#: by :func:`check_initial_gaps` (the step's push-out resolves only what arises within a step).
INITIAL_PENETRATION_TOL = 1e-6


def check_initial_gaps(system_name: str, contacts, functions, q, p, contact_model: str, weight: float,
                       depth: bool = True) -> np.ndarray:
    """The gaps ``g`` (m) of ``contacts`` at ``(q, p)`` (``functions``: the model's, with
    :func:`contact_functions`' ``gap`` and ``contact_jacobian``), after refusing what no run
    can start from, naming the contact and the depth (``depth=False``: only the first two, at a
    configuration the run does not start from, as a URDF's zero pose before its initial
    joints are applied):

    * coincident sphere centres (the normal is undefined);
    * any other contact whose normal is undefined, its Jacobian rows not finite: the
      nearest points of its shapes' cores coincide (a capsule's end on the other's segment);
    * ``contact_model="nonsmooth"``: a penetration deeper than :data:`INITIAL_PENETRATION_TOL`;
    * the smooth law: two spheres overlapping past a centre (the normal, from centre to
      centre, points the wrong way), or a sphere deeper in a plane than its radius and than
      ten times the depth ``(W/k)^(1/n)`` at which the contact alone would carry the system's
      weight ``W`` (N) — a start that launches the members.
    """
    g = np.array(functions["gap"](q, p), float).reshape(-1)
    points = point_contacts(contacts)
    undefined = _undefined_normals(points, functions["contact_jacobian"], q, p)
    for k, (c, gk) in enumerate(zip(points, g)):
        radius = c.radius_a + c.radius_b if c.kind == "SphereSphere" else getattr(c, "total_radius", c.radius)
        if c.kind == "SphereSphere" and gk + radius <= 1e-12 * max(radius, 1.0):
            raise ModelError(f"system {system_name!r}: {c.label}: the centres of the spheres on {c.a.name!r} "
                             f"and {c.b.name!r} coincide in the initial configuration (the contact normal is "
                             "undefined); move one of the members")
        if k in undefined:
            others = [points[i].name for i in undefined if i != k]
            raise ModelError(
                f"system {system_name!r}: {c.label} between "
                f"{' and '.join(repr(m.name) for m in c.members())}: its contact normal is undefined in the "
                f"initial configuration (the Jacobian rows {', '.join(undefined[k])} are not finite, gap "
                f"{gk:.6g} m): the nearest points of the two shapes' cores coincide, as where a capsule's end "
                "lies on the other's axis"
                + (f" (also {', '.join(others)})" if others else "")
                + ". Move the members apart, or leave this pair out of the contacts (in MJCF: contype/"
                "conaffinity or <contact><exclude>)")
        if not depth:
            continue
        if contact_model == "nonsmooth":
            limit, why = INITIAL_PENETRATION_TOL, f"the nonsmooth stepper starts from at most {INITIAL_PENETRATION_TOL:g} m"
        elif c.kind == "SphereSphere":
            limit, why = radius, "past a sphere's centre, where the compliant law pushes the spheres the wrong way"
        else:
            resting = (weight / c.stiffness) ** (1.0 / c.exponent)
            limit = max(radius, 10 * resting)
            why = (f"deeper than the sphere's radius and than 10 × the depth {resting:.3g} m at which the compliant "
                   "law carries the system's weight: the run would start with an explosion")
        if -gk > limit:
            raise ModelError(f"system {system_name!r}: {c.label}: the initial configuration penetrates by "
                             f"{-gk:.6g} m (gap {gk:.6g} m); {why}. Start the members apart (move them by "
                             f"at least {-gk:.6g} m along the contact normal)")
    return g


def _undefined_normals(points, jacobian, q, p) -> dict[int, list[str]]:
    """``{k: ["W_N", "W_T"] (those not finite)}`` of the point contacts whose Jacobian rows
    ``jacobian(q, p)`` are not all finite."""
    WN, WT = (np.array(x, float) for x in jacobian(q, p))
    per = WT.shape[0] // max(len(points), 1)
    out = {}
    for k in range(len(points)):
        bad = [name for name, rows in (("W_N", WN[k:k + 1]), ("W_T", WT[k * per:(k + 1) * per]))
               if not np.all(np.isfinite(rows))]
        if bad:
            out[k] = bad
    return out


def contact_specs(contacts) -> list[dict]:
    """Plain-data description of the point contacts (``model.contacts``, one per point)."""
    return [c.spec() for c in point_contacts(contacts)]

