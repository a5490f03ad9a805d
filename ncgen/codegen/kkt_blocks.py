"""The stepper's KKT solves by blocks of the constant M⁻¹: the template data of
``kkt_schur`` in ``templates/c/runtime/ncgen_rattle.h``.

The stepper's KKT matrices are ``K = [[M, A₀ᵀ], [A₁, 0]]`` (the velocity half-step and the
projection: ``A₀ = A₁ = A(q⁺)``; Newton's first half-step: ``A₀ = A(q)``, ``A₁ = A(q + h w)``,
and its upper-left block ``M − h/2 ∂F/∂v`` is ``M`` only when the forces do not depend on
``v``).  With ``M`` constant and regular, ``K [x; y] = [r; s]`` is

    S y = A₁ M⁻¹ r − s,   x = M⁻¹ (r − A₀ᵀ y),   S = A₁ M⁻¹ A₀ᵀ  (nc × nc),

and ``S`` splits into independent blocks: the coordinates fall into the connected components
of the graph joining two coordinates when ``M⁻¹`` couples them or a constraint row touches
both (a heap of free bodies: one block per body, its intrinsic constraints only; a chain
sharing its points: one block).  Each block's ``S`` is small and dense: the C factorises it
by LU with partial pivoting, and takes the sparse QR of the whole ``K`` where a pivot is
numerically zero (redundant constraints, a singular configuration), so the redundancy
handling of the QR path is kept.
"""
from __future__ import annotations

import numpy as np

from ncgen.assembly.mass import mass_is_regular
from ncgen.codegen.cnames import c_real

#: The largest block (constraints) solved by the Schur complement: beyond, the dense LU of a
#: block (nc_b³/3 multiply-adds) costs more than the sparse QR of the whole KKT matrix.
KKT_BLOCK_MAX = 24
#: ... and of at most this many coordinates (M's coupled coordinates are inverted densely).
KKT_BLOCK_MAX_Q = 192
#: M is inverted only when its condition number is below this (as the contact Delassus path).
KKT_MAX_COND = 1e12


