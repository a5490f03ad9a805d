"""The rotation formulas of the joint coordinates (SymPy source in ncgen.symbolic.rigid_motion,
CasADi by translation in ncgen.rigid_motion.casadi_forms) against scipy's independent
conversions: quaternions at random rotations and near 180° (every Shepperd branch), swings
and their small-angle series."""
import casadi as ca
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ncgen.rigid_motion import casadi_forms as rotation_forms


def canonical(quat):
    """scipy's [x, y, z, w] with w ≥ 0 (q and −q are the same rotation)."""
    quat = np.asarray(quat, float)
    return quat if quat[3] >= 0 else -quat


def rotations():
    rng = np.random.default_rng(7)
    out = list(Rotation.random(200, random_state=11))
    for axis in [*np.eye(3), *rng.standard_normal((20, 3))]:      # θ = π − ε about many axes
        axis = axis / np.linalg.norm(axis)
        for eps in (0.0, 1e-12, 1e-8, 1e-4, 0.1):
            out.append(Rotation.from_rotvec((np.pi - eps) * axis))
    out += [Rotation.identity(), Rotation.from_rotvec([1e-9, -2e-9, 0.5e-9])]
    return out


def test_quaternion_matches_scipy_everywhere():
    f = rotation_forms.function("quaternion")
    worst = 0.0
    for rot in rotations():
        q = np.array(f(rot.as_matrix())).reshape(-1)
        assert q[3] >= 0
        ref = canonical(rot.as_quat())
        if abs(ref[3]) < 1e-9:          # at 180° ±q both have qw = 0: compare the rotations
            err = min(np.abs(q - ref).max(), np.abs(q + ref).max())
        else:
            err = np.abs(q - ref).max()
        worst = max(worst, err)
    assert worst < 1e-13


def test_quaternion_derivative_matches_finite_differences():
    """Jacobian of the SX form (what the joint rates use) against central differences along a
    rotation's tangent, in each Shepperd branch."""
    qf = rotation_forms.function("quaternion")
    Rs, Ws = ca.SX.sym("R", 3, 3), ca.SX.sym("W", 3, 3)
    dq = ca.Function("dq", [Rs, Ws], [ca.jtimes(qf(Rs), Rs, Ws)])
    for rotvec in ([0.3, -0.2, 0.1], [2.9, 0.1, 0.2], [0.1, 3.0, -0.2], [0.2, -0.1, 3.05]):
        R0 = Rotation.from_rotvec(rotvec).as_matrix()
        W = R0 @ np.array([[0, -0.3, 0.2], [0.3, 0, -0.5], [-0.2, 0.5, 0]])   # R0 ω̂: tangent at R0
        h = 1e-6
        fd = (np.array(qf(R0 + h * W)) - np.array(qf(R0 - h * W))).reshape(-1) / (2 * h)
        np.testing.assert_allclose(np.array(dq(R0, W)).reshape(-1), fd, atol=1e-8)


@pytest.mark.parametrize("angle", [0.0, 1e-7, 5e-3, 0.011, 0.7, 2.0, 3.1])
def test_swing_is_the_rotation_vector_between_two_directions(angle):
    rng = np.random.default_rng(int(angle * 1e3) + 1)
    u0 = rng.standard_normal(3)
    u0 /= np.linalg.norm(u0)
    k = np.cross(u0, rng.standard_normal(3))
    k /= np.linalg.norm(k)
    u = Rotation.from_rotvec(angle * k).apply(u0)
    phi = np.array(rotation_forms.swing(u0, u)).reshape(-1)
    np.testing.assert_allclose(phi, angle * k, atol=2e-15 * max(1.0, 1 / max(np.sin(angle), 1e-3)))
    R = np.array(rotation_forms.exp_so3(phi))
    np.testing.assert_allclose(R @ u0, u, atol=1e-14)
    np.testing.assert_allclose(R, Rotation.from_rotvec(angle * k).as_matrix(), atol=1e-14)
