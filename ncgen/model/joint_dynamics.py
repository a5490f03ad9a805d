"""Joint dynamics: damping, friction and position limits of one-coordinate joints
(Revolute, Prismatic), as data on the joint (``joint.dynamics``, ``joint.limits``; URDF
``<dynamics damping friction>`` and ``<limit lower upper>``) and as the joint effort they
produce in simulation (``simulate(..., joint_dynamics=True)``).  A
:class:`~ncgen.model.joints.JointSequence` has one such law per coordinate
(``joint.laws``, :func:`coordinate_laws`).

The law, per joint coordinate ``x`` (rad or m) and rate ``w`` (rad/s or m/s), an effort
``τ_jd`` (N·m or N) added to the joint's own effort:

    τ_jd = − d·w − f·tanh(w / w_f) + τ_limit,
    τ_limit = − max(0, k δ_u + c w)   if δ_u = x − upper > 0,
            + max(0, k δ_l − c w)     if δ_l = lower − x > 0,   else 0

* ``d`` = ``damping`` (viscous, N·m·s/rad or N·s/m), ``f`` = ``friction`` (Coulomb, N·m or N)
  regularised by ``tanh`` over the rate scale ``w_f`` = ``friction_velocity`` (default
  :data:`FRICTION_VELOCITY`): a smooth law that explicit and BDF integrators can take (a
  stuck joint creeps at rates below ``w_f``).
* ``armature`` (kg·m² or kg: a rotor's reflected inertia) adds to the joint's diagonal of
  the joint-space mass matrix, ``(M_j + diag(armature)) a_j = τ − C``: joint-space
  simulation only (the natural-coordinate mass matrix is constant; IDAS refuses it).
* the limit is a one-sided spring-damper (stiff penalty): stiffness ``k`` =
  ``limit_stiffness`` (default :data:`LIMIT_STIFFNESS`), damping ``c`` = ``limit_damping``
  (default :data:`LIMIT_DAMPING`); it only pushes back (the ``max``), never pulls.  A joint
  loaded by a constant effort ``τ`` into its bound rests at the penetration ``τ / k``; one
  arriving with kinetic energy ``E`` penetrates at most ``(τ + sqrt(τ² + 2kE)) / k``
  (energy balance, the damper only dissipates).  Raise ``k`` for less penetration (the
  error-controlled integrators take steps of about ``1/sqrt(k/I)`` s in contact).
"""
from __future__ import annotations

import math

import casadi as ca

from ncgen.errors import ModelError

#: Default stiffness of the limit law (N·m/rad or N/m).
LIMIT_STIFFNESS = 1.0e4
#: Default damping of the limit law (N·m·s/rad or N·s/m).
LIMIT_DAMPING = 10.0
#: Default rate scale of the regularised Coulomb friction (rad/s or m/s).
FRICTION_VELOCITY = 1.0e-2
DYNAMICS_KEYS = ("damping", "friction", "limit_stiffness", "limit_damping", "friction_velocity", "armature")
LIMIT_KEYS = ("lower", "upper")
#: Joint kinds with one coordinate, where the law applies.
KINDS = ("Revolute", "Prismatic")


def set_joint_dynamics(joint, values: dict) -> None:
    """Check ``values`` (keys of :data:`DYNAMICS_KEYS` and :data:`LIMIT_KEYS`) and store them on
    ``joint`` (``dynamics``, ``limits``)."""
    for key, value in values.items():
        if key not in DYNAMICS_KEYS + LIMIT_KEYS:
            raise ModelError(f"{joint.label}: set_dynamics: unknown key {key!r}; expected "
                             f"{', '.join(DYNAMICS_KEYS + LIMIT_KEYS)}")
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise ModelError(f"{joint.label}: {key}: expected a number, got {value!r}") from None
        if key in LIMIT_KEYS:
            if math.isnan(x):
                raise ModelError(f"{joint.label}: {key}: expected a number, got nan")
        elif not (math.isfinite(x) and x >= 0) or (key == "friction_velocity" and x == 0):
            # every other key is a finite number >= 0 (friction_velocity > 0)
            raise ModelError(f"{joint.label}: {key}: expected a finite number "
                             f"{'> 0' if key == 'friction_velocity' else '>= 0'}, got {x!r}")
    merged = {**joint.limits, **{k: float(v) for k, v in values.items() if k in LIMIT_KEYS}}
    if merged.get("lower", -math.inf) > merged.get("upper", math.inf):
        raise ModelError(f"{joint.label}: lower = {merged['lower']:g} is above upper = {merged['upper']:g}")
    joint.limits = merged
    joint.dynamics = {**joint.dynamics, **{k: float(v) for k, v in values.items() if k in DYNAMICS_KEYS}}


def coordinate_laws(joint) -> list:
    """The objects holding the law of each of ``joint``'s coordinates, in order: the joint
    itself for a one-coordinate joint, ``joint.laws`` for a joint sequence."""
    return list(getattr(joint, "laws", [joint]))


def has_dynamics(joint) -> bool:
    """Whether the law of the module docstring gives ``joint`` a nonzero effort somewhere."""
    d = getattr(joint, "dynamics", {}) or {}
    return bool(d.get("damping", 0.0) or d.get("friction", 0.0)
                or math.isfinite(joint.limits.get("lower", -math.inf))
                or math.isfinite(joint.limits.get("upper", math.inf)))


def joint_effort(joint, x, w):
    """``τ_jd(x, w)`` of the module docstring (CasADi SX scalars in and out); raises
    :class:`ModelError` for a joint with more than one coordinate."""
    if joint.kind not in KINDS:
        raise ModelError(f"{joint.label}: joint dynamics (damping, friction, limits) apply to Revolute and "
                         f"Prismatic joints only, not {joint.kind}")
    d = getattr(joint, "dynamics", {}) or {}
    tau = ca.SX(0)
    if d.get("damping", 0.0):
        tau = tau - d["damping"] * w
    if d.get("friction", 0.0):
        tau = tau - d["friction"] * ca.tanh(w / d.get("friction_velocity", FRICTION_VELOCITY))
    k = d.get("limit_stiffness", LIMIT_STIFFNESS)
    c = d.get("limit_damping", LIMIT_DAMPING)
    upper, lower = joint.limits.get("upper", math.inf), joint.limits.get("lower", -math.inf)
    if math.isfinite(upper):
        du = x - upper
        tau = tau - ca.if_else(du > 0, ca.fmax(0, k * du + c * w), 0)
    if math.isfinite(lower):
        dl = lower - x
        tau = tau + ca.if_else(dl > 0, ca.fmax(0, k * dl - c * w), 0)
    return tau


def armature(joint) -> float:
    """The joint's armature (0 when not given)."""
    return float((getattr(joint, "dynamics", {}) or {}).get("armature", 0.0))
