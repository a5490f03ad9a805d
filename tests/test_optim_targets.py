"""Final conditions in the user's terms (member poses), the default guess, and warm starts
from a coarser mesh."""
import sys
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import OptimizationError
from ncgen.optim.guess import make_guess

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
from optimal_control import arm_frames, arm_system  # noqa: E402


def double_pendulum(motors: int = 2):
    """Two uniform 1 m, 1 kg bars hanging from the origin; ``motors`` = 2: shoulder and
    elbow torques, 1: elbow only."""
    s = nc.System("double_pendulum", gravity=(0, -9.81))
    upper = s.add_bar("upper", mass=1.0, ends=[s.ground.point((0, 0)), (0, -1)])
    fore = s.add_bar("fore", mass=1.0, ends=[upper.end(1), (0, -2)])
    tau = s.add_input("tau", motors)
    if motors == 2:
        s.add_force(nc.Torque(upper, tau[0] - tau[1]))
        s.add_force(nc.Torque(fore, tau[1]))
    else:
        s.add_force(nc.Torque(upper, -tau))
        s.add_force(nc.Torque(fore, tau))
    return s.build()


@pytest.mark.parametrize("form, share", [("joint", True), ("ggl", True),
                                         pytest.param("ggl", False, marks=pytest.mark.slow)])   # ggl: same path
def test_final_pose_of_a_3d_member_places_the_rest_by_the_joints(form, share):
    """The forearm's pose (rotation and centre) as the target; the upper rod must end where
    the hinges put it (shoulder +90° about y), at rest.  With coordinate sharing (the
    default) the hinge axes and the elbow are shared coordinates: natural-coordinate Newton
    stalls from the hanging start and the target is found by joint-space inverse kinematics."""
    model = arm_system().build(share=share)
    ocp = nc.OptimalControl(model, N=8, t_final=1.0, form=form)
    ocp.bound_input("tau", -5, 5)
    (R1, p1), (R2, p2), _ = arm_frames(np.pi / 2, np.pi / 2)
    ocp.final(pose={"fore": (R2, p2)}, v=0)
    ocp.minimize_effort()
    sol = ocp.solve()
    R, p = model.poses(sol.q[-1])
    np.testing.assert_allclose(R[1], R2, atol=1e-7)
    np.testing.assert_allclose(p[1], p2, atol=1e-7)
    np.testing.assert_allclose(R[0], R1, atol=1e-7)          # from the joints, not imposed
    np.testing.assert_allclose(p[0], p1, atol=1e-7)
    np.testing.assert_allclose(sol.v[-1], 0.0, atol=1e-7)
    assert sol.constraint_residual.max() < 1e-10


def test_final_pose_equals_the_full_configuration_target():
    """A small point-to-point motion (one optimum): upper link at 0.5 rad, forearm at 1 rad
    from hanging, given as the forearm's pose or as the full configuration."""
    model = double_pendulum()
    elbow = np.array([np.sin(0.5), -np.cos(0.5)])
    hand = elbow + [np.sin(1.0), -np.cos(1.0)]

    def solve(**final):
        ocp = nc.OptimalControl(model, N=12, t_final=1.0)
        ocp.final(v=0, **final)
        ocp.minimize_effort()
        return ocp.solve()
    a = solve(pose={"fore": (-np.pi / 2 + 1.0, (elbow + hand) / 2)})      # x̄ from elbow to hand
    b = solve(q=[*elbow, *hand])
    assert abs(a.stats.objective - b.stats.objective) < 1e-8 * b.stats.objective
    np.testing.assert_allclose(a.q[-1], [*elbow, *hand], atol=1e-8)


@pytest.mark.parametrize("pose, message", [
    ({"elbow": (0.0, (0, 1))}, "no member named 'elbow'"),
    ({"fore": (np.pi / 2, (0, 5))}, "the joints cannot reach it"),
    ({"fore": "up"}, "expected (rotation, position)"),
])
def test_bad_final_pose_is_named(pose, message):
    ocp = nc.OptimalControl(double_pendulum(), N=4, t_final=1.0)
    with pytest.raises(OptimizationError, match=message.replace("(", r"\(").replace(")", r"\)")):
        ocp.final(pose=pose)
        ocp.solve()


