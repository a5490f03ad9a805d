"""The joint-space step and MPC of tree robots (ncgen.control.joint_step, joint_mpc, box_qp).

* the step's Jacobians against central differences of the step itself, and the step and its
  Jacobians against MuJoCo's Euler step and ``mjd_transitionFD`` on the robot's MuJoCo twin;
* iLQR through the step against IPOPT on the same discrete problem written with RNEA;
* the box QP against CasADi's qpOASES (an independent active-set solver) and its KKT conditions;
* the MPC in closed loop against the joint-space simulator (``nc.simulate(method="joint")``,
  Dormand–Prince on ABA: another integrator than the controller's semi-implicit Euler), with
  torque bounds that bind; its inputs against the same MPC solving its QPs with qpOASES;
* slow: the 7-DOF Panda (example-robot-data, fingers locked) tracking a joint-space reach.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.control.box_qp import box_qp, kkt_error
from ncgen.control.stagewise_hessian import StagewiseHessian
from ncgen.control.joint_mpc import JointMPC
from ncgen.control.joint_step import JointStep
from ncgen.control.reference import solve_joint_discrete
from ncgen.errors import NcgenError

TWO_LINK = """<robot name="two_link">
  <link name="base"><inertial><mass value="1"/>
    <inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="upper"><inertial><origin xyz="0.25 0 0"/><mass value="1.5"/>
    <inertia ixx="0.01" iyy="0.03" izz="0.03" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="fore"><inertial><origin xyz="0.2 0 0.02"/><mass value="0.8"/>
    <inertia ixx="0.005" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="12" velocity="5"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/><origin xyz="0.5 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="4" velocity="5"/></joint>
</robot>"""


@pytest.fixture(scope="module")
def two_link():
    pytest.importorskip("yourdfpy")
    return nc.System.from_urdf(TWO_LINK).build()


def central_jacobians(f, x, u, eps=1e-6):
    A = np.column_stack([(f(x + eps * e, u) - f(x - eps * e, u)) / (2 * eps) for e in np.eye(len(x))])
    B = np.column_stack([(f(x, u + eps * e) - f(x, u - eps * e)) / (2 * eps) for e in np.eye(len(u))])
    return A, B


def test_joint_step_jacobians_match_central_differences(two_link):
    step = JointStep(two_link, 0.01)
    rng = np.random.default_rng(3)
    for _ in range(3):
        x, u = rng.normal(size=4), rng.normal(size=2) * 3
        x1, A, B = step.jacobians(x, u)
        assert np.allclose(x1, step(x, u), rtol=0, atol=1e-13)      # ABA's kernel, without derivatives
        An, Bn = central_jacobians(step, x, u)
        assert np.max(np.abs(A - An)) < 1e-7 * (1 + np.max(np.abs(A)))
        assert np.max(np.abs(B - Bn)) < 1e-7 * (1 + np.max(np.abs(B)))
        # semi-implicit Euler: q⁺ = q + h v⁺ exactly
        assert np.allclose(x1[:2], x[:2] + 0.01 * x1[2:], rtol=0, atol=1e-15)


@pytest.mark.parametrize("kernels", ["auto", "tables"])
def test_joint_step_results_are_its_own_and_equal_the_formula_of_aba_derivatives(two_link, kernels):
    """The step assembles x⁺, A, B from the kernel's output buffers without copying them first
    (issue 37's ≤ 0.5× ``mjd_transitionFD``; the flat kernel: one C call of the compiled formula,
    the tables': CasADi evaluates it): a later call must not change earlier results, ``out=`` is
    written in place with the same values, a bad ``out`` is named, and each result equals the
    module's formula written here in NumPy on ``nc.aba_derivatives`` (the flat kernel; Pinocchio's
    conventions, checked against Pinocchio in tests/test_tree_algorithms_pinocchio.py) and central
    differences of the step."""
    from ncgen.errors import ShapeError
    from ncgen.runtime.tree_algorithm_kernels import aba_derivatives
    step, h = JointStep(two_link, 0.01, kernels=kernels), 0.01
    assert (step._assemble is None) == (kernels == "tables")
    rng = np.random.default_rng(5)
    states = [(rng.normal(size=4), 3 * rng.normal(size=2)) for _ in range(3)]
    results = [step.jacobians(x, u) for x, u in states]
    out = (np.empty(4), np.empty((4, 4)), np.empty((4, 2)))
    for (x, u), (x1, A, B) in zip(states, results):
        a, da_dq, da_dv, Minv = aba_derivatives(two_link, x[:2], x[2:], u)
        v1 = x[2:] + h * a
        dv = h * np.hstack((da_dq, da_dv)) + np.hstack((np.zeros((2, 2)), np.eye(2)))
        close = dict(rtol=1e-12, atol=1e-12)        # the tables' and the flat kernel's round-off
        assert np.allclose(x1, np.concatenate([x[:2] + h * v1, v1]), **close)
        assert np.allclose(A, np.vstack((np.hstack((np.eye(2), np.zeros((2, 2)))) + h * dv, dv)), **close)
        assert np.allclose(B, np.vstack((h * h * Minv, h * Minv)), **close)
        An, Bn = central_jacobians(step, x, u)
        assert np.max(np.abs(A - An)) < 1e-7 * (1 + np.max(np.abs(A)))
        assert np.max(np.abs(B - Bn)) < 1e-7 * (1 + np.max(np.abs(B)))
        assert step.jacobians(x, u, out=out) is out
        for got, want in zip(out, (x1, A, B)):
            np.testing.assert_array_equal(got, want)
    with pytest.raises(ShapeError, match=r"JointStep.jacobians: out: expected a writable C-contiguous float64 "
                                         r"array of shape \(4, 2\), got float64 array of shape \(2, 4\)"):
        step.jacobians(*states[0], out=(np.empty(4), np.empty((4, 4)), np.empty((2, 4))))
    with pytest.raises(NcgenError, match="kernels: expected one of 'auto', 'tables', 'flat', got 'fast'"):
        JointStep(two_link, 0.01, kernels="fast")


def test_joint_step_is_mujocos_euler_step(two_link):
    """The same discrete map as MuJoCo's (semi-)implicit Euler on the same URDF: x⁺ to round-off,
    A and B to the accuracy of MuJoCo's centred differences."""
    pytest.importorskip("mujoco")
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from joint_step_jacobians import agreement, twin
    step = JointStep(two_link, 0.01)
    m = twin(TWO_LINK, two_link.joint_names, 0.01)
    rng = np.random.default_rng(4)
    for _ in range(3):
        dx, dA, dB = agreement(step, m, 0.5 * rng.normal(size=4), 3 * rng.normal(size=2), 1e-6)
        assert dx < 1e-13 and dA < 1e-7 and dB < 1e-7, (dx, dA, dB)


