"""Optimal control through nonsmooth contacts (ncgen.optim.contact_implicit): refusals of
what no transcription handles, settings checks, and solved problems against closed forms
and the nonsmooth stepper."""
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import OptimizationError, ProblemFileError

QUICK_COMPILE = True             # its replays' time is gcc compiling their scenes: -O0 (tests/conftest.py)


def _ball(contacts="nonsmooth", restitution=0.8, mu=0.0):
    s = nc.System("ball", gravity=(0, -9.81))
    b = s.add_point("ball", mass=1.0, position=(0, 1.0))
    b.add_marker("c", (0, 0))
    s.add_contact(nc.SpherePlane(b, radius=0.1, restitution=restitution, mu=mu, name="floor"))
    return s.build(contacts=contacts)


def _box_on_box():
    s = nc.System("boxes", gravity=(0, 0, -9.81))
    box = s.add_body("box", mass=1.0, inertia=np.eye(3) * 0.01, position=(0, 0, 0.2))
    s.add_contact(nc.BoxBox(box, (0.1, 0.1, 0.1), s.ground, (1, 1, 0.2), at_b=(0, 0, 0.0), name="on_table"))
    return s.build(contacts="nonsmooth")


@pytest.mark.parametrize("method", ["collocation", "shooting"])
def test_other_transcriptions_refuse_nonsmooth_contacts(method):
    model = _ball()
    with pytest.raises(OptimizationError, match=r"nonsmooth contacts \('floor' \(SpherePlane\)\).*as if they were absent"):
        nc.OptimalControl(model, N=10, t_final=1.0, method=method)


def test_unhandled_contact_kind_is_refused_by_name():
    model = _box_on_box()
    with pytest.raises(OptimizationError, match=r"no optimal-control transcription handles the contact\(s\) "
                                                r"'on_table\.a_corner0' \(BoxBox of element 'on_table'\)"):
        nc.OptimalControl(model, N=10, t_final=1.0)


def test_nonsmooth_model_defaults_to_contact_implicit_and_smooth_to_collocation():
    assert "contact-implicit" in repr(nc.OptimalControl(_ball(), N=4, t_final=1.0))
    assert "contact-implicit" not in repr(nc.OptimalControl(_ball("smooth"), N=4, t_final=1.0))
    with pytest.raises(OptimizationError, match="has no nonsmooth contacts"):
        nc.OptimalControl(_ball("smooth"), N=4, t_final=1.0, method="contact_implicit")


@pytest.mark.parametrize("settings, match", [
    ({"sigma_final": 0.0}, r"contacts\.sigma_final: expected a finite number > 0"),
    ({"sigma0": 1e-6, "sigma_final": 1e-3}, r"contacts\.sigma_final: expected at most sigma0"),
    ({"sigma_factor": 1.5}, r"contacts\.sigma_factor: expected a number in \(0, 1\)"),
    ({"step_lengths": "adaptive"}, r"contacts\.step_lengths: expected \"equal\" or \"free\""),
    ({"step_bounds": (2.0, 3.0)}, r"contacts\.step_bounds"),
    ({"directions": 3}, r"contacts\.directions"),
    ({"sigma": 1.0}, r"contacts: unknown setting\(s\) sigma"),
    ({"step_lengths": "equal"}, r"contact\(s\) 'floor' have restitution > 0; use \"free\""),
])
def test_contact_settings_are_checked(settings, match):
    with pytest.raises(OptimizationError, match=match):
        nc.OptimalControl(_ball(), N=4, t_final=1.0, contacts=settings)


def test_problem_file_contacts_table(tmp_path):
    from ncgen.optim.problem_file import problem_from_data
    ocp, _ = problem_from_data({"horizon": {"N": 4, "t_final": 1.0}, "contacts": {"step_lengths": "free"}},
                               _ball(), "p.toml")
    assert ocp.transcription.settings["step_lengths"] == "free"
    with pytest.raises(ProblemFileError, match=r"contacts\.tol"):
        problem_from_data({"contacts": {"tol": -1.0}}, _ball(), "p.toml")


# ------------------------------------------------------------------ solved problems
def _example(name):
    import importlib.util
    from pathlib import Path
    path = Path(__file__).resolve().parent.parent / "examples" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def ball():
    ex = _example("ball_bounce_target")
    model = ex.build()
    sol = ex.problem(model).solve(ex.guess(model))
    return ex, model, sol


