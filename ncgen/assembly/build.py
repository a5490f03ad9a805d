"""From a :class:`~ncgen.model.system.System` to a :class:`~ncgen.model.model.Model`:
layout, CasADi expressions, constant mass matrix, redundancy and initial-state checks."""
from __future__ import annotations

import copy
import warnings

import casadi as ca
import numpy as np

from ncgen.assembly.drive_assembly import assemble_drives
from ncgen.assembly.contact_kinematics import (check_initial_gaps, contact_functions, contact_specs, contact_terms,
                                     smooth_forces)
from ncgen.assembly.functions import system_functions
from ncgen.assembly.initial_state import consistent_state
from ncgen.assembly.joint_space import JointSpace, actuator_forces, build_joint_coordinates
from ncgen.assembly import kinematics
from ncgen.assembly.kinematics import resolve_fix
from ncgen.assembly.manifold import system_size
from ncgen.assembly.limits import model_limits
from ncgen.assembly.manifold import check_tangent_inertia
from ncgen.assembly.mass import assemble_mass, dense_dm, flat_members, flat_support, mass_factor
from ncgen.assembly.rank import dependent_rows
from ncgen.assembly.redundancy import classify
from ncgen.assembly.springs import spring_table
from ncgen.assembly.unshared import UnsharedForm
from ncgen.errors import ModelError
from ncgen.interrupts import raise_if_interrupted
from ncgen.model.context import Context
from ncgen.model.function_set import FunctionSet
from ncgen.model.layout import Layout, make_layout
from ncgen.model.sharing import SharingPlan, intrinsic_key, share_coordinates

#: Default Baumgarte coefficients (α, β) in 1/s: constraint errors decay like a critically
#: damped oscillator with time constant 0.2 s.  IDAS keeps the drift small anyway; the
#: terms only stop it from growing over long runs.
BAUMGARTE = (5.0, 5.0)

REDUNDANT_MODES = ("drop", "error", "keep")
#: How contacts enter the model: compliant forces in F, or unilateral constraints for the
#: nonsmooth compiled stepper (docs/contact.md).
CONTACT_MODELS = ("smooth", "nonsmooth")


