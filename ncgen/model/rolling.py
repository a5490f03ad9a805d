"""Nonholonomic elements: a wheel rolling without slipping and a knife edge on the ground.

A :class:`RollingDisc` is a wheel fixed to a body, with its axle along ``axle`` (a
direction in the body's local frame, through the centre of mass), touching the plane
``z = 0`` (normal ``+z``): a knife-edge disc of radius ``radius`` (m), or with
``tube_radius = r > 0`` a torus (a tyre) whose tube of radius ``r`` (m) is centred on the
circle of radius ``radius`` about the axle.  It imposes one holonomic constraint (the lowest
point of the wheel is on the plane) and two nonholonomic ones (the material point of the
wheel at the contact has no velocity along the plane): velocity constraints
``B(q) v = 0`` that are not the derivative of any position constraint.  A
:class:`KnifeEdge` (the Chaplygin sleigh's blade, a skate) lets a body-fixed point move only
along a body-fixed blade direction in the plane (one nonholonomic constraint).  A :class:`RollingSphere` is a ball rolling without slipping.

A plane that moves along itself (a treadmill, a cart's floor) is given to an element as its
velocity ``plane_velocity = (w_x, w_y)`` (m/s: numbers, text expressions of ``t``, CasADi SX of
a time symbol or callables ``f(t)``, :mod:`ncgen.model.expressions`): the contact point's
material velocity along the plane then equals the plane's, rheonomic velocity constraints
``B(q) v = c(q, t)`` (``c = w`` for a disc or ball, ``(e_z × R b̄)·w`` for a knife edge).

Each element gives its equations from its body's pose ``(R, p)`` (CasADi, functions of the
natural coordinates ``q``): ``equations(R, p, q) -> (holonomic residuals, rows of B)`` and
``rate(R, t) -> c`` (zeros on a plane at rest);
:mod:`ncgen.assembly.nonholonomic` assembles them.  An element joins a system by
``System.add_rolling`` (TOML ``[[rolling]]``, :data:`ROLLING_TYPES`; ``spec()`` is its table)
and is then part of the built model (``model.rolling``), which ``nc.simulate`` runs with
``method="rolling"``.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.errors import ModelError
from ncgen.model.expressions import evaluate, scope, value_to_toml
from ncgen.validation import as_vector

#: The time symbol (s) the planes' velocities are written in.
_T = ca.SX.sym("t")


def plane_velocity_text(value, what: str):
    """``value`` (two components, each a number or a value of ``t``; None: a plane at rest)
    checked and kept as TOML data: a list of two numbers or expression strings."""
    if value is None:
        return None
    sc = scope(_T, {})
    text = value_to_toml(evaluate(value, sc, 2, what), sc, what)
    return [float(x) if isinstance(x, (int, float)) else x for x in text]


class _MovingPlane:
    """The plane's velocity along itself, shared by the elements."""

    plane_velocity = None

    @property
    def rheonomic(self) -> bool:
        """Whether the plane moves (the velocity constraints depend on time)."""
        return self.plane_velocity is not None and any(x != 0.0 for x in self.plane_velocity)

    def plane_velocity_at(self, t) -> ca.SX:
        """``(w_x, w_y, 0)`` (m/s) at the time symbol ``t``."""
        if self.plane_velocity is None:
            return ca.SX.zeros(3)
        w = evaluate(self.plane_velocity, scope(_T, {}), 2, f"{self!r}: plane_velocity")
        return ca.vertcat(ca.substitute(w, _T, t), 0.0)

    def rate(self, R, t) -> ca.SX:
        """``c(q, t)``: the value of the element's rows ``B v`` (the plane's velocity along the
        rows' directions; ``R`` the body's rotation)."""
        return self.plane_velocity_at(t)[:2]

    def _spec_plane(self, spec: dict) -> dict:
        if self.plane_velocity is not None:
            spec["plane_velocity"] = list(self.plane_velocity)
        return spec


