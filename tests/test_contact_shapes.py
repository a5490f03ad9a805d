"""Boxes, capsules and cylinders against planes (``nc.BoxPlane``, ``nc.CapsulePlane``,
``nc.CylinderPlane``): gaps and contact Jacobians against closed forms and finite
differences; the nonsmooth stepper against closed forms (sliding to rest, resting corner
forces, sticking/sliding/tipping on inclines, rolling capsules and cylinders)."""
import warnings

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError, NcgenError
from ncgen.runtime.contact_outputs import STICK

G = 9.81
H, SUB = 0.01, 10                                    # output step, substeps: h = 1 ms
QUICK_COMPILE = True             # its time is gcc compiling its scenes: -O0 (tests/conftest.py)


def R_y(b):
    return np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])


def R_x(b):
    return np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])


def box_inertia(m, size):
    a, b, c = size
    return m / 12 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


def incline(alpha):
    """Normal of a plane through the y axis rising along +x, and its downhill direction."""
    return np.array([-np.sin(alpha), 0, np.cos(alpha)]), np.array([-np.cos(alpha), 0, -np.sin(alpha)])


def simulate(model, t_end):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")               # faces landing flat: redundant contact points
        return nc.simulate(model, t_end, H, method="stepper", substeps=SUB)


# ------------------------------------------------------------------------ kinematics
def test_shape_gaps_and_jacobians_against_closed_forms_and_finite_differences():
    s = nc.System("shapes")
    rot = R_y(0.4) @ R_x(0.3)
    n = np.array([0.1, -0.2, 1.0]) / np.linalg.norm([0.1, -0.2, 1.0])
    kw = dict(mass=1.0, inertia=np.diag([0.1, 0.2, 0.3]), rotation=rot, velocity=(0.3, -0.2, 0.5),
              angular_velocity=(1.0, -2.0, 0.7))
    box = s.add_body("box", position=(0, 0, 1), **kw)
    cap = s.add_body("cap", position=(1, 0, 1), **kw)
    cyl = s.add_body("cyl", position=(2, 0, 1), **kw)
    at = np.array([0.01, 0.02, -0.03])
    s.add_contact(nc.BoxPlane(box, size=(0.2, 0.3, 0.4), at=at, normal=n, point=(0, 0, 0.1), mu=0.5, name="bx"))
    s.add_contact(nc.CapsulePlane(cap, radius=0.1, length=0.5, normal=n, mu=0.5, name="cp"))
    Rs = R_x(0.5) @ R_y(-0.2)                          # the cylinder's axes in its body's frame
    s.add_contact(nc.CylinderPlane(cyl, radius=0.1, length=0.5, at=at, rotation=Rs, normal=n, mu=0.5, name="cy"))
    model = s.build(contacts="nonsmooth")
    assert model.contact_names[:9] == [f"bx.corner{i}" for i in range(8)] + ["cp.end0"]
    assert model.contact_names[10:] == ["cy.end0", "cy.end1"] + [f"cy.face{i}" for i in range(6)]
    assert model.contacts[3]["element"] == "bx" and model.contacts[3]["type"] == "BoxPlane"
    q, v = model.q0, model.v0
    g = model.gap(q)
    origin = {"box": np.array([0, 0, 1.0]), "cap": np.array([1, 0, 1.0]), "cyl": np.array([2, 0, 1.0])}
    # closed forms: a corner's height, a capsule end sphere's, a rim circle's lowest point
    corners = [at + np.array([(1 if i >> j & 1 else -1) * (0.2, 0.3, 0.4)[j] / 2 for j in range(3)]) for i in range(8)]
    np.testing.assert_allclose(g[:8], [n @ (origin["box"] + rot @ c - (0, 0, 0.1)) for c in corners], atol=1e-14)
    ax = rot[:, 2]
    ends = [n @ (origin["cap"] + s_ * 0.25 * ax) for s_ in (-1, 1)]
    np.testing.assert_allclose(g[8:10], np.array(ends) - 0.1, atol=1e-14)
    ax = rot @ Rs[:, 2]
    ends = [n @ (origin["cyl"] + rot @ at + s_ * 0.25 * ax) for s_ in (-1, 1)]
    # (RIM_EPS = 1e-4 raises a rim's gap by ≈ ρ ε² / (2 sin β) ≈ 5e-10 m here)
    np.testing.assert_allclose(g[10:12], np.array(ends) - 0.1 * np.sqrt(1 - (n @ ax) ** 2), rtol=0, atol=1e-9)
    assert np.all(g[12:] > g[10:12].min() - 1e-12)   # the face points are never below the rim's lowest
    # W_N = ∂g/∂q along every motion the constraints allow (the rim point's W_N is the
    # derivative of the lowest point only while the body's axis stays a unit vector)
    WN, WT = model.contact_jacobian(q)
    eps = 1e-7
    _, sv, Vt = np.linalg.svd(model.A(q))
    tangent = Vt[np.sum(sv > 1e-10):].T
    dg = np.array([(model.gap(q + eps * e) - model.gap(q - eps * e)) / (2 * eps) for e in tangent.T]).T
    np.testing.assert_allclose(WN @ tangent, dg, atol=1e-7)
    np.testing.assert_allclose(WN[:10], np.array([(model.gap(q + eps * e) - model.gap(q - eps * e))[:10] / (2 * eps)
                                                  for e in np.eye(model.nq)]).T, atol=1e-7)
    ddt = (model.gap(q + eps * v) - model.gap(q - eps * v)) / (2 * eps)
    np.testing.assert_allclose(WN @ v, ddt, atol=1e-7)
    assert WT.shape == (2 * model.nk, model.nq)


