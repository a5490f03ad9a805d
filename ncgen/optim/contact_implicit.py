"""Contact-implicit transcription: optimal control through nonsmooth contacts.

For a model built with ``contacts="nonsmooth"`` (:mod:`ncgen.model.contacts`), the motion
over ``N`` intervals of lengths ``h_k`` (equal, or decision variables summing to ``T``) is:

* in each interval, the compiled stepper's RATTLE step (docs/contact.md) from the node
  ``(q_k, w_k)`` with a contact force ``f_k`` (N) constant over the interval, half of it in
  each half-step along the contact Jacobian where it acts::

      M (m − w_k)     = h/2 F(t_k, q_k, w_k, u_k)         − A(q_k)ᵀ ν₁ + h/2 W(q_k)ᵀ f_k
      q_{k+1}         = q_k + h m,                         Φ(q_{k+1}) = 0
      M (v_{k+1} − m) = h/2 F(t_{k+1}, q_{k+1}, v_{k+1}, u_k) − A(q_{k+1})ᵀ ν₂ + h/2 W(q_{k+1})ᵀ f_k
      A(q_{k+1}) v_{k+1} + Φ_t = 0

  (exact for constant accelerations: free flight under gravity, a block sliding under a
  piecewise-constant push);
* at the inner nodes k = 1..N−1, an impact impulse ``P_k`` (N·s) takes the velocity before
  the node ``v_k`` to the velocity after it ``w_k``: ``M (w_k − v_k) = W(q_k)ᵀ P_k − A(q_k)ᵀ ν₃``,
  ``A(q_k) w_k + Φ_t = 0`` (``w_0 = v_0``).  With free step lengths a node lands on each
  impact, which is then resolved exactly.

Contact laws, per point contact (``W = [W_N; W_T]``, ``U = W v``; the polyhedral Coulomb
cone with ``n_d`` unit directions ``d_j`` in the tangent plane, ``f_T = Σ β_j d_j``):

* force over interval k: ``g(q_{k+1}) ≥ 0 ⊥ f_N ≥ 0``, and with free step lengths also
  ``g(q_k) ⊥ f_N`` (a force only while in contact at both ends: an impact must then fall on a
  node; with equal steps an impact inside a step is absorbed by its force, without
  restitution, as in Stewart–Trinkle time stepping, so contacts with restitution > 0 need
  free steps, the default for them); friction with maximum dissipation on the interval's mean
  velocity ``m``: ``γ + d_jᵀ W_T m ≥ 0 ⊥ β_j ≥ 0``, ``μ f_N − Σ β_j ≥ 0 ⊥ γ ≥ 0``;
* impulse at node k: ``g(q_k) ≥ 0 ⊥ P_N ≥ 0``; Newton's law as the nonsmooth stepper has it,
  ``r = U⁺_N + e U⁻_N``, ``r + b ≥ 0 ⊥ P_N`` with a slack ``b ≥ 0`` (an approach without
  impulse, allowed only while apart: ``b ⊥ P_N`` and ``b ⊥ f_N`` of the interval after the
  node, so that an impulse restores exactly ``U⁺_N = −e U⁻_N``), and no impulse where the
  interval before the node had a contact force (a lasting contact is carried by forces);
  friction on ``U⁺_T + e U⁻_T`` (the stepper's law) as above with ``P_N``.

Each complementarity pair ``a ≥ 0, c ≥ 0, a c = 0`` is relaxed to ``a c ≤ σ`` (Scholtes) and
IPOPT solves the sequence ``σ = σ₀, σ₀ κ, …, σ_final`` (σ a parameter of the NLP built once;
the first solve with the adaptive barrier update, the others warm started from the last
solution and its multipliers on the same IPOPT instance: :data:`FIRST_SOLVE`,
:data:`WARM_START`), with
``ρ Σ a·c`` in the cost (every pair but the friction cone's ``(μ f_N − Σ β) γ``: ``γ`` is
unbounded where ``μ f_N = 0``, and the tolerance on the cone would pay for it).  The polish
then solves once more with the active set fixed (the smaller side of every pair set to 0),
which removes the relaxation's bias; where IPOPT fails on it the homotopy's last solution is
kept.  The optimum is returned when its complementarity residual ``max_i min(a_i, c_i)`` (in
the pairs' units: m, N, N·s, m/s) is below ``tol``.  The relaxed problems of large ``σ`` are
the smoothed-contact variant: contact forces act a little before contact, friction a little
before sliding.
"""
from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ncgen.errors import OptimizationError
from ncgen.optim.diagnostics import SUCCESS
from ncgen.optim.transcription import Discretisation, Horizon, Transcription, guess_times

