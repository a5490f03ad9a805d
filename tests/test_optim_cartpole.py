"""Trajectory optimisation end to end: cart-pole swing-up (convergence, defects, final
state, re-simulation with nc.simulate, warm start, multiple shooting) and closed-form
optimal controls of the double integrator."""
import copy

import numpy as np
import pytest

import ncgen as nc
from ncgen.optim.diagnostics import equality_rank

from optim_models import G, cartpole, pendulum, slider

UP = {"cart.r_i.x": 0.0, "pole.r_j.x": 0.0, "pole.r_j.y": 0.5}


@pytest.fixture(scope="module")
def swingup():
    model = cartpole()
    ocp = nc.OptimalControl(model, N=40, t_final=2.0)
    ocp.bound_input("force", -20, 20)
    ocp.bound_coordinate("cart.r_i.x", -1.5, 1.5)
    ocp.final(q=UP, v=0)
    ocp.minimize_effort()
    return model, ocp, ocp.solve()


def test_swingup_converges_from_the_standard_guess(swingup):
    """Default guess: every member turned along the shortest arc to the final pose."""
    model, ocp, sol = swingup
    assert sol.stats.success and sol.stats.status == "Solve_Succeeded"
    assert sol.stats.iterations < 300
    assert sol.stats.max_defect < 1e-8
    assert isinstance(sol, nc.Trajectory) and sol.q.shape == (41, model.nq) and sol.u.shape == (41, 1)
    np.testing.assert_allclose(sol.marker("pole.tip")[-1], [0.0, 0.5], atol=1e-6)
    np.testing.assert_allclose(sol.v[-1], 0.0, atol=1e-6)
    np.testing.assert_allclose(sol.q[0], model.q0, atol=1e-12)
    assert np.all(np.abs(sol.u) <= 20 + 1e-6)
    assert np.all(np.abs(sol.q[:, 0]) <= 1.5 + 1e-6)
    assert sol.constraint_residual.max() < 1e-4        # drift of the index-1 dynamics, O(h^5)


def test_equality_jacobian_has_full_row_rank(swingup):
    rank = equality_rank(swingup[2])
    assert rank.full_rank, (rank.rank, rank.n_equalities)
    assert rank.condition < 1e8


def test_resimulating_the_inputs_reproduces_the_motion(swingup):
    """IDAS (tight tolerances) with the optimal inputs held piecewise constant follows the
    optimised nodes, and the gap is the transcription error: below 5 cm at N = 40 (the
    open-loop replay of a motion that ends balancing upright amplifies it) and below 1 mm,
    more than 10× smaller, at N = 80."""
    model, ocp, sol = swingup

    def gap(s):
        h = s.t[1] - s.t[0]
        sim = nc.simulate(model, s.t[-1], h, u=s.u, hold="zoh", q0=s.q[0], v0=s.v[0], rtol=1e-9, atol=1e-11)
        np.testing.assert_allclose(sim.t, s.t, atol=1e-12)
        return max(np.max(np.abs(sim.q - s.q)), np.max(np.abs(sim.marker("pole.tip") - s.marker("pole.tip"))))

    fine = copy.copy(ocp)
    fine.N = 80
    coarse_gap, fine_gap = gap(sol), gap(fine.solve(warm_start=sol))
    assert coarse_gap < 5e-2 and fine_gap < 1e-3 and fine_gap < coarse_gap / 10, (coarse_gap, fine_gap)


def test_warm_start_from_the_solution_converges_at_once(swingup):
    _, ocp, sol = swingup
    again = ocp.solve(warm_start=sol)
    assert again.stats.iterations <= 10
    assert again.stats.objective == pytest.approx(sol.stats.objective, rel=1e-6)


def test_warm_start_from_a_simulation(swingup):
    """A simulation (here: of the optimal inputs, on a finer grid) resampled onto another
    mesh (N = 30) is a guess from which IPOPT converges quickly."""
    model, _, sol = swingup
    sim = nc.simulate(model, 2.0, 0.01, u=sol.input, q0=sol.q[0], v0=sol.v[0])
    ocp = nc.OptimalControl(model, N=30, t_final=2.0)
    ocp.bound_input("force", -20, 20)
    ocp.bound_coordinate("cart.r_i.x", -1.5, 1.5)
    ocp.final(q=UP, v=0)
    ocp.minimize_effort()
    again = ocp.solve(warm_start=sim)
    assert again.stats.success and again.stats.max_defect < 1e-8
    assert again.stats.iterations < 40
    assert again.stats.objective == pytest.approx(sol.stats.objective, rel=0.05)
    np.testing.assert_allclose(again.marker("pole.tip")[-1], [0.0, 0.5], atol=1e-5)


