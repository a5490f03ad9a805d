"""``CapstanCable``: an elastic cable through the points of ``path`` with capstan
(Euler–Eytelwein) friction at one or several drums, sticking or slipping in a simulation.

The drums ``path[j₁], …, path[j_n]`` (``pulley``: one index or an increasing list) split the
cable into ``n + 1`` sides ``0 … n`` (side ``i`` from drum ``i − 1`` to drum ``i``, the path's
ends closing the first and the last; named ``a, b, c, …``); the other points of the path are
frictionless pulleys.  The cable material is state: drum ``k`` carries the *cumulative* rest
length ``S_k`` of sides ``0 … k`` (m), the coordinate of a *material point* of mass ``m_s`` (the
cable's mass lumped at the drum, kg) that slides on a line of the ground perpendicular to
gravity (``S_k = S_k0 + e·(r_k − r_k0)``, :func:`add_capstan_cable`).  Side ``i`` has the rest
length ``ρ_i = S_i − S_{i−1}`` (``S_{−1} = 0``, ``S_n = L₀`` the whole rest length, conserved).
The rate ``Ṡ_k`` (m/s, > 0: material passes from side ``k + 1`` to side ``k``) is drum k's slip.

Sides (axial stiffness ``EA``, N; damping ``c``, N·s/m, on each side's stretching rate):
``T_i = EA (l_i − ρ_i)/ρ_i + c (l̇_i − ρ̇_i)`` (kept ≥ 0: slack), potential
``V = Σ EA (l_i − ρ_i)²/(2 ρ_i)`` over taut sides.  Material point ``k`` is driven by
``P_k = T_k + E_k²/(2EA) − T_{k+1} − E_{k+1}²/(2EA)`` (``E`` the elastic part of ``T``: the
elastic part of ``P_k`` is ``−∂V/∂S_k``) and held by drum k's friction between its two
neighbouring sides (``T_a = T_k``, ``T_b = T_{k+1}``)

    F_f = (e^{μθ} − 1) (T_b max(τ, 0) + T_a min(τ, 0)),   τ = tanh(Ṡ_k / v_s)

(``μ`` friction coefficient, ``θ`` wrap angle in rad, both per drum; ``v_s`` the slip velocity
scale, m/s): ``m_s S̈_k = P_k − F_f``.  Sliding at ``|Ṡ| ≫ v_s``, ``|F_f|`` is the capstan
bound: slipping towards a, ``T_a = T_b e^{μθ}``; towards b, ``T_b = T_a e^{μθ}``, each up to the
relative error ``1 − tanh(|Ṡ|/v_s)`` in the friction, the material's inertia ``m_s S̈`` and the
strain terms ``T²/(2EA)`` of ``P``; over several slipping drums the ratios multiply
(``e^{μ₁θ₁ + μ₂θ₂ + …}``).  While ``e^{−μθ} < T_a/T_b < e^{μθ}`` the drum sticks: the material
creeps at ``|Ṡ| = v_s atanh(|P|/F_max)`` (``F_max`` the bound on that side), the
regularisation's error.  The friction's power ``−F_f Ṡ`` is ≤ 0, the damping's
``−c Σ (stretching rate)²`` too: they only dissipate.

Winches (``reeled = (w_a, w_z)``, m): the rest length reeled in at the path's first and last
ends, values of ``t``, parameters and inputs (> 0 reels in, < 0 pays out): ``S_{−1} = w_a``,
``S_n = L₀ − w_z``, so the first side's rest length is ``S_0 − w_a`` and the last's
``L₀ − w_z − S_{n−1}``, their rates ``∂w/∂t``.  The winch at the last end does the work
``∫ (E_n + E_n²/(2EA)) ẇ_z dt`` (``E_n`` the last side's elastic tension; the same at the first
end), which a run's energy balance reports as ``drives`` (``∂V/∂t``) for a reel given as an
expression of time; a reel depending on inputs leaves the potential out (0, as an input rest
length of a :class:`~ncgen.model.cables.ClusteredCable`), the forces' work then being in
``inputs`` and ``dampers``, and needs ``damping = 0`` (an input's rate is unknown).

A drum may sit on a moving member: its point (a drum of radius 0 fixed to the member, not
spinning) and, with ``wrap=None``, its wrap angle follow the member; the cable's pull on the
drum's point is ``T_k`` and ``T_{k+1}`` along the two sides, so the friction's reaction acts on
the member.  The wrap angle is given, or (``wrap=None``) taken from the shape: the angle
between the directions ``u₁``, ``u₂`` of the cable into and out of the drum,
``θ = 2 atan2(|u₁ − u₂|, |u₁ + u₂|)`` (0 straight through, π turned back; the norms
regularised by ``(1e-9)²`` so that its derivative stays finite there), plus ``2π`` per extra
turn in ``turns``.  ``mu``, ``wrap``, ``ea``, ``damping`` and ``slip_velocity`` are values
(:mod:`ncgen.model.expressions`: parameters and inputs allowed), the rest lengths values of
parameters (they enter the potential energy).  The material mode is stiff (``m_s`` small on a
stiff rope): IDAS takes it as it is, the compiled stepper needs steps of about 0.1 ms.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.errors import ModelError
from ncgen.model.expressions import ExpressionError
from ncgen.model.forces import Force
from ncgen.validation import as_scalar

#: Default slip velocity scale ``v_s`` (m/s) of the regularised stick.
SLIP_VELOCITY = 1e-4

#: Most drums on one cable (its sides are named by the letters a to z).
MAX_DRUMS = 25


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
    """Friction ``F_f`` (N) a drum exerts against the slip ``rate`` (module docstring)."""
    tau = ca.tanh(rate / slip_velocity)
    return (ca.exp(mu * wrap) - 1) * (t_b * ca.fmax(tau, 0) + t_a * ca.fmin(tau, 0))


def _is_number(v) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def _one_or_many(value) -> bool:
    """Whether ``value`` is a list of per-drum values (not one value)."""
    return isinstance(value, (list, tuple, np.ndarray))


class CapstanCable(Force):
    """A cable through ``path`` with capstan friction at the drums ``path[pulley]`` (one index
    or an increasing list; module docstring): ``mu`` ≥ 0 and ``wrap`` θ (rad, > 0; ``None``:
    from the shape, plus ``turns`` full turns), each one value or one per drum; ``ea`` (N, > 0),
    ``damping`` c (N·s/m, ≥ 0), ``rest_lengths`` the ``n + 1`` sides' (m, > 0), ``material`` the
    point member (one per drum, a list with several) whose position along ``axis`` (a world
    unit vector) is the drum's cumulative rest length, ``slip_velocity`` ``v_s`` (m/s, > 0),
    ``reeled`` ``(w_a, w_z)`` the rest length winches at the path's first and last ends have
    reeled in (m, values of t, parameters and inputs; None: no winch; module docstring)."""

    kind = "CapstanCable"

    def __init__(self, path, *, pulley, mu, ea, rest_lengths, material, axis, wrap=None, damping=0.0,
                 turns=0, slip_velocity=SLIP_VELOCITY, reeled=None, name: str | None = None):
        super().__init__(name)
        self.reeled = reeled
        self.damping = damping
        self.path, self.pulley = list(path), pulley
        self.mu, self.wrap, self.ea, self.slip_velocity, self.turns = mu, wrap, ea, slip_velocity, turns
        self.rest_lengths, self.material, self.axis = rest_lengths, material, axis

    # ------------------------------------------------------------ structure
    @property
    def drums(self) -> list[int]:
        """The path indices of the drums."""
        return [int(j) for j in self.pulley] if _one_or_many(self.pulley) else [int(self.pulley)]

    @property
    def materials(self) -> list:
        """The material points, one per drum."""
        return list(self.material) if _one_or_many(self.material) else [self.material]

    def per_drum(self, key: str) -> list:
        """The value of ``key`` (``mu``, ``wrap``, ``turns``) at each drum."""
        value = getattr(self, key)
        return list(value) if _one_or_many(value) else [value] * len(self.drums)

    def side_names(self) -> list[str]:
        """``<name>.a``, ``<name>.b``, …: the sides in path order."""
        return [f"{self.name}.{chr(ord('a') + i)}" for i in range(len(self.drums) + 1)]

    def side_paths(self) -> list[list]:
        """The ``(member, point)`` pairs each side runs through (drums shared by neighbours)."""
        cuts = [0, *self.drums, len(self.path) - 1]
        return [self.path[i:j + 1] for i, j in zip(cuts, cuts[1:])]

    def members(self):
        return [item[0] for item in self.path if isinstance(item, (tuple, list)) and len(item) == 2] + \
            [m for m in self.materials if m is not None]

    # ------------------------------------------------------------ checks
    def check(self, system):
        self.check_values()
        for k, m in enumerate(self.materials):
            if m is None or m.is_ground or m.kind != "point":
                raise ModelError(f"{self.label}: material{self._at(k)}: expected a point member, got "
                                 f"{getattr(m, 'name', m)} ({getattr(m, 'kind', type(m).__name__)})")
        e = np.asarray(self.axis, float)
        if e.shape != (system.dim,) or abs(np.linalg.norm(e) - 1) > 1e-12:
            raise ModelError(f"{self.label}: axis: expected a unit vector of {system.dim} components, got {self.axis!r}")

    def _at(self, k) -> str:
        return f"[{k}]" if _one_or_many(self.pulley) else ""

    def check_values(self):
        """Check the path, the drums' indices and the numbers (not the materials)."""
        n = len(self.path)
        if n < 3:
            raise ModelError(f"{self.label}: path: expected three or more (member, point) pairs, got {n}")
        for i, item in enumerate(self.path):
            if not isinstance(item, (tuple, list)) or len(item) != 2:
                raise ModelError(f"{self.label}: path[{i}]: expected a (member, point) pair, got {item!r}")
            self._local_point(item[0], item[1], f"path[{i}]")
        js = list(self.pulley) if _one_or_many(self.pulley) else [self.pulley]
        if not js or len(js) > min(MAX_DRUMS, n - 2) \
                or any(isinstance(j, bool) or not isinstance(j, (int, np.integer)) or not 0 < j < n - 1 for j in js) \
                or any(b <= a for a, b in zip(js, js[1:])):
            raise ModelError(f"{self.label}: pulley: expected the index of an inner point of the path "
                             f"(1 to {n - 2}), or an increasing list of up to {MAX_DRUMS} of them, got {self.pulley!r}")
        drums = len(js)
        for key in ("mu", "wrap", "turns", "material"):
            value = getattr(self, key)
            if _one_or_many(value) and not _one_or_many(self.pulley):
                raise ModelError(f"{self.label}: {key}: expected one value (pulley is one drum), got a list")
            if _one_or_many(value) and len(value) != drums:
                raise ModelError(f"{self.label}: {key}: expected one value or one per drum ({drums}), "
                                 f"got {len(value)}")
        wraps, turns = self.per_drum("wrap"), self.per_drum("turns")
        for k, (wrap, turn) in enumerate(zip(wraps, turns)):
            if isinstance(turn, bool) or not isinstance(turn, (int, np.integer)) or turn < 0:
                raise ModelError(f"{self.label}: turns{self._at(k)}: expected an integer >= 0, got {turn!r}")
            if wrap is not None and turn:
                raise ModelError(f"{self.label}: turns{self._at(k)}: only with wrap = None (the angle from the "
                                 f"shape); a given wrap includes its turns")
        checks = [("mu", v, k) for k, v in enumerate(self.per_drum("mu"))] + \
            [("wrap", v, k) for k, v in enumerate(wraps) if v is not None] + \
            [(key, getattr(self, key), None) for key in ("damping", "ea", "slip_velocity")]
        for key, value, k in checks:
            if isinstance(value, (str, ca.SX)) or callable(value):
                continue                                    # a value of parameters or inputs: checked when built
            v = as_scalar(value, f"{self.label}: {key}")
            if not np.isfinite(v) or v < 0 or (key not in ("mu", "damping") and v == 0):
                raise ModelError(f"{self.label}: {key}{self._at(k) if k is not None else ''}: expected a finite "
                                 f"number {'>= 0' if key in ('mu', 'damping') else '> 0'}, got {v:g}")
        if self.reeled is not None and (not _one_or_many(self.reeled) or len(self.reeled) != 2):
            raise ModelError(f"{self.label}: reeled: expected two values (the rest length reeled in at the path's "
                             f"first and last ends, m), got {self.reeled!r}")
        rest = self.rest_lengths
        if not _one_or_many(rest) or len(rest) != drums + 1 or any(
                _is_number(x) and (not np.isfinite(x) or x <= 0) for x in rest):
            raise ModelError(f"{self.label}: rest_lengths: expected {drums + 1} rest lengths > 0 (m), one per side "
                             f"(a to {chr(ord('a') + drums)}), got {rest!r}")

    # ------------------------------------------------------------ kinematics
    def _points(self, ctx):
        out = []
        for m, at in self.path:
            at = np.asarray(at, float)
            out.append((ca.DM(at), ca.DM.zeros(ctx.dim)) if m.is_ground else ctx.local_point(m, at))
        return out

    def _rests(self, ctx) -> list:
        """The sides' initial rest lengths (m) as SX (values of parameters)."""
        return [self._value(ctx, x, 1, f"rest_lengths[{i}]", inputs=False) for i, x in enumerate(self.rest_lengths)]

    def slip(self, ctx) -> list[tuple]:
        """``[(S_k, Ṡ_k)]``: each drum's cumulative rest length (m) and slip rate (m/s)."""
        e = ca.DM(np.asarray(self.axis, float))
        rests, out, total = self._rests(ctx), [], 0
        for k, m in enumerate(self.materials):
            total = total + rests[k]
            r, v = ctx.local_point(m, np.zeros(ctx.dim))
            out.append((total + ca.dot(e, r - ca.DM(np.asarray(m.p0, float))), ca.dot(e, v)))
        return out

    def reels(self, ctx, *, inputs: bool = True) -> list[tuple]:
        """``[(w_a, ẇ_a), (w_z, ẇ_z)]``: the rest length reeled in at the first and last ends (m)
        and its rate (m/s, ``∂w/∂t``; an input's rate is unknown: refused with damping)."""
        out = []
        for i, w in enumerate(self.reeled):
            x = self._value(ctx, w, 1, f"reeled[{i}]", inputs=inputs)
            u = [ca.vec(sym) for sym in ctx.system.inputs.values()]
            if u and not (_is_number(self.damping) and self.damping == 0) and ca.depends_on(x, ca.vertcat(*u)):
                raise ModelError(f"{self.label}: reeled[{i}]: an input's rate is unknown to the sides' damping: "
                                 f"give damping = 0, or the reel as an expression of t")
            out.append((x, ca.jacobian(x, ctx.t)))
        return out

    def _cumulative(self, ctx, *, inputs: bool = True) -> list[tuple]:
        """``[(S_{i−1}, S_i)]`` per side with their rates: ``S_{−1} = w_a``, ``S_n = L₀ − w_z``
        (``S_{−1} = 0``, ``S_n = L₀`` without winches)."""
        total = sum(self._rests(ctx), ca.SX(0))
        if self.reeled is None:
            cum = [(ca.SX(0), ca.SX(0))] + self.slip(ctx) + [(total, ca.SX(0))]
        else:
            (w_a, r_a), (w_z, r_z) = self.reels(ctx, inputs=inputs)
            cum = [(w_a, r_a)] + self.slip(ctx) + [(total - w_z, -r_z)]
        return list(zip(cum, cum[1:]))

    def side_rests(self, ctx, *, inputs: bool = True) -> list[tuple]:
        """``[(ρ_i, ρ̇_i)]``: the sides' rest lengths (m) and their rates (m/s)."""
        return [(s1 - s0, r1 - r0) for (s0, r0), (s1, r1) in self._cumulative(ctx, inputs=inputs)]

    def lengths(self, ctx) -> list[tuple]:
        """``[(l_i, l̇_i)]``: the lengths (m) of the sides and their rates (m/s)."""
        pts = self._points(ctx)
        seg = [ca.sqrt(ca.sumsqr(rb - ra)) for (ra, _), (rb, _) in zip(pts, pts[1:])]
        rate = [ca.dot(rb - ra, vb - va) / d for ((ra, va), (rb, vb)), d in zip(zip(pts, pts[1:]), seg)]
        cuts = [0, *self.drums, len(self.path) - 1]
        return [(sum(seg[i:j], ca.SX(0)), sum(rate[i:j], ca.SX(0))) for i, j in zip(cuts, cuts[1:])]

    # ------------------------------------------------------------ forces
    def pulls(self, ctx) -> list:
        """``[P_i]`` (N): the sides' ``EA (l − ρ)/ρ + c (l̇ − ρ̇)`` before the cut at 0."""
        ea = self._value(ctx, self.ea, 1, "ea")
        c = self._value(ctx, self.damping, 1, "damping")
        return [ea * (length - s1 + s0) / (s1 - s0) + c * (rate - (r1 - r0))
                for (length, rate), ((s0, r0), (s1, r1)) in zip(self.lengths(ctx), self._cumulative(ctx))]

    def tensions(self, ctx) -> list:
        """``[T_i]`` (N) of the sides, with their damping: the pulls kept ≥ 0."""
        return [ca.fmax(pull, 0) for pull in self.pulls(ctx)]

    def wrap_angles(self, ctx) -> list:
        """θ_k (rad) of each drum: the given ``wrap``, or the shape's (module docstring)."""
        pts, out = self._points(ctx), []
        for k, (j, wrap, turns) in enumerate(zip(self.drums, self.per_drum("wrap"), self.per_drum("turns"))):
            if wrap is not None:
                out.append(self._value(ctx, wrap, 1, f"wrap{self._at(k)}"))
                continue
            (r0, _), (r1, _), (r2, _) = pts[j - 1:j + 2]
            out.append(wrap_angle((r1 - r0) / ca.sqrt(ca.sumsqr(r1 - r0)), (r2 - r1) / ca.sqrt(ca.sumsqr(r2 - r1)),
                                  turns))
        return out

    def friction(self, ctx) -> list:
        """``[F_f,k]`` (N): each drum's friction on its material (module docstring)."""
        t = self.tensions(ctx)
        v_s = self._value(ctx, self.slip_velocity, 1, "slip_velocity")
        mus = [self._value(ctx, mu, 1, f"mu{self._at(k)}") for k, mu in enumerate(self.per_drum("mu"))]
        return [capstan_friction(t[k], t[k + 1], rate, mu, wrap, v_s)
                for k, ((_, rate), mu, wrap) in enumerate(zip(self.slip(ctx), mus, self.wrap_angles(ctx)))]

    def generalized(self, ctx):
        t = self.tensions(ctx)
        pts = self._points(ctx)
        side = np.searchsorted(np.asarray(self.drums), np.arange(len(pts) - 1), side="right")
        pull = [ca.SX.zeros(ctx.dim) for _ in pts]          # force of the cable on each point
        for i, ((ra, _), (rb, _)) in enumerate(zip(pts, pts[1:])):
            d = rb - ra
            f = t[side[i]] * d / ca.sqrt(ca.sumsqr(d))
            pull[i] += f
            pull[i + 1] -= f
        ea = self._value(ctx, self.ea, 1, "ea")
        strain = [side_tension(length, rho, ea) ** 2 / (2 * ea)
                  for (length, _), (rho, _) in zip(self.lengths(ctx), self.side_rests(ctx))]
        axis = ca.DM(np.asarray(self.axis, float))
        on_material = [(t[k] + strain[k] - t[k + 1] - strain[k + 1] - f) * axis
                       for k, f in enumerate(self.friction(ctx))]
        Q = ca.SX.zeros(ctx.layout.nq)
        at0 = np.zeros(ctx.dim)
        for (m, at), f in list(zip(self.path, pull)) + [((m, at0), f) for m, f in zip(self.materials, on_material)]:
            if not m.is_ground:
                C = ca.DM(m.rigid.C(m.rigid.affine(np.asarray(at, float))))
                Q += ctx.scatter(m, ca.mtimes(C.T, f))
        return Q

    def potential(self, ctx):
        """``Σ EA (l − ρ)²/(2 ρ)`` over the taut sides (J); 0 when a reel depends on inputs
        (the winch then does work on the system: the sides' forces are not counted as
        conservative, as :class:`~ncgen.model.cables.ClusteredCable`'s with an input rest length)."""
        ea = self._value(ctx, self.ea, 1, "ea (in the potential energy)", inputs=False)
        try:
            rests = self.side_rests(ctx, inputs=False)
        except ExpressionError:          # generalized() has accepted the reels with the inputs
            return ca.SX(0)
        return sum((side_energy(length, rho, ea) for (length, _), (rho, _) in
                    zip(self.lengths(ctx), rests)), ca.SX(0))


