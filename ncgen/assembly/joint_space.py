"""Joint space of a model: joint coordinates in and out, joint actuators.

:class:`JointSpace` holds the CasADi functions of the joint coordinates
(:mod:`ncgen.assembly.joint_coordinates`) of every joint that has them, in model order
(``joint_names``), and the maps between the two spaces:

* :meth:`JointSpace.to_joint_space` — ``q_j = q_j(q)``, ``v_j = J(q) q̇``,
  ``a_j = J(q) q̈ + J̇(q, q̇) q̇`` (exact, any model).
* :meth:`JointSpace.from_joint_space` — the members' poses are propagated from the ground
  through the joints (a spanning tree; Fixed joints included): for a tree this is exact.
  Members left unreached and loop-closing joints are then settled by Newton on
  ``[Φ(q); q_j,given(q) − q_j,given] = 0`` (minimum-norm steps), so for closed loops the
  user names the independent joint coordinates (a dict) and the rest are assembled; the
  rates solve ``[A; J_given] q̇ = [−Φ_t; v_j,given]``.

Actuators: a joint with ``effort=`` (a number, text expression, input, callable of t) acts
with the generalised force ``J(q)ᵀ τ`` (:func:`actuator_forces`): torques in N·m about
its axis, forces in N along it, ``[f, τ]`` in B's frame for a free joint.
"""
from __future__ import annotations

import math
from collections import deque

import casadi as ca
import numpy as np

from ncgen.assembly.joint_coordinates import JointCoordinates, joint_coordinates
from ncgen.assembly.joint_tree import (
    Edge, carry, edge_of, quaternion_matrix, quaternion_rate, relative_pose, rotation_2d,
)
from ncgen.assembly.derived import constraint_residuals_function, state_check_function
from ncgen.assembly.manifold import NEWTON_TOL as TOL, newton, solve_linear, system_size
from ncgen.model.buffered_call import buffered
from ncgen.model.data import model_data
from ncgen.symbolic.coordinates import component_names, matrix_names
from ncgen.errors import ModelError
from ncgen.validation import MAX_MAGNITUDE, as_vector

#: Largest constraint residual (relative to the squared size of q, or to |q| |v| for rates)
#: of a state whose joint coordinates :meth:`JointSpace.to_joint_space` returns: loose enough
#: for any integrator's drift, far below a state that is not on the constraints at all.
OFF_MANIFOLD_TOL = 1e-4
#: Largest distance (relative to the size of q, as :data:`~ncgen.assembly.manifold.NEWTON_TOL`
#: is to its square) of a start's q from the tree's natural coordinates at its joint positions
#: that the tree library's start check accepts; its rates within ``TREE_V_TOL (1 + |v|∞)``.
#: The residuals (quadratic in q) grow by about ``2 |q|`` per unit of distance, so these are
#: :func:`_holding`'s tolerances in the coordinates' own units; rows with coefficients ~1/L (short
#: members) grow faster, so near the limits the two can differ: moved along one coordinate to this
#: distance, the Panda's start has residuals up to ~300 times :func:`_holding`'s (measured at
#: stop 60).  Either way a start is kept within this distance (relative) of a tree state: the C's
#: joint state is that state, CasADi's refusal projects onto the constraints.  Round-off of the
#: check on the Panda: 4e-14 and 2e-13.
TREE_Q_TOL = 1e-13
TREE_V_TOL = 1e-11
#: Starts that passed a joint run's start check kept per model (``JointSpace._checked_state``, ~1 µs
#: where the check costs ~30 µs on the Panda):
#: runs from one start (sweeps of tolerances, inputs, horizons) check it once.
KEPT_STARTS = 16


def build_joint_coordinates(system, ctx) -> tuple[list[JointCoordinates], dict[str, str]]:
    """The coordinates of every joint that has them, and ``{joint: why not}`` for the joints
    whose members cannot carry them (a spherical joint to a bar, ...)."""
    coords, skipped = [], {}
    for j in system.joints:
        try:
            c = joint_coordinates(ctx, j)
        except ModelError as e:
            if j.options.get("effort") is not None:
                raise
            skipped[j.name] = str(e)
            continue
        if c is not None:
            coords.append(c)
    return coords, skipped


