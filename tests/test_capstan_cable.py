"""CapstanCable (ncgen.model.capstan): a weight held or lifted by a rope over a drum with
friction, against the capstan law's closed forms at θ = π and 2π with μ = 0.3 (stick and
slip), the energy balance (the friction only dissipates), the elastic force against finite
differences of the potential, bad input named.

The rig (examples/capstan_lift.py): weight m on side a, hand m_h on side b pulled down by F;
rope tensions T_a (weight side), T_b (hand side).  Newton, the weight rising at acceleration a
(the hand falling at a, a massless inextensible rope):

    m a = T_a − m g,        m_h a = F + m_h g − T_b.

Sticking: a = 0, T_a = m g, T_b = F + m_h g, possible while e^{−μθ} ≤ T_b/T_a ≤ e^{μθ}.
Slipping up (T_b > e^{μθ} T_a at rest): the hand side is the high side, T_b = e^{μθ} T_a, so
F + m_h g − m_h a = e^{μθ} m (g + a), i.e. a = (F + m_h g − e^{μθ} m g)/(m_h + e^{μθ} m)
(m_h → 0: a = g (F e^{−μθ}/(m g) − 1)).  Slipping down: e^{−μθ} in place of e^{μθ}.

The model's deviations from it (ncgen/model/capstan.py): the material's momentum ``m_s s̈``
and the strain terms ``(T_a² − T_b²)/(2EA)`` of the drive shift the tension balance by
``δ = (T_a² − T_b²)/(2EA) − m_s s̈`` (N), hence the acceleration by ``|δ|/(m_h + e^{±μθ} m)``;
the tanh regularisation adds ``1 − tanh(|ṡ|/v_s)`` (negligible once ``|ṡ| ≫ v_s``) and, while
sticking, a creep ``v_s atanh(|P|/F_max)``.
"""
import importlib.util
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError
from ncgen.model.capstan import CapstanCable, add_capstan_cable

G = 9.81
MU, M, MH, EA, MS, VS = 0.3, 1.0, 0.2, 1e5, 1e-3, 1e-4
_spec = importlib.util.spec_from_file_location("capstan_lift", Path(__file__).resolve().parent.parent
                                               / "examples" / "capstan_lift.py")
example = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(example)


def run(force, wrap, t_end=0.25):
    model = example.capstan_lift(force, wrap, mu=MU, mass=M, hand=MH, ea=EA, material_mass=MS, slip_velocity=VS).build()
    return model, nc.simulate(model, t_end=t_end, dt=0.005, backend="vm")


def ideal(force, wrap):
    """``(a, T_a, T_b)`` of the massless inextensible rope (module docstring)."""
    e = np.exp(MU * wrap)
    ratio = (force + MH * G) / (M * G)
    sign = 1 if ratio > e else -1 if ratio < 1 / e else 0
    if sign == 0:
        return 0.0, M * G, force + MH * G
    f = e**sign
    a = (force + MH * G - f * M * G) / (MH + f * M)
    return a, M * (G + a), force + MH * (G - a)


@pytest.mark.parametrize("wrap, force, slips", [
    (np.pi, 0.0, True), (np.pi, 10.0, False), (np.pi, 30.0, True),
    (2 * np.pi, 0.0, False), (2 * np.pi, 30.0, False), (2 * np.pi, 70.0, True)])
