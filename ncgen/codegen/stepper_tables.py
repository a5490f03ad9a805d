"""A model's compiled stepper as data: the tables of ``ncgen_stepper_tables``
(``templates/c/runtime/ncgen_table_stepper.h``), which the element library's stepper
(compiled once per ncgen version, :mod:`ncgen.runtime.table_library`) runs with no compiler.

:func:`stepper_tables` packs the element tables of the constraints and the mass
(:func:`~ncgen.codegen.model_tables.model_tables`), then the forces: gravity as a constant
generalised force ``f_gravity = Σ_I S_Iᵀ C(c_G)ᵀ m_I g`` (its energy
``V = v_gravity − f_gravityᵀ q``), each :class:`~ncgen.model.forces.Spring` with constant
``k``, rest length and damping as a spring element between two point features; each force
linear in the inputs with a constant map (``Q = B u``: a :class:`~ncgen.model.forces.PointForce`
or :class:`~ncgen.model.forces.GeneralizedForce` whose value is a constant matrix times the
inputs, :func:`input_force_map`) summed into ``B_u`` (``bu_*``, CSC); the efforts of actuated
Revolute and Prismatic joints, linear in the inputs, on their coordinates (each a quadratic
form of the coordinates it touches, or the angle ``atan2(y, x)`` of two such forms:
:func:`actuator_element`, ``act_*``); the markers
as point features; and the KKT matrix ``K = [[M − h/2 ∂F/∂w, Aᵀ], [A, 0]]``: its pattern
(``M``'s nonzero entries only), the nonzero of ``K`` every product of the loops adds to, and
the symbolic analyses of its sparse LU (:func:`lu_analysis`: an order without pivoting that
keeps each multiplier after the coordinates its constraint touches) and of its sparse QR, the
LU's fallback (CasADi's ``Sparsity.qr_sparse``, approximate minimum degree column order).

The other forces of numbers (:func:`force_elements`): constant
:class:`~ncgen.model.forces.PointForce` and
:class:`~ncgen.model.forces.GeneralizedForce` as one constant generalised force
``f_const`` (not part of the potential energy, as the flat functions count them); cables
(``Spring(cable=True)``) and :class:`~ncgen.model.forces.TorsionalSpring` on a
:class:`~ncgen.model.joints.Revolute` as force elements over features (``ff_*``: the ends,
or the gauge's directions ``b, m1, m2``); constant :class:`~ncgen.model.forces.Torque` as
torque elements on their member (``tq_*``).

Nonsmooth contacts (``contacts="nonsmooth"``) whose point contacts all have a pair kind of the
contact library are packed by :func:`ncgen.codegen.contact_tables.contact_arrays`
(``StepperTables.contacts``); such a model runs on the contact library's stepper.

A model is *table-covered* when every element is: joints as :mod:`ncgen.codegen.model_tables`
says, forces and actuated joints as above, contacts as just said, no controller or parameters,
inputs only through input forces and efforts.  :class:`UnsupportedElements`
names every element that is not.  Nothing here reads ``model.functions``.
"""
from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import casadi as ca
import numpy as np

from ncgen.assembly.mass import mass_is_regular
from ncgen.codegen.contact_tables import contact_arrays, uncovered_contacts
from ncgen.codegen.element_kernels import FEATURE_FORCE_KINDS, torque_constant_names
from ncgen.codegen.model_tables import ModelTables, UnsupportedElements, _csc, _ints, _ptr, _reals, model_tables
from ncgen.errors import CodegenError, NcgenError
from ncgen.model.context import Context
from ncgen.model.data import model_data
from ncgen.model.forces import GeneralizedForce, PointForce, Spring, Torque, TorsionalSpring
from ncgen.model.joint_equations import is_full


