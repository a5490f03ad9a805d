"""The MPC's QP blocks return the guess's merit (cost ``J``, infeasibility ``c``, largest step
residual) from the steps they linearise, in place of a separate merit call at every SQP
iteration (issue 37): their values equal the merit function's, whose steps are solved by
another Newton scheme (the staged RATTLE solve of :func:`ncgen.control.discrete.step_functions`
against the whole-residual rootfinder of the step Jacobians), to round-off, at a guess with
shooting gaps, a state bound violated and (with ``min_tension``) a slack cable; and ``c`` is
the sum of its terms evaluated by hand from the merit's own steps.  The blocks (built from one
interval's kernel per interval) equal central-difference step Jacobians and the whole
horizon's cost Hessian; the QP condensed from them by the controller's C (``ncgen_condense.h``,
the one condensing of every loop and option) equals the horizon's Gauss–Newton QP condensed
densely here, in NumPy."""
from __future__ import annotations

import numpy as np
import pytest

import ncgen as nc
from ncgen.control.discrete import step_functions
from ncgen.control.mpc import merit_function, mpc_functions
from ncgen.control.mpc_problem import mpc_problem

N, H = 3, 0.02
K, C, MASS = 200.0, 5.0, 1.0


def hanging():
    """A point mass hanging from the ground by a cable whose rest length is the input."""
    s = nc.System("hang", gravity=(0, 0, -9.81))
    p = s.add_point("p", mass=MASS, position=(0, 0, -1.0))
    u = s.add_input("l0", 1)
    s.add_force(nc.Spring(s.ground, (0, 0, 0), p, (0, 0, 0), k=K, rest_length=u[0], damping=C, cable=True,
                          name="c"))
    return s.build()


@pytest.fixture(scope="module")
def model():
    return hanging()


def ocp_of(model):
    ocp = nc.OptimalControl(model, N=N, t_final=N * H)
    ocp.bound_input("l0", 0.5, 1.5)
    ocp.bound_coordinate(model.coordinate_names[2], -1.2, -0.99)      # the height: violated by the guess below
    ocp.minimize_effort(1e-3)
    ocp.final(q=[0, 0, -0.95], v=[0, 0, 0])
    return ocp


def problem_of(model, min_tension):
    return mpc_problem(ocp_of(model), 1e3, min_tension=min_tension)


@pytest.mark.parametrize("min_tension", [None, 50.0])
def test_qp_blocks_return_the_merit_of_their_guess(model, min_tension):
    problem = problem_of(model, min_tension)
    data = mpc_functions(model, problem)[0]
    assert data.name() == "mpc_qp_blocks"
    merit = merit_function(model, problem)
    rng = np.random.default_rng(3)
    x = np.array([0.01, -0.02, -0.97, 0.1, 0.0, 0.4])
    X = x + 0.02 * rng.normal(size=(N + 1, 6))
    U = 0.9 + 0.05 * rng.normal(size=(N, 1))
    out = dict(zip(data.name_out(), data(x, 0.1, X.T, U.T)))
    J, c, res = (float(o) for o in merit(x, 0.1, X.T, U.T))
    assert out["res"] < 1e-10 and res < 1e-10
    assert abs(float(out["J"]) - J) <= 1e-12 * abs(J)
    assert abs(float(out["c"]) - c) <= 1e-12 * c
    # c by hand: the gaps of the merit's own steps, the height's bound, the cable's pull at both ends
    step = step_functions(model, H)["step"]
    X1 = np.array([np.array(step(X[k], U[k], problem.p, 0.1 + k * H)[0]).ravel() for k in range(N)])
    by_hand = np.abs(x - X[0]).sum() + np.abs(X1 - X[1:]).sum()
    by_hand += np.maximum(0, X[1:, 2] - (-0.99)).sum() + np.maximum(0, -1.2 - X[1:, 2]).sum()
    if min_tension is not None:
        def pull(q, w, u):                      # at the step's force evaluations: q_k, q_k+1 with w_k
            return K * (np.linalg.norm(q) - u) + C * q @ w / np.linalg.norm(q)
        by_hand += sum(max(0.0, min_tension - pull(X[j, :3], (X[k + 1, :3] - X[k, :3]) / H, U[k, 0]))
                       for k in range(N) for j in (k, k + 1))
    assert np.max(X[1:, 2]) > -0.99 and (min_tension is None or by_hand > np.abs(X1 - X[1:]).sum() + 1e-3)
    assert abs(float(out["c"]) - by_hand) <= 1e-12 * by_hand