def test_stick_and_slip_as_the_capstan_law(wrap, force, slips):
    """θ = π: e^{μθ} = 2.566, the 9.81 N weight is held by 3.82 to 25.2 N on the hand side
    (F + m_h g); θ = 2π: e^{μθ} = 6.586, 1.49 to 64.6 N."""
    a, t_a, t_b = ideal(force, wrap)
    assert (a != 0) == slips
    _, traj = run(force, wrap)
    z = traj.point("weight", (0, 0, 0))[:, 2]
    if slips:
        fit = 2 * np.polyfit(traj.t, z, 2)[0]
        e = np.exp(MU * wrap * np.sign(a))
        delta = abs(t_a**2 - t_b**2) / (2 * EA) + MS * abs(a)
        assert abs(fit - a) <= 1.2 * delta / (MH + e * M) + 1e-4 * abs(a), (fit, a)
        assert abs(fit - a) < 0.004 * abs(a)
    else:
        e = np.exp(MU * wrap)
        drive = abs(t_a - t_b)
        bound = (e - 1) * (t_b if t_a > t_b else t_a)
        creep = VS * np.arctanh(drive / bound)
        assert np.max(np.abs(z)) <= 1.5 * creep * traj.t[-1] + 1e-9


@pytest.mark.parametrize("factor, slips", [(0.97, False), (1.03, True)])
def test_the_holding_limit_is_w_e_mu_theta(factor, slips):
    """θ = π: the hand side sticks up to T_b = W e^{μθ} and slips just above."""
    force = factor * M * G * np.exp(MU * np.pi) - MH * G
    a, _, _ = ideal(force, np.pi)
    _, traj = run(force, np.pi, t_end=0.2)
    z = traj.point("weight", (0, 0, 0))[:, 2]
    if slips:
        assert a > 0 and z[-1] == pytest.approx(0.5 * a * traj.t[-1] ** 2, rel=0.05)
    else:
        assert a == 0 and abs(z[-1]) < 1e-4


def test_energy_balance_friction_dissipates():
    """θ = π, F = 30 N (slipping up): E(t) − E(0) = W_F − D with the pull's work
    W_F = −F (z_h(t) − z_h(0)) and the dissipation D ≥ 0, D close to the capstan friction's work
    (e^{μθ} − 1) T_a |Δs| (friction on the low side's tension over the slid length)."""
    force, wrap = 30.0, np.pi
    a, t_a, _ = ideal(force, wrap)
    _, traj = run(force, wrap)
    zh = traj.point("hand", (0, 0, 0))[:, 2]
    work = -force * (zh - zh[0])
    dissipated = work - (traj.energy - traj.energy[0])
    assert np.all(dissipated >= -1e-6 * np.abs(work).max())
    slid = 0.5 * a * traj.t**2
    friction = (np.exp(MU * wrap) - 1) * t_a * slid
    np.testing.assert_allclose(dissipated[-1], friction[-1], rtol=0.01)


def free_rig(mu=0.0, damping=0.0):
    s = nc.System("free_capstan", gravity=(0, 0, 0))
    pts = [s.add_point(f"p{i}", mass=1.0, position=x) for i, x in enumerate([(0, 0, 0), (1.5, 1, 0.3), (0.2, 1.4, -0.1)])]
    path = [(s.ground, (-1, 0, 0)), (pts[0], (0, 0, 0)), (s.ground, (1, 0.2, 0)), (pts[1], (0, 0, 0)), (pts[2], (0, 0, 0))]
    add_capstan_cable(s, path, pulley=2, mu=mu, wrap=2.0, ea=300.0, rest_lengths=(1.5, 2.0), material_mass=0.1,
                      damping=damping, name="rope")
    return s.build()


def test_elastic_force_is_minus_the_gradient_of_the_potential():
    """At rest (no friction, no damping) ``Q = −∂V/∂q``, the material's row included."""
    model = free_rig(mu=0.3)
    rng = np.random.default_rng(0)
    q = model.q0 + 0.05 * rng.normal(size=model.nq)
    zero_v, u, p = np.zeros(model.nq), np.zeros(0), np.zeros(0)
    F = np.array(model.functions["F"](0, q, zero_v, u, p)).reshape(-1)
    V = lambda x: float(model.functions["energy"](0, x, zero_v, p)[1])
    h = 1e-6
    grad = np.array([(V(q + h * e) - V(q - h * e)) / (2 * h) for e in np.eye(model.nq)])
    np.testing.assert_allclose(F, -grad, atol=1e-6 * np.abs(F).max())
    assert np.abs(F).max() > 1.0


