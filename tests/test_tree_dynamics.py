"""Joint-space forward dynamics of trees (ncgen.assembly.tree_dynamics, ncgen.runtime.tree_kernel).

The recursive kernel (world-frame spatial recursion + composite inertias) and the projected
one (``M_j = Gᵀ M G`` by AD of the tree map) against the exact KKT solve in natural
coordinates (``from_joint_space`` → ``forward_dynamics`` → ``to_joint_space``: an independent
formulation, multipliers and all) on a tree with every 3D joint type, rotated bodies and a
bar, at random states with springs and dampers; a 2D pendulum against its closed form;
models that are not trees fall back; bad input and singular states raise.  The URDF robots
against Pinocchio's ABA are in test_urdf_pinocchio.py.
"""
from __future__ import annotations

import numpy as np
import pytest

import ncgen as nc
from ncgen.assembly.joint_tree import quaternion_matrix
from ncgen.assembly.tree_dynamics import recursive_dynamics_function, tree_dynamics_function

G = 9.81


@pytest.fixture(scope="module")
def tree():
    """Every 3D joint type with coordinates, a rotated body, a bar (a member with no
    inertia about its axis), an actuated hinge, a torsional spring and a damper."""
    s = nc.System("tree", gravity=(0, 0, -G))
    tau = s.add_input("tau")
    R = quaternion_matrix(np.array([0.2, -0.4, 0.3, 0.8]) / np.linalg.norm([0.2, -0.4, 0.3, 0.8]))
    b = [s.add_body(f"b{k}", mass=1.0 + 0.2 * k, inertia=np.diag([0.1, 0.2, 0.25]) * (1 + 0.1 * k),
                    position=(k + 0.5, 0.1 * k, 0), rotation=R if k == 2 else np.eye(3)) for k in range(7)]
    bar = s.add_bar("bar", mass=0.7, ends=[(7, 0.6, 0), (7, 1.6, 0)])
    s.add_joint(nc.Free(s.ground, b[0], at=(0.5, 0, 0), rotation=np.eye(3), name="root"))
    s.add_joint(nc.Revolute(b[0], b[1], at=(1, 0, 0), axis=(0, 0.6, 0.8), name="hinge", effort=tau))
    s.add_joint(nc.Prismatic(b[1], b[2], at=(2, 0.1, 0), axis=(1, 0, 0), name="slider"))
    s.add_joint(nc.Cylindrical(b[2], b[3], at=(3, 0.2, 0), axis=(1, 0, 0), name="cyl"))
    s.add_joint(nc.Universal(b[3], b[4], at=(4, 0.3, 0), axis_a=(0, 1, 0), axis_b=(0, 0, 1), name="hooke"))
    s.add_joint(nc.Spherical(b[4], b[5], at=(5, 0.4, 0), name="ball"))
    s.add_joint(nc.Planar(b[5], b[6], at=(6, 0.5, 0), normal=(0, 1, 0), name="plane"))
    s.add_joint(nc.Revolute(b[6], bar, at=(7, 0.6, 0), axis=(1, 0, 0), name="tip"))
    s.add_force(nc.Spring(b[1], (0.1, 0.2, 0.0), b[3], (0.0, -0.1, 0.2), k=30.0, rest_length=2.1, damping=2.0))
    return s.build()


def random_state(model, rng):
    js = model.joint_space
    qj = rng.uniform(-1, 1, js.nq)
    for name, sl in js.slices().items():
        if js.nq_joint[name] in (4, 7):
            qj[sl.stop - 4:sl.stop] /= np.linalg.norm(qj[sl.stop - 4:sl.stop])
    return qj, rng.normal(size=js.nv), rng.normal(size=model.nu)


def kkt_path(model, qj, vj, u):
    q, v = model.from_joint_space(qj, vj)
    a, _ = nc.forward_dynamics(model, q, v, u=u)
    return model.to_joint_space(q, v, a)[2]


def test_recursive_and_projected_forms_match_the_kkt_solve(tree):
    rec, proj = recursive_dynamics_function(tree), tree_dynamics_function(tree)
    rng = np.random.default_rng(4)
    for _ in range(6):
        qj, vj, u = random_state(tree, rng)
        ref = kkt_path(tree, qj, vj, u)
        scale = max(1.0, np.max(np.abs(ref)))
        for f in (rec, proj):
            aj, check = (np.array(x).reshape(-1) for x in f(tree.t0, qj, vj, u, tree.p0))
            assert np.max(np.abs(aj - ref)) <= 1e-9 * scale
            assert 0 < check[0] <= 1 and abs(check[1] - np.sum(aj)) < 1e-12 * scale


