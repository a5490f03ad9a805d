"""Failures say what failed: infeasible problems name IPOPT's status and the likely
culprit, bad API calls name the argument, bad problem files name the key; and the
'ncgen optimize' command line."""
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import ncgen as nc
from ncgen.cli import main
from ncgen.errors import OptimizationError, ProblemFileError
from ncgen.optim.problem_file import problem_from_data

from optim_models import pendulum


@pytest.fixture(scope="module")
def model():
    return pendulum()


@pytest.fixture(autouse=True)
def unhurried_diagnosis(monkeypatch):
    """The relaxed re-solve's default wall-clock budget (10 s; it takes < 1 s here at load 10)
    raised to the tests' own time limit, so that which message comes out never depends on the
    machine's speed or load (the budget running out: test_diagnosis_out_of_budget_...)."""
    monkeypatch.setattr("ncgen.optim.diagnostics.DIAGNOSIS_BUDGET", 600.0)


def test_unreachable_final_marker_is_reported_as_infeasible(model):
    ocp = nc.OptimalControl(model, N=12, t_final=1.0)
    ocp.bound_input("tau", -5, 5)
    ocp.final(marker=("bar.tip", (2.0, 0.0)))         # the bar is 1 m long
    with pytest.raises(OptimizationError) as info:
        ocp.solve()
    err = info.value
    assert err.status in ("Infeasible_Problem_Detected", "Maximum_Iterations_Exceeded")
    assert err.status in str(err)
    assert "the nearest feasible motion misses final marker 'bar.tip' by 1" in str(err)
    assert "Likely culprit: final marker 'bar.tip'" in str(err)
    assert err.result is not None and err.result.stats.success is False


def test_too_weak_a_motor_names_the_final_condition_and_the_saturated_input(model):
    ocp = nc.OptimalControl(model, N=12, t_final=1.0)
    ocp.bound_input("tau", -1, 1)                      # holding the bar level takes 4.9 N·m
    ocp.final(q=[0.0, 1.0], v=0)
    with pytest.raises(OptimizationError) as info:
        ocp.solve()
    msg = str(info.value)
    assert info.value.status in ("Infeasible_Problem_Detected", "Restoration_Failed")
    assert "the nearest feasible motion misses final q by" in msg
    assert "Likely culprit: final q against the bounds on tau —" in msg
    assert "Inputs on their bounds in most intervals: tau" in msg


def test_diagnosis_can_be_turned_off_and_then_says_it_does_not_know(model):
    """No relaxed re-solve: the message says the cause is unknown and calls the largest
    violations symptoms, never a culprit (and the failure costs one solve, not two)."""
    ocp = nc.OptimalControl(model, N=12, t_final=1.0)
    ocp.bound_input("tau", -1, 1)
    ocp.final(q=[0.0, 1.0], v=0)
    with pytest.raises(OptimizationError) as info:
        ocp.solve(diagnose=False)
    msg = str(info.value)
    assert "Which condition conflicts is not known (the relaxed re-solve is off" in msg
    assert "Likely culprit" not in msg and "symptoms, not necessarily the cause" in msg


def test_diagnosis_out_of_budget_says_it_does_not_know(model):
    ocp = nc.OptimalControl(model, N=12, t_final=1.0)
    ocp.bound_input("tau", -1, 1)
    ocp.final(q=[0.0, 1.0], v=0)
    with pytest.raises(OptimizationError) as info:
        ocp.solve(diagnose=1e-6)
    msg = str(info.value)
    assert "Which condition conflicts is not known (the relaxed re-solve ended with" in msg
    assert "budget of 1e-06 s" in msg and "Likely culprit" not in msg


def test_unavailable_linear_solver_is_named(model):
    ocp = nc.OptimalControl(model, N=4, t_final=1.0)
    with pytest.raises(OptimizationError, match="linear_solver: expected one of mumps"):
        ocp.solve(linear_solver="lu")


def test_iteration_limit_is_a_failure_with_advice(model):
    ocp = nc.OptimalControl(model, N=12, t_final=2.0)
    ocp.final(q=[0.0, 1.0], v=0)
    ocp.minimize_effort()
    with pytest.raises(OptimizationError, match="Maximum_Iterations_Exceeded.*\n(.*\n)*.*max_iter"):
        ocp.solve(max_iter=2)


