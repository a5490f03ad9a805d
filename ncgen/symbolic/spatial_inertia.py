"""Spatial mass matrices and the Newton–Euler equations of a rigid body, in SymPy.

Conventions as in :mod:`ncgen.symbolic.rigid_motion` (twist ``[ω; v]``, wrench ``[τ; f]``,
``H_ab`` the pose of b in a).  Units: kg, m, kg·m², s.

The spatial mass matrix of a body at a frame b whose origin sees the centre of mass at
``r`` (b coordinates) is ``M_b = [[I_o, m r̂], [m r̂ᵀ, m 1]]``, with ``I_o`` the inertia tensor
about b's origin in b's axes; the kinetic energy is ``½ T_bᵀ M_b T_b`` for the body twist
``T_b``.  Frame changes keep the energy: ``M_b = Ad(H_ab)ᵀ M_a Ad(H_ab)``.

The inertia tensors of the primitive shapes are derived here by integrating second moments
over the solid (:func:`inertia_from_second_moment`), once per process.
"""
from __future__ import annotations

from functools import lru_cache

import sympy as sp

from ncgen.symbolic.rigid_motion import Ad, as_vector, ad, so3_hat, so3_vee


def mass_matrix(m, r, I_o) -> sp.Matrix:
    """``M = [[I_o, m r̂], [m r̂ᵀ, m 1]]`` (6x6) at a frame seeing the centre of mass at ``r``.

    ``I_o`` is the inertia tensor about the frame's origin, in the frame's axes (kg·m²).
    """
    R_hat = so3_hat(r)
    return sp.Matrix(sp.BlockMatrix([[sp.Matrix(I_o), m * R_hat], [m * R_hat.T, m * sp.eye(3)]]))


def inertia_about_point(m, r, I_c) -> sp.Matrix:
    """Parallel-axis theorem: ``I_o = I_c + m r̂ᵀ r̂``, the inertia about a point o from which
    the centre of mass is at ``r``, given the inertia ``I_c`` about the centre of mass."""
    R_hat = so3_hat(r)
    return sp.Matrix(I_c) + m * R_hat.T * R_hat


def mass_matrix_parts(M) -> tuple[sp.Expr, sp.Matrix, sp.Matrix]:
    """``(m, r, I_c)`` of a spatial mass matrix: mass, centre of mass in the frame, and inertia
    tensor about the centre of mass (frame axes).  Inverse of
    ``mass_matrix(m, r, inertia_about_point(m, r, I_c))``."""
    M = sp.Matrix(M)
    m = M[3, 3]
    r = so3_vee(M[:3, 3:]) / m
    R_hat = so3_hat(r)
    return m, r, M[:3, :3] - m * R_hat.T * R_hat


def transport_mass_matrix(M_a, H_ab) -> sp.Matrix:
    """``M_b = Ad(H_ab)ᵀ M_a Ad(H_ab)``: the mass matrix at frame b from the one at frame a.

    Follows from ``T_a = Ad(H_ab) T_b`` and the invariance of the kinetic energy.  Example:
    with ``M_a = diag(3, 2, 4, 1, 1, 1)`` (a at the centre of mass) and ``H_ab`` the
    translation by (1, 3, 0), ``M_b`` sees the centre of mass at ``r = (−1, −3, 0)``.
    """
    A = Ad(H_ab)
    return A.T * sp.Matrix(M_a) * A


# --- primitive shapes -------------------------------------------------------------------------

_x, _y, _z, _rho, _phi, _theta = sp.symbols("x y z rho phi theta", real=True)
_a, _b, _c, _h, _R = sp.symbols("a b c h R", positive=True)


def inertia_from_second_moment(S) -> sp.Matrix:
    """``I = tr(S) 1 − S``: the inertia tensor from the second moment ``S = ∫ x xᵀ dm`` about
    the same point (``S`` is the natural coordinates' ``J̄`` when taken about the centre of mass)."""
    S = sp.Matrix(S)
    return S.trace() * sp.eye(3) - S


@lru_cache(maxsize=None)
def _box_second_moment() -> sp.Matrix:
    """``S/m`` of the box ``|x| ≤ a, |y| ≤ b, |z| ≤ c``, integrated in Cartesian coordinates."""
    box = ((_x, -_a, _a), (_y, -_b, _b), (_z, -_c, _c))
    volume = sp.integrate(1, *box)
    return sp.diag(*[sp.simplify(sp.integrate(u ** 2, *box) / volume) for u in (_x, _y, _z)])


