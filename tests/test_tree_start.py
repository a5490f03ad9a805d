"""The tree library's start check (``templates/c/runtime/ncgen_tree_start.h``,
:class:`ncgen.runtime.tree_library.TreeStart`) against CasADi's (``JointSpace._holds``,
``JointSpace.state``) and against the tree map ``(q_j, v_j) -> (q, v)`` evaluated by CasADi
(``JointSpace.tree_function``, an independent route through the joints' relative poses):
the same verdict on starts on and off both constraint levels, on every joint kind of the
tables, the same joint state to 1e-12 (quaternions as CasADi's, not normalised), the distances
it reports equal to those of the tree map, its tolerances where they are, a floating-base robot's
run from a start it accepted against Pinocchio, and the trees it does not take named and left to
CasADi's check."""
from __future__ import annotations

import importlib.metadata as md
import re
import shutil

import numpy as np
import pytest

import ncgen as nc
import ncgen.assembly.joint_space as joint_space
import ncgen.model.buffered_call as buffered_call
import ncgen.runtime.run_start as run_start
from ncgen.assembly.joint_tree import quaternion_matrix
from ncgen.assembly.joint_space import TREE_Q_TOL, TREE_V_TOL, _tree_holding
from ncgen.codegen.compiler import CANDIDATES
from ncgen.codegen.tree_kernels import JOINT_KINDS
from ncgen.codegen.tree_start import start_tables
from ncgen.codegen.tree_tables import UnsupportedTree
from ncgen.runtime.tree_library import bound_tree, loaded_tree_start, tree_start

pytestmark = pytest.mark.skipif(not any(shutil.which(c) for c in CANDIDATES), reason="no C compiler for the tree library")


def kinds_tree() -> nc.Model:
    """Revolute joints about tilted axes, a prismatic and a fixed joint, a rotated body: every
    kind the start check takes."""
    s = nc.System("start_kinds", gravity=(0.0, 0.0, -9.81))
    R = quaternion_matrix(np.array([0.2, -0.4, 0.3, 0.8]) / np.linalg.norm([0.2, -0.4, 0.3, 0.8]))
    b = [s.add_body(f"b{k}", mass=1.0 + 0.1 * k, inertia=np.diag([0.02, 0.03, 0.04]), position=(0.4 * k + 0.2, 0.05 * k, 0),
                    rotation=R if k == 2 else np.eye(3)) for k in range(5)]
    s.add_joint(nc.Revolute(s.ground, b[0], at=(0, 0, 0), axis=(0, 0.6, 0.8), name="hinge"))
    s.add_joint(nc.Prismatic(b[0], b[1], at=(0.4, 0.05, 0), axis=(1, 0, 0), name="slider"))
    s.add_joint(nc.Fixed(b[1], b[2], at=(0.8, 0.1, 0), name="weld"))
    s.add_joint(nc.Revolute(b[2], b[3], at=(1.2, 0.15, 0), axis=(1, 0, 0), name="roll"))
    s.add_joint(nc.Revolute(b[3], b[4], at=(1.6, 0.2, 0), axis=(0, 1, 0), name="pitch"))
    return s.build()


def every_kind_tree() -> nc.Model:
    """Every joint kind of the tables: a free root, then revolute, cylindrical, universal,
    spherical, planar, prismatic and fixed joints, their axes tilted off the coordinate axes
    (the universal joint's two perpendicular), a rotated body."""
    s = nc.System("start_every_kind", gravity=(0.0, 0.0, -9.81))
    R = quaternion_matrix(np.array([0.2, -0.4, 0.3, 0.8]) / np.linalg.norm([0.2, -0.4, 0.3, 0.8]))
    b = [s.add_body(f"b{k}", mass=1.0 + 0.1 * k, inertia=np.diag([0.02, 0.03, 0.04]), position=(0.4 * k + 0.2, 0.05 * k, 0),
                    rotation=R if k == 3 else np.eye(3)) for k in range(8)]
    at = [(0.4 * k, 0.05 * k, 0.0) for k in range(8)]
    a, c = np.array([0.0, 0.6, 0.8]), np.array([1.0, 0.0, 0.0])
    s.add_joint(nc.Free(s.ground, b[0], at=at[0], rotation=R, name="root"))
    s.add_joint(nc.Revolute(b[0], b[1], at=at[1], axis=(0, 0.6, 0.8), name="hinge"))
    s.add_joint(nc.Cylindrical(b[1], b[2], at=at[2], axis=(0.48, 0.6, 0.64), name="cyl"))
    s.add_joint(nc.Universal(b[2], b[3], at=at[3], axis_a=a, axis_b=np.cross(a, c), name="hooke"))
    s.add_joint(nc.Spherical(b[3], b[4], at=at[4], name="ball"))
    s.add_joint(nc.Planar(b[4], b[5], at=at[5], normal=(0.36, 0.48, 0.8), name="plane"))
    s.add_joint(nc.Prismatic(b[5], b[6], at=at[6], axis=(1, 0, 0), name="slider"))
    s.add_joint(nc.Fixed(b[6], b[7], at=at[7], name="weld"))
    return s.build()


