"""``nc.MPC(ocp, solver="fatrop")`` on the cart-pole (examples/cartpole_mpc.toml).

The natural form (``fatrop_form="natural"``: the SQP's own discrete problem, ncgen.control.mpc_fatrop)
reaches the optimum the converged SQP reaches (first input and cost, the cost and
infeasibility evaluated by the SQP's own compiled merit function) and its closed loop is the
converged SQP's.  The joint form (the default on this tree, ncgen.control.mpc_fatrop_joint):
its step against the natural-coordinate model stepped finely (RATTLE at h/400), its solution
against IPOPT's of the same NLP (from a cold start), at the states of its own closed loop too,
its closed loop within the discretisation's difference of the SQP's.  Both: inputs within
their bounds, a warm start takes fewer interior-point iterations than a cold one, a failed
solve keeps the guess, and bad solver names, forms and Fatrop options are refused by name."""
from __future__ import annotations

import numpy as np
import pytest

import ncgen as nc
from ncgen.control.export import closed_loop
from ncgen.errors import OptimizationError

from cartpole_mpc import EXAMPLES, PUSH, cartpole_problem, tilted

QUICK_COMPILE = True             # the cart-pole MPC's packages at -O0 in both tiers, as in the other MPC modules and
#                                 benchmarks/control.py's smoke, which share them through the compile cache (tests/conftest.py)
# the tests that compare with the SQP are slow: its MPC compiles the horizon's step derivatives
# (minutes on a cold cache)


@pytest.fixture(scope="module")
def ocp():
    return cartpole_problem()


@pytest.fixture(scope="module")
def fatrop(ocp):
    return nc.MPC(ocp, "fatrop", terminal_weight=100.0, fatrop_form="natural")


@pytest.fixture(scope="module")
def joint(ocp):
    return nc.MPC(ocp, "fatrop", terminal_weight=100.0)


@pytest.fixture(scope="module")
def sqp(ocp):
    return nc.MPC(ocp, terminal_weight=100.0, iterations=10)


@pytest.mark.parametrize("bad", ["ipopt", "SQP", "", None, 3])
def test_bad_solver_names_are_refused_with_the_valid_ones(ocp, bad):
    with pytest.raises(OptimizationError, match=r"MPC: solver: expected one of sqp, fatrop, got "):
        nc.MPC(ocp, bad)


@pytest.mark.parametrize("options, match", [({"no_such_option": 1}, "not supported: no_such_option"),
                                            ({"tolerance": "tight"}, "type mismatch"),
                                            (["tolerance", 1e-8], "expected a dict")])
def test_bad_fatrop_options_are_refused_at_construction(ocp, options, match):
    with pytest.raises(OptimizationError, match=f"fatrop_options.*{match}"):
        nc.MPC(ocp, "fatrop", fatrop_options=options)


@pytest.mark.parametrize("angle, cart", [(0.2, 0.0), (-0.3, 0.5)])
@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_fatrop_reaches_the_converged_sqp_optimum(fatrop, sqp, angle, cart):
    x = tilted(angle, cart)
    sqp.reset(x, 0.0, iterations=3)                     # 30 SQP iterations
    assert sqp.qp_status[-1] == 0
    fatrop.reset(x, 0.0, iterations=1)
    assert fatrop.fatrop.status and all(s == "0" for s in fatrop.fatrop.status), fatrop.fatrop.status
    u_f, u_s = fatrop.U[0], sqp.U[0]
    assert abs(u_f[0]) > 1.0 and abs(u_f[0] - u_s[0]) <= 1e-6 * max(1.0, abs(u_s[0])), (u_f, u_s)
    J_s, c_s = sqp._merit(x, 0.0, sqp.X, sqp.U)
    J_f, c_f = sqp._merit(x, 0.0, fatrop.X, fatrop.U)    # Fatrop's solution through the SQP's C
    assert c_s < 1e-8 and c_f < 1e-7, (c_s, c_f)
    assert abs(J_f - J_s) <= 1e-6 * J_s, (J_f, J_s)
    assert np.max(np.abs(fatrop.U - sqp.U)) <= 1e-5 * max(1.0, np.max(np.abs(sqp.U)))


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_closed_loop_is_the_converged_sqp_loop(ocp, fatrop, sqp):
    plant = nc.step_function(ocp.model, fatrop.h / 5, kernels="flat")
    x0 = tilted(0.2)
    T, U_f, X_f = closed_loop(fatrop, x0, 4.0, disturbance=PUSH, plant=plant)
    assert all(s == "0" for s in fatrop.fatrop.status)
    _, U_s, X_s = closed_loop(sqp, x0, 4.0, disturbance=PUSH, plant=plant)
    assert np.max(np.abs(U_f)) > 5.0 and np.all(np.abs(U_f) <= 20.0)
    assert np.max(np.abs(U_f - U_s)) <= 1e-5 * np.max(np.abs(U_s)), np.max(np.abs(U_f - U_s))
    assert np.max(np.abs(X_f - X_s)) <= 2e-6, np.max(np.abs(X_f - X_s))
    assert abs(X_f[-1, 0]) < 2e-3 and np.linalg.norm(X_f[-1, 6:8] - [0.0, 0.5]) < 2e-3


