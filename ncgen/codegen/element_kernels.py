"""Element kernels: one small CasADi function per *kind* of element, the model's numbers as
arguments (the structured code generation of issue 34, docs/architecture.md, "Element tables").

Two families of kinds, both from :mod:`ncgen.symbolic`:

* **joint kinds** ``(primitive, dim)``: a joint primitive of :mod:`ncgen.symbolic.joint_primitives`
  (``coincidence``, ``dot``, ``offset_dot``, ``distance``, ``slider_ratio``) applied to points and directions
  ``f`` (each a dim-vector) and constant scalars ``s`` (a dot product, an offset, a length).
  Kernel ``jk_<primitive>_<dim>d``: input ``x = [f_1; …; f_n; s_1; …]``, outputs ``phi`` (the
  primitive's rows) and ``J = ∂phi/∂[f_1; …; f_n]`` (dense, column-major); kernel
  ``jk_<primitive>_<dim>d_hvv``: inputs ``x`` and the features' rates ``ḟ``, output
  ``[ḟᵀ ∇²_f phi_r ḟ]_r`` (the Hessian-vector products of ``γ``);
* **member kinds** ``(dim, coordinate type)``: kernel ``mk_<type>_<dim>d_phi`` (a type with
  intrinsic constraints): inputs the member's coordinates ``q_I`` and its constants ``c``,
  outputs ``phi`` (``Φ_I``) and ``J = ∂Φ_I/∂q_I``; kernel ``mk_<type>_<dim>d_hvv``: inputs
  ``q̇_I`` and ``c``, output ``[q̇_Iᵀ H_k q̇_I]_k`` (constant Hessians); kernel
  ``mk_<type>_<dim>d_mass``: input ``c``, output the member's constant mass matrix ``M_I``
  (dense).

* **force kinds** ``spring_<dim>d`` (:data:`FORCE_KINDS`): kernel ``fk_spring_<dim>d`` of a
  linear spring-damper (:func:`ncgen.model.forces.spring_tension`): input
  ``x = [r_a; r_b; ṙ_a; ṙ_b; k; l₀; c]``, outputs ``y = [f; V; P]`` (the force on ``b``, N,
  ``−f`` acting on ``a``; its energy, J; its damper's power ``−c l̇²``, W) and
  ``J = ∂f/∂[r_a; r_b; ṙ_a; ṙ_b]`` (dense, column-major).  Gravity needs no kernel: its
  generalised force is constant.
* **force kinds over features** ``cable_<dim>d``, ``torsion_<dim>d``
  (:data:`FEATURE_FORCE_KINDS`): kernel ``ff_<force>_<dim>d`` of a force acting on
  ``n`` features (points or directions): input ``x = [f_1; …; f_n; ḟ_1; …; ḟ_n; numbers]``,
  outputs ``y = [g; V; P]`` (``g``: the generalised force on the stacked features, so that
  ``Q = Σ_X G_Xᵀ g_X``; the energy V, J; the power ``P = ḟ·(g + ∇_f V)`` of its
  non-conservative part, W) and ``J = ∂g/∂ḟ`` (n dim × n dim, column-major).  ``cable``:
  a :class:`~ncgen.model.forces.Spring` with ``cable=True`` between points ``r_a``, ``r_b``
  (numbers ``k, l₀, c``; :func:`~ncgen.model.forces.cable_tension`); ``torsion``: a
  :class:`~ncgen.model.forces.TorsionalSpring` on a hinge whose gauge
  (:class:`~ncgen.model.joint_equations.AngleGauge`) has the directions ``b, m1, m2``
  (numbers ``k, c, rest_angle, sign``; :func:`~ncgen.model.forces.torsion_deflection`);
* **torque kinds** ``(dim, coordinate type)`` with an angular velocity map ``W``
  (:data:`TORQUE_KINDS`): kernel ``tq_<type>_<dim>d``: input ``x = [q_I; c_W; τ]`` (``c_W``
  the constants of ``W``, :func:`torque_constants`; τ 3 components in 3D, 1 in 2D), output
  ``Q_I = W(q_I)ᵀ τ`` (:class:`~ncgen.model.forces.Torque`).

The constants ``c`` of a member kind are the free symbols of its derivation's ``Φ`` and ``M``
other than the coordinates, sorted by name (:func:`member_constants`); a member's values are
``member.rigid.constants()`` at those symbols.  The order of the kinds (:data:`JOINT_KINDS`,
:data:`MEMBER_KINDS`) is their index in the tables (:mod:`ncgen.codegen.model_tables`) and in
the compiled library's kind arrays (``templates/c/element_tables.c.j2``).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import casadi as ca

from ncgen.errors import CodegenError
from ncgen.model.forces import cable_energy, cable_tension, spring_energy, spring_tension, torsion_deflection
from ncgen.model.sym2casadi import to_casadi
from ncgen.symbolic.coordinates import available_types, coordinate_type
from ncgen.symbolic.joint_primitives import PRIMITIVES, primitive

#: Joint kinds ``(primitive, dim)``, in table order: every primitive but ``angle``, which only
#: drives use (a drive is a function of t and the parameters, not a kind the tables cover).
JOINT_KINDS: tuple[tuple[str, int], ...] = tuple((p, d) for d in (3, 2) for p in PRIMITIVES if p != "angle")
#: Member kinds ``(dim, coordinate type)``, in table order.
MEMBER_KINDS: tuple[tuple[int, str], ...] = tuple(available_types())
#: Force kinds with a kernel ``(force, dim)``, in the order of the library's kernels.
FORCE_KINDS: tuple[tuple[str, int], ...] = (("spring", 3), ("spring", 2))


@dataclass(frozen=True)
class JointKind:
    """A joint kind's sizes: ``n_vec`` vector arguments of ``dim`` components, ``n_scalar``
    scalars, ``n_out`` rows; ``function`` its kernel."""

    name: str
    dim: int
    n_vec: int
    n_scalar: int
    n_out: int
    function: ca.Function
    hvv: ca.Function


@dataclass(frozen=True)
class MemberKind:
    """A member kind's sizes: ``n_q`` coordinates, ``n_c`` constants (``constants`` their
    symbols' names), ``n_out`` intrinsic constraints; its kernels ``phi`` (None without
    intrinsic constraints) and ``mass``."""

    name: str
    n_q: int
    n_c: int
    n_out: int
    constants: tuple[str, ...]
    phi: ca.Function | None
    mass: ca.Function
    hvv: ca.Function | None


def joint_kind_name(prim: str, dim: int) -> str:
    return f"jk_{prim}_{dim}d"


def member_kind_name(dim: int, ctype: str) -> str:
    return f"mk_{ctype}_{dim}d"


@lru_cache(maxsize=None)
def joint_kind(prim: str, dim: int) -> JointKind:
    """The kernel of joint kind ``(prim, dim)`` from :func:`ncgen.symbolic.joint_primitives.primitive`."""
    P = primitive(prim, dim)
    vectors = [a for a in P.args if hasattr(a, "shape")]
    scalars = [a for a in P.args if not hasattr(a, "shape")]
    x = ca.SX.sym("x", dim * len(vectors) + len(scalars))
    values, k = {}, 0
    for a in vectors:
        values.update({s: x[k + i] for i, s in enumerate(a)})
        k += dim
    for i, s in enumerate(scalars):
        values[s] = x[k + i]
    phi = to_casadi(P.expr, values)
    J = ca.jacobian(phi, x[:dim * len(vectors)])
    name = joint_kind_name(prim, dim)
    f = ca.Function(name, [x], [ca.densify(phi), ca.densify(J)], ["x"], ["phi", "J"])
    xd = ca.SX.sym("xd", dim * len(vectors))
    Jxd = ca.mtimes(J, xd)
    hvv = ca.Function(f"{name}_hvv", [x, xd], [ca.densify(ca.jtimes(Jxd, x[:dim * len(vectors)], xd))],
                      ["x", "xd"], ["hvv"])
    return JointKind(name, dim, len(vectors), len(scalars), int(phi.numel()), f, hvv)


@lru_cache(maxsize=None)
def member_constants(dim: int, ctype: str) -> tuple:
    """The constant symbols of a member kind's ``Φ`` and ``M``, sorted by name."""
    D = coordinate_type(ctype, dim).derivation
    coords = set(D.q)
    free = set(D.Phi.free_symbols) | set(D.M.free_symbols)
    return tuple(sorted(free - coords, key=str))


