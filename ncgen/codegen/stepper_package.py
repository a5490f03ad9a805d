"""The compiled stepper as C: its section of a model package.

:func:`stepper_section` adds to a model package (``nc.generate``) the kernels of
:mod:`ncgen.assembly.stepper_equations`, the Newton loop ``<model>_stepper.c`` with the API
declared in ``<model>_stepper.h`` (``<model>_step``, ``<model>_simulate``; templates
``stepper.c.j2``, ``stepper.h.j2``: the model's sizes, kernels and data around the
model-independent C of :func:`runtime_files`, copied into the package) and the example program ``<model>_simulate``
(``simulate_main.c.j2``), which simulates from the model's initial state without Python.
:mod:`ncgen.runtime.stepper_library` loads it from the model's compiled package.
"""
from __future__ import annotations

import numpy as np


from ncgen.assembly.mass import mass_is_regular
from ncgen.assembly.pair_kernels import pair_contacts, pair_kernels
from ncgen.assembly.stepper_equations import CONTACT_DOCS, DOCS, mass_scale, nonsmooth, stepper_functions
from ncgen.codegen import PackageDoc, write_package
from ncgen.codegen.cnames import c_real
from ncgen.codegen.looped import is_large, primitives, reroll_limit
from ncgen.codegen.package import ExtraSource
from ncgen.codegen.reroll import REROLL_INSTRUCTIONS
from ncgen.codegen.section import Section