#: Point-contact kinds transcribed here: their gap (ncgen.assembly.contact_kinematics, the formulas of the
#: simulator's pair kernels) is smooth in q, or, a sphere against a box, continuously
#: differentiable wherever the gap is ≥ 0 (the distance to a convex body; its normal and
#: tangents those of the face, edge or corner nearest to the sphere).  Refused, named, until
#: transcribed: box corners against a box (``BoxBox``: the gap jumps from face to face),
#: edge crossings, capsules against spheres, capsules and boxes, a cylinder against a sphere,
#: a mesh against a plane.
SUPPORTED_KINDS = ("SpherePlane", "SphereSphere", "BoxPlane", "CapsulePlane", "CylinderPlane", "SphereBox")

#: Default homotopy and discretisation settings (``OptimalControl(contacts={...})``).
DEFAULTS = {
    "sigma0": 1e-1,              # first relaxation σ (units of the pairs' products)
    "sigma_final": 1e-6,         # last relaxation σ (the polish then removes its bias)
    "sigma_factor": 0.01,        # σ ← κ σ between solves
    "tol": 1e-6,                 # complementarity residual the optimum must reach
    "step_lengths": None,        # "equal" (h = T/N) or "free" (h_k variables, Σ h_k = T); None: free
                                 # where a contact has restitution > 0, else equal
    "step_bounds": (0.25, 4.0),  # free steps: h_k / (T/N) within these
    "step_weight": 1e-4,         # free steps: weight (s⁻¹) of Σ (h_k − T/N)² / (T/N) in the cost
    "directions": None,          # friction cone directions per contact (None: 2 planar, 4 in 3D)
    "penalty": 1.0,              # weight ρ of Σ a·c over the pairs in the cost (0: none)
    "polish": True,              # a last solve with the active set fixed (module docstring)
    "reaction_guess": False,     # guess the half-steps' ν₁, ν₂ = h/2 λ from the guess's multipliers
                                 # (its inverse dynamics) instead of 0 (a robot holding its weight)
}


#: IPOPT options of the homotopy's first solve (from the guess): the adaptive barrier update
#: took 189 instead of 369 iterations on the push of examples/block_push.py (T = 0.6 s).
FIRST_SOLVE = {"mu_strategy": "adaptive"}

#: IPOPT options of the homotopy's solves after the first: start from the last solution and
#: its multipliers, with a small barrier parameter (not IPOPT's default 0.1, which would move
#: the iterate back into the interior and lose the warm start).
WARM_START = {"warm_start_init_point": "yes", "mu_init": 1e-4, "warm_start_bound_push": 1e-6,
              "warm_start_slack_bound_push": 1e-6, "warm_start_mult_bound_push": 1e-6}


def nonsmooth_contacts(model) -> list[dict]:
    """The point contacts of ``model`` that act as unilateral constraints (nonsmooth model)."""
    return list(model.contacts) if model.contact_model == "nonsmooth" else []


def _label(spec: dict) -> str:
    element = spec.get("element")
    return f"{spec['name']!r} ({spec['type']}{'' if element is None else f' of element {element!r}'})"


def refuse_unsupported(model, method: str) -> None:
    """Refuse an optimal-control problem on a model whose nonsmooth contacts ``method``
    would ignore, naming them."""
    contacts = nonsmooth_contacts(model)
    if not contacts:
        return
    if method != "contact_implicit":
        names = ", ".join(_label(c) for c in contacts)
        raise OptimizationError(
            f"model {model.name!r} has nonsmooth contacts ({names}); method={method!r} would solve the problem as if "
            "they were absent. Use method='contact_implicit' (the default for such a model) or build the model with "
            "contacts='smooth'")
    bad = [c for c in contacts if c["type"] not in SUPPORTED_KINDS]
    if bad:
        raise OptimizationError(
            f"model {model.name!r}: no optimal-control transcription handles the contact(s) "
            f"{', '.join(_label(c) for c in bad)}: the contact-implicit transcription handles "
            f"{', '.join(SUPPORTED_KINDS)} only. Build the model with "
            "contacts='smooth' to optimise with the compliant law")


