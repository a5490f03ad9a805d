"""Assembly context: the CasADi symbols of a system and the per-member expressions that
joints and forces are written with.

Symbols: ``t`` (1), ``q`` and ``v`` (nq, v = q̇), ``u`` (inputs), ``p`` (parameters).
A body-fixed point of member I is ``r = C(c) q_I`` and a body-fixed direction
``d = (C(c_d) − C(0)) q_I = X(q_I) c_d``, both from the member's derivation; the ground's
points and directions are constants.
"""
from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

import casadi as ca
import numpy as np

from ncgen.errors import BasisError
from ncgen.errors import ModelError
from ncgen.model.expressions import Scope, evaluate, scope
from ncgen.model.layout import Layout
from ncgen.model.members import Member
from ncgen.model.sym2casadi import to_casadi
from ncgen.reproducible import dot, matmul, matvec, norm, perpendicular_basis, snap
from ncgen.symbolic.joint_primitives import PRIMITIVES

#: The coordinate types' formulas as SX functions (generated: ncgen/codegen/forms_generator.py).
INSTANCE_FORMS = Path(__file__).with_name("instance_forms.json")


@lru_cache(maxsize=1)
def _instance_table() -> dict:
    return json.loads(INSTANCE_FORMS.read_text(encoding="utf-8"))


@lru_cache(maxsize=None)
def instance_form(name: str, dim: int, formula: str) -> tuple[tuple[str, ...], ca.Function]:
    """``(constant names, f(q_I, q̇_I, c))``: ``formula`` of coordinate type ``name`` as the
    SX function shipped in ``instance_forms.json`` (generated from the SymPy derivation by
    :mod:`ncgen.codegen.forms_generator`), ``c`` the constants' values in the order named."""
    entry = _instance_table()[f"{name}-{dim}d"]
    return tuple(entry["constants"]), ca.Function.deserialize(entry[formula])


def _gather(x: ca.SX, idx: list, fill: np.ndarray) -> ca.SX:
    """The column ``[x[i] if i is not None else fill[k] for k, i in enumerate(idx)]``, made of
    slices of ``x`` over runs of consecutive indices and constant blocks (a member's
    coordinates are whole nodes: one or a few slices instead of an entry each)."""
    parts, k = [], 0
    while k < len(idx):
        j = k + 1
        if idx[k] is None:
            while j < len(idx) and idx[j] is None:
                j += 1
            parts.append(ca.DM(fill[k:j]))
        else:
            while j < len(idx) and idx[j] is not None and idx[j] == idx[k] + j - k:
                j += 1
            parts.append(x[idx[k]:idx[k] + j - k])
        k = j
    return parts[0] if len(parts) == 1 else ca.vertcat(*parts)


