"""Contacts: gaps and contact Jacobians against finite differences; the nonsmooth compiled
stepper against closed forms (bounce heights, incline stick/slide, rolling), energy through
random impacts, the standalone C program; the smooth (compliant) law with IDAS."""
import shutil
import subprocess
import warnings

import numpy as np
import pytest

import ncgen as nc
from energy_helpers import assert_no_energy_created
from ncgen.codegen.stepper_package import REPEAT_TOL
from ncgen.errors import NcgenError
from ncgen.reproducible import perpendicular_basis
from ncgen.runtime.contact_outputs import OPEN, SLIP, STICK

G = 9.81
QUICK_COMPILE = True             # its time is gcc compiling its scenes: -O0 (tests/conftest.py)


def spinning_ball(R=0.1):
    s = nc.System("ball")
    b = s.add_body("ball", mass=1.3, inertia=0.4 * 1.3 * R**2 * np.eye(3), position=(0.1, -0.2, 0.5),
                   rotation=_rot(0.3, 0.5), velocity=(1.0, 0.4, -2.0), angular_velocity=(0.7, 2.0, -1.1))
    return s, b


def _rot(a, b):
    ca_, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    return np.array([[ca_, -sa, 0], [sa, ca_, 0], [0, 0, 1]]) @ np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])


def material_velocity_fd(model, member, q, v, x_world, eps=1e-7):
    """Velocity of the material point of ``member`` at ``x_world``: its local coordinates
    at q, then the central difference of its world position along v."""
    m = model.member(member)
    R, p = model.poses(q)
    k = model.member_names.index(member)
    rbar = R[k].T @ (x_world - p[k])
    return (m.rigid.position(q + eps * v, rbar) - m.rigid.position(q - eps * v, rbar)) / (2 * eps)


# ----------------------------------------------------------------------------- kinematics
def test_sphere_plane_gap_and_jacobians_against_finite_differences():
    s, b = spinning_ball()
    n = np.array([0.2, -0.1, 1.0]) / np.linalg.norm([0.2, -0.1, 1.0])
    s.add_contact(nc.SpherePlane(b, (0.01, 0.02, 0.0), radius=0.1, point=(0, 0, -0.3), normal=n, mu=0.4))
    model = s.build()
    rng = np.random.default_rng(1)
    for q, v in [(model.q0, model.v0), (model.q0 + 0.01 * rng.standard_normal(12), model.v0)]:
        g = model.gap(q)
        WN, WT = model.contact_jacobian(q)
        dg = np.array([(model.gap(q + 1e-7 * e) - model.gap(q - 1e-7 * e))[0] / 2e-7 for e in np.eye(12)])
        np.testing.assert_allclose(WN[0], dg, atol=1e-7)
    # the normal Jacobian of a plane fixed to the ground is constant (the gap is linear in q)
    WN2, _ = model.contact_jacobian(model.q0 + 0.05 * rng.standard_normal(12))
    np.testing.assert_allclose(WN2, model.contact_jacobian(model.q0)[0], atol=1e-14)
    # tangential velocity: the material point at the contact point, against finite differences
    q, v = model.q0, model.v0
    centre = model.member("ball").rigid.position(q, np.array([0.01, 0.02, 0.0]))
    x = centre - 0.1 * n
    vel = material_velocity_fd(model, "ball", q, v, x)
    WN, WT = model.contact_jacobian(q)
    t1, t2 = perpendicular_basis(n)
    np.testing.assert_allclose(WT @ v, [t1 @ vel, t2 @ vel], atol=1e-7)
    np.testing.assert_allclose(WN @ v, [n @ vel], atol=1e-7)
    assert g.shape == (1,) and abs(model.gap(model.q0)[0] - (n @ (centre - (0, 0, -0.3)) - 0.1)) < 1e-14


def test_sphere_sphere_and_member_plane_relative_velocities():
    s, b = spinning_ball()
    c = s.add_body("c", mass=2.0, inertia=np.diag([0.15, 0.2, 0.25]), position=(0.3, 0.1, 0.2),
                   velocity=(-0.5, 0.2, 0.3), angular_velocity=(-1.0, 0.5, 0.8))
    s.add_contact(nc.SphereSphere(b, (0, 0, 0), 0.1, c, (0.05, 0, 0), 0.15, mu=0.3, name="pair"))
    s.add_contact(nc.SpherePlane(b, (0, 0, 0), 0.1, plane=c, point=(0.3, 0.1, 0.0), normal=(0, 0, 1), name="table"))
    model = s.build()
    q, v = model.q0, model.v0
    WN, WT = model.contact_jacobian(q)
    ra = model.member("ball").rigid.position(q[:12], np.zeros(3))
    rb = model.member("c").rigid.position(q[12:], np.array([0.05, 0, 0]))
    n = (rb - ra) / np.linalg.norm(rb - ra)
    np.testing.assert_allclose(model.gap(q)[0], np.linalg.norm(rb - ra) - 0.25, atol=1e-14)
    # relative velocity of the two material points (b's surface minus a's surface)
    rel_b = _member_velocity(model, "c", q, v, rb - 0.15 * n)
    rel_a = _member_velocity(model, "ball", q, v, ra + 0.1 * n)
    rel = rel_b - rel_a
    np.testing.assert_allclose(WN[0] @ v, n @ rel, atol=1e-7)
    np.testing.assert_allclose(np.linalg.norm(WT[:2] @ v), np.linalg.norm(rel - (n @ rel) * n), atol=1e-7)
    # normal Jacobian = gradient of the gap (sphere-sphere)
    dg = np.array([(model.gap(q + 1e-7 * e) - model.gap(q - 1e-7 * e))[0] / 2e-7 for e in np.eye(24)])
    np.testing.assert_allclose(WN[0], dg, atol=1e-7)
    # plane on a member: relative velocity of the sphere's point and the plane's point
    R, _ = model.poses(q)
    nz = R[1] @ np.array([0, 0, 1.0])
    x = ra - 0.1 * nz
    rel = _member_velocity(model, "ball", q, v, x) - _member_velocity(model, "c", q, v, x)
    np.testing.assert_allclose(WN[1] @ v, nz @ rel, atol=1e-7)


