"""Rolling on a moving plane: rheonomic velocity constraints ``B(q) v = c(q, t)``
(``plane_velocity`` of the rolling elements, ncgen/model/rolling.py), run by
``nc.simulate(method="rolling")``.

A solid ball (I = 2/5 m r²) at rest on a plane that starts moving along x at the constant
acceleration a_p: the friction force f along x at the contact gives the centre m ẍ = f and
the spin I ω̇_y = −r f; no slip, ẋ − r ω_y = a_p t (the contact point moves with the plane),
so f (1/m + r²/I) = a_p:

    f = (2/7) m a_p,   ẍ = (2/7) a_p,   r ω_y = −(5/7) a_p t,

and the kinetic energy ½ m ẋ² + ½ I ω_y² = (1/7) m a_p² t² equals the plane's work
∫ f · (a_p t) dt.  A Chaplygin sleigh on a plane moving at a constant velocity w moves as the
sleigh on a plane at rest seen from the moving plane (Galilean invariance; its blade row
``c = (e_z × R b̄)·w`` depends on q).  A disc on a plane that oscillates: the energy
balance E(t) − E(0) = ∫ −λᵀc dt, the constraint forces' work."""
import numpy as np
import pytest
from scipy.integrate import cumulative_simpson

import ncgen as nc
from ncgen.assembly.nonholonomic import rolling_system
from ncgen.errors import ModelError, NcgenError

M, R, G, A_P = 2.0, 0.1, 9.81, 1.5


def ball_on_treadmill(plane_velocity=(f"{A_P}*t", 0.0)):
    s = nc.System("treadmill_ball", gravity=(0, 0, -G))
    s.add_body("ball", mass=M, inertia=0.4 * M * R * R * np.eye(3), position=(0, 0, R))
    s.add_rolling(nc.RollingSphere("ball", radius=R, plane_velocity=plane_velocity))
    return s


def drive_work(traj, c) -> np.ndarray:
    """∫ −λᵀ c dt (J) from the start to each output, ``c`` the rows' values per output
    (Simpson's rule on the outputs)."""
    return cumulative_simpson(-np.sum(traj.lam * c, axis=1), x=traj.t, initial=0.0)


def test_a_ball_on_an_accelerating_plane_as_the_closed_form_says():
    """Centre at (1/7) a_p t² (to 1e-9 m) and spin r ω_y = −(5/7) a_p t (the turned angle to
    1e-8 rad), friction (2/7) m a_p and
    normal force m g (1e-8), the contact point moving with the plane (velocity residual
    below 1e-12), and E(t) − E(0) = (1/7) m a_p² t² = the plane's work ∫ −λᵀc dt (1e-9 J)."""
    model = ball_on_treadmill().build()
    traj = nc.simulate(model, 1.0, 0.01, rtol=1e-10, atol=1e-12)
    t = traj.t
    x = traj.point("ball", (0, 0, 0))
    np.testing.assert_allclose(x[:, 0], A_P * t ** 2 / 7, rtol=0, atol=1e-9)
    np.testing.assert_allclose(x[:, 1:], [[0.0, R]] * len(t), rtol=0, atol=1e-12)
    turned = -5 * A_P * t ** 2 / (14 * R)                   # ∫ ω_y dt: the body's x axis turns about y
    axis = traj.point("ball", (1, 0, 0)) - x
    np.testing.assert_allclose(axis, np.column_stack([np.cos(turned), 0 * t, -np.sin(turned)]), rtol=0, atol=1e-8)
    names = traj.constraint_names
    friction = -traj.lam[:, names.index("ball.rolling.x")]
    np.testing.assert_allclose(friction, 2 * M * A_P / 7, rtol=1e-8)
    np.testing.assert_allclose(-traj.lam[:, names.index("ball.rolling.height")], M * G, rtol=1e-10)
    np.testing.assert_allclose(traj.lam[:, names.index("ball.rolling.y")], 0.0, atol=1e-8)
    assert np.max(traj.velocity_residual) < 1e-12 and np.max(traj.constraint_residual) < 1e-12
    c = np.array([np.asarray(rolling_system(model).rate(q, tk)).ravel() for q, tk in zip(traj.q, t)])
    np.testing.assert_allclose(c[:, -2], A_P * t, rtol=1e-15, atol=0)
    gained = traj.energy - traj.energy[0]
    np.testing.assert_allclose(gained, M * A_P ** 2 * t ** 2 / 7, rtol=0, atol=1e-9)
    np.testing.assert_allclose(gained, drive_work(traj, c), rtol=0, atol=1e-9)
    assert traj.info["backend"] == "vm"


