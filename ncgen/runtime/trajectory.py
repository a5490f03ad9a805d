"""``Trajectory``: the result of :func:`ncgen.simulate` (or a part of it, after a failure).

Arrays are indexed by output step first (``n_t = len(t)`` steps), SI units:

* ``t`` (s), ``q`` ``(n_t, nq)`` (m), ``v = q̇`` (m/s), ``lam`` ``(n_t, nc)`` multipliers,
  ``u`` ``(n_t, nu)`` input samples, ``p`` ``(np,)`` parameter values;
* ``kinetic``, ``potential`` and ``energy = kinetic + potential`` (J);
* ``constraint_residual = |Φ(t, q)|∞`` (m²: natural-coordinate constraints are quadratic)
  and ``velocity_residual = |A v + Φ_t|∞`` (m²/s), the drift of the two constraint levels;
* ``markers`` ``(n_t, n_markers, dim)``, world positions of the model's named markers;
* ``qj``, ``vj`` ``(n_t, Σ n_j)``: joint positions and rates (``model.joint_names`` order,
  columns named by ``joint_position_names``, ``joint_rate_names``); :meth:`joint` per joint;
* with contacts (``contact_names``): ``gap`` ``(n_t, nk)`` (m), ``contact_normal`` (N),
  ``contact_tangent`` ``(n_t, nk, dim − 1)`` (N) and ``contact_state`` (0 open, 1 stick,
  2 slip), see :mod:`ncgen.runtime.contact_outputs`;
* names: ``coordinate_names``, ``constraint_names``, ``input_names``, ``parameter_names``,
  ``member_names``, ``marker_names`` and ``model_name``; ``info`` holds how it was computed
  (method, backend, tolerances, integrator statistics, wall time, whether it is complete).

Files: ``save("x.npz")`` keeps everything (:meth:`load` reads it back; pass the model to
use :meth:`point` and :meth:`poses` again), ``save("x.csv")`` writes a table of ``t``, the
coordinates (columns named by the coordinate names), the joint positions and rates (columns
``qj.<name>``, ``vj.<name>``), energies and residuals.  Files are
written to a temporary sibling and renamed, so a reader never sees a partial file.
"""
from __future__ import annotations

import json
from functools import partial
from pathlib import Path

import numpy as np

from ncgen.errors import NcgenError
from ncgen.files import atomic_path
from ncgen.model.data import model_data
from ncgen.runtime import contact_outputs, outputs

NAME_KEYS = ("coordinate_names", "constraint_names", "input_names", "parameter_names",
             "member_names", "marker_names")
ARRAY_KEYS = ("t", "q", "v", "lam", "u", "p", "kinetic", "potential", "constraint_residual",
              "velocity_residual", "markers")
#: Joint space (optional in files written before it existed).
JOINT_NAME_KEYS = ("joint_names", "joint_position_names", "joint_rate_names")
JOINT_ARRAY_KEYS = ("qj", "vj")
ALL_NAME_KEYS = NAME_KEYS + JOINT_NAME_KEYS + ("contact_names",)
#: Arrays a trajectory may be given (else :meth:`Trajectory._default`): joint states, contact outputs.
OPTIONAL_ARRAY_KEYS = JOINT_ARRAY_KEYS + contact_outputs.KEYS


def output_names(model) -> dict:
    """The lists of names of a trajectory of ``model``: :data:`NAME_KEYS`, the joint names and,
    for a model with contacts, the contact names; made once per model (read only: a
    trajectory copies a list when it is read)."""
    data = model_data(model)
    if data.output_names is None:
        data.output_names = _output_names(model)
    return data.output_names


def _output_names(model) -> dict:
    js = model.joint_space
    names = {key: getattr(model, key) for key in NAME_KEYS}
    names.update(joint_names=js.joint_names, joint_position_names=js.position_names, joint_rate_names=js.rate_names)
    if getattr(model, "nk", 0):
        names["contact_names"] = model.contact_names
    return names


#: What :class:`Derived` computes, by key: the group computed at once and the item of it.
_GROUPS = {"kinetic": ("energy", 0), "potential": ("energy", 1), "constraint_residual": ("residual", 0),
           "velocity_residual": ("residual", 1), "markers": ("markers", None), "qj": ("joint", 0),
           "vj": ("joint", 1), **{key: ("contact", key) for key in contact_outputs.KEYS}}

