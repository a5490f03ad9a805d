"""``CapstanCable``: an elastic cable through the points of ``path`` with capstan
(Euler–Eytelwein) friction at one pulley, sticking or slipping in a simulation.

The pulley ``path[j]`` splits the cable into side a (``path[0..j]``, length ``l_a``) and
side b (``path[j..]``, ``l_b``); the other points of the path are frictionless pulleys.  The
cable material on each side is a state: the rest length ``s`` of side a (m; side b carries
``l₀ − s``, the whole rest length ``l₀`` is conserved), the coordinate of a *material point*
of mass ``m_s`` (the cable's mass lumped at the pulley, kg) that slides on a line of the
ground perpendicular to gravity (``s = s₀ + e·(r_m − r_m0)``, :func:`add_capstan_cable`).
Its rate ``ṡ`` (m/s, > 0: material passes from side b to side a) is the slip.

Sides (axial stiffness ``EA``, N; damping ``c``, N·s/m, on each side's stretching rate):
``T_a = EA (l_a − s)/s + c (l̇_a − ṡ)``, ``T_b = EA (l_b − l₀ + s)/(l₀ − s) + c (l̇_b + ṡ)`` (kept
≥ 0: slack), potential ``V = Σ EA (l − s)²/(2 s)`` over taut sides.  The material point is
driven by ``P = T_a + E_a²/(2EA) − T_b − E_b²/(2EA)`` (``E`` the elastic part of ``T``: the
elastic part of ``P`` is ``−∂V/∂s``) and held by the friction

    F_f = (e^{μθ} − 1) (T_b max(τ, 0) + T_a min(τ, 0)),   τ = tanh(ṡ / v_s)

(``μ`` friction coefficient, ``θ`` wrap angle in rad, ``v_s`` the slip velocity scale, m/s):
``m_s s̈ = P − F_f``.  Sliding at ``|ṡ| ≫ v_s``, ``|F_f|`` is the capstan bound: slipping
towards a, ``T_a − T_b = (e^{μθ} − 1) T_b`` i.e. ``T_a = T_b e^{μθ}``; towards b,
``T_b = T_a e^{μθ}``, each up to the relative error ``1 − tanh(|ṡ|/v_s)`` in the friction,
the material's inertia ``m_s s̈`` and the strain terms ``T²/(2EA)`` of ``P``.  While
``e^{−μθ} < T_a/T_b < e^{μθ}`` the cable sticks: ``τ = P / F_max`` balances ``P`` and the
material creeps at ``|ṡ| = v_s atanh(|P|/F_max)`` (``F_max`` the bound on that side), which
is the regularisation's error (``v_s → 0``: exact stick).  The friction's power ``−F_f ṡ`` is
≤ 0, and the damping's ``−c Σ (stretching rate)²`` too: they only dissipate.

The wrap angle is given, or (``wrap=None``) taken from the shape: the angle between the
directions ``u₁``, ``u₂`` of the cable into and out of the drum,
``θ = 2 atan2(|u₁ − u₂|, |u₁ + u₂|)`` (0 straight through, π turned back; the norms
regularised by ``(1e-9)²`` so that its derivative stays finite there), plus ``2π`` per extra
turn in ``turns``.  The material mode is stiff (``m_s`` small on a stiff rope): IDAS takes
it as it is, the compiled stepper needs steps of about 0.1 ms.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.errors import ModelError
from ncgen.model.forces import Force
from ncgen.validation import as_scalar

#: Default slip velocity scale ``v_s`` (m/s) of the regularised stick.
SLIP_VELOCITY = 1e-4


def side_tension(length, rest, ea, drag=0):
    """Tension ``EA (l − s)/s + drag`` (N) of a cable side of length ``l`` and rest length ``s``
    (m), ``drag`` its damping force (N), kept ≥ 0 (slack)."""
    return ca.fmax(ea * (length - rest) / rest + drag, 0)


def side_energy(length, rest, ea):
    """Elastic energy ``EA (l − s)²/(2 s)`` (J) of a taut side, 0 while slack."""
    return ca.if_else(length > rest, ea * (length - rest) ** 2 / (2 * rest), 0)


#: Regularisation of the norms in the wrap angle from the shape (dimensionless).
WRAP_EPSILON = 1e-9


def wrap_angle(u_in, u_out, turns):
    """``θ = 2 atan2(|u₁ − u₂|, |u₁ + u₂|) + 2π turns`` (rad) between the unit directions
    ``u_in`` into and ``u_out`` out of a drum (module docstring)."""
    def norm(x):
        return ca.sqrt(ca.sumsqr(x) + WRAP_EPSILON**2)

    return 2 * ca.atan2(norm(u_in - u_out), norm(u_in + u_out)) + 2 * np.pi * turns


def capstan_friction(t_a, t_b, rate, mu, wrap, slip_velocity):
    """Friction ``F_f`` (N) the pulley exerts against the slip ``rate`` (module docstring)."""
    tau = ca.tanh(rate / slip_velocity)
    return (ca.exp(mu * wrap) - 1) * (t_b * ca.fmax(tau, 0) + t_a * ca.fmin(tau, 0))


class CapstanCable(Force):
    """A cable through ``path`` with capstan friction at ``path[pulley]`` (module docstring):
    ``mu`` ≥ 0, ``wrap`` θ (rad, > 0; ``None``: from the shape, plus ``turns`` full turns),
    ``ea`` (N, > 0), ``damping`` c (N·s/m, ≥ 0), ``rest_lengths = (s₀, l₀ − s₀)`` of the two
    sides (m, > 0), ``material`` the point member whose position along ``axis`` (a world unit
    vector) is the slip, ``slip_velocity`` ``v_s`` (m/s, > 0)."""

    kind = "CapstanCable"

    def __init__(self, path, *, pulley: int, mu, ea, rest_lengths, material, axis, wrap=None, damping=0.0,
                 turns: int = 0, slip_velocity=SLIP_VELOCITY, name: str | None = None):
        super().__init__(name)
        self.damping = damping
        self.path, self.pulley = list(path), pulley
        self.mu, self.wrap, self.ea, self.slip_velocity, self.turns = mu, wrap, ea, slip_velocity, turns
        self.rest_lengths, self.material, self.axis = rest_lengths, material, axis

    def members(self):
        return [item[0] for item in self.path if isinstance(item, (tuple, list)) and len(item) == 2] + [self.material]

    def check(self, system):
        self.check_values()
        if self.material.is_ground or self.material.kind != "point":
            raise ModelError(f"{self.label}: material: expected a point member, got {self.material.name} "
                             f"({self.material.kind})")
        e = np.asarray(self.axis, float)
        if e.shape != (system.dim,) or abs(np.linalg.norm(e) - 1) > 1e-12:
            raise ModelError(f"{self.label}: axis: expected a unit vector of {system.dim} components, got {self.axis!r}")

    def check_values(self):
        """Check the path, the pulley's index and the numbers (not the material)."""
        n = len(self.path)
        if n < 3:
            raise ModelError(f"{self.label}: path: expected three or more (member, point) pairs, got {n}")
        for i, item in enumerate(self.path):
            if not isinstance(item, (tuple, list)) or len(item) != 2:
                raise ModelError(f"{self.label}: path[{i}]: expected a (member, point) pair, got {item!r}")
            self._local_point(item[0], item[1], f"path[{i}]")
        if isinstance(self.pulley, bool) or not isinstance(self.pulley, (int, np.integer)) \
                or not 0 < self.pulley < n - 1:
            raise ModelError(f"{self.label}: pulley: expected the index of an inner point of the path "
                             f"(1 to {n - 2}), got {self.pulley!r}")
        if isinstance(self.turns, bool) or not isinstance(self.turns, (int, np.integer)) or self.turns < 0:
            raise ModelError(f"{self.label}: turns: expected an integer >= 0, got {self.turns!r}")
        if self.wrap is not None and self.turns:
            raise ModelError(f"{self.label}: turns: only with wrap = None (the angle from the shape); "
                             f"a given wrap includes its turns")
        for key in ("mu", "damping", "ea", "slip_velocity") + (("wrap",) if self.wrap is not None else ()):
            v = as_scalar(getattr(self, key), f"{self.label}: {key}")
            if not np.isfinite(v) or v < 0 or (key not in ("mu", "damping") and v == 0):
                raise ModelError(f"{self.label}: {key}: expected a finite number "
                                 f"{'>= 0' if key in ('mu', 'damping') else '> 0'}, got {v:g}")
        rest = np.asarray(self.rest_lengths, float)
        if rest.shape != (2,) or not np.all(np.isfinite(rest)) or np.any(rest <= 0):
            raise ModelError(f"{self.label}: rest_lengths: expected two rest lengths > 0 (m), of sides a and b, "
                             f"got {self.rest_lengths!r}")

    def _points(self, ctx):
        out = []
        for m, at in self.path:
            at = np.asarray(at, float)
            out.append((ca.DM(at), ca.DM.zeros(ctx.dim)) if m.is_ground else ctx.local_point(m, at))
        return out

    def slip(self, ctx):
        """``(s, ṡ)``: the rest length of side a (m) and the slip rate (m/s)."""
        r, v = ctx.local_point(self.material, np.zeros(ctx.dim))
        e = ca.DM(np.asarray(self.axis, float))
        r0 = ca.DM(np.asarray(self.material.p0, float))
        return self.rest_lengths[0] + ca.dot(e, r - r0), ca.dot(e, v)

    def lengths(self, ctx):
        """``((l_a, l̇_a), (l_b, l̇_b))``: the lengths (m) of the two sides and their rates (m/s)."""
        pts = self._points(ctx)
        seg = [ca.sqrt(ca.sumsqr(rb - ra)) for (ra, _), (rb, _) in zip(pts, pts[1:])]
        rate = [ca.dot(rb - ra, vb - va) / d for ((ra, va), (rb, vb)), d in zip(zip(pts, pts[1:]), seg)]
        j = self.pulley
        return ((sum(seg[:j], ca.SX(0)), sum(rate[:j], ca.SX(0))),
                (sum(seg[j:], ca.SX(0)), sum(rate[j:], ca.SX(0))))

    def pulls(self, ctx):
        """``(P_a, P_b)`` (N): the sides' ``EA (l − s)/s + c (l̇ ∓ ṡ)`` before the cut at 0
        (rest lengths ``s`` and ``l₀ − s``)."""
        (l_a, rate_a), (l_b, rate_b) = self.lengths(ctx)
        s, slip = self.slip(ctx)
        total = float(sum(self.rest_lengths))
        ea = self._value(ctx, self.ea, 1, "ea")
        c = self._value(ctx, self.damping, 1, "damping")
        return (ea * (l_a - s) / s + c * (rate_a - slip),
                ea * (l_b - total + s) / (total - s) + c * (rate_b + slip))

    def tensions(self, ctx):
        """``(T_a, T_b)`` (N) of the two sides, with their damping: the pulls kept ≥ 0."""
        return tuple(ca.fmax(pull, 0) for pull in self.pulls(ctx))

    def wrap_angle(self, ctx):
        """θ (rad): the given ``wrap``, or the shape's (module docstring)."""
        if self.wrap is not None:
            return self._value(ctx, self.wrap, 1, "wrap")
        (r0, _), (r1, _), (r2, _) = self._points(ctx)[self.pulley - 1:self.pulley + 2]
        return wrap_angle((r1 - r0) / ca.sqrt(ca.sumsqr(r1 - r0)), (r2 - r1) / ca.sqrt(ca.sumsqr(r2 - r1)), self.turns)

    def friction(self, ctx):
        """``F_f`` (N), the pulley's friction on the material (module docstring)."""
        t_a, t_b = self.tensions(ctx)
        _, rate = self.slip(ctx)
        mu = self._value(ctx, self.mu, 1, "mu")
        wrap = self.wrap_angle(ctx)
        v_s = self._value(ctx, self.slip_velocity, 1, "slip_velocity")
        return capstan_friction(t_a, t_b, rate, mu, wrap, v_s)

    def generalized(self, ctx):
        t_a, t_b = self.tensions(ctx)
        pts = self._points(ctx)
        pull = [ca.SX.zeros(ctx.dim) for _ in pts]          # force of the cable on each point
        for i, ((ra, _), (rb, _)) in enumerate(zip(pts, pts[1:])):
            d = rb - ra
            f = (t_a if i < self.pulley else t_b) * d / ca.sqrt(ca.sumsqr(d))
            pull[i] += f
            pull[i + 1] -= f
        ea = self._value(ctx, self.ea, 1, "ea")
        (l_a, _), (l_b, _) = self.lengths(ctx)
        s, _ = self.slip(ctx)
        e_a, e_b = side_tension(l_a, s, ea), side_tension(l_b, float(sum(self.rest_lengths)) - s, ea)
        drive = t_a + e_a**2 / (2 * ea) - t_b - e_b**2 / (2 * ea)
        on_material = (drive - self.friction(ctx)) * ca.DM(np.asarray(self.axis, float))
        Q = ca.SX.zeros(ctx.layout.nq)
        for (m, at), f in list(zip(self.path, pull)) + [((self.material, np.zeros(ctx.dim)), on_material)]:
            if not m.is_ground:
                C = ca.DM(m.rigid.C(m.rigid.affine(np.asarray(at, float))))
                Q += ctx.scatter(m, ca.mtimes(C.T, f))
        return Q

    def potential(self, ctx):
        """``Σ EA (l − s)²/(2 s)`` over the taut sides (J)."""
        (l_a, _), (l_b, _) = self.lengths(ctx)
        s, _ = self.slip(ctx)
        ea = self._value(ctx, self.ea, 1, "ea (in the potential energy)", inputs=False)
        return side_energy(l_a, s, ea) + side_energy(l_b, float(sum(self.rest_lengths)) - s, ea)