def build_model(system, *, baumgarte=BAUMGARTE, redundant: str = "drop", tolerance: float = 1e-6,
                t0: float = 0.0, assemble: bool = False, fix=(), contacts: str = "smooth",
                share: bool = True):
    """Assemble ``system`` into a :class:`~ncgen.model.model.Model`.

    ``redundant``: constraints linearly dependent at the initial configuration are
    ``"drop"``-ped with a warning naming them, raise (``"error"``), or are kept
    (``"keep"``, for analysis only: the DAE is then singular).  A dependent constraint is
    dropped only if it is implied by the others near the initial configuration and
    satisfied (:mod:`ncgen.assembly.redundancy`); one that contradicts the others, or that is
    dependent only because the configuration is singular, is an error naming it.  ``tolerance``: the largest
    correction, relative to the system's size, that making the initial state consistent
    may apply; beyond it the build fails and says where.  ``assemble=True``: the members'
    initial poses are only a guess; Newton moves them onto the constraints (drives at
    ``t0`` included, continued from the given poses to their values at ``t0``, before the
    redundancy checks: :mod:`ncgen.assembly.drive_assembly`) without limit, keeping the coordinates named in ``fix``
    (:func:`ncgen.assembly.kinematics.resolve_fix`) and their rates as given.  Joints
    given at world points hold in the given poses by construction; what needs assembling
    is a drive or coordinate driver that prescribes another position at ``t0``.  To
    assemble an arbitrary configuration vector use :func:`ncgen.assemble`.  ``share``:
    eliminate the joints that shared coordinates can express (:mod:`ncgen.model.sharing`;
    ``model.sharing`` says which); ``share=False`` keeps every joint's equations, and so
    does ``fix`` (it names coordinates as written).
    """
    from ncgen.model.model import Constraints, Contacts, Dynamics, Model, Origin, Parameters

    system = copy.deepcopy(system)       # the model's own description: later edits of the caller's system do not reach it
    _check_build_options(system, contacts, redundant)
    alpha, beta = (float(x) for x in baumgarte)
    recipe = (system, dict(baumgarte=(alpha, beta), redundant=redundant, tolerance=tolerance, t0=t0,
                           assemble=assemble, fix=tuple(fix), contacts=contacts, share=share))
    plan = unshared = None
    if share and not fix:          # fix names coordinates as written: no sharing then
        system, plan, unshared = _shared_coordinates(system, dict(baumgarte=baumgarte, redundant=redundant,
                                                                  tolerance=tolerance, t0=t0, assemble=assemble,
                                                                  contacts=contacts))
    members = list(system.members.values())
    layout = make_layout(system.dim, members)
    ctx = Context(system, layout)
    fixed = resolve_fix(layout, system.members, fix)
    labels, rows = constraint_rows(system, ctx, plan)
    limits = model_limits(system, ctx)
    coords, skipped = build_joint_coordinates(system, ctx)
    actuation = actuator_forces(ctx, coords)
    F, V, passive, terms = _applied_forces(system, ctx, actuation, contacts)
    M, factor = _mass(layout, members)
    q_init, v_init, moving = initial_guess(layout, members)
    p0 = _parameter_values(system, limits)
    if assemble:                    # drives move the mechanism first: the checks below see where they put it
        q_init = assemble_drives(system, ctx, lambda c: constraint_rows(system, c, plan)[1], q_init, p0, t0, fixed)
    labels, rows, redundant_labels = _redundant_constraints(system.name, ctx, labels, rows, plan, redundant,
                                                            (q_init, p0, t0))
    phi = ca.vertcat(*rows) if rows else ca.SX(0, 1)
    if not factor.regular:        # a flat body: M must be positive definite on null(A)
        _check_flat_inertia(system.name, ctx, phi, M, members, (t0, q_init, p0))
    makers, potential = system_functions(ctx, phi, F, V, M, factor, alpha, beta, system)
    functions = FunctionSet(makers, contact_functions(ctx, terms) if terms else None)   # each made on first use
    start = _InitialState(system, functions, layout, labels, M, (p0, t0), fixed, tolerance, contacts if terms else None)
    state = start(q_init, v_init, depth=not _posture_given(system), assemble=assemble)   # depths after the posture
    if not assemble:
        check_fixed_points_at_rest(moving, v_init, q_init, tolerance)
    joint_space = JointSpace(ctx, coords, skipped, actuation, passive)
    dynamics = Dynamics(functions, M, factor, potential, springs=spring_table(system, ctx), joint_space=joint_space)
    constrained = Constraints(labels, (alpha, beta), redundant_labels, dropped=(redundant == "drop"))

    def model_with(state):
        return Model(description=system, layout=layout, dynamics=dynamics, constraints=constrained,
                     parameters=Parameters(p0, limits), state=state, t0=t0,
                     contacts=Contacts(contact_specs(system.contacts), contacts),
                     origin=Origin(sharing=plan, unshared=unshared, recipe=recipe))

    model = _posture(model_with(state), model_with, start, joint_space, system)
    raise_if_interrupted()               # a Ctrl-C that CasADi swallowed while the functions were built
    return model


class _InitialState:
    """A consistent initial state of the model being built at ``(q, v)``: the contacts' gaps
    checked first (:func:`check_initial_gaps`; ``contacts``: the contact model, None without
    contact terms), since the consistent state's contact forces need a defined normal, then
    ``(q, v)`` projected onto the constraints (:func:`consistent_state`) within ``tolerance``
    of the system's size, the coordinates ``fixed`` kept as given; ``at``: ``(p0, t0)``."""

    def __init__(self, system, functions, layout, labels, M, at: tuple, fixed, tolerance: float, contacts):
        self.system, self.functions, self.layout, self.labels, self.M = system, functions, layout, labels, M
        (self.p0, self.t0), self.fixed, self.tolerance, self.contacts = at, fixed, tolerance, contacts
        self.weight = sum(m.rigid.mass for m in system.members.values()) * float(np.linalg.norm(system.gravity))

    def __call__(self, q, v, depth: bool = True, assemble: bool = False):
        """The state from ``(q, v)``; ``depth=False``: the gaps' depths not checked (a
        configuration the run does not start from); ``assemble``: no limit on the corrections."""
        if self.contacts is not None:
            check_initial_gaps(self.system.name, self.system.contacts, self.functions, q, self.p0, self.contacts,
                               self.weight, depth=depth)
        return consistent_state(self.functions, self.layout, self.labels, q, v, self.p0, self.t0, self.tolerance,
                                self.M, fixed=self.fixed, assemble=assemble)