@pytest.mark.parametrize("form", ["joint", pytest.param("natural", marks=pytest.mark.slow)])
@pytest.mark.timeout(1800)
def test_swings_up_from_the_documented_start_with_inputs_within_the_bounds(ocp, form, request):
    """From the model's start (the pole hanging 0.3 rad off the downward vertical) the push
    saturates at the ±20 N bound (Fatrop's relaxed bound clipped), the cart stays within its
    ±1.5 m and the pole ends upright."""
    mpc = request.getfixturevalue("joint" if form == "joint" else "fatrop")
    model = ocp.model
    plant = nc.step_function(model, mpc.h / 5, kernels="flat")
    _, U, X = closed_loop(mpc, np.concatenate([model.q0, model.v0]), 4.0, plant=plant)
    assert np.all(np.abs(U) <= 20.0) and np.any(np.abs(U) == 20.0)
    assert np.all(np.abs(X[:, 0]) <= 1.5)
    assert abs(X[-1, 0]) < 2e-3 and np.linalg.norm(X[-1, 6:8] - [0.0, 0.5]) < 2e-3, X[-1]


@pytest.mark.parametrize("form", ["joint", pytest.param("natural", marks=pytest.mark.slow)])
def test_warm_start_takes_fewer_iterations_than_a_cold_start(form, request):
    mpc = request.getfixturevalue("joint" if form == "joint" else "fatrop")
    x = tilted(0.25)
    mpc.reset(x, 0.0, iterations=1)
    cold = mpc.fatrop.iteration_counts[-1]
    X = mpc.X
    mpc(x, 0.0)                                          # from the reset's solution
    again = mpc.fatrop.iteration_counts[-1]
    mpc(X[1], mpc.h)                                     # the predicted next state, the shifted guess
    shifted = mpc.fatrop.iteration_counts[-1]
    assert again < cold and shifted < cold, (cold, again, shifted)


@pytest.mark.parametrize("form", ["joint", pytest.param("natural", marks=pytest.mark.slow)])
def test_a_failed_solve_keeps_the_guess(ocp, form):
    mpc = nc.MPC(ocp, "fatrop", terminal_weight=100.0, fatrop_options={"max_iter": 1}, fatrop_form=form)
    x = tilted(0.2)
    mpc.reset(x, 0.0)
    X, U = mpc.X.copy(), mpc.U.copy()
    u = mpc(x, 0.0)
    assert len(mpc.fatrop.status) == 1 and mpc.fatrop.status[0] != "0"         # not converged
    assert np.array_equal(u, U[0]) and np.array_equal(mpc.solution[0], X) and np.array_equal(mpc.solution[1], U)


def test_controllers_of_one_problem_solve_side_by_side_and_give_their_solver_memory_back(ocp, joint):
    """A second joint-form MPC of the same problem in the process (its compiled solver's one
    memory slot was taken: the first solve segfaulted) answers as the first; the solver has
    :data:`~ncgen.control.compiled_nlp.SLOTS` slots, one more caller is refused by name, and a
    slot comes back when its holder goes."""
    import gc

    from ncgen.control.compiled_nlp import SLOTS
    from ncgen.errors import CodegenError
    other = nc.MPC(ocp, "fatrop", terminal_weight=100.0)
    x = tilted(0.2)
    joint.reset(x, 0.0)
    other.reset(x, 0.0)
    assert np.array_equal(other(x, 0.0), joint(x, 0.0)) and other.fatrop.status == joint.fatrop.status == ["0"]
    held = [joint.fatrop._compiled.copy() for _ in range(SLOTS - 2)]
    with pytest.raises(CodegenError, match=r"cartpole_fatrop_solver: no free memory slot in "
                                           r"libcartpole_fatrop_solver.so \(its C has CASADI_MAX_NUM_THREADS"):
        joint.fatrop._compiled.copy()
    del other
    gc.collect()
    held.append(joint.fatrop._compiled.copy())
    x1 = tilted(0.1)
    joint.reset(x1, 0.0)
    assert np.all(np.isfinite(joint(x1, 0.0))) and joint.fatrop.status == ["0"]


