"""ClusteredCable (ncgen.model.cables): a counterweight over two pulleys against the
Atwood machine's closed-form acceleration, a block and tackle (one tension: twice it on the
moving pulley) in equilibrium and in motion, energy conservation, the generalised force
against finite differences of the potential, slack, bad input."""
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError
from ncgen.model.cables import ClusteredCable

G = 9.81


def vertical_point(s, name, mass, x):
    p = s.add_point(name, mass=mass, position=(x, 0, 0))
    s.add_joint(nc.PointOnLine(s.ground, p, at=(x, 0, 0), axis=(0, 0, 1)))
    return p


def atwood(m1, m2, k=5e3, damping=0.0):
    """Masses at x = ∓0.1 below pulleys at z = 1 on the ground; the cable starts stretched
    to the Atwood tension 2 m1 m2 g / (m1 + m2), so that it keeps its length."""
    s = nc.System("atwood", gravity=(0, 0, -G))
    a, b = vertical_point(s, "a", m1, -0.1), vertical_point(s, "b", m2, 0.1)
    T = 2 * m1 * m2 * G / (m1 + m2)
    s.add_force(ClusteredCable([(a, (0, 0, 0)), (s.ground, (-0.1, 0, 1)), (s.ground, (0.1, 0, 1)), (b, (0, 0, 0))],
                               k=k, rest_length=2.2 - T / k, damping=damping, name="rope"))
    return s


def test_counterweight_over_pulleys_has_the_atwood_acceleration():
    m1, m2 = 2.0, 1.0
    traj = nc.simulate(atwood(m1, m2).build(), t_end=0.5, dt=0.01, backend="vm")
    acc = G * (m1 - m2) / (m1 + m2)
    np.testing.assert_allclose(traj.point("a", (0, 0, 0))[:, 2], -0.5 * acc * traj.t**2, atol=1e-8)
    np.testing.assert_allclose(traj.point("b", (0, 0, 0))[:, 2], 0.5 * acc * traj.t**2, atol=1e-8)
    assert np.ptp(traj.energy) < 1e-6 * (m1 + m2) * G * 0.5 * acc * 0.25


def block_and_tackle(M, m, k=2e4):
    """A mass M on a moving pulley (the cable from an anchor at z = 1 down round it and up
    over fixed pulleys at z = 1.2) against a counterweight m; one tension T, 2T on M."""
    s = nc.System("tackle", gravity=(0, 0, -G))
    pulley, weight = vertical_point(s, "pulley", M, 0.0), vertical_point(s, "weight", m, 0.1)
    T = 3 * G / (1 / m + 4 / M)                     # M a = 2T − M g, m a_m = T − m g, a_m = −2 a
    path = [(s.ground, (0, 0, 1.0)), (pulley, (0, 0, 0)), (s.ground, (0, 0, 1.2)), (s.ground, (0.1, 0, 1.2)),
            (weight, (0, 0, 0))]
    s.add_force(ClusteredCable(path, k=k, rest_length=3.5 - T / k, name="rope"))
    return s, T


def test_block_and_tackle_holds_twice_the_counterweight():
    s, T = block_and_tackle(2.0, 1.0)
    assert T == pytest.approx(1.0 * G)
    eq = nc.equilibrium(s.build())
    np.testing.assert_allclose(eq.q, s.build().q0, atol=1e-12)        # it stays: 2T = M g, T = m g
    assert eq.force_residual < 1e-9


def test_block_and_tackle_accelerates_as_the_closed_form():
    M, m = 3.0, 1.0
    s, T = block_and_tackle(M, m)
    traj = nc.simulate(s.build(), t_end=0.4, dt=0.01, backend="vm")
    a = (2 * T - M * G) / M
    np.testing.assert_allclose(traj.point("pulley", (0, 0, 0))[:, 2], 0.5 * a * traj.t**2, atol=1e-8)
    np.testing.assert_allclose(traj.point("weight", (0, 0, 0))[:, 2], -a * traj.t**2, atol=1e-8)


def test_generalized_force_is_minus_the_gradient_of_the_potential():
    s = nc.System("free", gravity=(0, 0, 0))
    pts = [s.add_point(f"p{i}", mass=1.0, position=x) for i, x in
           enumerate([(0, 0, 0), (1, 0.2, 0), (1.5, 1, 0.3), (0.2, 1.4, -0.1)])]
    s.add_force(ClusteredCable([(s.ground, (-1, 0, 0))] + [(p, (0, 0, 0)) for p in pts], k=300.0,
                               rest_length=2.0))
    model = s.build()
    q = model.q0 + 0.05 * np.random.default_rng(0).normal(size=model.nq)
    zero_v, u, p = np.zeros(model.nq), np.zeros(0), np.zeros(0)
    F = np.array(model.functions["F"](0, q, zero_v, u, p)).reshape(-1)
    V = lambda x: float(model.functions["energy"](0, x, zero_v, p)[1])
    h = 1e-6
    grad = np.array([(V(q + h * e) - V(q - h * e)) / (2 * h) for e in np.eye(model.nq)])
    np.testing.assert_allclose(F, -grad, atol=1e-6 * np.abs(F).max())
    assert np.abs(F).max() > 1.0                                  # taut


