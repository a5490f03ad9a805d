"""Natural-coordinate types, derived with SymPy from the seed's definitions.

A member (rigid body, rigid bar or point) of dimension ``dim`` (2 or 3) is described by
basic points ``r_i, r_j, r_k, r_l`` and base vectors ``u, v, w``.  The type's name lists
its slots in the seed's order, points first: slot 0 is always the basic point ``r_i``;
slot ``s >= 1`` is either a basic point (letter ``r``) or a base vector (``u, v, w``).
The base vectors are ``x_s = slot_s`` (vector) or ``x_s = slot_s - r_i`` (point), and the
matrix ``X = [x_1 ... x_k]`` spans the member's affine frame.

Everything below is *derived* from those definitions (nothing typed by hand):

* ``q_ruvw = Y q`` — conversion matrix, the Jacobian of ``[r_i; x_1; ...; x_k]`` w.r.t. ``q``;
* ``r = C(c) q`` — transformation of a body-fixed point with affine coordinates ``c``;
* ``Φ(q)`` — intrinsic (rigidity) constraints ``x_sᵀ x_t − x̄_sᵀ x̄_t`` for the seed's pairs;
* ``Φ_q`` and the constant Hessians ``H_k = ∂²Φ_k/∂q²``;
* ``M = Yᵀ (G ⊗ 1) Y`` with the generalised inertia ``G = [[m, m c_gᵀ], [m c_g, B]]``,
  ``c_g = X̄⁺ (r̄_g − r̄_i)`` and ``B = ∫ρ c cᵀ = X̄⁺ (J̄ + m r̄_i r̄_iᵀ) X̄⁺ᵀ`` (local frame at
  the centre of mass, ``r̄_g = 0``), ``J̄ = ½ tr(Ī) 1 − Ī`` for a 3D body, ``½ Ī 1`` for a
  planar body (``Ī`` its scalar moment) and ``diag(Ī_t, 0, ...)`` for a bar (``Ī_t`` its
  transverse moment);
* the pose ``R(q)``, ``p(q)`` and the angular velocity ``ω(q, q̇)`` of the member.

Derivations are cached: each type is derived once per process.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache
from typing import TYPE_CHECKING

from ncgen.errors import CoordinateTypeError
from ncgen.symbolic.notation import AXES, POINT_NAMES, VECTOR_NAMES

if TYPE_CHECKING:
    import sympy as sp

#: Known types per dimension, with their kind.
TYPES: dict[int, dict[str, str]] = {
    3: {"ruvw": "body", "rrvw": "body", "rrrw": "body", "rrrr": "body",
        "ru": "bar", "rr": "bar", "r": "point"},
    2: {"ruv": "body", "rrv": "body", "rrr": "body", "ru": "bar", "rr": "bar", "r": "point"},
}



def available_types(dim: int | None = None) -> list[tuple[int, str]]:
    """All (dim, name) pairs, 3D first."""
    dims = (3, 2) if dim is None else (dim,)
    return [(d, n) for d in dims for n in TYPES[d]]


def coordinate_type(name: str, dim: int = 3) -> "CoordinateType":
    """The coordinate type ``name`` in dimension ``dim``; raises :class:`CoordinateTypeError`."""
    if dim not in TYPES:
        raise CoordinateTypeError(f"dimension: expected 2 or 3, got {dim!r}")
    if not isinstance(name, str) or name not in TYPES[dim]:
        known = ", ".join(TYPES[dim])
        other = [d for d in TYPES if d != dim and name in TYPES[d]]
        hint = f" ({name!r} exists in {other[0]}D)" if other else ""
        raise CoordinateTypeError(
            f"coordinate type: expected one of {known} for dim={dim}, got {name!r}{hint}")
    return _coordinate_type(name, int(dim))


@lru_cache(maxsize=None)
def _coordinate_type(name: str, dim: int) -> "CoordinateType":
    return CoordinateType(name, dim)


def component_names(prefix: str, dim: int) -> list[str]:
    """Names of a vector's components: ``u`` -> u_x, u_y, ...; ``r_i`` -> r_ix, r_iy, ..."""
    sep = "" if "_" in prefix else "_"
    return [f"{prefix}{sep}{a}" for a in AXES[:dim]]


