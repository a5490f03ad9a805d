"""Step Jacobians of models with nonsmooth contacts (ncgen/control/contact_step.py): against
central differences of the step away from switches, the modes, the switch flag and its
one-sided choice, iLQR through contact replayed by the simulator, the MPC's refusal."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError, OptimizationError

QUICK_COMPILE = True             # its time is gcc compiling its scenes: -O0 (tests/conftest.py)
G, MASS, MU, H = 9.81, 2.0, 0.5, 0.01
#: Central differences stay inside the push-out's threshold (PENETRATION_TOL = 1e-8 m): a
#: resting contact pushed 1e-6 m down is pushed out, the other side is not (a switch).
EPS = 1e-9


def central(st, x, u):
    """``(A, B)`` of ``st`` by central differences of step ``EPS``."""
    cols = []
    for i in range(len(x)):
        d = np.zeros(len(x))
        d[i] = EPS
        cols.append((st(x + d, u) - st(x - d, u)) / (2 * EPS))
    A = np.column_stack(cols)
    cols = []
    for i in range(len(u)):
        d = np.zeros(len(u))
        d[i] = EPS
        cols.append((st(x, u + d) - st(x, u - d)) / (2 * EPS))
    return A, np.column_stack(cols) if cols else np.zeros((len(x), 0))


def assert_matches_differences(st, x, u, tol=1e-6):
    s = st.step(x, u)
    A, B = central(st, x, u)
    assert np.max(np.abs(s.A - A)) <= tol * max(1.0, np.max(np.abs(A)))
    if B.size:
        assert np.max(np.abs(s.B - B)) <= tol * max(1.0, np.max(np.abs(B)))
    return s


@pytest.fixture(scope="module")
def block():
    """A 2 kg block (a point) on the floor, μ = 0.5, pushed horizontally by input 0 (N) times
    the parameter ``gain`` (1 unless a test gives it)."""
    s = nc.System("cjac_block", gravity=(0, -G))
    b = s.add_point("block", mass=MASS, position=(0, 0))
    push, gain = s.add_input("push"), s.add_parameter("gain", 1.0)
    s.add_force(nc.PointForce(b, (0, 0), force=ca.vertcat(gain * push, 0)))
    s.add_contact(nc.SpherePlane(b, radius=0.0, mu=MU, name="floor"))
    model = s.build(contacts="nonsmooth")
    return model, nc.step_function(model, H)


def test_block_sticking_small_push(block):
    _, st = block
    s = assert_matches_differences(st, np.zeros(4), np.array([1.0]))
    assert s.modes == ["sticking"] and not s.at_switch and not s.impact
    assert np.allclose(s.x1, 0, atol=1e-15)
    # stuck: neither a small push nor the velocity moves it (the friction takes it up)
    assert np.max(np.abs(s.B)) < 1e-12 and np.max(np.abs(s.A[2:, 2:])) < 1e-12


def test_the_step_s_factorisations_run_on_one_blas_thread(block, monkeypatch):
    """The step's sparse LU and its solves see one BLAS thread (ncgen/blas_threads.py: the
    benchmark no longer sets OPENBLAS_NUM_THREADS); the caller's two threads are back after."""
    import threadpoolctl

    from ncgen import blas_threads
    from ncgen.control import contact_step

    _, st = block
    monkeypatch.delenv(blas_threads.ENV, raising=False)
    counts = lambda: {lib.filepath: lib.get_num_threads() for lib in blas_threads.blas_libraries()}  # noqa: E731
    seen, factor = [], contact_step._Factor

    def recording(*args, **kwargs):
        seen.append(counts())
        return factor(*args, **kwargs)

    monkeypatch.setattr(contact_step, "_Factor", recording)
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        for lib in blas_threads.blas_libraries():
            lib.set_num_threads(2)
        st.jacobians(np.array([0, 0, 0.5, 0]), np.array([20.0]))
        after = counts()
    assert seen and all(set(c.values()) == {1} for c in seen), seen
    assert set(after.values()) == {2}, after


