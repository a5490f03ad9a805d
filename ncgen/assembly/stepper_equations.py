"""The CasADi kernels of the compiled stepper; the Newton loop that calls them is C
(``templates/c/runtime/``, glued to a model by ``templates/c/stepper.c.j2``).

Scheme: RATTLE for constant mass matrices, in its Lobatto IIIA–IIIB form that also takes
velocity-dependent forces (springs with dampers).  One step from ``(t, q, v)`` with step
``h`` and inputs ``u`` held constant over the step (zero-order hold)::

    M (w − v) = h/2 (F(t, q, w) − A(t, q)ᵀ λ)             w = v_{n+½}: implicit in w (dampers)
    q⁺ = q + h w,   Φ(t + h, q⁺) = 0                        position constraints at t + h
    M (v⁺ − w) = h/2 (F(t + h, q⁺, w) − A(t + h, q⁺)ᵀ μ)    linear in (v⁺, μ)
    A(t + h, q⁺) v⁺ + Φ_t(t + h, q⁺) = 0                     velocity constraints at t + h

Why RATTLE (and not Zhong06): it enforces *both* constraint levels at every step (Zhong06
enforces Φ only), it is symmetric, second order and, for conservative forces, symplectic, so
the energy error stays bounded over long runs; with ``M`` constant the only nonlinearity is
the quadratic ``Φ`` (and the forces), and the second half-step is one linear KKT solve.

Newton system of the first half-step, unknowns ``x = [w; ν]`` with ``ν = h/2 λ`` (N·s/m²)::

    r(x) = [ M (w − v) − h/2 F(t, q, w) + A(t, q)ᵀ ν ;  Φ(t + h, q + h w) / h ]
    K = ∂r/∂x = [[M − h/2 ∂F/∂v(t, q, w), A(t, q)ᵀ], [A(t + h, q + h w), 0]]

and of the second, ``[[M, A⁺ᵀ], [A⁺, 0]] [v⁺; μ'] = [M w + h/2 F(t + h, q⁺, w); −Φ_t]`` with
``μ' = h/2 μ``.  Both matrices share one sparsity pattern (the second is stored in the
first's), so a single sparse-QR kernel solves them.

Kernels (name: inputs -> outputs; ``t`` in s, ``h`` in s):

* ``step_newton``: t, q, v, u, p, h, w, lam_h -> r (nq + nc), K (sparse)
* ``step_velocity``: t (= t + h), q (= q⁺), w, u, p, h -> b (nq + nc), K (same pattern)
* ``step_check``: t, q, v, p -> phi_max = ‖Φ‖∞ (m²), phidot_max = ‖A v + Φ_t‖∞ (m²/s)
* ``step_solve``: K, r -> x = K⁻¹ r (sparse QR, or the Schur complement with the constant
  mass matrix, generated as C; see :func:`solve_function`)
* ``step_project``: t, q, v, p -> K = [[M, Aᵀ], [A, 0]] (same pattern), Φ, A v + Φ_t: the
  mass-metric projection onto both constraint levels after an extrapolated step
  (``K [Δq; μ] = [0; Φ]``, ``q ← q − Δq`` until ``|Φ|∞ ≤ tol``, then the same for ``v``)
* ``step_power``: t, q, v, lam, u, p -> P = dE/dt = vᵀ(F + ∇V) + ∂V/∂t + λᵀΦ_t (W): the power
  of the non-conservative forces and of the drives (rheonomic constraints), whose integral
  closes the energy balance ``E(t) − E(t0) = W(t)``
* ``step_outputs``: t, q, v, lam, u, p -> y = [T; V; |Φ|∞; |A v + Φ_t|∞; P; markers
  (dim × n_markers, column-major)]: the derived quantities of a trajectory, one call per sample

Models built with ``contacts="nonsmooth"`` (and at least one contact) get the nonsmooth
variant (docs/contact.md and ``contact_step`` in templates/c/runtime/ncgen_contact.h document the scheme): ``step_newton`` and
``step_velocity`` take one more input, the generalised contact impulse ``j = Wᵀ P`` (N·s),
half of which enters each half-step (``− j/2`` in r, ``+ j/2`` in b), and two more kernels

* ``step_contact``: q, v, p -> g (nk, m), Wt = Wᵀ (nq × nk·dim, sparse: column r is row r of
  the contact Jacobian W, per contact its normal row, then its tangent rows; a row touches
  the coordinates of one or two members; a frictionless contact's tangent rows are
  structural zeros, as no tangential impulse acts there, so its tangent basis is never
  computed), U = W v (m/s)
* ``step_gap``: q, p -> g (the gaps alone)

give the gaps and contact Jacobians; or, given the element kernels of
:mod:`ncgen.assembly.pair_kernels` (``stepper_functions(pairs=...)``, the default of the
package: :data:`ncgen.codegen.stepper_package.CONTACT_PAIRS`), ``step_pair<k>_gap`` and
``step_pair<k>_rows`` in their place, which the C calls per element with a broad phase.  When the constant mass matrix is regular the C forms
the Delassus matrix from ``M⁻¹`` and the Schur complement ``A M⁻¹ Aᵀ`` (no kernel: ``A`` is
read from ``K``; :func:`ncgen.codegen.stepper_package.schur_context`).  For the other
cases, and where that complement is singular, when the QR factors are small enough to
unroll (:data:`SX_QR_MAX_NNZ`), two more split ``step_solve`` so that the Delassus matrix
needs one factorisation per step and one cheap solve per contact row:

* ``step_factor``: K -> V, R, beta (the sparse Householder QR of K)
* ``step_backsolve``: V, R, beta, b -> x = K⁻¹ b

Contact-free models get exactly the kernels above.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.assembly.mass import sparse_dm
from ncgen.reproducible import cholesky

#: Largest nnz(V) + nnz(R) of the QR factors for which the solve is unrolled into SX.
SX_QR_MAX_NNZ = 3_000

#: Names of the kernels, in the order the package lists them (the nonsmooth contact
#: stepper appends ``step_contact``, ``step_gap`` and, where small, ``step_factor`` and
#: ``step_backsolve``).
KERNELS = ("step_newton", "step_velocity", "step_check", "step_solve", "step_project", "step_power",
           "step_outputs")

DOCS = {
    "step_newton": {
        "purpose": "Stepper, first half-step: Newton residual r(w, lam_h) and its Jacobian K",
        "inputs": {"t": ("time at the start of the step", "s"), "q": ("coordinates at t", "m"),
                   "v": ("coordinate rates at t", "m/s"), "u": ("inputs, held over the step", ""),
                   "p": ("parameters", ""), "h": ("step", "s"), "w": ("midpoint rates v_{n+1/2}", "m/s"),
                   "lam_h": ("scaled multipliers h/2 lambda", "N s/m^2")},
        "outputs": {"r": ("[M (w - v) - h/2 F + A^T lam_h; Phi(t + h, q + h w) / h]", "N s; m^2/s"),
                    "K": ("dr/d[w; lam_h], sparse", "")}},
    "step_velocity": {
        "purpose": "Stepper, second half-step: KKT matrix and right-hand side for [v+; h/2 mu]",
        "inputs": {"t": ("time at the end of the step", "s"), "q": ("coordinates at the end", "m"),
                   "w": ("midpoint rates", "m/s"), "u": ("inputs, held over the step", ""),
                   "p": ("parameters", ""), "h": ("step", "s")},
        "outputs": {"b": ("[M w + h/2 F; -Phi_t]", "N s; m^2/s"),
                    "K": ("[[M, A^T], [A, 0]] in the pattern of step_newton's K", "")}},
    "step_check": {
        "purpose": "Stepper: constraint residuals of a state",
        "inputs": {"t": ("time", "s"), "q": ("coordinates", "m"), "v": ("coordinate rates", "m/s"),
                   "p": ("parameters", "")},
        "outputs": {"phi_max": ("max |Phi(t, q)|", "m^2"),
                    "phidot_max": ("max |A(t, q) v + Phi_t(t, q)|", "m^2/s")}},
    "step_solve": {
        "purpose": "Stepper: x = K^-1 r (sparse Householder QR in AMD column order, or the Schur "
                   "complement with the constant mass matrix's Cholesky factor)",
        "inputs": {"K": ("KKT matrix in the stepper's pattern", ""), "r": ("right-hand side", "")},
        "outputs": {"x": ("solution", "")}},
    "step_project": {
        "purpose": "Stepper: KKT matrix and constraint residuals for the projection onto both constraint levels",
        "inputs": {"t": ("time", "s"), "q": ("coordinates", "m"), "v": ("coordinate rates", "m/s"),
                   "p": ("parameters", "")},
        "outputs": {"K": ("[[M, A^T], [A, 0]] in the pattern of step_newton's K", ""),
                    "phi": ("Phi(t, q)", "m^2"), "phidot": ("A(t, q) v + Phi_t(t, q)", "m^2/s")}},
    "step_power": {
        "purpose": "Stepper: power of the non-conservative forces and drives, dE/dt",
        "inputs": {"t": ("time", "s"), "q": ("coordinates", "m"), "v": ("coordinate rates", "m/s"),
                   "lam": ("multipliers", "N per unit of Phi"), "u": ("inputs", ""), "p": ("parameters", "")},
        "outputs": {"P": ("[P, P_contacts, P_friction, P_inputs, P_drives]: P = v^T (F + grad V) + dV/dt + "
                          "lam^T Phi_t and its parts (smooth contacts' normal forces less their springs, "
                          "friction, inputs, drives)", "W")}},
    "step_outputs": {
        "purpose": "Stepper: derived quantities of one trajectory sample",
        "inputs": {"t": ("time", "s"), "q": ("coordinates", "m"), "v": ("coordinate rates", "m/s"),
                   "lam": ("multipliers", "N per unit of Phi"), "u": ("inputs", ""), "p": ("parameters", "")},
        "outputs": {"y": ("[T; V; max|Phi|; max|A v + Phi_t|; P; marker positions, column-major]",
                          "J; J; m^2; m^2/s; W; m")}},
}

#: Documentation of the nonsmooth contact stepper's kernels (where they differ).
CONTACT_DOCS = {
    "step_newton": {**DOCS["step_newton"],
                    "inputs": {**DOCS["step_newton"]["inputs"],
                               "j": ("generalised contact impulse W^T P of the step", "N s")},
                    "outputs": {**DOCS["step_newton"]["outputs"],
                                "r": ("[M (w - v) - h/2 F + A^T lam_h - j/2; Phi(t + h, q + h w) / h]",
                                      "N s; m^2/s")}},
    "step_velocity": {**DOCS["step_velocity"],
                      "inputs": {**DOCS["step_velocity"]["inputs"],
                                 "j": ("generalised contact impulse W^T P of the step", "N s")},
                      "outputs": {**DOCS["step_velocity"]["outputs"],
                                  "b": ("[M w + h/2 F + j/2; -Phi_t]", "N s; m^2/s")}},
    "step_contact": {
        "purpose": "Stepper: contact gaps, Jacobians (per contact: normal row, tangent rows) and velocities",
        "inputs": {"q": ("coordinates", "m"), "v": ("coordinate rates", "m/s"), "p": ("parameters", "")},
        "outputs": {"g": ("gaps, positive apart", "m"),
                    "Wt": ("transposed contact Jacobian W^T, nq x nk*dim, sparse (column r: row r of W)", "1"),
                    "U": ("contact velocities W v", "m/s")}},
    "step_gap": {
        "purpose": "Stepper: contact gaps",
        "inputs": {"q": ("coordinates", "m"), "p": ("parameters", "")},
        "outputs": {"g": ("gaps, positive apart", "m")}},
    "step_factor": {
        "purpose": "Stepper: sparse Householder QR of the KKT matrix (for the contact Delassus matrix)",
        "inputs": {"K": ("KKT matrix in the stepper's pattern", "")},
        "outputs": {"V": ("Householder vectors", ""), "R": ("triangular factor", ""),
                    "beta": ("reflector scales", "")}},
    "step_backsolve": {
        "purpose": "Stepper: x = K^-1 b from the factors of step_factor",
        "inputs": {"V": ("Householder vectors", ""), "R": ("triangular factor", ""),
                   "beta": ("reflector scales", ""), "b": ("right-hand side", "")},
        "outputs": {"x": ("solution", "")}},
}


def nonsmooth(model) -> bool:
    """Whether ``model`` gets the nonsmooth contact stepper."""
    return getattr(model, "contact_model", "smooth") == "nonsmooth" and getattr(model, "nk", 0) > 0


def stepper_functions(model, primitives: dict[str, ca.Function] | None = None, pairs=None) -> list[ca.Function]:
    """The kernels of :data:`KERNELS` for ``model`` (see the module docstring), and the contact
    kernels for the nonsmooth contact stepper: the flat ``step_contact`` and ``step_gap``, or
    the element kernels of ``pairs`` (:func:`ncgen.assembly.pair_kernels.pair_kernels`);
    ``primitives`` as in :func:`check_function`."""
    f = model.functions
    nq, nc = model.nq, model.nc
    t, h = ca.SX.sym("t"), ca.SX.sym("h")
    q, v, w = ca.SX.sym("q", nq), ca.SX.sym("v", nq), ca.SX.sym("w", nq)
    lam_h = ca.SX.sym("lam_h", nc)
    u, p = ca.SX.sym("u", model.nu), ca.SX.sym("p", model.np)
    M = sparse_dm(model.M)
    contact = nonsmooth(model)
    j = ca.SX.sym("j", nq) if contact else ca.SX.zeros(nq)
    j_in, j_name = ([j], ["j"]) if contact else ([], [])

    balance = ca.mtimes(M, w - v) - h / 2 * f["F"](t, q, w, u, p) + ca.mtimes(f["A"](t, q, p).T, lam_h)
    r = ca.densify(ca.vertcat(balance - j / 2 if contact else balance, f["phi"](t + h, q + h * w, p) / h))
    K = ca.jacobian(r, ca.vertcat(w, lam_h))
    newton = ca.Function("step_newton", [t, q, v, u, p, h, w, lam_h] + j_in, [r, K],
                         ["t", "q", "v", "u", "p", "h", "w", "lam_h"] + j_name, ["r", "K"])

    A = f["A"](t, q, p)
    momentum = ca.mtimes(M, w) + h / 2 * f["F"](t, q, w, u, p)
    b = ca.densify(ca.vertcat(momentum + j / 2 if contact else momentum, -f["phi_t"](t, q, p)))
    K2 = ca.project(ca.blockcat([[M, A.T], [A, ca.SX(nc, nc)]]), K.sparsity())
    velocity = ca.Function("step_velocity", [t, q, w, u, p, h] + j_in, [b, K2],
                           ["t", "q", "w", "u", "p", "h"] + j_name, ["b", "K"])

    phi = f["phi"](t, q, p)
    project = ca.Function("step_project", [t, q, v, p],
                          [K2, ca.densify(phi), ca.densify(ca.mtimes(A, v) + f["phi_t"](t, q, p))],
                          ["t", "q", "v", "p"], ["K", "phi", "phidot"])
    check = check_function(model, primitives)
    power = power_function(model)
    damped = ca.jacobian(f["F"](t, q, w, u, p), w).sparsity().get_triplet()
    solve = solve_function(K.sparsity(), np.asarray(model.M, dtype=float), set(damped[0]) | set(damped[1]),
                           constant_mass=True)
    out = [newton, velocity, check, solve, project, power,
           outputs_function(model, check, power)]
    if contact:
        out += list(pairs.functions) if pairs is not None else [contact_function(model), gap_function(model)]
        out += factor_functions(K.sparsity())
    return out

def factor_functions(pattern: ca.Sparsity) -> list[ca.Function]:
    """``[step_factor, step_backsolve]`` (see the module docstring), or ``[]`` when the
    factors are too large to unroll (the C then calls ``step_solve`` per contact row)."""
    n = pattern.size1()
    V, R, *_ = ca.qr_sparse(ca.DM(pattern, 1.0), True)
    if V.nnz() + R.nnz() > SX_QR_MAX_NNZ:
        return []
    K = ca.SX.sym("K", pattern)
    V, R, beta, prinv, pc = ca.qr_sparse(K, True)
    factor = ca.Function("step_factor", [K], [V, R, beta], ["K"], ["V", "R", "beta"])
    Vs, Rs, bs = ca.SX.sym("V", V.sparsity()), ca.SX.sym("R", R.sparsity()), ca.SX.sym("beta", beta.shape[0])
    r = ca.SX.sym("r", n)
    backsolve = ca.Function("step_backsolve", [Vs, Rs, bs, r], [ca.qr_solve(r, Vs, Rs, bs, prinv, pc)],
                            ["V", "R", "beta", "b"], ["x"])
    return [factor, backsolve]


def gap_function(model) -> ca.Function:
    """``step_gap: q, p -> g`` (the gaps alone: cheap, for the end-of-step penetration test)."""
    q, p = ca.SX.sym("q", model.nq), ca.SX.sym("p", model.np)
    return ca.Function("step_gap", [q, p], [ca.densify(model.functions["gap"](q, p))], ["q", "p"], ["g"])


def contact_function(model) -> ca.Function:
    """``step_contact: q, v, p -> g, W, U`` (see the module docstring)."""
    q, v, p = ca.SX.sym("q", model.nq), ca.SX.sym("v", model.nq), ca.SX.sym("p", model.np)
    g = model.functions["gap"](q, p)
    WN, WT = model.functions["contact_jacobian"](q, p)
    nt = model.dim - 1
    rows = []
    for k, contact in enumerate(model.contacts):
        rows += [WN[k, :], WT[k * nt:(k + 1) * nt, :] if contact["mu"] > 0 else ca.SX(nt, model.nq)]
    W = ca.vertcat(*rows)
    return ca.Function("step_contact", [q, v, p], [ca.densify(g), W.T, ca.densify(ca.mtimes(W, v))],
                       ["q", "v", "p"], ["g", "Wt", "U"])


#: The parts of ``step_power``'s output after the total (``WORK_CONTACTS`` .. ``WORK_DRIVES``
#: of ``runtime/ncgen_rattle.h``); the dampers' power is the total less these.
POWER_PARTS = ("contacts", "friction", "inputs", "drives")


def power_function(model) -> ca.Function:
    """``step_power``: ``[P, P_contacts, P_friction, P_inputs, P_drives]`` (W), ``P = vᵀ(F +
    ∇V) + ∂V/∂t + λᵀΦ_t``.  Along a motion ``dE/dt = vᵀ M a + ∇V·v + ∂V/∂t`` with ``M a = F −
    Aᵀλ`` and ``A v = −Φ_t``, so ``P`` is exactly the rate of change of ``E = T + V``; it
    vanishes for conservative models.  Its parts: the smooth contacts' normal forces less
    their springs ``−δ̇ (f_N − k δⁿ)`` (the springs are in V), their friction ``f_T·(W_T v)``,
    the inputs ``vᵀ(F(u) − F(0))`` and the drives ``λᵀΦ_t + ∂V/∂t``; the rest, ``vᵀ(F(0) +
    ∇V)`` less the contacts', is the dampers' and every other non-conservative force's."""
    f = model.functions
    t, q, v = ca.SX.sym("t"), ca.SX.sym("q", model.nq), ca.SX.sym("v", model.nq)
    lam, u, p = ca.SX.sym("lam", model.nc), ca.SX.sym("u", model.nu), ca.SX.sym("p", model.np)
    V = ca.sum1(model.potential_terms(t, q, p))
    F = f["F"](t, q, v, u, p)
    inputs = ca.dot(v, F - f["F"](t, q, v, ca.DM.zeros(model.nu), p)) if model.nu else ca.SX(0)
    drives = ca.jacobian(V, t) + ca.dot(lam, ca.densify(f["phi_t"](t, q, p)))
    P = ca.dot(v, F + ca.gradient(V, q)) + drives
    normal, friction = ca.SX(0), ca.SX(0)
    if getattr(model, "nk", 0) and getattr(model, "contact_model", "smooth") == "smooth":
        g = f["gap"](q, p)
        WN, WT = f["contact_jacobian"](q, p)
        fN, fT = f["contact_force"](t, q, v, p)
        rate = -ca.mtimes(WN, v)
        for k, c in enumerate(model.contacts):
            delta = ca.fmax(0, -g[k])
            spring = ca.if_else(delta > 0, c["stiffness"] * delta ** c["exponent"], 0)
            normal += -rate[k] * (fN[k] - spring)
        friction = ca.dot(fT, ca.mtimes(WT, v))
    out = ca.densify(ca.vertcat(P, normal, friction, inputs, drives))
    return ca.Function("step_power", [t, q, v, lam, u, p], [out], ["t", "q", "v", "lam", "u", "p"], ["P"])


