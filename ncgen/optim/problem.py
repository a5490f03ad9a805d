"""``OptimalControl``: the user-facing description of an optimal-control problem on a Model.

>>> ocp = nc.OptimalControl(model, N=60, t_final=2.0)          # or t_final=(lo, hi): free
>>> ocp.bound_input("force", -20, 20)
>>> ocp.initial(q=model.q0, v=0)
>>> ocp.final(q=q_up, v=0)
>>> ocp.minimize_effort()
>>> sol = ocp.solve()                                          # an OptimalTrajectory

Conventions: time in s; ``q`` natural coordinates (m), ``v = q̇`` (m/s); inputs ``u`` and
parameters ``p`` in the model's units; names as in ``model.input_names``,
``model.parameter_names`` (``"k"`` or one component ``"k[1]"``), ``model.coordinate_names``
(``"cart.r_i.x"``) or a coordinate as written that coordinate sharing re-based (its value
``s · q + c`` from ``model.coordinate(name)``: bounds on it are linear path constraints,
targets on it extra equations of the assembly) and ``model.marker_names`` (``"pole.tip"``).  Inputs are piecewise
constant over the ``N`` equal intervals.  Bounds and marker path constraints hold at every
state point of the transcription (collocation points, or shooting nodes).

Boundary conditions.  Unless :meth:`initial` is called the motion starts from the model's
initial state ``(model.q0, model.v0)``; :meth:`initial` replaces that, and what it leaves
``None`` is free.  Full-state targets (``final(q=...)``, ``final(v=...)``,
:meth:`periodic`) fix only the ``dof`` tangent components (see
:mod:`ncgen.optim.conditions`); marker conditions fix the components given.
"""
from __future__ import annotations

import copy
import re

import numpy as np

from ncgen.errors import NcgenError, OptimizationError
from ncgen.model.rolling import refuse_rolling
from ncgen.validation import as_numbers, as_scalar
from ncgen.optim.transcription import MODEL_STATE

METHODS = ("collocation", "shooting", "contact_implicit")
LINEAR_SOLVERS = ("mumps", "spral", "ma27", "ma57", "ma77", "ma86", "ma97", "pardiso", "pardisomkl")


def _method(model, method: str | None, contacts) -> str:
    """The transcription method: ``method``, or by default ``"contact_implicit"`` for a model
    with nonsmooth contacts and ``"collocation"`` otherwise; refused where it does not fit
    the model's contacts or the ``contacts`` settings."""
    from ncgen.optim.contact_implicit import nonsmooth_contacts, refuse_unsupported

    if method is None:
        method = "contact_implicit" if nonsmooth_contacts(model) else "collocation"
    if method not in METHODS:
        raise OptimizationError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    refuse_unsupported(model, method)
    if method == "contact_implicit" and not nonsmooth_contacts(model):
        raise OptimizationError(f"method='contact_implicit': model {model.name!r} has no nonsmooth contacts "
                                "(build it with contacts='nonsmooth'); use method='collocation'")
    if contacts is not None and method != "contact_implicit":
        raise OptimizationError("contacts: settings of the contact-implicit transcription, given with "
                                f"method={method!r}; the model has no nonsmooth contacts")
    return method


