"""A wheel as a torus of given radii (``RollingDisc(..., radius=R, tube_radius=r)``, a tyre)
rolling without slipping: its steady precession against the closed form of the Newton–Euler
equations of steady turning (derived below and checked as vectors), its steady upright
rolling, energy and both constraint levels on the three integrators (projected Runge–Kutta,
IDAS, the RATTLE stepper), the upright wheel's linearisation and stability limit against their
closed form, the r → 0 limit (the knife-edge disc), TOML, the model's hash and the viewer's
torus.

Steady turning: tilt β (the axle ``k = cos β e_y + sin β e_z``, ``d = cos β e_z − sin β e_y``
toward the top of the wheel's plane), heading turning at Ω about ``e_z = sin β k + cos β d``,
spin ``w3 = ω·k``, so ``ω = w3 k + Ω cos β d``.  The contact ``P = G − R d − r e_z``; rolling
gives ``v_G = ω × (G − P) = V e_x`` with ``V = w3 (R + r cos β) − Ω r sin β cos β``; the
centre's acceleration is ``Ω e_z × v_G`` and ``dH_G/dt = Ω e_z × H_G`` (``H_G = C w3 k +
A Ω cos β d``).  Euler's equation about G with the contact force ``F = m a_G + m g e_z``,
``Ω e_z × H_G = (P − G) × F``, has one nonzero component (along ``e_x``):

    Ω² [A sβ cβ + m r sβ cβ (R cβ + r)] − Ω w3 [C cβ + m (R cβ + r)(R + r cβ)] − m g R sβ = 0,

which for r = 0 is the disc's ``A Ω² sβ cβ − (C + m R²) w3 Ω cβ − m g R sβ = 0``."""
import casadi as ca
import numpy as np
import pytest
from scipy.optimize import brentq

import ncgen as nc
from ncgen.analysis.steady_motion import linearize_steady, spin_generator, translation_rate
from ncgen.assembly.nonholonomic import coordinate_function, rolling_system
from ncgen.errors import ModelError
from ncgen.viz.geometry import member_primitives, outline
from test_rolling import steady_precession

#: The wheel: mass (kg), radii (m), a solid torus' moments about a diameter and the axle (kg m²).
m, R, r, g = 1.0, 0.1, 0.03, 9.81
A_t, C_t = m * (R ** 2 / 2 + 5 * r ** 2 / 8), m * (R ** 2 + 3 * r ** 2 / 4)
BETA, W3 = 0.2, 30.0


def torus_precession(beta, w3, A=A_t, C=C_t, big=R, tube=r):
    """Ω (rad/s) of steady turning, the slower root of the module docstring's quadratic."""
    s, c = np.sin(beta), np.cos(beta)
    coeffs = [A * s * c + m * tube * s * c * (big * c + tube), -w3 * (C * c + m * (big * c + tube) * (big + tube * c)),
              -m * g * big * s]
    return min(np.roots(coeffs), key=abs).real


def steady_state(beta, w3, omega, wobble=0.0):
    """``(G, rotation, v_G, ω)`` of the tilted wheel turning steadily, contact at the origin,
    plus ``wobble`` (rad/s) about the rolling direction (then not steady)."""
    ex, ey, ez = np.eye(3)
    k = np.cos(beta) * ey + np.sin(beta) * ez
    d = np.cos(beta) * ez - np.sin(beta) * ey
    G = R * d + r * ez
    w = omega * ez + (w3 - omega * np.sin(beta)) * k + wobble * ex
    return G, np.column_stack([ex, k, d]), np.cross(w, G), w


def torus_wheel(beta=BETA, w3=W3, omega=None, wobble=0.0, tube=r):
    omega = torus_precession(beta, w3) if omega is None else omega
    G, rot, vG, w = steady_state(beta, w3, omega, wobble)
    s = nc.System("torus_wheel", gravity=(0.0, 0.0, -g))
    s.add_body("wheel", mass=m, inertia=np.diag([A_t, C_t, A_t]), position=G, rotation=rot, velocity=vG,
               angular_velocity=w)
    s.add_rolling(nc.RollingDisc("wheel", radius=R, tube_radius=tube))
    return s


@pytest.fixture(scope="module")
def precessing():
    return torus_wheel().build()


def axle(model, q):
    return q[:, model.layout.member_indices("wheel")[6:9]]


def test_the_closed_form_satisfies_newton_euler_as_vectors():
    """Independent of the quadratic's algebra: at its root, ``Ω e_z × (I ω) = (P − G) × (m a_G
    + m g e_z)`` holds in all three components, with ``I`` the world inertia; at r = 0 the root
    is the disc's of tests/test_rolling.py."""
    for beta, w3 in ((0.2, 30.0), (0.6, 12.0), (-0.4, 20.0)):
        omega = torus_precession(beta, w3)
        G, rot, vG, w = steady_state(beta, w3, omega)
        ez = np.array([0.0, 0.0, 1.0])
        P = np.zeros(3)
        assert abs(vG[2]) < 1e-15
        aG = omega * np.cross(ez, vG)
        H = rot @ np.diag([A_t, C_t, A_t]) @ rot.T @ w
        residual = omega * np.cross(ez, H) - np.cross(P - G, m * aG + m * g * ez)
        assert np.max(np.abs(residual)) < 1e-13 * max(1.0, np.max(np.abs(H * omega)))
    from test_rolling import A_d, C_d, a
    assert torus_precession(0.3, 25.0, A_d, C_d, a, 0.0) == pytest.approx(steady_precession(0.3, 25.0), rel=1e-13)