@dataclass
class StepperTables:
    """The stepper tables of one model (names as the fields of ``ncgen_stepper_tables``)."""

    name: str
    tables: ModelTables
    nu: int
    np: int
    n_markers: int
    n_spring: int
    n_ff: int
    n_torque: int
    mass_scale: float
    v_gravity: float
    nnz_k: int
    nnz_v: int
    nnz_r: int
    arrays: dict[str, np.ndarray]
    #: Whether every force is ``−∇V`` (no damping, no constant force or torque outside V; every
    #: covered constraint is scleronomic).
    conservative: bool = False
    #: Nonzeros of the sparse LU's factor L (:func:`lu_analysis`).
    nnz_l: int = 0
    #: Nonzero entries of M (``m_colind``, ``m_row``, ``m_val``: M's pattern in the element tables
    #: less the entries whose value is zero).
    m_nnz: int = 0
    #: Whether the stepper solves K by the sparse LU (M regular: every coordinate's pivot before
    #: its constraints' multipliers is a mass); a flat body's singular M leaves it to the QR.
    use_lu: bool = True
    #: The nonsmooth contacts (:func:`ncgen.codegen.contact_tables.contact_arrays`), None without.
    contacts: dict | None = None


def _number(value) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


#: Actuated joint kinds the tables cover (``effort=`` on one coordinate).
ACTUATED_KINDS = ("Revolute", "Prismatic")
#: Largest number of coordinates an actuated joint's coordinate may touch (``TAB_ACT_MAX_K``).
ACT_MAX_K = 32


@dataclass
class ActuatorElement:
    """An actuated joint in the tables: ``kind`` 0 (coordinate a quadratic form of
    ``q[cols]``) or 1 (``atan2(y, x)`` of two), ``forms`` each ``[c0; g; H (column-major)]``
    concatenated, ``tau`` the effort's coefficients of the inputs (nu)."""

    kind: int
    cols: np.ndarray
    forms: np.ndarray
    tau: np.ndarray


def _context(model, element) -> Context:
    """A context over the model's members and layout with the symbols of the inputs and
    parameters of the system ``element`` belongs to."""
    system = element.system
    view = SimpleNamespace(members=model.members, inputs=dict(system.inputs), parameters=dict(system.parameters),
                           dim=model.dim, name=model.name)
    return Context(view, model.layout)


def _linear_in_inputs(ctx, e: ca.SX, n_out: int) -> np.ndarray | None:
    """``B`` (n_out × nu) when ``e = B u`` with ``B`` constant (nothing else, nothing at u = 0), else None."""
    B = ca.jacobian(e, ctx.u)
    if ca.depends_on(e, ca.vertcat(ctx.t, ctx.q, ctx.v, ctx.p)) or ca.depends_on(B, ctx.u):
        return None
    try:
        e0, B0 = ca.Function("linear", [ctx.u], [e, B])(np.zeros(ctx.u.numel()))
    except RuntimeError:            # free symbols other than these: not a constant map
        return None
    e0, B0 = np.asarray(e0, float).ravel(), np.asarray(ca.densify(B0), float)
    return B0 if not np.any(e0) and np.all(np.isfinite(B0)) and B0.shape == (n_out, ctx.u.numel()) else None


def actuator_element(model, joint) -> ActuatorElement | None:
    """The :class:`ActuatorElement` of an actuated joint (``effort=``), or None when the
    tables do not cover it (another kind, an effort not linear in the inputs, a coordinate
    not of that form); worked out once per model and joint (``model.data.actuator_elements``)."""
    elements = model_data(model).actuator_elements
    hit = elements.get(id(joint))
    if hit is None or hit[0] is not joint:
        hit = elements[id(joint)] = (joint, _actuator_element(model, joint))
    return hit[1]