def _posture_given(system) -> bool:
    """Whether the system gives an initial posture (joints or coordinates, or their rates)."""
    return bool(system.initial_coordinates or system.initial_coordinate_rates or system.initial_joints
                or system.initial_joint_rates)


def _posture(model, model_with, initial: _InitialState, joint_space, system):
    """``model`` moved to the system's initial posture: its initial joints and rates (through
    the joint space), then its initial coordinates and rates by name, each state made
    consistent by ``initial`` and the model remade by ``model_with(state)``; the depths of the
    contacts' gaps checked at the last."""
    coordinates_later = bool(system.initial_coordinates or system.initial_coordinate_rates)
    if system.initial_joints or system.initial_joint_rates:
        q, v = joint_space.initial_state(model, system.initial_joints, system.initial_joint_rates)
        model = model_with(initial(q, v, depth=not coordinates_later))
    if coordinates_later:
        q, v = _initial_coordinates(model, system)
        model = model_with(initial(q, v))
    return model


def _mass(layout, members):
    """``(M, factor)``: the constant mass matrix and its factor (:func:`mass_factor`, flat
    members with their supports)."""
    M = assemble_mass(layout, members)
    flat = flat_members(members, layout)
    return M, mass_factor(M, layout.coordinate_names, flat, flat_support(members, layout, flat))


def _parameter_values(system, limits) -> np.ndarray:
    """``p0``: the parameters' values in declaration order, checked against their limits."""
    p0 = np.concatenate([v for _, v in system.parameters.values()]) if system.parameters else np.zeros(0)
    limits.check(p0, where=f"system {system.name!r}: ")
    return p0


def _check_flat_inertia(name: str, ctx, phi, M, members, at: tuple) -> None:
    """A model with flat members: ``M`` positive definite on ``null(A)`` at ``at = (t0, q, p)``
    (:func:`check_tangent_inertia`)."""
    A0 = dense_dm(ca.Function("A", [ctx.t, ctx.q, ctx.p], [ca.jacobian(phi, ctx.q)])(*at))
    check_tangent_inertia(M, A0, ctx.layout, members, f"system {name!r}")


def _check_build_options(system, contacts: str, redundant: str) -> None:
    """Refuse a system without members and an unknown ``contacts`` or ``redundant`` mode."""
    if not system.members:
        raise ModelError(f"system {system.name!r} has no members; add bodies, bars or points first")
    if contacts not in CONTACT_MODELS:
        raise ModelError(f"contacts: expected one of {', '.join(CONTACT_MODELS)}, got {contacts!r}")
    if redundant not in REDUNDANT_MODES:
        raise ModelError(f"redundant: expected one of {', '.join(REDUNDANT_MODES)}, got {redundant!r}")


def _shared_coordinates(system, options: dict):
    """``(system, plan, unshared)``: the system with the joints that shared coordinates express
    eliminated (:func:`ncgen.model.sharing.share_coordinates`), its plan, and the recipe of the
    ``share=False`` form when sharing changed anything (else None; ``options``: the build's)."""
    nq_before = make_layout(system.dim, list(system.members.values())).nq
    shared, plan = share_coordinates(system)
    plan.nq_before = nq_before
    unshared = UnsharedForm(system, options, build_model) if plan.eliminated or plan.partial else None
    return shared, plan, unshared


def _applied_forces(system, ctx, actuation, contacts: str):
    """``(F, V, passive, terms)``: the applied forces ``F`` (actuators included) and their
    potential ``V``, the passive part of ``F`` (without the actuators), and the contact terms,
    whose forces join ``F`` and ``V`` when contacts are ``"smooth"``."""
    F, V = force_terms(system, ctx)
    passive = F
    if actuation[2]:
        F = F + ca.mtimes(actuation[0], actuation[1])
    terms = contact_terms(ctx, system.contacts)
    if terms and contacts == "smooth":
        _, _, Q, Vc = smooth_forces(ctx, terms)
        F, V, passive = F + Q, ca.vertcat(V, Vc), passive + Q
    return F, V, passive, terms


