"""``Model``: a built system — dimensions, names, consistent initial state, the constant mass
matrix and the whole-system CasADi functions (see :mod:`ncgen.assembly.functions`).

A model is constant (Pinocchio's model/data split): it owns a private copy of the system's
description as built (``model.members``, ``model.joints``, ``model.forces``,
``model.contact_elements``: after coordinate sharing, the members the layout indexes; the
system as written is kept only to pickle it, ``model.recipe``), so editing the
:class:`~ncgen.model.system.System` afterwards does not reach it, and its attributes and
arrays cannot be reassigned or written.  What a run needs beyond it (loaded libraries, work
arrays) lives in its data, ``model.data`` (:mod:`ncgen.model.data`), outside its state.

Numeric conveniences (``model.phi(q)``, ``model.A(q)``, ...) evaluate those functions with
the default parameters and zero inputs unless told otherwise and return NumPy arrays.
"""
from __future__ import annotations

import hashlib
import weakref
from collections import OrderedDict
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from ncgen.errors import ModelError
from ncgen.model.data import ModelData
from ncgen.model.function_set import FunctionSet
from ncgen.validation import as_vector


class ReadOnlyList(list):
    """A list that refuses changes (a model's name lists: compares equal to plain lists)."""

    def _refuse(self, *args, **kwargs):
        raise TypeError("a Model's lists are read-only; copy with list(...) to change one")

    append = extend = insert = remove = pop = clear = sort = reverse = _refuse
    __setitem__ = __delitem__ = __iadd__ = __imul__ = _refuse


def _frozen(value):
    """``value`` made read-only: arrays lose their write flag, lists refuse changes."""
    if isinstance(value, np.ndarray):
        value = value.view()
        value.flags.writeable = False
        return value
    if isinstance(value, list):
        return ReadOnlyList(value)
    return value


def component_names(names, sizes) -> list[str]:
    """One name per value of inputs or parameters: ``k`` for a scalar, ``f[0]``, ``f[1]``, ...
    for a vector ``f`` (the order of ``u`` and ``p``)."""
    return [n if s == 1 else f"{n}[{i}]" for n, s in zip(names, sizes) for i in range(s)]


@dataclass(frozen=True)
class Dynamics:
    """What a model computes, as the builder makes it: the whole-system ``functions`` (name ->
    CasADi function, or a :class:`~ncgen.model.function_set.FunctionSet` making each on first
    use), the constant mass matrix ``M`` and its ``factor``, the ``potential`` terms, the
    springs and cables as plain data (:class:`ncgen.assembly.springs.SpringTable`) and the
    joint-space form (:class:`ncgen.assembly.joint_space.JointSpace`)."""

    functions: object
    M: np.ndarray
    factor: object
    potential: object
    springs: object = None
    joint_space: object = None


@dataclass(frozen=True)
class Constraints:
    """The constraints Φ as built: ``labels`` of its rows, the Baumgarte coefficients
    ``(α, β)`` (1/s), the ``redundant`` rows found at the initial configuration and whether
    they were ``dropped``."""

    labels: list
    baumgarte: tuple
    redundant: list = ()
    dropped: bool = False


@dataclass(frozen=True)
class Parameters:
    """The default parameter vector ``p0`` and the ``limits``: values that must stay >= 0 for
    any parameter vector (:class:`ncgen.assembly.limits.Limits`, or None)."""

    p0: np.ndarray
    limits: object = None


@dataclass(frozen=True)
class Contacts:
    """The point contacts as plain data (:mod:`ncgen.model.contacts`), in order, and the
    contact ``law``: ``"smooth"`` (compliant forces in F) or ``"nonsmooth"`` (the compiled
    stepper's impacts)."""

    specs: tuple = ()
    law: str = "smooth"


@dataclass(frozen=True)
class Origin:
    """How a model was built: the ``sharing`` plan of ``build(share=True)``, the ``unshared``
    form and the ``recipe`` (see :class:`Model`'s attributes of those names)."""

    sharing: object = None
    unshared: object = None
    recipe: object = None