def test_out_is_written_and_a_bad_out_is_named(block):
    """``out=`` of a call and of ``jacobians`` receives the fresh result bit for bit; a wrong
    ``out`` (shape, dtype, non-contiguous) is refused by name."""
    from ncgen.errors import ShapeError

    _, st = block
    x, u = np.array([0, 0, 0.5, 0]), np.array([20.0])
    x1, A, B = st.jacobians(x, u)
    out = np.full(4, np.nan)
    assert st(x, u, out=out) is out and np.array_equal(out, x1)
    outs = (np.empty(4), np.empty((4, 4)), np.empty((4, 1)))
    assert st.jacobians(x, u, out=outs) is outs
    assert all(np.array_equal(o, r) for o, r in zip(outs, (x1, A, B)))
    for bad in (np.empty(5), np.empty(4, dtype=np.float32), np.empty(8)[::2]):
        with pytest.raises(ShapeError, match="ContactStepFunction: out"):
            st(x, u, out=bad)
        with pytest.raises(ShapeError, match="ContactStepFunction.jacobians: out"):
            st.jacobians(x, u, out=(bad, outs[1], outs[2]))


def test_block_sliding_hard_push(block):
    _, st = block
    u = 20.0
    s = assert_matches_differences(st, np.array([0, 0, 0.5, 0]), np.array([u]))
    assert s.modes == ["sliding"] and not s.at_switch
    # closed form: x⁺ = x + h v + h²/2 a, v⁺ = v + h a, a = u/m − μ g
    a = u / MASS - MU * G
    assert np.allclose(s.x1, [H * 0.5 + H * H / 2 * a, 0, 0.5 + H * a, 0], atol=1e-13)
    assert np.allclose(s.B.ravel(), [H * H / (2 * MASS), 0, H / MASS, 0], atol=1e-13)
    assert np.isclose(s.impulses[0, 0], MASS * G * H, rtol=1e-12)           # P_N = m g h
    assert np.isclose(abs(s.impulses[0, 1]), MU * MASS * G * H, rtol=1e-12)   # |P_T| = μ P_N (against the slip)


def test_block_separated_above_the_ground(block):
    _, st = block
    x = np.array([0, 0.1, 0.3, 0.2])
    s = assert_matches_differences(st, x, np.array([1.0]))
    assert s.modes == ["separated"] and not s.at_switch
    assert np.allclose(s.x1, [0.3 * H + H * H / 2 / MASS, 0.1 + 0.2 * H - G * H * H / 2, 0.3 + H / MASS, 0.2 - G * H],
                       atol=1e-13)


def test_block_at_a_switch_is_flagged_one_sided(block):
    """Pushed by exactly μ m g from rest: stuck with the friction on the cone's boundary.  The
    derivative is the sticking side's: the backward difference, not the forward one."""
    _, st = block
    u = np.array([MU * MASS * G])
    s = st.step(np.zeros(4), u)
    assert s.at_switch and s.modes == ["sticking"]
    assert any("cone's boundary" in why for _, why in s.switches)
    assert s.switches[0][0] == "floor"
    backward = (st(np.zeros(4), u) - st(np.zeros(4), u - 1e-6)) / 1e-6
    assert np.allclose(s.B.ravel(), backward, atol=1e-9) and np.all(s.B == 0)
    # the other side slides (the stepper's cone holds to its tolerance, ~1e-8 relative: a
    # push 1e-3 N above the limit is past it); sliding is linear in the push
    forward = (st(np.zeros(4), u + 1e-3) - st(np.zeros(4), u)) / 1e-3
    assert np.allclose(forward, [H * H / (2 * MASS), 0, H / MASS, 0], rtol=1e-6)


def test_free_step_ending_on_the_surface_is_flagged(block):
    _, st = block
    s = st.step(np.array([0, G * H * H / 2, 0, 0]), np.array([0.0]))
    assert s.at_switch and any("gap at 0" in why for _, why in s.switches)


