"""Capsules against spheres, capsules and boxes (``nc.CapsuleSphere``, ``nc.CapsuleCapsule``,
``nc.CapsuleBox``) and the collision-pair table (``nc.contact_between``): gaps against hand
geometry and an independent nearest-point search, W_N against finite differences, TOML round
trips, and the nonsmooth stepper against closed forms (rest forces, a capsule rolling down a
tilted box)."""
import warnings

import numpy as np
import pytest
from scipy.optimize import minimize

import ncgen as nc
from ncgen.errors import ModelError

G = 9.81


def R_x(b):
    return np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])


def R_y(b):
    return np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])


def R_z(b):
    return np.array([[np.cos(b), -np.sin(b), 0], [np.sin(b), np.cos(b), 0], [0, 0, 1]])


def box_inertia(m, size):
    a, b, c = size
    return m / 12 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


def tangent_fd(model, q):
    eps = 1e-7
    _, sv, Vt = np.linalg.svd(model.A(q))
    T = Vt[np.sum(sv > 1e-10):].T
    dg = np.array([(model.gap(q + eps * e) - model.gap(q - eps * e)) / (2 * eps) for e in T.T]).T
    return model.contact_jacobian(q)[0] @ T, dg


def capsule_box_distance(c, u, L, r, cb, Rb, hb):
    """Distance (m) between a capsule (centre c, axis u, length L, radius r) and a solid box,
    by an independent search over the segment parameter and the box's local coordinates."""
    def f(x):
        return np.sum((c + x[0] * u - cb - Rb @ x[1:]) ** 2)
    bounds = [(-L / 2, L / 2)] + [(-h, h) for h in hb]
    best = min((minimize(f, x0, method="L-BFGS-B", bounds=bounds, options={"ftol": 1e-16, "gtol": 1e-13})
                for x0 in (np.zeros(4), np.r_[L / 4, hb / 2], np.r_[-L / 4, -hb / 2])), key=lambda s: s.fun)
    return np.sqrt(best.fun) - r


def segment_distance(c1, u1, L1, c2, u2, L2):
    def f(x):
        return np.sum((c1 + x[0] * u1 - c2 - x[1] * u2) ** 2)
    res = minimize(f, np.zeros(2), method="L-BFGS-B", bounds=[(-L1 / 2, L1 / 2), (-L2 / 2, L2 / 2)],
                   options={"ftol": 1e-16, "gtol": 1e-13})
    return np.sqrt(res.fun)


def rows(model, element):
    return [i for i, n in enumerate(model.contact_names) if n == element or n.startswith(element + ".")]