def check_settings(settings, dim: int, contacts=()) -> dict:
    """``contacts`` settings merged into :data:`DEFAULTS`, each checked (errors name the key);
    ``contacts``: the model's point contacts (restitution decides the step lengths)."""
    if settings is None:
        settings = {}
    if not isinstance(settings, dict):
        raise OptimizationError(f"contacts: expected a table of settings ({', '.join(DEFAULTS)}), got {settings!r}")
    unknown = sorted(set(settings) - set(DEFAULTS))
    if unknown:
        raise OptimizationError(f"contacts: unknown setting(s) {', '.join(unknown)}; known: {', '.join(DEFAULTS)}")
    out = {**DEFAULTS, **settings}
    for key in ("polish", "reaction_guess"):
        if not isinstance(out[key], bool):
            raise OptimizationError(f"contacts.{key}: expected true or false, got {out[key]!r}")
    for key in ("sigma0", "sigma_final", "tol", "step_weight", "penalty"):
        x = out[key]
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) or x < 0 or (
                key not in ("step_weight", "penalty") and x == 0):
            raise OptimizationError(f"contacts.{key}: expected a finite number "
                                    f"{'>= 0' if key in ('step_weight', 'penalty') else '> 0'}"
                                    f", got {x!r}")
        out[key] = float(x)
    if out["sigma_final"] > out["sigma0"]:
        raise OptimizationError(f"contacts.sigma_final: expected at most sigma0 = {out['sigma0']:g}, "
                                f"got {out['sigma_final']:g}")
    k = out["sigma_factor"]
    if isinstance(k, bool) or not isinstance(k, (int, float)) or not 0 < k < 1:
        raise OptimizationError(f"contacts.sigma_factor: expected a number in (0, 1), got {k!r}")
    bouncing = [c["name"] for c in contacts if c["restitution"] > 0]
    if out["step_lengths"] is None:
        out["step_lengths"] = "free" if bouncing else "equal"
    if out["step_lengths"] not in ("equal", "free"):
        raise OptimizationError(f"contacts.step_lengths: expected \"equal\" or \"free\", got {out['step_lengths']!r}")
    if out["step_lengths"] == "equal" and bouncing:
        raise OptimizationError(f"contacts.step_lengths: \"equal\" steps resolve an impact inside a step without "
                                f"restitution, and contact(s) {', '.join(map(repr, bouncing))} have restitution > 0; "
                                "use \"free\" (a node on each impact)")
    b = out["step_bounds"]
    if not (isinstance(b, (list, tuple)) and len(b) == 2 and all(isinstance(x, (int, float)) for x in b)
            and 0 < b[0] <= 1 <= b[1] and math.isfinite(b[1])):
        raise OptimizationError(f"contacts.step_bounds: expected (lower, upper) with 0 < lower <= 1 <= upper "
                                f"(fractions of T/N), got {b!r}")
    out["step_bounds"] = (float(b[0]), float(b[1]))
    nd = out["directions"]
    if nd is None:
        nd = 2 if dim == 2 else 4
    if isinstance(nd, bool) or not isinstance(nd, int) or nd < 2 or (dim == 2 and nd != 2) or nd % 2:
        raise OptimizationError(f"contacts.directions: expected an even integer >= 2 (2 in planar systems), got {nd!r}")
    out["directions"] = nd
    return out


@dataclass
class Pair:
    """A complementarity pair ``a ≥ 0, c ≥ 0, a c ≤ σ`` (``label`` names it in reports)."""

    label: str
    a: object
    c: object
    a_imposed: bool = False      # ``a ≥ 0`` is imposed elsewhere (gaps)
    penalised: bool = True       # in the cost's ρ Σ a·c (not the cone's: γ is unbounded where μ f_N = 0)


def _directions(nt: int, nd: int) -> np.ndarray:
    """``nt × nd`` unit directions in the tangent plane: ``±t`` (planar) or ``nd`` equally spaced."""
    if nt == 1:
        return np.array([[1.0, -1.0]])
    ang = 2 * np.pi * np.arange(nd) / nd
    return np.vstack([np.cos(ang), np.sin(ang)])



@dataclass
class _Unknowns:
    """The decision variables (module docstring's names) and the time grid: ``q``, ``v``, ``w``
    the nodes' positions and velocities before and after their impulse (``q_0``, ``v_0 = w_0``
    from the horizon), ``h`` the 1 × N step lengths (s), ``t`` the node times."""

    Q: object
    V: object
    W: object
    U: object
    Mid: object
    fN: object
    beta: object
    gam: object
    PN: object
    Pbeta: object
    Pgam: object
    slack: object
    scale: object
    h: object
    t: object
    q: object
    v: object
    w: object


