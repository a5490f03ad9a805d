"""Model-predictive control of the cart-pole (examples/cartpole_mpc.toml): the Python
controller stabilises it from disturbed states, never answers NaN or an input outside its
bounds (its iterates are rollouts, its line search rejects diverging trials), and its
converged SQP solution is IPOPT's on the same discrete problem; the exported C package
builds with -Wall -Wextra -Werror under AddressSanitizer and UndefinedBehaviorSanitizer, its
closed loop (controller and plant in C, no Python) stabilises the cart-pole and matches the
Python loop to 1e-9; the documented command (`ncgen mpc examples/cartpole_mpc.toml`, `make`,
`./demo`) works from the problem's documented start; the package's sources build warning-free
at -O0 to -O3 with and without the sanitizers."""
from __future__ import annotations

import os
import shutil
import subprocess

import numpy as np
import pytest

import ncgen as nc
from ncgen.cli import main
from ncgen.control.export import closed_loop
from ncgen.control.reference import solve_discrete
from ncgen.errors import OptimizationError

from cartpole_mpc import EXAMPLES, PUSH, cartpole, cartpole_problem, tilted

CC = os.environ.get("CC") or shutil.which("gcc") or shutil.which("cc")
SAN = "-fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer"
ENV = {**os.environ, "ASAN_OPTIONS": "detect_leaks=0", "UBSAN_OPTIONS": "halt_on_error=1"}
QUICK_COMPILE = True             # the cart-pole MPC's packages at -O0 in both tiers, as in the other MPC modules and
#                                 benchmarks/control.py's smoke, which share them through the compile cache (tests/conftest.py)
# nc.MPC compiles the horizon's step derivatives (400 s at load 10 on 2 cores, cold cache),
# the exported package is built under the sanitizers
pytestmark = [pytest.mark.slow, pytest.mark.timeout(1800)]


@pytest.fixture(scope="module")
def setup():
    ocp = cartpole_problem()
    return ocp, nc.MPC(ocp, terminal_weight=100.0)


def upright(x, tol):
    return abs(x[0]) < tol and np.linalg.norm(x[6:8] - [0.0, 0.5]) < tol and np.max(np.abs(x[8:])) < 10 * tol


@pytest.mark.parametrize("angle, cart", [(0.2, 0.0), (-0.3, 0.5)])
def test_python_mpc_stabilises_the_cartpole(setup, angle, cart):
    ocp, mpc = setup
    T, U, X = closed_loop(mpc, tilted(angle, cart, model=ocp.model), 4.0, disturbance=PUSH)
    assert np.all(np.abs(U) <= 20.0) and np.max(np.abs(U)) > 1.0
    assert np.all(np.abs(X[:, 0]) <= 1.5 + 1e-6)
    assert upright(X[-1], 2e-3), X[-1]


def test_reset_far_from_the_target_gives_a_finite_guess_within_the_bounds(setup):
    """``reset(x, 0, iterations=10)`` from the model's own initial state (the pole hanging 0.3
    rad off the downward vertical, far from the horizon's target) used to end with NaN in the
    guess and a good QP status; now every iterate is finite, its steps converge, its inputs are
    within ±20 N, and the line search reports its step lengths; a control step answers an input
    within the bounds."""
    from ncgen.control.mpc import ALPHAS
    ocp, mpc = setup
    model = ocp.model
    x = np.concatenate([model.q0, model.v0])
    mpc.reset(x, 0.0, iterations=10)
    assert np.all(np.isfinite(mpc.X)) and np.all(np.isfinite(mpc.U))
    assert mpc._merit(x, 0.0, mpc.X, mpc.U) is not None                 # every step along it converges
    assert np.all(np.abs(mpc.U) <= 20.0) and np.max(np.abs(mpc.U)) > 1.0
    assert len(mpc.step_lengths) == 1 and mpc.step_lengths[0] in ALPHAS + (0.0,)
    u = mpc(x, 0.0)
    assert np.all(np.isfinite(u)) and abs(u[0]) <= 20.0


class _FakeQP:
    """Stands in for the compiled qrqp: answers ``dU`` (model decrease ``cost``) with ``status``."""

    def __init__(self, dU, cost, status):
        self.outputs = [np.asarray(dU, dtype=float), np.array([cost]), np.zeros(0), np.zeros(len(dU))]
        self.status = status

    def status_call(self, *args):
        return self.status


