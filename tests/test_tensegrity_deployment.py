"""Deployment of a two-stage tensegrity tower by its cables' rest lengths (inputs of an
actuated ``tensegrity_system``): the compact and the deployed shapes (same struts) are both
prestressed equilibria of the one model; the energy balance of a deployment closes with the
work of the rest-length changes counted; the deployment posed as optimal control and
tracked in simulation."""
import numpy as np
import pytest

import ncgen as nc
from ncgen.analysis.tensegrity_model import rest_length_inputs
from ncgen.analysis.tensegrity_shapes import stacked_prisms, tower_of_radii

SUPPORTS = [0, 1, 2]
K = 2000.0


def tower(r1: float, r2: float):
    """The two-stage tower on a floor ring of 0.3 m, rings of radii ``r1``, ``r2`` (m), struts
    of the regular tower of radius 0.3 m and stage height 0.5 m."""
    nodes, struts, _ = stacked_prisms(3, stages=2, radius=0.3, height=0.5)
    return tower_of_radii([0.3, r1, r2], np.linalg.norm(nodes[struts[0][1]] - nodes[struts[0][0]]))


def test_least_prestress_of_the_compact_tower_is_the_qp_optimum():
    """The compact tower's least prestress (a QP on which ``qrqp`` stops short: a degenerate
    active set) satisfies its bounds and balance, and the QP's optimality conditions: the
    gradient ``H α + g`` of ``½ |t|²`` is ``−B_aᵀ μ`` on the active bounds with ``μ ≥ 0``."""
    from scipy.optimize import nnls

    from ncgen.analysis.inverse_statics import problem

    A, struts, cables = tower(0.35, 0.35)
    inv = nc.inverse_statics(A, struts, cables, supports=SUPPORTS, cable_min=10.0)
    assert inv.tensions.min() >= 10.0 - 1e-9 and inv.residual < 1e-9
    pr = problem(A, struts, cables, None, SUPPORTS, cable_min=10.0, who="test")
    alpha = np.linalg.lstsq(pr.T, inv.forces - pr.t_p, rcond=None)[0]
    np.testing.assert_allclose(pr.forces(alpha), inv.forces, atol=1e-9)
    active = np.flatnonzero(pr.B_alpha @ alpha - pr.b_alpha > -1e-7 * pr.scale)
    grad = pr.H @ alpha + pr.g
    mu, res = nnls(pr.B_alpha[active].T, -grad)
    assert active.size and res < 1e-8 * max(1.0, np.abs(grad).max())


CLUSTERS = [[9 + i, 12 + (i - 1) % 3] for i in range(3)]     # lower vertical i, then the upper one it meets


@pytest.fixture(scope="module", params=[None, CLUSTERS], ids=["independent", "clustered"])
def deployment(request):
    """The model (rest lengths as inputs, no damping), the compact (A) and deployed (B)
    designs: inputs and equilibria; with independent cables, or with each lower vertical
    cable running on over a middle-ring node into an upper one (``ClusteredCable``s over
    frictionless pulleys, as in benchmarks/tensegrity_clustered.py)."""
    clusters = request.param
    (A, struts, cables), B = tower(0.35, 0.35), tower(0.3, 0.3)[0]
    designs = [nc.inverse_statics(X, struts, cables, supports=SUPPORTS, cable_min=10.0, clusters=clusters)
               for X in (A, B)]
    model = nc.tensegrity_system(B, struts, cables, designs[1].rest_lengths(K)[:len(cables)], K,
                                 supports=SUPPORTS, clusters=clusters, actuated=True, node_mass=0.2).build()
    u = [rest_length_inputs(model, d.rest_lengths(K)[:len(cables)], clusters) for d in designs]
    eqs = [nc.equilibrium(model, u=ui) for ui in u]
    return model, (A, B), u, eqs


@pytest.mark.slow
def test_compact_and_deployed_shapes_are_equilibria_of_one_model(deployment):
    model, shapes, u, eqs = deployment
    np.testing.assert_allclose(shapes[1], stacked_prisms(3, stages=2, radius=0.3, height=0.5)[0], atol=1e-12)
    for X, eq in zip(shapes, eqs):
        top = [eq.coordinate(f"n{i}.r_i.z") for i in (6, 7, 8)]
        np.testing.assert_allclose(top, X[6:, 2], atol=1e-9)
        assert eq.stability == "stable" and not eq.slack
    assert shapes[0][6, 2] == pytest.approx(0.7964, abs=1e-4) and shapes[1][6, 2] == pytest.approx(1.0)


