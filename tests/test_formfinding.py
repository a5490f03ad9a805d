"""nc.form_find: the regular 3-strut prism (twist π/2 + π/n = 150°, force densities
1 : √3 : −√3) from rest lengths and from force densities; Snelson's X against a hand
derivation; slack cables; prestress stiffening the prism's mechanism."""
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError

SQ3 = np.sqrt(3.0)


def prism(alpha, r=0.3, h=0.5):
    """Nodes 0-2 bottom, 3-5 top turned by ``alpha``; struts i -> 3+i; cables: bottom ring,
    top ring, and bottom i -> top of strut i-1."""
    th = 2 * np.pi * np.arange(3) / 3
    nodes = np.vstack([np.column_stack([r * np.cos(th), r * np.sin(th), np.zeros(3)]),
                       np.column_stack([r * np.cos(th + alpha), r * np.sin(th + alpha), np.full(3, h)])])
    struts = [(i, 3 + i) for i in range(3)]
    cables = ([(i, (i + 1) % 3) for i in range(3)] + [(3 + i, 3 + (i + 1) % 3) for i in range(3)]
              + [(i, 3 + (i - 1) % 3) for i in range(3)])
    return nodes, struts, cables


def twists(X):
    """Angle (deg) from each bottom node to the top of its strut, about the prism's axis."""
    cb, ct = X[:3].mean(axis=0), X[3:].mean(axis=0)
    ang = [np.arctan2(*(X[3 + i] - ct)[1::-1]) - np.arctan2(*(X[i] - cb)[1::-1]) for i in range(3)]
    return np.degrees(np.mod(ang, 2 * np.pi))


def check_prism(res):
    np.testing.assert_allclose(twists(res.nodes), 90 + 180 / 3, atol=1e-7)
    rho = res.force_densities
    np.testing.assert_allclose(rho[:6], rho[0], rtol=1e-8)                    # top = bottom
    np.testing.assert_allclose(rho[6:9] / rho[0], SQ3, rtol=1e-8)            # verticals
    np.testing.assert_allclose(rho[9:] / rho[0], -SQ3, rtol=1e-8)            # struts
    assert res.stability == "stable" and res.slack == []
    assert res.equilibrium.force_residual < 1e-8


def test_prism_from_rest_lengths_twists_to_150_degrees():
    nodes, struts, cables = prism(np.radians(130))
    res = nc.form_find(nodes, struts, cables, rest_lengths=[0.45] * 9, stiffness=1000.0)
    check_prism(res)
    assert res.equilibrium.iterations > 0
    np.testing.assert_allclose(res.lengths(struts), np.linalg.norm(nodes[3] - nodes[0]), rtol=1e-10)


def test_prism_from_force_densities():
    nodes, struts, cables = prism(np.radians(120))
    res = nc.form_find(nodes, struts, cables, force_densities=[1.0] * 6 + [SQ3] * 3 + [-SQ3] * 3,
                       stiffness=1e4)
    check_prism(res)
    np.testing.assert_allclose(res.force_densities[0], 1.0, rtol=1e-8)


def test_prestress_stiffens_the_prism_mechanism():
    """The prism's infinitesimal mechanism is held by geometric stiffness alone: with
    nearly inextensible cables its ω² is proportional to the prestress."""
    nodes, struts, cables = prism(np.radians(120))
    w2 = []
    for scale in (1.0, 2.0):
        res = nc.form_find(nodes, struts, cables, stiffness=1e8,
                           force_densities=scale * np.array([1.0] * 6 + [SQ3] * 3 + [-SQ3] * 3))
        m = res.modes()
        assert m.kind[:6] == ["zero"] * 6                    # rigid motions of the free structure
        w2.append(m.omega2[6])
    np.testing.assert_allclose(w2[1] / w2[0], 2.0, rtol=1e-5)


def snelson_x(beta, L=1.0):
    """Two crossing struts of length L at angles beta and pi - beta, cables around."""
    ang = np.array([beta, np.pi - beta, np.pi + beta, 2 * np.pi - beta])
    nodes = 0.5 * L * np.column_stack([np.cos(ang), np.sin(ang)])
    return nodes, [(0, 2), (1, 3)], [(0, 1), (1, 2), (2, 3), (3, 0)]


def test_snelson_x_hand_derivation():
    """Equal cables, struts of length L: a square of side a = L/√2, cable tension
    T = k (a − l₀), strut force −√2 T, all force densities ±T/a."""
    L, k, l0 = 1.0, 100.0, 0.6
    res = nc.form_find(*snelson_x(np.radians(35), L), rest_lengths=[l0] * 4, stiffness=k)
    a = L / np.sqrt(2)
    T = k * (a - l0)
    np.testing.assert_allclose(res.lengths(res.cables), a, rtol=1e-9)
    np.testing.assert_allclose(res.tensions, T, rtol=1e-9)
    np.testing.assert_allclose(res.strut_forces, -np.sqrt(2) * T, rtol=1e-9)
    np.testing.assert_allclose(res.force_densities, [T / a] * 4 + [-T / a] * 2, rtol=1e-9)
    assert res.stability == "stable"


def test_slack_cables_reported():
    res = nc.form_find(*snelson_x(np.radians(45)), rest_lengths=[1.0] * 4, stiffness=100.0)
    assert res.slack == [0, 1, 2, 3]
    np.testing.assert_allclose(res.tensions, 0)
    assert res.stability == "neutral"          # no prestress: nothing holds the X
    assert "slack cables: c0, c1, c2, c3" in res.table()


def test_bad_force_densities():
    nodes, struts, cables = prism(np.radians(120))
    with pytest.raises(NcgenError, match="cables can only pull"):
        nc.form_find(nodes, struts, cables, force_densities=[-1.0] + [1.0] * 5 + [SQ3] * 3 + [-SQ3] * 3)
    with pytest.raises(NcgenError, match="nullity"):
        nc.form_find(nodes, struts, cables, force_densities=[1.0] * 6 + [1.0] * 3 + [-SQ3] * 3)
    with pytest.raises(NcgenError, match="exactly one"):
        nc.form_find(nodes, struts, cables)
    with pytest.raises(NcgenError, match=r"cables\[0\]"):
        nc.form_find(nodes, struts, [(0, 9)], rest_lengths=[1.0])
