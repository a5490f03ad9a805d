"""Flat bodies (thin discs and plates, I1 + I2 = I3): a singular natural-coordinate mass
matrix M, positive definite on the constraint tangent space, is a valid model on every path.

References are independent of ncgen's equations: scipy integrations of Euler's equations
with rotation-matrix kinematics and of the pendulum equation, the closed-form steady
precession of a heavy symmetric top (Goldstein §5.7), and Newton–Euler at one state.
Every model here is checked to take the singular path (``mass_is_regular`` false).
"""
from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import ncgen as nc
from ncgen.assembly.mass import mass_is_regular
from ncgen.cli.demo_job import Top

MASS, RADIUS = 2.0, 0.3
DISC = np.diag([MASS * RADIUS**2 / 4, MASS * RADIUS**2 / 4, MASS * RADIUS**2 / 2])   # normal: body z


def rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def hat(w) -> np.ndarray:
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


def axes(model, traj, member: str) -> np.ndarray:
    """Rotation body → world of ``member`` per sample, ``(n_t, 3, 3)``."""
    k = model.member_names.index(member)
    return np.array([np.array(model.functions["poses"](q)[0])[:, 3 * k:3 * k + 3] for q in traj.q])


# --------------------------------------------------------------------------- free disc
def free_disc(R0, omega_body, gravity=(0.0, 0.0, 0.0), velocity=None, inertia=DISC):
    s = nc.System("free_disc", gravity=gravity)
    s.add_body("disc", mass=MASS, inertia=inertia, rotation=R0, angular_velocity=R0 @ omega_body,
               velocity=velocity)
    return s.build()


def euler_reference(R0, omega_body, t, inertia=DISC):
    """Torque-free rigid body: Euler's equations and Ṙ = R [ω_b]×, DOP853 at 1e-12."""
    Id = np.diag(inertia)

    def rhs(_, y):
        R, w = y[:9].reshape(3, 3), y[9:]
        return np.concatenate([(R @ hat(w)).ravel(), np.cross(Id * w, w) / Id])

    sol = solve_ivp(rhs, (t[0], t[-1]), np.concatenate([R0.ravel(), omega_body]), method="DOP853",
                    rtol=1e-12, atol=1e-12, t_eval=t)
    return sol.y[:9].T.reshape(-1, 3, 3)


def test_free_spinning_disc_against_eulers_equations():
    """A thin disc spun about a tilted axis wobbles (torque-free precession); its attitude
    over 1 s agrees with an independent integration of Euler's equations (IDAS; the stepper
    is checked on the heavy top and the coin below)."""
    R0, wb = rot_x(0.4), np.array([0.5, -0.3, 10.0])
    model = free_disc(R0, wb)
    assert not mass_is_regular(model)
    traj = nc.simulate(model, t_end=1.0, dt=0.01, rtol=1e-10, atol=1e-12)
    R = axes(model, traj, "disc")
    assert np.max(np.abs(R - euler_reference(R0, wb, traj.t))) < 1e-7
    # the wobble is real: the axis moves by more than 0.05 rad
    assert np.max(np.abs(R[:, :, 2] - R0[:, 2])) > 0.05


def test_nearly_flat_disc_takes_the_singular_path():
    """A disc 1e-5 of its radius thick: M is regular but its constant inverse would amplify
    rounding by ~1e10, so it takes the augmented path too, and agrees with Euler's equations."""
    h = 1e-5 * RADIUS
    inertia = np.diag([MASS * (3 * RADIUS**2 + h**2) / 12] * 2 + [MASS * RADIUS**2 / 2])
    R0, wb = rot_x(0.4), np.array([0.5, -0.3, 10.0])
    model = free_disc(R0, wb, inertia=inertia)
    assert not mass_is_regular(model) and model.mass_factor.flat == ["disc"]
    traj = nc.simulate(model, t_end=1.0, dt=0.01, rtol=1e-10, atol=1e-12)
    assert np.max(np.abs(axes(model, traj, "disc") - euler_reference(R0, wb, traj.t, inertia))) < 1e-7