def _actuator_element(model, joint) -> ActuatorElement | None:
    if (joint.kind not in ACTUATED_KINDS or type(joint).__module__ != "ncgen.model.joints"
            or getattr(joint, "system", None) is None or not model.nu):
        return None
    ctx = _context(model, joint)
    try:
        forms = joint.gauge(ctx).terms(ctx) if joint.kind == "Revolute" else (joint.coordinate(ctx),)
        tau = ctx.expression(joint.options["effort"], 1, f"{joint.label}: effort")
    except (NcgenError, RuntimeError, TypeError):
        return None
    e = ca.densify(ca.vertcat(*forms))
    coef = _linear_in_inputs(ctx, ca.densify(tau), 1)
    if coef is None or ca.depends_on(e, ca.vertcat(ctx.t, ctx.v, ctx.u, ctx.p)):
        return None
    cols = np.unique(ca.jacobian(e, ctx.q).sparsity().get_col()).astype(int)
    if not 1 <= cols.size <= ACT_MAX_K:
        return None
    out = []
    for i in range(e.numel()):
        H = ca.hessian(e[i], ctx.q)[0]
        if ca.depends_on(H, ctx.q):
            return None
        c0, g, H0 = ca.Function("form", [ctx.q], [e[i], ca.jacobian(e[i], ctx.q), H])(np.zeros(model.nq))
        g, H0 = np.asarray(ca.densify(g), float).ravel()[cols], np.asarray(ca.densify(H0), float)[np.ix_(cols, cols)]
        out.append(np.concatenate([[float(c0)], g, H0.ravel(order="F")]))
    return ActuatorElement(len(forms) - 1, cols, np.concatenate(out), coef.ravel())


def input_force_map(model, force) -> np.ndarray | None:
    """``B`` (nq × nu) when the generalised force of ``force`` is ``Q = B u`` with ``B``
    constant (no dependence on t, q, v or the parameters, nothing at u = 0), else None;
    checked symbolically once per model and force (``model.data.input_force_maps``)."""
    maps = model_data(model).input_force_maps
    hit = maps.get(id(force))
    if hit is None or hit[0] is not force:
        B = _input_force_map(model, force)
        if B is not None:
            B.setflags(write=False)
        hit = maps[id(force)] = (force, B)
    return hit[1]


def _input_force_map(model, force) -> np.ndarray | None:
    if not model.nu or type(force) is Spring or getattr(force, "system", None) is None:
        return None
    ctx = _context(model, force)
    try:
        Q = ca.densify(force.generalized(ctx))
    except (NcgenError, RuntimeError, TypeError):
        return None
    return _linear_in_inputs(ctx, Q, model.nq)


def _numbers(value, n: int) -> np.ndarray | None:
    """``value`` as ``n`` floats when it is a number or a sequence of numbers, else None (an
    expression, a callable, a CasADi symbol)."""
    if _number(value):
        values = [value]
    elif isinstance(value, (list, tuple, np.ndarray)) and all(_number(x) for x in np.ravel(np.asarray(value, object))):
        values = np.ravel(np.asarray(value, float))
    else:
        return None
    return np.asarray(values, float) if len(values) == n else None


def _uncovered_force(f, dim: int, nq: int) -> str | None:
    """The uncovered kind of force ``f`` (as :func:`uncovered_elements` names it), or None."""
    if type(f) is Spring:
        numbers = all(_number(x) for x in (f.k, f.rest_length, f.damping))
        return None if numbers else f"Spring{' (cable)' if f.cable else ''} with an expression for k, rest_length " \
                                    "or damping"
    if type(f) is TorsionalSpring:
        if f.coordinate is not None:
            return "TorsionalSpring on a JointSequence"
        return None if all(_number(x) for x in (f.k, f.damping, f.rest_angle)) else \
            "TorsionalSpring with an expression for k, damping or rest_angle"
    if type(f) is PointForce:
        return None if _numbers(f.force, dim) is not None else "PointForce of t, inputs or parameters"
    if type(f) is Torque:
        return None if _numbers(f.torque, 3 if dim == 3 else 1) is not None else "Torque of t, inputs or parameters"
    if type(f) is GeneralizedForce:
        return None if _numbers(f.value, nq) is not None else "GeneralizedForce of t, q, v, inputs or parameters"
    return f.kind