def _unknowns(opti: ca.Opti, model, hz: Horizon, nk: int, s: dict) -> _Unknowns:
    """The transcription's variables, with the step scales' bounds (free steps) and the
    forces', impulses' and slacks' ``≥ 0``."""
    N, nq, nu = hz.N, model.nq, model.nu
    nd = _directions(model.dim - 1, s["directions"]).shape[1]
    Q, V, W, U = opti.variable(nq, N), opti.variable(nq, N), opti.variable(nq, N - 1), opti.variable(nu, N)
    Mid = opti.variable(nq, N)
    fN = opti.variable(nk, N)                      # interval contact forces (N)
    beta = opti.variable(nk * nd, N)
    gam = opti.variable(nk, N)
    PN = opti.variable(nk, N - 1)                  # node impulses (N·s), nodes 1..N−1
    Pbeta = opti.variable(nk * nd, N - 1)
    Pgam = opti.variable(nk, N - 1)
    slack = opti.variable(nk, N - 1)
    if s["step_lengths"] == "free":
        scale = opti.variable(N)
        opti.subject_to(opti.bounded(*s["step_bounds"][:1], scale, s["step_bounds"][1]))
        opti.subject_to(ca.sum1(scale) == N)
    else:
        scale = ca.DM.ones(N)
    h = hz.T / N * scale.T
    for x in (fN, beta, gam, PN, Pbeta, Pgam, slack):
        if x.numel():
            opti.subject_to(ca.vec(x) >= 0)
    return _Unknowns(Q=Q, V=V, W=W, U=U, Mid=Mid, fN=fN, beta=beta, gam=gam, PN=PN, Pbeta=Pbeta, Pgam=Pgam,
                     slack=slack, scale=scale, h=h, t=hz.t0 + ca.horzcat(ca.DM(0), ca.cumsum(h.T).T),
                     q=ca.horzcat(hz.q0, Q), v=ca.horzcat(hz.v0, V), w=ca.horzcat(hz.v0, W))


