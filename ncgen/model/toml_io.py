"""Model files: :class:`~ncgen.model.system.System` from and to TOML (docs/model-format.md).

Layout of a file (every table optional except ``members``)::

    [system]      name, gravity
    [parameters]  name = number or list of numbers      (symbolic in every function)
    [inputs]      name = size                           (control inputs)
    [[members]]   name, kind = "body" | "bar" | "point", and the arguments of
                  System.add_body / add_bar / add_point, plus markers = {name = [x, y, z]}
    [[joints]]    type = "Revolute", ..., name, between = ["ground", "crank"]
                  (CoordinateDriver: member = "crank"), and the joint's keywords
                  (JointSequence: steps = [{kind = "hinge", at = [...], axis = [...]}, ...],
                  names, effort = one value per step); dynamics = {damping, armature, friction,
                  lower, upper, ...} (docs/robots.md's joint dynamics; a JointSequence: one
                  such table per coordinate)
    [[forces]]    type = "Spring", ..., name, and the force's arguments
    [[contacts]]  type = "SpherePlane" (sphere, at, radius, plane = "ground", point, normal)
                  or "SphereSphere" (between = ["a", "b"], at_a, radius_a, at_b, radius_b),
                  or "BoxPlane" (body, size) / "CapsulePlane" (body, radius, length) /
                  "CylinderPlane" (body, radius, length, face_points) / "MeshPlane" (body, mesh, scale),
                  each with at, rotation, plane,
                  point, normal; or "SphereBox" (sphere, at, radius, box = "ground", size, box_at,
                  box_rotation) or "BoxBox" (between = ["a", "b"], size_a, size_b, at_a, rotation_a,
                  at_b, rotation_b, edges); "CapsuleSphere" (sphere, sphere_at, sphere_radius, capsule = "ground",
                  radius, length, at, rotation), "CylinderSphere" (the same with cylinder = "ground"),
                  "CapsuleCapsule" (between = ["a", "b"], radius_a, length_a,
                  radius_b, length_b, at_a, rotation_a, at_b, rotation_b) or "CapsuleBox" (capsule, radius,
                  length, at, rotation, box = "ground", size, box_at, box_rotation); all with mu,
                  restitution, stiffness, damping, exponent, slip_velocity, name
    [[rolling]]   type = "RollingDisc" (body, radius, tube_radius, axle), "RollingSphere" (body, radius) or
                  "KnifeEdge" (body, at, blade); all with name and plane_velocity (docs/rolling.md)

Shared basic points are written ``"crank.r_j"`` (slot ``r_j`` of member ``crank``) or
``{ground = [x, y, z]}``.  Values that may vary are numbers or expression strings
(:mod:`ncgen.model.expressions`).  Every error names the key path and what was expected,
e.g. ``joints[2].axis: expected 3 numbers, got 2``; unknown keys are errors.
"""
from __future__ import annotations

import inspect
import tomllib
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from ncgen.errors import NcgenError
from ncgen.errors import ModelError
from ncgen.files import decode_text
from ncgen.model import toml_write
from ncgen.model.expressions import did_you_mean, parse, scope, value_to_toml
from ncgen.model.capsule_contacts import CapsuleCapsule
from ncgen.model.contact_pairs import CONTACT_TYPES
from ncgen.model.contacts import BoxBox, SphereSphere
from ncgen.model.cables import ClusteredCable
from ncgen.model.capstan import CapstanCable
from ncgen.model.forces import FORCE_TYPES as _BASIC_FORCES
from ncgen.model.joint_base import Joint
from ncgen.model.joint_dynamics import DYNAMICS_KEYS, LIMIT_KEYS, coordinate_laws
from ncgen.model.joint_dynamics import KINDS as DYNAMICS_KINDS
from ncgen.model.joints import JOINT_TYPES, CoordinateDriver, JointSequence, Mimic
from ncgen.model.members import NodeRef
from ncgen.model.shapes import shape_from_table
from ncgen.validation import as_scalar, as_system_name

#: Force types by their TOML name.
FORCE_TYPES = {**_BASIC_FORCES, ClusteredCable.kind: ClusteredCable, CapstanCable.kind: CapstanCable}

TOP_KEYS = ("system", "parameters", "inputs", "members", "joints", "forces", "contacts", "rolling", "initial",
            "initial_rates", "controller")
#: Keys of each ``[[rolling]]`` type besides ``type`` and ``name``: ``(key, number of values)``
#: (:mod:`ncgen.model.rolling`; 0: a string, 1: a number, 3: a vector; None: values, numbers or
#: expressions of ``t``, checked by the element).
ROLLING_FIELDS = {"RollingDisc": (("body", 0), ("radius", 1), ("tube_radius", 1), ("axle", 3),
                                   ("plane_velocity", None)),
                  "RollingSphere": (("body", 0), ("radius", 1), ("plane_velocity", None)),
                  "KnifeEdge": (("body", 0), ("at", 3), ("blade", 3), ("plane_velocity", None))}
#: Material keys every contact table may have (:class:`~ncgen.model.contacts.Contact`).
CONTACT_MATERIAL = ("mu", "restitution", "stiffness", "damping", "exponent", "slip_velocity")


@dataclass(frozen=True)
class Field:
    """One key of a member, joint or force table: its ``kind`` (how the value is read, see
    :meth:`_Loader.value`), whether it is ``required``, and the constructor keyword it
    becomes (``arg``: the key itself if empty; a tuple spreads a pair, e.g. ``between`` into
    ``A, B``)."""

    key: str
    kind: str
    required: bool = False
    arg: str | tuple[str, ...] = ""
    default: object = None          # used when the key is missing; a callable takes the dimension