# --------------------------------------------------------------------------- heavy top
def disc_top(top: Top):
    """A disc top (I1 = I3/2) on a ball joint at the tip, body coordinates at the centre of
    mass (``share=False`` keeps the joint, so M stays singular), in steady precession."""
    th, Om = top.tilt, top.steady_precession()
    axis = np.array([math.sin(th), 0.0, math.cos(th)])
    R = np.array([[math.cos(th), 0.0, math.sin(th)], [0.0, 1.0, 0.0], [-math.sin(th), 0.0, math.cos(th)]])
    omega = Om * np.array([0.0, 0.0, 1.0]) + (top.spin - Om * math.cos(th)) * axis
    com = top.l * axis
    s = nc.System("disc_top", gravity=(0.0, 0.0, -top.g))
    b = s.add_body("top", mass=top.mass, inertia=np.diag([top.I1, top.I1, top.I3]), position=com, rotation=R,
                   angular_velocity=omega, velocity=np.cross(omega, com))
    s.add_joint(nc.Spherical(s.ground, b, at=(0.0, 0.0, 0.0)))
    return s.build(share=False)


# the stepper's case slow; fast: the IDAS case (the same precession) and, for the stepper with a singular M,
# test_spinning_coin_bounces_on_the_floor_with_the_nonsmooth_stepper
@pytest.mark.parametrize("method, options", [("idas", dict(rtol=1e-10, atol=1e-12)),
                                             pytest.param("stepper", dict(rtol=1e-9), marks=pytest.mark.slow)])
def test_disc_top_steady_precession(method, options):
    """Heavy symmetric disc top: the tilt stays at 30° to 1e-7 rad and the axis precesses at
    the closed-form rate to 1e-6."""
    top = Top(spin=150.0, I1=3e-4, I3=6e-4)
    assert top.I1 + top.I1 == top.I3
    model = disc_top(top)
    assert not mass_is_regular(model)
    traj = nc.simulate(model, t_end=1.0, dt=0.01, method=method, **options)
    w = axes(model, traj, "top")[:, :, 2]
    tilt, phi = np.arccos(w[:, 2]), np.unwrap(np.arctan2(w[:, 1], w[:, 0]))
    assert np.max(np.abs(tilt - top.tilt)) < 1e-7
    assert np.polyfit(traj.t, phi, 1)[0] == pytest.approx(top.steady_precession(), rel=1e-6)


# --------------------------------------------------------------------------- plate
PLATE_M, PLATE_A, PLATE_B, G = 1.5, 0.4, 0.3, 9.81
#: a rectangular plate of zero thickness in its x–z plane: width a along x, height b along z
PLATE = PLATE_M / 12 * np.diag([PLATE_B**2, PLATE_A**2 + PLATE_B**2, PLATE_A**2])


def plate_pendulum(theta0: float = 0.0, effort=None):
    """The plate hung by its top edge on a hinge along x (it swings out of its plane)."""
    s = nc.System("plate", gravity=(0.0, 0.0, -G))
    tau = s.add_input("tau") if effort else None
    R = rot_x(theta0)
    plate = s.add_body("plate", mass=PLATE_M, inertia=PLATE, position=R @ [0.0, 0.0, -PLATE_B / 2], rotation=R)
    s.add_joint(nc.Revolute(s.ground, plate, at=(0.0, 0.0, 0.0), axis=(1.0, 0.0, 0.0), name="hinge", effort=tau))
    return s.build()


def pendulum_reference(theta0, t, torque=lambda t: 0.0):
    """θ̈ = (τ − m g d sin θ) / I_hinge with d = b/2, I_hinge = m b²/3 (thin plate about its edge)."""
    d, I_h = PLATE_B / 2, PLATE_M * PLATE_B**2 / 3
    sol = solve_ivp(lambda tt, y: [y[1], (torque(tt) - PLATE_M * G * d * math.sin(y[0])) / I_h],
                    (t[0], t[-1]), [theta0, 0.0], method="DOP853", rtol=1e-12, atol=1e-12, t_eval=t)
    return sol.y


