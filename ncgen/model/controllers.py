"""Controllers compiled into the joint-space simulation loop (no Python per step).

A controller is a law ``u = κ(t, q_j, v_j, p)`` written in CasADi and generated into the
same C as the dynamics (:func:`ncgen.assembly.joint_ode.joint_ode_function`).  Joint space:
``q_j``, ``v_j`` in ``model.joint_names`` order (a free joint's ``[x, y, z, qx, qy, qz, qw]``
and body-frame ``[v, ω]``).

* :class:`PD` — ``τ = K_p (q* − q_j) + K_d (v* − v_j)`` on the actuated joints;
* :class:`ComputedTorque` — ``τ = M_j(q_j) (a* + K_p (q* − q_j) + K_d (v* − v_j)) + C(q_j, v_j)``
  (inverse dynamics of the model, gravity and passive forces included): the tracking error
  then obeys ``ë + K_d ė + K_p e = 0`` exactly on a fixed-base robot whose every joint is
  actuated;
* :class:`Controller` — any law: ``law(t, qj, vj, p)`` returning the model's ``nu`` inputs
  as CasADi SX (or a ``casadi.Function`` with those four inputs).

PD and computed torque produce efforts of the actuated joints (``model.actuated_joints``
order, one per joint rate); they reach the inputs through each joint's own input (a joint
whose effort is one input component, as from a URDF; others are refused by name).  Gains
``kp``, ``kd`` are scalars or one value per actuated joint rate; targets ``target`` (q*),
``rate`` (v*), ``acceleration`` (a*) are numbers, vectors (one per actuated joint rate),
dicts ``{joint: value}`` (others: 0) or callables of ``t`` returning such a vector as CasADi
SX (a trajectory to track).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.errors import ModelError
from ncgen.validation import as_numbers

KINDS = ("pd", "computed_torque", "expression")
#: The arguments of PD and computed torque that are gains (finite and >= 0).
GAINS = ("kp", "kd")


class Controller:
    """``u = law(t, qj, vj, p)`` (see the module docstring); ``name`` for reports."""

    kind = "expression"

    def __init__(self, law, *, name: str | None = None):
        if not (callable(law) or isinstance(law, ca.Function)):
            raise ModelError(f"Controller: law: expected a callable (t, qj, vj, p) -> u or a casadi.Function, "
                             f"got {type(law).__name__}")
        self.law = law
        self.name = name or "controller"

    def inputs(self, model, t, qj, vj, p, *, efforts_to_inputs, inverse_dynamics) -> ca.SX:
        """The inputs ``u`` (SX, ``model.nu``) at the symbols ``t, qj, vj, p``."""
        try:
            u = self.law(t, qj, vj, p)
            u = u[0] if isinstance(self.law, ca.Function) and isinstance(u, (list, tuple)) else u
            u = ca.vertcat(*u) if isinstance(u, (list, tuple)) else ca.SX(u)
        except Exception as e:      # noqa: BLE001 - the user's law: report it, named
            raise ModelError(f"{self.name}: law(t, qj, vj, p) failed on CasADi symbols "
                             f"(qj: {qj.numel()}, vj: {vj.numel()} values): {type(e).__name__}: {e}") from None
        if u.numel() != model.nu:
            raise ModelError(f"{self.name}: law(t, qj, vj, p) returned {u.numel()} values; model {model.name!r} "
                             f"has {model.nu} inputs ({', '.join(model.input_names)})")
        return ca.reshape(u, model.nu, 1)

    def describe(self) -> str:
        return f"{self.kind} ({self.name})"


class PD(Controller):
    """``τ = kp (target − q_j) + kd (rate − v_j)`` on the actuated joints (module docstring)."""

    kind = "pd"

    def __init__(self, kp, kd, target=0.0, rate=0.0, *, name: str | None = None):
        self.name = name or self.kind
        self.kp, self.kd, self.target, self.rate = (
            checked_value(v, f"{self.name}: {k}", gain=k in GAINS)
            for k, v in (("kp", kp), ("kd", kd), ("target", target), ("rate", rate)))

    def _vector(self, model, value, what: str, t) -> ca.SX:
        js, n = model.joint_space, _actuated_rates(model)
        if callable(value):
            try:
                value = value(t)
            except Exception as e:      # noqa: BLE001
                raise ModelError(f"{self.name}: {what}(t) failed on a CasADi symbol: {type(e).__name__}: {e}") from None
            out = ca.vertcat(*value) if isinstance(value, (list, tuple)) else ca.SX(value)
        elif isinstance(value, dict):
            full = np.zeros(n)
            offsets = _actuated_offsets(model)
            for name, x in value.items():
                if name not in offsets:
                    raise ModelError(f"{self.name}: {what}: {name!r} is not an actuated joint; actuated: "
                                     f"{', '.join(js.actuated) or 'none'}")
                s = offsets[name]
                full[s] = np.asarray(x, float).reshape(-1)
            out = ca.SX(ca.DM(full))
        else:
            arr = np.asarray(value, dtype=float).reshape(-1)
            if arr.size == 1:
                arr = np.full(n, float(arr[0]))
            out = ca.SX(ca.DM(arr))
        if out.numel() != n:
            raise ModelError(f"{self.name}: {what}: expected a scalar or {n} values (one per actuated joint rate: "
                             f"{', '.join(js.actuated)}), got {out.numel()}")
        return ca.reshape(out, n, 1)

    def error(self, model, t, qj, vj, p):
        """``(e, ė)``: ``target − q_j`` and ``rate − v_j`` on the actuated joints' rates."""
        rows_q, rows_v = _actuated_rows(model)
        for name in model.joint_space.actuated:
            if model.joint_space.nq_joint[name] != model.joint_space.nv_joint[name]:
                raise ModelError(f"{self.name}: joint {name!r} has {model.joint_space.nq_joint[name]} positions "
                                 f"but {model.joint_space.nv_joint[name]} rates; PD and computed torque take "
                                 "joints whose positions are their rates' integrals (revolute, prismatic, ...)")
        e = self._vector(model, self.target, "target", t) - qj[rows_q]
        ed = self._vector(model, self.rate, "rate", t) - vj[rows_v]
        return e, ed

    def efforts(self, model, t, qj, vj, p, inverse_dynamics) -> ca.SX:
        e, ed = self.error(model, t, qj, vj, p)
        return self._vector(model, self.kp, "kp", t) * e + self._vector(model, self.kd, "kd", t) * ed

    def inputs(self, model, t, qj, vj, p, *, efforts_to_inputs, inverse_dynamics) -> ca.SX:
        return efforts_to_inputs(self.efforts(model, t, qj, vj, p, inverse_dynamics))


