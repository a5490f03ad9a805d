"""Rigid-motion algebra on NumPy arrays, with input validation.

Every function here is the NumPy form (``sympy.lambdify``, through
:func:`ncgen.symbolic.numpy_forms.numpy_function`) of the SymPy formula of the same name in
:mod:`ncgen.symbolic.rigid_motion` or :mod:`ncgen.symbolic.spatial_inertia`; see those modules
for the mathematics and ``docs/notation.md`` for the symbols.  Conventions (arboris):
``H_ab = [[R_ab, p_ab], [0, 1]]`` is the pose of frame b in frame a, twists are ``[ω; v]``,
wrenches ``[τ; f]``, ``T_a = Ad(H_ab) T_b``, ``W_b = Ad(H_ab)ᵀ W_a``.  SI units.

Arguments may carry leading batch dimensions (``H_ab`` of shape ``(..., 4, 4)``, ``T`` of shape
``(..., 6)``, angles of shape ``(...)``); batch dimensions broadcast against each other and
lead the result.  Bad input raises :class:`~ncgen.errors.ShapeError` (wrong shape),
:class:`~ncgen.errors.RotationError` (a rotation or homogeneous matrix that is not one, beyond the
printed precision that :func:`ncgen.validation.nearest_rotation` projects) or :class:`~ncgen.errors.InertiaError` (non-positive mass or size,
an inertia that is not symmetric positive definite or violates the triangle inequality); the
message names the argument, what was expected and what was found.
"""
from __future__ import annotations

import numpy as np

from ncgen.errors import InertiaError, RotationError, ShapeError
from ncgen.symbolic.numpy_forms import numpy_function
from ncgen.validation import ROTATION_TOL, nearest_rotation

ROTATION_TOLERANCE = ROTATION_TOL
"""Largest accepted ``max |RᵀR − 1|`` (and deviation of a homogeneous matrix's bottom row)."""

INERTIA_TOLERANCE = 1e-9
"""Relative tolerance of the symmetry and structure checks on inertia and mass matrices."""

C_CORE = ("inverse", "Ad", "Ad_inv", "exp_se3", "log_se3", "transport_twist", "transport_wrench",
          "transport_mass_matrix")
"""Functions of the generated C package (:func:`write_c_package`)."""


# --- evaluation of the SymPy forms -----------------------------------------------------------

def _numpy_forms(name: str):
    from ncgen.symbolic.rigid_motion_forms import form    # SymPy: only when a form is first evaluated

    f = form(name)
    known = list(f.placeholders)
    stages = []
    for k, (symbols, expr) in enumerate(f.stages):
        stages.append(numpy_function(expr, list(known), key=("ncgen.rigid_motion", name, "stage", k)))
        known.append(symbols)
    outputs = [numpy_function(o.expr, known, key=("ncgen.rigid_motion", name, o.name)) for o in f.outputs]
    return f, stages, outputs


def _evaluate_one(name: str, values):
    f, stages, outputs = _numpy_forms(name)
    values = list(values)
    for stage in stages:
        values.append(stage(*values))
    results = tuple(np.reshape(fn(*values), o.shape) if o.shape else fn(*values)
                    for fn, o in zip(outputs, f.outputs))
    return results if len(results) > 1 else results[0]


def _evaluate(name: str, *values):
    """Evaluate form ``name`` on validated arrays, looping over broadcast batch dimensions."""
    from ncgen.symbolic.rigid_motion_forms import form

    f = form(name)
    batch = np.broadcast_shapes(*(v.shape[:v.ndim - len(a.shape)] for v, a in zip(values, f.args)))
    if batch == ():
        return _evaluate_one(name, values)
    values = [np.broadcast_to(v, batch + a.shape) for v, a in zip(values, f.args)]
    rows = [_evaluate_one(name, [v[i] for v in values]) for i in np.ndindex(batch)]
    if len(f.outputs) == 1:
        return np.asarray(rows).reshape(batch + f.outputs[0].shape)
    return tuple(np.asarray([row[k] for row in rows]).reshape(batch + o.shape)
                 for k, o in enumerate(f.outputs))


# --- validation ------------------------------------------------------------------------------

