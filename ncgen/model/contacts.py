"""Unilateral contact elements: a body-fixed sphere against a plane, or two spheres.

Geometry is given like a joint's: body-fixed points in the member's local frame (``at``,
as for forces), the plane by a world point and a world normal in the initial
configuration (fixed to the ground, or carried by a member).  In planar systems a "plane"
is a line and a "sphere" a disc.

Every contact has, besides its geometry (SI units):

* ``mu``: Coulomb friction coefficient (isotropic, dimensionless, ≥ 0);
* ``restitution``: Newton's normal restitution coefficient ``e`` in [0, 1] (nonsmooth
  stepper: post-impact normal velocity ``= −e ×`` pre-impact);
* the smooth (compliant) law used when the model is built with ``contacts="smooth"``
  (:mod:`ncgen.assembly.contacts`): ``stiffness`` k (N/m^n), ``damping`` d
  (N·s/m^(n+1)), ``exponent`` n (Hunt–Crossley: ``f_N = max(0, δⁿ (k + d δ̇))`` with the
  penetration ``δ = max(0, −g)``) and ``slip_velocity`` v_s (m/s, friction regularised as
  ``f_T = −μ f_N v_T / sqrt(|v_T|² + v_s²)``).  A contact given ``restitution`` and no
  ``damping`` gets the damping with which the law restores ``e`` at an impact speed of
  :data:`RESTITUTION_SPEED` (:func:`damping_for_restitution`; faster impacts lose more,
  slower ones less, as the law says); given ``damping``, the smooth law uses it and
  ``restitution`` is the nonsmooth stepper's only.

Sign conventions: the gap ``g`` (m) is positive when apart; the normal ``n`` points from the
plane (or sphere ``a``) towards the sphere (or sphere ``b``); contact forces are those on the
second element (the sphere, or ``b``), and ``−`` that on the first.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from ncgen.errors import BasisError
from ncgen.model.joint_base import attach_element, check_members
from ncgen.errors import ModelError
from ncgen.validation import as_vector

#: Defaults of the smooth law (steel-like ball of a few kg: a 1 kg ball rests ~0.1 mm deep).
STIFFNESS, DAMPING, EXPONENT, SLIP_VELOCITY = 1e6, 1e5, 1.5, 1e-3
#: Impact speed (m/s) at which the smooth law restores a contact's ``restitution``.
RESTITUTION_SPEED = 1.0


#: Smallest restitution the smooth law is fitted to (e → 0 needs infinite damping).
MIN_RESTITUTION = 0.01


def damping_for_restitution(stiffness: float, restitution: float, exponent: float = EXPONENT) -> float:
    """The damping d (N·s/m^(n+1)) with which ``f_N = δⁿ (k + d δ̇)`` returns a normal impact
    at :data:`RESTITUTION_SPEED` with restitution ``e`` (at least :data:`MIN_RESTITUTION`).
    Scaled by ``δ = L y``, ``L^(n+1) = m v²/k``, the impact is ``y'' = −yⁿ (1 + ζ y')⁺`` with
    ``ζ = d v / k`` alone, so ``ζ(e, n)`` is solved once (bisection) and ``d = ζ k / v``."""
    return _zeta(round(max(float(restitution), MIN_RESTITUTION), 6), float(exponent)) * stiffness / RESTITUTION_SPEED


@lru_cache(maxsize=64)
def _zeta(e: float, n: float) -> float:
    if e >= 1.0:
        return 0.0
    lo, hi = 0.0, 1.0
    while _rebound(hi, n) > e:
        hi *= 2.0
    while hi - lo > 1e-7 * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _rebound(mid, n) > e else (lo, mid)
    return 0.5 * (lo + hi)


def _rebound(zeta: float, n: float) -> float:
    """Rebound speed of the scaled impact ``y'' = −yⁿ (1 + ζ y')⁺``, ``y(0) = 0, y'(0) = 1``."""
    from scipy.integrate import solve_ivp

    def rhs(_, x):
        return [x[1], -max(x[0], 0.0) ** n * max(1.0 + zeta * x[1], 0.0)]

    def apart(_, x):          # the force has vanished while moving out, or the sphere left
        return min(x[0], 1.0 + zeta * x[1]) if x[1] < 0 else 1.0
    apart.terminal, apart.direction = True, -1
    sol = solve_ivp(rhs, (0.0, 100.0), [0.0, 1.0], events=apart, method="LSODA", rtol=1e-9, atol=1e-12)
    return float(-sol.y[1, -1])


def _check_name(name) -> None:
    if not isinstance(name, str) or not name.isidentifier():
        raise ModelError(f"contact name: expected an identifier (letters, digits, _), got {name!r}")


class Contact:
    """Base class: name, friction, restitution and the smooth law's parameters."""

    kind = "Contact"

    def __init__(self, *, mu=0.0, restitution=None, stiffness=STIFFNESS, damping=None, exponent=EXPONENT,
                 slip_velocity=SLIP_VELOCITY, name: str | None = None):
        self.name = name
        if damping is None:
            numbers = all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in (stiffness, restitution))
            damping = damping_for_restitution(stiffness, restitution, exponent) \
                if restitution is not None and numbers and isinstance(exponent, (int, float)) else DAMPING
        self.mu, self.restitution = mu, 0.0 if restitution is None else restitution
        self.stiffness, self.damping, self.exponent, self.slip_velocity = stiffness, damping, exponent, slip_velocity
        self.system = None

    @property
    def label(self) -> str:
        return f"contact {self.name!r} ({self.kind})"

    def members(self) -> list:
        raise NotImplementedError

    def attach(self, system, index: int):
        """Called by ``System.add_contact``: name, membership and argument checks."""
        def validate():
            check_members(self.members(), system, self.label)
            self._check_material()
            self.check(system)
            self.system = system

        attach_element(self, system, index, system.contacts, "contact", _check_name, validate)

    def _check_material(self):
        checks = (("mu", self.mu, 0.0, math.inf), ("restitution", self.restitution, 0.0, 1.0),
                  ("stiffness", self.stiffness, 0.0, math.inf), ("damping", self.damping, 0.0, math.inf),
                  ("exponent", self.exponent, 1.0, math.inf), ("slip_velocity", self.slip_velocity, 0.0, math.inf))
        for what, value, lo, hi in checks:
            try:
                x = float(value)
            except (TypeError, ValueError):
                raise ModelError(f"{self.label}: {what}: expected a number, got {value!r}") from None
            bad = not math.isfinite(x) or x < lo or x > hi or (what in ("stiffness", "slip_velocity") and x == 0)
            if bad:
                rng = f"in [{lo:g}, {hi:g}]" if math.isfinite(hi) else (f"> {lo:g}" if what in (
                    "stiffness", "slip_velocity") else f">= {lo:g}")
                raise ModelError(f"{self.label}: {what}: expected a finite number {rng}, got {value!r}")
            setattr(self, what, x)

    def check(self, system):
        """Geometry checks (subclasses)."""

    def _sphere(self, member, at, radius, what: str):
        """Check a sphere of ``radius`` (m) centred at local point ``at`` of ``member``."""
        if member.is_ground:
            raise ModelError(f"{self.label}: {what}: a sphere needs a moving member, got the ground")
        x = as_vector(at, member.dim, f"{self.label}: {what} at")
        try:
            member.rigid.affine(x)
        except BasisError as e:
            raise ModelError(f"{self.label}: {what} centre on {member.name} ({member.ctype.name} "
                             f"{member.kind}): {e}") from None
        try:
            r = float(radius)
        except (TypeError, ValueError):
            raise ModelError(f"{self.label}: {what} radius: expected a number (m), got {radius!r}") from None
        if not math.isfinite(r) or r < 0:
            raise ModelError(f"{self.label}: {what} radius: expected a finite number >= 0 (m), got {radius!r}")
        return x, r

    def spec(self) -> dict:
        """Plain data describing the contact (``model.contacts``, TOML)."""
        return {"name": self.name, "type": self.kind, "mu": self.mu, "restitution": self.restitution,
                "stiffness": self.stiffness, "damping": self.damping, "exponent": self.exponent,
                "slip_velocity": self.slip_velocity}

    def __repr__(self) -> str:
        return f"<{self.label}>"


class SpherePlane(Contact):
    """A sphere of ``radius`` (m) centred at the local point ``at`` of ``sphere`` against the
    plane through the world point ``point`` with world normal ``normal`` (initial
    configuration), fixed to ``plane`` (the ground by default, or a body carrying it).
    The plane is one-sided: the sphere is kept on the side ``normal`` points to."""

    kind = "SpherePlane"

    def __init__(self, sphere, at=None, radius=0.0, *, plane=None, point=None, normal=None, **material):
        super().__init__(**material)
        self.sphere, self.at, self.radius = sphere, at, radius
        self.plane, self.point, self.normal = plane, point, normal

    def members(self):
        return [self.sphere] + ([] if self.plane is None else [self.plane])

    def attach(self, system, index: int):
        given = self.plane
        if self.plane is None:
            self.plane = system.ground
        try:
            super().attach(system, index)
        except BaseException:
            self.plane = given
            raise

    def check(self, system):
        d = system.dim
        self.at = np.zeros(d) if self.at is None else self.at
        self.at, self.radius = self._sphere(self.sphere, self.at, self.radius, "sphere")
        self.point = as_vector(np.zeros(d) if self.point is None else self.point, d, f"{self.label}: point")
        default_n = np.eye(d)[-1]
        n = as_vector(default_n if self.normal is None else self.normal, d, f"{self.label}: normal")
        if np.linalg.norm(n) == 0:
            raise ModelError(f"{self.label}: normal: expected a non-zero vector, got {n.tolist()}")
        self.normal = n / np.linalg.norm(n)
        if self.plane is self.sphere:
            raise ModelError(f"{self.label}: the sphere and the plane are on the same member {self.sphere.name!r}")
        if not self.plane.is_ground and not (self.plane.kind == "body" or (self.plane.kind == "bar" and d == 2)):
            raise ModelError(f"{self.label}: plane: a plane needs the ground or a body (or a planar bar) to "
                             f"carry it, got the {self.plane.kind} {self.plane.name!r}")

    def spec(self):
        return {**super().spec(), "sphere": self.sphere.name, "at": np.asarray(self.at).tolist(),
                "radius": self.radius, "plane": self.plane.name, "point": self.point.tolist(),
                "normal": self.normal.tolist()}


class SphereSphere(Contact):
    """Two spheres: radius ``radius_a`` (m) at local point ``at_a`` of ``a``, ``radius_b`` at
    ``at_b`` of ``b``.  The normal points from the centre of ``a`` to that of ``b``."""

    kind = "SphereSphere"

    def __init__(self, a, at_a=None, radius_a=0.0, b=None, at_b=None, radius_b=0.0, **material):
        super().__init__(**material)
        self.a, self.at_a, self.radius_a = a, at_a, radius_a
        self.b, self.at_b, self.radius_b = b, at_b, radius_b

    def members(self):
        return [self.a, self.b]

    def check(self, system):
        d = system.dim
        if self.b is None:
            raise ModelError(f"{self.label}: b: expected the second member, got None")
        if self.a is self.b:
            raise ModelError(f"{self.label}: both spheres are on the same member {self.a.name!r}")
        self.at_a, self.radius_a = self._sphere(self.a, np.zeros(d) if self.at_a is None else self.at_a,
                                                self.radius_a, "a")
        self.at_b, self.radius_b = self._sphere(self.b, np.zeros(d) if self.at_b is None else self.at_b,
                                                self.radius_b, "b")
        if self.radius_a + self.radius_b <= 0:
            raise ModelError(f"{self.label}: radius_a + radius_b: expected > 0 (two points never touch)")

    def spec(self):
        return {**super().spec(), "a": self.a.name, "at_a": np.asarray(self.at_a).tolist(), "radius_a": self.radius_a,
                "b": self.b.name, "at_b": np.asarray(self.at_b).tolist(), "radius_b": self.radius_b}


CONTACT_TYPES: dict[str, type[Contact]] = {cls.kind: cls for cls in (SpherePlane, SphereSphere)}
