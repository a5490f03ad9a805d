"""The joint-space transcription (trees) and joint-coordinate targets, against the
minimal-coordinate formulation of benchmarks/optimal_control.py (joint angles, Lagrangian
equations of motion by CasADi's AD; no ncgen)."""
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import OptimizationError
from ncgen.optim.joint_radau import JointRadauCollocation, joint_dynamics_residual, joint_space_reason
from ncgen.optim.radau import RadauCollocation

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
import optimal_control as bench  # noqa: E402


def arm_ocp(N: int, form: str = "auto"):
    model = bench.arm_system().build()
    ocp = nc.OptimalControl(model, N=N, t_final=1.0, form=form)
    ocp.bound_input("tau", -5, 5)
    ocp.minimize_effort()
    return ocp


def test_joint_residual_vanishes_on_the_lagrangian_accelerations():
    """Jᵀ(M(J a_j + J̇ v_j) − F) = 0 when a_j are the minimal formulation's accelerations
    (3D arm, random states and torques)."""
    model = bench.arm_system().build()
    res = joint_dynamics_residual(model)
    ode = bench.lagrange_ode(bench.arm_minimal())
    rng = np.random.default_rng(3)
    for _ in range(5):
        th, dth, u = rng.uniform(-2, 2, 2), rng.uniform(-3, 3, 2), rng.uniform(-5, 5, 2)
        acc = np.array(ode(np.concatenate([th, dth]), u)).reshape(-1)[2:]
        r, q, v = res(0.0, th, dth, acc, u, model.p0)
        assert np.max(np.abs(np.array(r))) < 1e-12
        assert np.max(np.abs(model.phi(np.array(q).reshape(-1)))) < 1e-14
        r_off, *_ = res(0.0, th, dth, acc + [1e-3, 0], u, model.p0)
        assert np.max(np.abs(np.array(r_off))) > 1e-6          # the check can fail


def test_auto_form_picks_joint_space_for_trees_only():
    assert isinstance(arm_ocp(4).transcription, JointRadauCollocation)
    s = nc.System("shared", gravity=(0, -9.81))          # hinges by shared points: no joint coordinates
    upper = s.add_bar("upper", mass=1.0, ends=[s.ground.point((0, 0)), (0, -1)])
    s.add_bar("fore", mass=1.0, ends=[upper.end(1), (0, -2)])
    model = s.build()
    assert joint_space_reason(model) is not None
    assert isinstance(nc.OptimalControl(model, N=4).transcription, RadauCollocation)
    with pytest.raises(OptimizationError, match="form='joint'.*no joints"):
        nc.OptimalControl(model, N=4, form="joint")
    loop = nc.System.from_toml(Path(__file__).resolve().parent.parent / "examples" / "fourbar_planar.toml").build()
    assert isinstance(nc.OptimalControl(loop, N=4).transcription, RadauCollocation)
    with pytest.raises(OptimizationError, match=r"form='joint': joint space: the model is not a tree .*form='ggl'"):
        nc.OptimalControl(loop, N=4, form="joint")


def test_joint_space_optimum_is_the_minimal_formulations():
    """Same Radau IIA(3) on the same coordinates: the minimal formulation solved from ncgen's
    optimum stays there, with the same cost to 1e-8; the final joint angles are the target."""
    N = 10
    ocp = arm_ocp(N)
    _, fore, _ = bench.arm_frames(np.pi / 2, np.pi / 2)
    ocp.final(pose={"fore": fore}, v=0)
    sol = ocp.solve()
    model = ocp.model
    qj, vj = zip(*(model.to_joint_space(q, v) for q, v in zip(sol.q, sol.v)))
    np.testing.assert_allclose(qj[-1], [np.pi / 2, np.pi / 2], atol=1e-9)
    np.testing.assert_allclose(vj[-1], 0.0, atol=1e-9)
    th = np.unwrap(np.array([bench.arm_angles(model, q) for q in sol.q]), axis=0)
    ref = bench.solve_minimal(bench.arm_minimal(), N, guess=(sol.t, th, np.array(vj), sol.u[:-1]))
    assert ref["success"]
    assert abs(sol.stats.objective - ref["cost"]) < 1e-8 * ref["cost"]
    assert sol.constraint_residual.max() < 1e-12                    # q = q(q_j): on Φ = 0


@pytest.mark.parametrize("form", ["joint", "ggl"])
def test_final_joint_angles_are_reached(form):
    """final(joints=...) in both forms: the solved joint angles equal the target, at rest,
    and (joint form) the cost equals that of the same target given as the forearm's pose."""
    ocp = arm_ocp(8, form)
    ocp.final(joints={"shoulder": np.pi / 2, "elbow": np.pi / 2}, v=0)
    sol = ocp.solve()
    qj, vj = ocp.model.to_joint_space(sol.q[-1], sol.v[-1])
    np.testing.assert_allclose(qj, [np.pi / 2, np.pi / 2], atol=1e-8)
    np.testing.assert_allclose(vj, 0.0, atol=1e-8)
    if form == "joint":
        pose = arm_ocp(8, form)
        pose.final(pose={"fore": bench.arm_frames(np.pi / 2, np.pi / 2)[1]}, v=0)
        assert abs(pose.solve().stats.objective - sol.stats.objective) < 1e-8 * sol.stats.objective