def robot(name: str, mimic: bool = False) -> nc.Model:
    """The robot of example-robot-data, as shipped with ``mimic`` (the Panda's second finger
    mimics its first), else without its ``<mimic>`` and ``<dynamics>`` tags (Solo12 and Talos on a
    free-flyer base)."""
    rel = {"panda": "panda_description/urdf/panda.urdf", "ur10": "ur_description/urdf/ur10_robot.urdf",
           "solo12": "solo_description/robots/solo12.urdf", "talos": "talos_data/robots/talos_reduced.urdf"}[name]
    try:
        path = next(f.locate() for f in md.files("example-robot-data") if str(f).endswith(rel))
    except (md.PackageNotFoundError, StopIteration, TypeError):
        pytest.skip("example-robot-data is not installed")
    text = open(path).read()
    if not mimic:
        text = re.sub(r"<dynamics[^>]*/>", "", re.sub(r"<mimic[^>]*/>", "", text))
    return nc.System.from_urdf(text, floating_base=name in ("solo12", "talos")).build()


def on_the_tree(model, rng):
    js = model.joint_space
    return model.from_joint_space(rng.uniform(-2.5, 2.5, js.nq), rng.uniform(-3, 3, js.nv))


def tree_map_distances(model, q, v, qj, vj):
    """``(max |q − q(q_j)|, max |v − v(q_j, v_j)|)`` by CasADi's tree map."""
    qt, vt = model.joint_space.tree_function(model.layout)(qj, vj)
    return np.abs(q - np.array(qt).ravel()).max(), np.abs(v - np.array(vt).ravel()).max()


def states(model, rng):
    """Starts on the tree and moved off either level, non-finite and huge entries, with whether
    each holds."""
    out = []
    for _ in range(4):
        q, v = on_the_tree(model, rng)
        out += [(q, v, True), (q + 1e-6 * rng.standard_normal(model.nq), v, False),
                (q, v + 1e-6 * rng.standard_normal(model.nq), False)]
        for bad in (np.nan, np.inf, 1e101):
            for which in ("q", "v"):
                x = (q if which == "q" else v).copy()
                x[rng.integers(model.nq)] = bad
                out.append((x, v, False) if which == "q" else (q, x, False))
    return out


def assert_equal_to_casadi(model, seed: int):
    js, ts = model.joint_space, tree_start(model)
    for q, v, holds in states(model, np.random.default_rng(seed)):
        check, qj, vj = ts(q, v)
        assert _tree_holding(check) == holds == js._holds(model, q, v, model.t0, model.p0)
        if holds:
            qr, vr = js.state(model, q, v)
            np.testing.assert_allclose(qj, np.ravel(qr), rtol=0, atol=1e-12)
            np.testing.assert_allclose(vj, np.ravel(vr), rtol=0, atol=1e-12)
            e_q, e_v = tree_map_distances(model, q, v, qj, vj)
            assert abs(check[0] - e_q) <= 1e-14 and abs(check[1] - e_v) <= 1e-13
            state = js._checked_state(model, q, v, model.t0, model.p0, ts)
            np.testing.assert_array_equal(state[0], qj)
        elif np.all(np.isfinite(q)) and np.all(np.isfinite(v)) and np.abs(q).max() < 1e3 and np.abs(v).max() < 1e3:
            e_q, e_v = tree_map_distances(model, q, v, qj, vj)     # off the tree: the distances are the tree map's
            assert check[0] == pytest.approx(e_q, rel=1e-9, abs=1e-14)
            assert check[1] == pytest.approx(e_v, rel=1e-9, abs=1e-13)


