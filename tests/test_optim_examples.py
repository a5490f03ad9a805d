"""The optimal-control examples run as written, and 'ncgen optimize' solves the shipped
problem file."""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.cli import main

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
SCRIPTS = {
    "cartpole_swingup.py": ["cartpole_swingup.png", "cartpole_swingup.gif"],
    "double_pendulum_swingup.py": ["double_pendulum_swingup.png", "double_pendulum_swingup.gif"],
    "arm_min_time.py": ["arm_min_time.png", "arm_min_time.gif"],
    "spring_design.py": ["spring_design.png"],
}

#: Run in the slow tier (a solve and a GIF each, 30 s on a loaded 2-core machine); their problems
#: are solved in the fast tier by tests/test_optim_cartpole.py (free final time) and
#: tests/test_optim_targets.py (the double pendulum), the cart-pole's by its swing-up in
#: tests/test_optim_cartpole.py, spring_design.py's free parameters by tests/test_optim_nlp.py and
#: tests/test_capstan_winch_ocp.py.
SLOW_SCRIPTS = {"arm_min_time.py", "double_pendulum_swingup.py", "cartpole_swingup.py", "spring_design.py"}


@pytest.mark.parametrize("script", [pytest.param(s, marks=pytest.mark.slow) if s in SLOW_SCRIPTS else s
                                    for s in sorted(SCRIPTS)])
def test_example_runs_as_written(tmp_path, script):
    run = subprocess.run([sys.executable, str(EXAMPLES / script)], cwd=tmp_path, capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr
    assert "Solve_Succeeded" in run.stdout
    for name in SCRIPTS[script]:
        assert (tmp_path / name).stat().st_size > 10_000, name


def test_ncgen_optimize_the_shipped_problem(tmp_path, capsys):
    out = tmp_path / "swingup.npz"
    status = main(["optimize", str(EXAMPLES / "cartpole_swingup.toml"), "-o", str(out),
                   "--plot", str(tmp_path / "swingup.png")])
    assert status == 0, capsys.readouterr().err
    traj = nc.Trajectory.load(out)
    assert traj.info["optimization"]["status"] == "Solve_Succeeded"
    assert traj.info["optimization"]["max_defect"] < 1e-8
    tip = traj.markers[:, traj.marker_names.index("pole.tip")]
    np.testing.assert_allclose(tip[[0, -1]], [[0.0, -0.5], [0.0, 0.5]], atol=1e-6)