def actuator_forces(ctx, coords: list[JointCoordinates]) -> tuple[ca.SX, ca.SX, list[str]]:
    """``(B, τ, names)``: ``B = [J_kᵀ ...]`` (nq × Σ nv_k) and the efforts ``τ`` of the
    actuated joints (``effort=`` given), so that their generalised force is ``B τ``."""
    Bs, taus, names = [], [], []
    for c in coords:
        effort = c.joint.options.get("effort")
        if effort is None:
            continue
        tau = ctx.expression(effort, c.nv, f"{c.joint.label}: effort (N·m or N, conjugate to "
                             f"{', '.join(c.rate_names)})")
        Bs.append(ca.jacobian(c.v, ctx.v).T)
        taus.append(tau)
        names.append(c.name)
    if not Bs:
        return ca.SX(ctx.layout.nq, 0), ca.SX(0, 1), []
    return ca.horzcat(*Bs), ca.vertcat(*taus), names


class JointSpace:
    """Joint coordinates of one model (built by :func:`ncgen.assembly.build.build_model`)."""

    def __init__(self, ctx, coords: list[JointCoordinates], skipped: dict[str, str], actuation, passive):
        q, v = ctx.q, ctx.v
        a = ca.SX.sym("a", ctx.layout.nq)
        self.dim = ctx.dim
        self.joint_names = [c.name for c in coords]
        self.nq_joint = {c.name: c.nq for c in coords}
        self.nv_joint = {c.name: c.nv for c in coords}
        self.position_names = [n for c in coords for n in c.position_names]
        self.rate_names = [n for c in coords for n in c.rate_names]
        self.angles = np.array([x for c in coords for x in c.angles], dtype=bool)
        self.skipped = dict(skipped)
        qj = ca.vertcat(*[c.q for c in coords]) if coords else ca.SX(0, 1)
        vj = ca.vertcat(*[c.v for c in coords]) if coords else ca.SX(0, 1)
        J = ca.jacobian(vj, v)
        bias = ca.jtimes(vj, q, v)
        self.positions = ca.Function("joint_positions", [q], [qj], ["q"], ["qj"])
        self.position_jacobian = ca.Function("joint_position_jacobian", [q], [ca.jacobian(qj, q)], ["q"], ["Jq"])
        self.rates = ca.Function("joint_rates", [q, v], [vj], ["q", "v"], ["vj"])
        self.jacobian = ca.Function("joint_jacobian", [q], [J], ["q"], ["J"])
        self.accelerations = ca.Function("joint_accelerations", [q, v, a], [ca.mtimes(J, a) + bias],
                                         ["q", "v", "a"], ["aj"])
        self.bias = ca.Function("joint_bias", [q, v], [bias], ["q", "v"], ["Jdot_v"])
        B, tau, self.actuated = actuation
        self.actuation = ca.Function("actuation", [ctx.t, q, ctx.u, ctx.p], [B, tau],
                                     ["t", "q", "u", "p"], ["B", "tau"])
        self.passive_force = ca.Function("passive_force", [ctx.t, q, v, ctx.u, ctx.p], [passive],
                                         ["t", "q", "v", "u", "p"], ["F"])
        self.edges = [edge_of(c.joint) for c in coords] + \
            [edge_of(j) for j in ctx.system.joints if j.kind == "Fixed" and "point" not in
             (getattr(j.A, "kind", "ground"), getattr(j.B, "kind", "ground"))]
        self.limits = {c.name: dict(c.joint.limits) for c in coords}
        self.members = dict(ctx.system.members)
        self.joints = {j.name: j for j in ctx.system.joints}

    # ------------------------------------------------------------ sizes
    @property
    def nq(self) -> int:
        return len(self.position_names)

    @property
    def nv(self) -> int:
        return len(self.rate_names)

    def slices(self, rates: bool = False) -> dict[str, slice]:
        """``{joint: slice}`` into the position (or rate) vector."""
        sizes = self.nv_joint if rates else self.nq_joint
        out, k = {}, 0
        for n in self.joint_names:
            out[n] = slice(k, k + sizes[n])
            k += sizes[n]
        return out

    def split(self, x, rates: bool = False) -> dict[str, np.ndarray]:
        """A joint-space vector as ``{joint: values}``."""
        x = np.asarray(x, float)
        return {n: x[..., s] for n, s in self.slices(rates).items()}

    # ------------------------------------------------------------ out
    def to_joint_space(self, model, q, v=None, a=None, *, t=None, p=None):
        """``q_j`` (and ``v_j``, ``a_j`` when ``v``, ``a`` are given), in ``joint_names`` order.
        Refuses a state off the constraints at time ``t`` (default ``model.t0``) by more than
        :data:`OFF_MANIFOLD_TOL` (relative; joint angles of such a state mean nothing)."""
        q = as_vector(q, model.nq, "q")
        v = None if v is None else as_vector(v, model.nq, "v")
        if a is not None and v is None:
            raise ModelError("to_joint_space: a: accelerations need the rates v too")
        t, p = (model.t0 if t is None else t), (model.p0 if p is None else as_vector(p, model.np, "p"))
        phi, vel = self._residuals(model, q, np.zeros(model.nq) if v is None else v, t, p)
        s = max(1.0, float(np.abs(q).max(initial=0.0)))
        off = float(np.abs(phi).max(initial=0.0))
        if off > OFF_MANIFOLD_TOL * s * s:
            raise ModelError(f"to_joint_space: q is off the constraints: max |Φ(q)| = {off:.3g} m² (accepted up "
                             f"to {OFF_MANIFOLD_TOL * s * s:.3g} m²); joint coordinates of such a state are "
                             "meaningless: project it onto the constraints first (nc.simulate and "
                             "model.from_joint_space give consistent states)")
        if v is None:
            return buffered(model, "joint_positions", lambda: self.positions).call(q)[0]
        w = max(1.0, float(np.abs(v).max(initial=0.0)))
        off = float(np.abs(vel).max(initial=0.0))
        if off > OFF_MANIFOLD_TOL * s * w:
            raise ModelError(f"to_joint_space: v is off the constraints: max |A v + Φ_t| = {off:.3g} m²/s "
                             f"(accepted up to {OFF_MANIFOLD_TOL * s * w:.3g} m²/s); project it first")
        qj, vj = self.state(model, q, v)
        if a is None:
            return qj, vj
        return qj, vj, np.array(self.accelerations(q, v, as_vector(a, model.nq, "a"))).reshape(-1)

    # ------------------------------------------------------------ in
    def _given(self, x, rates: bool, what: str) -> dict[str, np.ndarray]:
        sizes = self.nv_joint if rates else self.nq_joint
        if isinstance(x, dict):
            out = {}
            for name, val in x.items():
                if name not in sizes:
                    why = f" ({self.skipped[name]})" if name in self.skipped else ""
                    raise ModelError(f"{what}: no joint with coordinates named {name!r}{why}; joints: "
                                     f"{', '.join(self.joint_names) or 'none'}")
                out[name] = as_vector(np.atleast_1d(np.asarray(val, float)), sizes[name], f"{what}[{name!r}]")
            return out
        n = self.nv if rates else self.nq
        flat = as_vector(x, n, f"{what} (one value per joint coordinate, joint_names order; or a dict)")
        return {name: flat[s] for name, s in self.slices(rates).items()}

    def from_joint_space(self, model, qj, vj=None, *, t=None, p=None):
        """``(q, v)`` from joint positions (and rates; zero if not given), see the module
        docstring.  ``qj``, ``vj``: vectors in ``joint_names`` order or dicts ``{joint:
        value}`` naming the independent joints of a closed loop."""
        t = model.t0 if t is None else float(t)
        p = model.p0 if p is None else as_vector(p, model.np, "p")
        given = self._given(qj, False, "qj")
        for name, x in given.items():
            if self.nq_joint[name] in (4, 7) and self.dim == 3:      # unit quaternion, qw ≥ 0
                qn = x[-4:]
                n = np.linalg.norm(qn)
                if not n > 0:
                    raise ModelError(f"qj[{name!r}]: the quaternion [qx, qy, qz, qw] is zero")
                x[-4:] = qn / n * (1.0 if qn[3] >= 0 else -1.0)
        if len(given) == len(self.joint_names) and self._tree(model) is not None:
            rates = None if vj is None else self._given(vj, True, "vj")
            if rates is None or len(rates) == len(self.joint_names):
                x = np.concatenate([given[n] for n in self.joint_names])
                w = np.zeros(self.nv) if rates is None else np.concatenate([rates[n] for n in self.joint_names])
                q, v = (np.array(y).reshape(-1) for y in self._tree(model)(x, w))
                if self._holds(model, q, v, t, p):
                    return q, v
        q = self._propagate(model, given)
        q = self._settle(model, q, given, t, p)
        v = self._velocity(model, q, vj, given, t, p)
        return q, v

    def _tree(self, model):
        """The :meth:`tree_function` (built on first use, kept in ``model.data``), or None for a
        model that is not a tree."""
        data = model_data(model)
        if data.joint_tree_function is None:
            try:
                data.joint_tree_function = (self.tree_function(model.layout),)
            except ModelError:
                data.joint_tree_function = (None,)
        return data.joint_tree_function[0]

    @staticmethod
    def _residuals(model, q, v, t, p) -> tuple[np.ndarray, np.ndarray]:
        """``(Φ, A v + Φ_t)`` at ``t``: the residuals of both constraint levels (one call of
        :func:`~ncgen.assembly.derived.constraint_residuals_function`)."""
        return buffered(model, "constraint_residuals", lambda: constraint_residuals_function(model)).call(t, q, v, p)

    def state(self, model, q, v) -> tuple[np.ndarray, np.ndarray]:
        """``(q_j, v_j)`` of a state ``(q, v)`` known to be consistent (unchecked, one call of
        :meth:`positions` and :meth:`rates` together; :meth:`to_joint_space` checks)."""
        return buffered(model, "joint_state", lambda: self._state_function(model.nq)).call(q, v)

    def _state_function(self, nq: int) -> ca.Function:
        """``(q, v) -> (q_j, v_j)``: :meth:`positions` and :meth:`rates` in one function."""
        x, w = ca.SX.sym("q", nq), ca.SX.sym("v", nq)
        return ca.Function("joint_state", [x, w], [self.positions(x), self.rates(x, w)], ["q", "v"], ["qj", "vj"])

    @staticmethod
    def _holds(model, q, v, t, p) -> bool:
        """Whether ``(q, v)`` is finite, of magnitudes at most
        :data:`~ncgen.validation.MAX_MAGNITUDE`, and satisfies both constraint levels (drives
        included) to round-off; one call of :func:`~ncgen.assembly.derived.state_check_function`."""
        return _holding(buffered(model, "state_check", lambda: state_check_function(model)).call(t, q, v, p)[0])

    def _checked_state(self, model, q, v, t, p, tree=None) -> tuple[np.ndarray, np.ndarray] | None:
        """``(q_j, v_j)`` of ``(q, v)`` (as :meth:`state`) when it holds as :meth:`_holds`
        decides, else None: both in one call (a run's start in joint space; common
        subexpressions merged: 14 % fewer instructions on the Panda).  A tree whose joint run
        is on the tree library is checked first by its C (``tree``: a
        :class:`~ncgen.runtime.tree_library.TreeStart` or None, :func:`_tree_holding`, nothing
        compiled); a start it does not accept goes to the call above, which decides.  ``q``, ``v``, ``p``:
        float64 arrays.  A start that held is kept by its bytes (up to :data:`KEPT_STARTS`,
        then forgotten all at once): the same start again is answered from them, as the call
        would."""
        starts = model_data(model).checked_starts
        key = (float(t), q.tobytes(), v.tobytes(), p.tobytes())
        hit = starts.get(key)
        if hit is not None:
            return hit[0].copy(), hit[1].copy()
        if tree is not None:
            check, qj, vj = tree(q, v)
            if _tree_holding(check):
                return _kept(starts, key, qj, vj)

        def make():
            f = state_check_function(model)
            t_, q_, v_, p_ = f.sx_in()
            qj, vj = self._state_function(model.nq)(q_, v_)
            return ca.Function("start_check", [t_, q_, v_, p_], [f(t_, q_, v_, p_), qj, vj], {"cse": True})

        check, qj, vj = buffered(model, "start_check", make).call(t, q, v, p)
        if not _holding(check):
            return None
        return _kept(starts, key, qj, vj)

    def initial_state(self, model, positions: dict, rates: dict):
        """``(q, v)`` of a joint-space initial state: the named joints' positions and rates,
        the others as in ``(model.q0, model.v0)`` (a closed loop: only the named ones)."""
        t, p = model.t0, model.p0
        given = self._given(dict(positions), False, "initial")
        q = self._settle(model, self._propagate(model, given), given, t, p)
        named = self._given(dict(rates), True, "initial_rates")
        full = self.split(np.array(self.rates(model.q0, model.v0)).reshape(-1), rates=True)
        try:
            return q, self._velocity(model, q, {**full, **named}, given, t, p)
        except ModelError:
            if not named:
                return q, self._velocity(model, q, None, given, t, p)
            return q, self._velocity(model, q, named, given, t, p)

    # ------------------------------------------------------------ symbolic tree map
    def tree_function(self, layout) -> ca.Function:
        """``(qj, vj) -> (q, v)`` as an SX function, for models whose members are all
        reached from the ground through the joints with coordinates and Fixed joints and
        have no other constraints between them (trees): the poses of :meth:`from_joint_space`
        written symbolically, ``q̇ = (∂q/∂q_j) q̇_j`` with ``q̇_j`` from the rates (quaternion
        rates ``½ q ⊗ [ω; 0]``, free-joint translation ``R v``).  Raises :class:`ModelError`
        for other models."""
        qj, vj, q, qj_dot = self.tree_map(layout)
        v = ca.jtimes(q, qj, qj_dot) if self.nv else ca.SX.zeros(layout.nq)
        return ca.Function("joint_tree", [qj, vj], [q, v], ["qj", "vj"], ["q", "v"])

    def spanning_tree(self) -> list[tuple[str, str, Edge, bool]]:
        """``(here, there, edge, forward)`` for every joint of a tree, breadth-first from the
        ground (``forward``: ``here`` is the joint's A).  Raises :class:`ModelError` when a
        member is not reached or a joint closes a loop."""
        out = list(_walk(self.edges))
        reached = {"ground"} | {there for _, there, _, _ in out}
        missing = [n for n in self.members if n not in reached]
        if missing or len(out) != len(self.edges):
            raise ModelError(f"joint space: the model is not a tree of joints with coordinates "
                             f"({'members not reached from the ground: ' + ', '.join(missing) if missing else 'a closed loop'}); "
                             "use from_joint_space (Newton) instead")
        return out

    def position_rates(self, name: str, x, w):
        """``q̇_j`` of joint ``name`` from its positions ``x`` and rates ``w`` (SX):
        quaternion rates ``½ q ⊗ [ω; 0]``, free-joint translation ``R v``, else ``w``."""
        return joint_position_rates(self.joints[name].kind, self.dim, self.nq_joint[name], x, w)

    def tree_map(self, layout) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
        """``(qj, vj, q, q̇_j)``: the symbols of the joint positions and rates, the natural
        coordinates ``q(q_j)`` and the position rates ``q̇_j(q_j, v_j)`` as SX (see
        :meth:`tree_function`; raises :class:`ModelError` for a model that is not a tree)."""
        d = self.dim
        qj, vj = ca.SX.sym("qj", self.nq), ca.SX.sym("vj", self.nv)
        sq, sv = self.slices(), self.slices(rates=True)
        poses = {"ground": (ca.SX.eye(d), ca.SX.zeros(d, 1))}
        for here, there, e, forward in self.spanning_tree():
            x = qj[sq[e.name]] if e.name in sq else ca.SX(0, 1)
            T = relative_pose(e, x, d, sym=True)
            poses[there] = carry(poses[here], e, T, forward, self.members, sym=True)
        q = [None] * layout.nq
        for name, (R, pos) in poses.items():
            if name == "ground":
                continue
            local = self.member_coordinates(name, R, pos)
            for k, i in enumerate(layout.member_indices(name)):
                if i is not None and q[i] is None:
                    q[i] = local[k]
        q = ca.vertcat(*q)
        qj_dot = [self.position_rates(n, qj[sq[n]], vj[sv[n]]) for n in self.joint_names]
        return qj, vj, q, ca.vertcat(*qj_dot) if qj_dot else ca.SX(0, 1)

    def member_coordinates(self, name: str, R, pos):
        """The natural coordinates of member ``name`` (its own slots) at the pose ``(R, pos)``
        of its frame (SX)."""
        m = self.members[name]
        d = self.dim
        vals = dict(m.rigid.constant_values)
        vals.update({n: R[a, b] for a, row in enumerate(matrix_names("R", d)) for b, n in enumerate(row)})
        vals.update(zip(component_names("p", d), (pos[a] for a in range(d))))
        from ncgen.model.member_forms import FORMS   # generated; a stored model never needs it
        return FORMS[m.ctype.name, d, "q_of_pose"](vals)

    def _propagate(self, model, given) -> np.ndarray:
        """Poses from the ground through the spanning tree; unreached members keep q0."""
        data = model_data(model)
        if data.joint_positions0 is None:
            data.joint_positions0 = self.split(np.array(self.positions(model.q0)).reshape(-1))
        values = {**data.joint_positions0, **given}
        members = self.members
        poses = {"ground": (np.eye(self.dim), np.zeros(self.dim))}
        for here, there, e, forward in _walk(self.edges):
            T = relative_pose(e, values.get(e.name, np.zeros(0)), self.dim)
            poses[there] = carry(poses[here], e, T, forward, members)
        q = model.q0.copy()
        for name, (R, pos) in poses.items():
            if name == "ground":
                continue
            m = members[name]
            local = m.rigid.q_from_pose(R, pos)
            for k, i in enumerate(model.layout.member_indices(name)):
                if i is not None:
                    q[i] = local[k]
        return q

    def _conflict(self, model, r, rows) -> str:
        """The equations left off by a least-squares compromise, in row order (constraints,
        then given joint coordinates): every row within half of the worst. Equations that
        contradict each other share the residual almost equally, so naming only the largest
        would pick one of them by rounding."""
        names = model.constraint_names + [self.position_names[i] for i in rows]
        off = np.abs(r)
        if not np.all(np.isfinite(off)):
            return "the residual is not finite at " + ", ".join(
                n for n, x in zip(names, off) if not np.isfinite(x))
        worst = off.max()
        return "still off: " + ", ".join(f"{n} by {x:.3g}" for n, x in zip(names, off) if x >= 0.5 * worst)

    def _settle(self, model, q, given, t, p) -> np.ndarray:
        rows = np.concatenate([np.arange(s.start, s.stop) for n, s in self.slices().items() if n in given]
                              ).astype(int) if given else np.zeros(0, int)
        target = np.concatenate([given[n] for n in self.joint_names if n in given]) if given else np.zeros(0)
        wrap = self.angles[rows]
        f = model.functions

        def residual(x):
            d = np.array(self.positions(x)).reshape(-1)[rows] - target
            d[wrap] = (d[wrap] + np.pi) % (2 * np.pi) - np.pi
            return np.concatenate([np.array(f["phi"](t, x, p)).reshape(-1), d])

        def jac(x):
            return np.vstack([np.array(f["A"](t, x, p)), np.array(self.position_jacobian(x))[rows]])

        size = system_size(q)
        tol = TOL * size**2
        q_new, it, res = newton(residual, jac, q, np.arange(model.nq), tol=tol)
        if not res <= tol:
            raise ModelError(
                f"from_joint_space: no configuration has these joint coordinates: after {it} Newton "
                f"iterations {self._conflict(model, residual(q_new), rows)}; in a closed loop give "
                f"only independent joint coordinates as a dict {{joint: value}} (the others are assembled)")
        return q_new

    def _velocity(self, model, q, vj, given, t, p) -> np.ndarray:
        f = model.functions
        A = np.array(f["A"](t, q, p))
        phi_t = np.array(f["phi_t"](t, q, p)).reshape(-1)
        sl = self.slices(rates=True)
        if vj is None:
            rates = {n: np.zeros(self.nv_joint[n]) for n in given}
        else:
            rates = self._given(vj, True, "vj")
        rows = np.concatenate([np.arange(sl[n].start, sl[n].stop) for n in self.joint_names if n in rates]
                              ).astype(int) if rates else np.zeros(0, int)
        target = np.concatenate([rates[n] for n in self.joint_names if n in rates]) if rates else np.zeros(0)
        K = np.vstack([A, np.array(self.jacobian(q))[rows]])
        b = np.concatenate([-phi_t, target])
        v = solve_linear(K, b)
        if v is None or K.shape[0] < model.nq:
            raise ModelError(f"from_joint_space: the rates of joints {', '.join(rates) or 'none'} do not "
                             f"determine the velocity uniquely, or contradict the constraints (closed loop?); "
                             f"give the rates of every joint of a tree ({', '.join(self.joint_names)}), "
                             "or of independent joints only")
        return v