def test_the_start_check_equals_casadis_on_every_kind_it_takes():
    """Revolute (tilted axes), prismatic, fixed, a rotated body: verdicts, joint states (1e-12)
    and the distances to the tree (CasADi's tree map) as CasADi's."""
    model = kinds_tree()
    kinds = {int(k) for k in bound_tree(model).tables.arrays["kind"]}
    assert kinds == {0, 1, 2}                               # fixed, revolute, prismatic
    assert_equal_to_casadi(model, 59)


def test_the_start_check_equals_casadis_on_every_joint_kind():
    """Free, revolute, cylindrical, universal, spherical, planar, prismatic and fixed joints
    (tilted axes): verdicts, joint states (1e-12: the quaternions Shepperd's of CasADi's
    joint state) and the distances to the tree (CasADi's tree map) as CasADi's."""
    model = every_kind_tree()
    kinds = {int(k) for k in bound_tree(model).tables.arrays["kind"]}
    assert kinds == set(range(len(JOINT_KINDS)))
    assert_equal_to_casadi(model, 61)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["panda", "ur10", "solo12"])
def test_the_start_check_equals_casadis_on_robots(name):
    assert_equal_to_casadi(robot(name), 7)


@pytest.mark.slow
def test_a_tree_whose_coordinates_round_off_beyond_the_tolerance_keeps_casadis_check():
    """Talos (free flyer; members whose coordinates are points 0.13 mm apart): read off joint by
    joint, the round-off of its initial state takes more than START_ROUNDOFF_SHARE of the C
    check's tolerance, and starts made by ``from_joint_space`` (which CasADi's check accepts) lie
    beyond it: no TreeStart (named), and a joint run's start is CasADi's."""
    model = robot("talos")
    with pytest.raises(UnsupportedTree, match="initial state .* of its tolerance off the tree"):
        tree_start(model)
    nc.simulate(model, 1e-3, 1e-3, method="joint", kernels="tables")
    assert loaded_tree_start(model) is None
    q, v = on_the_tree(model, np.random.default_rng(2))
    assert model.joint_space._holds(model, q, v, model.t0, model.p0)


@pytest.mark.slow
def test_a_mimic_joint_is_checked_through_the_tables_mimic_map():
    """The Panda as shipped (its second finger mimics the first): starts on the tree with the
    fingers as the mimic map puts them are accepted as CasADi's check accepts them, with its
    joint state (1e-12); the same start with the second finger moved or moving alone by 1e-6
    (a rigid tree that breaks only the mimic relation, made on the Panda without its ``<mimic>``
    tag, whose coordinates are the same) is refused by both."""
    stock, free = robot("panda", mimic=True), robot("panda")
    a, js, ts = bound_tree(stock).tables.arrays, stock.joint_space, tree_start(stock)
    dep = np.flatnonzero(a["q_src"] >= 0)
    assert dep.size == 1 and stock.nq == free.nq
    rng = np.random.default_rng(11)
    for _ in range(3):
        qj, vj = rng.uniform(-2.5, 2.5, js.nq), rng.uniform(-3, 3, js.nv)
        qj[dep] = a["q_coef"][dep] * qj[a["q_src"][dep]] + a["q_off"][dep]
        vj = a["rate_coef"] * vj[a["rate_src"]]
        q, v = stock.from_joint_space(qj, vj)
        check, qc, vc = ts(q, v)
        assert _tree_holding(check) and js._holds(stock, q, v, stock.t0, stock.p0)
        qr, vr = js.state(stock, q, v)
        np.testing.assert_allclose(qc, np.ravel(qr), rtol=0, atol=1e-12)
        np.testing.assert_allclose(vc, np.ravel(vr), rtol=0, atol=1e-12)
        for moved_q in (True, False):
            qb, vb = qj.copy(), vj.copy()
            (qb if moved_q else vb)[dep] += 1e-6
            q2, v2 = free.from_joint_space(qb, vb)
            assert not _tree_holding(ts(q2, v2)[0])
            assert not js._holds(stock, q2, v2, stock.t0, stock.p0)


def _moved_to(model, ts, q, v, which: int, ratio: float):
    """``(q, v)`` moved along a fixed random direction of ``q`` (which 0) or ``v`` (1) so that
    the check's distance is ``ratio`` times its tolerance (the distance is linear in the move)."""
    d = np.random.default_rng(3).standard_normal(model.nq)
    tol = TREE_Q_TOL * max(1.0, np.abs(q).max()) if which == 0 else TREE_V_TOL * (1.0 + np.abs(v).max())
    h = 1e-8
    probe = ts(q + h * d, v) if which == 0 else ts(q, v + h * d)
    step = ratio * tol / probe[0][which] * h
    return (q + step * d, v) if which == 0 else (q, v + step * d)


