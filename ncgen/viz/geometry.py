"""What each member looks like: primitives (box, cylinder, capsule, sphere, ellipsoid, torus, mesh)
placed in member frames, from the model alone (NumPy; no drawing library).

Rules, in order, per member:

* a shape given by the user (``shape=`` / ``member.set_shape``, :mod:`ncgen.model.shapes`);
  a bar's cylinder or capsule lies along the bar (x̄) through the middle of its ends;
* the URDF ``<visual>`` elements of the member (``model.visuals``: boxes, cylinders,
  spheres, meshes, placed by their origins);
* the ground: its URDF visuals, and the boxes fixed to it that contacts touch
  (``SphereBox``, ``BoxBox``);
* a bar: a cylinder between its ends; a body: the box of the same inertia (edges
  ``a_k = √(6 (I_i + I_j − I_k) / m)`` along the principal axes, a flat or line-like body
  thickened to 4 % of its largest edge) plus thin sticks from the centre of mass to its
  basic points and markers; a point member: a small sphere.

A body with a rolling disc or ball (``model.rolling``) is drawn as that disc (a thin
cylinder of its radius about its axle; a torus of its radii when it has a tube) or ball unless it has a shape or visuals of its own; a
knife edge as a thin blade along its direction.

Joints are drawn on their second member (the first when the second is the ground): a
hinge as a short cylinder along its axis, a ball joint as a sphere, a slider as a long thin
rod along its axis.  Dimensions in m; the member frame is the one of ``traj.poses()``
(planar systems are embedded in the plane z = 0).  ``size`` is the scene's size, which sets
the default radii."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ncgen.errors import NcgenError
from ncgen.model.expressions import did_you_mean
from ncgen.reproducible import perpendicular_basis

#: Colours of members, in member order (tab10).
PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
           "#bcbd22", "#17becf")
JOINT_COLOR = "#444444"
STICK_COLOR = "#555555"
GROUND_COLOR = "#999999"
#: Radii relative to the scene's size.
BAR_RADIUS, POINT_RADIUS, STICK_RADIUS, JOINT_RADIUS = 0.012, 0.025, 0.004, 0.018
#: Smallest edge of an inertia box, relative to its largest.
MIN_EDGE = 0.04


@dataclass
class Primitive:
    """One solid in a member frame: ``kind`` (box, cylinder, capsule, sphere, ellipsoid,
    torus, mesh), ``size`` (box edges; cylinder/capsule radius and length, axis along the
    primitive's z; sphere radius; ellipsoid semi-axes; torus radius and tube radius, axis
    along z; mesh scale), placement ``R``
    (primitive → member axes) and ``p`` (m), ``color`` and, for meshes, ``filename``."""

    kind: str
    size: np.ndarray
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    p: np.ndarray = field(default_factory=lambda: np.zeros(3))
    color: str = PALETTE[0]
    filename: str | None = None
    role: str = "member"            # member, joint, stick


def embed(x, dim: int) -> np.ndarray:
    """A 2D vector as (x, y, 0); 3D unchanged."""
    x = np.asarray(x, float)
    return x if dim == 3 else np.concatenate([x, np.zeros(x.shape[:-1] + (1,))], axis=-1)


def embed_rotation(R) -> np.ndarray:
    """A 2×2 rotation as the 3×3 rotation about z (3×3 unchanged); stacks too."""
    R = np.asarray(R, float)
    if R.shape[-1] == 3:
        return R
    out = np.zeros(R.shape[:-2] + (3, 3))
    out[..., :2, :2] = R
    out[..., 2, 2] = 1.0
    return out


def z_to(direction) -> np.ndarray:
    """A rotation taking the z axis to the unit vector along ``direction``."""
    z = np.asarray(direction, float)
    z = z / np.linalg.norm(z)
    return np.column_stack([*perpendicular_basis(z, unit=True), z])


def checked_colors(model, colors) -> dict:
    """``colors`` as a dict ``{member name: colour}``, every name a member of ``model`` and
    every colour a non-empty string."""
    if colors is None:
        return {}
    if not isinstance(colors, dict):
        raise NcgenError(f"colors: expected a dict {{member name: colour}}, got {type(colors).__name__}")
    for name, color in colors.items():
        if name not in model.member_names:
            raise NcgenError(f"colors: {name!r} is not a member of {model.name!r}"
                             f"{did_you_mean(name, model.member_names)}; members: {', '.join(model.member_names)}")
        if not isinstance(color, str) or not color.strip():
            raise NcgenError(f"colors[{name!r}]: expected a CSS colour (a name or '#rrggbb'), got {color!r}")
    return dict(colors)


def member_primitives(model, size: float, colors: dict | None = None) -> dict[str, list[Primitive]]:
    """``{member name or "ground": [Primitive, ...]}`` for ``model`` (see the module docstring);
    ``colors`` overrides the colour of named members (CSS colours: names or ``#rrggbb``)."""
    from ncgen.model.capstan import material_names

    colors = checked_colors(model, colors)
    materials = material_names(model.forces)               # a capstan cable's material: not drawn
    out: dict[str, list[Primitive]] = {}
    visuals: dict[str, list[dict]] = {}
    for v in model.visuals:
        visuals.setdefault(v["member"], []).append(v)
    for k, name in enumerate(model.member_names):
        m = model.member(name)
        color = colors.get(name, PALETTE[k % len(PALETTE)])
        shape = getattr(m, "shape", None)
        if shape is not None:
            prims = [_user_shape(m, shape, color)]
        elif name in visuals:
            prims = [p for v in visuals[name] if (p := _visual(v, color)) is not None]
        elif name in materials:
            prims = []
        else:
            prims = _default(m, size, color)
        wheels = [e for e in getattr(model, "rolling", ()) if e.body == name]
        if wheels:
            drawn = [_rolling(e, size, color) for e in wheels]
            plain = shape is None and name not in visuals and any(e.kind != "KnifeEdge" for e in wheels)
            prims = drawn if plain else prims + drawn
        out[name] = prims
    if "ground" in visuals:
        out["ground"] = [p for v in visuals["ground"] if (p := _visual(v, GROUND_COLOR)) is not None]
    if boxes := _ground_boxes(model):
        out.setdefault("ground", []).extend(boxes)
    for joint in model.joints:
        placed = _joint(model, joint, size)
        if placed is not None:
            out.setdefault(placed[0], []).append(placed[1])
    return out


def _rolling(element, size: float, color) -> Primitive:
    """A rolling disc (thickness a tenth of its radius; a torus of its radii when it has a
    tube), ball or knife edge (a blade a fifth of the scene long) in its body's frame."""
    if element.kind == "RollingDisc" and element.tube_radius:
        return Primitive("torus", np.array([element.radius, element.tube_radius]), z_to(element.axle), color=color)
    if element.kind == "RollingDisc":
        return Primitive("cylinder", np.array([element.radius, 0.1 * element.radius]), z_to(element.axle),
                         color=color)
    if element.kind == "RollingSphere":
        return Primitive("sphere", np.array([element.radius]), color=color)
    thin = STICK_RADIUS * size
    return Primitive("box", np.array([thin, 5 * thin, 0.2 * size]), z_to(element.blade), element.at.copy(),
                     JOINT_COLOR, role="joint")


def _ground_boxes(model) -> list[Primitive]:
    """The boxes fixed to the ground that contacts touch (``SphereBox``, ``BoxBox``: a table, a
    step, a ramp), each once; a planar box as a thin slab in the plane z = 0."""
    out, seen = [], set()
    for c in getattr(model, "contacts", ()):
        if c.get("box") != "ground":
            continue
        size, at, R = (np.asarray(c[k], float) for k in ("size", "box_at", "box_rotation"))
        key = tuple(np.round(np.concatenate([size, at, R.ravel()]), 12))
        if key in seen:
            continue
        seen.add(key)
        dim = len(size)
        edges = size if dim == 3 else np.append(size, MIN_EDGE * float(np.max(size)))
        out.append(Primitive("box", edges, embed_rotation(R), embed(at, dim), GROUND_COLOR))
    return out


def _user_shape(m, shape, color) -> Primitive:
    R, p = shape.rotation, shape.position
    if m.kind == "bar" and shape.kind in ("cylinder", "capsule"):
        ends = _bar_ends(m)
        p = p + (ends[0] + ends[1]) / 2
        R = z_to(ends[1] - ends[0]) @ R
    prim = Primitive(shape.kind, shape.size.copy(), R.copy(), np.asarray(p, float).copy(), color)
    if shape.kind == "mesh":
        prim.size, prim.filename = shape.scale.copy(), shape.filename
    return prim


def _visual(v: dict, color) -> Primitive | None:
    R, p = np.asarray(v["rotation"], float), np.asarray(v["position"], float)
    kind = v["shape"]
    if kind == "box":
        return Primitive("box", np.asarray(v["size"], float), R, p, color)
    if kind == "cylinder":
        return Primitive("cylinder", np.array([v["radius"], v["length"]]), R, p, color)
    if kind == "sphere":
        return Primitive("sphere", np.array([v["radius"]]), R, p, color)
    if kind == "mesh":
        scale = np.ones(3) if v.get("scale") is None else np.resize(np.asarray(v["scale"], float), 3)
        return Primitive("mesh", scale, R, p, color, filename=v["filename"])
    return None


def _bar_ends(m) -> np.ndarray:
    """The two ends of a bar in its local frame (3D)."""
    r = m.rigid
    return embed(np.stack([r.rbar_i, r.rbar_i + r.Xbar[:, 0]]), m.dim)


def _default(m, size: float, color) -> list[Primitive]:
    if m.kind == "bar":
        a, b = _bar_ends(m)
        radius = min(BAR_RADIUS * size, 0.1 * float(np.linalg.norm(b - a)))
        return [Primitive("cylinder", np.array([radius, float(np.linalg.norm(b - a))]), z_to(b - a),
                          (a + b) / 2, color)]
    if m.kind == "point":
        return [Primitive("sphere", np.array([POINT_RADIUS * size]), color=color)]
    prims = [inertia_box(m, size, color)]
    local = [m.rigid.rbar_i] + [m.rigid.rbar_i + m.rigid.Xbar[:, s - 1] for s in m.ctype.point_slots if s >= 1]
    local += list(m.markers.values())
    for x in local:
        x = embed(x, m.dim)
        length = float(np.linalg.norm(x))
        if length > 1e-9:
            prims.append(Primitive("cylinder", np.array([STICK_RADIUS * size, length]), z_to(x), x / 2,
                                   STICK_COLOR, role="stick"))
            prims.append(Primitive("sphere", np.array([2 * STICK_RADIUS * size]), p=x, color=STICK_COLOR,
                                   role="stick"))
    return prims


def inertia_box(m, size: float, color) -> Primitive:
    """The box of the same mass and inertia as body ``m`` (see the module docstring); a body
    without inertia (a point-like one) gets a small cube."""
    mass = float(m.rigid.mass)
    I = np.asarray(m.spec.get("inertia") if m.spec.get("inertia") is not None else 0.0, float)
    if m.dim == 2:
        a = np.sqrt(6 * max(float(I), 0.0) / mass) if mass > 0 else 0.0
        edges, R = np.array([a, a, 0.2 * a]), np.eye(3)
    else:
        I = 0.5 * (I + I.T)
        moments, R = np.linalg.eigh(I)
        if np.linalg.det(R) < 0:
            R[:, 2] *= -1
        total = moments.sum()
        edges = np.sqrt(np.maximum(6 * (total - 2 * moments) / mass, 0.0)) if mass > 0 else np.zeros(3)
    largest = float(edges.max())
    if largest <= 0:
        return Primitive("box", np.full(3, 2 * POINT_RADIUS * size), color=color)
    return Primitive("box", np.maximum(edges, MIN_EDGE * largest), R, np.zeros(3), color)


def _joint(model, joint, size: float) -> tuple[str, Primitive] | None:
    """``(member name, primitive)`` drawing ``joint``, or None (nothing to draw)."""
    at = joint.options.get("at")
    if at is None or np.ndim(at) != 1:
        return None
    host = joint.B if not joint.B.is_ground else joint.A
    if host.is_ground:
        return None
    local = embed(host.to_local(at), model.dim)
    r = JOINT_RADIUS * size
    kind = joint.kind
    axis = joint.options.get("axis")
    if axis is not None and model.dim == 3:
        axis = np.asarray(host.direction_to_local(axis), float)
    elif kind == "Revolute" and model.dim == 2:
        axis = np.array([0.0, 0.0, 1.0])
    else:
        axis = None if axis is None else embed(host.direction_to_local(axis), model.dim)
    if kind in ("Revolute", "Universal") and axis is not None:
        return host.name, Primitive("cylinder", np.array([r, 5 * r]), z_to(axis), local, JOINT_COLOR, role="joint")
    if kind in ("Prismatic", "Cylindrical") and axis is not None:
        return host.name, Primitive("cylinder", np.array([0.4 * r, 8 * r]), z_to(axis), local, JOINT_COLOR,
                                    role="joint")
    if kind in ("Spherical", "Revolute", "Universal", "Fixed"):
        return host.name, Primitive("sphere", np.array([1.2 * r]), p=local, color=JOINT_COLOR, role="joint")
    return None


def outline(prim: Primitive, segments: int = 24) -> np.ndarray:
    """Line drawing of a primitive in its member frame: ``(m, 3)`` points, NaN rows between
    separate strokes (box edges; cylinder and capsule end circles and four sides; three
    principal ellipses of spheres and ellipsoids; a torus's inner, outer, top and bottom
    circles and four cross-sections of its tube; a stick's axis).  Meshes: no rows."""
    a = np.linspace(0, 2 * np.pi, segments + 1)
    c, s, z = np.cos(a), np.sin(a), np.zeros_like(a)
    gap = np.full((1, 3), np.nan)
    strokes = []
    if prim.kind == "box":
        h = prim.size / 2
        square = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]], float)
        for zs in (-1, 1):
            strokes.append(np.column_stack([square * h[:2], np.full(5, zs * h[2])]))
        for x, y in square[:4]:
            strokes.append(np.array([[x * h[0], y * h[1], -h[2]], [x * h[0], y * h[1], h[2]]]))
    elif prim.kind in ("cylinder", "capsule"):
        r, half = prim.size[0], prim.size[1] / 2
        if prim.role == "stick":
            strokes.append(np.array([[0, 0, -half], [0, 0, half]]))
        else:
            for zs in (-half, half):
                strokes.append(np.column_stack([r * c, r * s, np.full_like(a, zs)]))
            for k in range(4):
                x, y = r * np.cos(k * np.pi / 2), r * np.sin(k * np.pi / 2)
                strokes.append(np.array([[x, y, -half], [x, y, half]]))
            if prim.kind == "capsule":
                arc = np.linspace(0, np.pi, segments // 2 + 1)
                for sign in (-1, 1):
                    for axis in (0, 1):
                        pts = np.zeros((len(arc), 3))
                        pts[:, axis] = r * np.cos(arc)
                        pts[:, 2] = sign * (half + r * np.sin(arc))
                        strokes.append(pts)
    elif prim.kind in ("sphere", "ellipsoid"):
        semi = np.full(3, prim.size[0]) if prim.kind == "sphere" else prim.size
        for ring in ((c, s, z), (c, z, s), (z, c, s)):
            strokes.append(np.column_stack(ring) * semi)
    elif prim.kind == "torus":
        big, tube = prim.size
        for radius, height in ((big - tube, 0.0), (big + tube, 0.0), (big, -tube), (big, tube)):
            strokes.append(np.column_stack([radius * c, radius * s, np.full_like(a, height)]))
        for k in range(4):
            e = np.array([np.cos(k * np.pi / 2), np.sin(k * np.pi / 2), 0.0])
            strokes.append(np.outer(big + tube * c, e) + np.outer(tube * s, [0.0, 0.0, 1.0]))
    if not strokes:
        return np.zeros((0, 3))
    local = np.concatenate([x for stroke in strokes for x in (stroke, gap)][:-1])
    return local @ prim.R.T + prim.p