def test_ball_thrown_to_a_target_after_one_bounce_matches_the_closed_form(ball):
    ex, model, sol = ball
    vx, vz, t1 = ex.closed_form()
    assert np.max(np.abs(sol.v[0] - [vx, vz])) < 1e-6
    impacts = np.flatnonzero(sol.contact_impulse[:, 0] > 1e-6)
    assert impacts.size == 1                                  # one bounce
    k = int(impacts[0])
    assert abs(sol.t[k] - t1) < 1e-6
    assert sol.q[k, 1] == pytest.approx(ex.RADIUS, abs=1e-8)   # a node on the floor at the impact
    # Newton's law at the impact node: the rebound is -e times the approach
    assert sol.contact_impulse[k, 0] == pytest.approx((1 + ex.RESTITUTION) * (ex.G * t1 - vz), rel=1e-6)
    assert np.max(sol.q[:, 1]) <= ex.CEILING + 1e-8
    assert np.linalg.norm(sol.marker("ball.centre")[-1] - ex.TARGET) < 1e-8


def test_ball_optimum_is_complementary_and_replays_in_the_nonsmooth_stepper(ball):
    ex, model, sol = ball
    assert sol.complementarity_residual < 1e-6
    sim = ex.replay(model, sol)                               # steps of 0.1 ms, impact inside a step
    assert np.linalg.norm(sim.marker("ball.centre")[-1] - sol.marker("ball.centre")[-1]) < 1e-4


@pytest.fixture(scope="module")
def block():
    ex = _example("block_push")
    return ex, ex.build()


def test_block_push_sliding_throughout_matches_the_closed_form(block):
    ex, model = block
    T = 0.6                                                   # shorter than sqrt(6D/(μg)) = 0.78 s
    sol = ex.problem(model, T).solve("rest")
    push, cost = ex.closed_form(T)
    assert np.max(np.abs(sol.u[:ex.N, 0] - push)) < 1e-6 * np.max(np.abs(push))
    h = T / ex.N
    assert h * np.sum(sol.u[:ex.N, 0] ** 2) == pytest.approx(cost, rel=1e-6)
    assert cost == pytest.approx(ex.continuous_cost(T), rel=5e-3)   # the continuous optimum, O(h²) away
    assert np.allclose(sol.contact_force[:, 0], ex.MASS * ex.G, rtol=1e-6)
    assert sol.complementarity_residual < 1e-6
    sim = ex.replay(model, sol)
    assert abs(sim.q[-1, 0] - sol.q[-1, 0]) < 1e-6 and abs(sim.q[-1, 0] - ex.DISTANCE) < 1e-6


@pytest.mark.slow      # fast: test_block_push_sliding_throughout_matches_the_closed_form (the same block, a shorter horizon)
def test_block_push_over_a_long_horizon_rests_part_of_the_time(block):
    ex, model = block
    T = 1.0                                                   # longer than 0.78 s: sticking is cheaper
    sol = ex.problem(model, T).solve("rest")
    effort = T / ex.N * np.sum(sol.u[:ex.N, 0] ** 2)
    best = min(ex.closed_form(T, n)[1] for n in range(2, ex.N + 1))
    assert effort == pytest.approx(best, rel=1e-6)
    assert effort < ex.closed_form(T)[1]                      # cheaper than sliding throughout
    assert np.any(np.abs(sol.v[1:-1, 0]) < 1e-9)              # it sticks somewhere
    assert sol.complementarity_residual < 1e-6
    sim = ex.replay(model, sol)
    assert np.max(np.abs(sim.q[:, 0] - sol.q[:, 0])) < 1e-6


@pytest.mark.slow      # a second solve by nosnoc; fast: test_block_push_sliding_throughout_matches_the_closed_form
#                       (the same block against its closed form)
def test_block_push_cost_agrees_with_nosnoc(block):
    """The same push solved by nosnoc (a test-only dependency: pip install nosnoc) as a
    Filippov system with FESD: both schemes are exact for piecewise-constant accelerations."""
    pytest.importorskip("nosnoc")
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
    from contact_implicit import contact_implicit, nosnoc_push
    ex, _ = block
    ours, theirs = contact_implicit(ex, 0.6)[0], nosnoc_push(ex, 0.6)[0]
    assert abs(ours - theirs) < 1e-4


