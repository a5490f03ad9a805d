"""URDF import on small hand-written robots: merging fixed links (inertia lumped exactly),
refusals naming the link or joint, limits, mimic, visuals, floating base, the CLI."""
from __future__ import annotations

import numpy as np
import pytest


import ncgen as nc  # noqa: E402

LINK1 = """<link name="link1"><inertial><origin xyz="1 0 0" rpy="0 0 0"/><mass value="1.0"/>
  <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.025"/></inertial>
  <visual><origin xyz="0.5 0 0"/><geometry><box size="1 0.1 0.1"/></geometry></visual></link>"""
TOOL = """<link name="tool"><inertial><origin xyz="0.1 0 0.2" rpy="0.3 0.2 0.1"/><mass value="2.0"/>
  <inertia ixx="0.04" ixy="0.001" ixz="-0.002" iyy="0.05" iyz="0.003" izz="0.06"/></inertial>
  <visual><geometry><mesh filename="package://tool.stl"/></geometry></visual></link>"""


def urdf(body: str, name="bot") -> str:
    return f'<?xml version="1.0"?>\n<robot name="{name}">\n<link name="base"/>\n{body}\n</robot>'


ARM = urdf(f"""{LINK1}
{TOOL}
<link name="tip"/>
<joint name="j1" type="continuous"><parent link="base"/><child link="link1"/>
  <origin xyz="0 0 0.5"/><axis xyz="0 0 1"/><limit effort="10" velocity="3"/></joint>
<joint name="weld" type="fixed"><parent link="link1"/><child link="tool"/><origin xyz="0 1 0" rpy="0 0 0.4"/></joint>
<joint name="tip_joint" type="fixed"><parent link="tool"/><child link="tip"/><origin xyz="0 0 0.3"/></joint>""")


def rot(rpy):
    r, p, y = rpy
    Rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    Ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    Rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def test_fixed_links_are_merged_with_their_inertia_lumped():
    """Kinetic energy at unit joint rate = ½ I_zz about the joint axis, by hand."""
    model = nc.System.from_urdf(ARM).build()
    assert model.member_names == ["link1"]
    assert model.joint_names == ["j1"] and model.input_names == ["tau"]
    assert model.joint_limits == {"j1": {"velocity": 3.0, "effort": 10.0}}
    q, v = model.from_joint_space([0.7], [1.0])
    T, _ = model.energy(q, v)
    Rt = rot((0, 0, 0.4)) @ rot((0.3, 0.2, 0.1))
    I_tool = Rt @ np.array([[0.04, 0.001, -0.002], [0.001, 0.05, 0.003], [-0.002, 0.003, 0.06]]) @ Rt.T
    c_tool = np.array([0, 1, 0]) + rot((0, 0, 0.4)) @ np.array([0.1, 0, 0.2])
    Izz = 0.025 + 1.0 * 1.0**2 + I_tool[2, 2] + 2.0 * (c_tool[0]**2 + c_tool[1]**2)
    assert abs(T - 0.5 * Izz) < 1e-12
    # the merged links' frames ride along
    R, p = model.frame_pose("tip", q)
    Rz = rot((0, 0, 0.7))
    np.testing.assert_allclose(p, [0, 0, 0.5] + Rz @ (np.array([0, 1, 0]) + rot((0, 0, 0.4)) @ [0, 0, 0.3]),
                               atol=1e-13)
    np.testing.assert_allclose(R, Rz @ rot((0, 0, 0.4)), atol=1e-13)


def test_visuals_are_kept():
    s = nc.System.from_urdf(ARM)
    shapes = {v["link"]: v for v in s.visuals}
    assert shapes["link1"]["shape"] == "box"
    np.testing.assert_allclose(shapes["link1"]["size"], [1, 0.1, 0.1])
    assert shapes["tool"]["shape"] == "mesh" and shapes["tool"]["filename"] == "package://tool.stl"
    assert shapes["tool"]["member"] == "link1"


