"""The nonsmooth contacts of a model as data for the table stepper (issue 34): the contact
rows of ``templates/c/runtime/ncgen_contact_pairs.h`` evaluated by the pair kinds of the
contact library (:func:`ncgen.assembly.pair_kinds.table_kinds`, compiled once per ncgen
version with the element kernels and the table stepper, :mod:`ncgen.runtime.table_library`).

:func:`contact_arrays` packs, besides the element table of the per-model package
(:func:`ncgen.codegen.stepper_package.pair_arrays`: each element's coordinates, bounding data
and bounds, the pattern of W), per point contact its kind (an index into
:func:`~ncgen.assembly.pair_kinds.table_kinds`), whether the kind's first side is the
element's second (``pk_swap``) and its numbers ``c`` (``pk_c_ptr``, ``pk_c``), and per element
side the map of its local coordinates to the canonical ones of its kind's side
(:func:`~ncgen.assembly.pair_kinds.canonical_map`: its rows ``cm_n`` and its nonzeros
``cm_ptr``, ``cm_row``, ``cm_col``, ``cm``: an identity for a body of the canonical type), so that
a kind serves every coordinate type with the same number of axes; then μ, e per contact and |g|;
and, where the constant mass matrix is regular (``schur``), ``M⁻¹`` with its nonzeros by columns
(:func:`ncgen.codegen.stepper_package.mass_inverse`, as the per-model package has it) and the
column of each nonzero of A (``a_col``), from which the C forms the Delassus matrix by the Schur
complement instead of one KKT solve per contact row.  ``templates/c/runtime/ncgen_table_contacts.h``
reads them.

:func:`uncovered_contacts` names what the tables do not cover: smooth contact laws (the
compiled package's penalty forces), and point contacts without a kind of the library (a
plane carried by a member, a sphere fixed to the ground against another, a kind between
sides it does not take).
"""
from __future__ import annotations

import numpy as np

from ncgen.assembly.pair_kernels import pair_contacts, pair_elements
from ncgen.assembly.pair_kinds import canonical_map, canonical_type, point_call, table_kinds
from ncgen.assembly.stepper_equations import nonsmooth
from ncgen.codegen.stepper_package import mass_inverse, pair_arrays

#: Sizes of :func:`contact_arrays` (``int`` fields of ``ncgen_contact_tables``), in order.
SIZES = ("nk", "ne", "ns", "max_q", "max_g", "max_w", "nnz_w", "schur")
#: Its integer arrays and real arrays (pointer fields of ``ncgen_contact_tables``), in order.
INT_ARRAYS = ("wt_colind", "wt_row", "pair_int", "pair_qidx", "pair_wpos", "pair_side", "pair_sid", "pair_srep",
              "pk_kind", "pk_swap", "pk_c_ptr", "cm_ptr", "cm_n", "cm_row", "cm_col", "minv_colind", "minv_row",
              "a_col")
REAL_ARRAYS = ("mu", "restitution", "pair_qconst", "pair_bdata", "pair_bound", "pk_c", "cm", "minv")


def _calls(model):
    """Per point contact of the model's contact elements: ``(element, point contact, call)``,
    the call between canonical sides (:func:`~ncgen.assembly.pair_kinds.point_call`; None: no
    kind of the library)."""
    out = []
    for element in pair_contacts(model) or ():
        for pc in element.point_contacts():
            out.append((element, pc, point_call(pc, model.dim, canonical=True)))
    return out


def uncovered_contacts(model) -> list[str]:
    """The contacts of ``model`` the table stepper does not cover (module docstring), named."""
    if not model.contacts:
        return []
    if not nonsmooth(model):
        return [f"contact {n!r} (smooth contact law: contacts='nonsmooth' runs on the tables)"
                for n in model.contact_names]
    calls = _calls(model)
    if len(calls) != model.nk:
        return [f"contact {n!r} (no contact element)" for n in model.contact_names]
    out = []
    for element, pc, call in calls:
        if call is None:
            sides = " and ".join(m.name for m in element.members())
            out.append(f"contact {pc.name!r} ({type(pc).__name__} between {sides}: no pair kind of the "
                       f"contact library for these sides)")
    return out


def contact_arrays(model, a_colind=None) -> dict:
    """The contact tables of ``model`` (module docstring): sizes :data:`SIZES`,
    ``gravity_norm`` and the arrays :data:`INT_ARRAYS`, :data:`REAL_ARRAYS` (NumPy); the model
    must be covered (:func:`uncovered_contacts` empty).  ``a_colind``: the column starts of A's
    nonzeros in the stepper tables, from which ``a_col`` is packed (None: none packed; the tables
    the C reads need them: :func:`ncgen.codegen.stepper_tables.stepper_tables` passes them)."""
    dim = model.dim
    elements = pair_elements(model)
    out = pair_arrays(dim, elements)
    index = {k: i for i, k in enumerate(table_kinds())}
    kind, swap, c_ptr, c = [], [], [0], []
    calls = _calls(model)
    for element, pc, call in calls:
        members = element.members()
        kind.append(index[(call.kind.kind, *(canonical_type(m, dim) for m in call.members), dim)])
        swap.append(int(call.members[0] is not members[0]))
        c += [float(x) for x in call.numbers]
        c_ptr.append(len(c))
    cm_ptr, cm_n, cm_row, cm_col, cm = [0], [], [], [], []
    for element in pair_contacts(model):
        for m in element.members():
            B = np.zeros((0, 0)) if m.is_ground else canonical_map(m.ctype.name, dim)
            cm_n.append(B.shape[0])
            rows, cols = np.nonzero(B.T)            # by local coordinates (columns of B)
            cm_row += [int(r) for r in cols]
            cm_col += [int(i) for i in rows]
            cm += [float(B[r, i]) for i, r in zip(rows, cols)]
            cm_ptr.append(len(cm))
    inverse = mass_inverse(model)
    minv, minv_colind, minv_row = inverse if inverse is not None else (np.zeros(1), [0] * (model.nq + 1), [0])
    a_colind = np.zeros(model.nq + 1, dtype=int) if a_colind is None else np.asarray(a_colind)
    out.update(pk_kind=kind, pk_swap=swap, pk_c_ptr=c_ptr, pk_c=c or [0.0], cm_ptr=cm_ptr, cm_n=cm_n,
               cm_row=cm_row or [0], cm_col=cm_col or [0], cm=cm or [0.0], mu=[float(k["mu"]) for k in model.contacts],
               restitution=[float(k["restitution"]) for k in model.contacts],
               nk=model.nk, ns=out["pair_ns"], max_q=out["pair_max_q"], max_g=out["pair_max_g"],
               max_w=out["pair_max_w"], nnz_w=len(out["wt_row"]), schur=int(inverse is not None),
               minv=minv.ravel(order="F"), minv_colind=minv_colind, minv_row=minv_row or [0],
               a_col=np.repeat(np.arange(model.nq), np.diff(a_colind)) if a_colind[-1] else [0],
               gravity_norm=float(np.linalg.norm(model.gravity)))
    arrays = {k: np.ascontiguousarray(out[k], dtype=np.int32) for k in INT_ARRAYS}
    arrays.update({k: np.ascontiguousarray(out[k], dtype=np.float64) for k in REAL_ARRAYS})
    return {**{k: int(out[k]) for k in SIZES}, "gravity_norm": out["gravity_norm"], "arrays": arrays}

