"""``OptimalControl.min_tension(T_min)``: a plan whose cables stay taut (issue 41).

A point mass hanging from the ground by one cable whose rest length is the input rises 5 cm
in 0.2 s and stops: stopping needs the cable to pull less than the weight, so a floor on the
pull binds.  The plan's inputs are replayed by the simulator (IDAS, inputs held per
interval) and the cable's pull ``k (l − l₀) + c l̇`` computed by hand along the replay: it
stays ≥ ``T_min`` (up to the collocation error between the points), and it touches it.  The
pull's function (:mod:`ncgen.optim.taut_cables`, the one the MPC uses too) is checked against the
formula by hand, its derivatives against central differences; bad values and models without
cables are refused by name."""
from __future__ import annotations

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError
from ncgen.optim.taut_cables import cable_pull_function

K, C, MASS = 200.0, 5.0, 1.0
T_FINAL, N = 0.2, 20
REST_LOW, REST_HIGH = 1.0 - MASS * 9.81 / K, 0.95 - MASS * 9.81 / K   # rest lengths holding -1 m and -0.95 m


def hanging(cable=True):
    s = nc.System("hang", gravity=(0, 0, -9.81))
    p = s.add_point("p", mass=MASS, position=(0, 0, -1.0))
    u = s.add_input("l0", 1)
    s.add_force(nc.Spring(s.ground, (0, 0, 0), p, (0, 0, 0), k=K, rest_length=u[0], damping=C, cable=cable,
                          name="c"))
    return s.build()


def pull(q, v, l0):
    """The cable's pull by hand (the cable from the origin to the mass), N."""
    length = np.linalg.norm(q)
    return K * (length - l0) + C * q @ v / length


def rising(model, T_min=None):
    ocp = nc.OptimalControl(model, N=N, t_final=T_FINAL)
    ocp.bound_input("l0", 0.5, 1.5)
    ocp.minimize_effort(1e-3)
    ocp.initial(q=[0, 0, -1.0], v=[0, 0, 0])
    ocp.final(q=[0, 0, -0.95], v=[0, 0, 0])
    return ocp if T_min is None else ocp.min_tension(T_min)


@pytest.fixture(scope="module")
def model():
    return hanging()


def test_pull_function_against_the_formula_and_central_differences(model):
    f = cable_pull_function(model, "test")
    rng = np.random.default_rng(41)
    q, v, u = np.array([0.1, -0.2, -0.9]), rng.normal(size=3), np.array([0.93])
    assert float(f(0.0, q, v, u, model.p0)) == pytest.approx(pull(q, v, u[0]), rel=1e-13)
    jac = ca_jacobian(f)
    J = np.asarray(jac(0.0, q, v, u, model.p0)).reshape(-1)
    z, eps = np.concatenate([q, v, u]), 1e-6
    by_hand = [(pull(*np.split(z + eps * e, [3, 6])) - pull(*np.split(z - eps * e, [3, 6]))) / (2 * eps)
               for e in np.eye(7)]
    np.testing.assert_allclose(J, np.ravel(by_hand), rtol=1e-7, atol=1e-7)


def ca_jacobian(f):
    """``(t, q, v, u, p) -> dP/d[q; v; u]`` of the pull function ``f``."""
    import casadi as ca
    t, q, v, u, p = (ca.SX.sym(n, f.size1_in(i)) for i, n in enumerate(f.name_in()))
    P = f(t, q, v, u, p)
    return ca.Function("dP", [t, q, v, u, p], [ca.jacobian(P, ca.vertcat(q, v, u))])


@pytest.mark.parametrize("T_min, message", [
    (-1.0, "min_tension: expected a finite tension >= 0"),
    (np.inf, "min_tension: expected a finite"),
    ("two", "min_tension"),
])
def test_bad_min_tension_refused_by_name(model, T_min, message):
    with pytest.raises(NcgenError, match=message):
        rising(model).min_tension(T_min)


def test_model_without_cables_refused_by_name():
    with pytest.raises(NcgenError, match="min_tension: the model 'hang' has no cables"):
        rising(hanging(cable=False)).min_tension(1.0)


def test_problem_file_key(model, tmp_path):
    from ncgen.optim.problem_file import problem_from_data
    ocp, _ = problem_from_data({"horizon": {"N": 4, "t_final": 0.1}, "bounds": {"min_tension": 3.0}}, model)
    assert ocp.cable_min_tension == 3.0
    with pytest.raises(NcgenError, match="bounds.min_tension: expected a number"):
        problem_from_data({"bounds": {"min_tension": "taut"}}, model)


def test_plan_keeps_the_cable_taut_in_the_simulator(model):
    """The floor binds (the plan's smallest pull is T_min) and the replayed plan keeps it."""
    T_min = 4.0
    ramp = nc.simulate(model, T_FINAL, T_FINAL / N, q0=[0, 0, -1.0], backend="vm",
                       u=lambda t: [REST_LOW + (REST_HIGH - REST_LOW) * 0.5 * (1 - np.cos(np.pi * min(t / 0.15, 1)))])
    plan = rising(model, T_min).solve(warm_start=ramp, diagnose=False)
    h = plan.t[1] - plan.t[0]
    at_nodes = [pull(plan.q[k], plan.v[k], plan.u[min(k, N - 1)][0]) for k in range(N)]
    at_nodes += [pull(plan.q[k + 1], plan.v[k + 1], plan.u[k][0]) for k in range(N)]
    assert min(at_nodes) >= T_min - 1e-6
    dt = h / 10
    grid = np.arange(10 * N + 1) * dt
    held = plan.u[np.minimum((grid / h + 1e-9).astype(int), N - 1)]
    replay = nc.simulate(model, T_FINAL, dt, u=held, q0=plan.q[0], v0=plan.v[0], backend="vm", rtol=1e-10,
                         atol=1e-12)
    np.testing.assert_allclose(replay.q[::10], plan.q, atol=2e-5)      # the plan is the model's motion
    pulls = np.array([pull(q, v, u[0]) for q, v, u in zip(replay.q, replay.v, held)])
    assert T_min - 0.05 <= pulls.min() <= T_min + 0.1, pulls.min()   # kept, and binding
    assert replay.q[-1, 2] == pytest.approx(-0.95, abs=1e-4)


@pytest.mark.slow      # a second transcription's solve; fast: test_plan_keeps_the_cable_taut_in_the_simulator (the
#                       same floor by collocation, replayed)
def test_multiple_shooting_keeps_the_floor_at_the_nodes(model):
    """With ``method="shooting"`` (the path points are the nodes) the floor holds at both ends of
    every interval, with the interval's input, and binds."""
    ocp = nc.OptimalControl(model, N=N, t_final=T_FINAL, method="shooting")
    ocp.bound_input("l0", 0.5, 1.5)
    ocp.minimize_effort(1e-3)
    ocp.initial(q=[0, 0, -1.0], v=[0, 0, 0])
    ocp.final(q=[0, 0, -0.95], v=[0, 0, 0])
    T_min = 4.0
    ramp = nc.simulate(model, T_FINAL, T_FINAL / N, q0=[0, 0, -1.0], backend="vm",
                       u=lambda t: [REST_LOW + (REST_HIGH - REST_LOW) * 0.5 * (1 - np.cos(np.pi * min(t / 0.15, 1)))])
    plan = ocp.min_tension(T_min).solve(warm_start=ramp, diagnose=False)
    pulls = [pull(plan.q[j], plan.v[j], plan.u[k][0]) for k in range(N) for j in (k, k + 1)]
    assert T_min - 1e-6 <= min(pulls) <= T_min + 1e-3, min(pulls)
