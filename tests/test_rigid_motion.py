"""Rigid-motion algebra, NumPy forms: reference values, group laws, exp/log near the singular
angles, derivatives against finite differences, mass matrices, Newton–Euler, bad inputs."""
import numpy as np
import pytest

import ncgen.rigid_motion as rm
from ncgen.errors import InertiaError, RotationError, ShapeError

RNG = np.random.default_rng(20240611)


def random_rotation(rng=RNG, angle=None):
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    return rm.exp_so3(axis * (rng.uniform(0, np.pi) if angle is None else angle))


def random_pose(rng=RNG):
    return rm.homogeneous(random_rotation(rng), rng.normal(size=3))


def random_mass_matrix(rng=RNG):
    """Mass matrix at a random frame of a box with random mass and size."""
    M_c = rm.box(rng.uniform(0.1, 1.0, size=3), rng.uniform(0.5, 3.0))
    return rm.transport_mass_matrix(M_c, random_pose(rng))


# --- reference values (arboris) ------------------------------------------------------------------
#: arboris' exp of the twist (1, 2, 3, 10, 11, 12) (8 decimals published).
ARBORIS_TWIST = [1, 2, 3, 10, 11, 12]
ARBORIS_EXP = [[-0.69492056, 0.71352099, 0.08929286, 2.90756949],
               [-0.19200697, -0.30378504, 0.93319235, 11.86705709],
               [0.69297817, 0.6313497, 0.34810748, 13.78610544],
               [0, 0, 0, 1]]
#: arboris' transport of diag(3, 2, 4, 1, 1, 1) to a frame at (1, 3, 0) from the centre of mass.
ARBORIS_M_C, ARBORIS_OFFSET = np.diag([3.0, 2, 4, 1, 1, 1]), [1, 3, 0]
ARBORIS_M_B = [[12, -3, 0, 0, 0, -3], [-3, 3, 0, 0, 0, 1], [0, 0, 14, 3, -1, 0],
               [0, 0, 3, 1, 0, 0], [0, 0, -1, 0, 1, 0], [-3, 1, 0, 0, 0, 1]]


def test_exp_matches_arboris():
    np.testing.assert_allclose(rm.exp_se3(ARBORIS_TWIST), ARBORIS_EXP, atol=1e-8)


def test_exp_matches_matrix_exponential():
    expm = pytest.importorskip("scipy.linalg").expm
    for _ in range(5):
        T = RNG.normal(size=6) * 2
        np.testing.assert_allclose(rm.exp_se3(T), expm(rm.se3_hat(T)), atol=1e-13)


def test_mass_matrix_transport_matches_arboris():
    """Arboris' value is Ad(H_ab)ᵀ M_a Ad(H_ab) with H_ab the translation by (1, 3, 0): the
    mass matrix at a frame b whose origin is at (1, 3, 0) from the centre of mass."""
    M_b = rm.transport_mass_matrix(ARBORIS_M_C, rm.translation(ARBORIS_OFFSET))
    np.testing.assert_allclose(M_b, ARBORIS_M_B, atol=1e-14)
    m, r, I_c = rm.mass_matrix_parts(M_b)
    assert m == 1 and np.allclose(r, [-1, -3, 0]) and np.allclose(I_c, np.diag([3, 2, 4]))


def test_shapes():
    np.testing.assert_allclose(rm.sphere(1, 5), np.diag([2, 2, 2, 5, 5, 5.0]), atol=1e-15)
    np.testing.assert_allclose(rm.box([1, 2, 3], 3), np.diag([13, 10, 5, 3, 3, 3.0]), atol=1e-14)
    np.testing.assert_allclose(rm.cylinder(2.0, 1.0, 12), np.diag([7, 7, 6, 12, 12, 12.0]), atol=1e-14)
    np.testing.assert_allclose(rm.ellipsoid([1, 2, 3], 5), np.diag([13, 10, 5, 5, 5, 5.0]), atol=1e-14)


