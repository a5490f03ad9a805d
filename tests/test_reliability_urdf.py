"""Hostile URDF files: each malformed tree is refused before anything is built, naming the
link or joint and the value found; the CLI exits 1 with that message (never loops, never an
internal error)."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest


import ncgen as nc  # noqa: E402


def link(name, mass=1.0, inertia=(0.01, 0.0, 0.0, 0.02, 0.0, 0.025), xyz="0 0 0"):
    ixx, ixy, ixz, iyy, iyz, izz = inertia
    return (f'<link name="{name}"><inertial><origin xyz="{xyz}"/><mass value="{mass}"/>'
            f'<inertia ixx="{ixx}" ixy="{ixy}" ixz="{ixz}" iyy="{iyy}" iyz="{iyz}" izz="{izz}"/>'
            "</inertial></link>")


def joint(name, parent, child, kind="revolute", xyz="0 0 0.1", axis="0 0 1"):
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz}"/><axis xyz="{axis}"/></joint>')


def robot(*parts):
    return '<?xml version="1.0"?>\n<robot name="r">\n<link name="base"/>\n' + "\n".join(parts) + "\n</robot>"


GOOD = [link("a"), link("b"), joint("ja", "base", "a"), joint("jb", "a", "b")]


def test_the_good_tree_builds():
    model = nc.System.from_urdf(robot(*GOOD)).build()
    assert model.dof == 2


@pytest.mark.parametrize("parts, message", [
    # a loop among three links hanging from nothing but each other
    ([link("a"), link("b"), link("c"), joint("ja", "base", "a"), joint("jb", "b", "c"), joint("jc", "c", "b")],
     r"kinematic loop"),
    ([link("a"), link("b"), joint("ja", "base", "a"), joint("jb", "base", "b"), joint("jb2", "a", "b")],
     r"link 'b' has two parent joints, 'jb' and 'jb2'"),
    ([link("a"), link("a", mass=2.0), joint("ja", "base", "a")], r"two <link> elements are named 'a'"),
    ([link("a"), link("b"), joint("j", "base", "a"), joint("j", "a", "b")], r"two <joint> elements are named 'j'"),
    ([link("a", mass=-0.5), joint("ja", "base", "a")], r"link 'a': mass -0.5 kg is negative"),
    ([link("a", inertia=("nan", 0, 0, 1, 0, 1)), joint("ja", "base", "a")], r"link 'a': <inertia ixx>.*finite"),
    ([link("a", xyz="0 inf 0"), joint("ja", "base", "a")], r"link 'a': <inertial>: <origin xyz>.*finite"),
    ([link("a"), joint("ja", "base", "a", xyz="0 0 nan")], r"joint 'ja': <origin xyz>.*finite"),
    ([link("a"), joint("ja", "base", "a", axis="0 0 0")], r"joint 'ja': <axis xyz> is the zero vector"),
    ([link("a"), joint("ja", "base", "a", axis="0 1")], r"joint 'ja': <axis xyz>: expected 3 number"),
    ([link("a", inertia=(1.0, 0, 0, 0.1, 0, 0.1)), joint("ja", "base", "a")],
     r"link 'a': the inertia tensor is not physical.*I_a \+ I_b"),
    ([link("a", inertia=(0.1, 0.5, 0, 0.1, 0, 0.1)), joint("ja", "base", "a")],
     r"link 'a': the inertia tensor is not physical"),
    ([link("a"), joint("ja", "base", "ghost")], r"joint 'ja': child link 'ghost' is not defined"),
])
def test_malformed_trees_are_refused_by_name(parts, message):
    with pytest.raises(nc.ModelError, match=message):
        nc.System.from_urdf(robot(*parts))


def test_a_negative_mass_merged_through_a_fixed_joint_is_refused():
    parts = [link("a"), link("pad", mass=-0.1), joint("ja", "base", "a"), joint("w", "a", "pad", kind="fixed")]
    with pytest.raises(nc.ModelError, match="link 'pad': mass -0.1 kg is negative"):
        nc.System.from_urdf(robot(*parts))


def test_sdf_and_other_xml_say_a_robot_element_was_expected(tmp_path):
    sdf = tmp_path / "model.urdf"
    sdf.write_text('<?xml version="1.0"?><sdf version="1.7"><model name="m"><link name="l"/></model></sdf>')
    with pytest.raises(nc.ModelError, match=r"expected a <robot> root element, found <sdf>.*SDF"):
        nc.System.from_urdf(sdf)
    broken = tmp_path / "broken.urdf"
    broken.write_text("<robot name='r'><link name='a'></robot>")
    with pytest.raises(nc.ModelError, match="not well-formed XML"):
        nc.System.from_urdf(broken)


def test_cli_check_of_a_looped_urdf_exits_1_at_once(tmp_path):
    path = tmp_path / "loop.urdf"
    path.write_text(robot(link("a"), link("b"), joint("ab", "a", "b"), joint("ba", "b", "a")))
    r = subprocess.run([sys.executable, "-m", "ncgen.cli", "check", str(path)], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 1, r.stderr
    assert "loop" in r.stderr and "internal error" not in r.stderr


PLACEHOLDER = (1e-6,) * 6        # Go1's and ANYmal's base link: rank one, I_a + I_b < I_c


def test_a_placeholder_inertia_welded_to_a_body_is_lumped_into_it():
    """A link of non-physical inertia welded to a massive one is accepted (only the lumped
    body is a rigid body), and the lumped inertia is the parallel-axis sum."""
    parts = [link("a"), link("pad", mass=1e-6, inertia=PLACEHOLDER), joint("ja", "base", "a"),
             joint("w", "a", "pad", kind="fixed", xyz="0 0 0")]
    s = nc.System.from_urdf(robot(*parts))
    (body,) = s.members.values()
    expected = np.diag([0.01, 0.02, 0.025]) + 1e-6 * np.ones((3, 3))     # both at the same point
    np.testing.assert_allclose(body.rigid.mass, 1.0 + 1e-6, rtol=1e-15)
    np.testing.assert_allclose(body.spec["inertia"], expected, atol=1e-15)


def test_a_placeholder_inertia_alone_or_lumped_into_nothing_physical_is_refused():
    alone = [link("a", inertia=PLACEHOLDER), joint("ja", "base", "a")]
    with pytest.raises(nc.ModelError, match=r"link 'a': the inertia tensor is not physical"):
        nc.System.from_urdf(robot(*alone))
    welded = [link("a", mass=1e-6, inertia=PLACEHOLDER), link("pad", mass=1e-6, inertia=PLACEHOLDER),
              joint("ja", "base", "a"), joint("w", "a", "pad", kind="fixed", xyz="0 0 0")]
    with pytest.raises(nc.ModelError, match=r"link\(s\) a, pad \(moved by joint 'ja'\): the inertia tensor is not physical"):
        nc.System.from_urdf(robot(*welded))


def test_contact_functions_of_a_model_without_contacts_are_refused_by_name():
    model = nc.System.from_urdf(robot(*GOOD)).build()
    with pytest.raises(nc.ModelError, match=r"has no function 'gap' \(it has no contacts\); its functions: .*phi"):
        model.gap(model.q0)
