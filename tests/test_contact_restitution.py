"""restitution= on a smooth (compliant) contact is honoured: the Hunt–Crossley damping is
fitted so that a normal impact at RESTITUTION_SPEED rebounds with e (checked here by IDAS
on the full model, against Newton's definition e = −v⁺/v⁻)."""
import pytest
from scipy.integrate import solve_ivp

import ncgen as nc
from ncgen.model.contacts import DAMPING, RESTITUTION_SPEED, damping_for_restitution, restitution_zeta


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


def scaled_rebound(zeta, n):
    """Rebound speed of the scaled impact ``y'' = −yⁿ (1 + ζ y')⁺``, ``y(0) = 0, y'(0) = 1``,
    integrated until the force vanishes while moving out."""
    def rhs(_, x):
        return [x[1], -max(x[0], 0.0) ** n * max(1.0 + zeta * x[1], 0.0)]

    def apart(_, x):
        return min(x[0], 1.0 + zeta * x[1]) if x[1] < 0 else 1.0
    apart.terminal, apart.direction = True, -1
    sol = solve_ivp(rhs, (0.0, 100.0), [0.0, 1.0], events=apart, method="LSODA", rtol=1e-11, atol=1e-13)
    return -sol.y[1, -1]


@pytest.mark.parametrize("n", [1.0, 1.5, 2.0])
@pytest.mark.parametrize("e", [0.01, 0.2, 0.5, 0.8, 0.99])
def test_zeta_is_the_integrated_impact_s_for_every_exponent(e, n):
    """The closed form's ζ (no integration) rebounds the scaled impact, integrated numerically,
    with e, for each exponent; and d = ζ k / v."""
    zeta = restitution_zeta(e)
    assert scaled_rebound(zeta, n) == pytest.approx(e, rel=1e-7)
    assert damping_for_restitution(2e5, e, n) == 2e5 * zeta / RESTITUTION_SPEED


def test_restitution_one_and_below_the_fitted_minimum():
    assert restitution_zeta(1.0) == 0.0
    assert damping_for_restitution(1e6, 0.0) == damping_for_restitution(1e6, 0.01)
