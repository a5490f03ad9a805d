"""The whole-system CasADi functions (the contract every backend consumes).

Arguments: ``t`` (s), ``q`` (natural coordinates, m), ``v = q̇``, ``lam`` (multipliers),
``u`` (inputs), ``p`` (parameters).  Equations of motion (docs/architecture.md)::

    M q̈ + Aᵀ λ = F(t, q, v, u, p),   Φ(t, q) = 0   ⇒   A q̈ = γ,
    γ = −(∂(A v)/∂q) v − 2 ∂(A v)/∂t − Φ_tt

(for the scleronomic, quadratic constraints ``γ_k = −vᵀ H_k v`` with constant ``H_k``:
forward-mode AD of the linear-in-q product ``A v`` yields exactly that).  The index-1 DAE
integrated by IDAS has ``x = [q; v]``, ``z = λ`` and

    q̇ = v,   v̇ = a = M⁻¹ (F − Aᵀ λ),   0 = A a − γ + 2α Φ̇ + β² Φ     (Baumgarte).

Functions (name: inputs -> outputs):

* ``phi``: t, q, p -> phi;  ``A``: t, q, p -> A (sparse);  ``phi_t``: t, q, p -> phi_t
* ``gamma``: t, q, v, p -> gamma;  ``F``: t, q, v, u, p -> F;  ``Minv``: b -> x = M⁻¹ b
* ``mass``: () -> M  (the constant mass matrix, sparse)
* ``ode``: t, q, v, lam, u, p -> qdot, vdot;  ``alg``: t, q, v, lam, u, p -> res
* ``dae``: t, x, z, u, p -> ode, alg  (IDAS's form, ``x = [q; v]``, ``z = [a; λ]``, see below)
* ``accel``: t, q, v, u, p -> a, lam  (the KKT system solved, Baumgarte terms included)
* ``energy``: t, q, v, p -> T, V;  ``markers``: q, v -> r, rdot (dim × n_markers)
* ``poses``: q -> R (dim × dim·n_members), p (dim × n_members)

``dae`` keeps the accelerations among the algebraic states, ``ode = [v; a]``,
``alg = [M a + Aᵀλ − F; A a − γ + 2α Φ̇ + β² Φ]``: its Jacobian is as sparse as ``M`` and
``A`` (O(n) nonzeros), whereas eliminating ``a = M⁻¹(F − Aᵀλ)`` makes it dense wherever
``M⁻¹`` is — for a chain of n bars, O(n²) nonzeros and as many instructions in its C kernel.

Every function is an SX function except ``accel`` (MX: it calls the others and CasADi's
sparse QR).  :data:`DOCS` gives the meaning and units of each function and argument; it is
the one source of the generated C header's documentation (:mod:`ncgen.codegen.model_package`).
"""
from __future__ import annotations

import functools
from typing import Sequence

import casadi as ca
import numpy as np

from ncgen.assembly.mass import CholeskyFactor, SingularMass, sparse_dm
from ncgen.model.context import Context

#: Inputs shared by the functions: name -> (meaning, SI units).
IN = {
    "t": ("time", "s"),
    "q": ("natural coordinates q: basic points and base vectors of every member, layout order "
          "(see coordinate_names)", "m"),
    "v": ("coordinate rates q̇", "m/s"),
    "lam": ("Lagrange multipliers λ, one per constraint (Aᵀλ is the constraint force)",
            "N per unit of Φ"),
    "u": ("inputs, in the order of input_names", "SI units of each input"),
    "p": ("parameters, in the order of parameter_names", "SI units of each parameter"),
    "b": ("right-hand side: a generalised force", "N"),
    "x": ("state [q; v]", "m, m/s"),
    "z": ("algebraic state [a; λ]: the accelerations q̈ and the Lagrange multipliers", "m/s², N per unit of Φ"),
}