class _Laws:
    """The transcription's equations, gathered in ``defects`` (``(label, expression = 0)``) and
    ``pairs`` (:class:`Pair`): the RATTLE half-steps with their contact forces over each
    interval, the impacts at the inner nodes, Signorini's and Coulomb's laws on both."""

    def __init__(self, model, p, contacts, D: np.ndarray):
        self.f, self.p, self.contacts = model.functions, p, contacts
        self.nq, self.nc, self.nk, self.nt = model.nq, model.nc, len(contacts), model.dim - 1
        self.D, self.nd = D, D.shape[1]
        self.mu = np.array([c["mu"] for c in contacts])
        self.e = np.array([c["restitution"] for c in contacts])
        self.M = ca.DM(self.f["mass"]()["M"])
        self.pairs: list[Pair] = []
        self.defects = []

    def contact_rows(self, qk):
        """``(g, W_N, W_T)`` at configuration ``qk``."""
        g = self.f["gap"](qk, self.p)
        WN, WT = self.f["contact_jacobian"](qk, self.p)
        return g, WN, WT

    def tangential(self, WT, beta_k):
        """Generalised force of the friction components ``β`` (nk·nd) along W_T."""
        nd = self.nd
        if self.nt == 0 or self.nk == 0:
            return ca.MX.zeros(self.nq, 1)
        fT = ca.vertcat(*[ca.mtimes(ca.DM(self.D), beta_k[i * nd:(i + 1) * nd]) for i in range(self.nk)])
        return ca.mtimes(WT.T, fT)

    def friction(self, label, normal, UT, beta_k, gam_k):
        """Maximum dissipation on the tangential velocity ``UT`` and the polyhedral Coulomb
        cone of ``normal`` (a force or an impulse); a frictionless contact's ``β``, ``γ`` = 0."""
        nd, nt, D = self.nd, self.nt, ca.DM(self.D)
        for i in range(self.nk):
            name = self.contacts[i]["name"]
            if self.mu[i] == 0:
                self.defects.append((f"{label} (frictionless contact {name!r})",
                                     ca.vertcat(beta_k[i * nd:(i + 1) * nd], gam_k[i])))
                continue
            ut = UT[i * nt:(i + 1) * nt]
            for j in range(nd):
                self.pairs.append(Pair(f"{label}: maximum dissipation, contact {name!r}",
                                       gam_k[i] + ca.dot(D[:, j], ut), beta_k[i * nd + j]))
            self.pairs.append(Pair(f"{label}: Coulomb cone, contact {name!r}",
                                   self.mu[i] * normal[i] - ca.sum1(beta_k[i * nd:(i + 1) * nd]), gam_k[i],
                                   penalised=False))

    def interval(self, opti: ca.Opti, x: _Unknowns, k: int, rows, free: bool):
        """Interval k's RATTLE step with its contact force and the force's laws (``free``:
        free step lengths, a force only while in contact at both ends); returns the
        half-steps' multipliers ``(ν₁, ν₂)`` (None without constraints)."""
        f, p, nk = self.f, self.p, self.nk
        tk, tk1, hk = x.t[k], x.t[k + 1], x.h[k]
        qk, wk, qk1, vk1, mk = x.q[:, k], x.w[:, k], x.q[:, k + 1], x.v[:, k + 1], x.Mid[:, k]
        uk = x.U[:, k]
        force = ca.MX.zeros(self.nq, 1)
        force1 = ca.MX.zeros(self.nq, 1)
        if nk:
            g0, WN0, WT0 = rows[k]
            g1, WN1, WT1 = rows[k + 1]
            force = ca.mtimes(WN0.T, x.fN[:, k]) + self.tangential(WT0, x.beta[:, k])
            force1 = ca.mtimes(WN1.T, x.fN[:, k]) + self.tangential(WT1, x.beta[:, k])
        r1 = ca.mtimes(self.M, mk - wk) - hk / 2 * (f["F"](tk, qk, wk, uk, p) + force)
        r2 = ca.mtimes(self.M, vk1 - mk) - hk / 2 * (f["F"](tk1, qk1, vk1, uk, p) + force1)
        half_step = None
        if self.nc:
            nu1, nu2 = opti.variable(self.nc), opti.variable(self.nc)
            half_step = (nu1, nu2)                     # λ at node k+1: the second half-step's ν₂ = h/2 λ
            r1 += ca.mtimes(f["A"](tk, qk, p).T, nu1)
            r2 += ca.mtimes(f["A"](tk1, qk1, p).T, nu2)
            self.defects.append((f"position constraints Φ at node {k + 1}", f["phi"](tk1, qk1, p)))
            self.defects.append((f"velocity constraints at node {k + 1}",
                                 ca.mtimes(f["A"](tk1, qk1, p), vk1) + f["phi_t"](tk1, qk1, p)))
        self.defects.append((f"dynamics (first half-step, interval {k})", r1))
        self.defects.append((f"dynamics (positions, interval {k})", qk1 - qk - hk * mk))
        self.defects.append((f"dynamics (second half-step, interval {k})", r2))
        if nk:
            opti.subject_to(g1 >= 0)
            if k == 0 and ca.symvar(g0):
                opti.subject_to(g0 >= 0)
            if free:
                self.pairs.append(Pair(f"interval {k}: gap at its start ⊥ contact force", g0, x.fN[:, k], True))
            self.pairs.append(Pair(f"interval {k}: gap at its end ⊥ contact force", g1, x.fN[:, k], True))
            self.friction(f"interval {k}", x.fN[:, k], ca.mtimes(WT1, mk), x.beta[:, k], x.gam[:, k])
        return half_step

    def impact(self, opti: ca.Opti, x: _Unknowns, k: int, rows):
        """The impulse at inner node k from ``v_k`` to ``w_k`` and its laws (Signorini,
        Newton's impact law with its approach slack, Coulomb)."""
        f, p, nk, e = self.f, self.p, self.nk, self.e
        qk, vk, wk, t = x.q[:, k], x.v[:, k], x.w[:, k], x.t
        jump = ca.mtimes(self.M, wk - vk)
        if nk:
            g, WN, WT = rows[k]
            jump -= ca.mtimes(WN.T, x.PN[:, k - 1]) + self.tangential(WT, x.Pbeta[:, k - 1])
        if self.nc:
            nu3 = opti.variable(self.nc)
            jump += ca.mtimes(f["A"](t[k], qk, p).T, nu3)
            self.defects.append((f"velocity constraints after the impulse at node {k}",
                                 ca.mtimes(f["A"](t[k], qk, p), wk) + f["phi_t"](t[k], qk, p)))
        self.defects.append((f"impact at node {k}", jump))
        if nk:
            r = ca.mtimes(WN, wk) + e * ca.mtimes(WN, vk)
            PN, slack, fN = x.PN, x.slack, x.fN
            self.pairs += [
                Pair(f"node {k}: gap ⊥ impulse", g, PN[:, k - 1], True),
                Pair(f"node {k}: Newton's impact law (U⁺ + e U⁻) ⊥ impulse", r + slack[:, k - 1], PN[:, k - 1]),
                Pair(f"node {k}: approach without impulse ⊥ impulse", slack[:, k - 1], PN[:, k - 1], True),
                Pair(f"node {k}: contact force before the node ⊥ impulse", fN[:, k - 1], PN[:, k - 1], True),
                Pair(f"node {k}: approach without impulse ⊥ contact force after the node", slack[:, k - 1],
                     fN[:, k], True)]
            self.friction(f"node {k}", PN[:, k - 1], ca.mtimes(WT, wk) + np.repeat(e, self.nt) * ca.mtimes(WT, vk),
                          x.Pbeta[:, k - 1], x.Pgam[:, k - 1])


def _relax(opti: ca.Opti, pairs: list[Pair], sigma) -> None:
    """Scholtes' relaxation ``a c ≤ σ`` of every pair, with ``a ≥ 0`` where not imposed
    elsewhere (every ``c`` is a variable bounded below by 0), in one ``subject_to``."""
    rows = []
    for pair in pairs:
        product = pair.a * pair.c
        if ca.symvar(product):                     # (a gap fixed at 0 by the initial state leaves c free)
            rows.append(product - sigma)
        if not pair.a_imposed:
            rows.append(-pair.a)
    if rows:                                       # one call: Opti's subject_to costs ~2 ms a call
        opti.subject_to(ca.vertcat(*rows) <= 0)