# ------------------------------------------------------------------------ kinematics
def test_capsule_gaps_equal_the_brute_force_distance():
    """Random poses of a capsule against a box, a capsule and a sphere: the smallest gap of
    each element is the distance between the shapes (nearest points searched independently),
    and every gap is at least it; W_N = ∂g/∂q where the gaps hold."""
    rng = np.random.default_rng(7)
    size, r, L = np.array([0.3, 0.2, 0.1]), 0.04, 0.25
    done = 0
    for _ in range(8):
        Rc = R_z(rng.uniform(-3, 3)) @ R_y(rng.uniform(-3, 3)) @ R_x(rng.uniform(-3, 3))
        Rb = R_z(rng.uniform(-3, 3)) @ R_y(rng.uniform(-3, 3))
        R2 = R_x(rng.uniform(-3, 3)) @ R_y(rng.uniform(-3, 3))
        c = rng.normal(size=3)
        c *= 0.3 / np.linalg.norm(c)
        c2, cs = np.array([0.2, -0.35, 0.1]) + rng.normal(size=3) * 0.05, c + rng.normal(size=3) * 0.1
        u, u2 = Rc[:, 2], R2[:, 2]
        d_box = capsule_box_distance(c, u, L, r, np.zeros(3), Rb, size / 2)
        d_cap = segment_distance(c, u, L, c2, u2, 0.3) - r - 0.03
        t = np.clip(u @ (cs - c), -L / 2, L / 2)
        d_sph = np.linalg.norm(cs - c - t * u) - r - 0.02
        if min(d_box, d_cap, d_sph) < 1e-3:
            continue
        s = nc.System("capsules")
        box = s.add_body("box", mass=1.0, inertia=box_inertia(1.0, size), rotation=Rb, position=(0, 0, 0),
                         velocity=(0.1, 0.2, -0.1), angular_velocity=(0.5, -1, 0.3))
        cap = s.add_body("cap", mass=1.0, inertia=np.diag([0.01, 0.01, 0.002]), rotation=Rc, position=c,
                         velocity=(-0.3, 0.1, 0.2), angular_velocity=(1, 0.2, -0.7))
        cap2 = s.add_body("cap2", mass=1.0, inertia=np.diag([0.01, 0.01, 0.002]), rotation=R2, position=c2)
        ball = s.add_body("ball", mass=1.0, inertia=0.01 * np.eye(3), position=cs, velocity=(0, 0.3, 0))
        s.add_contact(nc.CapsuleBox(cap, r, L, box=box, size=size, name="cb"))
        s.add_contact(nc.CapsuleCapsule(cap, r, L, cap2, 0.03, 0.3, name="cc"))
        s.add_contact(nc.CapsuleSphere(ball, sphere_radius=0.02, capsule=cap, radius=r, length=L, name="cs"))
        model = s.build(contacts="nonsmooth")
        g = model.gap(model.q0)
        for name, d in (("cb", d_box), ("cc", d_cap), ("cs", d_sph)):
            np.testing.assert_allclose(g[rows(model, name)].min(), d, atol=1e-7, err_msg=name)
        WN_T, dg = tangent_fd(model, model.q0)
        held = g < 1.0
        np.testing.assert_allclose(WN_T[held], dg[held], atol=1e-6)
        done += 1
    assert done >= 4, done


def test_capsule_pairs_at_known_configurations():
    """Hand geometry: a capsule lying across a narrower box touches it where its segment
    crosses the top face's two edges (gap = height − r − top, normal +z); two capsules
    crossed at 90° 1 cm apart; a sphere beside a capsule's middle and beyond its end."""
    s = nc.System("known")
    r = 0.05
    cap = s.add_body("cap", mass=1.0, inertia=np.diag([0.01, 0.01, 0.002]), rotation=R_y(np.pi / 2),
                     position=(0.02, 0.01, 0.1 + r + 0.003))             # along x, 3 mm above the top
    s.add_contact(nc.CapsuleBox(cap, r, 0.6, size=(0.2, 0.3, 0.2), name="across"))   # ground box, top at z = 0.1
    c2 = s.add_body("c2", mass=1.0, inertia=np.diag([0.01, 0.01, 0.002]), rotation=R_x(np.pi / 2),
                    position=(0.02, 0.01, 0.1 + 3 * r + 0.013))          # along y, on top of cap
    s.add_contact(nc.CapsuleCapsule(cap, r, 0.6, c2, r, 0.4, name="crossed"))
    ball = s.add_body("ball", mass=1.0, inertia=0.01 * np.eye(3), position=(0.12, 0.01 - r - 0.03 - 0.02, 0.153))
    far = s.add_body("far", mass=1.0, inertia=0.01 * np.eye(3), position=(0.02 + 0.3 + 0.1, 0.01, 0.153 + 0.06))
    s.add_contact(nc.CapsuleSphere(ball, sphere_radius=0.03, capsule=cap, radius=r, length=0.6, name="side"))
    s.add_contact(nc.CapsuleSphere(far, sphere_radius=0.03, capsule=cap, radius=r, length=0.6, name="end"))
    model = s.build(contacts="nonsmooth")
    g = model.gap(model.q0)
    across = rows(model, "across")
    held = sorted(across, key=lambda k: g[k])[:2]
    np.testing.assert_allclose(g[held], 0.003, atol=1e-12)
    assert sorted(model.contact_names[k] for k in held) == ["across.edge2100", "across.edge2101"]
    assert np.sort(g[across])[2] > 0.003 + 0.01
    WN = model.contact_jacobian(model.q0)[0]
    i = model.layout.nodes[model.layout.slots["cap"][0]].index
    np.testing.assert_allclose(WN[held][:, i:i + 3], [[0, 0, 1]] * 2, atol=1e-12)    # lifting the capsule opens them
    crossed = rows(model, "crossed")
    np.testing.assert_allclose(g[model.contact_names.index("crossed.segments")], 0.01, atol=1e-12)
    np.testing.assert_allclose(g[model.contact_names.index("side")], 0.02, atol=1e-12)
    np.testing.assert_allclose(g[model.contact_names.index("end")], np.hypot(0.1, 0.06) - r - 0.03, atol=1e-12)