def test_steady_precession_on_the_rolling_integrator(precessing):
    """Tilt kept to 1e-8 rad, heading rate within 1e-7 of the closed form, energy and both
    constraint levels at round-off; the centre stays at height R cos β + r."""
    omega = torus_precession(BETA, W3)
    tr = nc.simulate(precessing, 0.5, 0.02, method="rolling", rtol=1e-10, atol=1e-12, backend="vm")
    k = axle(precessing, tr.q)
    assert np.max(np.abs(np.arcsin(k[:, 2]) - BETA)) < 1e-8
    heading = np.unwrap(np.arctan2(-k[:, 0], k[:, 1]))
    assert abs(np.polyfit(tr.t, heading, 1)[0] / omega - 1) < 1e-7
    np.testing.assert_allclose(tr.point("wheel", (0, 0, 0))[:, 2], R * np.cos(BETA) + r, rtol=0, atol=1e-10)
    assert np.ptp(tr.energy) <= 1e-9 * np.max(np.abs(tr.energy))
    assert max(tr.constraint_residual.max(), tr.velocity_residual.max()) <= 1e-12
    # the knife-edge disc of the same radius and state turns at another rate (the tube matters)
    assert abs(torus_precession(BETA, W3, tube=0.0) / omega - 1) > 0.05


def test_steady_precession_on_idas_and_the_stepper(precessing):
    """IDAS (rtol 1e-10) and RATTLE (h = 1 ms): heading rate within 1e-5 and 1e-4 of the
    closed form, both constraint levels at the outputs ≤ 1e-10 and ≤ 1e-12."""
    omega = torus_precession(BETA, W3)
    for method, kw, tol, level in (("idas", {"rtol": 1e-10, "atol": 1e-12}, 1e-5, 1e-10),
                                   ("stepper", {"substeps": 20}, 1e-4, 1e-12)):
        tr = nc.simulate(precessing, 0.5, 0.02, method=method, **kw)
        k = axle(precessing, tr.q)
        heading = np.unwrap(np.arctan2(-k[:, 0], k[:, 1]))
        assert abs(np.polyfit(tr.t, heading, 1)[0] / omega - 1) < tol, method
        assert max(tr.constraint_residual.max(), tr.velocity_residual.max()) <= level, method
        np.testing.assert_allclose(-tr.lam[:, precessing.nc], m * g, rtol=10 * tol)


def upright_linearisation(speed):
    """``linearize_steady`` of the upright torus wheel rolling along x at ``speed`` (m/s), in
    lean and heading (as tests/test_rolling.py does for the disc)."""
    model = torus_wheel(0.0, 0.0, 0.0).build()
    rs = rolling_system(model)
    K = spin_generator(model, "wheel", (0.0, 1.0, 0.0))
    T = translation_rate(model, (1.0, 0.0, 0.0))
    Aq = np.asarray(rs.A(model.q0))
    rate = np.linalg.lstsq((Aq @ K @ model.q0)[:, None], -Aq @ T, rcond=None)[0][0]
    idx = model.layout.member_indices("wheel")

    def lean_heading(q):
        k = q[idx[6]], q[idx[7]], q[idx[8]]
        return ca.vertcat(ca.asin(k[2]), ca.atan2(-k[0], k[1]))
    return linearize_steady(rs, model.q0, speed * (T + rate * K @ model.q0), speed * rate * K,
                            coordinate_function(lean_heading, model.nq))


def test_upright_torus_against_the_closed_form_and_its_stability_limit():
    """Lean α and heading ψ of the upright torus wheel rolling at v = ω ρ, ρ = R + r (the
    centre's height): the contact force's lateral part ``m (v ψ̇ + ρ α̈)`` acts at the height ρ
    below the centre, the weight at the horizontal offset ``R α`` (the potential is
    ``m g (R cos α + r)``), so ``(A + m ρ²) α̈ ± (C + m ρ²) ω ψ̇ − m g R α = 0`` and
    ``A ψ̈ ∓ C ω α̇ = 0``; stable above ``v_c = ρ √(m g R A / (C (C + m ρ²)))``."""
    rho, v = R + r, 1.3
    lin = upright_linearisation(v)
    w = v / rho
    assert lin.closure < 1e-11 and lin.reference < 1e-9
    np.testing.assert_allclose(lin.M, np.diag([A_t + m * rho ** 2, A_t]), atol=1e-12)
    np.testing.assert_allclose(np.abs(lin.C), [[0, (C_t + m * rho ** 2) * w], [C_t * w, 0]], atol=1e-12)
    assert lin.C[0, 1] * lin.C[1, 0] < 0
    np.testing.assert_allclose(lin.K, [[-m * g * R, 0], [0, 0]], atol=1e-12)

    def stiffness(speed):       # of α̈ + k α = 0 once ψ̇ is eliminated
        L = upright_linearisation(speed)
        return (L.K[0, 0] - L.C[0, 1] * L.C[1, 0] / L.M[1, 1]) / L.M[0, 0]
    v_c = rho * np.sqrt(m * g * R * A_t / (C_t * (C_t + m * rho ** 2)))
    assert abs(brentq(stiffness, 0.1, 2.0, xtol=1e-14) - v_c) < 1e-10