def _walk(edges):
    """``(here, there, edge, forward)`` breadth-first from the ground through the joints
    ``edges``, each member reached once (the first way found), across passable edges only
    (:func:`_passable`)."""
    adjacent: dict[str, list[tuple[Edge, bool]]] = {}
    for e in edges:
        adjacent.setdefault(e.A, []).append((e, True))
        adjacent.setdefault(e.B, []).append((e, False))
    reached, queue, spinless = {"ground"}, deque(["ground"]), set()
    while queue:
        here = queue.popleft()
        for e, forward in adjacent.get(here, []):
            there = e.B if forward else e.A
            if there in reached or not _passable(e, forward, here, spinless):
                continue
            reached.add(there)
            yield here, there, e, forward
            queue.append(there)


def _passable(e: Edge, forward: bool, here: str, spinless: set) -> bool:
    """Whether the tree walk may carry a pose across ``e`` from ``here``: not out of a bar
    reached through a one-way edge (its spin is not known), and a one-way edge only from its
    full member to the bar (which is then marked ``spinless``)."""
    if here in spinless or (e.one_way and not forward):
        return False
    if e.one_way:
        spinless.add(e.B)
    return True


def joint_position_rates(kind: str, dim: int, nq: int, x, w):
    """``q̇_j`` of a joint of ``kind`` with ``nq`` positions ``x`` and rates ``w`` (SX):
    quaternion rates ``½ q ⊗ [ω; 0]``, free-joint translation ``R v``, else ``w``."""
    if kind == "Spherical" and nq == 4:      # a quaternion (not a bar's swing)
        return quaternion_rate(x, w)
    if kind == "Free" and dim == 3:
        R = quaternion_matrix(x[3:], sym=True)
        return ca.vertcat(ca.mtimes(R, w[:3]), quaternion_rate(x[3:], w[3:]))
    if kind == "Free":
        return ca.vertcat(ca.mtimes(rotation_2d(x[2], sym=True), w[:2]), w[2])
    return w


