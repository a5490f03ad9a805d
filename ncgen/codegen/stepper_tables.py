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
as point features; and the KKT matrix ``K = [[M − h/2 ∂F/∂w, Aᵀ], [A, 0]]``: its pattern,
the nonzero of ``K`` every product of the loops adds to, and the symbolic analysis of its
sparse QR (CasADi's ``Sparsity.qr_sparse``, approximate minimum degree column order).

A model is *table-covered* when every element is: joints as :mod:`ncgen.codegen.model_tables`
says, forces and actuated joints as above, no contacts, controller or parameters, inputs
only through input forces and efforts.  :class:`UnsupportedElements`
names every element that is not.  Nothing here reads ``model.functions``.
"""
from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import casadi as ca
import numpy as np

from ncgen.codegen.model_tables import ModelTables, UnsupportedElements, _csc, _ints, _ptr, _reals, model_tables
from ncgen.errors import CodegenError, NcgenError
from ncgen.model.context import Context
from ncgen.model.forces import Spring


@dataclass
class StepperTables:
    """The stepper tables of one model (names as the fields of ``ncgen_stepper_tables``)."""

    name: str
    tables: ModelTables
    nu: int
    np: int
    n_markers: int
    n_spring: int
    mass_scale: float
    v_gravity: float
    nnz_k: int
    nnz_v: int
    nnz_r: int
    arrays: dict[str, np.ndarray]


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
    not of that form)."""
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
    constant (no dependence on t, q, v or the parameters, nothing at u = 0), else None."""
    if not model.nu or type(force) is Spring or getattr(force, "system", None) is None:
        return None
    ctx = _context(model, force)
    try:
        Q = ca.densify(force.generalized(ctx))
    except (NcgenError, RuntimeError, TypeError):
        return None
    return _linear_in_inputs(ctx, Q, model.nq)


def uncovered_elements(model) -> dict[str, list[str]]:
    """The elements of ``model`` outside the stepper tables' kinds (other than joints), by kind."""
    out: dict[str, list[str]] = {}
    for f in model.forces:
        if type(f) is not Spring:
            if input_force_map(model, f) is None:
                out.setdefault(f.kind, []).append(f"force {f.name!r}")
        elif f.cable or not all(_number(x) for x in (f.k, f.rest_length, f.damping)):
            what = "cable" if f.cable else "with an expression for k, rest_length or damping"
            out.setdefault(f"Spring {what}", []).append(f"force {f.name!r}")
    if model.contacts:
        names = [f"contact {n!r}" for n in model.contact_names]
        out["contact"] = names[:4] + ([f"{len(names) - 4} more"] if len(names) > 4 else [])
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
    springs = [f for f in model.forces if type(f) is Spring]
    B_u = sum((input_force_map(model, f) for f in model.forces if type(f) is not Spring),
              np.zeros((model.nq, model.nu)))
    acts = [actuator_element(model, j) for j in model.joints if j.options.get("effort") is not None]
    bu_rows = [np.flatnonzero(B_u[:, j]) for j in range(model.nu)]
    bu_row = _ints(np.concatenate(bu_rows)) if bu_rows else _ints([])
    bu_val = _reals(np.concatenate([B_u[r, j] for j, r in enumerate(bu_rows)])) if bu_rows else _reals([])
    points = [(s.a, s.at_a) for s in springs] + [(s.b, s.at_b) for s in springs]
    points += [(m, local) for m in model.members.values() for local in m.markers.values()]
    T = model_tables(model, points)
    ns = len(springs)
    ends, markers = T.point_features[:2 * ns], T.point_features[2 * ns:]
    spr_feat = [f for s in range(ns) for f in (ends[s], ends[ns + s])]
    f_gravity, v_gravity = _gravity(model)
    nq, nc = T.nq, T.nc
    n = nq + nc
    a = T.arrays
    # the entries of K, in the loops' order: M, A (lower block), Aᵀ (upper block), dampers
    m_cols = np.repeat(np.arange(nq), np.diff(T.m_indptr))
    a_cols = np.repeat(np.arange(nq), np.diff(T.a_indptr))
    rows = [T.m_indices, nq + T.a_indices, a_cols]
    cols = [m_cols, a_cols, nq + T.a_indices]
    counts = []
    for s in range(ns):
        fa = [(a["feat_ptr"][f], a["feat_ptr"][f + 1]) for f in (spr_feat[2 * s], spr_feat[2 * s + 1])]
        r_s, c_s = [], []
        for lo, hi in fa:
            for e in range(lo, hi):
                for lo2, hi2 in fa:
                    r_s += [a["feat_col"][e]] * (hi2 - lo2)
                    c_s += list(a["feat_col"][lo2:hi2])
        rows.append(_ints(r_s))
        cols.append(_ints(c_s))
        counts.append(len(r_s))
    k_indptr, k_indices, pos = _csc(n, n, np.concatenate(rows), np.concatenate(cols))
    m_nnz, a_nnz = T.m_nnz, T.a_nnz
    qr = _qr_analysis(model.name, n, k_indptr, k_indices)
    M = np.asarray(model.M, dtype=float)
    arrays = {
        "a_colind": T.a_indptr, "a_row": T.a_indices, "m_colind": T.m_indptr, "m_row": T.m_indices,
        "m_val": _reals(M[T.m_indices, m_cols]),
        "f_gravity": _reals(f_gravity),
        "spr_feat": _ints(spr_feat),
        "spr_par": _reals([x for s in springs for x in (s.k, s.rest_length, s.damping)]),
        "spr_kpos_ptr": _ptr(counts), "spr_kpos": pos[m_nnz + 2 * a_nnz:],
        "marker_feat": _ints(markers),
        "k_mpos": pos[:m_nnz], "k_apos": pos[m_nnz:m_nnz + a_nnz], "k_atpos": pos[m_nnz + a_nnz:m_nnz + 2 * a_nnz],
        "bu_colind": _ptr([len(r) for r in bu_rows]), "bu_row": bu_row, "bu_val": bu_val,
        "act_kind": _ints([a.kind for a in acts]), "act_ptr": _ptr([a.cols.size for a in acts]),
        "act_col": _ints(np.concatenate([a.cols for a in acts]) if acts else []),
        "act_form_ptr": _ptr([a.forms.size for a in acts]),
        "act_form": _reals(np.concatenate([a.forms for a in acts]) if acts else []),
        "act_tau": _reals(np.concatenate([a.tau for a in acts]) if acts else []),
        "k_colind": k_indptr, "k_row": k_indices, **qr,
    }
    return StepperTables(model.name, T, model.nu, model.np, len(markers), ns,
                         float(np.max(np.abs(M))) if nq else 1.0, v_gravity, int(k_indices.size),
                         int(qr["v_row"].size), int(qr["r_row"].size), arrays)


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
