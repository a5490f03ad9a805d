"""One member's local description and its numeric formulas (NumPy forms of the derivation).

A :class:`RigidMember` holds a coordinate type, the local basis (basic point ``r̄_i`` and
base vectors ``X̄`` in the member's local frame, whose origin is the centre of mass), the
mass and the inertia.  Every numeric method evaluates a SymPy formula of
:class:`ncgen.symbolic.coordinates.Derivation` in its shipped NumPy form
(:func:`ncgen.symbolic.numpy_forms.shipped_function`: no SymPy at run time); the same formulas
are instantiated in CasADi with the values of :attr:`RigidMember.constant_values`.

Conventions: SI units; ``R`` maps local to world axes; ``p`` is the centre of mass;
``omega`` is the angular velocity in world axes (a scalar in 2D); ``v`` the velocity of the
centre of mass.  Local frames: a body's is the one its user gives; a bar's has ``x̄`` from
its first end to its second; a point's is a translated world frame.
"""
from __future__ import annotations

from functools import cached_property

import numpy as np

from ncgen.errors import BasisError, InertiaError, ShapeError
from ncgen.reproducible import inv, matmul, matvec, snap
from ncgen.symbolic.coordinates import (CoordinateType, com_names, component_names, coordinate_type, matrix_names,
                                        symmetric_names)
from ncgen.symbolic.notation import VECTOR_NAMES
from ncgen.symbolic.numpy_forms import shipped_function
from ncgen.validation import as_array, as_scalar, as_vector, positive, rotation

#: Relative tolerance below which a body's base vectors count as coplanar.
COPLANAR_TOL = 1e-9
#: Relative tolerance for a point to lie on a bar's axis.
AXIS_TOL = 1e-9


def inertia_J(ctype: CoordinateType, inertia, length: float | None = None) -> np.ndarray:
    """``J̄ = ∫ρ r̄ r̄ᵀ`` about the centre of mass from the user's inertia.

    Evaluates the derivation's ``Jbar_formula`` (shipped form ``Jbar``).  3D body: ``Ī`` (3×3, body axes, about the
    COM), ``J̄ = ½ tr(Ī) 1 − Ī``.  2D body: the scalar moment ``I`` about the COM,
    ``J̄ = ½ I 1`` (only tr J̄ is seen by rigid motion).  Bar: the transverse moment ``I_t``
    about the COM, ``J̄ = diag(I_t, 0[, 0])``.
    """
    d = ctype.dim
    J_of = shipped_function(ctype.name, d, "Jbar")[0]
    if ctype.kind == "bar":
        return J_of(positive(inertia, "inertia (transverse moment of the bar about its centre of mass)"))
    if d == 2:
        return J_of(positive(inertia, "inertia (moment about the centre of mass)"))
    Ib = as_array(inertia, (3, 3), "inertia")
    scale = max(np.max(np.abs(Ib)), 1e-300)
    if np.max(np.abs(Ib - Ib.T)) > 1e-9 * scale:
        raise InertiaError(f"inertia: expected a symmetric 3x3 matrix, got {Ib.tolist()}")
    ev = np.linalg.eigvalsh(Ib)
    if ev[0] < -1e-12 * scale:
        raise InertiaError(f"inertia: expected positive principal moments (or zero, for a body whose mass "
                           f"lies on a line), got {ev.tolist()}")
    if ev[0] + ev[1] < ev[2] * (1 - 1e-12):
        raise InertiaError(
            f"inertia: principal moments {ev.tolist()} violate the triangle inequality "
            f"I1 + I2 >= I3 ({ev[0] + ev[1]:.6g} < {ev[2]:.6g}): no rigid body has them")
    # I1 + I2 = I3 (a thin disc or plate) makes J̄, and so M, singular: accepted; the model
    # checks that M is positive definite on the constraint tangent space (assembly.mass)
    return J_of(Ib)


def constant_symbols(ctype: CoordinateType) -> list:
    """The derivation's constant symbols (a member's numbers), each once: ``m``, ``r̄_i``,
    ``x̄_s``, ``c_g``, ``B``, and ``X̄⁻¹``, ``Ḡ`` for bodies."""
    D = ctype.derivation
    symbols = [D.m, *D.rbar_i, *(x for s in range(ctype.k) for x in D.xbar[s]), *D.c_g, *D.B]
    if ctype.kind == "body":
        symbols += [*D.Xbar_inv, *D.Gbar]
    return list(dict.fromkeys(symbols))


