"""A winch on a CapstanCable (``reeled``: rest length reeled in at an end of the path) against
closed forms of the massless rope.

Rig W: a weight m hangs on side a from a ground drum (wrap θ, friction μ); side b runs from the
drum to a winch at a ground point, which reels in ``w(t)``.  Reeling in at the rate r, side b's
tension rises until the drum slips (``T_b = e^{μθ} T_a``); in steady state the weight rises at r
with ``T_a = m g``.  Paying out (``w < 0``) lowers ``T_b``; while ``T_b > e^{−μθ} m g`` the drum
sticks and the weight stays (creeping at ``v_s atanh(...)``, ncgen/model/capstan.py), where a
frictionless drum lets it down by the paid-out length.  The winch's work is
``∫ (E_b + E_b²/(2EA)) ẇ dt`` (``E_b = EA (l_b − ρ_b)/ρ_b``): with it the energy balance closes.
"""
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError

G = 9.81
M, MS, VS, C = 1.0, 1e-3, 1e-4, 200.0
DRUM, WINCH = (0.0, 0, 1.0), (0.5, 0, 1.0)


def winch(reel, *, mu=0.3, ea=1e5, damping=C, material_mass=MS, slip_velocity=VS, name="winch"):
    """Rig W (module docstring), both sides at the tension m g at the start."""
    s = nc.System(name, gravity=(0, 0, -G))
    w = s.add_point("weight", mass=M, position=(0, 0, 0))
    s.add_joint(nc.PointOnLine(s.ground, w, at=(0, 0, 0), axis=(0, 0, 1)))
    rests = [length / (1 + M * G / ea) for length in (1.0, 0.5)]
    nc.add_capstan_cable(s, [(w, (0, 0, 0)), (s.ground, DRUM), (s.ground, WINCH)], pulley=1, mu=mu, wrap=np.pi,
                         ea=ea, damping=damping, rest_lengths=rests, material_mass=material_mass,
                         slip_velocity=slip_velocity, reeled=(0, reel), name="rope")
    return s


def tensions(model, traj, u=None):
    u = np.zeros((len(traj.t), 0)) if u is None else u
    return np.array([np.array(model.springs.function(t, q, v, ui, model.p0)[0]).reshape(-1)
                     for t, q, v, ui in zip(traj.t, traj.q, traj.v, u)])


def weight_z(traj):
    return traj.point("weight", (0, 0, 0))[:, 2]


def test_reeling_in_over_a_slipping_drum_lifts_the_weight_at_the_reel_rate():
    """r = 0.1 m/s: once steady the weight rises at r, T_a = m g and T_b/T_a = e^{μθ}."""
    r = 0.1
    model = winch(f"{r}*t").build()
    traj = nc.simulate(model, t_end=0.6, dt=0.005, backend="vm")
    late = traj.t >= 0.3
    rate = np.polyfit(traj.t[late], weight_z(traj)[late], 1)[0]
    assert rate == pytest.approx(r, rel=1e-3)
    t = tensions(model, traj)[late]
    np.testing.assert_allclose(t[:, 0], M * G, rtol=0.01)
    np.testing.assert_allclose(t[:, 1] / t[:, 0], np.exp(0.3 * np.pi), rtol=1e-3)


def test_a_sticking_drum_holds_while_the_winch_pays_out():
    """A soft rope (EA = 1 kN, c = 20 N·s/m) paid out by 2 mm over 0.2 s: T_b falls to m g − EA Δ/ρ_b
    (5.8 N > e^{−μπ} m g = 3.8 N: the drum holds) and the weight stays within the creep;
    over a frictionless drum the weight comes down by the paid-out length."""
    ea, pay = 1e3, 2e-3
    reel = f"-{pay}*min(t/0.2, 1)"
    model = winch(reel, ea=ea, damping=20.0).build()
    traj = nc.simulate(model, t_end=0.6, dt=0.005, backend="vm")
    z = weight_z(traj)
    assert np.abs(z - z[0]).max() < 0.05 * pay
    rho_b = 0.5 / (1 + M * G / ea) + pay
    expected = ea * (0.5 - rho_b) / rho_b
    assert expected > np.exp(-0.3 * np.pi) * M * G
    assert tensions(model, traj)[-1, 1] == pytest.approx(expected, rel=0.02)
    free = winch(reel, ea=ea, damping=20.0, mu=0.0).build()
    fall = weight_z(nc.simulate(free, t_end=0.6, dt=0.005, backend="vm"))
    assert fall[0] - fall[-1] == pytest.approx(pay, rel=0.05)


def _winch_work(system, traj, ea, w, w_dot):
    """``∫ (E_b + E_b²/(2EA)) ẇ dt`` (trapezoid) from side b's rest length, ρ_b = L₀ − w − S_0."""
    force = next(f for f in system.forces if f.kind == "CapstanCable")
    material = traj.point("rope_material", (0, 0, 0)) @ np.asarray(force.axis, float)
    s0 = force.rest_lengths[0] + material - material[0]
    rho_b = sum(force.rest_lengths) - w(traj.t) - s0
    e_b = ea * (0.5 - rho_b) / rho_b
    power = (e_b + e_b**2 / (2 * ea)) * w_dot(traj.t)
    return np.concatenate([[0], np.cumsum(0.5 * (power[1:] + power[:-1]) * np.diff(traj.t))])