#: Every function of :func:`system_functions`: its purpose and its outputs, name -> (meaning,
#: SI units).  Inputs are documented by :data:`IN`.
DOCS = {
    "phi": ("constraint residuals Φ(t, q): intrinsic constraints of every member, then joint "
            "equations, in the order of constraint_names",
            {"phi": ("Φ", "m² or m, per constraint")}),
    "A": ("constraint Jacobian A = ∂Φ/∂q (sparse, linear in q)",
          {"A": ("A, nc × nq", "m or 1")}),
    "phi_t": ("explicit time derivative ∂Φ/∂t (non-zero for driven joints only)",
              {"phi_t": ("∂Φ/∂t", "units of Φ per s")}),
    "gamma": ("acceleration right-hand side γ = −(∂(A q̇)/∂q) q̇ − 2 ∂(A q̇)/∂t − Φ_tt, "
              "so that A q̈ = γ",
              {"gamma": ("γ", "units of Φ per s²")}),
    "F": ("generalised applied force F(t, q, q̇, u, p): gravity and force elements",
          {"F": ("F", "N (N·m for rows of base vectors)")}),
    "mass": ("the constant mass matrix M (sparse; no inputs)",
             {"M": ("M, nq × nq", "kg (kg·m for mixed point/vector entries, kg·m² for vector/vector)")}),
    "Minv": ("application of the constant inverse mass matrix: x = M⁻¹ b (two sparse "
             "triangular solves with the Cholesky factor of M); for a singular M (a flat body) "
             "the pseudo-inverse M⁺ b",
             {"x": ("M⁻¹ b", "m/s²")}),
    "ode": ("differential part of the index-1 DAE: q̇ = v, v̇ = a = M⁻¹ (F − Aᵀ λ) (for a "
            "singular M, from the augmented mass matrix M + κ AᵀA, exact where A a = γ)",
            {"qdot": ("q̇", "m/s"), "vdot": ("q̈ = a", "m/s²")}),
    "alg": ("algebraic residual of the index-1 DAE: A a − γ + 2α Φ̇ + β² Φ (Baumgarte "
            "stabilised acceleration constraints)",
            {"res": ("residual, zero on solutions", "units of Φ per s²")}),
    "dae": ("the index-1 DAE in IDAS's form, ẋ = ode, 0 = alg, with x = [q; v], z = [a; λ], ode = [v; a] "
            "and alg = [M a + Aᵀλ − F; A a − γ + 2α Φ̇ + β² Φ] (sparse Jacobian)",
            {"ode": ("ẋ = [q̇; q̈]", "m/s, m/s²"),
             "alg": ("equations of motion and Baumgarte-stabilised acceleration constraints", "N; units of Φ per s²")}),
    "accel": ("accelerations and multipliers from the KKT system [[M, Aᵀ], [A, 0]] [a; λ] = "
              "[F; γ − 2α Φ̇ − β² Φ], solved by sparse QR",
              {"a": ("q̈", "m/s²"), "lam": ("λ", "N per unit of Φ")}),
    "energy": ("kinetic energy T = ½ q̇ᵀ M q̇ and potential energy V (gravity and springs)",
               {"T": ("kinetic energy", "J"), "V": ("potential energy", "J")}),
    "markers": ("world positions and velocities of the named markers, one column each, in "
                "the order of marker_names",
                {"r": ("positions, dim × n_markers", "m"), "rdot": ("velocities, dim × n_markers", "m/s")}),
    "poses": ("pose of every member: rotation local → world and centre of mass, one block "
              "each, in the order of member_names",
              {"R": ("rotations, dim × dim·n_members", "1"), "p": ("centres of mass, dim × n_members", "m")}),
}