def test_initial_joint_angles_and_a_single_final_joint():
    """initial(joints=...) starts there (the elbow as in model.q0); a final condition on
    the elbow alone leaves the shoulder free."""
    ocp = arm_ocp(8)
    ocp.initial(joints={"shoulder": 0.3}, v=0)
    ocp.final(joints={"elbow": -0.8}, v=0)
    sol = ocp.solve()
    qj0 = ocp.model.to_joint_space(sol.q[0])
    qjN = ocp.model.to_joint_space(sol.q[-1])
    np.testing.assert_allclose(qj0, [0.3, 0.0], atol=1e-10)
    assert abs(qjN[1] + 0.8) < 1e-8


@pytest.mark.parametrize("call, message", [
    (lambda o: o.final(joints={"wrist": 1.0}), "no joint with coordinates named 'wrist'"),
    (lambda o: o.final(joints={"elbow": [1.0, 2.0]}), r"final joints\['elbow'\]: expected 1 finite"),
    (lambda o: o.final(joints={"elbow": 1.0}, q={"upper.w.x": 0.0}), "give one of q, pose, joints"),
    (lambda o: o.initial(joints={"elbow": np.nan}), "expected 1 finite"),
])
def test_bad_joint_targets_are_named(call, message):
    with pytest.raises(OptimizationError, match=message):
        call(arm_ocp(4))


def test_joint_inertias_are_the_rods_moments_about_the_hinges():
    """The row scales of the joint form (diagonal of Jᵀ M J) at the arm held horizontal:
    both rods about the shoulder and the forearm about the elbow (parallel-axis theorem)."""
    from ncgen.optim.joint_radau import joint_inertias
    model = bench.arm_system().build()
    m = joint_inertias(model, [np.pi / 2, 0.0])
    x = ca.SX.sym("x", 2)
    q = model.joint_space.tree_function(model.layout)(x, ca.DM.zeros(2))[0]
    J = np.array(ca.Function("J", [x], [ca.jacobian(q, x)])([np.pi / 2, 0.0]))
    np.testing.assert_allclose(m, np.diag(J.T @ model.M @ J), rtol=1e-12)
    I1 = bench.ARM_M * bench.ARM_L ** 2 / 12 + bench.ARM_M * bench.ARM_RADIUS ** 2 / 4
    I_sh = 2 * I1 + bench.ARM_M * (bench.ARM_L / 2) ** 2 + bench.ARM_M * (1.5 * bench.ARM_L) ** 2
    np.testing.assert_allclose(m, [I_sh, I1 + bench.ARM_M * (bench.ARM_L / 2) ** 2], rtol=1e-12)


ARM_PROBLEM = """
[horizon]
N = 6
t_final = 1.0
[bounds.inputs]
tau = [-5, 5]
[final]
v = 0
{target}
[cost]
effort = 1.0
"""


@pytest.mark.parametrize("target", [
    "joints = {shoulder = 1.5707963267948966, elbow = 1.5707963267948966}",
    "[final.pose.fore]\nrotation = [[-1, 0, 0], [0, 1, 0], [0, 0, -1]]\nposition = [-0.4, 0.0, 0.2]",
])
def test_problem_file_joint_and_pose_targets(target):
    """Both spellings of the arm's end configuration in a problem file reach it."""
    import tomllib
    from ncgen.optim.problem_file import problem_from_data
    model = bench.arm_system().build()
    ocp, options = problem_from_data(tomllib.loads(ARM_PROBLEM.format(target=target)), model, "arm.toml")
    sol = ocp.solve(max_iter=options.max_iter, tol=options.tol)
    np.testing.assert_allclose(model.to_joint_space(sol.q[-1]), [np.pi / 2, np.pi / 2], atol=1e-8)
    R, p = model.poses(sol.q[-1])
    np.testing.assert_allclose(R[1], bench.arm_frames(np.pi / 2, np.pi / 2)[1][0], atol=1e-8)


@pytest.mark.parametrize("target, key", [
    ("joints = {elbow = 'up'}", "final.joints.elbow: expected a number"),
    ("joints = {wrist = 1.0}", "final: final joints: no joint with coordinates named 'wrist'"),
    ("[final.pose.fore]\nrotation = [[1, 0, 0]]\nposition = [0, 0, 0]", "final.pose.fore.rotation: expected 3 rows"),
    ("[final.pose.fore]\nrotation = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]", "final.pose.fore.position: missing"),
])
def test_problem_file_bad_targets_name_the_key(target, key):
    import tomllib
    from ncgen.errors import ProblemFileError
    from ncgen.optim.problem_file import problem_from_data
    with pytest.raises(ProblemFileError, match=key.replace("(", r"\(")):
        problem_from_data(tomllib.loads(ARM_PROBLEM.format(target=target)), bench.arm_system().build(), "arm.toml")


def test_free_initial_configuration_at_rest_in_joint_space():
    """initial(q=None, v=0): the start is a decision variable (no invariants needed), at rest;
    a nonzero initial velocity with a free q is refused by name."""
    ocp = arm_ocp(6, "joint")
    ocp.initial(q=None, v=0)
    ocp.final(joints={"elbow": 0.5}, v=0)
    sol = ocp.solve()
    np.testing.assert_allclose(sol.v[0], 0.0, atol=1e-12)
    assert abs(ocp.model.to_joint_space(sol.q[-1])[1] - 0.5) < 1e-8
    assert sol.constraint_residual.max() < 1e-12
    bad = arm_ocp(4, "joint")
    bad.initial(q=None, v=np.ones(bad.model.nq))
    with pytest.raises(OptimizationError, match="nonzero velocity with a free initial q"):
        bad.solve()