def test_bad_capsule_contacts_and_unsupported_pairs_are_named():
    s = nc.System("bad")
    b = s.add_body("b", mass=1.0, inertia=np.eye(3) * 0.01, position=(0, 0, 1), shape=nc.Cylinder(0.1, 0.3))
    c = s.add_body("c", mass=1.0, inertia=np.eye(3) * 0.01, position=(0, 0, 2), shape=nc.Box(0.1, 0.2, 0.3))
    e = s.add_body("e", mass=1.0, inertia=np.eye(3) * 0.01, position=(0, 0, 3), shape=nc.Ellipsoid(0.1, 0.2, 0.3))
    n = s.add_body("n", mass=1.0, inertia=np.eye(3) * 0.01, position=(0, 0, 4))
    with pytest.raises(ModelError, match=r"contact_between\('b', 'c'\): no contact between a cylinder and a box"):
        nc.contact_between(b, c)
    with pytest.raises(ModelError, match=r"contact_between\('e', 'ground'\): no contact between an ellipsoid and "
                                         r"a plane"):
        nc.contact_between(e, s.ground)
    with pytest.raises(ModelError, match=r"member 'n' has no shape"):
        nc.contact_between(n, c)
    with pytest.raises(ModelError, match=r"'cb' \(CapsuleBox\): capsule radius: expected a finite number > 0"):
        s.add_contact(nc.CapsuleBox(c, 0.0, 0.2, size=(1, 1, 1), name="cb"))
    with pytest.raises(ModelError, match=r"'cb' \(CapsuleBox\): box size: expected the box's 3 full edge lengths"):
        s.add_contact(nc.CapsuleBox(c, 0.1, 0.2, name="cb"))
    with pytest.raises(ModelError, match=r"both capsules are on the same member 'c'"):
        s.add_contact(nc.CapsuleCapsule(c, 0.1, 0.2, c, 0.1, 0.2, name="cc"))
    with pytest.raises(ModelError, match=r"'cs' \(CapsuleSphere\): capsule length: expected a finite number >= 0"):
        s.add_contact(nc.CapsuleSphere(n, sphere_radius=0.1, capsule=c, radius=0.1, length=-1, name="cs"))
    flat = nc.System("flat", gravity=(0, -G))
    p = flat.add_body("p", coords="ruv", mass=1.0, inertia=0.01, position=(0, 1))
    with pytest.raises(ModelError, match=r"a capsule needs a 3D system"):
        flat.add_contact(nc.CapsuleSphere(p, sphere_radius=0.1, radius=0.1, length=0.2, name="cs"))
    assert not s.contacts


