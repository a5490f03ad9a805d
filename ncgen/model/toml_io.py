"""Model files: :class:`~ncgen.model.system.System` from and to TOML (docs/model-format.md).

Layout of a file (every table optional except ``members``)::

    [system]      name, gravity
    [parameters]  name = number or list of numbers      (symbolic in every function)
    [inputs]      name = size                           (control inputs)
    [[members]]   name, kind = "body" | "bar" | "point", and the arguments of
                  System.add_body / add_bar / add_point, plus markers = {name = [x, y, z]}
    [[joints]]    type = "Revolute", ..., name, between = ["ground", "crank"]
                  (CoordinateDriver: member = "crank"), and the joint's keywords
    [[forces]]    type = "Spring", ..., name, and the force's arguments
    [[contacts]]  type = "SpherePlane" (sphere, at, radius, plane = "ground", point, normal)
                  or "SphereSphere" (between = ["a", "b"], at_a, radius_a, at_b, radius_b),
                  with mu, restitution, stiffness, damping, exponent, slip_velocity, name

Shared basic points are written ``"crank.r_j"`` (slot ``r_j`` of member ``crank``) or
``{ground = [x, y, z]}``.  Values that may vary are numbers or expression strings
(:mod:`ncgen.model.expressions`).  Every error names the key path and what was expected,
e.g. ``joints[2].axis: expected 3 numbers, got 2``; unknown keys are errors.
"""
from __future__ import annotations

import inspect
import tomllib
from pathlib import Path

import casadi as ca
import numpy as np

from ncgen.errors import NcgenError
from ncgen.model import toml_write
from ncgen.model.expressions import did_you_mean, parse, scope, value_to_toml
from ncgen.model.contacts import CONTACT_TYPES, SpherePlane, SphereSphere
from ncgen.model.forces import FORCE_TYPES, GeneralizedForce, PointForce, Spring, Torque, TorsionalSpring
from ncgen.model.joints import JOINT_TYPES, CoordinateDriver, Distance
from ncgen.model.members import ModelError, NodeRef

TOP_KEYS = ("system", "parameters", "inputs", "members", "joints", "forces", "contacts")
#: Material keys every contact table may have (:class:`~ncgen.model.contacts.Contact`).
CONTACT_MATERIAL = ("mu", "restitution", "stiffness", "damping", "exponent", "slip_velocity")


# ======================================================================= reading
def system_from_toml(source):
    """A :class:`~ncgen.model.system.System` from a path or TOML text."""
    text, origin = _source_text(source)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ModelError(f"{origin}: invalid TOML: {e}") from None
    try:
        return _Loader(data, origin).system
    except ModelError:
        raise
    except NcgenError as e:
        raise ModelError(str(e)) from None


def _source_text(source) -> tuple[str, str]:
    if isinstance(source, Path) or (isinstance(source, str) and "\n" not in source
                                    and (source.endswith(".toml") or Path(source).is_file())):
        path = Path(source)
        try:
            return path.read_text(encoding="utf-8"), str(path)
        except OSError as e:
            raise ModelError(f"cannot read model file {str(path)!r}: {e.strerror}") from None
    if not isinstance(source, str):
        raise ModelError(f"from_toml: expected a path or TOML text, got {type(source).__name__}")
    return source, "<toml text>"


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
    return float(v)


def _string(v, path) -> str:
    if not isinstance(v, str):
        raise ModelError(f"{path}: expected a string, got {_describe(v)}")
    return v


def _bool(v, path) -> bool:
    if not isinstance(v, bool):
        raise ModelError(f"{path}: expected true or false, got {_describe(v)}")
    return v


def _vector(v, n, path) -> list[float]:
    if not isinstance(v, list) or len(v) != n or not all(_is_number(x) for x in v):
        raise ModelError(f"{path}: expected {n} numbers, got {_describe(v)}")
    return [float(x) for x in v]


def _matrix(v, n, path) -> list[list[float]]:
    if not isinstance(v, list) or len(v) != n:
        raise ModelError(f"{path}: expected a {n}×{n} matrix ({n} rows of {n} numbers), got {_describe(v)}")
    return [_vector(row, n, f"{path}[{i}]") for i, row in enumerate(v)]


