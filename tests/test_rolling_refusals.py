"""Functions of a model's own constraints refuse a model with rolling elements by name,
instead of returning the result of the model without the elements' rows (before this, a
batch of the rolling disc fell through the plane: its centre at z < 0 after 0.2 s)."""
import numpy as np
import pytest

import ncgen as nc
from ncgen.control.discrete import step_functions
from ncgen.errors import ModelError
from ncgen.model.rolling import refuse_rolling


@pytest.fixture(scope="module")
def ball():
    """A ball rolling along x on the plane z = 0 (docs/rolling.md's)."""
    s = nc.System("ball", gravity=(0.0, 0.0, -9.81))
    s.add_body("ball", mass=1.0, inertia=0.004 * np.eye(3), position=(0, 0, 0.1), velocity=(0.5, 0, 0),
               angular_velocity=(0, 5.0, 0))
    s.add_rolling(nc.RollingSphere("ball", radius=0.1))
    return s.build()


CALLS = {
    "simulate_batch": lambda m, tmp: nc.simulate_batch(m, 0.2, 0.05, q0=np.array([m.q0])),
    "sweep(method='stepper')": lambda m, tmp: nc.sweep(m, None, t_end=0.2, dt=0.05, q0=np.array([m.q0])),
    "step_function": lambda m, tmp: nc.step_function(m, 0.01),
    "the RATTLE step": lambda m, tmp: step_functions(m, 0.01),
    "OptimalControl": lambda m, tmp: nc.OptimalControl(m, 5, 0.1),
    "linearize": lambda m, tmp: nc.linearize(m, m.q0, m.v0),
    "equilibrium": lambda m, tmp: nc.equilibrium(m),
    "modes": lambda m, tmp: nc.modes(m),
    "forward_dynamics": lambda m, tmp: nc.forward_dynamics(m, m.q0, m.v0),
    "forward_dynamics_kernel": lambda m, tmp: nc.forward_dynamics_kernel(m),
    "generate": lambda m, tmp: nc.generate(m, tmp / "ball"),
}


@pytest.mark.parametrize("what", sorted(CALLS))
def test_refused_by_name(ball, what, tmp_path):
    """Each names itself, the model and its element, and says what keeps the rows."""
    with pytest.raises(ModelError) as e:
        CALLS[what](ball, tmp_path)
    message = str(e.value)
    assert message.startswith(what) and "'ball'" in message and "(ball.rolling)" in message, message
    assert not any(tmp_path.iterdir())


def test_models_without_rolling_pass(ball):
    """The check is silent for a model without rolling elements; ``sweep(method='idas')``
    (``nc.simulate`` per run) keeps the rows: the ball rolls on at its speed (x = 0.5 t, on
    the plane)."""
    s = nc.System("free_ball", gravity=(0.0, 0.0, -9.81))
    s.add_body("ball", mass=1.0, inertia=0.004 * np.eye(3))
    refuse_rolling(s.build(), "anything", "")
    res = nc.sweep(ball, None, t_end=0.2, dt=0.05, method="idas", q0=np.array([ball.q0]), rtol=1e-10, atol=1e-12)
    assert not res.failures, res.failures
    q = np.asarray(res["q"])[0]
    np.testing.assert_allclose(q[:, :3], np.column_stack([0.5 * res.t, 0 * res.t, 0.1 + 0 * res.t]), atol=1e-8)
