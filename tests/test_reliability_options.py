"""Statics, form-finding and optimal-control options checked where they enter, naming the
option and what was found: no LinAlgError, no CasADi assertion, no 'internal error' exit."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError, OptimizationError


@pytest.fixture(scope="module")
def pendulum():
    s = nc.System("pend", gravity=(0, -9.81))
    s.add_bar("b", coords="rr", mass=1.0, ends=[s.ground.point((0, 0)), (1, 0)])
    return s.build()


@pytest.mark.parametrize("kwargs, message", [
    (dict(tol=-1), r"equilibrium: tol: expected a number > 0"),
    (dict(tol=float("nan")), r"equilibrium: tol: expected a finite number"),
    (dict(max_iter=0), r"equilibrium: max_iter: expected an integer ≥ 1"),
    (dict(max_iter=2.5), r"equilibrium: max_iter"),
])
def test_equilibrium_options(pendulum, kwargs, message):
    with pytest.raises(NcgenError, match=message):
        nc.equilibrium(pendulum, **kwargs)


def test_form_finding_refuses_non_finite_numbers_by_name():
    nodes = np.array([[1.0, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]])
    with pytest.raises(NcgenError, match=r"form_find: force_densities: expected finite numbers, found nan at index \(1,\)"):
        nc.form_find(nodes, [(0, 2)], [(0, 1), (1, 2)], force_densities=[1.0, float("nan"), -1.0])
    with pytest.raises(NcgenError, match=r"form_find: nodes: expected finite numbers"):
        nc.form_find(np.where(nodes == 1.0, np.inf, nodes), [(0, 2)], [(0, 1), (1, 2)], rest_lengths=[1.0, 1.0])


@pytest.fixture(scope="module")
def ocp(pendulum):
    return nc.OptimalControl(pendulum, N=6, t_final=0.5)


@pytest.mark.parametrize("ipopt, message", [
    ({"no_such_option": 3}, r"ipopt\.no_such_option = 3: IPOPT refuses it: no such option"),
    ({"max_iter": "many"}, r"ipopt\.max_iter = 'many': IPOPT refuses it: wrong type"),
    ({"mu_strategy": "bogus"}, r"ipopt\.mu_strategy = 'bogus'.*Valid settings: monotone, adaptive"),
    ({"acceptable_tol": -2.0}, r"ipopt\.acceptable_tol = -2\.0.*Valid range"),
    ({"tol": float("inf")}, r"ipopt\.tol: expected a finite number"),
    ({"print_level": [1]}, r"ipopt\.print_level: expected a number or a string"),
    ("print_level=3", r"ipopt: expected a dict of IPOPT options"),
])
def test_ipopt_options_are_named(ocp, ipopt, message):
    with pytest.raises(OptimizationError, match=message):
        ocp.solve(ipopt=ipopt, diagnose=False)


def test_solve_tol_and_max_iter(ocp):
    with pytest.raises(OptimizationError, match=r"tol: expected a number > 0"):
        ocp.solve(tol=0.0)
    with pytest.raises(OptimizationError, match=r"max_iter: expected an integer"):
        ocp.solve(max_iter=-3)


def test_a_nan_in_a_warm_start_is_named(pendulum, ocp):
    traj = nc.simulate(pendulum, 0.5, 0.05)

    class Damaged:
        t, q, v = traj.t, traj.q.copy(), traj.v

    Damaged.q[3, 1] = np.nan
    with pytest.raises(OptimizationError, match=r"warm_start\.q: expected finite numbers, found nan at index \(3, 1\)"):
        ocp.solve(warm_start=Damaged(), diagnose=False)


PROBLEM = """
model = "{model}"
[horizon]
N = 5
t_final = 0.5
[solver.ipopt]
mu_strategy = "sideways"
"""


def test_problem_file_with_a_bad_ipopt_option_exits_1_naming_it(tmp_path):
    import shutil
    shutil.copy("examples/cartpole.toml", tmp_path / "cartpole.toml")
    path = tmp_path / "p.toml"
    path.write_text(PROBLEM.format(model="cartpole.toml"))
    r = subprocess.run([sys.executable, "-m", "ncgen.cli", "optimize", str(path), "-o", str(tmp_path / "o.npz")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 1, (r.returncode, r.stderr)
    assert "solver.ipopt.mu_strategy = 'sideways'" in r.stderr and "internal error" not in r.stderr