def test_contact_between_follows_the_pair_table():
    s = nc.System("table")
    shapes = {"ball": nc.Sphere(0.05), "crate": nc.Box(0.2, 0.3, 0.1), "pill": nc.Capsule(0.03, 0.2),
              "can": nc.Cylinder(0.04, 0.1)}
    members = {k: s.add_body(k, mass=1.0, inertia=0.01 * np.eye(3), position=(i, 0, 1), shape=v)
               for i, (k, v) in enumerate(shapes.items())}
    made = {(a, b): type(nc.contact_between(members[a], members[b])).__name__
            for a in ("ball", "crate", "pill") for b in ("ball", "crate", "pill") if a != b}
    assert made == {("ball", "crate"): "SphereBox", ("ball", "pill"): "CapsuleSphere",
                    ("crate", "ball"): "SphereBox", ("crate", "pill"): "CapsuleBox",
                    ("pill", "ball"): "CapsuleSphere", ("pill", "crate"): "CapsuleBox"}
    assert type(nc.contact_between(members["can"], members["ball"])).__name__ == "CylinderSphere"
    assert type(nc.contact_between(members["ball"], members["can"])).__name__ == "CylinderSphere"
    for k, kind in (("ball", "SpherePlane"), ("crate", "BoxPlane"), ("pill", "CapsulePlane"), ("can", "CylinderPlane")):
        assert type(nc.contact_between(members[k], s.ground)).__name__ == kind
        assert type(nc.contact_between(s.ground, members[k])).__name__ == kind
    s.add_contact(nc.contact_between(members["crate"], members["pill"], mu=0.3, name="cp"))
    s.add_contact(nc.contact_between(members["can"], s.ground, name="can_floor"))
    model = s.build(contacts="smooth")
    assert [n for n in model.contact_names if n.startswith("cp.")][:2] == ["cp.end0", "cp.end1"]
    again = nc.System.from_toml(s.to_toml()).build(contacts="smooth")
    assert again.contacts == model.contacts


def test_capsule_pairs_round_trip_through_toml():
    text = """
[system]
name = "caps"
[[members]]
name = "pill"
kind = "body"
mass = 1.0
inertia = [[0.01, 0, 0], [0, 0.01, 0], [0, 0, 0.002]]
position = [0, 0, 0.5]
[[members]]
name = "rod"
kind = "body"
mass = 1.0
inertia = [[0.01, 0, 0], [0, 0.01, 0], [0, 0, 0.002]]
position = [0, 0, 0.7]
rotation = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
[[members]]
name = "ball"
kind = "body"
mass = 1.0
inertia = [[0.001, 0, 0], [0, 0.001, 0], [0, 0, 0.001]]
position = [0.5, 0, 0.5]
[[contacts]]
type = "CapsuleBox"
name = "on_table"
capsule = "pill"
radius = 0.05
length = 0.2
size = [1.0, 1.0, 0.2]
box_at = [0, 0, 0.1]
[[contacts]]
type = "CapsuleCapsule"
name = "pair"
between = ["pill", "rod"]
radius_a = 0.05
length_a = 0.2
radius_b = 0.05
length_b = 0.3
mu = 0.4
[[contacts]]
type = "CapsuleSphere"
name = "ball_pill"
sphere = "ball"
sphere_radius = 0.05
capsule = "pill"
radius = 0.05
length = 0.2
"""
    s = nc.System.from_toml(text)
    model = s.build(contacts="smooth")
    assert model.contact_names[:2] == ["on_table.end0", "on_table.end1"]
    assert "pair.segments" in model.contact_names and model.contact_names[-1] == "ball_pill"
    again = nc.System.from_toml(s.to_toml()).build(contacts="smooth")
    assert again.contacts == model.contacts
    g = model.gap(model.q0)
    # the pill stands upright on the table: its lower end sphere 0.5 − 0.1 − 0.05 − 0.2 = 0.15 m up
    np.testing.assert_allclose(g[:2], [0.15, 0.35], atol=1e-12)
    np.testing.assert_allclose(g[model.contact_names.index("ball_pill")], 0.5 - 0.1, atol=1e-12)
    with pytest.raises(ModelError, match=r"contacts\[1\].*radius_b"):
        nc.System.from_toml(text.replace("radius_b = 0.05\n", ""))


# ------------------------------------------------------------------------ dynamics
R_CAP, L_CAP, M_CAP = 0.04, 0.3, 1.0
I_AX, I_TR = 0.4 * M_CAP * R_CAP ** 2, 0.02           # about the axis, across it
THETA = 0.2


#: The tests of the capsule scenes below run in the slow tier (one model of several scenes,
#: compiled and run for 1 s); the same paths in the fast tier: the capsule pairs' gaps against
#: brute-force distances and at known configurations above, capsules and cylinders rolling on a
#: plane against the closed form (tests/test_contact_shapes.py), the ball on a can's end face.
SCENES = pytest.mark.slow