@lru_cache(maxsize=None)
def shipped_constant_names(dim: int, ctype: str, formulas: tuple[str, ...]) -> tuple[str, ...]:
    """The names of the constants of a member kind's ``formulas``, sorted, read from their shipped
    numeric forms (:mod:`ncgen.symbolic.numeric_forms`, generated from the derivation) so that
    packing a model's tables needs no SymPy: ``("Phi", "M")`` gives the names of
    :func:`member_constants`, ``("W",)`` those of :func:`torque_constants`."""
    from ncgen.symbolic.numeric_forms import FORMS

    names = set()
    for formula in formulas:
        if (ctype, dim, formula) in FORMS:
            names.update(FORMS[ctype, dim, formula][3])
    return tuple(sorted(names))


def member_constant_names(dim: int, ctype: str) -> tuple[str, ...]:
    """The names of :func:`member_constants` (:func:`shipped_constant_names`)."""
    return shipped_constant_names(dim, ctype, ("Phi", "M"))


@lru_cache(maxsize=None)
def member_kind(dim: int, ctype: str) -> MemberKind:
    """The kernels of member kind ``(dim, ctype)`` from its derivation."""
    ct = coordinate_type(ctype, dim)
    D = ct.derivation
    consts = member_constants(dim, ctype)
    q, c = ca.SX.sym("q", ct.nq), ca.SX.sym("c", len(consts))
    values = {s: c[k] for k, s in enumerate(consts)}
    values.update({s: q[k] for k, s in enumerate(D.q)})
    name = member_kind_name(dim, ctype)
    phi = hvv = None
    if ct.pairs:
        e = to_casadi(D.Phi, values)
        J = ca.jacobian(e, q)
        phi = ca.Function(f"{name}_phi", [q, c], [ca.densify(e), ca.densify(J)], ["q", "c"], ["phi", "J"])
        v = ca.SX.sym("v", ct.nq)
        Hvv = ca.jtimes(ca.mtimes(J, v), q, v)     # the Hessians are constant: no q is left in it
        hvv = ca.Function(f"{name}_hvv", [v, c], [ca.densify(Hvv)], ["v", "c"], ["hvv"])
    M = ca.densify(to_casadi(D.M, values))
    mass = ca.Function(f"{name}_mass", [c], [M], ["c"], ["M"])
    return MemberKind(name, ct.nq, len(consts), len(ct.pairs), tuple(map(str, consts)), phi, mass, hvv)