def input_forces(model) -> list[tuple]:
    """The forces of ``model`` that the tables take as input forces: ``(force, B)`` for each
    force of the inputs with a constant map ``Q = B u`` (:func:`input_force_map`) that is not
    one of the kinds of numbers (:func:`force_elements`)."""
    out = []
    for f in model.forces:
        if _uncovered_force(f, model.dim, model.nq) is not None:
            B = input_force_map(model, f)
            if B is not None:
                out.append((f, B))
    return out


def uncovered_elements(model) -> dict[str, list[str]]:
    """The elements of ``model`` outside the stepper tables' kinds (other than joints), by kind."""
    out: dict[str, list[str]] = {}
    for f in model.forces:
        kind = _uncovered_force(f, model.dim, model.nq)
        if kind is not None and input_force_map(model, f) is None:
            out.setdefault(kind, []).append(f"force {f.name!r}")
    contacts = uncovered_contacts(model)
    if contacts:
        out["contact"] = contacts[:4] + ([f"{len(contacts) - 4} more"] if len(contacts) > 4 else [])
    actuated = [f"joint {j.name!r}" for j in model.joints
                if j.options.get("effort") is not None and actuator_element(model, j) is None]
    if actuated:
        out["actuated joint (effort=) other than a Revolute or Prismatic with an effort linear in the inputs"] = \
            actuated
    if getattr(model, "controller", None) is not None:
        out["controller"] = ["the model's controller"]
    if model.np:
        out.setdefault("parameter", []).extend(f"parameter {n!r}" for n in model.parameter_names)
    return out


def stepper_tables(model) -> StepperTables:
    """The stepper tables of ``model`` (module docstring); raises :class:`UnsupportedElements`."""
    missing = uncovered_elements(model)
    if missing:
        raise UnsupportedElements(model.name, missing)
    springs = [f for f in model.forces if type(f) is Spring and not f.cable]
    elements = force_elements(model)
    ff, tq = elements["ff"], elements["torque"]
    points = [(s.a, s.at_a) for s in springs] + [(s.b, s.at_b) for s in springs]
    points += [(m, local) for m in model.members.values() for local in m.markers.values()]
    n_points = len(points)
    points += [v for e in ff for v in e["vectors"]]
    T = model_tables(model, points)
    ns = len(springs)
    ends, markers = T.point_features[:2 * ns], T.point_features[2 * ns:n_points]
    ff_feat = T.point_features[n_points:]
    spr_feat = [f for s in range(ns) for f in (ends[s], ends[ns + s])]
    f_gravity, v_gravity = _gravity(model)
    M = np.asarray(model.M, dtype=float)
    K, k_arrays = _kkt_pattern(model.name, M, T, spr_feat, ff_feat, _ptr([len(e["vectors"]) for e in ff]))
    arrays = {
        "f_gravity": _reals(f_gravity),
        "spr_feat": _ints(spr_feat),
        "spr_par": _reals([x for s in springs for x in (s.k, s.rest_length, s.damping)]),
        "marker_feat": _ints(markers),
        **_input_arrays(model), **k_arrays,
        "f_const": _reals(elements["f_const"]),
        "ff_kind": _ints([e["kind"] for e in ff]), "ff_feat": _ints(ff_feat),
        "ff_par_ptr": _ptr([len(e["par"]) for e in ff]), "ff_par": _reals([x for e in ff for x in e["par"]]),
        "tq_member": _ints([e["member"] for e in tq]), "tq_c_ptr": _ptr([len(e["c"]) for e in tq]),
        "tq_c": _reals([x for e in tq for x in e["c"]]), "tq_val": _reals([x for e in tq for x in e["tau"]]),
    }
    conservative = not any(s.damping for s in springs) and not any(e["damping"] for e in ff) \
        and not np.any(elements["f_const"]) and not any(np.any(e["tau"]) for e in tq)
    return StepperTables(model.name, T, model.nu, model.np, len(markers), ns, len(ff), len(tq),
                         float(np.max(np.abs(M))) if T.nq else 1.0, v_gravity, int(K.indices.size),
                         int(K.qr["v_row"].size), int(K.qr["r_row"].size), arrays, conservative,
                         int(K.lu["l_row"].size), K.m_nnz, mass_is_regular(model),
                         contact_arrays(model, k_arrays["a_colind"]) if model.contacts else None)