def material_names(forces) -> set[str]:
    """The names of the material points of the :class:`CapstanCable` elements in ``forces``:
    state, not bodies (the viewer does not draw them)."""
    return {m.name for f in forces if isinstance(f, CapstanCable) for m in f.materials if m is not None}


def add_capstan_cable(system, path, *, pulley, mu, ea, rest_lengths, material_mass: float, wrap=None,
                      damping=0.0, turns=0, slip_velocity=SLIP_VELOCITY, reeled=None, name: str = "capstan"):
    """Add a :class:`CapstanCable` to ``system`` with a material point per drum (mass
    ``material_mass`` kg > 0, at the drum's point if on the ground, else at the origin) on a
    ground line perpendicular to gravity: ``<name>_material`` for one drum (``pulley`` an
    index), ``<name>_material1``, ``<name>_material2``, … for a list of drums; returns the force."""
    from ncgen.model.joints import PointOnLine

    m_s = as_scalar(material_mass, f"capstan cable {name!r}: material_mass")
    if not np.isfinite(m_s) or m_s <= 0:
        raise ModelError(f"capstan cable {name!r}: material_mass: expected a number > 0 (kg), got {m_s:g}")
    g = np.asarray(system.gravity, float)
    axis = _across(g)
    many = _one_or_many(pulley)
    force = CapstanCable(path, pulley=pulley, mu=mu, wrap=wrap, ea=ea, rest_lengths=rest_lengths,
                         material=[None] * len(pulley) if many else None, axis=axis, damping=damping, turns=turns,
                         slip_velocity=slip_velocity, reeled=reeled, name=name)
    force.check_values()
    materials = []
    for k, j in enumerate(force.drums):
        member, at = path[j]
        where = np.asarray(at, float) if member.is_ground else np.zeros(system.dim)
        material = system.add_point(f"{name}_material{k + 1 if many else ''}", mass=m_s, position=where)
        system.add_joint(PointOnLine(system.ground, material, at=where, axis=axis))
        materials.append(material)
    force.material = materials if many else materials[0]
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