class Model:
    """A validated, assembled, constant system (create it with ``System.build()``)."""

    def __init__(self, *, description, layout, dynamics: Dynamics, constraints: Constraints, parameters: Parameters,
                 state, t0, contacts: Contacts = Contacts(), origin: Origin = Origin()):
        system = description
        self.layout = layout
        self._describe(system)
        #: name -> CasADi function, each made on first access (:class:`~ncgen.model.function_set.FunctionSet`)
        self.functions = dynamics.functions if isinstance(dynamics.functions, FunctionSet) \
            else MappingProxyType(dict(dynamics.functions))
        self.M = dynamics.M
        self.mass_factor = dynamics.factor
        self.potential_terms = dynamics.potential
        self.constraint_names = list(constraints.labels)
        self.p0 = np.asarray(parameters.p0, dtype=float)
        self.q0, self.v0 = state.q0, state.v0
        self.lam0, self.a0 = state.lam0, state.a0
        self.initial_correction = (state.dq, state.dv)
        self.initial_residual = (state.phi_given, state.velocity_given)
        self.baumgarte = constraints.baumgarte
        self.redundant = list(constraints.redundant)
        self.redundant_dropped = constraints.dropped and bool(constraints.redundant)
        self.t0 = t0
        #: the springs and cables as plain data (:class:`ncgen.assembly.springs.SpringTable`)
        self.springs = dynamics.springs
        #: values that must stay >= 0 for any parameter vector (ncgen.assembly.limits.Limits)
        self.limits = parameters.limits
        self.joint_space = dynamics.joint_space
        #: Plain-data descriptions of the contacts (:mod:`ncgen.model.contacts`), in order.
        self.contacts = [dict(c) for c in contacts.specs]
        self.contact_names = [c["name"] for c in self.contacts]
        #: "smooth" (compliant forces in F) or "nonsmooth" (the compiled stepper's impacts).
        self.contact_model = contacts.law
        #: :class:`~ncgen.model.sharing.SharingPlan` of ``build(share=True)`` (None with share=False).
        self.sharing = origin.sharing
        #: how to build the same system with ``share=False`` (reactions of the eliminated joints;
        #: :class:`ncgen.assembly.unshared.UnsharedForm`; the built model is kept in ``data``), or None
        self.unshared = origin.unshared
        #: ``(system as written, build options)`` it was built from: what a pickled model sends
        #: (see :meth:`__reduce__`); None for a model made otherwise, which cannot be pickled.
        #: Its members are not the built ones (coordinate sharing re-bases bodies): read those
        #: from ``members``, ``joints``, ``forces``, ``contact_elements``
        self.recipe = origin.recipe
        for key, value in vars(self).items():
            object.__setattr__(self, key, _frozen(value))
        object.__setattr__(self, "_data", ModelData())
        object.__setattr__(self, "_frozen", True)

    def _describe(self, system) -> None:
        """The model's own copy of the system's description: members, joints, forces, names,
        frames, visuals, controller, contact and rolling elements."""
        self.members = MappingProxyType(dict(system.members))
        self.joints = tuple(system.joints)
        self.forces = tuple(system.forces)
        self.name = system.name
        self.dim = system.dim
        self.coordinate_names = self.layout.coordinate_names
        self.input_names = list(system.inputs)
        self.input_sizes = [int(s.shape[0]) for s in system.inputs.values()]
        self.parameter_names = list(system.parameters)
        self.parameter_sizes = [int(v.size) for _, v in system.parameters.values()]
        self.member_names = list(system.members)
        self.marker_names = [f"{m.name}.{k}" for m in system.members.values() for k in m.markers]
        self.gravity = system.gravity.copy()
        self.frames = MappingProxyType({k: (mem, np.array(R), np.array(pos)) for k, (mem, R, pos) in system.frames.items()})
        self.visuals = [dict(v) for v in system.visuals]
        #: the system's compiled controller (TOML ``[controller]``) or None
        self.controller = getattr(system, "controller", None)
        #: The contact elements as built (:mod:`ncgen.model.contacts`), in order: their members
        #: are ``model.members`` (re-based by coordinate sharing, as the layout indexes them),
        #: what the element kernels and their broad phase read (:mod:`ncgen.assembly.pair_kernels`).
        self.contact_elements = tuple(getattr(system, "contacts", ()))
        #: The nonholonomic elements (:mod:`ncgen.model.rolling`), in order: velocity
        #: constraints beside ``phi``, kept by ``nc.simulate(method="rolling")``.
        self.rolling = tuple(getattr(system, "rolling", ()))

    def __setattr__(self, key, value):
        if getattr(self, "_frozen", False):
            raise AttributeError(f"Model {self.name!r} is constant: build a new one with System.build() "
                                 f"(cannot set {key!r})")
        object.__setattr__(self, key, value)

    def __delattr__(self, key):
        raise AttributeError(f"Model {self.name!r} is constant (cannot delete {key!r})")

    # ------------------------------------------------------------ identity and pickling
    @property
    def content_hash(self) -> str:
        """sha256 of what the model computes: every CasADi function (serialised), the mass
        matrix, the initial state, the parameters and the names; equal for two builds of the
        same description."""
        data = self.data
        if data.content_hash is None:
            data.content_hash = content_hash(self)
        return data.content_hash

    def __copy__(self) -> "Model":
        return self              # constant: copies share it (pickling goes by description instead)

    def __deepcopy__(self, memo) -> "Model":
        return self

    def __reduce__(self):
        """Pickled by description: the system's TOML text (with frames and visuals), the
        build options and :attr:`content_hash`; unpickling rebuilds the model once per
        process (:meth:`ncgen.model.system.System.rebuilt_model`) and checks the hash.  Run-time caches (loaded
        libraries, work arrays) never travel: a worker loads the compiled library from the
        compile cache (``ncgen.codegen.compile_cache``), which the same content hits."""
        if self.recipe is None:
            raise TypeError(f"model {self.name!r} cannot be pickled: it was not made by System.build()")
        data = self.data
        if data.description is None:
            data.description = self.recipe[0].description()
        _known[self.content_hash] = self
        from ncgen.version import __version__
        return type(self.recipe[0]).rebuilt_model, (data.description, self.recipe[1], self.content_hash, __version__)

    @property
    def data(self) -> ModelData:
        """The model's run-time data: compiled libraries, loaded kernels, functions built on
        demand (:class:`~ncgen.model.data.ModelData`); not part of the constant model."""
        return self._data

    def frame_pose(self, name: str, q) -> tuple[np.ndarray, np.ndarray]:
        """World ``(R, p)`` of the named frame (``model.frames``, e.g. a URDF link) at ``q``."""
        if name not in self.frames:
            raise KeyError(f"no frame named {name!r}; frames: {', '.join(self.frames) or 'none'}")
        member, R_loc, p_loc = self.frames[name]
        if member == "ground":
            return R_loc.copy(), p_loc.copy()
        R, pos = self.poses(q)
        i = self.member_names.index(member)
        return R[i] @ R_loc, R[i] @ p_loc + pos[i]

    # ------------------------------------------------------------ joint space
    @property
    def joint_names(self) -> list[str]:
        """The joints that have coordinates, in model order (a floating base ``root`` first).
        A joint to a 3D bar has only what is measurable (no spin about the bar's axis: a ball
        joint gives the bar's swing, two angles); joints with nothing defined (Spherical,
        Universal or Planar between two 3D bars or with a point member) are left out, and
        ``model.joint_space.skipped`` says why (:mod:`ncgen.assembly.joint_coordinates`)."""
        return list(self.joint_space.joint_names)

    @property
    def actuated_joints(self) -> list[str]:
        """The joints with an actuator (``effort=``), in ``joint_names`` order."""
        return list(self.joint_space.actuated)

    @property
    def joint_limits(self) -> dict[str, dict]:
        """``{joint: {"lower", "upper", "velocity", "effort"}}`` as given (URDF ``<limit>``)."""
        return {k: dict(v) for k, v in self.joint_space.limits.items() if v}

    def to_joint_space(self, q, v=None, a=None, *, t=None, p=None):
        """Joint positions ``qj`` (and rates ``vj``, accelerations ``aj`` when ``v``, ``a``
        are given), concatenated in ``joint_names`` order (see
        :mod:`ncgen.assembly.joint_coordinates` for each joint's coordinates); a state off
        the constraints (at time ``t``, parameters ``p``) is refused."""
        return self.joint_space.to_joint_space(self, q, v, a, t=t, p=p)

    def from_joint_space(self, qj, vj=None, *, t=None, p=None):
        """``(q, v)`` with the given joint positions and rates (vectors in ``joint_names``
        order, or dicts ``{joint: value}``; closed loops: the independent joints only)."""
        return self.joint_space.from_joint_space(self, qj, vj, t=t, p=p)

    def coordinate(self, name: str) -> tuple[np.ndarray, float]:
        """``(s, c)`` with the coordinate ``name`` equal to ``s · q + c`` (m) and its rate to
        ``s · v``: one of :attr:`coordinate_names` (``s`` a unit row), or a coordinate as
        written (``"upper.r_i.x"``) that coordinate sharing re-based or merged (a row of the
        affine map to the ``share=False`` coordinates, :mod:`ncgen.assembly.unshared`; its
        first use builds that form, ~0.2 s).  Raises :class:`ModelError` naming what exists."""
        if name in self.coordinate_names:
            s = np.zeros(self.nq)
            s[self.coordinate_names.index(name)] = 1.0
            return s, 0.0
        if self.unshared is not None and isinstance(name, str) and name.split(".")[0] in self.member_names:
            written = self.unshared.model(self)
            if name in written.coordinate_names:
                S, c = self.unshared.coordinate_map(self)
                i = written.coordinate_names.index(name)
                return S[i].copy(), float(c[i])
        from ncgen.model.expressions import did_you_mean
        shown = ", ".join(self.coordinate_names[:12]) + (", ..." if self.nq > 12 else "")
        aside = "; coordinates as written before coordinate sharing resolve too" if self.unshared else ""
        raise ModelError(f"model {self.name!r}: no coordinate named {name!r}"
                         f"{did_you_mean(str(name), self.coordinate_names)} (coordinates: {shown}{aside})")

    # ------------------------------------------------------------ dimensions
    @property
    def nq(self) -> int:
        return self.layout.nq

    @property
    def nc(self) -> int:
        return len(self.constraint_names)

    @property
    def nu(self) -> int:
        return int(sum(self.input_sizes))

    @property
    def np(self) -> int:
        return int(self.p0.size)

    @property
    def nk(self) -> int:
        """Number of contacts."""
        return len(self.contacts)

    @property
    def rank(self) -> int:
        """Rank of A at the initial configuration, by the manifold's one rank rule
        (:func:`ncgen.assembly.manifold.numerical_rank`): the model's own constraints (with
        rolling elements, ``nc.dof_report`` counts their heights and rolling rows too)."""
        from ncgen.assembly.manifold import numerical_rank
        return numerical_rank(self.A(self.q0))

    @property
    def dof(self) -> int:
        """Degrees of freedom of the model's own constraints: nq − rank A(q0) (with rolling
        elements, ``nc.dof_report`` gives the configuration's and the velocities')."""
        return self.nq - self.rank

    @property
    def Minv(self) -> np.ndarray:
        """Dense M⁻¹ (constant; for small models and checks).  Raises ModelError for a
        singular M (a flat body; see :mod:`ncgen.assembly.mass`)."""
        return self.mass_factor.solve_numeric(np.eye(self.nq))

    # ------------------------------------------------------------- numerics
    def _args(self, q=None, v=None, t=None, u=None, p=None):
        out = {}
        if q is not None:
            out["q"] = as_vector(q, self.nq, "q")
        if v is not None:
            out["v"] = as_vector(v, self.nq, "v")
        out["t"] = self.t0 if t is None else float(t)
        out["u"] = np.zeros(self.nu) if u is None else as_vector(u, self.nu, "u")
        out["p"] = self.p0 if p is None else as_vector(p, self.np, "p")
        return out

    def _call(self, name, **kw):
        f = self.functions.get(name)
        if f is None:
            why = (" (it has no contacts)" if name in ("gap", "contact_jacobian", "contact_force") else "")
            raise ModelError(f"model {self.name!r} has no function {name!r}{why}; its functions: "
                             f"{', '.join(sorted(self.functions))}")
        a = self._args(**kw)
        res = f.call({k: a[k] for k in f.name_in()})
        outs = [np.array(res[k]) for k in f.name_out()]
        outs = [o.reshape(-1) if o.ndim == 2 and o.shape[1] == 1 else o for o in outs]
        return outs[0] if len(outs) == 1 else tuple(outs)

    def phi(self, q, t=None, p=None) -> np.ndarray:
        return self._call("phi", q=q, t=t, p=p)

    def A(self, q, t=None, p=None) -> np.ndarray:
        return self._call("A", q=q, t=t, p=p)

    def gamma(self, q, v, t=None, p=None) -> np.ndarray:
        return self._call("gamma", q=q, v=v, t=t, p=p)

    def F(self, q, v, t=None, u=None, p=None) -> np.ndarray:
        return self._call("F", q=q, v=v, t=t, u=u, p=p)

    def accel(self, q, v, t=None, u=None, p=None):
        """``(a, λ)`` from the KKT system (Baumgarte terms included)."""
        return self._call("accel", q=q, v=v, t=t, u=u, p=p)

    def energy(self, q, v, t=None, p=None):
        """``(T, V)``: kinetic and potential energy (J)."""
        T, V = self._call("energy", q=q, v=v, t=t, p=p)
        return float(np.asarray(T).item()), float(np.asarray(V).item())

    def gap(self, q, p=None) -> np.ndarray:
        """Contact gaps ``g(q)`` (m, positive apart), one per contact."""
        return np.atleast_1d(self._call("gap", q=q, p=p))

    def contact_jacobian(self, q, p=None):
        """``(W_N, W_T)``: normal (nk × nq) and tangential (nk·(dim−1) × nq) contact Jacobians."""
        WN, WT = self._call("contact_jacobian", q=q, p=p)
        return np.atleast_2d(WN).reshape(self.nk, self.nq), np.atleast_2d(WT).reshape(-1, self.nq)

    def markers(self, q, v=None):
        """``(r, ṙ)``: world positions (m) and velocities (m/s) of the named markers, each
        ``dim × n_markers`` (columns in ``marker_names`` order, also for one marker)."""
        v = np.zeros(self.nq) if v is None else v
        r, rdot = self._call("markers", q=q, v=v)
        shape = (self.dim, len(self.marker_names))
        return np.reshape(r, shape), np.reshape(rdot, shape)

    def poses(self, q):
        """``(R, p)`` of every member: ``R`` is ``n × dim × dim``, ``p`` is ``n × dim``."""
        R, p = self._call("poses", q=q)
        n, d = len(self.member_names), self.dim
        R = np.asarray(R).reshape(d, n, d).transpose(1, 0, 2) if n else np.zeros((0, d, d))
        return R, np.asarray(p).reshape(d, n).T

    def parameters(self, **values) -> np.ndarray:
        """The parameter vector with some entries replaced by name: ``model.parameters(k=50)``."""
        p = self.p0.copy()
        offsets = np.cumsum([0, *self.parameter_sizes])
        for name, val in values.items():
            if name not in self.parameter_names:
                raise KeyError(f"unknown parameter {name!r}; parameters: {', '.join(self.parameter_names)}")
            i = self.parameter_names.index(name)
            size = self.parameter_sizes[i]
            given = [val] if np.ndim(val) == 0 else val
            p[offsets[i]:offsets[i + 1]] = as_vector(given, size, f"parameter {name!r}")
        if self.limits is not None:
            self.limits.check(p, where=f"model {self.name!r}: ")
        return p

    def member(self, name: str):
        """The member ``name`` as it was when the model was built."""
        try:
            return self.members[name]
        except KeyError:
            known = ", ".join(self.members) or "none"
            raise ModelError(f"no member named {name!r} in model {self.name!r} (members: {known})") from None

    def _repr_html_(self) -> str:
        """Jupyter's display: a table of the model's sizes (:mod:`ncgen.viz.notebook`)."""
        from ncgen.viz.notebook import model_table
        return model_table(self)

    def to_mjcf(self, path) -> None:
        """Write this tree model as a MuJoCo MJCF file (atomically); see
        :mod:`ncgen.model.mjcf_export`."""
        from ncgen.model.mjcf_export import write_mjcf
        write_mjcf(self, path)

    def __repr__(self) -> str:
        rolling = f", rolling elements={len(self.rolling)} (nc.dof_report)" if self.rolling else ""
        return (f"<Model {self.name!r}: dim={self.dim}, nq={self.nq}, nc={self.nc}, dof={self.dof}, "
                f"nu={self.nu}, np={self.np}{rolling}>")


