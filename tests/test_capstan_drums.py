"""CapstanCable with several friction drums, a drum on a moving member, and its friction
coefficient as a model parameter, against closed forms of the massless inextensible rope.

Rig A (two ground drums): weight m on side a, hand m_h on side c pulled down by F, the
horizontal side b between the drums.  Slipping at both drums towards the hand, the ratios
multiply, T_c = e^{μ₁θ₁} e^{μ₂θ₂} T_a, and with ``m a = T_a − m g``, ``m_h a = F + m_h g − T_c``:

    a = (F + m_h g − e m g)/(m_h + e m),   e = e^{μ₁θ₁ + μ₂θ₂}.

The model's deviations (ncgen/model/capstan.py): at drum k the balance ``T_{k+1} = e_k T_k``
is shifted by ``ε_k`` with ``|ε_k| ≤ |T_k² − T_{k+1}²|/(2EA) + m_s |S̈_k|``, so
``T_c = e T_a + e₂ ε₁ + ε₂`` and the acceleration by ``(e₂|ε₁| + |ε₂|)/(m_h + e m)``.

Rig B (one drum sticks, one slips): weight m on side a over drum 1, side b down to a
frictionless pulley on a block M_B and back up, over drum 2 to the hand (side c).  Drum 1
holding the weight (T_a = m g, T_b/T_a within e^{±μ₁θ₁}), drum 2 slipping towards the hand
(T_c = e₂ T_b), the block rising at half the hand's acceleration a_h:

    M_B (−a_h/2) = M_B g − 2 T_b,   m_h a_h = F + m_h g − T_c
    ⇒ a_h = (F + m_h g − e₂ M_B g/2)/(m_h + e₂ M_B/4).

Rig C (drum on a moving member): a rope from a ceiling anchor down around a drum carried by a
falling block M (wrap π, friction μ) and up over frictionless ceiling pulleys to a hanging
counterweight m_h.  The block falling at a, the rope slides over the drum towards the anchor's
side a (T_a = e T_b), the counterweight rises at 2a:

    M a = M g − T_a − T_b,   2 m_h a = T_b − m_h g
    ⇒ a = (M g − (1 + e) m_h g)/(M + 2 (1 + e) m_h),   e = e^{μπ}.
"""
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError

G = 9.81
MU, M, MH, EA, MS, VS, C = 0.3, 1.0, 0.2, 1e5, 1e-3, 1e-4, 20.0


def _vertical(s, name, mass, x, z=0.0):
    p = s.add_point(name, mass=mass, position=(x, 0, z))
    s.add_joint(nc.PointOnLine(s.ground, p, at=(x, 0, z), axis=(0, 0, 1)))
    return p


def _rests(lengths, tensions):
    return [length / (1 + t / EA) for length, t in zip(lengths, tensions)]


def two_drums(force, wraps=(np.pi, np.pi), mu=(MU, MU)):
    """Rig A (module docstring); ``mu`` may be parameter names."""
    s = nc.System("two_drums", gravity=(0, 0, -G))
    w, h = _vertical(s, "weight", M, -0.1), _vertical(s, "hand", MH, 0.1)
    s.add_force(nc.PointForce(h, (0, 0, 0), force=(0, 0, -force), name="pull"))
    t_a, t_c = M * G, force + MH * G
    path = [(w, (0, 0, 0)), (s.ground, (-0.1, 0, 1)), (s.ground, (0.1, 0, 1)), (h, (0, 0, 0))]
    nc.add_capstan_cable(s, path, pulley=[1, 2], mu=list(mu), wrap=list(wraps), ea=EA, damping=C,
                         rest_lengths=_rests((1.0, 0.2, 1.0), (t_a, np.sqrt(t_a * t_c), t_c)),
                         material_mass=MS, slip_velocity=VS, name="rope")
    return s


def ideal_two(force, e):
    """``(a, T_a, T_c)`` of rig A's ideal rope (0 acceleration: sticking)."""
    ratio = (force + MH * G) / (M * G)
    sign = 1 if ratio > e else -1 if ratio < 1 / e else 0
    if sign == 0:
        return 0.0, M * G, force + MH * G
    f = e**sign
    a = (force + MH * G - f * M * G) / (MH + f * M)
    return a, M * (G + a), force + MH * (G - a)


def run(system, t_end=0.25, **kw):
    model = system.build()
    return model, nc.simulate(model, t_end=t_end, dt=0.005, backend="vm", **kw)


def acceleration(traj, name):
    return 2 * np.polyfit(traj.t, traj.point(name, (0, 0, 0))[:, 2], 2)[0]