def test_the_joint_form_is_the_default_on_a_tree(joint):
    """4 states (the cart's slide and the hinge's angle, their rates) and 1 control a stage."""
    fp = joint.fatrop.nlp
    assert joint.fatrop.form == fp.form == "joint" and "joint form" in repr(joint)
    assert [len(i) for i in fp.state] == [4] * 21 and [len(i) for i in fp.input] == [1] * 20 and not fp.unknowns


@pytest.mark.parametrize("form, match", [
    ("Joint", r"MPC: fatrop_form: expected one of joint, natural or None .*, got 'Joint'"),
    (3, r"MPC: fatrop_form: expected one of joint, natural or None .*, got 3")])
def test_bad_fatrop_forms_are_refused_by_name(ocp, form, match):
    with pytest.raises(OptimizationError, match=match):
        nc.MPC(ocp, "fatrop", fatrop_form=form)


def test_a_fatrop_form_without_fatrop_is_refused(ocp):
    with pytest.raises(OptimizationError, match=r"MPC: fatrop_form: the stage-wise form of solver='fatrop', "
                                                r"got fatrop_form='joint' with solver='sqp'"):
        nc.MPC(ocp, fatrop_form="joint")


def test_the_joint_form_of_a_closed_loop_is_refused_by_name():
    """The four-bar is no tree: ``fatrop_form="joint"`` is refused naming the model and why;
    by default the natural form is chosen."""
    from ncgen.control.mpc_fatrop import choose_form
    model = nc.System.from_toml(EXAMPLES / "fourbar_planar.toml").build()
    with pytest.raises(OptimizationError, match=rf"fatrop_form='joint': model {model.name!r}: .*; use "
                                                r"fatrop_form='natural'"):
        choose_form(model, "joint")
    assert choose_form(model, None) == "natural"


@pytest.mark.parametrize("u", [0.0, 15.0])
def test_the_joint_step_follows_the_natural_coordinate_model(ocp, u):
    """One explicit midpoint step of h = 0.05 s in joint space against the natural-coordinate
    model (RATTLE, its constraints solved by Newton) stepped 400 times over the same interval:
    a second-order step's local error (measured 4.0e-3 and 1.2e-2, m or m/s), about 4 times
    smaller for two steps of h/2 (third order locally: 2 (h/2)³ = h³/4; measured 3.7;
    semi-implicit Euler's would halve)."""
    from ncgen.control.mpc_fatrop_joint import joint_step_function, natural_state_function
    model, h = ocp.model, 0.05
    T = natural_state_function(model)
    xj = np.array([0.2, 2.5, 1.5, -3.0])                 # moving, the pole 2.5 rad from the upright
    fine = nc.step_function(model, h / 400, kernels="flat")
    x = np.array(T(xj)).ravel()
    for k in range(400):
        x = fine(x, [u], model.p0, k * h / 400)
    one = np.array(T(joint_step_function(model, h)(xj, u, model.p0, 0.0))).ravel()
    half = joint_step_function(model, h / 2)
    two = np.array(T(half(half(xj, u, model.p0, 0.0), u, model.p0, h / 2))).ravel()
    e1, e2 = np.abs(one - x).max(), np.abs(two - x).max()
    assert e1 < 3e-2 and e2 < e1 / 3, (e1, e2)


def ipopt_solution(mpc, x, t=0.0):
    """IPOPT on the joint form's NLP (the same problem), from the state held with zero input."""
    import casadi as ca
    from ncgen.control.mpc_fatrop import pack, unpack
    fp = mpc.fatrop.nlp
    solver = ca.nlpsol("ipopt_joint", "ipopt", fp.nlp, {"print_time": False, "ipopt.print_level": 0,
                                                        "ipopt.tol": 1e-12, "ipopt.sb": "yes"})
    xj = mpc.fatrop.guess(np.tile(x, (mpc.N + 1, 1)))
    r = solver(x0=pack(fp, xj, np.zeros((mpc.N, 1))), p=np.append(xj[0], t), lbx=fp.lbx, ubx=fp.ubx,
               lbg=fp.lbg, ubg=fp.ubg)
    assert solver.stats()["success"], solver.stats()["return_status"]
    return unpack(fp, np.array(r["x"]).ravel())[:2], float(r["f"])


