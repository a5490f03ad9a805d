"""MJCF frames: the ``<compiler>`` settings that read them and an element's pose.

An element's orientation is at most one of ``quat`` (w x y z, normalised), ``axisangle``
(axis, angle), ``euler`` (three angles about the axes of ``<compiler eulerseq>``: a lowercase
letter turns about the moving frame's axis, an uppercase one about the fixed frame's),
``xyaxes`` (x, then y made orthogonal to it; z = x × y) and ``zaxis`` (the smallest rotation
taking (0, 0, 1) to it); angles are in ``<compiler angle>`` units (degrees by default).
Poses are 4 × 4 homogeneous matrices ``[[R, p], [0, 1]]`` of the element in its parent's
frame (metres).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ncgen.errors import ModelError
from ncgen.model.mjcf_xml import choice, numbers, where

ORIENTATIONS = ("quat", "axisangle", "euler", "xyaxes", "zaxis")


@dataclass(frozen=True)
class Compiler:
    """The ``<compiler>`` settings the import reads (MuJoCo's defaults); ``meshdir`` and
    ``texturedir`` are accepted and unused (meshes are not read)."""

    degrees: bool = True
    eulerseq: str = "xyz"
    inertiafromgeom: str = "auto"
    autolimits: bool = True
    group_range: tuple = (0, 5)
    totalmass: float = -1.0

    def angle(self, value: float) -> float:
        """An angle of the file in radians."""
        return float(np.deg2rad(value)) if self.degrees else float(value)


def read_compiler(root) -> tuple[Compiler, list]:
    """The compiler settings of the document and the elements carrying settings the import
    does not apply (each ``(element, attribute)``)."""
    settings: dict = {}
    unsupported = []
    for el in root.findall("compiler"):
        a = el.attrib
        if "angle" in a:
            settings["degrees"] = choice(el, a, "angle", ("degree", "radian"), "degree") == "degree"
        if "eulerseq" in a:
            seq = a["eulerseq"]
            if len(seq) != 3 or any(c not in "xyzXYZ" for c in seq):
                raise ModelError(f"MJCF {where(el)}: <compiler eulerseq={seq!r}>: expected three letters "
                                 "of xyzXYZ")
            settings["eulerseq"] = seq
        if "inertiafromgeom" in a:
            settings["inertiafromgeom"] = choice(el, a, "inertiafromgeom", ("auto", "true", "false"), "auto")
        if "autolimits" in a:
            settings["autolimits"] = choice(el, a, "autolimits", ("true", "false"), "true") == "true"
        if "inertiagrouprange" in a:
            settings["group_range"] = tuple(int(x) for x in numbers(el, a, "inertiagrouprange", 2))
        if a.get("coordinate", "local") != "local":
            raise ModelError(f"MJCF {where(el)}: <compiler coordinate={a['coordinate']!r}>: only local "
                             "coordinates are supported (as in MuJoCo since 2.3.3)")
        if "settotalmass" in a:
            settings["totalmass"] = float(numbers(el, a, "settotalmass", 1)[0])
        for key in ("boundmass", "boundinertia"):
            if key in a and float(a[key]) > 0:
                unsupported.append((el, key))
        if a.get("balanceinertia") == "true":
            unsupported.append((el, "balanceinertia"))
        if a.get("alignfree") == "true":
            unsupported.append((el, "alignfree"))
    return Compiler(**settings), unsupported


def quat_matrix(q) -> np.ndarray:
    """The rotation of a quaternion ``(w, x, y, z)`` (normalised here)."""
    q = np.asarray(q, float)
    n = np.linalg.norm(q)
    if not n > 0:
        raise ValueError("zero quaternion")
    w, x, y, z = q / n
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def axis_angle_matrix(axis, angle: float) -> np.ndarray:
    """Rodrigues' rotation by ``angle`` (rad) about ``axis`` (normalised here)."""
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def z_to(z) -> np.ndarray:
    """The smallest rotation taking (0, 0, 1) to the direction ``z``."""
    z = np.asarray(z, float) / np.linalg.norm(z)
    e = np.array([0.0, 0.0, 1.0])
    c = float(e @ z)
    axis = np.cross(e, z)
    s = np.linalg.norm(axis)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    return axis_angle_matrix(axis / s, float(np.arctan2(s, c)))


def rotation(el, attrs: dict, compiler: Compiler) -> np.ndarray:
    """The orientation of an element in its parent's frame (module docstring)."""
    given = [k for k in ORIENTATIONS if k in attrs]
    if len(given) > 1:
        raise ModelError(f"MJCF {where(el)}: <{el.tag}> gives its orientation twice ({', '.join(given)}); "
                         "give one")
    if not given:
        return np.eye(3)
    key = given[0]
    bad = f"MJCF {where(el)}: <{el.tag} {key}={attrs[key]!r}>"
    if key == "quat":
        q = numbers(el, attrs, key, 4)
        if not np.linalg.norm(q) > 0:
            raise ModelError(f"{bad}: the zero quaternion is not a rotation")
        return quat_matrix(q)
    if key == "axisangle":
        v = numbers(el, attrs, key, 4)
        if not np.linalg.norm(v[:3]) > 0:
            raise ModelError(f"{bad}: the axis is the zero vector")
        return axis_angle_matrix(v[:3], compiler.angle(v[3]))
    if key == "euler":
        v = numbers(el, attrs, key, 3)
        R = np.eye(3)
        for letter, angle in zip(compiler.eulerseq, v):
            Ri = axis_angle_matrix(np.eye(3)["xyz".index(letter.lower())], compiler.angle(angle))
            R = R @ Ri if letter.islower() else Ri @ R
        return R
    if key == "xyaxes":
        v = numbers(el, attrs, key, 6)
        x, y = v[:3], v[3:]
        if not np.linalg.norm(x) > 0:
            raise ModelError(f"{bad}: the x axis is the zero vector")
        x = x / np.linalg.norm(x)
        y = y - (x @ y) * x
        if not np.linalg.norm(y) > 1e-12:
            raise ModelError(f"{bad}: the y axis is parallel to the x axis")
        y = y / np.linalg.norm(y)
        return np.column_stack([x, y, np.cross(x, y)])
    v = numbers(el, attrs, key, 3)
    if not np.linalg.norm(v) > 0:
        raise ModelError(f"{bad}: the z axis is the zero vector")
    return z_to(v)


def pose(el, attrs: dict, compiler: Compiler) -> np.ndarray:
    """``[[R, p], [0, 1]]`` of an element's ``pos`` and orientation in its parent's frame."""
    T = np.eye(4)
    T[:3, :3] = rotation(el, attrs, compiler)
    T[:3, 3] = numbers(el, attrs, "pos", 3, default=(0.0, 0.0, 0.0))
    return T


def direction(el, attrs: dict, key: str, default) -> np.ndarray:
    """A unit direction (attribute ``key``, e.g. a joint's ``axis``)."""
    v = numbers(el, attrs, key, 3, default=default)
    n = np.linalg.norm(v)
    if not n > 0:
        raise ModelError(f"MJCF {where(el)}: <{el.tag} {key}={attrs.get(key)!r}>: the zero vector is not a direction")
    return v / n