def _member_velocity(model, name, q, v, x, eps=1e-7):
    k = model.member_names.index(name)
    sl = slice(12 * k, 12 * k + 12)
    m = model.member(name)
    R, p = model.poses(q)
    rbar = R[k].T @ (x - p[k])
    return (m.rigid.position(q[sl] + eps * v[sl], rbar) - m.rigid.position(q[sl] - eps * v[sl], rbar)) / (2 * eps)


def test_bad_contacts_are_named():
    s = nc.System("bad")
    b = s.add_body("b", mass=1.0, inertia=np.eye(3), position=(0, 0, 1))
    with pytest.raises(NcgenError, match="restitution"):
        s.add_contact(nc.SpherePlane(b, radius=0.1, restitution=1.5))
    with pytest.raises(NcgenError, match="radius"):
        s.add_contact(nc.SpherePlane(b, radius=-1))
    with pytest.raises(NcgenError, match="same member"):
        s.add_contact(nc.SphereSphere(b, None, 0.1, b, None, 0.1))
    with pytest.raises(NcgenError, match="contacts"):
        s.build(contacts="soft")
    s.add_contact(nc.SpherePlane(b, radius=0.1, name="c"))
    with pytest.raises(NcgenError, match="already used"):
        s.add_contact(nc.SpherePlane(b, radius=0.1, name="c"))
    model = s.build(contacts="nonsmooth")
    with pytest.raises(NcgenError, match="method='stepper'"):
        nc.simulate(model, 0.1, 0.01)


# ------------------------------------------------------------------ nonsmooth stepper
def drops_model():
    """Two point masses dropped from 1 m: e = 0.9 and e = 0."""
    s = nc.System("drops")
    for name, e, y in (("bouncy", 0.9, 0.0), ("dead", 0.0, 1.0)):
        p = s.add_point(name, mass=1.0, position=(0, y, 1.0))
        s.add_contact(nc.SpherePlane(p, radius=0.0, restitution=e, name=f"{name}_floor"))
    return s.build(contacts="nonsmooth")


@pytest.fixture(scope="module")
def drops():
    return drops_model()


def bounce_apexes(tr):
    """Heights (m) of the e = 0.9 mass's apexes in a run of :func:`drops_model`; closed form
    ``0.81^k`` (each bounce keeps e² of the height)."""
    z = tr.q[:, 2]
    return z[[i for i in range(1, len(z) - 1) if z[i - 1] < z[i] >= z[i + 1]]]


def test_bounce_heights_follow_restitution(drops):
    tr = nc.simulate(drops, 3.0, 1e-4, method="stepper", substeps=10)           # h = 10 µs
    apex = bounce_apexes(tr)
    assert len(apex) >= 3
    np.testing.assert_allclose(apex[:3], 0.81 ** np.arange(1, 4), rtol=1e-3)
    # e = 0: at rest after the first impact, no penetration beyond the push-out tolerance
    # (PENETRATION_TOL = 1e-8 m; without the push-out it would be up to h·v_impact/2), no drift
    zd = tr.q[:, 5]
    assert zd.min() > -1e-8
    # the deepest penetration at the end of any step is reported; no sample is deeper
    depth = tr.info["contacts"]["penetration"]
    assert depth <= 1e-8 and -tr.gap.min() <= depth + 1e-15
    rest = tr.t > 0.5
    # (at rest each step repeats the last impulses while the contact velocities stay within
    # REPEAT_TOL (1 + max|U|), max|U| the other ball's, so the height may creep at that rate)
    creep = REPEAT_TOL * (1 + np.abs(tr.v[:, 2]).max())
    assert np.ptp(zd[rest]) < creep * (tr.t[-1] - 0.5) and np.max(np.abs(tr.v[rest, 5])) < creep
    # its contact force carries the weight once at rest (to m·creep/dt where a full contact
    # solve takes up the creep); the open contact carries nothing
    np.testing.assert_allclose(tr.contact_normal[rest, 1], G, rtol=1e-9, atol=creep / 1e-4)
    assert np.all(tr.contact_state[rest, 1] != OPEN)
    flight = (tr.t > 0.05) & (tr.t < 0.4)
    assert np.all(tr.contact_normal[flight, 0] == 0) and np.all(tr.contact_state[flight, 0] == OPEN)


@pytest.mark.slow      # the exported package built by make at -O2; fast: test_bounce_heights_follow_restitution (the
#                       same drops in Python), tests/c/test_contact.c (the C contact solve)
@pytest.mark.skipif(shutil.which("make") is None, reason="make not installed")
def test_c_program_simulates_contacts_like_python(drops, tmp_path):
    pkg = nc.generate(drops, tmp_path / drops.name)
    subprocess.run(["make", "-s"], cwd=pkg.path, check=True, capture_output=True)
    out = subprocess.run([str(pkg.path / f"{drops.name}_simulate"), "1.0", "0.001"], cwd=pkg.path,
                         capture_output=True, text=True, check=True).stdout
    final = {}
    for line in out.splitlines():
        key, _, value = line.partition(" = ")
        final.setdefault(key.split("[")[0], []).append(float(value))
    tr = nc.simulate(drops, 1.0, 1.0, method="stepper", substeps=1000)
    np.testing.assert_allclose(final["q"], tr.q[-1], atol=1e-12)
    # closed form for the bouncing ball at t = 1 s (h = 1 ms: impact resolved to h·v)
    t_hit = np.sqrt(2 / G)
    v_up = 0.9 * G * t_hit
    z = v_up * (1 - t_hit) - G / 2 * (1 - t_hit) ** 2
    assert abs(final["q"][2] - z) < 5e-3