class Context:
    """Symbols and member expressions of one system being assembled."""

    def __init__(self, system, layout: Layout):
        self.system = system
        self.layout = layout
        self.dim = system.dim
        self.t = ca.SX.sym("t")
        self.q = ca.SX.sym("q", layout.nq)
        self.v = ca.SX.sym("v", layout.nq)
        self.u = ca.vertcat(*system.inputs.values()) if system.inputs else ca.SX(0, 1)
        self.p = ca.vertcat(*(s for s, _ in system.parameters.values())) if system.parameters else ca.SX(0, 1)
        self._local: dict[str, tuple[ca.SX, ca.SX]] = {}
        self._points: dict[tuple, tuple[ca.SX, ca.SX]] = {}
        #: joint name -> f(drive expression) replacing it (assembly by continuation of the drives)
        self.drive_blend: dict = {}

    @classmethod
    def of_members(cls, system, members) -> "Context":
        """A context of ``system`` over ``members`` only (and the members whose points they
        share, which their coordinates are made of): enough to write the equations of one
        element that joins them, at a cost that does not grow with the system (adding n
        elements, each checked in such a context, costs O(n), not O(n²))."""
        from ncgen.model.layout import make_layout
        wanted, todo = set(), [m for m in members if not m.is_ground]
        while todo:
            m = todo.pop()
            if m.name not in wanted:
                wanted.add(m.name)
                todo += [ref.member for ref in m.shared.values() if not ref.member.is_ground]
        subset = [m for name, m in system.members.items() if name in wanted]
        return cls(system, make_layout(system.dim, subset))

    # -------------------------------------------------------------- members
    def q_of(self, member: Member) -> ca.SX:
        return self._member_symbols(member.name)[0]

    def v_of(self, member: Member) -> ca.SX:
        return self._member_symbols(member.name)[1]

    def _member_symbols(self, name: str) -> tuple[ca.SX, ca.SX]:
        """``(q_I, v_I)`` of the layout's member ``name`` (its fixed coordinates constants),
        made on first use: a context over all members pays only for those it is asked about."""
        found = self._local.get(name)
        if found is None:
            idx = self.layout.member_indices(name)         # KeyError: not a member of the layout
            b = self.layout.member_constant(name)
            found = self._local[name] = (_gather(self.q, idx, b), _gather(self.v, idx, np.zeros(len(idx))))
        return found

    def instantiate(self, member: Member, formula: str):
        """A formula of ``member``'s derivation (``"Phi"``, ``"p"``, ``"R"``, ``"omega"``,
        ``"W"``) in CasADi (q ↦ q_I, q̇ ↦ v_I): its shipped SX function of (q_I, q̇_I, the
        member's constants) called on the member (:func:`instance_form`; no SymPy)."""
        names, f = instance_form(member.ctype.name, member.ctype.dim, formula)
        constants = member.rigid.constant_values
        return f.call([self.q_of(member), self.v_of(member), ca.DM([float(constants[n]) for n in names])])[0]

    def scatter(self, member: Member, Q_local) -> ca.SX:
        """``S_Iᵀ Q_I``: a member's generalised force as a system vector."""
        out = ca.SX.zeros(self.layout.nq)
        for k, i in enumerate(self.layout.member_indices(member.name)):
            if i is not None:
                out[i] += Q_local[k]
        return out

    # -------------------------------------------------- points and directions
    def _local_point(self, member, world, what: str) -> np.ndarray:
        rbar = member.to_local(world)
        try:
            member.rigid.affine(rbar)
        except BasisError as e:
            raise ModelError(f"{what}: {member.name} ({member.ctype.name} {member.kind}): {e}") from None
        return rbar

    def point(self, member, world, what: str):
        """World position and velocity expressions of the point of ``member`` that is at
        ``world`` in the initial configuration."""
        if member.is_ground:
            return ca.DM(np.asarray(world, float)), ca.DM.zeros(self.dim)
        return self.local_point(member, self._local_point(member, world, what))

    def local_point(self, member, rbar):
        """World position and velocity expressions of the point at local ``rbar`` of
        ``member``; one pair per point, so that the elements at a point share its nodes."""
        key = (member.name, np.asarray(rbar, float).tobytes())
        found = self._points.get(key)
        if found is None:
            C = ca.DM(member.rigid.C(member.rigid.affine(rbar)))
            found = self._points[key] = (ca.mtimes(C, self.q_of(member)), ca.mtimes(C, self.v_of(member)))
        return found

    def direction(self, member, world_dir, what: str):
        """Expression of the body-fixed direction of ``member`` equal to ``world_dir``
        initially (its length is kept), and its rate.

        A body's directions are ``X(q) c_d``.  A 3D bar carries only its own axis ``u``; a
        planar bar carries every direction ``(d̄_x u + d̄_y J u) / L`` (``J`` the rotation by
        +90°, ``d̄`` the local direction), linear in q like a body's.  The coefficients are
        snapped (:func:`ncgen.reproducible.snap`): a direction along a base vector is exactly
        that vector."""
        w = np.asarray(world_dir, float)
        if member.is_ground:
            return ca.DM(w), ca.DM.zeros(self.dim)
        if member.kind == "point":
            raise ModelError(f"{what}: {member.name} is a point member and carries no direction")
        dbar = member.direction_to_local(w)
        loc = member.rigid
        if member.kind == "bar" and self.dim == 2:
            U = loc.C(np.ones(1)) - loc.C(np.zeros(1))            # u = U q
            J = np.array([[0.0, -1.0], [1.0, 0.0]])
            c = snap(dbar / loc.Xbar[0, 0])
            C = ca.DM(c[0] * U + c[1] * matmul(J, U))
            return ca.mtimes(C, self.q_of(member)), ca.mtimes(C, self.v_of(member))
        c = snap(matvec(loc.Xbar_pinv, dbar))
        if norm(matvec(loc.Xbar, c) - dbar) > 1e-9 * max(norm(dbar), 1e-300):
            raise ModelError(f"{what}: bar {member.name} carries only its own axis as a direction, "
                             f"and {np.round(w, 12).tolist()} is not along it")
        C = ca.DM(loc.C(c) - loc.C(np.zeros_like(c)))
        return ca.mtimes(C, self.q_of(member)), ca.mtimes(C, self.v_of(member))

    def carries_direction(self, member, world_dir) -> bool:
        """Whether ``member`` can express ``world_dir`` as a body-fixed direction."""
        if member.is_ground or member.kind == "body" or (member.kind == "bar" and self.dim == 2):
            return True
        if member.kind == "point":
            return False
        d = member.direction_to_local(np.asarray(world_dir, float))
        return bool(norm(d[1:]) <= 1e-9 * norm(d))

    def perpendiculars(self, member, world_axis, what: str) -> list:
        """Body-fixed directions of ``member`` spanning the plane ⟂ ``world_axis`` (two in 3D,
        one in 2D), each a unit vector initially."""
        return [self.direction(member, n, what)[0] for n in perpendicular_basis(world_axis)]

    def plane_tangents(self, normal) -> list:
        """Unit tangents (constants) of a ground plane with world ``normal``, completing it to
        a right-handed basis (:func:`ncgen.reproducible.perpendicular_basis`)."""
        return [ca.DM(t) for t in perpendicular_basis(normal)]

    def nearest_point(self, member, world) -> np.ndarray:
        """The world point of ``member`` nearest to ``world`` in the initial configuration:
        ``world`` itself for the ground and bodies, its projection onto a bar's axis, a
        point member's position."""
        w = np.asarray(world, float)
        if member.is_ground or member.kind == "body":
            return w
        if member.kind == "point":
            return member.p0.copy()
        e = member.R0[:, 0]
        return member.p0 + dot(w - member.p0, e) * e

    # ---------------------------------------------------------- values
    def scope(self, *, inputs: bool = True, state: bool = False) -> Scope:
        """Names usable in value expressions: ``t``, parameters, inputs (if ``inputs``) and
        ``q``, ``v`` (if ``state``)."""
        pars = {n: s for n, (s, _) in self.system.parameters.items()}
        ins = dict(self.system.inputs) if inputs else {}
        extra = {"q": self.q, "v": self.v} if state else {}
        return scope(self.t, pars, ins, **extra)

    def expression(self, value, size: int, what: str, *, inputs: bool = True, state: bool = False,
                   call=None) -> ca.SX:
        """A model value (number, text, SX, callable; :mod:`ncgen.model.expressions`) as an
        SX column of ``size`` components over the names allowed here."""
        return evaluate(value, self.scope(inputs=inputs, state=state), size, what, call=call)

    def apply(self, name: str, *args):
        """Instantiate the joint primitive ``name`` (:mod:`ncgen.symbolic.joint_primitives`) with CasADi
        arguments, through its generated Python form (:mod:`ncgen.model.primitive_forms`; no SymPy)."""
        from ncgen.model.primitive_forms import FORMS
        form = FORMS.get((name, self.dim))
        if form is None:
            raise KeyError(f"unknown joint primitive {name!r}; known: {', '.join(PRIMITIVES)}")
        return form(*args)