@pytest.mark.slow      # fast: test_block_push_sliding_throughout_matches_the_closed_form (the same transcription, planar)
def test_push_in_3d_on_the_polyhedral_cone_matches_the_planar_closed_form(block):
    """The push along x of a 3D block: friction on 4 cone directions (±t₁, ±t₂ of the floor),
    the same closed form as in the plane."""
    import casadi as ca
    ex, _ = block
    s = nc.System("block3d", gravity=(0, 0, -ex.G))
    b = s.add_point("block", mass=ex.MASS, position=(0, 0, 0))
    b.add_marker("centre", (0, 0, 0))
    s.add_force(nc.PointForce(b, (0, 0, 0), force=ca.vertcat(s.add_input("push"), 0, 0)))
    s.add_contact(nc.SpherePlane(b, radius=0.0, mu=ex.MU, name="floor"))
    model = s.build(contacts="nonsmooth")
    T = 0.6
    ocp = nc.OptimalControl(model, N=ex.N, t_final=T)
    assert ocp.transcription.settings["directions"] == 4
    ocp.final(marker=("block.centre", (ex.DISTANCE, 0.0, 0.0)), v=0)
    ocp.minimize_effort()
    sol = ocp.solve("rest")
    push, cost = ex.closed_form(T)
    assert np.max(np.abs(sol.u[:ex.N, 0] - push)) < 1e-6 * np.max(np.abs(push))
    assert np.max(np.abs(sol.q[:, 1:])) < 1e-8                 # no sideways drift, no lift
    assert sol.complementarity_residual < 1e-6


def test_an_optimum_above_the_complementarity_tolerance_is_refused(block):
    ex, model = block
    ocp = nc.OptimalControl(model, N=4, t_final=0.6, contacts={"sigma_final": 1e-2, "polish": False, "tol": 1e-5})
    ocp.final(marker=("block.centre", (ex.DISTANCE, 0.0)), v=0)
    ocp.minimize_effort()
    with pytest.raises(OptimizationError, match=r"complementarity residual .* exceeds contacts\.tol = 1e-05 \(worst: "):
        ocp.solve("rest")


@pytest.mark.slow      # fast: test_problem_file_contacts_table (the problem file's contacts) and
#                         test_block_push_sliding_throughout_matches_the_closed_form (the same solve)
def test_ncgen_optimize_with_nonsmooth_contacts(tmp_path, block, capsys):
    """The command line: a model file, a problem file with a [contacts] table, --contacts nonsmooth."""
    import casadi as ca
    from ncgen.cli import main
    ex, _ = block
    s = nc.System("block_push", gravity=(0, -ex.G))
    b = s.add_point("block", mass=ex.MASS, position=(0, 0))
    b.add_marker("centre", (0, 0))
    s.add_force(nc.PointForce(b, (0, 0), force=ca.vertcat(s.add_input("push"), 0)))
    s.add_contact(nc.SpherePlane(b, radius=0.0, mu=ex.MU, name="floor"))
    (tmp_path / "push.toml").write_text(s.to_toml())
    (tmp_path / "problem.toml").write_text(
        'model = "push.toml"\n[horizon]\nN = 20\nt_final = 0.6\n[final]\nv = 0\nmarkers = { "block.centre" = [0.5, 0.0] }\n'
        '[cost]\neffort = 1.0\n[contacts]\nsigma_final = 1e-6\n[solver]\nwarm_start = "rest"\n')
    out = tmp_path / "push.npz"
    assert main(["optimize", str(tmp_path / "problem.toml"), "--contacts", "nonsmooth", "-o", str(out)]) == 0
    assert "contact-implicit" in capsys.readouterr().out
    traj = nc.Trajectory.load(out)
    push, _ = ex.closed_form(0.6)
    assert np.max(np.abs(traj.u[:ex.N, 0] - push)) < 1e-6 * np.max(np.abs(push))