TH, R_BALL, M_BALL, MU_SPIN, V0_SPIN, W0_SPIN = 0.3, 0.1, 1.5, 0.3, 2.0, -10.0


def slopes_run():
    """One model (one compilation) of independent members, each with its own contact: on a
    0.3 rad incline, two blocks (point masses, μ = 0.2 < tan θ slides, μ = 0.5 sticks) and two
    balls (μ = 1 rolls, μ = 0.05 slips); on flat ground, a ball launched with backspin.
    Coordinates: slider 0:3, sticker 3:6, roller 6:18, skidder 18:30, spinner 30:42."""
    n = np.array([-np.sin(TH), 0, np.cos(TH)])
    inertia = 0.4 * M_BALL * R_BALL**2 * np.eye(3)
    s = nc.System("slopes")
    for name, mu, y in (("slider", 0.2, 0.0), ("sticker", 0.5, 1.0)):
        p = s.add_point(name, mass=2.0, position=(0, y, 0))
        s.add_contact(nc.SpherePlane(p, radius=0.0, point=(0, y, 0), normal=n, mu=mu, name=name))
    for name, mu, y in (("roller", 1.0, 2.0), ("skidder", 0.05, 3.0)):
        b = s.add_body(name, mass=M_BALL, inertia=inertia, position=R_BALL * n + (0, y, 0))
        s.add_contact(nc.SpherePlane(b, radius=R_BALL, point=(0, y, 0), normal=n, mu=mu, name=name))
    b = s.add_body("spinner", mass=M_BALL, inertia=inertia, position=(0, 10.0, R_BALL), velocity=(V0_SPIN, 0, 0),
                   angular_velocity=(0, W0_SPIN, 0))
    s.add_contact(nc.SpherePlane(b, radius=R_BALL, mu=MU_SPIN, name="spinner"))
    model = s.build(contacts="nonsmooth")
    return model, nc.simulate(model, 1.0, 0.01, method="stepper", substeps=10)


@pytest.fixture(scope="module")
def slopes():
    return slopes_run()


DOWN = np.array([-np.cos(TH), 0, -np.sin(TH)])


def test_block_on_incline_slides_or_sticks(slopes):
    _, tr = slopes
    a = np.diff(tr.v[:, :3] @ DOWN) / 0.01
    np.testing.assert_allclose(a, G * (np.sin(TH) - 0.2 * np.cos(TH)), rtol=1e-6)
    np.testing.assert_allclose(tr.v[:, 3:6], 0, atol=1e-12)
    assert np.all(tr.contact_state[1:, 0] == SLIP) and np.all(tr.contact_state[1:, 1] == STICK)
    np.testing.assert_allclose(tr.contact_normal[1:, :2], 2 * G * np.cos(TH), rtol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(tr.contact_tangent[1:, 0], axis=1), 0.2 * 2 * G * np.cos(TH),
                               rtol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(tr.contact_tangent[1:, 1], axis=1), 2 * G * np.sin(TH), rtol=1e-9)
    assert np.max(np.abs(tr.gap[:, :2])) < 1e-12


def test_sphere_rolls_without_slipping_or_slips(slopes):
    model, tr = slopes
    a_roll = np.diff(tr.v[:, 6:9] @ DOWN) / 0.01
    a_slip = np.diff(tr.v[:, 18:21] @ DOWN) / 0.01
    # second order: the error grows like (h ω)², 3e-5 after 1 s (ω = 21 rad/s, h = 1 ms)
    np.testing.assert_allclose(a_roll, 5 / 7 * G * np.sin(TH), rtol=5e-5)
    np.testing.assert_allclose(a_slip, G * (np.sin(TH) - 0.05 * np.cos(TH)), rtol=1e-6)
    assert np.all(tr.contact_state[1:, 2] == STICK) and np.all(tr.contact_state[1:, 3] == SLIP)
    # rolling without slipping dissipates nothing (the scheme's error is O(h²): 1.5e-5 after
    # 1 s at h = 1 ms, 4e-6 at 0.5 ms, like the acceleration's)
    v, M = tr.v[:, 6:18], model.M[6:18, 6:18]
    E = np.einsum("ti,ij,tj->t", v, M, v) / 2 + M_BALL * G * tr.q[:, 8]
    assert np.max(np.abs(E - E[0])) < 3e-5 * (E[-1] - M_BALL * G * tr.q[-1, 8])
    assert tr.constraint_residual.max() < 1e-9