def test_bad_shapes_are_named():
    s = nc.System("bad")
    b = s.add_body("b", mass=1.0, inertia=np.eye(3) * 0.01, position=(0, 0, 1))
    p = s.add_point("p", mass=1.0, position=(0, 0, 1))
    with pytest.raises(NcgenError, match=r"'bx' \(BoxPlane\): size: expected 3"):
        s.add_contact(nc.BoxPlane(b, size=(1, 2), name="bx"))
    with pytest.raises(ModelError, match=r"size\[1\]: expected a finite number > 0"):
        s.add_contact(nc.BoxPlane(b, size=(1, -2, 1), name="bx"))
    with pytest.raises(ModelError, match=r"body: a CapsulePlane needs a rigid body, got the point 'p'"):
        s.add_contact(nc.CapsulePlane(p, radius=0.1, length=0.2, name="cp"))
    with pytest.raises(ModelError, match=r"face_points: expected 0 or an integer >= 3"):
        s.add_contact(nc.CylinderPlane(b, radius=0.1, length=0.2, face_points=2, name="cy"))
    with pytest.raises(ModelError, match=r"radius: expected a number \(m\), got None"):
        s.add_contact(nc.CylinderPlane(b, radius=None, length=0.2, name="cy"))
    assert not s.contacts
    s.add_contact(nc.BoxPlane(b, size=(0.1, 0.1, 0.1), point=(0, 0, 1.0), name="sunk"))
    with pytest.raises(ModelError, match=r"'sunk.corner0' \(BoxPlane\): the initial configuration penetrates by 0.05"):
        s.build(contacts="nonsmooth")
    planar = nc.System("flat", gravity=(0, -G))
    bp = planar.add_body("b", coords="ruv", mass=1.0, inertia=0.01, position=(0, 1))
    with pytest.raises(ModelError, match=r"needs a 3D system"):
        planar.add_contact(nc.CapsulePlane(bp, radius=0.1, length=0.2, name="cp"))
    planar.add_contact(nc.BoxPlane(bp, size=(0.2, 0.1), name="rect"))
    assert planar.build(contacts="nonsmooth").contact_names == [f"rect.corner{i}" for i in range(4)]


