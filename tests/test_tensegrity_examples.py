"""The tensegrity example scripts run as written and print what they claim: the closed-form
force densities, the realised structures back at their design, every loaded equilibrium
balanced by its own equilibrium matrix, the stiffest prestress sagging less."""
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def run(name, tmp_path, timeout=600):
    env = {**os.environ, "MPLBACKEND": "Agg", "NCGEN_CACHE_DIR": str(tmp_path / "cache")}
    out = subprocess.run([sys.executable, str(EXAMPLES / name)], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=timeout)
    assert out.returncode == 0, out.stderr
    return out.stdout


@pytest.mark.timeout(900)
def test_prisms_example(tmp_path):
    out = run("tensegrity_prisms.py", tmp_path)
    assert "1 - 1 = 12 - (18 - 6)" in out and "1 - 3 = 16 - (24 - 6)" in out
    assert "1 : 1.732051 : -1.732051 (closed form 2 sin(pi/n) = 1.732051)" in out
    assert "1 : 1.414214 : -1.414214 (closed form 2 sin(pi/n) = 1.414214)" in out
    for shape, tension in re.findall(r"within ([\d.e+-]+) m, tensions within ([\d.e+-]+) N", out):
        assert float(shape) < 1e-10 and float(tension) < 1e-9
    assert out.count("of the design; stable") == 2


@pytest.mark.slow       # a fresh process building two models; fast: test_prisms_example (an example script of the same
#                         steps), test_prestress.py's two-stage tower (its stiffest prestress, loaded equilibrium balanced)
@pytest.mark.timeout(900)
def test_tower_example(tmp_path):
    out = run("tensegrity_tower.py", tmp_path)
    assert "5 - 2 = 21 - (18 - 0)" in out
    sags = [float(s) for s in re.findall(r"top sags ([\d.]+) mm", out)]
    assert len(sags) == 2 and sags[1] < sags[0]
    assert all(float(r) < 1e-9 for r in re.findall(r"\|A t - f\| = ([\d.e+-]+) N", out))


@pytest.mark.slow       # a fresh process building a model: ~20 s; fast: test_inverse_statics.py's T-bar
@pytest.mark.timeout(900)
def test_tbar_example(tmp_path):
    """The T-bar's strut forces against statics by hand: F + t L / ℓ and t h / ℓ (L = 1, h = 0.4,
    F = 50 N, t = 10 N, ℓ = √(L² + h²) / 2); the realised model back at the design."""
    out = run("tensegrity_tbar.py", tmp_path)
    assert "1 - 0 = 8 - (7 - 0)" in out
    assert "cables 10.000000..10.000000 N" in out
    struts = [float(x) for x in re.search(r"struts \(compression\) \[([^\]]+)\]", out).group(1).split()]
    ell = np.hypot(1.0, 0.4) / 2
    np.testing.assert_allclose(struts, [50 + 10 / ell] * 2 + [10 * 0.4 / ell] * 2, atol=2e-6)   # printed to 1e-6
    shape, tension, strut = re.search(r"within ([\d.e+-]+) m, tensions within ([\d.e+-]+) N, struts within "
                                      r"([\d.e+-]+) N of the design; stable", out).groups()
    assert float(shape) < 1e-10 and float(tension) < 1e-7 and float(strut) < 1e-7


@pytest.mark.slow       # a fresh process building a body model: ~20 s; fast: test_rigid_tensegrity.py's table
@pytest.mark.timeout(900)
def test_bodies_example(tmp_path):
    out = run("tensegrity_bodies.py", tmp_path)
    assert "2 rigid bodies" in out and "1 - 3 = 4 - (12 - 6)" in out
    assert "ratio 3.000000, by hand 3" in out and "prestress stability: stable" in out
    shape, tension = re.search(r"within ([\d.e+-]+) m, tensions within ([\d.e+-]+) N", out).groups()
    assert float(shape) < 1e-9 and float(tension) < 1e-9


@pytest.fixture(scope="module")
def deployment_output(tmp_path_factory):
    """What examples/tensegrity_deployment.py prints (run once: the optimal-control solve, about
    4 min at load 16 on 2 cores, and the MPC's build, 2–3 min)."""
    return run("tensegrity_deployment.py", tmp_path_factory.mktemp("deployment"), timeout=1700)


def end_errors(out):
    """``|q − qB|`` (m) at the end of each tracked run the example prints, by name."""
    return {name: float(e) for name, e in re.findall(r"(open loop|tracked|MPC) from a disturbed start: .*?\|q - qB\| "
                                                     r"([\d.e+-]+) m", out)}


@pytest.mark.slow
@pytest.mark.timeout(1800)
@pytest.mark.xfail(reason="issue 41: on the merged tree of stop 46 the tracked run ended 9.5e-3 m from the "
                          "target against 1.24e-2 m open loop (the bound asks for a third; on its branch: 5.4e-3 "
                          "against 7.6e-2) — the plan of 20 intervals does not resolve the cables' ~100 rad/s "
                          "oscillation, so the open-loop figure is not a stable reference; cause of the change "
                          "not found; with the plan's cables kept taut (min_tension) the figures are 1.9e-3 m "
                          "tracked against 3.7e-3 m open loop, still short of a third", strict=False)
def test_deployment_example(deployment_output):
    """The plan reaches the deployed design (IPOPT's defects), and the cable-space feedback
    tracks it from a disturbed start better than its inputs replayed open loop."""
    out = deployment_output
    assert "compact top 0.7964 m, deployed top 1.0000 m" in out
    assert float(re.search(r"largest dynamics defect ([\d.e+-]+)", out).group(1)) < 1e-8
    errors = end_errors(out)
    assert errors["tracked"] < errors["open loop"] / 3


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_deployment_plan_keeps_the_cables_taut(deployment_output):
    """The plan (``OptimalControl.min_tension``) keeps every cable's pull at both ends of each
    interval above its floor (without it the plan's own inputs slackened a cable: −111 N), and
    so does the simulator (IDAS) replaying its inputs, sampled ten times an interval."""
    pull, floor = (float(x) for x in re.search(r"smallest cable pull at the nodes ([\d.e+-]+) N \(floor "
                                                r"([\d.e+-]+) N\)", deployment_output).groups())
    assert floor > 0 and pull >= floor - 1e-6, (pull, floor)
    replayed = float(re.search(r"replayed \(IDAS, open loop\).*smallest cable pull ([\d.e+-]+) N",
                               deployment_output).group(1))
    assert replayed >= floor, replayed          # the simulator's motion under the plan's inputs keeps them taut


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_deployment_tracked_by_mpc(deployment_output):
    """nc.MPC with the plan as its reference (IDAS plant, the same disturbed start) ends within
    5 mm of the deployed design, closer than the plan's inputs replayed open loop and than the
    cable-space feedback; the strut lengths held along the run."""
    out = deployment_output
    errors = end_errors(out)
    assert errors["MPC"] <= 5e-3 and errors["MPC"] < errors["open loop"] and errors["MPC"] < errors["tracked"], errors
    assert float(re.search(r"MPC: constraints within ([\d.e+-]+)", out).group(1)) < 1e-6
    assert "wrote tensegrity_deployment.html" in out


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_deployment_mpc_iterates_feasible_at_the_end(deployment_output):
    """The MPC's last solution is feasible: its l1 infeasibility (shooting gaps and the cables'
    pull shortfall) below 1e-6 — with the plan's cables and the horizon's kept taut
    (``min_tension``) and qpOASES solving the QPs."""
    gap = float(re.search(r"l1 gap of its last solution ([\d.e+-]+)", deployment_output).group(1))
    assert gap < 1e-6, gap