def test_bounce_impact(block):
    """A ball falling at 2 m/s reaches the floor within the step (restitution 0.6): an impact,
    its push-out in the equations; the step's ends as the simulator's."""
    s_ = nc.System("cjac_bounce", gravity=(0, -G))
    b = s_.add_point("ball", mass=0.5, position=(0, 0.05))
    push = s_.add_input("push")
    s_.add_force(nc.PointForce(b, (0, 0), force=ca.vertcat(push, 0)))
    s_.add_contact(nc.SpherePlane(b, radius=0.05, mu=0.4, restitution=0.6, name="floor"))
    model = s_.build(contacts="nonsmooth")
    st = nc.step_function(model, H)
    for vx, mode in ((1.0, "sliding"), (0.1, "sticking")):
        x = np.array([0, 0.053, vx, -2.0])
        s = assert_matches_differences(st, x, np.array([0.5]))
        assert s.impact and s.modes == [mode] and not s.at_switch
        assert s.push_out[0] > 0 and s.stepper_difference < 1e-12
        assert np.isclose(s.x1[3], 0.6 * 2.0, rtol=1e-12)    # Newton's law on the start-of-step approach speed


@pytest.mark.slow      # a sphere scene compiled; fast: test_block_sticking_small_push and
#                       test_block_sliding_hard_push (stick and slip on a plane), test_three_sphere_pile
def test_sphere_rolling_and_sliding_on_a_plane():
    """A rigid sphere (12 natural coordinates, 6 constraints) on the floor, pushed at its
    centre: it rolls (sticking) under a small push, slides under a large one."""
    s = nc.System("cjac_sphere", gravity=(0, 0, -G))
    R = 0.1
    ball = s.add_body("ball", mass=1.0, inertia=0.4 * R * R * np.eye(3), position=(0, 0, R))
    f = s.add_input("fx")
    s.add_force(nc.PointForce(ball, (0, 0, 0), force=ca.vertcat(f, 0, 0)))
    s.add_contact(nc.SpherePlane(ball, None, R, mu=0.3, name="floor"))
    model = s.build(contacts="nonsmooth")
    st = nc.step_function(model, 0.005)
    x = np.concatenate([model.q0, np.zeros(model.nq)])
    rolling = assert_matches_differences(st, x, np.array([1.0]))
    sliding = assert_matches_differences(st, x, np.array([30.0]))
    assert rolling.modes == ["sticking"] and sliding.modes == ["sliding"]
    # rolling from rest under F: the centre's acceleration 5F/(7m) (the sphere's closed form),
    # to the scheme's O(h) (the friction impulse of a step): dv/du = 5h/(7m)
    i = model.nq                    # the centre's x rate (the body's first coordinate)
    assert np.isclose(rolling.B[i, 0], 5 * 0.005 / 7, rtol=1e-9)


R3, H3 = 0.05, 0.002


@pytest.fixture(scope="module")
def three_spheres():
    """Three 0.3 kg spheres (r = 5 cm) with floor and pair contacts (μ = 0.5), their step
    function at 2 ms and its all-contacts reference: one model for the resting pile and the
    dropped column (their initial positions given to ``simulate``)."""
    s = nc.System("cjac_pile3", gravity=(0, 0, -G))
    balls = [s.add_point(f"b{k}", mass=0.3, position=(0.01 * k, 0.005 * k, R3 + 2 * R3 * k)) for k in range(3)]
    for k, b in enumerate(balls):
        s.add_contact(nc.SpherePlane(b, None, R3, mu=0.5, name=f"floor{k}"))
    for i in range(3):
        for j in range(i + 1, 3):
            s.add_contact(nc.SphereSphere(balls[i], None, R3, balls[j], None, R3, mu=0.5, name=f"pair{i}{j}"))
    model = s.build(contacts="nonsmooth")
    return model, nc.step_function(model, H3), all_contacts(model, H3)


def test_three_sphere_pile(three_spheres):
    """Three spheres resting in a pile (settled by the simulator): contacts on the floor and
    between the spheres sticking, the rest separated."""
    model, st, reference = three_spheres
    traj = nc.simulate(model, 0.2, H3, method="stepper")
    x = np.concatenate([traj.q[-1], traj.v[-1]])
    s_ = assert_matches_differences(st, x, np.zeros(0))
    assert s_.modes == ["sticking", "separated", "separated", "sticking", "separated", "sticking"]
    assert not s_.at_switch
    assert_equals_all_contacts(reference, st, x, np.zeros(0))