#: Keys of each member kind: the arguments of System.add_body / add_bar / add_point.
MEMBER_FIELDS = {
    "body": (Field("coords", "string", default=lambda dim: "ruvw"[:dim + 1]), Field("mass", "number", True), Field("inertia", "inertia", True),
             Field("position", "vector"), Field("rotation", "rotation"), Field("velocity", "vector"),
             Field("angular_velocity", "angular velocity"), Field("basis", "basis"), Field("share", "share"),
             Field("shape", "shape")),
    "bar": (Field("coords", "string"), Field("mass", "number", True), Field("ends", "ends", True),
            Field("inertia", "number"), Field("com", "number"), Field("velocity", "vector"),
            Field("angular_velocity", "angular velocity"), Field("shape", "shape")),
    "point": (Field("mass", "number", True), Field("position", "point or node", True), Field("velocity", "vector"),
              Field("shape", "shape")),
}

#: Keys of each force type: the arguments of its class.
FORCE_FIELDS = {
    "PointForce": (Field("member", "member", True), Field("at", "vector", True), Field("force", "force", True)),
    "Torque": (Field("member", "member", True), Field("torque", "torque", True)),
    "Spring": (Field("between", "two members", True, ("a", "b")), Field("at_a", "vector", True),
               Field("at_b", "vector", True), Field("k", "value", True), Field("rest_length", "value"),
               Field("damping", "value"), Field("cable", "bool")),
    "TorsionalSpring": (Field("joint", "joint", True), Field("k", "value", True), Field("damping", "value"),
                        Field("rest_angle", "value of t and parameters"), Field("coordinate", "index")),
    "GeneralizedForce": (Field("value", "generalized force", True),),
    "ClusteredCable": (Field("path", "cable path", True), Field("k", "value", True),
                       Field("rest_length", "value", True), Field("damping", "value")),
    "CapstanCable": (Field("path", "cable path", True), Field("pulley", "index or indices", True),
                     Field("mu", "value or values", True), Field("wrap", "value or values"),
                     Field("turns", "index or indices"), Field("ea", "value", True),
                     Field("rest_lengths", "values of parameters", True),
                     Field("material", "member or members, not the ground", True), Field("axis", "vector", True),
                     Field("damping", "value"), Field("slip_velocity", "value"), Field("reeled", "value or values")),
}

_SHAPE_PLANE = (Field("at", "vector"), Field("rotation", "rotation"), Field("plane", "member"), Field("point", "vector"), Field("normal", "vector"))
#: Keys of each contact type besides the material (:data:`CONTACT_MATERIAL`).
CONTACT_FIELDS = {
    "SpherePlane": (Field("sphere", "member", True), Field("at", "vector"), Field("radius", "number"),
                    Field("plane", "member"), Field("point", "vector"), Field("normal", "vector")),
    "SphereSphere": (Field("between", "two members", True, ("a", "b")), Field("at_a", "vector"),
                     Field("radius_a", "number"), Field("at_b", "vector"), Field("radius_b", "number")),
    "BoxPlane": (Field("body", "member", True), Field("size", "vector", True), *_SHAPE_PLANE),
    "CapsulePlane": (Field("body", "member", True), Field("radius", "number", True), Field("length", "number", True),
                     *_SHAPE_PLANE),
    "CylinderPlane": (Field("body", "member", True), Field("radius", "number", True), Field("length", "number", True),
                      Field("face_points", "number"), *_SHAPE_PLANE),
    "SphereBox": (Field("sphere", "member", True), Field("at", "vector"), Field("radius", "number"),
                  Field("box", "member"), Field("size", "vector", True), Field("box_at", "vector"),
                  Field("box_rotation", "rotation")),
    "BoxBox": (Field("between", "two members", True, ("a", "b")), Field("size_a", "vector", True),
               Field("size_b", "vector", True), Field("at_a", "vector"), Field("rotation_a", "rotation"),
               Field("at_b", "vector"), Field("rotation_b", "rotation"), Field("edges", "bool")),
    "CapsuleSphere": (Field("sphere", "member", True), Field("sphere_at", "vector"), Field("sphere_radius", "number"),
                      Field("capsule", "member"), Field("radius", "number", True), Field("length", "number", True),
                      Field("at", "vector"), Field("rotation", "rotation")),
    "MeshPlane": (Field("body", "member", True), Field("mesh", "string", True), Field("scale", "number or vector"),
                  *_SHAPE_PLANE),
    "CylinderSphere": (Field("sphere", "member", True), Field("sphere_at", "vector"), Field("sphere_radius", "number"),
                       Field("cylinder", "member"), Field("radius", "number", True), Field("length", "number", True),
                       Field("at", "vector"), Field("rotation", "rotation")),
    "CapsuleCapsule": (Field("between", "two members", True, ("a", "b")), Field("radius_a", "number", True),
                       Field("length_a", "number", True), Field("radius_b", "number", True),
                       Field("length_b", "number", True), Field("at_a", "vector"), Field("rotation_a", "rotation"),
                       Field("at_b", "vector"), Field("rotation_b", "rotation")),
    "CapsuleBox": (Field("capsule", "member", True), Field("radius", "number", True), Field("length", "number", True),
                   Field("at", "vector"), Field("rotation", "rotation"), Field("box", "member"),
                   Field("size", "vector", True), Field("box_at", "vector"), Field("box_rotation", "rotation")),
}

#: Joints whose keys are not ``between`` and their keyword arguments.
SPECIAL_JOINT_FIELDS = {
    "CoordinateDriver": (Field("member", "member, not the ground", True), Field("slot", "slot or axis", True),
                         Field("axis", "slot or axis", True), Field("value", "value of t and parameters")),
    "Mimic": (Field("leader", "joint", True), Field("follower", "joint", True), Field("multiplier", "number"),
              Field("offset", "number")),
}
#: How a joint's keyword argument is read, where it is not a world vector.
JOINT_ARGUMENT_KINDS = {"drive": "value of t and parameters", "rotation": "rotation", ("Distance", "at"): "two points",
                        "steps": "joint steps", "names": "names"}