def test_friction_and_damping_only_dissipate():
    """``Qᵀv + ∂V/∂q v = −F_f ṡ − c Σ (stretching rate)² ≤ 0`` at random states."""
    model = free_rig(mu=0.3, damping=2.0)
    rng = np.random.default_rng(1)
    u, p, h = np.zeros(0), np.zeros(0), 1e-6
    powers = []
    for _ in range(20):
        q = model.q0 + 0.05 * rng.normal(size=model.nq)
        v = rng.normal(size=model.nq)
        F = np.array(model.functions["F"](0, q, v, u, p)).reshape(-1)
        dV = (float(model.functions["energy"](0, q + h * v, v, p)[1])
              - float(model.functions["energy"](0, q - h * v, v, p)[1])) / (2 * h)
        powers.append(F @ v + dV)
    assert max(powers) <= 1e-6 and min(powers) < -1e-2


def test_bad_values_are_named():
    s = nc.System("bad", gravity=(0, 0, -G))
    w = s.add_point("w", mass=1.0, position=(0, 0, 0))
    h = s.add_point("h", mass=1.0, position=(1, 0, 0))
    path = [(w, (0, 0, 0)), (s.ground, (0, 0, 1)), (h, (0, 0, 0))]
    ok = dict(pulley=1, mu=0.3, wrap=np.pi, ea=1e4, rest_lengths=(1.0, 1.4), material_mass=1e-3)
    for key, value, message in (("mu", -0.1, r"mu: expected a finite number >= 0, got -0.1"),
                                ("wrap", 0.0, r"wrap: expected a finite number > 0, got 0"),
                                ("ea", -1.0, r"ea: expected a finite number > 0"),
                                ("damping", -1.0, r"damping: expected a finite number >= 0"),
                                ("slip_velocity", 0.0, r"slip_velocity: expected a finite number > 0"),
                                ("pulley", 2, r"pulley: expected the index of an inner point of the path \(1 to 1\)"),
                                ("rest_lengths", (1.0, -1.0), r"rest_lengths: expected 2 rest lengths > 0 \(m\), one per side \(a to b\)"),
                                ("material_mass", 0.0, r"material_mass: expected a number > 0 \(kg\), got 0"),
                                ("turns", -1, r"turns: expected an integer >= 0, got -1"),
                                ("turns", 1, r"turns: only with wrap = None")):
        with pytest.raises(ModelError, match=message):
            add_capstan_cable(s, path, **{**ok, key: value}, name=f"bad_{key}")
    assert list(s.members) == ["w", "h"]                       # a refused cable adds nothing
    with pytest.raises(ModelError, match=r"material: expected a point member, got b \(bar\)"):
        bar = s.add_bar("b", coords="rr", mass=1.0, ends=[(0, 1, 0), (1, 1, 0)])
        s.add_force(CapstanCable(path, pulley=1, mu=0.3, wrap=1.0, ea=1.0, rest_lengths=(1, 1), material=bar,
                                 axis=(1, 0, 0)))
    with pytest.raises(ModelError, match=r"path: expected three or more"):
        add_capstan_cable(s, path[:2], **ok, name="short")


def test_toml_round_trip_and_bad_values():
    s = example.capstan_lift(30.0, np.pi)
    text = s.to_toml()
    assert 'type = "CapstanCable"' in text
    back = nc.System.from_toml(text)
    assert back.to_toml() == text
    m1, m2 = s.build(), back.build()
    rng = np.random.default_rng(4)
    q, v = m1.q0 + 0.01 * rng.normal(size=m1.nq), rng.normal(size=m1.nq)
    F1 = np.array(m1.functions["F"](0, q, v, np.zeros(0), np.zeros(0)))
    np.testing.assert_allclose(np.array(m2.functions["F"](0, q, v, np.zeros(0), np.zeros(0))), F1, rtol=1e-14)
    assert np.abs(F1).max() > 1.0
    for old, new, message in (("mu = 0.3", "mu = -0.3", r"forces\[1\].*mu: expected a finite number >= 0"),
                              ("pulley = 1", "pulley = 3", r"forces\[1\].*pulley: expected the index of an inner point"),
                              ('material = "rope_material"', 'material = "nobody"', r"forces\[1\]\.material"),
                              ("wrap = 3.14", "wrap = -3.14", r"forces\[1\].*wrap: expected a finite number > 0")):
        assert old in text
        with pytest.raises(ModelError, match=message):
            nc.System.from_toml(text.replace(old, new))


