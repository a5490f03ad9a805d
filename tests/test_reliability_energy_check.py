"""The stepper's energy check near zero energy (issue 35): a motion whose energy is of the
size of round-off (a slider at rest pushed by 1e-15 N) is no false alarm, since the energy
error is measured against at least what rounding the positions can make
(:func:`ncgen.runtime.stepper_checks.roundoff_energy`); a real energy error (an unstable
step) is still caught, and the contact-implicit block push replays with the checks on."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import SimulationError

ROOT = Path(__file__).resolve().parents[1]
K, MASS = 100.0, 1.0                  # the slider's spring (N/m) and mass (kg): ω = 10 rad/s


@pytest.fixture(scope="module")
def slider():
    """A point on a line through (1, 0), held at x = 1 m by a spring of rest length 1 m from
    the origin and pushed along the line by the input ``push`` (N)."""
    s = nc.System("slider", gravity=(0.0, -9.81))
    p = s.add_point("p", mass=MASS, position=(1.0, 0.0))
    s.add_joint(nc.PointOnLine(s.ground, p, at=(1.0, 0.0), axis=(1.0, 0.0)))
    push = s.add_input("push")
    s.add_force(nc.PointForce(p, (0, 0), force=ca.vertcat(push, 0)))
    s.add_force(nc.Spring(s.ground, (0, 0), p, (0, 0), k=K, rest_length=1.0))
    return s.build()


@pytest.mark.parametrize("push", [1e-15, 1e-13, 1e-10, 1e-8])
def test_a_motion_at_round_off_energy_is_no_false_alarm(slider, push):
    """Pushed by a constant ``F``, the slider moves by ``(F/k)(1 − cos ωt)``, from less than
    one unit in the last place of x = 1 m to ~1e5 of them: its energy (1e-32 to 1e-18 J) is
    at the level of round-off (gravity's potential alone, on y held at 0 to round-off, is
    off by ~2e-18 J), and the energy balance used to be flagged at relative error 1 at the
    first output time.  It runs checked.  Its momentum obeys the impulse bound
    ``|m v| ≤ (F + k max|x − 1|) t`` (the largest force along the line); where the amplitude
    is thousands of units in the last place of x, the velocity follows the closed form
    ``F/(m ω) sin ωt`` to 5 % (x's increments are rounded, ~1e-16 m each of 2000 steps)."""
    traj = nc.simulate(slider, 2.0, 0.01, u=lambda t: [push], method="stepper", substeps=10)
    assert traj.info["complete"] and traj.info["energy"]["relative"] <= 0.01     # the report agrees (it said 1)
    stretch = np.max(np.abs(traj.q[:, 0] - 1.0))
    assert stretch <= 2 * push / K + 2000 * np.finfo(float).eps
    assert np.all(np.abs(MASS * traj.v[:, 0]) <= (push + K * stretch) * traj.t * (1 + 1e-9))
    w = np.sqrt(K / MASS)
    if push / K > 1000 * np.finfo(float).eps:
        exact = push / (MASS * w) * np.sin(w * traj.t)
        assert np.max(np.abs(traj.v[:, 0] - exact)) < 0.05 * push / (MASS * w)


def test_a_real_energy_error_is_still_caught(slider):
    """RATTLE is unstable for h ω > 2: at h = 0.25 s the pushed slider's energy grows (about
    fourfold a step), and the check stops the run within its first output times, tiny push or
    not.  Pushed by 1e-10 N the energy starts at 1e-22 J, inside the round-off floor of the
    check (gravity's potential on y = 0 held to round-off), and is caught once the growth lifts
    it out: by t = 1.5 s (6 steps) where y stays exactly 0 (the element tables' solve), at once
    where y carries round-off (the flat kernels)."""
    for push, within in ((1.0, r"0.(25|5|75)"), (1e-10, r"(0.25|0.5|0.75|1|1.25|1.5)")):
        with pytest.raises(SimulationError, match=r"energy balance E - E0 - W .* is off by .* of its energy scale "
                                                  rf"by t = {within} s") as err:
            nc.simulate(slider, 5.0, 0.25, u=lambda t: [push], method="stepper", substeps=1, scheme="rattle",
                        estimate=False)
        assert len(err.value.trajectory.t) <= (3 if push == 1.0 else 7)


def test_block_push_replays_checked():
    """The optimal push of examples/block_push.py (the block rests under a push of
    round-off size before and after it slides) replays with the stepper's checks on, within
    1e-6 m of the optimum at every node."""
    spec = importlib.util.spec_from_file_location("block_push", ROOT / "examples" / "block_push.py")
    ex = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ex)
    model = ex.build()
    sol = ex.problem(model, 1.0).solve("rest")
    assert np.any(np.abs(sol.u[:ex.N, 0]) < 1e-9)            # rests under a round-off push somewhere
    sim = ex.replay(model, sol)
    assert sim.info["complete"]
    assert np.max(np.abs(sim.q[:, 0] - sol.q[:, 0])) < 1e-6
