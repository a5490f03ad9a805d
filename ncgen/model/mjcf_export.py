"""MJCF export of a tree model: ``model.to_mjcf(path)``.

Each body member becomes a ``<body>`` whose frame is the member's (origin at its centre of
mass, its axes; a free joint's frame for a member on a free joint), nested under the member
its joint hangs from, with an ``<inertial>`` of its mass, centre and ``fullinertia``.  Joints, written in the child body's frame: Revolute → ``hinge``,
Prismatic → ``slide``, Spherical → ``ball``, Free → ``<freejoint>``, Planar → ``slide``,
``slide``, ``hinge`` (along two perpendicular directions in the plane, then about the
normal), JointSequence → its hinges and slides in order (named ``<joint>_<coordinate>``).  A hinge's or slide's ``damping``, ``armature``, ``friction`` (as ``frictionloss``)
and limits (as ``range``) are written; a :class:`~ncgen.model.forces.TorsionalSpring` on a
hinge becomes its ``stiffness``, ``springref`` and extra ``damping``.  Every actuated hinge
or slide gets a ``<motor gear="1">`` (``ctrl`` = the joint efforts in ``model.joint_names``
order).  Angles are in radians (``<compiler angle="radian"/>``), contacts are disabled.

Loops: a Spherical, Fixed or Mimic joint that closes a loop (its member already hangs from
a tree joint) is written as ``<equality>`` ``connect`` (anchor in body1's frame), ``weld``
(the initial relative pose) or ``joint`` (``polycoef = offset multiplier``): MuJoCo then
holds them softly.  Markers become sites named ``<member>_<marker>``.

Refused, naming what: planar models, bars and points, joints of other kinds, members not
reached from the ground through tree joints and forces other than torsional springs on
hinges.
"""
from __future__ import annotations

import numpy as np

from ncgen.errors import ModelError
from ncgen.files import atomic_path
from ncgen.reproducible import perpendicular_basis

KINDS = ("Revolute", "Prismatic", "Spherical", "Free", "Planar", "JointSequence")
#: Joints written as equality constraints when they close a loop.
CLOSURES = ("Spherical", "Fixed", "Mimic")


def _fmt(values) -> str:
    return " ".join(repr(float(x)) for x in np.ravel(values))


def _quat(R) -> np.ndarray:
    """``(w, x, y, z)`` of a rotation matrix (Shepperd's method)."""
    t = np.trace(R)
    k = int(np.argmax([t, R[0, 0], R[1, 1], R[2, 2]]))
    if k == 0:
        w = np.sqrt(1 + t) / 2
        q = [w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)]
    else:
        i, j, m = k - 1, k % 3, (k + 1) % 3
        s = np.sqrt(1 + R[i, i] - R[j, j] - R[m, m]) * 2
        q = [0.0] * 4
        q[0] = (R[m, j] - R[j, m]) / s
        q[1 + i], q[1 + j], q[1 + m] = s / 4, (R[j, i] + R[i, j]) / s, (R[m, i] + R[i, m]) / s
    return np.asarray(q)


def _frame(member):
    """(R, p) of a body member's frame in the world, initial configuration."""
    if member.is_ground:
        return np.eye(3), np.zeros(3)
    R = member.spec.get("rotation")
    return (np.eye(3) if R is None else np.asarray(R, float)), np.asarray(member.spec["position"], float)


def mjcf_text(model) -> str:
    """The MJCF text of ``model`` (module docstring)."""
    if model.dim != 3:
        raise ModelError(f"to_mjcf: model {model.name!r} is planar; MJCF export writes 3D models")
    for m in model.members.values():
        if m.spec.get("kind") != "body" or m.spec.get("basis") is not None:
            raise ModelError(f"to_mjcf: member {m.name!r} is a {m.kind} ({m.ctype.name}); export writes bodies "
                             "given by position, rotation and inertia")
    parent_joint, closures = {}, []
    for j in model.joints:
        if j.kind in KINDS and not j.B.is_ground and j.B.name not in parent_joint:
            parent_joint[j.B.name] = j
        elif j.kind in CLOSURES:
            closures.append(j)
        else:
            raise ModelError(f"to_mjcf: {j.label}: a {j.kind} joint is exported as a tree joint ({', '.join(KINDS)}, "
                             f"to a member without one) or as an equality constraint ({', '.join(CLOSURES)})")
    children: dict = {}
    for j in parent_joint.values():
        children.setdefault("ground" if j.A.is_ground else j.A.name, []).append(j)
    reached, todo = set(), ["ground"]
    while todo:
        here = todo.pop()
        for j in children.get(here, []):
            reached.add(j.B.name)
            todo.append(j.B.name)
    for name in model.members:
        if name not in reached:
            raise ModelError(f"to_mjcf: member {name!r} is not reached from the ground through tree joints")
    springs = {}
    for f in model.forces:
        joint = getattr(f, "joint", None)
        if f.kind != "TorsionalSpring" or joint is None:
            raise ModelError(f"to_mjcf: {f.label}: only torsional springs on hinges are exported")
        springs[joint.name if f.coordinate is None else (joint.name, f.coordinate)] = f
    lines = [f'<mujoco model="{model.name}">', '  <compiler angle="radian"/>',
             f'  <option gravity="{_fmt(model.gravity)}"><flag contact="disable"/></option>', "  <worldbody>"]
    motors = []
    _bodies(lines, "ground", (np.eye(3), np.zeros(3)), children, springs, motors, "    ")
    lines.append("  </worldbody>")
    if closures:
        frames = {n: _body_frame(j) for n, j in parent_joint.items()}
        lines += ["  <equality>"] + ["    " + _closure(j, frames) for j in closures] + ["  </equality>"]
    if motors:
        lines.append("  <actuator>")
        lines += [f'    <motor name="{n}" joint="{n}" gear="1"/>' for n in motors]
        lines.append("  </actuator>")
    lines.append("</mujoco>")
    return "\n".join(lines) + "\n"


