"""RigidMember: kinetic energy, mass matrix, pose/twist maps, generalised forces, bad input."""
import numpy as np
import pytest

from natural_helpers import (ALL_TYPES, IDS, YBAR, cross, random_basis, random_inertia, random_member,
                             random_rotation, random_state)
from ncgen.errors import BasisError, InertiaError, NcgenError, RotationError, ShapeError
from ncgen.symbolic.coordinates import coordinate_type
from ncgen.symbolic.member import RigidMember

BODIES = [t for t in ALL_TYPES if coordinate_type(t[1], t[0]).kind == "body"]
BODY_IDS = [f"{n}-{d}d" for d, n in BODIES]


def _reference_energy(member, inertia, R, omega, v):
    """½ m |v_G|² + ½ ωᵀ I_world ω from the rigid-body description alone."""
    ct, m = member.ctype, member.mass
    T = 0.5 * m * v @ v
    if ct.kind == "body" and ct.dim == 3:
        T += 0.5 * omega @ (R @ inertia @ R.T) @ omega
    elif ct.kind == "body":
        T += 0.5 * inertia * omega**2
    elif ct.kind == "bar":
        T += 0.5 * inertia * (omega @ omega if ct.dim == 3 else omega**2)
    return T


@pytest.mark.parametrize("dim,name", ALL_TYPES, ids=IDS)
def test_kinetic_energy_equals_the_rigid_body_energy(dim, name):
    rng = np.random.default_rng(10)
    for _ in range(4):
        member, inertia = random_member(rng, name, dim)
        R, p, omega, v = random_state(rng, member, omega_normal_to_axis=True)
        q = member.q_from_pose(R, p)
        qd = member.qd_from_twist(R, p, omega, v)
        T = 0.5 * qd @ member.M @ qd
        T_ref = _reference_energy(member, inertia, R, omega, v)
        assert abs(T - T_ref) <= 1e-12 * T_ref
        np.testing.assert_allclose(member.phi(q), 0, atol=1e-12)


@pytest.mark.parametrize("dim,name", ALL_TYPES, ids=IDS)
def test_mass_matrix_is_symmetric_positive_definite(dim, name):
    member, _ = random_member(np.random.default_rng(11), name, dim)
    M = member.M
    np.testing.assert_allclose(M, M.T, atol=1e-14)
    assert np.linalg.eigvalsh(M)[0] > 0


@pytest.mark.parametrize("dim", [3, 2])
def test_uniform_bar_mass_matrices(dim):
    I = np.eye(dim)
    m, L = 1.7, 0.9
    rr = RigidMember.bar("rr", m, L, dim=dim)
    np.testing.assert_allclose(rr.M, np.kron(m / 6 * np.array([[2, 1], [1, 2]]), I), rtol=1e-14)
    ru = RigidMember.bar("ru", m, L, dim=dim)   # r_i at the first end, u to the second
    np.testing.assert_allclose(ru.M, np.kron(np.array([[m, m / 2], [m / 2, m / 3]]), I), rtol=1e-14)


# ------------------------------------------------- independent check of M by quadrature
def _gauss_box(half, n=3):
    """Gauss–Legendre nodes and weights on the box [-h, h]^d (exact for degree <= 2n-1)."""
    x, w = np.polynomial.legendre.leggauss(n)
    grids = np.meshgrid(*[h * x for h in half], indexing="ij")
    weights = np.prod(np.meshgrid(*[h * w for h in half], indexing="ij"), axis=0)
    return np.stack([g.reshape(-1) for g in grids], axis=1), weights.reshape(-1)


def _seed_C(name, dim, c):
    return np.kron(np.r_[1.0, c][None, :], np.eye(dim)) @ np.kron(np.array(YBAR[(dim, name)], float), np.eye(dim))


def _quadrature_M(member, name, dim, points, weights, rho):
    """∫ρ CᵀC with the seed's C(c) and c = X̄⁺(r̄ − r̄_i) at each quadrature point."""
    M = np.zeros((member.ctype.nq,) * 2)
    Xp = np.linalg.pinv(member.Xbar)
    for r, w in zip(points, weights):
        C = _seed_C(name, dim, Xp @ (r - member.rbar_i))
        M += rho * w * C.T @ C
    return M


