"""The frictional contact solve (semismooth Newton on the Coulomb cone, ``cone_newton`` in
templates/c/runtime/ncgen_cone_newton.h, after projected Gauss–Seidel's first 4 sweeps, with
Levenberg–Marquardt steps where Newton's give no descent, and the least-norm impulses where
the support is statically indeterminate) on the cases that made Gauss–Seidel stop at its
sweep limit: a box landing flat on its four corners, a resting pyramid of spheres with
friction, a dropped heap; and a ball resting on a crate, whose contact opened and closed
by round-off while the crate fell into its own floor contact.  The forces match statics (a
box's corners carry a quarter of its weight each, a pyramid's floor the weight of all
five spheres, the ball its weight at every step); no solve stops at the limit and the
contact laws hold at every step's impulses (``info["contacts"]["cone_residual"]``)."""
import warnings

import numpy as np
import pytest

import ncgen as nc
from energy_helpers import assert_no_energy_created

G, R, M, MU = 9.81, 0.03, 0.2, 0.5
BOX = (0.4, 0.3, 0.2)
QUICK_COMPILE = True             # its time is gcc compiling its scenes: -O0 (tests/conftest.py)


def _run(model, t_end, strict=True):
    with warnings.catch_warnings():
        warnings.simplefilter("error" if strict else "ignore")   # a solve at the sweep limit warns
        return nc.simulate(model, t_end, 0.01, method="stepper", substeps=10)


#: The tests of the landing scenes below run in the slow tier (a compile and a 1 s run of two
#: frictional scenes); the same solver in the fast tier: the five-box frictional stack
#: (tests/test_contact_shapes_pairs.py), the dropped cubes with friction
#: (tests/test_contact_edges.py), the ball on a crate below and tests/c/test_cone_newton.c.
SCENES = pytest.mark.slow


@pytest.fixture(scope="module")
def scenes():
    s = nc.System("cone_scenes")
    a, b, c = BOX
    box = s.add_body("box", mass=2.0, inertia=2.0 / 12 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b]),
                     position=(0, 0, c / 2 + 0.05), angular_velocity=(0, 0, 1.0))
    s.add_contact(nc.BoxPlane(box, size=BOX, mu=MU, name="box"))
    # a pyramid with friction, 3 m away: four spheres touching in a square, one on top
    base = [np.array([3 + dx * R, dy * R, R]) for dx in (-1, 1) for dy in (-1, 1)]
    top = np.array([3, 0, R + np.sqrt(2) * R])
    balls = [s.add_body(f"p{k}", mass=M, inertia=0.4 * M * R ** 2 * np.eye(3), position=tuple(x))
             for k, x in enumerate([*base, top])]
    for k, ball in enumerate(balls):
        s.add_contact(nc.SpherePlane(ball, None, R, mu=MU, name=f"p{k}_floor"))
    for i in range(5):
        for j in range(i + 1, 5):
            s.add_contact(nc.SphereSphere(balls[i], None, R, balls[j], None, R, mu=MU, name=f"p{i}_{j}"))
    model = s.build(contacts="nonsmooth")
    return model, _run(model, 1.0, strict=False)


@SCENES
def test_box_landing_flat_and_pyramid_with_friction_converge_every_solve(scenes):
    _, tr = scenes
    assert tr.info["contacts"]["pgs_unconverged"] == 0
    assert tr.info["contacts"]["cone_residual"] < 1e-9
    top = tr.point("p4", (0, 0, 0))                   # no creep of the pyramid
    np.testing.assert_allclose(top, [[3, 0, R + np.sqrt(2) * R]] * len(top), atol=1e-9)


@SCENES
def test_box_landing_flat_with_friction_rests_on_a_quarter_of_its_weight_per_corner(scenes):
    model, tr = scenes
    rest = tr.t > 0.5
    f = np.array([tr.contact_normal[rest, tr.contact_names.index(f"box.corner{i}")] for i in range(8)]).T
    corners = np.array([tr.point("box", [(1 if i >> j & 1 else -1) * BOX[j] / 2 for j in range(3)])[rest]
                        for i in range(8)])                    # (corner, time, xyz)
    assert np.all(f[:, corners[:, 0, 2] > 0.1] == 0)           # the top corners carry nothing
    np.testing.assert_allclose(f.sum(axis=1), 2.0 * G, rtol=1e-9)
    # four coplanar supports are statically indeterminate: the weight and the two moments
    # about the centre fix three combinations of the corner forces exactly
    centre = tr.point("box", (0, 0, 0))[rest]
    moment = np.einsum("tk,ktx->tx", f, corners[:, :, :2] - centre[None, :, :2])
    np.testing.assert_allclose(moment, 0, atol=1e-9)
    # the least-norm distribution (cone_min_norm): a quarter of the weight on each corner
    np.testing.assert_allclose(f[:, corners[:, 0, 2] < 0.1], 2.0 * G / 4, rtol=1e-9)
    # it landed spinning at 1 rad/s about the vertical: friction stopped it
    assert np.abs(tr.v[tr.t > 0.6, :3]).max() < 1e-9