#: Keys of one step of a JointSequence (``steps = [{kind, at, axis}, ...]``).
STEP_KEYS = ("kind", "at", "axis")
#: Field kinds that name elements of the system (read by ``_Loader._reference``).
REFERENCE_KINDS = frozenset({"share", "point or node", "ends", "member", "member, not the ground", "two members",
                             "member or members, not the ground", "joint", "cable path"})
#: Field kinds that are expressions of t, parameters and inputs (``_Loader._expression``; and ``value[n]``).
EXPRESSION_KINDS = frozenset({"value or values", "values of parameters", "value", "value of t and parameters",
                              "force", "torque", "generalized force"})
#: Components of a joint's actuator effort (``effort``), where not one.
EFFORT_SIZE = {"Cylindrical": 2, "Universal": 2, "Planar": 3, "Spherical": 3}


def joint_fields(cls, dim: int, steps: int = 1) -> tuple[Field, ...]:
    """The keys of joint type ``cls``: ``between`` (its two members) and its keyword-only
    arguments (required when they have no default), or :data:`SPECIAL_JOINT_FIELDS`;
    ``steps``: a JointSequence's number of steps (the size of its ``effort``)."""
    if cls.kind in SPECIAL_JOINT_FIELDS:
        return SPECIAL_JOINT_FIELDS[cls.kind]
    fields = [Field("between", "two members", True, ("A", "B"))]
    for k, p in inspect.signature(cls).parameters.items():
        if p.kind != p.KEYWORD_ONLY or k == "name":
            continue
        if k == "effort":
            n = (6 if dim == 3 else 3) if cls.kind == "Free" else steps if cls is JointSequence \
                else EFFORT_SIZE.get(cls.kind, 1)
            kind = f"value[{n}]"
        else:
            kind = JOINT_ARGUMENT_KINDS.get((cls.kind, k), JOINT_ARGUMENT_KINDS.get(k, "vector"))
        fields.append(Field(k, kind, p.default is p.empty))
    return tuple(fields)


# ======================================================================= reading
def system_from_toml(source, system_class):
    """A system (an instance of ``system_class``, :class:`~ncgen.model.system.System`) from a
    path or TOML text."""
    text, origin = _source_text(source)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ModelError(f"{origin}: invalid TOML: {e}") from None
    try:
        return _Loader(data, origin, system_class).system
    except ModelError:
        raise
    except NcgenError as e:
        raise ModelError(str(e)) from None


def _source_text(source) -> tuple[str, str]:
    if isinstance(source, Path) or (isinstance(source, str) and "\n" not in source
                                    and (source.endswith(".toml") or Path(source).is_file())):
        path = Path(source)
        try:
            return decode_text(path.read_bytes(), str(path)), str(path)
        except NcgenError as e:
            raise ModelError(str(e)) from None
        except OSError as e:
            raise ModelError(f"cannot read model file {str(path)!r}: {e.strerror}") from None
    if not isinstance(source, str):
        raise ModelError(f"from_toml: expected a path or TOML text, got {type(source).__name__}")
    return source.removeprefix("\ufeff"), "<toml text>"


def _describe(v) -> str:
    if isinstance(v, bool):
        return f"a boolean ({str(v).lower()})"
    if isinstance(v, (int, float)):
        return f"a number ({v!r})"
    if isinstance(v, str):
        return f"a string ({v!r})"
    if isinstance(v, dict):
        return "a table"
    if isinstance(v, list):
        return f"{len(v)}" if all(_is_number(x) for x in v) else f"a list of {len(v)}"
    return type(v).__name__


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


class _Table:
    """One TOML table with its key path; every key must be taken, the rest are unknown."""

    def __init__(self, data, path: str, what: str = "a table"):
        if not isinstance(data, dict):
            raise ModelError(f"{path}: expected {what}, got {_describe(data)}")
        self.data, self.path, self.taken = data, path, set()

    def at(self, k) -> str:
        return f"{self.path}.{k}" if self.path else str(k)

    def get(self, k, default=None, required: bool = False):
        self.taken.add(k)
        if k not in self.data:
            if required:
                for other in self.data:
                    if other not in self.taken and did_you_mean(other, [k]):
                        raise ModelError(f"{self.at(other)}: unknown key (did you mean {k!r}?)")
                raise ModelError(f"{self.at(k)}: missing (required)")
            return default
        return self.data[k]

    def finish(self, allowed):
        for k in self.data:
            if k not in self.taken:
                raise ModelError(f"{self.at(k)}: unknown key{did_you_mean(k, allowed)}; "
                                 f"expected one of: {', '.join(allowed)}")


def _number(v, path) -> float:
    if not _is_number(v):
        raise ModelError(f"{path}: expected a number, got {_describe(v)}")
    return as_scalar(v, path)


def _string(v, path) -> str:
    if not isinstance(v, str):
        raise ModelError(f"{path}: expected a string, got {_describe(v)}")
    return v


def _bool(v, path) -> bool:
    if not isinstance(v, bool):
        raise ModelError(f"{path}: expected true or false, got {_describe(v)}")
    return v


def _pair(v, path, expected: str) -> list:
    """``v``, checked to be a list of two (``expected`` says of what, for the error)."""
    if not isinstance(v, list) or len(v) != 2:
        raise ModelError(f"{path}: expected {expected}, got {_describe(v)}")
    return v


def _vector(v, n, path) -> list[float]:
    if not isinstance(v, list) or len(v) != n or not all(_is_number(x) for x in v):
        raise ModelError(f"{path}: expected {n} numbers, got {_describe(v)}")
    return [as_scalar(x, f"{path}[{i}]") for i, x in enumerate(v)]


def _matrix(v, n, path) -> list[list[float]]:
    if not isinstance(v, list) or len(v) != n:
        raise ModelError(f"{path}: expected a {n}×{n} matrix ({n} rows of {n} numbers), got {_describe(v)}")
    return [_vector(row, n, f"{path}[{i}]") for i, row in enumerate(v)]