def test_shapes_against_monte_carlo_free_integration():
    """Inertia of the ellipsoid from a sampled point cloud (independent of the integration)."""
    a = np.array([0.5, 1.0, 2.0])
    pts = RNG.uniform(-1, 1, size=(400_000, 3))
    pts = pts[np.sum(pts ** 2, axis=1) <= 1] * a
    S = pts.T @ pts / len(pts)
    I = np.trace(S) * np.eye(3) - S
    np.testing.assert_allclose(rm.ellipsoid(a, 1.0)[:3, :3], I, atol=0.02)


# --- rotations and poses -------------------------------------------------------------------------

def test_elementary_rotations_and_zyx():
    az, ay, ax = 0.3, -0.4, 1.2
    R = rm.rotzyx(az, ay, ax)
    np.testing.assert_allclose(R, rm.rotz(az) @ rm.roty(ay) @ rm.rotx(ax), atol=1e-15)
    np.testing.assert_allclose(rm.rotx(0.5), rm.exp_so3([0.5, 0, 0]), atol=1e-15)
    np.testing.assert_allclose(rm.roty(0.5), rm.exp_so3([0, 0.5, 0]), atol=1e-15)
    np.testing.assert_allclose(rm.rotz(0.5), rm.exp_so3([0, 0, 0.5]), atol=1e-15)
    np.testing.assert_allclose(rm.zyx_angles(R), [az, ay, ax], atol=1e-14)


@pytest.mark.parametrize("ay", [np.pi / 2, -np.pi / 2, np.pi / 2 - 1e-12, np.pi / 2 - 1e-7, -np.pi / 2 + 1e-9])
def test_zyx_angles_near_gimbal_lock(ay):
    R = rm.rotzyx(0.7, ay, -0.4)
    angles = rm.zyx_angles(R)
    np.testing.assert_allclose(rm.rotzyx(*angles), R, atol=1e-12)
    if abs(abs(ay) - np.pi / 2) < 1e-10:
        assert angles[2] == 0.0


def test_zyx_angles_batch_and_range():
    angles = np.column_stack([RNG.uniform(-np.pi, np.pi, 20), RNG.uniform(-np.pi / 2, np.pi / 2, 20),
                              RNG.uniform(-np.pi, np.pi, 20)])
    R = rm.rotzyx(angles[:, 0], angles[:, 1], angles[:, 2])
    assert R.shape == (20, 3, 3)
    np.testing.assert_allclose(rm.zyx_angles(R), angles, atol=1e-12)


def test_inverse_and_transforms():
    H = random_pose()
    np.testing.assert_allclose(rm.inverse(H) @ H, np.eye(4), atol=1e-14)
    x_b = RNG.normal(size=3)
    x_a = rm.transform_point(H, x_b)
    np.testing.assert_allclose(np.append(x_a, 1), H @ np.append(x_b, 1), atol=1e-14)
    np.testing.assert_allclose(rm.transform_point(rm.inverse(H), x_a), x_b, atol=1e-14)
    np.testing.assert_allclose(rm.transform_vector(H, x_b), H[:3, :3] @ x_b, atol=1e-14)
    np.testing.assert_allclose(rm.translation([1, 0, 2 / 3])[:3, 3], [1, 0, 2 / 3])


def test_hat_vee():
    w, u = RNG.normal(size=3), RNG.normal(size=3)
    np.testing.assert_allclose(rm.so3_hat(w) @ u, np.cross(w, u), atol=1e-15)
    np.testing.assert_allclose(rm.so3_vee(rm.so3_hat(w)), w, atol=1e-15)
    T = RNG.normal(size=6)
    np.testing.assert_allclose(rm.se3_vee(rm.se3_hat(T)), T, atol=1e-15)
    T2 = RNG.normal(size=6)
    bracket = rm.se3_hat(T) @ rm.se3_hat(T2) - rm.se3_hat(T2) @ rm.se3_hat(T)
    np.testing.assert_allclose(rm.ad(T) @ T2, rm.se3_vee(bracket), atol=1e-14)


# --- adjoints, group laws ------------------------------------------------------------------------