def test_energy_balance_closes_with_the_winch_work():
    """w(t) = 0.05 (1 − cos 4t) (in and back out): the run's reported drives work equals the
    winch's work by hand to 2e-5 of its largest value, E − E0 − W closes, and friction and damping dissipate."""
    ea = 1e5
    system = winch("0.05*(1 - cos(4*t))")
    model = system.build()
    traj = nc.simulate(model, t_end=0.8, dt=0.002, backend="vm", rtol=1e-9, atol=1e-11)
    works = traj.info["energy"]["works"]
    by_hand = _winch_work(system, traj, ea, lambda t: 0.05 * (1 - np.cos(4 * t)), lambda t: 0.2 * np.sin(4 * t))
    scale = np.abs(by_hand).max()
    assert scale > 1.0
    np.testing.assert_allclose(works["drives"], by_hand, atol=2e-5 * scale)
    gain = traj.energy - traj.energy[0]
    np.testing.assert_allclose(gain, works["total"], atol=1e-5 * scale)
    assert np.all(by_hand - gain >= -1e-5 * scale)            # dissipated ≥ 0
    assert by_hand[-1] - gain[-1] > 0.05 * scale


def test_an_input_winch_moves_as_the_expression_and_the_stepper_agrees(tmp_path, monkeypatch):
    """The reel as an input (damping 0, potential left out) follows the same motion as the
    same reel as an expression of t (IDAS); its total work closes the balance; the compiled
    stepper (31 µs steps) moves the weight as IDAS on a smoothly started reel (the stick regularised
    as in the capstan OCP: m_s = 0.05 kg, v_s = 5 mm/s; c = 20 N·s/m)."""
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    r = 0.1
    by_input = winch("w", damping=0.0)
    by_input.add_input("w")
    model = by_input.build()
    u = lambda t: [r * t]                                               # noqa: E731
    traj = nc.simulate(model, t_end=0.3, dt=0.005, u=u, hold="linear", backend="vm", rtol=1e-9, atol=1e-11)
    expr = nc.simulate(winch(f"{r}*t", damping=0.0).build(), t_end=0.3, dt=0.005, backend="vm", rtol=1e-9,
                       atol=1e-11)
    np.testing.assert_allclose(weight_z(traj), weight_z(expr), atol=1e-5)
    gain = traj.energy - traj.energy[0]
    works = traj.info["energy"]["works"]
    np.testing.assert_allclose(gain, works["total"], atol=1e-4 * np.abs(gain).max())
    smooth = f"{r}*(t - 0.05*(1 - exp(-t/0.05)))"
    soft = dict(damping=20.0, material_mass=0.05, slip_velocity=5e-3)
    step = nc.simulate(winch(smooth, **soft).build(), t_end=0.3, dt=0.005, method="stepper", substeps=160)
    ref = nc.simulate(winch(smooth, **soft).build(), t_end=0.3, dt=0.005, backend="vm", rtol=1e-9,
                      atol=1e-11)
    np.testing.assert_allclose(weight_z(step), weight_z(ref), atol=2e-5)
    # its shadow run (62.5 µs steps) fails Newton: the estimate comes from a run at h/2 and measures the error
    estimate = step.info["error_estimate"]
    assert "h/2" in estimate["how"]
    assert 0.3 < estimate["q"] / np.max(np.abs(step.q - ref.q)) < 3.0


def test_toml_round_trip_and_bad_reels():
    s = winch("0.1*t")
    text = s.to_toml()
    assert 'reeled = [0.0, "0.1*t"]' in text
    back = nc.System.from_toml(text)
    assert back.to_toml() == text
    m1, m2 = s.build(), back.build()
    rng = np.random.default_rng(5)
    q, v = m1.q0 + 0.01 * rng.normal(size=m1.nq), rng.normal(size=m1.nq)
    F1 = np.array(m1.functions["F"](0.3, q, v, np.zeros(0), m1.p0))
    np.testing.assert_allclose(np.array(m2.functions["F"](0.3, q, v, np.zeros(0), m2.p0)), F1, rtol=1e-14)
    with pytest.raises(ModelError, match=r"rope.*reeled: expected two values"):
        nc.System.from_toml(text.replace('reeled = [0.0, "0.1*t"]', 'reeled = [0, 1, 2]'))
    with pytest.raises(ModelError, match=r"reeled\[1\]"):
        nc.System.from_toml(text.replace('"0.1*t"', '"0.1*tt"'))
    damped = winch("w")
    damped.add_input("w")
    with pytest.raises(ModelError, match=r"rope.*reeled\[1\]: an input's rate is unknown .* damping = 0"):
        damped.build()