@pytest.mark.parametrize("force", [10.0, 30.0])
def test_compiled_stepper_sticks_and_slips_as_the_closed_form(force, tmp_path, monkeypatch):
    """The compiled stepper (generated C, RATTLE) on the rig at θ = π: it needs steps of
    0.125 ms (``substeps=40`` of 5 ms) for the stiff material mode (m_s = 1 g on a 1e5 N rope)."""
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    model = example.capstan_lift(force, np.pi, mu=MU, mass=M, hand=MH, ea=EA, material_mass=MS,
                                 slip_velocity=VS).build()
    traj = nc.simulate(model, t_end=0.25, dt=0.005, method="stepper", substeps=40)
    z = traj.point("weight", (0, 0, 0))[:, 2]
    a, t_a, t_b = ideal(force, np.pi)
    if a:
        fit = 2 * np.polyfit(traj.t, z, 2)[0]
        assert abs(fit - a) < 0.004 * abs(a), (fit, a)
    else:
        assert np.max(np.abs(z)) < 1e-5


def test_wrap_angle_from_the_shape():
    """``wrap=None``: on the rig the rope comes up into the drum and leaves it horizontally,
    θ = π/2 all along the lift (e^{0.3 π/2} = 1.60): F = 20 N slips as the closed form at
    θ = π/2; at a drum the rope turns back over (weight straight below, θ = π) the force's
    Jacobian stays finite, and ``turns`` adds 2π each."""
    from ncgen.model.capstan import wrap_angle
    u = np.array([0.0, 0, 1])
    assert float(wrap_angle(u, -u, 0)) == pytest.approx(np.pi, abs=1e-8)
    assert float(wrap_angle(u, np.array([1.0, 0, 0]), 1)) == pytest.approx(2.5 * np.pi, abs=1e-12)
    assert float(wrap_angle(u, u, 0)) == pytest.approx(0, abs=1e-8)
    force = 20.0
    model = example.capstan_lift(force, None, mu=MU, mass=M, hand=MH, ea=EA, material_mass=MS,
                                 slip_velocity=VS).build()
    traj = nc.simulate(model, t_end=0.25, dt=0.005, backend="vm")
    a, _, _ = ideal(force, np.pi / 2)
    assert a > 0
    fit = 2 * np.polyfit(traj.t, traj.point("weight", (0, 0, 0))[:, 2], 2)[0]
    assert abs(fit - a) < 0.004 * a, (fit, a)
    s = nc.System("over", gravity=(0, 0, -G))
    w = s.add_point("w", mass=1.0, position=(0, 0, 0))
    h = s.add_point("h", mass=1.0, position=(0, 0, 0.5))
    add_capstan_cable(s, [(w, (0, 0, 0)), (s.ground, (0, 0, 1)), (h, (0, 0, 0))], pulley=1, mu=0.3, ea=1e4,
                      rest_lengths=(0.99, 0.49), material_mass=1e-3, name="rope")
    m = s.build()
    q, v = ca.SX.sym("q", m.nq), ca.SX.sym("v", m.nq)
    J = ca.Function("J", [q, v], [ca.jacobian(m.functions["F"](0, q, v, np.zeros(0), np.zeros(0)), ca.vertcat(q, v))])
    values = np.array(J(m.q0, np.full(m.nq, 0.1)))
    assert np.all(np.isfinite(values)) and np.abs(values).max() > 0