def test_a_nan_or_wild_qp_answer_is_never_kept_nor_answered(setup):
    """A QP that answers NaN, or -70 N steps against a ±20 N bound (as qrqp did when it failed
    on the exported demo): the NaN step is not taken (the guess is kept, α = 0), the wild one is
    clipped into the bounds and taken only if the filter accepts it."""
    ocp, mpc = setup
    x = tilted(0.2, model=ocp.model)
    mpc.reset(x, 0.0, iterations=3)
    X0, U0 = mpc.X.copy(), mpc.U.copy()
    qp = mpc._qp
    try:
        mpc._qp = _FakeQP(np.full(mpc.N, np.nan), -1.0, 0)
        X, U = mpc._solve(x, 0.0, X0, U0)
        assert mpc.step_lengths == [0.0] and np.array_equal(U, U0) and np.array_equal(X, X0)
        mpc._qp = _FakeQP(np.full(mpc.N, -70.0), -1.0, 3)
        X, U = mpc._solve(x, 0.0, X0, U0)
        assert np.all(np.abs(U) <= 20.0) and np.all(np.isfinite(X))
        assert mpc.step_lengths[0] > 0 or (np.array_equal(U, U0) and np.array_equal(X, X0))
        u = mpc(x, 0.0)
        assert -20.0 <= u[0] <= 20.0
    finally:
        mpc._qp = qp


def test_the_filter_accepts_progress_and_refuses_the_rest():
    """:func:`ncgen.control.mpc.acceptable` on hand-made cases."""
    from ncgen.control.mpc import acceptable
    assert acceptable(1.0, 0.0, 0.9, 0.0, 1.0, -0.2)             # feasible: Armijo on the cost
    assert not acceptable(1.0, 0.0, 0.99999, 0.0, 1.0, -0.2)     # too little decrease
    assert not acceptable(1.0, 0.0, 0.5, 1e-3, 1.0, -0.2)        # cheaper but infeasible
    assert acceptable(1.0, 1.0, 5.0, 0.5, 1.0, 3.0)              # less infeasible
    assert acceptable(1.0, 1.0, 0.5, 1.0, 1.0, 3.0)              # cheaper, no more infeasible
    assert not acceptable(1.0, 1.0, 1.5, 1.0, 1.0, 3.0)          # neither
    assert not acceptable(1.0, 1.0, np.nan, np.nan, 1.0, 3.0)    # NaN is never progress


def test_converged_sqp_is_the_ipopt_solution_of_the_horizon_problem(setup):
    """Thirty SQP iterations at one state against IPOPT on the same discrete problem (the
    step equations as constraints: :func:`ncgen.control.reference.solve_discrete`)."""
    ocp, mpc = setup
    x = tilted(0.1, model=ocp.model)
    mpc.reset(x, iterations=30)
    X, U = mpc.X, mpc.U
    st = nc.step_function(ocp.model, mpc.h)
    assert np.allclose(X[1:], st.rollout(x, U), atol=1e-9)              # converged: the states are a rollout
    assert np.max(np.abs(U)) < 19.0                                     # bounds inactive: IPOPT needs none
    _, U_ip, J_ip = solve_discrete(st, x, U, (mpc.problem.stage, mpc.problem.terminal))
    assert np.max(np.abs(U - U_ip)) < 1e-6 * np.max(np.abs(U_ip))


def test_unsupported_problems_and_solvers_are_named(setup):
    ocp, _ = setup
    model = ocp.model
    free = nc.OptimalControl(model, N=10, t_final=(0.5, 2.0))
    with pytest.raises(OptimizationError, match="a free final time"):
        nc.MPC(free)
    with pytest.raises(OptimizationError, match="solver: expected one of sqp, fatrop, got 'qpoases'"):
        nc.MPC(ocp, solver="qpoases")
    with pytest.raises(OptimizationError, match="iterations: expected a positive integer"):
        nc.MPC(ocp, iterations=0)


