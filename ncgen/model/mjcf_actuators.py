"""MJCF actuators: MuJoCo's force law of each actuator on its joint or fixed tendon, and a
compiled controller that applies them.

MuJoCo's actuator ``i`` (no activation dynamics) has the length ``L_i = Σ_k m_ik qpos_k`` and
rate ``L̇_i = Σ_k m_ik q̇_k`` with the moment arms ``m_ik`` (``gear`` on a joint, ``gear ×
coef_k`` on a fixed tendon: the columns of ``system.actuator_gear``; MuJoCo's ``qpos_k`` is
ncgen's coordinate plus the joint's ``ref``).  Its scalar force (N or N·m) is

    ``f_i = clamp(gain_i u_i + bias_i, forcerange)``,  ``u_i = clamp(ctrl_i, ctrlrange)``,
    ``gain = g0 + g1 L + g2 L̇`` (``gaintype="affine"``; ``"fixed"``: ``g0``),
    ``bias = b0 + b1 L + b2 L̇`` (``biastype="affine"``; ``"none"``: 0),

and the generalised force on coordinate ``k`` is ``τ_k = Σ_i m_ik f_i``, clamped to the
joint's ``actuatorfrcrange`` when it has one.  The shortcuts set ``g`` and ``b``:
``motor`` ``g = (1)``; ``position`` (``kp``, ``kv``) ``g = (kp)``, ``b = (0, −kp, −kv)`` —
the PD law ``kp (u − L) − kv L̇``; ``velocity`` (``kv``) ``g = (kv)``, ``b = (0, 0, −kv)``;
``damper`` (``kv``) ``g = (0, 0, −kv)``.  A clamp applies where the element is limited
(``ctrllimited``/``forcelimited`` true, or auto with the range given); a ``position``'s
``inheritrange`` r sets its ``ctrlrange`` to its joint's range scaled by r about the centre.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ncgen.errors import ModelError
from ncgen.model.controllers import Controller
from ncgen.model.mjcf_xml import number, numbers, where

#: The actuator elements the import takes (others are unsupported).
KINDS = ("motor", "position", "velocity", "damper", "general")


@dataclass
class Actuator:
    """One MJCF actuator: ``gain``, ``bias`` (3 coefficients each, on ``(1, L, L̇)``), the
    ``ctrlrange`` and ``forcerange`` clamps (None: not limited); a position servo's
    ``inheritrange`` (> 0: its ``ctrlrange`` is its joint's range scaled about the centre,
    :func:`inherited_range`)."""

    name: str
    gain: tuple
    bias: tuple
    ctrlrange: tuple | None
    forcerange: tuple | None
    inheritrange: float = 0.0


def _limited(attrs: dict, flag: str, key: str, el) -> tuple | None:
    value = attrs.get(flag, "auto")
    if value == "false" or (value == "auto" and key not in attrs):
        return None
    lo, hi = numbers(el, attrs, key, 2, default=(0, 0))
    if lo > hi:
        raise ModelError(f"MJCF {where(el)}: <{el.tag} {key}={attrs[key]!r}>: the lower bound is above the upper")
    return float(lo), float(hi)


def actuator_law(el, attrs: dict, name: str) -> tuple[Actuator | None, str | None]:
    """``(Actuator, None)`` for an element of :data:`KINDS` that MuJoCo computes without
    activation state, or ``(None, why it is not imported)``."""
    tag = el.tag
    if tag not in KINDS:
        return None, f"actuator {tag} {name!r} (only {', '.join(KINDS)} are imported)"
    if tag == "general":
        dyn, gtype, btype = (attrs.get(k, d) for k, d in (("dyntype", "none"), ("gaintype", "fixed"),
                                                          ("biastype", "none")))
        if dyn != "none" or gtype not in ("fixed", "affine") or btype not in ("none", "affine"):
            return None, (f"actuator {name!r} (dyntype={dyn!r}, gaintype={gtype!r}, biastype={btype!r}: only "
                          "dyntype none, gaintype fixed/affine and biastype none/affine are imported)")
        g = np.r_[numbers(el, attrs, "gainprm", None, default=(1.0,)), np.zeros(3)][:3]
        b = np.r_[numbers(el, attrs, "biasprm", None, default=(0.0,)), np.zeros(3)][:3]
        if gtype == "fixed":
            g[1:] = 0.0
        if btype == "none":
            b[:] = 0.0
    else:
        for key in ("timeconst", "dampratio"):
            if tag == "position" and number(el, attrs, key, 0.0) != 0:
                return None, f"actuator {name!r}: {key} (activation dynamics or derived gains are not imported)"
        kp = number(el, attrs, "kp", 1.0)
        kv = number(el, attrs, "kv", 0.0 if tag == "position" else 1.0)
        g, b = {"motor": ((1.0, 0, 0), (0, 0, 0)), "position": ((kp, 0, 0), (0, -kp, -kv)),
                "velocity": ((kv, 0, 0), (0, 0, -kv)), "damper": ((0, 0, -kv), (0, 0, 0))}[tag]
    inherit = number(el, attrs, "inheritrange", 0.0) if tag == "position" else 0.0
    if inherit < 0:
        raise ModelError(f"MJCF {where(el)}: <position inheritrange={attrs['inheritrange']!r}>: expected a number ≥ 0")
    return Actuator(name, tuple(map(float, g)), tuple(map(float, b)),
                    _limited(attrs, "ctrllimited", "ctrlrange", el),
                    _limited(attrs, "forcelimited", "forcerange", el), inherit), None


def inherited_range(law: Actuator, joint_range: tuple) -> tuple:
    """A position servo's ``ctrlrange`` from ``inheritrange`` r and its joint's range ``(lo,
    hi)`` (MuJoCo's ``qpos`` units): the centre ± r × the half width."""
    lo, hi = joint_range
    mid, half = 0.5 * (lo + hi), 0.5 * law.inheritrange * (hi - lo)
    return float(mid - half), float(mid + half)


def _clamp(x, bounds):
    return x if bounds is None else ca.fmin(ca.fmax(x, bounds[0]), bounds[1])


class Actuation:
    """The imported actuators (:class:`Actuator`) and their transmission: ``gear`` (the
    moment arms, coordinates × actuators, ``system.actuator_gear``), ``ref`` (MuJoCo's
    ``qpos`` of each coordinate at ncgen's zero), ``coordinates`` (the driven coordinates'
    names, ``tau``'s order) and ``joint_ranges`` (``{coordinate index: actuatorfrcrange}``)."""

    def __init__(self, actuators, gear, ref, coordinates, joint_ranges):
        self.actuators = list(actuators)
        self.gear = np.asarray(gear, float).reshape(len(coordinates), len(self.actuators))
        self.ref, self.coordinates, self.joint_ranges = np.asarray(ref, float), list(coordinates), dict(joint_ranges)

    @property
    def nu(self) -> int:
        return len(self.actuators)

    def forces(self, x, xd, ctrl):
        """``(f, τ)``: the actuator forces and the generalised forces on the driven coordinates
        at coordinates ``x``, rates ``xd`` and controls ``ctrl`` (CasADi SX or numbers)."""
        x, xd, ctrl = (ca.reshape(ca.SX(v) if not isinstance(v, ca.SX) else v, -1, 1) for v in (x, xd, ctrl))
        if ctrl.numel() != self.nu:
            raise ModelError(f"MJCF actuation: ctrl: expected {self.nu} values (one per actuator: "
                             f"{', '.join(a.name for a in self.actuators)}), got {ctrl.numel()}")
        G = ca.DM(self.gear)
        L, Ld = ca.mtimes(G.T, x + ca.DM(self.ref)), ca.mtimes(G.T, xd)
        f = []
        for i, a in enumerate(self.actuators):
            gain = a.gain[0] + a.gain[1] * L[i] + a.gain[2] * Ld[i]
            bias = a.bias[0] + a.bias[1] * L[i] + a.bias[2] * Ld[i]
            f.append(_clamp(gain * _clamp(ctrl[i], a.ctrlrange) + bias, a.forcerange))
        f = ca.vertcat(*f) if f else ca.SX(0, 1)
        tau = ca.mtimes(G, f) if self.nu else ca.SX.zeros(len(self.coordinates))
        tau = ca.vertcat(*[_clamp(tau[k], self.joint_ranges.get(k)) for k in range(len(self.coordinates))])
        return f, tau

    def rows(self, model) -> list[tuple[int, int]]:
        """``(row in q_j, row in v_j)`` of each driven coordinate in ``model``'s joint space."""
        js = model.joint_space
        sq, sv = js.slices(), js.slices(rates=True)
        out = []
        for c in self.coordinates:
            joint, _, law = c.partition(".")
            if joint not in sq:
                raise ModelError(f"MJCF actuation: coordinate {c!r} is not a joint of model {model.name!r}")
            k = 0 if not law else [lw.name for lw in js.joints[joint].laws].index(law)
            out.append((sq[joint].start + k, sv[joint].start + k))
        return out

    def tau(self, model, qj, vj, ctrl) -> np.ndarray:
        """The generalised forces (``tau``, numbers) at a joint-space state of ``model``."""
        rq, rv = zip(*self.rows(model)) if self.coordinates else ((), ())
        qj, vj = np.asarray(qj, float), np.asarray(vj, float)
        _, tau = self.forces(qj[list(rq)], vj[list(rv)], np.asarray(ctrl, float).reshape(-1))
        return np.asarray(ca.evalf(tau), float).ravel()

    def controller(self, ctrl, *, name: str = "mjcf_actuators") -> "ActuatorController":
        """A compiled controller (``nc.simulate(..., u=...)``) that applies the actuators with
        the controls ``ctrl``: numbers (one per actuator) or a function of ``t`` returning them
        as CasADi SX."""
        return ActuatorController(self, ctrl, name=name)


class ActuatorController(Controller):
    """``tau = Σ_i m_i f_i(u_i(t), L_i, L̇_i)`` of an :class:`Actuation` (module docstring)."""

    kind = "mjcf_actuators"

    def __init__(self, actuation: Actuation, ctrl, *, name: str):
        if not callable(ctrl):
            arr = np.asarray(ctrl, float).reshape(-1)
            if arr.size != actuation.nu or not np.all(np.isfinite(arr)):
                raise ModelError(f"{name}: ctrl: expected {actuation.nu} finite numbers (one per actuator) or a "
                                 f"function of t, got {arr.tolist()}")
        self.actuation, self.ctrl, self.name = actuation, ctrl, name

    def inputs(self, model, t, qj, vj, p, *, efforts_to_inputs, inverse_dynamics) -> ca.SX:
        n = len(self.actuation.coordinates)
        if model.nu != n:
            raise ModelError(f"{self.name}: model {model.name!r} has {model.nu} inputs; the MJCF actuation drives "
                             f"{n} coordinates through the input tau")
        ctrl = self.ctrl(t) if callable(self.ctrl) else ca.DM(np.asarray(self.ctrl, float))
        ctrl = ca.vertcat(*ctrl) if isinstance(ctrl, (list, tuple)) else ctrl
        rows = self.actuation.rows(model)
        x = ca.vertcat(*[qj[r] for r, _ in rows]) if rows else ca.SX(0, 1)
        xd = ca.vertcat(*[vj[r] for _, r in rows]) if rows else ca.SX(0, 1)
        return self.actuation.forces(x, xd, ctrl)[1]
