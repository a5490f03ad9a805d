"""The URDF robots of example-robot-data, by name: ``nc.robots.urdf_path("panda")``.

example-robot-data (the optional extra ``pip install 'ncgen[robots]'``, which also brings
the URDF parser yourdfpy) ships no Python module: its URDFs are package data under
``cmeel.prefix/share/example-robot-data/robots``, found here through the distribution's
file list.  A robot's name is its URDF file's stem (``panda``, ``ur5_robot``, ``solo12``,
``talos_reduced``, ...), with ``_robot`` optional (``ur5``).  :func:`locked_urdf` gives a
robot's URDF text with some joints locked (e.g. the Panda's fingers, for the 7-DOF arm).
"""
from __future__ import annotations

import difflib
import xml.etree.ElementTree as ET
from importlib import metadata
from pathlib import Path

from ncgen.errors import ModelError

DISTRIBUTION = "example-robot-data"
INSTALL = "pip install 'ncgen[robots]'"


def _urdf_files() -> dict[str, Path]:
    """Every URDF of example-robot-data, by stem."""
    try:
        files = metadata.files(DISTRIBUTION) or []
    except metadata.PackageNotFoundError:
        raise ModelError(f"the example robots come from the package {DISTRIBUTION}, which is not "
                         f"installed: {INSTALL}") from None
    found = {}
    for f in files:
        if str(f).endswith(".urdf") and "/robots/" in str(f):
            found.setdefault(Path(str(f)).stem, Path(f.locate()))
    return dict(sorted(found.items()))


def names() -> list[str]:
    """The names of the robots :func:`urdf_path` finds."""
    return list(_urdf_files())


def urdf_path(name: str) -> Path:
    """The path of example-robot-data's URDF ``name`` (e.g. ``"panda"``, ``"ur5"``), for
    ``nc.System.from_urdf``; a clear error naming the extra to install when it is missing."""
    files = _urdf_files()
    for stem in (name, f"{name}_robot"):
        if stem in files:
            return files[stem]
    close = difflib.get_close_matches(name, list(files), n=5) or list(files)[:10]
    raise ModelError(f"robot {name!r}: example-robot-data has no URDF of that name; close names: "
                     f"{', '.join(close)} (nc.robots.names() lists all {len(files)})")


def locked_urdf(name: str, joints) -> str:
    """The URDF text of the robot ``name`` (:func:`urdf_path`) with the movable ``joints``
    (names) turned into fixed joints at their zero position, their ``<mimic>`` tags dropped:
    e.g. ``locked_urdf("panda", ["panda_finger_joint1", "panda_finger_joint2"])``, the 7-DOF arm
    for ``nc.System.from_urdf``.  A joint not in the file, or a kept joint that mimics a locked
    one, is an error naming it."""
    root = ET.parse(urdf_path(name)).getroot()
    by_name = {j.get("name"): j for j in root.iter("joint") if j.get("type") is not None}
    joints = list(joints)
    for j in joints:
        if j not in by_name:
            raise ModelError(f"locked_urdf({name!r}): no joint {j!r}; its joints: {', '.join(by_name)}")
    for n, j in by_name.items():
        mimic = j.find("mimic")
        if mimic is not None and n not in joints and mimic.get("joint") in joints:
            raise ModelError(f"locked_urdf({name!r}): joint {n!r} mimics the locked joint "
                             f"{mimic.get('joint')!r}: lock it too")
    for j in joints:
        joint = by_name[j]
        joint.set("type", "fixed")
        for child in [c for c in joint if c.tag in ("mimic", "limit", "dynamics", "axis", "safety_controller")]:
            joint.remove(child)
    return ET.tostring(root, encoding="unicode")