class _Loader:
    def __init__(self, data: dict, origin: str, system_class):
        top = _Table(data, "")
        if "model" in data and not {"system", "members"} & set(data):
            raise ModelError(f"{origin}: this is an optimal-control problem file (it names the model "
                             f"{data['model']!r}), not a model: use `ncgen optimize` or `ncgen mpc` "
                             "(in Python: ncgen.optim.load_problem(path, model))")
        for k in data:
            if k not in TOP_KEYS:
                raise ModelError(f"{k}: unknown top-level key{did_you_mean(k, TOP_KEYS)}; "
                                 f"expected tables: {', '.join(TOP_KEYS)}")
        sysd = _Table(top.get("system", {}), "system")
        name = _string(sysd.get("name", _default_name(origin)), "system.name")
        gravity = sysd.get("gravity", [0.0, 0.0, -9.81])
        if not isinstance(gravity, list) or len(gravity) not in (2, 3) or not all(_is_number(x) for x in gravity):
            raise ModelError(f"system.gravity: expected 2 (planar) or 3 numbers, got {_describe(gravity)}")
        sysd.finish(("name", "gravity"))
        self.s = system_class(name, gravity=[as_scalar(x, f"system.gravity[{i}]") for i, x in enumerate(gravity)])
        self.dim = self.s.dim
        self.base = Path(origin).parent if origin != "<toml text>" else None
        self._parameters(_Table(top.get("parameters", {}), "parameters"))
        self._inputs(_Table(top.get("inputs", {}), "inputs"))
        for i, m in enumerate(self._array(top.get("members", required=True), "members")):
            self._member(_Table(m, f"members[{i}]"))
        for i, j in enumerate(self._array(top.get("joints", []), "joints")):
            self._joint(_Table(j, f"joints[{i}]"))
        for i, f in enumerate(self._array(top.get("forces", []), "forces")):
            self._force(_Table(f, f"forces[{i}]"))
        for i, c in enumerate(self._array(top.get("contacts", []), "contacts")):
            self._contact(_Table(c, f"contacts[{i}]"))
        for i, r in enumerate(self._array(top.get("rolling", []), "rolling")):
            self._rolling(_Table(r, f"rolling[{i}]"))
        for key in ("initial", "initial_rates"):
            self._initial(top.get(key, {}), key)
        if "controller" in data:
            from ncgen.model.controllers import controller_from_dict
            self.s.controller = controller_from_dict(data["controller"], "controller")
        self.system = self.s

    def _initial(self, table, key):
        """``initial = {elbow = 0.3}``: joint positions (rad, m; a list for multi-coordinate
        joints) of the initial state, or coordinates as written (``"link.r_i.x" = 0.3``, m);
        ``initial_rates`` likewise for rates."""
        if not isinstance(table, dict):
            raise ModelError(f"{key}: expected a table {{joint = value}}, got {_describe(table)}")
        names = [j.name for j in self.s.joints]
        joints, coords = {}, {}
        for name, v in table.items():
            path = f"{key}.{name}"
            if "." in name:
                coords[name] = _number(v, path)
                self._coordinate_name(name, path)
            elif name not in names:
                raise ModelError(f"{path}: no joint named {name!r}{did_you_mean(name, names)} (a coordinate "
                                 "is named member.slot.axis, e.g. \"link.r_i.x\")")
            elif isinstance(v, list):
                joints[name] = [_number(x, f"{path}[{i}]") for i, x in enumerate(v)]
            else:
                joints[name] = _number(v, path)
        rates = key != "initial"
        (self.s.initial_joint_rates if rates else self.s.initial_joints).update(joints)
        (self.s.initial_coordinate_rates if rates else self.s.initial_coordinates).update(coords)

    def _coordinate_name(self, name: str, path: str) -> None:
        """Check ``member.slot.axis`` against the members as written."""
        parts = name.split(".")
        m = self.s.members.get(parts[0])
        if m is None:
            raise ModelError(f"{path}: no member named {parts[0]!r}{did_you_mean(parts[0], list(self.s.members))}")
        slots, axes = m.ctype.slots, "xyz"[:self.s.dim]
        if len(parts) != 3 or parts[1] not in slots or parts[2] not in axes:
            raise ModelError(f"{path}: expected a coordinate {m.name}.SLOT.AXIS with SLOT one of "
                             f"{', '.join(slots)} and AXIS one of {', '.join(axes)}, got {name!r}")

    @staticmethod
    def _array(v, path):
        if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
            raise ModelError(f"{path}: expected an array of tables ([[{path}]]), got {_describe(v)}")
        return v

    # ---------------------------------------------------------------- header
    def _parameters(self, t: _Table):
        for k, v in t.data.items():
            path = t.at(k)
            if _is_number(v):
                val = as_scalar(v, path)
            elif isinstance(v, list) and v and all(_is_number(x) for x in v):
                val = [as_scalar(x, f"{path}[{i}]") for i, x in enumerate(v)]
            else:
                raise ModelError(f"{path}: expected a number or a list of numbers, got {_describe(v)}")
            self._wrap(path, self.s.add_parameter, k, val)

    def _inputs(self, t: _Table):
        for k, v in t.data.items():
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ModelError(f"{t.at(k)}: expected the input's size (a positive integer), got {_describe(v)}")
            self._wrap(t.at(k), self.s.add_input, k, v)

    @staticmethod
    def _wrap(path, f, *args, **kw):
        try:
            return f(*args, **kw)
        except NcgenError as e:
            raise ModelError(f"{path}: {e}") from None

    # --------------------------------------------------------------- members
    def _member(self, t: _Table):
        name = _string(t.get("name", required=True), t.at("name"))
        kind = _string(t.get("kind", required=True), t.at("kind"))
        if kind not in MEMBER_FIELDS:
            raise ModelError(f"{t.at('kind')}: expected one of body, bar, point, got {kind!r}"
                             f"{did_you_mean(kind, MEMBER_FIELDS)}")
        markers = _Table(t.get("markers", {}), t.at("markers"))
        kw = self._fields(t, MEMBER_FIELDS[kind], ("name", "kind", "markers"))
        member = self._wrap(t.path, getattr(self.s, f"add_{kind}"), name, **kw)
        for k, v in markers.data.items():
            self._wrap(markers.at(k), member.add_marker, k, _vector(v, self.dim, markers.at(k)))

    # ------------------------------------------------------------ field tables
    def _fields(self, t: _Table, fields, other_keys=()) -> dict:
        """The keyword arguments of ``fields`` read from ``t`` (a missing optional key keeps
        the constructor's default); every other key of ``t`` must be in ``other_keys``."""
        kw = {}
        for f in fields:
            v = t.get(f.key, required=f.required)
            if v is None:
                if f.default is None:
                    continue
                value = f.default(self.dim) if callable(f.default) else f.default
            else:
                value = self.value(f.kind, v, t.at(f.key))
            if isinstance(f.arg, tuple):
                kw.update(zip(f.arg, value))
            else:
                kw[f.arg or f.key] = value
        t.finish((*other_keys, *(f.key for f in fields)))
        return kw

    def value(self, kind: str, v, path):
        """Value ``v`` at key ``path`` read as ``kind``: a reference to an element of the system
        (:data:`REFERENCE_KINDS`), an expression of t, parameters and inputs
        (:data:`EXPRESSION_KINDS`, ``value[n]``), else a plain value (:meth:`_plain_value`)."""
        if kind in REFERENCE_KINDS:
            return self._reference(kind, v, path)
        if kind in EXPRESSION_KINDS or kind.startswith("value["):
            return self._expression(kind, v, path)
        return self._plain_value(kind, v, path)

    def _plain_value(self, kind: str, v, path):
        """A number, string, vector, matrix, shape or index at ``path``, of the system's dimension."""
        d = self.dim
        if kind == "number":
            return _number(v, path)
        if kind == "string":
            return _string(v, path)
        if kind == "bool":
            return _bool(v, path)
        if kind == "vector":
            return _vector(v, d, path)
        if kind == "number or vector":
            return _vector(v, d, path) if isinstance(v, list) else _number(v, path)
        if kind == "two points":
            pair = _pair(v, path, "two points (one on each member)")
            return [_vector(x, d, f"{path}[{i}]") for i, x in enumerate(pair)]
        if kind == "inertia":
            return _matrix(v, 3, path) if d == 3 else _number(v, path)
        if kind == "rotation":
            return _number(v, path) if d == 2 and not isinstance(v, list) else _matrix(v, d, path)
        if kind == "angular velocity":
            return _vector(v, 3, path) if d == 3 else _number(v, path)
        if kind == "basis":
            if not isinstance(v, list):
                raise ModelError(f"{path}: expected a list of vectors, got {_describe(v)}")
            return [_vector(b, d, f"{path}[{i}]") for i, b in enumerate(v)]
        if kind == "shape":
            return shape_from_table(v, path, self.base)
        if kind == "joint steps":
            return self._joint_steps(v, path)
        if kind == "names":
            if not isinstance(v, list):
                raise ModelError(f"{path}: expected a list of names, got {_describe(v)}")
            return [_string(x, f"{path}[{i}]") for i, x in enumerate(v)]
        if kind == "index":
            if not isinstance(v, int) or isinstance(v, bool) or v < 0:
                raise ModelError(f"{path}: expected an index (an integer ≥ 0), got {_describe(v)}")
            return v
        if kind == "index or indices":
            return [self.value("index", x, f"{path}[{i}]") for i, x in enumerate(v)] if isinstance(v, list) \
                else self.value("index", v, path)
        if kind == "slot or axis":
            if not isinstance(v, (str, int)) or isinstance(v, bool):
                raise ModelError(f"{path}: expected a name or an index, got {_describe(v)}")
            return v
        raise AssertionError(f"unknown field kind {kind!r}")

    def _reference(self, kind: str, v, path):
        """Members, joints, nodes or points of the system named at ``path`` (:data:`REFERENCE_KINDS`)."""
        if kind == "share":
            st = _Table(v, path, "a table of slot = node")
            return {k: self._node(x, st.at(k)) for k, x in st.data.items()}
        if kind == "point or node":
            return self._point_or_node(v, path)
        if kind == "ends":
            return [self._point_or_node(e, f"{path}[{i}]") for i, e in enumerate(_pair(v, path, "two points or nodes"))]
        if kind == "member":
            return self._member_ref(v, path)
        if kind == "member, not the ground":
            return self._member_ref(v, path, ground=False)
        if kind == "two members":
            pair = _pair(v, path, "two member names (\"ground\" for the ground)")
            return [self._member_ref(m, f"{path}[{i}]") for i, m in enumerate(pair)]
        if kind == "member or members, not the ground":
            return [self._member_ref(x, f"{path}[{i}]", ground=False) for i, x in enumerate(v)] \
                if isinstance(v, list) else self._member_ref(v, path, ground=False)
        if kind == "joint":
            return self._joint_ref(v, path)
        return self._cable_path(v, path)                     # "cable path"

    def _expression(self, kind: str, v, path):
        """An expression (or a list of them) of t, parameters and, unless ``kind`` says otherwise,
        inputs, with the components ``kind`` asks for (:data:`EXPRESSION_KINDS`, ``value[n]``)."""
        d = self.dim
        if kind == "value or values":                # one value, or a list of them (one each)
            return [self._expr(x, f"{path}[{i}]") for i, x in enumerate(v)] if isinstance(v, list) \
                else self._expr(v, path)
        if kind == "values of parameters":           # a list of values of t and parameters
            if not isinstance(v, list) or not v:
                raise ModelError(f"{path}: expected a list of numbers or expression strings, got {_describe(v)}")
            return [self._expr(x, f"{path}[{i}]", inputs=False) for i, x in enumerate(v)]
        if kind == "value":                     # of t, parameters and inputs
            return self._expr(v, path)
        if kind.startswith("value["):           # value[n]: n components
            return self._expr(v, path, int(kind[6:-1]))
        if kind == "value of t and parameters":
            return self._expr(v, path, inputs=False)
        if kind == "force":
            return self._expr(v, path, d)
        if kind == "torque":
            return self._expr(v, path, 3 if d == 3 else 1)
        nq = self._scope(state=True).names["q"].numel()     # "generalized force"
        return self._expr(v, path, nq, state=True)

    def _cable_path(self, v, path) -> list:
        """``[(member, local point), …]``: a cable's path over two or more members."""
        if not isinstance(v, list) or len(v) < 2:
            raise ModelError(f"{path}: expected a list of [member, [local point]] pairs (two or more), "
                             f"got {_describe(v)}")
        out = []
        for i, item in enumerate(v):
            if not isinstance(item, list) or len(item) != 2:
                raise ModelError(f"{path}[{i}]: expected [member, [local point]], got {_describe(item)}")
            out.append((self._member_ref(item[0], f"{path}[{i}][0]"), _vector(item[1], self.dim, f"{path}[{i}][1]")))
        return out

    def _joint_steps(self, v, path) -> list:
        """``[(kind, at, axis), …]``: the hinge and slide steps of a JointSequence."""
        if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
            raise ModelError(f"{path}: expected a list of tables {{kind = \"hinge\" or \"slide\", at = [x, y, z], "
                             f"axis = [x, y, z]}}, got {_describe(v)}")
        out = []
        for i, step in enumerate(v):
            st = _Table(step, f"{path}[{i}]")
            kind = _string(st.get("kind", required=True), st.at("kind"))
            if kind not in ("hinge", "slide"):
                raise ModelError(f"{st.at('kind')}: expected \"hinge\" or \"slide\", got {kind!r}")
            out.append((kind, _vector(st.get("at", required=True), self.dim, st.at("at")),
                        _vector(st.get("axis", required=True), self.dim, st.at("axis"))))
            st.finish(STEP_KEYS)
        return out

    def _joint_ref(self, name, path):
        name = _string(name, path)
        joint = next((j for j in self.s.joints if j.name == name), None)
        if joint is None:
            known = [j.name for j in self.s.joints]
            raise ModelError(f"{path}: no joint named {name!r}{did_you_mean(name, known)} "
                             f"(joints: {', '.join(known) or 'none'})")
        return joint

    def _node(self, v, path) -> NodeRef:
        if isinstance(v, dict):
            nt = _Table(v, path)
            p = _vector(nt.get("ground", required=True), self.dim, nt.at("ground"))
            nt.finish(("ground",))
            return self.s.ground.point(p)
        if isinstance(v, str) and v.count(".") == 1:
            mname, slot = v.split(".")
            member = self._member_ref(mname, path, ground=False)
            return self._wrap(path, member.node, slot)
        raise ModelError(f"{path}: expected a node \"member.slot\" (e.g. \"crank.r_j\") or "
                         f"{{ground = [...]}}, got {_describe(v)}")

    def _point_or_node(self, v, path):
        if isinstance(v, list):
            return _vector(v, self.dim, path)
        return self._node(v, path)

    def _member_ref(self, name, path, ground=True):
        if not isinstance(name, str):
            raise ModelError(f"{path}: expected a member name, got {_describe(name)}")
        if ground and name == "ground":
            return self.s.ground
        if name not in self.s.members:
            known = list(self.s.members) + (["ground"] if ground else [])
            raise ModelError(f"{path}: no member named {name!r}{did_you_mean(name, known)} "
                             f"(members defined so far: {', '.join(known) or 'none'})")
        return self.s.members[name]

    # ---------------------------------------------------------------- values
    def _scope(self, *, inputs=True, state=False):
        pars = {n: s for n, (s, _) in self.s.parameters.items()}
        extra = {}
        if state:
            from ncgen.model.layout import make_layout
            nq = make_layout(self.dim, list(self.s.members.values())).nq
            extra = {"q": ca.SX.sym("q", nq), "v": ca.SX.sym("v", nq)}
        return scope(ca.SX.sym("t"), pars, dict(self.s.inputs) if inputs else {}, **extra)

    def _expr(self, v, path, n=1, sc=None, **scope_kw):
        """A number or expression string (n = 1), or n of them / one vector-valued string;
        strings are parsed (over the names of ``sc`` or ``self._scope(**scope_kw)``) to
        check them, and kept as text."""
        sc = sc or self._scope(**scope_kw)
        if n == 1 or isinstance(v, str):
            if _is_number(v) and n == 1:
                return as_scalar(v, path)
            if not isinstance(v, str):
                what = "a number or an expression string" if n == 1 else \
                    f"{n} numbers or expression strings, or one vector expression"
                raise ModelError(f"{path}: expected {what}, got {_describe(v)}")
            e = parse(v, sc.names, path)
            if e.numel() != n:
                raise ModelError(f"{path}: expected {n} component{'s' * (n != 1)}, {v!r} has {e.numel()}")
            return v
        if not isinstance(v, list) or len(v) != n:
            raise ModelError(f"{path}: expected {n} numbers or expression strings, got {_describe(v)}")
        return [self._expr(x, f"{path}[{i}]", sc=sc) for i, x in enumerate(v)]

    # ---------------------------------------------------------------- joints
    def _joint(self, t: _Table):
        typ = _string(t.get("type", required=True), t.at("type"))
        cls = JOINT_TYPES.get(typ)
        if cls is None:
            raise ModelError(f"{t.at('type')}: unknown joint type {typ!r}{did_you_mean(typ, JOINT_TYPES)}; "
                             f"expected one of {', '.join(JOINT_TYPES)}")
        steps = t.data.get("steps")
        n = len(steps) if isinstance(steps, list) else 1
        dynamics = t.get("dynamics")
        kw = self._fields(t, (Field("name", "string"), *joint_fields(cls, self.dim, n)), ("type", "dynamics"))
        joint = self._wrap(t.path, self.s.add_joint, cls(**kw))
        if dynamics is not None:
            self._joint_dynamics(joint, dynamics, t.at("dynamics"))

    def _joint_dynamics(self, joint, dynamics, path: str) -> None:
        """``dynamics``: a table of :func:`~ncgen.model.joint_dynamics.set_joint_dynamics`'s
        keys (one-coordinate joints), or one per coordinate (a JointSequence)."""
        laws = coordinate_laws(joint)
        many = isinstance(joint, JointSequence)
        if many and (not isinstance(dynamics, list) or len(dynamics) != len(laws)):
            raise ModelError(f"{path}: expected {len(laws)} tables (one per coordinate of {joint.label}), "
                             f"got {_describe(dynamics)}")
        if not many and joint.kind not in DYNAMICS_KINDS:
            raise ModelError(f"{path}: joint dynamics apply to {', '.join(DYNAMICS_KINDS)} joints and joint "
                             f"sequences, not {joint.kind}")
        for k, (law, values) in enumerate(zip(laws, dynamics if many else [dynamics])):
            at = f"{path}[{k}]" if many else path
            values = _Table(values, at).data
            for key, v in values.items():
                if key not in DYNAMICS_KEYS + LIMIT_KEYS:
                    raise ModelError(f"{at}.{key}: unknown key{did_you_mean(key, DYNAMICS_KEYS + LIMIT_KEYS)}; "
                                     f"expected one of: {', '.join(DYNAMICS_KEYS + LIMIT_KEYS)}")
                _number(v, f"{at}.{key}")
            self._wrap(at, law.set_dynamics, **values)

    # ---------------------------------------------------------------- forces
    def _force(self, t: _Table):
        typ = _string(t.get("type", required=True), t.at("type"))
        if typ not in FORCE_TYPES:
            raise ModelError(f"{t.at('type')}: unknown force type {typ!r}{did_you_mean(typ, FORCE_TYPES)}; "
                             f"expected one of {', '.join(FORCE_TYPES)}")
        kw = self._fields(t, (Field("name", "string"), *FORCE_FIELDS[typ]), ("type",))
        self._wrap(t.path, self.s.add_force, FORCE_TYPES[typ](**kw))

    def _contact(self, t: _Table):
        typ = _string(t.get("type", required=True), t.at("type"))
        if typ not in CONTACT_TYPES:
            raise ModelError(f"{t.at('type')}: unknown contact type {typ!r}{did_you_mean(typ, CONTACT_TYPES)}; "
                             f"expected one of {', '.join(CONTACT_TYPES)}")
        fields = (Field("name", "string"), *CONTACT_FIELDS[typ], *(Field(k, "number") for k in CONTACT_MATERIAL))
        kw = self._fields(t, fields, ("type",))
        self._wrap(t.path, self.s.add_contact, CONTACT_TYPES[typ](**kw))


    def _rolling(self, t: _Table):
        from ncgen.model.rolling import ROLLING_TYPES
        typ = _string(t.get("type", required=True), t.at("type"))
        if typ not in ROLLING_TYPES:
            raise ModelError(f"{t.at('type')}: unknown rolling element {typ!r}{did_you_mean(typ, ROLLING_TYPES)}; "
                             f"expected one of {', '.join(ROLLING_TYPES)}")
        kw = {}
        for key, n in ROLLING_FIELDS[typ]:
            v = t.get(key, required=key in ("body", "radius"))
            if v is not None:
                where = t.at(key)
                kw[key] = v if n is None else _string(v, where) if n == 0 else _number(v, where) if n == 1 \
                    else _vector(v, n, where)
        name = t.get("name")
        t.finish(("type", "name", *(k for k, _ in ROLLING_FIELDS[typ])))
        name = None if name is None else _string(name, t.at("name"))
        self._wrap(t.path, lambda: self.s.add_rolling(ROLLING_TYPES[typ](name=name, **kw)))


