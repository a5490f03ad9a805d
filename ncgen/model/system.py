"""``System``: the user-facing builder of a multibody model.

>>> import ncgen as nc
>>> s = nc.System("pendulum", gravity=(0, 0, -9.81))
>>> b = s.add_bar("b", coords="rr", mass=1.0, ends=[s.ground.point((0, 0, 0)), (1, 0, 0)])
>>> model = s.build()

The dimension follows ``len(gravity)`` (2 = planar).  Positions, axes and velocities are
given in world coordinates in the initial configuration; SI units throughout.
"""
from __future__ import annotations

import copy
import os
import warnings
from pathlib import Path

import numpy as np
import casadi as ca

from ncgen.errors import ModelError, NcgenError
from ncgen.model.expressions import check_name
from ncgen.model.members import Ground, Member, NodeRef, model_name
from ncgen.reproducible import frame_along, norm
from ncgen.symbolic.coordinates import coordinate_type
from ncgen.symbolic.member import RigidMember
from ncgen.validation import as_scalar, as_vector, rotation, system_name

DEFAULT_GRAVITY = (0.0, 0.0, -9.81)
#: What a model file's import attaches to a system (``from_mjcf``, ``from_urdf``) that TOML does
#: not hold; pickles (and the store of read files) carry it (:meth:`System.description`).
IMPORTED = ("actuation", "actuator_gear", "actuators", "tendons", "mjcf_ignored", "mjcf_unsupported",
            "skipped_collisions")


