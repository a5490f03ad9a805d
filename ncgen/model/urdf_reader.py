"""A URDF document read into plain records with the standard library's ``xml.etree`` (no
third-party parser: a first import of a robot does not pay for one).

The records carry what :mod:`ncgen.model.urdf` maps: links (``<inertial>``, ``<visual>``,
``<collision>`` with their box, cylinder, sphere or mesh geometry) and joints (type, parent,
child, ``<origin>``, ``<axis>``, ``<limit>``, ``<dynamics>``, ``<mimic>``).  An ``<origin>`` is
the 4×4 pose ``[[R, xyz], [0, 1]]`` with ``R = R_z(yaw) R_y(pitch) R_x(roll)`` (URDF's fixed-axis
roll, pitch, yaw); a missing element is ``None``, a missing ``<axis>`` the x axis.  ``<dynamics>`` attributes stay text, as the
document gives them.  The document is validated first (:func:`ncgen.model.urdf_checks.check_urdf_document`).
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from types import SimpleNamespace as Record

import numpy as np


def origin(el) -> np.ndarray | None:
    """The pose of an ``<origin xyz rpy>`` element (see the module docstring)."""
    if el is None:
        return None
    x = [float(s) for s in el.get("xyz", "0 0 0").split()]
    roll, pitch, yaw = (float(s) for s in el.get("rpy", "0 0 0").split())
    si, sj, sk = math.sin(roll), math.sin(pitch), math.sin(yaw)
    ci, cj, ck = math.cos(roll), math.cos(pitch), math.cos(yaw)
    cc, cs, sc, ss = ci * ck, ci * sk, si * ck, si * sk
    return np.array([[cj * ck, sj * sc - cs, sj * cc + ss, x[0]],
                     [cj * sk, sj * ss + cc, sj * cs - sc, x[1]],
                     [-sj, cj * si, cj * ci, x[2]],
                     [0.0, 0.0, 0.0, 1.0]])


def _number(text):
    return None if text is None else float(text)


def _vector(text):
    return None if text is None else np.array([float(s) for s in text.split()])


def _geometry(el):
    if el is None:
        return None
    box, cyl, sphere, mesh = (el.find(t) for t in ("box", "cylinder", "sphere", "mesh"))
    return Record(
        box=None if box is None else Record(size=_vector(box.get("size"))),
        cylinder=None if cyl is None else Record(radius=_number(cyl.get("radius")), length=_number(cyl.get("length"))),
        sphere=None if sphere is None else Record(radius=_number(sphere.get("radius"))),
        mesh=None if mesh is None else Record(filename=mesh.get("filename"), scale=_vector(mesh.get("scale"))))


def _shapes(link, tag: str) -> list:
    return [Record(origin=origin(el.find("origin")), geometry=_geometry(el.find("geometry"))) for el in link.findall(tag)]


def _inertial(el):
    if el is None:
        return None
    mass, inertia = el.find("mass"), el.find("inertia")
    I = None
    if inertia is not None:
        v = {k: float(inertia.get(k, "0")) for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
        I = np.array([[v["ixx"], v["ixy"], v["ixz"]], [v["ixy"], v["iyy"], v["iyz"]], [v["ixz"], v["iyz"], v["izz"]]])
    return Record(origin=origin(el.find("origin")), mass=None if mass is None else _number(mass.get("value")),
                  inertia=I)


def _joint(el) -> Record:
    limit, dyn, mimic, axis = (el.find(t) for t in ("limit", "dynamics", "mimic", "axis"))
    return Record(
        name=el.get("name"), type=el.get("type"), parent=el.find("parent").get("link"),
        child=el.find("child").get("link"), origin=origin(el.find("origin")),
        axis=_vector("1 0 0" if axis is None else axis.get("xyz", "1 0 0")),
        limit=None if limit is None else Record(**{k: _number(limit.get(k)) for k in ("lower", "upper", "velocity", "effort")}),
        dynamics=None if dyn is None else Record(damping=dyn.get("damping"), friction=dyn.get("friction")),
        mimic=None if mimic is None else Record(joint=mimic.get("joint"), multiplier=_number(mimic.get("multiplier", "1")),
                                                offset=_number(mimic.get("offset", "0"))))


def read_urdf(text: str) -> Record:
    """The robot's record (``name``, ``links``, ``joints``) of a URDF document already checked
    by ``check_urdf_document``; a number that is not one raises ``ValueError``."""
    root = ET.fromstring(text)
    links = [Record(name=ln.get("name"), inertial=_inertial(ln.find("inertial")), visuals=_shapes(ln, "visual"),
                    collisions=_shapes(ln, "collision")) for ln in root.findall("link")]
    return Record(name=root.get("name"), links=links, joints=[_joint(j) for j in root.findall("joint")])
