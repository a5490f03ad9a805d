"""The frictional contact solve (semismooth Newton on the Coulomb cone, ``cone_newton`` in
templates/c/runtime/ncgen_cone_newton.h, after projected Gauss–Seidel's first 32 sweeps) on
the cases that made Gauss–Seidel stop at its sweep limit: a box landing flat on its four
corners, a resting pyramid of spheres with friction, a dropped heap.  The forces match
statics (a box's corners carry its weight with no moment, a pyramid's floor the weight of
all five spheres); the heap has no solve at the limit and its contact laws hold at every
step's impulses (``info["contacts"]["cone_residual"]``); the box and the pyramid still have
some (an expected failure, see its reason)."""
import warnings

import numpy as np
import pytest

import ncgen as nc

G, R, M, MU = 9.81, 0.03, 0.2, 0.5
BOX = (0.4, 0.3, 0.2)


def _run(model, t_end, strict=True):
    with warnings.catch_warnings():
        warnings.simplefilter("error" if strict else "ignore")   # a solve at the sweep limit warns
        return nc.simulate(model, t_end, 0.01, method="stepper", substeps=10)


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


@pytest.mark.xfail(reason="cone_newton runs only after 32 sweeps (CONE_FIRST): started there it finds no descent on "
                          "some of the landing box's and the pyramid's solves, which stop at the sweep limit; started "
                          "after 4 it converged here but made a ball resting on a crate alternate between 0 and twice "
                          "its weight per step (tests/test_contact_shapes_pairs.py)", strict=False)
def test_box_landing_flat_and_pyramid_with_friction_converge_every_solve(scenes):
    _, tr = scenes
    assert tr.info["contacts"]["pgs_unconverged"] == 0
    assert tr.info["contacts"]["cone_residual"] < 1e-9
    top = tr.point("p4", (0, 0, 0))                   # no creep of the pyramid
    np.testing.assert_allclose(top, [[3, 0, R + np.sqrt(2) * R]] * len(top), atol=1e-9)


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
    np.testing.assert_allclose(f[:, corners[:, 0, 2] < 0.1], 2.0 * G / 4, rtol=0.05)
    # it landed spinning at 1 rad/s about the vertical: friction stopped it
    assert np.abs(tr.v[tr.t > 0.6, :3]).max() < 1e-9


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
    assert np.max(tr.energy - tr.energy[0]) < 1e-9
