"""Second order on persistent sliding contact (nonsmooth stepper): a ball sliding while it
spins about the vertical goes straight, and a sliding ball's centre converges to the closed
form at order ≥ 2 in h.  Closed form (sphere sliding on a plane, μ, any spin): the slip
velocity of the contact point keeps its direction û and the centre decelerates at μ g û
until it rolls, ``x(t) = x0 + v0 t − μ g t² û / 2``."""
import numpy as np
import pytest

import ncgen as nc

G, R, M, MU = 9.81, 0.1, 1.0, 0.1
V0 = np.array([2.0, 0.0, 0.0])
W0 = np.array([5.0, 3.0, 20.0])
T_END = 0.4                                            # sliding lasts 0.52 s


@pytest.fixture(scope="module")
def sliders():
    s = nc.System("sliders")
    for name, y, w in (("spinner", 0.0, (0.0, 0.0, 20.0)), ("tumbler", 1.0, W0)):
        b = s.add_body(name, mass=M, inertia=0.4 * M * R ** 2 * np.eye(3), position=(0, y, R), velocity=V0,
                       angular_velocity=w)
        s.add_contact(nc.SpherePlane(b, radius=R, mu=MU, point=(0, y, 0), name=name))
    model = s.build(contacts="nonsmooth")
    return {sub: nc.simulate(model, T_END, 0.01, method="stepper", substeps=sub) for sub in (5, 10, 20)}


def _closed_form(t, w0, y):
    vc = V0 + np.cross(w0, [0, 0, -R])
    u = vc / np.linalg.norm(vc)
    return np.array([0, y, R]) + V0 * t[:, None] - MU * G * t[:, None] ** 2 / 2 * u


def test_ball_sliding_with_spin_about_the_vertical_goes_straight(sliders):
    """Friction along x, torque about y only: no sideways velocity, no spin about x (the
    tangential rows taken at the free step's end in both half-steps made it veer by
    6.6e-4 m/s at h = 1 ms, halving with h)."""
    for tr in sliders.values():
        x = tr.point("spinner", (0, 0, 0))
        np.testing.assert_allclose(x, _closed_form(tr.t, np.array([0, 0, 20.0]), 0.0), atol=1e-9)
        assert np.abs(tr.v[:, 1]).max() < 1e-9


def test_persistent_sliding_converges_at_second_order(sliders):
    errors = []
    for sub, tr in sliders.items():
        x = tr.point("tumbler", (0, 0, 0))
        errors.append(np.abs(x - _closed_form(tr.t, W0, 1.0)).max())
    rates = np.log2(np.array(errors[:-1]) / errors[1:])
    assert np.all(rates > 1.9), (errors, rates)
    assert errors[1] < 1e-9, errors                    # h = 1 ms