#: Models of this process by content hash: those pickled here (weakly) and those rebuilt
#: from a description (the last :data:`KEEP_REBUILT`, strongly, so that a worker keeps its
#: models between tasks).
_known: "weakref.WeakValueDictionary[str, Model]" = weakref.WeakValueDictionary()
_rebuilt: "OrderedDict[str, Model]" = OrderedDict()
KEEP_REBUILT = 8


def content_hash(model: Model) -> str:
    """See :attr:`Model.content_hash`."""
    h = hashlib.sha256()
    for name in sorted(model.functions):
        h.update(name.encode())
        h.update(model.functions[name].serialize().encode())
    for a in (model.M, model.q0, model.v0, model.p0, model.gravity):
        h.update(np.ascontiguousarray(a, dtype=float).tobytes())
    names = [model.name, model.coordinate_names, model.constraint_names, model.input_names, model.input_sizes,
             model.parameter_names, model.parameter_sizes, model.marker_names, model.contact_model, model.t0,
             list(model.baumgarte), model.member_names, sorted(model.frames), model.joint_names,
             model.joint_limits]
    if model.rolling:
        names.append([e.spec() for e in model.rolling])
    h.update(repr(names).encode())
    return h.hexdigest()


def model_state(model: Model) -> dict:
    """The attributes of ``model`` (what :func:`restored_model` makes it from again), for a
    store of built models (:mod:`ncgen.codegen.model_cache`); pickling goes by description."""
    return {k: v for k, v in vars(model).items() if k not in ("_frozen", "_data")}