def test_thin_plate_pendulum_against_the_pendulum_equation():
    model = plate_pendulum(0.3)
    assert not mass_is_regular(model)
    traj = nc.simulate(model, t_end=2.0, dt=0.01, rtol=1e-10, atol=1e-12)
    theta = 0.3 + np.array([np.ravel(model.to_joint_space(q))[0] for q in traj.q])
    assert np.max(np.abs(theta - pendulum_reference(0.3, traj.t)[0])) < 1e-7
    # small-oscillation period for the record: 2π sqrt(2b / 3g)
    assert theta.min() < -0.29


def test_thin_plate_optimal_control_replays_in_the_pendulum_equation():
    """Minimum-effort swing of the hinged plate to 0.5 rad at rest in 1 s; the optimal
    piecewise-constant torque, replayed in the pendulum equation, lands there."""
    model = plate_pendulum(effort=True)
    ocp = nc.OptimalControl(model, N=20, t_final=1.0)
    q1, _ = model.from_joint_space([0.5])
    ocp.final(q=q1, v=0)
    ocp.minimize_effort(1.0)
    sol = ocp.solve()
    assert sol.stats.success
    u = np.asarray(sol.u)[:, 0]
    h = 1.0 / 20
    torque = lambda tt: u[min(int(tt / h), 19)]           # noqa: E731
    ends = [0.0]
    theta, omega = 0.0, 0.0
    for k in range(20):                                     # exact replay interval by interval
        y = solve_ivp(lambda tt, y: [y[1], (u[k] - PLATE_M * G * PLATE_B / 2 * math.sin(y[0]))
                                     / (PLATE_M * PLATE_B**2 / 3)],
                      (k * h, (k + 1) * h), [theta, omega], method="DOP853", rtol=1e-12, atol=1e-12).y[:, -1]
        theta, omega = y
        ends.append(theta)
    assert torque(0.0) == u[0]
    assert theta == pytest.approx(0.5, abs=1e-4) and abs(omega) < 1e-3
    qj = np.array([np.ravel(model.to_joint_space(q))[0] for q in sol.q])
    assert np.max(np.abs(qj - np.array(ends))) < 1e-4


# --------------------------------------------------------------------------- forward dynamics
@pytest.mark.parametrize("backend", ["numpy", "compiled"])
def test_forward_dynamics_of_a_thin_disc_against_newton_euler(backend):
    """Free disc under gravity at a general state: q̈ from the KKT solve against Newton–Euler
    (a_G = g, α = R I⁻¹(−ω_b × I ω_b), ẍ_k = α × x_k + ω × (ω × x_k))."""
    R0 = rot_x(0.7) @ np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]) @ rot_x(0.2)
    wb, g = np.array([1.3, -0.4, 7.0]), np.array([0.0, -3.0, -9.81])
    model = free_disc(R0, wb, gravity=g, velocity=(0.1, 0.2, -0.3))
    assert not mass_is_regular(model)
    a, lam = nc.forward_dynamics(model, model.q0, model.v0, backend=backend)
    Id = np.diag(DISC)
    alpha = R0 @ (np.cross(Id * wb, wb) / Id)
    omega = R0 @ wb
    expected = np.concatenate([g] + [np.cross(alpha, R0[:, k]) + np.cross(omega, np.cross(omega, R0[:, k]))
                                     for k in range(3)])
    names = model.coordinate_names
    order = [names.index(f"disc.{slot}.{c}") for slot in ("r_i", "u", "v", "w") for c in "xyz"]
    assert np.max(np.abs(a[order] - expected)) < 1e-10 * np.max(np.abs(expected))
    assert np.all(np.isfinite(lam))