def all_contacts(model, h):
    """The step function of the all-contacts equations (one function of every contact, the
    modes as selectors): the reference of the active-contact ones (the default)."""
    from ncgen.control.contact_step import ContactStepFunction
    return ContactStepFunction(model, h, max_iter=20, abstol=1e-12, equations="all")


def assert_equals_all_contacts(reference, st, x, u, tol=1e-8):
    """``st`` (the active-contact equations) gives ``reference``'s step at ``x``."""
    assert st.evaluation == "active" and reference.equations == "all"
    ref = reference.step(x, u)
    s = st.step(x, u)
    assert s.modes == ref.modes and s.impact == ref.impact and s.switches == ref.switches
    assert np.max(np.abs(s.x1 - ref.x1)) <= tol * max(1.0, np.max(np.abs(ref.x1)))
    for a, b in ((s.A, ref.A), (s.B, ref.B), (s.impulses, ref.impulses)):
        assert np.max(np.abs(a - b), initial=0.0) <= tol * max(1.0, np.max(np.abs(b), initial=0.0))
    return s


@pytest.fixture(scope="module")
def heap20():
    """The 20-sphere heap of benchmarks/contact_step_jacobians.py (210 contacts), its step
    function at 1 ms and its all-contacts reference."""
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from contact import heap
    model = heap(20, rotating=False)
    return model, nc.step_function(model, 1e-3), all_contacts(model, 1e-3)


@pytest.mark.slow       # the heap's packages: compiled for minutes
def test_heap_of_twenty_active_equals_all_contacts(heap20):
    """The benchmark's settled 20-sphere heap (benchmarks/contact_step_jacobians.py): 20 of 210
    contacts closed; the active-contact step equals the all-contacts one (1e-8).  Not against
    central differences: touching pairs keep their free-step gap at 0 (the step is flagged at a
    switch), and a perturbation of 1e-9 m closes them."""
    model, st, reference = heap20
    traj = nc.simulate(model, 0.5, 0.5, method="stepper", substeps=500)
    x = np.concatenate([traj.q[-1], traj.v[-1]])
    s = assert_equals_all_contacts(reference, st, x, np.zeros(0))
    assert s.modes.count("sticking") == 20 and s.modes.count("separated") == 190
    assert s.at_switch and any(why == "the free step ends with the gap at 0" for _, why in s.switches)


@pytest.mark.slow       # the heap's packages: compiled for minutes
@pytest.mark.parametrize("landed", ["sticking", "sliding"])
def test_heap_of_twenty_landing_against_central_differences(heap20, landed):
    """The heap 64 ms after its release (its own simulator): four spheres landed on the floor,
    sixteen in flight, no contact at a switch; as simulated (the landed ones sticking), and with
    the landed ones given 0.2 m/s along the floor (sliding).  The Jacobian of the active-contact
    equations (the default) equals central differences (1e-6) and the all-contacts equations'
    (1e-12)."""
    model, st, reference = heap20
    traj = nc.simulate(model, 0.064, 0.064, method="stepper", substeps=64)
    x, nq = np.concatenate([traj.q[-1], traj.v[-1]]), model.nq
    on_floor = [k for k in range(model.nk) if st.step(x, np.zeros(0)).modes[k] != "separated"]
    assert on_floor == [0, 1, 2, 3]            # the floor contacts of the first four spheres
    if landed == "sliding":
        for k in on_floor:
            x[nq + 3 * k:nq + 3 * k + 2] = 0.2 * np.cos(k), 0.2 * np.sin(k)
    s = assert_matches_differences(st, x, np.zeros(0))
    assert [s.modes[k] for k in on_floor] == [landed] * 4 and s.modes.count("separated") == model.nk - 4
    assert not s.at_switch and not s.impact and not s.push_out.any()
    assert_equals_all_contacts(reference, st, x, np.zeros(0), tol=1e-12)