@pytest.fixture(scope="module")
def scenes():
    """One model, independent scenes (h = 1 ms, 0.6 s): a capsule lying across a narrower
    fixed box (on the two crossings of its top edges); a capsule lying across two parallel
    fixed capsules (rails); a ball in the groove between two touching rails (frictionless: with
    friction the wedge is statically indeterminate); a capsule lying
    along a fixed box tilted by θ, rolling down it (μ = 1)."""
    s = nc.System("capsule_scenes")
    inertia = np.diag([I_TR, I_TR, I_AX])
    across = s.add_body("across", mass=M_CAP, inertia=inertia, rotation=R_y(np.pi / 2),
                        position=(0.01, 0.0, 0.2 + R_CAP))
    s.add_contact(nc.CapsuleBox(across, R_CAP, L_CAP, size=(0.1, 0.2, 0.2), box_at=(0, 0, 0.1), mu=0.5,
                                name="across_box"))
    log = s.add_body("log", mass=M_CAP, inertia=inertia, rotation=R_y(np.pi / 2), position=(0, 2.0, 3 * R_CAP))
    for i, x in enumerate((-0.1, 0.1)):                # rails along y under the log's ends
        s.add_contact(nc.CapsuleCapsule(log, R_CAP, L_CAP, s.ground, R_CAP, 1.0, at_b=(x, 2.0, R_CAP),
                                        rotation_b=R_x(np.pi / 2), mu=0.5, name=f"rail{i}"))
    rb = 0.05
    # rails along x at y = 4 ± R_CAP, touching; the ball on both: its centre at distance R_CAP + rb
    # from both axes, height R_CAP + sqrt((R_CAP + rb)² − R_CAP²)
    ball = s.add_body("ball", mass=1.0, inertia=0.4 * rb * rb * np.eye(3),
                      position=(0, 4.0, R_CAP + np.sqrt((R_CAP + rb) ** 2 - R_CAP ** 2)))
    for i, y in enumerate((4.0 - R_CAP, 4.0 + R_CAP)):
        s.add_contact(nc.CapsuleSphere(ball, sphere_radius=rb, at=(0, y, R_CAP), rotation=R_y(np.pi / 2),
                                       radius=R_CAP, length=1.0, name=f"groove{i}"))    # frictionless: determinate
    ramp = R_x(THETA)                                   # falls towards −y
    at = np.array([0, 6.0, 0.2])
    roll = s.add_body("roll", mass=M_CAP, inertia=inertia, rotation=ramp @ R_y(np.pi / 2),
                      position=at + ramp[:, 2] * (0.1 + R_CAP))
    s.add_contact(nc.CapsuleBox(roll, R_CAP, L_CAP, size=(1.0, 3.0, 0.2), box_at=at, box_rotation=ramp, mu=1.0,
                                name="roll_ramp"))
    model = s.build(contacts="nonsmooth")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return model, nc.simulate(model, 0.6, 0.01, method="stepper", substeps=10)


def _f(tr, element):
    return tr.contact_normal[:, [i for i, n in enumerate(tr.contact_names) if n.startswith(element + ".")
                                 or n == element]]


@SCENES
def test_capsule_rests_across_a_narrower_box_on_its_two_edge_crossings(scenes):
    _, tr = scenes
    f = _f(tr, "across_box")
    names = [n for n in tr.contact_names if n.startswith("across_box.")]
    np.testing.assert_allclose(f[1:].sum(axis=1), M_CAP * G, rtol=1e-9)
    loaded = {names[k] for k in np.flatnonzero(f[-1] > 0)}
    assert loaded == {"across_box.edge2100", "across_box.edge2101"}, loaded
    # two supports at x = ±0.05 about the centre at x = 0.01: moments fix the split
    np.testing.assert_allclose(f[-1, [names.index("across_box.edge2100"), names.index("across_box.edge2101")]],
                               M_CAP * G * np.array([0.04, 0.06]) / 0.1, rtol=1e-8)
    np.testing.assert_allclose(tr.point("across", (0, 0, 0))[:, 2], 0.2 + R_CAP, atol=1e-9)