def test_bilateral_multipliers_of_a_bar_pushed_on_frictionless_ends():
    """A planar 'rr' bar of length L lying on the floor on its two ends (frictionless), pushed
    along its axis at its first end by u: rigid translation, m a = u, and the length
    constraint |r_j − r_i|² = L² carries λ = −u / (4 L) (from M a + Aᵀλ = F with
    M = m/6 [[2, 1], [1, 2]] ⊗ I)."""
    import casadi as ca
    L, m = 0.4, 1.5
    s = nc.System("bar_push", gravity=(0, -9.81))
    bar = s.add_bar("bar", coords="rr", mass=m, ends=[(0, 0), (L, 0)])
    bar.add_marker("mid", (0, 0))
    s.add_force(nc.PointForce(bar, (-L / 2, 0), force=ca.vertcat(s.add_input("push"), 0)))
    for name, x in (("left", -L / 2), ("right", L / 2)):
        s.add_contact(nc.SpherePlane(bar, (x, 0), radius=0.0, name=name))
    model = s.build(contacts="nonsmooth")
    assert model.nc == 1
    ocp = nc.OptimalControl(model, N=10, t_final=0.5)
    ocp.final(marker=("bar.mid", (L / 2 + 0.3, 0.0)), v=0)
    ocp.minimize_effort()
    sol = ocp.solve("rest")
    u = sol.u[:10, 0]
    assert np.max(np.abs(u)) > 1.0
    assert np.max(np.abs(sol.lam[1:, 0] + u / (4 * L))) < 1e-6 * np.max(np.abs(u))
    assert np.allclose(sol.contact_force.sum(axis=1), m * 9.81, rtol=1e-6)


@pytest.fixture(scope="module")
def hopper():
    ex = _example("hopper_gait")
    model = ex.build()
    return ex, model, ex.problem(model).solve("rest")


@pytest.mark.slow      # fast: test_block_push_sliding_throughout_matches_the_closed_form (the same transcription)
def test_hopper_finds_a_hop_from_standing(hopper):
    """From the standing guess the optimum pushes off, flies and lands: contact force in the
    first and last intervals, an interval where the foot is off the floor on both ends with
    no force, every pair complementary; in flight the foot falls under gravity and the leg
    force alone (the step is exact for constant accelerations: a closed form)."""
    ex, model, sol = hopper
    assert sol.complementarity_residual < 1e-6
    stance, flight = ex.phases(sol)
    assert stance[0] and stance[-1]
    assert flight.any()
    first, last = np.flatnonzero(flight)[[0, -1]]
    assert not stance[first:last + 1].any()                   # breaks contact, then makes it again
    gap = sol.marker("foot.centre")[:, 1] - ex.RADIUS
    assert gap.max() > 0.1 and gap.min() > -1e-9
    h = ex.T / ex.N
    y, vy = sol.marker("foot.centre")[:, 1], sol.v[:, model.coordinate_names.index("foot.r_i.y")]
    for k in np.flatnonzero(flight):
        a = -sol.u[k, 0] / ex.FOOT - ex.G
        assert y[k + 1] == pytest.approx(y[k] + h * vy[k] + h * h / 2 * a, abs=1e-9)
        assert vy[k + 1] == pytest.approx(vy[k] + h * a, abs=1e-9)
    # standing still with the body on the reference is a worse optimum (the hop is not a tie)
    assert sol.stats.objective < 0.75 * _standing_cost(ex)


@pytest.mark.slow      # fast: test_block_push_cost_agrees_with_nosnoc (the same comparison on the push)
def test_hopper_standing_optimum_agrees_with_closed_form_and_nosnoc(hopper):
    """The standing local optimum (the homotopy from σ₀ = 0.3 keeps the foot down; nosnoc's
    time-freezing hopper of benchmarks/contact_implicit.py ends there from standing): ncgen's
    cost equals the least-squares closed form, and nosnoc's (a continuous-time integral, FESD)
    agrees with both within 1e-5."""
    ex, model, _ = hopper
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
    from contact_implicit import STANDING_SIGMA0, nosnoc_hopper
    sol = ex.problem(model, contacts={"sigma0": STANDING_SIGMA0}).solve("rest")
    reference = _standing_cost(ex)
    assert sol.marker("foot.centre")[:, 1].max() - ex.RADIUS < 1e-9
    assert sol.stats.objective == pytest.approx(reference, rel=1e-9)
    pytest.importorskip("nosnoc")
    cost, *_, lift = nosnoc_hopper(ex)
    assert lift < 1e-6
    assert abs(cost - reference) < 1e-5