#: Status codes of ``<model>_step`` (``templates/c/stepper.h.j2``) and what they mean.
STATUS = {
    0: "converged",
    1: "Newton's method did not converge within max_iter iterations, on the whole step nor on "
       "its halves (try a smaller step dt or more max_halvings; or the motion is singular there)",
    2: "a residual or Newton update was not finite: the KKT matrix is singular (a singular "
       "configuration or redundant constraints) or the forces are not finite",
    3: "the velocity constraints are violated after the second half-step: the KKT matrix is "
       "nearly singular (a singular configuration or redundant constraints)",
    4: "a generated kernel returned an error",
    5: "bad input (non-positive step, non-finite time) or out of memory",
    6: "more step attempts than max_steps in one output interval (the error control keeps "
       "rejecting steps: a singular or very stiff motion, or a tolerance below round-off)",
    7: "the error-controlled step fell below 1e-13 (|t| + dt): the motion is singular there or "
       "the tolerance is below round-off",
    8: "interrupted (Ctrl-C)",
}
#: Status of a loop stopped through ``options->stop`` (``<MODEL>_STEP_INTERRUPTED``).
STEP_INTERRUPTED = 8
#: The classes of work the C loops accumulate step by step beside the total (``WORK_*`` of
#: ``runtime/ncgen_rattle.h``, in its order): contacts' normal forces and impulses, friction
#: forces and impulses, inputs, drives (rheonomic constraints, time-dependent potentials),
#: dampers and every other force doing work outside V, and the energy changed by the
#: push-out of penetrating nonsmooth contacts.
WORK_PARTS = ("contacts", "friction", "inputs", "drives", "dampers", "push_out")
#: Columns of the per-output-row statistics of the C loops (``<MODEL>_STEP_NSTATS``); the
#: work columns hold the work (J) since the start of the run.
STATS = ("steps", "newton_iterations", "splits", "error_q", "error_v", "work") + tuple(f"work_{k}" for k in WORK_PARTS)
#: Columns the nonsmooth contact stepper appends to :data:`STATS` (fixed steps): contact
#: solves whose projected Gauss–Seidel stopped at PGS_MAX_ITER sweeps, the largest
#: last-sweep change of a contact velocity among them, relative to 1 + max |U|, and the
#: deepest penetration (m) left at the end of a step (after the push-out), and the largest
#: residual of the contact laws at a step's impulses (m/s, relative to 1 + max |U|:
#: ``cone_residual`` in ``runtime/ncgen_cone_newton.h``).
CONTACT_STATS = ("pgs_unconverged", "pgs_residual", "penetration", "cone_residual")
#: Default Newton tolerance: |Φ|∞ ≤ tol (m²), momentum residual ≤ tol·max|M|·(1 + |w|∞),
#: |A v + Φ_t|∞ ≤ tol·(1 + |v|∞) (see ``<model>_stepper.h``).
TOL = 1e-10
#: Default Newton iterations allowed per step.
MAX_ITER = 12
#: Default number of times a failing step may be split in halves, and the most the C
#: workspace allows (``<MODEL>_STEP_MAX_HALVINGS``).
MAX_HALVINGS, HALVINGS_LIMIT = 4, 10
#: Nonsmooth contact stepper: projected Gauss–Seidel sweeps allowed per step, and its
#: convergence test: no sweep changes a contact velocity by more than PGS_TOL (1 + max |U|)
#: (m/s; a test on the impulses would never pass where contacts are redundant, as under a
#: box or a chain lying flat, whose impulses are not unique).  A solve that reaches the
#: sweep limit is counted (:data:`CONTACT_STATS`): where redundant contacts with friction
#: make PGS crawl or cycle, more sweeps mostly cost time (the falling chain of
#: benchmarks/contact.py: 2000 sweeps instead of 300 moved its final state by 4e-8 m).
PGS_MAX_ITER, PGS_TOL = 300, 1e-12
#: Nonsmooth contact stepper: a contact whose gap is below −PENETRATION_TOL (m) at the end of
#: a step is put back on its surface (``push_out`` in ``runtime/ncgen_contact.h``).  The push-out is
#: linearised and followed by the projection back onto Φ = 0, which moves the gaps again at
#: second order (~1e-8 m when the falling chain of benchmarks/contact.py lands), so a smaller
#: tolerance would only repeat push-outs.
PENETRATION_TOL = 1e-8
#: Nonsmooth contact stepper: a contact still open at the end of the free step,
#: with e = 0 and a gap below GAP_REACH h/2 × the fastest approach speed of a closed contact,
#: takes part in the step's contact problem with U_N ≥ min(0, U_free,N − 2 g/h): the impulses
#: on its neighbours may close it within the step but not push it through its surface, so the
#: push-out rarely runs (``contact_step`` in ``runtime/ncgen_contact.h``).
GAP_REACH = 2.0
#: Nonsmooth contact stepper: a step with closed contacts is retaken with corrected impulses
#: (at most CONTACT_REFINE_MAX times) until its end-of-step contact velocities match the
#: linearised prediction to CONTACT_REFINE_TOL (relative to 1 m/s or the largest of them).
CONTACT_REFINE_MAX, CONTACT_REFINE_TOL = 10, 1e-8
#: Nonsmooth contact stepper: a step first tries the last step's impulses again and keeps
#: them if the contact laws hold on the measured end velocities to REPEAT_TOL (1 + max |U|)
#: m/s (``repeat_step`` in ``runtime/ncgen_contact.h``; rows that moved, rolling spheres, take
#: the second half-step again along the rows at its end): at rest that is every step.
REPEAT_TOL = 1e-12
#: Nonsmooth contact stepper: the Delassus matrix comes from the constant M⁻¹ (stored dense
#: in the C) and the Schur complement A M⁻¹ Aᵀ when M is regular (``mass_is_regular``: no
#: flat or nearly flat body; condition number below MINV_MAX_COND) and nq ≤ MINV_MAX_NQ;
#: else from the sparse QR of the whole KKT matrix.
MINV_MAX_NQ, MINV_MAX_COND = 400, 1e12
#: Nonsmooth contact stepper: the contact rows from one kernel per contact element and a
#: broad phase (:mod:`ncgen.assembly.pair_kernels`, ``runtime/ncgen_contact_pairs.h``), or
#: (False) from the flat kernels ``step_contact``/``step_gap`` of every contact at once.
CONTACT_PAIRS = True
#: The demo program's defaults: simulated time and step (s).
DEMO_T_END, DEMO_H = 1.0, 1e-3

def stepper_section(model, reroll_instructions: int | None = REROLL_INSTRUCTIONS):
    """The stepper's part of ``model``'s C package (a
    :class:`~ncgen.codegen.section.Section`)."""

    pairs = pair_kernels(model) if nonsmooth(model) and CONTACT_PAIRS and pair_contacts(model) is not None else None
    functions = stepper_functions(model, primitives(model) if is_large(model, reroll_instructions) else None, pairs)
    names = {f.name() for f in functions}
    docs = {k: v for k, v in {**DOCS, **CONTACT_DOCS, **pair_docs(functions)}.items() if k in names} \
        if nonsmooth(model) else DOCS
    return Section(functions=functions, docs=docs, extra_sources=extra_sources(model, functions, pairs))