class _Loader:
    def __init__(self, data: dict, origin: str):
        from ncgen.model.system import System
        top = _Table(data, "")
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
        self.s = System(name, gravity=[float(x) for x in gravity])
        self.dim = self.s.dim
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
        self.system = self.s

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
                val = float(v)
            elif isinstance(v, list) and v and all(_is_number(x) for x in v):
                val = [float(x) for x in v]
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
    MEMBER_KEYS = {
        "body": ("name", "kind", "coords", "mass", "inertia", "position", "rotation", "velocity",
                 "angular_velocity", "basis", "share", "markers"),
        "bar": ("name", "kind", "coords", "mass", "ends", "inertia", "com", "velocity",
                "angular_velocity", "markers"),
        "point": ("name", "kind", "mass", "position", "velocity", "markers"),
    }

    def _member(self, t: _Table):
        d = self.dim
        name = _string(t.get("name", required=True), t.at("name"))
        kind = _string(t.get("kind", required=True), t.at("kind"))
        if kind not in self.MEMBER_KEYS:
            raise ModelError(f"{t.at('kind')}: expected one of body, bar, point, got {kind!r}"
                             f"{did_you_mean(kind, self.MEMBER_KEYS)}")
        kw = {"mass": _number(t.get("mass", required=True), t.at("mass"))}
        if t.get("velocity") is not None:
            kw["velocity"] = _vector(t.data["velocity"], d, t.at("velocity"))
        if kind != "point":
            kw["coords"] = _string(t.get("coords", "ruvw"[:d + 1] if kind == "body" else "rr"), t.at("coords"))
            w = t.get("angular_velocity")
            if w is not None:
                kw["angular_velocity"] = _vector(w, 3, t.at("angular_velocity")) if d == 3 else \
                    _number(w, t.at("angular_velocity"))
        if kind == "body":
            self._body_args(t, kw)
            add = self.s.add_body
        elif kind == "bar":
            ends = t.get("ends", required=True)
            if not isinstance(ends, list) or len(ends) != 2:
                raise ModelError(f"{t.at('ends')}: expected two points or nodes, got {_describe(ends)}")
            kw["ends"] = [self._point_or_node(e, f"{t.at('ends')}[{i}]") for i, e in enumerate(ends)]
            for k in ("inertia", "com"):
                if t.get(k) is not None:
                    kw[k] = _number(t.data[k], t.at(k))
            add = self.s.add_bar
        else:
            kw["position"] = self._point_or_node(t.get("position", required=True), t.at("position"))
            add = self.s.add_point
        markers = _Table(t.get("markers", {}), t.at("markers"))
        t.finish(self.MEMBER_KEYS[kind])
        member = self._wrap(t.path, add, name, **kw)
        for k, v in markers.data.items():
            self._wrap(markers.at(k), member.add_marker, k, _vector(v, d, markers.at(k)))

    def _body_args(self, t: _Table, kw: dict):
        d = self.dim
        inertia = t.get("inertia", required=True)
        kw["inertia"] = _matrix(inertia, 3, t.at("inertia")) if d == 3 else _number(inertia, t.at("inertia"))
        if t.get("position") is not None:
            kw["position"] = _vector(t.data["position"], d, t.at("position"))
        R = t.get("rotation")
        if R is not None:
            kw["rotation"] = _number(R, t.at("rotation")) if d == 2 and not isinstance(R, list) else \
                _matrix(R, d, t.at("rotation"))
        basis = t.get("basis")
        if basis is not None:
            if not isinstance(basis, list):
                raise ModelError(f"{t.at('basis')}: expected a list of vectors, got {_describe(basis)}")
            kw["basis"] = [_vector(b, d, f"{t.at('basis')}[{i}]") for i, b in enumerate(basis)]
        share = t.get("share")
        if share is not None:
            st = _Table(share, t.at("share"), "a table of slot = node")
            kw["share"] = {k: self._node(v, st.at(k)) for k, v in st.data.items()}

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
            from ncgen.assembly.layout import make_layout
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
                return float(v)
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
        name = t.get("name")
        kw = {"name": _string(name, t.at("name")) if name is not None else None}
        keys = ["type", "name"]
        if cls is CoordinateDriver:
            keys += ["member", "slot", "axis", "value"]
            args = [self._member_ref(t.get("member", required=True), t.at("member"), ground=False)]
            for k in ("slot", "axis"):
                v = t.get(k, required=True)
                if not isinstance(v, (str, int)) or isinstance(v, bool):
                    raise ModelError(f"{t.at(k)}: expected a name or an index, got {_describe(v)}")
                args.append(v)
            if t.get("value") is not None:
                kw["value"] = self._expr(t.data["value"], t.at("value"), inputs=False)
        else:
            between = t.get("between", required=True)
            if not isinstance(between, list) or len(between) != 2:
                raise ModelError(f"{t.at('between')}: expected two member names (\"ground\" for the "
                                 f"ground), got {_describe(between)}")
            args = [self._member_ref(m, f"{t.at('between')}[{i}]") for i, m in enumerate(between)]
            keys.append("between")
            for k, p in inspect.signature(cls).parameters.items():
                if p.kind != p.KEYWORD_ONLY or k == "name":
                    continue
                keys.append(k)
                v = t.get(k, required=p.default is p.empty)
                if v is not None:
                    kw[k] = self._joint_value(cls, k, v, t.at(k))
        t.finish(keys)
        self._wrap(t.path, self.s.add_joint, cls(*args, **kw))

    def _joint_value(self, cls, k, v, path):
        d = self.dim
        if k == "drive":
            return self._expr(v, path, inputs=False)
        if cls is Distance and k == "at":
            if not isinstance(v, list) or len(v) != 2:
                raise ModelError(f"{path}: expected two points (one on each member), got {_describe(v)}")
            return [_vector(x, d, f"{path}[{i}]") for i, x in enumerate(v)]
        return _vector(v, d, path)

    # ---------------------------------------------------------------- forces
    def _force(self, t: _Table):
        d = self.dim
        typ = _string(t.get("type", required=True), t.at("type"))
        if typ not in FORCE_TYPES:
            raise ModelError(f"{t.at('type')}: unknown force type {typ!r}{did_you_mean(typ, FORCE_TYPES)}; "
                             f"expected one of {', '.join(FORCE_TYPES)}")
        name = t.get("name")
        kw = {"name": _string(name, t.at("name")) if name is not None else None}

        def member(k="member"):
            return self._member_ref(t.get(k, required=True), t.at(k))

        def expr(k, n=1, default=None, **sk):
            v = t.get(k, required=default is None)
            return default if v is None else self._expr(v, t.at(k), n, **sk)

        if typ == "PointForce":
            keys = ("member", "at", "force")
            f = PointForce(member(), _vector(t.get("at", required=True), d, t.at("at")), expr("force", d), **kw)
        elif typ == "Torque":
            keys = ("member", "torque")
            f = Torque(member(), expr("torque", 3 if d == 3 else 1), **kw)
        elif typ == "Spring":
            keys = ("between", "at_a", "at_b", "k", "rest_length", "damping", "cable")
            between = t.get("between", required=True)
            if not isinstance(between, list) or len(between) != 2:
                raise ModelError(f"{t.at('between')}: expected two member names, got {_describe(between)}")
            a, b = (self._member_ref(m, f"{t.at('between')}[{i}]") for i, m in enumerate(between))
            f = Spring(a, _vector(t.get("at_a", required=True), d, t.at("at_a")),
                       b, _vector(t.get("at_b", required=True), d, t.at("at_b")),
                       k=expr("k"), rest_length=expr("rest_length", default=0.0),
                       damping=expr("damping", default=0.0),
                       cable=_bool(t.get("cable", False), t.at("cable")), **kw)
        elif typ == "TorsionalSpring":
            keys = ("joint", "k", "damping", "rest_angle")
            jname = _string(t.get("joint", required=True), t.at("joint"))
            joint = next((j for j in self.s.joints if j.name == jname), None)
            if joint is None:
                known = [j.name for j in self.s.joints]
                raise ModelError(f"{t.at('joint')}: no joint named {jname!r}{did_you_mean(jname, known)} "
                                 f"(joints: {', '.join(known) or 'none'})")
            f = TorsionalSpring(joint, k=expr("k"), damping=expr("damping", default=0.0),
                                rest_angle=expr("rest_angle", default=0.0, inputs=False), **kw)
        else:
            keys = ("value",)
            v = t.get("value", required=True)
            nq = self._scope(state=True).names["q"].numel()
            f = GeneralizedForce(self._expr(v, t.at("value"), nq, state=True), **kw)
        t.finish(("type", "name", *keys))
        self._wrap(t.path, self.s.add_force, f)

    def _contact(self, t: _Table):
        _contact_table(self, t)