def test_steady_upright_rolling():
    """Upright (β = 0, Ω = 0): the centre at height R + r moves straight at w3 (R + r), the
    material point at the contact being at rest."""
    model = torus_wheel(0.0, 20.0, 0.0).build()
    tr = nc.simulate(model, 1.0, 0.05, method="rolling", rtol=1e-10, atol=1e-12, backend="vm")
    centre = tr.point("wheel", (0, 0, 0))
    np.testing.assert_allclose(centre[:, 0], 20.0 * (R + r) * tr.t, rtol=0, atol=1e-9)
    np.testing.assert_allclose(centre[:, 1:], np.column_stack([0 * tr.t, (R + r) + 0 * tr.t]), rtol=0, atol=1e-9)


def test_a_wobbling_torus_conserves_energy_on_both_levels():
    """Not a steady motion (it wobbles by more than 0.01 rad; 0.055 rad in these 0.4 s): energy
    kept to 1e-9 of itself on the projected DOPRI5 (measured 8.6e-11; 2.2e-10 over 1 s) and
    falling with the stepper's h² (4 ± 0.5 per halving), both levels at round-off."""
    model = torus_wheel(0.3, 25.0, 0.0, wobble=1.0).build()
    tr = nc.simulate(model, 0.4, 0.02, method="rolling", rtol=1e-10, atol=1e-12, backend="vm")
    assert np.ptp(np.arcsin(axle(model, tr.q)[:, 2])) > 0.01
    assert np.ptp(tr.energy) <= 1e-9 * np.max(np.abs(tr.energy))
    assert max(tr.constraint_residual.max(), tr.velocity_residual.max()) <= 1e-12
    spread = []
    for n in (5, 10):
        st = nc.simulate(model, 0.4, 0.02, method="stepper", substeps=n, check=False)     # h = 4, 2 ms: coarse
        assert max(st.constraint_residual.max(), st.velocity_residual.max()) <= 1e-12
        spread.append(np.ptp(st.energy))
    assert 3.5 < spread[0] / spread[1] < 4.5, spread


def test_toml_round_trip_hash_and_errors():
    s = torus_wheel()
    text = s.to_toml()
    assert "tube_radius = 0.03" in text
    model = s.build()
    again = nc.System.from_toml(text).build()
    assert again.rolling[0].tube_radius == r and again.content_hash == model.content_hash
    # a knife-edge disc's table and hash are those of a disc without the key
    plain = torus_wheel(tube=0.0)
    assert "tube_radius" not in plain.to_toml() and "tube_radius" not in plain.rolling[0].spec()
    assert plain.build().content_hash != model.content_hash
    for value, expected in (("-0.1", "rolling\\[0\\].*tube_radius: expected a number ≥ 0 "
                                      "\\(m; 0: a knife-edge disc\\), found -0.1"),
                            ('"thin"', "rolling\\[0\\].tube_radius")):
        with pytest.raises(ModelError, match=expected):
            nc.System.from_toml(text.replace("tube_radius = 0.03", f"tube_radius = {value}"))
    with pytest.raises(ModelError, match="tube"):
        nc.System.from_toml(text.replace("tube_radius = 0.03", "tube = 0.03"))
    with pytest.raises(ModelError, match="tube_radius: expected a number ≥ 0"):
        nc.RollingDisc("wheel", radius=R, tube_radius=float("nan"))


def test_the_viewer_draws_the_torus(precessing, tmp_path):
    tr = nc.simulate(precessing, 0.1, 0.05, method="rolling", backend="vm")
    html = tr.to_html(tmp_path / "torus.html").read_text()
    assert '"kind":"torus","size":[0.1,0.03]' in html and "case 'torus': return new THREE.TorusGeometry" in html
    prims = member_primitives(precessing, 1.0)["wheel"]
    assert [p.kind for p in prims] == ["torus"]
    np.testing.assert_allclose(prims[0].size, [R, r])
    pts = outline(prims[0])
    pts = pts[~np.isnan(pts[:, 0])]
    # about the axle (body y): every point within the tube of the centre circle, reaching R + r
    radial = np.hypot(pts[:, 0], pts[:, 2])
    np.testing.assert_allclose(np.hypot(radial - R, pts[:, 1]), r, rtol=0, atol=1e-12)
    assert radial.max() == pytest.approx(R + r)