@pytest.mark.slow      # a package of its own compiled; fast:
#                       test_forward_dynamics_of_a_thin_disc_against_newton_euler (the same disc's compiled forward
#                       dynamics)
def test_generated_package_of_a_thin_disc(tmp_path):
    """The generated C package of a free disc: ``ode`` (the augmented form) with the exact
    multipliers gives the Newton–Euler accelerations, ``alg`` vanishes there, and ``Minv``
    applies the pseudo-inverse M⁺ (M M⁺ M = M)."""
    from ncgen.codegen import load_functions
    R0, wb, g = rot_x(0.3), np.array([0.8, 0.1, 6.0]), np.array([0.0, 0.0, -9.81])
    model = free_disc(R0, wb, gravity=g)
    f = load_functions(nc.generate(model, tmp_path / "disc"), backend="compiled")
    a, lam = nc.forward_dynamics(model, model.q0, model.v0)
    args = (model.t0, model.q0, model.v0, lam, np.zeros(0), np.zeros(0))
    qdot, vdot = (np.array(x).reshape(-1) for x in f["ode"](*args))
    Id = np.diag(DISC)
    alpha, omega = R0 @ (np.cross(Id * wb, wb) / Id), R0 @ wb
    expected = np.concatenate([g] + [np.cross(alpha, R0[:, k]) + np.cross(omega, np.cross(omega, R0[:, k]))
                                     for k in range(3)])
    order = [model.coordinate_names.index(f"disc.{slot}.{c}") for slot in ("r_i", "u", "v", "w") for c in "xyz"]
    assert np.allclose(qdot, model.v0, rtol=0, atol=1e-15)
    assert np.max(np.abs(vdot[order] - expected)) < 1e-10 * np.max(np.abs(expected))
    assert np.max(np.abs(np.array(f["alg"](*args)))) < 1e-10
    Mp = np.array(ca.densify(f["Minv"](np.eye(model.nq))))
    assert np.allclose(model.M @ Mp @ model.M, model.M, atol=1e-12)


# --------------------------------------------------------------------------- URDF
URDF_DISC = """<?xml version="1.0"?>
<robot name="disc_on_{axis}">
  <link name="base"/>
  <link name="wheel">
    <inertial><origin xyz="{com}" rpy="0 0 0"/><mass value="2"/>
      <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.04"/></inertial>
  </link>
  <joint name="pivot" type="revolute"><parent link="base"/><child link="wheel"/>
    <origin xyz="0 0 0"/><axis xyz="{axis}"/><limit lower="-3" upper="3" effort="10" velocity="10"/></joint>
</robot>"""


@pytest.mark.parametrize("axis, I_axis, regular", [("1 0 0", 0.02, False), ("0 0 1", 0.04, True)])
def test_urdf_thin_disc_link_turned_by_a_torque(axis, I_axis, regular):
    """A URDF link whose inertia is a thin disc (r = 0.2 m, m = 2 kg: ixx = iyy = m r²/4,
    izz = m r²/2), hinged at its centre about a diameter or its normal, turned by a constant
    torque τ: θ = τ t² / (2 I) (gravity acts through the hinge).  About the normal, the
    normal is the hinge axis, shared with the ground: no coordinate lacks inertia then."""
    text = URDF_DISC.format(axis=axis, com="0 0 0")
    model = nc.System.from_urdf(text, gravity=(0.0, 0.0, -G)).build()
    assert mass_is_regular(model) == regular
    tau = 0.05
    traj = nc.simulate(model, t_end=1.0, dt=0.01, u=lambda t: [tau], rtol=1e-10, atol=1e-12)
    theta = np.array([np.ravel(model.to_joint_space(q))[0] for q in traj.q])
    assert np.max(np.abs(theta - tau * traj.t**2 / (2 * I_axis))) < 1e-8


def test_urdf_thin_disc_pendulum():
    """The disc hung 0.5 m below a hinge along a diameter: θ follows I_p θ̈ = −m g d sin θ
    with I_p = m r²/4 + m d² (here M happens to be regular: the hinge point carries inertia)."""
    model = nc.System.from_urdf(URDF_DISC.format(axis="1 0 0", com="0 0 -0.5"), gravity=(0.0, 0.0, -G)).build()
    q0, v0 = model.from_joint_space([0.4])
    traj = nc.simulate(model, t_end=1.5, dt=0.01, q0=q0, v0=v0, rtol=1e-10, atol=1e-12)
    theta = np.array([np.ravel(model.to_joint_space(q))[0] for q in traj.q])
    m, d = 2.0, 0.5
    I_p = 0.02 + m * d * d
    ref = solve_ivp(lambda t, y: [y[1], -m * G * d * math.sin(y[0]) / I_p], (0, 1.5), [0.4, 0.0],
                    method="DOP853", rtol=1e-12, atol=1e-12, t_eval=traj.t).y[0]
    assert np.max(np.abs(theta - ref)) < 1e-7