def _contact_table(loader, t: _Table):
    """A contact from its table (see the module docstring)."""
    d = loader.dim
    typ = _string(t.get("type", required=True), t.at("type"))
    if typ not in CONTACT_TYPES:
        raise ModelError(f"{t.at('type')}: unknown contact type {typ!r}{did_you_mean(typ, CONTACT_TYPES)}; "
                         f"expected one of {', '.join(CONTACT_TYPES)}")
    kw = {k: _number(t.get(k), t.at(k)) for k in CONTACT_MATERIAL if t.get(k) is not None}
    if t.get("name") is not None:
        kw["name"] = _string(t.get("name"), t.at("name"))

    def vec(k):
        v = t.get(k)
        return None if v is None else _vector(v, d, t.at(k))

    def num(k):
        return _number(t.get(k, 0.0), t.at(k))

    if typ == "SpherePlane":
        keys = ("sphere", "at", "radius", "plane", "point", "normal")
        sphere = loader._member_ref(t.get("sphere", required=True), t.at("sphere"))
        plane = loader._member_ref(t.get("plane", "ground"), t.at("plane"))
        c = SpherePlane(sphere, vec("at"), num("radius"), plane=plane, point=vec("point"), normal=vec("normal"), **kw)
    else:
        keys = ("between", "at_a", "radius_a", "at_b", "radius_b")
        between = t.get("between", required=True)
        if not isinstance(between, list) or len(between) != 2:
            raise ModelError(f"{t.at('between')}: expected two member names, got {_describe(between)}")
        a, b = (loader._member_ref(m, f"{t.at('between')}[{i}]") for i, m in enumerate(between))
        c = SphereSphere(a, vec("at_a"), num("radius_a"), b, vec("at_b"), num("radius_b"), **kw)
    t.finish(("type", "name", *CONTACT_MATERIAL, *keys))
    loader._wrap(t.path, loader.s.add_contact, c)