@pytest.mark.parametrize("which", [0, 1])
@pytest.mark.parametrize("tree", [kinds_tree, every_kind_tree])
def test_a_start_just_beyond_the_tolerance_goes_to_casadis_check_and_one_within_is_accepted(tree, which, monkeypatch):
    """Moved to 0.5 of the tolerance: the C accepts (no CasADi call); to 2×: the C does not,
    CasADi's check decides (accepts: still within its own tolerance, the joint state its own);
    far beyond (1e4×): refused by both, and simulate projects it as it did before."""
    model = tree()
    ts = tree_start(model)
    q, v = on_the_tree(model, np.random.default_rng(1))
    js = model.joint_space
    within = _moved_to(model, ts, q, v, which, 0.5)
    beyond = _moved_to(model, ts, q, v, which, 2.0)
    far = _moved_to(model, ts, q, v, which, 1e4)
    assert _tree_holding(ts(*within)[0]) and not _tree_holding(ts(*beyond)[0])
    assert ts(*within)[0][which] == pytest.approx(0.5 * (TREE_Q_TOL if which == 0 else TREE_V_TOL * (1 + np.abs(v).max())),
                                                  rel=1e-3)
    calls = []
    real = type(js)._holds
    monkeypatch.setattr(type(js), "_holds", staticmethod(lambda *a: calls.append(1) or real(*a)))
    assert js._checked_state(model, *within, model.t0, model.p0, ts) is not None
    state = js._checked_state(model, *beyond, model.t0, model.p0, ts)
    assert state is not None and js._holds(model, *beyond, model.t0, model.p0)
    np.testing.assert_allclose(state[0], np.ravel(js.state(model, *beyond)[0]), atol=1e-12)
    assert js._checked_state(model, *far, model.t0, model.p0, ts) is None
    assert not js._holds(model, *far, model.t0, model.p0)


def test_simulate_takes_the_c_check_after_the_first_run_and_runs_as_from_casadis(monkeypatch):
    """The first joint run on the tables loads the forward unit; later new starts take the C
    check (counted) and give the trajectory of CasADi's check (joint states equal to round-off:
    the trajectories to 1e-12)."""
    model = kinds_tree()
    rng = np.random.default_rng(5)
    run = (lambda q, v: nc.simulate(model, 0.05, 0.01, q0=q, v0=v, method="joint", kernels="tables"))
    run(*on_the_tree(model, rng))
    assert loaded_tree_start(model) is not None
    q, v = on_the_tree(model, rng)
    calls = []
    real = loaded_tree_start
    monkeypatch.setattr(run_start, "loaded_tree_start", lambda m: calls.append(1) or real(m))
    fast = run(q, v)
    assert calls == [1]
    monkeypatch.setattr(run_start, "loaded_tree_start", lambda m: None)
    slow = run(q, v)
    for name in ("q", "v", "qj", "vj"):
        np.testing.assert_allclose(getattr(fast, name), getattr(slow, name), rtol=0, atol=1e-12)


def test_trees_the_check_does_not_take_are_named_and_keep_casadis_check():
    """A tree with parameters (the tables hold the model's numbers): refused by name; no
    TreeStart, and the start check is CasADi's."""
    s = nc.System("start_uncovered", gravity=(0.0, 0.0, -9.81))
    s.add_parameter("unused", 1.0)
    b = [s.add_body(f"b{k}", mass=1.0, inertia=np.diag([0.02, 0.03, 0.04]), position=(0.4 * k + 0.2, 0, 0))
         for k in range(3)]
    s.add_joint(nc.Free(s.ground, b[0], at=(0.2, 0, 0), rotation=np.eye(3), name="root"))
    s.add_joint(nc.Spherical(b[0], b[1], at=(0.4, 0, 0), name="ball"))
    s.add_joint(nc.Revolute(b[0], b[2], at=(0.6, 0, 0), axis=(0, 0, 1), name="f1"))
    model = s.build()
    with pytest.raises(UnsupportedTree, match="start check does not take it: parameters"):
        start_tables(model)
    nc.simulate(model, 0.01, 0.01, method="joint", kernels="tables")
    assert loaded_tree_start(model) is None


