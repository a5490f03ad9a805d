"""The standard-library URDF reader (``ncgen/model/urdf_reader.py``) reads every URDF of
example-robot-data as yourdfpy (an independent parser) does: the same names, tree, poses,
axes, limits, dynamics, mimics, inertials and shapes, bit for bit."""
from __future__ import annotations

import numpy as np
import pytest


def _urdfs():
    import ncgen as nc
    try:
        root = nc.robots.urdf_path("panda").parents[3]
    except Exception:  # noqa: BLE001 - example-robot-data missing: nothing to compare
        return []
    return sorted(root.rglob("*.urdf"))


def _equal(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return np.array_equal(np.asarray(a, float), np.asarray(b, float))


def _same(a, b, keys) -> bool:
    return (a is None) == (b is None) and (a is None or all(getattr(a, k) == getattr(b, k) for k in keys))


def differences(theirs, ours) -> list[str]:
    out = []
    if (theirs.name, len(theirs.links), len(theirs.joints)) != (ours.name, len(ours.links), len(ours.joints)):
        out.append("robot name or counts")
    for a, b in zip(theirs.joints, ours.joints):
        if (a.name, a.type, a.parent, a.child) != (b.name, b.type, b.parent, b.child):
            out.append(f"joint {a.name}")
        if not (_equal(a.origin, b.origin) and _equal(a.axis, b.axis)):
            out.append(f"joint {a.name}: origin or axis")
        for what, keys in (("limit", ("lower", "upper", "velocity", "effort")), ("dynamics", ("damping", "friction")),
                           ("mimic", ("joint", "multiplier", "offset"))):
            if not _same(getattr(a, what), getattr(b, what), keys):
                out.append(f"joint {a.name}: {what}")
    for a, b in zip(theirs.links, ours.links):
        if a.name != b.name or (a.inertial is None) != (b.inertial is None):
            out.append(f"link {a.name}")
        elif a.inertial is not None and not (_equal(a.inertial.origin, b.inertial.origin) and a.inertial.mass == b.inertial.mass
                                             and _equal(a.inertial.inertia, b.inertial.inertia)):
            out.append(f"link {a.name}: inertial")
        for A, B in ((a.visuals, b.visuals), (a.collisions, b.collisions)):
            if len(A) != len(B):
                out.append(f"link {a.name}: shapes")
                continue
            for x, y in zip(A, B):
                g, h = x.geometry, y.geometry
                if not _equal(x.origin, y.origin) or (g is None) != (h is None):
                    out.append(f"link {a.name}: shape origin or geometry")
                    continue
                if g is None:
                    continue
                ok = (_same(g.box, h.box, ()) and (g.box is None or _equal(g.box.size, h.box.size))
                      and _same(g.cylinder, h.cylinder, ("radius", "length")) and _same(g.sphere, h.sphere, ("radius",))
                      and _same(g.mesh, h.mesh, ("filename",)) and (g.mesh is None or _equal(g.mesh.scale, h.mesh.scale)))
                if not ok:
                    out.append(f"link {a.name}: shape")
    return out


def test_reader_equals_yourdfpy_on_every_example_robot():
    yourdfpy = pytest.importorskip("yourdfpy")      # here, not at collection: every worker would import it
    from ncgen.model.urdf_reader import read_urdf

    paths = _urdfs()
    if not paths:
        pytest.skip("example-robot-data is not installed")
    compared, found = 0, {}
    for path in paths:
        try:
            theirs = yourdfpy.URDF.load(str(path), build_scene_graph=False, load_meshes=False,
                                        build_collision_scene_graph=False, load_collision_meshes=False).robot
        except Exception:  # noqa: BLE001 - a file yourdfpy cannot read is no reference
            continue
        compared += 1
        diff = differences(theirs, read_urdf(path.read_text(encoding="utf-8")))
        if diff:
            found[path.name] = diff[:3]
    assert compared >= 20, f"only {compared} URDFs compared"
    assert not found, found


def test_a_bad_number_outside_the_checks_names_the_file(tmp_path):
    import ncgen as nc

    text = ('<robot name="r"><link name="a"/><link name="b"><inertial><mass value="1"/>'
            '<inertia ixx="1" iyy="1" izz="1"/></inertial></link>'
            '<joint name="j" type="revolute"><parent link="a"/><child link="b"/>'
            '<limit lower="x" upper="1" effort="1" velocity="1"/></joint></robot>')
    with pytest.raises(nc.ModelError, match="URDF text: cannot parse it"):
        nc.System.from_urdf(text)