def _contact_entries(c) -> dict:
    spec = c.spec()
    out = {"type": spec.pop("type"), "name": spec.pop("name")}
    if isinstance(c, (SphereSphere, BoxBox, CapsuleCapsule)):
        out["between"] = [spec.pop("a"), spec.pop("b")]
    out.update({k: _plain(v) for k, v in spec.items()})
    return out


def _default_name(origin: str) -> str:
    return as_system_name(Path(origin).stem if origin != "<toml text>" else "model", "model")


# ======================================================================= writing
def system_to_toml(system) -> str:
    """TOML text for ``system`` (see the module docstring); values given as CasADi
    expressions or callables are printed as expression strings."""
    t = ca.SX.sym("t")
    pars = {n: s for n, (s, _) in system.parameters.items()}
    sc = scope(t, pars, dict(system.inputs))
    parts = [f"# ncgen model {system.name!r}: written by System.to_toml\n",
             toml_write.table("system", {"name": system.name, "gravity": system.gravity.tolist()})]
    if system.parameters:
        parts.append(toml_write.table("parameters", {
            n: (float(v[0]) if v.size == 1 else v.tolist()) for n, (_, v) in system.parameters.items()}))
    if system.inputs:
        parts.append(toml_write.table("inputs", {n: int(u.numel()) for n, u in system.inputs.items()}))
    for m in system.members.values():
        parts.append(toml_write.table("members", _member_entries(m), array=True))
    for j in system.joints:
        parts.append(toml_write.table("joints", _joint_entries(j, sc), array=True))
    for f in system.forces:
        parts.append(toml_write.table("forces", _force_entries(f, sc, system), array=True))
    for c in system.contacts:
        parts.append(toml_write.table("contacts", _contact_entries(c), array=True))
    for r in getattr(system, "rolling", ()):
        parts.append(toml_write.table("rolling", r.spec(), array=True))
    for key, values in (("initial", {**system.initial_joints, **system.initial_coordinates}),
                        ("initial_rates", {**system.initial_joint_rates, **system.initial_coordinate_rates})):
        if values:
            parts.append(toml_write.table(key, {n: _plain(v) for n, v in values.items()}))
    ctrl = getattr(system, "controller", None)
    if ctrl is not None:
        from ncgen.model.controllers import controller_to_dict
        parts.append(toml_write.table("controller", controller_to_dict(ctrl)))
    return "\n".join(parts)