def step_jacobians_by_differences(model, problem, t, X, U):
    """``(A, B)``: the step Jacobians at the nodes by central differences of the merit's own
    step (another Newton scheme than the QP blocks'), and the step ``f(k, x, u)``."""
    nx, nu = X.shape[1], U.shape[1]
    step = step_functions(model, H)["step"]

    def f(k, xk, uk):
        return np.array(step(xk, uk, problem.p, t + k * H)[0]).ravel()

    eps = 1e-6
    A = [np.column_stack([(f(k, X[k] + eps * e, U[k]) - f(k, X[k] - eps * e, U[k])) / (2 * eps) for e in np.eye(nx)])
         for k in range(N)]
    B = [np.column_stack([(f(k, X[k], U[k] + eps * e) - f(k, X[k], U[k] - eps * e)) / (2 * eps) for e in np.eye(nu)])
         for k in range(N)]
    return A, B, f


def horizon_hessian(problem, t, X, U):
    """``(H, g)``: the Hessian (with the regularisation) and gradient of the whole horizon's
    cost in ``[vec X; vec U]`` (one SX expression in all the nodes and inputs)."""
    import casadi as ca
    from ncgen.control.mpc import REGULARIZATION, total_cost
    nx, nu = X.shape[1], U.shape[1]
    Xs, Us, ts = ca.SX.sym("X", nx, N + 1), ca.SX.sym("U", nu, N), ca.SX.sym("t")
    y = ca.vertcat(ca.vec(Xs), ca.vec(Us))
    Hy, gy = ca.hessian(total_cost(problem, Xs, Us, ts), y)
    Hy, gy = (np.array(ca.Function("hg", [Xs, Us, ts], [Hy, gy])(X.T, U.T, t)[i]) for i in (0, 1))
    return Hy + REGULARIZATION * np.eye(len(Hy)), gy.ravel()


def horizon_condensed_densely(model, problem, x, t, X, U):
    """``(S, s, Hc, gc)``: the Gauss–Newton QP of the whole horizon condensed densely: the
    cost's Hessian and gradient of the whole horizon (:func:`horizon_hessian`), the step
    Jacobians by central differences (:func:`step_jacobians_by_differences`), ``S`` and ``s``
    by the linearised recursion in NumPy."""
    nx, nu = X.shape[1], U.shape[1]
    A, B, f = step_jacobians_by_differences(model, problem, t, X, U)
    S, s = np.zeros((N + 1, nx, N * nu)), np.zeros((N + 1, nx))
    s[0] = x - X[0]
    for k in range(N):
        S[k + 1] = A[k] @ S[k]
        S[k + 1][:, k * nu:(k + 1) * nu] = B[k]
        s[k + 1] = A[k] @ s[k] + f(k, X[k], U[k]) - X[k + 1]
    S, s = S.reshape(-1, N * nu), s.reshape(-1)
    Hy, gy = horizon_hessian(problem, t, X, U)
    E = np.vstack([S, np.eye(N * nu)])                   # [δX; δU] = E δU + [s; 0]
    return S, s, E.T @ Hy @ E, E.T @ (Hy @ np.concatenate([s, np.zeros(N * nu)]) + gy)


def guess(nx=6, nu=1):
    """A guess with shooting gaps and the height's upper bound violated."""
    rng = np.random.default_rng(5)
    x = np.array([0.01, -0.02, -0.97, 0.1, 0.0, 0.4])
    return x, x + 0.02 * rng.normal(size=(N + 1, nx)), 0.9 + 0.05 * rng.normal(size=(N, nu))


def check_condensed(out, reference, x, X, U):
    """``out`` (the QP data by name, flat or shaped) against the dense reference: ``S``, ``Xs``,
    ``H``, ``g`` to the central differences' accuracy, the height's rows and the bounds."""
    S, s, Hc, gc = reference
    out = {k: np.asarray(v).reshape(-1, order="F") for k, v in out.items()}
    nU = S.shape[1]
    # measured: 1.1e-10, 1.0e-11, 1.6e-10, 9.9e-11 (relative; the central differences' accuracy)
    assert np.max(np.abs(out["S"].reshape(-1, nU, order="F") - S)) <= 1e-8 * np.max(np.abs(S))
    assert np.max(np.abs(out["Xs"] - (X.ravel() + s))) <= 1e-8 * np.max(np.abs(s))
    assert np.max(np.abs(out["H"].reshape(nU, nU, order="F") - Hc)) <= 1e-8 * np.max(np.abs(Hc))
    assert np.max(np.abs(out["g"] - gc)) <= 1e-8 * np.max(np.abs(gc))
    rows = [6 * k + 2 for k in range(1, N + 1)]                     # the height at nodes 1..N
    Xn = X.ravel() + s
    assert np.max(np.abs(out["A"].reshape(-1, nU, order="F") - S[rows])) <= 1e-8 * np.max(np.abs(S))
    assert np.max(np.abs(out["lba"] - (-1.2 - Xn[rows]))) <= 1e-9 and np.max(np.abs(out["uba"] - (-0.99 - Xn[rows]))) <= 1e-9
    assert np.array_equal(out["lbx"], 0.5 - U.ravel()) and np.array_equal(out["ubx"], 1.5 - U.ravel())