def _redundant_constraints(name: str, ctx, labels: list, rows: list, plan, redundant: str, at: tuple):
    """``(labels, rows, redundant labels)``: the constraint rows linearly dependent at ``at`` =
    ``(q, p, t0)`` found, then refused (``"error"``), dropped once shown implied and satisfied
    (``"drop"``, with a warning naming them) or kept (``"keep"``)."""
    q, p, t0 = at
    A_fn = ca.Function("A", [ctx.t, ctx.q, ctx.p], [ca.jacobian(ca.vertcat(*rows), ctx.q)]) if rows else None
    dependent = dependent_rows(dense_dm(A_fn(t0, q, p)) if A_fn else np.zeros((0, ctx.layout.nq)))
    redundant_labels = [labels[i] for i in dependent]
    hint = ""
    if dependent and plan is not None and plan.eliminated:
        hint = (f" (coordinate sharing replaced the joints {', '.join(plan.eliminated)} by shared coordinates; "
                "build(share=False) keeps their equations, so the redundant ones are named)")
    if dependent and redundant == "error":
        raise ModelError(f"system {name!r}: redundant constraints at the initial configuration: "
                         f"{', '.join(redundant_labels)}{hint}; remove them or build(redundant='drop')")
    if dependent and redundant == "drop":
        phi_fn = ca.Function("phi", [ctx.t, ctx.q, ctx.p], [ca.vertcat(*rows)])
        _check_droppable(name, labels, dependent, phi_fn, A_fn, q, p, t0)
        warnings.warn(f"system {name!r}: dropping redundant constraints "
                      f"{', '.join(redundant_labels)} (implied by the others near the initial "
                      f"configuration, and satisfied){hint}", stacklevel=4)
        keep = [i for i in range(len(rows)) if i not in set(dependent)]
        labels, rows = [labels[i] for i in keep], [rows[i] for i in keep]
    return labels, rows, redundant_labels


def _initial_coordinates(model, system) -> tuple[np.ndarray, np.ndarray]:
    """``(q, v)`` with ``system.initial_coordinates`` / ``initial_coordinate_rates`` set (names
    as written resolve through ``model.coordinate``), the others assembled from the model's."""
    try:
        q = kinematics.assemble(model, model.q0, values=system.initial_coordinates)
        v = kinematics.project_velocity(model, q, model.v0, values=system.initial_coordinate_rates)
    except ModelError as exc:
        given = {**system.initial_coordinates, **system.initial_coordinate_rates}
        raise ModelError(f"system {system.name!r}: initial coordinates "
                         f"{', '.join(f'{k} = {x:g}' for k, x in given.items())}: {exc}") from None
    return q, v


def _check_droppable(name, labels, dependent, phi_fn, A_fn, q, p, t0) -> None:
    """Raise unless every ``dependent`` row is implied by the others near ``q`` and satisfied
    (:mod:`ncgen.assembly.redundancy`), naming the constraints that are not."""
    found = classify(lambda t, x: np.array(phi_fn(t, x, p)).reshape(-1),
                     lambda t, x: dense_dm(A_fn(t, x, p)), q, t0, dependent)
    named = lambda rows: ", ".join(labels[i] for i in rows)   # noqa: E731
    if found.violated:
        items = ", ".join(f"{labels[i]} (Φ = {r:.3g})" for i, r in found.violated.items())
        raise ModelError(
            f"system {name!r}: the constraints {items} contradict the others: they are implied by "
            f"them near the initial configuration (dependent wherever the others hold) but violated. "
            f"Fix the joint (its drive, distance or points) or remove it")
    if found.unverified:
        raise ModelError(
            f"system {name!r}: the constraints {named(found.unverified)} depend linearly on the others at "
            f"the initial configuration, and whether they are implied by them could not be checked "
            f"(Newton on the other constraints did not converge near it), so they are not dropped. "
            f"Check the initial configuration, remove the constraints if they are redundant, or "
            f"build(redundant='keep') for analysis only")
    if found.singular:
        rows = list(found.singular)
        raise ModelError(
            f"system {name!r}: the initial configuration is singular: the constraints {named(rows)} "
            f"depend linearly on the others there but are not implied by them nearby (they still "
            f"remove motion), so they cannot be dropped and a DAE keeping them is singular at t0. "
            f"Start the mechanism away from the singular position (build(assemble=True) with a "
            f"perturbed guess), remove those constraints if they are not meant, or build("
            f"redundant='keep') for analysis only")