def test_planar_pendulum_compiled_closed_form():
    """θ̈ = (τ − m g (L/2) cos θ) / (m L²/3), uniform bar hinged at one end, 2D (projected form)."""
    L, mass = 1.2, 2.0
    s = nc.System("pendulum2d", gravity=(0, -G))
    tau = s.add_input("tau")
    bar = s.add_bar("bar", mass=mass, ends=[(0, 0), (L, 0)])
    s.add_joint(nc.Revolute(s.ground, bar, at=(0, 0), name="pivot", effort=tau))
    model = s.build()
    k = nc.joint_forward_dynamics_kernel(model)
    assert k.method == "projection"
    for th, om, t in [(0.4, 1.3, 3.0), (-2.0, 0.0, -1.0)]:
        expected = (t - mass * G * L / 2 * np.cos(th)) / (mass * L**2 / 3)
        assert abs(k([th], [om], [t])[0] - expected) < 1e-12 * max(1, abs(expected))
        assert abs(nc.joint_forward_dynamics(model, [th], [om], [t])[0] - expected) < 1e-12 * max(1, abs(expected))
    a = k([0.4], [1.3], [3.0])                  # the kernel's buffer: nc.joint_forward_dynamics has its own
    kept = a.copy()
    nc.joint_forward_dynamics(model, [-1.0], [0.0], [0.0])
    np.testing.assert_array_equal(a, kept)
    k2 = k.copy()
    k2([-1.0], [0.0], [0.0])
    np.testing.assert_array_equal(a, kept)
    with pytest.raises(nc.ModelError, match="expected qj of 1, vj of 1 and u of 1 values; got 2"):
        k([0.1, 0.2], [0.0], [0.0])
    with pytest.raises(nc.ModelError, match="accelerations are not finite"):
        k([0.3], [np.inf], [0.0])
    with pytest.raises(nc.ModelError, match="method: expected one of"):
        nc.joint_forward_dynamics_kernel(model, method="aba")


def test_models_that_are_not_trees_fall_back_to_the_kkt_solve_and_mimic_joints_get_the_kernel():
    s = nc.System("loop", gravity=(0, -G))
    crank = s.add_bar("crank", mass=1.0, ends=[(0, 0), (0, 1)])
    coupler = s.add_bar("coupler", mass=1.0, ends=[(0, 1), (2, 1)])
    rocker = s.add_bar("rocker", mass=1.0, ends=[(2, 0), (2, 1)])
    s.add_joint(nc.Revolute(s.ground, crank, at=(0, 0), name="j0"))
    s.add_joint(nc.Revolute(crank, coupler, at=(0, 1), name="j1"))
    s.add_joint(nc.Revolute(coupler, rocker, at=(2, 1), name="j2"))
    s.add_joint(nc.Revolute(s.ground, rocker, at=(2, 0), name="j3"))
    loop = s.build()
    with pytest.raises(nc.ModelError, match="not a tree"):
        nc.joint_forward_dynamics_kernel(loop)
    qj, vj = loop.to_joint_space(*loop.from_joint_space({"j0": -0.3}, {"j0": 1.5}))
    np.testing.assert_allclose(nc.joint_forward_dynamics(loop, qj, vj), kkt_path(loop, qj, vj, None), atol=1e-12)

    s = nc.System("gripper", gravity=(0, 0, -G))
    b1 = s.add_body("b1", mass=1.0, inertia=np.diag([0.1, 0.2, 0.25]), position=(0.5, 0, 0))
    b2 = s.add_body("b2", mass=1.0, inertia=np.diag([0.1, 0.2, 0.25]), position=(0.5, 1, 0))
    j1 = s.add_joint(nc.Prismatic(s.ground, b1, at=(0.5, 0, 0), axis=(0, 0, 1), name="f1"))
    j2 = s.add_joint(nc.Prismatic(s.ground, b2, at=(0.5, 1, 0), axis=(0, 0, 1), name="f2"))
    s.add_joint(nc.Mimic(j1, j2, multiplier=-2.0, name="link"))
    mimic = s.build()
    # a mimic joint is not a loop: the kernel takes it (the follower set from its leader);
    # f1 + f2 masses move together: z̈1 (m + 4m) = −m g + 2 m g
    k = nc.joint_forward_dynamics_kernel(mimic)
    np.testing.assert_allclose(k([0.1, -0.2], [0.0, 0.0]), [G / 5, -2 * G / 5], atol=1e-12)
    np.testing.assert_allclose(nc.joint_forward_dynamics(mimic, [0.1, -0.2], [0.0, 0.0]), [G / 5, -2 * G / 5],
                               atol=1e-12)
    np.testing.assert_allclose(nc.joint_forward_dynamics(mimic, [0.1, -0.2], [0.3, -0.6], backend="numpy"),
                               k([0.1, -0.2], [0.3, -0.6]), atol=1e-12)


