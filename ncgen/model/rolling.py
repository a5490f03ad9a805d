"""Nonholonomic elements: a wheel rolling without slipping and a knife edge on the ground.

A :class:`RollingDisc` is a knife-edge disc of radius ``radius`` (m), fixed to a body,
with its axle along ``axle`` (a direction in the body's local frame, through the centre of
mass), touching the plane ``z = 0`` (normal ``+z``).  It imposes one holonomic constraint
(the lowest point of the rim is on the plane) and two nonholonomic ones (the material
point of the rim at the contact has no velocity along the plane): velocity constraints
``B(q) v = 0`` that are not the derivative of any position constraint.  A
:class:`KnifeEdge` (the Chaplygin sleigh's blade, a skate) lets a body-fixed point move only
along a body-fixed blade direction in the plane (one nonholonomic constraint).  A :class:`RollingSphere` is a ball rolling without slipping.

Each element gives its equations from its body's pose ``(R, p)`` (CasADi, functions of the
natural coordinates ``q``): ``equations(R, p, q) -> (holonomic residuals, rows of B)``;
:mod:`ncgen.assembly.nonholonomic` assembles them.  An element joins a system by
``System.add_rolling`` (TOML ``[[rolling]]``, :data:`ROLLING_TYPES`; ``spec()`` is its table)
and is then part of the built model (``model.rolling``), which ``nc.simulate`` runs with
``method="rolling"``.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.errors import ModelError
from ncgen.validation import as_vector


class RollingDisc:
    """A disc of ``radius`` (m) on ``body`` (a body or its name), axle ``axle`` in the
    body's frame, rolling without slipping on the plane ``z = 0``."""

    kind = "RollingDisc"

    def __init__(self, body, *, radius: float, axle=(0.0, 1.0, 0.0), name: str | None = None):
        self.body = body if isinstance(body, str) else getattr(body, "name", None)
        if not isinstance(self.body, str):
            raise ModelError(f"RollingDisc: body: expected a body or its name, found {body!r}")
        if not (isinstance(radius, (int, float)) and np.isfinite(radius) and radius > 0):
            raise ModelError(f"RollingDisc on {self.body}: radius: expected a positive number (m), "
                             f"found {radius!r}")
        a = as_vector(axle, 3, f"RollingDisc on {self.body}: axle")
        if np.linalg.norm(a) < 1e-12:
            raise ModelError(f"RollingDisc on {self.body}: axle: expected a nonzero direction, found {a}")
        self.radius = float(radius)
        self.axle = a / np.linalg.norm(a)
        self.name = name or f"{self.body}.rolling"

    def equations(self, R, p, q) -> tuple[ca.SX, ca.SX]:
        """Height of the rim's lowest point ``n·p − ρ|d|`` (1) and the contact point's
        material velocity along the plane as rows of ``B`` (2 × nq): ``d = n − (n·â)â``,
        ``P = p − ρ d/|d|``, ``v_P = ṗ + Ṙ ℓ`` with ``ℓ = Rᵀ(P − p)`` held fixed."""
        n = ca.DM([0.0, 0.0, 1.0])
        a = ca.mtimes(R, ca.DM(self.axle))
        a_hat = a / ca.norm_2(a)
        d = n - ca.dot(n, a_hat) * a_hat
        d_norm = ca.norm_2(d)
        ell = ca.mtimes(R.T, -self.radius * d / d_norm)
        ell_frozen = ca.SX.sym("ell", 3)
        B = ca.jacobian((p + ca.mtimes(R, ell_frozen))[:2], q)
        return ca.dot(n, p) - self.radius * d_norm, ca.substitute(B, ell_frozen, ell)

    def spec(self) -> dict:
        """The element as plain data (its TOML table)."""
        return {"type": self.kind, "name": self.name, "body": self.body, "radius": self.radius,
                "axle": self.axle.tolist()}

    def __repr__(self) -> str:
        return f"RollingDisc({self.body!r}, radius={self.radius}, axle={tuple(self.axle)})"