@pytest.mark.parametrize("name", ["ruvw", "rrvw", "rrrw", "rrrr"])
def test_body_mass_matrix_equals_quadrature_over_a_uniform_box(name):
    rng = np.random.default_rng(12)
    sides = np.array([0.4, 0.7, 1.1])
    mass = 2.3
    Q = random_rotation(rng)              # box axes in the member's local frame
    a, b, c = sides
    I_box = mass / 12 * np.diag([b**2 + c**2, a**2 + c**2, a**2 + b**2])
    member = RigidMember.body(name, mass, Q @ I_box @ Q.T, basis=random_basis(rng, name, 3))
    s, w = _gauss_box(sides / 2)
    M = _quadrature_M(member, name, 3, s @ Q.T, w, mass / np.prod(sides))
    np.testing.assert_allclose(member.M, M, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("name", ["ruv", "rrv", "rrr"])
def test_planar_mass_matrix_against_quadrature_over_a_plate(name):
    rng = np.random.default_rng(13)
    mass, Q = 1.4, random_rotation(rng, 2)
    for sides, exact in (([0.6, 0.6], True), ([0.5, 1.2], False)):
        sides = np.array(sides)
        member = RigidMember.body(name, mass, mass * (sides @ sides) / 12, basis=random_basis(rng, name, 2), dim=2)
        s, w = _gauss_box(sides / 2)
        M = _quadrature_M(member, name, 2, s @ Q.T, w, mass / np.prod(sides))
        if exact:   # square plate: J̄ = ∫ρ r̄ r̄ᵀ is isotropic, as ncgen takes it
            np.testing.assert_allclose(member.M, M, rtol=1e-12, atol=1e-12)
        # any plate: the same kinetic energy for every rigid motion
        for _ in range(3):
            R, p, omega, v = random_state(rng, member)
            qd = member.qd_from_twist(R, p, omega, v)
            assert qd @ member.M @ qd == pytest.approx(qd @ M @ qd, rel=1e-12)


@pytest.mark.parametrize("dim,name", [(3, "ru"), (3, "rr"), (2, "ru"), (2, "rr")])
def test_bar_mass_matrix_against_quadrature_of_a_tapered_bar(dim, name):
    # density rho(s) = 1 + 2 s/L along s in [0, L]: centre of mass and moment by quadrature
    L = 1.3
    x, w = np.polynomial.legendre.leggauss(4)
    s, w = L / 2 * (x + 1), L / 2 * w
    rho = 1 + 2 * s / L
    mass = rho @ w
    com = (rho * s) @ w / mass
    It = (rho * (s - com) ** 2) @ w
    member = RigidMember.bar(name, mass, L, inertia=It, com=com, dim=dim)
    points = np.zeros((s.size, dim))
    points[:, 0] = s - com                # local frame: origin at the centre of mass
    M = _quadrature_M(member, name, dim, points, w * rho, 1.0)
    np.testing.assert_allclose(member.M, M, rtol=1e-12, atol=1e-13)


# ---------------------------------------------------------------- pose and twist maps
@pytest.mark.parametrize("dim,name", ALL_TYPES, ids=IDS)
def test_pose_and_twist_round_trip(dim, name):
    rng = np.random.default_rng(14)
    member, _ = random_member(rng, name, dim)
    kind = member.ctype.kind
    for _ in range(3):
        R, p, omega, v = random_state(rng, member)
        q = member.q_from_pose(R, p)
        qd = member.qd_from_twist(R, p, omega, v)
        np.testing.assert_allclose(member.phi(q), 0, atol=1e-12)
        if member.ctype.n_phi:
            np.testing.assert_allclose(member.phi_q(q) @ qd, 0, atol=1e-12)
        R2, p2 = member.pose(q)
        w2, v2 = member.twist(q, qd)
        np.testing.assert_allclose(p2, p, atol=1e-12)
        np.testing.assert_allclose(v2, v, atol=1e-12)
        if kind == "point":
            assert R2 is None and w2 is None
        elif kind == "body":
            np.testing.assert_allclose(R2, R, atol=1e-12)
            np.testing.assert_allclose(w2, omega, atol=1e-12)
        else:   # a bar keeps its axis; its angular velocity is the part normal to the axis
            np.testing.assert_allclose(R2[:, 0], R[:, 0], atol=1e-12)
            np.testing.assert_allclose(R2.T @ R2, np.eye(dim), atol=1e-12)
            assert np.linalg.det(R2) == pytest.approx(1.0)
            w_normal = omega - (omega @ R[:, 0]) * R[:, 0] if dim == 3 else omega
            np.testing.assert_allclose(w2, w_normal, atol=1e-12)


@pytest.mark.parametrize("dim,name", BODIES, ids=BODY_IDS)
def test_body_fixed_points_move_rigidly(dim, name):
    rng = np.random.default_rng(15)
    member, _ = random_member(rng, name, dim)
    R, p, omega, v = random_state(rng, member)
    q, qd = member.q_from_pose(R, p), member.qd_from_twist(R, p, omega, v)
    for rbar in rng.normal(size=(3, dim)):
        np.testing.assert_allclose(member.position(q, rbar), p + R @ rbar, atol=1e-12)
        np.testing.assert_allclose(member.velocity(qd, rbar), v + cross(omega, R @ rbar), atol=1e-12)


# ------------------------------------------------------------- power of forces/torques
@pytest.mark.parametrize("dim,name", [t for t in ALL_TYPES if t[1] != "r"], ids=[i for t, i in zip(ALL_TYPES, IDS) if t[1] != "r"])
def test_power_of_torque_and_force(dim, name):
    rng = np.random.default_rng(16)
    member, _ = random_member(rng, name, dim)
    for _ in range(3):
        R, p, omega, v = random_state(rng, member, omega_normal_to_axis=True)
        q, qd = member.q_from_pose(R, p), member.qd_from_twist(R, p, omega, v)
        tau = rng.normal(size=3) if dim == 3 else float(rng.normal())
        # τ·ω = Qᵀ q̇
        assert member.torque(q, tau) @ qd == pytest.approx(np.dot(tau, omega), rel=1e-12, abs=1e-12)
        # f·v_point = Qᵀ q̇, with v_point = v + ω × R r̄ from rigid kinematics
        rbar = rng.normal(size=dim)
        if member.ctype.kind == "bar":
            rbar[1:] = 0
        f = rng.normal(size=dim)
        v_point = v + cross(omega, R @ rbar)
        assert member.force_at(rbar, f) @ qd == pytest.approx(f @ v_point, rel=1e-12, abs=1e-12)


def test_point_member_forces():
    m = RigidMember.point("r", 2.0)
    q, qd, f = np.array([1.0, 2, 3]), np.array([0.5, -1, 2]), np.array([3.0, 1, -1])
    assert m.force_at([0, 0, 0], f) @ qd == pytest.approx(f @ qd)
    np.testing.assert_allclose(m.M, 2.0 * np.eye(3))
    with pytest.raises(BasisError, match="cannot carry a torque"):
        m.torque(q, [0, 0, 1])


# --------------------------------------------------------------------------- bad input
def _raises(exc, *words):
    """pytest.raises for ``exc`` (an NcgenError, hence a ValueError) whose message has ``words``."""
    class _Check:
        def __enter__(self):
            self.ctx = pytest.raises(exc)
            self.info = self.ctx.__enter__()
            return self.info

        def __exit__(self, *a):
            out = self.ctx.__exit__(*a)
            assert isinstance(self.info.value, NcgenError) and isinstance(self.info.value, ValueError)
            for w in words:
                assert w in str(self.info.value), (w, str(self.info.value))
            return out
    return _Check()


@pytest.mark.parametrize("mass", [0.0, -1.0])
def test_non_positive_mass(mass):
    with _raises(InertiaError, "mass", "positive", str(mass)):
        RigidMember.body("ruvw", mass, np.eye(3))
    with _raises(InertiaError, "mass", "positive"):
        RigidMember.bar("rr", mass, 1.0)
    with _raises(InertiaError, "mass", "positive"):
        RigidMember.point("r", mass)


def test_bad_inertia_tensors():
    with _raises(InertiaError, "inertia", "symmetric"):
        RigidMember.body("ruvw", 1.0, [[1, 0.2, 0], [0, 1, 0], [0, 0, 1]])
    with _raises(InertiaError, "inertia", "positive principal moments"):
        RigidMember.body("ruvw", 1.0, np.diag([1.0, 1.0, -0.5]))
    with _raises(InertiaError, "triangle inequality", "I1 + I2 >= I3"):
        RigidMember.body("ruvw", 1.0, np.diag([1.0, 1.0, 3.0]))
    with _raises(ShapeError, "inertia", "(3, 3)"):
        RigidMember.body("ruvw", 1.0, np.eye(2))
    with _raises(InertiaError, "inertia", "moment about the centre of mass", "positive"):
        RigidMember.body("ruv", 1.0, -0.1, dim=2)
    with _raises(InertiaError, "transverse moment", "positive"):
        RigidMember.bar("rr", 1.0, 1.0, inertia=0.0)


def test_rotated_physical_inertia_is_accepted():
    I = random_inertia(np.random.default_rng(17))
    assert RigidMember.body("rrrr", 1.0, I).M.shape == (12, 12)


def test_degenerate_bases():
    with _raises(BasisError, "coplanar"):
        RigidMember.body("ruvw", 1.0, np.eye(3), basis=[[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    with _raises(BasisError, "coplanar"):   # four basic points on one plane
        RigidMember.body("rrrr", 1.0, np.eye(3), basis=[[0, 0, 1], [1, 0, 1], [0, 1, 1], [2, 3, 1]])
    with _raises(BasisError, "collinear"):
        RigidMember.body("rrr", 1.0, 0.1, basis=[[0, 0], [1, 1], [2, 2]], dim=2)
    with _raises(BasisError, "x̄_2", "zero"):
        RigidMember.body("rrvw", 1.0, np.eye(3), basis=[[0, 0, 0], [1, 0, 0], [0, 0, 0], [0, 0, 1]])
    with _raises(ShapeError, "basis", "expected 4 vectors", "r_i, r_j, v, w"):
        RigidMember.body("rrvw", 1.0, np.eye(3), basis=[[0, 0, 0], [1, 0, 0]])
    with _raises(ShapeError, "basis[2] (v)", "expected 3 numbers"):
        RigidMember.body("rrvw", 1.0, np.eye(3), basis=[[0, 0, 0], [1, 0, 0], [0, 1], [0, 0, 1]])
    with _raises(BasisError, "not a body type"):
        RigidMember.body("rr", 1.0, np.eye(3))
    with _raises(BasisError, "not a bar type"):
        RigidMember.bar("ruvw", 1.0, 1.0)
    with _raises(InertiaError, "bar length", "positive"):
        RigidMember.bar("rr", 1.0, 0.0)


def test_bar_basis_must_follow_its_axis():
    ct = coordinate_type("rr")
    J = np.diag([0.1, 0, 0])
    # regression: a base vector along -x̄ was accepted and q_from_pose then put the bar's
    # points on the wrong side of its centre of mass
    with _raises(BasisError, "+x̄"):
        RigidMember(ct, 1.0, [0.5, 0, 0], [[-1.0], [0], [0]], J)
    with _raises(BasisError, "+x̄"):
        RigidMember(ct, 1.0, [-0.5, 0, 0], [[1.0], [0.2], [0]], J)
    with _raises(BasisError, "r̄_i", "x̄ axis"):
        RigidMember(ct, 1.0, [-0.5, 0.1, 0], [[1.0], [0], [0]], J)
    bar = RigidMember.bar(ct, 1.0, 1.0)
    with _raises(BasisError, "off the bar's axis"):
        bar.affine([0.1, 0.2, 0])


def test_bad_rotations_and_shapes():
    m = RigidMember.body("ruvw", 1.0, np.eye(3))
    with _raises(RotationError, "orthonormal"):
        m.q_from_pose(np.diag([1.0, 1.0, 1.1]), [0, 0, 0])
    with _raises(RotationError, "reflection", "det"):
        m.q_from_pose(np.diag([1.0, 1.0, -1.0]), [0, 0, 0])
    with _raises(ShapeError, "rotation", "(3, 3)"):
        m.q_from_pose(np.eye(2), [0, 0, 0])
    with _raises(ShapeError, "position", "expected 3 numbers", "got 2"):
        m.q_from_pose(np.eye(3), [0, 0])
    with _raises(ShapeError, "q of a ruvw member", "expected 12 numbers", "got 6"):
        m.phi(np.zeros(6))
    with _raises(ShapeError, "angular_velocity"):
        m.qd_from_twist(np.eye(3), [0, 0, 0], [1, 0], [0, 0, 0])
    with _raises(ShapeError, "finite"):
        m.phi(np.full(12, np.nan))
    planar = RigidMember.body("ruv", 1.0, 0.2, dim=2)
    with _raises(ShapeError, "angular_velocity (a scalar in 2D)"):
        planar.qd_from_twist(0.3, [0, 0], [1, 2], [0, 0])


def test_point_twist_without_angular_velocity():
    # regression: qd_from_twist(omega=None) on a 3D point tried to read 0.0 as a 3-vector
    for dim in (3, 2):
        m = RigidMember.point("r", 1.0, dim=dim)
        v = np.arange(1.0, dim + 1)
        np.testing.assert_allclose(m.qd_from_twist(None, np.zeros(dim), None, v), v)


def test_off_centre_bar_needs_its_inertia():
    with pytest.raises(InertiaError, match="not the middle"):
        RigidMember.bar("rr", 1.0, 2.0, com=0.5)
    assert RigidMember.bar("rr", 1.0, 2.0, com=1.0).Jbar[0, 0] == pytest.approx(1.0 * 4 / 12)


def test_printed_rotation_is_projected_and_reported():
    """|RᵀR − 1| ~ 1e-6 (6 printed digits) is projected to the nearest rotation with a warning."""
    import warnings

    from ncgen.validation import RotationProjected, rotation

    c, s = np.cos(0.3), np.sin(0.3)
    R = np.round(np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]), 6)
    with pytest.warns(RotationProjected, match="projected to the nearest rotation"):
        P = rotation(R, 3, "rotation")
    np.testing.assert_allclose(P.T @ P, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(P, [[c, -s, 0], [s, c, 0], [0, 0, 1]], atol=1e-6)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rotation(np.eye(3), 3)                     # exact: no report
    with pytest.raises(RotationError, match="orthonormal"):
        rotation(np.diag([1.0, 1.0, 1.0001]), 3)