def system_functions(ctx: Context, phi, F, V, M: np.ndarray, factor: CholeskyFactor | SingularMass, alpha: float,
                     beta: float, system) -> tuple[dict, ca.Function]:
    """The makers of the functions of :data:`DOCS` by name (each ``maker(functions) ->
    ca.Function``, run on first access by :class:`~ncgen.model.function_set.FunctionSet`), and
    ``V: t, q, p -> V`` (the terms of the potential energy, column ``V`` of
    :func:`~ncgen.assembly.build.force_terms`).  ``Minv``, ``mass``, ``markers``, ``poses``
    and the composites are partials of module-level functions (they stay lazy in a stored
    model); the others close over the assembly's expressions."""
    t, q, v, u, p = ctx.t, ctx.q, ctx.v, ctx.u, ctx.p
    symbols = {"t": t, "q": q, "v": v, "u": u, "p": p}

    @functools.cache
    def jacobian():
        return ca.jacobian(phi, q)

    @functools.cache
    def phi_t():
        return ca.jacobian(phi, t)

    def gamma():
        Av = ca.mtimes(jacobian(), v)
        return -(ca.jtimes(Av, q, v) + 2 * ca.jacobian(Av, t) + ca.jacobian(phi_t(), t))

    def function(name, ins, outs, out_names):
        return lambda _: ca.Function(name, [symbols[i] for i in ins], outs(), list(ins), out_names)

    Msp = sparse_dm(M)
    makers = {
        "phi": function("phi", ("t", "q", "p"), lambda: [phi], ["phi"]),
        "A": function("A", ("t", "q", "p"), lambda: [jacobian()], ["A"]),
        "phi_t": function("phi_t", ("t", "q", "p"), lambda: [phi_t()], ["phi_t"]),
        "gamma": function("gamma", ("t", "q", "v", "p"), lambda: [gamma()], ["gamma"]),
        "F": function("F", ("t", "q", "v", "u", "p"), lambda: [F], ["F"]),
        "mass": functools.partial(_mass, Msp),
        "Minv": functools.partial(_minv, factor, ctx.layout.nq),
        "markers": functools.partial(_member_function, "markers", system, ctx.layout),
        "poses": functools.partial(_member_function, "poses", system, ctx.layout),
    }
    potential = ca.Function("V", [t, q, p], [V], ["t", "q", "p"], ["V"])
    for name in COMPOSITES:
        makers[name] = functools.partial(_composite, name, potential, Msp, alpha, beta, factor.regular)
    return {name: makers[name] for name in FUNCTIONS}, potential


def _member_function(name: str, system, layout, _functions) -> ca.Function:
    """``markers: q, v -> r, rdot`` or ``poses: q -> R, p`` of ``system``'s members, in a
    context of their own (so that a stored model makes them on first use too)."""
    ctx = Context(system, layout)
    if name == "markers":
        return ca.Function("markers", [ctx.q, ctx.v], list(_markers(ctx, system)), ["q", "v"], ["r", "rdot"])
    return ca.Function("poses", [ctx.q], list(_poses(ctx, system)), ["q"], ["R", "p"])


def _mass(M: ca.DM, _functions) -> ca.Function:
    """``mass: () -> M``, the constant sparse mass matrix."""
    return ca.Function("mass", [], [M], [], ["M"])


def _minv(factor: CholeskyFactor | SingularMass, nq: int, _functions) -> ca.Function:
    """``Minv: b -> M⁻¹ b`` (``M⁺ b`` for a singular ``M``) by the constant factor."""
    b = ca.SX.sym("b", nq)
    return ca.Function("Minv", [b], [factor.solve(b) if factor.regular else factor.pseudo_solve(b)], ["b"], ["x"])


def _composite(name: str, potential: ca.Function, M: ca.DM, alpha: float, beta: float, regular: bool,
               functions) -> ca.Function:
    """The composite ``name`` of :func:`composite_functions` from the model's primitives."""
    return composite_functions(functions, potential, M, alpha, beta, ca.SX, (name,), regular=regular)[name]


#: The system functions, in the order of :data:`DOCS`.
FUNCTIONS = tuple(DOCS)


#: The functions :func:`composite_functions` builds from the primitives.
COMPOSITES = ("ode", "alg", "dae", "energy", "accel")


