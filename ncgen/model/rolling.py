"""Rolling without slipping: the description of a wheel on the ground plane.

A :class:`RollingDisc` is a knife-edge disc of radius ``radius`` (m), fixed to a body,
with its axle along ``axle`` (a direction in the body's local frame, through the centre of
mass), touching the plane ``z = 0`` (normal ``+z``).  It imposes one holonomic constraint
(the lowest point of the rim is on the plane) and two nonholonomic ones (the material
point of the rim at the contact has no velocity along the plane): velocity constraints
``B(q) v = 0`` that are not the derivative of any position constraint.  Its equations are
assembled by :mod:`ncgen.assembly.nonholonomic`.
"""
from __future__ import annotations

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

    def __repr__(self) -> str:
        return f"RollingDisc({self.body!r}, radius={self.radius}, axle={tuple(self.axle)})"