class OptimalControl:
    """An optimal-control problem on ``model`` over ``N`` intervals.

    ``t_final``: horizon length (s), a number (fixed) or ``(lower, upper)`` (free final
    time, a decision variable); ``method``: ``"collocation"`` (Radau IIA of ``degree``,
    default 3, in the ``form`` ``"joint"`` (joint coordinates as states, trees only:
    :mod:`ncgen.optim.joint_radau`), ``"ggl"``, ``"index3"`` or ``"index1"`` (natural
    coordinates: :mod:`ncgen.optim.radau`); ``"auto"`` (default): ``"joint"`` when the model
    allows it, else ``"ggl"``), ``"shooting"`` (multiple shooting with ``integrator``, default IDAS;
    ``integrator_options`` go to its factory) or ``"contact_implicit"`` (time stepping through
    nonsmooth contacts, :mod:`ncgen.optim.contact_implicit`, with the ``contacts`` settings;
    the default, and the only method accepted, for a model built with
    ``contacts="nonsmooth"``: the others would ignore its contacts); ``parameters``: values
    replacing the model's defaults (``{"k": 50.0}``).
    """

    def __init__(self, model, N: int = 50, t_final=1.0, method: str | None = None, *, degree: int = 3,
                 form: str = "auto", integrator: str = "idas", integrator_options: dict | None = None,
                 parameters: dict | None = None, contacts: dict | None = None):
        refuse_rolling(model, "OptimalControl", "optimal control with rolling elements is not supported yet")
        if not isinstance(N, (int, np.integer)) or isinstance(N, bool) or N < 1:
            raise OptimizationError(f"N: expected a positive integer number of intervals, got {N!r}")
        method = _method(model, method, contacts)
        self.model = model
        self.N = int(N)
        self.method = method
        self.t0 = float(model.t0)
        self.t_final, self.t_final_bounds = _horizon(t_final)
        if method == "collocation":
            self.transcription = _collocation(model, degree, form)
        elif method == "contact_implicit":
            from ncgen.optim.contact_implicit import ContactImplicit
            self.transcription = ContactImplicit(model, contacts)
        else:
            from ncgen.optim.shooting import MultipleShooting
            self.transcription = MultipleShooting(integrator, **(integrator_options or {}))
        self._unconstrained()
        for name, value in (parameters or {}).items():
            self.set_parameter(name, value)

    def _unconstrained(self) -> None:
        """No bounds, boundary conditions, free parameters or costs yet; the model's state at
        the start and its parameter values."""
        nq, nu = self.model.nq, self.model.nu
        inf = np.inf
        self.u_bounds = np.array([[-inf] * nu, [inf] * nu]).reshape(2, nu)
        self.q_bounds = np.array([[-inf] * nq, [inf] * nq]).reshape(2, nq)
        self.v_bounds = self.q_bounds.copy()
        #: Bounds on coordinates as written that sharing re-based: ``(kind, name, s, c, lower,
        #: upper)``, ``kind`` "coordinate" (``s · q + c``) or "velocity of" (``s · v``).
        self.row_bounds: list[tuple[str, str, np.ndarray, float, float, float]] = []
        self.p_values = self.model.p0.copy()
        self.p_free: dict[int, tuple[float, float]] = {}
        self.marker_bounds: list[tuple[str, np.ndarray, np.ndarray]] = []
        #: Joint-space path constraints: (joint, "position" or "rate", lower, upper).
        self.joint_bounds: list[tuple[str, str, float, float]] = []
        #: ``T_min`` (N) of :meth:`min_tension`, or None.
        self.cable_min_tension: float | None = None
        self.initial_spec = {"q": MODEL_STATE, "v": MODEL_STATE, "markers": []}
        self.final_spec = {"q": None, "v": None, "markers": [], "pose": None, "joints": None}
        self.periodic_spec = {"q": False, "v": False}
        self.effort_R: np.ndarray | None = None
        self.tracking: list[tuple[str, object, float]] = []
        self.terminal: list[tuple[str, object]] = []
        self.time_weight = 0.0
        self.guess_turns: dict[str, object] = {}

    # ------------------------------------------------------------------ names
    def input_indices(self, name: str) -> list[int]:
        """Indices into ``u`` of input ``name`` (all components) or ``name[i]``."""
        return _indices(name, self.model.input_names, self.model.input_sizes, "input")

    def parameter_indices(self, name: str) -> list[int]:
        return _indices(name, self.model.parameter_names, self.model.parameter_sizes, "parameter")

    def coordinate_index(self, name: str) -> int | None:
        """Index in ``q`` of coordinate ``name``, None for a coordinate as written that
        coordinate sharing re-based (:meth:`coordinate_row` gives its row)."""
        names = self.model.coordinate_names
        if name in names:
            return names.index(name)
        self.coordinate_row(name)
        return None

    def coordinate_row(self, name: str) -> tuple[np.ndarray, float]:
        """``(s, c)`` with coordinate ``name`` equal to ``s · q + c`` (``model.coordinate``)."""
        try:
            return self.model.coordinate(name)
        except NcgenError:
            aside = "; coordinates as written before coordinate sharing resolve too" if self.model.unshared else ""
            raise OptimizationError(f"no coordinate named {name!r}; coordinates: "
                                    f"{', '.join(self.model.coordinate_names)}{aside}") from None

    def marker_index(self, name: str) -> int:
        names = self.model.marker_names
        if name not in names:
            known = ", ".join(names) or "none (add them with member.add_marker(name, local_point))"
            raise OptimizationError(f"no marker named {name!r}; markers: {known}")
        return names.index(name)

    # ----------------------------------------------------------------- bounds
    def bound_input(self, name: str, lower=-np.inf, upper=np.inf) -> "OptimalControl":
        """``lower ≤ u ≤ upper`` for input ``name`` (scalars or one value per component)."""
        idx = self.input_indices(name)
        self.u_bounds[:, idx] = _bound_pair(lower, upper, len(idx), f"input {name!r}")
        return self

    def bound_coordinate(self, name: str, lower=-np.inf, upper=np.inf) -> "OptimalControl":
        """``lower ≤ q_i ≤ upper`` (m) along the whole motion."""
        return self._bound_row("coordinate", self.q_bounds, name, lower, upper)

    def _bound_row(self, kind: str, bounds: np.ndarray, name: str, lower, upper) -> "OptimalControl":
        i = self.coordinate_index(name)
        pair = _bound_pair(lower, upper, 1, f"{kind} {name!r}")
        if i is not None:
            bounds[:, [i]] = pair
        else:
            s, c = self.coordinate_row(name)
            self.row_bounds = [b for b in self.row_bounds if b[:2] != (kind, name)]
            if np.any(np.isfinite(pair)):
                self.row_bounds.append((kind, name, s, c if kind == "coordinate" else 0.0, *pair[:, 0]))
        return self

    def bound_velocity(self, name: str, lower=-np.inf, upper=np.inf) -> "OptimalControl":
        """``lower ≤ q̇_i ≤ upper`` (m/s) along the whole motion."""
        return self._bound_row("velocity of", self.v_bounds, name, lower, upper)

    def bound_marker(self, name: str, lower=None, upper=None) -> "OptimalControl":
        """Path constraint ``lower ≤ r ≤ upper`` on a marker's world position (m); each
        bound is a ``dim``-vector whose ``None`` entries are unbounded."""
        self.marker_index(name)
        d = self.model.dim
        lo = _partial(lower, d, f"bound_marker {name!r}: lower", fill=-np.inf)
        hi = _partial(upper, d, f"bound_marker {name!r}: upper", fill=np.inf)
        if np.any(lo > hi):
            raise OptimizationError(f"bound_marker {name!r}: lower {lo.tolist()} exceeds upper {hi.tolist()}")
        self.marker_bounds.append((name, lo, hi))
        return self

    def min_tension(self, T_min) -> "OptimalControl":
        """Path constraint: every cable's pull ``P = k (l − l₀) + c l̇ ≥ T_min`` (N, ≥ 0) at both
        ends of every interval and at its path points, with the interval's input
        (:mod:`ncgen.optim.taut_cables`): the cables stay taut, so the plan never relies on the
        tension's cut at zero.  Refused on a model without cables."""
        from ncgen.optim.taut_cables import cable_indices, tension_floor
        value = tension_floor(T_min, "min_tension")
        cable_indices(self.model, "min_tension")
        self.cable_min_tension = value
        return self

    def bound_joint(self, name: str, lower=-np.inf, upper=np.inf, *, rate=None) -> "OptimalControl":
        """Path constraints on a joint with one coordinate: ``lower ≤ θ ≤ upper`` (rad or m)
        and, with ``rate``, ``|θ̇| ≤ rate`` (rad/s or m/s).  An angle bounded on both sides
        within a turn is measured on the turn centred on the bounds' middle (continuous over
        a range beyond ±π, as the Panda's joint 6: :func:`ncgen.optim.nlp.continuous_angle`)."""
        js = self.model.joint_space
        if name not in js.joint_names:
            raise OptimizationError(f"bound_joint: no joint with coordinates named {name!r}; joints: "
                                    f"{', '.join(js.joint_names) or 'none'}")
        if js.nq_joint[name] != 1:
            raise OptimizationError(f"bound_joint: joint {name!r} has {js.nq_joint[name]} coordinates; "
                                    "only one-coordinate joints (Revolute, Prismatic) can be bounded")
        lo, hi = (float(x) for x in _bound_pair(lower, upper, 1, f"joint {name!r}")[:, 0])
        if np.isfinite(lo) or np.isfinite(hi):
            self.joint_bounds.append((name, "position", lo, hi))
        if rate is not None:
            r = float(rate)
            if not r >= 0:
                raise OptimizationError(f"bound_joint {name!r}: rate: expected a bound ≥ 0, got {rate!r}")
            self.joint_bounds.append((name, "rate", -r, r))
        return self

    def joint_limits(self) -> "OptimalControl":
        """The model's joint limits (``model.joint_limits``, e.g. from a URDF) as bounds:
        positions and rates as path constraints (:meth:`bound_joint`), efforts as bounds on
        the input component that is the joint's effort (URDF: ``tau``)."""
        model = self.model
        js = model.joint_space
        effort_input = _effort_inputs(model)
        for name, lim in model.joint_limits.items():
            if js.nq_joint[name] == 1:
                self.bound_joint(name, lim.get("lower", -np.inf), lim.get("upper", np.inf),
                                 rate=lim.get("velocity"))
            if "effort" in lim and name in effort_input:
                i = effort_input[name]
                self.u_bounds[:, [i]] = _bound_pair(-lim["effort"], lim["effort"], 1, f"effort of joint {name!r}")
        return self

    def set_parameter(self, name: str, value) -> "OptimalControl":
        """Fix parameter ``name`` at ``value`` (instead of the model's default)."""
        idx = self.parameter_indices(name)
        self.p_values[idx] = _values(value, len(idx), f"parameter {name!r}")
        return self

    def free_parameter(self, name: str, lower=-np.inf, upper=np.inf, guess=None) -> "OptimalControl":
        """Make parameter ``name`` a decision variable (constant over the motion) with
        bounds; ``guess`` defaults to its current value (clipped into the bounds)."""
        idx = self.parameter_indices(name)
        lo, hi = _bound_pair(lower, upper, len(idx), f"parameter {name!r}")
        if guess is not None:
            self.p_values[idx] = _values(guess, len(idx), f"parameter {name!r}: guess")
        for k, i in enumerate(idx):
            self.p_free[i] = (float(lo[k]), float(hi[k]))
        return self

    # ------------------------------------------------------ boundary conditions
    def initial(self, q=None, v=None, marker=None, joints=None) -> "OptimalControl":
        """Initial conditions, ``None`` = free.  ``q``: a full configuration (projected onto
        the constraints) or ``{coordinate name: value}`` (those kept, the rest assembled
        from ``model.q0``); ``joints``: instead of ``q``, ``{joint name: coordinate(s)}``
        (rad or m, ``model.joint_space``; the other joints as in ``model.q0``, a closed
        loop assembled); ``v``: full rates, a scalar such as 0, or ``{name: rate}`` (the
        rest as small as the constraints allow); ``marker``: ``(name, position)`` or a list
        of them, ``None`` components free (needs a free ``q``)."""
        if joints is not None:
            if q is not None:
                raise OptimizationError("initial: give q or joints, not both")
            q = self._joint_configuration(joints, "initial joints")
        self.initial_spec = {"q": self._state(q, "initial q"), "v": self._state(v, "initial v"),
                             "markers": self._markers(marker, "initial")}
        if self.initial_spec["markers"] and self.initial_spec["q"] is not None:
            raise OptimizationError("initial: marker conditions need a free initial configuration; "
                                    "pass q=None together with marker=...")
        return self

    def final(self, q=None, v=None, marker=None, pose=None, joints=None) -> "OptimalControl":
        """Final conditions (``None`` = free): ``q``, ``v`` targets given as in
        :meth:`initial` (a dict ``q`` is assembled from the initial configuration; their
        ``dof`` tangent components are imposed), ``marker``: ``(name, position)`` or a list
        of them; ``pose``: ``{member name: (rotation, position)}`` — a member's frame
        (rotation body→world, 3×3, or an angle in planar systems; position of its origin,
        m: a body's centre of mass as given to ``add_body``), the other members left to the
        joints (:mod:`ncgen.optim.targets`); ``joints``: ``{joint name: coordinate(s)}`` (rad or
        m, ``model.joint_space``; angles reached in any winding, the other joints free; in a
        closed loop name independent joints only).  ``v`` without ``q`` is taken in the
        tangent space of the final configuration (the target's, else the guess's): exact for
        ``v=0``."""
        given = [k for k, x in (("q", q), ("pose", pose), ("joints", joints)) if x is not None]
        if len(given) > 1:
            raise OptimizationError(f"final: give one of q, pose, joints (got {', '.join(given)}): each fixes "
                                    "part of the configuration")
        if pose is not None and (not isinstance(pose, dict) or not pose):
            raise OptimizationError(f"final pose: expected {{member name: (rotation, position)}}, got {pose!r}")
        if joints is not None:
            self._joint_configuration(joints, "final joints")
        self.final_spec = {"q": self._state(q, "final q"), "v": self._state(v, "final v"),
                           "markers": self._markers(marker, "final"), "pose": pose, "joints": joints}
        self._check_periodic()
        return self

    def periodic(self, q: bool = True, v: bool = True) -> "OptimalControl":
        """The final state equals the initial one (tangent components); frees the initial
        state unless :meth:`initial` fixed it."""
        self.periodic_spec = {"q": bool(q), "v": bool(v)}
        if self.initial_spec["q"] is MODEL_STATE and q:
            self.initial_spec["q"] = None
        if self.initial_spec["v"] is MODEL_STATE and v:
            self.initial_spec["v"] = None
        self._check_periodic()
        return self

    def _check_periodic(self):
        for key in ("q", "v"):
            if self.periodic_spec[key] and (self.final_spec[key] is not None or key == "q" and (
                    self.final_spec.get("pose") is not None or self.final_spec.get("joints") is not None)):
                raise OptimizationError(f"final {key} and periodic {key} both given: the final {key} would "
                                        "be imposed twice; keep one of them")

    def _joint_configuration(self, joints, what: str) -> np.ndarray:
        """The configuration with these joint coordinates, the others as in ``model.q0``
        (checks the names and sizes)."""
        from ncgen.optim.targets import joint_target
        return joint_target(self.model, joints, self.model.q0, what=what).q_ref

    def _state(self, x, what: str):
        if x is None:
            return None
        if isinstance(x, dict):
            out = {}
            for name, value in x.items():
                self.coordinate_index(name)
                out[name] = float(_values(value, 1, f"{what}: {name}")[0])
            if not out:
                raise OptimizationError(f"{what}: an empty table; give coordinate values or None")
            return out
        if isinstance(x, str):
            raise OptimizationError(f"{what}: expected numbers or None, got {x!r}")
        a = _numbers(x, what, f"{self.model.nq} numbers")
        if a.ndim == 0:
            a = np.full(self.model.nq, float(a))
        names = self.model.coordinate_names
        if a.shape != (self.model.nq,):
            raise OptimizationError(f"{what}: expected {self.model.nq} finite numbers "
                                    f"({', '.join(names)}), got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            k = int(np.flatnonzero(~np.isfinite(a))[0])
            raise OptimizationError(f"{what}: expected {self.model.nq} finite numbers, got {a[k]} for {names[k]}")
        return a

    def _markers(self, spec, what: str) -> list[tuple[str, np.ndarray]]:
        if spec is None:
            return []
        if isinstance(spec, tuple) and len(spec) == 2 and isinstance(spec[0], str):
            spec = [spec]
        out = []
        for item in spec:
            if not (isinstance(item, (tuple, list)) and len(item) == 2 and isinstance(item[0], str)):
                raise OptimizationError(f"{what} marker: expected (name, position), got {item!r}")
            name, pos = item
            self.marker_index(name)
            target = _partial(pos, self.model.dim, f"{what} marker {name!r}", fill=np.nan)
            if np.all(np.isnan(target)):
                raise OptimizationError(f"{what} marker {name!r}: every component is None; give at least one")
            out.append((name, target))
        return out

    def guess_turn(self, member: str, axis) -> "OptimalControl":
        """In the interpolated guess, turn ``member`` the positive way about ``axis`` (a
        world direction in 3D, about which its rotation from the initial to the final pose
        must be; ``+1`` counter-clockwise or ``−1`` clockwise in a plane) instead of along
        the shortest arc."""
        if member not in self.model.member_names:
            raise OptimizationError(f"guess_turn: no member named {member!r}; members: "
                                    f"{', '.join(self.model.member_names)}")
        self.guess_turns[member] = axis
        return self

    # ------------------------------------------------------------------ costs
    def minimize_effort(self, weight=1.0) -> "OptimalControl":
        """Add ``∫ uᵀ R u dt``: ``weight`` a number (``R = weight I``), a dict of per-input
        weights (``{"force": 0.1}``, others 0) or an ``nu × nu`` matrix."""
        nu = self.model.nu
        if isinstance(weight, dict):
            R = np.zeros((nu, nu))
            for name, w in weight.items():
                idx = self.input_indices(name)
                R[idx, idx] = _values(w, len(idx), f"effort weight of {name!r}")
        else:
            w = np.asarray(weight, dtype=float)
            R = w * np.eye(nu) if w.ndim == 0 else w
        if R.shape != (nu, nu) or not np.allclose(R, R.T) or np.any(np.linalg.eigvalsh(R) < -1e-12):
            raise OptimizationError(f"minimize_effort: expected a non-negative weight or a symmetric positive "
                                    f"semidefinite {nu}×{nu} matrix, got {weight!r}")
        self.effort_R = R if self.effort_R is None else self.effort_R + R
        return self

    def track_marker(self, name: str, reference, weight: float = 1.0) -> "OptimalControl":
        """Add ``weight ∫ |r(t) − r_ref(t)|² dt`` (m²·s); ``reference``: a position or a
        callable ``t -> position`` (called with numbers; with a free final time with CasADi
        symbols, so use ``casadi`` functions in it)."""
        self.marker_index(name)
        if not callable(reference):
            reference = _values(reference, self.model.dim, f"track_marker {name!r}: reference")
        self.tracking.append((name, reference, _weight(weight, f"track_marker {name!r}")))
        return self

    def minimize_terminal(self, fn=None, *, marker=None, weight: float = 1.0) -> "OptimalControl":
        """Add a terminal cost: ``weight · fn(q_N, v_N, p)`` (a CasADi scalar), or with
        ``marker=(name, target)`` the squared distance ``weight |r(q_N) − target|²``."""
        w = _weight(weight, "minimize_terminal")
        if marker is not None:
            (name, target), = self._markers(marker, "minimize_terminal")
            self.terminal.append((f"terminal marker {name!r}", ("marker", name, target, w)))
        elif callable(fn):
            self.terminal.append((f"terminal cost {getattr(fn, '__name__', 'fn')}", ("fn", fn, w)))
        else:
            raise OptimizationError("minimize_terminal: give fn(q, v, p) or marker=(name, target)")
        return self

    def minimize_time(self, weight: float = 1.0) -> "OptimalControl":
        """Add ``weight · T``; needs a free final time (``t_final=(lower, upper)``)."""
        if self.t_final_bounds is None:
            raise OptimizationError("minimize_time: the final time is fixed; pass t_final=(lower, upper)")
        self.time_weight += _weight(weight, "minimize_time")
        return self

    # ------------------------------------------------------------------ solve
    def solve(self, warm_start=None, *, max_iter: int = 1000, tol: float = 1e-8, verbose: bool = False,
              ipopt: dict | None = None, linear_solver: str = "mumps", diagnose: float | bool = True,
              coarse_start: bool = False):
        """Solve with IPOPT and return an :class:`~ncgen.optim.result.OptimalTrajectory`.

        ``warm_start``: ``"rest"`` (the initial configuration held at rest by the inputs
        that hold it, clipped into their bounds), ``"interpolate"`` (every member's pose
        moved from the initial to the final configuration, at rest at the ends where the
        problem says so, inputs by inverse dynamics; the default when ``final(q=...)`` is
        given, else ``"rest"``), a simulation ``Trajectory`` or a previous solution (times
        rescaled to the horizon).  ``coarse_start``: first solve on ``N // 2`` intervals
        from that guess, then on ``N`` from the coarse solution.
        ``tol``: IPOPT's tolerance, also on the unscaled constraint violation (so the
        dynamics defects end below it); ``ipopt``: any IPOPT options, passed through
        (they override ncgen's); ``linear_solver``: IPOPT's KKT solver (``"mumps"``,
        ``"spral"``; ``"ma27"``, ``"ma57"``, ... with the HSL library).
        ``diagnose``: wall-clock seconds allowed for the relaxed re-solve that names the
        condition in conflict when IPOPT fails (``True``: 10 s, ``False``/0: skip it).
        Raises :class:`~ncgen.errors.OptimizationError` when IPOPT fails (with the last
        iterate as ``exc.result``)."""
        from ncgen.optim.diagnostics import DIAGNOSIS_BUDGET
        from ncgen.optim.ipopt_options import check_ipopt_options
        from ncgen.optim.nlp import build_and_solve
        if linear_solver not in LINEAR_SOLVERS:
            raise OptimizationError(f"linear_solver: expected one of {', '.join(LINEAR_SOLVERS)}, "
                                    f"got {linear_solver!r}")
        budget = DIAGNOSIS_BUDGET if diagnose is True else float(diagnose or 0.0)
        if budget < 0 or not np.isfinite(budget):
            raise OptimizationError(f"diagnose: expected True, False or a number of seconds ≥ 0, got {diagnose!r}")
        if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < 0:
            raise OptimizationError(f"max_iter: expected an integer ≥ 0, got {max_iter!r}")
        tol = as_scalar(tol, "tol")
        if tol <= 0:
            raise OptimizationError(f"tol: expected a number > 0, got {tol:g}")
        ipopt = check_ipopt_options(ipopt, "ipopt")
        options = dict(max_iter=int(max_iter), tol=tol, verbose=verbose, ipopt=ipopt,
                       linear_solver=linear_solver, diagnose_budget=budget)
        if coarse_start and self.N >= 2:
            coarse = copy.copy(self)
            coarse.N = self.N // 2
            warm_start = build_and_solve(coarse, warm_start, **options)
        return build_and_solve(self, warm_start, **options)

    def __repr__(self) -> str:
        T = self.t_final if self.t_final_bounds is None else f"free in {self.t_final_bounds}"
        return (f"<OptimalControl on {self.model.name!r}: N={self.N}, T={T}, "
                f"{self.transcription.describe()}>")


#: Collocation forms: ``"auto"`` picks ``"joint"`` for trees, ``"ggl"`` otherwise.
FORMS = ("auto", "joint", "ggl", "index3", "index1")


def _collocation(model, degree: int, form: str):
    from ncgen.optim.joint_radau import JointRadauCollocation, joint_space_reason
    from ncgen.optim.radau import RadauCollocation
    if form not in FORMS:
        raise OptimizationError(f"collocation form: expected one of {', '.join(FORMS)}, got {form!r}")
    try:
        if form in ("auto", "joint"):
            why = joint_space_reason(model)
            if why is None:
                return JointRadauCollocation(degree)
            if form == "joint":
                raise OptimizationError(f"form='joint': {why}; use form='ggl' (natural coordinates)")
            form = "ggl"
        return RadauCollocation(degree, form)
    except ValueError as exc:
        raise OptimizationError(str(exc)) from None


def _horizon(t_final):
    if np.ndim(t_final) == 0:
        T = float(t_final)
        if not np.isfinite(T) or T <= 0:
            raise OptimizationError(f"t_final: expected a positive duration (s), got {t_final!r}")
        return T, None
    b = np.asarray(t_final, dtype=float).reshape(-1)
    if b.size != 2 or not np.all(np.isfinite(b)) or not 0 < b[0] < b[1]:
        raise OptimizationError(f"t_final: expected a duration or (lower, upper) with 0 < lower < upper, "
                                f"got {t_final!r}")
    return float(b.mean()), (float(b[0]), float(b[1]))


def _indices(name: str, names: list[str], sizes: list[int], what: str) -> list[int]:
    m = re.fullmatch(r"([A-Za-z_]\w*)(?:\[(\d+)\])?", name) if isinstance(name, str) else None
    if m is None or m.group(1) not in names:
        raise OptimizationError(f"no {what} named {name!r}; {what}s: {', '.join(names) or 'none'}")
    i = names.index(m.group(1))
    start = int(sum(sizes[:i]))
    if m.group(2) is None:
        return list(range(start, start + sizes[i]))
    k = int(m.group(2))
    if k >= sizes[i]:
        raise OptimizationError(f"{what} {name!r}: {m.group(1)} has {sizes[i]} component(s)")
    return [start + k]


def _numbers(x, what: str, expected: str) -> np.ndarray:
    """``x`` as real numbers (:func:`ncgen.validation.as_numbers`), any shape."""
    try:
        return as_numbers(x, what, expected)
    except NcgenError as exc:
        raise OptimizationError(str(exc)) from None


def _values(x, n: int, what: str) -> np.ndarray:
    a = _numbers(x, what, f"{n} finite number(s)").reshape(-1)
    if a.size == 1:
        a = np.full(n, a[0])
    if a.size != n or not np.all(np.isfinite(a)):
        raise OptimizationError(f"{what}: expected {n} finite number(s), got {x!r}")
    return a


def _bound_pair(lower, upper, n: int, what: str) -> np.ndarray:
    out = []
    for b, name in ((lower, "lower"), (upper, "upper")):
        a = _numbers(-np.inf if b is None and name == "lower" else np.inf if b is None else b,
                     f"{what}: {name} bound", f"{n} number(s)").reshape(-1)
        if a.size == 1:
            a = np.full(n, a[0])
        if a.size != n or np.any(np.isnan(a)):
            raise OptimizationError(f"{what}: {name} bound: expected {n} number(s), got {b!r}")
        out.append(a)
    if np.any(out[0] > out[1]):
        raise OptimizationError(f"{what}: lower bound {out[0].tolist()} exceeds upper bound {out[1].tolist()}")
    return np.array(out)


def _partial(x, d: int, what: str, fill: float) -> np.ndarray:
    """A ``d``-vector whose ``None`` entries become ``fill``."""
    if x is None:
        return np.full(d, fill)
    items = list(x) if isinstance(x, (list, tuple, np.ndarray)) else None
    if items is None or len(items) != d:
        raise OptimizationError(f"{what}: expected {d} components (None where free), got {x!r}")
    try:
        given = [None if e is None else float(e) for e in items]
    except (TypeError, ValueError):
        given = [np.nan]
    if any(e is not None and not np.isfinite(e) for e in given):
        raise OptimizationError(f"{what}: components must be finite numbers or None, got {x!r}")
    return np.array([fill if e is None else e for e in given])


def _weight(w, what: str) -> float:
    w = float(w)
    if not np.isfinite(w) or w < 0:
        raise OptimizationError(f"{what}: weight: expected a non-negative number, got {w!r}")
    return w


def _effort_inputs(model) -> dict[str, int]:
    """``{joint: index in u}`` for the actuated joints whose effort is exactly one input
    component (τ = u_i), found by evaluating the actuation map at unit inputs."""
    js = model.joint_space
    if not js.actuated or model.nu == 0:
        return {}
    t, q, p = model.t0, model.q0, model.p0

    def tau(u):
        return np.array(js.actuation(t, q, u, p)[1]).reshape(-1)

    base = tau(np.zeros(model.nu))
    G = np.column_stack([tau(e) - base for e in np.eye(model.nu)])
    out, k = {}, 0
    for name in js.actuated:
        n = js.nv_joint[name]
        if n == 1 and base[k] == 0:
            row = G[k]
            hits = np.flatnonzero(row)
            if hits.size == 1 and row[hits[0]] == 1.0:
                out[name] = int(hits[0])
        k += n
    return out