def _contact_entries(c) -> dict:
    spec = c.spec()
    out = {"type": spec.pop("type"), "name": spec.pop("name")}
    if isinstance(c, SphereSphere):
        out["between"] = [spec.pop("a"), spec.pop("b")]
    out.update({k: _plain(v) for k, v in spec.items()})
    return out


def _default_name(origin: str) -> str:
    stem = Path(origin).stem if origin != "<toml text>" else "model"
    name = "".join(c if c.isalnum() or c == "_" else "_" for c in stem)
    return name if name.isidentifier() else "model"


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
    return "\n".join(parts)


def _plain(v):
    """Numbers, arrays and node references in TOML-writable form."""
    if isinstance(v, NodeRef):
        if v.member.is_ground:
            return {"ground": [float(x) for x in v.position]}
        return f"{v.member.name}.{v.member.ctype.slots[v.slot]}"
    if isinstance(v, str):
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
    out.update({k: _plain(v) for k, v in m.spec.items() if v is not None and k != "kind"})
    if m.markers:
        out["markers"] = {k: _plain(v) for k, v in m.markers.items()}
    return out


def _joint_entries(j, sc) -> dict:
    out = {"type": j.kind, "name": j.name}
    if isinstance(j, CoordinateDriver):
        out["member"] = j.A.name
    else:
        out["between"] = ["ground" if m.is_ground else m.name for m in j.members()]
    for k, v in j.options.items():
        if v is None:
            continue
        if k in ("drive", "value"):
            out[k] = value_to_toml(v, sc, f"{j.label}: {k}")
        elif k in ("slot", "axis") and isinstance(j, CoordinateDriver):
            out[k] = v if isinstance(v, str) else int(v)
        else:
            out[k] = _plain(v)
    return out


def _force_entries(f, sc, system) -> dict:
    out = {"type": f.kind, "name": f.name}

    def val(v, what):
        return value_to_toml(v, sc, f"{f.label}: {what}")

    if isinstance(f, PointForce):
        out.update(member=f.member.name, at=_plain(f.at), force=val(f.force, "force"))
    elif isinstance(f, Torque):
        out.update(member=f.member.name, torque=val(f.torque, "torque"))
    elif isinstance(f, Spring):
        out.update(between=["ground" if m.is_ground else m.name for m in (f.a, f.b)], at_a=_plain(f.at_a),
                   at_b=_plain(f.at_b), k=val(f.k, "k"), rest_length=val(f.rest_length, "rest_length"),
                   damping=val(f.damping, "damping"), cable=f.cable)
    elif isinstance(f, TorsionalSpring):
        out.update(joint=f.joint.name, k=val(f.k, "k"), damping=val(f.damping, "damping"),
                   rest_angle=val(f.rest_angle, "rest_angle"))
    elif isinstance(f, GeneralizedForce):
        from ncgen.assembly.layout import make_layout
        nq = make_layout(system.dim, list(system.members.values())).nq
        q, v = ca.SX.sym("q", nq), ca.SX.sym("v", nq)
        st = scope(sc.t, {n: s for n, (s, _) in system.parameters.items()}, dict(system.inputs), q=q, v=v)
        u = ca.vertcat(*system.inputs.values()) if system.inputs else ca.SX(0, 1)
        p = ca.vertcat(*(s for s, _ in system.parameters.values())) if system.parameters else ca.SX(0, 1)
        out["value"] = value_to_toml(f.value, st, f"{f.label}: value", call=lambda fn: fn(sc.t, q, v, u, p))
    else:
        raise ModelError(f"to_toml: {f.label} has no TOML form")
    return out
