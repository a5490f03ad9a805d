"""Rigid-motion algebra in SymPy: rotations, poses, twists, wrenches, exponential and logarithm.

This is the single source of every rigid-motion formula in ncgen: the NumPy forms
(:mod:`ncgen.rigid_motion`), the CasADi forms (:mod:`ncgen.assembly.rigid_motion`) and the
generated C are all produced from these expressions.  The module never imports CasADi.

Conventions (arboris-python; symbols in ``docs/notation.md``, section "Rigid motion"):

- ``H_ab = [[R_ab, p_ab], [0, 1]]`` is the pose of frame b relative to frame a: the columns
  of ``R_ab`` are b's unit vectors in a's coordinates and ``p_ab`` is b's origin in a's
  coordinates, so a point with coordinates ``x_b`` in b has ``x_a = R_ab x_b + p_ab``.
- A twist is ``[ω; v]`` (angular part first), a wrench ``[τ; f]`` (moment first).
- ``T_b`` denotes the body twist of b relative to a, expressed in b:
  ``se3_hat(T_b) = H_ab⁻¹ dH_ab/dt``, i.e. ``ω`` is b's angular velocity and ``v`` the
  velocity of b's origin, both in b's coordinates.
- ``Ad(H_ab) = [[R, 0], [p̂ R, R]]`` changes the frame a twist is expressed in:
  ``T_a = Ad(H_ab) T_b``.  Wrenches go the other way with the transpose:
  ``W_b = Ad(H_ab)ᵀ W_a``, so that the power ``Wᵀ T`` is the same in every frame.
- ``ad([ω; v]) = [[ω̂, 0], [v̂, ω̂]]``.

Units: radians, metres, seconds; twists in rad/s and m/s, wrenches in N·m and N.
Vectors are SymPy column matrices; every function accepts anything ``sp.Matrix`` accepts.

Exponential and logarithm coefficients such as ``sin θ / θ`` are ``Piecewise``: below
``θ² < SERIES_THRESHOLD`` a Taylor polynomial in ``θ²`` (derived here with
:func:`sympy.series`), above it the closed form evaluated at ``max(θ², SERIES_THRESHOLD)``.
The ``max`` never changes a value (that branch is only selected above the threshold) but keeps
the unselected branch finite, so that branch-evaluating back ends (NumPy ``select``, CasADi
``if_else``, the generated C) produce neither NaN values nor NaN derivatives at ``θ = 0``.
"""
from __future__ import annotations

from functools import lru_cache

import sympy as sp

SERIES_THRESHOLD = sp.Rational(1, 10**4)
"""Squared angle below which exp/log coefficients use their Taylor polynomial (θ < 0.01 rad)."""

SERIES_TERMS = 4
"""Terms of each Taylor polynomial in θ²; at the threshold the first omitted term is below 1e-17."""

GIMBAL_LOCK_TOLERANCE = sp.Rational(1, 10**10)
"""``cos(ay)`` below which :func:`zyx_angles` treats the rotation as gimbal-locked."""


def as_vector(x, n: int) -> sp.Matrix:
    """``x`` (any sequence or matrix of ``n`` entries) as an ``n x 1`` SymPy column."""
    v = sp.Matrix(x)
    if v.shape != (n, 1):
        v = v.reshape(n, 1)
    return v


def _blocks(a, b, c, d) -> sp.Matrix:
    return sp.Matrix(sp.BlockMatrix([[a, b], [c, d]]))


# --- so(3) and rotations -------------------------------------------------------------------

def so3_hat(omega) -> sp.Matrix:
    """``ω̂``, the 3x3 skew-symmetric matrix with ``ω̂ x = ω × x``."""
    w1, w2, w3 = as_vector(omega, 3)
    return sp.Matrix([[0, -w3, w2], [w3, 0, -w1], [-w2, w1, 0]])


def so3_vee(Omega) -> sp.Matrix:
    """Inverse of :func:`so3_hat`: the vector of the skew part of a 3x3 matrix."""
    W = sp.Matrix(Omega)
    return sp.Matrix([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]]) / 2


