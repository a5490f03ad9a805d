"""Second order on persistent sliding and rolling contact (nonsmooth stepper): a ball sliding
while it spins about the vertical goes straight, a sliding ball's centre and a rolling ball's
centre converge to the closed form at order ≥ 2 in h.  Closed form (sphere sliding on a
plane, μ, any spin): the slip velocity of the contact point keeps its direction û and the
centre decelerates at μ g û until it rolls, ``x(t) = x0 + v0 t − μ g t² û / 2``; rolling: see
:func:`test_persistent_rolling_converges_at_second_order`."""
import numpy as np
import pytest

import ncgen as nc

G, R, M, MU = 9.81, 0.1, 1.0, 0.1
QUICK_COMPILE = True             # its time is gcc compiling its scenes: -O0 (tests/conftest.py)
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


TH = 0.3                                               # incline (rad), rolling needs μ ≥ 2/7 tan θ
N_INCLINE = np.array([-np.sin(TH), 0.0, np.cos(TH)])
V_SIDE = np.array([0.0, 1.0, 0.0])                     # across the slope, rolling from the start


@pytest.fixture(scope="module")
def roller():
    """A ball rolling down a 0.3 rad incline (μ = 1) while it crosses the slope at 1 m/s and
    spins at 20 rad/s about the normal: its rows of the contact Jacobian turn with it."""
    s = nc.System("roller")
    w0 = np.cross(N_INCLINE, V_SIDE) / R + 20.0 * N_INCLINE
    b = s.add_body("ball", mass=M, inertia=0.4 * M * R ** 2 * np.eye(3), position=tuple(R * N_INCLINE),
                   velocity=tuple(V_SIDE), angular_velocity=tuple(w0))
    s.add_contact(nc.SpherePlane(b, radius=R, mu=1.0, point=(0, 0, 0), normal=tuple(N_INCLINE), name="roller"))
    model = s.build(contacts="nonsmooth")
    return {sub: nc.simulate(model, T_END, 0.01, method="stepper", substeps=sub) for sub in (5, 10, 20)}


def test_persistent_rolling_converges_at_second_order(roller):
    """Closed form: a rolling sphere's centre accelerates at 5/7 of gravity's component in the
    plane, whatever its spin, x(t) = x0 + v0 t + 5/14 g_t t² (g_t = −g sin θ (cos θ, 0, sin θ))."""
    g_t = -G * np.sin(TH) * np.array([np.cos(TH), 0.0, np.sin(TH)])
    errors = []
    for tr in roller.values():
        exact = R * N_INCLINE + V_SIDE * tr.t[:, None] + 5 / 14 * g_t * tr.t[:, None] ** 2
        errors.append(np.abs(tr.point("ball", (0, 0, 0)) - exact).max())
        assert tr.info["contacts"]["pgs_unconverged"] == 0
    rates = np.log2(np.array(errors[:-1]) / errors[1:])
    assert np.all(rates > 1.9), (errors, rates)
    assert errors[1] < 1e-6, errors                    # h = 1 ms


@pytest.mark.slow      # 1000 steps per output; fast: the second-order tests above (h = 2 to 0.5 ms) take the same path
def test_sliding_with_spin_is_second_order_down_to_ten_microseconds():
    """h = 1e-3 to 1e-5 s: the error against the closed form stays within the second-order
    bound e(h) ≤ e(1 ms) (h / 1 ms)^1.8 (plus 1e-12 m of round-off), and the spinner never
    veers.  The step with the contact impulses started from a warm start whose residual,
    O(ω h² μ g) from the rows turning with the spin, fell below the Newton tolerance at
    small h and was accepted without an iteration: 6.8e-5 m/s sideways at h = 25 µs."""
    s = nc.System("slider_small_h")
    for name, y, w in (("spinner", 0.0, (0.0, 0.0, 20.0)), ("tumbler", 1.0, W0)):
        b = s.add_body(name, mass=M, inertia=0.4 * M * R ** 2 * np.eye(3), position=(0, y, R), velocity=V0,
                       angular_velocity=w)
        s.add_contact(nc.SpherePlane(b, radius=R, mu=MU, point=(0, y, 0), name=name))
    model = s.build(contacts="nonsmooth")
    errors = {}
    for sub in (10, 50, 400, 1000):                    # h = 1e-3, 2e-4, 2.5e-5, 1e-5 s
        tr = nc.simulate(model, T_END, 0.01, method="stepper", substeps=sub)
        assert np.abs(tr.v[:, 1]).max() < 1e-10, sub
        errors[0.01 / sub] = np.abs(tr.point("tumbler", (0, 0, 0)) - _closed_form(tr.t, W0, 1.0)).max()
    for h, e in errors.items():
        assert e <= errors[1e-3] * (h / 1e-3) ** 1.8 + 1e-12, errors
