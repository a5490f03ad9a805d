"""Every example: the model files build and simulate, the scripts run as written, and the
physics the examples claim (tensegrity equilibrium, energy conservation of the chain and the
double pendulum over long runs)."""
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
MODELS = [p for p in sorted(EXAMPLES.glob("*.toml")) if "members" in tomllib.loads(p.read_text())]
#: Scripts of the model files (optimisation scripts are tested with the optimiser).
SCRIPTS = [p for p in sorted(EXAMPLES.glob("*.py")) if p.with_suffix(".toml") in MODELS]


def load(name: str, **replace) -> nc.System:
    text = (EXAMPLES / f"{name}.toml").read_text()
    for old, new in replace.items():
        assert old in text
        text = text.replace(old, new)
    return nc.System.from_toml(text)


#: The largest example (19.6 s on 2 loaded cores) in the slow tier; fast: the other contact examples
#: (``boxes``, ``falling_chain``) take the same path.
SLOW_MODELS = {"box_stack"}


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.slow) if p.stem in SLOW_MODELS else p
                                  for p in MODELS], ids=[p.stem for p in MODELS])
def test_model_builds_and_simulates(path):
    model = nc.System.from_toml(path).build()
    traj = nc.simulate(model, t_end=0.2, dt=0.02, backend="vm")
    assert traj.complete and np.all(np.isfinite(traj.q))
    assert np.max(traj.constraint_residual) < 1e-5


@pytest.mark.slow
def test_box_stack_idas_work_is_bounded():
    """``ncgen simulate box_stack``'s default path (IDAS, smooth contacts) over the landings of
    the crate and the top box (0.1 s): 1604 steps and 109 error-test failures, the same on
    c791e2a and 8976e34; at most 2000 and 150 so that a change costing the run more steps
    fails here (a step count, not a time: CPU time varies with the load).  The contacts' work
    closes the energy balance (E − E0 = W to 1e-6 of the energy scale)."""
    traj = nc.simulate(nc.System.from_toml(EXAMPLES / "box_stack.toml").build(), 0.1, 0.01, backend="vm")
    stats = traj.info["stats"]
    assert traj.complete and stats["nsteps"] <= 2000 and stats["netfails"] <= 150, stats
    assert traj.info["energy"]["relative"] < 1e-6 and traj.info["energy"]["parts"]["contacts"] < 0


#: Scripts run in the slow tier (a subprocess, a compile and a plot each); their models build and
#: simulate in the fast tier above, and the chain's script takes the same path there.
SLOW_SCRIPTS = {"capstan_winch", "cartpole", "double_pendulum", "heavy_top", "slider_crank", "tensegrity"}


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.slow) if p.stem in SLOW_SCRIPTS else p
                                  for p in SCRIPTS], ids=[p.stem for p in SCRIPTS])
def test_script_runs_as_written(tmp_path, path):
    """Run from a scratch directory (the scripts write their plot to the current directory);
    generated C is compiled at -O0 to keep the test quick, into the run's compile cache (the
    models built above and the element library are compiled once)."""
    env = {**os.environ, "MPLBACKEND": "Agg", "NCGEN_CFLAGS": "-O0"}
    out = subprocess.run([sys.executable, str(path)], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert f"wrote {path.stem}.png" in out.stdout
    assert (tmp_path / f"{path.stem}.png").stat().st_size > 0


def test_chain_script_is_the_chain_file():
    sys.path.insert(0, str(EXAMPLES))
    try:
        from chain import chain
    finally:
        sys.path.remove(str(EXAMPLES))
    from ncgen.codegen.model_package import model_hash
    assert model_hash(chain(5).build()) == model_hash(nc.System.from_toml(EXAMPLES / "chain.toml").build())


# ------------------------------------------------------------------------ tensegrity
def cable_tensions(model, traj) -> np.ndarray:
    """Tension (N) of every cable per step, from the end points' positions."""
    p = dict(zip(model.parameter_names, model.p0))
    out = []
    for f in model.forces:
        ra, rb = traj.point(f.a.name, f.at_a), traj.point(f.b.name, f.at_b)
        rest = float(eval(f.rest_length, {}, p))                  # "L - c*tension/k_cable"
        out.append(p["k_cable"] * (np.linalg.norm(rb - ra, axis=1) - rest))
    return np.array(out).T


def test_tensegrity_is_in_self_equilibrium_without_gravity():
    """The 150° twisted prism with top/bottom : vertical : strut force densities
    1 : √3 : −√3 is an equilibrium: without gravity nothing accelerates."""
    model = load("tensegrity", **{"gravity = [0.0, 0.0, -9.81]": "gravity = [0.0, 0.0, 0.0]"}).build()
    assert np.max(np.abs(model.a0)) < 1e-9
    tensions = cable_tensions(model, nc.simulate(model, t_end=0.01, dt=0.01, backend="vm"))[0]
    assert np.allclose(tensions[:6], 20.0) and np.allclose(tensions[6:], 20.0 * np.sqrt(3) * 0.523560337801481
                                                            / 0.5196152422706631)


def test_tensegrity_stands_under_gravity():
    """With gravity (3 N against 20-35 N of pretension) it sags by about a millimetre and
    every cable stays taut."""
    model = nc.System.from_toml(EXAMPLES / "tensegrity.toml").build()
    traj = nc.simulate(model, t_end=1.0, dt=0.01, backend="vm")
    top = traj.marker("strut1.top")
    assert 1e-4 < np.max(np.abs(top - top[0])) < 3e-3
    assert np.min(cable_tensions(model, traj)) > 10.0


def test_pretension_stiffens_the_tensegrity():
    """The prism has an infinitesimal mechanism that only the pretension stiffens: with 1 %
    of it the top sags more than five times as far."""
    model = nc.System.from_toml(EXAMPLES / "tensegrity.toml").build()
    drop = {}
    for tension in (20.0, 0.2):
        traj = nc.simulate(model, t_end=1.0, dt=0.01, p={"tension": tension}, backend="vm")
        top = traj.marker("strut1.top")
        drop[tension] = top[0, 2] - top[:, 2].min()
    assert drop[0.2] > 5 * drop[20.0]


# ----------------------------------------------------------- energy over long runs
@pytest.mark.slow                                  # 20 s of IDAS at 1e-10
@pytest.mark.parametrize("name", ["chain", "double_pendulum"])
def test_energy_is_conserved_over_a_long_run(name):
    """Conservative systems, 20 s at rtol 1e-10: |E − E₀| stays below 2e-6 of the energy
    scale (measured: 3e-7 for the chain, 1.3e-7 for the double pendulum), while the motion
    exchanges the whole energy scale between kinetic and potential."""
    model = nc.System.from_toml(EXAMPLES / f"{name}.toml").build()
    traj = nc.simulate(model, t_end=20.0, dt=0.01, rtol=1e-10, atol=1e-12, backend="auto")
    assert np.ptp(traj.kinetic) > 0.5 * traj.energy_scale
    assert traj.energy_drift < 2e-6 * traj.energy_scale
    assert np.max(traj.constraint_residual) < 1e-7