class ComputedTorque(PD):
    """``τ = ID(q_j, v_j, acceleration + kp e + kd ė)`` (module docstring)."""

    kind = "computed_torque"

    def __init__(self, kp, kd, target=0.0, rate=0.0, acceleration=0.0, *, name: str | None = None):
        super().__init__(kp, kd, target, rate, name=name)
        self.acceleration = checked_value(acceleration, f"{self.name}: acceleration", gain=False)

    def efforts(self, model, t, qj, vj, p, inverse_dynamics) -> ca.SX:
        js = model.joint_space
        if len(js.actuated) != len(js.joint_names):
            free = [n for n in js.joint_names if n not in js.actuated]
            raise ModelError(f"{self.name}: computed torque needs every joint actuated; not actuated: "
                             f"{', '.join(free)} (use PD, or a Controller law)")
        e, ed = self.error(model, t, qj, vj, p)
        a = self._vector(model, self.acceleration, "acceleration", t) \
            + self._vector(model, self.kp, "kp", t) * e + self._vector(model, self.kd, "kd", t) * ed
        _, rows_v = _actuated_rows(model)
        aj = ca.SX.zeros(js.nv)
        aj[rows_v] = a
        return inverse_dynamics(aj)[rows_v]


def checked_value(value, what: str, *, gain: bool):
    """``value`` (a gain, a target, ...) if it is a callable of ``t``, or finite numbers (a
    scalar, a vector, or a dict of them by joint), and for a gain (``kp``, ``kd``) none negative:
    a negative gain drives the joint away from its target."""
    if callable(value):
        return value
    for key, x in (value.items() if isinstance(value, dict) else [(None, value)]):
        label = what if key is None else f"{what}[{key!r}]"
        expected = "a number, one per actuated joint rate, a dict by joint or a function of t"
        if isinstance(x, (str, bytes)):
            raise ModelError(f"{label}: expected {expected}, got the text {x!r}")
        a = as_numbers(x, label, expected)
        if a.size == 0 or not np.all(np.isfinite(a)):
            raise ModelError(f"{label}: expected finite numbers, got {a.tolist()}")
        if gain and np.any(a < 0):
            raise ModelError(f"{label}: expected gains >= 0 (a negative gain drives the joint away from its "
                             f"target), got {a.tolist()}")
    return value