def material_names(forces) -> set[str]:
    """The names of the material points of the :class:`CapstanCable` elements in ``forces``:
    state, not bodies (the viewer does not draw them)."""
    return {f.material.name for f in forces if isinstance(f, CapstanCable) and f.material is not None}


def add_capstan_cable(system, path, *, pulley: int, mu, ea, rest_lengths, material_mass: float, wrap=None,
                      damping=0.0, turns: int = 0, slip_velocity=SLIP_VELOCITY, name: str = "capstan"):
    """Add a :class:`CapstanCable` to ``system`` with its material point ``<name>_material``
    (mass ``material_mass`` kg > 0, at the pulley's point if on the ground, else at the
    origin) on a ground line perpendicular to gravity; returns the force."""
    from ncgen.model.joints import PointOnLine

    m_s = as_scalar(material_mass, f"capstan cable {name!r}: material_mass")
    if not np.isfinite(m_s) or m_s <= 0:
        raise ModelError(f"capstan cable {name!r}: material_mass: expected a number > 0 (kg), got {m_s:g}")
    g = np.asarray(system.gravity, float)
    axis = _across(g)
    force = CapstanCable(path, pulley=pulley, mu=mu, wrap=wrap, ea=ea, rest_lengths=rest_lengths, material=None,
                         axis=axis, damping=damping, turns=turns, slip_velocity=slip_velocity, name=name)
    force.check_values()
    member, at = path[pulley]
    where = np.asarray(at, float) if member.is_ground else np.zeros(system.dim)
    material = system.add_point(f"{name}_material", mass=m_s, position=where)
    system.add_joint(PointOnLine(system.ground, material, at=where, axis=axis))
    force.material = material
    return system.add_force(force)


def _across(g: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to the gravity ``g`` (any one if ``g`` is 0)."""
    if g.size == 2:
        e = np.array([-g[1], g[0]]) if np.linalg.norm(g) > 0 else np.array([1.0, 0.0])
    else:
        e = np.cross(g, [1.0, 0, 0]) if np.linalg.norm(np.cross(g, [1.0, 0, 0])) > 1e-9 * np.linalg.norm(g) \
            else np.cross(g, [0, 1.0, 0])
        e = e if np.linalg.norm(e) > 0 else np.array([1.0, 0, 0])
    return e / np.linalg.norm(e)