@pytest.mark.parametrize("angle, cart", [(0.2, 0.0), (-0.3, 0.5), (np.pi - 0.3, 0.0)])
def test_the_joint_form_reaches_the_ipopt_optimum(joint, angle, cart):
    """Fatrop's solution (reset, from the state held) and IPOPT's of the same NLP, both cold:
    the same inputs and states to 1e-6, the same cost."""
    x = tilted(angle, cart)
    joint.reset(x, 0.0, iterations=1)
    assert joint.fatrop.status == ["0"]
    (Xj, U), J = ipopt_solution(joint, x)
    assert np.max(np.abs(joint.U - U)) <= 1e-6 * max(1.0, np.max(np.abs(U))), np.max(np.abs(joint.U - U))
    assert np.max(np.abs(joint.Z - Xj)) <= 1e-6, np.max(np.abs(joint.Z - Xj))
    fp = joint.fatrop.nlp
    import casadi as ca
    cost = ca.Function("J", [fp.nlp["x"], fp.nlp["p"]], [fp.nlp["f"]])
    from ncgen.control.mpc_fatrop import pack
    J_f = float(cost(pack(fp, joint.Z, joint.U), np.append(joint.Z[0], 0.0)))
    assert abs(J_f - J) <= 1e-8 * max(1.0, J), (J_f, J)


def test_the_joint_closed_loop_answers_the_ipopt_optimum_with_inputs_within_bounds(ocp, joint):
    """The closed loop from the pole 0.2 rad off upright with an 8 N push at 1 s (one Fatrop
    solve a step from the shifted solution): every solve succeeds, every input is within
    ±20 N, and at every 8th state the input is IPOPT's first input of the same horizon problem
    solved cold there (to 1e-6)."""
    plant = nc.step_function(ocp.model, joint.h / 5, kernels="flat")
    T, U, X = closed_loop(joint, tilted(0.2), 4.0, disturbance=PUSH, plant=plant, warmup=1)
    assert np.max(np.abs(U)) > 5.0 and np.all(np.abs(U) <= 20.0)
    for k in range(0, len(T), 8):
        (_, U_ip), _ = ipopt_solution(joint, X[k], T[k])
        assert abs(U[k, 0] - U_ip[0, 0]) <= 1e-6 * max(1.0, abs(U_ip[0, 0])), (k, U[k], U_ip[0])
    assert abs(X[-1, 0]) < 2e-3 and np.linalg.norm(X[-1, 6:8] - [0.0, 0.5]) < 2e-3


@pytest.mark.slow
@pytest.mark.timeout(1800)
@pytest.mark.parametrize("start", ["tilted", "documented"])
def test_the_joint_closed_loop_is_within_the_discretisation_of_the_sqp_loop(ocp, joint, sqp, start):
    """Not the same discrete problem (midpoint in joint space against RATTLE in natural
    coordinates, h = 0.05 s): the closed loops' costs Σ ℓ(x_k, u_k) agree to 1 %
    (measured: 0.17 % and 0.77 % lower with the joint form), the tilted loop's inputs to 0.5 N."""
    import casadi as ca
    plant = nc.step_function(ocp.model, joint.h / 5, kernels="flat")
    x0, push = (tilted(0.2), PUSH) if start == "tilted" else (np.concatenate([ocp.model.q0, ocp.model.v0]), [])
    _, U_j, X_j = closed_loop(joint, x0, 4.0, disturbance=push, plant=plant)
    _, U_s, X_s = closed_loop(sqp, x0, 4.0, disturbance=push, plant=plant)
    x, u = ca.SX.sym("x", 16), ca.SX.sym("u", 1)
    stage = ca.Function("stage", [x, u], [sqp.problem.stage(x, u)]).map(len(U_j))
    J_j, J_s = (float(np.sum(np.array(stage(X.T, U.T)))) for X, U in ((X_j, U_j), (X_s, U_s)))
    assert abs(J_j / J_s - 1.0) <= 0.01, (J_j, J_s)
    if start == "tilted":
        assert np.max(np.abs(U_j - U_s)) <= 0.5, np.max(np.abs(U_j - U_s))