def _plain(v):
    """Numbers, arrays and node references in TOML-writable form."""
    if isinstance(v, NodeRef):
        if v.member.is_ground:
            return {"ground": [float(x) for x in v.position]}
        return f"{v.member.name}.{v.member.ctype.slots[v.slot]}"
    if isinstance(v, (str, bool)):
        return v
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    a = np.asarray(v, dtype=float)
    return float(a) if a.ndim == 0 else a.tolist()


def _member_entries(m) -> dict:
    if not m.spec:
        raise ModelError(f"to_toml: member {m.name!r} was not created by System.add_body/add_bar/add_point")
    out = {"name": m.name, "kind": m.spec["kind"]}
    out.update({k: v.to_toml() if k == "shape" else _plain(v) for k, v in m.spec.items()
                if v is not None and k != "kind"})
    if m.markers:
        out["markers"] = {k: _plain(v) for k, v in m.markers.items()}
    return out


def _joint_entries(j, sc) -> dict:
    if j.kind not in JOINT_TYPES:
        raise ModelError(f"to_toml: {j.label}: a {j.kind} joint has no TOML form (joint types: "
                         f"{', '.join(JOINT_TYPES)})")
    out = {"type": j.kind, "name": j.name}
    if isinstance(j, CoordinateDriver):
        out["member"] = j.A.name
    elif not isinstance(j, Mimic):                   # a Mimic joins its follower's members
        out["between"] = [_member_name(m) for m in j.members()]
    for k, v in j.options.items():
        if v is None:
            continue
        if k in ("drive", "value", "effort"):
            out[k] = value_to_toml(v, sc, f"{j.label}: {k}")
        elif k in ("slot", "axis") and isinstance(j, CoordinateDriver):
            out[k] = v if isinstance(v, str) else int(v)
        elif isinstance(v, Joint):                   # a Mimic's leader and follower
            out[k] = v.name
        elif k == "steps" and isinstance(j, JointSequence):
            out[k] = [dict(zip(STEP_KEYS, (kind, _plain(at), _plain(axis)))) for kind, at, axis in v]
        else:
            out[k] = _plain(v)
    laws = [{**law.dynamics, **{k: v for k, v in law.limits.items() if k in LIMIT_KEYS and np.isfinite(v)}}
            for law in coordinate_laws(j)] if isinstance(j, JointSequence) or j.kind in DYNAMICS_KINDS else []
    if any(laws):
        out["dynamics"] = laws if isinstance(j, JointSequence) else laws[0]
    return out


