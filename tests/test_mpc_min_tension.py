"""``nc.MPC(ocp, min_tension=T_min)``: the cables kept taut along the horizon (issue 41).

A point mass hanging from the ground by one cable whose rest length is the input, asked to
rise 5 cm in 0.1 s and stop: the unconstrained controller slackens the cable (its optimum
throws the mass up and lets it fall), and its SQP iterates stay infeasible along the kink of
``max(P, 0)`` (tiny steps, ℓ1 gap ~0.5); with ``T_min`` the cable's pull ``P = k (l − l₀) + c l̇``
stays ≥ ``T_min`` at both ends of every interval, where the step evaluates it (with the
half-step velocity), and the iterates are feasible (gaps checked with an independent step
function).  The constraint's rows are the pull's first-order model
(checked against the pull itself); its violation enters the infeasibility as
``Σ max(0, T_min − P)`` (checked by hand); bad values are refused by name."""
from __future__ import annotations

import os
import shutil
import subprocess

import numpy as np
import pytest

import ncgen as nc
from ncgen.control.mpc import merit_function
from ncgen.control.mpc_problem import mpc_problem
from ncgen.errors import NcgenError

K, C, MASS = 200.0, 5.0, 1.0
CC = os.environ.get("CC") or shutil.which("gcc") or shutil.which("cc")
SAN = "-fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer"


def hanging(cable=True):
    s = nc.System("hang", gravity=(0, 0, -9.81))
    p = s.add_point("p", mass=MASS, position=(0, 0, -1.0))
    u = s.add_input("l0", 1)
    s.add_force(nc.Spring(s.ground, (0, 0, 0), p, (0, 0, 0), k=K, rest_length=u[0], damping=C, cable=cable,
                          name="c"))
    return s.build()


def rising(model, N=5, t_final=0.1, top=-0.95):
    ocp = nc.OptimalControl(model, N=N, t_final=t_final)
    ocp.bound_input("l0", 0.5, 1.5)
    ocp.minimize_effort(1e-3)
    ocp.final(q=[0, 0, top], v=[0, 0, 0])
    return ocp


def pull(x, u):
    """The cable's pull by hand: ``k (l − l₀) + c l̇`` (the cable from the origin to the mass)."""
    q, v = x[:3], x[3:]
    l = np.linalg.norm(q)
    return K * (l - u) + C * q @ v / l


def step_pull(X, U, k, j, h):
    """The pull by hand where the step of interval ``k`` evaluates it: at ``q_j`` (``j = k, k + 1``)
    with the half-step velocity ``w_k = (q_{k+1} − q_k) / h``."""
    w = (X[k + 1][:3] - X[k][:3]) / h
    return pull(np.concatenate([X[j][:3], w]), U[k][0])


@pytest.fixture(scope="module")
def model():
    return hanging()


@pytest.mark.parametrize("kwargs, message", [
    ({"min_tension": -1.0}, "min_tension: expected a finite tension >= 0"),
    ({"min_tension": np.nan}, "min_tension: expected a finite"),
    ({"min_tension": "one"}, "min_tension"),
    ({"min_tension": 1.0, "solver": "fatrop"}, "min_tension: supported by solver='sqp' only"),
])
def test_bad_min_tension_refused_by_name(model, kwargs, message):
    with pytest.raises(NcgenError, match=message):
        nc.MPC(rising(model), **kwargs)


def test_bad_qp_solver_refused_by_name(model):
    with pytest.raises(NcgenError, match="qp_solver: expected one of qrqp, qpoases, got 'gurobi'"):
        nc.MPC(rising(model), qp_solver="gurobi")


def test_the_ocps_floor_is_the_mpcs(model):
    ocp = rising(model).min_tension(3.0)
    assert mpc_problem(ocp, 1e3).min_tension == 3.0
    assert mpc_problem(ocp, 1e3, min_tension=1.0).min_tension == 1.0


def test_min_tension_refused_without_cables():
    with pytest.raises(NcgenError, match="min_tension: the model 'hang' has no cables"):
        nc.MPC(rising(hanging(cable=False)), min_tension=1.0)


@pytest.mark.slow                # compiles the controller's package
def test_taut_rows_are_the_pulls_first_order_model(model):
    """The QP's tension rows ``A δU ≥ lb`` (condensed by the controller's C, ``ncgen_condense.h``,
    from the pulls' blocks) are ``f(0) + f′(0) ≥ T_min`` with
    ``f(τ) = P(q̄_j + τ δq_j, w̄_k + τ δw_k, ū_k + τ δu_k)`` (``w_k = (q_{k+1} − q_k) / h``: where
    the step evaluates the pull), ``vec δX = S δU + s`` (the QP's own prediction,
    ``s``: the guess's gaps closed), ``f′`` by central differences of the pull by hand."""
    N, T_min = 3, 2.0
    mpc = nc.MPC(rising(model, N=N, t_final=0.06), min_tension=T_min, sx_qr_max_nnz=0)
    rng = np.random.default_rng(1)
    x = np.array([0.01, -0.02, -0.97, 0.1, 0.0, 0.4])
    X = x + 0.01 * rng.normal(size=(N + 1, 6))
    U = 0.9 + 0.01 * rng.normal(size=(N, 1))
    _, _, A, lba, uba, _, _, Xs, S = (o.copy() for o in mpc._data(x, np.array([0.0]), X.ravel(), U.ravel())[:9])
    A, S = A.reshape(-1, N, order="F"), S.reshape(-1, N, order="F")
    assert A.shape == (2 * N, N) and np.all(np.isinf(uba))
    for dU in (np.zeros(N), rng.normal(size=N)):
        dX = (Xs.ravel() + S @ dU).reshape(N + 1, 6) - X
        model_rows = A @ dU - lba.ravel() + T_min
        eps = 1e-6
        f = lambda tau, k, j: step_pull(X + tau * dX, U + tau * dU[:, None], k, j, 0.02)  # noqa: E731
        by_hand = [f(0, k, j) + (f(eps, k, j) - f(-eps, k, j)) / (2 * eps) for k in range(N) for j in (k, k + 1)]
        np.testing.assert_allclose(model_rows, by_hand, rtol=0, atol=1e-6)