@SCENES
def test_capsule_rests_across_two_rails_and_a_ball_in_their_groove(scenes):
    _, tr = scenes
    for i in range(2):
        np.testing.assert_allclose(_f(tr, f"rail{i}")[1:].sum(axis=1), M_CAP * G / 2, rtol=1e-9)
        assert _f(tr, f"rail{i}")[-1, -1] > 0                                      # the segments carry it
    np.testing.assert_allclose(tr.point("log", (0, 0, 0)), [[0, 2.0, 3 * R_CAP]] * len(tr), atol=1e-9)
    rb = 0.05
    cos_a = np.sqrt((R_CAP + rb) ** 2 - R_CAP ** 2) / (R_CAP + rb)             # normal's angle from vertical
    # measured: 6.6e-6 above the closed form after the first step, decreasing (cause not found;
    # the two frictionless rows are curved: their normals turn with the ball)
    for i in range(2):
        np.testing.assert_allclose(_f(tr, f"groove{i}")[1:, 0], G / (2 * cos_a), rtol=2e-5)
    assert np.ptp(tr.point("ball", (0, 0, 0)), axis=0).max() < 1e-6


@SCENES
def test_capsule_rolls_down_a_tilted_box(scenes):
    """Rolling on its side without slipping: a = g sin θ / (1 + I_axis / (m r²))."""
    _, tr = scenes
    down = -R_x(THETA)[:, 1]
    s = tr.point("roll", (0, 0, 0)) @ down
    a = np.diff(s, 2) / 0.01 ** 2
    np.testing.assert_allclose(a[1:], G * np.sin(THETA) / (1 + I_AX / (M_CAP * R_CAP ** 2)), rtol=1e-4)


def cylinder_distance(m, R3, radius, length, x):
    """Distance (m) from x to a solid cylinder (axis the z of R3), by an independent search
    over cylindrical coordinates of its points, from several starts."""
    e1, e2, u = R3[:, 0], R3[:, 1], R3[:, 2]

    def f(y):
        return np.sum((m + y[0] * (np.cos(y[1]) * e1 + np.sin(y[1]) * e2) + y[2] * u - x) ** 2)
    starts = [(radius / 2, th, 0.0) for th in np.linspace(0, 2 * np.pi, 8, endpoint=False)]
    res = min((minimize(f, y0, method="L-BFGS-B", bounds=[(0, radius), (None, None), (-length / 2, length / 2)],
                        options={"ftol": 1e-16, "gtol": 1e-13}) for y0 in starts), key=lambda r: r.fun)
    return np.sqrt(res.fun)


def test_cylinder_sphere_gap_is_the_signed_distance():
    """Balls beside the side, over an end face, off the rim and inside a tilted moving can:
    gaps against an independent search (outside) and the depth below the nearest surface
    (inside); W_N = ∂g/∂q."""
    s = nc.System("can")
    rot, c0 = R_y(0.4) @ R_x(0.3), np.array([0.1, -0.2, 1.0])
    radius, length = 0.1, 0.3
    can = s.add_body("can", mass=1.0, inertia=np.diag([0.1, 0.1, 0.05]), position=c0, rotation=rot,
                     velocity=(0.3, -0.2, 0.5), angular_velocity=(1.0, -2.0, 0.7))
    targets = {"side": (0.13, 0.05, 0.02), "face": (0.02, -0.03, 0.2), "rim": (0.1, 0.08, -0.19),
               "inside_side": (0.07, 0.05, 0.0), "inside_face": (0.01, 0.0, 0.14)}
    r_ball = 0.02
    for k, name in enumerate(targets):
        ball = s.add_body(name, mass=0.5, inertia=1e-4 * np.eye(3), position=(0, 0, 10.0 + k),
                          velocity=(0.1, 0.2, -0.3))
        s.add_contact(nc.CylinderSphere(ball, sphere_radius=r_ball, cylinder=can, radius=radius, length=length,
                                        mu=0.3, name=name))
    model = s.build(contacts="smooth")
    q = model.q0.copy()
    for name, local in targets.items():
        i = model.layout.nodes[model.layout.slots[name][0]].index
        q[i:i + 3] = c0 + rot @ np.array(local)
    g = model.gap(q)
    for k, (name, local) in enumerate(targets.items()):
        rho, z = np.hypot(local[0], local[1]), abs(local[2])
        if rho < radius and z < length / 2:
            expected = -min(radius - rho, length / 2 - z) - r_ball
        else:
            expected = cylinder_distance(c0, rot, radius, length, c0 + rot @ np.array(local)) - r_ball
        np.testing.assert_allclose(g[k], expected, atol=1e-8, err_msg=name)
    WN_T, dg = tangent_fd(model, q)
    np.testing.assert_allclose(WN_T, dg, atol=1e-7)


