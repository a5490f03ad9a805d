"""The rolling RATTLE step compiled (ncgen/assembly/rolling_rattle.py: ``step_function``, one
CasADi function per step with both Newton solves inside, compiled to C through the
content-keyed cache; ``nc.simulate(model, method="stepper", backend=...)``): its step equal
to the Python-driven step's, its order on the rolling disc against a tight DOPRI5 reference,
both constraint levels, the choice of ``backend="auto"``, the fallback without a compiler and
a Newton failure named."""
import numpy as np
import pytest

import ncgen as nc
import ncgen.runtime.rolling_stepper as rolling_rattle
from ncgen.assembly.nonholonomic import rolling_system
from ncgen.errors import CompilerNotFound, SimulationError
from ncgen.runtime.options import SimulationOptions
from test_rolling_forces import pushed_ball
from test_rolling_system import disc_toml

TOL, MAX_ITER = SimulationOptions().newton_tol, SimulationOptions().max_newton


@pytest.fixture(scope="module")
def wobbly():
    """A disc tilted by 0.3 rad, spinning at 25 rad/s and wobbling (tests/test_rolling_rattle.py's)."""
    return nc.System.from_toml(disc_toml(0.3, 25.0, 0.0, wobble=1.0)).build()


def test_the_compiled_step_equals_the_python_step(wobbly):
    """From states along a wobbling disc's motion and a ball pushed by an input (``u0`` and
    ``u1`` differ), for h = 1 ms and 10 ms: positions and velocities equal to 1e-12, the
    multipliers to 1e-12 of their size."""
    ball = pushed_ball()
    for model, u0, u1 in ((wobbly, np.zeros(0), np.zeros(0)), (ball, np.array([1.0]), np.array([2.5]))):
        rs = rolling_system(model)
        step = rolling_rattle.compiled_step(rs, TOL, MAX_ITER)
        q, v = rolling_rattle.project(rs, model.q0, model.v0)
        for k, h in enumerate((1e-3, 1e-2, 1e-3)):
            a = rolling_rattle.rattle_step(rs, 0.1 * k, q, v, h, u0, u1, model.p0, TOL, MAX_ITER)
            b = rolling_rattle.compiled_rattle_step(step, 0.1 * k, q, v, h, u0, u1, model.p0, TOL)
            np.testing.assert_allclose(b[0], a[0], rtol=0, atol=1e-12)
            np.testing.assert_allclose(b[1], a[1], rtol=0, atol=1e-12)
            np.testing.assert_allclose(b[2], a[2], rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(a[2]))))
            q, v = a[0], a[1]