@lru_cache(maxsize=None)
def _cylinder_second_moment() -> sp.Matrix:
    """``S/m`` of the cylinder of radius R and length h along z, centred at the origin,
    integrated in cylindrical coordinates ``(ρ, φ, z)``."""
    cyl = ((_rho, 0, _R), (_phi, 0, 2 * sp.pi), (_z, -_h / 2, _h / 2))
    volume = sp.integrate(_rho, *cyl)
    coords = (_rho * sp.cos(_phi), _rho * sp.sin(_phi), _z)
    return sp.diag(*[sp.simplify(sp.integrate(u ** 2 * _rho, *cyl) / volume) for u in coords])


@lru_cache(maxsize=None)
def _ball_second_moment() -> sp.Matrix:
    """``S/m`` of the unit ball, integrated in spherical coordinates ``(ρ, θ, φ)``."""
    ball = ((_rho, 0, 1), (_theta, 0, sp.pi), (_phi, 0, 2 * sp.pi))
    jac = _rho ** 2 * sp.sin(_theta)
    volume = sp.integrate(jac, *ball)
    coords = (_rho * sp.sin(_theta) * sp.cos(_phi), _rho * sp.sin(_theta) * sp.sin(_phi),
              _rho * sp.cos(_theta))
    return sp.diag(*[sp.simplify(sp.integrate(u ** 2 * jac, *ball) / volume) for u in coords])


def _at_centre(m, inertia) -> sp.Matrix:
    return mass_matrix(m, sp.zeros(3, 1), inertia)


def box(half_extents, m) -> sp.Matrix:
    """Mass matrix at the centre of a homogeneous box with half extents ``(a, b, c)`` along
    x, y, z: ``I = m/3 diag(b² + c², a² + c², a² + b²)``."""
    a, b, c = as_vector(half_extents, 3)
    S = _box_second_moment().xreplace({_a: a, _b: b, _c: c})
    return _at_centre(m, m * inertia_from_second_moment(S))


def cylinder(length, radius, m) -> sp.Matrix:
    """Mass matrix at the centre of a homogeneous cylinder of axis z (full ``length`` along z):
    ``I = m diag(r²/4 + l²/12, r²/4 + l²/12, r²/2)``."""
    S = _cylinder_second_moment().xreplace({_h: length, _R: radius})
    return _at_centre(m, m * inertia_from_second_moment(S))


def ellipsoid(semi_axes, m) -> sp.Matrix:
    """Mass matrix at the centre of a homogeneous ellipsoid with semi-axes ``(a, b, c)`` along
    x, y, z: the image of the unit ball by ``D = diag(a, b, c)``, so ``S = D S_ball D`` and
    ``I = m/5 diag(b² + c², a² + c², a² + b²)``."""
    D = sp.diag(*as_vector(semi_axes, 3))
    return _at_centre(m, m * inertia_from_second_moment(D * _ball_second_moment() * D))


def sphere(radius, m) -> sp.Matrix:
    """Mass matrix at the centre of a homogeneous ball: ``I = 2/5 m r² 1``."""
    return ellipsoid((radius, radius, radius), m)


# --- Newton–Euler ----------------------------------------------------------------------------

def newton_euler_bias(M_b, T_b) -> sp.Matrix:
    """``−ad(T_b)ᵀ M_b T_b``: the velocity-dependent term of the Newton–Euler equations
    ``M_b dT_b/dt − ad(T_b)ᵀ M_b T_b = W_b`` of a rigid body.

    ``T_b`` is the body twist (b relative to an inertial frame g, in b), ``M_b`` the constant
    mass matrix at b and ``W_b`` the total wrench applied to the body, in b, moment about b's
    origin.  Derivation: the momentum ``h_b = M_b T_b`` expressed in g,
    ``h_g = Ad(H_gb)⁻ᵀ h_b``, obeys ``dh_g/dt = W_g = Ad(H_gb)⁻ᵀ W_b``; with
    ``d/dt Ad(H_gb)⁻ᵀ = −Ad(H_gb)⁻ᵀ ad(T_b)ᵀ`` this gives ``dh_b/dt − ad(T_b)ᵀ h_b = W_b``.
    At the centre of mass (``M_b = diag(I_c, m 1)``) the bias is ``[ω × I_c ω; m ω × v]``.
    """
    T = as_vector(T_b, 6)
    return -ad(T).T * sp.Matrix(M_b) * T