def model_error(a, t_a, t_c, e1):
    """The bound on the acceleration's deviation from the ideal rope (module docstring)."""
    t_b = e1 * t_a
    eps1 = abs(t_a**2 - t_b**2) / (2 * EA) + MS * abs(a)
    eps2 = abs(t_b**2 - t_c**2) / (2 * EA) + MS * abs(a)
    return (e1 * eps1 + eps2) / (MH + e1 * e1 * M)


def test_two_drums_slipping_multiply_the_ratios():
    """θ₁ = θ₂ = π, μ = 0.3: e^{μ(θ₁+θ₂)} = 6.59; F = 90 N slips up at both drums, the
    sides' tensions in the ratios 1 : e^{μθ₁} : e^{μ(θ₁+θ₂)}."""
    force, e1 = 90.0, np.exp(MU * np.pi)
    e = e1 * e1
    a, t_a, t_c = ideal_two(force, e)
    assert a > 0
    model, traj = run(two_drums(force))
    fit = acceleration(traj, "weight")
    bound = model_error(a, t_a, t_c, e1)
    assert abs(fit - a) <= 1.2 * bound + 1e-4 * a, (fit, a, bound)
    assert abs(fit - a) < 0.004 * a
    table = model.springs
    assert table.names == ("rope.a", "rope.b", "rope.c")
    q, v = traj.q[-1], traj.v[-1]
    tension = np.array(table.function(traj.t[-1], q, v, np.zeros(0), model.p0)[0]).reshape(-1)
    np.testing.assert_allclose(tension / tension[0], [1, e1, e], rtol=0.01)


@pytest.mark.parametrize("factor, slips", [(0.97, False), (1.03, True)])
def test_two_drums_hold_up_to_the_product_of_the_ratios(factor, slips):
    """The hand side holds the weight up to T_c = W e^{μ(θ₁+θ₂)} (64.6 N), far beyond one
    drum's W e^{μθ₁} (25.2 N): both drums carry."""
    e = np.exp(2 * MU * np.pi)
    force = factor * M * G * e - MH * G
    assert force + MH * G > 2 * M * G * np.exp(MU * np.pi)
    a, _, _ = ideal_two(force, e)
    _, traj = run(two_drums(force), t_end=0.2)
    z = traj.point("weight", (0, 0, 0))[:, 2]
    if slips:
        assert a > 0 and z[-1] == pytest.approx(0.5 * a * traj.t[-1] ** 2, rel=0.05)
    else:
        assert a == 0 and abs(z[-1]) < 1e-4


def test_two_drums_energy_friction_dissipates():
    """F = 90 N: E(t) − E(0) = W_F − D, D ≥ 0 and D the two drums' friction work
    ((e₁ − 1) T_a + (e₂ − 1) T_b) Δs to 1 %."""
    force, e1 = 90.0, np.exp(MU * np.pi)
    a, t_a, _ = ideal_two(force, e1 * e1)
    _, traj = run(two_drums(force))
    zh = traj.point("hand", (0, 0, 0))[:, 2]
    work = -force * (zh - zh[0])
    dissipated = work - (traj.energy - traj.energy[0])
    assert np.all(dissipated >= -1e-6 * np.abs(work).max())
    slid = 0.5 * a * traj.t[-1] ** 2
    friction = ((e1 - 1) * t_a + (e1 - 1) * e1 * t_a) * slid
    assert dissipated[-1] == pytest.approx(friction, rel=0.01)


def stick_and_slip(force, mu1):
    """Rig B (module docstring): block M_B = 2 kg, weight m = 0.5 kg, θ₁ = θ₂ = π."""
    mb, m = 2.0, 0.5
    s = nc.System("stick_and_slip", gravity=(0, 0, -G))
    w, b, h = _vertical(s, "weight", m, -0.2), _vertical(s, "block", mb, 0.0), _vertical(s, "hand", MH, 0.2)
    s.add_force(nc.PointForce(h, (0, 0, 0), force=(0, 0, -force), name="pull"))
    path = [(w, (0, 0, 0)), (s.ground, (-0.2, 0, 1)), (s.ground, (0, 0, 1)), (b, (0, 0, 0)),
            (s.ground, (0, 0, 1)), (s.ground, (0.2, 0, 1)), (h, (0, 0, 0))]
    t_b = mb * G / 2
    nc.add_capstan_cable(s, path, pulley=[1, 5], mu=[mu1, MU], wrap=[np.pi, np.pi], ea=EA, damping=C,
                         rest_lengths=_rests((1.0, 2.4, 1.0), (m * G, t_b, force + MH * G)),
                         material_mass=MS, slip_velocity=VS, name="rope")
    return s, mb, m