def outputs_function(model, check: ca.Function, power: ca.Function) -> ca.Function:
    """``step_outputs`` (MX: calls the energy, marker, check and power functions)."""
    t, q, v = ca.MX.sym("t"), ca.MX.sym("q", model.nq), ca.MX.sym("v", model.nq)
    lam, u, p = ca.MX.sym("lam", model.nc), ca.MX.sym("u", model.nu), ca.MX.sym("p", model.np)
    T, V = model.functions["energy"](t, q, v, p)
    r_max, rd_max = check(t, q, v, p)
    parts = [T, V, r_max, rd_max, power(t, q, v, lam, u, p)[0]]
    if model.marker_names:
        parts.append(ca.vec(model.functions["markers"](q, v)[0]))
    return ca.Function("step_outputs", [t, q, v, lam, u, p], [ca.densify(ca.vertcat(*parts))],
                       ["t", "q", "v", "lam", "u", "p"], ["y"])


def check_function(model, primitives: dict[str, ca.Function] | None = None) -> ca.Function:
    """``step_check``: an SX function of ``model.functions``, or, given ``primitives``
    (``phi``, ``A``, ``phi_t`` as called functions, e.g. the rerolled ones of a large
    model's package, :func:`ncgen.codegen.looped.primitives`), an MX function calling them:
    its two norms couple every constraint, so flat SX would not reroll."""
    if primitives is not None:
        f, sym = primitives, ca.MX
    else:
        f, sym = model.functions, ca.SX
    t, q, v, p = sym.sym("t"), sym.sym("q", model.nq), sym.sym("v", model.nq), sym.sym("p", model.np)
    phidot = ca.mtimes(f["A"](t, q, p), v) + f["phi_t"](t, q, p)
    return ca.Function("step_check", [t, q, v, p],
                       [ca.densify(ca.norm_inf(f["phi"](t, q, p))), ca.densify(ca.norm_inf(phidot))],
                       ["t", "q", "v", "p"], ["phi_max", "phidot_max"])


