"""nc.equilibrium and nc.modes against closed forms and independent minimal-coordinate
solutions: double pendulums (point masses; uniform bars), an N-bar chain, a chain of
torsional springs under a tip load, slack cables."""
import numpy as np
import pytest
import scipy.linalg

import ncgen as nc
from ncgen.errors import NcgenError

G = 9.81


def point_double_pendulum(m1, m2, l1, l2):
    s = nc.System("pp", gravity=(0.0, -G))
    r1 = l1 * np.array([np.sin(0.3), -np.cos(0.3)])            # off the equilibrium
    r2 = r1 + l2 * np.array([np.sin(-0.5), -np.cos(-0.5)])
    p1 = s.add_point("p1", mass=m1, position=r1)
    p2 = s.add_point("p2", mass=m2, position=r2)
    s.add_joint(nc.Distance(s.ground, p1, at=[(0, 0), r1]))
    s.add_joint(nc.Distance(p1, p2, at=[r1, r2]))
    return s.build()


def bar_chain(masses, lengths, angle=0.0):
    """Planar chain of uniform bars hanging from the origin, each turned by ``angle``."""
    s = nc.System("chain", gravity=(0.0, -G))
    top = np.zeros(2)
    prev = s.ground
    for i, (m, l) in enumerate(zip(masses, lengths)):
        end = top + l * np.array([np.sin(angle), -np.cos(angle)])
        b = s.add_bar(f"b{i}", mass=m, ends=[top, end])
        s.add_joint(nc.Revolute(prev, b, at=top))
        prev, top = b, end
    return s.build()


def pendulum_frequencies(M, K):
    """Frequencies (Hz) of M θ̈ + K θ = 0, ascending."""
    return np.sqrt(scipy.linalg.eigh(K, M, eigvals_only=True)) / (2 * np.pi)


def test_point_double_pendulum_closed_form():
    m1, m2, l1, l2 = 1.5, 0.7, 0.8, 0.5
    model = point_double_pendulum(m1, m2, l1, l2)
    modes = nc.modes(model)
    eq = modes.equilibrium
    assert eq.stability == "stable" and eq.iterations > 0
    np.testing.assert_allclose(eq.q, [0, -l1, 0, -l1 - l2], atol=1e-9)
    # reactions: the rods carry the weight below them
    np.testing.assert_allclose(np.abs(eq.reaction[[1, 3]]), [m1 * G, m2 * G], rtol=1e-10)
    reactions = {(j, m): (f, mo) for j, m, f, mo in eq.joint_reactions()}
    np.testing.assert_allclose(reactions["distance_0", "p1"][0], [0, (m1 + m2) * G], atol=1e-8)
    np.testing.assert_allclose(reactions["distance_1", "p1"][0], [0, -m2 * G], atol=1e-8)
    np.testing.assert_allclose(reactions["distance_1", "p2"][0], [0, m2 * G], atol=1e-8)
    # closed form: ω² roots of det(K − ω² M), M = [[(m1+m2) l1², m2 l1 l2], [m2 l1 l2, m2 l2²]],
    # K = diag((m1+m2) g l1, m2 g l2):  a ω⁴ − b ω² + c = 0
    a = m1 * m2 * l1**2 * l2**2
    b = (m1 + m2) * G * l1 * l2 * (l1 + l2) * m2
    c = (m1 + m2) * m2 * G**2 * l1 * l2
    w2 = (b + np.array([-1, 1]) * np.sqrt(b * b - 4 * a * c)) / (2 * a)
    np.testing.assert_allclose(modes.frequencies, np.sqrt(w2) / (2 * np.pi), rtol=1e-10)
    assert modes.kind == ["vibration", "vibration"]


def test_equal_point_double_pendulum_textbook():
    modes = nc.modes(point_double_pendulum(1.0, 1.0, 1.0, 1.0))
    np.testing.assert_allclose(modes.frequencies,
                               np.sqrt(G * np.array([2 - np.sqrt(2), 2 + np.sqrt(2)])) / (2 * np.pi), rtol=1e-10)


def chain_matrices(masses, lengths):
    """Minimal coordinates θ_i (absolute angles from the vertical), hanging equilibrium:
    M_ij = l_i l_j (m_j/2 + Σ_{k>j} m_k) for i < j, M_ii = l_i² (m_i/3 + Σ_{k>i} m_k),
    K_ii = g l_i (m_i/2 + Σ_{k>i} m_k)."""
    n = len(masses)
    below = [sum(masses[k] for k in range(i + 1, n)) for i in range(n)]
    M = np.zeros((n, n))
    for i in range(n):
        M[i, i] = lengths[i] ** 2 * (masses[i] / 3 + below[i])
        for j in range(i + 1, n):
            M[i, j] = M[j, i] = lengths[i] * lengths[j] * (masses[j] / 2 + below[j])
    K = np.diag([G * lengths[i] * (masses[i] / 2 + below[i]) for i in range(n)])
    return M, K


@pytest.mark.parametrize("masses,lengths", [([1.0, 0.6], [0.9, 0.4]),
                                            ([1.0, 0.8, 0.5, 0.7, 0.3], [0.5, 0.4, 0.6, 0.3, 0.35])])