def test_one_drum_sticks_the_other_slips():
    """F = 25 N: drum 2 slips (T_c = 26.96 N > e^{μπ} T_b = 25.17 N), the hand falls at
    a_h = 1.21 m/s² and the block rises at a_h/2, while drum 1 (T_b/T_a ≈ 2.1 < 2.57) holds
    the weight; without friction at drum 1 the weight rises instead."""
    force = 25.0
    s, mb, m = stick_and_slip(force, MU)
    e2 = np.exp(MU * np.pi)
    a_h = (force + MH * G - e2 * mb * G / 2) / (MH + e2 * mb / 4)
    t_b = mb * (G + a_h / 2) / 2
    assert a_h > 0 and t_b / (m * G) < e2
    _, traj = run(s)
    fit_h, fit_b = -acceleration(traj, "hand"), acceleration(traj, "block")
    assert abs(fit_h - a_h) < 0.01 * a_h, (fit_h, a_h)
    assert abs(fit_b - a_h / 2) < 0.01 * a_h, (fit_b, a_h / 2)
    assert np.max(np.abs(traj.point("weight", (0, 0, 0))[:, 2])) < 1e-4
    _, free = run(stick_and_slip(force, 0.0)[0])
    assert free.point("weight", (0, 0, 0))[-1, 2] > 0.01


def movable_drum(mu=MU):
    """Rig C (module docstring): block M = 2 kg carrying the drum, counterweight m_h = 0.2 kg."""
    mb = 2.0
    s = nc.System("movable_drum", gravity=(0, 0, -G))
    b, h = _vertical(s, "block", mb, 0.0), _vertical(s, "counterweight", MH, 0.3)
    path = [(s.ground, (0, 0, 1)), (b, (0, 0, 0)), (s.ground, (0, 0, 1)), (s.ground, (0.3, 0, 1)), (h, (0, 0, 0))]
    e = np.exp(mu * np.pi)
    t_b = (mb * G) / (1 + e)
    nc.add_capstan_cable(s, path, pulley=1, mu=mu, wrap=np.pi, ea=EA, damping=C,
                         rest_lengths=_rests((1.0, 2.3), (e * t_b, t_b)), material_mass=MS, slip_velocity=VS,
                         name="rope")
    return s, mb


def test_drum_on_a_falling_block_as_the_closed_form():
    """μ = 0.3, θ = π: the block falls at a = (M g − (1+e) m_h g)/(M + 2(1+e) m_h) = 3.69 m/s²,
    the counterweight rises at 2a; energy: E(t) − E(0) = −D, D ≥ 0 and the friction's work
    (e − 1) T_b Δs (Δs the slid length, the block's drop) to 1 %."""
    s, mb = movable_drum()
    e = np.exp(MU * np.pi)
    a = (mb * G - (1 + e) * MH * G) / (mb + 2 * (1 + e) * MH)
    _, traj = run(s)
    fit_b, fit_h = -acceleration(traj, "block"), acceleration(traj, "counterweight")
    assert abs(fit_b - a) < 0.005 * a, (fit_b, a)
    assert abs(fit_h - 2 * a) < 0.01 * a, (fit_h, 2 * a)
    dissipated = -(traj.energy - traj.energy[0])
    assert np.all(dissipated >= -1e-9 * np.abs(traj.energy).max())
    t_b = MH * (G + 2 * a)
    drop = 0.5 * a * traj.t[-1] ** 2
    assert dissipated[-1] == pytest.approx((e - 1) * t_b * drop, rel=0.01)


def test_a_sweep_over_mu_as_a_parameter_reproduces_the_capstan_law():
    """One build, μ a parameter: the weight's acceleration on rig A at F = 90 N follows
    e^{μ(θ₁+θ₂)} for μ = 0.2, 0.3, 0.35 (slipping, within the model's stated bound), and
    μ = 0.4 (e^{0.8π} = 12.3 > 9.37 = (F + m_h g)/(m g)) sticks."""
    s = two_drums(90.0, mu=("mu", "mu"))
    s.add_parameter("mu", MU)
    model = s.build()
    for mu in (0.2, 0.3, 0.35, 0.4):
        e1 = np.exp(mu * np.pi)
        a, t_a, t_c = ideal_two(90.0, e1 * e1)
        traj = nc.simulate(model, t_end=0.25, dt=0.005, backend="vm", p={"mu": mu})
        fit = acceleration(traj, "weight")
        if a:
            assert abs(fit - a) <= 1.2 * model_error(a, t_a, t_c, e1) + 1e-4 * a, (mu, fit, a)
        else:
            assert mu == 0.4 and np.max(np.abs(traj.point("weight", (0, 0, 0))[:, 2])) < 1e-4