def test_joint_step_refuses_quaternions_and_bad_input(two_link):
    floating = nc.System.from_urdf(TWO_LINK, floating_base=True).build()
    with pytest.raises(NcgenError, match="quaternion"):
        JointStep(floating, 0.01)
    with pytest.raises(NcgenError, match="h"):
        JointStep(two_link, -0.01)
    with pytest.raises(NcgenError, match="tau"):
        JointStep(two_link, 0.01).jacobians(np.zeros(4), np.zeros(3))
    step = JointStep(two_link, 0.01)
    for bad in (np.array([0.0, np.nan, 0.0, 0.0]), np.array([0.0, 0.0, np.inf, 0.0])):
        with pytest.raises(NcgenError, match="finite"):
            step.jacobians(bad, np.zeros(2))
    x1, A, B = step.jacobians([0.1, 0.2, 0.0, 0.0], [1, 2])        # lists and integers are converted
    assert np.array_equal(x1, step.jacobians(np.array([0.1, 0.2, 0.0, 0.0]), np.array([1.0, 2.0]))[0])


def test_locked_urdf_fixes_the_named_joints_and_names_bad_ones():
    pytest.importorskip("yourdfpy")
    fingers = ["panda_finger_joint1", "panda_finger_joint2"]
    text = nc.robots.locked_urdf("panda", fingers)
    assert "<mimic" not in text and text.count('type="fixed"') > nc.robots.urdf_path("panda").read_text().count(
        'type="fixed"')
    with pytest.raises(nc.ModelError, match="no joint 'panda_finger'"):
        nc.robots.locked_urdf("panda", ["panda_finger"])
    with pytest.raises(nc.ModelError, match="'panda_finger_joint2' mimics the locked joint 'panda_finger_joint1'"):
        nc.robots.locked_urdf("panda", fingers[:1])


def test_box_qp_matches_qpoases_with_active_bounds():
    import casadi as ca

    rng = np.random.default_rng(7)
    for n in (5, 30):
        L = rng.normal(size=(n, n))
        H, g = L @ L.T + 0.1 * np.eye(n), rng.normal(size=n) * 10
        l, u = -np.abs(rng.normal(size=n)), np.abs(rng.normal(size=n))
        x, converged, iterations = box_qp(H, g, l, u)
        assert converged and kkt_error(H, g, l, u, x) < 1e-9
        solver = ca.conic("q", "qpoases", {"h": ca.Sparsity.dense(n, n), "a": ca.Sparsity.dense(0, n)},
                          {"printLevel": "none"})
        ref = np.asarray(solver(h=H, g=g, lbx=l, ubx=u)["x"]).ravel()
        active = np.sum((ref <= l + 1e-9) | (ref >= u - 1e-9))
        assert active >= 2, "the test wants bounds that bind"
        assert np.max(np.abs(x - ref)) < 1e-7