def test_shape_contacts_round_trip_through_toml(tmp_path):
    text = """
[system]
name = "toml_shapes"
[[members]]
name = "box"
kind = "body"
mass = 2.0
inertia = [[0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]]
position = [0, 0, 0.5]
[[members]]
name = "can"
kind = "body"
mass = 1.0
inertia = [[0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]]
position = [1, 0, 0.5]
[[contacts]]
type = "BoxPlane"
name = "box_floor"
body = "box"
size = [0.2, 0.3, 0.4]
mu = 0.5
[[contacts]]
type = "CylinderPlane"
name = "can_floor"
body = "can"
radius = 0.1
length = 0.3
face_points = 4
normal = [0, 0, 1]
"""
    s = nc.System.from_toml(text)
    model = s.build(contacts="nonsmooth")
    assert model.contact_names == [f"box_floor.corner{i}" for i in range(8)] + ["can_floor.end0", "can_floor.end1"] \
        + [f"can_floor.face{i}" for i in range(8)]
    again = nc.System.from_toml(s.to_toml()).build(contacts="nonsmooth")
    assert again.contacts == model.contacts
    np.testing.assert_allclose(model.gap(model.q0)[:8], [0.3] * 4 + [0.7] * 4, atol=1e-14)
    with pytest.raises(ModelError, match=r"contacts\[0\]: missing key 'size'|contacts\[0\].*size"):
        nc.System.from_toml(text.replace("size = [0.2, 0.3, 0.4]\n", ""))


# ------------------------------------------------------------------------ blocks
MU = 0.4
V0_SLIDE = 1.5
ALPHA_STICK, ALPHA_SLIP = np.arctan(0.8 * MU), np.arctan(1.2 * MU)
TIP_SIZE = np.array([0.1, 0.2, 0.3])                 # base b = 0.1 m along the slope, height h = 0.3 m
ALPHA_STAND, ALPHA_TIP = np.arctan(0.9 * 0.1 / 0.3), np.arctan(1.1 * 0.1 / 0.3)
BOX = np.array([0.2, 0.3, 0.1])
M_BOX = 2.0


def blocks_run():
    """Boxes of 2 kg on their own planes: sliding on the flat to rest (v0 = 1.5 m/s, μ = 0.4),
    dropped flat from 5 cm, resting on inclines below and above tan α = μ, and standing tall
    boxes (μ = 1) on inclines below and above their tipping angle tan α = b/h."""
    s = nc.System("blocks")
    I = box_inertia(M_BOX, BOX)
    slide = s.add_body("slide", mass=M_BOX, inertia=I, position=(0, 0, BOX[2] / 2), velocity=(V0_SLIDE, 0, 0))
    s.add_contact(nc.BoxPlane(slide, size=BOX, mu=MU, name="slide"))
    drop = s.add_body("drop", mass=M_BOX, inertia=I, position=(0, 2, BOX[2] / 2 + 0.05))
    s.add_contact(nc.BoxPlane(drop, size=BOX, mu=MU, point=(0, 2, 0), name="drop"))
    for name, alpha, y, size, mu in (("stick", ALPHA_STICK, 4, BOX, MU), ("slip", ALPHA_SLIP, 6, BOX, MU),
                                     ("stand", ALPHA_STAND, 8, TIP_SIZE, 1.0), ("tip", ALPHA_TIP, 10, TIP_SIZE, 1.0)):
        n, _ = incline(alpha)
        b = s.add_body(name, mass=M_BOX, inertia=box_inertia(M_BOX, size), rotation=R_y(-alpha),
                       position=np.array([0, y, 0]) + n * size[2] / 2)
        s.add_contact(nc.BoxPlane(b, size=size, mu=mu, point=(0, y, 0), normal=n, name=name))
    model = s.build(contacts="nonsmooth")
    return model, simulate(model, 1.5)