def rotx(angle) -> sp.Matrix:
    """Rotation by ``angle`` (rad) about the x axis."""
    c, s = sp.cos(angle), sp.sin(angle)
    return sp.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]])


def roty(angle) -> sp.Matrix:
    """Rotation by ``angle`` (rad) about the y axis."""
    c, s = sp.cos(angle), sp.sin(angle)
    return sp.Matrix([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rotz(angle) -> sp.Matrix:
    """Rotation by ``angle`` (rad) about the z axis."""
    c, s = sp.cos(angle), sp.sin(angle)
    return sp.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def rotation_about(axis, angle) -> sp.Matrix:
    """Rodrigues for a unit ``axis`` ``u``: ``R = 1 + sin θ û + (1 − cos θ) û²`` (θ = ``angle``, rad).
    Unlike :func:`exp_so3` it has no small-angle branch: ``u`` is a unit vector, not ``θ u``."""
    U = so3_hat(axis)
    return sp.eye(3) + sp.sin(angle) * U + (1 - sp.cos(angle)) * U * U


def rotzyx(az, ay, ax) -> sp.Matrix:
    """``R = Rz(az) Ry(ay) Rx(ax)``: yaw, pitch, roll about the moving axes z, y', x''."""
    return rotz(az) * roty(ay) * rotx(ax)


def zyx_angles(R_ab) -> sp.Matrix:
    """The angles ``[az, ay, ax]`` with ``rotzyx(az, ay, ax) = R_ab``.

    ``ay = atan2(−R₂₀, √(R₂₁² + R₂₂²)) ∈ [−π/2, π/2]`` and ``ax = atan2(R₂₁, R₂₂)``;
    ``az`` is then read from ``R Rx(ax)ᵀ = Rz(az) Ry(ay)``, which stays exact whatever ``ax``.
    Gimbal lock: when ``cos ay < GIMBAL_LOCK_TOLERANCE`` only ``az ∓ ax`` is defined; then
    ``ax = 0`` and ``az`` carries the whole rotation about the vertical.  The returned angles
    always reproduce ``R_ab``.
    """
    R = sp.Matrix(R_ab)
    cos_ay_sq = R[2, 1] ** 2 + R[2, 2] ** 2
    ay = sp.atan2(-R[2, 0], sp.sqrt(cos_ay_sq))
    ax = sp.Piecewise((0, cos_ay_sq < GIMBAL_LOCK_TOLERANCE ** 2), (sp.atan2(R[2, 1], R[2, 2]), True), evaluate=False)
    cx, sx = sp.cos(ax), sp.sin(ax)
    az = sp.atan2(R[0, 2] * sx - R[0, 1] * cx, R[1, 1] * cx - R[1, 2] * sx)
    return sp.Matrix([az, ay, ax])


# --- poses ---------------------------------------------------------------------------------

def homogeneous(R_ab, p_ab) -> sp.Matrix:
    """``H_ab = [[R_ab, p_ab], [0, 1]]``."""
    return _blocks(sp.Matrix(R_ab), as_vector(p_ab, 3), sp.zeros(1, 3), sp.ones(1, 1))


def translation(p_ab) -> sp.Matrix:
    """``H_ab`` of a pure translation by ``p_ab`` (m)."""
    return homogeneous(sp.eye(3), p_ab)


def rotation_of(H_ab) -> sp.Matrix:
    """``R_ab``, the rotation block of ``H_ab``."""
    return sp.Matrix(H_ab)[:3, :3]


def position_of(H_ab) -> sp.Matrix:
    """``p_ab``, the translation column of ``H_ab``."""
    return sp.Matrix(H_ab)[:3, 3]


def inverse(H_ab) -> sp.Matrix:
    """``H_ba = H_ab⁻¹ = [[R_abᵀ, −R_abᵀ p_ab], [0, 1]]``."""
    R, p = rotation_of(H_ab), position_of(H_ab)
    return homogeneous(R.T, -R.T * p)


def transform_point(H_ab, x_b) -> sp.Matrix:
    """``x_a = R_ab x_b + p_ab``: coordinates in a of the point with coordinates ``x_b`` in b."""
    return rotation_of(H_ab) * as_vector(x_b, 3) + position_of(H_ab)


def transform_vector(H_ab, u_b) -> sp.Matrix:
    """``u_a = R_ab u_b``: a free vector (direction, velocity, force) from b to a coordinates."""
    return rotation_of(H_ab) * as_vector(u_b, 3)


# --- twists, se(3) and adjoints ------------------------------------------------------------

def se3_hat(T) -> sp.Matrix:
    """``T̂ = [[ω̂, v], [0, 0]]`` (4x4) for the twist ``T = [ω; v]``."""
    T = as_vector(T, 6)
    return _blocks(so3_hat(T[:3, 0]), T[3:, 0], sp.zeros(1, 3), sp.zeros(1, 1))


def se3_vee(That) -> sp.Matrix:
    """Inverse of :func:`se3_hat`: ``[ω; v]`` from a 4x4 element of se(3)."""
    X = sp.Matrix(That)
    return sp.Matrix.vstack(so3_vee(X[:3, :3]), X[:3, 3])


def Ad(H_ab) -> sp.Matrix:
    """``Ad(H_ab) = [[R, 0], [p̂ R, R]]``; ``T_a = Ad(H_ab) T_b``."""
    R, p = rotation_of(H_ab), position_of(H_ab)
    return _blocks(R, sp.zeros(3, 3), so3_hat(p) * R, R)


def Ad_inv(H_ab) -> sp.Matrix:
    """``Ad(H_ab)⁻¹ = Ad(H_ba) = [[Rᵀ, 0], [−Rᵀ p̂, Rᵀ]]`` (the adjoint of the inverse pose)."""
    return Ad(inverse(H_ab))


def ad(T) -> sp.Matrix:
    """``ad([ω; v]) = [[ω̂, 0], [v̂, ω̂]]``: ``ad(T₁) T₂`` is the Lie bracket of twists."""
    T = as_vector(T, 6)
    w, v = so3_hat(T[:3, 0]), so3_hat(T[3:, 0])
    return _blocks(w, sp.zeros(3, 3), v, w)


def Ad_dot(H_ab, T_b) -> sp.Matrix:
    """``d/dt Ad(H_ab) = Ad(H_ab) ad(T_b)``.

    ``T_b`` is the body twist of b relative to a expressed in b,
    ``se3_hat(T_b) = H_ab⁻¹ dH_ab/dt``.
    """
    return Ad(H_ab) * ad(T_b)


def transport_twist(H_ab, T_b) -> sp.Matrix:
    """``T_a = Ad(H_ab) T_b``: the same twist, expressed in a instead of b."""
    return Ad(H_ab) * as_vector(T_b, 6)


def transport_wrench(H_ab, W_a) -> sp.Matrix:
    """``W_b = Ad(H_ab)ᵀ W_a``: the wrench ``W_a = [τ; f]`` expressed in b (moment about b's origin)."""
    return Ad(H_ab).T * as_vector(W_a, 6)


def power(W, T):
    """``Wᵀ T`` (W): the power of a wrench on a twist expressed in the same frame; frame invariant."""
    return (as_vector(W, 6).T * as_vector(T, 6))[0, 0]


# --- exponential and logarithm ---------------------------------------------------------------

_t = sp.Dummy("t", positive=True)
_s = sp.Dummy("s", nonnegative=True)

_GENERATORS = {
    "sinc": sp.sin(_t) / _t,                                      # sin θ / θ
    "cosc": 2 * sp.sin(_t / 2) ** 2 / _t ** 2,                    # (1 − cos θ) / θ²
    "sinc3": (_t - sp.sin(_t)) / _t ** 3,                         # (θ − sin θ) / θ³
    "dlog": (1 - _t * sp.cos(_t / 2) / (2 * sp.sin(_t / 2))) / _t ** 2,  # (1 − (θ/2) cot(θ/2)) / θ²
    "asinc": sp.asin(_t) / _t,                                    # asin(s) / s
}


@lru_cache(maxsize=None)
def _taylor(name: str) -> sp.Expr:
    poly = sp.series(_GENERATORS[name], _t, 0, 2 * SERIES_TERMS).removeO()
    return sp.expand(poly.subs(_t, sp.sqrt(_s)))


def taylor_in_square(name: str, x_sq) -> sp.Expr:
    """Taylor polynomial at 0 of the even function ``_GENERATORS[name](t)`` (``SERIES_TERMS``
    terms), as a polynomial in ``x_sq = t²``; derived with :func:`sympy.series`."""
    return _taylor(name).xreplace({_s: x_sq})


def _lt(lhs, rhs) -> sp.Basic:
    """``lhs < rhs`` left unevaluated (no assumption queries on large expressions)."""
    return sp.StrictLessThan(lhs, rhs, evaluate=False)


def coefficient(name: str, x_sq, exact=None, small=None) -> sp.Expr:
    """An exp/log coefficient (``"sinc"``, ``"cosc"``, ``"sinc3"``, ``"dlog"``, ``"asinc"``) as a
    ``Piecewise``: its Taylor polynomial in ``x_sq`` where ``small`` holds (by default
    ``x_sq < SERIES_THRESHOLD``), else ``exact(t)`` (by default the closed form) at
    ``t = √max(x_sq, SERIES_THRESHOLD)``.

    Conditions must not contain a ``Piecewise``: SymPy would fold it into the condition.
    """
    t = sp.sqrt(sp.Max(x_sq, SERIES_THRESHOLD, evaluate=False))
    closed = exact(t) if exact is not None else _GENERATORS[name].xreplace({_t: t})
    small = _lt(x_sq, SERIES_THRESHOLD) if small is None else small
    return sp.Piecewise((taylor_in_square(name, x_sq), small), (closed, True), evaluate=False)


def exp_so3(omega) -> sp.Matrix:
    """Rodrigues: ``R = exp(ω̂) = 1 + (sin θ/θ) ω̂ + ((1 − cos θ)/θ²) ω̂²`` with ``θ = |ω|``."""
    w = as_vector(omega, 3)
    theta_sq = w.dot(w)
    W = so3_hat(w)
    return sp.eye(3) + coefficient("sinc", theta_sq) * W + coefficient("cosc", theta_sq) * W * W


def exp_se3(T) -> sp.Matrix:
    """``H = exp(T̂)`` for ``T = [ω; v]``: ``R = exp(ω̂)``, ``p = V v`` with
    ``V = 1 + ((1 − cos θ)/θ²) ω̂ + ((θ − sin θ)/θ³) ω̂²``.

    ``exp_se3(t T_b)`` is the pose reached after moving with the constant body twist ``T_b``
    for a time ``t`` from the identity.
    """
    T = as_vector(T, 6)
    w, v = T[:3, 0], T[3:, 0]
    theta_sq = w.dot(w)
    W = so3_hat(w)
    V = sp.eye(3) + coefficient("cosc", theta_sq) * W + coefficient("sinc3", theta_sq) * W * W
    return homogeneous(exp_so3(w), V * v)


def log_so3(R_ab) -> sp.Matrix:
    """``ω`` with ``exp_so3(ω) = R_ab`` and ``|ω| = θ ∈ [0, π]``.

    With ``c = cos θ = (tr R − 1)/2`` and ``a = vee(R) = sin θ u`` (u the unit axis):

    - ``c ≥ 0`` (θ ≤ π/2): ``ω = (θ / sin θ) a`` with ``θ = atan2(|a|, c)``; the factor is
      ``asin(s)/s`` at ``s = |a|``, a Taylor polynomial in ``|a|²`` near θ = 0;
    - ``c < 0`` (θ > π/2, where ``a`` vanishes at π): the axis comes from the symmetric part,
      ``(R + Rᵀ)/2 − c 1 = (1 − c) u uᵀ``, read from its column of largest diagonal entry and
      oriented so that ``u·a ≥ 0``; then ``θ = atan2(u·a, c)``.  At θ = π exactly both axes
      ``±u`` are logarithms and ``+u`` (as read) is returned.
    """
    R = sp.Matrix(R_ab)
    c, a, sin_sq = _angle_parts(R)

    B = (R + R.T) / 2 - c * sp.eye(3)
    candidates = []
    for k in range(3):
        u = B[:, k] / sp.sqrt(sp.Max((1 - c) * B[k, k], sp.Rational(1, 3), evaluate=False))
        candidates.append(sp.Piecewise((-1, _lt(u.dot(a), 0)), (1, True), evaluate=False) * u)
    first = (R[0, 0] >= R[1, 1]) & (R[0, 0] >= R[2, 2])
    second = R[1, 1] >= R[2, 2]
    axis = sp.Matrix([sp.Piecewise((candidates[0][i], first), (candidates[1][i], second),
                                   (candidates[2][i], True), evaluate=False) for i in range(3)])
    near_pi = sp.atan2(axis.dot(a), c) * axis

    factor = coefficient("asinc", sin_sq, exact=lambda s: sp.atan2(s, c) / s)
    return sp.Matrix([sp.Piecewise((near_pi[i], _lt(c, 0)), (factor * a[i], True), evaluate=False)
                      for i in range(3)])


def _angle_parts(R) -> tuple:
    """``(cos θ, a = sin θ u, sin² θ)`` of a rotation matrix: Piecewise-free, for conditions."""
    c = (R.trace() - 1) / 2
    a = so3_vee(R)
    return c, a, a.dot(a)


def log_se3(H_ab) -> sp.Matrix:
    """``T = [ω; v]`` with ``exp_se3(T) = H_ab`` and ``|ω| ∈ [0, π]``: ``ω = log_so3(R_ab)``
    and ``v = log_se3_translation(ω, R_ab, p_ab)``."""
    R, p = rotation_of(H_ab), position_of(H_ab)
    return sp.Matrix.vstack(log_so3(R), log_se3_translation(log_so3(R), R, p))


def log_se3_translation(omega, R_ab, p_ab) -> sp.Matrix:
    """``v = V⁻¹ p`` of :func:`log_se3`, given its rotation part ``ω = log_so3(R_ab)``.

    ``V⁻¹ = 1 − ω̂/2 + ((1 − (θ/2) cot(θ/2))/θ²) ω̂²`` (regular up to θ = π).  The Taylor
    branch is chosen from ``R_ab`` (θ < asin 0.01), not from ``ω``, so that the condition stays
    free of the ``Piecewise`` of ``log_so3`` whether ``omega`` is that expression or a symbol
    standing for it (numeric forms evaluate ``log_so3`` first and pass its value).
    """
    w = as_vector(omega, 3)
    W = so3_hat(w)
    c, _, sin_sq = _angle_parts(sp.Matrix(R_ab))
    near_zero = _lt(sin_sq, SERIES_THRESHOLD) & (c > 0)
    V_inv = sp.eye(3) - W / 2 + coefficient("dlog", w.dot(w), small=near_zero) * W * W
    return V_inv * as_vector(p_ab, 3)


# --- quaternions and swings --------------------------------------------------------------------

def _sign_of(x) -> sp.Expr:
    """``−1`` where ``x < 0``, else ``1`` (``x`` free of ``Piecewise``)."""
    return sp.Piecewise((-1, _lt(x, 0)), (1, True), evaluate=False)


def quaternion(R_ab) -> sp.Matrix:
    """Unit quaternion ``[qx, qy, qz, qw]`` (Hamilton, Pinocchio's order) of the rotation
    ``R_ab``, with ``qw ≥ 0``.

    Shepperd's method: of ``4qw² = 1 + tr R`` and ``4qx² = 1 + R₀₀ − R₁₁ − R₂₂`` (and y, z
    alike) the largest is ≥ 1, so its root is well conditioned and the other components
    follow from the off-diagonal sums and differences divided by it.  The branch is the
    largest of ``tr R, R₀₀, R₁₁, R₂₂`` (``qw² ≥ qx² ⇔ tr R ≥ R₀₀``, ...).  Each branch is
    multiplied by the sign of its ``qw`` (a Piecewise-free expression there); the roots
    are taken of ``max(·, 1)``, which never changes the selected branch and keeps the others
    finite."""
    R = sp.Matrix(R_ab)
    tr = R.trace()

    def root(x):
        return sp.sqrt(sp.Max(x, 1, evaluate=False)) / 2

    w, x, y, z = (root(1 + tr), root(1 + R[0, 0] - R[1, 1] - R[2, 2]),
                  root(1 - R[0, 0] + R[1, 1] - R[2, 2]), root(1 - R[0, 0] - R[1, 1] + R[2, 2]))
    d21, d02, d10 = R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]
    s01, s02, s12 = R[0, 1] + R[1, 0], R[0, 2] + R[2, 0], R[1, 2] + R[2, 1]
    branches = [
        ([d21 / (4 * w), d02 / (4 * w), d10 / (4 * w), w], 1),
        ([x, s01 / (4 * x), s02 / (4 * x), d21 / (4 * x)], _sign_of(d21)),
        ([s01 / (4 * y), y, s12 / (4 * y), d02 / (4 * y)], _sign_of(d02)),
        ([s02 / (4 * z), s12 / (4 * z), z, d10 / (4 * z)], _sign_of(d10)),
    ]
    ge = lambda a, b: sp.GreaterThan(a, b, evaluate=False)   # noqa: E731
    conditions = [ge(tr, R[0, 0]) & ge(tr, R[1, 1]) & ge(tr, R[2, 2]),
                  ge(R[0, 0], R[1, 1]) & ge(R[0, 0], R[2, 2]),
                  ge(R[1, 1], R[2, 2]), sp.true]
    return sp.Matrix([sp.Piecewise(*[(sign * comps[i], cond) for (comps, sign), cond in zip(branches, conditions)],
                                   evaluate=False) for i in range(4)])


def quaternion_matrix(quat) -> sp.Matrix:
    """Rotation matrix of the quaternion ``[qx, qy, qz, qw]`` (Hamilton), normalised first."""
    x, y, z, w = as_vector(quat, 4)
    n = sp.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    return sp.Matrix([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                      [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                      [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def quaternion_rate(quat, omega) -> sp.Matrix:
    """``q̇ = ½ q ⊗ [ω; 0]`` for the angular velocity ``ω`` in the rotated frame's axes
    (body axes), ``[qx, qy, qz, qw]`` order: ``q̇_v = ½ (q_w ω + q_v × ω)``, ``q̇_w = −½ q_v·ω``."""
    quat, omega = as_vector(quat, 4), as_vector(omega, 3)
    qv, qw = quat[:3, :], quat[3]
    return sp.Matrix.vstack((qw * omega + so3_hat(qv) * omega) / 2, sp.Matrix([-qv.dot(omega) / 2]))


def swing(u0, u) -> sp.Matrix:
    """Rotation vector ``φ = θ k`` of the smallest rotation taking the unit direction ``u0`` to
    the unit direction ``u`` (``k = u0 × u / |u0 × u|``, ``θ = atan2(|u0 × u|, u0·u)``):
    ``φ = (θ / sin θ)(u0 × u)``, ⟂ ``u0``.  The factor is ``asin(s)/s`` (``s = |u0 × u|``), a
    Taylor polynomial in ``s²`` near θ = 0; defined for θ < π (singular at ``u = −u0``)."""
    u0, u = as_vector(u0, 3), as_vector(u, 3)
    w = u0.cross(u)
    s_sq, c = w.dot(w), u0.dot(u)
    s = sp.sqrt(sp.Max(s_sq, sp.Rational(1, 10**300), evaluate=False))
    near_zero = _lt(s_sq, SERIES_THRESHOLD) & sp.StrictGreaterThan(c, 0, evaluate=False)
    factor = coefficient("asinc", s_sq, exact=lambda t: sp.atan2(s, c) / s, small=near_zero)
    return factor * w