def _shape_text(core: tuple[int, ...]) -> str:
    return "(..., " + ", ".join(map(str, core)) + ")" if core else "(...) (a scalar or an array of scalars)"


def _array(x, name: str, core: tuple[int, ...]) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ShapeError(f"{name}: expected a numeric array of shape {_shape_text(core)}, "
                         f"found {type(x).__name__} ({exc})") from None
    if a.ndim < len(core) or a.shape[a.ndim - len(core):] != core:
        raise ShapeError(f"{name}: expected an array of shape {_shape_text(core)}, found shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ShapeError(f"{name}: expected finite numbers, found NaN or infinity")
    return a


def _scalar(x, name: str) -> np.ndarray:
    return _array(x, name, ())


def check_vector(x, name: str, n: int = 3) -> np.ndarray:
    """``x`` as an array of ``n``-vectors ``(..., n)``; raises naming ``name``."""
    return _array(x, name, (n,))


def check_rotation(R, name: str) -> np.ndarray:
    """``R`` as an array of rotation matrices ``(..., 3, 3)``, those given with printed
    precision projected onto SO(3) (:func:`ncgen.validation.nearest_rotation`, the one rule);
    raises naming ``name``."""
    return nearest_rotation(_array(R, name, (3, 3)), name)


def check_homogeneous(H, name: str) -> np.ndarray:
    """``H`` as an array of homogeneous matrices ``(..., 4, 4)``; raises naming ``name``."""
    H = _array(H, name, (4, 4))
    rows = H[..., 3, :].reshape(-1, 4)
    bottom_error = np.max(np.abs(rows - [0.0, 0.0, 0.0, 1.0]), axis=1, initial=0.0)
    if np.any(bottom_error > ROTATION_TOLERANCE):
        worst = rows[np.argmax(bottom_error)]
        raise RotationError(f"{name}: expected a homogeneous matrix [[R, p], [0, 1]] with bottom row "
                            f"(0, 0, 0, 1), found bottom row {tuple(worst.tolist())}")
    H = H.copy()
    H[..., :3, :3] = check_rotation(H[..., :3, :3], f"{name}[:3, :3]")
    return H


def _positive(x, name: str, what: str) -> np.ndarray:
    a = _array(x, name, ())
    if np.any(a <= 0):
        raise InertiaError(f"{name}: expected a positive {what}, found {np.min(a):g}")
    return a


def _positive_vector(x, name: str, what: str) -> np.ndarray:
    a = check_vector(x, name)
    if np.any(a <= 0):
        raise InertiaError(f"{name}: expected three positive {what}, found {a.tolist()}")
    return a


def _inertia_tensor(I, name: str) -> np.ndarray:
    I = _array(I, name, (3, 3))
    scale = max(1.0, float(np.max(np.abs(I), initial=0.0)))
    asym = np.max(np.abs(I - np.swapaxes(I, -1, -2)), initial=0.0)
    if asym > INERTIA_TOLERANCE * scale:
        raise InertiaError(f"{name}: expected a symmetric inertia tensor, found max |I − Iᵀ| = {asym:.3g}")
    moments = np.linalg.eigvalsh(I).reshape(-1, 3)
    if np.any(moments <= 0):
        found = moments[np.argmin(moments[:, 0])]
        raise InertiaError(f"{name}: expected a positive definite inertia tensor, "
                           f"found principal moments {found.tolist()}")
    excess = moments[:, 2] - moments[:, 0] - moments[:, 1]
    if np.any(excess > INERTIA_TOLERANCE * scale):
        found = moments[np.argmax(excess)]
        raise InertiaError(f"{name}: principal moments violate the triangle inequality "
                           f"(largest ≤ sum of the other two), found {found.tolist()}")
    return I


def check_mass_matrix(M, name: str) -> np.ndarray:
    """``M`` as an array of spatial mass matrices ``(..., 6, 6)``; raises naming ``name``."""
    M = _array(M, name, (6, 6))
    m = M[..., 3, 3]
    if np.any(m <= 0):
        raise InertiaError(f"{name}: expected a positive mass M[3, 3], found {np.min(m):g}")
    scale = max(1.0, float(np.max(np.abs(M), initial=0.0)))
    upper = M[..., :3, 3:]
    defects = {
        "symmetric": np.max(np.abs(M - np.swapaxes(M, -1, -2)), initial=0.0),
        "lower-right block m·1": np.max(np.abs(M[..., 3:, 3:] - m[..., None, None] * np.eye(3)), initial=0.0),
        "upper-right block m r̂ skew-symmetric": np.max(np.abs(upper + np.swapaxes(upper, -1, -2)), initial=0.0),
    }
    for what, defect in defects.items():
        if defect > INERTIA_TOLERANCE * scale:
            raise InertiaError(f"{name}: expected a spatial mass matrix [[I_o, m r̂], [m r̂ᵀ, m 1]] "
                               f"({what}), found a deviation of {defect:.3g}")
    eigenvalues = np.linalg.eigvalsh(M).reshape(-1, 6)
    if np.any(eigenvalues <= 0):
        found = eigenvalues[np.argmin(eigenvalues[:, 0])]
        raise InertiaError(f"{name}: expected a positive definite mass matrix, found eigenvalues {found.tolist()}")
    return M


# --- rotations ---------------------------------------------------------------------------------

def rotx(angle) -> np.ndarray:
    """Rotation matrix by ``angle`` (rad) about x; shape ``(..., 3, 3)``."""
    return _evaluate("rotx", _scalar(angle, "angle"))


def roty(angle) -> np.ndarray:
    """Rotation matrix by ``angle`` (rad) about y; shape ``(..., 3, 3)``."""
    return _evaluate("roty", _scalar(angle, "angle"))


def rotz(angle) -> np.ndarray:
    """Rotation matrix by ``angle`` (rad) about z; shape ``(..., 3, 3)``."""
    return _evaluate("rotz", _scalar(angle, "angle"))


def rotzyx(az, ay, ax) -> np.ndarray:
    """``Rz(az) Ry(ay) Rx(ax)`` (rad); shape ``(..., 3, 3)``."""
    return _evaluate("rotzyx", _scalar(az, "az"), _scalar(ay, "ay"), _scalar(ax, "ax"))


def zyx_angles(R_ab) -> np.ndarray:
    """``[az, ay, ax]`` with ``rotzyx(az, ay, ax) = R_ab``, ``ay ∈ [−π/2, π/2]``; at gimbal lock
    ``ax = 0`` (see :func:`ncgen.symbolic.rigid_motion.zyx_angles`)."""
    return _evaluate("zyx_angles", check_rotation(R_ab, "R_ab"))


def so3_hat(omega) -> np.ndarray:
    """``ω̂`` with ``ω̂ x = ω × x``; shape ``(..., 3, 3)``."""
    return _evaluate("so3_hat", check_vector(omega, "omega"))


def so3_vee(Omega) -> np.ndarray:
    """The vector of the skew-symmetric part of ``Omega``; shape ``(..., 3)``."""
    return _evaluate("so3_vee", _array(Omega, "Omega", (3, 3)))


def exp_so3(omega) -> np.ndarray:
    """Rotation ``exp(ω̂)`` (Rodrigues) of the rotation vector ``omega`` (rad)."""
    return _evaluate("exp_so3", check_vector(omega, "omega"))


def log_so3(R_ab) -> np.ndarray:
    """Rotation vector ``ω`` with ``exp_so3(ω) = R_ab``, ``|ω| ≤ π``."""
    return _evaluate("log_so3", check_rotation(R_ab, "R_ab"))


# --- poses -----------------------------------------------------------------------------------

def homogeneous(R_ab, p_ab) -> np.ndarray:
    """``H_ab = [[R_ab, p_ab], [0, 1]]``."""
    return _evaluate("homogeneous", check_rotation(R_ab, "R_ab"), check_vector(p_ab, "p_ab"))


def translation(p_ab) -> np.ndarray:
    """``H_ab`` of the translation by ``p_ab`` (m)."""
    return _evaluate("translation", check_vector(p_ab, "p_ab"))


def inverse(H_ab) -> np.ndarray:
    """``H_ba = H_ab⁻¹``."""
    return _evaluate("inverse", check_homogeneous(H_ab, "H_ab"))


def transform_point(H_ab, x_b) -> np.ndarray:
    """``x_a = R_ab x_b + p_ab``."""
    return _evaluate("transform_point", check_homogeneous(H_ab, "H_ab"), check_vector(x_b, "x_b"))


def transform_vector(H_ab, u_b) -> np.ndarray:
    """``u_a = R_ab u_b`` (free vectors: directions, velocities, forces)."""
    return _evaluate("transform_vector", check_homogeneous(H_ab, "H_ab"), check_vector(u_b, "u_b"))


# --- twists and wrenches ---------------------------------------------------------------------

def se3_hat(T) -> np.ndarray:
    """``[[ω̂, v], [0, 0]]`` (4x4) of the twist ``T = [ω; v]``."""
    return _evaluate("se3_hat", check_vector(T, "T", 6))


def se3_vee(T_hat) -> np.ndarray:
    """``[ω; v]`` from a 4x4 element of se(3) (the skew part of its 3x3 block gives ω)."""
    return _evaluate("se3_vee", _array(T_hat, "T_hat", (4, 4)))


def Ad(H_ab) -> np.ndarray:
    """``Ad(H_ab) = [[R, 0], [p̂ R, R]]``; ``T_a = Ad(H_ab) T_b``."""
    return _evaluate("Ad", check_homogeneous(H_ab, "H_ab"))


def Ad_inv(H_ab) -> np.ndarray:
    """``Ad(H_ab)⁻¹ = Ad(H_ba)``."""
    return _evaluate("Ad_inv", check_homogeneous(H_ab, "H_ab"))


def ad(T) -> np.ndarray:
    """``ad([ω; v]) = [[ω̂, 0], [v̂, ω̂]]``."""
    return _evaluate("ad", check_vector(T, "T", 6))


def Ad_dot(H_ab, T_b) -> np.ndarray:
    """``d/dt Ad(H_ab) = Ad(H_ab) ad(T_b)``, ``T_b`` the body twist of b relative to a, in b."""
    return _evaluate("Ad_dot", check_homogeneous(H_ab, "H_ab"), check_vector(T_b, "T_b", 6))


def transport_twist(H_ab, T_b) -> np.ndarray:
    """``T_a = Ad(H_ab) T_b``."""
    return _evaluate("transport_twist", check_homogeneous(H_ab, "H_ab"), check_vector(T_b, "T_b", 6))


def transport_wrench(H_ab, W_a) -> np.ndarray:
    """``W_b = Ad(H_ab)ᵀ W_a`` (moment taken about b's origin, in b's axes)."""
    return _evaluate("transport_wrench", check_homogeneous(H_ab, "H_ab"), check_vector(W_a, "W_a", 6))


def power(W, T) -> np.ndarray:
    """``Wᵀ T`` (W), wrench and twist expressed in the same frame."""
    return _evaluate("power", check_vector(W, "W", 6), check_vector(T, "T", 6))


def exp_se3(T) -> np.ndarray:
    """``H = exp(T̂)``: the pose reached from the identity with constant body twist ``T`` in 1 s."""
    return _evaluate("exp_se3", check_vector(T, "T", 6))


def log_se3(H_ab) -> np.ndarray:
    """Twist ``T = [ω; v]`` with ``exp_se3(T) = H_ab`` and ``|ω| ≤ π``."""
    return _evaluate("log_se3", check_homogeneous(H_ab, "H_ab"))


# --- mass matrices -----------------------------------------------------------------------------

def mass_matrix(m, r, I_o) -> np.ndarray:
    """``[[I_o, m r̂], [m r̂ᵀ, m 1]]``: mass ``m`` (kg), centre of mass ``r`` (m) seen from the
    frame, inertia ``I_o`` (kg·m²) about the frame's origin in its axes."""
    return _evaluate("mass_matrix", _positive(m, "m", "mass"), check_vector(r, "r"),
                     _inertia_tensor(I_o, "I_o"))


def inertia_about_point(m, r, I_c) -> np.ndarray:
    """Parallel axis: ``I_o = I_c + m r̂ᵀ r̂`` for a centre of mass at ``r`` from the point o."""
    return _evaluate("inertia_about_point", _positive(m, "m", "mass"), check_vector(r, "r"),
                     _inertia_tensor(I_c, "I_c"))


def inertia_from_second_moment(S) -> np.ndarray:
    """``I = tr(S) 1 − S`` from the second moment ``S = ∫ x xᵀ dm`` (kg·m²)."""
    return _evaluate("inertia_from_second_moment", _array(S, "S", (3, 3)))


def mass_matrix_parts(M) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(m, r, I_c)``: mass, centre of mass in the frame, inertia about the centre of mass."""
    return _evaluate("mass_matrix_parts", check_mass_matrix(M, "M"))


def transport_mass_matrix(M_a, H_ab) -> np.ndarray:
    """``M_b = Ad(H_ab)ᵀ M_a Ad(H_ab)``: the mass matrix at frame b from the one at frame a."""
    return _evaluate("transport_mass_matrix", check_mass_matrix(M_a, "M_a"), check_homogeneous(H_ab, "H_ab"))


def principal_frame(M_a) -> tuple[np.ndarray, np.ndarray]:
    """``(H_ap, M_p)``: the principal frame p of a mass matrix given at frame a, and the
    (diagonal) mass matrix there.

    p's origin is the centre of mass and its axes are principal axes of inertia, ordered by
    increasing principal moment, right-handed; ``M_p = transport_mass_matrix(M_a, H_ap)
    = diag(I₁, I₂, I₃, m, m, m)``.  The eigen-decomposition is NumPy's (``eigh``); centre of
    mass and central inertia come from :func:`mass_matrix_parts`.
    """
    m, r, I_c = mass_matrix_parts(M_a)
    moments, axes = np.linalg.eigh(I_c)
    axes[..., :, 2] *= np.sign(np.linalg.det(axes))[..., None]
    H_ap = homogeneous(axes, r)
    M_p = np.zeros(np.shape(m) + (6, 6))
    diagonal = np.concatenate([moments, np.repeat(np.asarray(m)[..., None], 3, axis=-1)], axis=-1)
    M_p[..., range(6), range(6)] = diagonal
    return H_ap, M_p


def box(half_extents, m) -> np.ndarray:
    """Mass matrix at the centre of a homogeneous box of half extents ``(a, b, c)`` (m)."""
    return _evaluate("box", _positive_vector(half_extents, "half_extents", "half extents"),
                     _positive(m, "m", "mass"))


def cylinder(length, radius, m) -> np.ndarray:
    """Mass matrix at the centre of a homogeneous cylinder of axis z (full ``length``)."""
    return _evaluate("cylinder", _positive(length, "length", "length"),
                     _positive(radius, "radius", "radius"), _positive(m, "m", "mass"))


def sphere(radius, m) -> np.ndarray:
    """Mass matrix at the centre of a homogeneous ball."""
    return _evaluate("sphere", _positive(radius, "radius", "radius"), _positive(m, "m", "mass"))


def ellipsoid(semi_axes, m) -> np.ndarray:
    """Mass matrix at the centre of a homogeneous ellipsoid of semi-axes ``(a, b, c)``."""
    return _evaluate("ellipsoid", _positive_vector(semi_axes, "semi_axes", "semi-axes"),
                     _positive(m, "m", "mass"))


# --- Newton–Euler ------------------------------------------------------------------------------

def newton_euler_bias(M_b, T_b) -> np.ndarray:
    """``−ad(T_b)ᵀ M_b T_b`` of ``M_b dT_b/dt − ad(T_b)ᵀ M_b T_b = W_b``."""
    return _evaluate("newton_euler_bias", check_mass_matrix(M_b, "M_b"), check_vector(T_b, "T_b", 6))


def newton_euler_acceleration(M_b, T_b, W_b) -> np.ndarray:
    """``dT_b/dt = M_b⁻¹ (W_b + ad(T_b)ᵀ M_b T_b)``: body-twist derivative of a free rigid body
    under the total wrench ``W_b`` (in b, moment about b's origin)."""
    M = check_mass_matrix(M_b, "M_b")
    rhs = check_vector(W_b, "W_b", 6) - newton_euler_bias(M, T_b)
    return np.linalg.solve(M, rhs[..., None])[..., 0]