@pytest.mark.parametrize("call, message", [
    (lambda o: o.bound_input("torque", -1, 1), "no input named 'torque'; inputs: tau"),
    (lambda o: o.bound_input("tau", 1, -1), "lower bound [1.0] exceeds upper bound [-1.0]"),
    (lambda o: o.bound_coordinate("bar.x", 0, 1), "no coordinate named 'bar.x'; coordinates: bar.r_j.x, bar.r_j.y"),
    (lambda o: o.bound_marker("bar.top", lower=(0, 0)), "no marker named 'bar.top'; markers: bar.tip"),
    (lambda o: o.bound_marker("bar.tip", lower=(0, 0, 0)), "expected 2 components"),
    (lambda o: o.free_parameter("kk", 0, 1), "no parameter named 'kk'; parameters: k"),
    (lambda o: o.minimize_time(), "the final time is fixed"),
    (lambda o: o.final(q=[0, 1, 2]), "final q: expected 2 finite numbers"),
    (lambda o: o.final(marker=("bar.tip", (None, None))), "every component is None"),
    (lambda o: o.initial(q=[0, -1], marker=("bar.tip", (0, -1))), "need a free initial configuration"),
    (lambda o: (o.final(q=[0, 1]), o.periodic()), "final q and periodic q both given"),
    (lambda o: o.minimize_effort(-1.0), "positive semidefinite"),
])
def test_bad_calls_name_the_argument(model, call, message):
    ocp = nc.OptimalControl(model, N=4, t_final=1.0)
    with pytest.raises(OptimizationError) as info:
        call(ocp)
    assert message in str(info.value)


@pytest.mark.parametrize("kwargs, message", [
    ({"N": 0}, "N: expected a positive integer"),
    ({"t_final": -1.0}, "t_final: expected a positive duration"),
    ({"t_final": (2.0, 1.0)}, "0 < lower < upper"),
    ({"method": "pseudospectral"}, "method: expected one of collocation, shooting"),
    ({"method": "shooting", "integrator": "euler"}, "integrator 'euler' is not available; registered: idas"),
])
def test_bad_problem_setup(model, kwargs, message):
    with pytest.raises(OptimizationError, match=message):
        nc.OptimalControl(model, **kwargs)


def test_inconsistent_target_configuration_is_named(model):
    ocp = nc.OptimalControl(model, N=4, t_final=1.0)
    ocp.final(q=[0.0, 2.0])                             # 2 m from the pivot of a 1 m bar
    with pytest.raises(OptimizationError, match="final q: the configuration violates the constraints"):
        ocp.solve()


PROBLEM = """
[horizon]
N = 8
t_final = 1.5
[bounds.inputs]
tau = [-10, 10]
[final]
q = [0.0, 1.0]
v = 0
[cost]
effort = 0.1
"""


@pytest.mark.parametrize("change, key", [
    ("[horizon]\nN = 8\nt_final = 1.5\nmetod = 'collocation'", "horizon.metod: unknown key (did you mean 'method'?)"),
    ("[horizon]\nN = 'eight'", "horizon.N: expected a positive integer, got the string 'eight'"),
    ("[bounds.inputs]\ntorque = [-1, 1]", "bounds.inputs.torque: no input named 'torque'"),
    ("[bounds.inputs]\ntau = [-1]", "bounds.inputs.tau: expected 2 numbers"),
    ("[final]\nv = true", "final.v: expected \"free\", a number"),
    ("[final]\nq = {'bar.r_j.z' = 1.0}", "final: no coordinate named 'bar.r_j.z'"),
    ("[final]\nmarkers = {'bar.tip' = [0, 'up']}", "final.markers.bar.tip[1]: expected a number"),
    ("[[cost.track]]\nreference = [0, 1]", "cost.track[0].marker: missing"),
    ("[cost]\ntime = 1.0", "cost.time: minimize_time: the final time is fixed"),
    ("[solver]\nwarm_start = 'cold'", "solver.warm_start: expected \"rest\" or \"interpolate\""),
    ("[solvr]\ntol = 1e-6", "solvr: unknown key (did you mean 'solver'?)"),
])
def test_bad_problem_file_names_the_key(model, change, key):
    import tomllib
    with pytest.raises(ProblemFileError) as info:
        problem_from_data(tomllib.loads(change), model, "p.toml")
    assert key in str(info.value) and str(info.value).startswith("p.toml: ")


