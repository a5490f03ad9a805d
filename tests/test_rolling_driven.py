"""Drives (time-dependent joints) together with rolling elements: a ball pulled along the
plane by a driven distance from a ground point at the height of its centre, d(t) = d0 + ½ a t².
It rolls without slipping, so the centre follows x = d(t) exactly, its spin ω_y = ẋ/r, the
friction at the contact is −(2/5) m a (it spins the ball up: I ω̇ = r f), the pull of the
drive (7/5) m a (m ẍ = pull + friction) and the kinetic energy ½ (7/5) m ẋ² is the drive's
work.  IDAS (the choice of ``method="auto"`` for such a model) and the RATTLE stepper run it;
the projected Runge–Kutta integrator refuses it by name."""
import numpy as np
import pytest

import ncgen as nc
from ncgen.analysis.steady_motion import linearize_steady
from ncgen.assembly.nonholonomic import rolling_system
from ncgen.errors import NcgenError

M, R, D0, ACC = 2.0, 0.1, 0.5, 0.8


@pytest.fixture(scope="module")
def model():
    s = nc.System("pulled_ball", gravity=(0, 0, -9.81))
    ball = s.add_body("ball", mass=M, inertia=0.4 * M * R * R * np.eye(3), position=(D0, 0, R))
    s.add_joint(nc.Distance(s.ground, ball, at=[(0, 0, R), (D0, 0, R)], drive=f"{D0} + 0.5*{ACC}*t**2"))
    s.add_rolling(nc.RollingSphere(ball, radius=R))
    return s.build()


@pytest.mark.parametrize("method, options, spin_tol", [("auto", {"rtol": 1e-10, "atol": 1e-12}, 1e-8),
                                                       ("stepper", {"substeps": 10}, 6e-4)])
def test_a_ball_pulled_by_a_driven_distance(model, method, options, spin_tol):
    """The centre, the friction, the pull and the energy to round-off on both methods (the
    centre's motion is prescribed; the forces follow from it); the spin (the base vectors,
    integrated) to 1e-8 on IDAS at rtol 1e-10 (measured 2.9e-9) and to 6e-4 on the stepper at
    h = 5 ms (measured 4.0e-4, and 1.0e-4 at 2.5 ms: its second order)."""
    tr = nc.simulate(model, 1.0, 0.05, method=method, **options)
    assert tr.info["method"] == ("idas" if method == "auto" else "stepper")
    t = tr.t
    x = tr.point("ball", (0, 0, 0))
    np.testing.assert_allclose(x, np.column_stack([D0 + 0.5 * ACC * t ** 2, 0 * t, R + 0 * t]), rtol=0, atol=1e-12)
    idx = model.layout.member_indices("ball")
    spin = tr.q[:, idx[3:6]]                         # the body's x axis turns about +y at ẋ / r
    turned = 0.5 * ACC * t ** 2 / R
    np.testing.assert_allclose(spin, np.column_stack([np.cos(turned), 0 * t, -np.sin(turned)]), rtol=0, atol=spin_tol)
    names = tr.constraint_names
    friction = -tr.lam[:, names.index("ball.rolling.x")]
    np.testing.assert_allclose(friction, -0.4 * M * ACC, rtol=1e-9)
    d = D0 + 0.5 * ACC * t ** 2                      # the drive's row |r − r_A|² − d² = 0: pull −2 d λ
    np.testing.assert_allclose(-2 * d * tr.lam[:, names.index("distance_0.drive")], 1.4 * M * ACC, rtol=1e-9)
    np.testing.assert_allclose(tr.energy - tr.energy[0], 0.5 * 1.4 * M * (ACC * t) ** 2, rtol=0, atol=1e-9)
    assert max(tr.constraint_residual.max(), tr.velocity_residual.max()) < 1e-12


def test_the_driven_rows_in_the_rolling_system(model):
    """``ĉ`` of the drive's row is ``−∂Φ/∂t`` (here ``2 d ḋ``), against a central difference
    of ``phi_at`` in time; ``gamma_t`` against finite differences of the velocity level
    ``Â(q, t) v − ĉ(q, t)`` along the motion."""
    rs = rolling_system(model)
    assert rs.driven
    q, v, t, eps = model.q0, model.v0 + 0.01, 0.3, 1e-6
    dphi_dt = (np.asarray(rs.phi_at(q, t + eps)) - np.asarray(rs.phi_at(q, t - eps))).ravel() / (2 * eps)
    c = np.asarray(rs.rate(q, t)).ravel()
    np.testing.assert_allclose(c[:rs.n_holonomic], -dphi_dt, rtol=0, atol=1e-8)

    def level(s):
        qs, ts = q + s * v, t + s
        return np.asarray(rs.A_at(qs, ts)).dot(v) - np.asarray(rs.rate(qs, ts)).ravel()
    np.testing.assert_allclose(np.asarray(rs.gamma_t(q, v, t)).ravel(), -(level(eps) - level(-eps)) / (2 * eps),
                               rtol=0, atol=1e-7)


def test_refusals_are_named(model):
    with pytest.raises(NcgenError, match="method='rolling': model 'pulled_ball' has drives"):
        nc.simulate(model, 0.1, 0.05, method="rolling")
    with pytest.raises(NcgenError, match="linearize_steady: the model has drives"):
        linearize_steady(rolling_system(model), model.q0, model.v0, np.zeros((model.nq, model.nq)), None)