def _input_arrays(model) -> dict[str, np.ndarray]:
    """The input map ``B_u`` of the input forces (``bu_*``, CSC) and the actuated joints'
    efforts (``act_*``, :func:`actuator_element`)."""
    B_u = sum((B for _, B in input_forces(model)), np.zeros((model.nq, model.nu)))
    acts = [actuator_element(model, j) for j in model.joints if j.options.get("effort") is not None]
    bu_rows = [np.flatnonzero(B_u[:, j]) for j in range(model.nu)]
    return {
        "bu_colind": _ptr([len(r) for r in bu_rows]),
        "bu_row": _ints(np.concatenate(bu_rows)) if bu_rows else _ints([]),
        "bu_val": _reals(np.concatenate([B_u[r, j] for j, r in enumerate(bu_rows)])) if bu_rows else _reals([]),
        "act_kind": _ints([a.kind for a in acts]), "act_ptr": _ptr([a.cols.size for a in acts]),
        "act_col": _ints(np.concatenate([a.cols for a in acts]) if acts else []),
        "act_form_ptr": _ptr([a.forms.size for a in acts]),
        "act_form": _reals(np.concatenate([a.forms for a in acts]) if acts else []),
        "act_tau": _reals(np.concatenate([a.tau for a in acts]) if acts else []),
    }