def test_written_out_cholesky():
    import casadi as ca

    from ncgen.assembly.tree_dynamics import cholesky_solve

    K, b = ca.SX.sym("K", 3, 3), ca.SX.sym("b", 3)
    x, r = cholesky_solve(K, b)
    f = ca.Function("f", [K, b], [x, r])
    A = np.random.default_rng(0).normal(size=(3, 3))
    S = A @ A.T + 0.1 * np.eye(3)
    x_num, r_num = f(S, [1.0, -2.0, 0.5])
    np.testing.assert_allclose(np.array(x_num).reshape(-1), np.linalg.solve(S, [1.0, -2.0, 0.5]), rtol=1e-12)
    L = np.linalg.cholesky(S)
    assert abs(float(r_num) - min(L[k, k] ** 2 / S[k, k] for k in range(3))) < 1e-14
    assert float(f(np.ones((3, 3)), np.ones(3))[1]) <= 0.0          # singular: a zero pivot


def test_joint_motion_subspace_and_its_rate_against_finite_differences(tree):
    """Per joint of every type: the child's world twist is ``[ω_p; v_p] + S w`` and
    ``c = Ṡ w``, against central differences of the child's pose and of ``S w`` along a
    motion of the parent with twist ``[ω_p; v_p]`` at t = 0 and of the joint (``x + ẋ t``)."""
    import casadi as ca
    from scipy.spatial.transform import Rotation

    from ncgen.assembly.tree_dynamics import _edge_function

    js = tree.joint_space
    rng = np.random.default_rng(7)
    h = 1e-6
    for here, there, e, forward in js.spanning_tree():
        f = _edge_function(js, e, forward)
        nq, nv = js.nq_joint.get(e.name, 0), js.nv_joint.get(e.name, 0)
        Rp, pp = Rotation.random(random_state=rng).as_matrix(), rng.normal(size=3)
        wp, vp = rng.normal(size=3), rng.normal(size=3)
        x, w = rng.uniform(-1, 1, nq), rng.normal(size=nv)
        if nq in (4, 7):
            x[-4:] /= np.linalg.norm(x[-4:])
        xs = ca.SX.sym("x", nq)
        xdot = np.array(ca.Function("xd", [xs], [js.position_rates(e.name, xs, ca.DM(w))])(x)).reshape(-1) \
            if nq else np.zeros(0)

        def at(t):
            turn = Rotation.from_rotvec(wp * t).as_matrix()
            R, p = turn @ Rp, turn @ pp + vp * t          # ṗ = v_p + ω_p × p_p at t = 0
            out = f(R, p, wp, vp, x + xdot * t, w)
            return [np.array(o) for o in out]

        Rc, pc, S, c = at(0.0)
        (Rm, pm, Sm, _), (Rq, pq, Sq, _) = at(-h), at(h)
        W = (Rq - Rm) / (2 * h) @ Rc.T
        omega = 0.5 * np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]])
        twist = np.concatenate([omega, (pq - pm).reshape(-1) / (2 * h) - np.cross(omega, pc.reshape(-1))])
        np.testing.assert_allclose(twist, np.concatenate([wp, vp]) + (S @ w if nv else 0.0), atol=1e-7)
        if nv:
            np.testing.assert_allclose(c.reshape(-1), (Sq - Sm) @ w / (2 * h), atol=1e-6)


def test_uniform_gravity_is_recognised_only_when_it_is_all_the_passive_force(tree):
    """Gravity alone rides on the ground's acceleration; any other force (a spring, a
    constant point force) keeps the general wrench path — both checked against the KKT solve."""
    from ncgen.assembly.tree_dynamics import _owned, uniform_gravity

    assert uniform_gravity(tree, _owned(tree, tree.joint_space.spanning_tree())) is None   # the spring
    for extra in (False, True):
        s = nc.System("arm", gravity=(0.0, 1.0, -G))
        b0 = s.add_body("b0", mass=1.0, inertia=np.diag([0.1, 0.2, 0.25]), position=(0.5, 0, 0))
        b1 = s.add_body("b1", mass=2.0, inertia=np.diag([0.2, 0.1, 0.25]), position=(1.5, 0, 0))
        s.add_joint(nc.Revolute(s.ground, b0, at=(0, 0, 0), axis=(0, 1, 0), name="j0"))
        s.add_joint(nc.Revolute(b0, b1, at=(1, 0, 0), axis=(0, 0.6, 0.8), name="j1"))
        if extra:
            s.add_force(nc.PointForce(b1, (0.2, 0.1, 0.0), (0.0, 3.0, 1.0)))
        model = s.build()
        g = uniform_gravity(model, _owned(model, model.joint_space.spanning_tree()))
        assert g is None if extra else np.allclose(g, [0.0, 1.0, -G], atol=1e-12)
        f = recursive_dynamics_function(model)
        rng = np.random.default_rng(2)
        for _ in range(3):
            qj, vj = rng.uniform(-1, 1, 2), rng.normal(size=2)
            ref = kkt_path(model, qj, vj, None)
            np.testing.assert_allclose(np.array(f(0.0, qj, vj, [], [])[0]).reshape(-1), ref, atol=1e-10 * max(1, np.max(np.abs(ref))))