def test_infeasibility_counts_the_tension_below_its_minimum(model):
    """``c`` with ``min_tension`` = ``c`` without it + ``Σ max(0, T_min − P)`` over both ends of
    each interval (P by hand, at the step's half-step velocity)."""
    N, T_min = 3, 5.0
    ocp = rising(model, N=N, t_final=0.06)
    with_, without = (merit_function(model, mpc_problem(ocp, 1e3, min_tension=m)) for m in (T_min, None))
    x = np.array([0.0, 0.0, -1.0, 0.0, 0.0, 0.3])
    X = np.tile(x, (N + 1, 1))
    U = np.array([[0.99], [1.0], [0.97]])            # pulls near and below T_min
    c1, c0 = (float(f(x, 0.0, X.T, U.T)[1]) for f in (with_, without))
    by_hand = sum(max(0.0, T_min - step_pull(X, U, k, j, 0.02)) for k in range(N) for j in (k, k + 1))
    assert by_hand > 1.0
    assert c1 == pytest.approx(c0 + by_hand, rel=1e-12, abs=1e-12)


def closed_loop(model, min_tension, calls=6, qp_solver="qrqp"):
    """The MPC's solutions from rest, each applied as planned: ``(infeasibility, pulls)`` per call,
    the gaps measured by an independent step function, the pulls by hand."""
    mpc = nc.MPC(rising(model), min_tension=min_tension, iterations=3, sx_qr_max_nnz=0, qp_solver=qp_solver)
    step = nc.step_function(model, mpc.h)
    x, gaps, pulls = np.array([0, 0, -1.0, 0, 0, 0]), [], []
    for i in range(calls):
        mpc(x, i * mpc.h)
        X, U = mpc.solution
        gaps.append(sum(np.abs(step(X[k], U[k], mpc.problem.p, (i + k) * mpc.h) - X[k + 1]).sum()
                        for k in range(mpc.N)))
        pulls.append(min(step_pull(X, U, k, j, mpc.h) for k in range(mpc.N) for j in (k, k + 1)))
        x = X[1]
    return np.array(gaps), np.array(pulls)


@pytest.mark.parametrize("qp_solver", ["qrqp", "qpoases"])
def test_mpc_keeps_the_cable_taut_and_its_iterates_feasible(model, qp_solver):
    gaps, pulls = closed_loop(model, None, qp_solver=qp_solver)
    assert pulls.min() < 0 and gaps[-3:].min() > 0.1         # the problem the option solves
    T_min = 2.0
    gaps, pulls = closed_loop(model, T_min, qp_solver=qp_solver)
    feasible = gaps < 1e-8
    assert feasible[-4:].all(), gaps                         # the last four solutions feasible
    assert np.all(pulls[feasible] >= T_min - 1e-6), pulls


@pytest.mark.slow                # builds the exported package under the sanitizers
@pytest.mark.skipif(CC is None, reason="no C compiler")
def test_exported_package_and_c_loop_answer_the_python_loops_inputs(model, tmp_path):
    """An OCP with a floor (``ocp.min_tension``) exported: the package (its QP's cable rows
    condensed by the same ``ncgen_condense.h``) builds with ``-Wall -Wextra -Werror`` under the
    sanitizers, and its demo's closed loop (controller and plant in C), ``loop="c"`` and the
    Python loop answer the same inputs and states to 1e-9; the last solution keeps the cable's
    pull ≥ T_min (by hand)."""
    from ncgen.control.export import closed_loop
    T_min, t_end = 2.0, 0.3
    ocp = rising(model).min_tension(T_min)
    out = tmp_path / "hang"
    nc.export_mpc(ocp, out, iterations=3, t_end=t_end, warmup=3)
    build = subprocess.run(["make", f"CC={CC}", f"CFLAGS=-O0 -g -Werror {SAN}", f"LDFLAGS={SAN}", "demo"], cwd=out,
                           capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    run = subprocess.run(["./demo"], cwd=out, capture_output=True, text=True, timeout=300,
                         env={**os.environ, "ASAN_OPTIONS": "detect_leaks=0", "UBSAN_OPTIONS": "halt_on_error=1"})
    assert run.returncode == 0 and not run.stderr, run.stderr[-3000:]
    C = np.array([[float(v) for v in line.split()] for line in run.stdout.splitlines()])
    x0 = np.array([0, 0, -1.0, 0, 0, 0])
    for loop in ("python", "c"):
        mpc = nc.MPC(ocp, iterations=3, loop=loop)
        T, U, X = closed_loop(mpc, x0, t_end, warmup=3)
        assert C.shape == (len(T), 2 + 6) and np.max(np.abs(C[:, 1] - U[:, 0])) <= 1e-9, loop
        assert np.max(np.abs(C[:, 2:] - X)) <= 1e-9, loop
        Xs, Us = mpc.solution
        assert min(step_pull(Xs, Us, k, j, mpc.h) for k in range(mpc.N) for j in (k, k + 1)) >= T_min - 1e-6