def test_toml_round_trip_of_several_drums_and_parameters():
    s = two_drums(90.0, mu=("mu", 0.3))
    s.add_parameter("mu", MU)
    text = s.to_toml()
    assert "pulley = [1, 2]" in text and 'mu = ["mu", 0.3]' in text
    back = nc.System.from_toml(text)
    assert back.to_toml() == text
    m1, m2 = s.build(), back.build()
    rng = np.random.default_rng(3)
    q, v = m1.q0 + 0.01 * rng.normal(size=m1.nq), rng.normal(size=m1.nq)
    F1 = np.array(m1.functions["F"](0, q, v, np.zeros(0), m1.p0))
    np.testing.assert_allclose(np.array(m2.functions["F"](0, q, v, np.zeros(0), m2.p0)), F1, rtol=1e-14)
    assert np.abs(F1).max() > 1.0
    for old, new, message in (("pulley = [1, 2]", "pulley = [2, 1]", r"pulley: expected .* an increasing list"),
                              ('mu = ["mu", 0.3]', 'mu = ["mu", 0.3, 0.3]', r"mu: expected one value or one per drum \(2\), got 3"),
                              ('mu = ["mu", 0.3]', 'mu = ["nu", 0.3]', r"mu\[0\]")):
        assert old in text
        with pytest.raises(ModelError, match=message):
            nc.System.from_toml(text.replace(old, new))
    with pytest.raises(ModelError, match=r"to_toml: .*rope.*: wrap: a list with None .* has no TOML form"):
        two_drums(90.0, wraps=(None, np.pi)).to_toml()


def test_several_drums_bad_values_are_named():
    s = nc.System("bad", gravity=(0, 0, -G))
    w, h = s.add_point("w", mass=1.0, position=(0, 0, 0)), s.add_point("h", mass=1.0, position=(1, 0, 0))
    path = [(w, (0, 0, 0)), (s.ground, (0, 0, 1)), (s.ground, (1, 0, 1)), (h, (0, 0, 0))]
    ok = dict(pulley=[1, 2], mu=0.3, wrap=[np.pi, np.pi], ea=1e4, rest_lengths=(1.0, 1.0, 1.0), material_mass=1e-3)
    for key, value, message in (("rest_lengths", (1.0, 1.0), r"rest_lengths: expected 3 rest lengths > 0 \(m\), one per side \(a to c\)"),
                                ("wrap", [np.pi], r"wrap: expected one value or one per drum \(2\), got 1"),
                                ("mu", [0.3, -0.1], r"mu\[1\]: expected a finite number >= 0, got -0.1"),
                                ("pulley", [1, 1], r"pulley: expected .* an increasing list"),
                                ("pulley", [1, 3], r"pulley: expected the index of an inner point of the path \(1 to 2\)")):
        with pytest.raises(ModelError, match=message):
            nc.add_capstan_cable(s, path, **{**ok, key: value}, name=f"bad_{key}")
    assert list(s.members) == ["w", "h"]


def free_rig(mu=0.0, damping=0.0):
    """No gravity, three drums: on the ground, on a moving point and on the ground again, wrap
    angles from the shape at the moving one."""
    s = nc.System("free_drums", gravity=(0, 0, 0))
    pts = [s.add_point(f"p{i}", mass=1.0, position=x) for i, x in
           enumerate([(0, 0, 0), (1.5, 1, 0.3), (0.2, 1.4, -0.1), (-0.5, 2.0, 0.4)])]
    path = [(s.ground, (-1, 0, 0)), (pts[0], (0, 0, 0)), (s.ground, (1, 0.2, 0)), (pts[1], (0, 0, 0)),
            (pts[2], (0, 0, 0)), (s.ground, (0, 2.5, 0)), (pts[3], (0, 0, 0))]
    nc.add_capstan_cable(s, path, pulley=[2, 4, 5], mu=[mu, 0.5 * mu, mu], wrap=[2.0, None, 1.0], ea=300.0,
                         rest_lengths=(1.5, 1.2, 0.8, 0.9), material_mass=0.1, damping=damping, name="rope")
    return s.build()


def test_several_drums_elastic_force_is_minus_the_gradient_of_the_potential():
    """At rest (no damping; friction is 0 at zero slip rate) ``Q = −∂V/∂q``, the three
    materials' rows included (central differences, h = 1e-6)."""
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


