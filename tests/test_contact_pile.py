"""Piles of frictionless spheres in the nonsmooth contact stepper: redundant contact sets.

A pile is full of redundant contacts (a sphere held by more contacts than it has degrees of
freedom), on which projected Gauss–Seidel alone crawls; the stepper finishes its sweeps with
Newton steps on the contacts that carry an impulse (``lcp_newton`` in ``templates/c/runtime/ncgen_contact.h``).
A frictionless contact about to close (open after the free step, but closed within it by
its neighbours' impulses) takes part in the step's contact problem (``contact_step``).
References: statics (the floor carries the whole weight), the closed-form rest geometry, the
push-out's stated tolerance, energy that never rises (restitution 0), and the closed-form
perfectly inelastic impact of a row of spheres.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

import ncgen as nc
from energy_helpers import assert_no_energy_created

R, M, G = 0.03, 0.1, 9.81
#: The push-out's tolerance (m): no step may end deeper than this (PENETRATION_TOL).
PENETRATION_TOL = 1e-8


def box_walls(b: float):
    """Floor z = 0 and four walls at |x|, |y| = b, normals inwards."""
    return [((0, 0, 0), (0, 0, 1)), ((-b, 0, 0), (1, 0, 0)), ((b, 0, 0), (-1, 0, 0)),
            ((0, -b, 0), (0, 1, 0)), ((0, b, 0), (0, -1, 0))]


def sphere_pile(name: str, centres, b: float):
    """Point members of mass M, radius R, in the box of half-width b, every pair in contact."""
    s = nc.System(name, gravity=(0, 0, -G))
    balls = [s.add_point(f"ball{k}", mass=M, position=tuple(c)) for k, c in enumerate(centres)]
    for k, ball in enumerate(balls):
        for w, (point, normal) in enumerate(box_walls(b)):
            s.add_contact(nc.SpherePlane(ball, None, R, point=point, normal=normal, name=f"wall{w}_{k}"))
    for i in range(len(balls)):
        for j in range(i + 1, len(balls)):
            s.add_contact(nc.SphereSphere(balls[i], None, R, balls[j], None, R, name=f"pair{i}_{j}"))
    return s.build(contacts="nonsmooth")


def test_pyramid_at_rest_carries_its_weight_on_the_floor():
    """Four spheres in the corners of a box of half-width 2R (each on the floor and two
    walls) and a fifth on top of them: its centres lie 45° above theirs, so it rests at
    z = R (1 + √2).  Every sphere has 4 contacts for 3 degrees of freedom.  Held for 0.2 s:
    the floor's normal forces add up to the total weight (statics) to 1e-6 relative, no
    sphere moves from the closed-form configuration by more than 1e-9 m, no step ends
    deeper than the push-out tolerance, and every contact solve converges."""
    b = 2 * R
    centres = [(sx * R, sy * R, R) for sx in (-1, 1) for sy in (-1, 1)] + [(0, 0, R * (1 + np.sqrt(2)))]
    model = sphere_pile("pyramid5", centres, b)
    tr = nc.simulate(model, 0.2, 0.01, method="stepper", substeps=10)               # h = 1 ms
    floor = [k for k, name in enumerate(model.contact_names) if name.startswith("wall0_")]
    total = tr.contact_normal[1:, floor].sum(axis=1)
    np.testing.assert_allclose(total, 5 * M * G, rtol=1e-6)
    np.testing.assert_allclose(tr.q, np.tile(np.ravel(centres), (len(tr.t), 1)), rtol=0, atol=1e-9)
    assert tr.info["contacts"]["penetration"] <= PENETRATION_TOL
    assert tr.info["contacts"]["pgs_unconverged"] == 0


def test_dropped_pile_never_sinks_in_nor_gains_energy():
    """The benchmark's pile of 8 spheres (benchmarks/contact.py) dropped into its box for
    0.4 s at h = 1 ms: impacts, then a pile with redundant contacts.  No step ends deeper
    than the push-out tolerance (before the Newton steps the push-out's Gauss–Seidel left
    up to 2.5e-4 m in the pile of 20), the energy never rises above its start (restitution
    0, no friction: contacts only dissipate), and every contact solve converges."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    try:
        import contact as bench
    finally:
        sys.path.pop(0)
    model = sphere_pile("dropped8", bench.ball_centres(8), bench.BOX)
    tr = nc.simulate(model, 0.4, 0.01, method="stepper", substeps=10)
    assert tr.info["contacts"]["penetration"] <= PENETRATION_TOL
    assert -tr.gap.min() <= PENETRATION_TOL
    assert_no_energy_created(tr, 1e-9 * abs(tr.energy[0]))
    assert tr.energy[-1] < tr.energy[0] - 0.1                       # the impacts dissipated
    assert tr.info["contacts"]["pgs_unconverged"] == 0


def test_row_of_spheres_struck_moves_as_one_in_the_impact_step():
    """Three equal spheres on a line without gravity: B and C at rest, 1e-7 m apart; A
    strikes B at v = 1 m/s, restitution 0.  Perfectly inelastic (closed form): all three end
    at v/3, momentum M v is kept and kinetic energy M v²/3 is lost.  C's contact is still
    open at the end of the impact step's free step, but B's push closes it within the step:
    the stepper takes it into that step's contact problem (a contact about to close), so C
    already moves at v/3 (to 1e-3: the 1e-7 m gap closes at 2e-4 m/s) when the impact step
    ends, instead of being pushed out of B afterwards.  No step ends deeper than the
    push-out tolerance, and every solve converges."""
    v, h, gap = 1.0, 1e-3, 1e-7
    s = nc.System("row3", gravity=(0, 0, 0))
    xs = (-2 * R - 0.5 * v * h, 0.0, 2 * R + gap)              # A closes on B within the first step
    balls = [s.add_point(f"ball{k}", mass=M, position=(x, 0, 0), velocity=(v if k == 0 else 0, 0, 0))
             for k, x in enumerate(xs)]
    for i, j in ((0, 1), (1, 2), (0, 2)):
        s.add_contact(nc.SphereSphere(balls[i], None, R, balls[j], None, R, name=f"pair{i}_{j}"))
    model = s.build(contacts="nonsmooth")
    one = nc.simulate(model, h, h, method="stepper")                 # the impact step alone
    vx = one.v[-1, 0::3]
    np.testing.assert_allclose(vx, v / 3, rtol=1e-3)
    tr = nc.simulate(model, 0.05, 0.01, method="stepper", substeps=10)
    vx = tr.v[-1, 0::3]
    np.testing.assert_allclose(vx, v / 3, rtol=1e-9)
    np.testing.assert_allclose(M * vx.sum(), M * v, rtol=1e-12)
    np.testing.assert_allclose(tr.energy[0] - tr.energy[-1], M * v**2 / 3, rtol=1e-9)
    assert tr.info["contacts"]["penetration"] <= PENETRATION_TOL
    assert tr.info["contacts"]["pgs_unconverged"] == 0
