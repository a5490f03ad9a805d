"""The members' coordinate maps of a tree for the start check of the tree library
(``templates/c/runtime/ncgen_tree_start.h``): per body of the tree tables
(:mod:`ncgen.codegen.tree_tables`, same order) where its member's 12 local coordinates are in
``q`` (``idx``, −1 where fixed), how its joint is read off its relative pose (``how``:
:data:`READ` of its kind) and the numbers ``[cst; P; L]``: the fixed coordinates, the pose
of the body's joint frame after the motion ``f_b`` (the member frame times the inverse of the
tables' ``member``) ``[vec R; p] = P [q_m; 1]`` and back ``q_m = L [vec R; p; 1]`` (both affine:
the member's coordinates are points and directions fixed in it,
:meth:`~ncgen.assembly.joint_space.JointSpace.member_coordinates`).

:func:`start_tables` raises :class:`~ncgen.codegen.tree_tables.UnsupportedTree` naming why the
check does not cover a tree (the caller keeps CasADi's check): parameters, a member whose coordinates are not 12 fixed
points and directions spanning its frame, constraints beyond the tree's own (drives, distances).
The ``num`` rows are ``NCGEN_TREE_START_NUM`` (324) doubles.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.assembly.manifold import numerical_rank
from ncgen.codegen.tree_kernels import JOINT_KINDS
from ncgen.codegen.tree_tables import UnsupportedTree, tree_tables
from ncgen.model.data import model_data

#: How the check reads each joint kind off its relative pose (``NCGEN_START_*`` of
#: ``ncgen_tree_start.h``): the tables' modes of the kinds written out about z
#: (:data:`~ncgen.codegen.tree_kernels.LOCAL_MODES`), then each kind moved by its kernel.
READ = {"revolute": 1, "prismatic": 2, "fixed": 3, "cylindrical": 4, "universal": 5, "planar": 6, "spherical": 7,
        "free": 8}


def start_tables(model) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(idx, how, nz_ptr, nz, num)`` (int32 ``(nb, 12)``, ``nb``, ``2 nb + 1``, the nonzeros of
    ``P``'s and ``L``'s linear parts, float64 ``(nb, 324)``) of ``model``, packed once per
    model (kept in ``model.data``); raises :class:`UnsupportedTree` (module docstring)."""
    data = model_data(model)
    key = ("start tables",)
    if key not in data.table_algorithms:
        try:
            data.table_algorithms[key] = (_pack(model), None)
        except UnsupportedTree as e:
            data.table_algorithms[key] = (None, e)
    tables, error = data.table_algorithms[key]
    if error is not None:
        raise error
    return tables


def _pack(model) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    tables = tree_tables(model)
    js, a = model.joint_space, tables.arrays
    reasons = []
    if model.np:
        reasons.append("parameters (the tables hold the model's numbers)")
    mimicked = int(np.count_nonzero(a["rate_src"] != np.arange(tables.nv)))     # rates a mimic map gives
    if model.nq - model.nc != js.nv - mimicked:
        reasons.append(f"{model.nc} constraints for {model.nq} coordinates and {js.nv} joint rates "
                       "(constraints beyond the tree's own)")
    members = [there for _, there, _, _ in js.spanning_tree()]
    idx, num, seen = [], [], set()
    for b, name in enumerate(members):
        ix = [-1 if i is None else i for i in model.layout.member_indices(name)]
        maps = _member_maps(js, name, a["member"][12 * b:12 * b + 12])
        if len(ix) != 12 or maps is None:
            reasons.append(f"member {name!r}: its coordinates are not 12 points and directions spanning its frame")
            continue
        seen.update(i for i in ix if i >= 0)
        num.append(np.concatenate([model.layout.member_constant(name), *maps]))
        idx.append(ix)
    if len(seen) != model.nq and not reasons:
        reasons.append("coordinates of no member of the tree")
    if reasons:
        raise UnsupportedTree(model.name, [f"the start check does not take it: {'; '.join(reasons)}"])
    nz = [_nonzeros(x[12 + 156 * m:12 + 156 * m + 144]) for x in num for m in (0, 1)]
    ptr = np.concatenate([[0], np.cumsum([len(z) for z in nz])])
    how = np.array([READ[JOINT_KINDS[k].name] for k in a["kind"]], dtype=np.int32)
    return (np.ascontiguousarray(idx, dtype=np.int32), how, ptr.astype(np.int32),
            np.concatenate(nz).astype(np.int32), np.ascontiguousarray(num, dtype=np.float64))


def _nonzeros(M: np.ndarray) -> np.ndarray:
    """``r | k << 4`` of the nonzeros of the 12 × 12 column-major ``M``, whose entries below
    1e-14 of its largest (an inverse's round-off where the exact value is 0) are set to 0."""
    M[np.abs(M) < 1e-14 * np.abs(M).max()] = 0.0
    k, r = np.divmod(np.flatnonzero(M), 12)
    return r | k << 4


def _member_maps(js, name: str, C: np.ndarray):
    """``(P, L)`` column-major (156 each) of member ``name``: the pose of its joint frame
    ``f_b = m C⁻¹`` from its coordinates and back (``C``: the member frame in ``f_b``), or None
    when its coordinates are not an invertible affine map of its frame's pose."""
    R, p = ca.SX.sym("R", 3, 3), ca.SX.sym("p", 3)
    x = ca.vertcat(ca.vec(R), p)
    local = ca.vec(ca.SX(js.member_coordinates(name, R, p)))
    if local.numel() != 12:
        return None
    J = ca.jacobian(local, x)
    if ca.depends_on(J, x):
        return None
    Jn = np.array(ca.evalf(J), float)
    c = np.array(ca.evalf(ca.substitute(local, x, ca.DM.zeros(12))), float).reshape(-1)
    if numerical_rank(Jn) < 12:
        return None
    Rc, pc = C[:9].reshape(3, 3, order="F"), C[9:]
    to_f, to_m = _right_product(Rc.T, -Rc.T @ pc), _right_product(Rc, pc)      # f_b = m C⁻¹, m = f_b C
    Jinv = to_f @ np.linalg.inv(Jn)
    P = np.column_stack([Jinv, -Jinv @ c])
    L = np.column_stack([Jn @ to_m, c])
    return P.reshape(-1, order="F"), L.reshape(-1, order="F")


def _right_product(R, p) -> np.ndarray:
    """``K`` (12 × 12) with ``[vec(R_a R); R_a p + p_a] = K [vec R_a; p_a]``: a pose times the
    constant pose ``(R, p)`` as a linear map of the first."""
    K = np.zeros((12, 12))
    K[:9, :9] = np.kron(R.T, np.eye(3))
    K[9:, :9] = np.kron(p.reshape(1, 3), np.eye(3))
    K[9:, 9:] = np.eye(3)
    return K
