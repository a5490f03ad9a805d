"""Rigid-body tensegrities (``bodies`` in ncgen.analysis.self_stress / inverse_statics /
tensegrity_system): a plate hung by three vertical cables against the tensions by statics
by hand (its weight split by the barycentric coordinates of its centre of mass), a prism
whose struts are rigid bodies against the bar prism (same cable forces, counts by
Calladine's rule, the same stiffness of its mechanism: the rotation's curvature term stands
for the struts' geometric stiffness), ncgen's own statics of the realised models, a
class-2 tower, bad input named."""
import numpy as np
import pytest

import ncgen as nc
from ncgen.analysis.tensegrity_shapes import prism

W = 10.0                                     # the plate's weight (N)


def hung_plate():
    """Plate nodes 0, 1, 2 (corners) and 3 (centre of mass, loaded), anchors 4, 5, 6 at z = 1."""
    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    com = np.array([0.2, 0.3, 0.0])
    nodes = np.vstack([corners, com, corners + [0, 0, 1]])
    loads = np.zeros((7, 3))
    loads[3, 2] = -W
    return nodes, [(0, 4), (1, 5), (2, 6)], loads, [4, 5, 6]


def test_plate_hung_by_three_cables_has_the_tensions_by_hand():
    nodes, cables, loads, anchors = hung_plate()
    # by hand: vertical forces balance W, moments about the x and y axes through the corner 0:
    # T1 * 1 = W * 0.2 (about y), T2 * 1 = W * 0.3 (about x), T0 = W - T1 - T2
    by_hand = [W * 0.5, W * 0.2, W * 0.3]
    inv = nc.inverse_statics(nodes, [], cables, loads, anchors, bodies=[[0, 1, 2, 3]])
    np.testing.assert_allclose(inv.tensions, by_hand, rtol=1e-12)
    assert inv.residual < 1e-12
    an = nc.self_stress(nodes, [], cables, anchors, bodies=[[0, 1, 2, 3]])
    assert (an.n_self_stress, an.n_mechanisms, an.n_free) == (0, 3, 6)      # sway x, y and yaw
    k = 1e4
    model = nc.tensegrity_system(nodes, [], cables, inv.rest_lengths(k), k, loads, anchors,
                                 bodies=[[0, 1, 2, 3]]).build()
    eq = nc.equilibrium(model)
    np.testing.assert_allclose([T for _, T, _, _ in eq.springs], by_hand, rtol=1e-9)
    np.testing.assert_allclose(eq.q, model.q0, atol=1e-10)
    assert eq.stability == "stable"          # the tensions stiffen the sway (T / l) and the yaw


def rigid_prism():
    """The 3-prism with each strut a rigid body of its two ends and a node off its axis."""
    nodes, struts, cables = prism(3, radius=0.3, height=0.5)
    extra = []
    for a, b in struts:
        mid = (nodes[a] + nodes[b]) / 2
        extra.append(mid + 0.05 * np.cross(nodes[b] - nodes[a], [0, 0, 1]) / np.linalg.norm(nodes[b] - nodes[a]))
    bodies = [[a, b, len(nodes) + e] for e, (a, b) in enumerate(struts)]
    return nodes, struts, cables, np.vstack([nodes, extra]), bodies


def test_rigid_body_prism_has_the_bar_prisms_forces_counts_and_stiffness():
    nodes, struts, cables, rnodes, bodies = rigid_prism()
    bar = nc.self_stress(nodes, struts, cables)
    rig = nc.self_stress(rnodes, [], cables, bodies=bodies)
    # a body of 6 coordinates replaces 2 nodes and a strut (5): one more mechanism each (its
    # spin about the strut's axis, which no cable loads)
    assert (rig.n_self_stress, rig.n_mechanisms, rig.n_rigid) == (1, bar.n_mechanisms + 3, 6)
    assert rig.n_self_stress - rig.n_mechanisms == rig.n_tensions - (rig.n_free - rig.n_rigid)
    q_bar = bar.self_stresses[:9, 0] / bar.framework.lengths()[:9]
    q_rig = rig.self_stresses[:, 0] / rig.framework.lengths()
    np.testing.assert_allclose(q_rig / q_rig[0], q_bar / q_bar[0], rtol=1e-10)
    inv_bar = nc.inverse_statics(nodes, struts, cables, cable_min=10.0)
    inv_rig = nc.inverse_statics(rnodes, [], cables, cable_min=10.0, bodies=bodies)
    np.testing.assert_allclose(inv_rig.forces, inv_bar.forces[:9], rtol=1e-10)
    # the bar prism's mechanism as a motion of the bodies: the same energy under the prestress
    t_bar, t_rig = inv_bar.forces, inv_rig.forces
    m = bar.mechanisms[:, 0]
    T = rig.framework.kinematic_map()
    ends = np.concatenate([np.arange(3 * i, 3 * i + 3) for i in range(len(nodes))])
    a = np.linalg.lstsq(T[ends] @ rig.mechanisms, m, rcond=None)[0]
    z = rig.mechanisms @ a
    np.testing.assert_allclose(T[ends] @ z, m, atol=1e-10)                    # it is a mechanism of both
    e_bar = m @ bar.geometric_stiffness(t_bar) @ m
    e_rig = z @ rig.geometric_stiffness(t_rig) @ z
    assert e_bar > 0 and e_rig == pytest.approx(e_bar, rel=1e-9)
    ev = np.sort(rig.prestress_stability(t_rig)[1])
    assert np.all(ev[:3] > -1e-9 * ev[-1]) and np.sum(ev > 1e-6 * ev[-1]) == bar.n_mechanisms