def test_ball_with_backspin_against_closed_form_and_mujoco(slopes):
    """A ball (R = 0.1 m, 1.5 kg, μ = 0.3) launched at 2 m/s with 10 rad/s of backspin slips
    until t* = s0 / (3.5 μ g), then rolls at (5 v0 + 2 R ω0) / 7.  MuJoCo with the same mass,
    inertia, radius, μ and gravity (elliptic cone, impratio 100, stiff solref 0.002 s; what
    cannot be matched: its soft contact penetrates ~0.1 mm and creeps) agrees to 3e-4."""
    mujoco = pytest.importorskip("mujoco")
    _, tr = slopes
    R, m, mu, v0, w0 = R_BALL, M_BALL, MU_SPIN, V0_SPIN, W0_SPIN
    x_ncgen, v_ncgen, state = tr.q[:, 30], tr.v[:, 30], tr.contact_state[:, 4]
    t_roll = (v0 - R * w0) / (3.5 * mu * G)
    v_roll = (5 * v0 + 2 * R * w0) / 7
    slipping = tr.t < t_roll - 0.01
    np.testing.assert_allclose(v_ncgen[slipping], v0 - mu * G * tr.t[slipping], rtol=1e-9)
    np.testing.assert_allclose(v_ncgen[tr.t > t_roll + 0.01], v_roll, rtol=1e-5)
    assert np.all(state[slipping][1:] == SLIP) and state[-1] == STICK

    x, v_end = mujoco_backspin(mujoco)
    np.testing.assert_allclose(x_ncgen[1:], x, atol=3e-4)
    np.testing.assert_allclose(v_end, v_ncgen[-1], rtol=3e-4)


def mujoco_backspin(mujoco):
    """MuJoCo's twin of the backspin ball: its x (m) every 0.01 s over 1 s and its final speed."""
    R, m, mu, v0, w0 = R_BALL, M_BALL, MU_SPIN, V0_SPIN, W0_SPIN
    xml = f"""<mujoco><option timestep="1e-4" gravity="0 0 -{G}" cone="elliptic" impratio="100"/>
      <worldbody><geom type="plane" size="10 10 0.1" friction="{mu} 0 0"/>
      <body pos="0 0 {R}"><freejoint/><geom type="sphere" size="{R}" mass="{m}" friction="{mu} 0 0"
        solref="0.002 1"/></body></worldbody></mujoco>"""
    M = mujoco.MjModel.from_xml_string(xml)
    D = mujoco.MjData(M)
    D.qvel[:] = [v0, 0, 0, 0, w0, 0]
    x = []
    for i in range(10_000):
        mujoco.mj_step(M, D)
        if (i + 1) % 100 == 0:
            x.append(D.qpos[0])
    return np.array(x), float(D.qvel[0])


def box_and_ball(name="box"):
    """A box (8 corner contacts, e = 0.7, μ = 0.4) and a ball (e = 1, μ = 0.6)."""
    s = nc.System(name)
    a = np.array([0.2, 0.15, 0.1])
    box = s.add_body("box", mass=2.0, inertia=2.0 / 3 * np.diag([a[1]**2 + a[2]**2, a[0]**2 + a[2]**2,
                                                                    a[0]**2 + a[1]**2]), position=(0, 0, 1))
    for i, corner in enumerate(np.array(np.meshgrid(*[[-1, 1]] * 3)).reshape(3, -1).T * a):
        s.add_contact(nc.SpherePlane(box, corner, 0.0, mu=0.4, restitution=0.7, name=f"c{i}"))
    ball = s.add_body("ball", mass=1.0, inertia=0.004 * np.eye(3), position=(3, 0, 1))
    s.add_contact(nc.SpherePlane(ball, radius=0.1, mu=0.6, restitution=1.0, name="ball"))
    return s.build(contacts="nonsmooth")


# the box landing flat on four corners with friction: some contact solves stop at the sweep
# limit with small residuals (reported by a warning, which is not what this test is about)
@pytest.mark.slow      # a contact scene compiled, several runs; fast: test_bounce_heights_follow_restitution (the
#                       energy of each impact against restitution),
#                       tests/test_energy_work.py::test_impact_work_is_the_kinetic_energy_lost
@pytest.mark.filterwarnings("ignore:simulate.*contact solve")
def test_energy_never_increases_through_impacts():
    """The box and the ball of :func:`box_and_ball` dropped with random orientations and
    spins: the energy never rises above its initial value beyond the O(h²) error of an impact
    resolved inside a RATTLE step (here at most 1.5e-8 relative, from the e = 1 ball; an e = 1
    frictionless box gains up to 2e-3 at h = 1 ms and 1e-4 at 0.25 ms).  Newton's law with
    Coulomb friction on the end velocity alone would gain up to 25 % here (Kane's paradox):
    the stepper applies Coulomb's law to U_T + e U⁻_T, which makes every impact dissipative."""
    model = box_and_ball()
    rng = np.random.default_rng(7)
    for trial in range(12):
        R0 = _rot(*rng.uniform(-np.pi, np.pi, 2))
        q0 = model.q0.copy()
        q0[:12] = model.member("box").rigid.q_from_pose(R0, (0, 0, rng.uniform(0.4, 1.0)))
        v0 = np.zeros(model.nq)
        v0[:12] = model.member("box").rigid.qd_from_twist(R0, q0[:3], rng.normal(0, 3, 3), rng.normal(0, 1, 3))
        v0[12:24] = model.member("ball").rigid.qd_from_twist(np.eye(3), q0[12:15], rng.normal(0, 5, 3),
                                                             (rng.normal(0, 1), 0, -1))
        tr = nc.simulate(model, 2.0, 0.01, method="stepper", substeps=10, q0=q0, v0=v0)
        assert_no_energy_created(tr, 1e-6 * tr.energy_scale)
        assert tr.gap.min() > -1e-8                     # push-out tolerance
        assert tr.constraint_residual.max() < 1e-9


# ------------------------------------------------------------------------- smooth law
SOFT = {"th": 0.2, "m": 2.0, "k": 1e5, "n_exp": 1.5, "mu": 0.1}