@pytest.fixture(scope="module")
def blocks():
    return blocks_run()


def _corner_forces(tr, name):
    """Normal forces (N) of the box ``name``'s corner contacts, one column per corner."""
    k = [i for i, c in enumerate(tr.contact_names) if c.startswith(name + ".")]
    return tr.contact_normal[:, k]


def test_box_slides_to_rest_over_the_closed_form_distance(blocks):
    _, tr = blocks
    x = tr.point("slide", (0, 0, 0))
    stop = V0_SLIDE / (MU * G)
    np.testing.assert_allclose(x[-1, 0], V0_SLIDE ** 2 / (2 * MU * G), rtol=2e-3)
    moving = tr.t < stop - 2 * H
    np.testing.assert_allclose(np.diff(tr.v[:, 0])[moving[1:]] / H, -MU * G, rtol=1e-6)
    assert np.abs(tr.v[tr.t > stop + 2 * H, :3]).max() < 1e-9
    np.testing.assert_allclose(x[:, 1:], [[0, BOX[2] / 2]] * len(x), atol=1e-9)
    # the four bottom corners carry the weight, the top ones nothing
    f = _corner_forces(tr, "slide")
    np.testing.assert_allclose(f[1:, :4].sum(axis=1), M_BOX * G, rtol=1e-9)
    assert np.all(f[:, 4:] == 0)


def test_box_dropped_flat_rests_on_four_corners_with_a_quarter_of_its_weight_each(blocks):
    _, tr = blocks
    f = _corner_forces(tr, "drop")
    rest = tr.t > 0.5
    # four coplanar supports are statically indeterminate: the weight and the two moments fix
    # three combinations exactly; the fourth (f0 − f1 − f2 + f3) is the solver's choice
    corners = np.array([[(1 if i >> j & 1 else -1) * BOX[j] / 2 for j in range(2)] for i in range(4)])
    np.testing.assert_allclose(f[rest, :4].sum(axis=1), M_BOX * G, rtol=1e-9)
    np.testing.assert_allclose(f[rest, :4] @ corners, 0, atol=1e-9)
    np.testing.assert_allclose(f[rest, :4], M_BOX * G / 4, rtol=5e-3)
    assert np.all(f[:, 4:] == 0)
    assert np.abs(tr.gap[rest][:, [tr.contact_names.index(f"drop.corner{i}") for i in range(4)]]).max() < 1e-9
    np.testing.assert_allclose(tr.point("drop", (0, 0, 0))[-1], [0, 2, BOX[2] / 2], atol=1e-9)


def test_box_on_incline_sticks_below_tan_alpha_mu_and_slides_above(blocks):
    _, tr = blocks
    down_stick, down_slip = incline(ALPHA_STICK)[1], incline(ALPHA_SLIP)[1]
    x_stick = tr.point("stick", (0, 0, 0)) @ down_stick
    assert np.ptp(x_stick) < 1e-9
    states = tr.contact_state[1:, [tr.contact_names.index(f"stick.corner{i}") for i in range(4)]]
    assert np.all(states == STICK)
    a = np.diff(tr.point("slip", (0, 0, 0)) @ down_slip, 2) / H ** 2
    np.testing.assert_allclose(a, G * (np.sin(ALPHA_SLIP) - MU * np.cos(ALPHA_SLIP)), rtol=1e-6)


def test_box_on_incline_tips_iff_tan_alpha_exceeds_base_over_height(blocks):
    _, tr = blocks
    for name, alpha, tips in (("stand", ALPHA_STAND, False), ("tip", ALPHA_TIP, True)):
        n = incline(alpha)[0]
        up = tr.point(name, (0, 0, 1)) - tr.point(name, (0, 0, 0))
        tilt = np.arccos(np.clip(up @ n, -1, 1))
        if tips:
            assert tilt[-1] > 1.0, tilt[-1]                 # fallen onto its downhill face
        else:
            assert tilt.max() < 1e-9, tilt.max()
            assert np.ptp(tr.point(name, (0, 0, 0)) @ incline(alpha)[1]) < 1e-9


