"""CasADi forms of the rigid-motion algebra.

Each function is the CasADi translation (:func:`ncgen.model.sym2casadi.to_casadi`) of the
SymPy formula of the same name in :mod:`ncgen.symbolic.rigid_motion` or
:mod:`ncgen.symbolic.spatial_inertia` (table: :mod:`ncgen.symbolic.rigid_motion_forms`),
held as one SX :class:`casadi.Function` per formula.  Calling it with SX arguments returns SX
(the expressions are inlined), with MX arguments MX, with numbers DM.  Conventions as in the
SymPy modules: ``H_ab`` pose of b in a, twists ``[ω; v]``, wrenches ``[τ; f]``.

These functions are also what :func:`ncgen.codegen.rigid_motion_package.write_c_package`
generates C from.  Besides the table, the rotations of the joint coordinates
(:data:`ROTATIONS`: ``rotation_about``, ``quaternion``, ``quaternion_matrix``,
``quaternion_rate``, ``swing``) have CasADi forms here, translated the same way.
The exponential and logarithm are ``if_else`` on the small-angle branch; both branches are
finite everywhere (see :mod:`ncgen.symbolic.rigid_motion`), so values and derivatives are
finite at the zero twist and at the identity.
"""
from __future__ import annotations

from functools import lru_cache

import casadi as ca

from ncgen.model.sym2casadi import to_casadi

#: Rotations of the joint coordinates with a CasADi form only: ``name: ((argument, rows, cols)...), output``.
ROTATIONS = {
    "rotation_about": ((("axis", 3, 1), ("angle", 1, 1)), "R"),
    "quaternion": ((("R_ab", 3, 3),), "quat"),
    "quaternion_matrix": ((("quat", 4, 1),), "R"),
    "quaternion_rate": ((("quat", 4, 1), ("omega", 3, 1)), "quat_dot"),
    "swing": ((("u0", 3, 1), ("u", 3, 1)), "phi"),
}


def _bind(values: dict, placeholder, x) -> None:
    """Map every symbol of ``placeholder`` (scalar or matrix) to the entry of ``x`` it stands for."""
    if not hasattr(placeholder, "shape"):
        values[placeholder] = x
        return
    for i in range(placeholder.shape[0]):
        for j in range(placeholder.shape[1]):
            values[placeholder[i, j]] = x[i, j]


def _rotation_function(name: str) -> ca.Function:
    import sympy as sp

    from ncgen.symbolic import rigid_motion as srm

    shapes, out = ROTATIONS[name]
    inputs = [ca.SX.sym(a, r, c) for a, r, c in shapes]
    placeholders = [sp.Matrix(r, c, lambda i, j, a=a: sp.Symbol(f"{a}_{i}{j}", real=True)) for a, r, c in shapes]
    values: dict = {}
    for placeholder, x in zip(placeholders, inputs):
        _bind(values, placeholder, x)
    args = [p[0] if p.shape == (1, 1) else p for p in placeholders]
    return ca.Function(name, inputs, [ca.SX(to_casadi(getattr(srm, name)(*args), values))],
                       [a for a, _, _ in shapes], [out])


@lru_cache(maxsize=None)
def function(name: str) -> ca.Function:
    """The SX function ``name`` (one of ``rigid_motion_forms.NAMES`` or :data:`ROTATIONS`),
    inputs and outputs named as in the table (derived through SymPy on first use)."""
    from ncgen.symbolic.rigid_motion_forms import NAMES, form

    if name not in NAMES:
        return _rotation_function(name)
    f = form(name)
    inputs = [ca.SX.sym(a.name, *(a.shape + (1,) * (2 - len(a.shape)))) for a in f.args]
    values: dict = {}
    for placeholder, x in zip(f.placeholders, inputs):
        _bind(values, placeholder, x)
    for symbols, expr in f.stages:
        _bind(values, symbols, to_casadi(expr, values))
    outputs = [ca.SX(to_casadi(o.expr, values)) for o in f.outputs]
    return ca.Function(name, inputs, outputs, [a.name for a in f.args], [o.name for o in f.outputs])


def _call(name: str, *args):
    out = function(name).call(list(args))
    return out[0] if len(out) == 1 else tuple(out)


def rotation_about(axis, angle):
    """``1 + sin θ û + (1 − cos θ) û²``: rotation by ``angle`` (rad) about the unit ``axis``."""
    return _call("rotation_about", axis, angle)


def quaternion(R_ab):
    """Unit quaternion ``[qx, qy, qz, qw]`` (``qw ≥ 0``, Shepperd) of the rotation ``R_ab``."""
    return _call("quaternion", R_ab)


def quaternion_matrix(quat):
    """Rotation matrix of the quaternion ``[qx, qy, qz, qw]`` (normalised first)."""
    return _call("quaternion_matrix", quat)


def quaternion_rate(quat, omega):
    """``q̇ = ½ q ⊗ [ω; 0]``, ``ω`` in body axes."""
    return _call("quaternion_rate", quat, omega)


def swing(u0, u):
    """``φ = (θ / sin θ)(u0 × u)``: the rotation vector taking the unit ``u0`` to ``u``."""
    return _call("swing", u0, u)


def rotx(angle):
    """Rotation by ``angle`` (rad) about x."""
    return _call("rotx", angle)