class RollingSphere:
    """A ball of ``radius`` (m) centred at ``body``'s centre of mass (a body or its name),
    rolling without slipping on the plane ``z = 0``."""

    kind = "RollingSphere"

    def __init__(self, body, *, radius: float, name: str | None = None):
        self.body = body if isinstance(body, str) else getattr(body, "name", None)
        if not isinstance(self.body, str):
            raise ModelError(f"RollingSphere: body: expected a body or its name, found {body!r}")
        if not (isinstance(radius, (int, float)) and np.isfinite(radius) and radius > 0):
            raise ModelError(f"RollingSphere on {self.body}: radius: expected a positive number (m), "
                             f"found {radius!r}")
        self.radius = float(radius)
        self.name = name or f"{self.body}.rolling"

    def equations(self, R, p, q) -> tuple[ca.SX, ca.SX]:
        """Height ``p_z − ρ`` (1) and the material velocity along the plane of the point at
        ``ℓ = Rᵀ(−ρ e_z)`` (held fixed) as rows of ``B`` (2 × nq)."""
        ell = ca.mtimes(R.T, ca.DM([0.0, 0.0, -self.radius]))
        ell_frozen = ca.SX.sym("ell", 3)
        B = ca.jacobian((p + ca.mtimes(R, ell_frozen))[:2], q)
        return p[2] - self.radius, ca.substitute(B, ell_frozen, ell)

    def spec(self) -> dict:
        """The element as plain data (its TOML table)."""
        return {"type": self.kind, "name": self.name, "body": self.body, "radius": self.radius}

    def __repr__(self) -> str:
        return f"RollingSphere({self.body!r}, radius={self.radius})"


class KnifeEdge:
    """A blade on ``body`` (a body or its name) at ``at`` (body frame, m) along ``blade``
    (body frame): the point's velocity along ``e_z × R blade`` (in the plane ``z = 0``'s
    directions, across the blade) is zero.  The body is kept on the plane by its joints."""

    kind = "KnifeEdge"

    def __init__(self, body, *, at=(0.0, 0.0, 0.0), blade=(1.0, 0.0, 0.0), name: str | None = None):
        self.body = body if isinstance(body, str) else getattr(body, "name", None)
        if not isinstance(self.body, str):
            raise ModelError(f"KnifeEdge: body: expected a body or its name, found {body!r}")
        self.at = as_vector(at, 3, f"KnifeEdge on {self.body}: at")
        b = as_vector(blade, 3, f"KnifeEdge on {self.body}: blade")
        if np.linalg.norm(b) < 1e-12:
            raise ModelError(f"KnifeEdge on {self.body}: blade: expected a nonzero direction, found {b}")
        self.blade = b / np.linalg.norm(b)
        self.name = name or f"{self.body}.knife_edge"

    def equations(self, R, p, q) -> tuple[ca.SX, ca.SX]:
        """No holonomic residual; one row: ``(e_z × R blade)ᵀ ∂(p + R at)/∂q``."""
        across = ca.cross(ca.DM([0.0, 0.0, 1.0]), ca.mtimes(R, ca.DM(self.blade)))
        row = ca.mtimes(across.T, ca.jacobian(p + ca.mtimes(R, ca.DM(self.at)), q))
        return ca.SX(0, 1), row

    def spec(self) -> dict:
        """The element as plain data (its TOML table)."""
        return {"type": self.kind, "name": self.name, "body": self.body, "at": self.at.tolist(),
                "blade": self.blade.tolist()}

    def __repr__(self) -> str:
        return f"KnifeEdge({self.body!r}, at={tuple(self.at)}, blade={tuple(self.blade)})"


#: The nonholonomic elements by their TOML ``type``.
ROLLING_TYPES = {cls.kind: cls for cls in (RollingDisc, RollingSphere, KnifeEdge)}
