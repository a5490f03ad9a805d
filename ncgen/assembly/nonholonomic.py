"""Nonholonomic constraints ``B(q) v = c(q, t)`` beside a model's holonomic ones.

:class:`RollingSystem` joins a built model and its nonholonomic elements
(:class:`ncgen.model.rolling.RollingDisc`, :class:`~ncgen.model.rolling.RollingSphere`,
:class:`~ncgen.model.rolling.KnifeEdge`, whose
``equations`` give their rows).  Per disc of radius ρ on a body with pose
``(R, p)`` and world axle ``a = R ā`` (ā the axle in body axes), with ``n = e_z`` the
plane's normal and ``d = n − (n·â) â`` the direction from the centre to the top of the rim
in the disc's plane:

* holonomic: ``n·p − ρ |d| = 0``, the lowest point ``P = p − ρ d/|d|`` on ``z = 0``;
* nonholonomic: ``e_x·v_P = e_y·v_P = 0`` with ``v_P = ṗ + Ṙ ℓ``, ``ℓ = Rᵀ(P − p)`` the
  contact point in body axes held fixed: the velocity of the material point at the contact.

All constraints together, ``Φ̂(q) = 0`` (the model's Φ and the discs' heights) and
``Â(q) v = ĉ(q, t)`` (``Â = [∂Φ̂/∂q; B]``; ``ĉ`` is zero but for the rows of elements on a
moving plane, whose contact point moves with the plane: ``c = w(t)``, the plane's velocity,
:mod:`ncgen.model.rolling`), give the accelerations from the KKT system
``[[M, Âᵀ], [Â, 0]] [a; λ] = [F + f; γ̂ + ĉ_q v + ĉ_t]``, ``γ̂ = −∂(Â v)/∂q v`` (no
stabilisation terms: exact on the constraint manifold).  ``f`` is an extra generalised
force (N in the natural coordinates' sense: its power is ``fᵀ v``).  The constraint forces
``−Âᵀλ`` of a moving plane do work, power ``−λᵀ ĉ`` (W): ``dE/dt = vᵀ(F + f + ∇V) − λᵀ ĉ``.
The model's own constraints may depend on time (drives): ``Φ̂(q, t)``, and their rows of ``ĉ``
are ``−∂Φ̂/∂t``; only IDAS and the RATTLE stepper run such a model (``driven``).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.assembly.manifold import RANK_TOL
from ncgen.errors import ModelError
from ncgen.model.data import model_data
from ncgen.model.rolling import KnifeEdge, RollingDisc, RollingSphere


def coordinate_function(y, nq: int) -> ca.Function:
    """``y`` as a CasADi function ``q -> (y, y_q, ∂(y_q v)/∂[q; v])`` (``y``: a function of the
    natural coordinates, SX in and out)."""
    q, v = ca.SX.sym("q", nq), ca.SX.sym("v", nq)
    yq = y(q)
    Y = ca.jacobian(yq, q)
    yd = ca.mtimes(Y, v)
    return ca.Function("y", [q, v], [yq, Y, ca.jacobian(ca.vertcat(yq, yd), ca.vertcat(q, v))])


def _checked_elements(model, elements) -> list:
    """``elements`` as a list, each a nonholonomic element on a member of a 3D ``model``."""
    if model.dim != 3:
        raise ModelError(f"RollingSystem: model {model.name!r}: nonholonomic elements need a 3D model, "
                         f"found dim = {model.dim}")
    elements = list(elements)
    for element in elements:
        if not isinstance(element, (RollingDisc, RollingSphere, KnifeEdge)):
            raise ModelError(f"RollingSystem: elements: expected RollingDisc, RollingSphere or KnifeEdge "
                             f"elements, found {element!r}")
        if element.body not in model.member_names:
            raise ModelError(f"RollingSystem: {element!r}: body {element.body!r} is not a member of "
                             f"model {model.name!r} (members: {', '.join(model.member_names)})")
    return elements


def _element_equations(model, elements, q, t):
    """Each element's rows at its body's pose (SX of ``q`` and ``t``): ``(heights,
    nonholonomic rows, their planes' rates, height row names, nonholonomic row names)``."""
    R_all, p_all = model.functions["poses"](q)
    heights, rows, rates, height_names, row_names = [], [], [], [], []
    for element in elements:
        k = model.member_names.index(element.body)
        h, B = element.equations(R_all[:, 3 * k:3 * k + 3], p_all[:, k], q)
        heights.append(h)
        rows.append(B)
        rates.append(element.rate(R_all[:, 3 * k:3 * k + 3], t))
        height_names += [f"{element.name}.height"] * int(h.shape[0])
        row_names += [f"{element.name}.{axis}" for axis in
                      (("lateral",) if isinstance(element, KnifeEdge) else ("x", "y"))]
    return heights, rows, rates, height_names, row_names


class RollingSystem:
    """A model with nonholonomic elements: the CasADi functions of all its constraints and
    its accelerations.

    ``phi(q)``: holonomic residuals (model's, then the elements' heights; ``phi_at(q, t)``
    and ``A_at(q, t)`` at the time ``t``, which a driven model's need); ``B(q)``:
    the nonholonomic rows (2 per disc or ball, 1 per knife edge); ``A(q)``: ``[∂phi/∂q; B]``; ``gamma(q, v)``;
    ``rate(q, t)``: ``ĉ`` (``−∂Φ̂/∂t`` for the holonomic rows: zeros without drives);
    ``gamma_t(q, v, t) = −∂(Â v − ĉ)/∂q v + ∂ĉ/∂t − ∂Â/∂t v``; ``accel(q, v, f) -> (a, lam)``, on a
    plane at rest, and ``accel_t(q, v, f, t)``, any plane (``lam`` by ``row_names``: the force of a height row on
    the body is ``−λ e_z`` at the contact, N, so the normal force is ``−λ``; of the ``.x``/``.y``
    rows ``−λ e_x``/``−λ e_y`` at the contact, the friction force); ``tangent(q, v)``: the Jacobian of the state constraints
    ``[phi; A v]`` with respect to ``[q; v]`` (its null space is the tangent space of the
    motion's manifold)."""

    def __init__(self, model, elements):
        elements = _checked_elements(model, elements)
        self.model, self.elements = model, elements
        #: ``{method: DirectFunction}``: its compiled steps, made on first use by
        #: :func:`ncgen.runtime.rolling_integrator.compiled_step`.
        self.compiled_steps: dict = {}
        nq = model.nq
        self.nq = nq
        q, v = ca.SX.sym("q", nq), ca.SX.sym("v", nq)
        t = ca.SX.sym("t")
        phi_model = model.functions["phi"](t, q, ca.DM(model.p0))
        #: Whether the model's own constraints depend on time (drives): then ``phi``, ``A``,
        #: ``gamma``, ``accel``, ``accel_t``, ``tangent`` and the compiled steps, written at
        #: ``t = 0``, do not describe the motion, and only ``phi_at``, ``A_at``, ``rate`` and
        #: ``gamma_t`` (IDAS, the RATTLE stepper) do.
        self.driven = bool(ca.depends_on(phi_model, t))
        heights, rows, rates, height_names, row_names = _element_equations(model, elements, q, t)
        #: Names of the rows of ``A`` (and of the multipliers ``lam``): the model's constraints,
        #: then the elements' heights and their nonholonomic rows (``<element>.x``/``.y``: the
        #: contact point's material velocity along the plane; ``.lateral``: across a blade).
        self.row_names = list(model.constraint_names) + height_names + row_names
        #: Whether an element's plane moves (``ĉ`` depends on time or is not zero).
        self.rheonomic = any(e.rheonomic for e in elements)
        self._constraint_functions(q, v, t, ca.vertcat(phi_model, *heights), rows, rates)
        self._force_functions(q, v, t)
        self._kkt_functions()

    def _constraint_functions(self, q, v, t, phi_t, rows, rates) -> None:
        """``phi``, ``phi_at``, ``A_at``, ``B``, ``A``, ``gamma``, ``rate``, ``gamma_t`` and
        ``tangent`` from ``Φ̂(q, t)`` (``phi_t``), the nonholonomic ``rows`` and their planes'
        ``rates`` (SX of ``q``, ``v``, ``t``)."""
        phi = ca.substitute(phi_t, t, 0.0)
        B = ca.vertcat(*rows) if rows else ca.SX(0, self.nq)
        A = ca.vertcat(ca.jacobian(phi, q), B)
        A_t = ca.vertcat(ca.jacobian(phi_t, q), B)
        Av = ca.mtimes(A, v)
        gamma = -ca.jtimes(Av, q, v)
        # ĉ: −∂Φ̂/∂t for the holonomic rows (drives), the planes' rates for the rolling rows
        c = ca.vertcat(-ca.jacobian(phi_t, t), *rates)
        level = ca.mtimes(A_t, v) - c
        gamma_t = -ca.jtimes(level, q, v) - ca.jacobian(level, t)
        self.n_holonomic, self.n_nonholonomic = int(phi.shape[0]), int(B.shape[0])
        self.phi = ca.Function("phi", [q], [phi], ["q"], ["phi"])
        self.phi_at = ca.Function("phi_at", [q, t], [phi_t], ["q", "t"], ["phi"])
        self.A_at = ca.Function("A_at", [q, t], [A_t], ["q", "t"], ["A"])
        self.B = ca.Function("B", [q], [B], ["q"], ["B"])
        self.A = ca.Function("A", [q], [A], ["q"], ["A"])
        self.gamma = ca.Function("gamma", [q, v], [gamma], ["q", "v"], ["gamma"])
        self.rate = ca.Function("rate", [q, t], [c], ["q", "t"], ["c"])
        self.gamma_t = ca.Function("gamma_t", [q, v, t], [gamma_t], ["q", "v", "t"], ["gamma"])
        self.tangent = ca.Function("tangent", [q, v], [ca.jacobian(ca.vertcat(phi, Av), ca.vertcat(q, v))],
                                   ["q", "v"], ["G"])

    def _force_functions(self, q, v, t) -> None:
        """``F(q, v)``, the model's applied forces at ``t = 0``, ``u = 0`` and ``model.p0``, and
        whether the forces depend on time (``timed_forces``) and the constraints on the
        parameters (``parametric_constraints``): the equations here hold those values."""
        model = self.model
        u0, p0 = ca.DM.zeros(model.nu), ca.DM(model.p0)
        self.F = ca.Function("F", [q, v], [model.functions["F"](0.0, q, v, u0, p0)], ["q", "v"], ["F"])
        self.timed_forces = bool(ca.depends_on(model.functions["F"](t, q, v, u0, p0), t))
        p_sym = ca.SX.sym("p", len(model.p0))
        self.parametric_constraints = bool(len(model.p0)) and bool(ca.depends_on(model.functions["phi"](0.0, q, p_sym),
                                                                                  p_sym))

    def _kkt_functions(self) -> None:
        """``accel``, ``accel_t`` (the KKT system's solution, module docstring) and
        ``jacobians`` (of the state's rate ``[v; a]`` by ``[q; v]`` and of ``a`` by ``f``)."""
        nq = self.nq
        qm, vm, fm = ca.MX.sym("q", nq), ca.MX.sym("v", nq), ca.MX.sym("f", nq)
        Am = self.A(qm)
        m = Am.shape[0]
        K = ca.blockcat([[ca.MX(ca.DM(self.model.M)), Am.T], [Am, ca.MX(m, m)]])
        z = ca.solve(K, ca.vertcat(self.F(qm, vm) + fm, self.gamma(qm, vm)))
        self.accel = ca.Function("accel", [qm, vm, fm], [z[:nq], z[nq:]], ["q", "v", "f"], ["a", "lam"])
        tm = ca.MX.sym("t")
        z_t = ca.solve(K, ca.vertcat(self.F(qm, vm) + fm, self.gamma_t(qm, vm, tm)))
        self.accel_t = ca.Function("accel_t", [qm, vm, fm, tm], [z_t[:nq], z_t[nq:]], ["q", "v", "f", "t"],
                                   ["a", "lam"])
        x = ca.vertcat(qm, vm)
        rhs = ca.vertcat(vm, z[:nq])
        self.jacobians = ca.Function("jacobians", [qm, vm, fm],
                                     [ca.jacobian(rhs, x), ca.jacobian(z[:nq], fm)],
                                     ["q", "v", "f"], ["J", "a_f"])

    def check_rank(self, q) -> None:
        """Raise if the constraint rows ``Â(q)`` are dependent (no unique multipliers)."""
        A = np.asarray(self.A(q))
        s = np.linalg.svd(A, compute_uv=False)
        if s[-1] < RANK_TOL * s[0]:
            raise ModelError(f"RollingSystem: model {self.model.name!r}: the {A.shape[0]} constraint rows "
                             f"(holonomic and rolling) are dependent at this configuration "
                             f"(smallest singular value {s[-1]:.3g} of {s[0]:.3g})")

    def residuals(self, q, v, t: float = 0.0) -> tuple[float, float]:
        """``(|phi(q)|∞, |A(q) v − ĉ(q, t)|∞)``: holonomic and velocity-level constraint
        residuals at time ``t`` (s)."""
        level = np.asarray(self.A_at(q, t)) @ np.asarray(v, float) - np.asarray(self.rate(q, t)).ravel()
        return (float(np.max(np.abs(np.asarray(self.phi_at(q, t))), initial=0.0)),
                float(np.max(np.abs(level), initial=0.0)))


def rolling_system(model) -> RollingSystem:
    """The :class:`RollingSystem` of ``model`` and its own elements (``model.rolling``),
    made once and kept in the model's data."""
    data = model_data(model)
    if data.rolling_system is None:
        data.rolling_system = RollingSystem(model, model.rolling)
    return data.rolling_system


def multiplier_count(model) -> int:
    """The number of multipliers of a run of ``model``: its constraints' ``model.nc``, and
    with rolling elements also their heights and rolling rows (``rolling_system(model).row_names``)."""
    return len(rolling_system(model).row_names) if model.rolling else model.nc


def power_function(system: RollingSystem) -> ca.Function:
    """``(t, q, v, lam, u, p) -> [P; P_contacts; P_friction; P_inputs; P_drives]`` (W, one vector) of a
    model with rolling elements, ``lam`` its multipliers on all of ``system.row_names``: the
    model's own (:func:`ncgen.assembly.derived.power_parts_function` with its rows'
    multipliers) and the power the moving planes put in through their rows, ``−λ_rᵀ ĉ_r``
    (``M a = F − Âᵀλ`` and ``Â v = ĉ``), added to ``P`` and to the drives' part; a plane at
    rest does no work (``ĉ_r = 0``)."""
    from ncgen.assembly.derived import power_parts_function
    model = system.model
    t, q, v = ca.SX.sym("t"), ca.SX.sym("q", model.nq), ca.SX.sym("v", model.nq)
    lam, u, p = ca.SX.sym("lam", len(system.row_names)), ca.SX.sym("u", model.nu), ca.SX.sym("p", len(model.p0))
    plane = -ca.dot(lam[model.nc:], system.rate(q, t)[model.nc:])
    P = power_parts_function(model)(t, q, v, lam[:model.nc], u, p) + ca.vertcat(plane, 0, 0, 0, plane)
    return ca.Function("rolling_power", [t, q, v, lam, u, p], [P], ["t", "q", "v", "lam", "u", "p"], ["P"])