def test_adjoint_group_laws():
    for _ in range(10):
        H1, H2 = random_pose(), random_pose()
        np.testing.assert_allclose(rm.Ad(H1 @ H2), rm.Ad(H1) @ rm.Ad(H2), atol=1e-13)
        np.testing.assert_allclose(rm.Ad(rm.inverse(H1)), np.linalg.inv(rm.Ad(H1)), atol=1e-12)
        np.testing.assert_allclose(rm.Ad_inv(H1), np.linalg.inv(rm.Ad(H1)), atol=1e-12)
        T = RNG.normal(size=6)
        np.testing.assert_allclose(rm.se3_hat(rm.Ad(H1) @ T), H1 @ rm.se3_hat(T) @ rm.inverse(H1), atol=1e-13)


def test_adjoint_batch_broadcasts():
    H = rm.exp_se3(RNG.normal(size=(4, 6)))
    T = RNG.normal(size=6)
    np.testing.assert_allclose(rm.transport_twist(H, T), np.einsum("nij,j->ni", rm.Ad(H), T), atol=1e-13)


def test_Ad_dot_against_finite_differences():
    xi1, xi2, H0 = RNG.normal(size=6), RNG.normal(size=6), random_pose()

    def H(t):
        return rm.exp_se3(t * xi1) @ H0 @ rm.exp_se3(np.sin(t) * xi2)

    h = 1e-5
    for t in (0.0, 0.4, 1.3):
        H_dot = (H(t + h) - H(t - h)) / (2 * h)
        T_b = rm.se3_vee(rm.inverse(H(t)) @ H_dot)
        Ad_dot_fd = (rm.Ad(H(t + h)) - rm.Ad(H(t - h))) / (2 * h)
        np.testing.assert_allclose(rm.Ad_dot(H(t), T_b), Ad_dot_fd, atol=1e-8)


def test_wrench_transport_and_power_invariance():
    for _ in range(5):
        H_ab = random_pose()
        W_a, T_b = RNG.normal(size=6), RNG.normal(size=6)
        T_a = rm.transport_twist(H_ab, T_b)
        W_b = rm.transport_wrench(H_ab, W_a)
        assert rm.power(W_b, T_b) == pytest.approx(rm.power(W_a, T_a), abs=1e-12)
    f, x_b = RNG.normal(size=3), RNG.normal(size=3)
    W_point = rm.transport_wrench(rm.translation(-x_b), np.concatenate([[0, 0, 0], f]))
    np.testing.assert_allclose(W_point, np.concatenate([np.cross(x_b, f), f]), atol=1e-14)


# --- exponential and logarithm --------------------------------------------------------------------

SINGULAR_ANGLES = [0.0, 1e-12, 1e-9, 1e-5, 1e-2 - 1e-12, 1e-2 + 1e-12, 0.3, np.pi / 2 - 1e-12,
                   np.pi / 2 + 1e-12, 2.0, np.pi - 1e-4, np.pi - 1e-9, np.pi - 1e-13, np.pi]


@pytest.mark.parametrize("theta", SINGULAR_ANGLES)
def test_exp_log_near_singular_angles(theta):
    for _ in range(4):
        axis = RNG.normal(size=3)
        axis /= np.linalg.norm(axis)
        T = np.concatenate([theta * axis, RNG.normal(size=3)])
        H = rm.exp_se3(T)
        T_back = rm.log_se3(H)
        np.testing.assert_allclose(rm.exp_se3(T_back), H, atol=2e-15 * 8)
        np.testing.assert_allclose(rm.exp_so3(rm.log_so3(H[:3, :3])), H[:3, :3], atol=1e-15 * 8)
        if theta < np.pi - 1e-6:
            np.testing.assert_allclose(T_back, T, atol=1e-12)
        else:
            assert np.linalg.norm(T_back[:3]) == pytest.approx(theta, abs=1e-12)


def test_exp_log_random_poses():
    H = np.array([random_pose() for _ in range(30)])
    np.testing.assert_allclose(rm.exp_se3(rm.log_se3(H)), H, atol=1e-13)


def test_exp_continuous_across_series_threshold():
    axis = np.array([0.6, -0.8, 0.0])
    t = 1e-2
    below, above = rm.exp_se3(np.r_[axis * t * (1 - 1e-13), 1, 2, 3]), rm.exp_se3(np.r_[axis * t * (1 + 1e-13), 1, 2, 3])
    np.testing.assert_allclose(below, above, atol=1e-14)