def composite_functions(f: dict, potential: ca.Function, M: ca.DM, alpha: float, beta: float,
                        sym, names: Sequence[str] = COMPOSITES, regular: bool = True) -> dict[str, ca.Function]:
    """The functions ``names`` (of ``ode``, ``alg``, ``dae``, ``energy``, ``accel``) from the
    primitive functions ``f`` (``phi``, ``A``, ``phi_t``, ``gamma``, ``F``, ``Minv``) and
    ``potential: t, q, p -> V``, the terms of the potential energy.

    ``sym`` is the symbol type of the result: ``ca.SX`` inlines the primitives (one flat
    expression per function, the model's form), ``ca.MX`` keeps them as calls (the form of
    very large models, whose primitives are rerolled, see :mod:`ncgen.codegen.reroll`).
    ``accel`` is MX either way (it calls CasADi's sparse QR).

    ``regular=False`` (a singular ``M``, :mod:`ncgen.assembly.mass`): ``ode`` and ``alg`` are
    :func:`_augmented_ode_alg` (MX, sparse QR of the augmented mass matrix)."""
    nc, nq = f["A"].size1_out(0), f["A"].size2_out(0)
    nu, npar = f["F"].numel_in(3), f["F"].numel_in(4)
    t, q, v = sym.sym("t"), sym.sym("q", nq), sym.sym("v", nq)
    lam, u, p = sym.sym("lam", nc), sym.sym("u", nu), sym.sym("p", npar)

    @functools.cache
    def ode_alg():
        if not regular:
            return _augmented_ode_alg(f, M, alpha, beta, nq, nc, nu, npar)
        A = f["A"](t, q, p)
        phidot = ca.mtimes(A, v) + f["phi_t"](t, q, p)
        a = f["Minv"](f["F"](t, q, v, u, p) - ca.mtimes(A.T, lam))
        alg = ca.mtimes(A, a) - f["gamma"](t, q, v, p) + 2 * alpha * phidot + beta**2 * f["phi"](t, q, p)
        return a, alg

    def energy():
        T = 0.5 * ca.dot(v, ca.mtimes(M, v))
        return _function("energy", [t, q, v, p], [T, ca.sum1(potential(t, q, p))], ["t", "q", "v", "p"],
                         ["T", "V"])

    makers = {
        "ode": lambda: ode_alg()[0] if not regular else
        _function("ode", [t, q, v, lam, u, p], [v, ode_alg()[0]], ["t", "q", "v", "lam", "u", "p"], ["qdot", "vdot"]),
        "alg": lambda: ode_alg()[1] if not regular else
        _function("alg", [t, q, v, lam, u, p], [ode_alg()[1]], ["t", "q", "v", "lam", "u", "p"], ["res"]),
        "dae": lambda: _dae(f, M, alpha, beta, nq, nc, nu, npar, sym),
        "energy": energy,
        "accel": lambda: _accel(f, M, nc, alpha, beta, nq, nu, npar),
    }
    unknown = sorted(set(names) - set(makers))
    if unknown:
        raise ValueError(f"composite_functions: unknown function(s) {unknown}; expected some of {COMPOSITES}")
    return {name: makers[name]() for name in names}


def _markers(ctx: Context, system):
    rs, rds = [], []
    for m in system.members.values():
        for local in m.markers.values():
            r, rd = ctx.local_point(m, local)
            rs.append(r)
            rds.append(rd)
    if not rs:
        return ca.SX(ctx.dim, 0), ca.SX(ctx.dim, 0)
    return ca.horzcat(*rs), ca.horzcat(*rds)


def _poses(ctx: Context, system):
    Rs, ps = [], []
    for m in system.members.values():
        ps.append(ctx.instantiate(m, "p"))
        Rs.append(ctx.instantiate(m, "R") if m.ctype.kind != "point" else ca.SX.eye(ctx.dim))
    return ca.horzcat(*Rs), ca.horzcat(*ps)


def _dae(f, M: ca.DM, alpha: float, beta: float, nq: int, nc: int, nu: int, npar: int, sym) -> ca.Function:
    """IDAS's form: ``x = [q; v]``, ``z = [a; λ]``, ``ẋ = [v; a]``,
    ``0 = [M a + Aᵀλ − F; A a − γ + 2α Φ̇ + β² Φ]`` (index 1: ∂alg/∂z is the KKT matrix)."""
    t, x, z = sym.sym("t"), sym.sym("x", 2 * nq), sym.sym("z", nq + nc)
    u, p = sym.sym("u", nu), sym.sym("p", npar)
    q, v, a, lam = x[:nq], x[nq:], z[:nq], z[nq:]
    A = f["A"](t, q, p)
    phidot = ca.mtimes(A, v) + f["phi_t"](t, q, p)
    alg = ca.vertcat(ca.mtimes(M, a) + ca.mtimes(A.T, lam) - f["F"](t, q, v, u, p),
                     ca.mtimes(A, a) - f["gamma"](t, q, v, p) + 2 * alpha * phidot + beta**2 * f["phi"](t, q, p))
    return _function("dae", [t, x, z, u, p], [ca.vertcat(v, a), alg], ["t", "x", "z", "u", "p"], ["ode", "alg"])