class RollingDisc(_MovingPlane):
    """A disc of ``radius`` (m) on ``body`` (a body or its name), axle ``axle`` in the
    body's frame, rolling without slipping on the plane ``z = 0`` (moving along itself at
    ``plane_velocity``, m/s, if given); with ``tube_radius`` (m, default 0: a knife edge) a
    torus of radii ``radius`` (centre to the tube's centre line) and ``tube_radius``."""

    kind = "RollingDisc"

    def __init__(self, body, *, radius: float, axle=(0.0, 1.0, 0.0), name: str | None = None,
                 plane_velocity=None, tube_radius: float = 0.0):
        self.body = body if isinstance(body, str) else getattr(body, "name", None)
        if not isinstance(self.body, str):
            raise ModelError(f"RollingDisc: body: expected a body or its name, found {body!r}")
        if not (isinstance(radius, (int, float)) and np.isfinite(radius) and radius > 0):
            raise ModelError(f"RollingDisc on {self.body}: radius: expected a positive number (m), "
                             f"found {radius!r}")
        if isinstance(tube_radius, bool) or not (isinstance(tube_radius, (int, float)) and np.isfinite(tube_radius)
                                                 and tube_radius >= 0):
            raise ModelError(f"RollingDisc on {self.body}: tube_radius: expected a number ≥ 0 (m; 0: a knife-edge "
                             f"disc), found {tube_radius!r}")
        self.tube_radius = float(tube_radius)
        a = as_vector(axle, 3, f"RollingDisc on {self.body}: axle")
        if np.linalg.norm(a) < 1e-12:
            raise ModelError(f"RollingDisc on {self.body}: axle: expected a nonzero direction, found {a}")
        self.radius = float(radius)
        self.axle = a / np.linalg.norm(a)
        self.name = name or f"{self.body}.rolling"
        self.plane_velocity = plane_velocity_text(plane_velocity, f"RollingDisc on {self.body}: plane_velocity")

    def equations(self, R, p, q) -> tuple[ca.SX, ca.SX]:
        """Height of the wheel's lowest point ``n·p − ρ|d| − r`` (1) and the contact point's
        material velocity along the plane as rows of ``B`` (2 × nq): ``d = n − (n·â)â``,
        ``P = p − ρ d/|d| − r n`` (``ρ`` the radius, ``r`` the tube's: the tube's centre
        circle's lowest point, then straight down through the tube), ``v_P = ṗ + Ṙ ℓ`` with
        ``ℓ = Rᵀ(P − p)`` held fixed."""
        n = ca.DM([0.0, 0.0, 1.0])
        a = ca.mtimes(R, ca.DM(self.axle))
        a_hat = a / ca.norm_2(a)
        d = n - ca.dot(n, a_hat) * a_hat
        d_norm = ca.norm_2(d)
        ell = ca.mtimes(R.T, -self.radius * d / d_norm - self.tube_radius * n)
        ell_frozen = ca.SX.sym("ell", 3)
        B = ca.jacobian((p + ca.mtimes(R, ell_frozen))[:2], q)
        return ca.dot(n, p) - self.radius * d_norm - self.tube_radius, ca.substitute(B, ell_frozen, ell)

    def spec(self) -> dict:
        """The element as plain data (its TOML table; ``tube_radius`` only when not zero)."""
        spec = {"type": self.kind, "name": self.name, "body": self.body, "radius": self.radius,
                "axle": self.axle.tolist()}
        if self.tube_radius:
            spec["tube_radius"] = self.tube_radius
        return self._spec_plane(spec)

    def __repr__(self) -> str:
        tube = f", tube_radius={self.tube_radius}" if self.tube_radius else ""
        return f"RollingDisc({self.body!r}, radius={self.radius}{tube}, axle={tuple(self.axle)})"


class RollingSphere(_MovingPlane):
    """A ball of ``radius`` (m) centred at ``body``'s centre of mass (a body or its name),
    rolling without slipping on the plane ``z = 0`` (moving along itself at
    ``plane_velocity``, m/s, if given)."""

    kind = "RollingSphere"

    def __init__(self, body, *, radius: float, name: str | None = None, plane_velocity=None):
        self.body = body if isinstance(body, str) else getattr(body, "name", None)
        if not isinstance(self.body, str):
            raise ModelError(f"RollingSphere: body: expected a body or its name, found {body!r}")
        if not (isinstance(radius, (int, float)) and np.isfinite(radius) and radius > 0):
            raise ModelError(f"RollingSphere on {self.body}: radius: expected a positive number (m), "
                             f"found {radius!r}")
        self.radius = float(radius)
        self.name = name or f"{self.body}.rolling"
        self.plane_velocity = plane_velocity_text(plane_velocity, f"RollingSphere on {self.body}: plane_velocity")

    def equations(self, R, p, q) -> tuple[ca.SX, ca.SX]:
        """Height ``p_z − ρ`` (1) and the material velocity along the plane of the point at
        ``ℓ = Rᵀ(−ρ e_z)`` (held fixed) as rows of ``B`` (2 × nq)."""
        ell = ca.mtimes(R.T, ca.DM([0.0, 0.0, -self.radius]))
        ell_frozen = ca.SX.sym("ell", 3)
        B = ca.jacobian((p + ca.mtimes(R, ell_frozen))[:2], q)
        return p[2] - self.radius, ca.substitute(B, ell_frozen, ell)

    def spec(self) -> dict:
        """The element as plain data (its TOML table)."""
        return self._spec_plane({"type": self.kind, "name": self.name, "body": self.body, "radius": self.radius})

    def __repr__(self) -> str:
        return f"RollingSphere({self.body!r}, radius={self.radius})"