def symmetric_names(name: str, n: int) -> list[list[str]]:
    """Names of a symmetric n×n matrix's entries, ``name_ab`` (a ≤ b), row by row."""
    return [[f"{name}_{min(a, b) + 1}{max(a, b) + 1}" for b in range(n)] for a in range(n)]


def matrix_names(name: str, n: int) -> list[list[str]]:
    """Names of an n×n matrix's entries, ``name_ab``, row by row."""
    return [[f"{name}_{a + 1}{b + 1}" for b in range(n)] for a in range(n)]


def com_names(k: int) -> list[str]:
    """Names of the centre of mass's affine coordinates c_g1, c_g2, ..."""
    return [f"c_g{s}" for s in range(1, k + 1)]


def _vec(prefix: str, dim: int) -> sp.Matrix:
    """Component symbols (:func:`component_names`; SymPy renders ``ubar_x`` as ū_x and
    ``rdot_ix`` as ṙ_ix)."""
    import sympy as sp
    return sp.Matrix([sp.Symbol(n, real=True) for n in component_names(prefix, dim)])


def _sym_matrix(name: str, n: int) -> sp.Matrix:
    """Symmetric n×n matrix of symbols ``name_ab`` (a ≤ b)."""
    import sympy as sp
    names = symmetric_names(name, n)
    return sp.Matrix(n, n, lambda a, b: sp.Symbol(names[a][b], real=True))


def _skew_vee(S: sp.Matrix, dim: int):
    """vee of the skew-symmetric part of ``S``: a 3-vector in 3D, a scalar in 2D."""
    import sympy as sp
    if dim == 3:
        return sp.Matrix([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]]) / 2
    return sp.Matrix([(S[1, 0] - S[0, 1]) / 2])


def _cross(a: sp.Matrix, b: sp.Matrix, dim: int) -> sp.Matrix:
    import sympy as sp
    if dim == 3:
        return a.cross(b)
    return sp.Matrix([a[0] * b[1] - a[1] * b[0]])