def sleigh(plane=(0.0, 0.0)):
    """The sleigh of tests/test_rolling.py on a plane moving at ``plane`` (m/s), started with
    the same velocity relative to the plane."""
    ms, b, u0, w0 = 2.0, 0.3, 0.2, 1.5
    w = np.array([*plane, 0.0])
    s = nc.System("sleigh", gravity=(0.0, 0.0, -G))
    body = s.add_body("sleigh", mass=ms, inertia=np.diag([0.02, 0.04, 0.05]), position=(0.0, 0.0, 0.1),
                      velocity=np.array([u0, b * w0, 0.0]) + w, angular_velocity=(0.0, 0.0, w0))
    s.add_joint(nc.Planar(s.ground, body, at=(0.0, 0.0, 0.1), normal=(0.0, 0.0, 1.0)))
    s.add_rolling(nc.KnifeEdge(body, at=(-b, 0.0, 0.0), blade=(1.0, 0.0, 0.0),
                               plane_velocity=None if not any(plane) else plane))
    return s.build()


def test_a_sleigh_on_a_plane_moving_steadily_is_the_sleigh_seen_from_the_plane():
    """A knife edge's row depends on q (c = (e_z × R b̄)·w): the sleigh on a plane moving at
    w = (0.4, −0.3) m/s is the sleigh at rest shifted by w t (to 1e-9 m); its turning decays
    as at rest."""
    w = np.array([0.4, -0.3])
    at_rest = nc.simulate(sleigh(), 2.0, 0.05, rtol=1e-10, atol=1e-12)
    moving = nc.simulate(sleigh(tuple(w)), 2.0, 0.05, rtol=1e-10, atol=1e-12)
    shift = np.column_stack([np.outer(moving.t, w), np.zeros(len(moving.t))])
    for point in ((0, 0, 0), (1, 0, 0), (-0.3, 0.2, 0)):
        np.testing.assert_allclose(moving.point("sleigh", point), at_rest.point("sleigh", point) + shift,
                                   rtol=0, atol=1e-9)
    assert np.max(moving.velocity_residual) < 1e-12
    assert rolling_system(moving.model).rheonomic and not rolling_system(at_rest.model).rheonomic


@pytest.mark.slow      # a disc shaken for 1 s at 1 ms outputs; fast:
#                       test_a_ball_on_an_accelerating_plane_as_the_closed_form_says (a driven plane against its
#                       closed form)
def test_a_disc_on_an_oscillating_plane_keeps_its_energy_balance():
    """A disc rolling and precessing on a plane shaken along x and y: E(t) − E(0) equals the
    constraint forces' work ∫ −λᵀc dt (Simpson's rule on 1 ms outputs, whose own error is
    O(h⁴): 2e-6 J at 5 ms, 1.3e-7 J at 2.5 ms) to 1e-8 of the energy's scale (measured 2.6e-9),
    both constraint levels at 1e-10."""
    s = nc.System("shaken_disc", gravity=(0, 0, -G))
    rho, tilt = 0.1, 0.2
    Rx = np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
    centre = np.array([0.0, 0.0, rho * np.cos(tilt)])
    s.add_body("disc", mass=1.0, inertia=np.diag([0.0025, 0.005, 0.0025]), position=centre, rotation=Rx,
               velocity=(0.3, 0.0, 0.0), angular_velocity=Rx @ (0.0, -3.0, 0.0) + (0.0, 0.0, 1.0))
    s.add_rolling(nc.RollingDisc("disc", radius=rho, axle=(0, 1, 0),
                                 plane_velocity=("0.2*sin(5*t)", "0.1*(1 - cos(3*t))")))
    model = s.build()
    traj = nc.simulate(model, 2.0, 0.001, rtol=1e-10, atol=1e-12)
    rs = rolling_system(model)
    c = np.array([np.asarray(rs.rate(q, tk)).ravel() for q, tk in zip(traj.q, traj.t)])
    work = drive_work(traj, c)
    scale = np.max(np.abs(traj.energy))
    assert np.max(np.abs(work)) > 1e-3 * scale                   # the plane does work
    assert np.max(np.abs(traj.energy - traj.energy[0] - work)) < 1e-8 * scale
    assert np.max(traj.velocity_residual) < 1e-10 and np.max(traj.constraint_residual) < 1e-10


