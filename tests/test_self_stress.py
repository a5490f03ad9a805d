"""Self-stress and mechanisms (ncgen.analysis.self_stress) against closed forms: the regular
n-prism's equilibrium twist 90° − 180°/n and force densities 1 : 2 sin(π/n) : −2 sin(π/n)
(Tibert & Pellegrino 2003), the 3-prism's one state of self-stress and one infinitesimal
mechanism (Calladine 1978), prestress stiffening that mechanism in proportion, Snelson's X,
and the tangent stiffness against finite differences."""
import numpy as np
import pytest

import ncgen as nc

from ncgen.analysis.self_stress import framework, self_stress
from ncgen.analysis.tensegrity_shapes import prism, prism_twist, stacked_prisms
from ncgen.errors import NcgenError


@pytest.mark.parametrize("n", [4, 5, 6])
def test_form_found_n_prism_twists_to_the_closed_form(n):
    """The force density method from a wrong twist (and the closed-form densities) lands on
    the shape whose vertical cables turn by 90° − 180°/n about the axis, which has exactly
    one state of self-stress."""
    nodes, struts, cables = prism(n, twist=prism_twist(n) - np.radians(12))
    r = 2 * np.sin(np.pi / n)
    res = nc.form_find(nodes, struts, cables, force_densities=[1.0] * 2 * n + [r] * n + [-r] * n, stiffness=1e5)
    X = res.nodes - res.nodes.mean(axis=0)
    for a, b in cables[2 * n:]:
        turn = np.arctan2(X[b, 1], X[b, 0]) - np.arctan2(X[a, 1], X[a, 0])
        assert np.degrees(turn) % 360 == pytest.approx(90 - 180 / n, abs=1e-7)
    assert self_stress(res.nodes, struts, cables).n_self_stress == 1


@pytest.mark.parametrize("n", [3, 4, 5, 6, 8])
def test_n_prism_has_one_self_stress_only_at_its_twist(n):
    for off in (-3.0, 3.0):
        assert self_stress(*prism(n, twist=prism_twist(n) + np.radians(off))).n_self_stress == 0
    an = self_stress(*prism(n, radius=0.4, height=0.7))
    assert an.n_self_stress == 1 and an.n_rigid == 6
    assert an.n_mechanisms == 2 * n - 5                        # s − m = 4n − (6n − 6)
    q = an.self_stresses[:, 0] / an.framework.lengths()
    ratio = 2 * np.sin(np.pi / n)
    np.testing.assert_allclose(q[:2 * n] / q[0], 1.0, rtol=1e-10)               # both rings
    np.testing.assert_allclose(q[2 * n:3 * n] / q[0], ratio, rtol=1e-10)        # vertical cables
    np.testing.assert_allclose(q[3 * n:] / q[0], -ratio, rtol=1e-10)            # struts
    assert q[0] > 0


def test_three_prism_one_self_stress_one_mechanism_prestress_stable():
    an = self_stress(*prism(3))
    assert (an.n_self_stress, an.n_mechanisms, an.rank) == (1, 1, 11)
    assert an.maxwell() == "s - m = n_t - (n_free - k): 1 - 1 = 12 - (18 - 6)  [rank 11]"
    S = an.self_stresses[:, 0]
    np.testing.assert_allclose(an.A @ S, 0, atol=1e-13)
    np.testing.assert_allclose(an.mechanisms.T @ an.A, 0, atol=1e-13)        # no first-order elongation
    np.testing.assert_allclose(an.mechanisms.T @ an.rigid, 0, atol=1e-13)
    Q1 = an.prestress_stiffness(10 * S)
    np.testing.assert_allclose(an.prestress_stiffness(20 * S), 2 * Q1, rtol=1e-12)   # grows with prestress
    assert Q1[0, 0] > 0 and an.prestress_stability(10 * S)[0] == "stable"
    assert an.prestress_stability(-10 * S)[0] == "unstable"         # cables pushed, struts pulled
    assert "1 - 1 = 12" in an.table()


def test_mechanism_stiffness_is_the_energy_curvature_along_the_mechanism():
    """Nodes moved by ε along the mechanism with inextensible members fixed in force t:
    the work ½ εᵀ Q ε is the second-order change of Σ t_e l_e."""
    an = self_stress(*prism(3))
    fw, S = an.framework, an.self_stresses[:, 0]
    m = np.zeros(fw.nodes.size)
    m[fw.free] = an.mechanisms[:, 0]
    eps = 1e-4

    def work(e):
        x = fw.nodes + e * m.reshape(fw.nodes.shape)
        return S @ np.array([np.linalg.norm(x[j] - x[i]) for i, j in fw.members])
    curvature = (work(eps) - 2 * work(0) + work(-eps)) / eps**2
    assert curvature == pytest.approx(an.prestress_stiffness(S)[0, 0], rel=1e-5)