@pytest.mark.slow      # an iLQR solve through the contact step; fast: the block's step Jacobians above,
#                       tests/test_control_ilqr.py (iLQR's gradient and curvature)
def test_ilqr_pushes_the_block_to_its_target(block):
    """iLQR through the contact steps: the block pushed from rest to x = 0.5 m at rest in
    0.8 s with the least effort (soft terminal penalty); replayed by the simulator."""
    model, st = block
    N, D = 80, 0.5
    res = nc.ilqr(st, np.zeros(4), 15 * np.ones((N, 1)),
                  (lambda x, u: 1e-2 * H * ca.sumsqr(u), lambda x: 1e3 * ((x[0] - D) ** 2 + x[2] ** 2)),
                  max_iter=50, tol=1e-6)
    assert res.converged
    assert abs(res.X[-1, 0] - D) < 2e-3 and abs(res.X[-1, 2]) < 1e-3
    modes = [st.step(res.X[k], res.U[k]).modes[0] for k in range(N)]
    assert "sliding" in modes
    traj = nc.simulate(model, N * H, H, u=res.U, hold="zoh", method="stepper", substeps=1)
    assert np.max(np.abs(np.column_stack([traj.q, traj.v]) - res.X)) < 1e-9


def test_mpc_refuses_nonsmooth_contacts_by_name(block):
    model, _ = block
    ocp = nc.OptimalControl(model, N=10, t_final=0.2)
    ocp.minimize_effort()
    with pytest.raises(OptimizationError, match="nonsmooth contacts \\('floor'\\)"):
        nc.MPC(ocp)


def test_tables_kernels_refused(block):
    model, _ = block
    with pytest.raises(NcgenError, match="nonsmooth contacts"):
        nc.step_function(model, H, kernels="tables")


def test_parameter_jacobian_sliding(block):
    """``C = ∂x⁺/∂p``: the push scaled by the parameter ``gain``; sliding, ∂v⁺/∂gain = h u/m."""
    _, st = block
    x, u, p = np.array([0, 0, 0.5, 0]), np.array([20.0]), np.array([1.2])
    x1, A, B, C = st.jacobians(x, u, p, parameters=True)
    central_p = (st(x, u, p + EPS) - st(x, u, p - EPS)) / (2 * EPS)
    assert np.allclose(C.ravel(), central_p, atol=1e-6 * max(1.0, np.max(np.abs(central_p))))
    assert np.isclose(C[2, 0], H * 20.0 / MASS, rtol=1e-12) and st.last.modes == ["sliding"]


@pytest.mark.slow      # every step of a dropped pile; fast: test_three_sphere_pile (the same model)
def test_dropped_pile_every_step(three_spheres):
    """Three spheres dropped in a column (gaps 1 cm, e = 0): every step of the simulator's
    run has Jacobians, its state equals the simulator's next one (1e-8), and at impacts away
    from switches the Jacobians equal central differences."""
    model, st, reference = three_spheres
    h = H3
    q0 = np.concatenate([(0.01 * k, 0.005 * k, R3 + 0.01 + (2 * R3 + 0.01) * k) for k in range(3)])
    traj = nc.simulate(model, 0.4, h, method="stepper", q0=q0)
    assert np.array_equal(traj.q[0], q0)
    X = np.column_stack([traj.q, traj.v])
    checked = compared = 0
    for k in range(len(X) - 1):
        step = st.step(X[k], np.zeros(0))
        assert np.max(np.abs(step.x1 - X[k + 1])) < 1e-8
        if step.impact and not step.at_switch and checked < 2:
            assert_matches_differences(st, X[k], np.zeros(0))
            checked += 1
        if k % 20 == 0 and not step.push_out.any():   # a push-out's step is the all-contacts equations'
            assert_equals_all_contacts(reference, st, X[k], np.zeros(0))
            compared += 1
    assert checked == 2 and compared >= 5


def test_virtual_machine_path_equals_compiled(block, monkeypatch):
    """The all-contacts equations above COMPILE_MAX_INSTRUCTIONS run on CasADi's VM: the same
    step as compiled, and as the active-contact equations (the default)."""
    import ncgen.control.contact_step as contact_step
    model, st = block
    compiled = contact_step.ContactStepFunction(model, H, max_iter=20, abstol=1e-12, equations="all")
    monkeypatch.setattr(contact_step, "COMPILE_MAX_INSTRUCTIONS", 0)
    vm = contact_step.ContactStepFunction(model, H, max_iter=20, abstol=1e-12, equations="all")
    assert vm.evaluation == "casadi-vm" and compiled.evaluation == "compiled" and st.evaluation == "active"
    x, u = np.array([0, 0, 0.5, 0]), np.array([20.0])
    a, b, c = vm.step(x, u), compiled.step(x, u), st.step(x, u)
    assert a.modes == b.modes == c.modes and np.allclose(a.x1, b.x1, atol=1e-15) and np.allclose(c.x1, b.x1, atol=1e-15)
    for s in (a, c):
        assert np.allclose(s.A, b.A, atol=1e-12) and np.allclose(s.B, b.B, atol=1e-12)


