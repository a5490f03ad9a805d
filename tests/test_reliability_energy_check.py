"""The stepper's energy check near zero energy (issue 35): a motion whose energy is of the
size of round-off (a slider at rest pushed by 1e-15 N) is no false alarm, since the energy
error is measured against at least what rounding the positions can make
(:func:`ncgen.runtime.stepper_checks.roundoff_energy`); a real energy error (an unstable
step) is still caught, and the contact-implicit block push replays with the checks on.  With
nonsmooth contacts the floor also holds what the contact solves' velocity tolerance lets the
contacts do (a block at the origin creeping at 1e-13 m/s under a push of 1e-12 N that
reverses), and an unstable step is still caught there."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import SimulationError
from ncgen.codegen.stepper_package import PGS_TOL, REPEAT_TOL
from ncgen.runtime import stepper_checks

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


G, BLOCK = 9.81, 2.0                  # gravity (m/s²) and the block's mass (kg)


def block_on_floor(name, mu, k=None):
    """A point block of 2 kg at the origin resting on the floor y = 0 (nonsmooth contact of
    radius 0, friction ``mu``), pushed along x by the input ``push`` (N), and held at x = 0 by
    a spring of stiffness ``k`` (N/m) from (−1, 0), rest length 1 m, if given."""
    s = nc.System(name, gravity=(0.0, -G))
    b = s.add_point("block", mass=BLOCK, position=(0.0, 0.0))
    push = s.add_input("push")
    s.add_force(nc.PointForce(b, (0, 0), force=ca.vertcat(push, 0)))
    if k is not None:
        s.add_force(nc.Spring(s.ground, (-1.0, 0.0), b, (0, 0), k=k, rest_length=1.0))
    s.add_contact(nc.SpherePlane(b, radius=0.0, mu=mu, name="floor"))
    return s.build(contacts="nonsmooth")


@pytest.fixture(scope="module")
def block():
    return block_on_floor("block_at_origin", mu=0.5)


def reversing_push(force):
    """``force`` (N) held over each 0.05 s output interval of 1 s, its sign reversing at
    t = 0.05 s and again every few intervals (as the optimal push of examples/block_push.py
    before the block starts, -2.8e-12 then 3e-12 N)."""
    return force * np.array([-1.0, 1, 1, -1, 1] * 4 + [1])[:, None]


@pytest.mark.parametrize("force", [1e-14, 1e-12, 3e-12, 1e-11])
def test_a_block_at_the_origin_under_a_reversing_round_off_push_is_no_false_alarm(block, force, monkeypatch):
    """Friction (μ m g = 9.8 N) holds the block; where the push reverses, the stepper keeps
    the last step's friction impulse as long as the contact laws hold to the contact solves'
    tolerance τ (1 + max|U|) m/s (τ = 1e-12), so the block creeps with friction pushing it:
    a kinetic energy of ~1e-26 J, half its energy scale, where the positions' round-off
    floor is ~0 (max|q| ~ 1e-15 m at the origin) and the check raised.  It now runs checked:
    the contacts' work is measured against at least τ h N max‖F‖₁.  Independent bounds: the
    contact velocity stays within the tolerance, the block within τ t of the origin, and
    the energy the contacts made (E − E0 less the push's work) within that floor.  With the
    contact term taken out of the floor (τ = 0) the check raises again (the cause)."""
    U = reversing_push(force)
    traj = nc.simulate(block, 1.0, 0.05, u=U, hold="zoh", method="stepper", substeps=10)
    assert traj.info["complete"]
    tol = max(PGS_TOL, REPEAT_TOL)
    assert np.max(np.abs(traj.v)) <= tol * (1 + 1e-9)
    assert np.all(np.abs(traj.q[:, 0]) <= tol * traj.t + 1e-30) and np.all(traj.q[:, 1] == 0)
    steps = 10 * np.arange(1, len(traj.t))                              # 10 steps of 5 ms per output interval
    floor = tol * 0.005 * steps * (BLOCK * G + force)                   # τ h N ‖F‖₁ at rest
    works = traj.info["energy"]["works"]
    contacts = sum(np.asarray(works[k]) for k in ("contacts", "friction", "push_out"))
    made = traj.energy - traj.energy[0] - (np.asarray(works["total"]) - contacts)   # the contacts' doing
    assert np.all(made[1:] <= floor)
    monkeypatch.setattr(stepper_checks, "PGS_TOL", 0.0)
    monkeypatch.setattr(stepper_checks, "REPEAT_TOL", 0.0)
    with pytest.raises(SimulationError, match=r"rose through its contacts by .* of its energy scale by t = 0.1 s"):
        nc.simulate(block, 1.0, 0.05, u=U, hold="zoh", method="stepper", substeps=10)


@pytest.mark.parametrize("x0", [1e-3, 1e-13])
def test_an_unstable_step_with_contacts_is_still_caught(x0):
    """A block on the floor held by a spring of 5e5 N/m (ω = 500 rad/s), started x0 off its
    rest position: at h = 5 ms (h ω = 2.5 > 2) RATTLE is unstable, x grows fourfold a step
    (λ + 1/λ = 2 − (h ω)²), and the energy sixteenfold.  The contact check (one-sided, against
    at least the floor of the contact solves' tolerance, here ~1e-12 J) stops the run at the
    first step for x0 = 1 mm (0.25 J), and for x0 = 1e-13 m (2.5e-21 J) once the growth passes
    the floor: 8 to 11 steps.  At h = 1 ms (h ω = 0.5) the same motions run checked, their
    amplitude within 5 % of x0 (RATTLE's is within 1/sqrt(1 − (h ω / 2)²) = 1.03 of it)."""
    model = block_on_floor("block_spring", mu=0.0, k=5e5)
    q0 = model.q0.copy()
    q0[0] = x0
    within = "0.005" if x0 > 1e-6 else r"0.0(4|45|5|55)"
    caught = rf"rose through its contacts by .* of its energy scale by t = {within} s"
    with pytest.raises(SimulationError, match=caught):
        nc.simulate(model, 0.2, 0.005, q0=q0, u=lambda t: [0.0], method="stepper", substeps=1)
    traj = nc.simulate(model, 0.2, 0.001, q0=q0, u=lambda t: [0.0], method="stepper", substeps=1)
    assert traj.info["complete"]
    assert np.max(np.abs(traj.q[:, 0])) <= 1.05 * x0