def test_geometric_stiffness_is_the_hessian_of_the_prestress_energy():
    """``K_G`` of the bodies against finite differences of ``Σ ½ q l²`` over their motions."""
    from scipy.spatial.transform import Rotation

    _, _, cables, rnodes, bodies = rigid_prism()
    rig = nc.self_stress(rnodes, [], cables, bodies=bodies)
    fw = rig.framework
    q = rig.self_stresses[:, 0] / fw.lengths()
    nz = rig.n_free

    def energy(z):
        x = rnodes.copy()
        for b, body in enumerate(bodies):
            c = rnodes[body].mean(axis=0)
            R = Rotation.from_rotvec(z[6 * b + 3:6 * b + 6]).as_matrix()
            x[body] = c + z[6 * b:6 * b + 3] + (rnodes[body] - c) @ R.T
        return 0.5 * sum(qe * np.sum((x[i] - x[j]) ** 2) for qe, (i, j) in zip(q, cables))

    h, H = 1e-4, np.zeros((nz, nz))
    for a in range(nz):
        for b in range(nz):
            ea, eb = np.eye(nz)[a] * h, np.eye(nz)[b] * h
            H[a, b] = (energy(ea + eb) - energy(ea - eb) - energy(eb - ea) + energy(-ea - eb)) / (4 * h * h)
    np.testing.assert_allclose(rig.geometric_stiffness(rig.self_stresses[:, 0]), H, atol=1e-6 * np.abs(H).max())


def test_two_bodies_held_by_cables_realised_and_in_equilibrium():
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parent.parent / "examples" / "tensegrity_bodies.py"
    spec = importlib.util.spec_from_file_location("tensegrity_bodies", path)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    nodes, cables, bodies = example.table()
    an = nc.self_stress(nodes, [], cables, bodies=bodies)
    inv = nc.inverse_statics(nodes, [], cables, cable_min=5.0, bodies=bodies)
    assert (an.n_self_stress, an.n_mechanisms) == (1, 3) and an.prestress_stability(inv.forces)[0] == "stable"
    # by hand: the upper body's vertical balance, the central cable against three outer ones
    np.testing.assert_allclose(inv.tensions, [15.0, 5.0, 5.0, 5.0], rtol=1e-12)
    k = 5e3
    model = nc.tensegrity_system(nodes, [], cables, inv.rest_lengths(k), k, bodies=bodies).build()
    eq = nc.equilibrium(model)
    np.testing.assert_allclose([T for _, T, _, _ in eq.springs], inv.tensions, rtol=1e-8)
    np.testing.assert_allclose(eq.q, model.q0, atol=1e-9)
    assert eq.stability == "neutral"          # free-floating: its rigid motions cost nothing


@pytest.mark.parametrize("bodies, match", [
    ([[0]], r"bodies\[0\]: expected two or more"),
    ([[0, 1], [1, 2]], r"bodies\[1\]: node 1 is already in bodies\[0\]"),
    ([[4, 0]], r"bodies\[0\]: node 4 is supported"),
    ([[0, 0, 1]], r"bodies\[0\]: expected two or more different"),
])
def test_bad_bodies_are_named(bodies, match):
    nodes, cables, _, anchors = hung_plate()
    with pytest.raises(nc.NcgenError, match=match):
        nc.self_stress(nodes, [], cables, anchors, bodies=bodies)


def test_member_inside_a_body_is_refused():
    nodes, cables, _, anchors = hung_plate()
    with pytest.raises(nc.NcgenError, match=r"struts\[0\]: nodes 0 and 1 are both in bodies\[0\]"):
        nc.self_stress(nodes, [(0, 1)], cables, anchors, bodies=[[0, 1, 2]])


def test_design_file_with_bodies(tmp_path, capsys):
    """``bodies`` in a design file (``ncgen tensegrity``): the two-body table's analysis."""
    from ncgen.cli import main

    a = 2 * np.pi * np.arange(3) / 3
    ring = [[float(0.3 * np.cos(x)), float(0.3 * np.sin(x))] for x in a]
    nodes = [[*p, 0.0] for p in ring] + [[0, 0, 0.6]] + [[*p, 0.8] for p in ring] + [[0, 0, 0.2]]
    path = tmp_path / "table.tensegrity.toml"
    path.write_text(f"nodes = {nodes}\nstruts = []\ncables = [[3, 7], [0, 4], [1, 5], [2, 6]]\n"
                    "bodies = [[0, 1, 2, 3], [4, 5, 6, 7]]\n\n[prestress]\ncable_min = 5.0\n")
    assert main(["tensegrity", str(path)]) == 0
    out = capsys.readouterr().out
    assert "2 rigid bodies" in out and "1 - 3 = 4 - (12 - 6)" in out and "prestress stability: stable" in out
    forces = [float(line.split()[3]) for line in out.splitlines() if line.startswith("cables[")]
    np.testing.assert_allclose(forces, [15, 5, 5, 5], rtol=1e-12)