class KnifeEdge(_MovingPlane):
    """A blade on ``body`` (a body or its name) at ``at`` (body frame, m) along ``blade``
    (body frame): the point's velocity along ``e_z × R blade`` (in the plane ``z = 0``'s
    directions, across the blade) is zero, or the plane's (``plane_velocity``, m/s).  The
    body is kept on the plane by its joints."""

    kind = "KnifeEdge"

    def __init__(self, body, *, at=(0.0, 0.0, 0.0), blade=(1.0, 0.0, 0.0), name: str | None = None,
                 plane_velocity=None):
        self.body = body if isinstance(body, str) else getattr(body, "name", None)
        if not isinstance(self.body, str):
            raise ModelError(f"KnifeEdge: body: expected a body or its name, found {body!r}")
        self.at = as_vector(at, 3, f"KnifeEdge on {self.body}: at")
        b = as_vector(blade, 3, f"KnifeEdge on {self.body}: blade")
        if np.linalg.norm(b) < 1e-12:
            raise ModelError(f"KnifeEdge on {self.body}: blade: expected a nonzero direction, found {b}")
        self.blade = b / np.linalg.norm(b)
        self.name = name or f"{self.body}.knife_edge"
        self.plane_velocity = plane_velocity_text(plane_velocity, f"KnifeEdge on {self.body}: plane_velocity")

    def equations(self, R, p, q) -> tuple[ca.SX, ca.SX]:
        """No holonomic residual; one row: ``(e_z × R blade)ᵀ ∂(p + R at)/∂q``."""
        across = ca.cross(ca.DM([0.0, 0.0, 1.0]), ca.mtimes(R, ca.DM(self.blade)))
        row = ca.mtimes(across.T, ca.jacobian(p + ca.mtimes(R, ca.DM(self.at)), q))
        return ca.SX(0, 1), row

    def rate(self, R, t) -> ca.SX:
        """``(e_z × R blade)·w(t)``: the plane's velocity across the blade."""
        across = ca.cross(ca.DM([0.0, 0.0, 1.0]), ca.mtimes(R, ca.DM(self.blade)))
        return ca.dot(across, self.plane_velocity_at(t))

    def spec(self) -> dict:
        """The element as plain data (its TOML table)."""
        return self._spec_plane({"type": self.kind, "name": self.name, "body": self.body, "at": self.at.tolist(),
                                 "blade": self.blade.tolist()})

    def __repr__(self) -> str:
        return f"KnifeEdge({self.body!r}, at={tuple(self.at)}, blade={tuple(self.blade)})"


#: The nonholonomic elements by their TOML ``type``.
ROLLING_TYPES = {cls.kind: cls for cls in (RollingDisc, RollingSphere, KnifeEdge)}


#: Where a model with rolling elements is linearised (about a steady motion, not a state of rest).
STEADY_MOTIONS = ("linearise about a steady motion with ncgen.analysis.steady_motion.linearize_steady("
                  "ncgen.assembly.nonholonomic.rolling_system(model), q0, v0, K_spin, coordinates)")
#: Where the step of a model with rolling elements is.
ROLLING_STEP = ("nc.simulate(model, ..., method='stepper') runs the RATTLE step with the velocity constraints "
                "(ncgen.assembly.rolling_rattle.step_function)")


def refuse_rolling(model, what: str, instead: str) -> None:
    """Raise :class:`~ncgen.errors.ModelError` if ``model`` has rolling elements
    (``model.rolling``): ``what`` (a function of the model's own constraints, which would
    give a motion, an equilibrium or a step without the elements' rows) does not keep them;
    the message names the elements and says what does (``instead``)."""
    elements = getattr(model, "rolling", ())
    if elements:
        raise ModelError(f"{what}: model {model.name!r} has rolling elements "
                         f"({', '.join(e.name for e in elements)}), whose constraints {what} does not keep "
                         f"(its result would be the model's without them); {instead}")