def test_slack_cable_pulls_nothing():
    s = nc.System("slack", gravity=(0, 0, 0))
    a = s.add_point("a", mass=1.0, position=(0, 0, 0))
    s.add_force(ClusteredCable([(s.ground, (1, 0, 0)), (a, (0, 0, 0)), (s.ground, (0, 1, 0))], k=100.0,
                               rest_length=3.0))
    model = s.build()
    F = np.array(model.functions["F"](0, model.q0, np.zeros(3), np.zeros(0), np.zeros(0))).reshape(-1)
    np.testing.assert_allclose(F, 0)


def test_bad_paths_are_named():
    s = nc.System("bad", gravity=(0, 0, -G))
    a = s.add_point("a", mass=1.0, position=(0, 0, 0))
    with pytest.raises(ModelError, match=r"path: expected two or more"):
        s.add_force(ClusteredCable([(a, (0, 0, 0))], k=1.0, rest_length=1.0))
    with pytest.raises(ModelError, match=r"path\[1\]: expected a \(member, point\) pair"):
        s.add_force(ClusteredCable([(a, (0, 0, 0)), a], k=1.0, rest_length=1.0))
    with pytest.raises(ModelError, match="every point is on the ground"):
        s.add_force(ClusteredCable([(s.ground, (0, 0, 1)), (s.ground, (0, 0, 2))], k=1.0, rest_length=1.0))
    with pytest.raises(ModelError, match="k: expected a number >= 0"):
        s.add_force(ClusteredCable([(s.ground, (0, 0, 1)), (a, (0, 0, 0))], k=-1.0, rest_length=1.0))


def test_compiled_stepper_moves_the_atwood_machine_as_the_closed_form(tmp_path, monkeypatch):
    """The compiled stepper (generated C, RATTLE) on the same machine: a constant
    acceleration is integrated exactly."""
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    m1, m2 = 2.0, 1.0
    traj = nc.simulate(atwood(m1, m2).build(), t_end=0.5, dt=0.01, method="stepper")
    acc = G * (m1 - m2) / (m1 + m2)
    np.testing.assert_allclose(traj.point("a", (0, 0, 0))[:, 2], -0.5 * acc * traj.t**2, atol=1e-12)


def test_rest_length_as_an_input_and_as_a_parameter():
    """A weight m on a cable over a pulley at z = 1, anchored 1 m away: L = (1 − z) + 1 and
    k (L − l₀) = m g put the weight at z = 2 − l₀ − m g / k, for the actuated rest length
    (an input) and for a design rest length (a parameter)."""
    m, k = 2.0, 500.0
    for kind in ("input", "parameter"):
        s = nc.System("winch", gravity=(0, 0, -G))
        w = vertical_point(s, "w", m, 0.0)
        l0 = s.add_input("l0") if kind == "input" else s.add_parameter("l0", 1.5)
        s.add_force(ClusteredCable([(s.ground, (1, 0, 1)), (s.ground, (0, 0, 1)), (w, (0, 0, 0))], k=k,
                                   rest_length=l0))
        model = s.build()
        for value in (1.5, 1.2):
            eq = nc.equilibrium(model, u=[value]) if kind == "input" else nc.equilibrium(model, p=[value])
            assert eq.coordinate("w.r_i.z") == pytest.approx(2 - value - m * G / k, abs=1e-10)


def test_toml_round_trip_and_errors():
    s = atwood(2.0, 1.0, damping=0.5)
    text = s.to_toml()
    assert 'type = "ClusteredCable"' in text
    back = nc.System.from_toml(text)
    assert back.to_toml() == text
    m1, m2 = s.build(), back.build()
    rng = np.random.default_rng(4)
    q, v = m1.q0 + 0.01 * rng.normal(size=m1.nq), rng.normal(size=m1.nq)
    F1 = np.array(m1.functions["F"](0, q, v, np.zeros(0), np.zeros(0)))
    np.testing.assert_allclose(np.array(m2.functions["F"](0, q, v, np.zeros(0), np.zeros(0))), F1, rtol=1e-14)
    bad = text.replace('path = [["a"', 'path = [["nobody"')
    with pytest.raises(ModelError, match=r"forces\[0\]\.path\[0\]\[0\]"):
        nc.System.from_toml(bad)


