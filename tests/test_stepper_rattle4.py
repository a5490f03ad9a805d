"""The stepper's fourth-order fixed-step scheme (``scheme="rattle4"``: the symmetric triple
jump of RATTLE steps): order 4 against an independent reference (the joint-space DOPRI5
loop at tight tolerances), the shadow run's error estimate, bounded energy over a long
conservative run, both constraint levels, and the refusals."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import ncgen as nc

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def pendulum():
    return nc.System.from_toml(ROOT / "examples" / "double_pendulum.toml").build()


def test_rattle4_is_fourth_order_with_a_working_error_estimate(pendulum):
    ref = nc.simulate(pendulum, 1.0, 0.1, method="joint", rtol=1e-13, atol=1e-14)
    errors = []
    for substeps in (40, 80, 160):
        traj = nc.simulate(pendulum, 1.0, 0.1, method="stepper", substeps=substeps, scheme="rattle4")
        assert traj.info["scheme"] == "RATTLE, triple-jump composition" and traj.info["order"] == 4
        error = np.abs(traj.q[-1] - ref.q[-1]).max()
        errors.append(error)
        estimate = traj.info["error_estimate"]["q"]
        assert 0.3 * error < estimate < 3 * error, (substeps, estimate, error)
        assert traj.constraint_residual.max() < 1e-10 and traj.velocity_residual.max() < 1e-10
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 14) & (ratios < 18)), ratios          # 2^4 per halving of h
    rattle = nc.simulate(pendulum, 1.0, 0.1, method="stepper", substeps=160)
    assert np.abs(rattle.q[-1] - ref.q[-1]).max() > 100 * errors[-1]


def test_rattle4_keeps_the_energy_of_a_conservative_chain_bounded():
    chain = nc.System.from_toml(ROOT / "examples" / "chain.toml").build()
    traj = nc.simulate(chain, 100.0, 0.05, method="stepper", substeps=20, scheme="rattle4", check=False,
                       estimate=False)
    assert traj.info["energy"]["conservative"]
    drift = np.abs(traj.energy - traj.energy[0])
    fifth = len(drift) // 5
    assert drift.max() < 1e-3 * np.abs(traj.kinetic).max(), drift.max()
    assert drift[-fifth:].max() < 3 * drift[:fifth].max(), (drift[:fifth].max(), drift[-fifth:].max())
    assert traj.constraint_residual.max() < 1e-10 and traj.velocity_residual.max() < 1e-10
    assert traj.info["stats"]["step_splits"] == 0


def test_rattle4_refusals(pendulum):
    with pytest.raises(nc.NcgenError, match="scheme: expected one of rattle, rattle4"):
        nc.SimulationOptions(scheme="rk4")
    with pytest.raises(nc.NcgenError, match="scheme: 'rattle4' is a fixed-step scheme"):
        nc.simulate(pendulum, 0.1, 0.1, method="stepper", rtol=1e-6, scheme="rattle4")
    s = nc.System("drop")
    point = s.add_point("ball", mass=1.0, position=(0, 0, 1.0))
    s.add_contact(nc.SpherePlane(point, radius=0.0, name="floor"))
    with pytest.raises(nc.NcgenError, match="scheme: 'rattle4' needs a smooth model; 'drop' has nonsmooth"):
        nc.simulate(s.build(contacts="nonsmooth"), 0.1, 0.01, method="stepper", scheme="rattle4")