def _kkt_pattern(name: str, M: np.ndarray, T: ModelTables, spr_feat, ff_feat, ff_ptr):
    """The pattern of ``K = [[M − h/2 ∂F/∂w, Aᵀ], [A, 0]]`` (``M``'s nonzero entries only)
    and where each product of the loops adds into it: the entries of M, A (lower block), Aᵀ
    (upper block), then the springs' and the force elements' dampers (:func:`_velocity_entries`;
    ``spr_feat``: two features per spring, ``ff_feat`` the force elements' at ``ff_ptr``),
    with the symbolic LU and QR analyses.  Returns ``(K, arrays)``: ``K`` with ``indices``,
    ``m_nnz``, ``qr``, ``lu``; ``arrays`` the tables' ``m_*``, ``k_*``, ``spr_k*``, ``ff_k*``,
    ``ff_feat_ptr``, ``a_*`` and the analyses'."""
    nq, a = T.nq, T.arrays
    n = nq + T.nc
    m_cols = np.repeat(np.arange(nq), np.diff(T.m_indptr))
    nonzero = M[T.m_indices, m_cols] != 0
    m_rows, m_cols = T.m_indices[nonzero], m_cols[nonzero]
    a_cols = np.repeat(np.arange(nq), np.diff(T.a_indptr))
    rows = [m_rows, nq + T.a_indices, a_cols]
    cols = [m_cols, a_cols, nq + T.a_indices]
    dampers = {}
    for kind, feats, spring in (("spr", [spr_feat[2 * s:2 * s + 2] for s in range(len(spr_feat) // 2)], True),
                                ("ff", [ff_feat[ff_ptr[k]:ff_ptr[k + 1]] for k in range(len(ff_ptr) - 1)], False)):
        counts, coef, index = [], [], []
        for f in feats:
            r_s, c_s, g_s, j_s = _velocity_entries(a, f, T.dim, spring=spring)
            rows.append(r_s)
            cols.append(c_s)
            counts.append(len(r_s))
            coef.append(g_s)
            index.append(j_s)
        dampers[kind] = counts, coef, index
    k_indptr, k_indices, pos = _csc(n, n, np.concatenate(rows), np.concatenate(cols))
    m_nnz, a_nnz = int(m_rows.size), T.a_nnz
    n_spr = m_nnz + 2 * a_nnz + sum(dampers["spr"][0])
    qr = _qr_analysis(name, n, k_indptr, k_indices)
    lu = lu_analysis(nq, k_indptr, k_indices)
    (spr_counts, spr_coef, spr_j), (ff_counts, ff_coef, ff_j) = dampers["spr"], dampers["ff"]
    arrays = {
        "a_colind": T.a_indptr, "a_row": T.a_indices,
        "m_colind": _ptr(np.bincount(m_cols, minlength=nq)), "m_row": _ints(m_rows), "m_val": _reals(M[m_rows, m_cols]),
        "spr_kpos_ptr": _ptr(spr_counts), "spr_kpos": pos[m_nnz + 2 * a_nnz:n_spr],
        "spr_kcoef": _reals(np.concatenate(spr_coef) if spr_coef else []),
        "spr_kj": _ints(np.concatenate(spr_j) if spr_j else []),
        "k_mpos": pos[:m_nnz], "k_apos": pos[m_nnz:m_nnz + a_nnz], "k_atpos": pos[m_nnz + a_nnz:m_nnz + 2 * a_nnz],
        "ff_feat_ptr": ff_ptr, "ff_kpos_ptr": _ptr(ff_counts), "ff_kpos": pos[n_spr:],
        "ff_kcoef": _reals(np.concatenate(ff_coef) if ff_coef else []),
        "ff_kj": _ints(np.concatenate(ff_j) if ff_j else []),
        "k_colind": k_indptr, "k_row": k_indices, **qr, **lu,
    }
    return SimpleNamespace(indices=k_indices, m_nnz=m_nnz, qr=qr, lu=lu), arrays


def _velocity_entries(a: dict, feats, dim: int, spring: bool) -> tuple[np.ndarray, ...]:
    """The products that the velocity derivative of a force on the features ``feats`` adds
    into ``K``, in the loops' order (every entry ``e`` of each feature ``X`` against every entry
    ``e2`` of each feature ``Y``): ``(row, column, coefficient, index)``, the product being
    ``K[col_e, col_e2] += kscale · coefficient · J[index]`` with ``coefficient = s_X G_e G_e2``
    (``s_X`` the sign of the force on ``X``: −1 on a spring's first end, else +1) and ``index``
    the entry ``∂g_(X, row_e)/∂ḟ_(Y, row_e2)`` of the kernel's ``J`` (column-major): a spring's
    ``J = ∂f/∂[r_a; r_b; ṙ_a; ṙ_b]`` (dim × 4 dim), a force element's ``J = ∂g/∂ḟ``
    (n dim × n dim)."""
    spans = [(a["feat_ptr"][f], a["feat_ptr"][f + 1]) for f in feats]
    nd = len(feats) * dim
    r_s, c_s, g_s, j_s = [], [], [], []
    for X, (lo, hi) in enumerate(spans):
        sign = (1.0 if X else -1.0) if spring else 1.0
        for e in range(lo, hi):
            i = a["feat_row"][e] if spring else X * dim + a["feat_row"][e]
            for Y, (lo2, hi2) in enumerate(spans):
                for e2 in range(lo2, hi2):
                    r_s.append(a["feat_col"][e])
                    c_s.append(a["feat_col"][e2])
                    g_s.append(sign * a["feat_coef"][e] * a["feat_coef"][e2])
                    j_s.append(i + dim * ((2 + Y) * dim + a["feat_row"][e2]) if spring
                               else i + nd * (Y * dim + a["feat_row"][e2]))
    return _ints(r_s), _ints(c_s), _reals(g_s), _ints(j_s)


def force_elements(model) -> dict:
    """The forces of ``model`` other than gravity and spring-dampers, as table elements:
    ``f_const`` (nq; constant point forces and generalised forces), ``ff`` (force elements over
    features: ``kind`` in :data:`~ncgen.codegen.element_kernels.FEATURE_FORCE_KINDS`,
    ``vectors`` (``(member, point)`` pairs or callables for :func:`model_tables`), ``par`` and
    ``damping``)
    and ``torque`` (``member`` index, constants ``c`` of ``W``, ``tau``)."""
    dim, layout = model.dim, model.layout
    f_const = np.zeros(model.nq)
    ff, torques = [], []
    names = list(model.members)
    for f in model.forces:
        if _uncovered_force(f, dim, model.nq) is not None:       # an input force (input_forces)
            continue
        if type(f) is PointForce:
            m = f.member
            C = np.asarray(m.rigid.C(m.rigid.affine(np.asarray(f.at, float))), float)
            _scatter(f_const, layout.member_indices(m.name), C.T @ _numbers(f.force, dim))
        elif type(f) is GeneralizedForce:
            f_const += _numbers(f.value, model.nq)
        elif type(f) is Spring and f.cable:
            ff.append({"kind": FEATURE_FORCE_KINDS.index(("cable", dim)), "vectors": [(f.a, f.at_a), (f.b, f.at_b)],
                       "par": [f.k, f.rest_length, f.damping], "damping": f.damping})
        elif type(f) is TorsionalSpring:
            vectors = [lambda ctx, j=f.joint, a=a: getattr(j.gauge(ctx), a) for a in ("b", "m1", "m2")]
            sign = _torsion_sign(model, f.joint)
            ff.append({"kind": FEATURE_FORCE_KINDS.index(("torsion", dim)), "vectors": vectors,
                       "par": [f.k, f.damping, f.rest_angle, sign], "damping": f.damping})
        elif type(f) is Torque:
            m = f.member
            values = m.rigid.constant_values
            torques.append({"member": names.index(m.name),
                            "c": [float(values[n]) for n in torque_constant_names(dim, m.ctype.name)],
                            "tau": _numbers(f.torque, 3 if dim == 3 else 1)})
    return {"f_const": f_const, "ff": ff, "torque": torques}


def _torsion_sign(model, joint) -> float:
    """``AngleGauge.sign`` of the hinge ``joint``: +1 when its full side (the ground or a body)
    is A or the system is planar (:func:`ncgen.model.joint_equations.angle_gauge`)."""
    return 1.0 if model.dim == 2 or is_full(joint.A) else -1.0


def _scatter(out: np.ndarray, indices, values) -> None:
    """``out[i] += value`` for the free coordinates ``i`` of a member (None: a ground point's)."""
    for i, x in zip(indices, values):
        if i is not None:
            out[i] += x


def _gravity(model) -> tuple[np.ndarray, float]:
    """``(f_gravity, v_gravity)``: gravity's generalised force ``Σ S_Iᵀ C(c_G)ᵀ m_I g`` (as
    :func:`ncgen.assembly.build.force_terms` assembles it) and the constant of its energy
    ``V = −Σ m_I g·C(c_G) q_I = v_gravity − f_gravityᵀ q`` (the ground points' share)."""
    g = np.asarray(model.gravity, float)
    f = np.zeros(model.nq)
    v0 = 0.0
    for m in model.members.values():
        C = np.asarray(m.rigid.C(m.rigid.c_g), float)
        force = C.T @ (m.rigid.mass * g)
        b = np.asarray(model.layout.member_constant(m.name), float)
        for k, i in enumerate(model.layout.member_indices(m.name)):
            if i is None:
                v0 -= force[k] * b[k]
            else:
                f[i] += force[k]
    return f, v0


def _qr_analysis(name: str, n: int, indptr: np.ndarray, indices: np.ndarray) -> dict[str, np.ndarray]:
    """The sparse QR's analysis of the pattern (``ncgen_qr_pattern``): V, R, prinv, pc."""
    pattern = ca.Sparsity(n, n, indptr.astype(np.int64).tolist(), indices.astype(np.int64).tolist())
    vs, rs, prinv, pc = pattern.qr_sparse(True)
    if vs.size1() != n:
        raise CodegenError(f"model {name!r}: its KKT matrix [[M, Aᵀ], [A, 0]] is structurally singular "
                           f"(redundant constraints?); the stepper tables need a structurally regular one")
    return {"v_colind": _ints(vs.colind()), "v_row": _ints(vs.row()), "r_colind": _ints(rs.colind()),
            "r_row": _ints(rs.row()), "prinv": _ints(prinv), "pc": _ints(pc)}


def lu_analysis(nq: int, indptr: np.ndarray, indices: np.ndarray) -> dict[str, np.ndarray]:
    """The sparse LU's analysis (``ncgen_lu_pattern`` of ``ncgen_sparse_lu.h``) of the KKT
    pattern ``[[M̃, Aᵀ], [A, 0]]`` (n × n, ``nq`` coordinates first, symmetric): the order
    ``p`` (the coordinates in the approximate minimum degree order of ``M̃ + AᵀA``'s pattern,
    each multiplier right after the last coordinate its constraint touches, so that no pivot is
    a structural zero and each is a Schur complement of a KKT block whose constraints are whole),
    its inverse, the rows of ``K``'s nonzeros in that order (``lu_k_prow``), the patterns of ``L``
    and ``U = Lᵀ`` (CSC) of the ordered matrix, and the position in ``L`` of the transpose of each
    entry of ``U``."""
    n = indptr.size - 1
    cols = np.repeat(np.arange(n), np.diff(indptr))
    rows = indices.astype(np.int64)
    qq = (rows < nq) & (cols < nq)
    r_q, c_q = [rows[qq], cols[qq], np.arange(nq)], [cols[qq], rows[qq], np.arange(nq)]
    touched = [r[r < nq] for r in (rows[indptr[c]:indptr[c + 1]] for c in range(nq, n))]
    for t in touched:                                # AᵀA: the coordinates of one constraint
        r_q.append(np.repeat(t, t.size))
        c_q.append(np.tile(t, t.size))
    order_q = list(ca.Sparsity.triplet(nq, nq, np.concatenate(r_q).tolist(), np.concatenate(c_q).tolist()).amd()) \
        if nq else []
    where = np.empty(nq, dtype=np.int64)
    where[order_q] = np.arange(nq)
    after: dict[int, list[int]] = {}
    for i, t in enumerate(touched):
        after.setdefault(int(where[t].max()) if t.size else -1, []).append(nq + i)
    order = after.get(-1, [])
    for k, c in enumerate(order_q):
        order += [c] + after.get(k, [])
    p = np.asarray(order, dtype=np.int64)
    pinv = np.empty(n, dtype=np.int64)
    pinv[p] = np.arange(n)
    sym = ca.Sparsity.triplet(n, n, np.concatenate([pinv[rows], pinv[cols], np.arange(n)]).tolist(),
                              np.concatenate([pinv[cols], pinv[rows], np.arange(n)]).tolist())
    upper, _ = sym.ldl(False)                        # the pattern of Lᵀ = U (strictly upper)
    u_colind, u_row = (np.asarray(x, dtype=np.int64) for x in (upper.colind(), upper.row()))
    u_col = np.repeat(np.arange(n), np.diff(u_colind))
    # L = Uᵀ in CSC: entry U(k, c) is L(c, k), in column k
    by_col = np.lexsort((u_col, u_row))              # sort U's entries by (k, c): L's CSC order
    l_pos = np.empty(by_col.size, dtype=np.int64)
    l_pos[by_col] = np.arange(by_col.size)
    l_colind = np.concatenate([[0], np.cumsum(np.bincount(u_row, minlength=n))])
    return {"lu_p": _ints(p), "lu_pinv": _ints(pinv), "lu_k_prow": _ints(pinv[rows]), "l_colind": _ints(l_colind), "l_row": _ints(u_col[by_col]),
            "u_colind": _ints(u_colind), "u_row": _ints(u_row), "u_lpos": _ints(l_pos)}