def force_kind_name(force: str, dim: int) -> str:
    return f"fk_{force}_{dim}d"


@lru_cache(maxsize=None)
def spring_kind(dim: int) -> ca.Function:
    """The spring-damper kernel ``fk_spring_<dim>d`` (module docstring)."""
    x = ca.SX.sym("x", 4 * dim + 3)
    ra, rb, va, vb = (x[i * dim:(i + 1) * dim] for i in range(4))
    k, l0, c = x[4 * dim], x[4 * dim + 1], x[4 * dim + 2]
    d = rb - ra
    length = ca.sqrt(ca.sumsqr(d))
    rate = ca.dot(d, vb - va) / length
    f = -spring_tension(length, rate, k, l0, c) * d / length
    y = ca.vertcat(f, spring_energy(length - l0, k), -c * rate ** 2)
    J = ca.jacobian(f, x[:4 * dim])
    return ca.Function(force_kind_name("spring", dim), [x], [ca.densify(y), ca.densify(J)], ["x"], ["y", "J"])


#: Force kinds over features ``(force, dim)``, in table order (``ff_kind`` of the stepper tables).
FEATURE_FORCE_KINDS: tuple[tuple[str, int], ...] = tuple((f, d) for f in ("cable", "torsion") for d in (3, 2))


@dataclass(frozen=True)
class FeatureForceKind:
    """A force kind over ``n_feat`` features of ``dim`` components and ``n_par`` numbers;
    ``function`` its kernel (module docstring)."""

    name: str
    dim: int
    n_feat: int
    n_par: int
    function: ca.Function