@dataclass(frozen=True)
class CoordinateType:
    """One natural-coordinate type; its SymPy derivation is built lazily and cached."""

    name: str
    dim: int

    # ------------------------------------------------------------------ layout
    @property
    def kind(self) -> str:
        """``"body"``, ``"bar"`` or ``"point"``."""
        return TYPES[self.dim][self.name]

    @property
    def k(self) -> int:
        """Number of base vectors (columns of X): dim for bodies, 1 for bars, 0 for points."""
        return len(self.name) - 1

    @property
    def nq(self) -> int:
        return self.dim * len(self.name)

    @property
    def pairs(self) -> list[tuple[int, int]]:
        """Index pairs (s, t) of base vectors in the intrinsic constraints, seed order."""
        if self.kind == "bar":
            return [(0, 0)]
        if self.kind == "point":
            return []
        if self.dim == 3:
            return [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
        return [(0, 0), (1, 1), (0, 1)]

    @property
    def n_phi(self) -> int:
        return len(self.pairs)

    @property
    def dof(self) -> int:
        return self.nq - self.n_phi

    @property
    def slots(self) -> list[str]:
        """Slot names in order, e.g. ``['r_i', 'r_j', 'v', 'w']`` for rrvw."""
        return ["r_i"] + [f"r_{POINT_NAMES[s]}" if ch == "r" else VECTOR_NAMES[s - 1]
                          for s, ch in enumerate(self.name[1:], start=1)]

    @property
    def point_slots(self) -> list[int]:
        """Slots holding basic points (shareable between members)."""
        return [0] + [s for s, ch in enumerate(self.name[1:], start=1) if ch == "r"]

    @property
    def label(self) -> str:
        return f"{self.dim}D {self.kind} {self.name}"

    def __repr__(self) -> str:
        return f"CoordinateType({self.name!r}, dim={self.dim})"

    def __deepcopy__(self, memo) -> "CoordinateType":
        return self              # immutable, and its derivation is cached per (name, dim)

    def __reduce__(self):
        """Pickled by name: a stored model reads back without its SymPy derivation (derived again on use)."""
        return coordinate_type, (self.name, self.dim)

    # ------------------------------------------------------------- derivation
    @cached_property
    def derivation(self) -> "Derivation":
        """The SymPy derivation, read from the store of derivations when it holds it
        (:mod:`ncgen.symbolic.derivation_store`), else derived (and stored)."""
        from ncgen.symbolic.derivation_store import stored_derivation
        return stored_derivation(self, Derivation)

    def report(self):
        """The derivation step by step (:func:`ncgen.symbolic.teaching.coordinates_report`)."""
        from ncgen.symbolic.teaching import coordinates_report
        return coordinates_report(self)

    def _repr_markdown_(self) -> str:
        return self.report().render("markdown")

    def _repr_latex_(self) -> str:
        from ncgen.symbolic.teaching import jupyter_latex
        return jupyter_latex(self.report())


class Derivation:
    """SymPy derivation of one coordinate type (see module docstring).

    Symbols: ``q`` (coordinates), ``qd`` (their rates), ``c`` (affine coordinates),
    ``Xbar`` (local base vectors x̄_s as columns), ``rbar_i`` (local basic point),
    ``m``, ``c_g`` (affine coordinates of the centre of mass), ``B`` (∫ρ c cᵀ),
    ``Xbar_inv`` (X̄⁻¹) and ``Gbar`` ((X̄ᵀX̄)⁻¹) for bodies, ``R_sym``, ``p_sym``,
    ``omega_sym``, ``v_sym`` (pose and twist, inputs of the inverse maps).
    """

    def report(self):
        """The derivation step by step, as a :class:`ncgen.symbolic.report.Report`."""
        return self.ctype.report()

    def _repr_markdown_(self) -> str:
        return self.ctype._repr_markdown_()

    def _repr_latex_(self) -> str:
        return self.ctype._repr_latex_()

    def __init__(self, ctype: CoordinateType):
        import sympy as sp
        self.ctype = ct = ctype
        d, k = ct.dim, ct.k
        # coordinates and their rates, slot by slot
        self.slot_vectors = [_vec(s, d) for s in ct.slots]
        self.q = sp.Matrix.vstack(*self.slot_vectors)
        self.qd = sp.Matrix([sp.Symbol(f"{sym.name[0]}dot{sym.name[1:]}", real=True) for sym in self.q])
        r_i = self.slot_vectors[0]
        self.r_i = r_i
        self.x = [self.slot_vectors[s] - (r_i if ch == "r" else sp.zeros(d, 1))
                  for s, ch in enumerate(ct.name[1:], start=1)]
        self.X = sp.Matrix.hstack(*self.x) if k else sp.zeros(d, 0)
        # Y: q_ruvw = Y q
        self.q_ruvw = sp.Matrix.vstack(r_i, *self.x)
        self.Y = self.q_ruvw.jacobian(self.q)
        self.Y_inv = self.Y.inv()
        # C(c): r = r_i + X c
        self.c = sp.Matrix([sp.Symbol(f"c_{s}", real=True) for s in range(1, k + 1)])
        self.r_c = r_i + (self.X * self.c if k else sp.zeros(d, 1))
        self.C = self.r_c.jacobian(self.q)
        self.C_kron = sp.kronecker_product(sp.Matrix([[1, *self.c]]), sp.eye(d)) * self.Y
        # local basis
        self.xbar = [_vec(f"{VECTOR_NAMES[s]}bar", d) for s in range(k)]
        self.Xbar = sp.Matrix.hstack(*self.xbar) if k else sp.zeros(d, 0)
        self.rbar_i = _vec("rbar_i", d)
        # intrinsic constraints, Jacobian, Hessians
        self.Phi = sp.Matrix([(self.x[s].T * self.x[t])[0] - (self.xbar[s].T * self.xbar[t])[0]
                              for s, t in ct.pairs])
        self.Phi_q = self.Phi.jacobian(self.q) if ct.pairs else sp.zeros(0, ct.nq)
        self.hessians = [sp.hessian(phi, self.q) for phi in self.Phi]
        # mass matrix from the generalised inertia G = [[m, m c_gᵀ], [m c_g, B]]
        self.m = sp.Symbol("m", positive=True)
        self.c_g = sp.Matrix([sp.Symbol(n, real=True) for n in com_names(k)])
        self.B = _sym_matrix("B", k)
        G = sp.zeros(k + 1, k + 1)
        G[0, 0] = self.m
        for s in range(k):
            G[0, s + 1] = G[s + 1, 0] = self.m * self.c_g[s]
            for t in range(k):
                G[s + 1, t + 1] = self.B[s, t]
        self.G = G
        self.M = (self.Y.T * sp.kronecker_product(G, sp.eye(d)) * self.Y).applyfunc(sp.expand)
        # kinetic energy ½ q̇ᵀ M q̇
        self.T = sp.expand((self.qd.T * self.M * self.qd)[0] / 2)
        self._derive_inertia_formulas()
        self._derive_pose_and_twist()

    # -- inertia: c_g, B, J̄ as matrix expressions (shown in reports, evaluated numerically)
    def _derive_inertia_formulas(self):
        import sympy as sp
        ct, d, k = self.ctype, self.ctype.dim, self.ctype.k
        self.Xbar_sym = sp.MatrixSymbol("Xbar", d, k) if k else None
        self.rbar_i_sym = sp.MatrixSymbol("rbar_i", d, 1)
        self.Jbar_sym = sp.MatrixSymbol("Jbar", d, d)
        if k == 0:
            self.Ibar_sym = None
            self.Jbar_formula = None
            self.Xbar_pinv = None
            self.c_g_formula = None
            self.B_formula = None
            return
        # J̄ = ∫ρ r̄ r̄ᵀ from the user's inertia Ī about the centre of mass
        if ct.kind == "body" and d == 3:            # Ī: the 3×3 inertia tensor in body axes
            self.Ibar_sym = sp.MatrixSymbol("Ibar", 3, 3)
            self.Jbar_formula = sp.Trace(self.Ibar_sym) / 2 * sp.Identity(3) - self.Ibar_sym
        elif ct.kind == "body":                     # Ī: the planar moment; only tr J̄ = Ī acts
            self.Ibar_sym = sp.Symbol("Ibar", positive=True)
            self.Jbar_formula = self.Ibar_sym / 2 * sp.eye(2)
        else:                                       # bar: Ī_t, the transverse moment, = ∫ρ x̄²
            self.Ibar_sym = sp.Symbol("Ibar_t", positive=True)
            self.Jbar_formula = sp.diag(self.Ibar_sym, *[0] * (d - 1))
        X = self.Xbar_sym
        self.Xbar_pinv = X.I if ct.kind == "body" else (X.T * X).I * X.T
        self.c_g_formula = -self.Xbar_pinv * self.rbar_i_sym
        self.B_formula = self.Xbar_pinv * (self.Jbar_sym + self.m * self.rbar_i_sym * self.rbar_i_sym.T) \
            * self.Xbar_pinv.T

    # -- pose (R, p) and twist (ω, v) of the member's local frame (origin at the COM)
    def _derive_pose_and_twist(self):
        import sympy as sp
        ct, d, k = self.ctype, self.ctype.dim, self.ctype.k
        self.p = self.r_i + (self.X * self.c_g if k else sp.zeros(d, 1))   # centre of mass
        self.v_com = self.p.jacobian(self.q) * self.qd
        if k:
            xd = sp.Matrix.vstack(*self.x).jacobian(self.q) * self.qd
            Xd = sp.Matrix.hstack(*[xd[s * d:(s + 1) * d, 0] for s in range(k)])   # columns ẋ_s
        else:
            Xd = None
        self.Xdot = Xd
        self.R = None
        self.omega = None
        if ct.kind == "body":
            self.Xbar_inv = sp.Matrix(d, d, lambda a, b: sp.Symbol(matrix_names("Xbarinv", d)[a][b], real=True))
            self.R = self.X * self.Xbar_inv
            self.Gbar = _sym_matrix("Gbar", d)              # (X̄ᵀX̄)⁻¹, so that ω̂ = Ẋ Ḡ Xᵀ
            self.omega = _skew_vee(Xd * self.Gbar * self.X.T, d).applyfunc(sp.expand)
        elif ct.kind == "bar":
            u, ud = self.x[0], Xd[:, 0]
            L2 = (self.xbar[0].T * self.xbar[0])[0]          # |ū|², constant on the manifold
            self.omega = (_cross(u, ud, d) / L2).applyfunc(sp.expand)
            e1 = u / sp.sqrt((u.T * u)[0])
            if d == 2:
                self.R = sp.Matrix.hstack(e1, sp.Matrix([-e1[1], e1[0]]))
            else:
                ax = [sp.Abs(u[a]) for a in range(3)]
                helper = sp.Matrix([
                    sp.Piecewise((1, sp.And(ax[0] <= ax[1], ax[0] <= ax[2])), (0, True)),
                    sp.Piecewise((0, sp.And(ax[0] <= ax[1], ax[0] <= ax[2])), (1, ax[1] <= ax[2]), (0, True)),
                    sp.Piecewise((0, sp.And(ax[0] <= ax[1], ax[0] <= ax[2])), (0, ax[1] <= ax[2]), (1, True)),
                ])
                e3u = e1.cross(helper)
                e3 = e3u / sp.sqrt((e3u.T * e3u)[0])
                e2 = e3.cross(e1)
                self.R = sp.Matrix.hstack(e1, e2, e3)
        if self.omega is not None:
            self.W = self.omega.jacobian(self.qd)   # ω = W(q) q̇; torque τ ↦ Q = Wᵀ τ
        else:
            self.W = None
        self._derive_inverse_maps()

    def _derive_inverse_maps(self):
        """(R, p, ω, v) ↦ (q, q̇): slots from the pose and the twist of the COM frame."""
        import sympy as sp
        ct, d, k = self.ctype, self.ctype.dim, self.ctype.k
        self.R_sym = sp.Matrix(d, d, lambda a, b: sp.Symbol(matrix_names("R", d)[a][b], real=True))
        self.p_sym = _vec("p", d)
        self.v_sym = _vec("v", d)
        self.omega_sym = _vec("omega", 3) if d == 3 else sp.Matrix([sp.Symbol("omega", real=True)])
        if k and ct.kind == "body":
            xs = [self.R_sym * xb for xb in self.xbar]
        elif k:
            xs = [self.R_sym[:, 0] * sp.sqrt((self.xbar[0].T * self.xbar[0])[0])]
        else:
            xs = []
        rbar_i = self.rbar_i if ct.kind == "body" else (
            self.R_sym[:, 0] * self.rbar_i[0] if k else sp.zeros(d, 1))
        r_i = self.p_sym + (self.R_sym * self.rbar_i if ct.kind == "body" else rbar_i)
        self.q_of_pose = (self.Y_inv * sp.Matrix.vstack(r_i, *xs)).applyfunc(sp.expand)

        def rate(vec):
            if d == 3:
                return self.omega_sym.cross(vec)
            return sp.Matrix([-self.omega_sym[0] * vec[1], self.omega_sym[0] * vec[0]])

        lever = r_i - self.p_sym
        rates = [self.v_sym + rate(lever)] + [rate(x) for x in xs]
        self.qd_of_twist = (self.Y_inv * sp.Matrix.vstack(*rates)).applyfunc(sp.expand)


__all__ = ["TYPES", "CoordinateType", "Derivation", "available_types", "coordinate_type"]