class System:
    """A multibody system under construction; :meth:`build` turns it into a :class:`Model`."""

    def __init__(self, name: str, gravity=DEFAULT_GRAVITY):
        try:
            system_name(name, "system name")
        except NcgenError as e:
            raise ModelError(str(e)) from None
        g = np.asarray(gravity, dtype=float).reshape(-1) if np.ndim(gravity) == 1 else None
        if g is None or g.size not in (2, 3):
            raise ModelError(f"gravity: expected 2 (planar) or 3 numbers, got {gravity!r}")
        self.name = name
        self.dim = int(g.size)
        self.gravity = as_vector(g, self.dim, "gravity")
        self.ground = Ground(self.dim)
        self.members: dict[str, Member] = {}
        self.joints: list = []
        self.forces: list = []
        self.contacts: list = []
        #: Nonholonomic elements (``add_rolling``: rolling discs and balls, knife edges).
        self.rolling: list = []
        self.inputs: dict[str, ca.SX] = {}
        self.parameters: dict[str, tuple[ca.SX, np.ndarray]] = {}
        #: Named frames ``{name: (member name or "ground", R_local, p_local)}`` (URDF links).
        self.frames: dict[str, tuple] = {}
        #: Visual geometry (URDF ``<visual>``), plain dicts in member frames.
        self.visuals: list[dict] = []
        #: A compiled controller (:mod:`ncgen.model.controllers`; TOML ``[controller]``) that
        #: ``ncgen simulate`` runs; the Python API passes controllers as ``simulate(u=...)``.
        self.controller = None
        #: Joint-space initial state ``{joint: position}`` / ``{joint: rate}`` applied by
        #: :meth:`build` (TOML ``initial = {elbow = 0.3}``, ``initial_rates``); joints not
        #: named keep the coordinates and rates of the members' given poses and twists.
        self.initial_joints: dict = {}
        self.initial_joint_rates: dict = {}
        #: Initial coordinates ``{"link.r_i.x": value}`` / rates (m, m/s) applied by :meth:`build`
        #: after the joint-space state, the others assembled (``nc.assemble(values=...)``); a
        #: coordinate as written resolves also when coordinate sharing re-based its member.
        self.initial_coordinates: dict = {}
        self.initial_coordinate_rates: dict = {}

    # ------------------------------------------------------------- members
    def _new_name(self, name: str, what: str) -> str:
        model_name(name, f"{what} name")
        if name in self.members or name == "ground" or name in self.inputs or name in self.parameters:
            raise ModelError(f"{what} {name!r}: the name is already used in system {self.name!r}")
        if what in ("input", "parameter"):
            check_name(name, what)
        return name

    def _ctype(self, coords, kind: str, name: str):
        ct = coordinate_type(coords, self.dim)
        if ct.kind != kind:
            raise ModelError(f"{kind} {name!r}: coords={coords!r} is a {ct.kind} type in {self.dim}D")
        return ct

    def _omega(self, w, name):
        if self.dim == 3:
            return as_vector(w, 3, f"{name}: angular_velocity")
        return as_scalar(w, f"{name}: angular_velocity (a scalar in a planar system)")

    def _add(self, member: Member) -> Member:
        self._check_shared(member)
        self.members[member.name] = member
        return member

    def _check_shared(self, member: Member):
        for slot, ref in member.shared.items():
            if not isinstance(ref, NodeRef):
                raise ModelError(f"{member.name}: shared slot {slot}: expected a node reference "
                                 f"(other.node(...), bar.end(i) or system.ground.point(...)), got {ref!r}")
            if ref.member.is_ground and ref.member.dim != self.dim:
                raise ModelError(f"{member.name}: shared slot {member.ctype.slots[slot]}: a ground point of a "
                                 f"{ref.member.dim}D system in the {self.dim}D system {self.name!r}")
            if not ref.member.is_ground and self.members.get(ref.member.name) is not ref.member:
                raise ModelError(f"{member.name}: shares a point with {ref.member.name!r}, "
                                 f"which is not a member of system {self.name!r}")
            here = member.slot_position(slot)
            gap = float(np.linalg.norm(here - np.asarray(ref.position)))
            if gap > 1e-9 * max(1.0, float(np.linalg.norm(here))):
                raise ModelError(
                    f"{member.name}: basic point {member.ctype.slots[slot]} is at {here.tolist()} but the "
                    f"shared {ref.label} is at {list(ref.position)}: {gap:.3g} m apart")

    def add_body(self, name: str, coords: str = "ruvw", *, mass: float, inertia,
                 position=None, rotation=None, velocity=None, angular_velocity=None,
                 basis=None, share: dict | None = None, shape=None) -> Member:
        """A rigid body.  ``inertia``: 3×3 tensor about the centre of mass in body axes (a
        scalar in 2D); ``position``: centre of mass; ``rotation``: body→world (2D: an angle
        or 2×2 matrix); ``angular_velocity`` in world axes; ``basis``: the slot values in
        the body frame, seed order (default: ``r̄_i = 0`` and unit axes); ``share``: maps
        slot names (``"r_i"``, ``"r_j"``, ...) to nodes of other members or the ground;
        ``shape``: what viewers draw (``nc.Box(a, b, c)``, ... :mod:`ncgen.model.shapes`;
        default: the box of the same inertia)."""
        name = self._new_name(name, "body")
        ct = self._ctype(coords, "body", name)
        d = self.dim
        local = RigidMember.body(ct, mass, inertia, basis=basis)
        R = np.eye(d) if rotation is None else _rotation(rotation, d, name)
        p = np.zeros(d) if position is None else as_vector(position, d, f"{name}: position")
        v = np.zeros(d) if velocity is None else as_vector(velocity, d, f"{name}: velocity")
        w = self._omega(np.zeros(3) if d == 3 and angular_velocity is None else
                        (0.0 if angular_velocity is None else angular_velocity), name)
        shared = {}
        for key, ref in (share or {}).items():
            shared[_slot_index(ct, key, name)] = ref
        member = Member(name, local, R, p, w, v, shared)
        member.spec = dict(kind="body", coords=ct.name, mass=mass, inertia=inertia, position=position,
                           rotation=rotation, velocity=velocity, angular_velocity=angular_velocity,
                           basis=basis, share={ct.slots[k]: ref for k, ref in shared.items()} or None)
        return self._add(member.set_shape(shape))

    def add_bar(self, name: str, coords: str = "rr", *, mass: float, ends, inertia=None, com=None,
                velocity=None, angular_velocity=None, shape=None) -> Member:
        """A rigid bar between ``ends`` (two world points, or nodes to share: ``other.end(1)``,
        ``system.ground.point(p)``).  ``inertia``: transverse moment about the centre of
        mass (default ``m L²/12``); ``com``: distance of the centre of mass from the first
        end (default: the middle); ``velocity`` of the centre of mass; the component of
        ``angular_velocity`` along the bar is ignored; ``shape``: what viewers draw (default:
        a cylinder between the ends)."""
        name = self._new_name(name, "bar")
        ct = self._ctype(coords, "bar", name)
        d = self.dim
        if not isinstance(ends, (list, tuple)) or len(ends) != 2:
            raise ModelError(f"bar {name!r}: ends: expected two points, got {ends!r}")
        pts, shared = [], {}
        for i, e in enumerate(ends):
            if isinstance(e, NodeRef):
                pts.append(np.asarray(e.position))
                if i == 1 and ct.name != "rr":
                    raise ModelError(f"bar {name!r}: the second end of an '{ct.name}' bar is not a basic "
                                     "point and cannot be shared; use coords='rr' or a Spherical joint")
                shared[i] = e
            else:
                pts.append(as_vector(e, d, f"bar {name!r}: ends[{i}]"))
        axis = pts[1] - pts[0]
        L = norm(axis)
        if L <= 0:
            raise ModelError(f"bar {name!r}: its two ends coincide at {pts[0].tolist()}")
        local = RigidMember.bar(ct, mass, L, inertia=inertia, com=com)
        R = _frame_along(axis / L, local)
        a = -local.rbar_i[0]
        p = pts[0] + a * axis / L
        v = np.zeros(d) if velocity is None else as_vector(velocity, d, f"{name}: velocity")
        w = self._omega(np.zeros(3) if d == 3 and angular_velocity is None else
                        (0.0 if angular_velocity is None else angular_velocity), name)
        member = Member(name, local, R, p, w, v, shared)
        member.spec = dict(kind="bar", coords=ct.name, mass=mass, ends=list(ends), inertia=inertia, com=com,
                           velocity=velocity, angular_velocity=angular_velocity)
        return self._add(member.set_shape(shape))

    def add_point(self, name: str, *, mass: float, position, velocity=None, shape=None) -> Member:
        """A point mass; ``position`` may be a node of another member (``bar.end(1)``), which
        adds the mass there without new coordinates; ``shape``: what viewers draw (default: a
        small sphere)."""
        name = self._new_name(name, "point")
        ct = coordinate_type("r", self.dim)
        d = self.dim
        shared = {}
        if isinstance(position, NodeRef):
            shared[0] = position
            position = position.position
        p = as_vector(position, d, f"point {name!r}: position")
        v = np.zeros(d) if velocity is None else as_vector(velocity, d, f"{name}: velocity")
        member = Member(name, RigidMember.point(ct, mass), None, p, None, v, shared)
        member.spec = dict(kind="point", mass=mass, position=shared.get(0, position), velocity=velocity)
        return self._add(member.set_shape(shape))

    # ----------------------------------------------------- joints and forces
    def add_joint(self, joint):
        """Add a joint (``nc.Spherical``, ``nc.Revolute``, ...); returns it."""
        from ncgen.model.joints import Joint
        if not isinstance(joint, Joint):
            raise ModelError(f"add_joint: expected a joint (nc.Spherical, nc.Revolute, ...), got {joint!r}")
        joint.attach(self, index=len(self.joints))
        self.joints.append(joint)
        return joint

    def add_force(self, force):
        """Add a force element (``nc.Spring``, ``nc.PointForce``, ``nc.Torque``, ...); returns it."""
        from ncgen.model.forces import Force
        if not isinstance(force, Force):
            raise ModelError(f"add_force: expected a force (nc.Spring, nc.PointForce, ...), got {force!r}")
        force.attach(self, index=len(self.forces))
        self.forces.append(force)
        return force

    def add_contact(self, contact):
        """Add a unilateral contact (``nc.SpherePlane``, ``nc.SphereSphere``; see
        :mod:`ncgen.model.contacts`); returns it."""
        from ncgen.model.contacts import Contact
        if not isinstance(contact, Contact):
            raise ModelError(f"add_contact: expected a contact (nc.SpherePlane, nc.SphereSphere), got {contact!r}")
        contact.attach(self, index=len(self.contacts))
        self.contacts.append(contact)
        return contact

    def add_rolling(self, element):
        """Add a nonholonomic element (``nc.RollingDisc``, ``nc.RollingSphere``,
        ``nc.KnifeEdge``; :mod:`ncgen.model.rolling`) on one of the system's bodies; returns
        it.  The built model carries it (``model.rolling``) and ``nc.simulate`` keeps its
        velocity constraints (``method="rolling"``, docs/rolling.md)."""
        from ncgen.model.rolling import ROLLING_TYPES
        if not isinstance(element, tuple(ROLLING_TYPES.values())):
            raise ModelError(f"add_rolling: expected a nonholonomic element ({', '.join(ROLLING_TYPES)}), "
                             f"got {element!r}")
        if self.dim != 3:
            raise ModelError(f"add_rolling: {element!r}: rolling elements need a 3D system; "
                             f"system {self.name!r} is planar")
        member = self.members.get(element.body)
        if member is None or member.kind != "body":
            found = "no member of that name" if member is None else f"a {member.kind}"
            bodies = ", ".join(m.name for m in self.members.values() if m.kind == "body") or "none"
            raise ModelError(f"add_rolling: {element!r}: body: expected a body of system {self.name!r} "
                             f"(bodies: {bodies}), found {found}")
        if any(e.name == element.name for e in self.rolling):
            raise ModelError(f"add_rolling: name {element.name!r} is already used by another rolling element; "
                             f"give name=...")
        self.rolling.append(element)
        return element

    def add_input(self, name: str, size: int = 1) -> ca.SX:
        """A control input: a symbol that stays symbolic in every assembled function."""
        name = self._new_name(name, "input")
        if not isinstance(size, int) or size < 1:
            raise ModelError(f"input {name!r}: size: expected a positive integer, got {size!r}")
        u = ca.SX.sym(name, size)
        self.inputs[name] = u
        return u

    def add_parameter(self, name: str, value) -> ca.SX:
        """A parameter with a default ``value`` (scalar or vector): symbolic in every
        assembled and generated function, so one kernel serves many values."""
        name = self._new_name(name, "parameter")
        given = [value] if np.ndim(value) == 0 else value
        try:
            val = as_vector(given, int(np.size(given)), f"parameter {name!r}")
        except NcgenError as e:
            raise ModelError(str(e)) from None
        if val.size == 0:
            raise ModelError(f"parameter {name!r}: expected at least one number, got {value!r}")
        p = ca.SX.sym(name, val.size)
        self.parameters[name] = (p, val)
        return p

    def member(self, name: str) -> Member:
        try:
            return self.members[name]
        except KeyError:
            known = ", ".join(self.members) or "none"
            raise ModelError(f"no member named {name!r} in system {self.name!r} (members: {known})") from None

    # ---------------------------------------------------------------- build
    def build(self, **options):
        """Validate and assemble: returns a :class:`~ncgen.model.model.Model`.

        Options (:func:`ncgen.assembly.build.build_model`): ``redundant`` ("drop", "error",
        "keep"), ``contacts`` ("smooth": compliant contact forces in F, for IDAS and optimal
        control; "nonsmooth": unilateral constraints for the compiled stepper; see
        docs/contact.md), ``tolerance`` (largest relative correction of the initial state),
        ``assemble=True`` with ``fix=[...]`` (the initial poses are a guess to assemble by
        Newton, keeping the named coordinates), ``baumgarte``, ``t0``, ``share`` (default
        True: joints that shared coordinates express are eliminated, see
        :mod:`ncgen.model.sharing`; ``model.sharing`` reports it).

        A system built before with the same content and options (in this or an earlier
        process) is read from the store of built models instead (:mod:`ncgen.codegen.model_cache`;
        ``NCGEN_MODEL_CACHE=0`` turns it off); a system holding a Python function or a SymPy
        expression is always built."""
        from ncgen.codegen.model_cache import build_system
        return build_system(self, **options)

    # ----------------------------------------------------------------- TOML
    @classmethod
    def from_toml(cls, source) -> "System":
        """A system from a TOML model file (a path) or TOML text; see docs/model-format.md."""
        from ncgen.model.toml_io import system_from_toml
        return _read_through_store(cls, "toml", source, lambda: system_from_toml(source, cls))

    @classmethod
    def from_urdf(cls, source, floating_base: bool = False, gravity=DEFAULT_GRAVITY, name=None,
                  collisions=False) -> "System":
        """A robot from a URDF file (a path) or URDF text: links become bodies (fixed joints
        merge them), movable joints are actuated by the input ``tau`` (one component per
        joint, ``model.joint_names`` order); ``floating_base=True`` adds a free joint
        ``root``; ``collisions=True`` (or a dict of contact keywords) turns the moving links'
        ``<collision>`` boxes, cylinders and spheres into contacts with the ground plane z = 0
        (``{"self": True, "exclude": [(link, link), ...]}``: between links too).  See
        :mod:`ncgen.model.urdf`."""
        from ncgen.model.urdf import system_from_urdf
        options = dict(floating_base=floating_base, gravity=gravity, name=name, collisions=collisions)
        return _read_through_store(cls, "urdf", source, lambda: system_from_urdf(source, cls, **options), **options)

    @classmethod
    def from_mjcf(cls, source, name=None, contacts=False) -> "System":
        """A MuJoCo model from an MJCF file (a path) or MJCF text: bodies, inertials,
        hinge/slide/ball/free joints (hinges and slides actuated by the input ``tau``, one
        component each, ``model.joint_names`` order), joint damping, armature, friction,
        range and stiffness, actuators as ``system.actuation`` (MuJoCo's force laws and clamps); what cannot be
        represented is named in one :class:`~ncgen.model.mjcf.MjcfWarning`.  See
        :mod:`ncgen.model.mjcf`.  ``contacts=True`` (or a dict of contact keywords: ``mu``,
        ``stiffness``, ...) makes the geoms contact shapes, paired as MuJoCo filters them
        (:mod:`ncgen.model.mjcf_contacts`; off by default).  A file read before (its bytes and
        those of its includes unchanged) comes from the store of built models without parsing."""
        from ncgen.model.mjcf import system_from_mjcf
        from ncgen.model.mjcf_xml import included_files
        path = _file(source)
        includes = [] if path is None else [(f, _digest(f)) for f in included_files(path)]
        return _read_through_store(cls, "mjcf", source,
                                   lambda: system_from_mjcf(source, cls, name=name, contacts=contacts),
                                   name=name, includes=includes, contacts=contacts)

    def to_toml(self) -> str:
        """The system as TOML text that :meth:`from_toml` reads back."""
        from ncgen.model.toml_io import system_to_toml
        return system_to_toml(self)

    def description(self) -> tuple:
        """``(toml, frames, visuals, joint_laws, imported)``: what the system is, as plain data
        (its TOML text, and the named frames, visual geometry and joint dynamics and limits, e.g.
        of a URDF or an MJCF file, that TOML does not hold: ``joint_laws = {joint: [(limits,
        dynamics) of each coordinate]}``, one pair for a one-coordinate joint, one per
        coordinate of a :class:`~ncgen.model.joints.JointSequence`; ``imported``: what a model
        file's import attached, :data:`IMPORTED` of the system and ``mjcf_*`` of each
        coordinate); :func:`from_description` makes the same system again.  Pickling a system
        sends this."""
        try:
            text = self.to_toml()
        except (NcgenError, TypeError, ValueError) as e:
            raise TypeError(f"system {self.name!r} cannot be pickled: its description is written as TOML, "
                            f"and that failed: {e}") from None
        frames = {k: (mem, np.array(R), np.array(p)) for k, (mem, R, p) in self.frames.items()}
        from ncgen.model.joint_dynamics import coordinate_laws
        laws = {j.name: [(dict(law.limits), dict(law.dynamics)) for law in coordinate_laws(j)] for j in self.joints
                if any(law.limits or law.dynamics for law in coordinate_laws(j))}
        imported = {"system": {k: copy.deepcopy(self.__dict__[k]) for k in IMPORTED if k in self.__dict__},
                    "coordinates": {j.name: [{k: v for k, v in vars(law).items() if k.startswith("mjcf_")}
                                             for law in coordinate_laws(j)] for j in self.joints}}
        return text, frames, [dict(v) for v in self.visuals], laws, imported

    def __reduce__(self):
        from ncgen.version import __version__
        return rebuilt_system, (__version__, self.description())

    def __deepcopy__(self, memo) -> "System":
        """A member-by-member copy (as without :meth:`__reduce__`, which pickling uses)."""
        new = object.__new__(type(self))
        memo[id(self)] = new
        new.__dict__.update(copy.deepcopy(self.__dict__, memo))
        return new

    @classmethod
    def rebuilt_model(cls, *pickled):
        """The model of a pickle (:meth:`ncgen.model.model.Model.__reduce__`: ``description``,
        build ``options``, ``expected_hash``, the ncgen version that pickled it): the one of this
        process with that content hash, else built from ``description`` with ``options`` and
        checked against ``expected_hash``; a pickle of another ncgen version is refused."""
        from ncgen.model.model import keep_rebuilt, known_model
        description, options, expected_hash = _same_version(pickled, 3, "model")
        model = known_model(expected_hash)
        if model is None:
            with warnings.catch_warnings():   # said when it was first built (e.g. dropped constraints)
                warnings.simplefilter("ignore")
                model = keep_rebuilt(_read_pickled(description).build(**options), expected_hash)
        return model

    def __repr__(self) -> str:
        return (f"System({self.name!r}, dim={self.dim}, members={len(self.members)}, "
                f"joints={len(self.joints)}, forces={len(self.forces)}"
                + (f", contacts={len(self.contacts)}" if self.contacts else "")
                + (f", rolling={len(self.rolling)})" if self.rolling else ")"))