def pair_docs(functions) -> dict:
    """Documentation of the element kernels ``step_pair<k>_gap`` / ``_rows`` among ``functions``."""
    inputs = {"q_a": ("local coordinates of the element's first member (fixed ones as in q)", "m"),
              "q_b": ("local coordinates of its second member", "m"), "p": ("parameters", "")}
    out = {}
    for f in functions:
        name = f.name()
        if name.startswith("step_pair") and name.endswith("_gap"):
            out[name] = {"purpose": "Stepper: the gaps of one contact element", "inputs": inputs,
                         "outputs": {"g": ("gaps of its point contacts, positive apart", "m")}}
        elif name.startswith("step_pair") and name.endswith("_rows"):
            out[name] = {"purpose": "Stepper: gaps and contact Jacobian rows of one contact element",
                         "inputs": inputs,
                         "outputs": {"g": ("gaps of its point contacts, positive apart", "m"),
                                     "W": ("per point contact its normal and tangent rows (zero without "
                                           "friction), columns q_a then q_b, dense", "1")}}
    return out


def _bounding_data(side) -> list[float]:
    """The bounding data of one side of a contact element: a member's centre, axes, extents,
    radius and gap-gradient norm; a fixed point and its radius; a half-space's point and
    normal; nothing for an unbounded side."""
    if side.kind == "member":
        values = [side.centre.ravel(order="F")] + [a.ravel(order="F") for a in side.axes] + \
            [side.extents, [side.radius, side.gnorm]]
    elif side.kind == "fixed":
        values = [side.fixed, [side.radius]]
    elif side.kind == "halfspace":
        values = [side.fixed, side.normal]
    else:
        values = []
    return [float(x) for v in values for x in np.asarray(v, float).ravel()]


#: The real-valued arrays of :func:`pair_arrays`.
PAIR_REALS = ("pair_qconst", "pair_bdata", "pair_bound")