def _force_entries(f, sc, system) -> dict:
    """The table of force ``f``: the keys of :data:`FORCE_FIELDS`, read back from its attributes."""
    if f.kind not in FORCE_FIELDS:
        raise ModelError(f"to_toml: {f.label} has no TOML form")
    out = {"type": f.kind, "name": f.name}
    for field in FORCE_FIELDS[f.kind]:
        value = tuple(getattr(f, a) for a in field.arg) if isinstance(field.arg, tuple) else getattr(f, field.key)
        if value is None and not field.required:
            continue
        if field.kind in ("member", "member, not the ground", "two members", "member or members, not the ground"):
            out[field.key] = [_member_name(m) for m in value] if isinstance(value, (tuple, list)) \
                else _member_name(value)
        elif field.kind == "joint":
            out[field.key] = value.name
        elif field.kind == "cable path":
            out[field.key] = [[_member_name(m), _plain(at)] for m, at in value]
        elif field.kind == "bool":
            out[field.key] = bool(value)
        elif field.kind in ("index", "index or indices"):
            out[field.key] = [int(x) for x in value] if isinstance(value, (tuple, list)) else int(value)
        elif field.kind in ("value or values", "values of parameters") and isinstance(value, (tuple, list, np.ndarray)):
            if any(x is None for x in value):
                raise ModelError(f"to_toml: {f.label}: {field.key}: a list with None (the angle from the shape) "
                                 f"has no TOML form; give every drum's or none")
            out[field.key] = [value_to_toml(x, sc, f"{f.label}: {field.key}[{i}]") for i, x in enumerate(value)]
        elif field.kind == "vector":
            out[field.key] = _plain(value)
        elif field.kind == "generalized force":
            out[field.key] = _generalized_force(value, sc, system, f"{f.label}: {field.key}")
        else:
            out[field.key] = value_to_toml(value, sc, f"{f.label}: {field.key}")
    return out


def _member_name(m) -> str:
    return "ground" if m.is_ground else m.name


def _generalized_force(value, sc, system, what: str):
    """A GeneralizedForce's value as an expression of t, q, v, inputs and parameters."""
    from ncgen.model.layout import make_layout
    nq = make_layout(system.dim, list(system.members.values())).nq
    q, v = ca.SX.sym("q", nq), ca.SX.sym("v", nq)
    st = scope(sc.t, {n: s for n, (s, _) in system.parameters.items()}, dict(system.inputs), q=q, v=v)
    u = ca.vertcat(*system.inputs.values()) if system.inputs else ca.SX(0, 1)
    p = ca.vertcat(*(s for s, _ in system.parameters.values())) if system.parameters else ca.SX(0, 1)
    return value_to_toml(value, st, what, call=lambda fn: fn(sc.t, q, v, u, p))