def _same_version(pickled: tuple, n: int, what: str) -> tuple:
    """The ``n`` fields of a pickle written as ``(*fields, version)``, if ``version`` is this
    ncgen's; else a :class:`ModelError` saying to rebuild."""
    from ncgen.version import __version__
    version = pickled[-1] if len(pickled) == n + 1 else None
    if version != __version__:
        said = f"version {version}" if isinstance(version, str) else "an older version"
        raise ModelError(f"this {what} was pickled by another ncgen version ({said}; this is {__version__}): "
                         f"rebuild the {what} (System.from_toml / System.build) in this process instead")
    return pickled[:n]


def _read_pickled(description) -> System:
    """``from_description(*description)``, a description it cannot read named as a pickle of
    another ncgen version."""
    try:
        return from_description(*description)
    except (TypeError, KeyError, AttributeError, IndexError) as e:
        raise ModelError(f"the pickled system cannot be read ({type(e).__name__}: {e}): pickled by another ncgen "
                         "version? Rebuild the model in this process") from None


def rebuilt_system(version: str, description: tuple) -> System:
    """The system of a pickle (:meth:`System.__reduce__`), if this ncgen version wrote it."""
    (description,) = _same_version((description, version), 1, "system")
    return _read_pickled(description)


def from_description(toml: str, frames: dict, visuals: list, joint_laws: dict, imported: dict) -> System:
    """The system of :meth:`System.description` (how a pickled system is read back)."""
    from ncgen.model.joint_dynamics import coordinate_laws
    system = System.from_toml(toml)
    system.frames = {k: (mem, np.array(R), np.array(p)) for k, (mem, R, p) in frames.items()}
    system.visuals = [dict(v) for v in visuals]
    for joint in system.joints:
        for law, (limits, dynamics) in zip(coordinate_laws(joint), joint_laws.get(joint.name, ())):
            law.limits, law.dynamics = dict(limits), dict(dynamics)
        for law, attributes in zip(coordinate_laws(joint), imported["coordinates"].get(joint.name, ())):
            law.__dict__.update(attributes)
    system.__dict__.update(copy.deepcopy(imported["system"]))
    return system