def restored_model(state: dict) -> Model:
    """The model whose attributes are ``state`` (from :func:`model_state`), constant again
    (arrays read-only, lists refusing changes) without building anything."""
    model = object.__new__(Model)
    for key, value in state.items():
        object.__setattr__(model, key, _frozen(value))
    object.__setattr__(model, "_data", ModelData())
    object.__setattr__(model, "_frozen", True)
    return model


def known_model(expected_hash: str) -> "Model | None":
    """The model of this process with that content hash (pickled or rebuilt here), or None."""
    model = _known.get(expected_hash) or _rebuilt.get(expected_hash)
    if model is not None and expected_hash in _rebuilt:
        _rebuilt.move_to_end(expected_hash)
    return model


def keep_rebuilt(model: Model, expected_hash: str) -> Model:
    """Check a model rebuilt from its description against the pickled ``expected_hash`` and
    keep it for the next unpickling (see :meth:`ncgen.model.system.System.rebuilt_model`)."""
    if model.content_hash != expected_hash:
        raise ModelError(f"model {model.name!r} rebuilt from its description differs from the pickled one "
                         f"(content hash {model.content_hash[:12]}... instead of {expected_hash[:12]}...): "
                         "its TOML form does not hold everything the model used (a force given as a Python "
                         "function?), or another ncgen version unpickles it; build the model in the worker")
    _rebuilt[expected_hash] = model
    while len(_rebuilt) > KEEP_REBUILT:
        _rebuilt.popitem(last=False)
    return model
