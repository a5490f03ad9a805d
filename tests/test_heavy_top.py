"""The heavy symmetric top against closed forms (independent of ncgen's equations).

Top: one 'ruvw' body whose tip is a shared ground point (ncgen.cli.demo_job.heavy_top).  Theory, with
θ the tilt, ω₃ the spin, I1' = I1 + m l² the transverse inertia about the tip:

* steady precession at the rate Ω solving m g l = Ω (I3 ω₃ − I1' Ω cos θ) (Goldstein §5.7);
* released without precession, θ oscillates between θ₀ and the other root of
  u̇² = (u₀ − u)(α(1 − u²) − a²(u₀ − u)), u = cos θ (exact turning points);
* fast-top limit: mean precession m g l/(I3 ω₃), nutation frequency I3 ω₃/I1' (relative
  errors O(m g l I1'/(I3 ω₃)²) = 0.4 % at ω₃ = 400 rad/s).
"""
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.cli.demo_job import Top, heavy_top, invariants

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def run(top, model, t_end, dt):
    traj = nc.simulate(model, t_end=t_end, dt=dt, rtol=1e-10, atol=1e-12, backend="vm")
    return traj, invariants(top, model, traj)


def test_example_file_is_the_steady_precession_of_the_formula():
    top = Top(spin=150.0)
    from_file = nc.System.from_toml(EXAMPLES / "heavy_top.toml").build()
    from_formula = heavy_top(top, precession=top.steady_precession()).build()
    assert from_file.coordinate_names == from_formula.coordinate_names
    assert np.allclose(from_file.q0, from_formula.q0, atol=1e-15)
    assert np.allclose(from_file.v0, from_formula.v0, rtol=1e-13, atol=1e-13)


def test_steady_precession():
    """Started in steady precession (heavy_top.toml), the tilt stays at 30° to 1e-6 rad over
    3 s (more than one full turn about the vertical) and the axis turns at the closed-form
    rate Ω to 1e-5."""
    top = Top(spin=150.0)
    model = nc.System.from_toml(EXAMPLES / "heavy_top.toml").build()
    traj, inv = run(top, model, 3.0, 0.01)
    assert np.max(np.abs(inv["tilt"] - top.tilt)) < 1e-6
    rate = np.polyfit(traj.t, inv["phi"], 1)[0]
    assert rate == pytest.approx(top.steady_precession(), rel=1e-5)
    assert inv["phi"][-1] - inv["phi"][0] > 6.0


def test_nutation_between_the_exact_turning_points():
    top = Top(spin=80.0)
    model = heavy_top(top).build()
    traj, inv = run(top, model, 1.0, 0.001)
    low, high = top.nutation_limits()
    assert inv["tilt"].min() == pytest.approx(low, abs=1e-6)
    assert inv["tilt"].max() == pytest.approx(high, abs=2e-5)     # sampled every 1 ms
    for key in ("L_z", "spin"):                                    # exact first integrals
        assert np.ptp(inv[key]) < 1e-6 * abs(inv[key][0])
    assert traj.energy_drift < 1e-6 * traj.energy_scale


def test_fast_top_limit():
    """At ω₃ = 400 rad/s: nutation period 2π I1'/(I3 ω₃) to 2 %, mean precession over whole
    nutation periods m g l/(I3 ω₃) to 1 %, amplitude = exact turning point to 1e-6 rad."""
    top = Top(spin=400.0)
    model = heavy_top(top).build()
    traj, inv = run(top, model, 0.5, 0.0005)
    tilt, t = inv["tilt"], traj.t
    peaks = np.flatnonzero((tilt[1:-1] > tilt[:-2]) & (tilt[1:-1] >= tilt[2:])) + 1
    assert len(peaks) >= 12
    period = np.mean(np.diff(t[peaks]))
    assert period == pytest.approx(2 * np.pi / top.nutation_frequency(), rel=0.02)
    mean_rate = (inv["phi"][peaks[-1]] - inv["phi"][peaks[0]]) / (t[peaks[-1]] - t[peaks[0]])
    assert mean_rate == pytest.approx(top.fast_top_precession(), rel=0.01)
    assert tilt.max() == pytest.approx(top.nutation_limits()[1], abs=1e-6)