class ContactImplicit(Transcription):
    """The contact-implicit transcription (module docstring); ``settings`` as in :data:`DEFAULTS`."""

    hessian = "exact"
    #: IPOPT keeps the bounds ``≥ 0`` of forces and impulses exactly (no relaxation): a
    #: product ``a·c`` then never turns negative by more than the constraint tolerance.
    #: (``mu_strategy="adaptive"`` took 119 instead of 386 iterations on the ball of
    #: examples/ball_bounce_target.py and 362 instead of 814 on the planar push of
    #: examples/block_push.py, but left the 3D push stuck for its first step: not the default.)
    ipopt_options = {"bound_relax_factor": 0.0}

    def __init__(self, model, settings=None):
        refuse_unsupported(model, "contact_implicit")
        self.contacts = nonsmooth_contacts(model)
        self.settings = check_settings(settings, model.dim, self.contacts)

    def describe(self) -> str:
        s = self.settings
        return (f"contact-implicit time stepping (RATTLE, {s['step_lengths']} steps, Scholtes σ "
                f"{s['sigma0']:g} → {s['sigma_final']:g})")

    # ------------------------------------------------------------------ build
    def build(self, opti: ca.Opti, model, hz: Horizon) -> Discretisation:
        s = self.settings
        N, nc = hz.N, model.nc
        self.sigma = opti.parameter()
        opti.set_value(self.sigma, s["sigma0"])
        x = _unknowns(opti, model, hz, len(self.contacts), s)
        laws = _Laws(model, hz.p, self.contacts, _directions(model.dim - 1, s["directions"]))
        rows = [laws.contact_rows(x.q[:, k]) for k in range(N + 1)] if laws.nk else None
        half_steps = [laws.interval(opti, x, k, rows, s["step_lengths"] == "free") for k in range(N)]
        for k in range(1, N):
            laws.impact(opti, x, k, rows)
        _relax(opti, laws.pairs, self.sigma)
        self.pairs = Pairs(laws.pairs)
        self.vars = dict(Q=x.Q, V=x.V, W=x.W, Mid=x.Mid, scale=x.scale, slack=x.slack, fN=x.fN, beta=x.beta,
                         PN=x.PN, Pbeta=x.Pbeta, t=x.t, h=x.h, D=laws.D)
        h = x.h
        quad_w = ca.horzcat(h[0] / 2, (h[:, :-1] + h[:, 1:]) / 2, h[-1] / 2) if N > 1 else ca.horzcat(h / 2, h / 2)
        lam = ca.horzcat(*[2 * nu2 / x.h[k] for k, (_, nu2) in enumerate(half_steps)]) if nc else None
        return Discretisation(q=x.q, v=x.v, lam=lam, U=x.U, path_t=x.t[:, 1:], path_q=x.Q, path_v=x.V,
                              quad_t=x.t, quad_q=x.q, quad_v=x.v, quad_w=quad_w, defects=laws.defects,
                              set_guess=functools.partial(self._set_guess, model, hz, x, half_steps), t_nodes=x.t,
                              interval_w=h, extra_cost=self._extra_cost(hz, x.scale, laws.pairs))

    def _extra_cost(self, hz: Horizon, scale, pairs):
        """The cost's terms of the transcription: the free steps' spread ``Σ (h_k − T/N)² / (T/N)``
        and the pairs' penalty ``ρ Σ a·c``."""
        s = self.settings
        extra = ca.MX(0)
        if s["step_lengths"] == "free":
            extra += s["step_weight"] * hz.T / hz.N * ca.sumsqr(scale - 1)
        if s["penalty"] and pairs:
            extra += s["penalty"] * sum(ca.dot(pair.a, pair.c) for pair in pairs if pair.penalised)
        return extra

    def _set_guess(self, model, hz: Horizon, x: _Unknowns, half_steps, o: ca.Opti, g):
        """Initial values from the guess ``g``: nodes, mean velocities, inputs, step scales,
        (``reaction_guess``) the half-steps' ``ν = h/2 λ``, and the impulses and forces it implies."""
        s, N, nu, nc, nk = self.settings, hz.N, model.nu, model.nc, len(self.contacts)
        p = hz.p
        p_num = np.array(p, float).reshape(-1) if isinstance(p, ca.DM) else np.array(model.p0, float)
        tg = guess_times(hz, g.T, np.array([1.0]))
        qg, vg = g.q(tg).T, g.v(tg).T
        o.set_initial(x.Q, qg)
        o.set_initial(x.V, vg)
        if N > 1:
            o.set_initial(x.W, vg[:, :-1])
        q_all = np.hstack([g.q(np.array([hz.t0])).T, qg])
        o.set_initial(x.Mid, np.diff(q_all, axis=1) / (g.T / N))
        if nu:
            o.set_initial(x.U, g.u(guess_times(hz, g.T, [0.0])).T)
        if s["step_lengths"] == "free":
            o.set_initial(x.scale, np.ones(N))
        if s["reaction_guess"] and nc:
            lam_g = g.lam(guess_times(hz, g.T, np.array([0.0, 1.0]))).T     # λ at the start and end of each step
            for k, (nu1, nu2) in enumerate(half_steps):
                o.set_initial(nu1, g.T / N / 2 * lam_g[:, 2 * k])
                o.set_initial(nu2, g.T / N / 2 * lam_g[:, 2 * k + 1])
        if nk and N > 1:
            v_all = np.hstack([g.v(np.array([hz.t0])).T, vg])
            u_all = g.u(guess_times(hz, g.T, [0.0])).T if nu else np.zeros((0, N))
            PN0, fN0, W0, slack0 = self._guess_impulses(model, q_all, v_all, u_all, g.T / N, hz.t0, p_num)
            o.set_initial(x.PN, PN0)
            o.set_initial(x.fN, fN0)
            o.set_initial(x.W, W0)
            o.set_initial(x.slack, slack0)

    def _guess_impulses(self, model, q, v, u, h, t0, p):
        """Node impulses (nk × N−1), interval forces (nk × N), velocities after the impulses
        and approach slacks that a guess sampled at equal steps implies: the normal impulse
        each interval's velocity change needs beyond the applied forces (none where the
        contact is farther apart at both ends than it moves in a step), put on the inner
        node with the smaller gap where the contact approaches (an impact), else spread over
        the interval as a force (a lasting contact)."""
        f = model.functions
        N = q.shape[1] - 1
        nk = len(self.contacts)
        e = np.array([c["restitution"] for c in self.contacts])
        M = np.array(f["mass"]()["M"], float)
        Minv = np.linalg.pinv(M)
        gaps = np.column_stack([np.array(f["gap"](q[:, k], p), float).reshape(-1) for k in range(N + 1)])
        PN, fN = np.zeros((nk, N - 1)), np.zeros((nk, N))
        for k in range(N):
            uk = u[:, k] if u.size else np.zeros(0)
            jump = M @ (v[:, k + 1] - v[:, k]) - h * np.array(f["F"](t0 + k * h, q[:, k], v[:, k], uk, p)).reshape(-1)
            WN = np.array(f["contact_jacobian"](q[:, k], p)[0], float).reshape(nk, -1)
            for i in range(nk):
                P = WN[i] @ Minv @ jump / (WN[i] @ Minv @ WN[i])
                inner = [j for j in (k, k + 1) if 1 <= j <= N - 1]
                reach = h * max(abs(WN[i] @ v[:, k]), abs(WN[i] @ v[:, k + 1])) + 1e-9
                if P <= 0 or min(gaps[i, k], gaps[i, k + 1]) > reach:   # no push where the guess is apart
                    continue
                if WN[i] @ v[:, k] < 0 and inner:         # an impact: an impulse at a node
                    j = min(inner, key=lambda j: gaps[i, j])
                    PN[i, j - 1] += P
                else:                                   # a lasting contact: a force
                    fN[i, k] = P / h
        W = np.zeros((model.nq, N - 1))
        slack = np.zeros((nk, N - 1))
        for j in range(1, N):
            WN = np.array(f["contact_jacobian"](q[:, j], p)[0], float).reshape(nk, -1)
            W[:, j - 1] = v[:, j] + Minv @ WN.T @ PN[:, j - 1]
            slack[:, j - 1] = np.maximum(0.0, -(WN @ W[:, j - 1] + e * (WN @ v[:, j])))
        return PN, fN, W, slack

    # ------------------------------------------------------------------ solve
    def solve(self, nlp, solve_once, tol_ipopt: float):
        """The Scholtes homotopy: ``solve_once()`` at each σ, warm started from the last."""
        s, opti = self.settings, nlp.opti
        sigma = s["sigma0"]
        self.history = []
        elapsed = 0.0
        extra = dict(FIRST_SOLVE)
        while True:
            opti.set_value(self.sigma, sigma)
            cpu = time.process_time()
            value = solve_once(**extra)
            cpu = time.process_time() - cpu
            elapsed += nlp.solve_time
            residual = complementarity_residual(self.pairs, value)
            stats = nlp.opti.stats()
            self.history.append({"sigma": sigma, "status": stats.get("return_status", ""),
                                 "iterations": int(stats.get("iter_count", 0)), "residual": residual,
                                 "cpu_time": cpu})
            self.status = stats.get("return_status", "")
            if sigma <= s["sigma_final"] or self.status not in SUCCESS:
                break
            opti.set_initial(opti.x, value(opti.x))
            opti.set_initial(opti.lam_g, value(opti.lam_g))
            extra = dict(WARM_START)
            sigma = sigma * s["sigma_factor"]
            if sigma < s["sigma_final"] * (1 + 1e-9):
                sigma = s["sigma_final"]
        if s["polish"] and self.status in SUCCESS:
            polished = self._polish(nlp, solve_once, value)
            elapsed += nlp.solve_time
            if polished is not None:
                value = polished
                residual = complementarity_residual(self.pairs, value)
        self.residual = residual
        nlp.solve_time = elapsed
        return value

    def _polish(self, nlp, solve_once, value):
        """One more solve with the active set of ``value`` fixed: in each pair the smaller
        side is set to 0 (an equality), which removes the relaxation's bias.  Returns the
        new solution, or ``None`` (the homotopy's kept) where IPOPT fails on it."""
        opti = nlp.opti
        fixed: dict[str, object] = {}
        for pair, (a, c) in zip(self.pairs, pair_values(self.pairs, value)):
            for i in range(a.size):
                side = pair.a[i] if a[i] <= c[i] else pair.c[i]
                if ca.symvar(side):
                    fixed.setdefault(str(side), side)
        if len(fixed) + sum(e.numel() for _, e in nlp.disc.defects) >= opti.nx:
            return None
        opti.subject_to(ca.vertcat(*fixed.values()) == 0)
        opti.set_initial(opti.x, value(opti.x))
        cpu = time.process_time()
        polished = solve_once()
        cpu = time.process_time() - cpu
        stats = opti.stats()
        self.history.append({"sigma": "polish", "status": stats.get("return_status", ""),
                             "iterations": int(stats.get("iter_count", 0)),
                             "cpu_time": cpu,
                             "residual": complementarity_residual(self.pairs, polished)})
        if stats.get("return_status", "") not in SUCCESS:
            return None
        self.status = stats["return_status"]
        return polished

    def finish(self, value, result) -> None:
        """Attach the contact forces (``result.contact_force``: N × nk normal, N), impulses
        (``result.contact_impulse``: (N+1) × nk, N·s), the complementarity residual and the
        homotopy's history to ``result``, with the status of the solve it returns (the
        homotopy's last where the polish failed); refuse a residual above ``tol``."""
        result.stats.status = self.status
        result.stats.success = self.status in SUCCESS
        v = self.vars
        result.contact_force = np.array(value(v["fN"])).reshape(len(self.contacts), -1).T
        PN = np.array(value(v["PN"])).reshape(len(self.contacts), -1).T
        z = np.zeros((1, len(self.contacts)))
        result.contact_impulse = np.vstack([z, PN, z])
        result.complementarity_residual = self.residual
        result.homotopy = list(self.history)
        result.stats.iterations = sum(h["iterations"] for h in self.history)
        if result.stats.success and self.residual > self.settings["tol"]:
            worst = worst_pair(self.pairs, value)
            raise OptimizationError(
                f"contact-implicit solve: the complementarity residual {self.residual:.3g} exceeds contacts.tol = "
                f"{self.settings['tol']:g} (worst: {worst}); lower contacts.sigma_final or raise N", result=result)


