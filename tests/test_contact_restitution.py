"""restitution= on a smooth (compliant) contact is honoured: the Hunt–Crossley damping is
fitted so that a normal impact at RESTITUTION_SPEED rebounds with e (checked here by IDAS
on the full model, against Newton's definition e = −v⁺/v⁻)."""
import pytest

import ncgen as nc
from ncgen.model.contacts import DAMPING, RESTITUTION_SPEED


def rebound(e, speed, **law):
    s = nc.System("drop", gravity=(0, 0, 0.0))
    ball = s.add_point("ball", mass=2.0, position=(0, 0, 0.1005), velocity=(0, 0, -speed))
    s.add_contact(nc.SpherePlane(ball, radius=0.1, restitution=e, **law))
    traj = nc.simulate(s.build(), 0.08, 2e-4, rtol=1e-9, atol=1e-12, backend="vm")
    assert traj.gap[-1, 0] > 0                      # apart again
    return traj.v[-1, 2] / speed


@pytest.mark.parametrize("e", [0.2, 0.5, 0.8])
def test_restitution_is_met_at_the_reference_speed(e):
    assert rebound(e, RESTITUTION_SPEED) == pytest.approx(e, abs=2e-3)


def test_faster_impacts_rebound_less_as_the_law_says():
    assert rebound(0.5, 2.0) < 0.5 < rebound(0.5, 0.5)


def test_explicit_damping_wins_and_is_documented_in_the_spec():
    c = nc.SpherePlane(nc.System("x").add_point("p", mass=1.0, position=(0, 0, 1)), radius=0.1, restitution=0.5, damping=123.0)
    assert c.damping == 123.0 and c.restitution == 0.5
    plain = nc.SpherePlane(nc.System("y").add_point("p", mass=1.0, position=(0, 0, 1)), radius=0.1)
    assert plain.damping == DAMPING and plain.restitution == 0.0