def test_problem_file_round_trip(model):
    import tomllib
    ocp, options = problem_from_data(tomllib.loads(PROBLEM), model, "p.toml")
    assert ocp.N == 8 and ocp.t_final == 1.5 and options.tol == 1e-8
    np.testing.assert_allclose(ocp.u_bounds[:, 0], [-10, 10])
    assert ocp.effort_R[0, 0] == 0.1


def _ncgen(*args, cwd, capsys, monkeypatch):
    """``ncgen ARGS`` in-process, in directory ``cwd``: (exit status, stdout, stderr)."""
    monkeypatch.chdir(cwd)
    status = main([str(a) for a in args])
    out = capsys.readouterr()
    return status, out.out, out.err


@pytest.fixture
def pendulum_files(tmp_path):
    (tmp_path / "pendulum.toml").write_text(textwrap.dedent("""
        [system]
        name = "pendulum"
        gravity = [0.0, -9.81]
        [inputs]
        tau = 1
        [[members]]
        name = "bar"
        kind = "bar"
        mass = 1.0
        ends = [{ground = [0.0, 0.0]}, [0.0, -1.0]]
        markers = { tip = [0.5, 0.0] }
        [[forces]]
        type = "Torque"
        member = "bar"
        torque = "tau"
        """))
    (tmp_path / "swing.toml").write_text('model = "pendulum.toml"\n' + PROBLEM)
    return tmp_path


@pytest.mark.slow      # an IPOPT solve and a plot through the CLI; fast: test_cli_optimize_failures (the same
#                       command's error paths), test_unreachable_final_marker_is_reported_as_infeasible (the solve)
def test_cli_optimize_writes_trajectory_and_plot(pendulum_files, capsys, monkeypatch):
    status, out, err = _ncgen("optimize", "swing.toml", "-o", "swing.npz", "--plot", "swing.png", cwd=pendulum_files,
                              capsys=capsys, monkeypatch=monkeypatch)
    assert status == 0, err
    assert "Solve_Succeeded" in out
    traj = nc.Trajectory.load(pendulum_files / "swing.npz")
    np.testing.assert_allclose(traj.markers[-1, 0], [0.0, 1.0], atol=1e-4)   # N = 8: drift 1e-5
    assert (pendulum_files / "swing.png").stat().st_size > 10_000


def test_cli_optimize_failures(pendulum_files, capsys, monkeypatch):
    def ncgen(*args):
        return _ncgen(*args, cwd=pendulum_files, capsys=capsys, monkeypatch=monkeypatch)

    (pendulum_files / "bad.toml").write_text(
        'model = "pendulum.toml"\n[bounds.inputs]\ntau = [-1, 1]\n[final]\nq = [0.0, 1.0]\n')
    status, _, err = ncgen("optimize", "bad.toml", "-o", "bad.npz", "--plot", "bad.png")
    assert status == 1 and "Likely culprit: final q" in err
    assert not (pendulum_files / "bad.npz").exists() and not (pendulum_files / "bad.png").exists()
    (pendulum_files / "typo.toml").write_text('model = "pendulum.toml"\n[bounds.input]\ntau = [-1, 1]\n')
    status, _, err = ncgen("optimize", "typo.toml")
    assert status == 1 and "bounds.input: unknown key (did you mean 'inputs'?)" in err
    status, _, err = ncgen("optimize", "pendulum.toml")
    assert status == 1 and "pendulum.toml: this is a model file" in err      # a model given as the problem
    status, _, err = ncgen("optimize", "pendulum.toml", "--problem", "swing.toml", "-o", "x.csv")
    assert status == 2 and "expected a file name ending in .npz" in err


def test_cli_optimize_help_as_a_module():
    """``python -m ncgen.cli optimize --help``: the subcommand registers in the importable
    module even when cli.py runs as __main__."""
    run = subprocess.run([sys.executable, "-m", "ncgen.cli", "optimize", "--help"], capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "--problem" in run.stdout and "docs/optimal-control.md" in run.stdout