def test_second_order_and_both_levels_compiled(wobbly):
    """``backend="compiled"``: the error at T = 0.2 s against DOPRI5 at rtol 1e-13 falls by 4
    per halving of h (order ≥ 1.8), every output on both levels to 1e-12, and the run equal to
    the Python-driven one to 1e-12."""
    T = 0.2
    ref = nc.simulate(wobbly, T, T, method="rolling", rtol=1e-13, atol=1e-15)
    err = []
    for substeps in (20, 40, 80):
        tr = nc.simulate(wobbly, T, 0.05, method="stepper", substeps=substeps // 4, backend="compiled", check=False)
        assert tr.info["backend"] == "compiled" and tr.info["stats"]["steps"] == substeps
        assert max(tr.constraint_residual.max(), tr.velocity_residual.max()) <= 1e-12
        err.append(np.max(np.abs(tr.q[-1] - ref.q[-1])))
    orders = np.log2(np.array(err[:-1]) / np.array(err[1:]))
    assert np.all((orders > 1.8) & (orders < 2.2)), orders
    py = nc.simulate(wobbly, T, 0.05, method="stepper", substeps=20, backend="vm", check=False)
    assert py.info["backend"] == "vm"
    np.testing.assert_allclose(tr.q, py.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(tr.v, py.v, rtol=0, atol=1e-12)


def test_auto_compiles_when_it_pays_and_falls_back_without_a_compiler(wobbly, monkeypatch):
    rs = rolling_system(wobbly)
    rs.compiled_steps.clear()
    monkeypatch.setattr(rolling_rattle, "COMPILE_PAYS", 1e9)
    tr = nc.simulate(wobbly, 1.0, 0.1, method="stepper", substeps=10, check=False)      # h = 10 ms: coarse
    assert tr.info["backend"] == "vm"
    monkeypatch.setattr(rolling_rattle, "COMPILE_PAYS", 0.0)
    monkeypatch.setattr(rolling_rattle, "PACE_AFTER", 0.0)      # a fast machine: the run may end within 0.5 s
    tried = []

    def no_compiler(*args, **kwargs):
        tried.append(args)
        raise CompilerNotFound("no C compiler (test)")

    monkeypatch.setattr(rolling_rattle, "compiled_step", no_compiler)
    tr = nc.simulate(wobbly, 1.0, 0.1, method="stepper", substeps=10, check=False)
    assert len(tried) == 1 and tr.info["backend"] == "vm" and tr.velocity_residual.max() <= 1e-12
    with pytest.raises(CompilerNotFound, match="backend='compiled' compiles the rolling RATTLE step; install gcc, "
                                               "or give backend='auto' or 'vm'"):
        nc.simulate(wobbly, 0.1, 0.1, method="stepper", backend="compiled")
    monkeypatch.undo()
    monkeypatch.setattr(rolling_rattle, "COMPILE_PAYS", 0.0)
    monkeypatch.setattr(rolling_rattle, "PACE_AFTER", 0.0)      # a fast machine: the run may end within 0.5 s
    tr = nc.simulate(wobbly, 1.0, 0.1, method="stepper", substeps=10, check=False)      # h = 10 ms: coarse
    assert tr.info["backend"] == "compiled" and tr.velocity_residual.max() <= 1e-12
    # compiled in this process: the next run takes it from its first step
    monkeypatch.setattr(rolling_rattle, "COMPILE_PAYS", 1e9)
    assert nc.simulate(wobbly, 0.1, 0.1, method="stepper", substeps=10, check=False).info["backend"] == "compiled"


def test_a_newton_failure_is_named(wobbly):
    with pytest.raises(SimulationError, match="\\(compiled\\): Newton's method did not bring the residual below"):
        nc.simulate(wobbly, 0.1, 0.1, method="stepper", backend="compiled", max_newton=1, newton_tol=1e-15)


def test_a_moving_plane_and_a_drive_compiled():
    """The compiled step carries the time of the rows: a ball on a plane accelerating at a_p
    (centre at a_p t² / 7, friction 2/7 m a_p: RATTLE is exact on this motion of constant
    acceleration) and a ball pulled by a driven distance (tests/test_rolling_driven.py: the
    centre on its prescribed path, the friction −(2/5) m a)."""
    from test_rolling_drives import A_P, M, ball_on_treadmill
    from test_rolling_forces import multipliers
    import test_rolling_driven as driven
    tr = nc.simulate(ball_on_treadmill().build(), 1.0, 0.05, method="stepper", substeps=5, backend="compiled")
    assert tr.info["backend"] == "compiled"
    np.testing.assert_allclose(tr.point("ball", (0, 0, 0))[:, 0], A_P * tr.t ** 2 / 7, rtol=0, atol=1e-11)
    np.testing.assert_allclose(multipliers(tr)[1], 2 * M * A_P / 7, rtol=1e-9)
    s = nc.System("pulled_ball", gravity=(0, 0, -9.81))
    ball = s.add_body("ball", mass=driven.M, inertia=0.4 * driven.M * driven.R ** 2 * np.eye(3),
                      position=(driven.D0, 0, driven.R))
    s.add_joint(nc.Distance(s.ground, ball, at=[(0, 0, driven.R), (driven.D0, 0, driven.R)],
                            drive=f"{driven.D0} + 0.5*{driven.ACC}*t**2"))
    s.add_rolling(nc.RollingSphere(ball, radius=driven.R))
    tr = nc.simulate(s.build(), 1.0, 0.05, method="stepper", substeps=10, backend="compiled")
    np.testing.assert_allclose(tr.point("ball", (0, 0, 0))[:, 0], driven.D0 + 0.5 * driven.ACC * tr.t ** 2,
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(-tr.lam[:, tr.constraint_names.index("ball.rolling.x")], -0.4 * driven.M * driven.ACC,
                               rtol=1e-9)
    assert max(tr.constraint_residual.max(), tr.velocity_residual.max()) < 1e-12