@pytest.mark.slow      # fast: test_cylinder_sphere_gap_is_the_signed_distance (the same pair's gap and Jacobian)
def test_ball_rests_on_the_end_face_of_a_standing_can():
    """A ball dropped 1 cm onto the top face of a can fixed to the ground, off its axis, and
    a ball lying in the angle between a can's side and the floor: at rest they carry m g on
    the face, and m g split by the two normals (frictionless: floor m g, side none)."""
    s = nc.System("can_rest")
    rb = 0.03
    top = s.add_body("top", mass=0.4, inertia=0.4 * 0.4 * rb * rb * np.eye(3), position=(0.05, 0.02, 0.3 + rb + 0.01))
    s.add_contact(nc.CylinderSphere(top, sphere_radius=rb, radius=0.1, length=0.3, at=(0, 0, 0.15), mu=0.5,
                                    name="face"))
    side = s.add_body("side", mass=0.4, inertia=0.4 * 0.4 * rb * rb * np.eye(3), position=(1.0 + 0.1 + rb, 0, rb))
    s.add_contact(nc.CylinderSphere(side, sphere_radius=rb, radius=0.1, length=0.3, at=(1.0, 0, 0.15), name="beside"))
    s.add_contact(nc.SpherePlane(side, radius=rb, name="floor"))
    model = s.build(contacts="nonsmooth")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tr = nc.simulate(model, 0.5, 0.01, method="stepper", substeps=10)
    rest = tr.t > 0.1
    f = tr.contact_normal
    np.testing.assert_allclose(f[rest, tr.contact_names.index("face")], 0.4 * G, rtol=1e-9)
    np.testing.assert_allclose(tr.point("top", (0, 0, 0))[rest], [[0.05, 0.02, 0.3 + rb]] * rest.sum(), atol=1e-8)
    np.testing.assert_allclose(f[1:, tr.contact_names.index("floor")], 0.4 * G, rtol=1e-9)
    assert np.all(f[:, tr.contact_names.index("beside")] == 0)
    np.testing.assert_allclose(tr.gap[:, tr.contact_names.index("beside")], 0, atol=1e-12)


