"""A tumbling free body (ruvw, non-orthonormal basis, full inertia tensor, no gravity) against
an independent integration of Euler's equations: orientation, angular velocity, momenta."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

import ncgen as nc
from ncgen.runtime import simulate

MASS = 2.3
INERTIA = np.array([[0.30, 0.04, -0.02],
                    [0.04, 0.22, 0.05],
                    [-0.02, 0.05, 0.12]])      # about the centre of mass, body axes (kg m²)


def hat(w):
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


def euler_reference(R0, w_body0, t):
    """Ṙ = R ω̂,  I ω̇ = −ω × I ω  (body axes), by scipy's DOP853."""
    Iinv = np.linalg.inv(INERTIA)

    def rhs(_, y):
        R, w = y[:9].reshape(3, 3), y[9:]
        return np.concatenate([(R @ hat(w)).reshape(-1), Iinv @ (-np.cross(w, INERTIA @ w))])

    sol = solve_ivp(rhs, (t[0], t[-1]), np.concatenate([R0.reshape(-1), w_body0]), method="DOP853",
                    t_eval=t, rtol=1e-12, atol=1e-13)
    assert sol.success
    return sol.y[:9].T.reshape(-1, 3, 3), sol.y[9:].T


@pytest.fixture(scope="module")
def tumbling():
    rng = np.random.default_rng(7)
    R0 = Rotation.random(random_state=11).as_matrix()
    basis = [rng.normal(scale=0.1, size=3),                  # r̄_i, off the centre of mass
             *(np.eye(3) + rng.normal(scale=0.3, size=(3, 3)))]   # ū, v̄, w̄: not orthonormal
    s = nc.System("tumbler", gravity=(0, 0, 0))
    w0 = np.array([0.4, 3.0, -1.2])                           # world axes, rad/s
    v0 = np.array([0.3, -0.2, 0.1])
    s.add_body("top", "ruvw", mass=MASS, inertia=INERTIA, basis=basis, position=(0.1, 0.2, 0.3),
               rotation=R0, velocity=v0, angular_velocity=w0)
    model = s.build()
    traj = simulate(model, 5.0, 0.01, rtol=1e-10, atol=1e-12)
    return model, traj, R0, w0, v0


def test_orientation_and_angular_velocity_match_euler(tumbling):
    model, traj, R0, w0, _ = tumbling
    R_ref, w_body_ref = euler_reference(R0, R0.T @ w0, traj.t)
    R, _ = traj.poses()
    assert np.max(np.abs(R[:, 0] - R_ref)) < 1e-7
    top = model.member("top")
    w = np.array([top.rigid.twist(q, v)[0] for q, v in zip(traj.q, traj.v)])
    w_ref = np.einsum("nij,nj->ni", R_ref, w_body_ref)
    assert np.max(np.abs(w - w_ref)) < 1e-6
    assert np.ptp(w_ref, axis=0).max() > 1.0                 # it really tumbles


def test_momenta_conserved(tumbling):
    _, traj, _, _, v0 = tumbling
    R, p = traj.poses()
    np.testing.assert_allclose(p[:, 0], np.array([0.1, 0.2, 0.3]) + np.outer(traj.t, v0), atol=1e-9)
    top = traj.model.member("top")
    w = np.array([top.rigid.twist(q, v)[0] for q, v in zip(traj.q, traj.v)])
    L = np.einsum("nij,jk,nlk,nl->ni", R[:, 0], INERTIA, R[:, 0], w)    # R I Rᵀ ω
    assert np.max(np.abs(L - L[0])) < 1e-7 * np.linalg.norm(L[0])
    assert traj.energy_drift / traj.energy_scale < 1e-8