# ------------------------------------------------------------------------ rollers
THETA, R_ROLL, L_ROLL, M_ROLL = 0.3, 0.08, 0.3, 1.5
I_AXIS, I_TRANS = 0.5 * M_ROLL * R_ROLL ** 2, 0.04


@pytest.fixture(scope="module")
def rollers():
    """A capsule and cylinders (3 points per end face by default, none, 16)
    lying across an incline θ = 0.3 rad (axis along y), μ = 1, released at rest; and a
    cylinder dropped 1 cm onto the flat on an end face."""
    s = nc.System("rollers")
    n, _ = incline(THETA)
    inertia = np.diag([I_TRANS, I_TRANS, I_AXIS])
    for name, cls, y, kw in (("capsule", nc.CapsulePlane, 0, {}), ("cylinder", nc.CylinderPlane, 1, {}),
                             ("bare", nc.CylinderPlane, 2, {"face_points": 0}),
                             ("many", nc.CylinderPlane, 3, {"face_points": 16})):
        b = s.add_body(name, mass=M_ROLL, inertia=inertia, rotation=R_y(-THETA) @ R_x(-np.pi / 2),
                       position=np.array([0, y, 0]) + n * R_ROLL)
        s.add_contact(cls(b, radius=R_ROLL, length=L_ROLL, point=(0, y, 0), normal=n, mu=1.0, name=name, **kw))
    can = s.add_body("can", mass=M_ROLL, inertia=inertia, position=(0, 5, L_ROLL / 2 + 0.01))
    s.add_contact(nc.CylinderPlane(can, radius=R_ROLL, length=L_ROLL, point=(0, 5, 0), mu=1.0, name="can"))
    model = s.build(contacts="nonsmooth")
    return model, simulate(model, 1.0)


@pytest.mark.parametrize("name", ["capsule", "cylinder", "bare", "many"])
def test_capsule_and_cylinder_roll_down_an_incline_at_the_closed_form_acceleration(rollers, name):
    _, tr = rollers
    n, down = incline(THETA)
    x = tr.point(name, (0, 0, 0))
    a = np.diff(x @ down, 2) / H ** 2
    np.testing.assert_allclose(a, G * np.sin(THETA) / (1 + I_AXIS / (M_ROLL * R_ROLL ** 2)), rtol=1e-4)
    np.testing.assert_allclose(x @ n, R_ROLL, atol=1e-9)
    axis = tr.point(name, (0, 0, 1)) - x
    np.testing.assert_allclose(axis, [[0, 1, 0]] * len(x), atol=1e-9)


def test_cylinder_dropped_on_its_end_stands_on_its_face(rollers):
    _, tr = rollers
    k = [i for i, c in enumerate(tr.contact_names) if c.startswith("can.")]
    rest = tr.t > 0.2
    np.testing.assert_allclose(tr.contact_normal[rest][:, k].sum(axis=1), M_ROLL * G, rtol=1e-9)
    np.testing.assert_allclose(tr.point("can", (0, 0, 0))[rest], [[0, 5, L_ROLL / 2]] * rest.sum(), atol=1e-8)
    top = [tr.contact_names.index(c) for c in ("can.end1", "can.face3", "can.face4", "can.face5")]
    assert np.all(tr.contact_normal[:, top] == 0)