# --------------------------------------------------------------------------- refusals
def test_line_like_body_free_to_spin_is_refused_by_name():
    """A body whose mass lies on a line (principal moments 0, I, I), free in space: its spin
    about the line has no inertia."""
    s = nc.System("rod_in_space", gravity=(0.0, 0.0, -G))
    s.add_body("rod", mass=1.0, inertia=np.diag([0.0, 0.1, 0.1]))
    s.add_body("disc", mass=1.0, inertia=DISC)
    with pytest.raises(nc.ModelError, match=r"no inertia.*member\(s\) rod[^,]"):
        s.build()


def test_point_like_body_on_a_ball_joint_is_refused_by_name():
    """A body with no rotational inertia (a point mass) on a ball joint at its centre of mass:
    every rotation is free and without inertia.  Its translation, fixed by the joint, is fine."""
    s = nc.System("point_on_ball", gravity=(0.0, 0.0, -G))
    b = s.add_body("bead", mass=1.0, inertia=np.zeros((3, 3)))
    s.add_joint(nc.Spherical(s.ground, b, at=(0.0, 0.0, 0.0)))
    with pytest.raises(nc.ModelError, match=r"no inertia.*bead"):
        s.build(share=False)


def test_line_like_body_whose_spin_is_stopped_is_accepted():
    """The same rod welded to a disc: the disc gives the spin inertia, so the model is valid
    (M singular, positive definite on the tangent space)."""
    s = nc.System("rod_on_disc", gravity=(0.0, 0.0, -G))
    rod = s.add_body("rod", mass=1.0, inertia=np.diag([0.0, 0.1, 0.1]), angular_velocity=(0.0, 0.0, 3.0))
    disc = s.add_body("disc", mass=1.0, inertia=DISC, angular_velocity=(0.0, 0.0, 3.0))
    s.add_joint(nc.Fixed(rod, disc, at=(0.0, 0.0, 0.0)))
    model = s.build(share=False)
    assert not mass_is_regular(model)
    traj = nc.simulate(model, t_end=0.2, dt=0.01, rtol=1e-10, atol=1e-12)
    assert traj.energy_drift < 1e-8 * max(traj.energy_scale, 1.0)


def test_thin_plate_linearisation_and_modes_give_the_pendulum_frequency():
    """About the hanging rest state, the linearised plate pendulum and its modal analysis give
    ω² = m g d / I_hinge = 3 g / (2 b)."""
    model = plate_pendulum()
    omega2 = 3 * G / (2 * PLATE_B)
    lin = nc.linearize(model, model.q0)
    assert np.sort(np.linalg.eigvals(lin.A).imag ** 2)[-1] == pytest.approx(omega2, rel=1e-9)
    md = nc.modes(model)
    assert list(md.kind) == ["vibration"]
    assert md.omega2[0] == pytest.approx(omega2, rel=1e-9)


def test_check_report_says_the_mass_matrix_is_singular():
    from ncgen.assembly.check import check_system
    s = nc.System("free_disc", gravity=(0.0, 0.0, -G))
    s.add_body("disc", mass=MASS, inertia=DISC)
    out = check_system(s).render()
    assert "mass matrix: singular" in out and "consistent: yes" in out
    s = nc.System("rod_in_space")
    s.add_body("rod", mass=1.0, inertia=np.diag([0.0, 0.1, 0.1]))
    out = check_system(s).render()
    assert "no inertia" in out and "rod" in out and "consistent: no" in out