def soft_block_run():
    """A point mass on a 0.2 rad incline through a smooth contact (Hunt–Crossley law
    ``k δ^1.5``, μ = 0.1), 1 s of IDAS at 1e-9; closed forms: the static penetration
    ``(m g cos θ / k)^(1/1.5)``, the normal force ``m g cos θ`` and the slide's acceleration
    ``g (sin θ − μ cos θ)``."""
    th, m, k, n_exp = SOFT["th"], SOFT["m"], SOFT["k"], SOFT["n_exp"]
    normal = np.array([-np.sin(th), 0, np.cos(th)])
    s = nc.System("soft")
    p = s.add_point("block", mass=m, position=(0, 0, 0))
    s.add_contact(nc.SpherePlane(p, radius=0.0, normal=normal, mu=SOFT["mu"], stiffness=k, damping=2e6,
                                 exponent=n_exp, slip_velocity=1e-4))
    model = s.build()                                   # contacts="smooth" by default
    return nc.simulate(model, 1.0, 0.01, rtol=1e-9, atol=1e-11)


def test_smooth_contact_rests_at_the_static_penetration_and_slides_with_idas():
    th, m, k, n_exp = SOFT["th"], SOFT["m"], SOFT["k"], SOFT["n_exp"]
    tr = soft_block_run()
    delta = (m * G * np.cos(th) / k) ** (1 / n_exp)     # static penetration under the weight
    np.testing.assert_allclose(-tr.gap[-20:, 0], delta, rtol=1e-4)
    np.testing.assert_allclose(tr.contact_normal[-20:, 0], m * G * np.cos(th), rtol=1e-4)
    down = np.array([-np.cos(th), 0, -np.sin(th)])
    speed = tr.v[:, :3] @ down
    a = np.gradient(speed, tr.t)[-30:-5]
    np.testing.assert_allclose(a, G * (np.sin(th) - 0.1 * np.cos(th)), rtol=1e-3)
    assert np.all(tr.contact_state[-20:, 0] == SLIP)


# ----------------------------------------------------------------------- TOML and check
TOML = """
[system]
name = "pair"
[[members]]
name = "a"
kind = "body"
mass = 1.0
inertia = [[0.004, 0, 0], [0, 0.004, 0], [0, 0, 0.004]]
position = [0, 0, 0.1]
[[members]]
name = "b"
kind = "point"
mass = 0.5
position = [0.0, 0.0, 0.5]
[[contacts]]
type = "SpherePlane"
name = "floor"
sphere = "a"
radius = 0.1
mu = 0.3
restitution = 0.5
[[contacts]]
type = "SphereSphere"
between = ["a", "b"]
radius_a = 0.1
radius_b = 0.05
"""


def test_contacts_from_toml_round_trip_and_check(tmp_path):
    from ncgen.assembly.check import check_system
    s = nc.System.from_toml(TOML)
    assert [c.kind for c in s.contacts] == ["SpherePlane", "SphereSphere"]
    assert s.contacts[0].mu == 0.3 and s.contacts[1].name == "spheresphere_1"
    again = nc.System.from_toml(s.to_toml())
    m1, m2 = s.build(), again.build()
    assert m1.contacts == m2.contacts
    np.testing.assert_allclose(m1.gap(m1.q0), [0.0, 0.25], atol=1e-15)
    text = check_system(s).render()
    assert "contacts (2):" in text and "floor" in text and "a – b" in text and "mu = 0.3, e = 0.5" in text
    with pytest.raises(NcgenError, match=r"contacts\[1\].radius_a: unknown key"):
        nc.System.from_toml(TOML.replace('type = "SphereSphere"', 'type = "SpherePlane"\nsphere = "b"')
                            .replace("between = [\"a\", \"b\"]\n", ""))


def test_contacts_are_drawn(drops, tmp_path):
    from ncgen.viz.animation import animate
    from ncgen.viz.summary_plot import plot
    from ncgen.viz.scene import scene
    tr = nc.simulate(drops, 1.0, 0.01, method="stepper", substeps=10)
    sc = scene(tr)
    assert sc.sphere_centres.shape == (len(tr), 2, 3) and sc.planes.shape == (1, 2, 3)
    loaded = ~np.isnan(sc.contact_points).any(axis=2)
    np.testing.assert_array_equal(loaded, tr.contact_normal > 0)
    np.testing.assert_allclose(sc.contact_points[loaded][:, 2], tr.q[:, [2, 5]][loaded], atol=1e-12)
    assert plot(tr, tmp_path / "drops.png").stat().st_size > 0
    assert animate(tr, tmp_path / "drops.gif", max_frames=5).stat().st_size > 0
    saved = tr.save(tmp_path / "drops.npz")
    back = nc.Trajectory.load(saved)
    assert back.contact_names == tr.contact_names
    np.testing.assert_array_equal(back.contact_normal, tr.contact_normal)
    np.testing.assert_array_equal(back.contact_state, tr.contact_state)