def test_smooth_box_rests_on_its_four_corners_at_the_static_penetration():
    """Compliant law (IDAS): four equal corner springs each carry m g / 4 (determinate here),
    so each sinks ``δ = (m g / (4 k))^(1/n)``."""
    k, n_exp = 1e5, 1.5
    s = nc.System("soft_box")
    box = s.add_body("box", mass=M_BOX, inertia=box_inertia(M_BOX, BOX), position=(0, 0, BOX[2] / 2))
    s.add_contact(nc.BoxPlane(box, size=BOX, mu=0.5, stiffness=k, damping=2e6, exponent=n_exp, name="soft"))
    tr = nc.simulate(s.build(), 1.0, 0.01, rtol=1e-9, atol=1e-11)
    delta = (M_BOX * G / 4 / k) ** (1 / n_exp)
    np.testing.assert_allclose(-tr.gap[-20:, :4], delta, rtol=1e-4)
    np.testing.assert_allclose(tr.contact_normal[-20:, :4], M_BOX * G / 4, rtol=1e-4)
    assert np.all(tr.contact_normal[:, 4:] == 0)


def test_shape_contact_points_are_drawn_on_the_plane(rollers):
    from ncgen.viz.scene import scene
    _, tr = rollers
    sc = scene(tr)
    n, _ = incline(THETA)
    for name in ("cylinder.end0", "cylinder.end1", "capsule.end0"):
        k = tr.contact_names.index(name)
        loaded = tr.contact_normal[:, k] > 0
        assert loaded[1:].all()
        np.testing.assert_allclose(sc.contact_points[loaded, k] @ n, 0, atol=1e-8)


URDF = """<robot name="crate">
  <link name="base">
    <inertial><origin xyz="0 0 0"/><mass value="2.0"/>
      <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.03" iyz="0" izz="0.04"/></inertial>
    <collision><origin xyz="0.01 0 0.1" rpy="0 0 0.3"/><geometry><box size="0.2 0.3 0.1"/></geometry></collision>
    <collision><origin xyz="0 0.1 0.3" rpy="1.5707963267948966 0 0"/>
      <geometry><cylinder radius="0.05" length="0.2"/></geometry></collision>
    <collision><origin xyz="0.2 0 0.2"/><geometry><sphere radius="0.03"/></geometry></collision>
    <collision><geometry><mesh filename="crate.stl"/></geometry></collision>
  </link>
</robot>"""


def test_urdf_collision_boxes_cylinders_spheres_become_ground_contacts():
    s = nc.System.from_urdf(URDF, floating_base=True, collisions={"mu": 0.7})
    assert [c.name for c in s.contacts] == ["base_collision0", "base_collision1", "base_collision2"]
    assert s.skipped_collisions == ["base_collision3"]
    assert all(c.mu == 0.7 for c in s.contacts)
    model = s.build(contacts="nonsmooth")
    assert model.contact_names[:8] == [f"base_collision0.corner{i}" for i in range(8)]
    assert model.contact_names[-1] == "base_collision2"
    g = model.gap(model.q0)
    # the link frame is the world frame at q0: the box's corners at 0.1 ∓ 0.05 m; the
    # cylinder's axis is along y (horizontal), its rims' lowest points a radius below 0.3 m
    np.testing.assert_allclose(np.sort(g[:8]), [0.05] * 4 + [0.15] * 4, atol=1e-12)
    np.testing.assert_allclose(g[8:10], 0.3 - 0.05, rtol=0, atol=1e-9)
    # face points at half the radius, angle φ_j = 2πj/3 from the shape's x; its y is up
    np.testing.assert_allclose(g[10:16], np.tile(0.3 + 0.025 * np.sin(np.arange(3) * 2 * np.pi / 3), 2), atol=1e-12)
    np.testing.assert_allclose(g[-1], 0.2 - 0.03, atol=1e-12)
    assert nc.System.from_urdf(URDF, floating_base=True).contacts == []
    with pytest.raises(ModelError, match=r"collisions: expected True, False or a dict"):
        nc.System.from_urdf(URDF, floating_base=True, collisions="yes")
    with pytest.raises(ModelError, match=r"collisions: unknown key\(s\) 'friction'; expected ground, self, exclude, mu"):
        nc.System.from_urdf(URDF, floating_base=True, collisions={"friction": 0.7})
