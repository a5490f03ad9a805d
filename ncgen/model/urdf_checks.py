"""Validation of a URDF document before it is mapped to a system.

The document must describe a tree (URDF's own rule): a ``<robot>`` root element, unique link
and joint names, every joint naming defined links, one parent joint per link, no kinematic
loop, finite numbers in every origin, axis, mass and inertia, ``mass > 0`` where an
``<inertial>`` is given, and a physically valid inertia tensor (positive semidefinite, principal
moments obeying the triangle inequality ``I_a + I_b ≥ I_c`` to the relative tolerance
:data:`INERTIA_TOL`).  Every error names the link or joint and the value found.

Parsed with the standard library's ``xml.etree`` so that duplicates and loops are seen before
a parser that would silently keep one of them.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np

from ncgen.errors import ModelError

#: Relative tolerance (of the largest principal moment) on positive semidefiniteness and the
#: triangle inequality of an inertia tensor.
INERTIA_TOL = 1e-9


def check_urdf_document(text: str, where: str) -> None:
    """Raise :class:`~ncgen.errors.ModelError` unless ``text`` is a URDF tree as described
    in the module docstring; ``where`` names the file in messages."""
    try:
        robot = ET.fromstring(text)
    except ET.ParseError as e:
        raise ModelError(f"URDF {where}: not well-formed XML ({e})") from None
    if robot.tag != "robot":
        hint = " (this looks like an SDF file; ncgen reads URDF)" if robot.tag == "sdf" else ""
        raise ModelError(f"URDF {where}: expected a <robot> root element, found <{robot.tag}>{hint}")
    links = _named(robot, "link", where)
    joints = _named(robot, "joint", where)
    welded = {el.get("link") for j in joints.values() if j.get("type") == "fixed"
              for el in (j.find("parent"), j.find("child")) if el is not None}
    for name, link in links.items():
        _check_link(link, f"URDF {where}: link {name!r}", lumped=name in welded)
    parent_of: dict[str, str] = {}
    for name, joint in joints.items():
        what = f"URDF {where}: joint {name!r}"
        ends = {}
        for role in ("parent", "child"):
            el = joint.find(role)
            ends[role] = None if el is None else el.get("link")
            if ends[role] is None:
                raise ModelError(f"{what}: no <{role} link=...> element")
            if ends[role] not in links:
                raise ModelError(f"{what}: {role} link {ends[role]!r} is not defined")
        child = ends["child"]
        if child in parent_of:
            raise ModelError(f"URDF {where}: link {child!r} has two parent joints, {parent_of[child]!r} "
                             f"and {name!r} (a URDF is a tree: one parent per link)")
        parent_of[child] = name
        _check_origin(joint, what)
        axis = joint.find("axis")
        if axis is not None:
            xyz = _floats(axis.get("xyz", "1 0 0"), 3, f"{what}: <axis xyz>")
            if not np.linalg.norm(xyz) > 0 and joint.get("type") not in ("fixed", "floating"):
                raise ModelError(f"{what}: <axis xyz> is the zero vector")     # a fixed joint's axis is unused
    _check_no_loop(joints, where)


def _named(robot, tag: str, where: str) -> dict:
    out = {}
    for el in robot.findall(tag):
        name = el.get("name")
        if not name:
            raise ModelError(f"URDF {where}: a <{tag}> element has no name")
        if name in out:
            raise ModelError(f"URDF {where}: two <{tag}> elements are named {name!r} (names must be unique)")
        out[name] = el
    return out


def _check_no_loop(joints: dict, where: str) -> None:
    """Follow parents from every link: coming back to a link on the path is a loop."""
    parent_link = {}
    joint_to = {}
    for name, joint in joints.items():
        child, parent = joint.find("child").get("link"), joint.find("parent").get("link")
        parent_link[child], joint_to[child] = parent, name
    done: set[str] = set()
    for start in parent_link:
        path, here = [], start
        while here in parent_link and here not in done:
            if here in path:
                loop = path[path.index(here):]
                names = ", ".join(repr(joint_to[ln]) for ln in loop)
                raise ModelError(f"URDF {where}: the joints {names} form a kinematic loop through links "
                                 f"{', '.join(map(repr, loop))} (a URDF is a tree)")
            path.append(here)
            here = parent_link[here]
        done.update(path)


def _check_link(link, what: str, lumped: bool) -> None:
    """Finite numbers, a mass ≥ 0 and principal moments ≥ 0; and ``I_a + I_b ≥ I_c`` unless
    the link is ``lumped`` (welded by a fixed joint): then only the inertia of the body it is
    lumped into is a rigid body's (checked when the groups are made, :mod:`ncgen.model.urdf`) —
    stock URDFs weld placeholder links of a point-like, non-physical inertia (Go1's and
    ANYmal's ``base``: 1e-6 in every entry) to the body that carries the mass."""
    inertial = link.find("inertial")
    if inertial is None:
        return
    _check_origin(inertial, f"{what}: <inertial>")
    mass_el = inertial.find("mass")
    mass = 0.0 if mass_el is None else _floats(mass_el.get("value", "nan"), 1, f"{what}: <mass value>")[0]
    if mass < 0:
        raise ModelError(f"{what}: mass {mass:g} kg is negative (expected mass > 0)")
    el = inertial.find("inertia")
    if el is None:
        return
    keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    v = {k: _floats(el.get(k, "0"), 1, f"{what}: <inertia {k}>")[0] for k in keys}
    I = np.array([[v["ixx"], v["ixy"], v["ixz"]], [v["ixy"], v["iyy"], v["iyz"]], [v["ixz"], v["iyz"], v["izz"]]])
    e = np.linalg.eigvalsh(I)
    tol = INERTIA_TOL * max(float(np.abs(e).max()), 1e-300)
    triangle = min(e[1] + e[2] - e[0], e[0] + e[2] - e[1], e[0] + e[1] - e[2])
    if e.min() < -tol or (triangle < -tol and not lumped):
        raise ModelError(f"{what}: the inertia tensor is not physical: principal moments "
                         f"{np.array2string(e, precision=6)} kg·m² (expected all ≥ 0 and I_a + I_b ≥ I_c)")


def _check_origin(el, what: str) -> None:
    origin = el.find("origin")
    if origin is None:
        return
    for key in ("xyz", "rpy"):
        _floats(origin.get(key, "0 0 0"), 3, f"{what}: <origin {key}>")


def _floats(text: str, n: int, what: str) -> np.ndarray:
    try:
        vals = [float(s) for s in text.split()]
    except ValueError:
        raise ModelError(f"{what}: expected {n} number(s), found {text!r}") from None
    if len(vals) != n:
        raise ModelError(f"{what}: expected {n} number(s), found {len(vals)} ({text!r})")
    if not all(math.isfinite(x) for x in vals):
        raise ModelError(f"{what}: expected finite numbers, found {text!r}")
    return np.array(vals)