@pytest.mark.skipif(CC is None, reason="no C compiler")
def test_exported_package_builds_under_sanitizers_and_matches_python(setup, tmp_path):
    ocp, mpc = setup
    out = tmp_path / "cartpole_mpc"
    x0 = tilted(0.2, model=ocp.model)
    assert main(["mpc", str(EXAMPLES / "cartpole_mpc.toml"), "-o", str(out), "--terminal-weight", "100",
                 "--x0", f"pole.r_j.x={float(x0[6])!r},pole.r_j.y={float(x0[7])!r}", "--t-end", "3",
                 "--disturbance", "1.0:1.1:8"]) == 0
    header = (out / "cartpole_mpc.h").read_text()
    assert "int cartpole_mpc_step(cartpole_mpc* m, const casadi_real* x, casadi_real t, casadi_real* u_out);" in header
    flags = f"-O0 -g -Werror {SAN}"
    build = subprocess.run(["make", f"CC={CC}", f"CFLAGS={flags}", f"LDFLAGS={SAN}", "demo"], cwd=out,
                           capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    assert "-Wall -Wextra" in build.stdout
    runs = {}
    for angle in (0.2, -0.25):
        x = tilted(angle, model=ocp.model)
        run = subprocess.run(["./demo", "3"] + [repr(float(v)) for v in x], cwd=out, capture_output=True, text=True,
                             env=ENV, timeout=300)
        assert run.returncode == 0 and not run.stderr, run.stderr[-3000:]
        C = np.array([[float(v) for v in line.split()] for line in run.stdout.splitlines()])
        T, U, X = closed_loop(mpc, x, 3.0, disturbance=PUSH)
        assert C.shape == (60, 1 + 1 + 16)
        assert np.max(np.abs(C[:, 1] - U[:, 0])) <= 1e-9
        assert np.max(np.abs(C[:, 2:] - X)) <= 1e-9
        runs[angle] = C
        assert upright(C[-1, 2:], 1e-2)
    default = subprocess.run(["./demo"], cwd=out, capture_output=True, text=True, env=ENV, timeout=300)
    assert default.returncode == 0 and np.allclose(
        [float(v) for v in default.stdout.splitlines()[-1].split()], runs[0.2][-1], rtol=0, atol=1e-12)
    for args, named in ((["-1"], "T"), (["abc"], "T"), (["1", "0"], "give all 16"), (["1"] + ["x"] * 16, "x_1")):
        bad = subprocess.run(["./demo"] + args, cwd=out, capture_output=True, text=True, env=ENV, timeout=60)
        assert bad.returncode == 2 and named in bad.stderr, (args, bad.stderr)


def _documented_package(tmp_path):
    out = tmp_path / "cartpole_mpc"
    assert main(["mpc", str(EXAMPLES / "cartpole_mpc.toml"), "-o", str(out)]) == 0
    return out


@pytest.mark.skipif(CC is None, reason="no C compiler")
def test_documented_command_works_from_the_documented_start(tmp_path):
    """`ncgen mpc examples/cartpole_mpc.toml -o DIR`, `make` (its default flags, every warning an
    error), `./demo`: the closed loop from the model's initial state (the pole hanging 0.3 rad
    off the downward vertical: it used to stop at t = 0.35 s after inputs of -70 N) runs its 5 s,
    every input within ±20 N, the cart within ±1.5 m, and ends upright at rest (a swing-up)."""
    model = cartpole()
    out = _documented_package(tmp_path)
    build = subprocess.run(["make", f"CC={CC}", "WARNINGS=-std=c99 -Wall -Wextra -pedantic -Werror", "demo"],
                           cwd=out, capture_output=True, text=True, timeout=3600)
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    run = subprocess.run(["./demo"], cwd=out, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0 and not run.stderr, run.stderr[-3000:]
    C = np.array([[float(v) for v in line.split()] for line in run.stdout.splitlines()])
    assert C.shape == (100, 18)
    assert np.array_equal(C[0, 2:], np.concatenate([model.q0, model.v0]))
    assert C[0, 9] < -0.4                                        # the pole's tip starts below the cart
    assert np.all(np.abs(C[:, 1]) <= 20.0) and np.all(np.abs(C[:, 2]) <= 1.5)
    assert upright(C[-1, 2:], 1e-2), C[-1]


@pytest.mark.skipif(CC is None, reason="no C compiler")
@pytest.mark.parametrize("sanitize", [False, True], ids=["plain", "sanitizers"])
def test_package_sources_are_warning_free_at_every_optimisation_level(tmp_path, sanitize):
    """Every object of the package, built by its own Makefile at -O0, -O1, -O2 and -O3 with
    -Wall -Wextra -pedantic -Werror: the kernels (the QP data calling one interval's kernel
    per interval, CasADi's qrqp — on which gcc's -Wmaybe-uninitialized misfires with the
    sanitizers: the Makefile turns that one warning off for the file holding it —, the full
    step, the merit rollouts, the plant), the controller's glue and the demo, of the documented
    package (its kernels hold one interval of the horizon: 0.4 MB of C, ~10 CPU-s at -O2)."""
    out = _documented_package(tmp_path)
    objects = [f.with_suffix(".o").name for f in sorted(out.glob("*.c")) if f.name != "main.c"]
    assert len(objects) == 8                            # 5 kernel files, the metadata, the controller, the demo
    qp = [f.name for f in sorted(out.glob("*.c")) if "casadi_qp" in f.read_text()]
    assert len(qp) == 1 and f"{qp[0][:-2]}.o: {qp[0]}" in (out / "Makefile").read_text()
    san = f" {SAN}" if sanitize else ""
    for level in ("-O0", "-O1", "-O2", "-O3"):
        subprocess.run(["make", "clean"], cwd=out, capture_output=True, timeout=60)
        built = subprocess.run(["make", f"CC={CC}", f"CFLAGS={level}{san}", f"LARGE_CFLAGS={level}{san}",
                                "WARNINGS=-std=c99 -Wall -Wextra -pedantic -Werror", *objects], cwd=out,
                               capture_output=True, text=True, timeout=1800)
        assert built.returncode == 0, (level, built.stdout[-2000:] + built.stderr[-3000:])