@pytest.mark.slow      # IDAS sensitivities over every interval; fast:
#                       test_multiple_shooting_with_the_stepper_scheme_replays_on_the_compiled_stepper
def test_multiple_shooting_with_idas():
    """Pendulum swing-up by multiple shooting: the IDAS defects vanish, and the motion
    re-simulates to the integrator's tolerance."""
    model = pendulum()
    ocp = nc.OptimalControl(model, N=12, t_final=2.0, method="shooting")
    ocp.bound_input("tau", -8, 8)
    ocp.final(q=[0.0, 1.0], v=0)
    ocp.minimize_effort()
    sol = ocp.solve()
    assert sol.stats.success and sol.stats.max_defect < 1e-7
    np.testing.assert_allclose(sol.marker("bar.tip")[-1], [0.0, 1.0], atol=1e-6)
    sim = nc.simulate(model, sol.t[-1], sol.t[1], u=sol.u, q0=sol.q[0], v0=sol.v[0], rtol=1e-10, atol=1e-12)
    assert np.max(np.abs(sim.q - sol.q)) < 1e-6


def test_minimum_time_double_integrator_is_bang_bang():
    """m ẍ = F, |F| ≤ F_max, rest to rest over D: T* = 2 √(m D / F_max), full thrust then
    full brake, switching at T*/2 (a node when N is even, so the discrete optimum is exact).
    The rail carries the weight: λ balances m g."""
    m, D, F = 2.0, 1.5, 3.0
    model = slider(m)
    ocp = nc.OptimalControl(model, N=10, t_final=(0.5, 10.0))
    ocp.bound_input("force", -F, F)
    ocp.final(q=[D, 0.0], v=0)
    ocp.minimize_time()
    sol = ocp.solve()
    assert sol.t_final == pytest.approx(2 * np.sqrt(m * D / F), rel=1e-6)
    np.testing.assert_allclose(sol.u[:5, 0], F, rtol=1e-5)
    np.testing.assert_allclose(sol.u[5:10, 0], -F, rtol=1e-5)
    normal = -sol.lam @ model.A(sol.q[0])[:, 1]         # generalised constraint force along y
    np.testing.assert_allclose(normal, m * G, rtol=1e-8)


def test_minimum_effort_double_integrator_matches_the_continuous_optimum():
    """min ∫ F² dt, rest to rest over D in T: F*(t) = (6 m D / T²)(1 − 2t/T), cost
    12 m² D² / T³.  Piecewise-constant F at N = 20 comes within 1 % of it."""
    m, D, T = 2.0, 1.5, 2.0
    model = slider(m)
    ocp = nc.OptimalControl(model, N=20, t_final=T)
    ocp.final(q=[D, 0.0], v=0)
    ocp.minimize_effort()
    sol = ocp.solve()
    assert sol.stats.objective == pytest.approx(12 * m**2 * D**2 / T**3, rel=1e-2)
    mid = sol.t[:-1] + (sol.t[1] - sol.t[0]) / 2
    np.testing.assert_allclose(sol.u[:-1, 0], 6 * m * D / T**2 * (1 - 2 * mid / T), atol=0.02 * 6 * m * D / T**2)


def test_multiple_shooting_with_the_stepper_scheme_replays_on_the_compiled_stepper():
    """Shooting with RATTLE (the compiled stepper's scheme, differentiable in CasADi): the
    nodes lie on both constraint levels, and the generated C stepper, fed the optimal
    inputs, reproduces them to round-off."""
    from ncgen.errors import CompilerNotFound
    from ncgen.runtime.stepper import simulate_stepper

    model = pendulum()
    ocp = nc.OptimalControl(model, N=12, t_final=2.0, method="shooting", integrator="rattle",
                            integrator_options={"substeps": 4})
    ocp.bound_input("tau", -8, 8)
    ocp.final(q=[0.0, 1.0], v=0)
    ocp.minimize_effort()
    sol = ocp.solve()
    assert sol.stats.success and sol.stats.max_defect < 1e-10
    assert sol.constraint_residual.max() < 1e-12 and sol.velocity_residual.max() < 1e-12
    try:
        # the OCP's own coarse discretisation (h = 0.04 s), replayed as is: unchecked
        replay = simulate_stepper(model, sol.t, sol.u, sol.p, sol.q[0], sol.v[0], sol.lam[0], substeps=4,
                                  check=False, scheme="rattle")
    except CompilerNotFound:
        pytest.skip("no C compiler")
    assert np.max(np.abs(replay.q - sol.q)) < 1e-8 and np.max(np.abs(replay.v - sol.v)) < 1e-8