@pytest.mark.slow      # 35 s on a loaded 2-core machine; fast tier: the viewer's and the rigid bodies' tests
def test_energy_balance_of_a_deployment(deployment):
    """``l₀(t) = l₀A + (l₀B − l₀A) (1 − cos πt)/2`` over 1 s, no damping: the change of the
    kinetic and elastic energy ``½ vᵀ M v + Σ ½ k (l − l₀)²`` equals the work of the
    rest-length changes ``−Σ ∫ T l̇₀ dt`` (the input is interpolated linearly between the
    samples, so ``l̇₀`` is constant on each interval, and ``∫ T dt`` there is the trapezoid
    rule with its end correction ``h² (Ṫ₀ − Ṫ₁) / 12``, ``Ṫ = k (l̇ − l̇₀)``).  A clustered
    cable of two segments: its total length and rest length, stiffness ``K/2`` (in series)."""
    model, _, (uA, uB), (eqA, _) = deployment
    k = np.array([K / 2 if name.startswith("k") else K for name in model.springs.names])
    l0 = lambda t: uA + np.multiply.outer(0.5 * (1 - np.cos(np.pi * np.minimum(t, 1.0))), uB - uA)  # noqa: E731
    traj = nc.simulate(model, 1.2, 1e-3, u=lambda t: l0(t), q0=eqA.q, hold="linear", backend="vm", rtol=1e-10,
                       atol=1e-12)
    n, f = len(traj), model.springs.function.map(len(traj))

    def springs(q):
        return (np.asarray(x).reshape(len(uA), n).T for x in f(traj.t[None, :], q.T, traj.v.T, traj.u.T,
                                                                  np.zeros((0, n))))
    T, length, _ = springs(traj.q)
    eps = 1e-6
    rate = (list(springs(traj.q + eps * traj.v))[1] - list(springs(traj.q - eps * traj.v))[1]) / (2 * eps)
    stretch = length - traj.u
    assert stretch.min() > 0, "a cable went slack"
    kinetic = np.array([0.5 * v @ (model.M @ v) for v in traj.v])
    np.testing.assert_allclose(traj.energy - traj.energy[0], kinetic - kinetic[0], atol=1e-9)  # no other potential
    E = kinetic + 0.5 * np.sum(k * stretch**2, axis=1)
    h, du = np.diff(traj.t)[:, None], np.diff(traj.u, axis=0)
    Tdot = k * (rate[:, :] - np.vstack([du / h, du[-1:] / h[-1:]]))      # l̇₀ of the interval after each sample
    Tdot_end = k * (rate[1:] - du / h)                                     # and at each interval's end
    integral = 0.5 * h * (T[1:] + T[:-1]) + h**2 / 12 * (Tdot[:-1] - Tdot_end)
    work = np.concatenate([[0], np.cumsum(-np.sum(integral * du / h, axis=1))])
    np.testing.assert_allclose(E - E[0], work, atol=1e-6 * np.abs(work).max())
    assert np.abs(work).max() > 0.05
    top = traj.q[:, model.coordinate_names.index("n6.r_i.z")]
    assert top[-1] > 0.95, "the tower deployed"


@pytest.mark.slow      # one 1.2 s IDAS run of the tower (VM backend) per model
def test_viewer_shows_the_deploying_towers_tensions(deployment):
    """The viewer's scene and HTML page of a deployment: every drawn cable segment carries its
    cable's tension, equal to ``k (l − l₀(t))`` computed by NumPy from the nodes' positions and
    the input rest lengths (a clustered cable: its segments' summed length, ``K/2``, the same
    tension on both segments), and the tensions change along the deployment."""
    from ncgen.viz import html
    from ncgen.viz.scene import scene

    model, (_, B), (uA, uB), (eqA, _) = deployment
    traj = nc.simulate(model, 1.2, 0.02, u=lambda t: uA + 0.5 * (1 - np.cos(np.pi * min(t, 1.0))) * (uB - uA),
                       q0=eqA.q, hold="linear", backend="vm", rtol=1e-9, atol=1e-11)
    names = model.coordinate_names
    X = np.stack([np.broadcast_to(B[i], (len(traj), 3)) if i in SUPPORTS else
                  traj.q[:, [names.index(f"n{i}.r_i.{c}") for c in "xyz"]] for i in range(len(B))], axis=1)
    _, struts, cables = tower(0.3, 0.3)
    clusters = dict(enumerate(CLUSTERS)) if any(n.startswith("k") for n in model.springs.names) else {}
    expected = []
    for j, name in enumerate(model.springs.names):
        members = clusters[int(name[1:])] if name.startswith("k") else [int(name[1:])]
        length = sum(np.linalg.norm(X[:, cables[e][0]] - X[:, cables[e][1]], axis=1) for e in members)
        expected.append(K / len(members) * (length - traj.u[:, j]))
    expected = np.column_stack(expected)
    assert expected.min() > 0 and np.ptp(expected, axis=0).max() > 5.0, "taut cables whose tensions change"
    sc = scene(traj)
    assert sc.spring_names == list(model.springs.names) and sc.spring_cable.all()
    assert len(sc.spring_owner) == len(cables) - len(SUPPORTS)        # every realised segment drawn
    np.testing.assert_allclose(sc.spring_tension, expected[:, sc.spring_owner], rtol=1e-9, atol=1e-9)
    data = html.page_data(traj)
    panel = [p for p in data["plots"] if p["title"] == "spring and cable tensions"]
    assert panel and [s["label"] for s in panel[0]["series"]] == list(model.springs.names)