def solve_function(pattern: ca.Sparsity, mass: np.ndarray | None = None, damped=frozenset(),
                   constant_mass: bool = False) -> ca.Function:
    """``step_solve: (K, r) -> K⁻¹ r`` by sparse Householder QR with an approximate-minimum-
    degree column order (stable without pivoting, so the order depends on the pattern only).

    Up to :data:`SX_QR_MAX_NNZ` nonzeros in the factors it is an SX function: the
    factorisation unrolled into straight-line code, about 15 instructions per nonzero and
    twice as fast as the library routine (the whole step of a 20-bar chain: 15 µs instead
    of 30 µs), but slow to compile (gcc -O2: about 0.3 ms per instruction, 15 s at the
    limit).  Beyond, where K is block diagonal (the connected components of its pattern:
    free bodies, which only contacts couple), each block is solved alone by
    :func:`_block_solves`; else it is an MX function calling CasADi's ``qr`` linear solver,
    generated as loops over the factors' patterns.

    ``mass``: the constant mass matrix M (nq × nq), the upper-left block of every K solved
    except in the coordinates ``damped`` (where ``∂F/∂v`` enters it); given, a block whose
    coordinates are undamped and whose block of M is well conditioned
    (:data:`SCHUR_MAX_COND`) is solved through its Schur complement (:func:`_schur_solve`).
    ``constant_mass``: the upper-left block of K is ``mass`` itself wherever it is undamped
    (no contact impulse or stiffness enters it); then, where the factors are small enough to
    unroll, the whole K undamped and ``mass`` well conditioned, the Schur complement with
    ``mass``'s Cholesky factor as constants in the code (:func:`_mass_schur_solve`) is used
    if it takes fewer instructions than the QR (the 5-bar chain: 1 279 instead of 3 277; not
    the 20-bar chain, whose dense 20×20 complement costs more than K's sparse QR); and per
    diagonal block, its block of ``mass`` in place of H read from K (a rotating sphere's
    15×15 block of u, v, w: 797 instead of 899 instructions)."""
    n = pattern.size1()
    V, R, *_ = ca.qr_sparse(ca.DM(pattern, 1.0), True)
    if V.nnz() + R.nnz() <= SX_QR_MAX_NNZ:
        qr = _sx_solve(pattern, "step_solve")
        schur = _mass_schur_solve(pattern, mass, V.nnz() + R.nnz(), "step_solve") if constant_mass and not damped \
            else None
        return schur if schur is not None and schur.n_instructions() < qr.n_instructions() else qr
    K, r = ca.MX.sym("K", pattern), ca.MX.sym("r", n)
    blocks = _components(pattern)
    schur = _schur_blocks(pattern, blocks, mass, damped)
    x = _block_solves(pattern, blocks, K, r, schur, mass if constant_mass else None) if len(blocks) > 1 \
        else ca.solve(K, r, "qr")
    return ca.Function("step_solve", [K, r], [x], ["K", "r"], ["x"])