def _standing_cost(ex):
    """The cost of the best motion that keeps the foot on the floor: the body then follows
    ``ÿ = leg/m − g`` alone, a linear least-squares problem in the N leg forces (the foot's
    tracking error ``∫ lift² dt`` is fixed); the RATTLE step is exact for it."""
    h, n, w, e = ex.T / ex.N, ex.N, 1000.0, ex.EFFORT
    t = np.arange(n + 1) * h
    # y_k = y_0 + Σ_j c_kj a_j with a_j = leg_j/m − g; v_N = h Σ a_j = 0, y_N = y_0
    C = np.array([[h * h * (k - j - 0.5) if j < k else 0.0 for j in range(n)] for k in range(n + 1)])
    quad = np.concatenate([[h / 2], np.full(n - 1, h), [h / 2]])            # trapezoid on the nodes
    ref = ex.lift(t)
    # minimise w Σ quad (C a − ref)² + e h Σ (m (a + g))² subject to Σ a = 0, C[-1] a = 0
    Hq = 2 * (w * C.T @ np.diag(quad) @ C + e * h * ex.BODY ** 2 * np.eye(n))
    gq = -2 * (w * C.T @ (quad * ref)) + 2 * e * h * ex.BODY ** 2 * ex.G * np.ones(n)
    A = np.vstack([np.ones(n), C[-1]])
    kkt = np.block([[Hq, A.T], [A, np.zeros((2, 2))]])
    a = np.linalg.solve(kkt, np.concatenate([-gq, [0, 0]]))[:n]
    body = w * quad @ (C @ a - ref) ** 2 + e * h * np.sum((ex.BODY * (a + ex.G)) ** 2)
    return body + w * quad @ ref ** 2


@pytest.mark.slow      # fast: test_ball_optimum_is_complementary_and_replays_in_the_nonsmooth_stepper
def test_hopper_optimum_replays_in_the_nonsmooth_stepper(hopper):
    """The optimal leg force held over each step, simulated by the nonsmooth stepper at
    T/N/400: the body (driven by the leg force alone) agrees to round-off; the foot, which
    lands inside steps, to 2 mm (first order in the stepper's step: 3.6 mm at T/N/200)."""
    ex, model, sol = hopper
    sim = ex.replay(model, sol, substeps=400)
    assert np.max(np.abs(sim.marker("body.centre") - sol.marker("body.centre"))) < 1e-9
    assert np.max(np.abs(sim.marker("foot.centre") - sol.marker("foot.centre"))) < 2e-3
    assert np.max(np.abs(sim.q[-1] - sol.q[-1])) < 1e-9


@pytest.mark.parametrize("reaction_guess", [False, True])
def test_reaction_guess_puts_the_guide_reaction_in_the_half_steps(reaction_guess):
    """A 2 kg cart on a horizontal guide (its weight carried by the guide's reaction) and a
    ball resting on the floor, guessed at rest: with ``reaction_guess`` the half-steps'
    multipliers start at ν = h/2 λ, λ the static reaction (m g on the guide), and the first
    iterate's dynamics hold; without it they start at 0 and every half-step is off by the
    impulse h/2 m g the guide must carry."""
    import casadi as ca
    m, g, N, T = 2.0, 9.81, 4, 0.4
    s = nc.System("cart_ball", gravity=(0, -g))
    cart = s.add_point("cart", mass=m, position=(0, 0.5))
    s.add_joint(nc.PointOnLine(s.ground, cart, at=(0, 0.5), axis=(1, 0), name="guide"))
    s.add_force(nc.PointForce(cart, (0, 0), force=ca.vertcat(s.add_input("push"), 0)))
    ball = s.add_point("ball", mass=1.0, position=(1.0, 0.1))
    s.add_contact(nc.SpherePlane(ball, radius=0.1, name="floor"))
    model = s.build(contacts="nonsmooth")
    ocp = nc.OptimalControl(model, N=N, t_final=T, contacts={"reaction_guess": reaction_guess})
    ocp.minimize_effort()
    with pytest.raises(OptimizationError) as info:
        ocp.solve("rest", max_iter=0, diagnose=False)
    nlp = info.value.result.nlp
    half_steps = [grp for grp in nlp.groups if "half-step" in grp.label]
    assert len(half_steps) == 2 * N
    residual = ca.Function("r", [nlp.opti.x], [ca.vertcat(*[grp.expr for grp in half_steps])])
    worst = float(np.max(np.abs(np.array(residual(nlp.x_opt)))))
    expected = 0.0 if reaction_guess else T / N / 2 * m * g
    assert worst == pytest.approx(expected, abs=1e-9)