def test_plane_velocity_in_toml_and_its_errors(tmp_path):
    """``plane_velocity`` round-trips through TOML (expressions of t kept as text) and is part
    of the model's hash; bad values are named with their table and key; the compiled step
    and the steady-motion linearisation refuse a moving plane."""
    system = ball_on_treadmill()
    text = system.to_toml()
    assert 'plane_velocity = ["1.5*t", 0.0]' in text.replace(" * ", "*")
    again = nc.System.from_toml(text)
    assert again.rolling[0].plane_velocity == system.rolling[0].plane_velocity
    assert again.build().content_hash == system.build().content_hash != ball_on_treadmill(None).build().content_hash
    bad = text.replace("1.5 * t", "1.5 * k")
    with pytest.raises(ModelError, match=r"rolling\[0\].*plane_velocity\[0\]: unknown name 'k'"):
        nc.System.from_toml(bad)
    with pytest.raises(ModelError, match="plane_velocity: expected 2 components, got 3"):
        nc.RollingSphere("ball", radius=R, plane_velocity=(1.0, 0.0, 0.0))
    model = system.build()
    with pytest.raises(NcgenError, match="moving planes; give backend='vm'"):
        nc.simulate(model, 0.1, 0.05, backend="compiled")
    from ncgen.analysis.steady_motion import linearize_steady
    with pytest.raises(NcgenError, match="moving plane"):
        linearize_steady(rolling_system(model), model.q0, model.v0, np.zeros((model.nq, model.nq)), None)


def test_the_acceleration_right_side_against_finite_differences():
    """``gamma_t(q, v, t) = −d/dε [Â(q + εv) v − ĉ(q + εv, t + ε)]`` at ε = 0 (central
    differences, 1e-7 of its scale) for a knife edge, whose ``ĉ`` depends on q and t, and a
    ball on a plane shaken along x and y, at random states off the motion."""
    s = nc.System("shaken", gravity=(0.0, 0.0, -G))
    s.add_body("ball", mass=M, inertia=0.4 * M * R * R * np.eye(3), position=(0, 0, R))
    s.add_rolling(nc.RollingSphere("ball", radius=R, plane_velocity=("0.3*sin(2*t)", "t*t")))
    sled = s.add_body("sled", mass=1.0, inertia=np.diag([0.02, 0.04, 0.05]), position=(1.0, 0.0, 0.1))
    s.add_joint(nc.Planar(s.ground, sled, at=(1.0, 0.0, 0.1), normal=(0.0, 0.0, 1.0)))
    s.add_rolling(nc.KnifeEdge(sled, at=(-0.3, 0.0, 0.0), plane_velocity=("cos(t)", "0.5*t")))
    rs = rolling_system(s.build())
    rng = np.random.default_rng(7)
    for _ in range(3):
        q = rs.model.q0 + 0.1 * rng.standard_normal(rs.nq)
        v, t, h = rng.standard_normal(rs.nq), float(rng.uniform(0, 2)), 1e-5

        def level(e):
            return np.asarray(rs.A(q + e * v)).dot(v) - np.asarray(rs.rate(q + e * v, t + e)).ravel()
        fd = -(level(h) - level(-h)) / (2 * h)
        got = np.asarray(rs.gamma_t(q, v, t)).ravel()
        np.testing.assert_allclose(got, fd, rtol=0, atol=1e-7 * max(1.0, np.abs(fd).max()))
        assert np.abs(got - np.asarray(rs.gamma(q, v)).ravel()).max() > 1e-3     # the plane's terms count
