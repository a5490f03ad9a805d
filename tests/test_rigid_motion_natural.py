"""Natural coordinates ↔ rigid motion: pose/twist round trips, and the Newton–Euler
accelerations of a free body against the natural-coordinate dynamics (KKT system)."""
import numpy as np
import pytest

import ncgen.rigid_motion as rm
from ncgen.errors import BasisError, CoordinateTypeError
from ncgen.rigid_motion.natural import (member_mass_matrix, member_pose, member_state, member_twist,
                                       member_wrench_force)
from ncgen.symbolic.member import RigidMember

RNG = np.random.default_rng(31)
BODY_TYPES = ("ruvw", "rrvw", "rrrw", "rrrr")


def random_body(ctype, rng=RNG):
    """A body with a random non-diagonal inertia and a random non-orthonormal local basis."""
    I_c = rm.transport_mass_matrix(rm.box(rng.uniform(0.2, 1.0, 3), 1.0),
                                   rm.homogeneous(rm.exp_so3(rng.normal(size=3)), np.zeros(3)))[:3, :3]
    while True:
        r_i = rng.normal(scale=0.3, size=3)
        X = np.eye(3) + rng.normal(scale=0.35, size=(3, 3))
        if abs(np.linalg.det(X)) > 0.3:
            break
    slots = [r_i] + [r_i + X[:, s] if ch == "r" else X[:, s] for s, ch in enumerate(ctype[1:])]
    return RigidMember.body(ctype, rng.uniform(0.5, 3.0), I_c, basis=slots)


def kkt_acceleration(member, q, qd, Q):
    """q̈ from [[M, Aᵀ], [A, 0]] [q̈; λ] = [Q; γ], γ = −[q̇ᵀ H_k q̇]_k."""
    A = member.phi_q(q)
    n, k = A.shape[1], A.shape[0]
    K = np.block([[member.M, A.T], [A, np.zeros((k, k))]])
    return np.linalg.solve(K, np.concatenate([Q, member.gamma(qd)]))[:n]


def point_acceleration(H_gb, T_b, dT_b, x_b):
    """World acceleration of the body point x_b from the body twist and its derivative."""
    R = H_gb[:3, :3]
    w, v, dw, dv = T_b[:3], T_b[3:], dT_b[:3], dT_b[3:]
    return R @ (dv + np.cross(w, v) + np.cross(dw, x_b) + np.cross(w, np.cross(w, x_b)))


@pytest.mark.parametrize("ctype", BODY_TYPES)
def test_pose_twist_round_trip(ctype):
    body = random_body(ctype)
    for _ in range(3):
        H, T = rm.exp_se3(RNG.normal(size=6)), RNG.normal(size=6)
        q, qd = member_state(body, H, T)
        assert np.max(np.abs(body.phi(q))) < 1e-12
        assert np.max(np.abs(body.phi_q(q) @ qd)) < 1e-12
        np.testing.assert_allclose(member_pose(body, q), H, atol=1e-13)
        np.testing.assert_allclose(member_twist(body, q, qd), T, atol=1e-12)


@pytest.mark.parametrize("ctype", BODY_TYPES)
def test_kinetic_energy_and_power_agree(ctype):
    body = random_body(ctype)
    H, T, W = rm.exp_se3(RNG.normal(size=6)), RNG.normal(size=6), RNG.normal(size=6)
    q, qd = member_state(body, H, T)
    M_b = member_mass_matrix(body)
    assert 0.5 * qd @ body.M @ qd == pytest.approx(0.5 * T @ M_b @ T, rel=1e-12)
    assert member_wrench_force(body, q, W) @ qd == pytest.approx(rm.power(W, T), rel=1e-12)