def _function(name: str, ins: list, outs: list, in_names: list[str], out_names: list[str]) -> ca.Function:
    """A function of a composition; an SX one with common subexpressions of the inlined
    primitives merged (``A`` evaluated by ``A`` and inside ``gamma``, for instance)."""
    if isinstance(ins[0], ca.SX):
        outs = ca.cse(outs)
    return ca.Function(name, ins, outs, in_names, out_names)


def _augmented_ode_alg(f, M: ca.DM, alpha: float, beta: float, nq: int, nc: int, nu: int,
                       npar: int) -> tuple[ca.Function, ca.Function]:
    """``ode`` and ``alg`` of a singular ``M`` (a flat body): ``M̄ a = F − Aᵀλ + κ Aᵀc`` with
    ``M̄ = M + κ AᵀA``, ``c = γ − 2αΦ̇ − β²Φ`` and ``alg = A a − c``, so that ``M a = F − Aᵀλ``
    wherever ``alg`` vanishes.  ``M̄`` depends on ``q``: MX functions calling the primitives
    and CasADi's sparse QR (as ``accel``), not an SX expansion of its inverse (O(nq³)).
    ``κ = max diag M`` (constraint rows are O(1) in natural coordinates); it only scales."""
    t, q, v = ca.MX.sym("t"), ca.MX.sym("q", nq), ca.MX.sym("v", nq)
    lam, u, p = ca.MX.sym("lam", nc), ca.MX.sym("u", nu), ca.MX.sym("p", npar)
    A = f["A"](t, q, p)
    phidot = ca.mtimes(A, v) + f["phi_t"](t, q, p)
    c = f["gamma"](t, q, v, p) - 2 * alpha * phidot - beta**2 * f["phi"](t, q, p)
    k = float(np.max(np.array(ca.diag(M)), initial=1.0))
    a = ca.solve(ca.MX(M) + k * ca.mtimes(A.T, A), f["F"](t, q, v, u, p) - ca.mtimes(A.T, lam - k * c), "qr")
    ins, names = [t, q, v, lam, u, p], ["t", "q", "v", "lam", "u", "p"]
    return (ca.Function("ode", ins, [v, a], names, ["qdot", "vdot"]),
            ca.Function("alg", ins, [ca.mtimes(A, a) - c], names, ["res"]))


def _accel(f, M: ca.DM, nc: int, alpha: float, beta: float, nq: int, nu: int, npar: int,
           name: str = "accel") -> ca.Function:
    """Explicit KKT form: ``[[M, Aᵀ], [A, 0]] [a; λ] = [F; γ − 2αΦ̇ − β²Φ]`` solved by
    CasADi's sparse QR (an MX function calling the SX functions above); with ``α = β = 0``
    the unstabilised forward dynamics (:func:`ncgen.assembly.derived.kkt_qr_function`)."""
    t, q, v = ca.MX.sym("t"), ca.MX.sym("q", nq), ca.MX.sym("v", nq)
    u, p = ca.MX.sym("u", nu), ca.MX.sym("p", npar)
    A = f["A"](t, q, p)
    c = f["gamma"](t, q, v, p)
    if alpha or beta:                    # α = β = 0: Φ and Φ_t are not evaluated at all
        phidot = ca.mtimes(A, v) + f["phi_t"](t, q, p)
        c = c - 2 * alpha * phidot - beta**2 * f["phi"](t, q, p)
    rhs = ca.vertcat(f["F"](t, q, v, u, p), c)
    if nc == 0:
        # a = M⁻¹ F with M constant: CasADi 3.8 serialises a QR solve whose matrix is structurally
        # diagonal (point masses) but cannot read it back, and built models are stored serialised
        sol = ca.mtimes(ca.MX(sparse_dm(np.linalg.inv(np.array(M, dtype=float)))), rhs)
    else:
        sol = ca.solve(ca.blockcat([[ca.MX(M), A.T], [A, ca.MX(nc, nc)]]), rhs, "qr")
    return ca.Function(name, [t, q, v, u, p], [sol[:nq], sol[nq:]],
                       ["t", "q", "v", "u", "p"], ["a", "lam"])