@pytest.mark.slow
def test_a_floating_base_robot_runs_from_a_start_the_c_check_took_as_pinocchio(monkeypatch):
    """Solo12 (example-robot-data, free-flyer base): a new start after the first run is taken
    by the C check (CasADi's start check not called) and the joint run from it (0.05 s, no
    input) ends where Pinocchio's ABA integrated by RK4 on its configuration space
    (``pinocchio.integrate``, 1e-4 s steps) ends, to 1e-8 (the base's quaternion up to its sign)."""
    pin = pytest.importorskip("pinocchio")
    from pinocchio_robots import JointMap, pinocchio_models, random_configuration
    from test_tree_algorithms_pinocchio import model_of

    model = model_of("solo12")
    pm = pinocchio_models("solo12")[1]
    jm, d, js = JointMap(model, pm), pm.createData(), model.joint_space
    rng = np.random.default_rng(4)
    run = (lambda q, v: nc.simulate(model, 0.05, 0.05, q0=q, v0=v, method="joint", kernels="tables", rtol=1e-12,
                                    atol=1e-12))
    qp = random_configuration(pm, rng, bound=0.8)
    run(*model.from_joint_space(jm.q_to_ncgen(qp), np.zeros(js.nv)))     # loads the forward unit
    qp, vp = random_configuration(pm, rng, bound=0.8), rng.normal(size=pm.nv)
    q, v = model.from_joint_space(jm.q_to_ncgen(qp), jm.P.T @ vp)
    assert _tree_holding(tree_start(model)(q, v)[0])
    casadi_checks = []
    real = buffered_call.buffered
    monkeypatch.setattr(joint_space, "buffered", lambda m, name, make: (casadi_checks.append(name), real(m, name, make))[1])
    tr = run(q, v)
    assert "start_check" not in casadi_checks and "state_check" not in casadi_checks
    js._checked_state(model, q + 0.0, v + 1.0, model.t0, model.p0)      # (without the C: CasADi's, counted)
    assert casadi_checks == ["start_check"]
    monkeypatch.undo()
    h, x, w = 1e-4, qp.copy(), vp.copy()
    accel = (lambda x_, w_: pin.aba(pm, d, x_, w_, np.zeros(pm.nv)))
    for _ in range(500):
        k1v, k1a = w, accel(x, w)
        k2v = w + 0.5 * h * k1a
        k2a = accel(pin.integrate(pm, x, 0.5 * h * k1v), k2v)
        k3v = w + 0.5 * h * k2a
        k3a = accel(pin.integrate(pm, x, 0.5 * h * k2v), k3v)
        k4v = w + h * k3a
        k4a = accel(pin.integrate(pm, x, h * k3v), k4v)
        x = pin.integrate(pm, x, h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v))
        w = w + h / 6 * (k1a + 2 * k2a + 2 * k3a + k4a)
    canonical = (lambda y: np.concatenate([y[:3], y[3:7] * (1.0 if y[6] >= 0 else -1.0), y[7:]]))   # qw ≥ 0
    assert pm.joints[1].shortname() == "JointModelFreeFlyer" and pm.joints[1].idx_q == 0
    np.testing.assert_allclose(canonical(jm.q_to_pin(tr.qj[-1], pm.nq)), canonical(x), rtol=0, atol=1e-8)
    np.testing.assert_allclose(jm.P @ tr.vj[-1], w, rtol=0, atol=1e-8)


def test_the_readings_of_the_c_header_are_the_kinds():
    """``READ`` (ncgen/codegen/tree_start.py) names the header's ``NCGEN_START_*`` codes, and the
    header's positions and rates per code are the joint kinds' (:data:`JOINT_KINDS`)."""
    from ncgen.codegen.render import shipped_templates_dir
    from ncgen.codegen.tree_kernels import LOCAL_MODES
    from ncgen.codegen.tree_start import READ

    text = (shipped_templates_dir() / "runtime" / "ncgen_tree_start.h").read_text()
    codes = {m.group(1).lower(): int(m.group(2)) for m in re.finditer(r"#define NCGEN_START_([A-Z]+) (\d+)", text)}
    assert codes == READ and set(READ) == {k.name for k in JOINT_KINDS}
    assert all(READ[k] == mode for k, mode in LOCAL_MODES.items())      # the tables' modes written out about z
    sizes = {w: [int(x) for x in re.search(rf"NCGEN_START_{w}\[9\] = \{{([^}}]*)\}}", text).group(1).split(",")]
             for w in ("NQ", "NV")}
    for k in JOINT_KINDS:
        assert (sizes["NQ"][READ[k.name]], sizes["NV"][READ[k.name]]) == (k.nq, k.nv), k.name
