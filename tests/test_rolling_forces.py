"""Rolling runs with open-loop inputs, parameters and the rolling constraints' multipliers
(``nc.simulate(method="rolling")``, ncgen/runtime/rolling_integrator.py): a ball pushed
along the plane by a horizontal force at its centre against the closed form

    a = P / (m + I / r²) = 5 P / (7 m),   friction −2 P / 7,   normal force m g

(solid ball, I = 2/5 m r²), with the force an input (held constant or linearly between
samples) scaled by a parameter; and a disc in steady precession, whose contact carries the
weight and the centripetal force of its centre."""
import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError

M, R, G = 2.0, 0.1, 9.81


def pushed_ball():
    s = nc.System("pushed_ball", gravity=(0, 0, -G))
    ball = s.add_body("ball", mass=M, inertia=0.4 * M * R * R * np.eye(3), position=(0, 0, R))
    push = s.add_input("push")
    scale = s.add_parameter("scale", 1.0)
    s.add_force(nc.PointForce(ball, (0, 0, 0), force=ca.vertcat(scale * push, 0, 0)))
    s.add_rolling(nc.RollingSphere(ball, radius=R))
    return s.build()


def multipliers(traj, element="ball.rolling"):
    """(normal force, friction x, friction y) per output (N): −λ of the element's rows."""
    names = traj.constraint_names
    return tuple(-traj.lam[:, names.index(f"{element}.{row}")] for row in ("height", "x", "y"))


def test_a_pushed_ball_rolls_as_the_closed_form_says():
    """A constant input P = 3 N scaled by the parameter 2: the centre moves by ½ (5·6/(7m)) t²,
    the contact carries m g and a friction of −2·6/7 N (to 1e-8), the rows named after the
    element."""
    model = pushed_ball()
    traj = nc.simulate(model, 1.0, 0.05, u=lambda t: [3.0], p={"scale": 2.0}, rtol=1e-10, atol=1e-12)
    P = 6.0
    x = traj.point("ball", (0, 0, 0))
    np.testing.assert_allclose(x[:, 0], 0.5 * 5 * P / (7 * M) * traj.t ** 2, rtol=0, atol=1e-9)
    np.testing.assert_allclose(x[:, 2], R, rtol=0, atol=1e-12)
    normal, fx, fy = multipliers(traj)
    np.testing.assert_allclose(normal, M * G, rtol=1e-10)
    np.testing.assert_allclose(fx, -2 * P / 7, rtol=0, atol=1e-8)
    np.testing.assert_allclose(fy, 0.0, rtol=0, atol=1e-8)
    assert traj.lam.shape == (len(traj.t), len(traj.constraint_names))
    assert traj.constraint_names[-3:] == ["ball.rolling.height", "ball.rolling.x", "ball.rolling.y"]
    assert traj.info["backend"] == "vm" and np.max(traj.velocity_residual) < 1e-12


def test_an_input_held_linearly_between_samples():
    """P(t) = c t sampled on the grid and held linearly (hold="linear") is exact: the centre
    moves by 5 c t³ / (42 m)."""
    model = pushed_ball()
    c = 4.0
    t = np.linspace(0, 1.0, 21)
    traj = nc.simulate(model, 1.0, 0.05, u=(c * t)[:, None], hold="linear", rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(traj.point("ball", (0, 0, 0))[:, 0], 5 * c * traj.t ** 3 / (42 * M), rtol=0,
                               atol=1e-9)
    np.testing.assert_allclose(multipliers(traj)[1], -2 * c * traj.t / 7, rtol=0, atol=1e-8)


def test_without_inputs_the_compiled_step_stays_available_and_with_them_is_refused():
    model = pushed_ball()
    with pytest.raises(NcgenError, match="backend='compiled': the compiled step is built without inputs"):
        nc.simulate(model, 0.1, 0.05, u=lambda t: [1.0], backend="compiled")
    traj = nc.simulate(model, 0.1, 0.05)
    np.testing.assert_allclose(traj.point("ball", (0, 0, 0)), [[0, 0, R]] * len(traj.t), atol=1e-14)