@pytest.mark.parametrize("share", [True, False])
def test_thin_disc_and_bar_swing_in_the_compiled_kernel(share):
    """A thin disc (singular M) on a ball joint and a 3D bar swinging on a body's ball joint
    (two swing angles, no spin): the compiled tree kernel against the KKT solve."""
    s = nc.System("disc_and_bar", gravity=(0, 0, -9.81))
    m, r = 1.0, 0.3
    disc = s.add_body("disc", mass=m, inertia=np.diag([m * r * r / 4, m * r * r / 4, m * r * r / 2]),
                      position=(0, 0, 0.5))
    s.add_joint(nc.Spherical(s.ground, disc, at=(0, 0, 0), name="ball"))
    arm = s.add_body("arm", mass=2.0, inertia=np.diag([0.1, 0.2, 0.15]), position=(1.0, 0, 0))
    s.add_joint(nc.Revolute(s.ground, arm, at=(0.5, 0, 0), axis=(0, 1, 0), name="hinge"))
    bar = s.add_bar("bar", mass=1.0, ends=[(1.5, 0, 0), (2.0, 0.3, -0.4)])
    s.add_joint(nc.Spherical(arm, bar, at=(1.5, 0, 0), name="swing"))
    model = s.build(share=share)
    js = model.joint_space
    assert js.nq == 7 and js.nv == 6               # quaternion, angle, two swing angles
    rng = np.random.default_rng(3)
    q0j = np.array(js.positions(model.q0)).reshape(-1)
    kernel = nc.joint_forward_dynamics_kernel(model)          # a tree: no fallback
    for _ in range(3):
        qj, vj = q0j + 0.3 * rng.standard_normal(js.nq), rng.standard_normal(js.nv)
        qj[:4] /= np.linalg.norm(qj[:4])
        a_c = kernel(qj, vj).copy()
        a_n = nc.joint_forward_dynamics(model, qj, vj, backend="numpy")
        np.testing.assert_allclose(a_c, a_n, rtol=0, atol=1e-9 * np.max(np.abs(a_n)))


def test_mimic_chains_resolve_to_their_leader_and_match_the_kkt_solve():
    """f3 mimics f2 (×3, +0.1), which mimics f1 (×−2): f3 = −6 f1 + 0.1.  The kernel sets the
    followers from the leader and agrees with the constrained (KKT) solve; the independent
    rate is f1's alone."""
    from ncgen.assembly.tree_dynamics import MimicMap

    s = nc.System("chain_of_mimics", gravity=(0, 0, -G))
    bodies = [s.add_body(f"b{k}", mass=1.0 + k, inertia=np.diag([0.1, 0.2, 0.25]), position=(0.5, k, 0))
              for k in range(3)]
    js = [s.add_joint(nc.Prismatic(s.ground, b, at=(0.5, k, 0), axis=(0, 0, 1), name=f"f{k + 1}"))
          for k, b in enumerate(bodies)]
    s.add_joint(nc.Mimic(js[0], js[1], multiplier=-2.0, name="m2"))
    s.add_joint(nc.Mimic(js[1], js[2], multiplier=3.0, offset=0.1, name="m3"))
    model = s.build(assemble=True)
    mimic = MimicMap(model)
    np.testing.assert_array_equal(mimic.G, [[1.0], [-2.0], [-6.0]])
    assert mimic.position[2] == (0, -6.0, 0.1)
    k = nc.joint_forward_dynamics_kernel(model)
    qj, vj = np.array([0.2, -0.4, -1.1]), np.array([0.5, -1.0, -3.0])
    # m1 z̈ + (−2) m2 (−2 z̈) + (−6) m3 (−6 z̈) = −g (m1 − 2 m2 − 6 m3)
    m = np.array([1.0, 2.0, 3.0])
    z = -G * (m[0] - 2 * m[1] - 6 * m[2]) / (m[0] + 4 * m[1] + 36 * m[2])
    np.testing.assert_allclose(k(qj, vj), [z, -2 * z, -6 * z], atol=1e-12)
    np.testing.assert_allclose(nc.joint_forward_dynamics(model, qj, vj, backend="numpy"), [z, -2 * z, -6 * z],
                               atol=1e-10)
