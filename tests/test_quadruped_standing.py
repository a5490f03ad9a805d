"""The A1 quadruped of examples/quadruped_standing.py: stock URDF, floating base, its own
collision geometry against the floor, held standing by joint PD on the nonsmooth stepper.

References independent of ncgen: the robot's mass from the URDF's ``<inertial>`` masses
(read with the standard library's XML parser), the legs' kinematics from the URDF's joint
origins and axes (a hand-written chain of translations and axis rotations), statics (the
feet carry m g once the base is at rest) and the energy balance's sign (contacts only take
energy)."""
import importlib.util
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc

pytestmark = pytest.mark.slow   # robot scale: the A1's 148 contact points, a C package compiled once (minutes)

G = 9.81
SETTLED = 1.5                  # s: from here on the base is at rest


def _example():
    path = Path(__file__).resolve().parent.parent / "examples" / "quadruped_standing.py"
    spec = importlib.util.spec_from_file_location("quadruped_standing", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def standing():
    ex = _example()
    model = ex.build()
    return ex, model, ex.run(model)


def _urdf():
    return ET.parse(nc.robots.urdf_path("a1")).getroot()


def _rotation(axis, angle):
    """Rodrigues' rotation about the unit ``axis`` by ``angle`` (rad)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def _foot_in_trunk(root, leg, angles):
    """The ``<leg>_foot`` origin in the trunk frame from the URDF's joints (all with rpy 0 in
    the A1, checked) at the joint angles ``angles`` (dict, rad)."""
    joints = {j.find("child").get("link"): j for j in root.findall("joint")}
    chain, link = [], f"{leg}_foot"
    while link != "trunk":
        chain.append(joints[link])
        link = joints[link].find("parent").get("link")
    R, p = np.eye(3), np.zeros(3)
    for j in reversed(chain):
        origin = j.find("origin")
        assert np.allclose([float(x) for x in origin.get("rpy", "0 0 0").split()], 0.0)
        p = p + R @ np.array([float(x) for x in origin.get("xyz").split()])
        if j.get("type") == "revolute":
            R = R @ _rotation([float(x) for x in j.find("axis").get("xyz").split()], angles[j.get("name")])
    return p


def _quaternion_matrix(x, y, z, w):
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def test_all_collision_geometry_is_kept(standing):
    ex, model, traj = standing
    assert len({name.split(".")[0] for name in model.contact_names}) == 22 and model.nk == 148
    assert traj.info["method"] == "stepper" and traj.info["feedback"] == "joint"
    assert traj.t[-1] == pytest.approx(ex.T)


def test_feet_carry_the_weight_once_settled(standing):
    ex, model, traj = standing
    mass = sum(float(i.find("mass").get("value")) for i in _urdf().iter("inertial"))
    late = traj.t >= SETTLED
    assert np.abs(traj.vj[late, 2]).max() < 1e-3                        # m/s: the base at rest
    feet = [k for k, name in enumerate(traj.contact_names) if "foot" in name]
    others = [k for k in range(len(traj.contact_names)) if k not in feet]
    np.testing.assert_allclose(traj.contact_normal[late][:, feet].sum(axis=1), mass * G, rtol=1e-2)
    assert np.abs(traj.contact_normal[late][:, others]).max() == 0.0   # under PD: only the feet touch
    rest = ex.held(model, traj)                  # the stepper's own contact forces, torques held
    feet = [k for k, name in enumerate(rest.contact_names) if "foot" in name]
    others = [k for k in range(len(rest.contact_names)) if k not in feet]
    support = rest.contact_normal[1:, feet].sum(axis=1)
    np.testing.assert_allclose(support, mass * G, rtol=1e-4)       # measured: 1.6e-5
    assert np.abs(rest.contact_normal[1:, others]).max() == 0.0         # only the feet touch
    assert np.ptp(rest.qj[:, 2]) < 1e-4                                 # m: still standing
    assert traj.qj[-1, 2] + ex.FLOOR > 0.25                              # standing, not collapsed


def test_no_penetration(standing):
    _, _, traj = standing
    assert traj.gap.min() > -1e-6


def test_contacts_never_add_energy(standing):
    _, _, traj = standing
    energy = traj.info["energy"]
    assert energy["relative"] < 1e-4
    works = energy["works"]
    contact = sum(np.asarray(works[k]) for k in ("contacts", "friction", "push_out"))
    assert contact[-1] < 0.0
    assert np.all(np.diff(contact) <= 1e-6)     # J per output interval: no step adds energy


def test_base_height_from_the_leg_kinematics(standing):
    ex, model, traj = standing
    root = _urdf()
    qj = traj.qj[-1]
    angles = {name: qj[7 + k] for k, name in enumerate(model.joint_names[1:])}
    R = _quaternion_matrix(*qj[3:7])
    for leg in ex.LEGS:
        foot = R @ _foot_in_trunk(root, leg, angles)
        height = ex.FOOT_RADIUS - foot[2]          # the base above the floor with this foot's sphere on it
        assert qj[2] + ex.FLOOR == pytest.approx(height, abs=1e-3), leg