def test_actuated_rest_length_step_oscillates_as_the_closed_form():
    """Winch of the test above, rest length stepped from 1.5 m to 1.48 m at t = 0: the weight
    oscillates about its new equilibrium, z(t) = z₁ + (z₀ − z₁) cos(√(k/m) t) (the swing,
    0.02 m, is below the static stretch m g / k = 0.039 m: the cable stays taut)."""
    m, k = 2.0, 500.0
    s = nc.System("winch", gravity=(0, 0, -G))
    w = vertical_point(s, "w", m, 0.0)
    s.add_force(ClusteredCable([(s.ground, (1, 0, 1)), (s.ground, (0, 0, 1)), (w, (0, 0, 0))], k=k,
                               rest_length=s.add_input("l0")))
    z0, z1 = 2 - 1.5 - m * G / k, 2 - 1.48 - m * G / k
    model = s.build()
    q0 = model.q0.copy()
    q0[model.coordinate_names.index("w.r_i.z")] = z0
    traj = nc.simulate(model, 1.0, 0.01, u=[1.48], q0=q0, backend="vm", rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(traj.point("w", (0, 0, 0))[:, 2], z1 + (z0 - z1) * np.cos(np.sqrt(k / m) * traj.t),
                               atol=1e-7)


def test_optimal_control_lifts_a_weight_by_the_rest_length():
    """The winch's rest length as the control of an optimal-control problem (feasibility:
    lift the weight 0.2 m in 2 s, at rest at both ends); the simulation of the solution's
    inputs (IDAS) ends where the collocation says."""
    m, k = 1.0, 200.0
    s = nc.System("winch", gravity=(0, 0, -G))
    w = vertical_point(s, "w", m, 0.0)
    s.add_force(ClusteredCable([(s.ground, (1, 0, 1)), (s.ground, (0, 0, 1)), (w, (0, 0, 0))], k=k,
                               rest_length=s.add_input("l0"), damping=5.0))
    model = s.build()
    z0 = 2 - 1.5 - m * G / k
    ocp = nc.OptimalControl(model, N=40, t_final=2.0)
    ocp.bound_input("l0", 1.2, 1.6)
    ocp.initial(q={"w.r_i.z": z0}, v=0)
    ocp.final(q={"w.r_i.z": z0 + 0.2}, v=0)
    sol = ocp.solve()
    sim = nc.simulate(model, sol.t[-1], sol.t[1], u=sol.u, q0=sol.q[0], v0=sol.v[0], backend="vm")
    z = model.coordinate_names.index("w.r_i.z")
    assert sim.q[-1, z] == pytest.approx(z0 + 0.2, abs=1e-5)
    assert abs(sim.v[-1, z]) < 1e-4
    assert np.all((sol.u >= 1.2 - 1e-8) & (sol.u <= 1.6 + 1e-8))


def test_actuated_cable_energy_balance():
    """Rest length l₀(t) = 1.5 − 0.01 sin 3t (the cable stays taut): the change of
    ½ m ż² + m g z + ½ k (L − l₀)² equals the work −∫ T l̇₀ dt the winch does."""
    m, k = 2.0, 500.0
    s = nc.System("winch", gravity=(0, 0, -G))
    w = vertical_point(s, "w", m, 0.0)
    s.add_force(ClusteredCable([(s.ground, (1, 0, 1)), (s.ground, (0, 0, 1)), (w, (0, 0, 0))], k=k,
                               rest_length=s.add_input("l0")))
    model = s.build()
    q0 = model.q0.copy()
    q0[model.coordinate_names.index("w.r_i.z")] = 2 - 1.5 - m * G / k
    l0 = lambda t: 1.5 - 0.01 * np.sin(3 * t)                               # noqa: E731
    traj = nc.simulate(model, 2.0, 1e-3, u=lambda t: [l0(t)], q0=q0, hold="linear", backend="vm", rtol=1e-10,
                       atol=1e-12)
    z = traj.point("w", (0, 0, 0))[:, 2]
    zdot = traj.v[:, model.coordinate_names.index("w.r_i.z")]
    stretch = (2 - z) - l0(traj.t)
    assert stretch.min() > 0
    E = 0.5 * m * zdot**2 + m * G * z + 0.5 * k * stretch**2
    T = k * stretch
    # l₀ is interpolated linearly between the samples: −∫ T l̇₀ dt by the trapezoid rule per interval
    work = np.concatenate([[0], np.cumsum(-0.5 * (T[1:] + T[:-1]) * np.diff(l0(traj.t)))])
    np.testing.assert_allclose(E - E[0], work, atol=1e-6 * np.abs(work).max())
    assert np.abs(work).max() > 0.01