class RigidMember:
    """Numeric local description of one member (see module docstring); constant once made."""

    def __deepcopy__(self, memo) -> "RigidMember":
        return self              # constant: copies of a model share it

    def __getstate__(self) -> dict:
        """The description only: the memo of NumPy functions and the constants' values are
        rebuilt on use."""
        return {k: v for k, v in self.__dict__.items() if k not in ("_fn_memo", "constant_values")}

    def __init__(self, ctype: CoordinateType, mass: float, rbar_i, Xbar, Jbar):
        self.ctype = ctype
        d, k = ctype.dim, ctype.k
        self.mass = positive(mass, "mass")
        self.rbar_i = as_vector(rbar_i, d, "local basic point r̄_i")
        self.Xbar = as_array(Xbar, (d, k), "local base vectors X̄")
        self.Jbar = as_array(Jbar, (d, d), "J̄")
        self._check_basis()

    # ---------------------------------------------------------------- constructors
    @classmethod
    def body(cls, ctype: CoordinateType | str, mass: float, inertia, basis=None, dim: int = 3):
        """A body; ``basis`` lists the slot values in the local frame, seed order (for rrvw:
        ``[r̄_i, r̄_j, v̄, w̄]``); default: ``r̄_i = 0`` and unit axes."""
        ct = ctype if isinstance(ctype, CoordinateType) else coordinate_type(ctype, dim)
        if ct.kind != "body":
            raise BasisError(f"RigidMember.body: {ct.label} is not a body type")
        d = ct.dim
        if basis is None:
            slots = [np.zeros(d)] + [np.eye(d)[s] for s in range(d)]
        else:
            if len(basis) != len(ct.name):
                raise ShapeError(f"basis of a {ct.name} body: expected {len(ct.name)} vectors "
                                 f"({', '.join(ct.slots)}), got {len(basis)}")
            slots = [as_vector(b, d, f"basis[{s}] ({name})") for s, (b, name) in enumerate(zip(basis, ct.slots))]
        rbar_i = slots[0]
        X = np.column_stack([slots[s] - (rbar_i if ch == "r" else 0) for s, ch in enumerate(ct.name[1:], 1)])
        return cls(ct, mass, rbar_i, X, inertia_J(ct, inertia))

    @classmethod
    def bar(cls, ctype: CoordinateType | str, mass: float, length: float, inertia=None,
            com: float | None = None, dim: int = 3):
        """A bar of ``length`` from its first end to its second; ``com`` is the distance of
        the centre of mass from the first end (default ``length/2``); ``inertia`` the
        transverse moment about the centre of mass (default ``m L²/12``, a uniform bar)."""
        ct = ctype if isinstance(ctype, CoordinateType) else coordinate_type(ctype, dim)
        if ct.kind != "bar":
            raise BasisError(f"RigidMember.bar: {ct.label} is not a bar type")
        L = positive(length, "bar length")
        mass = positive(mass, "mass")
        a = L / 2 if com is None else as_scalar(com, "com (distance of the centre of mass from the first end)")
        if inertia is None:
            if abs(a - L / 2) > 1e-12 * L:
                raise InertiaError(f"bar: com={a:g} is not the middle of the bar (L={L:g}), so it is not "
                                   "uniform; give its transverse inertia about the centre of mass")
            inertia = mass * L**2 / 12
        d = ct.dim
        rbar_i = np.zeros(d)
        rbar_i[0] = -a
        X = np.zeros((d, 1))
        X[0, 0] = L
        return cls(ct, mass, rbar_i, X, inertia_J(ct, inertia))

    @classmethod
    def point(cls, ctype: CoordinateType | str, mass: float, dim: int = 3):
        ct = ctype if isinstance(ctype, CoordinateType) else coordinate_type(ctype, dim)
        if ct.kind != "point":
            raise BasisError(f"RigidMember.point: {ct.label} is not a point type")
        return cls(ct, mass, np.zeros(ct.dim), np.zeros((ct.dim, 0)), np.zeros((ct.dim, ct.dim)))

    def _check_basis(self):
        ct, X = self.ctype, self.Xbar
        norms = np.linalg.norm(X, axis=0)
        for s, n in enumerate(norms):
            if n <= 1e-12 * max(1.0, np.max(norms)):
                raise BasisError(f"{ct.name}: base vector x̄_{s + 1} is zero")
        if ct.kind == "body":
            vol = abs(np.linalg.det(X)) / np.prod(norms)
            if vol < COPLANAR_TOL:
                raise BasisError(f"{ct.name}: base vectors are {'collinear' if ct.dim == 2 else 'coplanar'} "
                                 f"(normalised volume {vol:.3g}); they must span the body frame")
        if ct.kind == "bar":
            if np.linalg.norm(X[1:, 0]) > AXIS_TOL * norms[0] or X[0, 0] < 0:
                raise BasisError(f"{ct.name}: a bar's base vector must point along its local +x̄ axis "
                                 f"(from its first end to its second), got {X[:, 0].tolist()}")
            if np.linalg.norm(self.rbar_i[1:]) > AXIS_TOL * max(norms[0], abs(self.rbar_i[0])):
                raise BasisError(f"{ct.name}: a bar's basic point r̄_i must lie on its local x̄ axis, "
                                 f"got {self.rbar_i.tolist()}")

    # -------------------------------------------------------------- constants
    def _shipped(self, formula: str):
        return shipped_function(self.ctype.name, self.ctype.dim, formula)[0]

    @cached_property
    def Xbar_pinv(self) -> np.ndarray:
        return self._shipped("Xbar_pinv")(self.Xbar)

    @cached_property
    def c_g(self) -> np.ndarray:
        """Affine coordinates of the centre of mass."""
        if self.ctype.k == 0:
            return np.zeros(0)
        return self._shipped("c_g")(self.Xbar, self.rbar_i.reshape(-1, 1)).reshape(-1)

    @cached_property
    def B(self) -> np.ndarray:
        """``∫ρ c cᵀ``."""
        if self.ctype.k == 0:
            return np.zeros((0, 0))
        return self._shipped("B")(self.Xbar, self.Jbar, self.mass, self.rbar_i.reshape(-1, 1))

    @cached_property
    def constant_values(self) -> dict[str, float]:
        """Values of the derivation's constant symbols, by symbol name (the names of
        :mod:`ncgen.symbolic.coordinates`): ``m``, ``r̄_i``, ``x̄_s``, ``c_g``, ``B``, and
        ``X̄⁻¹``, ``Ḡ = (X̄ᵀX̄)⁻¹`` for bodies."""
        ct, d, k = self.ctype, self.ctype.dim, self.ctype.k
        vals = {"m": self.mass}
        vals.update(zip(component_names("rbar_i", d), self.rbar_i))
        B_names = symmetric_names("B", k)
        for s in range(k):
            vals.update(zip(component_names(f"{VECTOR_NAMES[s]}bar", d), self.Xbar[:, s]))
            vals[com_names(k)[s]] = self.c_g[s]
            for t in range(k):
                vals[B_names[s][t]] = self.B[s, t]
        if ct.kind == "body":
            Xi = inv(self.Xbar)
            vals.update(zip((n for row in matrix_names("Xbarinv", d) for n in row), Xi.reshape(-1)))
            vals.update(zip((n for row in symmetric_names("Gbar", d) for n in row), matmul(Xi, Xi.T).reshape(-1)))
        return vals

    def constants(self) -> dict:
        """Values of every constant symbol of the derivation, for instantiation (SymPy ↦ float)."""
        named = self.constant_values
        return {sym: named[sym.name] for sym in constant_symbols(self.ctype)}

    def _fn(self, formula: str):
        """The shipped NumPy form of ``formula`` (its arguments but the constants), constants bound."""
        memo = self.__dict__.setdefault("_fn_memo", {})
        hit = memo.get(formula)
        if hit is None:
            f, names = shipped_function(self.ctype.name, self.ctype.dim, formula)
            cvals = [self.constant_values[n] for n in names]
            hit = memo[formula] = lambda *vals: f(*vals, cvals)
        return hit

    # ----------------------------------------------------------- mass matrix
    @cached_property
    def M(self) -> np.ndarray:
        return self._fn("M")()

    @cached_property
    def hessians(self) -> list[np.ndarray]:
        """Constant Hessians ``H_k = ∂²Φ_k/∂q²``."""
        from ncgen.symbolic.numeric_forms import HESSIANS
        return [np.array(H, dtype=float) for H in HESSIANS[self.ctype.name, self.ctype.dim]]

    # ------------------------------------------------------------ constraints
    def _q(self, q, what="q") -> np.ndarray:
        return as_vector(q, self.ctype.nq, f"{what} of a {self.ctype.name} member")

    def phi(self, q) -> np.ndarray:
        return self._fn("Phi")(self._q(q)).reshape(-1)

    def phi_q(self, q) -> np.ndarray:
        return self._fn("Phi_q")(self._q(q)).reshape(self.ctype.n_phi, self.ctype.nq)

    def gamma(self, qd) -> np.ndarray:
        """``γ = −Ȧ q̇ = −[q̇ᵀ H_k q̇]_k``."""
        qd = self._q(qd, "q̇")
        return np.array([-(qd @ H @ qd) for H in self.hessians])

    # ------------------------------------------------------------ points
    def affine(self, rbar) -> np.ndarray:
        """Affine coordinates ``c = X̄⁺ (r̄ − r̄_i)`` of a local point (entries within 1e-12 of
        an integer snapped to it: basic points are exactly 0 or 1); a bar's point must lie
        on its axis and a point member's at its origin."""
        ct = self.ctype
        rbar = as_vector(rbar, ct.dim, "local point")
        if ct.k == 0:
            if np.linalg.norm(rbar) > 0:
                raise BasisError(f"a point member has only its origin; got local point {rbar.tolist()}")
            return np.zeros(0)
        c = snap(matvec(self.Xbar_pinv, rbar - self.rbar_i))
        off = np.linalg.norm(self.Xbar @ c - (rbar - self.rbar_i))
        scale = max(np.linalg.norm(self.Xbar), np.linalg.norm(rbar - self.rbar_i), 1e-300)
        if off > AXIS_TOL * scale:
            raise BasisError(f"local point {rbar.tolist()} is {off:.3g} m off the bar's axis; "
                             "a bar carries points on its axis only")
        return c

    def C(self, c) -> np.ndarray:
        return self._fn("C")(as_vector(c, self.ctype.k, "affine coordinates c"))

    def position(self, q, rbar) -> np.ndarray:
        """World position of the body-fixed point with local coordinates ``rbar``."""
        return self.C(self.affine(rbar)) @ self._q(q)

    def velocity(self, qd, rbar) -> np.ndarray:
        return self.C(self.affine(rbar)) @ self._q(qd, "q̇")

    # ------------------------------------------------------- pose and twist
    def pose(self, q):
        """``(R, p)``: rotation local→world (``None`` for a point) and centre of mass."""
        q = self._q(q)
        p = self._fn("p")(q).reshape(-1)
        R = None if self.ctype.kind == "point" else self._fn("R")(q)
        return R, p

    def twist(self, q, qd):
        """``(ω, v)``: world angular velocity (minimum-norm, ⟂ axis, for bars; ``None`` for a
        point; a scalar in 2D) and velocity of the centre of mass."""
        q, qd = self._q(q), self._q(qd, "q̇")
        v = self._fn("v_com")(q, qd).reshape(-1)
        if self.ctype.kind == "point":
            return None, v
        w = self._fn("omega")(q, qd).reshape(-1)
        return (w if self.ctype.dim == 3 else float(w[0])), v

    def _pose_args(self, R, p):
        d = self.ctype.dim
        R = np.eye(d) if R is None and self.ctype.kind == "point" else rotation(R, d)
        return R, as_vector(p, d, "position")

    def _omega(self, omega):
        if self.ctype.dim == 3:
            return as_vector(omega, 3, "angular_velocity")
        return np.array([as_scalar(omega, "angular_velocity (a scalar in 2D)")])

    def q_from_pose(self, R, p) -> np.ndarray:
        R, p = self._pose_args(R, p)
        return self._fn("q_of_pose")(R, p).reshape(-1)

    def qd_from_twist(self, R, p, omega, v) -> np.ndarray:
        R, p = self._pose_args(R, p)
        w = np.zeros(3 if self.ctype.dim == 3 else 1) if omega is None else self._omega(omega)
        v = as_vector(v, self.ctype.dim, "velocity")
        f = self._fn("qd_of_twist")
        return f(R, p, w, v).reshape(-1)

    # ------------------------------------------------------- generalised forces
    def force_at(self, rbar, f) -> np.ndarray:
        """Generalised force ``Q = C(c)ᵀ f`` of a world force ``f`` at local point ``rbar``."""
        return self.C(self.affine(rbar)).T @ as_vector(f, self.ctype.dim, "force")

    def torque(self, q, tau) -> np.ndarray:
        """Generalised force ``Q = W(q)ᵀ τ`` of a pure couple (world axes; scalar in 2D),
        where ``ω = W(q) q̇``.  On a bar only the part of τ normal to the axis acts."""
        if self.ctype.kind == "point":
            raise BasisError("a point member cannot carry a torque")
        W = self._fn("W")(self._q(q))
        return W.T @ self._omega(tau)

    def __repr__(self) -> str:
        return f"RigidMember({self.ctype.name!r}, dim={self.ctype.dim}, mass={self.mass:g})"