class Pairs(list):
    """A list of :class:`Pair` with both sides of every pair stacked in one expression, built
    once (evaluating a side per pair cost 2.3 s on the push of examples/block_push.py,
    stacking them anew at each evaluation 0.06 s)."""

    @functools.cached_property
    def stacked(self):
        sides = [ca.MX(x) for pair in self for x in (pair.a, pair.c)]
        return ca.vertcat(*sides), [ca.MX(pair.a).numel() for pair in self]


def pair_values(pairs, value) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(a, c)`` of every pair at the solution ``value``, in one evaluation."""
    if not pairs:
        return []
    stacked, sizes = (pairs if isinstance(pairs, Pairs) else Pairs(pairs)).stacked
    flat = np.array(ca.DM(value(stacked)), float).reshape(-1)
    out, at = [], 0
    for n in sizes:
        out.append((flat[at:at + n], flat[at + n:at + 2 * n]))
        at += 2 * n
    return out


def complementarity_residual(pairs, value) -> float:
    """``max_i min(a_i, c_i)`` over every pair (0 when every pair is complementary)."""
    return max((float(np.max(np.abs(np.minimum(a, c)), initial=0.0)) for a, c in pair_values(pairs, value)),
               default=0.0)


def worst_pair(pairs, value) -> str:
    best, label = -1.0, ""
    for pair, (a, c) in zip(pairs, pair_values(pairs, value)):
        r = float(np.max(np.abs(np.minimum(a, c)), initial=0.0))
        if r > best:
            best, label = r, pair.label
    return f"{label}: {best:.3g}"