# ------------------------------------------------------------------------ convex meshes
def _tetra(tmp_path, side):
    """An OBJ file (written by hand, full precision) of a tetrahedron, centroid at the origin."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]) * side - side / 4
    path = tmp_path / "tetra.obj"
    path.write_text("".join(f"v {x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in v)
                    + "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    return path, v


def test_mesh_plane_takes_the_convex_hull_vertices(tmp_path):
    """A tetrahedron with an extra vertex inside (non-convex as given): the hull's 4
    vertices are the contact points, at their heights above a tilted plane."""
    import trimesh
    path, v = _tetra(tmp_path, 0.2)
    dented = tmp_path / "dented.obj"
    inner = np.vstack([v, [0.0, 0.0, 0.0]])
    trimesh.Trimesh(vertices=inner, faces=[[0, 2, 1], [0, 1, 4], [4, 1, 3], [0, 3, 2], [1, 2, 3], [0, 4, 3]],
                    process=False).export(dented)
    s = nc.System("mesh")
    rot, c0 = R_y(0.3), np.array([0.1, 0.0, 0.5])
    body = s.add_body("t", mass=1.0, inertia=0.01 * np.eye(3), position=c0, rotation=rot, shape=nc.Mesh(str(dented)))
    n = np.array([0.1, 0.0, 1.0]) / np.hypot(0.1, 1.0)
    s.add_contact(nc.MeshPlane(body, dented, scale=2.0, normal=n, name="floor"))
    model = s.build(contacts="nonsmooth")
    assert model.contact_names == [f"floor.vertex{i}" for i in range(4)]
    heights = sorted(n @ (c0 + rot @ (2.0 * x)) for x in v)
    np.testing.assert_allclose(sorted(model.gap(model.q0)), heights, atol=1e-12)
    assert type(nc.contact_between(body, s.ground)).__name__ == "MeshPlane"
    again = nc.System.from_toml(s.to_toml()).build(contacts="nonsmooth")
    assert again.contacts == model.contacts
    with pytest.raises(ModelError, match=r"'m' \(MeshPlane\): mesh: no such file"):
        s.add_contact(nc.MeshPlane(body, tmp_path / "none.stl", name="m"))


@pytest.mark.slow      # fast: test_mesh_plane_takes_the_convex_hull_vertices (the mesh's vertex contacts)
def test_tetrahedron_rests_on_a_face_with_the_closed_form_vertex_forces(tmp_path):
    """A uniform tetrahedron (vertices 0, s e_x, s e_y, s e_z) on its face z = 0: the centre
    of mass projects at barycentric (1/2, 1/4, 1/4) of the base, so its vertices carry
    m g (1/2, 1/4, 1/4), the apex nothing."""
    path, v = _tetra(tmp_path, 0.2)
    s = nc.System("tetra")
    m = 1.5
    t = s.add_body("t", mass=m, inertia=0.002 * np.eye(3), position=(0, 0, 0.05))       # base on z = 0
    s.add_contact(nc.MeshPlane(t, path, mu=0.5, name="floor"))
    model = s.build(contacts="nonsmooth")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tr = nc.simulate(model, 0.3, 0.01, method="stepper", substeps=10)
    g = model.gap(model.q0)
    base = np.flatnonzero(np.abs(g) < 1e-12)
    assert len(base) == 3
    share = {0: 0.5, 1: 0.25, 2: 0.25}                 # by the mesh's vertex index (the hull reorders them)
    want = [m * G * share[int(np.argmin(np.linalg.norm(v - model.contacts[k]["at"], axis=1)))] for k in base]
    np.testing.assert_allclose(tr.contact_normal[1:][:, base], [want] * (len(tr) - 1), rtol=1e-9)
    np.testing.assert_allclose(tr.point("t", (0, 0, 0))[:, 2], 0.05, atol=1e-12)


@SCENES
def test_capsule_contacts_and_edge_crossings_are_drawn(scenes):
    """The scene's contact forces: an edge crossing's along its normal (on the box: down),
    without a point; a ball against a rail at the ball's surface, along the rail's normal."""
    from ncgen.viz.scene import scene
    _, tr = scenes
    sc = scene(tr)
    k = tr.contact_names.index("across_box.edge2100")
    np.testing.assert_allclose(sc.contact_forces[-1, k], [0, 0, -tr.contact_normal[-1, k]], atol=1e-8)
    assert np.all(np.isnan(sc.contact_points[:, k]))
    k = tr.contact_names.index("groove0")
    centre = tr.point("ball", (0, 0, 0))[-1]
    axis_point = np.array([centre[0], 4.0 - R_CAP, R_CAP])          # the rail's axis, along x
    n = (centre - axis_point) / np.linalg.norm(centre - axis_point)
    np.testing.assert_allclose(sc.contact_points[-1, k], centre - 0.05 * n, atol=1e-8)
    np.testing.assert_allclose(sc.contact_forces[-1, k], tr.contact_normal[-1, k] * n, atol=1e-6)