def test_tangent_stiffness_against_finite_differences():
    rng = np.random.default_rng(3)
    nodes, struts, cables = stacked_prisms(3, 2)
    nodes = nodes + 0.02 * rng.normal(size=nodes.shape)
    fw = framework(nodes, struts, cables, {0: "xyz", 1: "xyz", 2: "z"}, who="test")
    an = self_stress(fw, None, None)
    k = rng.uniform(100, 200, len(fw.members))
    l0 = fw.lengths() * rng.uniform(0.9, 1.1, len(fw.members))
    t = k * (fw.lengths() - l0)
    K = an.tangent_stiffness(t, k)
    h = 1e-6
    J = np.zeros_like(K)
    for c, i in enumerate(fw.free):
        for sgn in (1, -1):
            x = fw.nodes.copy().reshape(-1)
            x[i] += sgn * h
            moved = framework(x.reshape(nodes.shape), struts, cables, {0: "xyz", 1: "xyz", 2: "z"}, who="t")
            J[:, c] += sgn * moved.internal_forces(l0, k) / (2 * h)
    np.testing.assert_allclose(K, J, atol=1e-6 * np.abs(K).max())


def test_snelson_x_planar():
    """Two crossing struts in a square of cables: s = 1, m = 0, all |q| equal."""
    ang = np.radians([45, 135, 225, 315])
    nodes = np.column_stack([np.cos(ang), np.sin(ang)])
    an = self_stress(nodes, [(0, 2), (1, 3)], [(0, 1), (1, 2), (2, 3), (3, 0)])
    assert (an.n_self_stress, an.n_mechanisms, an.n_rigid) == (1, 0, 3)
    q = an.self_stresses[:, 0] / an.framework.lengths()
    np.testing.assert_allclose(q / q[0], [1, 1, 1, 1, -1, -1], rtol=1e-12)
    assert an.prestress_stability(an.self_stresses[:, 0])[0] == "stable"


def test_supports_remove_rigid_motions():
    nodes, struts, cables = prism(3)
    assert self_stress(nodes, struts, cables, supports=[0, 1, 2]).n_rigid == 0
    floor = self_stress(nodes, struts, cables, supports={0: "z", 1: "z", 2: "z"})
    assert floor.n_rigid == 3                    # slides and turns on the floor
    assert floor.n_mechanisms == 1 and floor.n_self_stress == 1


def test_clustered_cable_adds_mechanisms_and_keeps_maxwell():
    nodes, struts, cables = prism(3)
    an = self_stress(nodes, struts, cables, clusters=[[0, 1, 2]])     # one cable round the bottom
    assert an.n_tensions == 10 and an.n_self_stress == 1
    assert an.n_mechanisms == 3                   # 1 − 10 + 12: the cable can slide over two nodes
    S = an.self_stresses[:, 0]
    np.testing.assert_allclose(S[:3], S[0], rtol=1e-12)


@pytest.mark.parametrize("kwargs, match", [
    (dict(supports={0: "w"}), r"supports\[0\]: expected axes"),
    (dict(supports=[9]), "supports: expected node indices"),
    (dict(clusters=[[0, 4]]), r"clusters\[0\]: consecutive segments cables\[0\]"),
    (dict(clusters=[[0, 1], [1, 2]]), r"clusters\[1\]: cable\(s\) \[1\] are already"),
    (dict(clusters=[[0]]), r"clusters\[0\]: expected two or more"),
])
def test_bad_input_is_named(kwargs, match):
    with pytest.raises(NcgenError, match=match):
        self_stress(*prism(3), **kwargs)


def test_bad_members_and_forces_are_named():
    nodes, struts, cables = prism(3)
    with pytest.raises(NcgenError, match=r"struts\[1\]: expected two different node indices"):
        self_stress(nodes, [(0, 3), (1, 1)], cables)
    same = nodes.copy()
    same[3] = same[0]
    with pytest.raises(NcgenError, match=r"struts\[0\]: nodes 0 and 3 coincide"):
        self_stress(same, struts, cables)
    with pytest.raises(NcgenError, match="expected 12 finite member forces"):
        self_stress(nodes, struts, cables).prestress_stiffness(np.ones(3))