#: Largest condition number of a block of M for which its KKT block is solved through the
#: Schur complement (the complement's round-off grows with it; beyond, the block's QR).
SCHUR_MAX_COND = 1e6


def _schur_blocks(pattern: ca.Sparsity, blocks: list[np.ndarray], mass: np.ndarray | None, damped) -> list[int]:
    """Per block of ``blocks`` (in ``pattern``): the number ``nb`` of its leading indices that
    are coordinates (< nq) if it is solved through its Schur complement (constraint rows after
    them with no nonzero among themselves, its coordinates undamped, their block of ``mass``
    regular to :data:`SCHUR_MAX_COND`), else 0."""
    out = []
    for idx in blocks:
        nb = int(np.sum(idx < mass.shape[0])) if mass is not None else 0
        rows = idx[nb:].tolist()
        if (0 < nb < len(idx) and not damped.intersection(idx[:nb].tolist())
                and pattern.sub(rows, rows)[0].nnz() == 0):
            Mb = mass[np.ix_(idx[:nb], idx[:nb])]
            nb = nb if np.all(np.isfinite(Mb)) and np.linalg.cond(Mb) <= SCHUR_MAX_COND else 0
        else:
            nb = 0
        out.append(nb)
    return out


def _sx_solve(pattern: ca.Sparsity, name: str) -> ca.Function:
    """``name: (K, r) -> K⁻¹ r``, K of ``pattern``: the sparse QR unrolled into SX."""
    K, r = ca.SX.sym("K", pattern), ca.SX.sym("r", pattern.size1())
    V, R, beta, prinv, pc = ca.qr_sparse(K, True)
    return ca.Function(name, [K, r], [ca.qr_solve(r, V, R, beta, prinv, pc)], ["K", "r"], ["x"])