def test_several_drums_friction_and_damping_only_dissipate():
    """``Qᵀv + ∂V/∂q v = −Σ F_f,k Ṡ_k − c Σ (stretching rate)² ≤ 0`` at random states."""
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


def test_viewer_rows_are_the_sides():
    """Rig B: three sides ``rope.a/b/c`` drawn as 1, 4 and 1 segments, each coloured by its own
    tension (equal to the table's row); drum 2 slipping: T_c/T_b = e^{μπ} within 1 %."""
    from ncgen.viz.scene import spring_scene

    model, traj = run(stick_and_slip(25.0, MU)[0])
    scene = spring_scene(traj)
    assert scene["spring_names"] == ["rope.a", "rope.b", "rope.c"]
    np.testing.assert_array_equal(scene["spring_owner"], [0, 1, 1, 1, 1, 2])
    tension = np.array(model.springs.function.map(len(traj))(traj.t[None, :], traj.q.T, traj.v.T, traj.u.T,
                                                              np.zeros((0, len(traj))))[0]).T
    np.testing.assert_allclose(scene["spring_tension"], tension[:, scene["spring_owner"]], rtol=1e-12)
    late = traj.t > 0.1
    np.testing.assert_allclose(tension[late, 2] / tension[late, 1], np.exp(MU * np.pi), rtol=0.01)
    assert scene["spring_ends"].shape[1] == 6


def test_compiled_stepper_with_a_drum_on_a_moving_block(tmp_path, monkeypatch):
    """Rig C in the compiled stepper (RATTLE, generated C; 0.125 ms steps for the stiff
    material mode): the block falls at the closed form's a within 0.5 %."""
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    s, mb = movable_drum()
    e = np.exp(MU * np.pi)
    a = (mb * G - (1 + e) * MH * G) / (mb + 2 * (1 + e) * MH)
    traj = nc.simulate(s.build(), t_end=0.25, dt=0.005, method="stepper", substeps=40)
    fit = -acceleration(traj, "block")
    assert abs(fit - a) < 0.005 * a, (fit, a)


def _parametric_rig(values, names=None):
    s = nc.System("parametric_drums", gravity=(0, 0, -G))
    pts = [s.add_point(f"p{i}", mass=1.0, position=x) for i, x in enumerate([(0, 0, 0), (1.5, 1, 0.3), (0.2, 1.4, -0.1)])]
    path = [(pts[0], (0, 0, 0)), (s.ground, (1, 0.2, 0)), (pts[1], (0, 0, 0)), (s.ground, (0, 2.5, 0)),
            (pts[2], (0, 0, 0))]
    if names:
        for n, v in zip(names, values):
            s.add_parameter(n, v)
    mu, wrap, ea, r0, r1, r2 = names or values
    nc.add_capstan_cable(s, path, pulley=[1, 3], mu=[mu, 0.2], wrap=[wrap, 1.0], ea=ea, rest_lengths=(r0, r1, r2),
                         material_mass=0.1, damping=1.0, name="rope")
    return s.build()


def test_parameters_give_what_a_rebuild_with_their_values_gives():
    """μ, θ, EA and the rest lengths as parameters: F and the energy at p equal those of a
    model built with p's numbers (random states), and differ from the defaults'."""
    names = ("mu", "wrap", "ea", "r0", "r1", "r2")
    default, other = (0.3, 2.0, 300.0, 1.2, 1.1, 0.9), (0.5, 2.5, 450.0, 1.3, 1.0, 1.0)
    model = _parametric_rig(default, names)
    rebuilt = _parametric_rig(other)
    rng = np.random.default_rng(5)
    p = np.array(other)
    for _ in range(5):
        q, v = model.q0 + 0.05 * rng.normal(size=model.nq), rng.normal(size=model.nq)
        F = np.array(model.functions["F"](0, q, v, np.zeros(0), p)).reshape(-1)
        np.testing.assert_allclose(F, np.array(rebuilt.functions["F"](0, q, v, np.zeros(0), np.zeros(0))).reshape(-1),
                                   rtol=1e-12, atol=1e-12 * np.abs(F).max())
        V = float(model.functions["energy"](0, q, v, p)[1])
        assert V == pytest.approx(float(rebuilt.functions["energy"](0, q, v, np.zeros(0))[1]), rel=1e-12)
        assert np.abs(F - np.array(model.functions["F"](0, q, v, np.zeros(0), model.p0)).reshape(-1)).max() > 1e-3