def test_box_qp_reports_a_hessian_that_is_not_positive_definite():
    x, converged, _ = box_qp(-np.eye(3), np.ones(3), -np.ones(3), 2 * np.ones(3), x0=np.zeros(3))
    assert not converged


def condensed_hessian(A, B, w, r):
    """``Sᵀ diag(w) S + diag(r)`` with ``S``'s blocks ``A_j ⋯ A_{k+1} B_k`` multiplied out one
    by one (the textbook condensing, independent of StagewiseHessian's recursions)."""
    N, nx, nu = B.shape
    S = np.zeros((N * nx, N * nu))
    for j in range(N):
        for k in range(j + 1):
            block = B[k]
            for i in range(k + 1, j + 1):
                block = A[i] @ block
            S[j * nx:(j + 1) * nx, k * nu:(k + 1) * nu] = block
    return S.T @ (w.reshape(-1)[:, None] * S) + np.diag(np.tile(r, N)), S


def test_stagewise_hessian_equals_the_condensed_matrix(two_link):
    """Products, gradients, Riccati Newton steps on subsets of the inputs (a stage all free,
    partly held, all held) and the box QP's answer equal those of the dense condensed matrix,
    on the two-link arm's linearisation along a rollout."""
    step = nc.JointStep(two_link, 0.02)
    rng = np.random.default_rng(3)
    N, nx, nu = 12, step.nx, step.nu
    A, B = np.empty((N, nx, nx)), np.empty((N, nx, nu))
    x = np.array([1.3, 0.2, 0.5, -0.4])
    for k in range(N):
        x, A[k], B[k] = step.jacobians(x, rng.normal(size=nu))
    w, r = rng.uniform(0.5, 1e3, size=(N, nx)), np.array([1e-3, 2e-3])
    H = StagewiseHessian(A, B, w, r)
    D, S = condensed_hessian(A, B, w, r)
    assert np.allclose(H.dense(), D, rtol=1e-12, atol=1e-12 * np.abs(D).max())
    dU, Y = rng.normal(size=N * nu), rng.normal(size=(N, nx))
    assert np.allclose(H @ dU, D @ dU, rtol=1e-10, atol=1e-10 * np.abs(D @ dU).max())
    assert np.allclose(H.rollout(dU).reshape(-1), S @ dU, rtol=1e-10, atol=1e-12)
    assert np.allclose(H.adjoint(Y), S.T @ (w * Y).reshape(-1), rtol=1e-10, atol=1e-10)
    g = rng.normal(size=N * nu)
    for free in (np.ones(N * nu, bool), rng.uniform(size=N * nu) < 0.6, np.zeros(N * nu, bool)):
        free[2 * nu:3 * nu] = False                  # one stage with every input held
        d = H.newton(free, g)
        ref = np.zeros(N * nu)
        if free.any():
            ref[free] = -np.linalg.solve(D[np.ix_(free, free)], g[free])
        assert np.allclose(d, ref, rtol=1e-9, atol=1e-9 * max(np.abs(ref).max(), 1.0))
        assert np.all(d[~free] == 0.0)
    l, u = -np.full(N * nu, 0.05), np.full(N * nu, 0.05)
    (a, ok_a, _), (b, ok_b, _) = box_qp(H, g, l, u), box_qp(D, g, l, u)
    assert ok_a and ok_b and np.sum((a <= l) | (a >= u)) >= 2, "bounds that bind"
    assert np.max(np.abs(a - b)) < 1e-9 * np.abs(b).max()
    # H = −diag(r) (no state weight): not positive definite, refused
    assert StagewiseHessian(A, B, np.zeros_like(w), -r).newton(np.ones(N * nu, bool), g) is None


def reach(q0, q1, T):
    """Minimum-jerk joint-space reach from q0 to q1 in T seconds: ``t -> (q_r, v_r)``."""
    def reference(t):
        s = min(max(t / T, 0.0), 1.0)
        return (q0 + (q1 - q0) * (10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5),
                (q1 - q0) * (30 * s ** 2 - 60 * s ** 3 + 30 * s ** 4) / T)
    return reference


def closed_loop(model, mpc, q0, t_end):
    """The MPC against ``nc.simulate(method="joint")`` (feedback held over each interval);
    returns the trajectory and the inputs."""
    inputs = []

    def u(t, qj, vj):
        inputs.append(mpc(np.concatenate([qj, vj]), t))
        return inputs[-1]

    n = len(q0)
    q, v = model.from_joint_space(q0, np.zeros(n))
    tr = nc.simulate(model, t_end, mpc.h, u=u, method="joint", q0=q, v0=v)
    return tr, np.array(inputs)


