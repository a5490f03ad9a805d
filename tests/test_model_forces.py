"""Force elements: torsional spring-damper, generalised force, springs and cables, point
forces and torques against the symbolic layer and closed forms."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import ncgen as nc


def _angular_acceleration_2d(model, q, a, k=0):
    """α of planar body ``k`` (a ruv body with unit u): ü = α J u − ω² u."""
    i = model.layout.member_indices(model.member_names[k])
    u, udd = q[i[2:4]], a[i[2:4]]
    return float(np.array([-u[1], u[0]]) @ udd)


@pytest.mark.parametrize("rest, omega", [(-0.5, 0.0), (0.3, 2.0), (-3.0, 0.0)])
def test_torsional_spring_planar_closed_form(rest, omega):
    """A body pinned at its centre of mass: I α = −k δ − c ω, δ = (0 − rest) wrapped to (−π, π]."""
    k, c, inertia = 4.0, 0.3, 0.2
    s = nc.System("tsp", gravity=(0, 0))
    body = s.add_body("body", coords="ruv", mass=1.5, inertia=inertia, angular_velocity=omega)
    hinge = s.add_joint(nc.Revolute(s.ground, body, at=(0, 0)))
    s.add_force(nc.TorsionalSpring(hinge, k=k, damping=c, rest_angle=rest))
    model = s.build()
    a, _ = model.accel(model.q0, model.v0)
    delta = np.angle(np.exp(-1j * rest))
    assert np.isclose(_angular_acceleration_2d(model, model.q0, a), (-k * delta - c * omega) / inertia)
    T, V = model.energy(model.q0, model.v0)
    assert np.isclose(V, 0.5 * k * delta**2) and np.isclose(T, 0.5 * inertia * omega**2)


def test_torsional_spring_is_a_pair_of_opposite_torques_3d():
    """Two free bodies joined by a revolute: the spring's accelerations equal those of the
    torques ∓(k δ + c θ̇) a on A and B."""
    axis = np.array([1.0, 2.0, 2.0]) / 3
    k, c, rest, w = 3.0, 0.4, -0.7, 1.5

    def system(with_spring: bool):
        s = nc.System("pair", gravity=(0, 0, 0))
        A = s.add_body("A", mass=2.0, inertia=np.diag([0.3, 0.4, 0.5]), position=(0, 0, 0))
        p_B = np.array([0.5, -0.2, 0.1])
        B = s.add_body("B", coords="rrrw", mass=1.0, inertia=np.diag([0.2, 0.25, 0.3]), position=p_B,
                       angular_velocity=w * axis, velocity=np.cross(w * axis, p_B - [0.1, 0.1, 0.1]))
        hinge = s.add_joint(nc.Revolute(A, B, at=(0.1, 0.1, 0.1), axis=axis))
        tau = -(k * (0 - rest) + c * w)
        if with_spring:
            s.add_force(nc.TorsionalSpring(hinge, k=k, damping=c, rest_angle=rest))
        else:
            s.add_force(nc.Torque(B, tau * axis))
            s.add_force(nc.Torque(A, -tau * axis))
        return s.build()

    spring, torques = system(True), system(False)
    a_s, _ = spring.accel(spring.q0, spring.v0)
    a_t, _ = torques.accel(torques.q0, torques.v0)
    assert np.abs(a_s).max() > 0.1
    assert np.allclose(a_s, a_t, atol=1e-10)


def test_torsional_spring_with_a_bar_across_the_axis_conserves_energy():
    """Q = −∂V/∂q exactly: with a bar oblique to the hinge axis, F·v = −dV/dt."""
    s = nc.System("oblique", gravity=(0, 0, 0))
    bar = s.add_bar("bar", mass=1.0, ends=[(0, 0, 0), (1, 0, 1)])
    hinge = s.add_joint(nc.Revolute(s.ground, bar, at=(0, 0, 0), axis=(0, 0, 1)))
    s.add_force(nc.TorsionalSpring(hinge, k=2.0, rest_angle=0.4))
    model = s.build()
    q, v = model.q0, model.v0
    rng = np.random.default_rng(3)
    dq = rng.normal(size=model.nq)
    h = 1e-6
    dV = (model.energy(q + h * dq, v)[1] - model.energy(q - h * dq, v)[1]) / (2 * h)
    assert np.isclose(model.F(q, v) @ dq, -dV, rtol=1e-6)


def test_generalized_force_text_and_callable():
    s = nc.System("gf", gravity=(0, 0, 0))
    s.add_parameter("k", 2.0)
    s.add_input("push", 3)
    s.add_point("pt", mass=1.0, position=(1, 2, 3))
    s.add_force(nc.GeneralizedForce(["-k*q[0]", "push[1]", "0.5*sin(t) - v[2]"]))
    s.add_force(nc.GeneralizedForce(lambda t, q, v, u, p: ca.vertcat(p[0] * v[0], 0, u[2])))
    model = s.build()
    q, v, u = np.array([0.5, 0, 0]), np.array([1.0, 0, 2.0]), np.array([7.0, 8.0, 9.0])

    def expected(kv):
        return [-kv * 0.5 + kv * 1.0, 8.0, 0.5 * np.sin(0.3) - 2.0 + 9.0]

    assert np.allclose(model.F(q, v, t=0.3, u=u), expected(2.0))
    assert np.allclose(model.F(q, v, t=0.3, u=u, p=[5.0]), expected(5.0))


def test_spring_equilibrium_cable_and_damping():
    m, k, l0, c, g = 2.0, 50.0, 0.4, 3.0, 9.81
    x_eq = l0 + m * g / k

    def hanging(z, vz=0.0, cable=False):
        s = nc.System("hang")
        pt = s.add_point("pt", mass=m, position=(0, 0, -z), velocity=(0, 0, vz))
        s.add_force(nc.Spring(s.ground, (0, 0, 0), pt, (0, 0, 0), k=k, rest_length=l0, damping=c, cable=cable))
        model = s.build()
        return model.accel(model.q0, model.v0)[0], model.energy(model.q0, model.v0)

    a, (T, V) = hanging(x_eq)
    assert np.allclose(a, 0, atol=1e-12)
    assert np.isclose(V, 0.5 * k * (x_eq - l0) ** 2 + m * g * (-x_eq))
    a, _ = hanging(x_eq + 0.1, vz=-0.2)         # stretched more and moving down: pulled up, damped
    assert np.allclose(a, [0, 0, (k * 0.1 + c * 0.2) / m])
    a, _ = hanging(0.2, cable=True)              # shorter than the rest length: a slack cable
    assert np.allclose(a, [0, 0, -g])
    a, (_, V) = hanging(0.2, cable=False)        # a spring pushes the point away, downwards
    assert np.allclose(a, [0, 0, (-k * 0.2 - m * g) / m]) and np.isclose(V, 0.5 * k * 0.2**2 - m * g * 0.2)


def test_point_force_and_torque_match_the_symbolic_layer():
    s = nc.System("ft", gravity=(0, 0, 0))
    body = s.add_body("body", coords="rrvw", mass=1.0, inertia=np.diag([0.2, 0.3, 0.4]),
                      position=(0.1, 0.2, 0.3), basis=[(0.1, 0, 0), (0.5, 0.2, 0), (0, 1, 0.2), (0.1, 0, 1)])
    bar = s.add_bar("bar", coords="ru", mass=1.0, ends=[(1, 1, 1), (2, 1, 1)])
    f, tau, tau_bar = np.array([1.0, -2.0, 0.5]), np.array([0.3, 0.1, -0.2]), np.array([0.0, 1.0, 2.0])
    s.add_force(nc.PointForce(body, (0.2, -0.1, 0.3), force=f))
    s.add_force(nc.Torque(body, tau))
    s.add_force(nc.PointForce(bar, (0.3, 0, 0), force=["1", 2, "3*t"]))
    s.add_force(nc.Torque(bar, tau_bar))
    model = s.build()
    rng = np.random.default_rng(1)
    q = model.q0 + 0.1 * rng.normal(size=model.nq)
    F = model.F(q, np.zeros(model.nq), t=1.0)
    ib, ir = model.layout.member_indices("body"), model.layout.member_indices("bar")
    expect_body = body.rigid.force_at((0.2, -0.1, 0.3), f) + body.rigid.torque(q[ib], tau)
    expect_bar = bar.rigid.force_at((0.3, 0, 0), [1, 2, 3]) + bar.rigid.torque(q[ir], tau_bar)
    assert np.allclose(F[ib], expect_body) and np.allclose(F[ir], expect_bar)


def test_force_refusals():
    s = nc.System("bad")
    bar = s.add_bar("bar", mass=1, ends=[(0, 0, 0), (1, 0, 0)])
    pt = s.add_point("pt", mass=1, position=(0, 0, 1))
    with pytest.raises(nc.ModelError, match=r"at on bar \(rr bar\): local point \[0.0, 0.3, 0.0\] is 0.3 m off"):
        s.add_force(nc.PointForce(bar, (0, 0.3, 0), force=(0, 0, 1)))
    with pytest.raises(nc.ModelError, match="a torque needs a body or a bar"):
        s.add_force(nc.Torque(pt, (0, 0, 1)))
    with pytest.raises(nc.ModelError, match="expected a Revolute joint"):
        s.add_force(nc.TorsionalSpring(nc.Spherical(s.ground, bar, at=(0, 0, 0)), k=1.0))
    other = nc.System("other")
    b = other.add_body("b", mass=1, inertia=np.eye(3))
    j = other.add_joint(nc.Revolute(other.ground, b, at=(0, 0, 0), axis=(0, 0, 1)))
    with pytest.raises(nc.ModelError, match="'b' is not a member of system 'bad'"):
        s.add_force(nc.TorsionalSpring(j, k=1.0))
    s.add_force(nc.PointForce(bar, (0.5, 0, 0), force=["k", 0, 0]))
    with pytest.raises(nc.ModelError, match=r"force\[0\]: unknown name 'k' \(known names: t, pi\)"):
        s.build()
