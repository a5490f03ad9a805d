"""Control surfaces refuse bad input by name (issue 35, classes 1, 6 and 8): the exported
MPC's C API checks its inputs (tested from C under the sanitizers, ``tests/c/test_mpc_api.c``),
``export_mpc`` and ``ncgen mpc`` refuse a demo duration that is not positive and finite and a
state off the constraints, and iLQR refuses such a state as ``nc.simulate`` does, checks
``max_iter`` and reports a NaN cost as one."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.cli import main
from ncgen.errors import ModelError, NcgenError, OptimizationError
from ncgen.optim.problem_file import problem_from_data, read_problem_file

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
CC = os.environ.get("CC") or shutil.which("gcc") or shutil.which("cc")
SAN = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer"]
ENV = {**os.environ, "ASAN_OPTIONS": "detect_leaks=0", "UBSAN_OPTIONS": "halt_on_error=1:print_stacktrace=1"}
H = 0.02


def upright_at_rest(angle: float) -> np.ndarray:
    """The cart-pole at rest, pole ``angle`` rad off the upright: a consistent state [q; v]."""
    return np.array([0, 0, 1, 0, 0, 1, 0.5 * np.sin(angle), 0.5 * np.cos(angle)] + [0.0] * 8)


@pytest.fixture(scope="module")
def cartpole():
    """The cart-pole and examples/cartpole_mpc.toml's problem cut to 4 of its 20 intervals
    (0.2 s ahead): what these tests check (input checks, a refused call changing nothing) does
    not depend on the horizon (the full horizon: tests/test_control_mpc.py, slow tier)."""
    model = nc.System.from_toml(EXAMPLES / "cartpole.toml").build()
    data, origin = read_problem_file(EXAMPLES / "cartpole_mpc.toml")
    data["horizon"].update(N=4, t_final=0.2)
    ocp = problem_from_data(data, model, origin)[0]
    return model, ocp


@pytest.mark.slow      # a sanitizer build of the exported cart-pole MPC; fast: tests/c/test_mpc.c (the driver's checks)
@pytest.mark.skipif(CC is None, reason="no C compiler")
def test_exported_mpc_c_api_refuses_non_finite_input_from_c(cartpole, tmp_path):
    """<name>_mpc_init/_mpc_step/_plant called from C with NaN, ±inf and null pointers answer
    <NAME>_MPC_BAD_INPUT and change nothing; good calls between them answer bit-identically to
    a controller that never saw bad input.  The API's C (and the test) under ASan and UBSan; the
    solver's generated kernels (CasADi's, not ncgen's API) without, for build time.  The package
    of the 4-interval horizon (:func:`cartpole`): the API's code is the documented package's (its
    kernels too: the QP data call one interval's kernel per interval, whatever the horizon)."""
    out = tmp_path / "cp"
    nc.export_mpc(cartpole[1], out, terminal_weight=100.0)
    header = (out / "cartpole_mpc.h").read_text()
    assert "#define CARTPOLE_MPC_BAD_INPUT 2" in header and "CARTPOLE_MPC_BAD_INPUT (2)" in header
    objects = []
    for source in sorted(out.glob("cartpole_*.c")):
        flags = ["-O0"] if "kernels" in source.name else ["-O0", "-g", "-Werror", *SAN]
        obj = source.with_suffix(".o")
        built = subprocess.run([CC, "-std=c99", "-Wall", "-Wextra", "-pedantic", *flags, "-c", str(source), "-o",
                                str(obj)], capture_output=True, text=True, timeout=1800)
        assert built.returncode == 0, built.stderr[-3000:]
        objects.append(str(obj))
    exe = tmp_path / "test_mpc_api"
    built = subprocess.run([CC, "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O0", "-g", *SAN,
                            f"-I{out}", str(ROOT / "tests" / "c" / "test_mpc_api.c"), *objects, "-o", str(exe),
                            "-lm"], capture_output=True, text=True, timeout=600)
    assert built.returncode == 0, built.stderr[-3000:]
    run = subprocess.run([str(exe), *[repr(float(v)) for v in upright_at_rest(0.2)]], capture_output=True,
                         text=True, env=ENV, timeout=600)
    text = run.stdout + run.stderr
    assert "runtime error" not in text and "AddressSanitizer" not in text, text[-3000:]
    assert run.returncode == 0 and "checks passed" in run.stdout, text[-3000:]


def test_export_mpc_refuses_a_bad_demo_duration_and_an_inconsistent_x0(cartpole, tmp_path):
    _, ocp = cartpole
    for t_end, said in ((0.0, "got 0"), (-1.0, "got -1"), (float("nan"), "expected a finite number"),
                        (float("inf"), "expected a finite number"), ("soon", "expected a number")):
        with pytest.raises(NcgenError, match=f"export_mpc: t_end: .*{said}"):
            nc.export_mpc(ocp, tmp_path / "x", t_end=t_end)
    off = upright_at_rest(0.2)
    off[7] += 0.1                                   # the pole's tip 0.1 m off its circle
    with pytest.raises(ModelError, match=r"export_mpc: x0: the state is off the constraints .*pole"):
        nc.export_mpc(ocp, tmp_path / "x", x0=off)
    with pytest.raises(NcgenError, match=r"export_mpc: x0 \(the state \[q; v\]\): expected 16 numbers, got 3"):
        nc.export_mpc(ocp, tmp_path / "x", x0=[0.0, 1.0, 2.0])
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("args, said", [
    (["--t-end", "0"], r"--t-end: expected the demo's duration in seconds, 0 < T <= 1e\+06, got 0"),
    (["--t-end", "-2"], "--t-end: expected .* got -2"),
    (["--t-end", "nan"], "--t-end: expected .* got nan"),
    (["--x0", "pole.r_j.y=5"], "--x0 pole.r_j.y=5: no consistent state has these coordinates: assembly failed"),
    (["--x0", "pole.r_j.x=inf"], "--x0: 'pole.r_j.x=inf': expected coordinate=number"),
    (["--substeps", "0"], "--substeps: expected a positive integer, got 0"),
    (["--iterations", "-1"], "--iterations: expected a positive integer, got -1"),
    (["--terminal-weight", "nan"], "--terminal-weight: expected a finite number >= 0, got nan"),
    (["--disturbance", "1:0.5:8"], "--disturbance '1:0.5:8': expected finite numbers with T_ON < T_OFF"),
    (["--disturbance", "1:2:nan"], "--disturbance '1:2:nan': expected finite numbers"),
])
def test_ncgen_mpc_names_the_flag(tmp_path, capsys, args, said):
    assert main(["mpc", str(EXAMPLES / "cartpole_mpc.toml"), "-o", str(tmp_path / "x"), *args]) == 2
    assert re.search(said, capsys.readouterr().err), said
    assert not (tmp_path / "x").exists()


@pytest.fixture(scope="module")
def swingup(cartpole):
    model, _ = cartpole
    st = nc.step_function(model, H)
    x_up = upright_at_rest(0.0)
    costs = (lambda x, u: H * (0.01 * ca.sumsqr(u) + 0.1 * x[0] ** 2), lambda x: 100 * ca.sumsqr(x - x_up))
    return st, upright_at_rest(np.pi), np.zeros((20, 1)), costs


def test_ilqr_refuses_a_state_off_the_constraints_as_simulate_does(swingup):
    st, x0, U0, costs = swingup
    off = x0.copy()
    off[7] += 1e-3                                  # 1 mm off the circle: simulate refuses it too
    with pytest.raises(ModelError, match="simulate: initial state"):
        nc.simulate(st.model, 0.1, 0.01, q0=off[:8], v0=off[8:], method="idas")
    with pytest.raises(ModelError, match=r"ilqr: x0: the state is off the constraints of 'cartpole'.*pole"):
        nc.ilqr(st, off, U0, costs, max_iter=2)
    moving = x0.copy()
    moving[15] = 1.0                                # the tip moving along the pole: a velocity off the constraints
    with pytest.raises(ModelError, match="ilqr: x0: .*inconsistent initial velocities"):
        nc.ilqr(st, moving, U0, costs, max_iter=2)
    res = nc.ilqr(st, x0, U0, costs, max_iter=2)    # on the constraints: accepted, and the rows are a rollout
    assert np.array_equal(res.X[0], x0) and np.allclose(res.X[1:], st.rollout(x0, res.U), atol=1e-12)


@pytest.mark.parametrize("kw, said", [
    ({"max_iter": 0}, "ilqr: max_iter: expected a positive integer, got 0"),
    ({"max_iter": 2.5}, "ilqr: max_iter: expected a positive integer, got 2.5"),
    ({"max_iter": "10"}, "ilqr: max_iter: expected a positive integer, got '10'"),
    ({"max_iter": True}, "ilqr: max_iter: expected a positive integer, got True"),
    ({"tol": -1.0}, "ilqr: tol: expected a number >= 0"),
    ({"tol": float("nan")}, "ilqr: tol: expected a finite number"),
    ({"mu": "big"}, "ilqr: mu: expected a number"),
])
def test_ilqr_options_are_checked(swingup, kw, said):
    st, x0, U0, costs = swingup
    with pytest.raises(NcgenError, match=said.replace("(", r"\(")):
        nc.ilqr(st, x0, U0, costs, **kw)


def test_ilqr_reports_a_nan_cost_as_such(swingup):
    st, x0, U0, (stage, _) = swingup
    with pytest.raises(OptimizationError, match=r"ilqr: the cost of the initial guess is nan"):
        nc.ilqr(st, x0, U0, (stage, lambda x: ca.sqrt(x[0] - 1.0)), max_iter=3)   # x[0] = 0: sqrt(-1)
    # defined at the guess only, NaN at every other end state: every trial step's cost is NaN
    U1 = 0.5 * np.ones_like(U0)
    end = st.rollout(x0, U1)[-1]
    res = nc.ilqr(st, x0, U1, (lambda x, u: H * ca.sumsqr(u), lambda x: ca.if_else(ca.sumsqr(x - end) <= 0,
                                                                                   1.0, np.nan)), max_iter=50)
    assert not res.converged and res.cost == res.history[0] and np.isfinite(res.cost)
    assert "the cost was NaN at trial steps" in res.message, res.message


def test_python_mpc_and_step_refuse_bad_input_and_stay_unpoisoned(cartpole):
    """The Python side of class 1 on every entry point: ``nc.MPC`` (call, reset) and the
    step function (step, Jacobians, rollouts) refuse a non-finite state, time or input, raw
    bytes and ragged nestings by name, and a refused call leaves the controller answering
    bit-identically to one that never saw it."""
    model, ocp = cartpole
    x = upright_at_rest(0.2)
    nan_x = x.copy()
    nan_x[3] = np.nan
    mpc, reference = nc.MPC(ocp), nc.MPC(ocp)
    bad_calls = [
        (lambda: mpc(nan_x, 0.0), r"x: expected 16 finite number\(s\) \(the state \[q; v\]\), got 16 value\(s\) with NaN"),
        (lambda: mpc(x, float("nan")), r"MPC: t: expected a finite number, got nan"),
        (lambda: mpc(x, float("inf")), r"MPC: t: expected a finite number, got inf"),
        (lambda: mpc(bytes(128), 0.0), r"x: expected real numbers, got bytes \(raw bytes are not read as numbers\)"),
        (lambda: mpc(x[:3], 0.0), r"x: expected 16 finite number\(s\) .* got 3 value\(s\)"),
        (lambda: mpc.reset(nan_x, 0.0), r"x: expected 16 finite number\(s\)"),
        (lambda: mpc.reset(x, float("nan")), r"MPC.reset: t: expected a finite number, got nan"),
        (lambda: mpc.reset(x, 0.0, iterations=-1), r"MPC.reset: iterations: expected an integer >= 0, got -1"),
        (lambda: mpc.reset(x, 0.0, iterations=2.5), r"MPC.reset: iterations: expected an integer >= 0, got 2.5"),
    ]
    for k in range(3):
        for call, said in bad_calls:
            with pytest.raises(NcgenError, match=said):
                call()
        assert np.array_equal(mpc(x, k * H), reference(x, k * H))
    st = nc.step_function(model, H)
    for call, said in [
        (lambda: st(x, float("nan")), r"u: expected 1 finite number\(s\) \(the inputs\), got 1 value\(s\) with NaN"),
        (lambda: st(bytes(128), 0.0), r"x: expected real numbers, got bytes"),
        (lambda: st(x, 0.0, t=float("inf")), r"^t: expected a finite number, got inf"),
        (lambda: st.jacobians(nan_x, 0.0), r"x: expected 16 finite number\(s\)"),
        (lambda: st.rollout(x, [[1.0], [1.0, 2.0]]), r"U: expected finite inputs of shape \(N, 1\) \(one row per step\), "
                                                     r"got list"),
        (lambda: st.rollout(x, np.full((3, 1), np.inf)), r"U: expected finite inputs of shape \(N, 1\)"),
    ]:
        with pytest.raises(NcgenError, match=said):
            call()