def test_exp_derivative_is_the_body_twist():
    """d/dt exp(t T) = exp(t T) T̂: T is the (constant) body twist of the motion."""
    T, t, h = RNG.normal(size=6), 0.7, 1e-6
    H_dot = (rm.exp_se3((t + h) * T) - rm.exp_se3((t - h) * T)) / (2 * h)
    np.testing.assert_allclose(H_dot, rm.exp_se3(t * T) @ rm.se3_hat(T), atol=1e-8)


# --- mass matrices -----------------------------------------------------------------------------

def test_mass_matrix_construction_and_parts():
    m, r = 2.5, RNG.normal(size=3)
    I_c = rm.box([0.2, 0.5, 0.3], m)[:3, :3]
    I_o = rm.inertia_about_point(m, r, I_c)
    M = rm.mass_matrix(m, r, I_o)
    m2, r2, I_c2 = rm.mass_matrix_parts(M)
    assert m2 == pytest.approx(m) and np.allclose(r2, r) and np.allclose(I_c2, I_c)
    # the same matrix, transported from the centre of mass to a frame at −r from it
    np.testing.assert_allclose(M, rm.transport_mass_matrix(rm.mass_matrix(m, [0, 0, 0], I_c),
                                                           rm.translation(-r)), atol=1e-13)


def test_kinetic_energy_of_point_cloud():
    """½ TᵀM T equals Σ ½ mᵢ |vᵢ|² for point masses, M assembled from the points."""
    pts, masses = RNG.normal(size=(7, 3)), RNG.uniform(0.1, 1, size=7)
    m = masses.sum()
    r = masses @ pts / m
    I_o = sum(mi * (x @ x * np.eye(3) - np.outer(x, x)) for mi, x in zip(masses, pts))
    M = rm.mass_matrix(m, r, I_o)
    T = RNG.normal(size=6)
    v = T[3:] + np.cross(T[:3], pts)
    assert 0.5 * T @ M @ T == pytest.approx(0.5 * np.sum(masses * np.sum(v ** 2, axis=1)), rel=1e-12)


def test_principal_frame():
    M_c = rm.box([0.3, 0.1, 0.7], 2.0)
    H_ab = random_pose()
    M_b = rm.transport_mass_matrix(M_c, H_ab)
    H_bp, M_p = rm.principal_frame(M_b)
    np.testing.assert_allclose(rm.transport_mass_matrix(M_b, H_bp), M_p, atol=1e-12)
    np.testing.assert_allclose(np.diag(M_p), np.sort(np.diag(M_c)[:3]).tolist() + [2.0] * 3, atol=1e-12)
    np.testing.assert_allclose(H_bp[:3, 3], rm.inverse(H_ab)[:3, 3], atol=1e-12)
    assert np.linalg.det(H_bp[:3, :3]) == pytest.approx(1.0)


# --- Newton–Euler -------------------------------------------------------------------------------

def classical_com_acceleration(m, I_c, omega, v, tau, f):
    """Euler's and Newton's equations at the centre of mass in body axes (written independently)."""
    omega_dot = np.linalg.solve(I_c, tau - np.cross(omega, I_c @ omega))
    v_dot = f / m - np.cross(omega, v)
    return np.concatenate([omega_dot, v_dot])


def test_newton_euler_against_classical_form_off_centre():
    for _ in range(5):
        M_c = rm.box(RNG.uniform(0.1, 1, 3), RNG.uniform(0.5, 3))
        H_cb = random_pose()                  # body frame b, seen from the centre-of-mass frame c
        M_b = rm.transport_mass_matrix(M_c, H_cb)
        T_b, W_b = RNG.normal(size=6), RNG.normal(size=6)
        dT_b = rm.newton_euler_acceleration(M_b, T_b, W_b)
        T_c = rm.transport_twist(H_cb, T_b)
        W_c = rm.transport_wrench(rm.inverse(H_cb), W_b)
        dT_c = classical_com_acceleration(M_c[3, 3], M_c[:3, :3], T_c[:3], T_c[3:], W_c[:3], W_c[3:])
        np.testing.assert_allclose(rm.transport_twist(H_cb, dT_b), dT_c, atol=1e-12)