def _read_through_store(cls, kind: str, source, load, **options) -> System:
    """``load()``, or the system the store of built models keeps for the same file and
    ``options`` (:func:`ncgen.codegen.model_cache.cached_system`: a file read before is not
    parsed again, and its members need no SymPy); text, and subclasses of System, are read."""
    from ncgen.codegen import model_cache

    path = _file(source)
    if cls is not System or path is None or not model_cache.enabled():
        return load()
    return model_cache.cached_system(model_cache.source_key(kind, path, **options), load)


def _digest(path: str) -> str | None:
    """sha256 of a file's bytes, or None when it cannot be read."""
    import hashlib
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return None


def _file(source) -> Path | None:
    """``source`` as the path of an existing file, or None (model text, or no such file)."""
    if not isinstance(source, (str, os.PathLike)):
        return None
    text = os.fspath(source)
    if not isinstance(text, str) or "\n" in text or "<" in text:
        return None
    try:
        return Path(text) if Path(text).is_file() else None
    except (OSError, ValueError):
        return None


def _rotation(R, d, name):
    return rotation(R, d, f"{name}: rotation")


def _slot_index(ct, key, name) -> int:
    if isinstance(key, str):
        if key not in ct.slots:
            raise ModelError(f"body {name!r}: share: no slot {key!r}; a {ct.name} body has {', '.join(ct.slots)}")
        key = ct.slots.index(key)
    if key not in ct.point_slots:
        raise ModelError(f"body {name!r}: share: slot {ct.slots[key]} is a vector, not a basic point")
    return key


def _frame_along(e1: np.ndarray, local: RigidMember) -> np.ndarray:
    """The bar frame whose x̄ is ``e1``, completed exactly as the derivation completes it."""
    q = local.q_from_pose(frame_along(e1), np.zeros(len(e1)))
    R, _ = local.pose(q)
    return R