def test_default_guess_is_consistent_at_rest_with_inverse_dynamics_inputs():
    """On Φ = 0, velocities tangent and zero at both ends, and (fully actuated) inputs that
    satisfy the equations of motion along the path up to the finite-difference error."""
    model = double_pendulum()
    ocp = nc.OptimalControl(model, N=20, t_final=2.0)
    ocp.final(q=[0, 1, 0, 2], v=0)
    g, _ = make_guess(ocp, None, model.q0, np.zeros(model.nq), np.array([0, 1, 0, 2.0]), model.p0)
    t = np.linspace(0, 2, 41)
    q, v, a, lam, u = g.q(t), g.v(t), g.a(t), g.lam(t), g.u(t)
    assert max(np.max(np.abs(model.phi(qi))) for qi in q) < 1e-8
    assert max(np.max(np.abs(model.A(qi) @ vi)) for qi, vi in zip(q, v)) < 1e-8
    np.testing.assert_allclose(v[[0, -1]], 0.0, atol=1e-12)
    scale = np.max(np.abs(model.M @ a.T))
    for i in range(5, 36):                               # interior: central differences
        res = model.M @ a[i] + model.A(q[i]).T @ lam[i] - model.F(q[i], v[i], u=u[i])
        assert np.max(np.abs(res)) < 1e-2 * scale, (i, res)
    assert np.max(np.abs(u)) > 1.0                       # not the zero inputs of old


def test_coarse_start_solves_the_fine_problem_from_the_coarse_solution():
    model = double_pendulum()

    def ocp():
        o = nc.OptimalControl(model, N=16, t_final=2.0)
        o.bound_input("tau", -30, 30)
        o.final(q=[0, 1, 0, 2], v=0)
        o.minimize_effort(0.1)
        return o
    direct, coarse = ocp().solve(), ocp().solve(coarse_start=True)
    assert coarse.stats.success and coarse.q.shape == direct.q.shape
    np.testing.assert_allclose(coarse.q[-1], [0, 1, 0, 2], atol=1e-8)
    assert coarse.stats.iterations < direct.stats.iterations     # the fine solve starts near an optimum


def test_guess_turn_chooses_the_direction_of_a_rotation():
    """Planar: a pendulum swung up clockwise passes x < 0 halfway; 3D: the forearm's half
    turn about −y instead of the shortest arc's axis; an axis the turn is not about is an
    error naming the member."""
    from optim_models import pendulum
    model = pendulum()
    mid = {}
    for turn in (None, -1):
        ocp = nc.OptimalControl(model, N=10, t_final=1.0).final(q=[0, 1], v=0)
        if turn is not None:
            ocp.guess_turn("bar", turn)
        g, _ = make_guess(ocp, None, model.q0, np.zeros(2), np.array([0, 1.0]), model.p0)
        mid[turn] = g.q(np.array([0.5]))[0]
    np.testing.assert_allclose(mid[None], [1, 0], atol=1e-9)
    np.testing.assert_allclose(mid[-1], [-1, 0], atol=1e-9)

    arm = arm_system().build()
    _, (R2, p2), _ = arm_frames(np.pi / 2, np.pi / 2)
    ocp = nc.OptimalControl(arm, N=4, t_final=1.0).final(pose={"fore": (R2, p2)}, v=0)
    ocp.guess_turn("fore", (0, -1, 0))
    q_final = arm_system(np.pi / 2, np.pi / 2).build().q0
    g, _ = make_guess(ocp, None, arm.q0, np.zeros(arm.nq), q_final, arm.p0)
    R, _ = arm.poses(g.q(np.array([0.5]))[0])
    c = np.cos(-np.pi / 2)
    np.testing.assert_allclose(R[1], [[c, 0, -1], [0, 1, 0], [1, 0, c]], atol=1e-4)   # roty(−π/2), sampled guess
    ocp.guess_turn("fore", (1, 0, 0))
    with pytest.raises(OptimizationError, match="guess_turn 'fore'.*not about"):
        make_guess(ocp, None, arm.q0, np.zeros(arm.nq), q_final, arm.p0)