def test_newton_euler_momentum_balance_by_finite_differences():
    """d/dt (Ad(H_gb)⁻ᵀ M_b T_b) = Ad(H_gb)⁻ᵀ W_b: the world momentum changes by the applied
    wrench.  The motion near t = 0 is H(t) ≈ H₀ exp(t T + t²/2 Ṫ), T(t) ≈ T + t Ṫ."""
    M_b, H0 = random_mass_matrix(), random_pose()
    T, W = RNG.normal(size=6), RNG.normal(size=6)
    dT = rm.newton_euler_acceleration(M_b, T, W)

    def momentum(t):
        return rm.Ad_inv(H0 @ rm.exp_se3(t * T + t ** 2 / 2 * dT)).T @ M_b @ (T + t * dT)

    h = 1e-5     # the difference's error ∝ h²: at most 1.5e-8 of the scale below over 300 random draws
    dh, expected = (momentum(h) - momentum(-h)) / (2 * h), rm.Ad_inv(H0).T @ W
    scale = np.max(np.abs(momentum(0.0))) + np.max(np.abs(expected))
    np.testing.assert_allclose(dh, expected, rtol=0, atol=1e-6 * scale)


def test_newton_euler_energy_balance():
    M_b, T, W = random_mass_matrix(), RNG.normal(size=6), RNG.normal(size=6)
    dT = rm.newton_euler_acceleration(M_b, T, W)
    assert T @ M_b @ dT == pytest.approx(rm.power(W, T), rel=1e-12)
    np.testing.assert_allclose(M_b @ dT + rm.newton_euler_bias(M_b, T), W, atol=1e-12)


# --- bad inputs --------------------------------------------------------------------------------

@pytest.mark.parametrize("call, error, words", [
    (lambda: rm.Ad(np.eye(3)), ShapeError, ["H_ab", "(..., 4, 4)", "(3, 3)"]),
    (lambda: rm.exp_se3([1, 2, 3]), ShapeError, ["T", "(..., 6)", "(3,)"]),
    (lambda: rm.log_so3(np.diag([1, 1, 2.0])), RotationError, ["R_ab", "rotation", "RᵀR"]),
    (lambda: rm.log_so3(np.diag([1, 1, -1.0])), RotationError, ["R_ab", "det"]),
    (lambda: rm.inverse(np.vstack([np.eye(4)[:3], [0, 0, 1, 1]])), RotationError, ["H_ab", "bottom row"]),
    (lambda: rm.Ad(np.diag([1.1, 1, 1, 1])), RotationError, ["H_ab[:3, :3]", "rotation"]),
    (lambda: rm.sphere(1.0, -5), InertiaError, ["m", "positive mass", "-5"]),
    (lambda: rm.box([1, 0, 2], 1.0), InertiaError, ["half_extents", "positive"]),
    (lambda: rm.cylinder(-1.0, 1.0, 1.0), InertiaError, ["length"]),
    (lambda: rm.mass_matrix(1.0, [0, 0, 0], np.diag([1, 1, 3.0])), InertiaError, ["I_o", "triangle"]),
    (lambda: rm.mass_matrix(1.0, [0, 0, 0], np.diag([1, -1, 1.0])), InertiaError, ["I_o", "positive definite"]),
    (lambda: rm.newton_euler_bias(np.eye(6) * -1, np.zeros(6)), InertiaError, ["M_b", "mass"]),
    (lambda: rm.transport_mass_matrix(np.diag([1, 1, 1, 1, 2, 1.0]), np.eye(4)), InertiaError, ["M_a", "m·1"]),
    (lambda: rm.exp_so3([np.nan, 0, 0]), ShapeError, ["omega", "finite"]),
    (lambda: rm.rotx("a"), ShapeError, ["angle", "numeric"]),
])
def test_bad_inputs_raise_clear_errors(call, error, words):
    with pytest.raises(error) as info:
        call()
    for w in words:
        assert w in str(info.value)


def test_small_rotation_error_is_accepted():
    R = rm.rotx(0.3) + 1e-12
    assert rm.log_so3(R) == pytest.approx([0.3, 0, 0], abs=1e-10)