@pytest.mark.slow      # runs docs/contact.md again; fast: tests/test_docs_snippets.py runs the page and checks its output
def test_contact_doc_snippets_run(tmp_path, monkeypatch):
    import re
    from pathlib import Path
    monkeypatch.chdir(tmp_path)
    text = (Path(__file__).resolve().parents[1] / "docs" / "contact.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) == 4                       # the bounce, the incline, a box, a URDF's collisions
    runs = 0
    for code in blocks:
        scope: dict = {}
        exec(compile(code, "docs/contact.md", "exec"), scope)
        if "traj" in scope:                       # the snippets that simulate
            assert scope["traj"].complete
            runs += 1
    assert runs == 2


def test_planar_disc_rolls_and_block_slides():
    th, R, m = 0.3, 0.1, 1.5
    n = np.array([-np.sin(th), np.cos(th)])
    s = nc.System("disc2d", gravity=(0, -G))
    disc = s.add_body("disc", coords="ruv", mass=m, inertia=0.5 * m * R**2, position=R * n)
    s.add_contact(nc.SpherePlane(disc, radius=R, normal=n, mu=1.0))
    block = s.add_point("block", mass=1.0, position=(0, 1.0))
    s.add_contact(nc.SpherePlane(block, point=(0, 1.0), normal=n, mu=0.1))
    tr = nc.simulate(s.build(contacts="nonsmooth"), 0.5, 0.01, method="stepper", substeps=10)
    down = np.array([-np.cos(th), -np.sin(th)])
    np.testing.assert_allclose(np.diff(tr.v[:, :2] @ down) / 0.01, 2 / 3 * G * np.sin(th), rtol=2e-5)
    np.testing.assert_allclose(np.diff(tr.v[:, -2:] @ down) / 0.01, G * (np.sin(th) - 0.1 * np.cos(th)), rtol=1e-9)
    assert tr.contact_tangent.shape == (len(tr), 2, 1)


def test_head_on_sphere_collision_follows_newton_restitution():
    """Equal spheres, one at rest: after the impact v_a = (1 − e)/2 v, v_b = (1 + e)/2 v,
    momentum conserved; a third sphere with e = 1 and twice the mass: exact elastic formulas."""
    s = nc.System("billiard", gravity=(0, 0, 0))
    a = s.add_point("a", mass=1.0, position=(0, 0, 0), velocity=(2.0, 0, 0))
    b = s.add_point("b", mass=1.0, position=(0.5, 0, 0))
    c = s.add_point("c", mass=1.0, position=(0, 1, 0), velocity=(3.0, 0, 0))
    d = s.add_point("d", mass=2.0, position=(0.5, 1, 0))
    s.add_contact(nc.SphereSphere(a, None, 0.1, b, None, 0.1, restitution=0.6, mu=0.5))
    s.add_contact(nc.SphereSphere(c, None, 0.1, d, None, 0.1, restitution=1.0))
    tr = nc.simulate(s.build(contacts="nonsmooth"), 0.5, 0.01, method="stepper", substeps=10)
    np.testing.assert_allclose(tr.v[-1, [0, 3]], [0.4 * 2.0 / 2, 1.6 * 2.0 / 2], rtol=1e-12)
    np.testing.assert_allclose(tr.v[-1, [6, 9]], [3.0 * (1 - 2) / 3, 3.0 * 2 / 3], rtol=1e-12)
    np.testing.assert_allclose(tr.v[-1, [1, 2, 4, 5, 7, 8, 10, 11]], 0, atol=1e-14)
    assert tr.gap.min() > -1e-8


def test_optimal_control_through_smooth_friction():
    """Push a 1 kg block 1 m in 1 s, rest to rest, against Coulomb friction (smooth law):
    the push is a + μ g with the frictionless minimum-effort a(t) = 6 (1 − 2t), so the
    least effort is ∫ a² + (μ g)² = 12 + (μ g)²."""
    k, mu = 1e5, 0.3
    s = nc.System("pushbox")
    box = s.add_point("box", mass=1.0, position=(0, 0, -(G / k) ** (1 / 1.5)))
    s.add_contact(nc.SpherePlane(box, mu=mu, stiffness=k, damping=3e4, slip_velocity=1e-2))
    s.add_input("push", 1)
    s.add_force(nc.PointForce(box, (0, 0, 0), force=["push", 0, 0]))
    model = s.build()
    ocp = nc.OptimalControl(model, N=40, t_final=1.0)
    ocp.initial(q=model.q0, v=0)
    ocp.final(q={"box.r_i.x": 1.0}, v=0)
    ocp.minimize_effort()
    sol = ocp.solve()
    assert sol.stats.status == "Solve_Succeeded"
    np.testing.assert_allclose(sol.stats.objective, 12 + (mu * G) ** 2, rtol=1e-2)


@pytest.mark.slow      # three compiles of one scene; fast: tests/c/test_contact.c runs the Delassus paths alone
def test_delassus_paths_give_the_same_motion(monkeypatch):
    """The three ways the C forms the Delassus matrix give the same motion: from the constant
    M⁻¹ and the Schur complement A M⁻¹ Aᵀ (regular M, the default here), from the unrolled
    QR factors of the KKT matrix (what a singular M gets; forced with MINV_MAX_NQ = 0), and
    with one step_solve per contact row (models too large to unroll the factors; forced
    with SX_QR_MAX_NNZ = 0 as well)."""
    import ncgen.assembly.stepper_equations as kernels
    import ncgen.codegen.stepper_package as package

    schur = nc.simulate(box_and_ball(), 1.0, 0.01, method="stepper", substeps=10)
    assert package.schur_context(box_and_ball(), kernels.stepper_functions(box_and_ball())[0].sparsity_out("K"))[
        "schur"]
    monkeypatch.setattr(package, "MINV_MAX_NQ", 0)
    factored = nc.simulate(box_and_ball("box_qr"), 1.0, 0.01, method="stepper", substeps=10)
    monkeypatch.setattr(kernels, "SX_QR_MAX_NNZ", 0)
    model = box_and_ball("box_plain")
    assert "step_factor" not in [f.name() for f in kernels.stepper_functions(model)]
    plain = nc.simulate(model, 1.0, 0.01, method="stepper", substeps=10)
    assert np.count_nonzero(schur.contact_normal[:, :8]) > 0
    np.testing.assert_allclose(factored.q, schur.q, atol=1e-9)
    np.testing.assert_allclose(plain.q, schur.q, atol=1e-9)

@pytest.mark.slow      # a CLI subprocess compiling a contact scene; fast: the Python runs of this file, tests/test_cli_simulate.py
def test_cli_simulates_nonsmooth_contacts(tmp_path):
    import sys
    model = tmp_path / "pair.toml"
    model.write_text(TOML, encoding="utf-8")
    out = subprocess.run([sys.executable, "-m", "ncgen.cli", "simulate", str(model), "--t-end", "0.3", "--dt",
                          "0.001", "-o", str(tmp_path / "pair.npz"), "--method", "stepper", "--contacts", "nonsmooth"],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    tr = nc.Trajectory.load(tmp_path / "pair.npz")
    assert tr.contact_names == ["floor", "spheresphere_1"] and tr.info["scheme"] == "RATTLE, nonsmooth contacts"
    # the point falls 0.25 m onto the ball resting on the floor (e = 0) and stays on top
    assert tr.contact_normal[:, 1].max() > 0 and tr.gap.min() > -1e-3


def test_block_tips_over_its_edge_iff_above_the_critical_spin():
    """A planar block (2a × 2b, 4 corner contacts, μ = 2) set pivoting about its bottom-right
    corner with angular velocity ω0 tips over iff ½ I_O ω0² > m g (r − b) (r: pivot to centre
    of mass), the closed form for a rigid pivot; while it pivots no energy is lost."""
    m, a, b = 2.0, 0.1, 0.3
    inertia = m * ((2 * a) ** 2 + (2 * b) ** 2) / 12
    r = np.hypot(a, b)
    w_crit = np.sqrt(2 * m * G * (r - b) / (inertia + m * r**2))
    s = nc.System("tip2d", gravity=(0, -G))
    block = s.add_body("block", coords="ruv", mass=m, inertia=inertia, position=(0, b))
    for i, corner in enumerate([(-a, -b), (a, -b), (a, b), (-a, b)]):
        s.add_contact(nc.SpherePlane(block, corner, 0.0, mu=2.0, name=f"c{i}"))
    model = s.build(contacts="nonsmooth")
    centre, pivot = np.array([0.0, b]), np.array([a, 0.0])
    for factor, tips in ((0.99, False), (1.01, True)):
        w0 = -factor * w_crit                                # clockwise: over the right edge
        v_centre = w0 * np.array([-(centre - pivot)[1], (centre - pivot)[0]])
        v0 = model.member("block").rigid.qd_from_twist(np.eye(2), centre, w0, v_centre)
        tr = nc.simulate(model, 1.5, 0.005, method="stepper", substeps=5, v0=v0)
        x = tr.poses()[1][:, 0, 0]
        assert (x.max() > a) == tips, (factor, x.max())
        pivoting = tr.t < 0.15
        assert np.ptp(tr.energy[pivoting]) < 1e-6 * tr.energy[0]
        assert np.all(tr.contact_state[1:][pivoting[1:], 1] == STICK)


@pytest.mark.slow      # fast: test_block_tips_over_its_edge_iff_above_the_critical_spin (tipping over an edge against
#                         the rigid pivot's closed-form threshold)
def test_box_tips_over_its_edge_like_mujoco():
    """A 3D box (0.1 × 0.16 × 0.3 m, 1.5 kg, 8 corner points, μ = 1, e = 0) standing on the
    ground, set pivoting about its bottom edge x = +0.05 m with 0.9 and 1.1 times the critical
    spin ω_c = sqrt(2 m g (r − c) / I_O) of a rigid pivot, against MuJoCo with the same mass,
    inertia, gravity, friction and initial state (a box geom, condim 3, elliptic cone,
    impratio 10, stiff contacts solref 0.002 s, h = 0.25 ms).  Matched: the rigid-body data,
    the initial state and μ.  Not matched: MuJoCo's contacts are soft (they sink ~0.1 mm and
    creep), and its impacts have no restitution coefficient (damping ratio 1 instead of
    e = 0), so the comparison stops before the box lands again.  Agreement: the centre of
    mass to 1.5e-4 m over the pivot (measured 7e-5 and 1.3e-4 m), and the outcome: it tips
    onto its side (centre at 0.05 m) iff ω0 > ω_c, in both."""
    mujoco = pytest.importorskip("mujoco")
    m, a = 1.5, np.array([0.05, 0.08, 0.15])
    inertia = m / 3 * np.diag([a[1]**2 + a[2]**2, a[0]**2 + a[2]**2, a[0]**2 + a[1]**2])
    r = np.hypot(a[0], a[2])
    w_crit = np.sqrt(2 * m * G * (r - a[2]) / (inertia[1, 1] + m * r**2))
    s = nc.System("tip3d")
    box = s.add_body("box", mass=m, inertia=inertia, position=(0, 0, a[2]))
    for i, corner in enumerate(np.array(np.meshgrid(*[[-1, 1]] * 3)).reshape(3, -1).T * a):
        s.add_contact(nc.SpherePlane(box, corner, 0.0, mu=1.0, name=f"c{i}"))
    model = s.build(contacts="nonsmooth")
    xml = f"""<mujoco><option timestep="2.5e-4" gravity="0 0 -{G}" cone="elliptic" impratio="10"/>
        <worldbody><geom type="plane" size="5 5 0.1" friction="1 0 0"/>
        <body pos="0 0 {a[2]}"><freejoint/><inertial pos="0 0 0" mass="{m}" diaginertia="{_nums(np.diag(inertia))}"/>
        <geom type="box" size="{_nums(a)}" friction="1 0 0" condim="3" solref="0.002 1"/></body>
        </worldbody></mujoco>"""
    twin = mujoco.MjModel.from_xml_string(xml)
    for factor in (0.9, 1.1):
        w = np.array([0.0, factor * w_crit, 0.0])
        v = np.cross(w, [-a[0], 0.0, a[2]])                   # the pivot edge at rest
        v0 = model.member("box").rigid.qd_from_twist(np.eye(3), (0, 0, a[2]), w, v)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")                   # corners landing flat: redundant contacts
            tr = nc.simulate(model, 1.0, 0.005, method="stepper", substeps=5, v0=v0)
        ours = tr.point("box", (0, 0, 0))
        data = mujoco.MjData(twin)
        data.qvel[:3], data.qvel[3:6] = v, w
        mujoco.mj_forward(twin, data)
        theirs = [data.xpos[1].copy()]
        for _ in range(len(tr.t) - 1):
            mujoco.mj_step(twin, data, nstep=20)
            theirs.append(data.xpos[1].copy())
        theirs = np.array(theirs)
        pivot = tr.t < 0.4                                    # before it lands again
        assert np.abs(ours[pivot] - theirs[pivot]).max() < 1.5e-4, factor
        for centre in (ours[-1], theirs[-1]):
            assert abs(centre[2] - a[0]) < 2e-3 if factor > 1 else centre[2] > a[2] - 2e-3, (factor, centre)


def _nums(x) -> str:
    return " ".join(repr(float(v)) for v in x)

def test_unconverged_contact_solves_are_reported(monkeypatch):
    """A contact solve that stops at the projected Gauss–Seidel sweep limit is counted in
    info["contacts"] and warned about; where its last sweep still moved a contact velocity by
    more than PGS_TRUST the run is untrustworthy (SimulationError).  Forced here with a limit
    of one sweep, which an impact never meets (its first sweep changes the impulse)."""
    import ncgen.codegen.stepper_package as package
    from ncgen.errors import SimulationError

    s = nc.System("one_sweep")
    p = s.add_point("p", mass=1.0, position=(0, 0, 0.05))
    s.add_contact(nc.SpherePlane(p, radius=0.0, name="floor"))
    s.add_contact(nc.SpherePlane(p, radius=0.0, point=(0, 0, 0), normal=(0, 0.6, 0.8), name="slope"))
    monkeypatch.setattr(package, "PGS_MAX_ITER", 1)     # a constant of the model's own package (the
    model = s.build(contacts="nonsmooth")                # contact library's is compiled in): kernels="flat"
    with pytest.raises(SimulationError, match="contact impulses did not converge"):
        nc.simulate(model, 0.2, 0.01, method="stepper", substeps=10, kernels="flat")
    with pytest.warns(UserWarning, match="stopped at"):
        tr = nc.simulate(model, 0.2, 0.01, method="stepper", substeps=10, check=False, kernels="flat")
    report = tr.info["contacts"]
    assert report["pgs_unconverged"] >= 1 and report["pgs_residual"] > 1e-3
    # with the default limit the same drop converges: nothing to report, and it comes to rest
    monkeypatch.undo()
    model = s.build(contacts="nonsmooth")
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tr = nc.simulate(model, 0.2, 0.01, method="stepper", substeps=10)
    assert tr.info["contacts"]["pgs_unconverged"] == 0 and tr.gap.min() > -1e-8


def test_energy_check_with_contacts_is_one_sided(monkeypatch, drops):
    """The stepper's energy check on a contact model flags a rise of E only (contacts take
    energy out): the drops lose a third of their energy without complaint even with the
    check's threshold at 1e-6 of the energy scale (a two-sided check would stop them at the
    first impact).  That the check runs at all: with a negative threshold every sample is
    a "rise", and the run is refused naming it."""
    from ncgen.errors import SimulationError
    import ncgen.runtime.stepper_checks as checks

    monkeypatch.setattr(checks, "ENERGY_FRACTION", 1e-6)
    tr = nc.simulate(drops, 1.0, 1e-3, method="stepper", substeps=10)
    assert tr.energy[-1] < 0.7 * tr.energy[0]
    monkeypatch.setattr(checks, "ENERGY_FRACTION", -0.5)
    with pytest.raises(SimulationError, match="rose through its contacts"):
        nc.simulate(drops, 1.0, 1e-3, method="stepper", substeps=10)


def test_contact_forces_of_a_run_with_a_python_feedback_are_the_steppers():
    """A mass pressed on the floor by a feedback force: its contact force is the stepper's mean
    force per output interval (m g + push, as in the same run with the inputs given as a
    table), not the force at the sampled states, where a resting contact sits a round-off gap
    apart (it read 0 N throughout before)."""
    import casadi as ca
    s = nc.System("pressed")
    p = s.add_point("m", mass=2.0, position=(0, 0, 0.0))
    push = s.add_input("push")
    s.add_force(nc.PointForce(p, (0, 0, 0), force=ca.vertcat(0, 0, -push)))
    s.add_contact(nc.SpherePlane(p, radius=0.0, name="floor"))
    model = s.build(contacts="nonsmooth")
    t_out = np.linspace(0, 0.05, 6)
    fed = nc.simulate(model, 0.05, 0.01, method="stepper", u=lambda t, q, v: [3.0 + 10 * t])
    table = nc.simulate(model, 0.05, 0.01, method="stepper", u=np.array([[3.0 + 10 * t] for t in t_out]),
                        hold="zoh")
    expected = 2.0 * G + 3.0 + 10 * t_out[:-1]               # the push held over each interval
    np.testing.assert_allclose(fed.contact_normal[1:, 0], expected, rtol=1e-9)
    np.testing.assert_allclose(fed.contact_normal, table.contact_normal, rtol=1e-9, atol=1e-12)
    assert fed.contact_normal[0, 0] == 0.0 and np.all(fed.contact_state[1:, 0] > 0)