def test_joint_torque_drives_the_link():
    """τ = I_zz θ̈ about a vertical axis (gravity does no work)."""
    model = nc.System.from_urdf(ARM).build()
    q, v = model.from_joint_space([0.0], [0.0])
    a, _ = nc.forward_dynamics(model, q, v, u=[2.0])
    _, _, aj = model.to_joint_space(q, v, a)
    tau = nc.inverse_dynamics(model, [0.0], [0.0], aj)
    assert abs(tau[0] - 2.0) < 1e-12
    assert aj[0] > 0


def test_massless_moving_link_is_refused_by_name():
    text = urdf("""<link name="ghost"/>
<joint name="j" type="revolute"><parent link="base"/><child link="ghost"/><axis xyz="0 0 1"/>
  <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>""")
    with pytest.raises(nc.ModelError, match=r"ghost.*joint 'j'.*no mass"):
        nc.System.from_urdf(text)


def test_unsupported_joint_type_and_bad_input():
    text = urdf(f"""{LINK1}
<joint name="j" type="floating"><parent link="base"/><child link="link1"/></joint>""")
    with pytest.raises(nc.ModelError, match="joint 'j': type 'floating' is not supported"):
        nc.System.from_urdf(text)
    with pytest.raises(nc.ModelError, match="no file"):
        nc.System.from_urdf("/nonexistent/robot.urdf")
    text = urdf(f"""{LINK1}
<joint name="j" type="revolute"><parent link="base"/><child link="nope"/><axis xyz="0 0 1"/></joint>""")
    with pytest.raises(nc.ModelError, match="joint 'j'.*link 'nope'"):
        nc.System.from_urdf(text)


def test_mimic_and_prismatic():
    text = urdf(f"""{LINK1.replace('link1', 'f1')}
{LINK1.replace('link1', 'f2')}
<joint name="s1" type="prismatic"><parent link="base"/><child link="f1"/><axis xyz="0 1 0"/>
  <limit lower="0" upper="0.04" effort="20" velocity="0.2"/></joint>
<joint name="s2" type="prismatic"><parent link="base"/><child link="f2"/><axis xyz="0 -1 0"/>
  <limit lower="0" upper="0.04" effort="20" velocity="0.2"/><mimic joint="s1" multiplier="1" offset="0"/></joint>""")
    model = nc.System.from_urdf(text).build()
    assert model.dof == 1 and model.nu == 1
    assert model.actuated_joints == ["s1"]
    assert model.joint_limits["s2"] == {"lower": 0.0, "upper": 0.04, "velocity": 0.2, "effort": 20.0}
    q, _ = model.from_joint_space({"s1": 0.03})
    np.testing.assert_allclose(model.to_joint_space(q), [0.03, 0.03], atol=1e-12)
    R, p = model.frame_pose("f2", q)
    np.testing.assert_allclose(p, [0, -0.03, 0], atol=1e-12)


def test_floating_base():
    with pytest.raises(nc.ModelError, match=r"base \(moved by the floating base\) have no mass"):
        nc.System.from_urdf(ARM, floating_base=True)
    text = ARM.replace('<link name="base"/>', LINK1.replace("link1", "base"))
    model = nc.System.from_urdf(text, floating_base=True).build()
    assert model.joint_names == ["root", "j1"]
    assert model.dof == 7 and model.nu == 1
    qj = np.array([0.1, 0.2, 0.3, 0, 0, np.sin(0.2), np.cos(0.2), 0.5])
    q, _ = model.from_joint_space(qj)
    np.testing.assert_allclose(model.frame_pose("base", q)[1], [0.1, 0.2, 0.3], atol=1e-13)
    np.testing.assert_allclose(model.to_joint_space(q), qj, atol=1e-13)


def test_cli_check_and_simulate_a_urdf(tmp_path, capsys):
    from ncgen.cli import main
    from ncgen.runtime import Trajectory

    path = tmp_path / "arm.urdf"
    path.write_text(ARM)
    assert main(["check", str(path)]) == 0
    assert "DOF = 1" in capsys.readouterr().out
    out = tmp_path / "arm.npz"
    assert main(["simulate", str(path), "--t-end", "0.1", "--dt", "0.05", "-o", str(out), "--backend", "vm"]) == 0
    traj = Trajectory.load(out)
    assert traj.joint_names == ["j1"] and traj.qj.shape == (3, 1)
