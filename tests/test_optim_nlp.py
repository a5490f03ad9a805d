"""The NLP IPOPT sees: derivatives against finite differences, full-rank equality
constraints for every kind of boundary condition, the collocation rule, the guesses, and
the problem features (free parameters and final time, periodicity, path constraints,
tracking and terminal costs)."""
import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.optim.diagnostics import derivative_check, equality_rank
from ncgen.optim.interpolate import pose_path
from ncgen.assembly.manifold import tangent_basis
from ncgen.optim.radau import radau_coefficients

from optim_models import cartpole, pendulum


def everything(method: str = "collocation", N: int = 6) -> nc.OptimalControl:
    """A small problem using every kind of variable, constraint and cost: free final time
    and parameter, input and state bounds, a marker path constraint, tracking, terminal
    and time costs."""
    model = pendulum()
    ocp = nc.OptimalControl(model, N=N, t_final=(0.5, 3.0), method=method)
    ocp.bound_input("tau", -10, 10)
    ocp.bound_velocity("bar.r_j.x", -6, 6)
    ocp.free_parameter("k", 0.0, 50.0, guess=2.0)
    ocp.bound_marker("bar.tip", lower=(-0.9, None))
    ocp.final(marker=("bar.tip", (0.6, None)), v=0)
    ocp.minimize_effort(0.1)
    ocp.track_marker("bar.tip", lambda t: ca.vertcat(0.3 * t, -1.0), weight=2.0)
    ocp.minimize_terminal(lambda q, v, p: ca.sumsqr(v) + 0.01 * p[0] ** 2)
    ocp.minimize_time(0.5)
    return ocp


@pytest.mark.parametrize("method", ["collocation", pytest.param("shooting", marks=pytest.mark.slow)])   # fast: collocation;
def test_ipopt_derivatives_match_finite_differences(method):    # IDAS shooting: test_equality_constraints_are_never_redundant
    """IPOPT's own gradient and constraint Jacobian (the CasADi solver's nlp_grad_f and
    nlp_jac_g, after simple-bound detection) against central differences, at the solution
    and at a perturbed point."""
    sol = everything(method, N=4 if method == "shooting" else 6).solve(tol=1e-6)
    x = sol.nlp.x_opt
    rng = np.random.default_rng(0)
    tol = 1e-6 if method == "collocation" else 1e-4      # IDAS sensitivities: integration tolerance
    for point in (x, x + 1e-3 * rng.standard_normal(x.size)):
        report = derivative_check(sol, point, step=1e-6 if method == "collocation" else 1e-5)
        assert report.gradient_error < tol and report.jacobian_error < tol, report


def test_every_problem_feature_is_honoured():
    ocp = everything(N=10)
    sol = ocp.solve()
    assert sol.stats.success and sol.stats.max_defect < 1e-8
    assert 0.5 - 1e-8 <= sol.t_final <= 3.0 + 1e-8
    assert 0.0 <= sol.parameters()["k"] <= 50.0
    assert sol.marker("bar.tip")[-1, 0] == pytest.approx(0.6, abs=1e-8)
    np.testing.assert_allclose(sol.v[-1], 0.0, atol=1e-5)     # tangent part exact, the rest is drift
    assert np.all(sol.marker("bar.tip")[:, 0] >= -0.9 - 1e-6)
    assert np.all(np.abs(sol.v[:, 0]) <= 6 + 1e-6)
    assert sol.stats.n_variables == sol.nlp.opti.nx
    assert equality_rank(sol).full_rank


@pytest.mark.parametrize("case", ["fixed both ends", "free start with marker", "periodic", "free time",
                                  "final marker only", "final pose", "index3 form", "index1 form", "shooting"])