def _components(pattern: ca.Sparsity) -> list[np.ndarray]:
    """The diagonal blocks of a square ``pattern``: the connected components of the graph
    with an edge i–j for each structural nonzero (i, j), each as its sorted indices."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rows, cols = pattern.get_triplet()
    n = pattern.size1()
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    count, label = connected_components(graph, directed=False)
    return [np.flatnonzero(label == k) for k in range(count)]


def _block_solves(pattern: ca.Sparsity, blocks: list[np.ndarray], K: ca.MX, r: ca.MX, schur: list[int],
                  mass: np.ndarray | None = None) -> ca.MX:
    """K⁻¹ r for a block-diagonal K (``blocks``: the indices of each diagonal block, which
    together cover every row once): x_b = K_bb⁻¹ r_b per block, the blocks grouped by their
    pattern, one solve function per pattern (:func:`_schur_solve` where ``schur`` gives the
    block's number of coordinates, else the SX-unrolled QR where its factors are small enough,
    else CasADi's ``qr``) mapped over its group's blocks (one copy of the code).  The QR per
    block is the same as of the whole matrix, in a column order found per block.  Given the
    constant ``mass`` (the upper-left block of every K solved), a Schur block's group is also
    keyed by its block M_b, and solved with M_b's Cholesky factor as constants
    (:func:`_mass_schur_solve`) where that takes fewer instructions."""
    groups: dict[tuple, list[np.ndarray]] = {}
    for idx, nb in zip(blocks, schur):
        sub, _ = pattern.sub(idx.tolist(), idx.tolist())
        Mb = mass[np.ix_(idx[:nb], idx[:nb])].tobytes() if nb and mass is not None else None
        key = (sub.size1(), tuple(sub.colind()), tuple(sub.row()), Mb, nb)
        groups.setdefault(key, []).append(idx)
    parts, order = [], []
    for g, (key, members) in enumerate(groups.items()):
        idx0 = members[0].tolist()
        sub, _ = pattern.sub(idx0, idx0)
        V, R, *_ = ca.qr_sparse(ca.DM(sub, 1.0), True)
        if key[-1]:
            f = _schur_solve(sub, key[-1], f"step_solve_block{g}")
            nb = key[-1]
            fm = _mass_schur_solve(sub, mass[np.ix_(members[0][:nb], members[0][:nb])], None,
                                   f"step_solve_block{g}") if key[-2] is not None else None
            f = fm if fm is not None and fm.n_instructions() < f.n_instructions() else f
        elif V.nnz() + R.nnz() <= SX_QR_MAX_NNZ:
            f = _sx_solve(sub, f"step_solve_block{g}")
        else:
            Kb, rb = ca.MX.sym("K", sub), ca.MX.sym("r", sub.size1())
            f = ca.Function(f"step_solve_block{g}", [Kb, rb], [ca.solve(Kb, rb, "qr")], ["K", "r"], ["x"])
        Ks = ca.horzcat(*[K[idx.tolist(), idx.tolist()] for idx in members])
        rs = ca.horzcat(*[r[idx.tolist()] for idx in members])
        parts.append(ca.vec(f.map(len(members), "serial")(Ks, rs)))
        order.extend(np.concatenate(members).tolist())
    inverse = np.empty(len(order), dtype=int)
    inverse[order] = np.arange(len(order))
    return ca.vertcat(*parts)[inverse.tolist()]


def _schur_solve(pattern: ca.Sparsity, nb: int, name: str) -> ca.Function:
    """``name: (K, r) -> K⁻¹ r`` for a KKT block ``K = [[H, B], [C, 0]]`` of ``pattern`` with
    H (nb × nb) regular: ``S = C H⁻¹ B``, ``S y = C H⁻¹ r₁ − r₂``, ``x = H⁻¹ (r₁ − B y)``, H
    and S each by its sparse QR unrolled into SX (a free body's 15×15 block: 900 instructions
    instead of the whole block's QR's 2 100).  S is regular where K is; H is read from K."""
    K, r = ca.SX.sym("K", pattern), ca.SX.sym("r", pattern.size1())
    H, B, C = K[:nb, :nb], K[:nb, nb:], K[nb:, :nb]
    V, R, beta, prinv, pc = ca.qr_sparse(H, True)
    HB = ca.horzcat(*[ca.qr_solve(B[:, j], V, R, beta, prinv, pc) for j in range(B.shape[1])])
    Hr = ca.qr_solve(r[:nb], V, R, beta, prinv, pc)
    S = ca.mtimes(C, HB)
    V2, R2, beta2, prinv2, pc2 = ca.qr_sparse(S, True)
    y = ca.qr_solve(ca.mtimes(C, Hr) - r[nb:], V2, R2, beta2, prinv2, pc2)
    return ca.Function(name, [K, r], [ca.vertcat(Hr - ca.mtimes(HB, y), y)], ["K", "r"], ["x"])


def _mass_schur_solve(pattern: ca.Sparsity, mass: np.ndarray | None, qr_size: int | None, name: str) \
        -> ca.Function | None:
    """``name: (K, r) -> K⁻¹ r`` for ``K = [[M, B], [C, 0]]`` of ``pattern`` whose upper-left
    block is the constant ``mass`` M (nq × nq, the first nq rows; B and C read from K):
    ``S = C M⁻¹ B``, ``S y = C M⁻¹ r₁ − r₂``, ``x = [M⁻¹ (r₁ − B y); y]``, M⁻¹ applied by the
    triangular solves of its Cholesky factor L (constants, its zeros skipped: a chain's M is
    banded and so is L) and S by its sparse QR unrolled into SX.  None where it does not
    apply: no mass, M not positive definite or worse conditioned than
    :data:`SCHUR_MAX_COND`, nonzeros in K's lower-right block, or more than ``qr_size``
    (the nonzeros of K's QR factors; ``None``: no such bound, for a small block) cubed
    constraints, as the dense complement's QR alone takes about nc³ instructions (K's QR
    about 15 per nonzero).  L is computed without
    BLAS (:func:`ncgen.reproducible.cholesky`: the constants are the same on every CPU)."""
    nq = 0 if mass is None else mass.shape[0]
    n = pattern.size1()
    if not 0 < nq < n or (qr_size is not None and (n - nq) ** 3 > qr_size) or pattern.sub(list(range(nq, n)), list(range(nq, n)))[0].nnz():
        return None
    if not np.all(np.isfinite(mass)) or np.linalg.cond(mass) > SCHUR_MAX_COND:
        return None
    try:
        L = cholesky(mass)
    except ValueError:
        return None
    K, r = ca.SX.sym("K", pattern), ca.SX.sym("r", n)
    B, C = K[:nq, nq:], K[nq:, :nq]
    MB = ca.horzcat(*[_cholesky_solve(L, [B[i, j] for i in range(nq)]) for j in range(n - nq)])
    Mr = _cholesky_solve(L, [r[i] for i in range(nq)])
    V, R, beta, prinv, pc = ca.qr_sparse(ca.mtimes(C, MB), True)
    y = ca.qr_solve(ca.mtimes(C, Mr) - r[nq:], V, R, beta, prinv, pc)
    return ca.Function(name, [K, r], [ca.vertcat(Mr - ca.mtimes(MB, y), y)], ["K", "r"], ["x"])


def _cholesky_solve(L: np.ndarray, b: list) -> ca.SX:
    """``(L Lᵀ)⁻¹ b`` by forward and back substitution, ``L`` lower triangular (numbers, its
    zeros skipped; a product with the inverse of its diagonal, no division), ``b`` a list of
    SX scalars."""
    n, inverse = len(b), 1 / np.diag(L)
    y = [None] * n
    for i in range(n):
        s = b[i]
        for j in np.flatnonzero(L[i, :i]):
            s = s - L[i, j] * y[j]
        y[i] = s * inverse[i]
    x = [None] * n
    for i in reversed(range(n)):
        s = y[i]
        for j in i + 1 + np.flatnonzero(L[i + 1:, i]):
            s = s - L[j, i] * x[j]
        x[i] = s * inverse[i]
    return ca.vertcat(*x)


def mass_scale(model) -> float:
    """``m̄ = max |M_ij|`` (kg): the scale of the momentum residual in the convergence test."""
    return float(np.max(np.abs(model.M))) if model.nq else 1.0