def _cable_law(dim, f, k, l0, c):
    """Generalised force on ``[r_a; r_b]`` and energy of a cable (as ``Spring.generalized``)."""
    (ra, rb), (va, vb) = f
    d = rb - ra
    length = ca.sqrt(ca.sumsqr(d))
    rate = ca.dot(d, vb - va) / length
    f_b = -cable_tension(length, rate, k, l0, c) * d / length
    return ca.vertcat(-f_b, f_b), cable_energy(length - l0, k)


def _torsion_law(dim, f, k, c, rest, sign):
    """Generalised force on ``[b; m1; m2]`` and energy of a torsional spring-damper (as
    ``TorsionalSpring.generalized``): ``−(k δ + c δ̇) ∇δ``, ``½ k δ²``."""
    (b, m1, m2), rates = f
    x = ca.vertcat(b, m1, m2)
    delta = torsion_deflection(ca.dot(m1, b), sign * ca.dot(m2, b), rest)
    rate = ca.jtimes(delta, x, ca.vertcat(*rates))
    return -(k * delta + c * rate) * ca.gradient(delta, x), 0.5 * k * delta ** 2


_FEATURE_LAWS = {"cable": (2, 3, _cable_law), "torsion": (3, 4, _torsion_law)}


@lru_cache(maxsize=None)
def feature_force_kind(force: str, dim: int) -> FeatureForceKind:
    """The kernel ``ff_<force>_<dim>d`` of a force kind over features (module docstring)."""
    n, n_par, law = _FEATURE_LAWS[force]
    nd = n * dim
    x = ca.SX.sym("x", 2 * nd + n_par)
    feats = [x[i * dim:(i + 1) * dim] for i in range(n)]
    rates = [x[nd + i * dim:nd + (i + 1) * dim] for i in range(n)]
    g, V = law(dim, (feats, rates), *(x[2 * nd + i] for i in range(n_par)))
    P = ca.dot(x[nd:2 * nd], g + ca.gradient(V, x[:nd]))
    J = ca.jacobian(g, x[nd:2 * nd])
    name = f"ff_{force}_{dim}d"
    fn = ca.Function(name, [x], [ca.densify(ca.vertcat(g, V, P)), ca.densify(J)], ["x"], ["y", "J"])
    return FeatureForceKind(name, dim, n, n_par, fn)


#: Member kinds with a torque kernel, in the order of :data:`MEMBER_KINDS`: bodies and bars
#: (those whose derivation has an angular velocity map W; points have none).  From the kinds'
#: names, without the derivations (importing this module loads no SymPy).
TORQUE_KINDS: tuple[tuple[int, str], ...] = tuple(
    (d, t) for d, t in MEMBER_KINDS if coordinate_type(t, d).kind != "point")


@lru_cache(maxsize=None)
def torque_constants(dim: int, ctype: str) -> tuple:
    """The constant symbols of a member kind's ``W`` (other than its coordinates), sorted by name."""
    D = coordinate_type(ctype, dim).derivation
    return tuple(sorted(set(D.W.free_symbols) - set(D.q) - set(D.qd), key=str))


def torque_constant_names(dim: int, ctype: str) -> tuple[str, ...]:
    """The names of :func:`torque_constants` (:func:`shipped_constant_names`)."""
    return shipped_constant_names(dim, ctype, ("W",))


@lru_cache(maxsize=None)
def torque_kind(dim: int, ctype: str) -> ca.Function:
    """The kernel ``tq_<type>_<dim>d``: ``[q_I; c_W; τ] -> W(q_I)ᵀ τ`` (module docstring)."""
    ct = coordinate_type(ctype, dim)
    D = ct.derivation
    if D.W is None:
        raise CodegenError(f"torque kind {ctype} ({dim}D): its derivation has no angular velocity map W")
    consts = torque_constants(dim, ctype)
    n_tau = 3 if dim == 3 else 1
    x = ca.SX.sym("x", ct.nq + len(consts) + n_tau)
    values = {s: x[ct.nq + k] for k, s in enumerate(consts)}
    values.update({s: x[k] for k, s in enumerate(D.q)})
    W = to_casadi(D.W, values)
    Q = ca.mtimes(W.T, x[ct.nq + len(consts):])
    return ca.Function(f"tq_{ctype}_{dim}d", [x], [ca.densify(Q)], ["x"], ["Q"])