def test_joint_mpc_tracks_a_reach_with_binding_torque_bounds(two_link):
    q0, q1 = np.array([1.3, 0.0]), np.array([0.3, 1.2])        # from hanging near down, up and bent
    ref = reach(q0, q1, 0.5)
    bounds = (-np.array([10.0, 2.0]), np.array([10.0, 2.0]))
    mpc = JointMPC(two_link, 0.02, 15, ref, bounds=bounds, state_weight=(1e3, 1.0), input_weight=1e-3)
    tr, U = closed_loop(two_link, mpc, q0, 1.2)
    assert np.all(U >= bounds[0]) and np.all(U <= bounds[1])
    assert np.any(np.isclose(np.abs(U), bounds[1], rtol=0, atol=1e-9)), "the bounds should bind"
    qj = np.array(tr.qj)
    err = np.array([np.max(np.abs(q - ref(t)[0])) for q, t in zip(qj, tr.t)])
    assert err[-1] < 1e-6, err[-1]            # settled on the target after the reach
    assert err.max() < 0.05, err.max()        # the bounds slow the reach: a lag, no divergence
    # the same controller with CasADi's qpOASES for its QPs answers the same inputs
    other = JointMPC(two_link, 0.02, 15, ref, bounds=bounds, state_weight=(1e3, 1.0), input_weight=1e-3,
                     qp_solver="qpoases")
    x = np.concatenate([q0, np.zeros(2)])
    mpc.reset()
    for k in range(5):
        a, b = mpc(x, 0.02 * k), other(x, 0.02 * k)
        assert np.max(np.abs(a - b)) < 1e-6, (k, a, b)
        x = mpc.step(x, a)


def test_joint_mpc_refuses_bad_arguments(two_link):
    with pytest.raises(NcgenError, match="N"):
        JointMPC(two_link, 0.02, 0, lambda t: np.zeros(2))
    with pytest.raises(NcgenError, match="reference"):
        JointMPC(two_link, 0.02, 5, np.zeros(2))
    with pytest.raises(NcgenError, match="lb ≤ ub"):
        JointMPC(two_link, 0.02, 5, lambda t: np.zeros(2), bounds=(1.0, -1.0))
    mpc = JointMPC(two_link, 0.02, 5, lambda t: np.zeros(3))
    with pytest.raises(NcgenError, match="q_r"):
        mpc(np.zeros(4), 0.0)


@pytest.mark.slow
def test_panda_joint_mpc_tracks_a_reach():
    """The 7-DOF Panda (fingers locked) tracks a 1 s minimum-jerk reach of 0.4–0.8 rad per
    joint against the joint-space simulator, with the URDF's effort limits as bounds."""
    pytest.importorskip("yourdfpy")
    model = nc.System.from_urdf(nc.robots.locked_urdf("panda", ["panda_finger_joint1", "panda_finger_joint2"]),
                                name="panda_arm").build()
    q0 = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])
    q1 = q0 + np.array([0.8, 0.4, -0.5, 0.6, 0.5, -0.4, 0.6])
    ref = reach(q0, q1, 1.0)
    mpc = JointMPC(model, 0.01, 20, ref)
    tr, U = closed_loop(model, mpc, q0, 1.5)
    assert np.all(np.abs(U) <= np.array([87, 87, 87, 87, 12, 12, 12]))
    err = np.array([np.max(np.abs(q - ref(t)[0])) for q, t in zip(np.array(tr.qj), tr.t)])
    assert err.max() < 2e-3 and err[-1] < 1e-5, (err.max(), err[-1])


def test_ilqr_on_the_joint_step_reaches_ipopts_optimum(two_link):
    """iLQR through JointStep (Gauss–Newton) against IPOPT on the same discrete problem written
    with RNEA instead of ABA (ncgen.control.reference.solve_joint_discrete): the same cost to
    1e-6 relative, a stationary point (exact gradient ≤ 1e-6)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from joint_ilqr_reach import reach_costs
    h, N = 0.02, 40
    step = JointStep(two_link, h)
    x0 = np.zeros(4)
    U0 = np.tile(nc.rnea(two_link, np.zeros(2), np.zeros(2), np.zeros(2)), (N, 1))   # holds x0
    costs = reach_costs(2, h, np.array([0.8, -0.6]), np.array([12.0, 4.0]))
    res = nc.ilqr(step, x0, U0, costs, max_iter=500, tol=1e-7)
    assert res.converged, res.message
    _, U_ip, J_ip = solve_joint_discrete(step, x0, U0, costs)
    assert abs(res.cost - J_ip) <= 1e-6 * J_ip, (res.cost, J_ip)
    assert np.max(np.abs(res.U - U_ip)) < 1e-3 * np.max(np.abs(U_ip))
    with pytest.raises(NcgenError, match="p: the parameters are fixed"):
        nc.ilqr(step, x0, U0, costs, p=np.zeros(0))
