"""The URDF robots of example-robot-data, by name: ``nc.robots.urdf_path("panda")``.

example-robot-data (the optional extra ``pip install 'ncgen[robots]'``, which also brings
the URDF parser yourdfpy) ships no Python module: its URDFs are package data under
``cmeel.prefix/share/example-robot-data/robots``, found here through the distribution's
file list.  A robot's name is its URDF file's stem (``panda``, ``ur5_robot``, ``solo12``,
``talos_reduced``, ...), with ``_robot`` optional (``ur5``).
"""
from __future__ import annotations

import difflib
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