def test_disc_given_a_printed_rotation_is_projected_and_reported():
    """A rotation copied with 6 decimals (|RᵀR − 1| ~ 1e-6) is projected to the nearest
    rotation, with a warning naming the correction; 1e-4 off stays an error."""
    from ncgen.validation import RotationProjected
    R = np.round(rot_x(0.3) @ np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]) @ rot_x(1.1), 6)
    s = nc.System("printed")
    with pytest.warns(RotationProjected, match="projected to the nearest rotation"):
        s.add_body("disc", mass=MASS, inertia=DISC, rotation=R)
    model = s.build()
    Rm = np.array(model.functions["poses"](model.q0)[0])
    np.testing.assert_allclose(Rm.T @ Rm, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(Rm, R, atol=2e-6)
    with pytest.raises(nc.NcgenError, match="orthonormal"):
        nc.System("off").add_body("disc", mass=MASS, inertia=DISC, rotation=R + 1e-4 * np.eye(3))


@pytest.mark.slow      # a contact scene compiled; fast:
#                       test_nearly_flat_coin_forms_its_delassus_matrix_without_the_constant_inverse
def test_spinning_coin_bounces_on_the_floor_with_the_nonsmooth_stepper(quick_cflags):
    """A horizontal coin (thin disc) spinning at 20 rad/s about its normal, dropped from 0.5 m
    onto a point contact at its centre with restitution e = 0.5: the impulses pass through
    the centre of mass, so the apexes are e^{2k} h (to the 1 ms sampling) and the spin angle
    is ω t; the contact's Delassus matrix comes from the KKT factors, not M⁻¹ (its time is gcc
    compiling them: ``quick_cflags``, tests/conftest.py)."""
    s = nc.System("coin", gravity=(0.0, 0.0, -G))
    b = s.add_body("coin", mass=MASS, inertia=DISC, position=(0.0, 0.0, 0.5), angular_velocity=(0.0, 0.0, 20.0))
    s.add_contact(nc.SpherePlane(b, (0.0, 0.0, 0.0), radius=0.0, restitution=0.5, name="floor"))
    model = s.build(contacts="nonsmooth")
    assert not mass_is_regular(model)
    traj = nc.simulate(model, 1.2, 1e-3, method="stepper", substeps=10)
    z = traj.q[:, model.coordinate_names.index("coin.r_i.z")]
    apex = [i for i in range(1, len(z) - 1) if z[i - 1] < z[i] >= z[i + 1]]
    np.testing.assert_allclose(z[apex[:2]], 0.5 * 0.25 ** np.arange(1, 3), rtol=2e-3)   # h = 100 µs steps
    R = axes(model, traj, "coin")[-1]
    np.testing.assert_allclose(R, np.array([[math.cos(24.0), -math.sin(24.0), 0], [math.sin(24.0), math.cos(24.0), 0],
                                            [0, 0, 1]]), atol=1e-4)   # RATTLE phase error O((ωh)² ωt)


def test_nearly_flat_coin_forms_its_delassus_matrix_without_the_constant_inverse():
    """A coin 1e-4 of its radius thick has a regular M (condition ~1e9, below the stepper's
    MINV_MAX_COND) but counts as flat: the contact stepper must not store its M⁻¹."""
    from ncgen.assembly.stepper_equations import stepper_functions
    from ncgen.codegen.stepper_package import schur_context
    h = 1e-4 * RADIUS
    inertia = np.diag([MASS * (3 * RADIUS**2 + h**2) / 12] * 2 + [MASS * RADIUS**2 / 2])
    s = nc.System("thin_coin", gravity=(0.0, 0.0, -G))
    b = s.add_body("coin", mass=MASS, inertia=inertia, position=(0.0, 0.0, 0.5))
    s.add_contact(nc.SpherePlane(b, (0.0, 0.0, 0.0), radius=0.0, restitution=0.5, name="floor"))
    model = s.build(contacts="nonsmooth")
    assert not mass_is_regular(model)
    assert not schur_context(model, stepper_functions(model)[0].sparsity_out("K"))["schur"]