def _kept(starts: dict, key, qj: np.ndarray, vj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(qj, vj)``, a copy kept in ``starts`` under ``key`` (up to :data:`KEPT_STARTS`, then
    all forgotten at once)."""
    if len(starts) >= KEPT_STARTS:
        starts.clear()
    starts[key] = (qj.copy(), vj.copy())
    return qj, vj


def _tree_holding(check: np.ndarray) -> bool:
    """Whether the tree library's start check (``check = [max |q − q(q_j)|, max |v − v(q_j,
    v_j)|, |q|∞, |v|∞, s]``) accepts: finite, magnitudes at most
    :data:`~ncgen.validation.MAX_MAGNITUDE`, ``q`` within :data:`TREE_Q_TOL` (relative to its
    size) and ``v`` within :data:`TREE_V_TOL` ``(1 + |v|∞)`` of the tree's coordinates at its
    joint state."""
    e_q, e_v, q_max, v_max, probe = check.tolist()
    return (math.isfinite(probe) and q_max <= MAX_MAGNITUDE and v_max <= MAX_MAGNITUDE
            and e_q <= TREE_Q_TOL * max(1.0, q_max) and e_v <= TREE_V_TOL * (1.0 + v_max))


def _holding(check: np.ndarray) -> bool:
    """The decision of :meth:`JointSpace._holds` from the check vector of
    :func:`~ncgen.assembly.derived.state_check_function`."""
    phi, vel, q_max, v_max, probe = check.tolist()
    size = max(1.0, q_max)
    return (math.isfinite(probe) and q_max <= MAX_MAGNITUDE and v_max <= MAX_MAGNITUDE
            and phi <= TOL * size**2 and vel <= 1e-10 * size * (1.0 + v_max))