def kernels() -> list[ca.Function]:
    """Every kernel of the shipped kinds, in a fixed order (joint kinds, then member kinds'
    ``phi`` and ``mass``, then the force kinds: springs, forces over features, torques)."""
    out = [f for p, d in JOINT_KINDS for f in (joint_kind(p, d).function, joint_kind(p, d).hvv)]
    for d, t in MEMBER_KINDS:
        k = member_kind(d, t)
        out += ([k.phi, k.hvv] if k.phi is not None else []) + [k.mass]
    return (out + [spring_kind(d) for _, d in FORCE_KINDS]
            + [feature_force_kind(f, d).function for f, d in FEATURE_FORCE_KINDS]
            + [torque_kind(d, t) for d, t in TORQUE_KINDS])


#: Name of the package (and prefix of every C symbol) of the element kernels' library.
PACKAGE = "ncgen_elements"
#: The files the library is made of besides this module: the key of its cache entry hashes them.
SOURCES = ("runtime/ncgen_element_tables.h", "element_tables.c.j2", "runtime/ncgen_sparse_lu.h",
           "runtime/ncgen_sparse_qr.h",
           "runtime/ncgen_table_stepper.h", "runtime/ncgen_rattle.h", "runtime/ncgen_fixed.h",
           "runtime/ncgen_adaptive.h", "runtime/ncgen_table_jacobians.h")
#: The runtime headers the library's C includes (copied into its package as they are).
HEADERS = SOURCES[2:]
#: The contact library (:func:`write_element_package` with ``contacts``): the element library's
#: kernels and stepper with nonsmooth contacts and the pair kinds
#: (:func:`ncgen.assembly.pair_kinds.table_kinds`), in a library of its own so that models
#: without contacts do not compile its ≈ 36 k instructions of pair kinds.
CONTACT_PACKAGE = "ncgen_contacts"
#: The files the contact library is made of besides :data:`SOURCES`.
CONTACT_SOURCES = ("runtime/ncgen_table_contacts.h", "runtime/ncgen_cone_newton.h", "runtime/ncgen_contact_pairs.h",
                   "runtime/ncgen_contact.h")


def _contact_context() -> tuple[list, dict]:
    """The pair kinds' kernels and the template context of the contact library."""
    from ncgen.assembly.pair_kinds import pair_kind, table_kinds
    from ncgen.codegen.cnames import c_real
    from ncgen.codegen.stepper_package import (CONTACT_REFINE_MAX, CONTACT_REFINE_TOL, GAP_REACH, PENETRATION_TOL,
                                               PGS_MAX_ITER, PGS_TOL, REPEAT_TOL)

    kinds = [(pair_kind(*k), k[3]) for k in table_kinds()]
    fns = [k.plain for k, _ in kinds]
    qc = max(max(k.n_a, k.n_b) for k, _ in kinds)
    return fns, {"kinds": [{"name": k.name, "dim": d, "n_a": k.n_a, "n_b": k.n_b, "n_c": k.n_c} for k, d in kinds],
                 "pair_w": max(f.sz_w() for f in fns), "pair_qc": qc, "pgs_max_iter": PGS_MAX_ITER,
                 "pgs_tol": c_real(PGS_TOL), "refine_max": CONTACT_REFINE_MAX, "refine_tol": c_real(CONTACT_REFINE_TOL),
                 "penetration_tol": c_real(PENETRATION_TOL), "gap_reach": c_real(GAP_REACH),
                 "repeat_tol": c_real(REPEAT_TOL)}