def _closure(j, frames) -> str:
    """A loop-closing joint as an equality constraint (body1 a body, its anchor in its frame)."""
    if j.kind == "Mimic":
        o = j.options
        return (f'<joint name="{j.name}" joint1="{o["follower"].name}" joint2="{o["leader"].name}" '
                f'polycoef="{_fmt([o["offset"], o["multiplier"], 0, 0, 0])}"/>')
    one, two = (j.B, j.A) if j.A.is_ground else (j.A, j.B)
    R, p = frames[one.name]
    tag = "connect" if j.kind == "Spherical" else "weld"
    anchor = R.T @ (np.asarray(j.options["at"], float) - p)
    return (f'<{tag} name="{j.name}" body1="{one.name}" body2="{"world" if two.is_ground else two.name}" '
            f'anchor="{_fmt(anchor)}"/>')


def _body_frame(j):
    """(R, p) of the exported body of ``j.B``: the member's frame, or a free joint's frame."""
    R, p = _frame(j.B)
    if j.kind == "Free":
        return j.frame_rotation(), j.frame_origin()
    return R, p


def _bodies(lines, parent_name, frame, children, springs, motors, indent) -> None:
    Rp, pp = frame
    for j in children.get(parent_name, []):
        m = j.B
        Rm, pm = _frame(m)
        R, p = _body_frame(j)
        Rrel, prel = Rp.T @ R, Rp.T @ (p - pp)
        lines.append(f'{indent}<body name="{m.name}" pos="{_fmt(prel)}" quat="{_fmt(_quat(Rrel))}">')
        I = np.asarray(m.spec["inertia"], float)
        I = np.diag(I) if I.ndim == 1 else I
        Q = R.T @ Rm
        I = Q @ I @ Q.T
        lines.append(f'{indent}  <inertial pos="{_fmt(R.T @ (pm - p))}" mass="{float(m.spec["mass"])!r}" fullinertia="'
                     f'{_fmt([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])}"/>')
        lines += [indent + "  " + x for x in _joint(j, R, p, springs, motors)]
        for marker, local in m.markers.items():
            lines.append(f'{indent}  <site name="{m.name}_{marker}" pos="{_fmt(R.T @ (Rm @ local + pm - p))}"/>')
        _bodies(lines, m.name, (R, p), children, springs, motors, indent + "  ")
        lines.append(f"{indent}</body>")


def _joint(j, R, p, springs, motors) -> list[str]:
    o = j.options
    if j.kind == "Free":
        return [f'<freejoint name="{j.name}"/>']
    if j.kind == "JointSequence":
        return [_one(f"{j.name}_{law.name}", kind, R.T @ (c - p), R.T @ a, law, springs.get((j.name, k)),
                     o.get("effort") is not None, motors)
                for k, ((kind, c, a), law) in enumerate(zip(j.steps(), j.laws))]
    at = R.T @ (np.asarray(o["at"], float) - p)
    if j.kind == "Spherical":
        return [f'<joint name="{j.name}" type="ball" pos="{_fmt(at)}"/>']
    if j.kind == "Planar":
        n = np.asarray(o["normal"], float)
        n = n / np.linalg.norm(n)
        e1, e2 = perpendicular_basis(n)
        return [f'<joint name="{j.name}_{k}" type="{t}" pos="{_fmt(at)}" axis="{_fmt(R.T @ a)}"/>'
                for k, (t, a) in enumerate((("slide", e1), ("slide", e2), ("hinge", n)))]
    axis = np.asarray(o["axis"], float)
    return [_one(j.name, "hinge" if j.kind == "Revolute" else "slide", at, R.T @ axis / np.linalg.norm(axis), j,
                 springs.get(j.name), o.get("effort") is not None, motors)]


def _one(name, kind, at, axis, law, spring, actuated: bool, motors) -> str:
    """One hinge or slide: ``law`` holds its dynamics and limits."""
    attrs = {"name": name, "type": kind, "pos": _fmt(at), "axis": _fmt(axis)}
    dyn = dict(getattr(law, "dynamics", {}) or {})
    damping = dyn.get("damping", 0.0)
    if spring is not None:
        attrs["stiffness"] = repr(float(spring.k))
        attrs["springref"] = repr(float(spring.rest_angle))
        damping += float(spring.damping)
    if damping:
        attrs["damping"] = repr(float(damping))
    for ours, theirs in (("armature", "armature"), ("friction", "frictionloss")):
        if dyn.get(ours):
            attrs[theirs] = repr(float(dyn[ours]))
    lim = law.limits
    if "lower" in lim or "upper" in lim:
        attrs["range"] = _fmt([lim.get("lower", -1e10), lim.get("upper", 1e10)])
        attrs["limited"] = "true"
    if actuated:
        motors.append(name)
    return "<joint " + " ".join(f'{k}="{v}"' for k, v in attrs.items()) + "/>"


def write_mjcf(model, path) -> None:
    """Write ``model`` as MJCF to ``path`` atomically."""
    text = mjcf_text(model)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