def test_qp_blocks_by_intervals_equal_differences_and_the_horizon_hessian(model):
    """The QP blocks, built from one interval's kernel called per interval (a serial map), equal
    the step Jacobians by central differences (:func:`step_jacobians_by_differences`), the
    shooting gaps of the merit's own step and the whole horizon's cost Hessian and gradient
    (:func:`horizon_hessian`: its diagonal blocks, the cross terms ``M_k``; zero elsewhere), at a
    guess with shooting gaps and a state bound violated: what the controller's C condenses
    (``tests/c/test_condense.c`` checks its condensing; the slow test below the whole chain)."""
    problem = problem_of(model, None)
    t = 0.1
    x, X, U = guess()
    nx, nu = X.shape[1], U.shape[1]
    blocks = mpc_functions(model, problem)[0]
    out = {k: np.array(v) for k, v in zip(blocks.name_out(), blocks(x, t, X.T, U.T))}
    A, B, f = step_jacobians_by_differences(model, problem, t, X, U)
    # measured: 1e-10 relative (the central differences' accuracy)
    for k in range(N):
        assert np.max(np.abs(out["A"][:, nx * k:nx * (k + 1)] - A[k])) <= 1e-8 * np.max(np.abs(A[k]))
        assert np.max(np.abs(out["B"][:, nu * k:nu * (k + 1)] - B[k])) <= 1e-8 * np.max(np.abs(B[k]))
    gaps = np.column_stack([x - X[0]] + [f(k, X[k], U[k]) - X[k + 1] for k in range(N)])
    assert np.max(np.abs(out["d"] - gaps)) <= 1e-12 * np.max(np.abs(gaps))
    Hy, gy = horizon_hessian(problem, t, X, U)
    nX = nx * (N + 1)
    H_blocks = np.zeros_like(Hy)
    for k in range(N + 1):
        a = slice(nx * k, nx * (k + 1))
        H_blocks[a, a] = out["Q"][:, a]
        if k < N:
            b = slice(nX + nu * k, nX + nu * (k + 1))
            H_blocks[a, b], H_blocks[b, a] = out["M"][:, nu * k:nu * (k + 1)], out["M"][:, nu * k:nu * (k + 1)].T
            H_blocks[b, b] = out["R"][:, nu * k:nu * (k + 1)]
    np.testing.assert_allclose(H_blocks, Hy, rtol=1e-12, atol=1e-12 * np.max(np.abs(Hy)))
    np.testing.assert_allclose(np.concatenate([out["g_x"].ravel(order="F"), out["g_u"].ravel(order="F")]), gy,
                               rtol=1e-12, atol=1e-12 * np.max(np.abs(gy)))


@pytest.mark.slow                # compiles the controller's package
@pytest.mark.parametrize("options", [
    {"loop": "c"}, {"qp_solver": "qpoases"}, {"min_tension": 50.0},
    {"reference": (np.array([0.0, 0.2]), np.array([[0, 0, -1.0, 0, 0, 0], [0.02, 0, -0.95, 0, 0, 0.1]]),
                   np.array([[0.9], [1.1]])), "state_weight": 2.0, "input_weight": 0.5}],
    ids=["loop_c", "qpoases", "min_tension", "reference"])
def test_qp_condensed_by_the_controllers_c_equals_the_horizon_condensed_densely(model, options):
    """The QP condensed by the compiled controller's C (``ncgen_condense.h`` on the blocks of
    ``mpc_qp_blocks``: the exported package's, ``loop="c"``'s and every Python loop's, whatever
    the QP solver, with the cables' rows and with a reference to track, whose costs the dense
    reference's Hessian holds) against the same dense reference; the cables' rows
    are checked by ``tests/test_mpc_min_tension.py``."""
    mpc = nc.MPC(ocp_of(model), terminal_weight=1e3, sx_qr_max_nnz=0, **options)
    t = 0.1
    x, X, U = guess()
    names = ["H", "g", "A", "lba", "uba", "lbx", "ubx", "Xs", "S", "J", "c", "res"]
    out = dict(zip(names, mpc._c.condensed_qp(x, np.array([t]), X.ravel(), U.ravel())))
    if "min_tension" in options:                    # the height's rows first, then the cables' 2 N
        assert out["lba"].size == 3 * N and np.all(np.isinf(out["uba"][N:]))
        out["A"] = out["A"].reshape(3 * N, -1, order="F")[:N]
        out["lba"], out["uba"] = out["lba"][:N], out["uba"][:N]
    check_condensed(out, horizon_condensed_densely(model, mpc.problem, x, t, X, U), x, X, U)
    J, c, res = (float(o) for o in merit_function(model, mpc.problem)(x, t, X.T, U.T))
    assert out["res"][0] < 1e-10 and abs(out["J"][0] - J) <= 1e-12 * abs(J) and abs(out["c"][0] - c) <= 1e-12 * c