def kkt_block_context(model, K) -> dict:
    """The template context of the block Schur solve for the KKT pattern ``K`` (a CasADi
    Sparsity, (nq + nc)²): ``kkt_blocks`` False when it does not apply (M singular or
    ill-conditioned, no constraint, a block above :data:`KKT_BLOCK_MAX` constraints or
    :data:`KKT_BLOCK_MAX_Q` coordinates), else the blocks
    (``kkt_q0``/``kkt_q``: coordinates by block, ``kkt_c0``/``kkt_c``: constraints by block),
    each block's M⁻¹ by columns (``kkt_m_colind``: NQ + 1 starts, column j of block b at
    kkt_q0[b] + j; ``kkt_m_row``: rows within the block; ``kkt_m_val``), where the nonzeros of ``K``'s
    lower-left block ``A₁`` and upper-right block ``A₀ᵀ`` go in the blocks' dense ``A``
    (``kkt_a1_nz``/``kkt_a1_dst``, ``kkt_a0_nz``/``kkt_a0_dst``: row-major nc_b × nq_b per
    block, concatenated), the sizes ``kkt_na`` (Σ nc_b nq_b), ``kkt_ns`` (Σ nc_b²), ``kkt_cmax``,
    and ``kkt_newton``: whether Newton's K has M as its upper-left block (∂F/∂v structurally 0)."""
    nq, nc = model.nq, model.nc
    M = np.asarray(model.M, dtype=float)
    if nc == 0 or not mass_is_regular(model) or not np.all(np.isfinite(M)):
        return {"kkt_blocks": False}
    colind, row = K.colind(), K.row()
    lower, upper = [], []                      # (K index, constraint, coordinate)
    for j in range(nq + nc):
        for k in range(colind[j], colind[j + 1]):
            if j < nq and row[k] >= nq:
                lower.append((k, row[k] - nq, j))
            elif j >= nq and row[k] < nq:
                upper.append((k, j - nq, row[k]))
    parent = list(range(nq))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    def join(i, j):
        parent[root(i)] = root(j)

    for i, j in zip(*np.nonzero(M)):           # M's blocks: M⁻¹ has the same
        join(int(i), int(j))
    members = {}
    for i in range(nq):
        members.setdefault(root(i), []).append(i)
    if max(len(comp) for comp in members.values()) > KKT_BLOCK_MAX_Q:
        return {"kkt_blocks": False}
    minv, sigma = {}, []                       # M⁻¹ by M's blocks: (i, j) -> entry
    for comp in members.values():
        inv = np.linalg.inv(M[np.ix_(comp, comp)])
        inv = (inv + inv.T) / 2
        sigma += list(np.linalg.svd(M[np.ix_(comp, comp)], compute_uv=False))
        minv.update({(i, j): inv[a, b] for a, i in enumerate(comp) for b, j in enumerate(comp) if inv[a, b] != 0})
    if max(sigma) > KKT_MAX_COND * min(sigma):
        return {"kkt_blocks": False}
    touched = [[] for _ in range(nc)]
    for _, c, j in lower + upper:
        touched[c].append(j)
    for c, cols in enumerate(touched):
        for j in cols[1:]:
            join(cols[0], j)
    order = {}
    for i in range(nq):
        order.setdefault(root(i), len(order))
    qs = [[] for _ in order]
    cs = [[] for _ in order]
    for i in range(nq):
        qs[order[root(i)]].append(i)
    for c, cols in enumerate(touched):
        if not cols:                           # a constraint on no coordinate: S singular
            return {"kkt_blocks": False}
        cs[order[root(cols[0])]].append(c)
    if max(len(c) for c in cs) > KKT_BLOCK_MAX or max(len(q) for q in qs) > KKT_BLOCK_MAX_Q:
        return {"kkt_blocks": False}
    local_q, local_c, a_off = {}, {}, {}
    m_colind, m_row, m_val, off = [0], [], [], 0
    for b, (qb, cb) in enumerate(zip(qs, cs)):
        local_q.update({i: (b, k) for k, i in enumerate(qb)})
        local_c.update({c: k for k, c in enumerate(cb)})
        a_off[b] = off
        off += len(cb) * len(qb)
        for j in qb:
            rows = [(a, minv[i, j]) for a, i in enumerate(qb) if (i, j) in minv]
            m_row += [a for a, _ in rows]
            m_val += [c_real(x) for _, x in rows]
            m_colind.append(len(m_row))

    def scatter(entries):
        nz, dst = [], []
        for k, c, j in entries:
            b, jl = local_q[j]
            nz.append(int(k))
            dst.append(a_off[b] + local_c[c] * len(qs[b]) + jl)
        return nz, dst

    a1_nz, a1_dst = scatter(lower)
    a0_nz, a0_dst = scatter(upper)
    newton = model.functions["F"].jac_sparsity(0, 2).nnz() == 0
    return {"kkt_blocks": True, "kkt_newton": newton, "kkt_nb": len(qs),
            "kkt_q0": [int(x) for x in np.cumsum([0] + [len(q) for q in qs])], "kkt_q": [i for q in qs for i in q],
            "kkt_c0": [int(x) for x in np.cumsum([0] + [len(c) for c in cs])], "kkt_c": [c for cb in cs for c in cb],
            "kkt_m_colind": m_colind, "kkt_m_row": m_row, "kkt_m_val": m_val, "kkt_na": off,
            "kkt_ns": sum(len(c) ** 2 for c in cs),
            "kkt_cmax": max(len(c) for c in cs), "kkt_a1_nz": a1_nz, "kkt_a1_dst": a1_dst,
            "kkt_a0_nz": a0_nz, "kkt_a0_dst": a0_dst}