#: The keys :class:`Derived` gives, for a model with contacts and without.
_KEYS_CONTACTS = frozenset(("q", "v", *_GROUPS))
_KEYS = _KEYS_CONTACTS - set(contact_outputs.KEYS)


class Derived:
    """The outputs of a run derived from its states ``(t, q, v)`` (``q``, ``v``: arrays or
    functions computing them): the states themselves, energies, residuals, markers, joint
    states and, for a model with contacts, the contact outputs (from the nonsmooth stepper's
    ``impulses`` per output interval, or the compliant law); each group computed when first
    asked for (``derived(key)``) and kept — one object per run, where a function per output
    would cost a closure each."""

    __slots__ = ("model", "t", "p", "impulses", "_states", "_kept", "keys")

    def __init__(self, model, t, q, v, p, impulses=None):
        self.model, self.t, self.p, self.impulses = model, t, p, impulses
        self._states = [q if callable(q) else _float(q), v if callable(v) else _float(v)]
        self._kept: dict = {}
        self.keys = _KEYS_CONTACTS if getattr(model, "nk", 0) else _KEYS

    def state(self, i: int) -> np.ndarray:
        """q (``i = 0``) or v (1), as floats."""
        x = self._states[i]
        if callable(x):
            x = self._states[i] = _float(x())
        return x

    def __call__(self, key: str):
        if key == "q" or key == "v":
            return self.state(key == "v")
        group, item = _GROUPS[key]
        kept = self._kept.get(group)
        if kept is None:
            m, t, p, q = self.model, self.t, self.p, self.state(0)
            if group == "energy":
                kept = outputs.energies(m, t, q, self.state(1), p)
            elif group == "residual":
                kept = outputs.residuals(m, t, q, self.state(1), p)
            elif group == "markers":
                kept = outputs.markers(m, q, self.state(1))
            elif group == "joint":
                kept = outputs.joint_states(m, q, self.state(1))
            else:
                kept = contact_outputs.impulse_outputs(m, t, q, p, self.impulses) if self.impulses is not None \
                    else contact_outputs.smooth_outputs(m, t, q, self.state(1), p)
            self._kept[group] = kept
        return kept if item is None else kept[item]


def derived_outputs(model, t, q, v, p, impulses=None) -> tuple[dict, dict]:
    """``(names, arrays)`` of the outputs beyond the states, energies and markers: the joint
    states (``model.joint_names``) and, for a model with contacts, the contact outputs
    (:class:`Derived`); ``q`` and ``v``: the states, or functions giving them; the arrays are
    functions computing them (see :class:`Trajectory`)."""
    names = {key: x for key, x in output_names(model).items() if key not in NAME_KEYS}
    derived = Derived(model, t, q, v, p, impulses)
    return names, {key: partial(derived, key) for key in derived.keys if key in OPTIONAL_ARRAY_KEYS}


class _Array:
    """An array attribute of :class:`Trajectory` (of floats, or of ints when ``integer``),
    given either as an array or as a function of no arguments that computes it, called on
    first access (the derived outputs of a run cost nothing until read); the result is kept."""

    def __init__(self, integer: bool = False):
        self.integer = integer

    def __set_name__(self, owner, name: str):
        self.name = name

    def __get__(self, obj, owner=None):
        if obj is None:
            return self
        try:
            value = obj._arrays[self.name]
        except KeyError:                    # an optional array not given: its default
            value = obj._arrays[self.name] = obj._default(self.name)
            return value
        if callable(value):
            value = obj._arrays[self.name] = _integers(value()) if self.integer else _float(value())
        return value

    def __set__(self, obj, value):
        obj._arrays[self.name] = value


class _Names:
    """A list of names of :class:`Trajectory` (``coordinate_names``, ...): the run's own copy
    of the names it was given, made on first access (then an ordinary attribute)."""

    def __set_name__(self, owner, name: str):
        self.name = name

    def __get__(self, obj, owner=None):
        if obj is None:
            return self
        value = obj.__dict__[self.name] = list(obj._names.get(self.name, ()))
        return value


_FLOAT64 = np.dtype(np.float64)


def _float(value):
    """``value`` (an array or a function computing one) as floats, lazily."""
    if callable(value):
        return lambda: _float(value())
    if type(value) is np.ndarray and value.dtype is _FLOAT64:
        return value
    return np.asarray(value, dtype=float)