def constraint_rows(system, ctx: Context, plan: SharingPlan | None = None) -> tuple[list[str], list[ca.SX]]:
    """Intrinsic constraints of every member (from its derivation), then joint equations.
    With a sharing ``plan``, the equations that the shared coordinates imply are left out
    (listed in ``plan.removed``): joint equations the plan drops, and rigidity constraints
    stated twice or between fixed nodes only (:func:`~ncgen.model.sharing.intrinsic_key`)."""
    labels, rows, seen = [], [], set()
    for m in system.members.values():
        if not m.ctype.pairs:
            continue
        phi = ctx.instantiate(m, "Phi")
        names = "uvw"
        for k, (s, t) in enumerate(m.ctype.pairs):
            label = f"{m.name}.rigid.{names[s]}{names[t]}"
            if plan is not None:
                key = intrinsic_key(ctx.layout, m, (s, t))
                if key is None or key in seen:
                    plan.removed.append(label)
                    continue
                seen.add(key)
            labels.append(label)
            rows.append(phi[k])
    for j in system.joints:
        for label, e in j.equations(ctx):
            if plan is not None and not plan.keeps(j.name, label):
                plan.removed.append(label)
                continue
            labels.append(label)
            rows.append(e)
    return labels, rows


def force_terms(system, ctx: Context) -> tuple[ca.SX, ca.SX]:
    """Generalised force ``F`` (gravity and force elements) and the terms of the potential
    energy ``V``: one per member (gravity), then one per force element."""
    g = ca.DM(system.gravity)
    weights = np.zeros(ctx.layout.nq)              # gravity's part of F: constant, gathered numerically
    V = []
    for m in system.members.values():
        C = m.rigid.C(m.rigid.c_g)                  # centre of mass r_G = C(c_g) q
        mg = m.rigid.mass * system.gravity
        for k, i in enumerate(ctx.layout.member_indices(m.name)):
            if i is not None:                       # (Cᵀ m g)_k, summed in CasADi's order
                weights[i] += sum((C[j, k] * mg[j] for j in range(len(mg))), 0.0)
        V.append(-m.rigid.mass * ca.dot(g, ca.mtimes(ca.DM(C), ctx.q_of(m))))
    F = ca.SX(ca.DM(weights))
    for f in system.forces:
        F += f.generalized(ctx)
        V.append(f.potential(ctx))
    return F, ca.vertcat(*V)


def initial_guess(layout: Layout, members) -> tuple[np.ndarray, np.ndarray, list]:
    """System q and v gathered from each member's initial pose and twist, and the velocity
    components given to points fixed to the ground ``[(point, axis, m/s)]``, which ``q̇``
    cannot hold.  Where members share a point, their velocities there must agree."""
    moving = []
    q = np.full(layout.nq, np.nan)
    v = np.full(layout.nq, np.nan)
    src = [""] * layout.nq
    for m in members:
        for k, i in enumerate(layout.member_indices(m.name)):
            if i is None:                # a point fixed to the ground: its given velocity is dropped
                moving.append((f"{m.name}.{m.ctype.slots[k // layout.dim]}", "xyz"[k % layout.dim], m.qd0[k]))
                continue
            if np.isnan(v[i]):
                q[i], v[i], src[i] = m.q0[k], m.qd0[k], m.name
            elif abs(v[i] - m.qd0[k]) > 1e-9 * max(1.0, abs(v[i])):
                raise ModelError(
                    f"inconsistent initial velocity at the shared coordinate {layout.coordinate_names[i]}: "
                    f"{src[i]} gives {v[i]:.6g} m/s, {m.name} gives {m.qd0[k]:.6g} m/s")
    return q, v, moving


def check_fixed_points_at_rest(moving, v, q, tolerance: float) -> None:
    """Raise if a point fixed to the ground was given a velocity above the tolerance of the
    initial state (``tolerance`` × the velocity scale, as for the constraints): its motion would
    be dropped silently, and the member would move otherwise than given."""
    if not moving:
        return
    point, axis, speed = max(moving, key=lambda x: abs(x[2]))
    scale = max(float(np.max(np.abs(v), initial=0.0)), system_size(q))
    if abs(speed) > tolerance * scale:
        raise ModelError(
            f"inconsistent initial velocities: {point} is fixed to the ground (a ground point, or a joint "
            f"to the ground that coordinate sharing made one) but the member's velocity and "
            f"angular_velocity give it {speed:.6g} m/s along {axis}, more than the tolerance "
            f"{tolerance:g} × {scale:.3g} m/s; give velocities that leave it at rest")