def _actuated_rates(model) -> int:
    js = model.joint_space
    return sum(js.nv_joint[n] for n in js.actuated)


def _actuated_offsets(model) -> dict:
    """``{joint: slice}`` into the vector of the actuated joints' rates."""
    js, out, k = model.joint_space, {}, 0
    for n in js.actuated:
        out[n] = slice(k, k + js.nv_joint[n])
        k += js.nv_joint[n]
    return out


def _actuated_rows(model) -> tuple[list[int], list[int]]:
    """Rows of the actuated joints in ``q_j`` and in ``v_j``."""
    js = model.joint_space
    sq, sv = js.slices(), js.slices(rates=True)
    rq = [i for n in js.actuated for i in range(sq[n].start, sq[n].stop)]
    rv = [i for n in js.actuated for i in range(sv[n].start, sv[n].stop)]
    return rq, rv


def controller_from_dict(data: dict, where: str = "controller") -> Controller:
    """A :class:`PD` or :class:`ComputedTorque` from TOML-like data: ``kind`` (``"pd"`` or
    ``"computed_torque"``), ``kp``, ``kd``, ``target``, ``rate`` (and ``acceleration``)."""
    if not isinstance(data, dict):
        raise ModelError(f"{where}: expected a table, got {type(data).__name__}")
    kind = data.get("kind")
    allowed = {"pd": ("kind", "kp", "kd", "target", "rate"),
               "computed_torque": ("kind", "kp", "kd", "target", "rate", "acceleration")}
    if kind not in allowed:
        raise ModelError(f"{where}.kind: expected 'pd' or 'computed_torque', got {kind!r}")
    extra = [k for k in data if k not in allowed[kind]]
    if extra:
        raise ModelError(f"{where}: unknown key(s) {', '.join(extra)}; expected {', '.join(allowed[kind])}")
    for key in ("kp", "kd"):
        if key not in data:
            raise ModelError(f"{where}.{key}: missing (a number or one per actuated joint rate)")
    args = {k: checked_value(data[k], f"{where}.{k}", gain=k in GAINS) for k in allowed[kind][1:] if k in data}
    return PD(**args) if kind == "pd" else ComputedTorque(**args)


def controller_to_dict(c: Controller) -> dict:
    """The TOML table of a :class:`PD` or :class:`ComputedTorque` with plain (numeric) gains and
    targets; other controllers cannot be written (a :class:`ModelError` says so)."""
    if not isinstance(c, PD):
        raise ModelError(f"{c.name}: only PD and computed-torque controllers can be written to TOML "
                         f"(a {c.kind} law is Python code)")
    keys = ("kp", "kd", "target", "rate") + (("acceleration",) if isinstance(c, ComputedTorque) else ())
    out = {"kind": c.kind}
    for k in keys:
        v = getattr(c, k)
        if callable(v):
            raise ModelError(f"{c.name}: {k} is a function of time, which TOML cannot hold")
        if isinstance(v, dict):
            out[k] = {n: np.asarray(x, float).tolist() for n, x in v.items()}
        else:
            arr = np.asarray(v, float)
            out[k] = float(arr) if arr.ndim == 0 else arr.reshape(-1).tolist()
    return out