def roty(angle):
    """Rotation by ``angle`` (rad) about y."""
    return _call("roty", angle)


def rotz(angle):
    """Rotation by ``angle`` (rad) about z."""
    return _call("rotz", angle)


def rotzyx(az, ay, ax):
    """``Rz(az) Ry(ay) Rx(ax)``."""
    return _call("rotzyx", az, ay, ax)


def zyx_angles(R_ab):
    """``[az, ay, ax]`` with ``rotzyx(az, ay, ax) = R_ab`` (``ax = 0`` at gimbal lock)."""
    return _call("zyx_angles", R_ab)


def so3_hat(omega):
    """``ω̂`` with ``ω̂ x = ω × x``."""
    return _call("so3_hat", omega)


def so3_vee(Omega):
    """Vector of the skew-symmetric part of ``Omega``."""
    return _call("so3_vee", Omega)


def exp_so3(omega):
    """``exp(ω̂)`` (Rodrigues)."""
    return _call("exp_so3", omega)


def log_so3(R_ab):
    """``ω`` with ``exp_so3(ω) = R_ab``, ``|ω| ≤ π``."""
    return _call("log_so3", R_ab)


def homogeneous(R_ab, p_ab):
    """``[[R_ab, p_ab], [0, 1]]``."""
    return _call("homogeneous", R_ab, p_ab)


def translation(p_ab):
    """``H_ab`` of the translation by ``p_ab``."""
    return _call("translation", p_ab)


def inverse(H_ab):
    """``H_ba = H_ab⁻¹``."""
    return _call("inverse", H_ab)


def transform_point(H_ab, x_b):
    """``x_a = R_ab x_b + p_ab``."""
    return _call("transform_point", H_ab, x_b)


def transform_vector(H_ab, u_b):
    """``u_a = R_ab u_b``."""
    return _call("transform_vector", H_ab, u_b)


def se3_hat(T):
    """``[[ω̂, v], [0, 0]]``."""
    return _call("se3_hat", T)


def se3_vee(T_hat):
    """``[ω; v]`` from an element of se(3)."""
    return _call("se3_vee", T_hat)


def Ad(H_ab):
    """``[[R, 0], [p̂ R, R]]``; ``T_a = Ad(H_ab) T_b``."""
    return _call("Ad", H_ab)


def Ad_inv(H_ab):
    """``Ad(H_ab)⁻¹ = Ad(H_ba)``."""
    return _call("Ad_inv", H_ab)


def ad(T):
    """``[[ω̂, 0], [v̂, ω̂]]``."""
    return _call("ad", T)


def Ad_dot(H_ab, T_b):
    """``Ad(H_ab) ad(T_b)``, the time derivative of ``Ad(H_ab)`` for the body twist ``T_b``."""
    return _call("Ad_dot", H_ab, T_b)


def transport_twist(H_ab, T_b):
    """``T_a = Ad(H_ab) T_b``."""
    return _call("transport_twist", H_ab, T_b)


def transport_wrench(H_ab, W_a):
    """``W_b = Ad(H_ab)ᵀ W_a``."""
    return _call("transport_wrench", H_ab, W_a)


def power(W, T):
    """``Wᵀ T``."""
    return _call("power", W, T)


def exp_se3(T):
    """``exp(T̂)``."""
    return _call("exp_se3", T)


def log_se3(H_ab):
    """``T`` with ``exp_se3(T) = H_ab``, ``|ω| ≤ π``."""
    return _call("log_se3", H_ab)


def mass_matrix(m, r, I_o):
    """``[[I_o, m r̂], [m r̂ᵀ, m 1]]``."""
    return _call("mass_matrix", m, r, I_o)


def inertia_about_point(m, r, I_c):
    """``I_c + m r̂ᵀ r̂``."""
    return _call("inertia_about_point", m, r, I_c)


def inertia_from_second_moment(S):
    """``tr(S) 1 − S``."""
    return _call("inertia_from_second_moment", S)


def mass_matrix_parts(M):
    """``(m, r, I_c)`` of a spatial mass matrix."""
    return _call("mass_matrix_parts", M)


def transport_mass_matrix(M_a, H_ab):
    """``M_b = Ad(H_ab)ᵀ M_a Ad(H_ab)``."""
    return _call("transport_mass_matrix", M_a, H_ab)


def box(half_extents, m):
    """Mass matrix at the centre of a homogeneous box."""
    return _call("box", half_extents, m)


def cylinder(length, radius, m):
    """Mass matrix at the centre of a homogeneous cylinder of axis z."""
    return _call("cylinder", length, radius, m)


def sphere(radius, m):
    """Mass matrix at the centre of a homogeneous ball."""
    return _call("sphere", radius, m)


def ellipsoid(semi_axes, m):
    """Mass matrix at the centre of a homogeneous ellipsoid."""
    return _call("ellipsoid", semi_axes, m)


def newton_euler_bias(M_b, T_b):
    """``−ad(T_b)ᵀ M_b T_b``."""
    return _call("newton_euler_bias", M_b, T_b)


def newton_euler_acceleration(M_b, T_b, W_b):
    """``dT_b/dt = M_b⁻¹ (W_b + ad(T_b)ᵀ M_b T_b)`` (linear solve)."""
    return ca.solve(M_b, W_b - newton_euler_bias(M_b, T_b))

