"""The joint library: DOF removed per member kind, refusals, derivatives against finite
differences, the meaning of drives, shared points versus spherical joints."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

import ncgen as nc
from joint_helpers import (
    ACROSS2, ACROSS3, AT2, AT3, AXIS2, AXIS3, jacobian, make_member, removed_dof, rotation3,
)

KINDS3 = ("ground", "body", "bar_along", "bar_across", "point")
KINDS2 = ("ground", "body", "bar_along", "point")
SHORT = {"ground": "G", "body": "D", "bar_along": "L", "bar_across": "X", "point": "P"}

# Equations (= DOF removed, all independent) per (kind of A, kind of B); "-" = refused.
# G ground, D body, L bar along the joint axis (Universal: A along axis_a, B along axis_b;
# Planar/PointOnPlane: along the normal), X bar across it, P point member.
# Columns, in order: B = G D L X P.
EXPECTED3 = {
    "Spherical":    {"G": "-3333", "D": "33333", "L": "33333", "X": "33333", "P": "33333"},
    "Revolute":     {"G": "-5-4-", "D": "55-4-", "L": "-----", "X": "44---", "P": "-----"},
    "Prismatic":    {"G": "-544-", "D": "5544-", "L": "44---", "X": "44---", "P": "-----"},
    "Cylindrical":  {"G": "-443-", "D": "4443-", "L": "44---", "X": "33---", "P": "-----"},
    "Universal":    {"G": "-44--", "D": "444--", "L": "444--", "X": "-----", "P": "-----"},
    "Planar":       {"G": "-332-", "D": "3332-", "L": "33-2-", "X": "222--", "P": "-----"},
    "Fixed":        {"G": "-6553", "D": "66553", "L": "55--3", "X": "55--3", "P": "33333"},
    "Distance":     {"G": "-1111", "D": "11111", "L": "11111", "X": "11111", "P": "11111"},
    "PointOnLine":  {"G": "-2222", "D": "22222", "L": "-----", "X": "-----", "P": "-----"},
    "PointOnPlane": {"G": "-1111", "D": "11111", "L": "11111", "X": "-----", "P": "-----"},
}
# Planar systems; columns B = G D L P (a planar bar carries every direction).
EXPECTED2 = {
    "Revolute":    {"G": "-222", "D": "2222", "L": "2222", "P": "2222"},
    "Prismatic":   {"G": "-22-", "D": "222-", "L": "222-", "P": "----"},
    "Fixed":       {"G": "-332", "D": "3332", "L": "3332", "P": "2222"},
    "Distance":    {"G": "-111", "D": "1111", "L": "1111", "P": "1111"},
    "PointOnLine": {"G": "-111", "D": "1111", "L": "1111", "P": "----"},
}


def _joint3(kind, A, B, **extra):
    J = getattr(nc, kind)
    if kind == "Universal":
        return J(A, B, at=AT3, axis_a=AXIS3, axis_b=ACROSS3, **extra)
    if kind in ("Planar", "PointOnPlane"):
        return J(A, B, at=AT3, normal=AXIS3, **extra)
    if kind in ("Spherical", "Fixed"):
        return J(A, B, at=AT3, **extra)
    if kind == "Distance":
        return J(A, B, at=(AT3, AT3 + 0.5 * ACROSS3), **extra)
    return J(A, B, at=AT3, axis=AXIS3, **extra)


def _pair3(kind, ka, kb):
    s = nc.System("pair")
    A = make_member(s, ka, "a", AT3, AXIS3, ACROSS3)
    if kind == "Universal":            # B's bars: along axis_b or along axis_a (across axis_b)
        B = make_member(s, kb, "bb", AT3, ACROSS3, AXIS3)
    elif kind == "Distance":
        B = make_member(s, kb, "bb", AT3 + 0.5 * ACROSS3, AXIS3, np.cross(AXIS3, ACROSS3))
    else:
        B = make_member(s, kb, "bb", AT3, AXIS3, ACROSS3)
    return s, A, B


@pytest.mark.parametrize("kind", list(EXPECTED3))
def test_dof_removed_3d(kind):
    got = {}
    for ka, kb in itertools.product(KINDS3, KINDS3):
        if ka == kb == "ground":
            got[ka, kb] = "-"
            continue
        s, A, B = _pair3(kind, ka, kb)
        try:
            s.add_joint(_joint3(kind, A, B))
        except nc.ModelError:
            got[ka, kb] = "-"
            continue
        n, rank = removed_dof(s)
        assert n == rank, f"{kind} {ka}-{kb}: {n} equations but rank {rank}"
        got[ka, kb] = str(n)
    table = {SHORT[ka]: "".join(got[ka, kb] for kb in KINDS3) for ka in KINDS3}
    assert table == EXPECTED3[kind]


@pytest.mark.parametrize("kind", list(EXPECTED2))
def test_dof_removed_planar(kind):
    got = {}
    for ka, kb in itertools.product(KINDS2, KINDS2):
        if ka == kb == "ground":
            got[ka, kb] = "-"
            continue
        s = nc.System("pair", gravity=(0, -9.81))
        A = make_member(s, ka, "a", AT2, AXIS2, ACROSS2)
        atB = AT2 + 0.5 * ACROSS2 if kind == "Distance" else AT2
        B = make_member(s, kb, "bb", atB, AXIS2, ACROSS2)
        J = getattr(nc, kind)
        kw = {"at": AT2} if kind in ("Revolute", "Fixed") else \
            {"at": (AT2, atB)} if kind == "Distance" else {"at": AT2, "axis": AXIS2}
        try:
            s.add_joint(J(A, B, **kw))
        except nc.ModelError:
            got[ka, kb] = "-"
            continue
        n, rank = removed_dof(s)
        assert n == rank
        got[ka, kb] = str(n)
    table = {SHORT[ka]: "".join(got[ka, kb] for kb in KINDS2) for ka in KINDS2}
    assert table == EXPECTED2[kind]


def test_bar_sliding_along_its_axis_through_a_body_removes_4():
    s = nc.System("rod")
    guide = s.add_body("guide", mass=1, inertia=np.eye(3) * 0.1, position=(0, 0, 0))
    rod = s.add_bar("rod", mass=1, ends=[(-1, 0, 0), (1, 0, 0)])
    s.add_joint(nc.Fixed(s.ground, guide, at=(0, 0, 0)))
    s.add_joint(nc.Prismatic(guide, rod, at=(0, 0, 0), axis=(1, 0, 0)))
    model = s.build()
    assert [n for n in model.constraint_names if n.startswith("prismatic")] == \
        ["prismatic_1.lock.1", "prismatic_1.lock.2", "prismatic_1.line.1", "prismatic_1.line.2"]
    assert model.dof == 1


# ------------------------------------------------------------------- refusals
def _sys3():
    s = nc.System("r")
    body = s.add_body("body", mass=1, inertia=np.eye(3) * 0.1)
    bar = s.add_bar("bar", mass=1, ends=[(0, 0, 0), (1, 0, 0)])
    pt = s.add_point("pt", mass=1, position=(0, 0, 1))
    return s, body, bar, pt


@pytest.mark.parametrize("make, message", [
    (lambda s, body, bar, pt: nc.Spherical(s.ground, bar, at=(0.5, 0.2, 0)), "off the bar's axis"),
    (lambda s, body, bar, pt: nc.Revolute(s.ground, bar, at=(0, 0, 0), axis=(1, 0, 0)),
     "a bar cannot rotate about its own axis"),
    (lambda s, body, bar, pt: nc.Revolute(s.ground, pt, at=(0, 0, 1), axis=(1, 0, 0)),
     "pt is a point member and has no orientation"),
    (lambda s, body, bar, pt: nc.PointOnLine(bar, pt, at=(0, 0, 1), axis=(0, 0, 1)),
     "directions ⟂ to its axis are not coordinates"),
    (lambda s, body, bar, pt: nc.Universal(body, bar, at=(0, 0, 0), axis_a=(1, 0, 0), axis_b=(0, 1, 0)),
     "is not along bar bar, which carries only its own axis"),
    (lambda s, body, bar, pt: nc.Universal(s.ground, body, at=(0, 0, 0), axis_a=(1, 0, 0), axis_b=(1, 1, 0)),
     "expected perpendicular directions"),
    (lambda s, body, bar, pt: nc.Revolute(s.ground, body, at=(0, 0, 0), axis=(0, 0, 0)),
     "axis: expected a non-zero direction, got [0.0, 0.0, 0.0]"),
    (lambda s, body, bar, pt: nc.Revolute(s.ground, body, at=(0, 0), axis=(0, 0, 1)),
     "at: expected 3 numbers, got 2"),
    (lambda s, body, bar, pt: nc.Distance(body, pt, at=((0, 0, 1), (0, 0, 1))), "zero distance"),
    (lambda s, body, bar, pt: nc.Revolute(body, body, at=(0, 0, 0), axis=(0, 0, 1)), "to itself"),
    (lambda s, body, bar, pt: nc.Fixed(s.ground, s.ground, at=(0, 0, 0)), "the ground to itself"),
    (lambda s, body, bar, pt: nc.CoordinateDriver(bar, "r_k", "x"), "has slots r_i, r_j"),
    (lambda s, body, bar, pt: nc.CoordinateDriver(bar, "r_i", "w"), "expected one of x, y, z"),
    (lambda s, body, bar, pt: nc.CoordinateDriver(s.ground, "r_i", "x"), "the ground has no coordinates"),
])
def test_refusals(make, message):
    s, body, bar, pt = _sys3()
    with pytest.raises(nc.NcgenError) as err:
        s.add_joint(make(s, body, bar, pt))
    assert message in str(err.value)
    assert not s.joints


def test_refusals_two_bars_and_planar():
    s = nc.System("r")
    b1 = s.add_bar("b1", mass=1, ends=[(0, 0, 0), (1, 0, 0)])
    b2 = s.add_bar("b2", mass=1, ends=[(1, 0, 0), (1, 1, 0)])
    with pytest.raises(nc.ModelError, match="relative orientation of two bars is not a coordinate"):
        s.add_joint(nc.Prismatic(b1, b2, at=(1, 0, 0), axis=(0, 0, 1)))
    with pytest.raises(nc.ModelError, match="two bars cannot share the axis"):
        s.add_joint(nc.Revolute(b1, b2, at=(1, 0, 0), axis=(0, 0, 1)))
    p = nc.System("p", gravity=(0, -9.81))
    body = p.add_body("body", coords="ruv", mass=1, inertia=0.1)
    with pytest.raises(nc.ModelError, match="a planar system has no Spherical joint; use Revolute"):
        p.add_joint(nc.Spherical(p.ground, body, at=(0, 0)))
    with pytest.raises(nc.ModelError, match="leave axis out"):
        p.add_joint(nc.Revolute(p.ground, body, at=(0, 0), axis=(0, 0, 1)))
    g = p.ground.point((1, 0))
    bar = p.add_bar("bar", mass=1, ends=[g, (2, 0)])
    with pytest.raises(nc.ModelError, match="is a ground point, not a coordinate"):
        p.add_joint(nc.CoordinateDriver(bar, "r_i", "x", 0.0))


def test_a_failed_joint_can_be_fixed_and_added_again():
    s, body, bar, pt = _sys3()
    j = nc.Spherical(s.ground, bar, at=(0.5, 0.2, 0))
    with pytest.raises(nc.ModelError):
        s.add_joint(j)
    assert j.system is None and j.name is None
    j.options["at"] = (0.5, 0, 0)
    assert s.add_joint(j).name == "spherical_0"


# --------------------------------------------------- finite-difference checks
def _fd_check(model, t=0.3, seed=0):
    """A = ∂Φ/∂q and γ = −Φ̈ at zero acceleration, against central differences."""
    rng = np.random.default_rng(seed)
    q = model.q0 + 0.05 * rng.normal(size=model.nq)
    v = rng.normal(size=model.nq)
    A = model.A(q, t=t)
    h = 1e-6
    fd = np.column_stack([(model.phi(q + h * e, t=t) - model.phi(q - h * e, t=t)) / (2 * h)
                          for e in np.eye(model.nq)])
    assert np.allclose(A, fd, atol=1e-7 * max(1, np.abs(A).max())), np.abs(A - fd).max()
    h = 1e-4
    second = (model.phi(q + h * v, t=t + h) - 2 * model.phi(q, t=t) + model.phi(q - h * v, t=t - h)) / h**2
    assert np.allclose(-model.gamma(q, v, t=t), second, atol=1e-5 * max(1, np.abs(second).max()))
    phi_t = model.functions["phi_t"](t, q, model.p0).full().ravel()
    fd_t = (model.phi(q, t=t + h) - model.phi(q, t=t - h)) / (2 * h)
    assert np.allclose(phi_t, fd_t, atol=1e-7)
    # at most quadratic in q: the second difference along d is the same everywhere
    d = rng.normal(size=model.nq)
    q2 = q + rng.normal(size=model.nq)
    curv = [(model.phi(x + d, t=t) - 2 * model.phi(x, t=t) + model.phi(x - d, t=t)) for x in (q, q2)]
    assert np.allclose(curv[0], curv[1], atol=1e-9)


DRIVES3 = {"Revolute": "0.3*sin(w*t)", "Prismatic": lambda t: 0.2 * t**2, "Distance": "0.5 + 0.1*t"}


def _fd_system_3d(kind):
    """Two bodies joined by ``kind`` (driven where possible) and, for joints that accept
    one, a bar across the axis joined to the ground by the same kind of joint."""
    s = nc.System("fd")
    s.add_parameter("w", 1.5)
    a = make_member(s, "body", "a", AT3)
    b = make_member(s, "body", "bb", AT3 + 0.5 * ACROSS3 if kind == "Distance" else AT3)
    c = make_member(s, "bar_across", "c", AT3, AXIS3, ACROSS3)
    if kind == "CoordinateDriver":
        s.add_joint(nc.CoordinateDriver(c, "r_j", "z", "0.1*cos(t)"))
        return s
    s.add_joint(_joint3(kind, a, b, **({"drive": DRIVES3[kind]} if kind in DRIVES3 else {})))
    if kind == "Revolute":
        s.add_joint(nc.Revolute(s.ground, c, at=AT3, axis=AXIS3, drive="0.2*t"))
    elif kind in ("Cylindrical", "Prismatic", "Planar"):
        s.add_joint(_joint3(kind, s.ground, c))
    return s


@pytest.mark.parametrize("kind", [*EXPECTED3, "CoordinateDriver"])
def test_derivatives_3d(kind):
    model = _fd_system_3d(kind).build(redundant="keep", tolerance=np.inf)
    _fd_check(model)


@pytest.mark.parametrize("kind", list(EXPECTED2))
def test_derivatives_planar(kind):
    s = nc.System("fd", gravity=(0, -9.81))
    a = make_member(s, "body", "a", AT2)
    atB = AT2 + 0.5 * ACROSS2 if kind == "Distance" else AT2
    b = make_member(s, "bar_along", "bb", atB, AXIS2)
    kw = {"at": AT2} if kind in ("Revolute", "Fixed") else \
        {"at": (AT2, atB)} if kind == "Distance" else {"at": AT2, "axis": AXIS2}
    if kind in ("Revolute", "Prismatic", "Distance"):
        kw["drive"] = {"Revolute": "0.3*sin(t)", "Prismatic": "0.2*t*t", "Distance": "0.5 + t"}[kind]
    s.add_joint(getattr(nc, kind)(a, b, **kw))
    _fd_check(s.build(tolerance=np.inf))


# ------------------------------------------------------------ drive semantics
def _rot(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


@pytest.mark.parametrize("order", ["ground-body", "body-ground"])
def test_revolute_drive_is_the_rotation_of_B_relative_to_A(order):
    s = nc.System("drive")
    R0 = rotation3(4)
    body = s.add_body("body", coords="rrrw", mass=1, inertia=np.diag([0.1, 0.2, 0.25]),
                      position=AT3 + [0.2, 0.1, 0], rotation=R0)
    A, B = (s.ground, body) if order == "ground-body" else (body, s.ground)
    s.add_joint(nc.Revolute(A, B, at=AT3, axis=AXIS3, drive="0.8*sin(2*t)"))
    model = s.build()
    times = np.linspace(0, 1.5, 7)
    sol = nc.solve_kinematics(model, times)
    for t, q in zip(times, sol.q):
        R, p = model.poses(q)
        theta = 0.8 * np.sin(2 * t) * (1 if order == "ground-body" else -1)
        assert np.allclose(R[0], _rot(AXIS3, theta) @ R0, atol=1e-9)
        assert np.allclose(p[0] - AT3, _rot(AXIS3, theta) @ [0.2, 0.1, 0], atol=1e-9)


def test_revolute_drive_with_a_bar_across_the_axis():
    s = nc.System("drive")
    tilt = np.array([1.0, 0.0, 1.0]) / np.sqrt(2)       # 45° to the hinge axis z
    bar = s.add_bar("bar", mass=1, ends=[(0, 0, 0), tilt])
    s.add_joint(nc.Revolute(s.ground, bar, at=(0, 0, 0), axis=(0, 0, 1), drive="t"))
    model = s.build()
    assert model.dof == 0            # 5 − 3 (coincide) − 1 (align) − 1 (drive)
    sol = nc.solve_kinematics(model, [0.0, 0.5, 1.0, 2.5])
    for t, q in zip(sol.t, sol.q):
        R, _ = model.poses(q)
        assert np.allclose(R[0][:, 0], _rot((0, 0, 1), t) @ tilt, atol=1e-9)


def test_planar_drives():
    s = nc.System("drive2", gravity=(0, -9.81))
    crank = s.add_body("crank", coords="rrv", mass=1, inertia=0.1, position=(0.5, 0), rotation=0.2)
    slider = s.add_body("slider", coords="ruv", mass=1, inertia=0.1, position=(2, 0.5), rotation=0.1)
    s.add_joint(nc.Revolute(s.ground, crank, at=(0, 0), drive="3*t"))
    s.add_joint(nc.Prismatic(s.ground, slider, at=(2, 0.5), axis=(0.6, 0.8), drive="0.5*t*t"))
    model = s.build()
    assert model.dof == 0
    sol = nc.solve_kinematics(model, np.linspace(0, 1, 5))
    for t, q in zip(sol.t, sol.q):
        R, p = model.poses(q)
        assert np.allclose(R[0][:, 0], [np.cos(0.2 + 3 * t), np.sin(0.2 + 3 * t)])
        assert np.allclose(p[1], np.array([2, 0.5]) + 0.5 * t * t * np.array([0.6, 0.8]))
        assert np.isclose(np.arctan2(R[1][1, 0], R[1][0, 0]), 0.1)


def test_prismatic_distance_and_coordinate_drives_3d():
    s = nc.System("drive3")
    body = make_member(s, "body", "body", AT3)
    bar = s.add_bar("bar", mass=1, ends=[(0, 0, 0), (0, 0, 1)])
    pt = s.add_point("pt", mass=1, position=(2, 0, 0))
    s.add_joint(nc.Prismatic(body, s.ground, at=AT3, axis=AXIS3, drive="0.3*t"))   # ground moves +s: body −s
    s.add_joint(nc.Spherical(s.ground, bar, at=(0, 0, 0)))
    s.add_joint(nc.CoordinateDriver(bar, "r_j", "x", "0.4*sin(t)"))
    s.add_joint(nc.CoordinateDriver(bar, "r_j", 1, 0.0))
    s.add_joint(nc.PointOnLine(s.ground, pt, at=(2, 0, 0), axis=(1, 0, 0)))
    s.add_joint(nc.Distance(s.ground, pt, at=((0, 0, 0), (2, 0, 0)), drive="2 + t"))
    model = s.build()
    assert model.dof == 0
    sol = nc.solve_kinematics(model, np.linspace(0, 1, 4))
    p_body0 = model.poses(model.q0)[1][0]
    for t, q, v in zip(sol.t, sol.q, sol.v):
        _, p = model.poses(q)
        assert np.allclose(p[0], p_body0 - 0.3 * t * AXIS3)
        rj = q[model.coordinate_names.index("bar.r_j.x"):][:3]
        assert np.isclose(rj[0], 0.4 * np.sin(t)) and abs(rj[1]) < 1e-12 and np.isclose(np.linalg.norm(rj), 1)
        assert np.allclose(q[model.coordinate_names.index("pt.r_i.x"):][:3], [2 + t, 0, 0])
        assert np.isclose(v[model.coordinate_names.index("pt.r_i.x")], 1.0)


# ------------------------------------------------- shared points = spherical
def _double_pendulum(shared: bool):
    s = nc.System("dp")
    b1 = s.add_bar("b1", coords="rr", mass=1.0, ends=[s.ground.point((0, 0, 0)), (1, 0, 0)],
                   velocity=(0, 0.5, 0), angular_velocity=(0, 0, 1))
    end = b1.end(1) if shared else (1, 0, 0)
    b2 = s.add_bar("b2", coords="rr", mass=0.5, ends=[end, (1, 0.6, -0.8)], velocity=(0, 1.4, 0.3),
                   angular_velocity=(1, 0, 0))
    b2.add_marker("tip", (0.5, 0, 0))
    b1.add_marker("elbow", (0.5, 0, 0))
    if not shared:
        s.add_joint(nc.Spherical(b1, b2, at=(1, 0, 0)))
    return s.build(share=False)         # the joint as equations (sharing would make it the other form)


def _rk4(model, q, v, dt, n):
    def f(q, v):
        a, _ = model.accel(q, v)
        return v, a
    for _ in range(n):
        k1 = f(q, v)
        k2 = f(q + dt / 2 * k1[0], v + dt / 2 * k1[1])
        k3 = f(q + dt / 2 * k2[0], v + dt / 2 * k2[1])
        k4 = f(q + dt * k3[0], v + dt * k3[1])
        q = q + dt / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        v = v + dt / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    return q, v


def test_shared_point_moves_like_a_spherical_joint():
    shared, joint = _double_pendulum(True), _double_pendulum(False)
    assert shared.nq == 6 and joint.nq == 9 and shared.dof == joint.dof == 4
    for m in (shared, joint):
        r, rd = m.markers(m.q0, m.v0)
        assert np.allclose(r, [[1, 1], [0, 0.6], [0, -0.8]])
    # same marker accelerations (world) initially: C a
    a_s, _ = shared.accel(shared.q0, shared.v0)
    a_j, _ = joint.accel(joint.q0, joint.v0)
    assert np.allclose(shared.markers(shared.q0, a_s)[1], joint.markers(joint.q0, a_j)[1], atol=1e-10)
    # and the same motion over 0.3 s (fixed-step RK4 of accel)
    qs, vs = _rk4(shared, shared.q0, shared.v0, 2e-3, 150)
    qj, vj = _rk4(joint, joint.q0, joint.v0, 2e-3, 150)
    assert np.allclose(shared.markers(qs, vs)[0], joint.markers(qj, vj)[0], atol=1e-7)
    assert np.allclose(shared.markers(qs, vs)[1], joint.markers(qj, vj)[1], atol=1e-6)
    T0 = sum(shared.energy(shared.q0, shared.v0))
    assert abs(sum(shared.energy(qs, vs)) - T0) < 1e-6 * max(1, abs(T0))


def test_constraint_jacobian_helper_matches_model():
    s = nc.System("h")
    make_member(s, "body", "a", AT3)
    labels, A = jacobian(s)
    assert labels == [f"a.rigid.{p}" for p in ("uu", "vv", "ww", "vw", "uw", "uv")] and A.shape == (6, 12)
