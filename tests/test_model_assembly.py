"""Assembled system functions against a direct NumPy evaluation of the symbolic layer
(RigidMember), and dynamics against closed-form solutions."""
from __future__ import annotations

import numpy as np

import ncgen as nc


def _mixed_system():
    """A body, two bars sharing a point, a point member on a bar's end, markers."""
    s = nc.System("mixed", gravity=(0.5, -1.0, -9.81))
    body = s.add_body("body", coords="rrrw", mass=1.2, inertia=np.diag([0.2, 0.3, 0.35]),
                      position=(0.1, 0.2, 0.3), rotation=np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]]),
                      basis=[(0.1, 0, 0), (0.6, 0.1, 0), (0, 0.8, 0.1), (0, 0, 1)])
    b1 = s.add_bar("b1", coords="rr", mass=0.7, ends=[body.node("r_j"), (1, 1, 0)])
    b2 = s.add_bar("b2", coords="ru", mass=0.4, ends=[b1.end(1), (1.5, 1.2, 0.4)], com=0.2, inertia=0.02)
    tip = s.add_point("tip", mass=0.3, position=b1.end(1))
    body.add_marker("corner", (0.3, -0.2, 0.1))
    b2.add_marker("free_end", (b2.rigid.Xbar[0, 0] - 0.2, 0, 0))
    return s, body, b1, b2, tip


def test_assembled_functions_match_the_symbolic_layer():
    s, body, b1, b2, tip = _mixed_system()
    model = s.build(share=False)         # the members as written (sharing re-bases bodies)
    rng = np.random.default_rng(2)
    q = model.q0 + 0.1 * rng.normal(size=model.nq)          # off the manifold on purpose
    v = rng.normal(size=model.nq)
    phi, A = model.phi(q), model.A(q)
    M = np.zeros((model.nq, model.nq))
    F = np.zeros(model.nq)
    T = 0.0
    row = 0
    markers = []
    for m in (body, b1, b2, tip):
        idx = model.layout.member_indices(m.name)
        cols = [i for i in idx if i is not None]
        keep = [k for k, i in enumerate(idx) if i is not None]
        qI = np.where([i is None for i in idx], m.q0, q[[i if i is not None else 0 for i in idx]])
        vI = np.where([i is None for i in idx], 0.0, v[[i if i is not None else 0 for i in idx]])
        n = m.ctype.n_phi
        assert np.allclose(phi[row:row + n], m.rigid.phi(qI))
        assert np.allclose(A[row:row + n][:, cols], m.rigid.phi_q(qI)[:, keep])
        row += n
        M[np.ix_(cols, cols)] += m.rigid.M[np.ix_(keep, keep)]
        F[cols] += m.rigid.force_at(np.zeros(3), m.rigid.mass * model.gravity)[keep]
        T += 0.5 * vI @ m.rigid.M @ vI
        markers += [m.rigid.position(qI, x) for x in m.markers.values()]
        R, p = model.poses(q)
        R_sym, p_sym = m.rigid.pose(qI)
        k = model.member_names.index(m.name)
        assert np.allclose(p[k], p_sym)
        assert np.allclose(R[k], np.eye(3) if R_sym is None else R_sym)
    assert np.allclose(model.M, M)
    assert np.allclose(model.F(q, v), F)
    assert np.isclose(model.energy(q, v)[0], T)
    assert np.allclose(model.markers(q)[0].T, markers)
    assert np.allclose(model.Minv @ model.M, np.eye(model.nq))


def test_bar_pendulum_tip_acceleration_is_3g_over_2():
    s = nc.System("pendulum")
    s.add_bar("bar", mass=2.0, ends=[s.ground.point((0, 0, 0)), (1.5, 0, 0)])
    model = s.build()
    a, _ = model.accel(model.q0, model.v0)
    assert np.allclose(a, [0, 0, -1.5 * 9.81])


def test_point_pendulum_on_a_distance_joint():
    """a = −(v²/L) e_r + g_tangential: a point on a massless rod of length L."""
    L, v = 0.8, 1.3
    s = nc.System("point_pendulum")
    pt = s.add_point("pt", mass=0.5, position=(L, 0, 0), velocity=(0, v, 0))
    s.add_joint(nc.Distance(s.ground, pt, at=((0, 0, 0), (L, 0, 0))))
    model = s.build()
    a, lam = model.accel(model.q0, model.v0)
    assert np.allclose(a, [-v**2 / L, 0, -9.81])


def test_point_on_an_incline_slides_with_g_sin_alpha():
    alpha = 0.3
    n = np.array([-np.sin(alpha), 0, np.cos(alpha)])
    s = nc.System("incline")
    pt = s.add_point("pt", mass=1.0, position=(0, 0, 0))
    s.add_joint(nc.PointOnPlane(s.ground, pt, at=(0, 0, 0), normal=n))
    model = s.build()
    a, _ = model.accel(model.q0, model.v0)
    assert np.allclose(a, -9.81 * np.sin(alpha) * np.array([np.cos(alpha), 0, np.sin(alpha)]))


def test_planar_body_pendulum_angular_acceleration():
    """Pinned at distance d from the centre of mass: α = −m g d / (I + m d²)."""
    m, inertia, d = 1.5, 0.05, 0.4
    s = nc.System("body_pendulum", gravity=(0, -9.81))
    body = s.add_body("body", coords="rrv", mass=m, inertia=inertia, position=(d, 0))
    s.add_joint(nc.Revolute(s.ground, body, at=(0, 0)))
    model = s.build(share=False)         # r_i, r_j as written (sharing would put r_i on the pin)
    a, _ = model.accel(model.q0, model.v0)
    idx = model.layout.member_indices("body")
    r_i, r_j = a[idx[0:2]], a[idx[2:4]]
    alpha = -m * 9.81 * d / (inertia + m * d**2)
    assert np.allclose(r_i, [0, alpha * d]) and np.allclose(r_j, [0, alpha * (d + 1)])


def test_cylindrical_and_prismatic_free_fall_along_the_axis():
    """Along a tilted guide, gravity's component along the axis accelerates the slider."""
    axis = np.array([0.6, 0.0, 0.8])
    for J in (nc.Cylindrical, nc.Prismatic):
        s = nc.System("slide")
        body = s.add_body("body", mass=2.0, inertia=np.diag([0.2, 0.25, 0.3]))
        s.add_joint(J(s.ground, body, at=(0, 0, 0), axis=axis))
        model = s.build()
        a, _ = model.accel(model.q0, model.v0)
        assert np.allclose(a[:3], -9.81 * 0.8 * axis) and np.allclose(a[3:], 0)


def test_markers_are_dim_by_n_also_for_one_marker():
    s = nc.System("one_marker")
    rod = s.add_bar("rod", mass=1.0, ends=[(0, 0, 0), (0, 0, -2)], velocity=(0.5, 0, 0))
    rod.add_marker("tip", (1.0, 0, 0))
    model = s.build()
    r, rdot = model.markers(model.q0, model.v0)
    assert r.shape == rdot.shape == (3, 1)
    assert np.allclose(r[:, 0], [0, 0, -2]) and np.allclose(rdot[:, 0], [0.5, 0, 0])
