"""A tree's numbers as data tables for the joint-space algorithms of the tree library
(``templates/c/runtime/ncgen_tree_tables.h``; kernels :mod:`ncgen.codegen.tree_kernels`).

:func:`tree_tables` packs a 3D tree (:func:`~ncgen.codegen.tree_check.check_tree`) into
:class:`TreeTables`: one body per member, parents before children (the spanning tree's
breadth-first order), each with the kind of the joint to its parent, where its positions and
rates start in ``qj``/``vj``, the joint's numbers (placements and axes) and the member's
``[m; c; I_c]``; the uniform gravity; the mimic map (``v_j = G v_i``: per rate the index of
the rate it copies, its factor and its independent column; per position the position it
copies, factor and offset).  For the local recursion (RNEA, CRBA, ABA) each body also has its
frame ``f_b`` (the joint frame after the joint's motion, turned so that a revolute or prismatic
joint's axis is z: :func:`axis_frame`), the constant pose ``xin`` of the joint frame before
the motion in the parent's ``f_p`` (``R`` column-major, ``p``), the member frame in ``f_b``
(``member``, the same 12 numbers: the start check's, :mod:`ncgen.codegen.tree_start`), and its rigid-body inertia
about ``f_b``'s origin in ``f_b`` axes, ``inertia = [m; h = m c; I_o]`` (kg, kg·m, kg·m²,
``I_o`` column-major).  :class:`UnsupportedTree` names what the tables do not cover:
passive forces other than a uniform gravity (springs, dampers, joint friction), a joint
traversed from its B side, joint kinds outside :data:`~ncgen.codegen.tree_kernels.JOINT_KINDS`
(bars' swings), members that are not rigid bodies.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ncgen.assembly.joint_tree import edge_placements
from ncgen.codegen.tree_kernels import JOINT_KINDS, joint_numbers
from ncgen.errors import CodegenError, ModelError
from ncgen.model.data import model_data


class UnsupportedTree(CodegenError):
    """The tree tables do not cover the model; ``reasons`` lists why."""

    def __init__(self, model_name: str, reasons: list[str]):
        self.reasons = reasons
        super().__init__(f"model {model_name!r}: the tree tables do not cover it: {'; '.join(reasons)}; "
                         "use the model's flat tree functions (kernels='flat')")


@dataclass
class TreeTables:
    """The arrays of ``ncgen_tree`` (``templates/c/runtime/ncgen_tree_tables.h``) of one model."""

    name: str
    nq: int
    nv: int
    ni: int
    arrays: dict[str, np.ndarray]

    @property
    def nb(self) -> int:
        return len(self.arrays["parent"])


_KIND = {k.kind: i for i, k in enumerate(JOINT_KINDS)}


def axis_frame(axis) -> np.ndarray:
    """A rotation ``Q`` whose third column is the unit ``axis`` (a right-handed frame; a
    permutation of the axes, exactly, when ``axis`` is ``±x``, ``±y`` or ``±z``), so that a
    rotation about ``axis`` is ``Q Rz(θ) Qᵀ``."""
    k = np.asarray(axis, float).reshape(3)
    i = int(np.argmin(np.abs(k)))
    u = np.zeros(3)
    u[i] = 1.0
    if np.count_nonzero(k) == 1:                  # ±x, ±y, ±z: the next two axes, exactly
        j = int(np.flatnonzero(k)[0])
        e1, e2 = np.eye(3)[(j + 1) % 3], np.eye(3)[(j + 2) % 3]
        return np.column_stack([e1, e2, k]) if k[j] > 0 else np.column_stack([e2, e1, k])
    e1 = u - k * (u @ k)
    e1 /= np.linalg.norm(e1)
    return np.column_stack([e1, np.cross(k, e1), k])


def _compose(A, B):
    """``(R, p)`` of ``[[R_a, p_a], [0, 1]] [[R_b, p_b], [0, 1]]``."""
    return A[0] @ B[0], A[0] @ B[1] + A[1]


def _local_inertia(m, c, I_c, R, p):
    """``[m; m c_f; I_o]`` (13 numbers, ``I_o`` column-major) of a body of mass ``m``, centre
    ``c`` and inertia ``I_c`` about it in its member frame placed at ``(R, p)`` in the frame
    ``f``: ``c_f = R c + p``, ``I_o = R I_c Rᵀ − m ĉ_f ĉ_f`` (about f's origin)."""
    c_f = R @ np.asarray(c, float) + p
    I_o = R @ np.asarray(I_c, float) @ R.T + m * (c_f @ c_f * np.eye(3) - np.outer(c_f, c_f))
    return [m, *(m * c_f), *I_o.reshape(-1, order="F")]


def tree_tables(model) -> TreeTables:
    """The :class:`TreeTables` of ``model``, packed once per model (kept in ``model.data``, and
    beside the model in the store of built models when it came through it:
    :func:`~ncgen.codegen.model_cache.derived_data`); raises :class:`UnsupportedTree` (module
    docstring)."""
    from ncgen.codegen.model_cache import derived_data

    data = model_data(model)
    if data.tree_tables is None:
        try:
            data.tree_tables = (derived_data(model, "tree-tables-2", lambda: _pack(model)), None)
        except UnsupportedTree as e:
            data.tree_tables = (None, e)
    tables, error = data.tree_tables
    if error is not None:
        raise error
    return tables


def _pack(model) -> TreeTables:
    from ncgen.assembly.tree_dynamics import MimicMap, _owned, uniform_gravity
    from ncgen.codegen.tree_check import check_tree

    js = model.joint_space
    if js.dim != 3:
        raise UnsupportedTree(model.name, ["a 2D model (the tree tables take 3D trees)"])
    try:
        check_tree(model)
    except ModelError as e:
        raise UnsupportedTree(model.name, [str(e)]) from None
    tree = js.spanning_tree()
    reasons = []
    g = uniform_gravity(model, _owned(model, tree))
    if g is None:
        reasons.append("passive forces other than a uniform gravity (springs, dampers, joint friction)")
    bodies = _Bodies(js, reasons)
    for here, there, e, forward in tree:
        bodies.add(here, there, e, forward)
    if reasons:
        raise UnsupportedTree(model.name, reasons)
    mimic = MimicMap(model)
    col = {i: c for c, i in enumerate(mimic.independent)}
    rate_src = [mimic.follows.get(i, (i, 1.0))[0] for i in range(js.nv)]
    rate_coef = [mimic.follows.get(i, (i, 1.0))[1] for i in range(js.nv)]
    rate_col = [col[s] for s in rate_src]
    q_src = [mimic.position[i][0] if i in mimic.position else -1 for i in range(js.nq)]
    q_coef = [mimic.position[i][1] if i in mimic.position else 1.0 for i in range(js.nq)]
    q_off = [mimic.position[i][2] if i in mimic.position else 0.0 for i in range(js.nq)]
    i32 = (lambda x: np.asarray(x, dtype=np.int32))
    f64 = (lambda x: np.asarray(x, dtype=np.float64))
    b = bodies
    arrays = {"parent": i32(b.parent), "kind": i32(b.kind), "q_at": i32(b.q_at), "v_at": i32(b.v_at),
              "num_ptr": i32(b.num_ptr), "num": f64(b.num), "body": f64(b.body), "gravity": f64(g),
              "rate_src": i32(rate_src), "rate_col": i32(rate_col), "rate_coef": f64(rate_coef),
              "q_src": i32(q_src), "q_coef": f64(q_coef), "q_off": f64(q_off),
              "xin": f64(b.xin), "inertia": f64(b.inertia), "member": f64(b.member)}
    return TreeTables(model.name, js.nq, js.nv, len(mimic.independent), arrays)


class _Bodies:
    """The tables' rows of the bodies, one per joint of the spanning tree in its order:
    parent, joint kind, where its positions and rates start, its numbers, the body's mass,
    centre and inertia, the joint's placement in the parent's member frame (``xin``) and the
    inertia in the joint frame; what the tables cannot take goes to ``reasons``."""

    def __init__(self, js, reasons: list):
        self.js, self.reasons = js, reasons
        self.index = {"ground": -1}
        self.parent, self.kind, self.q_at, self.v_at, self.num_ptr, self.num = [], [], [], [], [0], []
        self.body, self.xin, self.inertia, self.member = [], [], [], []
        self.to_member = {"ground": (np.eye(3), np.zeros(3))}      # member frame c in f_b
        self.sq, self.sv = js.slices(), js.slices(rates=True)

    def add(self, here: str, there: str, e, forward: bool) -> None:
        """The row of member ``there``, joined to ``here`` by the tree's edge ``e``."""
        from ncgen.assembly.tree_dynamics import member_inertia

        js, reasons, sq, sv = self.js, self.reasons, self.sq, self.sv
        self.index[there] = len(self.parent)
        self.parent.append(self.index[here])
        k = self._kind(e, forward)
        self.q_at.append(sq[e.name].start if e.name in sq else 0)
        self.v_at.append(sv[e.name].start if e.name in sv else 0)
        nq = sq[e.name].stop - sq[e.name].start if e.name in sq else 0
        if nq != JOINT_KINDS[k].nq and not reasons:
            reasons.append(f"joint {e.name!r}: {nq} positions, expected {JOINT_KINDS[k].nq} for a {e.kind} joint")
        a1, b1, a2, b2 = edge_placements(e, True, js.members, 3)
        numbers = joint_numbers(a1, b1, a2, b2, e.axes[:JOINT_KINDS[k].n_axes])
        if numbers.size != JOINT_KINDS[k].n_num and not reasons:
            reasons.append(f"joint {e.name!r}: {numbers.size} numbers, expected {JOINT_KINDS[k].n_num}")
        self.num.extend(numbers)
        self.num_ptr.append(len(self.num))
        Q = self._axis_frame(e, k)
        H_in = _compose(_compose(self.to_member[here], (a1, b1)), (Q, np.zeros(3)))
        self.to_member[there] = (Q.T @ a2, Q.T @ b2)
        self.member.extend([*self.to_member[there][0].reshape(-1, order="F"), *self.to_member[there][1]])
        self.xin.extend([*H_in[0].reshape(-1, order="F"), *H_in[1]])
        try:
            m, c, I_c = member_inertia(js, there)
        except ModelError as err:
            reasons.append(str(err))
            m, c, I_c = 0.0, np.zeros(3), np.zeros((3, 3))
        self.body.extend([m, *c, *np.asarray(I_c, float).reshape(-1, order="F")])
        self.inertia.extend(_local_inertia(m, c, I_c, *self.to_member[there]))

    def _kind(self, e, forward: bool) -> int:
        """The tables' kind of joint ``e`` (0 where it has none, with the reason)."""
        k = _KIND.get(e.kind)
        if k is None:
            self.reasons.append(f"joint {e.name!r}: its kind {e.kind} (tree tables: "
                                f"{', '.join(j.kind for j in JOINT_KINDS)})")
            k = 0
        elif not forward:
            self.reasons.append(f"joint {e.name!r}: traversed from its B side")
        self.kind.append(k)
        return k

    def _axis_frame(self, e, k: int) -> np.ndarray:
        """The joint frame of a revolute or prismatic joint (its axis the frame's z), else I."""
        if JOINT_KINDS[k].name in ("revolute", "prismatic") and not self.reasons:
            axis = np.asarray(e.axes[0], float)
            if abs(np.linalg.norm(axis) - 1.0) > 1e-12:
                self.reasons.append(f"joint {e.name!r}: its axis {axis.tolist()} is not a unit vector")
            else:
                return axis_frame(axis)
        return np.eye(3)