def test_equations_option_checked(block):
    model, _ = block
    from ncgen.control.contact_step import ContactStepFunction
    with pytest.raises(NcgenError, match="equations: expected one of 'active', 'all', got 'some'"):
        ContactStepFunction(model, H, max_iter=20, abstol=1e-12, equations="some")


@pytest.mark.slow      # a box scene of its own compiled; fast: test_block_sticking_small_push and
#                       test_block_at_a_switch_is_flagged_one_sided (the block's corners on the floor)
def test_box_standing_on_two_corners():
    """A planar box resting on two corners (redundant sticking contacts: the stepper takes the
    least-norm impulses of their family; R_Z is singular, solved least-norm).  Along the
    states a motion can have (the tangent space of both constraint levels) its Jacobians equal
    central differences; off it, the stepper's own redundant impulses jump (not checked)."""
    from scipy.linalg import null_space
    s = nc.System("cjac_box2d", gravity=(0, -G))
    a, b = 0.2, 0.1
    box = s.add_body("box", "ruv", mass=1.0, inertia=(a * a + b * b) / 12, position=(0, b / 2))
    f = s.add_input("f")
    s.add_force(nc.PointForce(box, (0, 0), force=ca.vertcat(f, 0)))
    s.add_contact(nc.BoxPlane(box, size=(a, b), mu=MU, name="floor"))
    model = s.build(contacts="nonsmooth")
    st = nc.step_function(model, 0.005)
    x, u = np.concatenate([model.q0, np.zeros(model.nq)]), np.array([1.0])
    step = st.step(x, u)
    assert step.modes == ["sticking", "sticking", "separated", "separated"]
    N = null_space(np.array(model.functions["A"](0, model.q0, model.p0)))
    T = np.block([[N, np.zeros_like(N)], [np.zeros_like(N), N]])       # v = 0: A v's q-derivative is 0
    fd_T = np.column_stack([(st(x + EPS * c, u) - st(x - EPS * c, u)) / (2 * EPS) for c in T.T])
    assert np.max(np.abs(step.A @ T - fd_T)) <= 1e-6 * max(1.0, np.max(np.abs(fd_T)))
    _, B = central(st, x, u)
    assert np.max(np.abs(step.B - B)) <= 1e-6 * max(1.0, np.max(np.abs(B)))
    assert np.max(np.abs(step.B)) < 1e-12          # stuck: a small push does not move it


@pytest.mark.slow      # a scene of its own compiled; fast: test_block_sticking_small_push, test_bounce_impact
def test_frictionless_contact_closed():
    """A frictionless block on the floor pushed sideways: mode ``"closed"``, no friction, so
    ``B = [h²/2m, 0, h/m, 0]`` and ``P_N = m g h``; the active-contact equations equal the
    all-contacts ones and central differences."""
    s = nc.System("cjac_slick", gravity=(0, -G))
    b = s.add_point("block", mass=MASS, position=(0, 0))
    push = s.add_input("push")
    s.add_force(nc.PointForce(b, (0, 0), force=ca.vertcat(push, 0)))
    s.add_contact(nc.SpherePlane(b, radius=0.0, mu=0.0, name="floor"))
    model = s.build(contacts="nonsmooth")
    st = nc.step_function(model, H)
    x, u = np.array([0, 0, 0.3, 0]), np.array([2.0])
    step = assert_matches_differences(st, x, u)
    assert step.modes == ["closed"] and not step.at_switch
    assert np.allclose(step.B.ravel(), [H * H / (2 * MASS), 0, H / MASS, 0], atol=1e-13)
    assert np.isclose(step.impulses[0, 0], MASS * G * H, rtol=1e-12) and step.impulses[0, 1] == 0
    assert_equals_all_contacts(all_contacts(model, H), st, x, u)