def test_equality_constraints_are_never_redundant(case):
    """Rank of the equality Jacobian = its number of rows, whatever is imposed: the
    invariants only where the initial state is free, full-state targets through their
    tangent components."""
    model = cartpole()
    method = "shooting" if case == "shooting" else "collocation"
    form = case.split()[0] if case.endswith("form") else "ggl"
    ocp = nc.OptimalControl(model, N=8, t_final=(1.0, 3.0) if case == "free time" else 1.5, method=method,
                            form=form)
    ocp.bound_input("force", -30, 30)
    ocp.minimize_effort()
    if case == "free start with marker":
        ocp.initial(q=None, v=0, marker=("pole.tip", (0.2, None)))
        ocp.final(q={"cart.r_i.x": 0.5, "pole.r_j.x": 0.5, "pole.r_j.y": -0.5}, v=0)
    elif case == "periodic":
        ocp.periodic()
        ocp.track_marker("pole.tip", (0.3, -0.4))
    elif case == "final marker only":
        ocp.final(marker=("pole.tip", (0.4, None)), v=0)
    elif case == "final pose":                       # the pole hanging (x̄ along −y) below x = 0.4
        ocp.final(pose={"pole": (-np.pi / 2, (0.4, -0.25))}, v=0)
    else:
        ocp.final(q={"cart.r_i.x": 0.4, "pole.r_j.x": 0.4, "pole.r_j.y": -0.5}, v=0)
        if case == "free time":
            ocp.minimize_time()
    sol = ocp.solve()
    report = equality_rank(sol)
    assert report.full_rank, (case, report.rank, report.n_equalities, report.groups)


def test_periodic_motion_returns_to_its_start():
    model = pendulum()
    ocp = nc.OptimalControl(model, N=20, t_final=2.0)
    ocp.periodic()
    ocp.track_marker("bar.tip", lambda t: (0.5 * np.sin(np.pi * t), -0.8), weight=10.0)
    ocp.minimize_effort(0.01)
    sol = ocp.solve()
    N = tangent_basis(model, sol.q[0])
    np.testing.assert_allclose(N.T @ (sol.q[-1] - sol.q[0]), 0.0, atol=1e-9)
    np.testing.assert_allclose(N.T @ (sol.v[-1] - sol.v[0]), 0.0, atol=1e-9)
    # the normal components differ by the drift of the index-1 dynamics only
    assert np.max(np.abs(sol.q[-1] - sol.q[0])) < 10 * sol.constraint_residual.max() + 1e-9
    assert np.ptp(sol.marker("bar.tip")[:, 0]) > 0.3          # it does swing


def test_design_parameter_reaches_the_target():
    """No input: the stiffness of a spring (a free parameter) is chosen so that the
    pendulum, released at rest from horizontal, has its tip at y = −0.6 m after 0.8 s; a
    simulation with the stiffness found gets there too."""
    s = nc.System("launcher", gravity=(0, -9.81))
    bar = s.add_bar("bar", mass=1.0, ends=[s.ground.point((0, 0)), (1.0, 0)])
    bar.add_marker("tip", (0.5, 0))
    k = s.add_parameter("k", 5.0)
    s.add_force(nc.Spring(s.ground, (0.0, 1.0), bar, (0.5, 0), k=k))
    model = s.build()
    ocp = nc.OptimalControl(model, N=16, t_final=0.8)
    ocp.free_parameter("k", 0.0, 100.0)
    ocp.final(marker=("bar.tip", (None, -0.6)))
    sol = ocp.solve()
    k_opt = sol.parameters()["k"]
    sim = nc.simulate(model, 0.8, 0.05, p={"k": k_opt}, rtol=1e-10, atol=1e-12)
    assert sim.marker("bar.tip")[-1, 1] == pytest.approx(-0.6, abs=1e-4)


def test_radau_collocation_rule():
    """Derivatives exact on polynomials of degree ≤ d at the collocation points; quadrature
    exact to degree 2d − 2; the last point is the interval's end."""
    for d in (1, 2, 3, 5):
        tau, C, b = radau_coefficients(d)
        assert tau[-1] == pytest.approx(1.0)
        for n in range(d + 1):
            np.testing.assert_allclose(tau**n @ C, n * tau[1:] ** max(n - 1, 0) if n else 0.0, atol=1e-10)
        for n in range(2 * d - 1):
            assert b @ tau[1:] ** n == pytest.approx(1 / (n + 1), abs=1e-12)


def test_pose_interpolation_stays_on_the_constraints():
    model = cartpole()
    up = np.array([0.3, 0.0, 0.3, 0.5])
    path = pose_path(model, model.q0, up, np.linspace(0, 1, 9))
    np.testing.assert_allclose(path[0], model.q0, atol=1e-12)
    np.testing.assert_allclose(path[-1], up, atol=1e-10)
    assert max(np.max(np.abs(model.phi(q))) for q in path) < 1e-10
    mid = path[4]                                         # half way: the pole horizontal, turned
    assert abs(mid[3] - mid[1]) < 1e-8 and abs(mid[2] - mid[0]) == pytest.approx(0.5)
