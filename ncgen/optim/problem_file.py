"""Optimal-control problem files (TOML), read into an :class:`OptimalControl`.

The format is documented in docs/optimal-control.md.  Every table is optional::

    model = "cartpole.toml"          # the model file, relative to this file
    [horizon]        N, t_final (s, or [lower, upper]: free), method, degree, form, integrator,
                     integrator_options = {...}
    [parameters]     name = value                   (fixed values)
    [free_parameters.NAME]  lower, upper, guess     (design parameters)
    [bounds.inputs] / [bounds.coordinates] / [bounds.velocities]   name = [lower, upper]
    [bounds.markers.NAME]   lower = [...], upper = [...]   ("free" = unbounded component)
    [bounds]         min_tension = T_min            (every cable's pull ≥ T_min, N)
    [initial] / [final]     q, v, markers = {NAME = [x, y(, z)]}, joints = {JOINT = value}
    [final.pose.MEMBER]     rotation = 3×3 rows (body→world; an angle in a plane), position
    [periodic]       q = true, v = true
    [cost]           effort, time, [[cost.track]], [[cost.terminal]]
    [solver]         max_iter, tol, warm_start, ipopt = {...}
    [contacts]       the contact-implicit transcription's settings (models with nonsmooth contacts):
                     sigma0, sigma_final, sigma_factor, tol, step_lengths, step_bounds, step_weight,
                     directions

Errors are :class:`~ncgen.errors.ProblemFileError` naming the key path (``final.v``) and
what was expected.
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ncgen.errors import NcgenError, OptimizationError, ProblemFileError
from ncgen.optim.ipopt_options import check_ipopt_options
from ncgen.files import decode_text
from ncgen.optim.problem import FORMS, METHODS, OptimalControl

TOP_KEYS = ("model", "horizon", "parameters", "free_parameters", "bounds", "initial", "final", "periodic",
            "cost", "solver", "contacts")
FREE = "free"


@dataclass
class SolveOptions:
    """The ``[solver]`` table: arguments of :meth:`OptimalControl.solve`."""

    max_iter: int = 1000
    tol: float = 1e-8
    warm_start: str | None = None
    verbose: bool = False
    ipopt: dict = field(default_factory=dict)

    def kwargs(self) -> dict:
        return {"max_iter": self.max_iter, "tol": self.tol, "verbose": self.verbose, "ipopt": dict(self.ipopt),
                "warm_start": self.warm_start}


def read_problem_file(path) -> tuple[dict, str]:
    """``(data, origin)``: the parsed TOML of a problem file."""
    path = Path(path)
    try:
        text = decode_text(path.read_bytes(), str(path))
    except NcgenError as exc:
        raise ProblemFileError(str(exc)) from None
    except OSError as exc:
        raise ProblemFileError(f"problem file {str(path)!r}: cannot be read ({exc.strerror or exc})") from None
    try:
        return tomllib.loads(text), str(path)
    except tomllib.TOMLDecodeError as exc:
        raise ProblemFileError(f"{path}: invalid TOML: {exc}") from None


def model_path(data: dict, origin: str) -> Path | None:
    """The ``model`` key resolved relative to the problem file, or None."""
    if "model" not in data:
        return None
    if not isinstance(data["model"], str) or not data["model"]:
        raise ProblemFileError(f"{origin}: model: expected the path of a model file, got {data['model']!r}")
    return (Path(origin).parent / data["model"]).resolve()


def problem_from_data(data: dict, model, origin: str = "problem") -> tuple[OptimalControl, SolveOptions]:
    """An :class:`OptimalControl` on ``model`` and the solver options from parsed TOML."""
    reader = _Reader(data, origin)
    try:
        return reader.build(model)
    except OptimizationError as exc:
        raise ProblemFileError(f"{origin}: {reader.where}: {exc}") from None


def load_problem(path, model) -> tuple[OptimalControl, SolveOptions]:
    """Read the problem file ``path`` for ``model``."""
    data, origin = read_problem_file(path)
    return problem_from_data(data, model, origin)


class _Reader:
    def __init__(self, data: dict, origin: str):
        self.data, self.origin = data, origin
        self.where = "(top level)"

    def fail(self, path: str, expected: str, got=None):
        shown = "" if got is None else f", got {_describe(got)}"
        raise ProblemFileError(f"{self.origin}: {path}: expected {expected}{shown}")

    def table(self, value, path: str, allowed) -> dict:
        if not isinstance(value, dict):
            self.fail(path, "a table", value)
        for k in value:
            if allowed is not None and k not in allowed:
                hint = _did_you_mean(k, allowed)
                raise ProblemFileError(f"{self.origin}: {path}.{k}: unknown key{hint}; "
                                       f"expected one of {', '.join(allowed)}")
        return value

    def number(self, value, path: str, positive: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
            self.fail(path, "a number", value)
        if positive and value <= 0:
            self.fail(path, "a positive number", value)
        return float(value)

    def numbers(self, value, path: str, n: int | None = None, free_ok: bool = False) -> list:
        if not isinstance(value, list) or (n is not None and len(value) != n):
            self.fail(path, f"{n if n is not None else 'a list of'} numbers" + (' (or "free")' if free_ok else ""),
                      value)
        out = []
        for i, x in enumerate(value):
            if free_ok and x == FREE:
                out.append(None)
            else:
                out.append(self.number(x, f"{path}[{i}]"))
        return out

    def build(self, model):
        d = self.table(self.data, "(top level)", TOP_KEYS)
        ocp = self._horizon(model, d.get("horizon", {}), d.get("contacts"))
        for name, value in self.table(d.get("parameters", {}), "parameters", None).items():
            self.where = f"parameters.{name}"
            ocp.set_parameter(name, value if isinstance(value, list) else self.number(value, self.where))
        for name, spec in self.table(d.get("free_parameters", {}), "free_parameters", None).items():
            path = f"free_parameters.{name}"
            spec = self.table(spec, path, ("lower", "upper", "guess"))
            lo, hi, guess = (self.number(spec[k], f"{path}.{k}") if k in spec else default
                             for k, default in (("lower", -np.inf), ("upper", np.inf), ("guess", None)))
            self.where = path
            ocp.free_parameter(name, lo, hi, guess)
        self._bounds(ocp, d.get("bounds", {}))
        self._conditions(ocp, d)
        self._cost(ocp, d.get("cost", {}))
        return ocp, self._solver(d.get("solver", {}))

    def _horizon(self, model, h, contacts):
        h = self.table(h, "horizon", ("N", "t_final", "method", "degree", "form", "integrator",
                                           "integrator_options"))
        N = h.get("N", 50)
        if isinstance(N, bool) or not isinstance(N, int) or N < 1:
            self.fail("horizon.N", "a positive integer", N)
        T = h.get("t_final", 1.0)
        T = self.numbers(T, "horizon.t_final", 2) if isinstance(T, list) else self.number(T, "horizon.t_final",
                                                                                          positive=True)
        method = h.get("method")
        if method is not None and method not in METHODS:
            self.fail("horizon.method", " or ".join(f'"{m}"' for m in METHODS), method)
        degree = h.get("degree", 3)
        if isinstance(degree, bool) or not isinstance(degree, int):
            self.fail("horizon.degree", "an integer 1..9", degree)
        form = h.get("form", "auto")
        if form not in FORMS:
            self.fail("horizon.form", " or ".join(f'"{f}"' for f in FORMS), form)
        integrator = h.get("integrator", "idas")
        if not isinstance(integrator, str):
            self.fail("horizon.integrator", "an integrator name", integrator)
        options = dict(self.table(h.get("integrator_options", {}), "horizon.integrator_options", None))
        if contacts is not None:
            contacts = dict(self.table(contacts, "contacts", None))
        self.where = "horizon"
        return OptimalControl(model, N=N, t_final=T, method=method, degree=degree, form=form,
                              integrator=integrator, integrator_options=options, contacts=contacts)

    def _bounds(self, ocp, b):
        b = self.table(b, "bounds", ("inputs", "coordinates", "velocities", "markers", "min_tension"))
        if "min_tension" in b:
            T_min = self.number(b["min_tension"], "bounds.min_tension")
            self.where = "bounds.min_tension"
            ocp.min_tension(T_min)
        setters = {"inputs": ocp.bound_input, "coordinates": ocp.bound_coordinate, "velocities": ocp.bound_velocity}
        for kind, setter in setters.items():
            for name, pair in self.table(b.get(kind, {}), f"bounds.{kind}", None).items():
                path = f"bounds.{kind}.{name}"
                lo, hi = self.numbers(pair, path, 2, free_ok=True)
                self.where = path
                setter(name, -np.inf if lo is None else lo, np.inf if hi is None else hi)
        for name, spec in self.table(b.get("markers", {}), "bounds.markers", None).items():
            path = f"bounds.markers.{name}"
            spec = self.table(spec, path, ("lower", "upper"))
            dim = ocp.model.dim
            lo = self.numbers(spec["lower"], f"{path}.lower", dim, free_ok=True) if "lower" in spec else None
            hi = self.numbers(spec["upper"], f"{path}.upper", dim, free_ok=True) if "upper" in spec else None
            self.where = path
            ocp.bound_marker(name, lo, hi)

    def _state(self, value, path: str, nq: int):
        if value == FREE:
            return None
        if isinstance(value, bool):
            self.fail(path, f'"free", a number, {nq} numbers or a table of coordinate values', value)
        if isinstance(value, (int, float)):
            return self.number(value, path)
        if isinstance(value, list):
            return self.numbers(value, path, nq)
        if isinstance(value, dict):
            return {k: self.number(x, f"{path}.{k}") for k, x in value.items()}
        self.fail(path, f'"free", a number, {nq} numbers or a table of coordinate values', value)

    def _joints(self, value, path: str) -> dict:
        """``{joint = angle or length, ...}`` (a list for a joint with several coordinates)."""
        out = {}
        for name, x in self.table(value, path, None).items():
            out[name] = self.numbers(x, f"{path}.{name}") if isinstance(x, list) else self.number(x, f"{path}.{name}")
        if not out:
            self.fail(path, "a table {joint name = value, ...}", value)
        return out

    def _poses(self, value, path: str, dim: int) -> dict:
        """``{MEMBER = {rotation = 3×3 rows (an angle in a plane), position = [...]}}``."""
        out = {}
        for name, spec in self.table(value, path, None).items():
            where = f"{path}.{name}"
            spec = self.table(spec, where, ("rotation", "position"))
            for k in ("rotation", "position"):
                if k not in spec:
                    raise ProblemFileError(f"{self.origin}: {where}.{k}: missing (expected "
                                           f"{'the member frame rotation' if k == 'rotation' else f'{dim} numbers'})")
            if dim == 2:
                R = self.number(spec["rotation"], f"{where}.rotation")
            else:
                rows = spec["rotation"]
                if not isinstance(rows, list) or len(rows) != 3:
                    self.fail(f"{where}.rotation", "3 rows of 3 numbers (body→world)", rows)
                R = np.array([self.numbers(r, f"{where}.rotation[{i}]", 3) for i, r in enumerate(rows)])
            out[name] = (R, np.array(self.numbers(spec["position"], f"{where}.position", dim)))
        if not out:
            self.fail(path, "a table of member poses", value)
        return out

    def _markers(self, value, path: str, dim: int):
        out = []
        for name, pos in self.table(value, path, None).items():
            out.append((name, self.numbers(pos, f"{path}.{name}", dim, free_ok=True)))
        return out or None

    def _conditions(self, ocp, d):
        nq, dim = ocp.model.nq, ocp.model.dim
        if "initial" in d:
            t = self.table(d["initial"], "initial", ("q", "v", "markers", "joints"))
            joints = self._joints(t["joints"], "initial.joints") if "joints" in t else None
            q = "model" if t.get("q", "model") == "model" else self._state(t["q"], "initial.q", nq)
            v = "model" if t.get("v", "model") == "model" else self._state(t["v"], "initial.v", nq)
            markers = self._markers(t.get("markers", {}), "initial.markers", dim)
            self.where = "initial"
            if joints is not None and "q" in t:
                raise ProblemFileError(f"{self.origin}: initial: give q or joints, not both")
            ocp.initial(q=None if joints is not None else ocp.model.q0 if q == "model" else q,
                        v=ocp.model.v0 if v == "model" else v, marker=markers, joints=joints)
        if "final" in d:
            t = self.table(d["final"], "final", ("q", "v", "markers", "joints", "pose"))
            q = self._state(t["q"], "final.q", nq) if "q" in t else None
            v = self._state(t["v"], "final.v", nq) if "v" in t else None
            markers = self._markers(t.get("markers", {}), "final.markers", dim)
            joints = self._joints(t["joints"], "final.joints") if "joints" in t else None
            pose = self._poses(t["pose"], "final.pose", dim) if "pose" in t else None
            self.where = "final"
            ocp.final(q=q, v=v, marker=markers, joints=joints, pose=pose)
        if "periodic" in d:
            t = self.table(d["periodic"], "periodic", ("q", "v"))
            for k in ("q", "v"):
                if not isinstance(t.get(k, True), bool):
                    self.fail(f"periodic.{k}", "true or false", t[k])
            self.where = "periodic"
            ocp.periodic(q=t.get("q", True), v=t.get("v", True))

    def _cost(self, ocp, c):
        c = self.table(c, "cost", ("effort", "time", "track", "terminal"))
        if "effort" in c:
            e = c["effort"]
            self.where = "cost.effort"
            ocp.minimize_effort({k: self.number(w, f"cost.effort.{k}") for k, w in e.items()}
                                if isinstance(e, dict) else self.number(e, "cost.effort"))
        if "time" in c:
            self.where = "cost.time"
            ocp.minimize_time(self.number(c["time"], "cost.time"))
        dim = ocp.model.dim
        for key, method in (("track", "reference"), ("terminal", "target")):
            items = c.get(key, [])
            if not isinstance(items, list):
                self.fail(f"cost.{key}", f"an array of tables ([[cost.{key}]])", items)
            for i, item in enumerate(items):
                path = f"cost.{key}[{i}]"
                item = self.table(item, path, ("marker", method, "weight"))
                for k in ("marker", method):
                    if k not in item:
                        raise ProblemFileError(f"{self.origin}: {path}.{k}: missing (expected "
                                               f"{'a marker name' if k == 'marker' else f'{dim} numbers'})")
                w = self.number(item.get("weight", 1.0), f"{path}.weight")
                self.where = path
                if key == "track":
                    ocp.track_marker(item["marker"], self.numbers(item[method], f"{path}.{method}", dim), w)
                else:
                    target = self.numbers(item[method], f"{path}.{method}", dim, free_ok=True)
                    ocp.minimize_terminal(marker=(item["marker"], target), weight=w)

    def _solver(self, s):
        s = self.table(s, "solver", ("max_iter", "tol", "warm_start", "verbose", "ipopt"))
        opts = SolveOptions()
        if "max_iter" in s:
            if isinstance(s["max_iter"], bool) or not isinstance(s["max_iter"], int) or s["max_iter"] < 0:
                self.fail("solver.max_iter", "a non-negative integer", s["max_iter"])
            opts.max_iter = s["max_iter"]
        if "tol" in s:
            opts.tol = self.number(s["tol"], "solver.tol", positive=True)
        if "warm_start" in s:
            if s["warm_start"] not in ("rest", "interpolate"):
                self.fail("solver.warm_start", '"rest" or "interpolate"', s["warm_start"])
            opts.warm_start = s["warm_start"]
        if "verbose" in s:
            if not isinstance(s["verbose"], bool):
                self.fail("solver.verbose", "true or false", s["verbose"])
            opts.verbose = s["verbose"]
        if "ipopt" in s:
            try:
                opts.ipopt = check_ipopt_options(self.table(s["ipopt"], "solver.ipopt", None), "solver.ipopt")
            except OptimizationError as e:
                raise ProblemFileError(f"{self.origin}: {e}") from None
        return opts


def _describe(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, dict):
        return "a table"
    if isinstance(v, list):
        return f"a list of {len(v)}"
    if isinstance(v, str):
        return f"the string {v!r}"
    return repr(v)


def _did_you_mean(key: str, allowed) -> str:
    import difflib
    close = difflib.get_close_matches(key, list(allowed), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""