def test_bar_chain_against_minimal_coordinates(masses, lengths):
    model = bar_chain(masses, lengths, angle=0.2)
    modes = nc.modes(model)
    assert modes.equilibrium.stability == "stable"
    np.testing.assert_allclose(modes.frequencies, pendulum_frequencies(*chain_matrices(masses, lengths)),
                               rtol=1e-9)
    # mode shapes: mass-normalised, on the tangent space
    M = np.asarray(model.M)
    np.testing.assert_allclose(modes.shapes.T @ M @ modes.shapes, np.eye(len(masses)), atol=1e-9)
    np.testing.assert_allclose(model.A(modes.equilibrium.q) @ modes.shapes, 0, atol=1e-10)


def test_upright_pendulum_is_unstable():
    model = bar_chain([1.0], [1.0], angle=np.pi - 0.05)
    eq = nc.equilibrium(model, method="newton")
    assert eq.stability == "unstable" and eq.n_negative == 1
    modes = nc.modes(model, eq)
    assert modes.kind == ["unstable"] and np.isnan(modes.frequencies[0])
    # growth rate √(−ω²) = √(3g/2l) for a uniform bar
    np.testing.assert_allclose(-modes.omega2[0], 1.5 * G, rtol=1e-10)
    # the default method descends to the stable, hanging equilibrium instead
    assert nc.equilibrium(model).stability == "stable"


def test_torsional_cantilever_tip_load_linear_closed_form():
    """n bars along x, hinged to each other and to the ground by torsional springs k; a
    small tip load P: rotations θ_i = P (L − x_i)/k, tip deflection P/k Σ (L − x_i)²."""
    n, length, k, P = 4, 0.25, 500.0, 1e-3
    s = nc.System("cantilever", gravity=(0.0, 0.0))
    prev, x = s.ground, 0.0
    for i in range(n):
        b = s.add_bar(f"b{i}", mass=0.1, ends=[(x, 0.0), (x + length, 0.0)])
        j = s.add_joint(nc.Revolute(prev, b, at=(x, 0.0)))
        s.add_force(nc.TorsionalSpring(j, k=k))
        prev, x = b, x + length
    s.add_force(nc.PointForce(prev, (length / 2, 0.0), force=(0.0, -P)))
    model = s.build(share=False)        # the root hinge's reaction needs its multipliers
    eq = nc.equilibrium(model)
    L = n * length
    xs = np.arange(n) * length
    tip = eq.q[model.coordinate_names.index(f"b{n - 1}.r_j.y")]
    expected = -P / k * np.sum((L - xs) ** 2)
    np.testing.assert_allclose(tip, expected, rtol=1e-6)
    assert eq.stability == "stable"
    # the root hinge holds the load: force P up at the hinge, i.e. moment −P l/2 about b0's centre
    (f, mo), = [(f, mo) for j, m, f, mo in eq.joint_reactions() if j == "revolute_0"]
    np.testing.assert_allclose(f, [0, P], atol=1e-9 * P)
    np.testing.assert_allclose(mo, -P * length / 2, rtol=1e-5)
    # the reduced stiffness of the unloaded chain is the torsional stiffness in joint angles
    lin = nc.linearize(model, eq)
    assert np.all(np.linalg.eigvals(lin.A).real < 1e-9)


def test_slack_cable_reported():
    s = nc.System("hang", gravity=(0.0, -G))
    p = s.add_point("p", mass=1.0, position=(0.0, -1.0))
    s.add_force(nc.Spring(s.ground, (0.0, 0.0), p, (0.0, 0.0), k=100.0, rest_length=0.9, cable=True, name="rope"))
    s.add_force(nc.Spring(s.ground, (0.0, -2.0), p, (0.0, 0.0), k=100.0, rest_length=1.5, cable=True,
                          name="floor_rope"))
    s.add_joint(nc.PointOnLine(s.ground, p, at=(0.0, -1.0), axis=(0.0, 1.0)))
    model = s.build()
    eq = nc.equilibrium(model)
    # only 'rope' carries the weight: stretch g/k below its rest length
    np.testing.assert_allclose(eq.q[1], -0.9 - G / 100.0, rtol=1e-10)
    assert eq.slack == ["floor_rope"]
    assert eq.springs[0][1] == pytest.approx(G)
    assert "SLACK" in eq.table()


def test_no_equilibrium_is_reported():
    s = nc.System("fall", gravity=(0.0, -G))
    s.add_point("p", mass=1.0, position=(0.0, 0.0))
    with pytest.raises(NcgenError, match="did not converge"):
        nc.equilibrium(s.build(), max_iter=20)


def test_bad_arguments_are_named():
    model = bar_chain([1.0], [1.0])
    with pytest.raises(NcgenError, match="method: expected 'descent' or 'newton'"):
        nc.equilibrium(model, method="bfgs")
    with pytest.raises(NcgenError, match="q_guess"):
        nc.equilibrium(model, q_guess=[0.0, 1.0, 2.0])