def _integers(value) -> np.ndarray:
    """``value`` as floats, then ints (contact states)."""
    return np.asarray(value, dtype=float).astype(int)


class Trajectory:
    """Simulated states and derived quantities (see the module docstring).  Any array may be
    given as a function computing it (evaluated on first access)."""

    def __init__(self, *, model_name: str, names: dict, info: dict, model=None, derived: Derived | None = None,
                 **arrays):
        self.model = model
        self.model_name = model_name
        missing = [key for key in NAME_KEYS if key not in names]
        if missing:
            raise KeyError(missing[0])
        self._names = names                      # copied into lists when read (_Names)
        self._derived = derived                  # the arrays not given, when first read (_default)
        a = self._arrays = {}                    # the _Array attributes' values (functions: converted when read)
        for key in ARRAY_KEYS:
            value = arrays.get(key)
            if value is None:
                if derived is None or key not in derived.keys:
                    raise KeyError(key)
                continue
            a[key] = value if callable(value) else _float(value)
        for key in OPTIONAL_ARRAY_KEYS:          # none given: the default (:meth:`_default`), made when first read
            value = arrays.get(key)
            if value is not None:
                a[key] = value if callable(value) else _integers(value) if key == "contact_state" else _float(value)
        self.info = dict(info)

    def _default(self, key: str) -> np.ndarray:
        """The value of the array ``key`` when none was given: derived from the states (the
        run's :class:`Derived`), else no joint coordinates, no contacts (zeros of ``(n_t, 0)``,
        ``(n_t, nk)``, ``(n_t, nk, dim − 1)``; states as int)."""
        derived = self.__dict__.get("_derived")     # (none in a trajectory pickled before it existed)
        if derived is not None and key in derived.keys:
            value = derived(key)
            return _integers(value) if key == "contact_state" else _float(value)
        n = len(self.t)
        if key in JOINT_ARRAY_KEYS:
            return np.zeros((n, 0))
        nk = len(self.contact_names)
        if key == "contact_tangent":
            return np.zeros((n, nk, self.dim - 1))
        return np.zeros((n, nk), dtype=int if key == "contact_state" else float)

    def __getstate__(self) -> dict:
        """Pickled with every array computed (functions do not pickle) and every list of names."""
        state = dict(self.__dict__)
        state["_arrays"] = {key: getattr(self, key) for key in ARRAY_KEYS + OPTIONAL_ARRAY_KEYS}
        state.update({key: getattr(self, key) for key in ALL_NAME_KEYS})
        state["_names"], state["_derived"] = {}, None
        return state

    @classmethod
    def from_states(cls, model, t, q, v, lam, u, p, info: dict, impulses=None) -> "Trajectory":
        """The trajectory of the states ``(t, q, v, lam)`` of ``model`` (each an array or a
        function computing it), its derived quantities computed on first access;
        ``impulses``: the nonsmooth stepper's contact impulse sums per output interval.  A run
        that has its joint states sets ``qj`` and ``vj`` afterwards (else they are derived)."""
        t = np.asarray(t, float)
        derived = Derived(model, t, q, v, p, impulses)
        arrays = {"t": t, "lam": lam if callable(lam) else _float(lam), "u": u if callable(u) else _float(u),
                  "p": _float(p)}
        if not callable(q):
            arrays["q"] = derived.state(0)
        if not callable(v):
            arrays["v"] = derived.state(1)
        return cls.of_run(model, derived, arrays, dict(info))

    @classmethod
    def of_run(cls, model, derived: Derived, arrays: dict, info: dict, names: dict | None = None) -> "Trajectory":
        """A run's trajectory made directly (a short run's fixed cost): ``arrays`` (``t`` and
        ``p`` as float arrays, the others float arrays or functions computing them; the
        arrays not given are ``derived``'s) and ``info`` become the trajectory's own (not
        copied: the caller's fresh objects); ``names``: :func:`output_names` of ``model``
        (found when None)."""
        traj = cls.__new__(cls)
        d = traj.__dict__
        d["model"], d["model_name"], d["_names"], d["_derived"], d["_arrays"], d["info"] = \
            model, model.name, output_names(model) if names is None else names, derived, arrays, info
        return traj

    def head(self, n: int) -> "Trajectory":
        """The first ``n`` samples (every per-sample array cut, names and ``info`` copied)."""
        names = {key: list(getattr(self, key)) for key in NAME_KEYS + JOINT_NAME_KEYS}
        names["contact_names"] = list(self.contact_names)
        arrays = {key: getattr(self, key)[:n] for key in ARRAY_KEYS + JOINT_ARRAY_KEYS + contact_outputs.KEYS
                  if key != "p"}
        return Trajectory(model_name=self.model_name, names=names, info=dict(self.info), model=self.model,
                          p=self.p, **arrays)

    # --------------------------------------------------------------- views
    def __len__(self) -> int:
        return len(self.t)

    coordinate_names, constraint_names, input_names, parameter_names, member_names, marker_names = \
        (_Names() for _ in NAME_KEYS)
    joint_names, joint_position_names, joint_rate_names, contact_names = (_Names() for _ in range(4))
    t, q, v, lam, u, p, kinetic, potential = (_Array() for _ in range(8))
    constraint_residual, velocity_residual, markers, qj, vj = (_Array() for _ in range(5))
    gap, contact_normal, contact_tangent, contact_state = _Array(), _Array(), _Array(), _Array(integer=True)

    @property
    def dim(self) -> int:
        return self.model.dim if self.model is not None else self.markers.shape[2]

    @property
    def energy(self) -> np.ndarray:
        """Total mechanical energy ``T + V`` (J) per step."""
        return self.kinetic + self.potential

    @property
    def complete(self) -> bool:
        """False for the partial trajectory attached to a :class:`~ncgen.errors.SimulationError`."""
        return bool(self.info.get("complete", True))

    @property
    def energy_drift(self) -> float:
        """``max |E − E(t0)|`` (J)."""
        return float(np.max(np.abs(self.energy - self.energy[0]))) if len(self) else 0.0

    @property
    def energy_scale(self) -> float:
        """``max(|E(t0)|, max T)`` (J): what relative energy drifts are relative to."""
        return float(max(abs(self.energy[0]), np.max(self.kinetic))) if len(self) else 0.0

    def _model(self, what: str):
        if self.model is None:
            raise NcgenError(f"{what} needs the model; this trajectory was loaded without it: "
                             f"use Trajectory.load(path, model=model)")
        return self.model

    def point(self, member: str, local) -> np.ndarray:
        """World positions ``(n_t, dim)`` of the point of ``member`` with local coordinates
        ``local`` (member frame, m), from ``r = C(c) q_I``."""
        model = self._model("point()")
        m = model.member(member)
        C = m.rigid.C(m.rigid.affine(np.asarray(local, dtype=float)))
        return outputs.member_coordinates(model, member, self.q) @ np.asarray(C).T

    def coordinate(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """``(values, rates)`` per step (m, m/s) of the coordinate ``name``: one of
        ``coordinate_names`` or one as written before coordinate sharing re-based its member
        (:meth:`~ncgen.model.model.Model.coordinate`)."""
        if name in self.coordinate_names:
            i = self.coordinate_names.index(name)
            return self.q[:, i].copy(), self.v[:, i].copy()
        s, c = self._model(f"the coordinate {name!r}").coordinate(name)
        return self.q @ s + c, self.v @ s

    def joint(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """``(positions, rates)`` of joint ``name`` per step: ``(n_t,)`` each for a joint with
        one coordinate (rad or m, rad/s or m/s), ``(n_t, k)`` otherwise (see
        ``joint_position_names``)."""
        if name not in self.joint_names:
            known = ", ".join(self.joint_names) or "none"
            js = getattr(self.model, "joint_space", None)
            why = f": {js.skipped[name]}" if js is not None and name in js.skipped else ""
            raise NcgenError(f"no joint with coordinates named {name!r}{why} (joints: {known})")
        pos = [i for i, n in enumerate(self.joint_position_names) if n == name or n.startswith(name + ".")]
        rate = [i for i, n in enumerate(self.joint_rate_names) if n == name or n.startswith(name + ".")]
        x, xd = self.qj[:, pos], self.vj[:, rate]
        return (x[:, 0], xd[:, 0]) if len(pos) == 1 else (x, xd)

    def reaction(self, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``(force, moment, effort)`` of joint ``name`` per step, from the multipliers
        (:func:`ncgen.analysis.reactions.joint_reactions`): force ``(n_t, dim)`` in N and moment
        (N·m; ``(n_t, 3)``, or ``(n_t,)`` in 2D) on the joint's second member in world axes
        about the joint point; ``effort`` ``(n_t, ...)`` for driven or actuated joints, else None."""
        from ncgen.analysis.reactions import joint_reactions

        model = self._model("reaction()")
        rows = [joint_reactions(model, q, lam, v=v, t=t, u=u, p=self.p, joints=[name]).get(name)
                for t, q, v, lam, u in zip(self.t, self.q, self.v, self.lam, self.u)]
        if not rows or rows[0] is None:
            raise NcgenError(f"joint {name!r} has no reaction (no equations and no actuator)")
        effort = None if rows[0].effort is None else np.array([r.effort for r in rows])
        return np.array([r.force for r in rows]), np.array([r.moment for r in rows]), effort

    def marker(self, name: str) -> np.ndarray:
        """World positions ``(n_t, dim)`` of the marker ``"member.marker"``."""
        if name not in self.marker_names:
            known = ", ".join(self.marker_names) or "none"
            raise NcgenError(f"no marker named {name!r} (markers: {known})")
        return self.markers[:, self.marker_names.index(name)]

    def poses(self) -> tuple[np.ndarray, np.ndarray]:
        """``(R, p)`` of every member per step: ``R`` ``(n_t, n_members, dim, dim)`` (local →
        world; identity for points), ``p`` ``(n_t, n_members, dim)`` centres of mass."""
        return outputs.poses(self._model("poses()"), self.q)

    def to_html(self, path, **options) -> Path:
        """Write an offline interactive 3D page of this run (:func:`ncgen.viz.html.to_html`:
        ``colors``, ``mesh_paths``, ``fps``, ``title``, ``trails``); ``?t=SECONDS`` in its
        URL opens it paused at that time.  Returns the path."""
        from ncgen.viz.html import to_html
        return to_html(self, path, **options)

    def summary(self) -> str:
        """A few lines for people: span, integrator work, energy and constraint drift."""
        info = self.info
        lines = [f"Trajectory of model {self.model_name!r}: {len(self)} steps, "
                 f"t = {self.t[0]:g} ... {self.t[-1]:g} s"]
        if info.get("method"):
            lines.append(f"  integrator: {info['method']} ({_settings(info)}): {_work(info)}")
        if info.get("kernels_reason"):
            lines.append(f"  kernels: {info['kernels']}: {info['kernels_reason']}")
        if "error_estimate" in info:
            est = info["error_estimate"]
            if np.isfinite(est["q"]) and np.isfinite(est["v"]):
                lines.append(f"  estimated error at the end: {est['q']:.3g} in q, {est['v']:.3g} in v "
                             f"({est.get('how', '')})")
            else:
                lines.append(f"  estimated error at the end: not estimated ({_no_estimate(est, self.model)})")
        energy = info.get("energy", {})
        if len(self) and energy.get("conservative") is False:
            lines.append(_balance_line(self, energy))
        elif len(self):
            scale = self.energy_scale
            rel = f" ({self.energy_drift / scale:.2g} relative)" if scale > 0 else ""
            known = energy.get("conservative", None if self.model is None else self._conservative())
            what = {True: "energy (conservative: constant up to the integration error)",
                    False: "energy (not conservative: forces that do work)", None: "energy"}[known]
            lines.append(f"  {what}: E(t0) = {self.energy[0]:.6g} J, max |E - E(t0)| = "
                         f"{self.energy_drift:.3g} J{rel}")
        if len(self):
            lines.append(f"  constraint drift: max |phi| = {np.max(self.constraint_residual):.3g}, "
                         f"max |A v + phi_t| = {np.max(self.velocity_residual):.3g}")
        if not self.complete:
            lines.append(f"  INCOMPLETE: {info.get('message', 'the integration stopped early')}")
        return "\n".join(lines)

    def _conservative(self) -> bool:
        """Whether the model conserves energy with this run's inputs (True if unknown: loaded
        without the model)."""
        from ncgen.runtime.stepper_checks import is_conservative

        driven = self.u is not None and bool(np.any(np.asarray(self.u) != 0))
        return True if self.model is None else is_conservative(self.model, inputs=driven)

    def _repr_html_(self) -> str | None:
        """Jupyter's display: the interactive 3D page in the cell (:mod:`ncgen.viz.notebook`)."""
        from ncgen.viz.notebook import trajectory_cell
        return trajectory_cell(self)

    def __repr__(self) -> str:
        span = f"t = {self.t[0]:g} ... {self.t[-1]:g} s" if len(self) else "empty"
        return (f"<Trajectory {self.model_name!r}: {len(self)} steps, {span}"
                f"{'' if self.complete else ', incomplete'}>")

    # ---------------------------------------------------------------- files
    def save(self, path) -> Path:
        """Write ``.npz`` (everything) or ``.csv`` (:func:`csv_columns`: t, q, v, joint positions and
        rates, markers, energies, residuals, contacts; units in the header); returns the path."""
        path = Path(path)
        suffix = path.suffix.lower()
        if suffix not in (".npz", ".csv"):
            raise NcgenError(f"save: {path}: expected a .npz or .csv file name")
        writer = self._write_npz if suffix == ".npz" else self._write_csv
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            writer(fh)
        return path

    def _write_npz(self, fh) -> None:
        data = {key: getattr(self, key) for key in ARRAY_KEYS}
        data.update({key: getattr(self, key) for key in JOINT_ARRAY_KEYS})
        data.update({key: np.array(getattr(self, key), dtype=str) for key in NAME_KEYS + JOINT_NAME_KEYS})
        if self.contact_names:
            data["contact_names"] = np.array(self.contact_names, dtype=str)
            data.update({key: getattr(self, key) for key in contact_outputs.KEYS})
        data["model_name"] = np.array(self.model_name)
        data["info_json"] = np.array(json.dumps(self.info, sort_keys=True, default=_json_default))
        data["format"] = np.array("ncgen-trajectory-1")
        np.savez_compressed(fh, **data)

    def _write_csv(self, fh) -> None:
        header, columns = csv_columns(self)
        table = np.column_stack(columns)
        fh.write((",".join(header) + "\n").encode())
        np.savetxt(fh, table, delimiter=",", fmt="%.17g")

    @classmethod
    def load(cls, path, model=None) -> "Trajectory":
        """Read a trajectory saved as ``.npz``; ``model`` (the same model) enables
        :meth:`point` and :meth:`poses`."""
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as data:
                if "format" not in data or str(data["format"]) != "ncgen-trajectory-1":
                    raise NcgenError(f"{path} is not a trajectory saved by ncgen (.npz)")
                arrays = {key: data[key] for key in ARRAY_KEYS + JOINT_ARRAY_KEYS if key in data}
                names = {key: [str(s) for s in data[key]] for key in NAME_KEYS + JOINT_NAME_KEYS if key in data}
                if "contact_names" in data:
                    names["contact_names"] = [str(s) for s in data["contact_names"]]
                    arrays.update({key: data[key] for key in contact_outputs.KEYS})
                name = str(data["model_name"])
                info = json.loads(str(data["info_json"]))
        except (OSError, ValueError, KeyError) as e:
            raise NcgenError(f"cannot read trajectory {path}: {e}") from None
        if model is not None and (model.name != name or list(model.coordinate_names) != names["coordinate_names"]):
            raise NcgenError(f"{path} holds a trajectory of model {name!r} with coordinates "
                             f"{names['coordinate_names'][:4]}...; the model given is {model.name!r} "
                             f"with {list(model.coordinate_names)[:4]}...")
        return cls(model_name=name, names=names, info=info, model=model, **arrays)


def _settings(info: dict) -> str:
    parts = [f"{info['backend']} backend"] if "backend" in info else []
    parts += [f"{info['kernels']} kernels"] if "kernels" in info else []
    parts += [info["scheme"]] if "scheme" in info else []
    parts += [f"{key} {info[key]:g}" for key in ("rtol", "atol", "h", "order", "tol") if key in info]
    return ", ".join(parts)


def _work(info: dict) -> str:
    stats = info.get("stats", {})
    labels = {"nsteps": "steps", "netfails": "error-test failures", "newton_iterations": "Newton iterations",
              "rejected_steps": "rejected steps", "step_splits": "step splits"}
    parts = [f"{stats[key]} {label}" for key, label in labels.items() if key in stats]
    cpu = f" ({info['cpu_time']:.3g} s CPU)" if "cpu_time" in info else ""
    return ", ".join(parts + [f"{info.get('wall_time', 0.0):.3g} s wall{cpu}"])


def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    raise TypeError(f"not JSON serialisable: {x!r}")


#: How the summary names the parts of an energy balance (ncgen.runtime.energy_balance).
_PART_NAMES = {"contacts": "contacts (normal)", "friction": "friction", "dampers": "dampers and other forces",
               "inputs": "inputs", "drives": "drives", "push_out": "contact push-out"}


def _balance_line(traj, energy: dict) -> str:
    """The summary's energy balance: change of E, the work of each class, the residual."""
    change = float(traj.energy[-1] - traj.energy[0])
    parts = energy.get("parts") or {}
    tiny = 1e-9 * (abs(float(traj.energy[0])) + abs(energy["work"]) + abs(change))
    shown = ", ".join(f"{_PART_NAMES[k]} {w:.4g} J" for k, w in parts.items() if abs(w) > tiny)
    how = energy.get("quadrature", "accumulated step by step in the integrator")
    head = f"  energy balance (dissipative or driven run): E(t0) = {traj.energy[0]:.6g} J, E(end) - E(t0) = {change:.4g} J"
    split = f" ({shown}; {how})" if shown else ""
    return (f"{head}; work W = {energy['work']:.4g} J{split}; residual max |E - E(t0) - W| = "
            f"{energy['balance_error']:.3g} J ({energy['relative']:.2g} relative)")


def _no_estimate(est: dict, model) -> str:
    """Why a run has no error estimate, in words."""
    if model is not None and getattr(model, "contact_model", "smooth") == "nonsmooth" and getattr(model, "nk", 0):
        return "nonsmooth contacts: impacts make the step-doubling estimate meaningless"
    how = est.get("how", "")
    return how.removeprefix("none: ").removeprefix("none ").strip("()") or "no shadow run"


def _coordinate_unit(name: str) -> str:
    """``m`` for a basic point's coordinate (slot ``r``, ``r_i``, ...), ``1`` for a base vector's."""
    parts = name.split(".")
    return "m" if len(parts) >= 3 and parts[-2].startswith("r") else "1"


def csv_columns(traj) -> tuple[list[str], list[np.ndarray]]:
    """Header (``name [unit]``) and columns of a trajectory's CSV file: ``t``, q, v, joint
    positions and rates, markers, energies, residuals and, with contacts, gaps, forces and
    states (0 open, 1 stick, 2 slip)."""
    units = [_coordinate_unit(n) for n in traj.coordinate_names]
    angles = getattr(getattr(traj.model, "joint_space", None), "angles", None)
    if angles is None or len(angles) != len(traj.joint_position_names):
        jq, jv = ["rad or m"] * len(traj.joint_position_names), ["rad/s or m/s"] * len(traj.joint_rate_names)
    else:
        jq = ["rad" if a else "m" for a in angles]
        jv = ["rad/s or m/s"] * len(traj.joint_rate_names)
    header = ["t [s]", *(f"{n} [{u}]" for n, u in zip(traj.coordinate_names, units)),
              *(f"v.{n} [{u}/s]" if u == "m" else f"v.{n} [1/s]" for n, u in zip(traj.coordinate_names, units)),
              *(f"qj.{n} [{u}]" for n, u in zip(traj.joint_position_names, jq)),
              *(f"vj.{n} [{u}]" for n, u in zip(traj.joint_rate_names, jv)),
              *(f"{m}.{a} [m]" for m in traj.marker_names for a in "xyz"[:traj.dim]),
              "energy [J]", "kinetic [J]", "potential [J]", "constraint_residual [m^2]", "velocity_residual [m^2/s]"]
    n = len(traj.t)
    columns = [traj.t, traj.q, traj.v, traj.qj, traj.vj, traj.markers.reshape(n, -1), traj.energy, traj.kinetic,
               traj.potential, traj.constraint_residual, traj.velocity_residual]
    if traj.contact_names:
        header += [f"gap.{c} [m]" for c in traj.contact_names]
        header += [f"contact_normal.{c} [N]" for c in traj.contact_names]
        header += [f"contact_tangent.{c}.{k + 1} [N]" for c in traj.contact_names for k in range(traj.dim - 1)]
        header += [f"contact_state.{c} [0 open; 1 stick; 2 slip]" for c in traj.contact_names]
        columns += [traj.gap, traj.contact_normal, traj.contact_tangent.reshape(n, -1), traj.contact_state]
    return header, columns