@pytest.mark.parametrize("ctype", BODY_TYPES)
def test_newton_euler_agrees_with_natural_coordinate_dynamics(ctype):
    """Same random wrench (a couple and forces at the centre of mass and at a body point), same
    state: the accelerations of several body points agree to 1e-10."""
    for _ in range(3):
        body = random_body(ctype)
        H, T = rm.exp_se3(RNG.normal(size=6)), RNG.normal(size=6)
        W_com, f_b, x_f = RNG.normal(size=6), RNG.normal(size=3), RNG.normal(scale=0.5, size=3)
        q, qd = member_state(body, H, T)

        Q = member_wrench_force(body, q, W_com) + body.force_at(x_f, H[:3, :3] @ f_b)
        qdd = kkt_acceleration(body, q, qd, Q)

        W_b = W_com + rm.transport_wrench(rm.translation(-x_f), np.r_[0, 0, 0, f_b])
        dT_b = rm.newton_euler_acceleration(member_mass_matrix(body), T, W_b)

        for x_b in [np.zeros(3), x_f, *RNG.normal(size=(4, 3))]:
            natural = body.C(body.affine(x_b)) @ qdd
            np.testing.assert_allclose(natural, point_acceleration(H, T, dT_b, x_b), atol=1e-10)


def test_newton_euler_off_centre_frame_agrees_too():
    """The same body described at a frame away from its centre of mass (transported M)."""
    body = random_body("rrvw")
    H_gc, T_c = rm.exp_se3(RNG.normal(size=6)), RNG.normal(size=6)
    W_c = RNG.normal(size=6)
    q, qd = member_state(body, H_gc, T_c)
    qdd = kkt_acceleration(body, q, qd, member_wrench_force(body, q, W_c))

    H_cb = rm.exp_se3(RNG.normal(size=6))                    # frame b, seen from the COM frame c
    M_b = rm.transport_mass_matrix(member_mass_matrix(body), H_cb)
    T_b = rm.transport_twist(rm.inverse(H_cb), T_c)
    W_b = rm.transport_wrench(H_cb, W_c)
    dT_b = rm.newton_euler_acceleration(M_b, T_b, W_b)
    x_b = RNG.normal(size=3)
    x_c = rm.transform_point(H_cb, x_b)
    np.testing.assert_allclose(body.C(body.affine(x_c)) @ qdd,
                               point_acceleration(H_gc @ H_cb, T_b, dT_b, x_b), atol=1e-10)


@pytest.mark.parametrize("ctype", ["ru", "rr"])
def test_bar_round_trip_drops_spin_about_the_axis(ctype):
    bar = RigidMember.bar(ctype, 1.5, 0.8)
    H, T = rm.exp_se3(RNG.normal(size=6)), RNG.normal(size=6)
    q, qd = member_state(bar, H, T)
    np.testing.assert_allclose(member_pose(bar, q)[:3, 3], H[:3, 3], atol=1e-13)
    np.testing.assert_allclose(member_pose(bar, q)[:3, :3] @ [1, 0, 0], H[:3, :3] @ [1, 0, 0], atol=1e-13)
    T_back = member_twist(bar, q, qd)
    T_world, T_world_back = (rm.transport_twist(rm.homogeneous(R, np.zeros(3)), t)
                             for R, t in ((H[:3, :3], T), (member_pose(bar, q)[:3, :3], T_back)))
    axis = H[:3, :3] @ [1, 0, 0]
    omega_normal = T_world[:3] - axis * (axis @ T_world[:3])
    np.testing.assert_allclose(T_world_back[:3], omega_normal, atol=1e-12)
    np.testing.assert_allclose(T_world_back[3:], T_world[3:], atol=1e-12)


def test_point_member():
    point = RigidMember.point("r", 2.0)
    H, T = rm.translation([1, 2, 3]), np.r_[0, 0, 0, 4, 5, 6]
    q, qd = member_state(point, H, T)
    np.testing.assert_allclose(member_pose(point, q), H)
    np.testing.assert_allclose(member_twist(point, q, qd), T)
    np.testing.assert_allclose(member_wrench_force(point, q, np.r_[0, 0, 0, 1, 2, 3]), [1, 2, 3])
    with pytest.raises(BasisError):
        member_wrench_force(point, q, np.r_[1, 0, 0, 0, 0, 0])


def test_planar_member_refused():
    planar = RigidMember.body("ruv", 1.0, 0.1, dim=2)
    with pytest.raises(CoordinateTypeError, match="3D member"):
        member_pose(planar, np.zeros(6))