@SCENES
def test_pyramid_with_friction_rests_on_its_closed_form_geometry(scenes):
    """The top sphere stays on the four below near height R + √2 R (to 1e-3 m: the solves
    that stop at the sweep limit let it creep by tens of µm, see the expected failure
    above, which asks 1e-9), and the floor carries the weight of all five (how the four
    base spheres share it, and the friction forces, are statically indeterminate)."""
    _, tr = scenes
    top = tr.point("p4", (0, 0, 0))
    np.testing.assert_allclose(top, [[3, 0, R + np.sqrt(2) * R]] * len(top), atol=1e-3)
    for k in range(4):
        np.testing.assert_allclose(tr.point(f"p{k}", (0, 0, 0))[-1, 2], R, atol=1e-8)
    floor = [tr.contact_names.index(f"p{k}_floor") for k in range(4)]
    f = tr.contact_normal[:, floor]
    np.testing.assert_allclose(f[tr.t > 0.1].sum(axis=1).mean(), 5 * M * G, rtol=1e-3)


@pytest.mark.slow      # 8 spheres, 36 pairs; fast: the box landing and the pyramid with friction above
def test_dropped_heap_with_friction_converges_every_solve():
    """Eight spheres with friction dropped in a loose column onto the floor: no solve stops
    at the sweep limit, the contact laws hold to 1e-9 of the velocities at every step's
    impulses, no step ends inside by more than the push-out tolerance, energy never rises."""
    rng = np.random.default_rng(3)
    s = nc.System("cone_heap")
    balls = []
    for k in range(8):
        layer, slot = divmod(k, 4)
        x = np.array([1.2 * R * (1 if slot & 1 else -1), 1.2 * R * (1 if slot & 2 else -1), R * (1.5 + 2.4 * layer)])
        x[:2] += rng.uniform(-0.005, 0.005, 2)
        balls.append(s.add_body(f"b{k}", mass=M, inertia=0.4 * M * R ** 2 * np.eye(3), position=tuple(x)))
    for k, b in enumerate(balls):
        s.add_contact(nc.SpherePlane(b, None, R, mu=MU, name=f"floor{k}"))
    for i in range(8):
        for j in range(i + 1, 8):
            s.add_contact(nc.SphereSphere(balls[i], None, R, balls[j], None, R, mu=MU, name=f"pair{i}_{j}"))
    tr = _run(s.build(contacts="nonsmooth"), 1.0)
    report = tr.info["contacts"]
    assert report["pgs_unconverged"] == 0
    assert report["cone_residual"] < 1e-9, report
    assert report["penetration"] <= report["penetration_tol"]
    assert_no_energy_created(tr, 1e-9)


def test_ball_on_a_crate_gets_its_weight_at_every_step():
    """A ball resting on a crate resting on the floor (h = 1 ms, one output per step): the
    crate and the ball fall together in the free step, so the gap between them stays 0 to
    round-off, and a frictional contact open by 1e-17 m was left out of the step while the
    floor stopped the crate: the ball then fell through by g h² and got twice its weight
    next step (0, 2 m g, 0, 2 m g, ... after the first steps).  Contacts about to close take
    part with friction as well now: the impulse is m g h from the first step on."""
    crate_size, m_crate, m_ball, r = np.array([0.2, 0.3, 0.1]), 2.0, 0.5, 0.05
    a, b, c = crate_size
    s = nc.System("ball_on_crate")
    crate = s.add_body("crate", mass=m_crate, inertia=m_crate / 12 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b]),
                       position=(0, 0, c / 2))
    s.add_contact(nc.BoxPlane(crate, size=tuple(crate_size), mu=0.5, name="floor"))
    ball = s.add_body("ball", mass=m_ball, inertia=0.4 * m_ball * r * r * np.eye(3), position=(0.03, 0.02, c + r))
    s.add_contact(nc.SphereBox(ball, radius=r, box=crate, size=tuple(crate_size), mu=0.5, name="ball_crate"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")                 # the crate's face: redundant corners
        tr = nc.simulate(s.build(contacts="nonsmooth"), 0.2, 0.001, method="stepper", substeps=1)
    np.testing.assert_allclose(tr.contact_normal[1:, tr.contact_names.index("ball_crate")], m_ball * G, rtol=1e-9)
    floor = [k for k, name in enumerate(tr.contact_names) if name.startswith("floor.")]
    np.testing.assert_allclose(tr.contact_normal[1:, floor].sum(axis=1), (m_crate + m_ball) * G, rtol=1e-9)
    np.testing.assert_allclose(tr.point("ball", (0, 0, 0)), [[0.03, 0.02, c + r]] * len(tr.t), atol=1e-9)
    assert_no_energy_created(tr, 1e-9)