def pair_arrays(dim: int, elements) -> dict:
    """The element table of ``runtime/ncgen_contact_pairs.h`` for the contact ``elements``
    (:func:`ncgen.assembly.pair_kernels.pair_elements`): the pattern of W (per contact row the
    coordinates of its element's members; none for the tangent rows of a frictionless contact)
    and the tables the header lists (reals: :data:`PAIR_REALS`, the bound's cap at most 1e300),
    with the distinct member sides (``pair_sid``, ``pair_srep``: equal coordinates and bounding
    data, so a sphere in twenty elements has its bounds computed once per broad phase)."""
    kinds = {"unbounded": 0, "member": 1, "fixed": 2, "halfspace": 3}
    colind, wrow = [0], []
    ints, qidx, qconst, wpos, sides, bdata, bound = [], [], [], [], [], [], []
    sid, srep, distinct = [], [], {}      # the distinct member sides: bounds computed once per member
    max_q = max_g = max_w = 1
    for e in elements:
        loc = e.idx_a + e.idx_b
        cols = sorted({i for i in loc if i >= 0})
        first_row = len(colind) - 1
        for k in range(e.count):
            for d in range(dim):
                if d == 0 or e.friction[k]:
                    wrow += cols
                colind.append(len(wrow))
        nrow = e.count * dim
        ints += [e.kernel, e.first, e.count, len(e.idx_a), len(e.idx_b), len(qidx), len(wpos), int(e.rate_bounded)]
        qidx += loc
        qconst += [float(x) for x in np.concatenate([e.const_a, e.const_b])]
        for i, c in enumerate(loc):
            for r in range(nrow):
                row = first_row + r
                start, stop = colind[row], colind[row + 1]
                wpos.append(start + cols.index(c) if c >= 0 and stop > start else -1)
        for which, (side, const) in enumerate(zip(e.sides, (e.const_a, e.const_b))):
            sides += [kinds[side.kind], len(side.extents), len(bdata)]
            numbers = _bounding_data(side)
            if side.kind == "member":
                key = (tuple(side.idx), tuple(c_real(x) for x in const), tuple(map(c_real, numbers)))
                if key not in distinct:
                    distinct[key] = len(srep) // 2
                    srep += [len(ints) // 8 - 1, which]
                sid.append(distinct[key])
            else:
                sid.append(-1)
            bdata += numbers
        bound += [float(e.kappa), float(e.dmin), float(min(e.cap, 1e300))]
        max_q, max_g, max_w = max(max_q, len(loc)), max(max_g, e.count), max(max_w, nrow * len(loc))
    return {"ne": len(elements), "pair_int": ints, "pair_qidx": qidx, "pair_qconst": qconst or [0.0],
            "pair_wpos": wpos, "pair_side": sides, "pair_bdata": bdata or [0.0], "pair_bound": bound,
            "pair_ns": len(srep) // 2, "pair_sid": sid, "pair_srep": srep or [0, 0],
            "pair_max_q": max_q, "pair_max_g": max_g, "pair_max_w": max_w, "wt_colind": colind, "wt_row": wrow}


def pair_context(model, pairs) -> dict:
    """The template context of the element table (``runtime/ncgen_contact_pairs.h``):
    :func:`pair_arrays` of ``pairs``' elements, reals as C literals, and the kernels by number."""
    out = pair_arrays(model.dim, pairs.elements)
    out.update({k: [c_real(x) for x in out[k]] for k in PAIR_REALS})
    nkernels = 1 + max(e.kernel for e in pairs.elements)
    return {"pairs": True, **out,
            "pair_gap_fn": [f"{model.name}_step_pair{k}_gap" for k in range(nkernels)],
            "pair_rows_fn": [f"{model.name}_step_pair{k}_rows" for k in range(nkernels)]}


def extra_sources(model, functions, pairs=None) -> list[ExtraSource]:
    """The Newton loop, its header and the example program, rendered for ``model`` (``pairs``:
    its contact element kernels, or None for the flat ones)."""
    name = model.name
    context = {"nq": model.nq, "nc": model.nc, "nu": model.nu, "np": model.np,
               "nnz_k": int(functions[0].sparsity_out("K").nnz()),
               "mass_scale": c_real(mass_scale(model)), "tol": c_real(TOL), "max_iter": MAX_ITER,
               "max_halvings": MAX_HALVINGS, "halvings_limit": HALVINGS_LIMIT, "dim": model.dim,
               "nout": n_outputs(model), "nstats": len(STATS) + (len(CONTACT_STATS) if nonsmooth(model) else 0),
               "kernels": [f"{name}_{f.name()}" for f in functions],
               # the default fixed-step scheme, as nc.simulate's scheme="auto": RATTLE with contacts
               "default_scheme": "RATTLE" if getattr(model, "contacts", None) else "RATTLE4"}
    if nonsmooth(model):
        factor = next((f for f in functions if f.name() == "step_factor"), None)
        if factor is not None:
            context.update(nnz_v=int(factor.sparsity_out(0).nnz()), nnz_r=int(factor.sparsity_out(1).nnz()),
                           n_beta=int(factor.sparsity_out(2).nnz()))
        context.update(factored=factor is not None, nk=model.nk, pgs_max_iter=PGS_MAX_ITER,
                       pgs_tol=c_real(PGS_TOL), penetration_tol=c_real(PENETRATION_TOL), gap_reach=c_real(GAP_REACH),
                       refine_max=CONTACT_REFINE_MAX, refine_tol=c_real(CONTACT_REFINE_TOL), repeat_tol=c_real(REPEAT_TOL),
                       gravity_norm=c_real(float(np.linalg.norm(model.gravity))),
                       mu=[c_real(c["mu"]) for c in model.contacts],
                       restitution=[c_real(c["restitution"]) for c in model.contacts],
                       any_restitution=any(c["restitution"] > 0 for c in model.contacts))
        context.update(schur_context(model, functions[0].sparsity_out("K")))
        if pairs is not None:
            context.update(pair_context(model, pairs))
        else:
            wt = next(f for f in functions if f.name() == "step_contact").sparsity_out("Wt")
            context.update(pairs=False, wt_colind=list(wt.colind()), wt_row=list(wt.row()))
    demo = {**context, "program": f"{name}_simulate", "t0": c_real(model.t0), "t_end": c_real(DEMO_T_END),
            "h": c_real(DEMO_H), "q0": [c_real(x) for x in model.q0], "v0": [c_real(x) for x in model.v0],
            "p0": [c_real(x) for x in model.p0]}
    runtime = [ExtraSource(f"runtime/{f}", f, included=True) for f in runtime_files(model)]
    return [*runtime, ExtraSource("stepper.c.j2", f"{name}_stepper.c", context),
            ExtraSource("stepper.h.j2", f"{name}_stepper.h", context),
            ExtraSource("simulate_main.c.j2", f"{name}_simulate.c", demo, program=True)]


def runtime_files(model) -> list[str]:
    """The model-independent C of the stepper that ``<model>_stepper.c`` includes, in order
    (``templates/c/runtime/``, copied into the package): the RATTLE step, the contact
    solvers (nonsmooth contacts only), fixed-step runs, error-controlled runs."""
    contact = ["ncgen_cone_newton.h", "ncgen_contact_pairs.h", "ncgen_contact.h"] if nonsmooth(model) else []
    return ["ncgen_rattle.h", *contact, "ncgen_fixed.h", "ncgen_adaptive.h"]


def schur_context(model, K) -> dict:
    """The template context of the Delassus matrix by the Schur complement (see
    :data:`MINV_MAX_NQ`): ``schur`` (whether it applies), ``minv`` (M⁻¹, column-major), its
    nonzeros by columns (``minv_colind``, ``minv_row``: members that share no coordinate give
    zero blocks) and
    where A's nonzeros sit in the nonzeros of the KKT matrix pattern ``K`` (``a_nz``,
    ``a_row``, ``a_col``)."""
    inverse = mass_inverse(model)
    if inverse is None:
        return {"schur": False}
    minv, minv_colind, minv_row = inverse
    nq = model.nq
    colind, row = K.colind(), K.row()
    a_nz, a_row, a_col = [], [], []
    for j in range(nq):
        for k in range(colind[j], colind[j + 1]):
            if row[k] >= nq:
                a_nz.append(k)
                a_row.append(row[k] - nq)
                a_col.append(j)
    return {"schur": True, "minv": [c_real(x) for x in minv.ravel(order="F")], "minv_colind": minv_colind,
            "minv_row": minv_row, "a_nz": a_nz, "a_row": a_row, "a_col": a_col}


def mass_inverse(model) -> tuple[np.ndarray, list[int], list[int]] | None:
    """``(M⁻¹, minv_colind, minv_row)`` of the Delassus matrix by the Schur complement (see
    :data:`MINV_MAX_NQ`): ``M⁻¹`` (nq × nq, symmetrised) and its nonzeros by columns (members
    that share no coordinate give zero blocks); None where it does not apply (M singular or too
    ill-conditioned, nq above MINV_MAX_NQ)."""
    M = np.asarray(model.M, dtype=float)
    nq = model.nq
    if (nq > MINV_MAX_NQ or not mass_is_regular(model) or not np.all(np.isfinite(M))
            or np.linalg.cond(M) > MINV_MAX_COND):
        return None
    minv = np.linalg.inv(M)
    minv = (minv + minv.T) / 2
    colind, row = [0], []
    for j in range(nq):
        row += [int(i) for i in np.flatnonzero(minv[:, j])]
        colind.append(len(row))
    return minv, colind, row


def n_impulses(model) -> int:
    """Contact impulse components per step of the nonsmooth contact stepper (else 0)."""
    return model.nk * model.dim if nonsmooth(model) else 0


def n_stats(nd: int) -> int:
    """Columns of the C loops' per-row statistics (``<MODEL>_STEP_NSTATS``) for ``nd``
    contact impulse components per step (:func:`n_impulses`)."""
    return len(STATS) + (len(CONTACT_STATS) if nd else 0)


def n_outputs(model) -> int:
    """Values per sample of ``<model>_outputs``: T, V, max|Φ|, max|A v + Φ_t|, P, markers."""
    return 5 + model.dim * len(model.marker_names)


def write_stepper_package(model, out_dir):
    """A package holding only the stepper of ``model`` (kernels, loop, example program)."""
    limit = reroll_limit(model)
    section = stepper_section(model, limit)
    doc = PackageDoc(summary=f"Compiled stepper (RATTLE) of model {model.name!r}", functions=section.docs)
    return write_package(model.name, section.functions, out_dir, doc=doc, extra_sources=section.extra_sources,
                         reroll_instructions=limit)