def write_element_package(out_dir, contacts: bool = False):
    """The C package of every shipped kind's kernels and the table loops (``PACKAGE``) in
    ``out_dir``: the kernels, ``ncgen_element_tables.h`` and ``element_tables.c``, whose
    functions are documented in ``templates/c/element_tables.c.j2``; with ``contacts``, the
    contact library (``CONTACT_PACKAGE``: also the pair kinds, its stepper with nonsmooth
    contacts and without step Jacobians)."""
    from ncgen.codegen.package import ExtraSource, PackageDoc, write_package

    joints = [joint_kind(p, d) for p, d in JOINT_KINDS]
    members = [member_kind(d, t) for d, t in MEMBER_KINDS]
    fns = kernels()
    pair_fns, contact = _contact_context() if contacts else ([], None)
    fns = fns + pair_fns
    if any(f.sz_iw() for f in fns) or any(f.sz_arg() > 2 or f.sz_res() > 2 for f in fns):
        raise CodegenError("element kernels: the table loops expect kernels with no integer work and at most "
                           "two arguments and results")
    names = [k.name for k in joints] + [k.name for k in members]
    from ncgen.codegen.stepper_package import CONTACT_STATS, HALVINGS_LIMIT, MAX_HALVINGS, MAX_ITER, STATS, TOL

    ffs = [feature_force_kind(f, d) for f, d in FEATURE_FORCE_KINDS]
    torques = [torque_kind(d, t) if (d, t) in TORQUE_KINDS else None for d, t in MEMBER_KINDS]
    ff_in = [f.function.nnz_in(0) for f in ffs] + [f.nnz_in(0) for f in torques if f is not None]
    ff_out = [f.function.nnz_out(0) + f.function.nnz_out(1) for f in ffs] + [
        f.nnz_out(0) for f in torques if f is not None]
    context = {"stepper": {"tol": TOL, "max_iter": MAX_ITER, "max_halvings": MAX_HALVINGS,
                           "halvings_limit": HALVINGS_LIMIT,
                           "nstats": len(STATS) + (len(CONTACT_STATS) if contacts else 0)},
               "joint_kinds": [{"name": k.name, "dim": k.dim, "n_vec": k.n_vec, "n_scalar": k.n_scalar,
                                "n_out": k.n_out} for k in joints],
               "member_kinds": [{"name": k.name, "phi": k.phi is not None, "n_q": k.n_q, "n_c": k.n_c,
                                 "n_out": k.n_out} for k in members],
               "feature_force_kinds": [{"name": k.name, "dim": k.dim, "n_feat": k.n_feat, "n_par": k.n_par}
                                       for k in ffs],
               "torque_kinds": [{"name": f.name() if f is not None else None,
                                 "n_c": len(torque_constants(d, t)) if f is not None else 0}
                                for f, (d, t) in zip(torques, MEMBER_KINDS)],
               "ff_in": max(ff_in), "ff_out": max(ff_out),
               "max_w": max(f.sz_w() for f in kernels()), "kind_names": ",".join(names), "contacts": contact}
    doc = PackageDoc(summary="Element kernels of the shipped kinds and the table-driven loops (ncgen "
                             "element tables): Φ, A, Φ_t and M of any model of these kinds from its tables, "
                             "and its compiled RATTLE stepper" + (" with nonsmooth contacts and the contact pair "
                                                                  "kinds" if contacts else ""))
    headers = HEADERS + (CONTACT_SOURCES if contacts else ())
    return write_package(CONTACT_PACKAGE if contacts else PACKAGE, fns, out_dir, doc=doc, max_file_instructions=None,
                         reroll_instructions=None,
                         extra_sources=[ExtraSource("runtime/ncgen_element_tables.h", "ncgen_element_tables.h",
                                                    included=True),
                                        *(ExtraSource(h, h.split("/")[-1], included=True) for h in headers),
                                        ExtraSource("element_tables.c.j2", "element_tables.c", context)])


def kind_names() -> str:
    """The kinds in table order, comma-separated, as the library's ``kind_names()`` gives them."""
    return ",".join([joint_kind_name(p, d) for p, d in JOINT_KINDS]
                    + [member_kind_name(d, t) for d, t in MEMBER_KINDS])
